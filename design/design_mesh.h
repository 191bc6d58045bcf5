// The design model: the part as designed, a triangle mesh in the stock's
// coordinates, read from STL (binary or ASCII) or STEP (tessellated through
// OpenCASCADE).
//
// Contract:
// - Units: millimetres once read (DesignReadOptions::scale converts inches),
//   already moved by DesignReadOptions::offset.
// - Vertices are welded (equal coordinates, bit for bit, are one vertex);
//   triangles index them. Degenerate triangles (two equal corners or zero
//   area) are dropped and counted.
// - Every error is InvalidArgument naming the file and what and where (the
//   STL line or triangle, the edge's coordinates), or ResourceExhausted for a
//   design over the stated limit. Value types: no sharing, no locking.
#ifndef SWARF_DESIGN_DESIGN_MESH_H_
#define SWARF_DESIGN_DESIGN_MESH_H_

#include <array>
#include <cstdint>
#include <string>
#include "absl/strings/string_view.h"
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry.h"

namespace swarf::design {

struct DesignMesh {
  std::vector<Vec3> vertices;
  std::vector<std::array<int32_t, 3>> triangles;
  int64_t degenerate_dropped = 0;
  // Every edge shared by exactly two triangles (a solid, not only its top
  // surface), and then whether the triangles wind outwards (positive
  // enclosed volume).
  bool closed = false;
  bool outward = true;
  // Bounds of the vertices (empty when there are none).
  Interval x, y, z;
};

// The largest design accepted by default (triangles): about 1.3 GB of
// vertices and indices at its worst.
inline constexpr int64_t kDefaultMaxDesignTriangles = 20'000'000;

// Coordinates beyond +-1e9 mm are refused (as the toolpath parsers'):
// the envelope holds floats.
inline constexpr double kMaxDesignCoordinate = 1e9;

struct DesignReadOptions {
  double scale = 1.0;   // file units -> mm (25.4 for inches)
  Vec3 offset;          // added after scaling, mm
  int64_t max_triangles = kDefaultMaxDesignTriangles;
  // STEP: the tessellation's linear deflection (mm, in file units times
  // scale) and angular deflection (radians).
  double step_deflection = 0.001;
  double step_angular_deflection = 0.1;
};

// STL bytes, binary or ASCII (binary when the size is 84 + 50 n for the
// count n in its header, as every binary writer leaves it; else ASCII).
// `name` prefixes messages.
absl::StatusOr<DesignMesh> ParseStl(absl::string_view bytes,
                                    const std::string& name,
                                    const DesignReadOptions& options = {});

// Reads `path` by content: STEP ("ISO-10303-21;" first), else STL.
// NotFound when it cannot be opened.
absl::StatusOr<DesignMesh> ReadDesignFile(const std::string& path,
                                          const DesignReadOptions& options = {});

// The bytes of a design file by content, as ReadDesignFile: STEP through a
// temporary file (OpenCASCADE reads files), else STL. `name` in messages.
absl::StatusOr<DesignMesh> ParseDesign(absl::string_view bytes,
                                       const std::string& name,
                                       const DesignReadOptions& options = {});

// Welds and checks a triangle soup (9 doubles a triangle, mm, options
// applied by the caller): NaN, infinite or out-of-range coordinates
// (kMaxDesignCoordinate), no triangle left,
// more than options.max_triangles, an edge shared by more than two
// triangles (non-manifold). Used by the readers and for uploaded designs.
absl::StatusOr<DesignMesh> MeshFromSoup(const std::vector<double>& soup,
                                        const std::string& name,
                                        int64_t max_triangles =
                                            kDefaultMaxDesignTriangles);

// Binary STL of a mesh (the tests' and examples' writer).
std::string ToBinaryStl(const DesignMesh& mesh);

}  // namespace swarf::design

#endif  // SWARF_DESIGN_DESIGN_MESH_H_
