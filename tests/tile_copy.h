// Test helper: a tile's nodes copied out of a workpiece.
#ifndef SWARF_TESTS_TILE_COPY_H_
#define SWARF_TESTS_TILE_COPY_H_

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/workpiece.h"

namespace swarf {

// Tile t's nodes as Workpiece::ReadTile gives them, row-major over its
// extent: heights, the five derivatives (wx, wy, wxx, wxy, wyy, each a run
// of nx * ny), owners.
struct TileCopy {
  Workpiece::TileExtent extent;
  std::vector<double> w;
  std::vector<float> d;
  std::vector<int32_t> owner;
};

inline TileCopy CopyTile(const Workpiece& wp, int32_t t) {
  TileCopy c;
  c.extent = wp.Extent(t);
  const size_t n = static_cast<size_t>(c.extent.nx) * c.extent.ny;
  c.w.resize(n);
  c.d.resize(5 * n);
  c.owner.resize(n);
  float* dp[5];
  for (int k = 0; k < 5; ++k) dp[k] = c.d.data() + k * n;
  wp.ReadTile(t, c.w.data(), dp, c.owner.data());
  return c;
}

}  // namespace swarf

#endif  // SWARF_TESTS_TILE_COPY_H_
