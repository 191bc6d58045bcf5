// Arcs through the API (issue 27 part 5): a MoveBatch's arcs are chorded by
// the server exactly as `swarf run` chords a program's arcs, so the tiles
// (heights as doubles, owners) are bit-identical to the program's chords
// sent as plain xyz; every bad arc is INVALID_ARGUMENT naming its field and
// index with nothing applied; the session's arc tolerance is bounds
// checked; a journaled arc session restarts identical.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "gcode/toolpath.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "swarf/v1/swarf.grpc.pb.h"
#include "tests/server_test_util.h"
#include "tests/sim_stream.h"

namespace swarf::server {
namespace {

namespace pb = ::swarf::v1;
using ::swarf::testing::MovesRequest;
using ::swarf::testing::GetSessionOrFail;
using ::swarf::testing::SerializedTiles;
using ::swarf::testing::SetDeadline;
using ::swarf::testing::SetStock;
using ::swarf::testing::SimStream;

constexpr int32_t kTool = 3;
const StockSpec kStock{-20, -20, 20, 20, 0, 160, 160};

// One arc of the program below as the API names it, and where it ends.
struct ProgramArc {
  Vec3 end, centre;
  pb::ArcPlane plane;
  bool cw;
  int turns;
};

// A program whose arcs are G2/G3 with I/J/K (incremental centres) in each
// plane, one of them a helix of two turns; between them straight feeds.
// The points as the API sends them: the straight moves' ends and the arcs'
// ends, with the arcs.
constexpr char kProgram[] =
    "G21 G90 G17\n"
    "G0 X-10 Y0 Z5\n"
    "G1 Z-1 F500\n"
    "G2 X10 Y0 I10 J0\n"              // half circle, XY, cw
    "G3 X0 Y10 I-10 J0\n"             // quarter, ccw
    "G1 X0 Y8 Z-1.5\n"
    "G2 X0 Y8 Z-3 I0 J-8 P2\n"        // helix: two full turns down 1.5
    "G18 G1 X-5 Y-12 Z-1\n"
    "G3 X5 Z-1 I5 K0\n"               // XZ: half circle below the top
    "G19 G1 X15 Y-5 Z-1\n"
    "G2 Y5 Z-1 J5 K0\n"               // YZ
    "G17 G1 X15 Y15 Z-0.5\n"
    "M2\n";

std::vector<Vec3> ApiPoints(std::vector<ProgramArc>* arcs,
                            std::vector<int64_t>* arc_index) {
  std::vector<Vec3> p = {{-10, 0, 5}, {-10, 0, -1}};
  auto arc = [&](Vec3 end, Vec3 c, pb::ArcPlane plane, bool cw, int turns) {
    arc_index->push_back(static_cast<int64_t>(p.size()));
    p.push_back(end);
    arcs->push_back({end, c, plane, cw, turns});
  };
  arc({10, 0, -1}, {0, 0, 0}, pb::ARC_PLANE_XY, true, 1);
  arc({0, 10, -1}, {0, 0, 0}, pb::ARC_PLANE_XY, false, 1);
  p.push_back({0, 8, -1.5});
  arc({0, 8, -3}, {0, 0, 0}, pb::ARC_PLANE_XY, true, 2);
  p.push_back({-5, -12, -1});
  // Plane XZ: the centre's x and z count, y is the axis.
  arc({5, -12, -1}, {0, 99, -1}, pb::ARC_PLANE_XZ, false, 1);
  p.push_back({15, -5, -1});
  arc({15, 5, -1}, {99, 0, -1}, pb::ARC_PLANE_YZ, true, 1);
  p.push_back({15, 15, -0.5});
  return p;
}

pb::SimulateRequest ArcBatch(uint64_t seq) {
  std::vector<ProgramArc> arcs;
  std::vector<int64_t> index;
  std::vector<Vec3> p = ApiPoints(&arcs, &index);
  std::vector<double> xyz;
  for (const Vec3& v : p) xyz.insert(xyz.end(), {v.x, v.y, v.z});
  pb::SimulateRequest r = MovesRequest(seq, kTool, xyz);
  r.mutable_moves()->set_reposition(true);
  for (size_t k = 0; k < arcs.size(); ++k) {
    pb::Arc* a = r.mutable_moves()->add_arcs();
    a->set_end_index(index[k]);
    a->mutable_centre()->set_x(arcs[k].centre.x);
    a->mutable_centre()->set_y(arcs[k].centre.y);
    a->mutable_centre()->set_z(arcs[k].centre.z);
    a->set_plane(arcs[k].plane);
    a->set_clockwise(arcs[k].cw);
    a->set_turns(arcs[k].turns);
  }
  return r;
}

// The program's points as `swarf run` makes them (the interpreter's
// ToolpathBuilder).
std::vector<double> CliChords(double tolerance) {
  gcode::GcodeOptions o;
  o.arc_tolerance = tolerance;
  auto path = gcode::ParseGcode(kProgram, o);
  EXPECT_TRUE(path.ok()) << path.status();
  std::vector<double> xyz;
  for (const gcode::ToolpathPoint& p : path->points()) {
    xyz.insert(xyz.end(), {p.position.x, p.position.y, p.position.z});
  }
  return xyz;
}

void Create(pb::Swarf::Stub* stub, const std::string& id,
            double tolerance = -1,  // -1: not given
            grpc::Status* status = nullptr,
            pb::Session* out = nullptr) {
  pb::CreateSessionRequest create;
  create.set_session_id(id);
  SetStock(kStock, &create);
  pb::Tool* tool = create.add_tools();
  tool->set_id(kTool);
  tool->mutable_ball()->set_radius(1.5);
  if (tolerance != -1) {  // -1: not given
    create.mutable_arc_tolerance()->set_value(tolerance);
  }
  pb::Session session;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  grpc::Status st = stub->CreateSession(&ctx, create, &session);
  if (status != nullptr) {
    *status = st;
  } else {
    ASSERT_TRUE(st.ok()) << st.error_message();
  }
  if (out != nullptr) *out = session;
}


// Sends one request and returns its one answer.
pb::SimulateResponse Send(pb::Swarf::Stub* stub, const std::string& id,
                          const pb::SimulateRequest& req) {
  SimStream s(stub, id);
  EXPECT_TRUE(s.Write(req));
  EXPECT_TRUE(s.WaitForCount(1));
  EXPECT_TRUE(s.Finish().ok());
  auto r = s.responses();
  return r.empty() ? pb::SimulateResponse() : r[0];
}


class ArcsApiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ServerOptions o;
    o.listen = "";
    o.limits.max_batch_points = 4096;
    server_ = *SwarfServer::Start(o);
    stub_ = pb::Swarf::NewStub(server_->InProcessChannel());
  }
  std::unique_ptr<SwarfServer> server_;
  std::unique_ptr<pb::Swarf::Stub> stub_;
};

TEST_F(ArcsApiTest, ArcsGiveTheClisChordsBitForBit) {
  for (const double tol : {0.001, 0.05}) {
    SCOPED_TRACE(tol);
    const std::string a = tol == 0.001 ? "arcs" : "arcs-coarse";
    const std::string b = a + "-xyz";
    Create(stub_.get(), a, tol == 0.001 ? -1 : tol);  // default 0.001
    Create(stub_.get(), b, tol);
    EXPECT_EQ(GetSessionOrFail(stub_.get(), a).arc_tolerance(), tol);
    const pb::SimulateResponse ra = Send(stub_.get(), a, ArcBatch(1));
    ASSERT_TRUE(ra.has_ack()) << ra.error().message();
    const std::vector<double> chords = CliChords(tol);
    pb::SimulateRequest rb = MovesRequest(1, kTool, chords);
    rb.mutable_moves()->set_reposition(true);
    const pb::SimulateResponse ack_b = Send(stub_.get(), b, rb);
    ASSERT_TRUE(ack_b.has_ack());
    // The chords are the moves: as many as the CLI's polyline has.
    EXPECT_EQ(ra.ack().moves_applied(),
              static_cast<int64_t>(chords.size() / 3) - 1);
    EXPECT_EQ(ra.ack().moves_applied(), ack_b.ack().moves_applied());
    EXPECT_EQ(ra.ack().node_lowerings(), ack_b.ack().node_lowerings());
    EXPECT_GT(ra.ack().moves_applied(), 100);  // arcs, not 9 lines
    EXPECT_EQ(SerializedTiles(stub_.get(), a), SerializedTiles(stub_.get(), b));
    const pb::Session sa = GetSessionOrFail(stub_.get(), a);
    EXPECT_EQ(sa.last_position().x(), 15);
    EXPECT_EQ(sa.last_position().y(), 15);
    EXPECT_EQ(sa.last_position().z(), -0.5);
    // A resent seq with the same arcs is the same batch.
    const pb::SimulateResponse again = Send(stub_.get(), a, ArcBatch(1));
    ASSERT_TRUE(again.has_ack());
    EXPECT_TRUE(again.ack().duplicate());
  }
}

// The helix of two turns from z -1.5 to -3: its chords descend linearly in
// the angle, so the deepest node under its path is 3 mm below the top, and
// its chord count is what the tolerance makes of 4 pi radians at r = 8.
TEST_F(ArcsApiTest, HelixDescendsOverItsTurns) {
  Create(stub_.get(), "helix");
  pb::SimulateRequest r = MovesRequest(1, kTool, {0, 8, -1.5, 0, 8, -3});
  r.mutable_moves()->set_reposition(true);
  pb::Arc* a = r.mutable_moves()->add_arcs();
  a->set_end_index(1);
  a->mutable_centre()->set_x(0);
  a->mutable_centre()->set_y(0);
  a->mutable_centre()->set_z(123);  // the axis coordinate is not used
  a->set_clockwise(true);
  a->set_turns(2);
  const pb::SimulateResponse ack = Send(stub_.get(), "helix", r);
  ASSERT_TRUE(ack.has_ack()) << ack.error().message();
  const double step = 4 * std::asin(std::sqrt(0.001 / (2 * 8.0)));
  EXPECT_EQ(ack.ack().moves_applied(),
            static_cast<int64_t>(std::ceil(4 * M_PI / step)));
  pb::ProbeRequest probe;
  probe.set_session_id("helix");
  // On the circle at angle 90 deg (the start), after one and two turns the
  // tool passed at -2.25 and -3: the ball's tip leaves the end's depth.
  probe.add_xy(0);
  probe.add_xy(8);
  probe.add_xy(0);
  probe.add_xy(-8);
  pb::ProbeResponse pr;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  ::swarf::testing::ForSession(&ctx, "helix");
  ASSERT_TRUE(stub_->Probe(&ctx, probe, &pr).ok());
  EXPECT_NEAR(pr.heights(0), -3, 1e-6);
  // Opposite side: the last pass there was at half a turn from the end,
  // z = -3 + 1.5 / 4 = -2.625.
  EXPECT_NEAR(pr.heights(1), -2.625, 1e-3);
}

TEST_F(ArcsApiTest, SessionArcToleranceIsBoundsChecked) {
  for (const double bad : {0.0, 1e-7, 10.5, -0.5,
                           std::numeric_limits<double>::quiet_NaN()}) {
    grpc::Status st;
    Create(stub_.get(), "tol", bad, &st);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << bad;
    EXPECT_NE(st.error_message().find("arc_tolerance"), std::string::npos)
        << st.error_message();
  }
  pb::Session s;
  grpc::Status st;
  Create(stub_.get(), "tol", 10, &st, &s);
  EXPECT_TRUE(st.ok());
  EXPECT_EQ(s.arc_tolerance(), 10);
  Create(stub_.get(), "tol-default", -1, &st, &s);
  EXPECT_EQ(s.arc_tolerance(), 0.001);
}

// Every bad arc: INVALID_ARGUMENT naming moves.arcs[k] and the field; the
// batch is not applied (its seq is free), the session goes on serving.
TEST_F(ArcsApiTest, BadArcsAreRefusedNamingTheField) {
  Create(stub_.get(), "bad");
  struct Case {
    const char* name;
    void (*edit)(pb::MoveBatch*);
    const char* expect;
  };
  const Case cases[] = {
      {"index 0",
       [](pb::MoveBatch* b) { b->mutable_arcs(0)->set_end_index(0); },
       "moves.arcs[0].end_index 0 is out of range"},
      {"index past the end",
       [](pb::MoveBatch* b) { b->mutable_arcs(4)->set_end_index(11); },
       "moves.arcs[4].end_index 11 is out of range"},
      {"not ascending",
       [](pb::MoveBatch* b) { b->mutable_arcs(1)->set_end_index(2); },
       "moves.arcs[1].end_index 2 is not after moves.arcs[0]"},
      {"radius mismatch",
       [](pb::MoveBatch* b) {
         b->mutable_arcs(1)->mutable_centre()->set_x(0.1);
       },
       "moves.arcs[1].centre: a counterclockwise arc: the radius to the end"},
      {"zero radius",
       [](pb::MoveBatch* b) {
         // From (10, 0) to (0, 10) about (10, 0): radius 0 at the start.
         b->mutable_arcs(1)->mutable_centre()->set_x(10);
       },
       "moves.arcs[1].centre: a counterclockwise arc has a zero radius"},
      {"turns 0", [](pb::MoveBatch* b) { b->mutable_arcs(2)->set_turns(0); },
       "moves.arcs[2].turns must be in [1, 10000]"},
      {"turns negative",
       [](pb::MoveBatch* b) { b->mutable_arcs(2)->set_turns(-3); },
       "moves.arcs[2].turns must be in [1, 10000]"},
      {"NaN centre",
       [](pb::MoveBatch* b) {
         b->mutable_arcs(3)->mutable_centre()->set_z(
             std::numeric_limits<double>::quiet_NaN());
       },
       "moves.arcs[3].centre must be finite"},
      {"no centre",
       [](pb::MoveBatch* b) { b->mutable_arcs(4)->clear_centre(); },
       "moves.arcs[4].centre is required"},
      {"bad plane",
       [](pb::MoveBatch* b) {
         b->mutable_arcs(4)->set_plane(static_cast<pb::ArcPlane>(7));
       },
       "moves.arcs[4].plane 7 is not an ArcPlane"},
      {"too many chords",
       [](pb::MoveBatch* b) { b->mutable_arcs(2)->set_turns(10000); },
       "moves.arcs[2]: an arc needs"},
  };
  SimStream s(stub_.get(), "bad");
  size_t n = 0;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    pb::SimulateRequest r = ArcBatch(1);
    c.edit(r.mutable_moves());
    ASSERT_TRUE(s.Write(r));
    ASSERT_TRUE(s.WaitForCount(++n));
    const pb::SimulateResponse resp = s.responses().back();
    ASSERT_TRUE(resp.has_error());
    EXPECT_EQ(resp.error().code(),
              static_cast<int>(grpc::StatusCode::INVALID_ARGUMENT));
    EXPECT_EQ(resp.error().kind(), pb::REQUEST_KIND_MOVES);
    EXPECT_EQ(resp.error().request_id(), 1u);
    EXPECT_NE(resp.error().message().find(c.expect), std::string::npos)
        << resp.error().message();
  }
  EXPECT_EQ(GetSessionOrFail(stub_.get(), "bad").last_seq(), 0u);
  EXPECT_EQ(GetSessionOrFail(stub_.get(), "bad").moves_applied(), 0);
  // The stream and the seq are still good.
  ASSERT_TRUE(s.Write(ArcBatch(1)));
  ASSERT_TRUE(s.WaitForCount(++n));
  EXPECT_TRUE(s.responses().back().has_ack());
  EXPECT_TRUE(s.Finish().ok());
}

// A journaled session with arcs, restarted (the server stopped and started
// on its data directory, replaying the journal): the same tiles.
TEST(ArcsRestartTest, ReplayedArcSessionIsIdentical) {
  std::string tmpl = (std::filesystem::temp_directory_path() /
                      "swarf_arcs_restart_XXXXXX").string();
  const std::string dir = mkdtemp(tmpl.data());
  ServerOptions o;
  o.listen = "";
  o.persistence.data_dir = dir;
  o.persistence.sync = JournalSync::kOff;
  std::vector<std::string> before;
  {
    auto server = *SwarfServer::Start(o);
    auto stub = pb::Swarf::NewStub(server->InProcessChannel());
    Create(stub.get(), "journaled", 0.01);
    ASSERT_TRUE(Send(stub.get(), "journaled", ArcBatch(1)).has_ack());
    before = SerializedTiles(stub.get(), "journaled");
    server->Shutdown(absl::Seconds(1));
  }
  auto server = *SwarfServer::Start(o);
  auto stub = pb::Swarf::NewStub(server->InProcessChannel());
  const pb::Session s = GetSessionOrFail(stub.get(), "journaled");
  EXPECT_EQ(s.last_seq(), 1u);
  EXPECT_EQ(s.arc_tolerance(), 0.01);
  EXPECT_EQ(SerializedTiles(stub.get(), "journaled"), before);
  // The resent batch is recognised after the restart too.
  const pb::SimulateResponse again = Send(stub.get(), "journaled", ArcBatch(1));
  ASSERT_TRUE(again.has_ack()) << again.error().message();
  EXPECT_TRUE(again.ack().duplicate());
  server->Shutdown(absl::Seconds(1));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace swarf::server
