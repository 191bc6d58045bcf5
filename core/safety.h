// Tool assemblies and what they meet: the non-cutting parts of a tool (the
// shank above the flutes, the holder above the stick-out) and the query of
// the height field that tells whether material stands where they pass.
//
// The cutting part's own checks (a rapid that cuts, the shank rubbing where
// a move cuts deeper than the flute length) come from the lowerings the
// move makes (Workpiece::Apply with ApplyOptions::cuts); the parts wider
// than the cutter are queried here, after the batch that holds the move:
// material still standing then stood when the move passed (nodes only go
// down), so a contact found is real; one with material that a later move of
// the same batch removed is not seen.
#ifndef SWARF_CORE_SAFETY_H_
#define SWARF_CORE_SAFETY_H_

#include "core/geometry.h"

namespace swarf {

class Workpiece;

// All lengths in mm; 0 where not known (no check is made on that part).
struct ToolAssembly {
  double flute_length = 0;     // from the tip up
  double shank_diameter = 0;   // 0: the cutter's diameter
  double holder_diameter = 0;  // the holder's (collet nut's) diameter
  double stickout = 0;         // from the holder's face down to the tip
  bool center_cutting = true;  // false: must not plunge straight down

  bool known() const {
    return flute_length > 0 || holder_diameter > 0 || !center_cutting;
  }
  friend bool operator==(const ToolAssembly&, const ToolAssembly&) = default;
};

// Material met by a vertical cylinder of `radius` whose bottom is `offset`
// above the tool tip, swept with the tip along from -> to: over the nodes
// within `radius` (in XY) of the segment, the node's height minus the
// lowest bottom of the cylinder over it while it covers the node.
struct Contact {
  bool hit = false;
  double depth = 0;        // the largest interference (mm)
  double x = 0, y = 0, z = 0;  // its node and height
  double volume_mm3 = 0;   // the interferences times dx * dy
};
Contact CylinderContact(const Workpiece& wp, const Vec3& from, const Vec3& to,
                        double radius, double offset);

}  // namespace swarf

#endif  // SWARF_CORE_SAFETY_H_
