#include "core/move_index.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/flag_words.h"
#include "core/target_clones.h"
#include "core/unfilled_vector.h"

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

// flag[k] = 1 where part q (of mask + 1) holds one of move k's diagonals
// bx + by, first[k] and the more[k] after it, else 0, for k < n: the
// part's first diagonal of the move's is first + ((q - first) & mask).
SWARF_TARGET_CLONES
void InPart(const int32_t* __restrict first, const int32_t* __restrict more,
            int32_t n, int32_t q, int32_t mask, uint8_t* __restrict flag) {
#pragma omp simd
  for (int32_t k = 0; k < n; ++k) {
    flag[k] = ((q - first[k]) & mask) <= more[k] ? 1 : 0;
  }
}

// Adds move first_id + k to each bin of bins[k] in turn, as
// add(bin, id) (returning the bytes the bin grew by), the bins shared among
// the pool's threads, each adding the ids of its own bins in order; returns
// the bytes added. Bin (bx, by) belongs to part (bx + by) mod parts: a
// raster's moves along x or along y spread over every part, and a part
// visits only its own bins of each move (a step of `parts` along the row).
template <typename Add>
int64_t AddInParts(int32_t bins_x, uint32_t first_id,
                   std::span<const MoveIndex::BinRect> bins, ThreadPool& pool,
                   Add add) {
  // Every part looks at every move. With a division each (its first bin
  // in the part) and its rows walked in every part, the index of a raster
  // of short moves took 6 times the instructions on 16 threads that it
  // took on 2. Now the parts are a power of two (the pool's size rounded
  // up, at most 64), a move's first bin in a part is a mask, and a part
  // visits only the moves it holds a bin of: 1.3 times.
  const int32_t parts = static_cast<int32_t>(
      std::bit_ceil(static_cast<uint32_t>(std::clamp(pool.size(), 1, 64))));
  const int32_t mask = parts - 1;
  // A move's bins lie on the diagonals bx + by from bx0 + by0 to bx1 +
  // by1: the first and how many more, taken once a move (negative for a
  // rectangle empty along both axes; one empty along x alone may be
  // flagged, and its rows add nothing). Each part flags the moves that
  // have one of its diagonals a block at a time, in a vectorized loop, and
  // visits those alone (most parts, for a short move, have none of its).
  // Unfilled: every entry is written below, before any part reads it.
  const size_t n = bins.size();
  UnfilledVector<int32_t> first(n), more(n);
  for (size_t k = 0; k < n; ++k) {
    const MoveIndex::BinRect& r = bins[k];
    first[k] = r.bx0 + r.by0;
    more[k] = (r.bx1 - r.bx0) + (r.by1 - r.by0);
  }
  constexpr int32_t kBlock = 256;
  std::vector<int64_t> grew(parts, 0);
  pool.ParallelFor(parts, [&](int64_t part) {
    const int32_t q = static_cast<int32_t>(part);
    int64_t bytes = 0;
    alignas(8) uint8_t flag[FlagBytes(kBlock)];
    for (size_t k0 = 0; k0 < n; k0 += kBlock) {
      const int32_t m = static_cast<int32_t>(std::min<size_t>(kBlock, n - k0));
      InPart(first.data() + k0, more.data() + k0, m, q, mask, flag);
      ClearFlagTail(flag, m);
      ForEachFlagged(flag, m, [&](int32_t b) {
        const size_t k = k0 + b;
        const MoveIndex::BinRect& r = bins[k];
        const uint32_t id = first_id + static_cast<uint32_t>(k);
        // The first bx >= bx0 with (bx + by) % parts == q is bx0 + skip,
        // skip in [0, parts): one down (mod parts) from one row to the
        // next.
        int32_t skip = (q - first[k]) & mask;
        for (int32_t by = r.by0; by <= r.by1; ++by) {
          const size_t row = static_cast<size_t>(by) * bins_x;
          for (int32_t x = r.bx0 + skip; x <= r.bx1; x += parts) {
            bytes += add(row + x, id);
          }
          skip = (skip - 1) & mask;
        }
      });
    }
    grew[part] = bytes;
  });
  int64_t bytes = 0;
  for (const int64_t b : grew) bytes += b;
  return bytes;
}

}  // namespace

MoveIndex::MoveIndex(const GridGeometry& grid)
    : grid_(grid),
      bins_x_(BinsAlong(grid.nx())),
      bins_y_(BinsAlong(grid.ny())),
      bins_(static_cast<size_t>(bins_x_) * bins_y_),
      bytes_(
          static_cast<int64_t>(bins_.size() * sizeof(std::vector<uint32_t>))) {}

int64_t MoveIndex::AddToBin(std::vector<uint32_t>* bin, uint32_t id) {
  std::vector<uint32_t>& v = *bin;
  const size_t n = v.size();
  const size_t capacity = v.capacity();
  // The last entry is a range's end when the one before starts a range.
  const bool last_ends_range = n >= 2 && (v[n - 2] & kRangeBit);
  if (last_ends_range && v[n - 1] + 1 == id) {
    v[n - 1] = id;  // the range grows
    return 0;
  }
  // Two singletons just before: the three become a range.
  if (!last_ends_range && n >= 2 && v[n - 1] + 1 == id && v[n - 2] + 2 == id &&
      !(n >= 3 && (v[n - 3] & kRangeBit))) {
    v[n - 2] |= kRangeBit;
    v[n - 1] = id;
    return 0;
  }
  v.push_back(id);
  return static_cast<int64_t>((v.capacity() - capacity) * sizeof(uint32_t));
}

void MoveIndex::BinIds(int32_t b, std::vector<uint32_t>* ids) const {
  ids->clear();
  for (const uint32_t id : Bin(b)) ids->push_back(id);
}

MoveIndex::BinRect MoveIndex::BinsOf(const GridGeometry& grid, int32_t bins_x,
                                     int32_t bins_y, const Rect& b) {
  const auto [bx0, bx1] =
      BinRange(b.x0, b.x1, grid.spec().x0, grid.dx() * kBinElements, bins_x);
  const auto [by0, by1] =
      BinRange(b.y0, b.y1, grid.spec().y0, grid.dy() * kBinElements, bins_y);
  return {bx0, bx1, by0, by1};
}

void MoveIndex::Add(uint32_t id, const Rect& b) {
  const BinRect r = BinsOf(b);
  for (int32_t by = r.by0; by <= r.by1; ++by) {
    for (int32_t bx = r.bx0; bx <= r.bx1; ++bx) {
      bytes_ += AddToBin(&bins_[static_cast<size_t>(by) * bins_x_ + bx], id);
    }
  }
}

void MoveIndex::AddAll(uint32_t first_id, std::span<const BinRect> bins,
                       ThreadPool& pool) {
  bytes_ += AddInParts(
      bins_x_, first_id, bins, pool,
      [this](size_t bin, uint32_t id) { return AddToBin(&bins_[bin], id); });
}

MoveIndexTally::MoveIndexTally(const GridGeometry& grid)
    : bins_x_(MoveIndex::BinsAlong(grid.nx())),
      tails_(static_cast<size_t>(bins_x_) * MoveIndex::BinsAlong(grid.ny())) {}

void MoveIndexTally::AddAll(uint32_t first_id,
                            std::span<const MoveIndex::BinRect> bins,
                            ThreadPool& pool) {
  // With ids ascending, AddToBin's entries for a run of consecutive ids are
  // the ids themselves up to two, then two (a range): one entry for the
  // run's first id and its second, none after. Without branches: a raster
  // adds hundreds of millions.
  AddInParts(bins_x_, first_id, bins, pool, [this](size_t bin, uint32_t id) {
    Tail& t = tails_[bin];
    const bool next = t.run != 0 && id == t.last + 1;
    t.entries += next && t.run != 1 ? 0 : 1;
    t.run = next ? std::min<uint32_t>(t.run + 1, 3) : 1;
    t.last = id;
    return int64_t{0};
  });
}

int64_t MoveIndexTally::MemoryBytes() const {
  // MoveIndex's bins and their capacities: std::vector's push_back
  // (libstdc++) grows a full vector to twice its size, an empty one to 1,
  // so n entries pushed take n rounded up to a power of two (MoveIndexTest
  // checks it against a MoveIndex).
  int64_t bytes =
      static_cast<int64_t>(tails_.size() * sizeof(std::vector<uint32_t>));
  for (const Tail& t : tails_) {
    if (t.entries > 0) {
      bytes +=
          static_cast<int64_t>(std::bit_ceil(t.entries) * sizeof(uint32_t));
    }
  }
  return bytes;
}

}  // namespace swarf
