// Moves as the core keeps them: a straight move of a cutter between two
// tool-tip positions, and the list of a workpiece's moves by id, stored in
// about 28 bytes a move instead of sizeof(Move) (88).
//
// Contract:
// - Units: millimetres; positions are tool tips.
// - MoveList::Get returns exactly the Move appended (every coordinate and
//   cutter dimension bit for bit): a move whose start is bit-identical to
//   the previous move's end shares it, and cutters are kept once each.
// - Thread safety: const methods may run concurrently with each other;
//   Append must not run concurrently with anything else.
#ifndef SWARF_CORE_MOVE_LIST_H_
#define SWARF_CORE_MOVE_LIST_H_

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "core/cutter/cutter.h"
#include "core/geometry.h"

namespace swarf {

// A straight move of a cutter between two tool-tip positions (mm).
struct Move {
  Move() = default;
  Move(const Vec3& tip_from, const Vec3& tip_to, const Cutter& c)
      : from(tip_from), to(tip_to), cutter(c) {}
  // A ball-end move: the paper's cutter.
  Move(const Vec3& tip_from, const Vec3& tip_to, double ball_radius)
      : from(tip_from), to(tip_to), cutter(Cutter::Ball(ball_radius)) {}

  Vec3 from, to;
  Cutter cutter;
};

// A move's parts by pointer, into a MoveList (valid until its next Append)
// or into a Move the caller keeps.
struct MoveView {
  const Vec3* from;
  const Vec3* to;
  const Cutter* cutter;
};

// Moves by id, 0 <= id < size(), however they are kept: a workpiece's
// MoveList, or a client's program (its toolpath points). Implementations
// state their own thread safety; Get must be safe to call concurrently.
class MoveSource {
 public:
  virtual ~MoveSource() = default;
  virtual int64_t size() const = 0;
  // Move `id`, 0 <= id < size().
  virtual Move Get(int64_t id) const = 0;
  // Every move, in id order (88 bytes each: for tests and small lists).
  std::vector<Move> ToVector() const {
    std::vector<Move> v;
    v.reserve(size());
    for (int64_t id = 0; id < size(); ++id) v.push_back(Get(id));
    return v;
  }
};

class MoveList final : public MoveSource {
 public:
  // Moves per chunk: chunks are allocated whole, never moved, so that
  // growing the list copies no move (a vector of 20 M moves would hold
  // three copies while it grows).
  static constexpr int kChunkBits = 12;  // 112 KiB a chunk
  static constexpr int64_t kChunkMoves = int64_t{1} << kChunkBits;
  // Bytes a move takes in a full chunk (its end and a tag).
  static constexpr int64_t kBytesPerMove = sizeof(Vec3) + sizeof(uint32_t);

  MoveList() = default;
  explicit MoveList(std::span<const Move> moves) { Append(moves); }
  MoveList(const MoveList&) = delete;
  MoveList& operator=(const MoveList&) = delete;

  int64_t size() const override { return size_; }
  Move Get(int64_t id) const override {
    const Chunk& c = *chunks_[id >> kChunkBits];
    const int64_t k = id & (kChunkMoves - 1);
    const uint32_t tag = c.tag[k];
    Move m;
    m.to = c.to[k];
    if (tag & kOwnStart) {
      const Start& s = starts_[tag & ~kOwnStart];
      m.from = s.from;
      m.cutter = cutters_[s.cutter];
    } else {
      m.from = k > 0 ? c.to[k - 1]
                     : chunks_[(id >> kChunkBits) - 1]->to[kChunkMoves - 1];
      m.cutter = cutters_[tag];
    }
    return m;
  }
  Move operator[](int64_t id) const { return Get(id); }
  // Move `id` without a copy: for the scans that look at many moves and
  // keep few.
  MoveView View(int64_t id) const {
    const Chunk& c = *chunks_[id >> kChunkBits];
    const int64_t k = id & (kChunkMoves - 1);
    const uint32_t tag = c.tag[k];
    if (tag & kOwnStart) {
      const Start& s = starts_[tag & ~kOwnStart];
      return {&s.from, &c.to[k], &cutters_[s.cutter]};
    }
    return {k > 0 ? &c.to[k - 1]
                  : &chunks_[(id >> kChunkBits) - 1]->to[kChunkMoves - 1],
            &c.to[k], &cutters_[tag]};
  }
  // Asks the cache for move id's end, its tag and its start, for a Get soon.
  void Prefetch(int64_t id) const {
    const Chunk& c = *chunks_[id >> kChunkBits];
    const int64_t k = id & (kChunkMoves - 1);
    __builtin_prefetch(&c.to[k > 0 ? k - 1 : 0]);
    __builtin_prefetch(&c.to[k]);
    __builtin_prefetch(&c.tag[k]);
  }
  void Append(const Move& move);
  void Append(std::span<const Move> moves);

  // Bytes held: the chunks allocated, the starts kept apart and the cutters.
  int64_t MemoryBytes() const;

 private:
  // A tag's high bit: the move's start is not the previous move's end; the
  // other bits index starts_ then, cutters_ otherwise.
  static constexpr uint32_t kOwnStart = uint32_t{1} << 31;
  struct Start {
    Vec3 from;
    uint32_t cutter;  // index in cutters_
  };
  struct Chunk {
    std::array<Vec3, kChunkMoves> to;
    std::array<uint32_t, kChunkMoves> tag;
  };
  // A cutter's dimensions as bits, so that -0.0 and 0.0 stay apart.
  using CutterKey = std::array<uint64_t, 6>;
  static CutterKey KeyOf(const Cutter& c);
  uint32_t CutterIndex(const Cutter& c);

  int64_t size_ = 0;
  std::vector<std::unique_ptr<Chunk>> chunks_;
  // Each move's whose start is its own, in id order.
  std::vector<Start> starts_;
  std::vector<Cutter> cutters_;
  absl::flat_hash_map<CutterKey, uint32_t> cutter_index_;
  uint32_t last_cutter_ = 0;  // the index Append found last
};

}  // namespace swarf

#endif  // SWARF_CORE_MOVE_LIST_H_
