// Issue 28, the limits in bytes and the CLI's defaults: `swarf load` with its
// defaults against its embedded server; its throughput counting only the
// sessions that succeeded; `swarf run`'s memory refusal and --help; swarfd's
// byte-limit flags and the refusal of the removed node cap. The CLI and
// swarfd (SWARF_CLI, SWARFD_PATH) run as child processes.
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"
#include "tests/swarfd_process.h"

namespace swarf {
namespace {

namespace fs = std::filesystem;

struct Ran {
  int code = -1;       // exit code
  std::string output;  // stdout and stderr together
};

Ran Shell(const std::string& command) {
  Ran r;
  FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

fs::path TempDir(const std::string& name) {
  fs::path d = fs::temp_directory_path() /
               absl::StrCat("swarf_scale_", name, "_", ::getpid());
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

// The defaults are 32 sessions; the embedded server used to admit 16
// streams from one client, so half of them failed.
TEST(LoadCommandTest, DefaultSessionsAllSucceedOnTheEmbeddedServer) {
  const Ran r = Shell(absl::StrCat(SWARF_CLI,
                                 " load --moves 2000 --batch 500 --mesh 64"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(absl::StrContains(r.output, "32 sessions x 2000 moves"))
      << r.output;
  EXPECT_TRUE(absl::StrContains(
      r.output, "(64000 moves of the 32 sessions that succeeded, in"))
      << r.output;
  EXPECT_TRUE(
      absl::StrContains(r.output, "errors      0 of 32 sessions failed"))
      << r.output;
  EXPECT_FALSE(absl::StrContains(r.output, "streams open")) << r.output;
}

// Sessions that fail count no moves: every session over the server's
// per-session bytes (a 64-element grid is 4 tiles in a 2 MiB chunk; the
// limit is 1 MiB) fails, and the throughput is of 0 moves.
TEST(LoadCommandTest, FailedSessionsCountNoMoves) {
  const fs::path dir = TempDir("load");
  testing::SwarfdProcess swarfd(
      "", (dir / "swarfd.log").string(),
      {"--max_session_memory_mb=1", "--data_dir="});
  ASSERT_GT(swarfd.port(), 0) << swarfd.Log();
  const Ran r = Shell(absl::StrCat(
      SWARF_CLI, " load --server 127.0.0.1:", swarfd.port(),
      " --sessions 3 --moves 100 --batch 50 --mesh 64"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(absl::StrContains(
      r.output, "throughput  0.00M moves/s (0 moves of the 0 sessions that "
                "succeeded, in"))
      << r.output;
  EXPECT_TRUE(absl::StrContains(r.output, "errors      3 of 3 sessions failed"))
      << r.output;
  EXPECT_TRUE(absl::StrContains(
      r.output,
      "swarf load: create: the session needs 2097472 bytes (2.0 MiB for 64 x "
      "64 elements, every tile cut); this server allows 1048576 bytes (1.0 "
      "MiB) per session (--max_session_memory_mb)"))
      << r.output;
  fs::remove_all(dir);
}

// Sessions created whose streams then fail (every batch of 50 points over
// the server's 10) applied nothing: they count no moves either (before,
// such a session counted all the moves it meant to send).
TEST(LoadCommandTest, FailedStreamsCountNoMoves) {
  const fs::path dir = TempDir("load_stream");
  testing::SwarfdProcess swarfd("", (dir / "swarfd.log").string(),
                                {"--max_batch_points=10", "--data_dir="});
  ASSERT_GT(swarfd.port(), 0) << swarfd.Log();
  const Ran r = Shell(absl::StrCat(
      SWARF_CLI, " load --server 127.0.0.1:", swarfd.port(),
      " --sessions 2 --moves 100 --batch 50 --mesh 64"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(absl::StrContains(
      r.output, "(0 moves of the 0 sessions that succeeded, in"))
      << r.output;
  EXPECT_TRUE(absl::StrContains(r.output, "errors      2 of 2 sessions failed"))
      << r.output;
  EXPECT_TRUE(absl::StrContains(
      r.output,
      "swarf load: batch: moves.xyz has 50 points, more than the limit 10 "
      "per batch"))
      << r.output;
  fs::remove_all(dir);
}

TEST(RunHelpTest, HelpListsEveryScheme) {
  const Ran r = Shell(absl::StrCat(SWARF_CLI, " run --help"));
  EXPECT_EQ(r.code, 0);
  EXPECT_TRUE(absl::StrContains(r.output, "--scheme guarded|exact|taylor|zmap"))
      << r.output;
  EXPECT_TRUE(absl::StrContains(r.output, "--max-memory MB")) << r.output;
}

// A grid that cannot fit is refused at once (exit 2), naming what it needs
// and what is allowed. 200 x 200 elements: 4 x 4 tiles, in one chunk of 2
// MiB, and 80 bytes each: 2098432 bytes. 200 moves of 64 bytes (the
// server's MoveList, 28, the parsed point, 32, its feed, 4): 12800 bytes,
// and the server's index (taylor: the client keeps none): the 2 mm ball at
// z = -0.5 cuts within 0.866 mm of its path, in bins of 0.8 mm: 3 bins
// across y; along x, for the moves to x = 1..9, 3, 4, 4, 5, 5, 4, 4, 5, 5
// bins, and 13 for the return from 9 to 0. A bin keeps its ids as single
// ids and ranges of 3 or more (2 entries): 1869 entries in 39 bins, whose
// vectors double from 1 to 2496 entries' capacity, 9984 bytes, and the 13
// x 13 bins' vectors, 24 bytes each, 4056 bytes: 14040 bytes (counted with
// a model of the encoding written apart, in Python). In all 2125272
// bytes, 3 MiB.
TEST(RunMemoryTest, AJobThatCannotFitIsRefusedNamingTheBytes) {
  const fs::path dir = TempDir("run");
  {
    FILE* f = std::fopen((dir / "line.xyz").c_str(), "w");
    ASSERT_NE(f, nullptr);
    for (int k = 0; k <= 200; ++k) std::fprintf(f, "%d,5,-0.5\n", k % 10);
    std::fclose(f);
  }
  const std::string job = absl::StrCat(
      SWARF_CLI, " run ", (dir / "line.xyz").string(),
      " --tool ball:d=2 --stock 0,0,10,10,0 --spacing 0.05 --scheme taylor");
  const Ran refused = Shell(job + " --max-memory 2");
  EXPECT_EQ(refused.code, 2) << refused.output;
  EXPECT_TRUE(absl::StrContains(
      refused.output,
      "swarf run: the grid of 200 x 200 elements (40401 nodes, 0.05 mm) "
      "and 200 moves need at least 3 MiB (2125272 bytes: 2098432 for the "
      "grid, every tile at 12 bytes a node, and 26840 for the moves, of "
      "which 14040 their index); --max-memory allows 2 MiB; give a coarser "
      "--spacing or --mesh"))
      << refused.output;
  // At 3 MiB it fits, and the spacing asked for is kept (the default is
  // 0.1 mm).
  const Ran ran = Shell(job + " --max-memory 3 --json --quiet");
  EXPECT_EQ(ran.code, 0) << ran.output;
  EXPECT_TRUE(absl::StrContains(ran.output, "\"nx\":200,\"ny\":200"))
      << ran.output;
  EXPECT_EQ(Shell(job + " --max-memory 0").code, 2);
  fs::remove_all(dir);
}

TEST(SwarfdFlagsTest, TheNodeCapIsRefusedNamingItsReplacement) {
  const Ran r = Shell(absl::StrCat(SWARFD_PATH,
                                   " --listen 127.0.0.1:0 --data_dir= "
                                   "--max_nodes_per_session=67108864"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_TRUE(absl::StrContains(
      r.output,
      "--max_nodes_per_session was removed: limits are in bytes now; use "
      "--max_session_memory_mb (12 bytes a node: 67108864 nodes is about 768 "
      "MiB) and --max_total_memory_mb"))
      << r.output;
  const Ran neg = Shell(absl::StrCat(SWARFD_PATH, " --listen 127.0.0.1:0 "
                                     "--data_dir= --max_session_memory_mb=-1"));
  EXPECT_EQ(neg.code, 2) << neg.output;
  EXPECT_TRUE(absl::StrContains(neg.output,
                                "--max_session_memory_mb must be in [0, "))
      << neg.output;
  const Ran help = Shell(absl::StrCat(SWARFD_PATH, " --help"));
  EXPECT_TRUE(absl::StrContains(help.output, "max_session_memory_mb"))
      << help.output;
}

// The large job's generator at 20 x 20 mm: what it writes (7 facing moves,
// the raster's 41 rows of 200 moves and 40 steps between them, and round
// each of the four bosses a plunge and two half circles) runs as a project
// with its three tools, at the spacing asked for.
TEST(PlateJobTest, TheSmallPlateRunsWithItsProject) {
  const fs::path dir = TempDir("plate");
  const Ran made = Shell(absl::StrCat("python3 ", SWARF_SOURCE_DIR,
                                    "/scripts/make-example --plate 20 ",
                                    dir.string()));
  ASSERT_EQ(made.code, 0) << made.output;
  EXPECT_TRUE(absl::StrContains(made.output, "8288 lines, 8259 moves"))
      << made.output;
  const Ran ran = Shell(absl::StrCat(SWARF_CLI, " run --project ",
                                   (dir / "plate.camotics").string(),
                                   " --spacing 0.05 --json --quiet"));
  EXPECT_EQ(ran.code, 0) << ran.output;
  EXPECT_TRUE(absl::StrContains(ran.output, "\"nx\":400,\"ny\":400"))
      << ran.output;
  EXPECT_TRUE(absl::StrContains(ran.output,
                                "\"tools\":{\"1\":\"flat d=10\",\"2\":"
                                "\"ball d=4\",\"3\":\"ball d=1\"}"))
      << ran.output;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace swarf
