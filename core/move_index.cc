#include "core/move_index.h"

#include <algorithm>
#include <cmath>

namespace swarf {
namespace {

// Bin index range [lo, hi] covering [a, b] along one axis; lo > hi if none.
std::pair<int32_t, int32_t> BinRange(double a, double b, double origin,
                                     double bin_size, int32_t bins) {
  const double lo = std::floor((a - origin) / bin_size);
  const double hi = std::floor((b - origin) / bin_size);
  if (!(hi >= 0) || !(lo < bins)) return {1, 0};
  // Not NaN here, so the conditionals are fmax/fmin without their calls.
  return {static_cast<int32_t>(lo > 0 ? lo : 0.0),
          static_cast<int32_t>(hi < bins - 1.0 ? hi : bins - 1.0)};
}

}  // namespace

MoveIndex::MoveIndex(const GridGeometry& grid)
    : grid_(grid),
      bins_x_((grid.nx() + kBinElements - 1) / kBinElements),
      bins_y_((grid.ny() + kBinElements - 1) / kBinElements),
      bins_(static_cast<size_t>(bins_x_) * bins_y_) {}

void MoveIndex::Add(uint32_t id, const Rect& b) {
  const auto [bx0, bx1] = BinRange(b.x0, b.x1, grid_.spec().x0,
                                   grid_.dx() * kBinElements, bins_x_);
  const auto [by0, by1] = BinRange(b.y0, b.y1, grid_.spec().y0,
                                   grid_.dy() * kBinElements, bins_y_);
  for (int32_t by = by0; by <= by1; ++by) {
    for (int32_t bx = bx0; bx <= bx1; ++bx) {
      bins_[static_cast<size_t>(by) * bins_x_ + bx].push_back(id);
    }
  }
}

}  // namespace swarf
