// Reconstruction schemes: how the surface inside an element is rebuilt from
// its four corner nodes. A scheme also decides which parameters a node keeps.
// To add a scheme: add a SchemeKind, a Scheme subclass in scheme.cc, and its
// name in ParseScheme.
#ifndef SWARF_CORE_SCHEME_H_
#define SWARF_CORE_SCHEME_H_

#include <string_view>

#include "absl/status/statusor.h"
#include "core/surface_jet.h"

namespace swarf {

enum class SchemeKind { kZmap, kTaylor };

// The four corner nodes of element [x0,x1] x [y0,y1]: c[0] at (x0,y0),
// c[1] at (x1,y0), c[2] at (x1,y1), c[3] at (x0,y1) (the paper's i, j, k, m).
struct ElementCorners {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  double z_top = 0;  // stock top: no reconstruction lies above it
  SurfaceJet c[4];
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

const Scheme& GetScheme(SchemeKind kind);
// "zmap" or "taylor"; InvalidArgument otherwise.
absl::StatusOr<SchemeKind> ParseScheme(std::string_view name);

}  // namespace swarf

#endif  // SWARF_CORE_SCHEME_H_
