#include "core/stock.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"

namespace swarf {

absl::Status ValidateStock(const StockSpec& s) {
  const struct {
    const char* name;
    double v;
  } fields[] = {{"x0", s.x0}, {"y0", s.y0}, {"x1", s.x1},
                {"y1", s.y1}, {"z_top", s.z_top}};
  for (const auto& f : fields) {
    if (!std::isfinite(f.v)) {
      return absl::InvalidArgumentError(
          absl::StrCat("stock.", f.name, " must be finite, got ", f.v));
    }
  }
  if (!(s.x1 > s.x0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "stock.x1 (", s.x1, ") must be greater than stock.x0 (", s.x0, ")"));
  }
  if (!(s.y1 > s.y0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "stock.y1 (", s.y1, ") must be greater than stock.y0 (", s.y0, ")"));
  }
  if (s.nx <= 0 || s.nx > kMaxElementsPerAxis) {
    return absl::InvalidArgumentError(absl::StrCat(
        "stock.nx must be in [1, ", kMaxElementsPerAxis, "], got ", s.nx));
  }
  if (s.ny <= 0 || s.ny > kMaxElementsPerAxis) {
    return absl::InvalidArgumentError(absl::StrCat(
        "stock.ny must be in [1, ", kMaxElementsPerAxis, "], got ", s.ny));
  }
  const int64_t nodes = (int64_t{s.nx} + 1) * (int64_t{s.ny} + 1);
  if (nodes > kMaxNodes) {
    return absl::InvalidArgumentError(absl::StrCat(
        "stock has ", nodes, " nodes, more than the limit ", kMaxNodes));
  }
  return absl::OkStatus();
}

int32_t GridGeometry::ElementX(double x) const {
  const double f = std::floor((x - spec_.x0) / dx_);
  return static_cast<int32_t>(std::clamp(f, 0.0, static_cast<double>(spec_.nx - 1)));
}

int32_t GridGeometry::ElementY(double y) const {
  const double f = std::floor((y - spec_.y0) / dy_);
  return static_cast<int32_t>(std::clamp(f, 0.0, static_cast<double>(spec_.ny - 1)));
}

}  // namespace swarf
