#include "client/outputs/surface_mesh.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string>
#include <string_view>

#include "absl/strings/str_format.h"
#include "client/outputs/colormap.h"
#include "client/outputs/file_writer.h"
#include "core/scheme.h"
#include "core/thread_pool.h"

namespace swarf::cli {
namespace {

// STL is little-endian; the writer copies floats as they are in memory.
static_assert(std::endian::native == std::endian::little,
              "WriteStl assumes a little-endian host");

constexpr Rgb kWallColor = {110, 110, 110};

// One binary STL record (50 bytes to `rec`): the unit normal from the
// cross product (zero for a degenerate triangle), the vertices as float32,
// a zero attribute word.
void StlRecord(const Vec3& p, const Vec3& q, const Vec3& r, char* rec) {
  const double ux = q.x - p.x, uy = q.y - p.y, uz = q.z - p.z;
  const double vx = r.x - p.x, vy = r.y - p.y, vz = r.z - p.z;
  double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
  const double len = std::sqrt(nx * nx + ny * ny + nz * nz);
  if (len > 0 && std::isfinite(len)) {
    nx /= len;
    ny /= len;
    nz /= len;
  } else {
    nx = ny = nz = 0;
  }
  const float f[12] = {static_cast<float>(nx),  static_cast<float>(ny),
                       static_cast<float>(nz),  static_cast<float>(p.x),
                       static_cast<float>(p.y), static_cast<float>(p.z),
                       static_cast<float>(q.x), static_cast<float>(q.y),
                       static_cast<float>(q.z), static_cast<float>(r.x),
                       static_cast<float>(r.y), static_cast<float>(r.z)};
  std::memcpy(rec, f, 48);
  rec[48] = rec[49] = 0;
}

constexpr size_t kStlRecordBytes = 50;

void AppendStlRecord(const Vec3& p, const Vec3& q, const Vec3& r,
                     FileWriter& out) {
  char rec[kStlRecordBytes];
  StlRecord(p, q, r, rec);
  out.Write(std::string_view(rec, kStlRecordBytes));
}

// Items a chunk of the meshes' files is made of (WriteChunks): about 800
// KB of STL records, 1 MB of VRML text.
constexpr int64_t kStlChunk = 16384;
constexpr int64_t kVrmlChunk = 32768;

// A vertex of the full-resolution mesh: top lattice vertex (i, j), or the
// bottom vertex under boundary vertex (i, j).
struct MeshVertex {
  bool bottom;
  int64_t i, j;
};

// The full mesh's walls and bottom face, in BuildSurfaceMesh's order, to
// emit(a, b, c).
template <typename Emit>
void EmitWallsAndBottom(int64_t big_nx, int64_t big_ny, Emit emit) {
  auto top = [](int64_t i, int64_t j) { return MeshVertex{false, i, j}; };
  auto bot = [](int64_t i, int64_t j) { return MeshVertex{true, i, j}; };
  // Side walls: the top's boundary runs counter-clockwise seen from above
  // (a -> b); each wall quad takes the reverse edge b -> a and its bottom
  // edge a' -> b', leaving b' -> a' to the bottom face.
  auto wall = [&](MeshVertex a, MeshVertex b, MeshVertex ab, MeshVertex bb) {
    emit(ab, bb, b);
    emit(ab, b, a);
  };
  for (int64_t i = 0; i < big_nx; ++i) {  // south, eastwards
    wall(top(i, 0), top(i + 1, 0), bot(i, 0), bot(i + 1, 0));
  }
  for (int64_t j = 0; j < big_ny; ++j) {  // east, northwards
    wall(top(big_nx, j), top(big_nx, j + 1), bot(big_nx, j),
         bot(big_nx, j + 1));
  }
  for (int64_t i = big_nx; i > 0; --i) {  // north, westwards
    wall(top(i, big_ny), top(i - 1, big_ny), bot(i, big_ny),
         bot(i - 1, big_ny));
  }
  for (int64_t j = big_ny; j > 0; --j) {  // west, southwards
    wall(top(0, j), top(0, j - 1), bot(0, j), bot(0, j - 1));
  }
  // Bottom face, clockwise seen from above, using only the walls' bottom
  // vertices and no degenerate (collinear) triangle: columns between the
  // south and north rows, with the west and east columns fanned from an
  // inner south vertex to take the vertices of the west and east sides.
  if (big_nx == 1) {
    for (int64_t j = 0; j < big_ny; ++j) {
      emit(bot(0, j), bot(1, j + 1), bot(1, j));
      emit(bot(0, j), bot(0, j + 1), bot(1, j + 1));
    }
  } else {
    const MeshVertex cw = bot(1, 0);
    for (int64_t j = 0; j < big_ny; ++j) emit(cw, bot(0, j), bot(0, j + 1));
    emit(cw, bot(0, big_ny), bot(1, big_ny));
    for (int64_t i = 1; i + 1 < big_nx; ++i) {
      emit(bot(i, 0), bot(i + 1, big_ny), bot(i + 1, 0));
      emit(bot(i, 0), bot(i, big_ny), bot(i + 1, big_ny));
    }
    const MeshVertex ce = bot(big_nx - 1, 0);
    for (int64_t j = 0; j < big_ny; ++j) {
      emit(ce, bot(big_nx, j + 1), bot(big_nx, j));
    }
    emit(ce, bot(big_nx - 1, big_ny), bot(big_nx, big_ny));
  }
}

// Index of bottom vertex (i, j) in the full mesh (after the top's): the
// south and north rows (corners included), then the west and east columns.
int64_t BottomIndex(int64_t big_nx, int64_t big_ny, int64_t i, int64_t j) {
  const int64_t top = (big_nx + 1) * (big_ny + 1);
  if (j == 0) return top + i;
  if (j == big_ny) return top + (big_nx + 1) + i;
  if (i == 0) return top + 2 * (big_nx + 1) + (j - 1);
  return top + 2 * (big_nx + 1) + (big_ny - 1) + (j - 1);
}

// The top cells' triangles, row by row from windows of rows, as
// BuildSurfaceMesh splits them, to emit(a, b, c) with the heights
// z(i, j) of the window (valid during the call). Keeps the boundary's
// heights in `boundary` (south row, north row, west and east columns).
struct BoundaryHeights {
  std::vector<double> south, north, west, east;
};

template <typename Emit>
absl::Status EmitTopCells(LatticeWindows& rows, int64_t big_nx, int64_t big_ny,
                          BoundaryHeights* boundary, Emit emit) {
  constexpr int64_t kRows = 64;
  boundary->west.resize(big_ny + 1);
  boundary->east.resize(big_ny + 1);
  for (int64_t j0 = 0; j0 < big_ny; j0 += kRows) {
    const int64_t j1 = std::min(big_ny, j0 + kRows);
    absl::StatusOr<const double*> z = rows.Rows(j0, j1);
    if (!z.ok()) return z.status();
    auto at = [&](int64_t i, int64_t j) {
      return (*z)[(j - j0) * (big_nx + 1) + i];
    };
    for (int64_t j = j0; j <= j1; ++j) {
      boundary->west[j] = at(0, j);
      boundary->east[j] = at(big_nx, j);
    }
    if (j0 == 0) boundary->south.assign(*z, *z + big_nx + 1);
    if (j1 == big_ny) {
      boundary->north.assign(*z + (j1 - j0) * (big_nx + 1),
                             *z + (j1 - j0 + 1) * (big_nx + 1));
    }
    for (int64_t j = j0; j < j1; ++j) {
      for (int64_t i = 0; i < big_nx; ++i) {
        const double z00 = at(i, j), z10 = at(i + 1, j), z11 = at(i + 1, j + 1),
                     z01 = at(i, j + 1);
        const MeshVertex v00{false, i, j}, v10{false, i + 1, j},
            v11{false, i + 1, j + 1}, v01{false, i, j + 1};
        // The diagonal along the smaller height change follows a crease or
        // a groove instead of cutting across it.
        if (std::fabs(z00 - z11) <= std::fabs(z10 - z01)) {
          emit(v00, v10, v11, at);
          emit(v00, v11, v01, at);
        } else {
          emit(v00, v10, v01, at);
          emit(v10, v11, v01, at);
        }
      }
    }
  }
  return absl::OkStatus();
}

class HeldRowsOf : public LatticeWindows {
 public:
  explicit HeldRowsOf(const LatticeHeights& h) : h_(h) {}
  absl::StatusOr<const double*> Rows(int64_t j0, int64_t) override {
    return h_.z.data() + j0 * (h_.nx + 1);
  }

 private:
  const LatticeHeights& h_;
};

// The binary STL's 80-byte header and its triangle count (WriteStl,
// WriteLatticeStl).
void WriteStlHeader(uint32_t triangles, FileWriter& out) {
  char header[80] = {};
  std::snprintf(header, sizeof header,
                "swarf machined surface, binary STL, mm, %zu triangles",
                static_cast<size_t>(triangles));
  out.Write(std::string_view(header, sizeof header));
  out.Write(std::string_view(reinterpret_cast<const char*>(&triangles), 4));
}

}  // namespace

double DefaultZBottom(const StockSpec& spec, double z_min) {
  const double longer = std::max(spec.x1 - spec.x0, spec.y1 - spec.y0);
  return z_min - std::max(0.1 * (spec.z_top - z_min), 0.02 * longer);
}

absl::StatusOr<LatticeHeights> NewLattice(const StockSpec& spec, int s,
                                          bool heights) {
  if (absl::Status st = ValidateStock(spec); !st.ok()) return st;
  if (s < 1 || s > 4096) {
    return absl::InvalidArgumentError(
        absl::StrFormat("subdivision must be in [1, 4096], got %d", s));
  }
  const int64_t nx = spec.nx, ny = spec.ny;
  const int64_t big_nx = nx * s, big_ny = ny * s;
  const int64_t top = (big_nx + 1) * (big_ny + 1);
  // Held heights cost 8 bytes a vertex; heights read again cost 1 (the
  // adaptive mesh's marks), so only the index width bounds those.
  const int64_t cap = heights ? kMaxMeshTopVertices : kMaxStreamedLatticeVertices;
  if (top > cap) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "a %d x %d lattice (grid %d x %d, subdivision %d) exceeds %d "
        "vertices%s",
        big_nx, big_ny, nx, ny, s, cap,
        heights ? " (with its heights held)" : ""));
  }
  const GridGeometry g(spec);
  LatticeHeights l;
  l.nx = big_nx;
  l.ny = big_ny;
  l.s = s;
  l.elements_y = spec.ny;
  l.xs.resize(big_nx + 1);
  l.ys.resize(big_ny + 1);
  for (int64_t i = 0; i <= big_nx; ++i) {
    l.xs[i] = g.NodeX(static_cast<int32_t>(i / s)) + (i % s) * (g.dx() / s);
  }
  for (int64_t j = 0; j <= big_ny; ++j) {
    l.ys[j] = g.NodeY(static_cast<int32_t>(j / s)) + (j % s) * (g.dy() / s);
  }
  if (heights) l.z.resize(top);
  l.row_min.assign(big_ny + 1, spec.z_top);
  return l;
}

void FillLatticeRows(const SurfaceGrid& grid, int32_t e0, int32_t e1,
                     LatticeHeights* lattice) {
  LatticeHeights& l = *lattice;
  const int s = l.s;
  const int64_t nx = grid.spec.nx, ny = grid.spec.ny;
  const int64_t big_nx = l.nx;
  const Scheme& scheme = GetScheme(grid.scheme);
  // Lattice rows of element rows [e0, e1): from e0 s to e1 s - 1, and the
  // last row (J = NY) with the last element row.
  const int64_t j0 = int64_t{e0} * s;
  const int64_t j1 = e1 == ny ? l.ny + 1 : int64_t{e1} * s;
  ThreadPool::Default().ParallelFor(j1 - j0, [&](int64_t r) {
    const int64_t j = j0 + r;
    const int32_t ej = static_cast<int32_t>(std::min(j / s, ny - 1));
    // The row's place among the nodes' rows, once a row (not three 64-bit
    // divisions a vertex).
    const bool node_row = j % s == 0;
    const int32_t nj = static_cast<int32_t>(j / s);
    double lo = grid.spec.z_top;
    double* const row = l.z.empty() ? nullptr : &l.z[j * (big_nx + 1)];
    // One element's corners at a time, in one object for the row: a
    // std::optional of them declared for each element had its storage
    // cleared each time, most of the pass's time at s = 1, where no
    // corners are needed.
    ElementCorners e;
    for (int32_t ei = 0; ei < nx; ++ei) {
      // Corners once per element for its s (s + 1 in the last) vertices,
      // and only where one lies between nodes (never at s = 1).
      bool have_e = false;
      // Vertex i = ei s + k: a node where k is 0 or s (node ei + k / s).
      const int64_t k_end = ei == nx - 1 ? s : s - 1;
      for (int64_t k = 0; k <= k_end; ++k) {
        const int64_t i = ei * int64_t{s} + k;
        // At a node its simulated height is exact; eq. (2) there can sit
        // below it where a neighbour's patch, extrapolated across a steep
        // element, undershoots. The patches fill in between nodes.
        double z;
        if (node_row && (k == 0 || k == s)) {
          z = std::min(grid.jet(k == 0 ? ei : ei + 1, nj).w, grid.spec.z_top);
        } else {
          if (!have_e) {
            e = grid.Corners(ei, ej);
            have_e = true;
          }
          z = scheme.Reconstruct(e, l.xs[i], l.ys[j]);
        }
        if (row != nullptr) row[i] = z;
        lo = std::min(lo, z);
      }
    }
    l.row_min[j] = lo;
  });
}

absl::StatusOr<TriangleMesh> BuildSurfaceMesh(
    const SurfaceGrid& grid, const SurfaceMeshOptions& options) {
  if (absl::Status st = grid.Validate(); !st.ok()) return st;
  auto lattice = NewLattice(grid.spec, options.subdivision);
  if (!lattice.ok()) return lattice.status();
  FillLatticeRows(grid, 0, grid.spec.ny, &*lattice);
  return MeshFromLattice(*std::move(lattice), grid.spec, options);
}

absl::StatusOr<TriangleMesh> MeshFromLattice(LatticeHeights lattice,
                                             const StockSpec& spec,
                                             const SurfaceMeshOptions& options,
                                             LatticeWindows* rows) {
  const LatticeHeights& l = lattice;
  const double z_min = *std::min_element(l.row_min.begin(), l.row_min.end());
  const double z_bottom =
      options.z_bottom ? *options.z_bottom : DefaultZBottom(spec, z_min);
  if (!std::isfinite(z_bottom) || !(z_bottom < z_min)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "z_bottom %g must be finite and below the lowest top vertex %g",
        z_bottom, z_min));
  }
  if (l.z.empty() && (rows == nullptr || options.tolerance == 0)) {
    return absl::InvalidArgumentError(
        "a lattice without heights needs them read again, for the adaptive "
        "mesh only");
  }
  // The adaptive mesh needs only the lattice's heights.
  if (options.tolerance != 0) {
    if (l.z.empty()) {
      return SimplifyLatticeRows(*rows, l.xs, l.ys, z_bottom,
                                 options.tolerance);
    }
    return SimplifyLattice(l, z_bottom, options.tolerance);
  }
  const int64_t big_nx = l.nx, big_ny = l.ny;
  const int64_t top = (big_nx + 1) * (big_ny + 1);
  const std::vector<double>& xs = l.xs;
  const std::vector<double>& ys = l.ys;
  TriangleMesh mesh;
  mesh.top_vertices = top;
  mesh.lattice_nx = static_cast<int32_t>(big_nx);
  mesh.lattice_ny = static_cast<int32_t>(big_ny);
  mesh.z_bottom = z_bottom;
  mesh.vertices.resize(top + 2 * (big_nx + big_ny));
  auto top_index = [big_nx](int64_t i, int64_t j) {
    return static_cast<int32_t>(j * (big_nx + 1) + i);
  };
  ThreadPool::Default().ParallelFor(big_ny + 1, [&](int64_t j) {
    for (int64_t i = 0; i <= big_nx; ++i) {
      mesh.vertices[top_index(i, j)] = {xs[i], ys[j], l.Z(i, j)};
    }
  });
  lattice.z = {};

  // Bottom vertices, one under each boundary vertex of the top: the south
  // and north rows (corners included), then the west and east columns.
  auto bottom_index = [&](int64_t i, int64_t j) {
    int64_t k;
    if (j == 0) {
      k = i;
    } else if (j == big_ny) {
      k = (big_nx + 1) + i;
    } else if (i == 0) {
      k = 2 * (big_nx + 1) + (j - 1);
    } else {
      k = 2 * (big_nx + 1) + (big_ny - 1) + (j - 1);
    }
    return static_cast<int32_t>(top + k);
  };
  auto set_bottom = [&](int64_t i, int64_t j) {
    mesh.vertices[bottom_index(i, j)] = {xs[i], ys[j], z_bottom};
  };
  for (int64_t i = 0; i <= big_nx; ++i) {
    set_bottom(i, 0);
    set_bottom(i, big_ny);
  }
  for (int64_t j = 1; j < big_ny; ++j) {
    set_bottom(0, j);
    set_bottom(big_nx, j);
  }

  const int64_t top_tris = 2 * big_nx * big_ny;
  mesh.triangles.resize(top_tris);
  ThreadPool::Default().ParallelFor(big_ny, [&](int64_t j) {
    for (int64_t i = 0; i < big_nx; ++i) {
      const int32_t v00 = top_index(i, j), v10 = top_index(i + 1, j),
                    v11 = top_index(i + 1, j + 1), v01 = top_index(i, j + 1);
      const double z00 = mesh.vertices[v00].z, z10 = mesh.vertices[v10].z,
                   z11 = mesh.vertices[v11].z, z01 = mesh.vertices[v01].z;
      auto* t = &mesh.triangles[2 * (j * big_nx + i)];
      // The diagonal along the smaller height change follows a crease or
      // a groove instead of cutting across it.
      if (std::fabs(z00 - z11) <= std::fabs(z10 - z01)) {
        t[0] = {v00, v10, v11};
        t[1] = {v00, v11, v01};
      } else {
        t[0] = {v00, v10, v01};
        t[1] = {v10, v11, v01};
      }
    }
  });

  // Side walls: the top's boundary runs counter-clockwise seen from above
  // (a -> b); each wall quad takes the reverse edge b -> a and its bottom
  // edge a' -> b', leaving b' -> a' to the bottom face.
  mesh.triangles.reserve(top_tris + 6 * (big_nx + big_ny) - 2);
  auto wall = [&](int32_t a, int32_t b, int32_t ab, int32_t bb) {
    mesh.triangles.push_back({ab, bb, b});
    mesh.triangles.push_back({ab, b, a});
  };
  for (int64_t i = 0; i < big_nx; ++i) {  // south, eastwards
    wall(top_index(i, 0), top_index(i + 1, 0), bottom_index(i, 0),
         bottom_index(i + 1, 0));
  }
  for (int64_t j = 0; j < big_ny; ++j) {  // east, northwards
    wall(top_index(big_nx, j), top_index(big_nx, j + 1),
         bottom_index(big_nx, j), bottom_index(big_nx, j + 1));
  }
  for (int64_t i = big_nx; i > 0; --i) {  // north, westwards
    wall(top_index(i, big_ny), top_index(i - 1, big_ny),
         bottom_index(i, big_ny), bottom_index(i - 1, big_ny));
  }
  for (int64_t j = big_ny; j > 0; --j) {  // west, southwards
    wall(top_index(0, j), top_index(0, j - 1), bottom_index(0, j),
         bottom_index(0, j - 1));
  }

  // Bottom face, clockwise seen from above, using only the walls' bottom
  // vertices and no degenerate (collinear) triangle: columns between the
  // south and north rows, with the west and east columns fanned from an
  // inner south vertex to take the vertices of the west and east sides.
  auto b = [&](int64_t i, int64_t j) { return bottom_index(i, j); };
  if (big_nx == 1) {
    for (int64_t j = 0; j < big_ny; ++j) {
      mesh.triangles.push_back({b(0, j), b(1, j + 1), b(1, j)});
      mesh.triangles.push_back({b(0, j), b(0, j + 1), b(1, j + 1)});
    }
  } else {
    const int32_t cw = b(1, 0);
    for (int64_t j = 0; j < big_ny; ++j) {
      mesh.triangles.push_back({cw, b(0, j), b(0, j + 1)});
    }
    mesh.triangles.push_back({cw, b(0, big_ny), b(1, big_ny)});
    for (int64_t i = 1; i + 1 < big_nx; ++i) {
      mesh.triangles.push_back({b(i, 0), b(i + 1, big_ny), b(i + 1, 0)});
      mesh.triangles.push_back({b(i, 0), b(i, big_ny), b(i + 1, big_ny)});
    }
    const int32_t ce = b(big_nx - 1, 0);
    for (int64_t j = 0; j < big_ny; ++j) {
      mesh.triangles.push_back({ce, b(big_nx, j + 1), b(big_nx, j)});
    }
    mesh.triangles.push_back({ce, b(big_nx - 1, big_ny), b(big_nx, big_ny)});
  }
  return mesh;
}

absl::Status WriteStl(const TriangleMesh& mesh, const std::string& path) {
  if (mesh.triangles.size() > UINT32_MAX) {
    return absl::InvalidArgumentError("too many triangles for STL");
  }
  FileWriter out(path);
  if (!out.status().ok()) return out.status();
  WriteStlHeader(static_cast<uint32_t>(mesh.triangles.size()), out);
  out.WriteChunks(static_cast<int64_t>(mesh.triangles.size()), kStlChunk,
                  [&](int64_t first, int64_t last, std::string* piece) {
                    piece->resize((last - first) * kStlRecordBytes);
                    char* rec = piece->data();
                    for (int64_t k = first; k < last; ++k) {
                      const auto& t = mesh.triangles[k];
                      StlRecord(mesh.vertices[t[0]], mesh.vertices[t[1]],
                                mesh.vertices[t[2]], rec);
                      rec += kStlRecordBytes;
                    }
                  });
  return out.Close();
}

std::vector<Rgb> SurfaceColors(const TriangleMesh& mesh, double z_top) {
  std::vector<Rgb> colors(mesh.vertices.size(), kWallColor);
  double lo = z_top;
  for (int64_t k = 0; k < mesh.top_vertices; ++k) {
    lo = std::min(lo, mesh.vertices[k].z);
  }
  constexpr int64_t kChunk = 65536;
  ThreadPool::Default().ParallelFor(
      (mesh.top_vertices + kChunk - 1) / kChunk, [&](int64_t c) {
        const int64_t end = std::min(mesh.top_vertices, (c + 1) * kChunk);
        for (int64_t k = c * kChunk; k < end; ++k) {
          const double z = mesh.vertices[k].z;
          colors[k] =
              z < z_top ? HeightTint((z - lo) / (z_top - lo)) : kStockColor;
        }
      });
  return colors;
}

namespace {

// VRML's lines: a point (its coordinates as float32, as the STL has them)
// or a face ("a b c -1"): three numbers in their shortest round-trip form,
// separated by spaces, then `end`. A colour's line comes from a table of
// the bytes as "%.3f" of k / 255. Then the text between the lists.
template <typename T>
void AppendThree(std::string& s, T a, T b, T c, std::string_view end) {
  char buf[32];
  const T v[3] = {a, b, c};
  for (int k = 0; k < 3; ++k) {
    if (k > 0) s += ' ';
    s.append(buf, std::to_chars(buf, buf + sizeof buf, v[k]).ptr);
  }
  s += end;
}

void AppendVrmlPoint(std::string& s, double x, double y, double z) {
  AppendThree(s, static_cast<float>(x), static_cast<float>(y),
              static_cast<float>(z), "\n");
}

void AppendVrmlFace(std::string& s, int64_t a, int64_t b, int64_t c) {
  AppendThree(s, a, b, c, " -1\n");
}

class VrmlColorText {
 public:
  VrmlColorText() {
    for (int k = 0; k < 256; ++k) {
      std::snprintf(text_[k], sizeof text_[k], "%.3f", k / 255.0);
    }
  }
  void Append(std::string& s, const Rgb& c) const {
    s += text_[c.r];
    s += ' ';
    s += text_[c.g];
    s += ' ';
    s += text_[c.b];
    s += '\n';
  }

 private:
  char text_[256][8];
};

constexpr std::string_view kVrmlListEnd = "      ]\n    }\n";
constexpr std::string_view kVrmlColorsHead =
    "    colorPerVertex TRUE\n    color Color {\n      color [\n";
constexpr std::string_view kVrmlFacesHead = "    coordIndex [\n";
constexpr std::string_view kVrmlTail = "    ]\n  }\n}\n";

// The VRML file up to its first coordinate (WriteVrml, WriteLatticeVrml).
std::string VrmlHeader(size_t vertices, size_t triangles) {
  return absl::StrFormat(
      "#VRML V2.0 utf8\n"
      "# swarf machined surface (mm): %d vertices, %d triangles\n"
      "Shape {\n"
      "  appearance Appearance { material Material { diffuseColor 0.8 0.8 "
      "0.8 } }\n"
      "  geometry IndexedFaceSet {\n"
      "    solid TRUE\n"
      "    ccw TRUE\n"
      "    creaseAngle 0.5\n"
      "    coord Coordinate {\n"
      "      point [\n",
      vertices, triangles);
}

}  // namespace

absl::Status WriteVrml(const TriangleMesh& mesh, const std::string& path,
                       std::span<const Rgb> vertex_colors) {
  if (!vertex_colors.empty() && vertex_colors.size() != mesh.vertices.size()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%d vertex colours for %d vertices",
                        vertex_colors.size(), mesh.vertices.size()));
  }
  FileWriter out(path);
  if (!out.status().ok()) return out.status();
  out.Write(VrmlHeader(mesh.vertices.size(), mesh.triangles.size()));
  out.WriteChunks(static_cast<int64_t>(mesh.vertices.size()), kVrmlChunk,
                  [&](int64_t first, int64_t last, std::string* s) {
                    for (int64_t k = first; k < last; ++k) {
                      const Vec3& v = mesh.vertices[k];
                      AppendVrmlPoint(*s, v.x, v.y, v.z);
                    }
                  });
  out.Write(kVrmlListEnd);
  if (!vertex_colors.empty()) {
    out.Write(kVrmlColorsHead);
    const VrmlColorText color_text;
    out.WriteChunks(static_cast<int64_t>(vertex_colors.size()), kVrmlChunk,
                    [&](int64_t first, int64_t last, std::string* s) {
                      for (int64_t k = first; k < last; ++k) {
                        color_text.Append(*s, vertex_colors[k]);
                      }
                    });
    out.Write(kVrmlListEnd);
  }
  out.Write(kVrmlFacesHead);
  out.WriteChunks(static_cast<int64_t>(mesh.triangles.size()), kVrmlChunk,
                  [&](int64_t first, int64_t last, std::string* s) {
                    for (int64_t k = first; k < last; ++k) {
                      const auto& t = mesh.triangles[k];
                      AppendVrmlFace(*s, t[0], t[1], t[2]);
                    }
                  });
  out.Write(kVrmlTail);
  return out.Close();
}

}  // namespace swarf::cli

namespace swarf::cli {

std::unique_ptr<LatticeWindows> HeldLatticeRows(const LatticeHeights& lattice) {
  return std::make_unique<HeldRowsOf>(lattice);
}

absl::Status WriteLatticeStl(LatticeWindows& rows,
                             const LatticeHeights& lattice, double z_bottom,
                             const std::string& path) {
  const int64_t big_nx = lattice.nx, big_ny = lattice.ny;
  const int64_t count = FullMeshTriangles(big_nx, big_ny);
  if (count > UINT32_MAX) {
    return absl::InvalidArgumentError("too many triangles for STL");
  }
  FileWriter out(path);
  if (!out.status().ok()) return out.status();
  WriteStlHeader(static_cast<uint32_t>(count), out);
  const std::vector<double>& xs = lattice.xs;
  const std::vector<double>& ys = lattice.ys;
  BoundaryHeights boundary;
  absl::Status st = EmitTopCells(
      rows, big_nx, big_ny, &boundary,
      [&](MeshVertex a, MeshVertex b, MeshVertex c, const auto& z) {
        AppendStlRecord({xs[a.i], ys[a.j], z(a.i, a.j)},
                        {xs[b.i], ys[b.j], z(b.i, b.j)},
                        {xs[c.i], ys[c.j], z(c.i, c.j)}, out);
      });
  if (!st.ok()) return st;
  auto point = [&](const MeshVertex& v) -> Vec3 {
    if (v.bottom) return {xs[v.i], ys[v.j], z_bottom};
    const double z = v.j == 0        ? boundary.south[v.i]
                     : v.j == big_ny ? boundary.north[v.i]
                     : v.i == 0      ? boundary.west[v.j]
                                     : boundary.east[v.j];
    return {xs[v.i], ys[v.j], z};
  };
  EmitWallsAndBottom(big_nx, big_ny,
                     [&](MeshVertex a, MeshVertex b, MeshVertex c) {
                       AppendStlRecord(point(a), point(b), point(c), out);
                     });
  return out.Close();
}

absl::Status WriteLatticeVrml(LatticeWindows& rows,
                              const LatticeHeights& lattice, double z_bottom,
                              double z_top, bool colors,
                              const std::string& path) {
  const int64_t big_nx = lattice.nx, big_ny = lattice.ny;
  const std::vector<double>& xs = lattice.xs;
  const std::vector<double>& ys = lattice.ys;
  const int64_t vertices = (big_nx + 1) * (big_ny + 1) + 2 * (big_nx + big_ny);
  FileWriter out(path);
  if (!out.status().ok()) return out.status();
  std::string s =
      VrmlHeader(static_cast<size_t>(vertices),
                 static_cast<size_t>(FullMeshTriangles(big_nx, big_ny)));
  constexpr size_t kChunk = size_t{1} << 20;
  auto flush = [&] {
    if (s.size() >= kChunk) {
      out.Write(s);
      s.clear();
    }
  };
  auto put_point = [&](double x, double y, double z) {
    AppendVrmlPoint(s, x, y, z);
    flush();
  };
  // Every top row once: rows [j0, j1) of windows of 64 (the last holds NY).
  auto top_rows = [&](const std::function<void(int64_t, const double*)>& row)
      -> absl::Status {
    for (int64_t j0 = 0; j0 <= big_ny; j0 += 64) {
      const int64_t j1 = std::min(big_ny, j0 + 63);
      absl::StatusOr<const double*> z = rows.Rows(j0, j1);
      if (!z.ok()) return z.status();
      for (int64_t j = j0; j <= j1; ++j) {
        row(j, *z + (j - j0) * (big_nx + 1));
      }
    }
    return absl::OkStatus();
  };
  absl::Status st = top_rows([&](int64_t j, const double* z) {
    for (int64_t i = 0; i <= big_nx; ++i) put_point(xs[i], ys[j], z[i]);
  });
  if (!st.ok()) return st;
  auto bottom_point = [&](int64_t i, int64_t j) {
    put_point(xs[i], ys[j], z_bottom);
  };
  for (int64_t i = 0; i <= big_nx; ++i) bottom_point(i, 0);
  for (int64_t i = 0; i <= big_nx; ++i) bottom_point(i, big_ny);
  for (int64_t j = 1; j < big_ny; ++j) bottom_point(0, j);
  for (int64_t j = 1; j < big_ny; ++j) bottom_point(big_nx, j);
  s += kVrmlListEnd;
  if (colors) {
    s += kVrmlColorsHead;
    const VrmlColorText color_text;
    auto put_color = [&](const Rgb& c) {
      color_text.Append(s, c);
      flush();
    };
    // SurfaceColors: the lowest top vertex (or z_top) is each row's
    // minimum's minimum.
    const double lo =
        *std::min_element(lattice.row_min.begin(), lattice.row_min.end());
    st = top_rows([&](int64_t, const double* z) {
      for (int64_t i = 0; i <= big_nx; ++i) {
        put_color(z[i] < z_top ? HeightTint((z[i] - lo) / (z_top - lo))
                               : kStockColor);
      }
    });
    if (!st.ok()) return st;
    for (int64_t k = 0; k < 2 * (big_nx + big_ny); ++k) put_color(kWallColor);
    s += kVrmlListEnd;
  }
  s += kVrmlFacesHead;
  auto index = [&](const MeshVertex& v) {
    return v.bottom ? BottomIndex(big_nx, big_ny, v.i, v.j)
                    : v.j * (big_nx + 1) + v.i;
  };
  auto put_face = [&](const MeshVertex& a, const MeshVertex& b,
                      const MeshVertex& c) {
    AppendVrmlFace(s, index(a), index(b), index(c));
    flush();
  };
  BoundaryHeights boundary;
  st = EmitTopCells(rows, big_nx, big_ny, &boundary,
                    [&](MeshVertex a, MeshVertex b, MeshVertex c, const auto&) {
                      put_face(a, b, c);
                    });
  if (!st.ok()) return st;
  EmitWallsAndBottom(big_nx, big_ny, put_face);
  s += kVrmlTail;
  out.Write(s);
  return out.Close();
}

}  // namespace swarf::cli
