#include "core/move_index.h"

#include <algorithm>
#include <bit>
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
  // A power of two (the pool's size rounded up, at most 64), so that a
  // part is a mask, not a division: every part visits every move, and with
  // a division each, and a move's rows walked in every part, the index of
  // a raster of short moves took 6 times the instructions on 16 threads
  // that it took on 2.
  const int32_t parts = static_cast<int32_t>(
      std::bit_ceil(static_cast<uint32_t>(std::clamp(pool.size(), 1, 64))));
  const int32_t mask = parts - 1;
  std::vector<int64_t> grew(parts, 0);
  pool.ParallelFor(parts, [&](int64_t part) {
    const int32_t q = static_cast<int32_t>(part);
    int64_t bytes = 0;
    for (size_t k = 0; k < bins.size(); ++k) {
      const MoveIndex::BinRect& r = bins[k];
      // The move's bins lie on the diagonals bx + by from bx0 + by0 to
      // bx1 + by1, and this part's first is bx0 + by0 + skip: it has none
      // of them when skip is past them (most parts, for a short move; an
      // empty rectangle's span is negative).
      int32_t skip = (q - (r.bx0 + r.by0)) & mask;
      if (skip > (r.bx1 - r.bx0) + (r.by1 - r.by0)) continue;
      const uint32_t id = first_id + static_cast<uint32_t>(k);
      // The first bx >= bx0 with (bx + by) % parts == q is bx0 + skip, skip
      // in [0, parts): one down (mod parts) from one row to the next.
      for (int32_t by = r.by0; by <= r.by1; ++by) {
        const size_t row = static_cast<size_t>(by) * bins_x;
        for (int32_t x = r.bx0 + skip; x <= r.bx1; x += parts) {
          bytes += add(row + x, id);
        }
        skip = (skip - 1) & mask;
      }
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
