// Programs interpreted by the server (issue 29 part 1): a G-code program
// uploaded in chunks on the Simulate stream gives the tiles (heights as
// doubles, owners) of the same program interpreted by the client and
// streamed as moves (cli::StreamPath, as `swarf run`), bit for bit; an
// error names the file and line; a real swarfd killed with SIGKILL
// mid-program keeps every acknowledged batch, and the program resumed
// after the restart ends as the uninterrupted run.
#include <unistd.h>

#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "client/cli/connection.h"
#include "nlohmann/json.hpp"
#include "server/convert.h"
#include "gcode/toolpath.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "swarf/v1/swarf.grpc.pb.h"
#include "tests/server_test_util.h"
#include "tests/shared_files.h"
#include "tests/sim_stream.h"
#include "tests/swarfd_process.h"

namespace swarf {
namespace {

namespace pb = ::swarf::v1;
using ::swarf::testing::ReadFileText;
using ::swarf::testing::GetSessionOrFail;
using ::swarf::testing::SerializedTiles;
using ::swarf::testing::SetDeadline;
using ::swarf::testing::SimStream;

const std::string kExamples = SWARF_SOURCE_DIR "/examples/";
const std::string kCorpus = SWARF_SOURCE_DIR "/../shared/corpus/";

struct Job {
  std::string file;
  std::map<int, Cutter> tools;  // session tool id (= T number): cutter
  double spacing;
};

// The session for a job over [x0, x1] x [y0, y1], top 0.
pb::CreateSessionRequest SessionOver(const Job& job, double x0, double y0,
                                     double x1, double y1,
                                     const std::string& id) {
  pb::CreateSessionRequest r;
  r.set_session_id(id);
  pb::Stock* s = r.mutable_stock();
  s->set_x0(x0);
  s->set_y0(y0);
  s->set_x1(x1);
  s->set_y1(y1);
  s->set_z_top(0);
  r.set_spacing(job.spacing);
  r.set_scheme(pb::SCHEME_GUARDED);
  for (const auto& [t, c] : job.tools) {
    server::ToolToProto({t, c, {}}, r.add_tools());
  }
  return r;
}

// The same over the program's bounds grown by the largest tool.
pb::CreateSessionRequest SessionFor(const Job& job, const gcode::Toolpath& p,
                                    const std::string& id) {
  double rmax = 0;
  for (const auto& [t, c] : job.tools) rmax = std::max(rmax, c.radius);
  return SessionOver(job, p.x_bounds().lo - rmax, p.y_bounds().lo - rmax,
                     p.x_bounds().hi + rmax, p.y_bounds().hi + rmax, id);
}

void Create(pb::Swarf::Stub* stub, const pb::CreateSessionRequest& r) {
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  pb::Session s;
  grpc::Status st = stub->CreateSession(&ctx, r, &s);
  ASSERT_TRUE(st.ok()) << st.error_message();
}


// Writes the program in chunks of `chunk` bytes (the options with the
// last), or a resume when `text` is null.
void WriteProgram(SimStream* s, const std::string* text,
                  const pb::ProgramOptions& options, size_t chunk,
                  uint64_t request_id = 9) {
  if (text == nullptr) {
    pb::SimulateRequest r;
    r.mutable_program()->set_request_id(request_id);
    r.mutable_program()->set_resume(true);
    r.mutable_program()->set_last(true);
    ASSERT_TRUE(s->Write(r));
    return;
  }
  for (size_t off = 0; off < text->size() || off == 0; off += chunk) {
    pb::SimulateRequest r;
    pb::ProgramChunk* c = r.mutable_program();
    c->set_request_id(request_id);
    c->set_offset(off);
    c->set_data(text->substr(off, chunk));
    c->set_last(off + chunk >= text->size());
    if (c->last()) *c->mutable_options() = options;
    ASSERT_TRUE(s->Write(r));
  }
}

bool Ended(const SimStream::Responses& rs) {
  return !rs.empty() &&
         (rs.back().has_program_done() || rs.back().has_error());
}

// Runs a program on a session and returns the stream's responses (the
// Acks, then a ProgramDone or a RequestError).
SimStream::Responses RunProgram(pb::Swarf::Stub* stub, const std::string& id,
                                const std::string& text,
                                const pb::ProgramOptions& options,
                                size_t chunk = 64 << 10) {
  SimStream s(stub, id);
  WriteProgram(&s, &text, options, chunk);
  EXPECT_TRUE(s.WaitFor(Ended));
  EXPECT_TRUE(s.Finish().ok());
  return s.responses();
}


// The client-side reference: the file read and interpreted as `swarf run`
// does it, its runs (gcode::SplitRuns, as run_command's Runs) streamed by
// cli::StreamPath in batches of `batch` points.
void StreamClientSide(cli::Connection* conn, const std::string& id,
                      const gcode::Toolpath& path, int64_t batch,
                      const std::map<int, Cutter>& tools) {
  // T numbers are the tool ids, or a job's only tool (as the server maps).
  const int only = tools.size() == 1 ? tools.begin()->first : -1;
  std::vector<cli::PathRun> runs;
  for (const gcode::ToolpathRun& r : gcode::SplitRuns(
           path, [&](int t) { return only >= 0 ? only : t; })) {
    cli::PathRun run;
    run.tool_id = r.tool_id;
    run.rapid = r.rapid;
    run.reposition = r.reposition;
    for (int64_t k = r.begin; k < r.end; ++k) {
      run.points.push_back(path.points()[k].position);
    }
    runs.push_back(std::move(run));
  }
  const absl::Status st = cli::StreamPath(*conn, id, runs, batch, nullptr);
  ASSERT_TRUE(st.ok()) << st;
}

void ExpectSameAsClientSide(const Job& job, int64_t batch) {
  SCOPED_TRACE(job.file);
  auto path = gcode::ReadToolpathFile(job.file);
  ASSERT_TRUE(path.ok()) << path.status();
  auto conn = *cli::Connection::Open("");
  pb::Swarf::Stub* stub = &conn->stub();
  Create(stub, SessionFor(job, *path, "client"));
  Create(stub, SessionFor(job, *path, "server"));
  StreamClientSide(conn.get(), "client", *path, batch, job.tools);
  pb::ProgramOptions o;
  o.set_name(std::filesystem::path(job.file).filename().string());
  o.set_batch_points(static_cast<int32_t>(batch));
  const std::string text = ReadFileText(job.file);
  const SimStream::Responses rs = RunProgram(stub, "server", text, o);
  ASSERT_FALSE(rs.empty());
  ASSERT_TRUE(rs.back().has_program_done()) << rs.back().error().message();
  const pb::ProgramDone& done = rs.back().program_done();
  EXPECT_EQ(done.first_seq(), 1u);
  EXPECT_EQ(done.moves(), path->move_count());
  EXPECT_EQ(done.points(), path->point_count());
  EXPECT_EQ(done.source_lines(), path->source_lines());
  // Progress: an Ack per batch, in seq order, as for streamed batches.
  uint64_t acks = 0;
  for (const auto& r : rs) {
    if (r.has_ack()) {
      EXPECT_EQ(r.ack().seq(), ++acks);
    }
  }
  EXPECT_EQ(acks, done.last_seq());
  const pb::Session client = GetSessionOrFail(stub, "client"),
                    server = GetSessionOrFail(stub, "server");
  EXPECT_EQ(server.last_seq(), client.last_seq());
  EXPECT_EQ(server.moves_applied(), client.moves_applied());
  EXPECT_EQ(server.version(), client.version());
  EXPECT_GT(server.moves_applied(), 1000);
  // (Not EXPECT_EQ: a failure would print every tile.)
  EXPECT_TRUE(SerializedTiles(stub, "server") ==
              SerializedTiles(stub, "client"));
}

TEST(ProgramApiTest, ExamplesGiveTheClientSideTilesBitForBit) {
  // Three flat end mills changed with M6, batches of 5000: several per run.
  ExpectSameAsClientSide({kExamples + "pocket.nc",
                          {{1, Cutter::Flat(3)},
                           {2, Cutter::Flat(1.5)},
                           {3, Cutter::Flat(0.5)}},
                          0.5},
                         5000);
  // A 60 degree V-bit, the CLI's default batch.
  ExpectSameAsClientSide(
      {kExamples + "vcarve.nc", {{1, Cutter::Cone(3, 30, 0)}}, 0.4}, 20000);
}

TEST(ProgramApiTest, CorpusGivesTheClientSideTilesBitForBit) {
  for (const char* f : {"vcarve.ngc", "bear.nc"}) {
    SWARF_SKIP_UNLESS_SHARED_FILE(kCorpus + f);
  }
  // Inches, G64: the program's T1 is the session's tool 1.
  ExpectSameAsClientSide(
      {kCorpus + "vcarve.ngc", {{1, Cutter::Cone(1, 45, 0)}}, 0.1}, 20000);
  ExpectSameAsClientSide(
      {kCorpus + "bear.nc", {{1, Cutter::Ball(1.5875)}}, 0.25}, 20000);
}

// Errors come back as the CLI prints them: file and line, the right code;
// nothing of the program is applied and the stream goes on.
TEST(ProgramApiTest, ErrorsNameTheFileAndLine) {
  auto conn = *cli::Connection::Open("");
  pb::Swarf::Stub* stub = &conn->stub();
  Job job{"", {{1, Cutter::Ball(1)}, {2, Cutter::Ball(2)}}, 0.5};
  Create(stub, SessionOver(job, -10, -10, 10, 10, "e"));
  const std::string bad =
      "G21 G90\nG0 X0 Y0 Z5\nG1 Z-1 F100\nG1 X5\n(fine so far)\nG1 Y5\n"
      "G1 X0 A7\nG1 Y0\nM2\n";
  // What `swarf run` prints for it (after its "FILE: ").
  const absl::Status cli = gcode::ParseGcode(bad).status();
  ASSERT_EQ(cli.code(), absl::StatusCode::kInvalidArgument);
  ASSERT_EQ(std::string(cli.message()).rfind("line 7: ", 0), 0u)
      << cli.message();
  pb::ProgramOptions o;
  o.set_name("bad.nc");
  SimStream s(stub, "e");
  auto expect_error = [&](grpc::StatusCode code, const std::string& message,
                          bool exact) {
    ASSERT_TRUE(s.WaitFor(Ended));
    const pb::SimulateResponse r = s.responses().back();
    ASSERT_TRUE(r.has_error());
    EXPECT_EQ(r.error().code(), static_cast<int>(code));
    EXPECT_EQ(r.error().kind(), pb::REQUEST_KIND_PROGRAM);
    EXPECT_EQ(r.error().request_id(), 9u);
    if (exact) {
      EXPECT_EQ(r.error().message(), message);
    } else {
      EXPECT_NE(r.error().message().find(message), std::string::npos)
          << r.error().message();
    }
  };
  size_t n = 0;
  auto next = [&] { return ++n; };
  WriteProgram(&s, &bad, o, 16);
  ASSERT_TRUE(s.WaitForCount(next()));
  expect_error(grpc::StatusCode::INVALID_ARGUMENT,
               "bad.nc: " + std::string(cli.message()), true);
  // A T number the session has no tool for (two tools: no default).
  const std::string t5 = "G21 G90\nT5 M6\nG0 X0 Y0 Z5\nG1 Z-1 F100\nM2\n";
  WriteProgram(&s, &t5, o, 1 << 20);
  ASSERT_TRUE(s.WaitForCount(next()));
  expect_error(grpc::StatusCode::INVALID_ARGUMENT,
               "bad.nc: line 2: T5 has no tool in session e (its tools: 1, "
               "2): map it in program.options.tools",
               false);
  // Bad options name their field.
  pb::ProgramOptions bad_batch = o;
  bad_batch.set_batch_points(1);
  const std::string ok = "G21 G90\nG0 X0 Y0 Z5\nG1 Z-1 F100\nG1 X3\nM2\n";
  WriteProgram(&s, &ok, bad_batch, 1 << 20);
  ASSERT_TRUE(s.WaitForCount(next()));
  expect_error(grpc::StatusCode::INVALID_ARGUMENT,
               "program.options.batch_points", false);
  // A chunk out of order.
  pb::SimulateRequest gap;
  gap.mutable_program()->set_request_id(9);
  gap.mutable_program()->set_offset(100);
  gap.mutable_program()->set_data("G0 X1");
  ASSERT_TRUE(s.Write(gap));
  ASSERT_TRUE(s.WaitForCount(next()));
  expect_error(grpc::StatusCode::FAILED_PRECONDITION,
               "a chunk at offset 100; this stream holds 0 bytes", false);
  // Resume on a memory-only server: nothing journaled.
  WriteProgram(&s, nullptr, o, 0);
  ASSERT_TRUE(s.WaitForCount(next()));
  expect_error(grpc::StatusCode::FAILED_PRECONDITION, "no journaled program",
               false);
  EXPECT_EQ(GetSessionOrFail(stub, "e").last_seq(), 0u);
  // The stream goes on: a good program, with warnings naming the lines.
  const std::string warn =
      "G90\nT1 M6\nG0 X0 Y0 Z5\nG1 Z-1 F100\nG1 X3 S1000\nM6 T2\nG1 X4\n"
      "M2\n";
  WriteProgram(&s, &warn, o, 1 << 20);
  ASSERT_TRUE(s.WaitForCount(next()));
  ASSERT_TRUE(s.WaitFor(Ended));
  ASSERT_TRUE(s.responses().back().has_program_done())
      << s.responses().back().error().message();
  const pb::ProgramDone done = s.responses().back().program_done();
  EXPECT_EQ(done.first_seq(), 1u);
  EXPECT_EQ(done.moves(), 3);
  ASSERT_GE(done.warnings_size(), 2);
  EXPECT_EQ(done.warnings(0),
            "bad.nc: note: no G20/G21 before the first move: millimetres "
            "assumed");
  EXPECT_EQ(done.warnings(1).rfind("bad.nc: ignored ", 0), 0u)
      << done.warnings(1);
  EXPECT_TRUE(s.Finish().ok());
  EXPECT_EQ(GetSessionOrFail(stub, "e").moves_applied(), 3);
}

// A Subscribe on the stream gets the tiles a program's batches change while
// the program runs (pushes and batches take turns), and a request after
// the program sees all of it.
TEST(ProgramApiTest, SubscribedTilesArePushedWhileTheProgramRuns) {
  const Job job{kExamples + "pocket.nc",
                {{1, Cutter::Flat(3)}, {2, Cutter::Flat(1.5)},
                 {3, Cutter::Flat(0.5)}},
                0.5};
  auto conn = *cli::Connection::Open("");
  pb::Swarf::Stub* stub = &conn->stub();
  Create(stub, SessionOver(job, 0, 0, 100, 80, "sub"));
  SimStream s(stub, "sub");
  pb::SimulateRequest sub;
  sub.mutable_subscribe()->set_request_id(5);
  ASSERT_TRUE(s.Write(sub));
  pb::ProgramOptions o;
  o.set_batch_points(500);
  const std::string text = ReadFileText(job.file);
  WriteProgram(&s, &text, o, 1 << 20);
  pb::SimulateRequest stats;
  stats.mutable_stats()->set_request_id(6);
  ASSERT_TRUE(s.Write(stats));
  // The last batch's pushes may come after the stats (a request queued
  // before the program ends is answered before them): waiting for the
  // stats to be the last response timed out on a loaded machine.
  ASSERT_TRUE(s.WaitFor([](const SimStream::Responses& rs) {
    return std::any_of(rs.begin(), rs.end(),
                       [](const auto& r) { return r.has_stats(); });
  }));
  EXPECT_TRUE(s.Finish().ok());
  const auto rs = s.responses();
  int64_t acks = 0, pushes_before_done = 0;
  bool done = false;
  for (const auto& r : rs) {
    if (r.has_ack()) ++acks;
    if (r.has_tile() && !done) ++pushes_before_done;
    if (r.has_program_done()) {
      done = true;
      EXPECT_EQ(static_cast<int64_t>(r.program_done().last_seq()), acks);
    }
    // Nothing of the program comes after the stats that follow it.
    if (r.has_stats()) {
      EXPECT_TRUE(done);
    }
  }
  EXPECT_TRUE(done);
  EXPECT_GT(acks, 30);
  EXPECT_GT(pushes_before_done, 0);
}

// A real swarfd killed with SIGKILL while it applies a program: restarted,
// it has every batch it acknowledged; the program resumed (no upload: the
// journaled one) ends as the uninterrupted run, bit for bit.
TEST(ProgramRestartTest, KilledMidProgramLosesNothingAcknowledged) {
  const Job job{kExamples + "pocket.nc",
                {{1, Cutter::Flat(3)}, {2, Cutter::Flat(1.5)},
                 {3, Cutter::Flat(0.5)}},
                0.5};
  auto path = gcode::ReadToolpathFile(job.file);
  ASSERT_TRUE(path.ok());
  const std::string text = ReadFileText(job.file);
  pb::ProgramOptions o;
  o.set_name("pocket.nc");
  o.set_batch_points(250);  // 70-odd batches, each fsynced
  std::vector<std::string> reference;
  uint64_t batches = 0;
  {
    auto conn = *cli::Connection::Open("");
    Create(&conn->stub(), SessionFor(job, *path, "ref"));
    const auto rs = RunProgram(&conn->stub(), "ref", text, o);
    ASSERT_TRUE(rs.back().has_program_done());
    batches = rs.back().program_done().last_seq();
    reference = SerializedTiles(&conn->stub(), "ref");
  }
  ASSERT_GT(batches, 50u);
  std::string tmpl = (std::filesystem::temp_directory_path() /
                      "swarf_program_restart_XXXXXX").string();
  const std::string dir = mkdtemp(tmpl.data());
  uint64_t acked = 0;
  {
    ::swarf::testing::SwarfdProcess p(dir + "/data", dir + "/swarfd.log", {});
    ASSERT_NE(p.port(), 0) << ReadFileText(dir + "/swarfd.log");
    auto stub = pb::Swarf::NewStub(
        grpc::CreateChannel("127.0.0.1:" + std::to_string(p.port()),
                            grpc::InsecureChannelCredentials()));
    Create(stub.get(), SessionFor(job, *path, "k"));
    SimStream s(stub.get(), "k");
    WriteProgram(&s, &text, o, 64 << 10);
    ASSERT_TRUE(s.WaitFor([](const SimStream::Responses& rs) {
      return rs.size() >= 5;
    }));
    p.Kill();
    s.Wait();
    for (const auto& r : s.responses()) {
      ASSERT_FALSE(r.has_error()) << r.error().message();
      ASSERT_FALSE(r.has_program_done()) << "the program ended before the kill";
      if (r.has_ack()) acked = r.ack().seq();
    }
  }
  ASSERT_GE(acked, 5u);
  ::swarf::testing::SwarfdProcess p(dir + "/data", dir + "/swarfd2.log", {});
  ASSERT_NE(p.port(), 0) << ReadFileText(dir + "/swarfd2.log");
  auto stub = pb::Swarf::NewStub(
      grpc::CreateChannel("127.0.0.1:" + std::to_string(p.port()),
                          grpc::InsecureChannelCredentials()));
  const pb::Session restored = GetSessionOrFail(stub.get(), "k");
  EXPECT_GE(restored.last_seq(), acked);
  EXPECT_LT(restored.last_seq(), batches);
  SimStream s(stub.get(), "k");
  WriteProgram(&s, nullptr, o, 0);
  ASSERT_TRUE(s.WaitFor(Ended));
  ASSERT_TRUE(s.Finish().ok());
  const auto rs = s.responses();
  ASSERT_TRUE(rs.back().has_program_done()) << rs.back().error().message();
  EXPECT_EQ(rs.back().program_done().last_seq(), batches);
  // The batches it had are acknowledged as duplicates, the rest applied.
  int64_t duplicates = 0;
  for (const auto& r : rs) duplicates += r.has_ack() && r.ack().duplicate();
  EXPECT_EQ(duplicates, static_cast<int64_t>(restored.last_seq()));
  EXPECT_TRUE(SerializedTiles(stub.get(), "k") == reference);
  p.Stop();
  std::filesystem::remove_all(dir);
}

// `swarf run --server ADDR --interpret server` against a real swarfd: every
// output file the same, byte for byte, as the moves sent by the client
// (stats.json apart from its timings and file names), safety and process
// facts included; a program with an error exits 1 naming the file and line.
TEST(ProgramCliTest, InterpretServerGivesTheSameOutputs) {
  std::string tmpl = (std::filesystem::temp_directory_path() /
                      "swarf_program_cli_XXXXXX").string();
  const std::string dir = mkdtemp(tmpl.data());
  ::swarf::testing::SwarfdProcess p(dir + "/data", dir + "/swarfd.log", {});
  ASSERT_NE(p.port(), 0) << ReadFileText(dir + "/swarfd.log");
  const std::string run =
      std::string(SWARF_CLI) + " run " + kExamples +
      "pocket.nc --tool T1=flat:d=6 --tool T2=flat:d=3 --tool T3=flat:d=1 "
      "--stock 0,0,100,80,0 --spacing 1 --picture-size 400 --batch 4000 "
      "--quiet --server 127.0.0.1:" + std::to_string(p.port());
  ASSERT_EQ(
      std::system((run + " --out " + dir + "/client > /dev/null").c_str()), 0);
  ASSERT_EQ(std::system((run + " --interpret server --out " + dir +
                         "/server > /dev/null")
                            .c_str()),
            0);
  int files = 0;
  for (const auto& f : std::filesystem::directory_iterator(dir + "/client")) {
    const std::string name = f.path().filename().string();
    const std::string a = ReadFileText(f.path().string());
    const std::string b = ReadFileText(dir + "/server/" + name);
    ++files;
    if (name != "stats.json") {
      EXPECT_TRUE(a == b) << name << " differs";
      continue;
    }
    auto ja = nlohmann::json::parse(a), jb = nlohmann::json::parse(b);
    for (auto* j : {&ja, &jb}) {
      for (const char* k : {"seconds", "moves_per_second", "files"}) {
        j->erase(k);
      }
    }
    EXPECT_EQ(ja, jb);
    EXPECT_GT(ja["moves"].get<int64_t>(), 15000);
  }
  EXPECT_GE(files, 8);
  // An error in the program: exit 1, the file and line as the client says.
  const std::string bad = dir + "/bad.nc";
  {
    std::ofstream out(bad);
    out << "G21 G90\nG0 X1 Y1 Z1\nG1 Z-1 F9\nG1 X2\nG1 X3 A1\nM2\n";
  }
  const std::string bad_run = std::string(SWARF_CLI) + " run " + bad +
                              " --tool ball:d=2 --interpret server --server "
                              "127.0.0.1:" + std::to_string(p.port()) +
                              " 2> " + dir + "/err.txt";
  EXPECT_EQ(WEXITSTATUS(std::system(bad_run.c_str())), 1);
  EXPECT_NE(ReadFileText(dir + "/err.txt").find(bad + ": line 5: A axis"),
            std::string::npos)
      << ReadFileText(dir + "/err.txt");
  EXPECT_EQ(WEXITSTATUS(std::system(
                (std::string(SWARF_CLI) + " run " + bad +
                 " --tool ball:d=2 --interpret elsewhere 2> /dev/null")
                    .c_str())),
            2);
  p.Stop();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace swarf
