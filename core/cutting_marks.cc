#include "core/cutting_marks.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <span>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/container/inlined_vector.h"
#include "absl/strings/str_cat.h"
#include "core/bucket_starts.h"
#include "core/unfilled_vector.h"

namespace swarf {
namespace {

// ---------------------------------------------------------------------------
// Quadratics along a segment.

// q(t) = a t^2 + b t + c.
struct Quad {
  double a = 0, b = 0, c = 0;
  double operator()(double t) const { return (a * t + b) * t + c; }
  Quad operator-(const Quad& o) const { return {a - o.a, b - o.b, c - o.c}; }
};

// Eq. (1) for the jet `n` of the node at (xn, yn), restricted to the segment
// (px, py) + t (ex, ey): exactly a quadratic in t.
Quad Restrict(const SurfaceJet& n, double xn, double yn, double px, double py,
              double ex, double ey) {
  double gx, gy;
  PatchGradient(n, xn, yn, px, py, &gx, &gy);
  return {0.5 * (n.wxx * ex * ex + 2 * n.wxy * ex * ey + n.wyy * ey * ey),
          gx * ex + gy * ey, EvaluatePatch(n, xn, yn, px, py)};
}

Quad Constant(double c) { return {0, 0, c}; }

// Real roots of q, in the numerically stable form (no cancellation between
// -b and the square root). Returns the count (0..2).
int QuadRoots(const Quad& q, double r[2]) {
  if (q.a == 0) {
    if (q.b == 0) return 0;
    r[0] = -q.c / q.b;
    return 1;
  }
  const double disc = q.b * q.b - 4 * q.a * q.c;
  if (disc < 0) return 0;
  const double s = q.b >= 0 ? -0.5 * (q.b + std::sqrt(disc))
                            : -0.5 * (q.b - std::sqrt(disc));
  if (s == 0) {  // b = 0 and c = 0: double root at 0
    r[0] = 0;
    return 1;
  }
  r[0] = s / q.a;
  r[1] = q.c / s;
  return 2;
}

// The root of q in [lo, hi] when q(lo) and q(hi) differ in sign (or one is
// zero): the closed-form root, so the crossing's position error is the
// patches' own, not a search step's. Bisection only if rounding put the
// closed-form roots outside the bracket.
double RootIn(const Quad& q, double lo, double hi) {
  const double flo = q(lo), fhi = q(hi);
  if (flo == 0) return lo;
  if (fhi == 0) return hi;
  double r[2];
  const int n = QuadRoots(q, r);
  const double slack = 1e-12 * (hi - lo);
  double best = std::nan(""), best_gap = kInf;
  for (int k = 0; k < n; ++k) {
    if (!std::isfinite(r[k])) continue;
    const double gap = std::fmax(lo - r[k], r[k] - hi);
    if (gap <= slack && gap < best_gap) {
      best = std::clamp(r[k], lo, hi);
      best_gap = gap;
    }
  }
  if (!std::isnan(best)) return best;
  double a = lo, b = hi, fa = flo;
  for (int it = 0; it < 200 && b - a > 0; ++it) {
    const double m = 0.5 * (a + b);
    if (m <= a || m >= b) break;
    const double fm = q(m);
    if ((fm < 0) == (fa < 0)) {
      a = m;
      fa = fm;
    } else {
      b = m;
    }
  }
  return 0.5 * (a + b);
}

// Where a crease between the surface of the node at t = lo and the one at
// t = hi crosses [lo, hi], with d = (surface at lo) - (surface at hi), which
// the node owners say is <= 0 at lo and >= 0 at hi. When the patches agree
// with the owners the crossing is the root. When they do not at one end, the
// crease lies within the patches' truncation error of that node and the
// crossing is placed on it (the paper assumes one mark per edge; a quadratic
// with equal signs at both ends has no or two roots, and two would be noise).
double CreaseRoot(const Quad& d, double lo, double hi) {
  const double dlo = d(lo), dhi = d(hi);
  if ((dlo <= 0 && dhi >= 0) || (dlo >= 0 && dhi <= 0)) {
    return RootIn(d, lo, hi);
  }
  return dlo > 0 ? lo : hi;
}

double Lerp(double a, double b, double t) { return (1 - t) * a + t * b; }

// ---------------------------------------------------------------------------
// Vertices and segments.

// Vertex keys: crossings on element edges are keyed by the edge, so that
// both elements sharing an edge name its crossings alike; other vertices get
// keys unique to their element or segment.
constexpr uint64_t kInteriorKey = uint64_t{1} << 62;
constexpr uint64_t kClipKey = uint64_t{1} << 61;

struct End {
  uint64_t key = 0;
  double x = 0, y = 0, z = 0;
  std::array<int32_t, 2> owners = {kStockTopOwner, kStockTopOwner};
  double angle = 0;  // radians
};

struct Segment {
  End e[2];
};

std::array<int32_t, 2> Sorted(int32_t a, int32_t b) {
  return a < b ? std::array<int32_t, 2>{a, b} : std::array<int32_t, 2>{b, a};
}

struct NodeRef {
  SurfaceJet jet;
  int32_t owner = kStockTopOwner;
  double x = 0, y = 0;
};

// A crossing along an edge or segment, in its own direction.
struct Crossing {
  double t = 0;
  int32_t before = 0, after = 0;  // labels (owners or groups) either side
  bool mark = false;              // eq. (5) holds
  End end;
};

struct Settings {
  double z_top = 0;
  double t2 = 0;  // radians
  double t1 = 0;
  double threshold_h = -1, threshold_v = -1;  // eq. (3) per edge direction
};

// Eq. (5): the printed slope difference must exceed t2 (it bounds the
// normal angle from above), and so must the angle between the normals.
// *angle is the normals' angle where the slope difference passes, else 0:
// a crossing that is no mark is never drawn, and its angle never read (on
// a plate most crossings are between the moves of a pass, and their
// atan2 was a twelfth of the bands' search).
bool IsMark(double ax, double ay, double bx, double by, double t2,
            double* angle) {
  if (!(SlopeDifference(ax, ay, bx, by) > t2)) {
    *angle = 0;
    return false;
  }
  *angle = NormalAngle(ax, ay, bx, by);
  return *angle > t2;
}

// The canonical crossings of the grid edge from node i (t = 0) to node j
// (t = 1), from the two nodes' patches and the stock top only, so that both
// elements sharing the edge find the same points. At most one crossing
// between the two owners (the paper's assumption), or two when their patches
// meet above the top: owner_i | top | owner_j. Returns the count.
int EdgeCrossings(const NodeRef& ni, const NodeRef& nj, uint64_t edge_key,
                  const Settings& s, Crossing out[2]) {
  const int32_t a = ni.owner, b = nj.owner;
  if (a == b) return 0;
  const double ex = nj.x - ni.x, ey = nj.y - ni.y;
  const Quad top = Constant(s.z_top);
  const Quad qi = a == kStockTopOwner
                      ? top
                      : Restrict(ni.jet, ni.x, ni.y, ni.x, ni.y, ex, ey);
  const Quad qj = b == kStockTopOwner
                      ? top
                      : Restrict(nj.jet, nj.x, nj.y, ni.x, ni.y, ex, ey);
  auto grad = [&](int32_t owner, const NodeRef& n, double x, double y,
                  double* gx, double* gy) {
    if (owner == kStockTopOwner) {
      *gx = *gy = 0;
    } else {
      PatchGradient(n.jet, n.x, n.y, x, y, gx, gy);
    }
  };
  auto make = [&](double t, int32_t lo_owner, const NodeRef& lo_node,
                  int32_t hi_owner, const NodeRef& hi_node, double z, int k) {
    Crossing& c = out[k];
    c.t = t;
    c.before = lo_owner;
    c.after = hi_owner;
    c.end.key = edge_key * 2 + k;
    c.end.x = Lerp(ni.x, nj.x, t);
    c.end.y = Lerp(ni.y, nj.y, t);
    c.end.z = z;
    c.end.owners = Sorted(lo_owner, hi_owner);
    double ax, ay, bx, by;
    grad(lo_owner, lo_node, c.end.x, c.end.y, &ax, &ay);
    grad(hi_owner, hi_node, c.end.x, c.end.y, &bx, &by);
    c.mark = IsMark(ax, ay, bx, by, s.t2, &c.end.angle);
  };
  const double t = CreaseRoot(qi - qj, 0, 1);
  // On a node (t clamped to 0 or 1) its own height, which is exact, so that
  // all edges meeting there agree; elsewhere the patches agree to rounding.
  const double z = a == kStockTopOwner   ? s.z_top
                   : b == kStockTopOwner ? s.z_top
                   : t == 0              ? ni.jet.w
                   : t == 1              ? nj.jet.w
                                         : 0.5 * (qi(t) + qj(t));
  if (z <= s.z_top || a == kStockTopOwner || b == kStockTopOwner) {
    make(t, a, ni, b, nj, std::fmin(z, s.z_top), 0);
    return 1;
  }
  // The owners' patches meet above the top: each meets the top first.
  const double t_a = CreaseRoot(qi - top, 0, t);
  const double t_b = CreaseRoot(top - qj, t, 1);
  make(t_a, a, ni, kStockTopOwner, nj, s.z_top, 0);
  make(t_b, kStockTopOwner, ni, b, nj, s.z_top, 1);
  return 2;
}

// ---------------------------------------------------------------------------
// One element: its surfaces (groups of owners) and the reconstruction.

constexpr int kMaxLabels = 5;  // four corners and the top

// How far outside its element (in element sizes) a junction is accepted.
constexpr double kJunctionMargin = 0.5;

struct Piece {
  const NodeRef* node = nullptr;  // null: the stock top
  int group = 0;
  int32_t owner = kStockTopOwner;
};

struct GroupValue {
  double w = kInf, gx = 0, gy = 0;
  int32_t owner = kStockTopOwner;
};

class ElementModel {
 public:
  ElementModel(const NodeRef* const c[4], const int group_of_corner[4],
               int top_group, double z_top)
      : z_top_(z_top) {
    for (int k = 0; k < 4; ++k) {
      if (c[k]->owner == kStockTopOwner) continue;  // its patch is the top
      pieces_[n_++] = {c[k], group_of_corner[k], c[k]->owner};
    }
    pieces_[n_++] = {nullptr, top_group, kStockTopOwner};
  }

  int pieces() const { return n_; }
  const Piece& piece(int k) const { return pieces_[k]; }

  double PieceValue(int k, double x, double y) const {
    const Piece& p = pieces_[k];
    return p.node == nullptr
               ? z_top_
               : EvaluatePatch(p.node->jet, p.node->x, p.node->y, x, y);
  }
  void PieceGradient(int k, double x, double y, double* gx, double* gy) const {
    const Piece& p = pieces_[k];
    if (p.node == nullptr) {
      *gx = *gy = 0;
    } else {
      PatchGradient(p.node->jet, p.node->x, p.node->y, x, y, gx, gy);
    }
  }
  Quad PieceQuad(int k, double px, double py, double ex, double ey) const {
    const Piece& p = pieces_[k];
    return p.node == nullptr
               ? Constant(z_top_)
               : Restrict(p.node->jet, p.node->x, p.node->y, px, py, ex, ey);
  }

  // The surface of group g at (x, y): the lowest of its pieces.
  GroupValue Group(int g, double x, double y) const {
    GroupValue v;
    int best = -1;
    for (int k = 0; k < n_; ++k) {
      if (pieces_[k].group != g) continue;
      const double w = PieceValue(k, x, y);
      if (w < v.w) {
        v.w = w;
        best = k;
      }
    }
    if (best >= 0) {
      PieceGradient(best, x, y, &v.gx, &v.gy);
      v.owner = pieces_[best].owner;
    }
    return v;
  }

  // Eq. (2): the group of the lowest piece at (x, y) (first on ties).
  int ArgMin(double x, double y, double* w = nullptr) const {
    int best = 0;
    double bw = PieceValue(0, x, y);
    for (int k = 1; k < n_; ++k) {
      const double v = PieceValue(k, x, y);
      if (v < bw) {
        bw = v;
        best = k;
      }
    }
    if (w != nullptr) *w = bw;
    return pieces_[best].group;
  }

 private:
  Piece pieces_[kMaxLabels];
  int n_ = 0;
  double z_top_;
};

// A crossing on the boundary of a cell, in counter-clockwise order: s is the
// side (0 bottom, 1 right, 2 top, 3 left) plus the fraction along it.
struct BoundaryCrossing {
  double s = 0;
  int left = 0, right = 0;  // groups before and after it
  End end;
};

// An element's (or a part's) boundary crossings: mostly two to four, held in
// place (a vector's allocation each was about 2% of the marks' instructions).
using Crossings = absl::InlinedVector<BoundaryCrossing, 8>;

struct Cell {
  double x0, y0, x1, y1;
};

// Builds the segments of one element from its boundary crossings, resolving
// junctions and elements with several marks (paper Fig. 3).
class ElementResolver {
 public:
  ElementResolver(const ElementModel& model, const Settings& s,
                  uint64_t element_index, std::vector<Segment>* out)
      : m_(model),
        s_(s),
        key_base_(kInteriorKey | (element_index << 16)),
        out_(out) {}

  void Resolve(const Cell& cell, Crossings x, int depth) {
    const int n = static_cast<int>(x.size());
    if (n == 0) return;
    bool consistent = n >= 2;
    for (int k = 0; k < n && consistent; ++k) {
      consistent = x[k].right == x[(k + 1) % n].left && x[k].left != x[k].right;
    }
    if (consistent) {
      if (n == 2) {
        Emit(x[0].end, x[1].end);
        return;
      }
      const int g0 = x[0].right, g1 = x[1].right;
      if (n == 3) {
        Junction(cell, x);
        return;
      }
      if (n == 4) {
        const int g2 = x[2].right, g3 = x[3].right;
        double cx = 0, cy = 0;
        for (const auto& c : x) {
          cx += 0.25 * c.end.x;
          cy += 0.25 * c.end.y;
        }
        const int gc = m_.ArgMin(cx, cy);
        // Arc k runs from crossing k to k+1. The group that connects through
        // the middle cuts the other group's arcs off with one crease each.
        const bool one_connects = (g1 == g3) && gc == g1;
        const bool zero_connects = (g0 == g2) && gc == g0;
        if (one_connects) {
          Emit(x[0].end, x[1].end);
          Emit(x[2].end, x[3].end);
          return;
        }
        if (zero_connects) {
          Emit(x[1].end, x[2].end);
          Emit(x[3].end, x[0].end);
          return;
        }
        if (TwoJunctions(cell, x)) return;
      }
    }
    if (depth < kMaxDepth && consistent) {
      Subdivide(cell, x, depth);
    } else {
      Star(x);
    }
  }

 private:
  static constexpr int kMaxDepth = 4;

  uint64_t NewKey() { return key_base_ | next_key_++; }

  void Emit(const End& a, const End& b) { out_->push_back({{a, b}}); }

  // The end of the crease between groups (g, h) at an interior point.
  End InteriorEnd(uint64_t key, double x, double y, int g, int h) const {
    const GroupValue a = m_.Group(g, x, y), b = m_.Group(h, x, y);
    End e;
    e.key = key;
    e.x = x;
    e.y = y;
    m_.ArgMin(x, y, &e.z);
    e.owners = Sorted(a.owner, b.owner);
    e.angle = NormalAngle(a.gx, a.gy, b.gx, b.gy);
    return e;
  }

  // Where groups g[0..2] meet: Newton's method on S_a - S_b = S_b - S_c = 0
  // over the element's patches (the active piece of each group may change
  // between steps), from (x, y). False if it does not converge within
  // kJunctionMargin cells of `cell`: the boundary crossings come from the
  // edge nodes' patches and the junction from all four, so a third surface
  // seen by this element only may put the junction just across an edge.
  bool SolveJunction(const int g[3], const Cell& cell, double* x,
                     double* y) const {
    const double size = std::fmax(cell.x1 - cell.x0, cell.y1 - cell.y0);
    double qx = *x, qy = *y;
    bool ok = false;
    for (int it = 0; it < 50; ++it) {
      const GroupValue a = m_.Group(g[0], qx, qy), b = m_.Group(g[1], qx, qy),
                       c = m_.Group(g[2], qx, qy);
      // Eq. (4) with t1 for each pair.
      if (PatchGap(a.w, b.w) <= s_.t1 && PatchGap(b.w, c.w) <= s_.t1) {
        ok = true;
        break;
      }
      const double f1 = a.w - b.w, f2 = b.w - c.w;
      const double j11 = a.gx - b.gx, j12 = a.gy - b.gy;
      const double j21 = b.gx - c.gx, j22 = b.gy - c.gy;
      const double det = j11 * j22 - j12 * j21;
      const double scale =
          (std::fabs(j11) + std::fabs(j12)) * (std::fabs(j21) + std::fabs(j22));
      if (!(std::fabs(det) > 1e-12 * scale)) break;  // parallel creases
      double dx = -(j22 * f1 - j12 * f2) / det;
      double dy = -(-j21 * f1 + j11 * f2) / det;
      const double len = std::hypot(dx, dy);
      if (len > size) {  // damp wild steps
        dx *= size / len;
        dy *= size / len;
      }
      qx += dx;
      qy += dy;
      if (std::hypot(dx, dy) <= 1e-14 * size) {
        // Converged in position; heights as close as rounding allows.
        ok = PatchGap(a.w, b.w) <= 1e3 * s_.t1 &&
             PatchGap(b.w, c.w) <= 1e3 * s_.t1;
        break;
      }
    }
    const double margin = kJunctionMargin * size;
    if (!ok || !(qx >= cell.x0 - margin && qx <= cell.x1 + margin &&
                 qy >= cell.y0 - margin && qy <= cell.y1 + margin)) {
      return false;
    }
    *x = qx;
    *y = qy;
    return true;
  }

  // Three crossings: the three creases meet at a junction; at the crossings'
  // centroid if Newton's method fails.
  void Junction(const Cell& cell, const Crossings& x) {
    const int g[3] = {x[0].right, x[1].right, x[2].right};
    double px = (x[0].end.x + x[1].end.x + x[2].end.x) / 3;
    double py = (x[0].end.y + x[1].end.y + x[2].end.y) / 3;
    double qx = px, qy = py;
    if (SolveJunction(g, cell, &qx, &qy)) {
      px = qx;
      py = qy;
    }
    const uint64_t key = NewKey();
    for (const auto& c : x) {
      Emit(c.end, InteriorEnd(key, px, py, c.left, c.right));
    }
  }

  // Four crossings between which two opposite arcs' groups meet inside the
  // cell (paper Fig. 3): two junctions joined by a short crease. Arc k (group
  // g[k]) runs from crossing k to k+1. If groups g[t] and g[t+2] meet, one
  // junction joins crossings t+1 and t+2 and the other t+3 and t. Tries both
  // t and keeps the one whose junctions have the fourth group above them;
  // false if neither converges.
  bool TwoJunctions(const Cell& cell, const Crossings& x) {
    const int g[4] = {x[0].right, x[1].right, x[2].right, x[3].right};
    int best_t = -1;
    double best_margin = -kInf, jx[2][2] = {}, jy[2][2] = {};
    for (int t = 0; t < 2; ++t) {
      if (g[t] == g[t + 2]) continue;  // a simple pair of creases instead
      const int ga[3] = {g[t], g[t + 1], g[t + 2]};
      const int gb[3] = {g[t + 2], g[(t + 3) % 4], g[t]};
      const BoundaryCrossing& a1 = x[t + 1];
      const BoundaryCrossing& a2 = x[(t + 2) % 4];
      const BoundaryCrossing& b1 = x[(t + 3) % 4];
      const BoundaryCrossing& b2 = x[t];
      double ax = 0.5 * (a1.end.x + a2.end.x), ay = 0.5 * (a1.end.y + a2.end.y);
      double bx = 0.5 * (b1.end.x + b2.end.x), by = 0.5 * (b1.end.y + b2.end.y);
      if (!SolveJunction(ga, cell, &ax, &ay) ||
          !SolveJunction(gb, cell, &bx, &by)) {
        continue;
      }
      // The group left out of each junction must lie above it.
      const double margin = std::fmin(
          m_.Group(g[(t + 3) % 4], ax, ay).w - m_.Group(g[t], ax, ay).w,
          m_.Group(g[t + 1], bx, by).w - m_.Group(g[t], bx, by).w);
      if (margin > best_margin) {
        best_margin = margin;
        best_t = t;
        jx[t][0] = ax;
        jy[t][0] = ay;
        jx[t][1] = bx;
        jy[t][1] = by;
      }
    }
    if (best_t < 0 || best_margin < -1e3 * s_.t1) return false;
    const int t = best_t;
    const uint64_t ka = NewKey(), kb = NewKey();
    const double ax = jx[t][0], ay = jy[t][0], bx = jx[t][1], by = jy[t][1];
    for (int k : {t + 1, (t + 2) % 4}) {
      Emit(x[k].end, InteriorEnd(ka, ax, ay, x[k].left, x[k].right));
    }
    for (int k : {(t + 3) % 4, t}) {
      Emit(x[k].end, InteriorEnd(kb, bx, by, x[k].left, x[k].right));
    }
    Emit(InteriorEnd(ka, ax, ay, g[t], g[t + 2]),
         InteriorEnd(kb, bx, by, g[t], g[t + 2]));
    return true;
  }

  // Last resort: every crossing to the crossings' centroid.
  void Star(const Crossings& x) {
    if (x.size() < 2) return;
    double px = 0, py = 0;
    for (const auto& c : x) {
      px += c.end.x / x.size();
      py += c.end.y / x.size();
    }
    const uint64_t key = NewKey();
    for (const auto& c : x) {
      if (c.left == c.right) continue;
      Emit(c.end, InteriorEnd(key, px, py, c.left, c.right));
    }
  }

  // Group of the boundary arc containing boundary parameter s.
  static int GroupAt(const Crossings& x, double s) {
    for (const auto& c : x) {
      if (c.s > s) return c.left;
    }
    return x.front().left;
  }

  // Crossings of the element's reconstruction along p -> q (an internal cut
  // of the element), with the groups at p and q given.
  std::vector<Crossing> ModelCrossings(double px, double py, double qx,
                                       double qy, int gp, int gq) {
    const double ex = qx - px, ey = qy - py;
    const int n = m_.pieces();
    Quad q[kMaxLabels];
    for (int k = 0; k < n; ++k) q[k] = m_.PieceQuad(k, px, py, ex, ey);
    std::vector<double> cuts = {0.0, 1.0};
    for (int f = 0; f < n; ++f) {
      for (int g = f + 1; g < n; ++g) {
        if (m_.piece(f).group == m_.piece(g).group) continue;
        double r[2];
        const int nr = QuadRoots(q[f] - q[g], r);
        for (int k = 0; k < nr; ++k) {
          if (r[k] > 0 && r[k] < 1) cuts.push_back(r[k]);
        }
      }
    }
    std::sort(cuts.begin(), cuts.end());
    // The lowest piece on each interval between cuts.
    struct Run {
      double mid;
      int piece;
    };
    std::vector<Run> runs;
    for (size_t k = 0; k + 1 < cuts.size(); ++k) {
      if (!(cuts[k + 1] > cuts[k])) continue;
      const double mid = 0.5 * (cuts[k] + cuts[k + 1]);
      int best = 0;
      for (int f = 1; f < n; ++f) {
        if (q[f](mid) < q[best](mid)) best = f;
      }
      if (!runs.empty() &&
          m_.piece(runs.back().piece).group == m_.piece(best).group) {
        continue;
      }
      runs.push_back({mid, best});
    }
    std::vector<Crossing> out;
    auto add = [&](double t, int g_before, int g_after) {
      Crossing c;
      c.t = t;
      c.before = g_before;
      c.after = g_after;
      const double x = Lerp(px, qx, t), y = Lerp(py, qy, t);
      c.end = InteriorEnd(NewKey(), x, y, g_before, g_after);
      c.mark = c.end.angle > s_.t2;
      out.push_back(c);
    };
    if (runs.empty()) return out;
    const int first = m_.piece(runs.front().piece).group;
    if (first != gp) add(0, gp, first);
    for (size_t k = 0; k + 1 < runs.size(); ++k) {
      const int f = runs[k].piece, g = runs[k + 1].piece;
      add(RootIn(q[f] - q[g], runs[k].mid, runs[k + 1].mid), m_.piece(f).group,
          m_.piece(g).group);
    }
    const int last = m_.piece(runs.back().piece).group;
    if (last != gq) add(1, last, gq);
    return out;
  }

  // Splits the cell in four and resolves each quarter; the cuts are
  // evaluated with the element's own reconstruction.
  void Subdivide(const Cell& cell, const Crossings& x, int depth) {
    const double w = cell.x1 - cell.x0, h = cell.y1 - cell.y0;
    // Split fractions, moved off any crossing lying on a split point.
    double fx = 0.5, fy = 0.5;
    auto hits = [&](double fx, double fy) {
      const double split[4] = {fx, 1 + fy, 2 + (1 - fx), 3 + (1 - fy)};
      for (const auto& c : x) {
        for (double sp : split) {
          if (std::fabs(c.s - sp) < 1e-9) return true;
        }
      }
      return false;
    };
    for (int k = 0; k < 8 && hits(fx, fy); ++k) {
      fx = 0.5 + 0.0137 * (k + 1);
      fy = 0.5 - 0.0113 * (k + 1);
    }
    const double xm = cell.x0 + fx * w, ym = cell.y0 + fy * h;
    const double s_m[4] = {fx, 1 + fy, 2 + (1 - fx), 3 + (1 - fy)};
    const double mx[4] = {xm, cell.x1, xm, cell.x0};
    const double my[4] = {cell.y0, ym, cell.y1, ym};
    const int gc = m_.ArgMin(xm, ym);
    // Cuts from the centre to each side's split point.
    std::vector<Crossing> cut[4];
    for (int k = 0; k < 4; ++k) {
      cut[k] = ModelCrossings(xm, ym, mx[k], my[k], gc, GroupAt(x, s_m[k]));
    }
    const Cell sub[4] = {{cell.x0, cell.y0, xm, ym},
                         {xm, cell.y0, cell.x1, ym},
                         {xm, ym, cell.x1, cell.y1},
                         {cell.x0, ym, xm, cell.y1}};
    Crossings parts[4];
    // Parent boundary crossings go to the quarters that hold them.
    for (const auto& c : x) {
      const int side = std::min(3, static_cast<int>(c.s));
      const double f = c.s - side;
      int q;
      BoundaryCrossing b = c;
      switch (side) {
        case 0:  // bottom: quarters 0 | 1
          q = f < fx ? 0 : 1;
          b.s = q == 0 ? f / fx : (f - fx) / (1 - fx);
          break;
        case 1:  // right: quarters 1 | 2
          q = f < fy ? 1 : 2;
          b.s = 1 + (q == 1 ? f / fy : (f - fy) / (1 - fy));
          break;
        case 2:  // top, right to left: quarters 2 | 3
          q = f < 1 - fx ? 2 : 3;
          b.s = 2 + (q == 2 ? f / (1 - fx) : (f - (1 - fx)) / fx);
          break;
        default:  // left, top to bottom: quarters 3 | 0
          q = f < 1 - fy ? 3 : 0;
          b.s = 3 + (q == 3 ? f / (1 - fy) : (f - (1 - fy)) / fy);
          break;
      }
      parts[q].push_back(b);
    }
    // Each cut borders two quarters: cut k runs from the centre to side k's
    // split point. Quarter q's sides in counter-clockwise order:
    //   0: bottom = parent, right = cut 0 (inwards), top = cut 3, left = parent
    //   1: bottom = parent, right = parent, top = cut 1 (inwards), left = cut 0
    //   2: bottom = cut 1, right = parent, top = parent, left = cut 2 (inwards)
    //   3: bottom = cut 3 (inwards), right = cut 2, top = parent, left = parent
    auto add_cut = [&](int q, int k, int side, bool outwards) {
      for (const Crossing& c : cut[k]) {
        BoundaryCrossing b;
        b.end = c.end;
        const double t = outwards ? c.t : 1 - c.t;
        b.s = side + t;
        b.left = outwards ? c.before : c.after;
        b.right = outwards ? c.after : c.before;
        parts[q].push_back(b);
      }
    };
    add_cut(0, 0, 1, false);
    add_cut(0, 3, 2, true);
    add_cut(1, 1, 2, false);
    add_cut(1, 0, 3, true);
    add_cut(2, 1, 0, true);
    add_cut(2, 2, 3, false);
    add_cut(3, 3, 0, false);
    add_cut(3, 2, 1, true);
    for (int q = 0; q < 4; ++q) {
      std::stable_sort(parts[q].begin(), parts[q].end(),
                       [](const BoundaryCrossing& a,
                          const BoundaryCrossing& b) { return a.s < b.s; });
      Resolve(sub[q], std::move(parts[q]), depth + 1);
    }
  }

  const ElementModel& m_;
  const Settings& s_;
  uint64_t key_base_;
  uint64_t next_key_ = 0;
  std::vector<Segment>* out_;
};

// Small union-find over an element's labels (owners).
struct Labels {
  int32_t owner[kMaxLabels];
  int parent[kMaxLabels];
  int n = 0;
  int Index(int32_t o) {
    for (int k = 0; k < n; ++k) {
      if (owner[k] == o) return k;
    }
    owner[n] = o;
    parent[n] = n;
    return n++;
  }
  int Find(int k) {
    while (parent[k] != k) k = parent[k] = parent[parent[k]];
    return k;
  }
  void Union(int a, int b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

// An edge's crossings (EdgeCrossings'), kept for the other element beside
// it: a function of the edge's two nodes and its key alone.
struct EdgeCrossed {
  Crossing c[2];
  int n = 0;
};

// The segments of element (ei, ej) with corners c (paper order i, j, k, m).
// `bottom` and `left`, where given, are those edges' crossings as an
// element beside them found them; `top` and `right`, where given, receive
// this element's, written after the known ones are read (`top` may be
// `bottom`, `right` may be `left`).
void ProcessElement(const NodeRef* const c[4], int32_t ei, int32_t ej,
                    int32_t nodes_x, const GridGeometry& grid,
                    const Settings& s, const EdgeCrossed* bottom,
                    const EdgeCrossed* left, EdgeCrossed* top,
                    EdgeCrossed* right, std::vector<Segment>* out) {
  // Canonical edges: bottom c0->c1, right c1->c2, top c3->c2, left c0->c3;
  // the top and left ones are walked backwards counter-clockwise.
  const uint64_t row0 = uint64_t(ej) * nodes_x, row1 = row0 + nodes_x;
  const struct {
    int from, to;
    uint64_t key;
    bool backwards;
  } edges[4] = {{0, 1, 2 * (row0 + ei), false},
                {1, 2, 2 * (row0 + ei + 1) + 1, false},
                {3, 2, 2 * (row1 + ei), true},
                {0, 3, 2 * (row0 + ei) + 1, true}};
  Crossing cr[4][2];
  int ncr[4];
  const EdgeCrossed* const known[4] = {bottom, nullptr, nullptr, left};
  for (int k = 0; k < 4; ++k) {
    if (known[k] != nullptr) {
      ncr[k] = known[k]->n;
      std::copy_n(known[k]->c, ncr[k], cr[k]);
    } else {
      ncr[k] = EdgeCrossings(*c[edges[k].from], *c[edges[k].to], edges[k].key,
                             s, cr[k]);
    }
  }
  EdgeCrossed* const keep[4] = {nullptr, right, top, nullptr};
  for (int k = 0; k < 4; ++k) {
    if (keep[k] == nullptr) continue;
    keep[k]->n = ncr[k];
    std::copy_n(cr[k], ncr[k], keep[k]->c);
  }
  // Owners meeting without a crease on any edge of this element (eq. 5
  // fails) are one surface here: consecutive moves of a pass, or the facets
  // of an arc.
  Labels labels;
  for (int k = 0; k < 4; ++k) labels.Index(c[k]->owner);
  labels.Index(kStockTopOwner);
  bool any_mark = false;
  for (int k = 0; k < 4; ++k) {
    for (int m = 0; m < ncr[k]; ++m) {
      const Crossing& x = cr[k][m];
      if (!x.mark) {
        labels.Union(labels.Index(x.before), labels.Index(x.after));
      }
    }
  }
  Crossings bx;
  for (int k = 0; k < 4; ++k) {
    for (int m = 0; m < ncr[k]; ++m) {
      const int mm = edges[k].backwards ? ncr[k] - 1 - m : m;
      const Crossing& x = cr[k][mm];
      const int gb = labels.Find(labels.Index(x.before));
      const int ga = labels.Find(labels.Index(x.after));
      if (!x.mark || gb == ga) continue;
      any_mark = true;
      BoundaryCrossing b;
      b.s = k + (edges[k].backwards ? 1 - x.t : x.t);
      b.left = edges[k].backwards ? ga : gb;
      b.right = edges[k].backwards ? gb : ga;
      b.end = x.end;
      bx.push_back(b);
    }
  }
  if (!any_mark) return;
  int group_of_corner[4];
  for (int k = 0; k < 4; ++k) {
    group_of_corner[k] = labels.Find(labels.Index(c[k]->owner));
  }
  const ElementModel model(c, group_of_corner,
                           labels.Find(labels.Index(kStockTopOwner)), s.z_top);
  ElementResolver resolver(model, s, uint64_t(ej) * nodes_x + ei, out);
  resolver.Resolve(
      {grid.NodeX(ei), grid.NodeY(ej), grid.NodeX(ei + 1), grid.NodeY(ej + 1)},
      std::move(bx), 0);
}

// ---------------------------------------------------------------------------
// Region clipping and chaining.

// Clips segment `seg` to r (Liang-Barsky); false if nothing is left.
bool ClipSegment(const Rect& r, uint64_t index, Segment* seg) {
  End& a = seg->e[0];
  End& b = seg->e[1];
  const double dx = b.x - a.x, dy = b.y - a.y;
  double t0 = 0, t1 = 1;
  const double p[4] = {-dx, dx, -dy, dy};
  const double q[4] = {a.x - r.x0, r.x1 - a.x, a.y - r.y0, r.y1 - a.y};
  for (int k = 0; k < 4; ++k) {
    if (p[k] == 0) {
      if (q[k] < 0) return false;
      continue;
    }
    const double t = q[k] / p[k];
    if (p[k] < 0) {
      t0 = std::fmax(t0, t);
    } else {
      t1 = std::fmin(t1, t);
    }
  }
  if (t0 > t1) return false;
  if (t0 == t1 && (t0 > 0 || t1 < 1)) return false;  // touches a corner only
  const End a0 = a, b0 = b;
  auto at = [&](double t, const End& near, uint64_t key) {
    End e = near;
    e.key = key;
    e.x = Lerp(a0.x, b0.x, t);
    e.y = Lerp(a0.y, b0.y, t);
    e.z = Lerp(a0.z, b0.z, t);
    e.angle = Lerp(a0.angle, b0.angle, t);
    return e;
  };
  if (t0 > 0) a = at(t0, b0, kClipKey | (2 * index));
  if (t1 < 1) b = at(t1, a0, kClipKey | (2 * index + 1));
  // Rounding in the interpolation must not leave the rectangle.
  for (End* e : {&a, &b}) {
    e->x = std::clamp(e->x, r.x0, r.x1);
    e->y = std::clamp(e->y, r.y0, r.y1);
  }
  return true;
}

// Drops vertices where the polyline doubles back (turns by more than 90
// degrees) over a short segment:
// - next to an end, up to `end_fold`: a junction is taken up to half an
//   element outside its element when the third surface, seen only there,
//   puts it in the neighbour (which does not see that surface); the
//   neighbour's crossing on the shared edge then lies behind the junction;
// - elsewhere up to `fold`: crossings clamped onto a node, or within the
//   patches' error of one, may come in the wrong order.
// The ends themselves are kept: junctions are shared with other polylines.
void RemoveFolds(MarkPolyline* p, double fold, double end_fold) {
  for (bool changed = true; changed;) {
    changed = false;
    const size_t n = p->vertices.size();
    if (n < 3) return;
    for (size_t k = 0; k < n; ++k) {
      if (!p->closed && (k == 0 || k + 1 == n)) continue;
      const Vec3& a = p->vertices[(k + n - 1) % n];
      const Vec3& b = p->vertices[k];
      const Vec3& c = p->vertices[(k + 1) % n];
      const double ux = b.x - a.x, uy = b.y - a.y;
      const double vx = c.x - b.x, vy = c.y - b.y;
      if (ux * vx + uy * vy >= 0) continue;
      double limit = fold;
      if (!p->closed && k == 1) limit = std::fmax(limit, end_fold);
      if (!p->closed && k + 2 == n) limit = std::fmax(limit, end_fold);
      const double near_end = !p->closed && k == 1       ? std::hypot(ux, uy)
                              : !p->closed && k + 2 == n ? std::hypot(vx, vy)
                                                         : kInf;
      const double shortest = std::fmin(std::hypot(ux, uy), std::hypot(vx, vy));
      if (shortest > fold && near_end > limit) continue;
      p->vertices.erase(p->vertices.begin() + k);
      p->angle_deg.erase(p->angle_deg.begin() + k);
      p->vertex_owners.erase(p->vertex_owners.begin() + k);
      changed = true;
      break;
    }
  }
}

// A vertex key's incidence: segment `seg`'s end `end`.
struct Inc {
  uint64_t key;
  int64_t seg;
  int end;
};

// Chain's arrays, kept from one window to the next: allocated for each
// window, their pages were faulted in and zeroed again on the chaining's
// thread, while the other threads waited for it (half its time on a
// plate). Every entry is written before it is read.
struct ChainScratch {
  UnfilledVector<Inc> inc, sorted;
  UnfilledVector<uint16_t> bucket;
  UnfilledVector<int64_t> other;
  UnfilledVector<uint8_t> used;
};

// With `starts`, each polyline's first segment (the lowest index of its
// chain: polylines come out in that order). `ghosts` counts, per vertex
// key, segments chained before that end there too (they count in its
// degree). Chains with a segment of index `grow_from` or more give no
// polyline: they may still grow. With `grows_out`, 1 for
// each segment of such a chain; with `next_ghosts` (which needs
// `grows_out`), the `ghosts` for those segments alone once the others are
// handed on: per key a growing segment ends at, the others that end there
// (ghosts included), where there are any. Its arrays are `scratch`'s.
std::vector<MarkPolyline> Chain(
    std::span<const Segment> segs, double tol, double fold, double end_fold,
    ThreadPool& pool, ChainScratch* scratch,
    std::vector<int64_t>* starts = nullptr,
    const absl::flat_hash_map<uint64_t, int32_t>* ghosts = nullptr,
    int64_t grow_from = INT64_MAX, UnfilledVector<uint8_t>* grows_out = nullptr,
    absl::flat_hash_map<uint64_t, int32_t>* next_ghosts = nullptr) {
  const int64_t n = static_cast<int64_t>(segs.size());
  // Incidences sorted by vertex key.
  UnfilledVector<Inc>& inc = scratch->inc;
  ResizeForWriting(&inc, 2 * n);
  constexpr int64_t kIncChunk = int64_t{1} << 14;
  pool.ParallelFor((n + kIncChunk - 1) / kIncChunk, [&](int64_t c) {
    const int64_t k1 = std::min(n, (c + 1) * kIncChunk);
    for (int64_t k = c * kIncChunk; k < k1; ++k) {
      inc[2 * k] = {segs[k].e[0].key, k, 0};
      inc[2 * k + 1] = {segs[k].e[1].key, k, 1};
    }
  });
  // A total order, so the result is the same however it is sorted.
  auto less = [](const Inc& a, const Inc& b) {
    return a.key != b.key ? a.key < b.key
                          : (a.seg != b.seg ? a.seg < b.seg : a.end < b.end);
  };
  // Sorted by buckets of keys on every thread: a window's chaining waits
  // for it, and two halves sorted at once, then merged, left all but two
  // threads of a many-core machine idle. The buckets' bounds are keys (a
  // sample's): a vertex's incidences fall in one bucket, whose ranges
  // (`bounds`) then serve the pass below too.
  const size_t m = inc.size();
  std::vector<size_t> bounds = {0, m};
  const int threads = pool.size();
  if (threads == 1 || m < (size_t{1} << 15)) {
    std::sort(inc.begin(), inc.end(), less);
  } else {
    const int buckets = 4 * threads;
    constexpr int kOversample = 32;
    std::vector<uint64_t> sample(static_cast<size_t>(buckets) * kOversample);
    for (size_t k = 0; k < sample.size(); ++k) {
      sample[k] = inc[k * m / sample.size()].key;
    }
    std::sort(sample.begin(), sample.end());
    std::vector<uint64_t> split(buckets - 1);
    for (int b = 1; b < buckets; ++b) split[b - 1] = sample[b * kOversample];
    // Each chunk of `inc` counts its incidences per bucket, then moves them
    // to their bucket's part for that chunk: the order within a bucket is
    // the chunks' (then sorted anyway).
    const int chunks = buckets;
    UnfilledVector<uint16_t>& bucket = scratch->bucket;
    ResizeForWriting(&bucket, m);
    std::vector<size_t> at(static_cast<size_t>(chunks) * buckets, 0);
    auto chunk_range = [&](int64_t c) {
      return std::pair<size_t, size_t>(c * m / chunks, (c + 1) * m / chunks);
    };
    pool.ParallelFor(chunks, [&](int64_t c) {
      const auto [i0, i1] = chunk_range(c);
      for (size_t i = i0; i < i1; ++i) {
        const auto b = static_cast<uint16_t>(
            std::upper_bound(split.begin(), split.end(), inc[i].key) -
            split.begin());
        bucket[i] = b;
        ++at[c * buckets + b];
      }
    });
    bounds.assign(buckets + 1, 0);
    BucketStarts<size_t>(chunks, buckets, at.data(), bounds.data());
    UnfilledVector<Inc>& sorted = scratch->sorted;
    ResizeForWriting(&sorted, m);
    pool.ParallelFor(chunks, [&](int64_t c) {
      const auto [i0, i1] = chunk_range(c);
      for (size_t i = i0; i < i1; ++i) {
        sorted[at[c * buckets + bucket[i]]++] = inc[i];
      }
    });
    pool.ParallelFor(buckets, [&](int64_t b) {
      std::sort(sorted.begin() + static_cast<std::ptrdiff_t>(bounds[b]),
                sorted.begin() + static_cast<std::ptrdiff_t>(bounds[b + 1]),
                less);
    });
    inc.swap(sorted);
  }
  // For each segment end at a vertex of degree 2, the other incidence
  // there; a bucket at a time (each writes its own incidences' entries).
  UnfilledVector<int64_t>& other = scratch->other;  // seg * 2 + end
  ResizeForWriting(&other, 2 * n);
  FillOnEvery<int64_t>(pool, other.data(), 2 * n, -1);
  pool.ParallelFor(static_cast<int64_t>(bounds.size()) - 1, [&](int64_t b) {
    const size_t end = bounds[b + 1];
    for (size_t i = bounds[b]; i < end;) {
      size_t j = i;
      while (j < end && inc[j].key == inc[i].key) ++j;
      int d = static_cast<int>(j - i);
      if (ghosts != nullptr) {
        const auto g = ghosts->find(inc[i].key);
        if (g != ghosts->end()) d += g->second;
      }
      // Both incidences here: one open segment and one handed on cannot
      // meet at a vertex of degree 2 (they would be one chain, handed on
      // together).
      if (d == 2 && j - i == 2) {
        other[2 * inc[i].seg + inc[i].end] =
            2 * inc[i + 1].seg + inc[i + 1].end;
        other[2 * inc[i + 1].seg + inc[i + 1].end] =
            2 * inc[i].seg + inc[i].end;
      }
      i = j;
    }
  });
  UnfilledVector<uint8_t>& used = scratch->used;
  ResizeForWriting(&used, n);
  FillOnEvery<uint8_t>(pool, used.data(), n, 0);
  if (grows_out != nullptr) {
    ResizeForWriting(grows_out, n);
    FillOnEvery<uint8_t>(pool, grows_out->data(), n, 0);
  }
  auto push_vertex = [&](MarkPolyline* p, const End& e) {
    if (!p->vertices.empty()) {
      const Vec3& last = p->vertices.back();
      if (std::hypot(last.x - e.x, last.y - e.y) <= tol) return;
    }
    p->vertices.push_back({e.x, e.y, e.z});
    p->angle_deg.push_back(e.angle * 180 / std::numbers::pi);
    p->vertex_owners.push_back(e.owners);
  };
  // The chain of segment s, s its lowest index, from the start its walk
  // back from end 0 reaches (or s, around a loop); none for a chain that
  // may grow or is too short. Chains are disjoint paths and loops (`other`
  // pairs ends), so chains run on different threads at once.
  auto chain_from = [&](int64_t s) -> std::optional<MarkPolyline> {
    // Walk back from end 0 of s to the start of its chain, or around a loop.
    int64_t seg = s;
    int end = 0;
    bool closed = false;
    for (;;) {
      const int64_t o = other[2 * seg + end];
      if (o < 0) break;
      const int64_t oseg = o / 2;
      if (oseg == s) {
        closed = true;
        break;
      }
      seg = oseg;
      end = 1 - static_cast<int>(o % 2);
    }
    if (closed) {
      seg = s;
      end = 0;
    }
    if (grow_from < n) {
      // A chain that may still grow is only marked: its polyline would be
      // built again, whole, once complete.
      bool grows = false;
      for (int64_t g = seg, ge = end;;) {
        grows = grows || g >= grow_from;
        const int64_t o = other[2 * g + (1 - ge)];
        if (o < 0 || o / 2 == seg || used[o / 2]) break;
        g = o / 2;
        ge = o % 2;
      }
      if (grows) {
        for (;;) {
          used[seg] = 1;
          if (grows_out != nullptr) (*grows_out)[seg] = 1;
          const int64_t o = other[2 * seg + (1 - end)];
          if (o < 0 || used[o / 2]) break;
          seg = o / 2;
          end = static_cast<int>(o % 2);
        }
        return std::nullopt;
      }
    }
    // Walk forward from (seg, end).
    MarkPolyline p;
    p.closed = closed;
    push_vertex(&p, segs[seg].e[end]);
    for (;;) {
      used[seg] = 1;
      const End& far = segs[seg].e[1 - end];
      push_vertex(&p, far);
      const int64_t o = other[2 * seg + (1 - end)];
      if (o < 0 || used[o / 2]) break;
      seg = o / 2;
      end = static_cast<int>(o % 2);
    }
    if (closed && p.vertices.size() > 1) {
      const Vec3& a = p.vertices.front();
      const Vec3& b = p.vertices.back();
      if (std::hypot(a.x - b.x, a.y - b.y) <= tol) {
        p.vertices.pop_back();
        p.angle_deg.pop_back();
        p.vertex_owners.pop_back();
      }
    }
    RemoveFolds(&p, fold, end_fold);
    if (p.vertices.size() < (closed ? 3u : 2u)) return std::nullopt;
    p.owners = p.vertex_owners.front();
    return p;
  };
  // The open chains on every thread (on many cores the serial walk was
  // the marks' longest step): each is walked from both its open ends, the
  // end of lower index keeps it, with its lowest segment.
  std::vector<int64_t> open_ends;
  constexpr int64_t kScanChunk = int64_t{1} << 16;
  const int64_t scan_chunks = (2 * n + kScanChunk - 1) / kScanChunk;
  {
    std::vector<std::vector<int64_t>> found(scan_chunks);
    // Each chunk's list is filled as a local and moved in, as below: the
    // lists' own vector objects share cache lines, and a thread's
    // push_backs into one (each storing its end) would keep them moving
    // between the cores filling its neighbours.
    pool.ParallelFor(scan_chunks, [&](int64_t c) {
      std::vector<int64_t> f;
      for (int64_t k = c * kScanChunk;
           k < std::min(2 * n, (c + 1) * kScanChunk); ++k) {
        if (other[k] < 0) f.push_back(k);
      }
      found[c] = std::move(f);
    });
    for (const std::vector<int64_t>& f : found) {
      open_ends.insert(open_ends.end(), f.begin(), f.end());
    }
  }
  std::vector<int64_t> lowest(open_ends.size(), -1);  // -1: the far end's
  pool.ParallelFor(static_cast<int64_t>(open_ends.size()), [&](int64_t i) {
    int64_t seg = open_ends[i] / 2;
    int end = static_cast<int>(open_ends[i] % 2);
    int64_t low = seg;
    for (;;) {
      const int64_t o = other[2 * seg + (1 - end)];
      if (o < 0) break;
      seg = o / 2;
      end = static_cast<int>(o % 2);
      low = std::min(low, seg);
    }
    if (open_ends[i] < 2 * seg + (1 - end)) lowest[i] = low;
  });
  std::vector<int64_t> heads;  // lowest segments of the open chains
  for (const int64_t low : lowest) {
    if (low >= 0) heads.push_back(low);
  }
  std::sort(heads.begin(), heads.end());
  std::vector<std::optional<MarkPolyline>> from_heads(heads.size());
  pool.ParallelFor(static_cast<int64_t>(heads.size()),
                   [&](int64_t i) { from_heads[i] = chain_from(heads[i]); });
  // The loops, in order, then every chain by its lowest segment. The
  // segments no open chain used are found on every thread; walking a loop
  // uses its others (checked again in order).
  std::vector<std::pair<int64_t, MarkPolyline>> loops;
  {
    std::vector<std::vector<int64_t>> unused(scan_chunks);
    pool.ParallelFor(scan_chunks, [&](int64_t c) {
      std::vector<int64_t> u;
      for (int64_t s = c * kScanChunk / 2;
           s < std::min(n, (c + 1) * kScanChunk / 2); ++s) {
        if (!used[s]) u.push_back(s);
      }
      unused[c] = std::move(u);
    });
    for (const std::vector<int64_t>& u : unused) {
      for (const int64_t s : u) {
        if (used[s]) continue;
        std::optional<MarkPolyline> p = chain_from(s);
        if (p.has_value()) loops.emplace_back(s, *std::move(p));
      }
    }
  }
  std::vector<MarkPolyline> out;
  auto take = [&](int64_t s, MarkPolyline p) {
    out.push_back(std::move(p));
    if (starts != nullptr) starts->push_back(s);
  };
  size_t l = 0;
  for (size_t i = 0; i < heads.size(); ++i) {
    for (; l < loops.size() && loops[l].first < heads[i]; ++l) {
      take(loops[l].first, std::move(loops[l].second));
    }
    if (from_heads[i].has_value()) take(heads[i], *std::move(from_heads[i]));
  }
  for (; l < loops.size(); ++l)
    take(loops[l].first, std::move(loops[l].second));
  // The ghosts the open segments keep: at each vertex key a growing chain
  // uses, the segments handed on (ghosts before, and the complete chains'
  // ends now) that end there; a bucket of keys at a time.
  if (next_ghosts != nullptr) {
    std::vector<std::vector<std::pair<uint64_t, int32_t>>> kept(bounds.size() -
                                                                1);
    pool.ParallelFor(static_cast<int64_t>(bounds.size()) - 1, [&](int64_t b) {
      std::vector<std::pair<uint64_t, int32_t>> bucket;  // see `found`
      const size_t end = bounds[b + 1];
      for (size_t i = bounds[b]; i < end;) {
        size_t j = i;
        int32_t growing = 0;
        for (; j < end && inc[j].key == inc[i].key; ++j) {
          growing += (*grows_out)[inc[j].seg];
        }
        if (growing > 0) {
          int32_t count = static_cast<int32_t>(j - i) - growing;
          if (ghosts != nullptr) {
            const auto g = ghosts->find(inc[i].key);
            if (g != ghosts->end()) count += g->second;
          }
          if (count > 0) bucket.emplace_back(inc[i].key, count);
        }
        i = j;
      }
      kept[b] = std::move(bucket);
    });
    next_ghosts->clear();
    for (const auto& bucket : kept) {
      for (const auto& [key, count] : bucket) next_ghosts->emplace(key, count);
    }
  }
  return out;
}

absl::Status ValidateOptions(const Workpiece& wp, const MarkOptions& o,
                             Rect* region) {
  if (!(o.t2_deg > 0 && o.t2_deg < 90)) {
    return absl::InvalidArgumentError(
        absl::StrCat("t2_deg must be in (0, 90), got ", o.t2_deg));
  }
  if (!(std::isfinite(o.t1) && o.t1 > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("t1 must be positive and finite, got ", o.t1));
  }
  if (o.window_segment_bytes < 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "window_segment_bytes must be >= 1, got ", o.window_segment_bytes));
  }
  if (o.screening_threshold.has_value() &&
      !(std::isfinite(*o.screening_threshold) && *o.screening_threshold >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("screening_threshold must be finite and >= 0, got ",
                     *o.screening_threshold));
  }
  const Rect b = wp.grid().bounds();
  *region = b;
  if (o.region.has_value()) {
    const Rect& r = *o.region;
    const struct {
      const char* name;
      double v;
    } f[] = {{"x0", r.x0}, {"y0", r.y0}, {"x1", r.x1}, {"y1", r.y1}};
    for (const auto& v : f) {
      if (!std::isfinite(v.v)) {
        return absl::InvalidArgumentError(
            absl::StrCat("region.", v.name, " must be finite, got ", v.v));
      }
    }
    if (r.x1 < r.x0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "region.x1 (", r.x1, ") must be >= region.x0 (", r.x0, ")"));
    }
    if (r.y1 < r.y0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "region.y1 (", r.y1, ") must be >= region.y0 (", r.y0, ")"));
    }
    if (!r.Intersects(b)) {
      return absl::InvalidArgumentError(
          absl::StrCat("region [", r.x0, ", ", r.x1, "] x [", r.y0, ", ", r.y1,
                       "] does not overlap the stock [", b.x0, ", ", b.x1,
                       "] x [", b.y0, ", ", b.y1, "]"));
    }
    *region = {std::fmax(r.x0, b.x0), std::fmax(r.y0, b.y0),
               std::fmin(r.x1, b.x1), std::fmin(r.y1, b.y1)};
  }
  return absl::OkStatus();
}

}  // namespace

double ScreeningMismatch(const SurfaceJet& ni, double xi, double yi,
                         const SurfaceJet& nj, double xj, double yj) {
  return std::fabs(ni.w - EvaluatePatch(nj, xj, yj, xi, yi)) +
         std::fabs(EvaluatePatch(ni, xi, yi, xj, yj) - nj.w);
}

double DefaultScreeningThreshold(double h, double t2_rad) {
  return 0.25 * t2_rad * h;
}

double SlopeDifference(double ax, double ay, double bx, double by) {
  return std::fabs(ax - bx) + std::fabs(ay - by);
}

double NormalAngle(double ax, double ay, double bx, double by) {
  // Upward normals (-g, 1); atan2 of |cross| and dot stays accurate for
  // small angles, where acos of the dot would not.
  const double cx = by - ay;  // (-ax,-ay,1) x (-bx,-by,1)
  const double cy = ax - bx;
  const double cz = ax * by - ay * bx;
  const double dot = ax * bx + ay * by + 1;
  return std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), dot);
}

namespace {

// Height and gradient of surface `id` (a move, or kStockTopOwner) at (x, y)
// from the exact sweeps; false where the sweep does not reach.
bool ExactSurface(const Workpiece& wp, int32_t id, double x, double y,
                  SurfaceJet* j) {
  if (id == kStockTopOwner) {
    *j = SurfaceJet{wp.spec().z_top, 0, 0, 0, 0, 0};
    return true;
  }
  if (id < 0 || id >= wp.move_count()) return false;
  *j = wp.surfaces().Jet(id, x, y);
  return j->w < kInf;
}

// The move lowest at (x, y) where one is below `cap` (else kStockTopOwner,
// *w = cap), over the moves indexed at that point. `near`, if given, holds
// the point's bin's moves for a box about it and a cap no lower
// (MoveSweeps::LowestNear: the same answer).
int32_t LowestMove(const Workpiece& wp, double x, double y, double cap,
                   double* w, const NearMoves* near = nullptr) {
  *w = cap;
  if (!wp.grid().bounds().Contains(x, y)) return kStockTopOwner;
  int32_t id = -1;
  *w = near != nullptr
           ? wp.sweeps().LowestNear(*near, x, y, cap, &id)
           : wp.surfaces().LowestAt(wp.grid().ElementX(x),
                                    wp.grid().ElementY(y), x, y, cap, &id);
  return id >= 0 ? id : kStockTopOwner;
}

// Newton on (S_a - S_b, S_a - S_c) = 0: where three surfaces meet.
bool TriplePoint(const Workpiece& wp, int32_t a_id, int32_t b_id, int32_t c_id,
                 double max_step, double t1, double* x, double* y,
                 SurfaceJet* a, SurfaceJet* b) {
  SurfaceJet c;
  const double x0 = *x, y0 = *y;
  for (int it = 0; it < 16; ++it) {
    if (!ExactSurface(wp, a_id, *x, *y, a) ||
        !ExactSurface(wp, b_id, *x, *y, b) ||
        !ExactSurface(wp, c_id, *x, *y, &c)) {
      return false;
    }
    const double f0 = a->w - b->w, f1 = a->w - c.w;
    if (std::fabs(f0) <= t1 && std::fabs(f1) <= t1) return true;
    const double j00 = a->wx - b->wx, j01 = a->wy - b->wy;
    const double j10 = a->wx - c.wx, j11 = a->wy - c.wy;
    const double det = j00 * j11 - j01 * j10;
    if (!(std::fabs(det) > 0)) return false;
    double sx = -(j11 * f0 - j01 * f1) / det;
    double sy = -(-j10 * f0 + j00 * f1) / det;
    const double len = std::hypot(sx, sy);
    if (len > max_step) {
      sx *= max_step / len;
      sy *= max_step / len;
    }
    *x += sx;
    *y += sy;
    if (std::hypot(*x - x0, *y - y0) > 2 * max_step) return false;
  }
  return false;
}

}  // namespace

namespace {

// A vertex's Newton steps onto the crease (ProjectOntoExactCrease): where
// they converge, the point and both surfaces' jets there.
struct CreasePoint {
  double x = 0, y = 0;
  SurfaceJet a, b;
};

// Newton on d = S_a - S_b along its gradient (the nearest point of the
// crease, to first order) from v; each step at most max_step, so a vertex
// never jumps to another crease of the same two surfaces. False where it
// fails (the vertex stays where the patches put it).
bool NewtonOntoCrease(const Workpiece& wp, const std::array<int32_t, 2>& owners,
                      double max_step, double t1, const Vec3& v,
                      CreasePoint* out) {
  double x = v.x, y = v.y;
  SurfaceJet a, b;
  for (int it = 0; it < 16; ++it) {
    if (!ExactSurface(wp, owners[0], x, y, &a) ||
        !ExactSurface(wp, owners[1], x, y, &b)) {
      return false;
    }
    const double d = a.w - b.w;
    if (std::fabs(d) <= t1) {
      *out = {x, y, a, b};
      return true;
    }
    const double gx = a.wx - b.wx, gy = a.wy - b.wy;
    const double g2 = gx * gx + gy * gy;
    if (!(g2 > 0)) return false;
    double sx = -d * gx / g2, sy = -d * gy / g2;
    const double len = std::hypot(sx, sy);
    if (len > max_step) {
      sx *= max_step / len;
      sy *= max_step / len;
    }
    x += sx;
    y += sy;
    if (std::hypot(x - v.x, y - v.y) > 2 * max_step) return false;  // diverged
  }
  return false;  // not converged
}

// The cap of the junction test at a crease point: a third surface below it
// makes the point a junction.
double JunctionCap(const CreasePoint& p, double t1) {
  return std::min(p.a.w, p.b.w) - t1;
}

// Puts the vertex on crease point p, given the move lowest there below
// JunctionCap (c, at height w: LowestMove's): where a third surface lies
// below the crease, at the junction (where the three meet), else left
// unchanged where that fails.
void SettleOnCrease(const Workpiece& wp, const std::array<int32_t, 2>& owners,
                    double max_step, double t1, CreasePoint p, int32_t c,
                    double w, Vec3* v, double* angle_deg) {
  if (w < JunctionCap(p, t1) && c != owners[0] && c != owners[1] &&
      !TriplePoint(wp, owners[0], owners[1], c, max_step, t1, &p.x, &p.y, &p.a,
                   &p.b)) {
    return;
  }
  v->x = p.x;
  v->y = p.y;
  v->z = std::min(p.a.w, wp.spec().z_top);
  *angle_deg =
      NormalAngle(p.a.wx, p.a.wy, p.b.wx, p.b.wy) * 180 / std::numbers::pi;
}

}  // namespace

void ProjectOntoExactCrease(const Workpiece& wp,
                            const std::array<int32_t, 2>& owners,
                            double max_step, double t1, Vec3* v,
                            double* angle_deg) {
  CreasePoint p;
  if (!NewtonOntoCrease(wp, owners, max_step, t1, *v, &p)) return;
  double w;
  const int32_t c = LowestMove(wp, p.x, p.y, JunctionCap(p, t1), &w);
  SettleOnCrease(wp, owners, max_step, t1, p, c, w, v, angle_deg);
}

void ProjectOntoExactCreases(const Workpiece& wp, MarkPolyline* poly,
                             uint32_t first, uint32_t end, double max_step,
                             double t1) {
  constexpr uint32_t kMost = 8;
  CreasePoint points[kMost];
  int32_t bins[kMost];
  const GridGeometry& grid = wp.grid();
  const MoveIndex& index = wp.index();
  for (uint32_t k0 = first; k0 < end; k0 += kMost) {
    const uint32_t n = std::min(kMost, end - k0);
    // Each vertex's Newton steps, and the bin of the point they reach
    // (-1: the steps failed; -2: off the grid, where LowestMove answers).
    int32_t bin = -1, in_bin = 0;
    Rect box;
    double cap = 0;
    for (uint32_t q = 0; q < n; ++q) {
      const uint32_t k = k0 + q;
      bins[q] = -1;
      if (!NewtonOntoCrease(wp, poly->vertex_owners[k], max_step, t1,
                            poly->vertices[k], &points[q])) {
        continue;
      }
      const CreasePoint& p = points[q];
      if (!grid.bounds().Contains(p.x, p.y)) {
        bins[q] = -2;
        continue;
      }
      bins[q] = index.BinOfElement(grid.ElementX(p.x), grid.ElementY(p.y));
      // The first bin's points share one junction test (mostly all: runs
      // of a crease's vertices in one bin; the Newton steps move them by
      // up to two elements).
      if (bin < 0) bin = bins[q];
      if (bins[q] != bin) continue;
      const double c = JunctionCap(p, t1);
      if (in_bin++ == 0) {
        box = Rect{p.x, p.y, p.x, p.y};
        cap = c;
      } else {
        box.x0 = std::min(box.x0, p.x);
        box.x1 = std::max(box.x1, p.x);
        box.y0 = std::min(box.y0, p.y);
        box.y1 = std::max(box.y1, p.y);
        cap = std::max(cap, c);
      }
    }
    // A vertex's own test costs as much as the box's: taken together
    // for two or more.
    thread_local NearMoves near;
    const bool shared = in_bin >= 2;
    if (shared) wp.sweeps().MovesNear(bin, box, cap, &near);
    for (uint32_t q = 0; q < n; ++q) {
      if (bins[q] == -1) continue;
      const uint32_t k = k0 + q;
      const CreasePoint& p = points[q];
      double w;
      const int32_t c = LowestMove(wp, p.x, p.y, JunctionCap(p, t1), &w,
                                   shared && bins[q] == bin ? &near : nullptr);
      SettleOnCrease(wp, poly->vertex_owners[k], max_step, t1, p, c, w,
                     &poly->vertices[k], &poly->angle_deg[k]);
    }
  }
}

absl::Status FindCuttingMarks(
    const Workpiece& wp, const MarkOptions& options,
    absl::FunctionRef<absl::Status(MarkPolyline)> emit,
    absl::FunctionRef<absl::Status()> poll) {
  if (!wp.scheme().stores_derivatives()) {
    return absl::FailedPreconditionError(absl::StrCat(
        "cutting marks need the node derivatives of the taylor scheme; this "
        "workpiece uses the ",
        std::string(wp.scheme().name()), " scheme"));
  }
  Rect region;
  if (absl::Status st = ValidateOptions(wp, options, &region); !st.ok()) {
    return st;
  }
  const GridGeometry& grid = wp.grid();
  Settings s;
  s.z_top = wp.spec().z_top;
  s.t2 = options.t2_deg * std::numbers::pi / 180;
  s.t1 = options.t1;
  s.threshold_h = options.screening_threshold.value_or(
      DefaultScreeningThreshold(grid.dx(), s.t2));
  s.threshold_v = options.screening_threshold.value_or(
      DefaultScreeningThreshold(grid.dy(), s.t2));

  const int32_t ei0 = grid.ElementX(region.x0), ei1 = grid.ElementX(region.x1);
  const int32_t ej0 = grid.ElementY(region.y0), ej1 = grid.ElementY(region.y1);
  const int32_t cols = ei1 - ei0 + 1;  // elements per row in the region
  // A band's rows: 16, fewer on many threads, so that the bands the threads
  // search at once (one each) lie in two tile rows. Sixteen threads' bands
  // of 16 rows spanned five, and evicted each tile's jets from a cache of
  // two before its next node row was read (the 300 mm plate's were computed
  // about seven times each); a cache of five is 73 MB more on the full
  // plate. The segments come out in the same order (rows, then elements
  // along each), whatever the bands.
  constexpr int32_t kWideBandRows = 16;
  const int32_t threads = wp.pool().size();
  const int32_t band_rows = static_cast<int32_t>(std::clamp(
      std::bit_floor(static_cast<uint32_t>(kTileSize / std::max(threads, 1))),
      4u, static_cast<uint32_t>(kWideBandRows)));
  const int32_t bands = (ej1 - ej0 + band_rows) / band_rows;

  // Bands are claimed in order, several to a tile row (and one more reads
  // its first node row): the nodes' jets in a cache of this traversal's
  // own, of the tile rows the threads' bands span at once (the
  // workpiece's, shared with other readers such as the valuation, holds
  // less than a row of a wide grid: each tile was computed up to once per
  // node row).
  const std::unique_ptr<Workpiece::JetCache> jets =
      wp.TraversalJetCache(threads * band_rows + 1);
  auto find_band = [&](int64_t band, std::vector<Segment>* out) {
    const int32_t r0 = ej0 + static_cast<int32_t>(band) * band_rows;
    const int32_t r1 = std::min(r0 + band_rows, ej1 + 1);  // rows [r0, r1)
    // Node rows r0..r1, columns ei0..ei1+1, a tile's columns at a time (a
    // row crosses every tile of the band).
    const int32_t nc = cols + 1;
    // Tile columns of the band whose tiles were never cut: their nodes are
    // the stock top (owner -1), so no edge between two of them is flagged
    // (owners differ on every crease edge). A band of untouched stock has
    // no segment at all.
    const int32_t tx0 = ei0 / kTileSize, tx1 = (ei0 + nc - 1) / kTileSize;
    std::vector<uint8_t> untouched(tx1 - tx0 + 1, 1);
    bool any_cut = false;
    for (int32_t tx = tx0; tx <= tx1; ++tx) {
      for (int32_t ty = r0 / kTileSize; ty <= r1 / kTileSize; ++ty) {
        if (wp.TileAllocated(ty * wp.tiles_x() + tx)) {
          untouched[tx - tx0] = 0;
          any_cut = true;
          break;
        }
      }
    }
    if (!any_cut) return;
    auto column_untouched = [&](int32_t i) {
      return untouched[i / kTileSize - tx0] != 0;
    };
    // Two node rows at a time (j and j + 1), not the band's 17: across a
    // wide grid a row is 72 bytes a node (1.4 MB at 20,000 elements), and
    // each thread searches a band. The elements are visited in the same
    // order, so the segments come out the same.
    std::vector<NodeRef> row_nodes(2 * static_cast<size_t>(nc));
    NodeRef* lo = row_nodes.data();       // node row j
    NodeRef* hi = row_nodes.data() + nc;  // node row j + 1
    auto fill_row = [&](int32_t j, NodeRef* row) {
      for (int32_t c0 = 0; c0 < nc;) {
        const int32_t c1 =
            std::min(nc, ((ei0 + c0) / kTileSize + 1) * kTileSize - ei0);
        // Untouched and beside untouched ones: no edge reads these nodes;
        // beside a cut tile, the edges across the border need their real
        // values.
        const int32_t tx = (ei0 + c0) / kTileSize - tx0;
        if (untouched[tx] && (tx == 0 || untouched[tx - 1]) &&
            (tx + tx0 == tx1 || untouched[tx + 1])) {
          c0 = c1;
          continue;
        }
        for (int32_t i = c0; i < c1; ++i) {
          const NodeValue v = wp.Node(ei0 + i, j, jets.get());
          NodeRef& n = row[i];
          n.jet = v.jet;
          n.owner = v.owner;
          n.x = grid.NodeX(ei0 + i);
          n.y = grid.NodeY(j);
        }
        c0 = c1;
      }
    };
    // Eq. (3) on the edges between nodes of different owners.
    auto flagged = [&](const NodeRef& a, const NodeRef& b, double threshold) {
      return a.owner != b.owner &&
             ScreeningMismatch(a.jet, a.x, a.y, b.jet, b.x, b.y) > threshold;
    };
    // The edges along a node row (element column i - ei0), and those up
    // from row j to j + 1 (node column i - ei0).
    std::vector<uint8_t> flags_h(2 * static_cast<size_t>(cols));
    std::vector<uint8_t> flag_v(nc);
    uint8_t* h_lo = flags_h.data();
    uint8_t* h_hi = flags_h.data() + cols;
    auto flag_row = [&](const NodeRef* row, uint8_t* f) {
      for (int32_t i = ei0; i <= ei1; ++i) {
        f[i - ei0] = !(column_untouched(i) && column_untouched(i + 1)) &&
                     flagged(row[i - ei0], row[i - ei0 + 1], s.threshold_h);
      }
    };
    fill_row(r0, lo);
    flag_row(lo, h_lo);
    // The crossings of each element's top edge in the last row (where
    // top_known) and, in a row, of the last processed element's right edge
    // (the left edge of element right_of).
    std::vector<EdgeCrossed> top_edges(cols);
    std::vector<uint8_t> top_known(cols, 0);
    EdgeCrossed right_edge;
    for (int32_t j = r0; j < r1; ++j) {
      int32_t right_of = -1;
      fill_row(j + 1, hi);
      flag_row(hi, h_hi);
      for (int32_t i = ei0; i <= ei1 + 1; ++i) {
        flag_v[i - ei0] = !column_untouched(i) &&
                          flagged(lo[i - ei0], hi[i - ei0], s.threshold_v);
      }
      for (int32_t i = ei0; i <= ei1; ++i) {
        const int32_t k = i - ei0;
        if (!h_lo[k] && !h_hi[k] && !flag_v[k] && !flag_v[k + 1]) {
          top_known[k] = 0;
          continue;
        }
        const NodeRef* const c[4] = {&lo[k], &lo[k + 1], &hi[k + 1], &hi[k]};
        // The bottom edge is the top edge of the element below, the left
        // edge the right edge of the one before, where those were
        // processed: each edge's crossings found once, not twice.
        // ProcessElement reads the known edges before it writes its own.
        ProcessElement(c, i, j, grid.nodes_x(), grid, s,
                       top_known[k] ? &top_edges[k] : nullptr,
                       right_of == i ? &right_edge : nullptr, &top_edges[k],
                       &right_edge, out);
        top_known[k] = 1;
        right_of = i + 1;
      }
      std::swap(lo, hi);
      std::swap(h_lo, h_hi);
    }
  };

  // Vertices closer than this are one (crossings clamped onto a node).
  const double tol = 1e-9 * std::fmax(grid.dx(), grid.dy());
  // Folds shorter than a tenth of an element are the patches' disagreement,
  // not the crease's shape; next to a junction, up to the half element by
  // which a junction may leave its element.
  const double h = std::fmin(grid.dx(), grid.dy());
  // Vertices [first, end) of a polyline chained: lifted and projected as
  // its scheme's marks are. Vertices are independent, so a window's
  // polylines are finished a run of vertices at a time: a few long creases
  // (a plate's passes, thousands of vertices each) kept as many threads
  // busy as there were polylines.
  auto finish_run = [&](MarkPolyline& p, uint32_t first, uint32_t end) {
    if (wp.scheme().kind() == SchemeKind::kGuarded) {
      // A crease lies on both owners' surfaces: never below either's lowest
      // point (patches met far from their nodes can cross lower): the
      // owner's lowest tip, ReachOf(...).z_low, without building its reach.
      for (uint32_t k = first; k < end; ++k) {
        for (int32_t id : p.vertex_owners[k]) {
          if (id < 0 || id >= wp.move_count()) continue;
          const Move m = wp.move(id);
          p.vertices[k].z =
              std::max(p.vertices[k].z, std::min(m.from.z, m.to.z));
        }
      }
    }
    // Sessions whose reconstruction uses the exact surfaces have their
    // marks on the exact creases too.
    if (wp.scheme().kind() == SchemeKind::kExact ||
        wp.scheme().kind() == SchemeKind::kGuarded) {
      ProjectOntoExactCreases(wp, &p, first, end, h, s.t1);
    }
  };
  // A chained polyline waiting to be handed on, finished or not yet.
  struct Ready {
    MarkPolyline p;
    bool finished = false;
  };
  const bool finishes = wp.scheme().kind() == SchemeKind::kExact ||
                        wp.scheme().kind() == SchemeKind::kGuarded;
  // Finishes the polylines and marks them so.
  auto finish_all = [&](const std::vector<Ready*>& chained) {
    if (!finishes) return;
    // The vertices a move bin at a time: the junction test (LowestAt)
    // keeps the moves of a thread's last few bins, and taken along each
    // polyline, a bin was filled again for every crease that crossed it.
    // Runs of up to kRun vertices of one polyline in one bin, sorted by
    // bin; an item is a bin's runs, up to kItem vertices.
    constexpr uint32_t kRun = 64;
    constexpr uint32_t kItem = 1024;
    struct Run {
      int32_t bin;
      uint32_t polyline, first, end;
    };
    const GridGeometry& grid = wp.grid();
    auto bin_of = [&](const Vec3& v) {
      // A vertex that is not finite (none is expected) takes bin -1: the
      // element lookup converts to int.
      if (!std::isfinite(v.x) || !std::isfinite(v.y)) return -1;
      return wp.index().BinOfElement(grid.ElementX(v.x), grid.ElementY(v.y));
    };
    std::vector<Run> runs;
    for (size_t q = 0; q < chained.size(); ++q) {
      const std::vector<Vec3>& v = chained[q]->p.vertices;
      const uint32_t n = static_cast<uint32_t>(v.size());
      for (uint32_t k = 0, k1; k < n; k = k1) {
        const int32_t bin = bin_of(v[k]);
        k1 = k + 1;
        while (k1 < n && k1 - k < kRun && bin_of(v[k1]) == bin) ++k1;
        runs.push_back(Run{bin, static_cast<uint32_t>(q), k, k1});
      }
    }
    std::sort(runs.begin(), runs.end(), [](const Run& a, const Run& b) {
      return std::tie(a.bin, a.polyline, a.first) <
             std::tie(b.bin, b.polyline, b.first);
    });
    std::vector<size_t> items;  // each item's first run, then runs.size()
    for (size_t r = 0, size = 0; r < runs.size(); ++r) {
      if (r == 0 || runs[r].bin != runs[r - 1].bin || size >= kItem) {
        items.push_back(r);
        size = 0;
      }
      size += runs[r].end - runs[r].first;
    }
    items.push_back(runs.size());
    wp.pool().ParallelFor(
        static_cast<int64_t>(items.size()) - 1, [&](int64_t i) {
          for (size_t r = items[i]; r < items[i + 1]; ++r) {
            MarkPolyline& p = chained[runs[r].polyline]->p;
            finish_run(p, runs[r].first, runs[r].end);
          }
        });
    for (Ready* r : chained) r->finished = true;
  };

  // The bands a window at a time, so that the segments of the whole grid
  // are never held: after each window, the chains that no segment of it
  // touches are complete (a later band's segments end on its own elements'
  // edges and junctions only) and are chained, in the order of their first
  // segment as if every segment had been chained at once (Chain numbers
  // the segments in band order; a chain's polyline and its place depend
  // only on its own segments and their order), and handed on once no open
  // chain can still come before them.
  //
  // A window is four bands a thread (their costs vary), fewer where the
  // marks are dense: its segments are held at once (in each band's vector,
  // then in `open`), so after each window the next takes as many bands as
  // fit options.window_segment_bytes at the last one's segments a band, one
  // band a thread at least. Four bands, not four of 16 rows: on 16 threads
  // (bands of 4 rows) windows of 1024 rows held the segments of 4x the
  // rows of 2 threads' windows, this one's and the next's, and raised the
  // 300 mm plate's peak on 16 threads by 266 MiB (1,162 against 896). The
  // marks do not depend on the windows.
  const int32_t most_bands = std::max(8, 4 * threads);
  int32_t window = most_bands;
  std::vector<std::vector<Segment>> band_segments;
  // Kept segments not chained yet, in order, and their index among every
  // kept segment: a window's are appended unfilled, then copied in on
  // every thread (zeroed first, on one thread, they were a serial step).
  UnfilledVector<Segment> open;
  UnfilledVector<int64_t> open_at;
  uint64_t raw_before = 0;       // segments found in earlier windows
  int64_t kept_before = 0;       // kept (clipped) in earlier windows
  // Polylines chained, by first segment, waiting for earlier open chains
  // or to be finished.
  std::map<int64_t, Ready> ready;
  // The last window's polylines in `ready`, not finished yet: they are
  // finished while the next window is chained (chaining alone left the
  // threads of a many-core machine idle between windows' projections),
  // and so handed on a window later. Polylines with nothing to finish (the
  // taylor scheme's) are handed on at once.
  std::vector<Ready*> unfinished;
  // Chain's arrays, and which open segments' chains may still grow: kept
  // from window to window (ChainScratch).
  ChainScratch chain_scratch;
  UnfilledVector<uint8_t> growing;
  // Polylines ready to hand on (in order), handed on during the next
  // window's work.
  std::vector<MarkPolyline> handing;
  // Segments handed on, per vertex key an open segment uses (Chain).
  absl::flat_hash_map<uint64_t, int32_t> ghosts;
  // The next window's bands are searched while this one's are chained and
  // the last one's polylines finished: neither keeps every thread busy (a
  // few long chains, a plate's creases along y spanning every band).
  std::vector<std::vector<Segment>> next_segments;
  auto find_window = [&](int32_t w0, int32_t wn,
                         std::vector<std::vector<Segment>>* out) {
    out->assign(wn, {});
    // Each band's segments as a local, moved in: the bands' vector objects
    // share cache lines, and each segment's push_back stores its band's end.
    wp.pool().ParallelFor(wn, [&](int64_t b) {
      std::vector<Segment> found;
      find_band(w0 + b, &found);
      (*out)[b] = std::move(found);
    });
  };
  find_window(0, std::min(window, bands), &band_segments);
  for (int32_t w0 = 0, wn = std::min(window, bands); w0 < bands;) {
    {
      int64_t found = 0;
      for (const std::vector<Segment>& band : band_segments) {
        found += static_cast<int64_t>(band.size());
      }
      const int64_t band_bytes =
          std::max<int64_t>(1, found * int64_t{sizeof(Segment)} / wn);
      window = static_cast<int32_t>(std::clamp<int64_t>(
          options.window_segment_bytes / band_bytes, threads, most_bands));
    }
    // Keep what lies in the region (junctions may sit a little outside
    // their element, hence outside the stock), each segment clipped with
    // its index among every band's segments.
    std::vector<uint64_t> first(wn + 1, raw_before);
    for (int32_t b = 0; b < wn; ++b) {
      first[b + 1] = first[b] + band_segments[b].size();
    }
    raw_before = first[wn];
    wp.pool().ParallelFor(wn, [&](int64_t b) {
      std::vector<Segment>& band = band_segments[b];
      size_t n = 0;
      for (size_t i = 0; i < band.size(); ++i) {
        Segment seg = band[i];
        if (ClipSegment(region, first[b] + i, &seg)) band[n++] = seg;
      }
      band.resize(n);
    });
    const size_t window_first = open.size();
    {
      std::vector<size_t> at(wn + 1, window_first);
      for (int32_t b = 0; b < wn; ++b) {
        at[b + 1] = at[b] + band_segments[b].size();
      }
      open.resize(at[wn]);
      open_at.resize(at[wn]);
      wp.pool().ParallelFor(wn, [&](int64_t b) {
        std::vector<Segment>& band = band_segments[b];
        std::copy(band.begin(), band.end(), open.begin() + at[b]);
        const int64_t first_kept =
            kept_before + static_cast<int64_t>(at[b] - window_first);
        for (size_t i = 0; i < band.size(); ++i) {
          open_at[at[b] + i] = first_kept + static_cast<int64_t>(i);
        }
        std::vector<Segment>().swap(band);
      });
      kept_before += static_cast<int64_t>(at[wn] - window_first);
    }
    const int32_t next_w0 = w0 + wn;
    const int32_t next_wn = std::min(window, bands - next_w0);
    // Chain what is open. A chain with a segment of this window may still
    // grow (not after the last): its segments stay open. Every other chain
    // is complete, every segment at its vertices known (a later window's
    // segments end on its own elements' edges and junctions only), so its
    // polyline is the one chaining every segment at once gives. The last
    // window's polylines are finished meanwhile: they are only read and
    // written through their own entries of `ready` (a std::map: inserting
    // others moves no entry).
    const bool last = next_w0 >= bands;
    std::vector<Ready*> finishing;
    finishing.swap(unfinished);
    auto window_work = [&](int64_t part) {
      if (part == 2) {
        if (!last) find_window(next_w0, next_wn, &next_segments);
        return;
      }
      if (part == 1) {
        finish_all(finishing);
        return;
      }
      std::vector<int64_t> starts;
      absl::flat_hash_map<uint64_t, int32_t> kept_ghosts;
      std::vector<MarkPolyline> chained =
          Chain(open, tol, 0.1 * h, kJunctionMargin * h, wp.pool(),
                &chain_scratch, &starts, &ghosts,
                last ? INT64_MAX : static_cast<int64_t>(window_first), &growing,
                &kept_ghosts);
      // Chain gave polylines for the complete chains only.
      for (size_t k = 0; k < chained.size(); ++k) {
        const auto it = ready.emplace(open_at[starts[k]],
                                      Ready{std::move(chained[k]), !finishes});
        if (finishes) unfinished.push_back(&it.first->second);
      }
      // The complete chains' segments leave; where one ends at a vertex an
      // open segment still uses, it stays counted there (a junction of
      // three chains must not join the other two once the first is handed
      // on): Chain counted them in kept_ghosts.
      size_t n = 0;
      for (size_t k = 0; k < open.size(); ++k) {
        if (!growing[k]) continue;
        open[n] = open[k];
        open_at[n++] = open_at[k];
      }
      open.resize(n);
      open_at.resize(n);
      ghosts.swap(kept_ghosts);
    };
    // The last window's polylines are handed on meanwhile, on a thread of
    // their own (emit may block while its reader catches up): handed on
    // between windows, they left every thread of a many-core machine idle
    // for about a third of the marks' time. The window's work stays on
    // this thread: run on a new thread each window, its allocations went
    // to another malloc arena, given back to the system and faulted in
    // again every window.
    if (handing.empty()) {
      wp.pool().ParallelFor(3, window_work);
    } else {
      absl::Status handed;
      std::thread emitter([&] {
        for (MarkPolyline& p : handing) {
          handed = emit(std::move(p));
          if (!handed.ok()) break;
        }
      });
      wp.pool().ParallelFor(3, window_work);
      emitter.join();
      handing.clear();
      if (!handed.ok()) return handed;
    }
    if (last) {
      finish_all(unfinished);
      unfinished.clear();
    }
    // Hand on what no open chain can come before (after the last window,
    // none is open).
    const int64_t before = open_at.empty() ? INT64_MAX : open_at.front();
    // Nor what is not finished yet (this window's polylines).
    while (!ready.empty() && ready.begin()->first < before &&
           ready.begin()->second.finished) {
      handing.push_back(std::move(ready.begin()->second.p));
      ready.erase(ready.begin());
    }
    if (absl::Status st = poll(); !st.ok()) return st;
    band_segments.swap(next_segments);
    w0 = next_w0;
    wn = next_wn;
  }
  for (MarkPolyline& p : handing) {
    if (absl::Status st = emit(std::move(p)); !st.ok()) return st;
  }
  return absl::OkStatus();
}

absl::Status FindCuttingMarks(const Workpiece& wp, const MarkOptions& options,
                              absl::FunctionRef<void(MarkPolyline)> emit) {
  return FindCuttingMarks(
      wp, options,
      [&](MarkPolyline p) {
        emit(std::move(p));
        return absl::OkStatus();
      },
      [] { return absl::OkStatus(); });
}

absl::StatusOr<std::vector<MarkPolyline>> FindCuttingMarks(
    const Workpiece& wp, const MarkOptions& options) {
  std::vector<MarkPolyline> marks;
  absl::Status st = FindCuttingMarks(
      wp, options, [&](MarkPolyline p) { marks.push_back(std::move(p)); });
  if (!st.ok()) return st;
  return marks;
}

double ExactCreaseDistance(const Workpiece& wp, int32_t a, int32_t b, double x,
                           double y) {
  auto surface = [&](int32_t id, double* w, double* gx, double* gy) {
    if (id == kStockTopOwner) {
      *w = wp.spec().z_top;
      *gx = *gy = 0;
      return true;
    }
    if (id < 0 || id >= wp.move_count()) return false;
    const SurfaceJet j = wp.MoveJet(id, x, y);
    if (!(j.w < kInf)) return false;
    *w = j.w;
    *gx = j.wx;
    *gy = j.wy;
    return true;
  };
  double wa, ax, ay, wb, bx, by;
  if (!surface(a, &wa, &ax, &ay) || !surface(b, &wb, &bx, &by)) return kInf;
  const double g = std::hypot(ax - bx, ay - by);
  if (!(g > 0)) return kInf;
  return std::fabs(wa - wb) / g;
}

double PolylineLength(const MarkPolyline& p) {
  double len = 0;
  const size_t n = p.vertices.size();
  for (size_t k = 0; k + 1 < n; ++k) {
    const Vec3& a = p.vertices[k];
    const Vec3& b = p.vertices[k + 1];
    len += std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) +
                     (a.z - b.z) * (a.z - b.z));
  }
  if (p.closed && n > 2) {
    const Vec3& a = p.vertices.back();
    const Vec3& b = p.vertices.front();
    len += std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) +
                     (a.z - b.z) * (a.z - b.z));
  }
  return len;
}

MarkSummarizer::MarkSummarizer() {
  s_.min_angle_deg = kInf;
  s_.max_angle_deg = -kInf;
}

void MarkSummarizer::Add(const MarkPolyline& p) {
  ++s_.polylines;
  s_.closed += p.closed;
  s_.vertices += static_cast<int64_t>(p.vertices.size());
  s_.total_length += PolylineLength(p);
  for (double a : p.angle_deg) {
    s_.min_angle_deg = std::fmin(s_.min_angle_deg, a);
    s_.max_angle_deg = std::fmax(s_.max_angle_deg, a);
  }
}

MarkSummary MarkSummarizer::summary() const {
  MarkSummary s = s_;
  if (s.vertices == 0) s.min_angle_deg = s.max_angle_deg = 0;
  return s;
}

MarkSummary Summarize(const std::vector<MarkPolyline>& marks) {
  MarkSummarizer s;
  for (const MarkPolyline& p : marks) s.Add(p);
  return s.summary();
}

MarkAccuracy MeasureMarkAccuracy(const Workpiece& wp,
                                 const std::vector<MarkPolyline>& marks) {
  MarkAccuracy acc;
  for (const MarkPolyline& p : marks) {
    for (size_t k = 0; k < p.vertices.size(); ++k) {
      const Vec3& v = p.vertices[k];
      const double d = ExactCreaseDistance(wp, p.vertex_owners[k][0],
                                           p.vertex_owners[k][1], v.x, v.y);
      ++acc.vertices;
      if (acc.vertices == 1 || !(d <= acc.max_distance)) {
        acc.max_distance = d;
        acc.max_x = v.x;
        acc.max_y = v.y;
      }
    }
  }
  return acc;
}

}  // namespace swarf
