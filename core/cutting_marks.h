// Cutting marks (paper section 3): the creases of the reconstructed surface,
// where two different swept surfaces, or a swept surface and the uncut stock
// top, meet with a jump in slope.
//
// Contract:
// - Units: millimetres; angles in degrees unless a name says otherwise.
// - Needs node derivatives (the patches of eq. 1: taylor, guarded, exact); a
//   zmap workpiece gives FailedPrecondition. For the exact scheme every
//   vertex is then moved onto the exact crease of its two owners' swept
//   surfaces (ProjectOntoExactCrease): x, y on the true crease within t1 in
//   height, z the exact height.
// - A "surface" is identified by the owner of the nodes it set: a move id, or
//   -1 for the stock top (z_top, flat). In an element the surface of owner o
//   is the minimum of the eq. (1) patches of the corners owned by o, and the
//   reconstruction is the minimum over all surfaces and the top (eq. 2).
// - Mark vertices on element edges are where the patches of the edge's two
//   nodes are equal (closed-form roots, eq. 4) and lowest, with the top:
//   eq. (2) restricted to the edge. The other two corners of an element are
//   left out on its edges: their patches are extrapolations over a whole
//   element, which undershoot at creases (five-cylinders at 100x100: up to
//   0.12 mm below the exact surface, against 0.019 mm for the edge nodes'
//   own), and without them both elements sharing an edge agree on its
//   vertices. Points where three surfaces meet inside an element (one, or
//   two joined by a short crease, paper Fig. 3) come from Newton's method on
//   all four corner patches. Straight segments join the vertices of one
//   element.
// - Different owners that meet without a crease (consecutive moves of one
//   pass, an arc made of short moves) are told apart from marks by eq. (5):
//   a vertex is a mark only where the two surfaces' normals differ by more
//   than t2_deg.
// - Limits (the paper's assumption that the mesh is dense enough): an edge
//   carries at most one crease between its two nodes' owners, or two when
//   the stock top lies between them (a surface owning neither node is not
//   seen on that edge); a surface owning no node at all (a band narrower
//   than the grid spacing) is not seen; a mark closed inside one element is
//   not found.
// - Results are deterministic: the same polylines in the same order, whatever
//   the thread count.
// - Thread safety: FindCuttingMarks only reads the workpiece and may run
//   concurrently with its other const methods, never with Apply. It uses the
//   workpiece's thread pool.
#ifndef SWARF_CORE_CUTTING_MARKS_H_
#define SWARF_CORE_CUTTING_MARKS_H_

#include <array>
#include <cstdint>
#include <optional>
#include <vector>

#include "absl/functional/function_ref.h"
#include "absl/status/statusor.h"
#include "core/geometry.h"
#include "core/surface_jet.h"
#include "core/workpiece.h"

namespace swarf {

// Owner id of the stock top in mark results.
inline constexpr int32_t kStockTopOwner = -1;

// Default t2 of eq. (5), as the angle between the two surfaces' normals. Two
// consecutive moves of a tool path turning by delta meet at a normal angle of
// at most delta, while the scallop between raster passes of stepover s with a
// ball of radius r has a normal angle of 2 asin(s / 2r). Finishing with
// r = 1..3 mm at s = 0.1..1 mm gives >= 1.91 degrees (s = 0.1, r = 3); an arc
// of radius 20 mm made of 0.5 mm chords turns by 1.43 degrees per move. 1.65
// degrees lies in between with ~15% margin on each side.
inline constexpr double kDefaultT2Deg = 1.65;

struct MarkOptions {
  // Only marks inside this rectangle (polylines are clipped to it); the
  // whole stock when absent. Must be finite, x0 <= x1, y0 <= y1, and overlap
  // the stock.
  std::optional<Rect> region;
  // Eq. (3)'s threshold r (mm) on the two patch mismatches of an edge. When
  // absent, t2 (in radians) * h / 4 per edge of length h: see
  // DefaultScreeningThreshold. Must be finite and >= 0.
  std::optional<double> screening_threshold;
  // Eq. (5)'s t2: smallest angle between the two surfaces' normals at a mark
  // point, in (0, 90) degrees.
  double t2_deg = kDefaultT2Deg;
  // Eq. (4)'s t1 (mm): Newton's method stops for a point where three
  // surfaces meet once their heights agree within t1. Edge crossings are
  // closed-form roots and agree to rounding. Must be finite and > 0.
  double t1 = 1e-9;
  // About how many bytes of crease segments the search holds at once (its
  // window of bands: see FindCuttingMarks); the marks do not depend on it.
  // Must be >= 1.
  int64_t window_segment_bytes = int64_t{64} << 20;
};

// A crease between junctions (points where three or more marks meet) or
// ends. Vertices are ordered along the crease, without duplicates; a closed
// polyline does not repeat its first vertex at the end.
struct MarkPolyline {
  bool closed = false;
  // The two surfaces meeting at the first vertex, ascending (-1: stock top).
  // Along a pass made of many moves the owners change smoothly; see
  // vertex_owners.
  std::array<int32_t, 2> owners = {kStockTopOwner, kStockTopOwner};
  // x, y and the reconstructed height z where the two surfaces' patches
  // meet (see the contract above for which patches).
  std::vector<Vec3> vertices;
  // Per vertex: the angle between the two surfaces' normals (degrees).
  std::vector<double> angle_deg;
  // Per vertex: the two owners meeting there, ascending.
  std::vector<std::array<int32_t, 2>> vertex_owners;
};

// Finds the cutting marks of the workpiece (issue 3). InvalidArgument naming
// the field for bad options; FailedPrecondition for a zmap workpiece.
absl::StatusOr<std::vector<MarkPolyline>> FindCuttingMarks(
    const Workpiece& wp, const MarkOptions& options = {});
// The same marks, in the same order, handed to `emit` as they are found:
// the grid is read a window of bands at a time and only the chains still
// open (and the polylines that wait for an earlier one) are held, not every
// crease segment of the grid. `emit` runs on one thread at a time (see
// below).
absl::Status FindCuttingMarks(const Workpiece& wp, const MarkOptions& options,
                              absl::FunctionRef<void(MarkPolyline)> emit);
// The same, and the caller may stop the search: the first non-OK status
// `emit` returns is returned once the window of bands in progress is done
// (no other polyline is handed on), and
// `poll`, called after every window of bands (a few ms to a second of work,
// whether or not it completed a polyline), stops it the same way, so that a
// caller that is cancelled does not wait for the next polyline: there may
// be none until the end (a crease along y spans every band). The polylines
// handed on before are the first ones of the whole result. `poll` runs on
// the calling thread; `emit` on one thread at a time, in order, not one of
// the workpiece's pool: a window's polylines are handed on while the next
// window is searched, from a thread of the search's own. Both may block
// (the pool is not held meanwhile).
absl::Status FindCuttingMarks(
    const Workpiece& wp, const MarkOptions& options,
    absl::FunctionRef<absl::Status(MarkPolyline)> emit,
    absl::FunctionRef<absl::Status()> poll);

// The paper's equations as used here.

// Eq. (3): |w_i(x_i) - w_j(x_i)| + |w_i(x_j) - w_j(x_j)| for the patches of
// nodes i at (xi, yi) and j at (xj, yj). Node jets with owner -1 are flat at
// their height, so this also covers the stock top.
double ScreeningMismatch(const SurfaceJet& ni, double xi, double yi,
                         const SurfaceJet& nj, double xj, double yj);

// Eq. (3)'s default threshold for an edge of length h given t2 in radians.
// Across a crease whose normals differ by at least t2, the slopes differ by
// at least t2, so the two extrapolations of eq. (3) miss by about
// t2 * (d_i + d_j), d the nodes' distances to the crease; on every element
// the crease crosses, one crossed edge has d_i + d_j >= h / sqrt(2), i.e. a
// mismatch >= 0.7 t2 h. A smooth surface's patches disagree only by their own
// truncation error, about |w'''| h^3 / 3 for the pair, plus the float storage
// of the derivatives (~1e-7 relative): t2 h / 4 keeps a factor ~3 below the
// smallest mark and is above the truncation error whenever
// h < 0.85 sqrt(t2 / |w'''|), i.e. on any grid fine enough to follow the
// surfaces. Flagged edges only select elements to examine; the eq. (5) test
// decides what is a mark, so a coarser grid costs time, not correctness.
double DefaultScreeningThreshold(double h, double t2_rad);

// Eq. (4): |w_a(x, y) - w_b(x, y)|, the height gap of two surfaces at a point.
inline double PatchGap(double wa, double wb) { return wa > wb ? wa - wb : wb - wa; }

// Eq. (5) as printed: |dwa/dx - dwb/dx| + |dwa/dy - dwb/dy|.
double SlopeDifference(double ax, double ay, double bx, double by);

// Eq. (5) as applied: the angle (radians) between the upward normals of two
// surfaces with gradients (ax, ay) and (bx, by). It never exceeds
// SlopeDifference (the gnomonic projection only stretches), does not depend
// on the crease's direction in the grid, and stays bounded on steep walls,
// where the printed form grows without bound.
double NormalAngle(double ax, double ay, double bx, double by);

// Accuracy, for tests and `swarf marks --check`.

// For the exact scheme: moves vertex *v onto the exact crease between the
// surfaces of `owners` (a move id or kStockTopOwner) by Newton steps of at
// most max_step (mm) until the two exact heights agree within t1 (mm), and
// sets its z to the exact height and *angle_deg to the exact normals'
// angle. Where a third surface lies below that crease point, the vertex is
// a junction and goes to where the three meet. Left unchanged where that
// fails (a sweep not reaching, parallel gradients, no convergence within 2
// max_step).
void ProjectOntoExactCrease(const Workpiece& wp,
                            const std::array<int32_t, 2>& owners,
                            double max_step, double t1, Vec3* v,
                            double* angle_deg);
// ProjectOntoExactCrease for vertices [first, end) of *p (their
// vertex_owners, vertices and angle_deg), bit for bit, with the junction
// tests of the vertices that reach one move bin taken together
// (MoveSweeps::MovesNear): for a run of a crease's vertices.
void ProjectOntoExactCreases(const Workpiece& wp, MarkPolyline* p,
                             uint32_t first, uint32_t end, double max_step,
                             double t1);

// Distance (mm, in XY) from (x, y) to the exact crease between the surfaces
// of moves a and b (-1: the stock top), to first order:
// |S_a - S_b| / |grad S_a - grad S_b| from the exact sweeps. +inf if a sweep
// does not reach (x, y) or the gradients agree.
double ExactCreaseDistance(const Workpiece& wp, int32_t a, int32_t b, double x,
                           double y);

struct MarkSummary {
  int64_t polylines = 0;
  int64_t closed = 0;
  int64_t vertices = 0;
  double total_length = 0;  // mm, in 3D
  double min_angle_deg = 0, max_angle_deg = 0;  // over all vertices
};
MarkSummary Summarize(const std::vector<MarkPolyline>& marks);

// Summarize one polyline at a time: after Add of each polyline in turn,
// summary() is Summarize of them all, bit for bit (the lengths are summed
// in the same order). Not thread-safe.
class MarkSummarizer {
 public:
  MarkSummarizer();
  void Add(const MarkPolyline& p);
  MarkSummary summary() const;

 private:
  MarkSummary s_;  // its angles +-inf until one is seen
};

// 3D length of a polyline, including the closing segment when closed.
double PolylineLength(const MarkPolyline& p);

struct MarkAccuracy {
  double max_distance = 0;  // mm, ExactCreaseDistance over all vertices
  double max_x = 0, max_y = 0;  // where
  int64_t vertices = 0;
};
MarkAccuracy MeasureMarkAccuracy(const Workpiece& wp,
                                 const std::vector<MarkPolyline>& marks);

}  // namespace swarf

#endif  // SWARF_CORE_CUTTING_MARKS_H_
