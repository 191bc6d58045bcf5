// The stock (raw workpiece) and the grid of vertical aligned lines over it.
#ifndef SWARF_CORE_STOCK_H_
#define SWARF_CORE_STOCK_H_

#include <cstdint>

#include "absl/status/status.h"
#include "core/geometry.h"

namespace swarf {

// Rectangular stock [x0,x1] x [y0,y1] with a flat top at z_top (mm), meshed
// into nx x ny elements, hence (nx+1) x (ny+1) nodes.
struct StockSpec {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  double z_top = 0;
  int32_t nx = 0, ny = 0;
};

// Largest element count per axis, and node count per workpiece, that the core
// accepts. Callers (the service) enforce their own, smaller, limits.
inline constexpr int32_t kMaxElementsPerAxis = 1 << 20;
inline constexpr int64_t kMaxNodes = int64_t{1} << 34;

// InvalidArgument naming the field when the spec is not finite, has an empty
// rectangle, a non-positive element count or too many nodes.
absl::Status ValidateStock(const StockSpec& spec);

// Node coordinates of a validated spec. Every part of the simulation computes
// node positions through this class so that they are bit-identical.
class GridGeometry {
 public:
  explicit GridGeometry(const StockSpec& spec)
      : spec_(spec),
        dx_((spec.x1 - spec.x0) / spec.nx),
        dy_((spec.y1 - spec.y0) / spec.ny) {}

  const StockSpec& spec() const { return spec_; }
  int32_t nx() const { return spec_.nx; }
  int32_t ny() const { return spec_.ny; }
  int32_t nodes_x() const { return spec_.nx + 1; }
  int32_t nodes_y() const { return spec_.ny + 1; }
  int64_t node_count() const { return int64_t{nodes_x()} * nodes_y(); }
  double dx() const { return dx_; }
  double dy() const { return dy_; }
  double NodeX(int32_t i) const { return spec_.x0 + i * dx_; }
  double NodeY(int32_t j) const { return spec_.y0 + j * dy_; }
  Rect bounds() const { return {spec_.x0, spec_.y0, spec_.x1, spec_.y1}; }

  // Element containing x (clamped to [0, nx-1]).
  int32_t ElementX(double x) const;
  int32_t ElementY(double y) const;

 private:
  StockSpec spec_;
  double dx_, dy_;
};

}  // namespace swarf

#endif  // SWARF_CORE_STOCK_H_
