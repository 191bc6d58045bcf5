// MoveList gives back every move bit for bit in about 28 bytes a move;
// MoveIndex's ranges list exactly the ids a plain list would, ascending.
#include "core/move_list.h"

#include <cstring>
#include <random>
#include <vector>

#include "core/move_index.h"
#include "core/stock.h"
#include "core/thread_pool.h"
#include "gtest/gtest.h"

namespace swarf {
namespace {

bool SameBits(const Move& a, const Move& b) {
  const auto same = [](const void* x, const void* y, size_t n) {
    return std::memcmp(x, y, n) == 0;
  };
  return same(&a.from, &b.from, sizeof(Vec3)) &&
         same(&a.to, &b.to, sizeof(Vec3)) && a.cutter.kind == b.cutter.kind &&
         same(&a.cutter.radius, &b.cutter.radius, sizeof(double)) &&
         same(&a.cutter.corner_radius, &b.cutter.corner_radius,
              sizeof(double)) &&
         same(&a.cutter.half_angle_deg, &b.cutter.half_angle_deg,
              sizeof(double)) &&
         same(&a.cutter.tip_radius, &b.cutter.tip_radius, sizeof(double));
}

// Chains with jumps, a tool change now and then, -0.0 against 0.0 in
// positions and cutters, across several chunks.
std::vector<Move> Program(int64_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-50, 50);
  const Cutter cutters[] = {Cutter::Ball(1), Cutter::Flat(3),
                            Cutter::BullNose(3, 1), Cutter::Cone(2, 30, 0),
                            Cutter::Cone(2, 30, -0.0),
                            Cutter::TaperedBall(3, 0.5, 10)};
  std::vector<Move> moves;
  Vec3 at{0, 0, 5};
  int tool = 0;
  for (int64_t k = 0; k < n; ++k) {
    Vec3 from = at;
    if (rng() % 97 == 0) from = {u(rng), u(rng), u(rng)};  // a jump
    if (rng() % 211 == 0) from.x = from.x == 0 ? -0.0 : from.x;
    if (rng() % 501 == 0) tool = static_cast<int>(rng() % 6);
    Vec3 to{u(rng), u(rng), u(rng)};
    if (k % 1000 == 7) to = {0.0, -0.0, 0.0};
    if (k % 1000 == 8) from = {-0.0, -0.0, 0.0};  // not the last end's bits
    moves.push_back({from, to, cutters[tool]});
    at = to;
  }
  return moves;
}

TEST(MoveListTest, GivesBackEveryMoveBitForBit) {
  for (const int64_t n : {int64_t{0}, int64_t{1}, MoveList::kChunkMoves - 1,
                          MoveList::kChunkMoves, MoveList::kChunkMoves + 1,
                          int64_t{3} * MoveList::kChunkMoves + 17}) {
    const std::vector<Move> moves = Program(n, static_cast<uint32_t>(n));
    MoveList list;
    // Appended in batches of varied sizes, as sessions apply them.
    for (size_t k = 0; k < moves.size();) {
      const size_t b = std::min(moves.size() - k, 1 + k % 3001);
      list.Append(std::span<const Move>(moves).subspan(k, b));
      k += b;
    }
    ASSERT_EQ(list.size(), n);
    for (int64_t id = 0; id < n; ++id) {
      ASSERT_TRUE(SameBits(list.Get(id), moves[id])) << "move " << id;
    }
    const std::vector<Move> back = list.ToVector();
    ASSERT_EQ(back.size(), moves.size());
  }
}

TEST(MoveListTest, AChainTakesAbout28BytesAMove) {
  MoveList list;
  Vec3 at{0, 0, 0};
  constexpr int64_t kMoves = 40 * MoveList::kChunkMoves;
  for (int64_t k = 0; k < kMoves; ++k) {
    const Vec3 to{at.x + 0.1, at.y, -1};
    list.Append(Move(at, to, Cutter::Ball(2)));
    at = to;
  }
  const double per_move = static_cast<double>(list.MemoryBytes()) / kMoves;
  EXPECT_GE(per_move, 28.0);
  EXPECT_LT(per_move, 28.5);
  EXPECT_EQ(MoveList::kBytesPerMove, 28);
}

// A square stock [0, side]^2 of n x n elements, top 0.
GridGeometry Square(double side, int32_t n) {
  StockSpec spec;
  spec.x1 = side;
  spec.y1 = side;
  spec.nx = n;
  spec.ny = n;
  return GridGeometry(spec);
}

// The ids each bin lists, as a plain list of every id (the reference).
TEST(MoveIndexTest, RangesListTheSameIdsAsAPlainList) {
  MoveIndex index(Square(64, 64));
  std::vector<std::vector<uint32_t>> want(
      static_cast<size_t>(index.bins_x()) * index.bins_y());
  std::mt19937 rng(7);
  // Runs of every length (1, 2, 3 and more consecutive ids in a bin),
  // gaps of one, and boxes over several bins.
  uint32_t id = 0;
  for (int k = 0; k < 4000; ++k) {
    const double x = static_cast<double>(rng() % 60);
    const double y = static_cast<double>(rng() % 60);
    const int run = 1 + static_cast<int>(rng() % 6);
    for (int r = 0; r < run; ++r) {
      const Rect b{x, y, x + (rng() % 3) * 9.0, y + (rng() % 2) * 17.0};
      index.Add(id, b);
      for (int32_t bj = 0; bj < index.bins_y(); ++bj) {
        for (int32_t bi = 0; bi < index.bins_x(); ++bi) {
          const double bx0 = bi * 16.0, by0 = bj * 16.0;
          if (b.x1 >= bx0 && b.x0 < bx0 + 16 && b.y1 >= by0 &&
              b.y0 < by0 + 16) {
            want[bj * index.bins_x() + bi].push_back(id);
          }
        }
      }
      ++id;
    }
    id += rng() % 3;  // sometimes a gap of one or two ids
  }
  std::vector<uint32_t> ids;
  for (int32_t b = 0; b < index.bins_x() * index.bins_y(); ++b) {
    std::vector<uint32_t> got;
    for (const uint32_t v : index.Bin(b)) got.push_back(v);
    EXPECT_EQ(got, want[b]) << "bin " << b;
    index.BinIds(b, &ids);
    EXPECT_EQ(ids, want[b]) << "bin " << b;
    EXPECT_EQ(index.Bin(b).empty(), want[b].empty());
  }
}

// AddAll, which shares the bins among threads, gives the index that Add in
// id order gives: every bin's ids (ranges, gaps) and the bytes held, for
// boxes over one bin, many, the grid's edges and none, ids left out (an
// empty BinRect), with any thread count (more parts than bins along a row,
// too), batch after batch. A MoveIndexTally given the same batches holds
// the same bytes after each, bit for bit (runs that grow into ranges, gaps,
// every doubling of a bin's capacity).
TEST(MoveIndexTest, AddAllIsAddInOrder) {
  // 80 threads: the bins shared among 64 parts, more than a move's.
  for (int threads : {1, 2, 3, 7, 16, 80}) {
    SCOPED_TRACE(threads);
    ThreadPool pool(threads);
    MoveIndex one(Square(64, 64)), all(Square(64, 64));
    MoveIndexTally tally(Square(64, 64));
    std::mt19937 rng(threads);
    uint32_t id = 0;
    for (int batch = 0; batch < 20; ++batch) {
      const uint32_t first = id;
      std::vector<MoveIndex::BinRect> bins;
      const int n = static_cast<int>(rng() % 400);
      for (int k = 0; k < n; ++k) {
        if (rng() % 7 == 0) {  // runs, and sometimes a gap: an id not added
          bins.push_back({});
          ++id;
        }
        const double x = static_cast<double>(rng() % 80) - 10;
        const double y = static_cast<double>(rng() % 80) - 10;
        const Rect b{x, y, x + (rng() % 4) * 11.0, y + (rng() % 3) * 13.0};
        one.Add(id++, b);
        bins.push_back(all.BinsOf(b));
      }
      all.AddAll(first, bins, pool);
      tally.AddAll(first, bins, pool);
      ASSERT_EQ(tally.MemoryBytes(), all.MemoryBytes()) << "batch " << batch;
    }
    EXPECT_EQ(all.MemoryBytes(), one.MemoryBytes());
    std::vector<uint32_t> want, got;
    for (int32_t b = 0; b < one.bins_x() * one.bins_y(); ++b) {
      one.BinIds(b, &want);
      all.BinIds(b, &got);
      EXPECT_EQ(got, want) << "bin " << b;
    }
  }
}

// A tally's bytes are the index's for a raster of short moves too, whose
// passes cross each bin in long runs of consecutive ids.
TEST(MoveIndexTest, TallyHoldsARastersBytes) {
  ThreadPool pool(3);
  const GridGeometry grid = Square(100, 2000);
  MoveIndex index(grid);
  MoveIndexTally tally(grid);
  std::vector<MoveIndex::BinRect> bins;
  uint32_t first = 0, id = 0;
  for (double y = 0; y <= 100; y += 0.5) {
    for (double x = 0; x < 100; x += 0.1) {
      bins.push_back(MoveIndex::BinsOf(grid, {x - 2, y - 2, x + 2.1, y + 2}));
      ++id;
    }
    index.AddAll(first, bins, pool);
    tally.AddAll(first, bins, pool);
    bins.clear();
    first = id;
  }
  EXPECT_EQ(tally.MemoryBytes(), index.MemoryBytes());
}

// A raster's pass crosses a bin in many consecutive moves: a few bytes a
// move instead of 4 a bin.
TEST(MoveIndexTest, ARasterTakesAFewBytesAMove) {
  MoveIndex index(Square(100, 2000));
  const double base = static_cast<double>(index.MemoryBytes());
  uint32_t id = 0;
  int64_t entries = 0;  // what a plain list would hold
  for (double y = 0; y <= 100; y += 0.5) {
    for (double x = 0; x < 100; x += 0.1) {
      const Rect b{x - 2, y - 2, x + 0.1 + 2, y + 2};
      index.Add(id++, b);
      const int64_t bx = static_cast<int64_t>(std::min(99.9, x + 2.1) / 0.8) -
                         static_cast<int64_t>(std::max(0.0, x - 2) / 0.8) + 1;
      const int64_t by = static_cast<int64_t>(std::min(99.9, y + 2) / 0.8) -
                         static_cast<int64_t>(std::max(0.0, y - 2) / 0.8) + 1;
      entries += bx * by;
    }
  }
  const double bytes = index.MemoryBytes() - base;
  EXPECT_LT(bytes / id, 16.0) << "plain: " << 4.0 * entries / id;
  EXPECT_GT(4.0 * entries / id, 100.0);
}

}  // namespace
}  // namespace swarf
