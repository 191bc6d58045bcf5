// The workpiece of state_fuzz, shared with state_seeds.cc (which writes
// valid states of it): the stock, the fixed moves recorded before a state
// is loaded, and the input's first byte (which scheme).
#ifndef SWARF_TESTS_FUZZ_STATE_FUZZ_H_
#define SWARF_TESTS_FUZZ_STATE_FUZZ_H_

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/scheme.h"
#include "core/stock.h"
#include "core/workpiece.h"

namespace swarf::state_fuzz {

// 98 x 72 nodes: 2 x 2 tiles, partial on both axes (as MixedStock in
// tests/workpiece_test.cc). Tile boundaries: x = 26.4, y = 27.0.
inline StockSpec Stock() { return StockSpec{0, 0, 40, 30, 10, 97, 71}; }

// Moves()[kCornerPlunge]: a plunge that cuts the far corner tile only.
inline constexpr size_t kCornerPlunge = 23;

// 31 moves: a zigzag raster over the whole stock (every tile cut), then a
// plunge in the far corner tile, a groove and a diagonal across the tile
// boundaries (the diagonal twice: exact ties), and moves that cut nothing
// (above the top, touching it, beside the stock, of zero length).
inline std::vector<Move> Moves() {
  std::vector<Move> m;
  for (int k = 0; k < 12; ++k) {
    const double y = 1 + 2.5 * k, z = 8.5 - 0.1 * k;
    const double x0 = k % 2 ? 41 : -1, x1 = k % 2 ? -1 : 41;
    if (k > 0) m.push_back({{x0, y - 2.5, z + 0.1}, {x0, y, z}, 1.5});
    m.push_back({{x0, y, z}, {x1, y, z}, 1.5});
  }
  const Move diagonal = {{0, 0, 9}, {40, 30, 6}, 0.5};
  m.push_back({{30, 29, 12}, {30, 29, 7}, 2});
  m.push_back({{26, 2, 9}, {27, 29, 6.8}, 0.75});
  m.push_back(diagonal);
  m.push_back(diagonal);
  m.push_back({{5, 5, 15}, {35, 25, 15}, 1});
  m.push_back({{10, 10, 11}, {20, 10, 11}, 1});
  m.push_back({{-10, -10, 5}, {-5, 35, 5}, 1});
  m.push_back({{20, 15, 7}, {20, 15, 7}, 1});
  return m;
}

// The input's first byte. Bit 0: the scheme the rest is loaded into.
inline SchemeKind SchemeOf(uint8_t first) {
  return first & 1 ? SchemeKind::kTaylor : SchemeKind::kZmap;
}
inline char FirstByte(SchemeKind scheme) {
  return scheme == SchemeKind::kTaylor ? 1 : 0;
}
// Bit 1: through the streaming overload, with a verify() that refuses.
inline constexpr char kStreamed = 2;

}  // namespace swarf::state_fuzz

#endif  // SWARF_TESTS_FUZZ_STATE_FUZZ_H_
