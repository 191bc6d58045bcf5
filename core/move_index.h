// Spatial index of moves: uniform bins of elements, each listing the moves
// whose footprint (where they cut below the stock top) overlaps the bin.
// Not thread-safe for Add; concurrent reads are safe.
#ifndef SWARF_CORE_MOVE_INDEX_H_
#define SWARF_CORE_MOVE_INDEX_H_

#include <cstdint>
#include <vector>

#include "core/cutter/ball_sweep.h"
#include "core/stock.h"

namespace swarf {

class MoveIndex {
 public:
  // Bins are kBinElements x kBinElements elements, so that every element
  // (and every point sampled inside it) lies in exactly one bin.
  static constexpr int32_t kBinElements = 16;

  explicit MoveIndex(const GridGeometry& grid);

  // Records move `id` under every bin its footprint's bounding box
  // (BallSweep::FootprintBounds) touches.
  void Add(uint32_t id, const Rect& bounds);

  const GridGeometry& grid() const { return grid_; }
  int32_t bins_x() const { return bins_x_; }
  int32_t bins_y() const { return bins_y_; }
  int32_t BinOfElement(int32_t ei, int32_t ej) const {
    return (ej / kBinElements) * bins_x_ + ei / kBinElements;
  }
  // Move ids in the bin, ascending.
  const std::vector<uint32_t>& Bin(int32_t b) const { return bins_[b]; }

 private:
  const GridGeometry grid_;
  int32_t bins_x_, bins_y_;
  std::vector<std::vector<uint32_t>> bins_;
};

}  // namespace swarf

#endif  // SWARF_CORE_MOVE_INDEX_H_
