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
// trustworthy, the bilinear elsewhere (see GuardedHeight). kExact: the
// minimum of the exact swept surfaces of the moves that can reach the
// element (see ExactCandidatesHeight). The values are stored in snapshots:
// append only.
enum class SchemeKind { kZmap, kTaylor, kGuarded, kExact };

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
};

// What a corner node's patch stands for: its owner's swept surface, which
// exists only over the owner's footprint (XY capsules: segments widened by
// their radius; the owner's, and those of the moves continuing it on the
// same path, whose surface carries on smoothly) and never goes below `z_low`
// (the lowest point the owner's tool reaches). Unbounded for uncut nodes (their
// patch is the stock top, everywhere) and where the owner is unknown.
struct CornerReach {
  struct Capsule {
    double ax = 0, ay = 0, bx = 0, by = 0;
    double radius = 0;
    bool Contains(double x, double y) const;  // closed
  };
  bool bounded = false;
  int count = 0;  // capsules in use
  Capsule capsule[3];
  double z_low = -std::numeric_limits<double>::infinity();

  // Whether (x, y) lies in a capsule (always, when unbounded).
  bool Contains(double x, double y) const;
};

// What TrustPatch derives from a jet alone (the rim distances, the
// principal direction, the slope), so that it is computed once per corner
// instead of once per sample. TrustPatch(TrustFrameOf(j), dx, dy) ==
// TrustPatch(j, dx, dy) for every offset.
struct PatchTrustFrame {
  bool unbounded = true;  // RimDistance is infinite: kFull everywhere
  double wx = 0, wy = 0;  // the jet's slope
  double s = 0;           // |slope|
  double ex = 0, ey = 0;  // direction of the larger principal curvature
  double se = 0;          // slope along it
  double reach2 = 0;      // (kPatchReach * min of the rim distances)^2
  double uphill = 0;      // kPatchUphill * RimDistance
  double uphill_e = 0;    // kPatchUphill * the rim distance along (ex, ey)
};

// The four corner nodes of element [x0,x1] x [y0,y1]: c[0] at (x0,y0),
// c[1] at (x1,y0), c[2] at (x1,y1), c[3] at (x0,y1) (the paper's i, j, k, m).
struct ElementCorners {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  double z_top = 0;  // stock top: no reconstruction lies above it
  SurfaceJet c[4];
  CornerReach reach[4];  // filled where the scheme uses_reach()
  // Filled where the scheme uses_candidates(): every move whose swept
  // surface can be the lowest somewhere in the element (MoveSweeps::
  // FillCandidates), ascending, and the surfaces of the moves (not owned;
  // outlives the corners).
  absl::InlinedVector<int32_t, 32> candidates;
  const MoveSurfaces* surfaces = nullptr;
  // With has_trust (FillTrust): TrustFrameOf each c[k], valid while c[] is
  // unchanged; without, computed where used (Scheme::uses_trust).
  bool has_trust = false;
  PatchTrustFrame trust[4];
};

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
  // Whether Reconstruct reads ElementCorners::trust (when has_trust; else it
  // derives the frames at every point: the same bits, more work).
  virtual bool uses_trust() const { return false; }
  // Height at (x, y) inside the element. Thread-safe.
  virtual double Reconstruct(const ElementCorners& e, double x,
                             double y) const = 0;
  // Gradient of the reconstruction at (x, y) (one-sided on a crease: that of
  // the piece Reconstruct picks).
  virtual void Gradient(const ElementCorners& e, double x, double y,
                        double* gx, double* gy) const = 0;
  // Reconstruct at n points of the element: out[q] = Reconstruct(e, x[q],
  // y[q]), bit for bit (schemes with per-element work override it).
  virtual void ReconstructMany(const ElementCorners& e, const double* x,
                               const double* y, int32_t n, double* out) const {
    for (int32_t q = 0; q < n; ++q) out[q] = Reconstruct(e, x[q], y[q]);
  }
  // Both: returns Reconstruct(e, x, y) and sets the Gradient, bit for bit
  // (schemes that find both at once override it).
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

// The guarded reconstruction (kGuarded). Eq. (2) assumes every element lies
// inside smooth pieces; at rims and walls a corner's patch, extrapolated
// across the element, can plunge far below anything the tool reaches (a rim
// node carries a slope of up to 1e4, and float storage of its huge, nearly
// singular Hessian leaves spurious negative curvature). A patch is a
// statement about its owner's swept surface near its node, so corner k's
// term of the minimum at (x, y) is:
// - nothing, outside its owner's footprint (CornerReach: where the owner's
//   sweep, or a move continuing it, reaches below the top): no surface of
//   the owner is there. Where no corner has a term, the bilinear.
// - its patch, held at or above the owner's lowest tip, where TrustPatch
//   trusts it (kFull); the larger of that and the bilinear where the patch
//   is only a lower bound (kLowerBound); the bilinear of eq. (16) (the
//   z-map's answer) beyond (kNone).
// The minimum starts at the top. So every value is the bilinear, the top or
// a patch inside its owner's reach held above the owner's lowest tip: never
// below the lowest tip of the moves owning the corners.
double GuardedHeight(const ElementCorners& e, double x, double y);
// GuardedHeight at n points of one element, bit for bit: the corners'
// frames and capsules once, the points in vectorized loops.
void GuardedHeights(const ElementCorners& e, const double* x, const double* y,
                    int32_t n, double* out);

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
// The same from the jet's frame (TrustFrameOf), without its libm calls.
PatchTrustFrame TrustFrameOf(const SurfaceJet& j);
PatchTrust TrustPatch(const PatchTrustFrame& f, double dx, double dy);
// Sets e->trust[k] = TrustFrameOf(e->c[k]) and e->has_trust: worth it when
// the guarded scheme reconstructs the element at several points.
void FillTrust(ElementCorners* e);

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
