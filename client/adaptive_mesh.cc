// Error-bounded adaptive triangulation of the top lattice (see
// SimplifySurfaceMesh in surface_mesh.h).
//
// Leaves are squares of 2^k lattice cells found top down: a block whose two
// corner triangles stay within the tolerance of the full-resolution surface
// is kept, else split in four. Each leaf is then triangulated conformingly:
// with two triangles when no smaller neighbour put a vertex on its sides,
// else as a fan from its centre vertex through every vertex on its sides.
// Every leaf's triangles are measured against the full-resolution surface
// (both piecewise linear, so the largest vertical gap lies at a lattice
// vertex or where a coarse edge crosses a fine one: all are checked); a leaf
// over the tolerance is split and everything retriangulated, until none is.
// Single cells are the full-resolution triangles, so this ends.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <vector>

#include "absl/strings/str_format.h"
#include "client/surface_mesh.h"
#include "core/thread_pool.h"

namespace swarf::cli {
namespace {

// Lattice vertex (i, j) in lattice units.
struct P {
  int64_t i, j;
};

class Lattice {
 public:
  Lattice(const TriangleMesh& full)
      : nx_(full.lattice_nx), ny_(full.lattice_ny), full_(full) {}

  int64_t nx() const { return nx_; }
  int64_t ny() const { return ny_; }
  int64_t Index(int64_t i, int64_t j) const { return j * (nx_ + 1) + i; }
  double Z(int64_t i, int64_t j) const {
    return full_.vertices[Index(i, j)].z;
  }
  // The full-resolution cell's split, as BuildSurfaceMesh chooses it.
  bool MainDiagonal(int64_t i, int64_t j) const {
    return std::fabs(Z(i, j) - Z(i + 1, j + 1)) <=
           std::fabs(Z(i + 1, j) - Z(i, j + 1));
  }
  // The full-resolution surface at (x, y), lattice units.
  double Fine(double x, double y) const {
    int64_t i = std::clamp<int64_t>(static_cast<int64_t>(std::floor(x)), 0,
                                    nx_ - 1);
    int64_t j = std::clamp<int64_t>(static_cast<int64_t>(std::floor(y)), 0,
                                    ny_ - 1);
    const double u = x - i, v = y - j;
    const double z00 = Z(i, j), z10 = Z(i + 1, j), z01 = Z(i, j + 1),
                 z11 = Z(i + 1, j + 1);
    if (MainDiagonal(i, j)) {
      return u >= v ? z00 + u * (z10 - z00) + v * (z11 - z10)
                    : z00 + u * (z11 - z01) + v * (z01 - z00);
    }
    return u + v <= 1 ? z00 + u * (z10 - z00) + v * (z01 - z00)
                      : z11 + (1 - u) * (z01 - z11) + (1 - v) * (z10 - z11);
  }

  // Largest |fine - coarse| over triangle (a, b, c) (counter-clockwise),
  // coarse being the plane through the three lattice vertices.
  double TriangleDeviation(P a, P b, P c) const {
    const double za = Z(a.i, a.j), zb = Z(b.i, b.j), zc = Z(c.i, c.j);
    const int64_t area2 = (b.i - a.i) * (c.j - a.j) - (b.j - a.j) * (c.i - a.i);
    if (area2 <= 0) return INFINITY;  // never built; refuse loudly
    double dev = 0;
    // Lattice vertices inside or on the triangle (exact integer tests).
    const int64_t i0 = std::min({a.i, b.i, c.i}), i1 = std::max({a.i, b.i, c.i});
    const int64_t j0 = std::min({a.j, b.j, c.j}), j1 = std::max({a.j, b.j, c.j});
    auto edge = [](P p, P q, int64_t i, int64_t j) {
      return (q.i - p.i) * (j - p.j) - (q.j - p.j) * (i - p.i);
    };
    for (int64_t j = j0; j <= j1; ++j) {
      for (int64_t i = i0; i <= i1; ++i) {
        const int64_t wa = edge(b, c, i, j), wb = edge(c, a, i, j),
                      wc = edge(a, b, i, j);
        if (wa < 0 || wb < 0 || wc < 0) continue;
        const double coarse =
            (wa * za + wb * zb + wc * zc) / static_cast<double>(area2);
        dev = std::max(dev, std::fabs(Z(i, j) - coarse));
      }
    }
    dev = std::max(dev, EdgeDeviation(a, b));
    dev = std::max(dev, EdgeDeviation(b, c));
    dev = std::max(dev, EdgeDeviation(c, a));
    return dev;
  }

  // Largest gap along the coarse edge p -> q, at its crossings with every
  // line a fine edge can lie on: x, y, x - y and x + y integer.
  double EdgeDeviation(P p, P q) const {
    const double zp = Z(p.i, p.j), zq = Z(q.i, q.j);
    const int64_t di = q.i - p.i, dj = q.j - p.j;
    double dev = 0;
    auto at = [&](double t) {
      if (!(t > 0 && t < 1)) return;
      const double x = p.i + t * di, y = p.j + t * dj;
      dev = std::max(dev, std::fabs(Fine(x, y) - (zp + t * (zq - zp))));
    };
    // Along direction d from s, the crossings of f(x, y) = integer, where f
    // changes by df per unit t.
    auto crossings = [&](int64_t s, int64_t df) {
      if (df == 0) return;
      const int64_t lo = std::min(s, s + df), hi = std::max(s, s + df);
      for (int64_t k = lo + 1; k < hi; ++k) {
        at(static_cast<double>(k - s) / static_cast<double>(df));
      }
    };
    crossings(p.i, di);
    crossings(p.j, dj);
    crossings(p.i - p.j, di - dj);
    crossings(p.i + p.j, di + dj);
    return dev;
  }

 private:
  const int64_t nx_, ny_;
  const TriangleMesh& full_;
};

struct Leaf {
  int64_t i0, j0, size;
};

// The two corner triangles of a square, split along the diagonal whose ends
// differ less in height (as the full-resolution cells are).
void CornerTriangles(const Lattice& l, const Leaf& f, std::vector<P>* out) {
  const P a{f.i0, f.j0}, b{f.i0 + f.size, f.j0},
      c{f.i0 + f.size, f.j0 + f.size}, d{f.i0, f.j0 + f.size};
  if (std::fabs(l.Z(a.i, a.j) - l.Z(c.i, c.j)) <=
      std::fabs(l.Z(b.i, b.j) - l.Z(d.i, d.j))) {
    out->insert(out->end(), {a, b, c, a, c, d});
  } else {
    out->insert(out->end(), {a, b, d, b, c, d});
  }
}

}  // namespace

absl::StatusOr<TriangleMesh> SimplifySurfaceMesh(const TriangleMesh& full,
                                                 double tolerance) {
  if (!(tolerance >= 0) || !std::isfinite(tolerance)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the mesh tolerance must be a finite number >= 0 (mm), got %g",
        tolerance));
  }
  const Lattice l(full);
  const int64_t nx = l.nx(), ny = l.ny();
  if (nx < 1 || ny < 1 ||
      full.top_vertices != (nx + 1) * (ny + 1)) {
    return absl::InvalidArgumentError("not a full-resolution lattice mesh");
  }
  ThreadPool& pool = ThreadPool::Default();

  // Top down: roots of kRoot cells; a block leaving the lattice or whose
  // corner triangles miss the tolerance is split.
  constexpr int64_t kRoot = 64;
  std::vector<Leaf> pending, leaves;
  for (int64_t j = 0; j < ny; j += kRoot) {
    for (int64_t i = 0; i < nx; i += kRoot) pending.push_back({i, j, kRoot});
  }
  while (!pending.empty()) {
    std::vector<char> split(pending.size());
    pool.ParallelFor(static_cast<int64_t>(pending.size()), [&](int64_t k) {
      const Leaf& f = pending[k];
      if (f.size == 1) return;
      if (f.i0 + f.size > nx || f.j0 + f.size > ny) {
        split[k] = 1;
        return;
      }
      std::vector<P> t;
      CornerTriangles(l, f, &t);
      split[k] = l.TriangleDeviation(t[0], t[1], t[2]) > tolerance ||
                 l.TriangleDeviation(t[3], t[4], t[5]) > tolerance;
    });
    std::vector<Leaf> next;
    for (size_t k = 0; k < pending.size(); ++k) {
      const Leaf& f = pending[k];
      if (!split[k]) {
        leaves.push_back(f);
        continue;
      }
      const int64_t h = f.size / 2;
      for (const Leaf& c : {Leaf{f.i0, f.j0, h}, Leaf{f.i0 + h, f.j0, h},
                            Leaf{f.i0, f.j0 + h, h},
                            Leaf{f.i0 + h, f.j0 + h, h}}) {
        if (c.i0 < nx && c.j0 < ny) next.push_back(c);
      }
    }
    pending = std::move(next);
  }

  // Conforming triangulation, measured; leaves over the tolerance are split
  // and the whole is redone (their neighbours' sides change).
  const int64_t lattice_vertices = (nx + 1) * (ny + 1);
  std::vector<std::vector<P>> tris;
  std::vector<double> leaf_dev;
  std::vector<uint8_t> used;
  for (;;) {
    used.assign(lattice_vertices, 0);
    for (const Leaf& f : leaves) {
      used[l.Index(f.i0, f.j0)] = used[l.Index(f.i0 + f.size, f.j0)] = 1;
      used[l.Index(f.i0, f.j0 + f.size)] = 1;
      used[l.Index(f.i0 + f.size, f.j0 + f.size)] = 1;
    }
    tris.assign(leaves.size(), {});
    leaf_dev.assign(leaves.size(), 0);
    pool.ParallelFor(static_cast<int64_t>(leaves.size()), [&](int64_t k) {
      const Leaf& f = leaves[k];
      const int64_t s = f.size;
      // The sides' used vertices, counter-clockwise from (i0, j0).
      std::vector<P> ring;
      for (int64_t d = 0; d < s; ++d) {
        if (used[l.Index(f.i0 + d, f.j0)]) ring.push_back({f.i0 + d, f.j0});
      }
      for (int64_t d = 0; d < s; ++d) {
        if (used[l.Index(f.i0 + s, f.j0 + d)]) {
          ring.push_back({f.i0 + s, f.j0 + d});
        }
      }
      for (int64_t d = s; d > 0; --d) {
        if (used[l.Index(f.i0 + d, f.j0 + s)]) {
          ring.push_back({f.i0 + d, f.j0 + s});
        }
      }
      for (int64_t d = s; d > 0; --d) {
        if (used[l.Index(f.i0, f.j0 + d)]) ring.push_back({f.i0, f.j0 + d});
      }
      std::vector<P>& t = tris[k];
      if (ring.size() == 4) {
        CornerTriangles(l, f, &t);
      } else {
        const P c{f.i0 + s / 2, f.j0 + s / 2};
        for (size_t q = 0; q < ring.size(); ++q) {
          t.insert(t.end(), {c, ring[q], ring[(q + 1) % ring.size()]});
        }
      }
      double dev = 0;
      for (size_t q = 0; q + 2 < t.size(); q += 3) {
        dev = std::max(dev, l.TriangleDeviation(t[q], t[q + 1], t[q + 2]));
      }
      leaf_dev[k] = dev;
    });
    std::vector<Leaf> next;
    bool refined = false;
    for (size_t k = 0; k < leaves.size(); ++k) {
      const Leaf& f = leaves[k];
      if (leaf_dev[k] <= tolerance || f.size == 1) {
        next.push_back(f);
        continue;
      }
      refined = true;
      const int64_t h = f.size / 2;
      next.insert(next.end(),
                  {Leaf{f.i0, f.j0, h}, Leaf{f.i0 + h, f.j0, h},
                   Leaf{f.i0, f.j0 + h, h}, Leaf{f.i0 + h, f.j0 + h, h}});
    }
    leaves = std::move(next);
    if (!refined) break;
  }

  // Fan centres are used too; then the used lattice vertices, row-major,
  // are the new top vertices.
  for (const std::vector<P>& t : tris) {
    for (const P& p : t) used[l.Index(p.i, p.j)] = 1;
  }
  TriangleMesh mesh;
  mesh.lattice_nx = full.lattice_nx;
  mesh.lattice_ny = full.lattice_ny;
  mesh.z_bottom = full.z_bottom;
  std::vector<int32_t> remap(lattice_vertices, -1);
  for (int64_t v = 0; v < lattice_vertices; ++v) {
    if (!used[v]) continue;
    remap[v] = static_cast<int32_t>(mesh.vertices.size());
    mesh.vertices.push_back(full.vertices[v]);
  }
  mesh.top_vertices = static_cast<int64_t>(mesh.vertices.size());
  for (size_t k = 0; k < tris.size(); ++k) {
    const std::vector<P>& t = tris[k];
    for (size_t q = 0; q + 2 < t.size(); q += 3) {
      mesh.triangles.push_back({remap[l.Index(t[q].i, t[q].j)],
                                remap[l.Index(t[q + 1].i, t[q + 1].j)],
                                remap[l.Index(t[q + 2].i, t[q + 2].j)]});
    }
    mesh.max_deviation = std::max(mesh.max_deviation, leaf_dev[k]);
  }

  // Walls under the top's boundary edges (counter-clockwise seen from
  // above), and a bottom fanned from a vertex under the middle.
  std::vector<int64_t> boundary;  // lattice indices, counter-clockwise
  for (int64_t i = 0; i < nx; ++i) boundary.push_back(l.Index(i, 0));
  for (int64_t j = 0; j < ny; ++j) boundary.push_back(l.Index(nx, j));
  for (int64_t i = nx; i > 0; --i) boundary.push_back(l.Index(i, ny));
  for (int64_t j = ny; j > 0; --j) boundary.push_back(l.Index(0, j));
  std::vector<int32_t> top_ring, bottom_ring;
  for (int64_t v : boundary) {
    if (!used[v]) continue;
    top_ring.push_back(remap[v]);
    bottom_ring.push_back(static_cast<int32_t>(mesh.vertices.size()));
    const Vec3& p = full.vertices[v];
    mesh.vertices.push_back({p.x, p.y, full.z_bottom});
  }
  const Vec3& lo = full.vertices[0];
  const Vec3& hi = full.vertices[lattice_vertices - 1];
  const int32_t middle = static_cast<int32_t>(mesh.vertices.size());
  mesh.vertices.push_back({(lo.x + hi.x) / 2, (lo.y + hi.y) / 2,
                           full.z_bottom});
  for (size_t q = 0; q < top_ring.size(); ++q) {
    const size_t r = (q + 1) % top_ring.size();
    const int32_t a = top_ring[q], b = top_ring[r];
    const int32_t ab = bottom_ring[q], bb = bottom_ring[r];
    mesh.triangles.push_back({ab, bb, b});
    mesh.triangles.push_back({ab, b, a});
    mesh.triangles.push_back({middle, bb, ab});
  }
  return mesh;
}

}  // namespace swarf::cli
