// Canonical commands: what the G-code interpreter (gcode/interpreter.cc)
// emits, after LinuxCNC's canonical machining functions. Every position is
// the tool tip in machine coordinates, mm (offsets, units and compensation
// applied). The interpreter emits to one sink:
// - ToolpathBuilder (gcode/toolpath.cc): the points of a Toolpath, arcs
//   chorded within the arc tolerance (what `swarf run` simulates);
// - `swarf moves` (client/cli/moves_command.cc): prints each command.
#ifndef SWARF_GCODE_CANON_H_
#define SWARF_GCODE_CANON_H_

#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "core/geometry.h"

namespace swarf::gcode {

// A straight move (or the first position of a run).
struct CanonStraight {
  Vec3 end;
  int32_t line = 0;    // the main program's line
  uint16_t tool = 0;   // tool in effect
  bool rapid = false;  // a traverse (G0 and the cycles' rapids)
  // A feed move's programmed feed (mm/min: F times the units; 0 for F0 or
  // before any F); 0 for rapids.
  double feed = 0;
  // No move reaches `end`: the position became known here (the program's
  // first point, or the first after the position was lost).
  bool starts_run = false;
};

// An arc (a helix, or a spiral when the radii differ) in the plane of axes
// (p0, p1) (0 = X, 1 = Y, 2 = Z) about the axis p2: from angle a0 (about
// the centre, measured from p0 towards p1) through `sweep` radians
// (positive: counterclockwise seen from +p2), the radius linear in the angle
// from r0 to r1 and the p2 coordinate linear from z0; it ends exactly at
// `end` (x, y, z). The start is the previous command's end.
struct CanonArc {
  Vec3 end;
  int p0 = 0, p1 = 1, p2 = 2;
  double cx = 0, cy = 0;  // the centre in (p0, p1)
  double r0 = 0, r1 = 0;
  double a0 = 0, sweep = 0;
  double z0 = 0;
  int32_t line = 0;
  uint16_t tool = 0;
  bool rapid = false;  // (never for programmed arcs)
  double feed = 0;     // as CanonStraight::feed

  // The centre in x, y, z (the axis coordinate of the start).
  Vec3 Centre() const {
    double c[3];
    c[p0] = cx;
    c[p1] = cy;
    c[p2] = z0;
    return {c[0], c[1], c[2]};
  }
  // LinuxCNC's rotation: the signed number of turns begun (+ ccw).
  int64_t Turns() const;
};

class CanonSink {
 public:
  virtual ~CanonSink() = default;
  // Errors are plain messages; the interpreter names the line.
  virtual absl::Status Straight(const CanonStraight& m) = 0;
  virtual absl::Status ArcFeed(const CanonArc& a) = 0;
  // M6 (after any move to the tool-change position), M61.
  virtual void ToolChange(int32_t /*line*/, int /*tool*/) {}
  // G4 (the cycles' dwells are not emitted: a dwell doesn't move the tool).
  virtual void Dwell(int32_t /*line*/, double /*seconds*/) {}
  // Messages for the user (none emitted yet: comments are skipped).
  virtual void Message(int32_t /*line*/, const std::string& /*text*/) {}
};

}  // namespace swarf::gcode

#endif  // SWARF_GCODE_CANON_H_
