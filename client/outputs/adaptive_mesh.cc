// Error-bounded adaptive triangulation of the top lattice (see
// SimplifySurfaceMesh in surface_mesh.h).
//
// Leaves are rectangles of 2^a x 2^b lattice cells found top down (a k-d
// tree: ridges and scallops along a pass get long thin leaves): a block
// whose two corner triangles stay within the tolerance of the
// full-resolution surface is kept, else halved across x or y, whichever
// fits better. Each leaf is then triangulated conformingly: with two
// triangles when no smaller neighbour put a vertex on its sides, else by
// clipping ears off the polygon of its corners and side vertices. Every
// leaf's triangles are measured against the full-resolution surface (both
// piecewise linear, so the largest vertical gap lies at a lattice vertex or
// where a coarse edge crosses a fine one: all are checked); a leaf over the
// tolerance is split, and its halves and neighbours are triangulated
// again, until none is. Single cells are the full-resolution triangles, so
// this ends.
#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "absl/strings/str_format.h"
#include "client/outputs/surface_mesh.h"
#include "core/bucket_starts.h"
#include "core/thread_pool.h"
#include "core/unfilled_vector.h"

namespace swarf::cli {
namespace {

// Lattice vertex (i, j) in lattice units. int32 (a lattice has at most
// 2^31 - 1 vertices): every leaf keeps its triangles' corners until the
// mesh is listed, 8 bytes each rather than 16.
struct P {
  P() = default;
  P(int64_t vi, int64_t vj)
      : i(static_cast<int32_t>(vi)), j(static_cast<int32_t>(vj)) {}
  int32_t i = 0, j = 0;
};
static_assert(sizeof(P) == 8);

class Lattice {
 public:
  // Heights of rows [j_base, ...] at z (row-major, nx + 1 a row): only
  // the rows a leaf's rectangle covers are read.
  Lattice(int64_t nx, int64_t ny, const double* z, int64_t j_base)
      : nx_(nx), ny_(ny), z_(z), j_base_(j_base) {}

  int64_t nx() const { return nx_; }
  int64_t ny() const { return ny_; }
  int64_t Index(int64_t i, int64_t j) const { return j * (nx_ + 1) + i; }
  double Z(int64_t i, int64_t j) const {
    return z_[(j - j_base_) * (nx_ + 1) + i];
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
  // coarse being the plane through the three lattice vertices; once it
  // passes `limit`, some value above it.
  double TriangleDeviation(P a, P b, P c, double limit = INFINITY) const {
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
      if (dev > limit) return dev;
    }
    dev = std::max(dev, EdgeDeviation(a, b));
    if (dev > limit) return dev;
    dev = std::max(dev, EdgeDeviation(b, c));
    if (dev > limit) return dev;
    return std::max(dev, EdgeDeviation(c, a));
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
    // Along an axis or a diagonal several families cross at the same t
    // (the same doubles: m / d and (2m) / (2d), or the same quotient of
    // negated integers): measuring them once gives the same maximum.
    if (dj == 0 || di == 0) {
      crossings(dj == 0 ? p.i : p.j, dj == 0 ? di : dj);
    } else if (di == dj) {
      crossings(p.i + p.j, di + dj);
    } else if (di == -dj) {
      crossings(p.i - p.j, di - dj);
    } else {
      crossings(p.i, di);
      crossings(p.j, dj);
      crossings(p.i - p.j, di - dj);
      crossings(p.i + p.j, di + dj);
    }
    return dev;
  }

 private:
  const int64_t nx_, ny_;
  const double* z_;
  const int64_t j_base_;
};

struct Leaf {
  int64_t i0, j0, w, h;  // cells [i0, i0 + w) x [j0, j0 + h)
};

// A leaf's four corners (lattice vertices).
std::array<P, 4> CornersOf(const Leaf& f) {
  return {P{f.i0, f.j0}, P{f.i0 + f.w, f.j0}, P{f.i0, f.j0 + f.h},
          P{f.i0 + f.w, f.j0 + f.h}};
}

// How a leaf is triangulated: with its two corner triangles, sharing the
// diagonal from corner (i0, j0) (kDiagonalAC) or the other one, or by a
// list of triangles (kEars: ClipEars').
enum LeafShape : uint8_t { kDiagonalAC = 0, kDiagonalBD = 1, kEars = 2 };

// The diagonal of a leaf's corner triangles: the one whose ends differ less
// in height (as the full-resolution cells are split).
LeafShape CornerDiagonal(const Lattice& l, const Leaf& f) {
  return std::fabs(l.Z(f.i0, f.j0) - l.Z(f.i0 + f.w, f.j0 + f.h)) <=
                 std::fabs(l.Z(f.i0 + f.w, f.j0) - l.Z(f.i0, f.j0 + f.h))
             ? kDiagonalAC
             : kDiagonalBD;
}

// The two corner triangles of the leaf from (i0, j0) to (i1, j1), sharing
// `diagonal`, appended to *out.
void CornerTriangles(int64_t i0, int64_t j0, int64_t i1, int64_t j1,
                     LeafShape diagonal, std::vector<P>* out) {
  const P a{i0, j0}, b{i1, j0}, c{i1, j1}, d{i0, j1};
  if (diagonal == kDiagonalAC) {
    out->insert(out->end(), {a, b, c, a, c, d});
  } else {
    out->insert(out->end(), {a, b, d, b, c, d});
  }
}
void CornerTriangles(const Lattice& l, const Leaf& f, std::vector<P>* out) {
  CornerTriangles(f.i0, f.j0, f.i0 + f.w, f.j0 + f.h, CornerDiagonal(l, f),
                  out);
}

// Largest distance of the lattice heights on the line from p to q (along a
// row or a column) from the straight line between its ends.
double LineDeviation(const Lattice& l, P p, P q) {
  const int64_t n = std::max(std::abs(q.i - p.i), std::abs(q.j - p.j));
  const int64_t si = (q.i - p.i) / std::max<int64_t>(n, 1);
  const int64_t sj = (q.j - p.j) / std::max<int64_t>(n, 1);
  const double z0 = l.Z(p.i, p.j), z1 = l.Z(q.i, q.j);
  double dev = 0;
  for (int64_t a = 1; a < n; ++a) {
    dev = std::max(dev, std::fabs(l.Z(p.i + a * si, p.j + a * sj) -
                                  (z0 + (z1 - z0) * a / n)));
  }
  return dev;
}

// Whether the corner triangles of a leaf are within `tolerance`. Its sides
// are edges of those triangles: checked first, they reject most blocks
// cheaply. When they fit, *dev is their deviation: what measuring the two
// triangles without a limit gives (a measure stops early only above the
// limit).
bool CornersFit(const Lattice& l, const Leaf& f, double tolerance,
                double* dev) {
  const P a{f.i0, f.j0}, b{f.i0 + f.w, f.j0}, c{f.i0 + f.w, f.j0 + f.h},
      d{f.i0, f.j0 + f.h};
  if (LineDeviation(l, a, b) > tolerance || LineDeviation(l, d, c) > tolerance ||
      LineDeviation(l, a, d) > tolerance || LineDeviation(l, b, c) > tolerance) {
    return false;
  }
  thread_local std::vector<P> t;
  t.clear();
  CornerTriangles(l, f, &t);
  const double d0 = l.TriangleDeviation(t[0], t[1], t[2], tolerance);
  if (!(d0 <= tolerance)) return false;
  const double d1 = l.TriangleDeviation(t[3], t[4], t[5], tolerance);
  if (!(d1 <= tolerance)) return false;
  *dev = std::max(std::max(0.0, d0), d1);
  return true;
}

// The halves of a leaf across x or across y: across the direction in which
// the surface is further from linear (a scallop along a pass is split
// across the pass, not along it); a side of one cell is not split.
std::array<Leaf, 2> Halves(const Lattice& l, const Leaf& f) {
  const std::array<Leaf, 2> across_x = {
      Leaf{f.i0, f.j0, f.w / 2, f.h}, Leaf{f.i0 + f.w / 2, f.j0, f.w / 2, f.h}};
  const std::array<Leaf, 2> across_y = {
      Leaf{f.i0, f.j0, f.w, f.h / 2}, Leaf{f.i0, f.j0 + f.h / 2, f.w, f.h / 2}};
  if (f.h == 1) return across_x;
  if (f.w == 1) return across_y;
  // The rows and columns at the sides and through the middle.
  double along_x = 0, along_y = 0;
  for (int64_t j : {f.j0, f.j0 + f.h / 2, f.j0 + f.h}) {
    along_x = std::max(along_x, LineDeviation(l, {f.i0, j}, {f.i0 + f.w, j}));
  }
  for (int64_t i : {f.i0, f.i0 + f.w / 2, f.i0 + f.w}) {
    along_y = std::max(along_y, LineDeviation(l, {i, f.j0}, {i, f.j0 + f.h}));
  }
  return along_x >= along_y ? across_x : across_y;
}

// Whether Halves(l, f) splits across x (else across y), and those halves
// from that answer alone.
bool SplitsAcrossX(const Lattice& l, const Leaf& f) {
  return Halves(l, f)[0].w != f.w;
}
std::array<Leaf, 2> HalvesAcross(const Leaf& f, bool across_x) {
  if (across_x) {
    return {Leaf{f.i0, f.j0, f.w / 2, f.h},
            Leaf{f.i0 + f.w / 2, f.j0, f.w / 2, f.h}};
  }
  return {Leaf{f.i0, f.j0, f.w, f.h / 2},
          Leaf{f.i0, f.j0 + f.h / 2, f.w, f.h / 2}};
}

int64_t Cross(P o, P a, P b) {
  return (a.i - o.i) * (b.j - o.j) - (a.j - o.j) * (b.i - o.i);
}

// Triangulates a convex polygon (counter-clockwise, collinear vertices
// allowed, positive area) without degenerate triangles: repeatedly cuts off
// a corner whose triangle has area and leaves a polygon with area, the one
// with the shortest cut. *poly is used up (its vertices erased as cut).
void ClipEars(std::vector<P>* polygon, std::vector<P>* out) {
  std::vector<P>& poly = *polygon;
  while (poly.size() > 3) {
    const size_t n = poly.size();
    size_t best = n;
    int64_t best_len = 0;
    for (size_t k = 0; k < n; ++k) {
      const P& prev = poly[(k + n - 1) % n];
      const P& next = poly[(k + 1) % n];
      if (Cross(prev, poly[k], next) <= 0) continue;  // not a corner
      // The rest must not be all on the line prev-next.
      bool area = false;
      for (size_t q = 2; q + 1 < n && !area; ++q) {
        area = Cross(prev, next, poly[(k + q) % n]) != 0;
      }
      if (!area) continue;
      const int64_t di = next.i - prev.i, dj = next.j - prev.j;
      const int64_t len = di * di + dj * dj;
      if (best == n || len < best_len) {
        best = k;
        best_len = len;
      }
    }
    if (best == n) return;  // cannot happen for a convex polygon with area
    out->insert(out->end(),
                {poly[(best + n - 1) % n], poly[best], poly[(best + 1) % n]});
    poly.erase(poly.begin() + static_cast<std::ptrdiff_t>(best));
  }
  out->insert(out->end(), poly.begin(), poly.end());
}

}  // namespace

absl::StatusOr<TriangleMesh> SimplifySurfaceMesh(const TriangleMesh& full,
                                                 double tolerance) {
  if (!(tolerance >= 0) || !std::isfinite(tolerance)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the mesh tolerance must be a finite number >= 0 (mm), got %g",
        tolerance));
  }
  const int64_t nx = full.lattice_nx, ny = full.lattice_ny;
  if (nx < 1 || ny < 1 ||
      full.top_vertices != (nx + 1) * (ny + 1) ||
      static_cast<int64_t>(full.vertices.size()) < full.top_vertices) {
    return absl::InvalidArgumentError("not a full-resolution lattice mesh");
  }
  // Its lattice's heights and coordinates (the same doubles).
  LatticeHeights h;
  h.nx = nx;
  h.ny = ny;
  h.xs.resize(nx + 1);
  h.ys.resize(ny + 1);
  for (int64_t i = 0; i <= nx; ++i) h.xs[i] = full.vertices[i].x;
  for (int64_t j = 0; j <= ny; ++j) h.ys[j] = full.vertices[j * (nx + 1)].y;
  h.z.resize(full.top_vertices);
  for (int64_t v = 0; v < full.top_vertices; ++v) h.z[v] = full.vertices[v].z;
  return SimplifyLattice(h, full.z_bottom, tolerance);
}

namespace {

// The rows of a lattice held in memory.
class HeldRows : public LatticeWindows {
 public:
  explicit HeldRows(const LatticeHeights& h) : h_(h) {}
  absl::StatusOr<const double*> Rows(int64_t j0, int64_t) override {
    return h_.z.data() + j0 * (h_.nx + 1);
  }

 private:
  const LatticeHeights& h_;
};

// Where each of `chunks` runs starts in a list made of them in order:
// count(c) (on every thread) is run c's length; starts[c] is the sum of
// those before it, starts[chunks] the total.
std::vector<int64_t> RunStarts(ThreadPool& pool, int64_t chunks,
                               const std::function<int64_t(int64_t)>& count) {
  std::vector<int64_t> starts(chunks + 1, 0);
  pool.ParallelFor(chunks, [&](int64_t c) { starts[c + 1] = count(c); });
  for (int64_t c = 0; c < chunks; ++c) starts[c + 1] += starts[c];
  return starts;
}

// fn(begin, end) over [0, n) in chunks, on every thread.
constexpr int64_t kFillChunk = int64_t{1} << 16;
void ForChunks(ThreadPool& pool, int64_t n,
               const std::function<void(int64_t, int64_t)>& fn) {
  pool.ParallelFor((n + kFillChunk - 1) / kFillChunk, [&](int64_t c) {
    fn(c * kFillChunk, std::min(n, (c + 1) * kFillChunk));
  });
}

// n copies of v, written on every thread: a std::vector's value
// initialisation wrote (and page-faulted in) every byte on one thread, a
// serial step of the mesh (millions of leaves on large jobs).
// n elements, unwritten, with room for `capacity` (reserved, not touched:
// pages never written take no memory).
template <typename T>
UnfilledVector<T> Unfilled(int64_t n, int64_t capacity = 0) {
  UnfilledVector<T> out;
  out.reserve(std::max(n, capacity));
  out.resize(n);
  return out;
}

template <typename T>
UnfilledVector<T> Filled(ThreadPool& pool, int64_t n, T v,
                         int64_t capacity = 0) {
  UnfilledVector<T> out = Unfilled<T>(n, capacity);
  FillOnEvery(pool, out.data(), n, v);
  return out;
}

// Room in the per-leaf arrays of n leaves for the conforming passes'
// halves: they split a few percent (cameo at 0.05 mm: 7,908 leaves more
// than its 995,012). Made exactly n long, the arrays were copied whole to
// grow for the first pass's halves: 83 of that pass's 105 ms serial step
// on 2 threads, where page faults are slow.
int64_t LeafCapacity(int64_t n) { return n + n / 16 + 4096; }

// Room for at least n elements in *v, its elements copied on every thread
// when it must grow (a reallocation copied them on one); grown by half at
// least, as each of the conforming passes grows it a little.
template <typename T>
void ReserveOnEveryThread(ThreadPool& pool, UnfilledVector<T>* v, int64_t n) {
  const int64_t capacity = static_cast<int64_t>(v->capacity());
  if (n <= capacity) return;
  UnfilledVector<T> grown;
  grown.reserve(std::max(n, capacity + capacity / 2));
  grown.resize(v->size());
  ForChunks(pool, static_cast<int64_t>(v->size()), [&](int64_t b, int64_t e) {
    std::copy(v->begin() + b, v->begin() + e, grown.begin() + b);
  });
  v->swap(grown);
}

}  // namespace

absl::StatusOr<TriangleMesh> SimplifyLattice(const LatticeHeights& heights,
                                             double z_bottom,
                                             double tolerance) {
  if (!(tolerance >= 0) || !std::isfinite(tolerance)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the mesh tolerance must be a finite number >= 0 (mm), got %g",
        tolerance));
  }
  const int64_t nx = heights.nx, ny = heights.ny;
  if (nx < 1 || ny < 1 ||
      static_cast<int64_t>(heights.z.size()) != (nx + 1) * (ny + 1) ||
      static_cast<int64_t>(heights.xs.size()) != nx + 1 ||
      static_cast<int64_t>(heights.ys.size()) != ny + 1) {
    return absl::InvalidArgumentError("not a full-resolution lattice");
  }
  HeldRows rows(heights);
  return SimplifyLatticeRows(rows, heights.xs, heights.ys, z_bottom,
                             tolerance);
}

absl::StatusOr<TriangleMesh> SimplifyLatticeRows(
    LatticeWindows& rows, const std::vector<double>& xs,
    const std::vector<double>& ys, double z_bottom, double tolerance) {
  if (!(tolerance >= 0) || !std::isfinite(tolerance)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the mesh tolerance must be a finite number >= 0 (mm), got %g",
        tolerance));
  }
  const int64_t nx = static_cast<int64_t>(xs.size()) - 1;
  const int64_t ny = static_cast<int64_t>(ys.size()) - 1;
  if (nx < 1 || ny < 1) {
    return absl::InvalidArgumentError("not a full-resolution lattice");
  }
  ThreadPool& pool = ThreadPool::Default();

  // Roots of kRoot x kRoot cells; every leaf lies in one root, so what a
  // leaf reads (its closed rectangle, and a row above) lies in its root
  // row's kRoot + 2 lattice rows: the heights are read a root row at a
  // time.
  constexpr int64_t kRoot = 64;
  const int64_t roots_x = (nx + kRoot - 1) / kRoot;
  const int64_t roots_y = (ny + kRoot - 1) / kRoot;
  // Fine() on a leaf's top side also reads the row above it (times 0), so
  // a window has one row more.
  auto window = [&](int64_t rr) -> absl::StatusOr<Lattice> {
    const int64_t j0 = rr * kRoot, j1 = std::min(ny, j0 + kRoot + 1);
    absl::StatusOr<const double*> z = rows.Rows(j0, j1);
    if (!z.ok()) return z.status();
    return Lattice(nx, ny, *z, j0);
  };

  // Top down: a block leaving the lattice or whose corner triangles miss
  // the tolerance is split. Each root's tree is built where its rows are
  // read; the leaves are then listed level by level across all roots, as
  // splitting every root's blocks a level at a time lists them.
  struct TreeNode {
    Leaf f;
    double dev = -1;  // as fit_dev below
    int32_t kid[2] = {-1, -1};
    int64_t leaf = -1;  // its index in `leaves`, when a leaf
  };
  std::vector<std::vector<TreeNode>> trees(roots_x * roots_y);
  for (int64_t rr = 0; rr < roots_y; ++rr) {
    absl::StatusOr<Lattice> l = window(rr);
    if (!l.ok()) return l.status();
    pool.ParallelFor(roots_x, [&](int64_t rx) {
      // Built in the thread's own vector, then copied out at its size:
      // built in place, each push_back stored the tree's end in `trees`,
      // whose vector objects share cache lines with the trees that other
      // threads build beside it (and its growth reallocated).
      thread_local std::vector<TreeNode> t;
      t.clear();
      t.push_back({Leaf{rx * kRoot, rr * kRoot, kRoot, kRoot}});
      for (size_t q = 0; q < t.size(); ++q) {
        const Leaf f = t[q].f;
        std::array<Leaf, 2> halves;
        double dev = -1;
        // Blocks leaving the lattice: halved across the side that leaves
        // it.
        if (f.i0 + f.w > nx) {
          halves = {Leaf{f.i0, f.j0, f.w / 2, f.h},
                    Leaf{f.i0 + f.w / 2, f.j0, f.w / 2, f.h}};
        } else if (f.j0 + f.h > ny) {
          halves = {Leaf{f.i0, f.j0, f.w, f.h / 2},
                    Leaf{f.i0, f.j0 + f.h / 2, f.w, f.h / 2}};
        } else if (f.w * f.h > 1 && !CornersFit(*l, f, tolerance, &dev)) {
          halves = Halves(*l, f);
        } else {
          t[q].dev = dev;
          continue;
        }
        // The first half starts where the block does: always inside.
        for (int c = 0; c < 2; ++c) {
          if (halves[c].i0 < nx && halves[c].j0 < ny) {
            t[q].kid[c] = static_cast<int32_t>(t.size());
            t.push_back({halves[c]});
          }
        }
      }
      // Kept until the conforming passes end.
      trees[rr * roots_x + rx].assign(t.begin(), t.end());
    });
  }
  // Both written on every thread, every entry (below).
  UnfilledVector<Leaf> leaves;
  // Per leaf, its corner triangles' deviation where CornersFit measured it
  // (-1: not measured): a leaf whose sides gain no vertex keeps those
  // triangles, and the conforming pass takes the value instead of
  // measuring them again.
  UnfilledVector<double> fit_dev;
  {
    // Listed on every thread: a tree is built as a queue, so its nodes lie
    // level by level, and the listing takes level 0 of every tree, then
    // level 1 of every tree... A leaf's index is the number of leaves of
    // lower levels, then of the same level in earlier trees, then before it
    // in its own.
    const int64_t n_trees = roots_x * roots_y;
    std::vector<std::vector<uint8_t>> depth(n_trees);
    std::vector<int> tree_levels(n_trees, 0);
    pool.ParallelFor(n_trees, [&](int64_t b) {
      const std::vector<TreeNode>& t = trees[b];
      std::vector<uint8_t>& d = depth[b];
      d.assign(t.size(), 0);
      for (size_t q = 0; q < t.size(); ++q) {
        for (int c = 0; c < 2; ++c) {
          if (t[q].kid[c] >= 0) d[t[q].kid[c]] = d[q] + 1;
        }
      }
      tree_levels[b] = t.empty() ? 0 : d.back() + 1;
    });
    const int levels =
        *std::max_element(tree_levels.begin(), tree_levels.end());
    // first[level * n_trees + b]: the index of tree b's first leaf of that
    // level (counts first, then their prefix).
    std::vector<int64_t> first(static_cast<size_t>(levels) * n_trees + 1, 0);
    pool.ParallelFor(n_trees, [&](int64_t b) {
      // Counted in the thread's own array, then stored once a level: the
      // trees beside it, counted on other threads, share cache lines of
      // `first`.
      thread_local std::vector<int64_t> count;
      count.assign(levels, 0);
      const std::vector<TreeNode>& t = trees[b];
      for (size_t q = 0; q < t.size(); ++q) {
        if (t[q].kid[0] < 0) ++count[depth[b][q]];
      }
      for (int lv = 0; lv < levels; ++lv)
        first[lv * n_trees + b + 1] = count[lv];
    });
    for (size_t k = 1; k < first.size(); ++k) first[k] += first[k - 1];
    leaves = Unfilled<Leaf>(first.back(), LeafCapacity(first.back()));
    fit_dev.resize(first.back());
    pool.ParallelFor(n_trees, [&](int64_t b) {
      std::vector<TreeNode>& t = trees[b];
      std::vector<int64_t> next(levels);
      for (int lv = 0; lv < levels; ++lv) next[lv] = first[lv * n_trees + b];
      for (size_t q = 0; q < t.size(); ++q) {
        if (t[q].kid[0] >= 0) continue;
        const int64_t k = next[depth[b][q]]++;
        t[q].leaf = k;
        leaves[k] = t[q].f;
        fit_dev[k] = t[q].dev;
      }
      std::vector<uint8_t>().swap(depth[b]);
    });
  }

  // Conforming triangulation, measured; leaves over the tolerance are
  // split and the leaves they touch (their sides gain vertices) are
  // triangulated and measured again, until none is over. A split leaf
  // stays in `leaves` with its halves appended (kids[k], kids[k] + 1): the
  // mesh lists the final leaves depth first, which is the order of
  // replacing each split leaf by its halves in place. Late passes split a
  // handful of leaves: only those and their neighbours are visited, a root
  // row's heights read once a pass.
  const int64_t lattice_vertices = (nx + 1) * (ny + 1);
  const int64_t roots = static_cast<int64_t>(leaves.size());
  UnfilledVector<int64_t> kids =
      Filled<int64_t>(pool, roots, -1, LeafCapacity(roots));
  // Each leaf's triangles: most leaves' are their corner triangles, kept
  // as a byte (shape); the rest are listed in ears, owned here (null
  // elsewhere) and freed when the leaf is split or listed. A vector a leaf
  // was 72 bytes and a malloc, zeroed on one thread.
  UnfilledVector<uint8_t> shape =  // written by the first pass
      Unfilled<uint8_t>(roots, LeafCapacity(roots));
  struct EarLists {
    UnfilledVector<std::vector<P>*> at;
    ~EarLists() {
      for (std::vector<P>* t : at) delete t;
    }
  } ears{Filled<std::vector<P>*>(pool, roots, nullptr, LeafCapacity(roots))};
  // Written by each pass for its work leaves before it is read (the first
  // pass's work is every leaf).
  UnfilledVector<double> leaf_dev =
      Unfilled<double>(roots, LeafCapacity(roots));
  // Which lattice vertices are leaf corners (splits only add corners: a
  // leaf's corners are its halves').
  // Which lattice vertices the mesh keeps, a bit each (the plate's 400 M
  // lattice vertices: 48 MiB, not the 381 of a byte each). Set on every
  // thread for the first leaves (below), then only on this thread
  // (add_corners), read by the parallel passes in between.
  UnfilledVector<uint64_t> used_bits =
      Filled<uint64_t>(pool, (lattice_vertices + 63) / 64, 0);
  auto used = [&used_bits](int64_t v) -> bool {
    return (used_bits[v >> 6] >> (v & 63)) & 1;
  };
  auto index = [nx](int64_t i, int64_t j) { return j * (nx + 1) + i; };
  // The leaf that holds cell (ci, cj) now: down its root's tree, then the
  // splits.
  auto leaf_at = [&](int64_t ci, int64_t cj) {
    auto inside = [&](const Leaf& a) {
      return ci >= a.i0 && ci < a.i0 + a.w && cj >= a.j0 && cj < a.j0 + a.h;
    };
    const std::vector<TreeNode>& t = trees[(cj / kRoot) * roots_x + ci / kRoot];
    int32_t q = 0;
    while (t[q].kid[0] >= 0) {
      q = inside(t[t[q].kid[0]].f) ? t[q].kid[0] : t[q].kid[1];
    }
    int64_t k = t[q].leaf;
    while (kids[k] >= 0) k = inside(leaves[kids[k]]) ? kids[k] : kids[k] + 1;
    return k;
  };
  std::vector<int64_t> corners_added;
  auto add_corners = [&](const Leaf& f) {
    for (const P& p : CornersOf(f)) {
      const int64_t v = index(p.i, p.j);
      if (!used(v)) corners_added.push_back(v);
      used_bits[v >> 6] |= uint64_t{1} << (v & 63);
    }
  };
  // The first leaves' corners, on every thread (a word of used_bits may
  // hold corners of leaves on several threads: an atomic or).
  UnfilledVector<int64_t> work(roots);
  ForChunks(pool, roots, [&](int64_t b, int64_t e) {
    for (int64_t k = b; k < e; ++k) {
      for (const P& p : CornersOf(leaves[k])) {
        const int64_t v = index(p.i, p.j);
        std::atomic_ref<uint64_t>(used_bits[v >> 6])
            .fetch_or(uint64_t{1} << (v & 63), std::memory_order_relaxed);
      }
      work[k] = k;
    }
  });
  std::vector<uint8_t> queued;
  // A pass's work by root row: its positions in `work`, row after row
  // (row_start[rr] .. row_start[rr + 1]), listed on every thread (chunks
  // of work counted per row, then placed where the rows and the chunks
  // before them end).
  UnfilledVector<int64_t> by_row;
  std::vector<int64_t> row_start(roots_y + 1);
  auto list_by_row = [&] {
    const int64_t n = static_cast<int64_t>(work.size());
    const int64_t chunks = (n + kFillChunk - 1) / kFillChunk;
    std::vector<int64_t> at(static_cast<size_t>(chunks) * roots_y, 0);
    ForChunks(pool, n, [&](int64_t b, int64_t e) {
      int64_t* count = &at[static_cast<size_t>(b / kFillChunk) * roots_y];
      for (int64_t w = b; w < e; ++w) ++count[leaves[work[w]].j0 / kRoot];
    });
    BucketStarts<int64_t>(chunks, roots_y, at.data(), row_start.data());
    ResizeForWriting(&by_row, n);
    ForChunks(pool, n, [&](int64_t b, int64_t e) {
      int64_t* next = &at[static_cast<size_t>(b / kFillChunk) * roots_y];
      for (int64_t w = b; w < e; ++w)
        by_row[next[leaves[work[w]].j0 / kRoot]++] = w;
    });
  };
  // Whether measured leaf k is split: over the tolerance, and more than a
  // cell.
  auto splits_leaf = [&](int64_t k) {
    return !(leaf_dev[k] <= tolerance) && leaves[k].w * leaves[k].h != 1;
  };
  for (bool first_pass = true;; first_pass = false) {
    // Each work leaf triangulated and measured where its root row's
    // heights are read; how one over the tolerance is halved too (a byte a
    // leaf, written for those alone: the first pass visits every leaf).
    UnfilledVector<uint8_t> split_x(work.size());
    list_by_row();
    for (int64_t rr = 0; rr < roots_y; ++rr) {
      if (row_start[rr] == row_start[rr + 1]) continue;
      absl::StatusOr<Lattice> window_rows = window(rr);
      if (!window_rows.ok()) return window_rows.status();
      const Lattice& l = *window_rows;
      const int64_t* const row_work = by_row.data() + row_start[rr];
      pool.ParallelFor(row_start[rr + 1] - row_start[rr], [&](int64_t x) {
        const int64_t w = row_work[x];
        const int64_t k = work[w];
        const Leaf& f = leaves[k];
        auto measure = [&] {
          // The sides' lattice vertices that are corners, counter-clockwise
          // from (i0, j0): this thread's, reused (a vector a leaf, grown as
          // it filled, was several mallocs a leaf).
          thread_local std::vector<P> ring;
          ring.clear();
          auto side_vertex = [&](int64_t i, int64_t j) {
            if (used(index(i, j))) ring.push_back({i, j});
          };
          for (int64_t d = 0; d < f.w; ++d) side_vertex(f.i0 + d, f.j0);
          for (int64_t d = 0; d < f.h; ++d) side_vertex(f.i0 + f.w, f.j0 + d);
          for (int64_t d = f.w; d > 0; --d) side_vertex(f.i0 + d, f.j0 + f.h);
          for (int64_t d = f.h; d > 0; --d) side_vertex(f.i0, f.j0 + d);
          std::vector<P>*& ear = ears.at[k];
          thread_local std::vector<P> corners;
          const std::vector<P>* t = &corners;
          if (ring.size() == 4) {
            delete ear;
            ear = nullptr;
            shape[k] = CornerDiagonal(l, f);
            if (first_pass && fit_dev[k] >= 0) {
              leaf_dev[k] = fit_dev[k];
              return;
            }
            corners.clear();
            CornerTriangles(f.i0, f.j0, f.i0 + f.w, f.j0 + f.h,
                            static_cast<LeafShape>(shape[k]), &corners);
          } else {
            if (ear == nullptr) ear = new std::vector<P>();
            ear->clear();
            ClipEars(&ring, ear);
            shape[k] = kEars;
            t = ear;
          }
          double dev = 0;
          for (size_t q = 0; q + 2 < t->size(); q += 3) {
            dev = std::max(
                dev, l.TriangleDeviation((*t)[q], (*t)[q + 1], (*t)[q + 2]));
          }
          leaf_dev[k] = dev;
        };
        measure();
        if (splits_leaf(k)) {
          split_x[w] = SplitsAcrossX(l, f);
        }
      });
    }
    corners_added.clear();
    std::vector<int64_t> halves;
    // The leaves' arrays grown once for the pass's halves, their copies on
    // every thread.
    int64_t splits = 0;
    for (const int64_t k : work) splits += splits_leaf(k);
    if (splits == 0) break;
    const int64_t grown = static_cast<int64_t>(leaves.size()) + 2 * splits;
    ReserveOnEveryThread(pool, &leaves, grown);
    ReserveOnEveryThread(pool, &kids, grown);
    ReserveOnEveryThread(pool, &leaf_dev, grown);
    ReserveOnEveryThread(pool, &shape, grown);
    ReserveOnEveryThread(pool, &ears.at, grown);
    for (size_t w = 0; w < work.size(); ++w) {
      const int64_t k = work[w];
      if (!splits_leaf(k)) continue;
      const Leaf f = leaves[k];  // a copy: `leaves` grows below
      kids[k] = static_cast<int64_t>(leaves.size());
      delete ears.at[k];
      ears.at[k] = nullptr;
      for (const Leaf& half : HalvesAcross(f, split_x[w])) {
        halves.push_back(static_cast<int64_t>(leaves.size()));
        leaves.push_back(half);
        kids.push_back(-1);
        shape.push_back(kDiagonalAC);  // written when it is measured
        ears.at.push_back(nullptr);
        leaf_dev.push_back(INFINITY);
        add_corners(half);
      }
    }
    // Next: the halves, and every leaf with a new corner on its sides (it
    // holds one of the four cells around that corner).
    queued.resize(leaves.size());
    work.assign(halves.begin(), halves.end());
    for (const int64_t k : halves) queued[k] = 1;
    for (const int64_t v : corners_added) {
      const int64_t i = v % (nx + 1), j = v / (nx + 1);
      for (int64_t cj = std::max<int64_t>(j - 1, 0); cj <= std::min(j, ny - 1);
           ++cj) {
        for (int64_t ci = std::max<int64_t>(i - 1, 0);
             ci <= std::min(i, nx - 1); ++ci) {
          const int64_t k = leaf_at(ci, cj);
          if (!queued[k]) {
            queued[k] = 1;
            work.push_back(k);
          }
        }
      }
    }
    for (const int64_t k : work) queued[k] = 0;
  }
  trees = {};

  // The final leaves, depth first from the roots: runs of roots on every
  // thread, counted, then listed where the runs before them end.
  constexpr int64_t kRootRun = 4096;
  const int64_t runs = (roots + kRootRun - 1) / kRootRun;
  UnfilledVector<int64_t> final_leaves;  // written on every thread
  auto depth_first = [&](int64_t run, auto&& visit) {
    std::vector<int64_t> stack;
    const int64_t end = std::min(roots, (run + 1) * kRootRun);
    for (int64_t r = run * kRootRun; r < end; ++r) {
      stack.push_back(r);
      while (!stack.empty()) {
        const int64_t k = stack.back();
        stack.pop_back();
        if (kids[k] < 0) {
          visit(k);
        } else {
          stack.push_back(kids[k] + 1);
          stack.push_back(kids[k]);
        }
      }
    }
  };
  const std::vector<int64_t> run_start =
      RunStarts(pool, runs, [&](int64_t run) {
        int64_t n = 0;
        depth_first(run, [&n](int64_t) { ++n; });
        return n;
      });
  final_leaves.resize(run_start[runs]);
  // Each final leaf's first and opposite corners, for its corner triangles
  // once `leaves` is gone.
  UnfilledVector<std::array<P, 2>> final_corners(run_start[runs]);
  pool.ParallelFor(runs, [&](int64_t run) {
    int64_t at = run_start[run];
    depth_first(run, [&](int64_t k) {
      const Leaf& f = leaves[k];
      final_corners[at] = {P{f.i0, f.j0}, P{f.i0 + f.w, f.j0 + f.h}};
      final_leaves[at++] = k;
    });
  });
  // What only the passes needed goes before the mesh is listed: on the
  // 1000 mm plate's 6.4 M triangles, hundreds of MB (buffers this large go
  // back to the system when freed).
  UnfilledVector<Leaf>().swap(leaves);
  UnfilledVector<int64_t>().swap(kids);
  UnfilledVector<double>().swap(fit_dev);
  UnfilledVector<int64_t>().swap(work);
  UnfilledVector<int64_t>().swap(by_row);
  std::vector<uint8_t>().swap(queued);

  // The used lattice vertices, row-major, are the new top vertices: their
  // heights read a root row at a time. A vertex's new index is the number
  // of used ones before it (counted from each block of 64's).
  // The mesh's indices are int32: its top vertices, a bottom one under
  // each boundary one and the bottom's middle must fit.
  // Listed on every thread (on the 1000 mm plate this listing, over all
  // 400 M lattice vertices, ran on one): a vertex's new index is the number
  // of used ones before it (a prefix over blocks of 64), a leaf's first
  // triangle the number of triangles of the leaves before it.
  UnfilledVector<uint32_t> block_rank(used_bits.size());  // every thread
  constexpr int64_t kRankChunk = 4096;  // blocks of 64 vertices
  const int64_t rank_chunks =
      (static_cast<int64_t>(used_bits.size()) + kRankChunk - 1) / kRankChunk;
  const std::vector<int64_t> chunk_used =
      RunStarts(pool, rank_chunks, [&](int64_t c) {
        const size_t end =
            std::min(used_bits.size(), size_t(c + 1) * kRankChunk);
        int64_t n = 0;
        for (size_t b = size_t(c) * kRankChunk; b < end; ++b) {
          n += std::popcount(used_bits[b]);
        }
        return n;
      });
  const int64_t kept = chunk_used[rank_chunks];
  if (2 * kept + 1 > INT32_MAX) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the adaptive mesh keeps %d of the lattice's vertices, more than "
        "its int32 indices hold: raise the mesh tolerance",
        kept));
  }
  pool.ParallelFor(rank_chunks, [&](int64_t c) {
    const size_t end = std::min(used_bits.size(), size_t(c + 1) * kRankChunk);
    uint32_t counted = static_cast<uint32_t>(chunk_used[c]);
    for (size_t b = size_t(c) * kRankChunk; b < end; ++b) {
      block_rank[b] = counted;
      counted += std::popcount(used_bits[b]);
    }
  });
  auto remap = [&](int64_t v) {
    const uint64_t below = used_bits[v >> 6] & ((uint64_t{1} << (v & 63)) - 1);
    return static_cast<int32_t>(block_rank[v >> 6] + std::popcount(below));
  };
  // The top's boundary, counter-clockwise seen from above: the walls stand
  // under its edges (below). With it, the mesh's exact sizes: its vectors
  // are filled without growing (a doubling holds up to three times the
  // final size while it copies).
  std::vector<int64_t> boundary;  // lattice indices, counter-clockwise
  for (int64_t i = 0; i < nx; ++i) boundary.push_back(index(i, 0));
  for (int64_t j = 0; j < ny; ++j) boundary.push_back(index(nx, j));
  for (int64_t i = nx; i > 0; --i) boundary.push_back(index(i, ny));
  for (int64_t j = ny; j > 0; --j) boundary.push_back(index(0, j));
  int64_t walls = 0;
  for (const int64_t v : boundary) walls += used(v) ? 1 : 0;
  const int64_t n_leaves = static_cast<int64_t>(final_leaves.size());
  constexpr int64_t kLeafChunk = 4096;
  const int64_t leaf_chunks = (n_leaves + kLeafChunk - 1) / kLeafChunk;
  const std::vector<int64_t> first_triangle =
      RunStarts(pool, leaf_chunks, [&](int64_t c) {
        int64_t n = 0;
        const int64_t end = std::min(n_leaves, (c + 1) * kLeafChunk);
        for (int64_t q = c * kLeafChunk; q < end; ++q) {
          const int64_t k = final_leaves[q];
          n += shape[k] == kEars ? static_cast<int64_t>(ears.at[k]->size() / 3)
                                 : 2;
        }
        return n;
      });
  const int64_t top_triangles = first_triangle[leaf_chunks];
  TriangleMesh mesh;
  mesh.vertices.reserve(kept + walls + 1);
  mesh.vertices.resize(kept);
  mesh.triangles.reserve(top_triangles + 3 * walls);
  mesh.triangles.resize(top_triangles);
  mesh.lattice_nx = static_cast<int32_t>(nx);
  mesh.lattice_ny = static_cast<int32_t>(ny);
  mesh.z_bottom = z_bottom;
  for (int64_t rr = 0; rr < roots_y; ++rr) {
    absl::StatusOr<Lattice> l = window(rr);
    if (!l.ok()) return l.status();
    const int64_t j0 = rr * kRoot;
    const int64_t j_end = rr + 1 == roots_y ? ny : j0 + kRoot - 1;
    pool.ParallelFor(j_end - j0 + 1, [&](int64_t dj) {
      const int64_t j = j0 + dj;
      for (int64_t i = 0; i <= nx; ++i) {
        const int64_t v = index(i, j);
        if (used(v)) mesh.vertices[remap(v)] = {xs[i], ys[j], l->Z(i, j)};
      }
    });
  }
  mesh.top_vertices = kept;
  // Each leaf's triangles; the ear-clipped lists freed as they are listed
  // (freeing them on one thread took longer than listing).
  std::vector<double> chunk_dev(leaf_chunks, 0);
  pool.ParallelFor(leaf_chunks, [&](int64_t c) {
    std::vector<P> corners;
    int64_t out = first_triangle[c];
    const int64_t end = std::min(n_leaves, (c + 1) * kLeafChunk);
    double dev = 0;
    for (int64_t q = c * kLeafChunk; q < end; ++q) {
      const int64_t k = final_leaves[q];
      const std::vector<P>* t = ears.at[k];
      if (shape[k] != kEars) {
        const auto& [lo, hi] = final_corners[q];
        corners.clear();
        CornerTriangles(lo.i, lo.j, hi.i, hi.j,
                        static_cast<LeafShape>(shape[k]), &corners);
        t = &corners;
      }
      for (size_t p = 0; p + 2 < t->size(); p += 3) {
        const P* v = t->data() + p;
        mesh.triangles[out++] = {remap(index(v[0].i, v[0].j)),
                                 remap(index(v[1].i, v[1].j)),
                                 remap(index(v[2].i, v[2].j))};
      }
      delete ears.at[k];
      ears.at[k] = nullptr;
      dev = std::max(dev, leaf_dev[k]);
    }
    chunk_dev[c] = dev;
  });
  for (const double dev : chunk_dev) {
    mesh.max_deviation = std::max(mesh.max_deviation, dev);
  }

  // Walls under the top's boundary edges, and a bottom fanned from a vertex
  // under the middle.
  std::vector<int32_t> top_ring, bottom_ring;
  for (int64_t v : boundary) {
    if (!used(v)) continue;
    top_ring.push_back(remap(v));
    bottom_ring.push_back(static_cast<int32_t>(mesh.vertices.size()));
    mesh.vertices.push_back({xs[v % (nx + 1)], ys[v / (nx + 1)], z_bottom});
  }
  const int32_t middle = static_cast<int32_t>(mesh.vertices.size());
  mesh.vertices.push_back({(xs[0] + xs[nx]) / 2, (ys[0] + ys[ny]) / 2,
                           z_bottom});
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
