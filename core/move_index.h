// Spatial index of moves: uniform bins of elements, each listing the moves
// whose footprint (where they cut below the stock top) overlaps the bin.
//
// A bin's ids are kept ascending, runs of three or more consecutive ids as
// a range (two entries): a pass of a raster crosses a bin in tens of
// consecutive moves, so a move costs a few bytes instead of 4 a bin.
// Not thread-safe for Add; concurrent reads are safe.
#ifndef SWARF_CORE_MOVE_INDEX_H_
#define SWARF_CORE_MOVE_INDEX_H_

#include <cstdint>
#include <iterator>
#include <span>
#include <vector>

#include "core/cutter/ball_sweep.h"
#include "core/stock.h"
#include "core/thread_pool.h"

namespace swarf {

class MoveIndex {
 public:
  // Bins are kBinElements x kBinElements elements, so that every element
  // (and every point sampled inside it) lies in exactly one bin.
  static constexpr int32_t kBinElements = 16;

  explicit MoveIndex(const GridGeometry& grid);

  // The bins along an axis of `elements` elements.
  static constexpr int32_t BinsAlong(int32_t elements) {
    return (elements + kBinElements - 1) / kBinElements;
  }

  // Records move `id` (< 2^31, and above every id already added to the
  // bins it reaches) under every bin its footprint's bounding box
  // (BallSweep::FootprintBounds) touches.
  void Add(uint32_t id, const Rect& bounds);

  // The bins Add(id, bounds) records id under: [bx0, bx1] x [by0, by1],
  // none where bx0 > bx1 or by0 > by1.
  struct BinRect {
    int32_t bx0 = 1, bx1 = 0, by0 = 1, by1 = 0;
  };
  BinRect BinsOf(const Rect& bounds) const {
    return BinsOf(grid_, bins_x_, bins_y_, bounds);
  }
  // The same for any index over `grid`.
  static BinRect BinsOf(const GridGeometry& grid, const Rect& bounds) {
    return BinsOf(grid, BinsAlong(grid.nx()), BinsAlong(grid.ny()), bounds);
  }
  // The index that Add(first_id + k, bounds_k) for k = 0, 1, ... in turn
  // gives, where bins[k] = BinsOf(bounds_k) (an empty BinRect adds id
  // first_id + k nowhere): the bins are shared among the pool's threads,
  // each adding the ids of its own bins in order. Blocks until done; not
  // concurrent with other Adds or reads.
  void AddAll(uint32_t first_id, std::span<const BinRect> bins,
              ThreadPool& pool);

  const GridGeometry& grid() const { return grid_; }
  int32_t bins_x() const { return bins_x_; }
  int32_t bins_y() const { return bins_y_; }
  int32_t BinOfElement(int32_t ei, int32_t ej) const {
    return (ej / kBinElements) * bins_x_ + ei / kBinElements;
  }

  // The move ids of a bin, ascending, for range-for. Valid until the next
  // Add.
  class BinView {
   public:
    class Iterator {
     public:
      using iterator_category = std::forward_iterator_tag;
      using value_type = uint32_t;
      using difference_type = std::ptrdiff_t;
      using pointer = const uint32_t*;
      using reference = uint32_t;
      Iterator() = default;
      Iterator(const uint32_t* p, const uint32_t* end) : p_(p), end_(end) {
        Load();
      }
      uint32_t operator*() const { return id_; }
      Iterator& operator++() {
        if (id_ < last_) {
          ++id_;
        } else {
          p_ += (*p_ & kRangeBit) ? 2 : 1;
          Load();
        }
        return *this;
      }
      Iterator operator++(int) {
        Iterator t = *this;
        ++*this;
        return t;
      }
      bool operator==(const Iterator& o) const {
        return p_ == o.p_ && (p_ == end_ || id_ == o.id_);
      }

     private:
      void Load() {
        if (p_ == end_) return;
        id_ = *p_ & ~kRangeBit;
        last_ = (*p_ & kRangeBit) ? p_[1] : id_;
      }
      const uint32_t* p_ = nullptr;
      const uint32_t* end_ = nullptr;
      uint32_t id_ = 0, last_ = 0;
    };
    BinView(const uint32_t* begin, const uint32_t* end)
        : begin_(begin), end_(end) {}
    Iterator begin() const { return Iterator(begin_, end_); }
    Iterator end() const { return Iterator(end_, end_); }
    bool empty() const { return begin_ == end_; }

   private:
    const uint32_t* begin_;
    const uint32_t* end_;
  };
  BinView Bin(int32_t b) const {
    const std::vector<uint32_t>& v = bins_[b];
    return BinView(v.data(), v.data() + v.size());
  }
  // The same ids into *ids (replacing its contents), for random access.
  void BinIds(int32_t b, std::vector<uint32_t>* ids) const;

  // Bytes the bins hold (their capacity, and the bins themselves).
  int64_t MemoryBytes() const { return bytes_; }

 private:
  // An entry with this bit starts a range; the next entry is its last id.
  static constexpr uint32_t kRangeBit = uint32_t{1} << 31;
  // BinsOf over `grid`, whose bins are bins_x x bins_y.
  static BinRect BinsOf(const GridGeometry& grid, int32_t bins_x,
                        int32_t bins_y, const Rect& bounds);
  // Returns the bytes the bin's capacity grew by.
  static int64_t AddToBin(std::vector<uint32_t>* bin, uint32_t id);

  const GridGeometry grid_;
  int32_t bins_x_, bins_y_;
  std::vector<std::vector<uint32_t>> bins_;
  int64_t bytes_ = 0;
};

// The bytes a MoveIndex over the same grid would hold (MemoryBytes) after
// the same AddAll calls, bit for bit, without holding the ids (a memory
// check before a run, of an index of hundreds of MB): 12 bytes a bin, its
// entry count, last id and the length of its last run of consecutive ids.
// Thread safety as MoveIndex's.
class MoveIndexTally {
 public:
  explicit MoveIndexTally(const GridGeometry& grid);
  // As MoveIndex::AddAll.
  void AddAll(uint32_t first_id, std::span<const MoveIndex::BinRect> bins,
              ThreadPool& pool);
  // O(bins).
  int64_t MemoryBytes() const;

 private:
  struct Tail {
    uint32_t entries = 0;
    uint32_t last = 0;  // id
    uint32_t run = 0;   // 0: empty; 1, 2, or 3 for three or more
  };

  int32_t bins_x_;
  std::vector<Tail> tails_;
};

}  // namespace swarf

#endif  // SWARF_CORE_MOVE_INDEX_H_
