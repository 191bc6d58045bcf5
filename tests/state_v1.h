// A workpiece's state in the version-1 format ("SWARFWP1"), which stored
// the five derivatives of taylor-family tiles (f32 x kTileNodes each, zeros
// for uncut nodes) after each tile's owners: what snapshots written before
// derivatives were computed on demand hold. For tests of reading them.
#ifndef SWARF_TESTS_STATE_V1_H_
#define SWARF_TESTS_STATE_V1_H_

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "core/workpiece.h"

namespace swarf {

inline std::string StateV1(const Workpiece& wp) {
  std::string v2;
  wp.SaveState([&](const void* data, size_t size) {
    v2.append(static_cast<const char*>(data), size);
  });
  constexpr size_t kHeader = 80;
  constexpr size_t kTile = 4 + 8 + kTileNodes * (sizeof(double) + 4);
  std::string out = v2.substr(0, kHeader);
  out[7] = '1';
  const bool derivs = wp.scheme().stores_derivatives();
  std::vector<float> d(5 * kTileNodes);
  for (size_t at = kHeader; at + kTile <= v2.size(); at += kTile) {
    out.append(v2, at, kTile);
    if (!derivs) continue;
    uint32_t t;
    std::memcpy(&t, v2.data() + at, 4);
    // ReadTile's rows are the tile's extent; the state's are kTileSize wide.
    const Workpiece::TileExtent e = wp.Extent(static_cast<int32_t>(t));
    std::vector<float> rows(5 * kTileNodes, 0.0f);
    float* dp[5];
    for (int c = 0; c < 5; ++c) dp[c] = rows.data() + c * kTileNodes;
    wp.ReadTile(static_cast<int32_t>(t), nullptr, dp, nullptr);
    std::fill(d.begin(), d.end(), 0.0f);
    for (int c = 0; c < 5; ++c) {
      for (int32_t j = 0; j < e.ny; ++j) {
        for (int32_t i = 0; i < e.nx; ++i) {
          d[c * kTileNodes + j * kTileSize + i] = dp[c][j * e.nx + i];
        }
      }
    }
    out.append(reinterpret_cast<const char*>(d.data()), d.size() * 4);
  }
  return out;
}

}  // namespace swarf

#endif  // SWARF_TESTS_STATE_V1_H_
