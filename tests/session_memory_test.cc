// Issue 28: what swarfd admits a session by (Session::EstimateMemoryBytes,
// every tile cut) against what the session reports (SessionState::
// memory_bytes) and what the process really takes (resident pages) once
// every tile is cut. One test per process (gtest_discover_tests), so the
// resident set is this session's.
#include <unistd.h>

#include <cstdio>
#include <vector>

#include "gtest/gtest.h"
#include "server/session.h"
#include "core/sanitizers.h"

namespace swarf::server {
namespace {

int64_t ResidentBytes() {
  long pages = 0, resident = 0;
  FILE* f = std::fopen("/proc/self/statm", "r");
  if (f == nullptr) return -1;
  const int n = std::fscanf(f, "%ld %ld", &pages, &resident);
  std::fclose(f);
  return n == 2 ? int64_t{resident} * sysconf(_SC_PAGESIZE) : -1;
}

// A 2047 x 2047-element taylor grid (32 x 32 tiles of 64 x 64 nodes) faced
// all over by a 4 mm flat end mill, rows 3 mm apart: every tile cut.
TEST(SessionMemoryTest, EstimateCoversTheSessionWithEveryTileCut) {
  SessionSpec spec;
  spec.id = "faced";
  spec.stock = {0, 0, 102.35, 102.35, 0, 2047, 2047};
  spec.scheme = SchemeKind::kTaylor;
  spec.tools = {{1, Cutter::Flat(2), {}}};
  const int64_t tiles = 32 * 32;
  const int64_t estimate =
      Session::EstimateMemoryBytes(spec.stock, spec.scheme);
  // 42 tiles of 49152 bytes a 2 MiB chunk: 25 chunks; 80 bytes a tile.
  ASSERT_EQ(estimate, 25 * (int64_t{2} << 20) + tiles * 80);

  const int64_t before = ResidentBytes();
  ASSERT_GT(before, 0);
  auto session = Session::Create(spec);
  ASSERT_TRUE(session.ok()) << session.status();
  std::vector<double> xyz;
  int rows = 0;
  for (double y = 0; y <= 104; y += 3, ++rows) {
    const bool even = rows % 2 == 0;
    xyz.insert(xyz.end(), {even ? -3.0 : 106.0, y, -0.5});
    xyz.insert(xyz.end(), {even ? 106.0 : -3.0, y, -0.5});
  }
  auto applied = (*session)->ApplyBatch(1, 1, xyz, 1 << 20, false);
  ASSERT_TRUE(applied.ok()) << applied.status();
  const SessionState st = (*session)->State();
  const int64_t moves = static_cast<int64_t>(xyz.size() / 3) - 1;
  EXPECT_EQ(st.moves_applied, moves);
  EXPECT_EQ(st.allocated_tiles, tiles);
  // What the session reports: its nodes (12 bytes each, every tile) and
  // its moves: their MoveList (one chunk of 4096 moves of 28 bytes here)
  // and their index (each of these long moves of a 4 mm flat end mill
  // lists itself in the bins of a band 4 mm wide, at most 7 rows of 128
  // bins of 0.8 mm: 4 bytes a bin, twice for the vectors' growth, and the
  // bins' own vectors).
  const int64_t nodes = tiles * 64 * 64 * 12;
  const int64_t move_bytes = st.memory_bytes - nodes;
  EXPECT_GE(move_bytes, MoveList::kChunkMoves * MoveList::kBytesPerMove);
  EXPECT_LE(move_bytes, MoveList::kChunkMoves * MoveList::kBytesPerMove +
                            int64_t{128} * 128 * 24 + moves * 7 * 128 * 4 * 2 +
                            4096);
  // The admission estimate covers the nodes (in whole chunks) and each
  // tile's bookkeeping; the moves come on top.
  EXPECT_GE(estimate + move_bytes, st.memory_bytes);
  // What the process took for it: the nodes are really resident (at
  // least their bytes), and no more than the estimate and the moves plus
  // what the process allocates once (the thread pool's stacks and
  // scratch, the move index): 4 MiB here.
#if defined(SWARF_SANITIZED)
  GTEST_SKIP() << "resident memory is not measured under the sanitizers "
                  "(their shadow memory and allocator are not the program's)";
#endif
  const int64_t taken = ResidentBytes() - before;
  std::printf("estimate %lld bytes, memory_bytes %lld, resident growth %lld "
              "(%.2f bytes a node)\n",
              static_cast<long long>(estimate),
              static_cast<long long>(st.memory_bytes),
              static_cast<long long>(taken),
              static_cast<double>(taken) / (2048.0 * 2048.0));
  EXPECT_GE(taken, tiles * 64 * 64 * 12);
  EXPECT_LE(taken, estimate + move_bytes + (int64_t{4} << 20));
}

}  // namespace
}  // namespace swarf::server
