// The machined workpiece as a closed triangle mesh: surface.stl (binary
// STL) and surface.wrl (VRML97, the display format the paper names).
//
// Contract of BuildSurfaceMesh:
// - Top: a lattice of (nx s + 1) x (ny s + 1) vertices, s the subdivision;
//   vertex (I, J) lies at NodeX(I / s) + (I % s) dx / s,
//   NodeY(J / s) + (J % s) dy / s (exactly on the grid nodes where I and J
//   are multiples of s), at the height of the scheme's reconstruction of
//   element (min(I / s, nx - 1), min(J / s, ny - 1)) - for
//   taylor the eq. (2) patches, between nodes too. Each lattice cell is two
//   triangles, split along the diagonal whose ends differ less in height;
//   they are the mesh's first 2 NX NY triangles, cell by cell, row-major.
// - Four vertical side walls from the top's boundary vertices (each one
//   used, so no T-junctions) down to z_bottom, and a flat bottom at
//   z_bottom made of the walls' bottom vertices only.
// - Closed and consistently oriented: every undirected edge belongs to
//   exactly two triangles, each directed edge to one, and triangles are
//   counter-clockwise seen from outside. Triangles:
//   2 NX NY + 6 (NX + NY) - 2 with NX = nx s, NY = ny s; vertices:
//   (NX + 1)(NY + 1) + 2 (NX + NY).
#ifndef SWARF_CLIENT_SURFACE_MESH_H_
#define SWARF_CLIENT_SURFACE_MESH_H_

#include <array>
#include <memory>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "client/outputs/png_image.h"
#include "client/outputs/surface_grid.h"
#include "core/geometry.h"

namespace swarf::cli {

struct TriangleMesh {
  std::vector<Vec3> vertices;  // mm
  std::vector<std::array<int32_t, 3>> triangles;  // ccw seen from outside
  // The first top_vertices vertices are the top lattice, row-major (J, I).
  int64_t top_vertices = 0;
  // (With a tolerance: the lattice vertices kept, in that order.)
  int32_t lattice_nx = 0, lattice_ny = 0;  // NX, NY: lattice cells
  double z_bottom = 0;
  // Largest vertical distance (mm) between the top and the full-resolution
  // lattice surface, measured (0 for the full lattice itself).
  double max_deviation = 0;
};

struct SurfaceMeshOptions {
  // s >= 1: every element as s x s lattice cells.
  int subdivision = 1;
  // The bottom plane (mm); must lie strictly below every top vertex. Absent:
  // DefaultZBottom of the lowest top vertex.
  std::optional<double> z_bottom;
  // > 0: SimplifySurfaceMesh with this tolerance (mm); 0: the full lattice.
  double tolerance = 0;
};

// Most top lattice vertices BuildSurfaceMesh accepts (int32 triangle
// indices with room for the walls), and the most a lattice whose heights
// are held may have (8 bytes a vertex: 2 GiB).
inline constexpr int64_t kMaxMeshTopVertices = int64_t{1} << 28;
// Most vertices of a lattice whose heights are read again (NewLattice with
// heights false: the streamed full mesh, the adaptive mesh): 1 byte a
// vertex, indices 64-bit. The streamed STL's triangle count must still fit
// its uint32 field, and the adaptive mesh's own vertices int32 indices.
inline constexpr int64_t kMaxStreamedLatticeVertices = (int64_t{1} << 31) - 1;

// A bottom plane below `z_min` (the lowest top vertex) by a tenth of the
// depth machined below the top, and at least 2% of the stock's longer side.
double DefaultZBottom(const StockSpec& spec, double z_min);

// The top lattice's heights, what both meshes are made from: filled band
// by band (FillLatticeRows), 8 bytes a lattice vertex plus its coordinates
// along x and y. Vertex (I, J) is (xs[I], ys[J], z[J (NX + 1) + I]), as
// BuildSurfaceMesh places it. Without heights (z empty) only row_min is
// kept: the adaptive mesh then reads them again (LatticeWindows).
struct LatticeHeights {
  int64_t nx = 0, ny = 0;  // NX, NY: lattice cells
  int s = 1;               // the subdivision
  int32_t elements_y = 0;  // the grid's ny
  std::vector<double> xs, ys, z;
  std::vector<double> row_min;  // per lattice row: min(z_top, its heights)
  double Z(int64_t i, int64_t j) const { return z[j * (nx + 1) + i]; }
};

// An empty lattice for `spec` at subdivision `s` (heights held unless
// `heights` is false); InvalidArgument for an invalid spec, s outside
// [1, 4096] or more than kMaxMeshTopVertices vertices (heights held) or
// kMaxStreamedLatticeVertices (not held).
absl::StatusOr<LatticeHeights> NewLattice(const StockSpec& spec, int s,
                                          bool heights = true);
// Sets the lattice rows J whose element row min(J / s, ny - 1) lies in
// [e0, e1), from `band` (which holds those elements), in parallel.
void FillLatticeRows(const SurfaceGrid& band, int32_t e0, int32_t e1,
                     LatticeHeights* lattice);
class LatticeWindows;

// The mesh BuildSurfaceMesh makes once every row is filled (`lattice` is
// not kept). A lattice without heights needs `rows` (its heights, read
// again) and a tolerance > 0 (the adaptive mesh); else InvalidArgument.
absl::StatusOr<TriangleMesh> MeshFromLattice(LatticeHeights lattice,
                                             const StockSpec& spec,
                                             const SurfaceMeshOptions& options,
                                             LatticeWindows* rows = nullptr);
// A lattice's heights a window of rows at a time, for SimplifyLatticeRows.
class LatticeWindows {
 public:
  virtual ~LatticeWindows() = default;
  // Rows [j0, j1] (inclusive), row-major, NX + 1 heights a row, exactly
  // LatticeHeights::z's; valid until the next call. Errors are returned by
  // SimplifyLatticeRows.
  virtual absl::StatusOr<const double*> Rows(int64_t j0, int64_t j1) = 0;
};

// SimplifyLattice with the heights read a window of 66 rows at a time
// (each root row of 64 x 64 cells, several times: once for the tree, once
// each conforming pass that has work there, once for the vertices) instead
// of held: memory is 1 byte a lattice vertex plus the leaves'. The same
// mesh, bit for bit. `xs` and `ys` as LatticeHeights'.
absl::StatusOr<TriangleMesh> SimplifyLatticeRows(
    LatticeWindows& rows, const std::vector<double>& xs,
    const std::vector<double>& ys, double z_bottom, double tolerance);

// The rows of a lattice whose heights are held (LatticeHeights::z); not
// owned, must outlive the result.
std::unique_ptr<LatticeWindows> HeldLatticeRows(const LatticeHeights& lattice);

// The full-resolution mesh (BuildSurfaceMesh with tolerance 0: the same
// vertices and triangles in the same order) written straight from the
// lattice's rows, read a window of 65 at a time (STL once, VRML three
// times: points, colours, faces), never built: WriteStl and WriteVrml (with
// SurfaceColors when `colors`) of that mesh, byte for byte. `lattice`
// gives xs, ys and row_min (its heights, if held, are not read: `rows`
// gives them). z_bottom must lie below every top vertex (MeshFromLattice's
// check). Errors as WriteStl's and WriteVrml's.
absl::Status WriteLatticeStl(LatticeWindows& rows,
                             const LatticeHeights& lattice, double z_bottom,
                             const std::string& path);
absl::Status WriteLatticeVrml(LatticeWindows& rows,
                              const LatticeHeights& lattice, double z_bottom,
                              double z_top, bool colors,
                              const std::string& path);
// Triangles of the full-resolution mesh of an NX x NY lattice.
inline int64_t FullMeshTriangles(int64_t nx, int64_t ny) {
  return 2 * nx * ny + 6 * (nx + ny) - 2;
}

// SimplifySurfaceMesh of the full mesh of `lattice` (with bottom z_bottom),
// without building that mesh.
absl::StatusOr<TriangleMesh> SimplifyLattice(const LatticeHeights& lattice,
                                             double z_bottom,
                                             double tolerance);

// InvalidArgument for an invalid grid, subdivision < 1, too many vertices,
// or a z_bottom that is not finite or not below every top vertex.
absl::StatusOr<TriangleMesh> BuildSurfaceMesh(
    const SurfaceGrid& grid, const SurfaceMeshOptions& options = {});

// An error-bounded adaptive version of a full-resolution mesh from
// BuildSurfaceMesh (only its vertices are read): the top is re-triangulated on a subset of the lattice
// vertices (squares of 2^k lattice cells, conforming, no T-junctions) so
// that its vertical distance to the full-resolution top, measured
// everywhere (at every lattice vertex and wherever an edge of one crosses
// an edge of the other; the largest in max_deviation), is at most
// `tolerance` mm. The same walls under the top's boundary edges and a flat
// bottom at the same z_bottom fanned from one vertex under its middle:
// closed and oriented as the full mesh. The top vertices come first, in
// lattice row-major order. InvalidArgument for a negative or non-finite
// tolerance or a mesh BuildSurfaceMesh did not make.
absl::StatusOr<TriangleMesh> SimplifySurfaceMesh(const TriangleMesh& full,
                                                 double tolerance);

// Binary STL: 80-byte header (not starting with "solid"), little-endian
// uint32 triangle count, per triangle the unit normal (from the vertices'
// cross product; zero for a degenerate triangle), three vertices as float32
// and a zero attribute word.
absl::Status WriteStl(const TriangleMesh& mesh, const std::string& path);

// Per-vertex colours for WriteVrml: top vertices tinted by height as in
// relief.png (kStockColor at z_top), walls and bottom darker grey.
std::vector<Rgb> SurfaceColors(const TriangleMesh& mesh, double z_top);

// VRML97: one Shape with an IndexedFaceSet (solid, ccw, creaseAngle 0.5),
// coordinates as the STL's float32 values, and per-vertex colours when
// `vertex_colors` has one per vertex (InvalidArgument if it has another
// non-zero size).
absl::Status WriteVrml(const TriangleMesh& mesh, const std::string& path,
                       std::span<const Rgb> vertex_colors = {});

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_SURFACE_MESH_H_
