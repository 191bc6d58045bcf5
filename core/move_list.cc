#include "core/move_list.h"

#include <algorithm>
#include <bit>

namespace swarf {

MoveList::CutterKey MoveList::KeyOf(const Cutter& c) {
  return {static_cast<uint64_t>(c.kind),
          std::bit_cast<uint64_t>(c.radius),
          std::bit_cast<uint64_t>(c.corner_radius),
          std::bit_cast<uint64_t>(c.half_angle_deg),
          std::bit_cast<uint64_t>(c.tip_radius),
          0};
}

uint32_t MoveList::CutterIndex(const Cutter& c) {
  // Programs use a few tools, in long runs: the last one mostly.
  if (!cutters_.empty() && KeyOf(cutters_[last_cutter_]) == KeyOf(c)) {
    return last_cutter_;
  }
  const auto [it, added] = cutter_index_.try_emplace(
      KeyOf(c), static_cast<uint32_t>(cutters_.size()));
  if (added) cutters_.push_back(c);
  last_cutter_ = it->second;
  return it->second;
}

void MoveList::Append(const Move& move) {
  const int64_t id = size_;
  if ((id & (kChunkMoves - 1)) == 0) chunks_.push_back(std::make_unique<Chunk>());
  uint32_t tag = CutterIndex(move.cutter);
  // Programs are chains: a move mostly starts where the last one ended.
  if (id == 0 || !SameBits(move.from, Get(id - 1).to)) {
    starts_.push_back({move.from, tag});
    tag = kOwnStart | static_cast<uint32_t>(starts_.size() - 1);
  }
  Chunk& c = *chunks_.back();
  c.to[id & (kChunkMoves - 1)] = move.to;
  c.tag[id & (kChunkMoves - 1)] = tag;
  ++size_;
}

void MoveList::Append(std::span<const Move> moves) {
  for (const Move& m : moves) Append(m);
}

int64_t MoveList::MemoryBytes() const {
  return static_cast<int64_t>(chunks_.size() * sizeof(Chunk) +
                              chunks_.capacity() * sizeof(chunks_[0]) +
                              starts_.capacity() * sizeof(starts_[0]) +
                              cutters_.capacity() * sizeof(Cutter)) +
         static_cast<int64_t>(cutter_index_.capacity()) *
             static_cast<int64_t>(sizeof(CutterKey) + sizeof(uint32_t) + 1);
}

}  // namespace swarf
