// Reconstruction schemes: how the surface inside an element is rebuilt from
// its four corner nodes. A scheme also decides which parameters a node keeps.
// To add a scheme: add a SchemeKind, a Scheme subclass in scheme.cc, and its
// name in ParseScheme.
#ifndef SWARF_CORE_SCHEME_H_
#define SWARF_CORE_SCHEME_H_

#include <cstdint>
#include <limits>
#include <string_view>

#include "absl/container/inlined_vector.h"
#include "absl/status/statusor.h"
#include "core/surface_jet.h"

namespace swarf {

// kZmap: eq. (16). kTaylor: the paper's eq. (1)-(2), unchanged. kGuarded (the
// default of sessions and `swarf run`): eq. (1)-(2) where the patches are
// checked to hold, the exact swept surfaces elsewhere (see GuardedHeight).
// kExact: the minimum of the exact swept surfaces of the moves that can
// reach the element (see ExactCandidatesHeight). The values are stored in
// snapshots: append only.
enum class SchemeKind { kZmap, kTaylor, kGuarded, kExact };

struct ElementCorners;

// The exact swept surfaces of a workpiece's moves, by move id: what the
// exact scheme reconstructs from. Implementations are thread-safe.
class MoveSurfaces {
 public:
  virtual ~MoveSurfaces() = default;
  // Height of move `id`'s swept surface at (x, y); +inf where the tool
  // never passes over it.
  virtual double Height(int32_t id, double x, double y) const = 0;
  // Its height and derivatives there (zeros where the height is +inf).
  virtual SurfaceJet Jet(int32_t id, double x, double y) const = 0;
  // The least of `cap` and of the heights at (x, y), a point of element
  // (ei, ej), of every move that can dip below cap there: the true surface
  // where it is below cap. *id (if not null) is the move that gives it, -1
  // for cap.
  virtual double LowestAt(int32_t ei, int32_t ej, double x, double y,
                          double cap, int32_t* id = nullptr) const = 0;
  // Fills e->candidates for element (e->ei, e->ej), from its corners and
  // their owners: every move that can be the lowest somewhere in the
  // element (see MoveSweeps::FillCandidates).
  virtual void FillCandidates(ElementCorners* e) const = 0;
};

// What a corner node's patch stands for: its owner's swept surface, which
// exists only over the owner's footprint below the top (an XY capsule: the
// segment widened by a radius) and never goes below `z_low` (the lowest
// point the owner's tool reaches). Not the moves continuing the owner's
// path: where the path turns or changes slope, the patch does not model
// their surface (measured: every corpus job errs less without them).
// Unbounded for uncut nodes (their patch is the stock top, everywhere) and
// where the owner is unknown.
struct CornerReach {
  struct Capsule {
    double ax = 0, ay = 0, bx = 0, by = 0;
    double radius = 0;
    bool Contains(double x, double y) const;  // closed
  };
  bool bounded = false;
  bool empty = false;  // bounded, and the owner never goes below the top
  Capsule capsule;
  double z_low = -std::numeric_limits<double>::infinity();

  // Whether (x, y) lies in the capsule (always, when unbounded).
  bool Contains(double x, double y) const;
};

// The four corner nodes of element [x0,x1] x [y0,y1]: c[0] at (x0,y0),
// c[1] at (x1,y0), c[2] at (x1,y1), c[3] at (x0,y1) (the paper's i, j, k, m).
struct ElementCorners {
  int32_t ei = 0, ej = 0;  // the element's indices
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  double z_top = 0;  // stock top: no reconstruction lies above it
  SurfaceJet c[4];
  int32_t owner[4] = {-1, -1, -1, -1};  // the corners' owners (-1: uncut)
  CornerReach reach[4];  // filled where the scheme uses_reach()
  // Filled where the scheme uses_candidates(): every move whose swept
  // surface can be the lowest somewhere in the element (MoveSweeps::
  // FillCandidates), ascending.
  absl::InlinedVector<int32_t, 32> candidates;
  // The surfaces of the moves (not owned; outlives the corners), where the
  // scheme uses_reach() or uses_candidates(); null where the moves are not
  // known.
  const MoveSurfaces* surfaces = nullptr;
  // What Scheme::Prepare found out about the element (kGuarded).
  struct Guard {
    bool smooth = false;  // the patches hold over the whole element
    bool inside[4] = {};  // reach[k] holds the whole element
    double lift[4][4] = {};  // [k][q]: patch k's shortfall at corner q
    // [k]: the bilinear interpolation of lift[k] over the element as
    // a * u + b * v + c * u * v, (u, v) the offset from corner k (lift[k][k]
    // is 0): {a, b, c}, added to patch k's wx, wy and wxy (LiftedJet).
    double lift_uv[4][3] = {};
  } guard;
};

// Sets e's indices, rectangle and stock top for element (ei, ej) of
// `grid` (top z_top): every holder of nodes builds its corners' frame here,
// so that reconstructions agree bit for bit.
class GridGeometry;
void SetElementFrame(const GridGeometry& grid, double z_top, int32_t ei,
                     int32_t ej, ElementCorners* e);

class Scheme {
 public:
  virtual ~Scheme() = default;
  virtual SchemeKind kind() const = 0;
  virtual std::string_view name() const = 0;
  // Parameters per node as the paper counts them (Tables 1-2).
  virtual int parameters_per_node() const = 0;
  // Whether nodes carry the sweep's derivatives (wx .. wyy), computed from
  // their owners when read.
  virtual bool stores_derivatives() const = 0;
  // Whether Reconstruct reads ElementCorners::reach (else it may be left
  // unbounded, saving the work of filling it).
  virtual bool uses_reach() const { return false; }
  // Whether Reconstruct reads ElementCorners::candidates and surfaces.
  virtual bool uses_candidates() const { return false; }
  // Bytes per allocated node, including the owning move id.
  virtual int bytes_per_node() const = 0;
  // Work done once per element, before Reconstruct and Gradient read it:
  // every holder of nodes calls it on the corners it fills.
  virtual void Prepare(ElementCorners* /*e*/) const {}
  // Height at (x, y) inside the element. Thread-safe.
  virtual double Reconstruct(const ElementCorners& e, double x,
                             double y) const = 0;
  // Gradient of the reconstruction at (x, y) (one-sided on a crease: that of
  // the piece Reconstruct picks).
  virtual void Gradient(const ElementCorners& e, double x, double y,
                        double* gx, double* gy) const = 0;
  // Reconstruct at n points of the element: out[q] = Reconstruct(e, x[q],
  // y[q]), bit for bit (schemes with work shared between points override
  // it).
  virtual void ReconstructMany(const ElementCorners& e, const double* x,
                               const double* y, int32_t n, double* out) const {
    for (int32_t q = 0; q < n; ++q) out[q] = Reconstruct(e, x[q], y[q]);
  }
  // The same where x and y hold n rounded up to a multiple of 8 entries,
  // those past n copies of the last point, and out has room for as many
  // (past n, left unspecified): a scheme that evaluates points 8 at a time
  // then reads and writes them in place instead of copying them.
  virtual void ReconstructManyPadded(const ElementCorners& e, const double* x,
                                     const double* y, int32_t n,
                                     double* out) const {
    ReconstructMany(e, x, y, n, out);
  }
  // Both at once: returns Reconstruct(e, x, y) and sets the Gradient, bit
  // for bit (schemes that find both together override it).
  virtual double HeightAndGradient(const ElementCorners& e, double x,
                                   double y, double* gx, double* gy) const {
    Gradient(e, x, y, gx, gy);
    return Reconstruct(e, x, y);
  }
};

// Eq. (16): bilinear interpolation of the corner heights.
double BilinearHeight(const ElementCorners& e, double x, double y);
// Eq. (2): minimum of the four corner patches of eq. (1), and of the top.
double MinOfPatches(const ElementCorners& e, double x, double y);

// The guarded reconstruction (kGuarded, the default). Eq. (2) assumes every
// element lies inside smooth pieces; at rims, walls and a cutter's own kinks
// (a V-bit's apex, a flat end's rim) a corner's patch, extrapolated across
// the element, can plunge far below anything the tool reaches (143 mm below
// a 1 mm cut), and a cut passing between the nodes is seen by no patch. A
// patch is a statement about its owner's swept surface near its node: it is
// used only where that statement is checked to hold, and the exact surfaces
// (MoveSurfaces, the workpiece's exact-surface entry point) answer where it
// does not. PrepareGuarded classifies each element once:
// - smooth: every corner is cut, every corner's patch is trusted over the
//   whole element (TrustPatch kFull at the other three corners; the trust
//   region is convex, so then everywhere in it), and no patch passes more
//   than kGuardConsistency x the element's size below another corner
//   inside its owner's reach (a patch that disagrees with a neighbouring
//   node by more than a third-order term does not model the surface there:
//   a kink, a wall, a crease inside the element). There, eq. (2) over the
//   corners whose reach holds (x, y) (the owner's own footprint: where the
//   path turns or changes slope the patch does not model the next move),
//   each patch lifted by the bilinear interpolation of its shortfalls below
//   the corners in its reach (so that every patch passes at or above every
//   node it should: the reconstruction interpolates the nodes) and held at
//   or above its owner's lowest tip.
//   Where a corner lies lower than the value found and its owner's reach
//   misses (x, y), a cut passes between the nodes: the true surface there
//   (MoveSurfaces::LowestAt).
// - otherwise (a rim, a wall, a cutter's own kink, a patch that disagrees
//   with its neighbours, an uncut element a cut may cross between its
//   nodes): the exact surface, as the exact scheme gives it (the minimum
//   over the element's candidates, MoveSurfaces::FillCandidates).
// Without surfaces (a grid whose moves are not known) every element is
// taken as smooth, and the bilinear answers where no corner's reach holds
// (x, y). So patches serve the smooth interiors, where they are accurate to
// third order, and the exact sweeps the rest. See docs/benchmarks.md,
// "Guarded scheme".
double GuardedHeight(const ElementCorners& e, double x, double y);
// The per-element part of the guarded reconstruction (ElementCorners::
// guard), from e's corners, reach and surfaces. `trust`, if given, holds
// TrustRegion(e->c[k]) for the cut corners (a node's region serves its four
// elements). `sure`, if given with `trust`, holds for each cut corner
// SurelyTrusted(*trust[k], hx, hy) for some hx and hy at least the
// element's width and height (a node's serves the elements of a region);
// false only means that the corner's trust is tested one offset at a time.
// Corners with one owner have one reach (a reach is its owner's, as every
// filler of ElementCorners gives it).
struct PatchTrustRegion;
void PrepareGuarded(ElementCorners* e,
                    const PatchTrustRegion* const trust[4] = nullptr,
                    const bool* sure = nullptr);
// Whether the guarded reconstruction of e (prepared, or classified below)
// is the exact surface: the minimum of the top and of e's candidates'
// heights, where e is not smooth and has surfaces.
inline bool GuardedIsExact(const ElementCorners& e) {
  return !e.guard.smooth && e.surfaces != nullptr;
}
// PrepareGuarded less the candidates: sets e->guard alone, for a caller
// that does not reconstruct an element that is not smooth (the valuation:
// there the reconstruction is the exact surface, its error 0).
void ClassifyGuarded(ElementCorners* e,
                     const PatchTrustRegion* const trust[4] = nullptr,
                     const bool* sure = nullptr);
// Patches that disagree with a corner in their reach by more than this
// fraction of the element's size mark the element as not smooth.
inline constexpr double kGuardConsistency = 0.05;

// Along the gradient, with slope s and curvature k, a patch is the
// osculating parabola of a circle of radius (1 + s^2)^(3/2) / |k| (a ball's
// sphere or cylinder is one), which turns vertical, ending the height field
// (a rim), at the distance
//   RimDistance = (1 + s^2) / (|k| (sqrt(1 + s^2) + s))
// uphill from the node; infinite for a plane. At a flat node, k is the
// larger principal curvature.
double RimDistance(const SurfaceJet& j);

// How far a patch is trusted, in rim distances (RimDistance along the
// gradient, and the same along the direction of the larger principal
// curvature: a ramp's cylinder has its rim across the axis, while its
// gradient mixes in the slope along it): in any direction up to
// kPatchReach of the smaller; uphill along either, towards its rim, up to
// kPatchUphill of it, beyond which the
// parabola, rising slower than the circle, only bounds the surface from
// below. Both measured on the corpus and the analytic walls
// (docs/benchmarks.md, "Guarded scheme"): uphill 1.0 lets the slot whose
// rim is at the top err 2% more than the z-map, 0.8 gives up half the gain
// on bear.nc; a reach of 2 gives up a third of it, 4 is where the gain
// stops growing.
inline constexpr double kPatchReach = 4;
inline constexpr double kPatchUphill = 0.9;
enum class PatchTrust { kFull, kLowerBound, kNone };
// The trust of the patch with jet `j` at offset (dx, dy) from its node.
PatchTrust TrustPatch(const SurfaceJet& j, double dx, double dy);
// The same in two steps, for many offsets of one patch: its trust region
// (from the jet's slopes and curvatures alone: j.w is not read, so nodes
// whose wx..wyy are the same bits share one, as MeasureError relies on),
// then the trust at an offset, as TrustPatch.
struct PatchTrustRegion {
  bool everywhere = true;  // a plane: trusted everywhere
  double delta = 0, de = 0, reach = 0;  // rim distances, trusted radius
  double gx = 0, gy = 0, s = 0;         // gradient and its length
  double ex = 0, ey = 0, se = 0;        // larger principal direction
};
PatchTrustRegion TrustRegion(const SurfaceJet& j);
PatchTrust Trust(const PatchTrustRegion& region, double dx, double dy);
// Whether Trust(region, dx, dy) is surely kFull at every dx in {0, +-hx}
// and dy in {0, +-hy} (hx, hy >= 0: an element's corners seen from one of
// them), in one test. False only says that the offsets must be tested one
// by one.
bool SurelyTrusted(const PatchTrustRegion& region, double hx, double hy);

// The exact reconstruction (kExact): the minimum of the stock top and of
// the exact swept surfaces of the element's candidates at (x, y). The
// candidates hold every move that can be the lowest anywhere in the element,
// so this is the true machined surface (Workpiece::ExactHeight), bit for
// bit. Without surfaces, MinOfPatches.
double ExactCandidatesHeight(const ElementCorners& e, double x, double y);

const Scheme& GetScheme(SchemeKind kind);
// "zmap", "taylor", "guarded" or "exact"; InvalidArgument otherwise.
absl::StatusOr<SchemeKind> ParseScheme(std::string_view name);

}  // namespace swarf

#endif  // SWARF_CORE_SCHEME_H_
