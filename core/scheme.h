// Reconstruction schemes: how the surface inside an element is rebuilt from
// its four corner nodes. A scheme also decides which parameters a node keeps.
// To add a scheme: add a SchemeKind, a Scheme subclass in scheme.cc, and its
// name in ParseScheme.
#ifndef SWARF_CORE_SCHEME_H_
#define SWARF_CORE_SCHEME_H_

#include <limits>
#include <string_view>

#include "absl/status/statusor.h"
#include "core/surface_jet.h"

namespace swarf {

// kZmap: eq. (16). kTaylor: the paper's eq. (1)-(2), unchanged. kGuarded (the
// default of sessions and `swarf run`): eq. (1)-(2) where the patches are
// trustworthy, the bilinear elsewhere (see GuardedHeight). The values are
// stored in snapshots: append only.
enum class SchemeKind { kZmap, kTaylor, kGuarded };

// What a corner node's patch stands for: its owner's swept surface, which
// exists only over the owner's footprint (an XY capsule: the segment
// (ax, ay)-(bx, by) widened by `radius`) and never goes below `z_low` (the
// lowest point the owner's tool reaches). Unbounded for uncut nodes (their
// patch is the stock top, everywhere) and where the owner is unknown.
struct CornerReach {
  bool bounded = false;
  double ax = 0, ay = 0, bx = 0, by = 0;
  double radius = 0;
  double z_low = -std::numeric_limits<double>::infinity();

  // Whether (x, y) lies in the footprint (always, when unbounded). Points
  // within 1e-9 of the radius count as inside: a node its owner lowered is
  // inside however the distance rounds.
  bool Contains(double x, double y) const;
};

// The four corner nodes of element [x0,x1] x [y0,y1]: c[0] at (x0,y0),
// c[1] at (x1,y0), c[2] at (x1,y1), c[3] at (x0,y1) (the paper's i, j, k, m).
struct ElementCorners {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  double z_top = 0;  // stock top: no reconstruction lies above it
  SurfaceJet c[4];
  CornerReach reach[4];  // used by kGuarded only
};

class Scheme {
 public:
  virtual ~Scheme() = default;
  virtual SchemeKind kind() const = 0;
  virtual std::string_view name() const = 0;
  // Parameters per node as the paper counts them (Tables 1-2).
  virtual int parameters_per_node() const = 0;
  // Whether nodes store the sweep's derivatives (wx .. wyy).
  virtual bool stores_derivatives() const = 0;
  // Bytes per allocated node, including the owning move id.
  virtual int bytes_per_node() const = 0;
  // Height at (x, y) inside the element. Thread-safe.
  virtual double Reconstruct(const ElementCorners& e, double x,
                             double y) const = 0;
  // Gradient of the reconstruction at (x, y) (one-sided on a crease: that of
  // the piece Reconstruct picks).
  virtual void Gradient(const ElementCorners& e, double x, double y,
                        double* gx, double* gy) const = 0;
};

// Eq. (16): bilinear interpolation of the corner heights.
double BilinearHeight(const ElementCorners& e, double x, double y);
// Eq. (2): minimum of the four corner patches of eq. (1), and of the top.
double MinOfPatches(const ElementCorners& e, double x, double y);

// The guarded reconstruction (kGuarded). Eq. (2) assumes every element lies
// inside smooth pieces; at rims and walls a corner's patch, extrapolated
// across the element, can plunge far below anything the tool reaches (a rim
// node carries a slope of up to 1e4). Two rules make a patch say only what it
// knows about its owner's surface:
// - Where: a patch counts only inside its owner's footprint (CornerReach),
//   and never below its owner's lowest point. Where no corner's patch counts
//   (a point that none of the four owners reaches), the bilinear.
// - How far: a patch is the osculating quadric of its owner's surface. Along
//   the gradient, with slope s and curvature k there, a surface that turns
//   like a circle (a ball's sphere or cylinder, the common case) has third
//   derivative 3 s k^2 / (1 + s^2), so the patch's error at distance d is
//   about s k^2 d^3 / (2 (1 + s^2)), while the bilinear's error over the
//   element is about k d^2 / 8. The patch is the better model when
//   4 s |k| d < 1 + s^2 with d the element's diagonal (PatchTrusted). If any
//   corner fails it (a node near a rim or a wall), the whole element is
//   the bilinear of eq. (16): exactly the z-map there, never worse.
// Every value is between the lowest z_low of the corners that count and the
// top, so nothing lies below what the owning tools reach.
double GuardedHeight(const ElementCorners& e, double x, double y);
// Whether a patch with jet `j` is trusted over an element of diagonal `d`.
bool PatchTrusted(const SurfaceJet& j, double d);

const Scheme& GetScheme(SchemeKind kind);
// "zmap", "taylor" or "guarded"; InvalidArgument otherwise.
absl::StatusOr<SchemeKind> ParseScheme(std::string_view name);

}  // namespace swarf

#endif  // SWARF_CORE_SCHEME_H_
