// The design over the API: SetDesign in chunks, GetDeviation against the
// same comparison run on the core directly (bit-identical), bad uploads
// (exact status codes, the session and its design unharmed), and a real
// swarfd killed with SIGKILL and restarted: the design and the deviation
// come back identical.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "client/outputs/deviation.h"
#include "client/outputs/surface_grid.h"
#include "core/workpiece.h"
#include "design/closest_point.h"
#include "design/design_mesh.h"
#include "design/top_envelope.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "swarf/v1/swarf.grpc.pb.h"
#include "tests/server_test_util.h"
#include "tests/sim_stream.h"
#include "tests/swarfd_process.h"

namespace swarf::server {
namespace {

namespace pb = ::swarf::v1;
using ::swarf::testing::ForSession;
using ::swarf::testing::SetDeadline;
using ::swarf::testing::SetStock;
using ::swarf::testing::SimStream;

constexpr int32_t kTool = 7;
constexpr double kRadius = 2;
constexpr double kFloor = -1;
constexpr int kDeepPass = 9;  // run 0.25 mm deeper
const StockSpec kStock{0, 0, 20, 20, 0, 200, 200};

// Raster passes along x at y = 0, 1, ..., 20 as one polyline (the links at
// x = -3 and 23 lie beside the stock), pass kDeepPass 0.25 mm deeper.
std::vector<Vec3> RasterPoints() {
  std::vector<Vec3> p;
  for (int k = 0; k <= 20; ++k) {
    const double z = k == kDeepPass ? kFloor - 0.25 : kFloor;
    const double xa = k % 2 ? 23 : -3, xb = k % 2 ? -3 : 23;
    p.push_back({xa, double(k), z});
    p.push_back({xb, double(k), z});
  }
  return p;
}

// The design: a wavy floor around z = -1 as a height field (2 x 60^2
// triangles), so that uploads take many chunks.
design::DesignMesh Floor() {
  std::vector<double> soup;
  const int q = 60;
  const double h = 30.0 / q;
  auto z = [](double x, double y) {
    return kFloor + 0.01 * std::sin(x) * std::cos(y);
  };
  auto add = [&](double x, double y) {
    soup.insert(soup.end(), {x, y, z(x, y)});
  };
  for (int j = 0; j < q; ++j) {
    for (int i = 0; i < q; ++i) {
      const double x0 = -5 + i * h, y0 = -5 + j * h;
      add(x0, y0), add(x0 + h, y0), add(x0 + h, y0 + h);
      add(x0, y0), add(x0 + h, y0 + h), add(x0, y0 + h);
    }
  }
  return *design::MeshFromSoup(soup, "floor");
}

// SetDesign of `bytes` in chunks of `chunk` bytes; the last answer.
grpc::Status Upload(pb::Swarf::Stub* stub, const std::string& id,
                    const std::string& bytes, size_t chunk,
                    pb::DesignInfo* info) {
  for (size_t off = 0; off < bytes.size() || off == 0; off += chunk) {
    pb::SetDesignRequest req;
    req.set_session_id(id);
    req.set_offset(off);
    req.set_data(bytes.substr(off, chunk));
    req.set_last(off + chunk >= bytes.size());
    req.set_name("floor.stl");
    grpc::ClientContext ctx;
    SetDeadline(&ctx);
    grpc::Status st = stub->SetDesign(&ctx, req, info);
    if (!st.ok() || req.last()) return st;
  }
  return grpc::Status::OK;
}

// A guarded session over `stock` with the ball kTool.
void Create(pb::Swarf::Stub* stub, const std::string& id,
            const StockSpec& stock = kStock) {
  pb::CreateSessionRequest create;
  create.set_session_id(id);
  SetStock(stock, &create);
  create.set_scheme(pb::SCHEME_GUARDED);
  pb::Tool* tool = create.add_tools();
  tool->set_id(kTool);
  tool->mutable_ball()->set_radius(kRadius);
  pb::Session session;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  ASSERT_TRUE(stub->CreateSession(&ctx, create, &session).ok());
}

// Create, then the whole raster in one batch.
void CreateAndCut(pb::Swarf::Stub* stub, const std::string& id,
                  const StockSpec& stock = kStock) {
  Create(stub, id, stock);
  std::vector<double> xyz;
  for (const Vec3& p : RasterPoints()) xyz.insert(xyz.end(), {p.x, p.y, p.z});
  SimStream s(stub, id);
  ASSERT_TRUE(s.Write(::swarf::testing::MovesRequest(1, kTool, xyz)));
  ASSERT_TRUE(s.WaitForCount(1));
  EXPECT_TRUE(s.Finish().ok());
}

grpc::Status Deviation(pb::Swarf::Stub* stub, const std::string& id,
                       pb::Deviation* out, double tolerance = 0.05) {
  pb::GetDeviationRequest req;
  req.set_session_id(id);
  req.mutable_options()->mutable_tolerance()->set_value(tolerance);
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  return stub->GetDeviation(&ctx, req, out);
}

// The same comparison on the core directly.
cli::DeviationReport Reference(const design::DesignMesh& mesh,
                               const StockSpec& stock = kStock) {
  auto wp = *Workpiece::Create(stock, SchemeKind::kGuarded);
  const std::vector<Vec3> p = RasterPoints();
  std::vector<Move> moves;
  for (size_t k = 1; k < p.size(); ++k) {
    moves.emplace_back(p[k - 1], p[k], Cutter::Ball(kRadius));
  }
  EXPECT_TRUE(wp->Apply(moves).ok());
  auto grid = *cli::SurfaceGrid::FromWorkpiece(*wp);
  auto env = *design::TopEnvelope::Build(mesh, grid.geometry());
  auto index = *design::ClosestPointIndex::Build(mesh);
  std::vector<cli::SourceLine> ids(moves.size());
  for (size_t k = 0; k < ids.size(); ++k) ids[k] = {0, int32_t(k)};
  cli::DeviationOptions o;
  o.tolerance = 0.05;
  return *cli::MeasureDeviation(grid, env, *index, ids, o);
}

void ExpectSame(const pb::Deviation& d, const cli::DeviationReport& r) {
  EXPECT_EQ(d.nodes(), r.nodes);
  EXPECT_EQ(d.samples(), r.samples);
  EXPECT_EQ(d.gouge_max(), r.gouge_max);
  EXPECT_EQ(d.gouge_x(), r.gouge_x);
  EXPECT_EQ(d.gouge_y(), r.gouge_y);
  EXPECT_EQ(d.gouge_move(), r.gouge_move);
  EXPECT_EQ(d.gouge_volume_mm3(), r.gouge_volume);
  EXPECT_EQ(d.excess_max(), r.excess_max);
  EXPECT_EQ(d.excess_mean(), r.excess_mean);
  EXPECT_EQ(d.normal_gouge_max(), r.normal_gouge_max);
  EXPECT_EQ(d.normal_excess_max(), r.normal_excess_max);
  EXPECT_EQ(d.out_of_tolerance_area_mm2(), r.out_area_mm2);
  EXPECT_EQ(d.ok(), r.ok);
  ASSERT_EQ(d.gouge_moves_size(), static_cast<int>(r.gouge_lines.size()));
  for (int k = 0; k < d.gouge_moves_size(); ++k) {
    EXPECT_EQ(d.gouge_moves(k).move(), r.gouge_lines[k].line);
    EXPECT_EQ(d.gouge_moves(k).depth(), r.gouge_lines[k].depth);
    EXPECT_EQ(d.gouge_moves(k).area_mm2(), r.gouge_lines[k].area_mm2);
  }
}

class DesignApiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ServerOptions o;
    o.listen = "";
    o.limits.max_design_bytes = 1 << 20;
    server_ = *SwarfServer::Start(o);
    stub_ = pb::Swarf::NewStub(server_->InProcessChannel());
  }
  std::unique_ptr<SwarfServer> server_;
  std::unique_ptr<pb::Swarf::Stub> stub_;
};

TEST_F(DesignApiTest, ChunkedDesignGivesTheCoresDeviationBitForBit) {
  CreateAndCut(stub_.get(), "d1");
  pb::Deviation none;
  EXPECT_EQ(Deviation(stub_.get(), "d1", &none).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  {
    pb::GetTilesRequest treq;
    treq.set_include_deviation(true);
    std::vector<pb::Tile> tiles;
    grpc::ClientContext tctx;
    EXPECT_EQ(::swarf::testing::CollectTiles(stub_.get(), &tctx, "d1", treq,
                                             &tiles).error_code(),
              grpc::StatusCode::FAILED_PRECONDITION);
  }
  const design::DesignMesh mesh = Floor();
  const std::string stl = design::ToBinaryStl(mesh);
  pb::DesignInfo info;
  ASSERT_TRUE(Upload(stub_.get(), "d1", stl, 4096, &info).ok());
  EXPECT_TRUE(info.placed());
  EXPECT_EQ(info.received(), stl.size());
  EXPECT_EQ(info.triangles(), 7200);
  EXPECT_EQ(info.covered_nodes(), 201 * 201);
  pb::Deviation d;
  ASSERT_TRUE(Deviation(stub_.get(), "d1", &d).ok());
  // The STL holds floats: the reference reads the same file.
  const design::DesignMesh read = *design::ParseStl(stl, "floor.stl");
  ExpectSame(d, Reference(read));
  // The deep pass (move 2 * 9 + 1: each pass is one move, each link one).
  EXPECT_FALSE(d.ok());
  ASSERT_GE(d.gouge_moves_size(), 1);
  EXPECT_EQ(d.gouge_moves(0).move(), 2 * kDeepPass);
  EXPECT_NEAR(d.gouge_moves(0).depth(), 0.25, 0.011);
  EXPECT_EQ(d.gouge_move(), 2 * kDeepPass);
  // Deviation tiles: each node's height less the envelope there.
  auto env = *design::TopEnvelope::Build(read, GridGeometry(kStock));
  pb::GetTilesRequest treq;
  treq.set_precision(pb::PRECISION_DOUBLE);
  treq.set_include_deviation(true);
  std::vector<pb::Tile> tiles;
  grpc::ClientContext tctx;
  ASSERT_TRUE(::swarf::testing::CollectTiles(stub_.get(), &tctx, "d1", treq,
                                             &tiles).ok());
  ASSERT_FALSE(tiles.empty());
  int64_t checked = 0;
  float deepest = 0;
  for (const pb::Tile& t : tiles) {
    ASSERT_EQ(t.deviation_size(), t.nx() * t.ny());
    for (int32_t j = 0; j < t.ny(); ++j) {
      for (int32_t i = 0; i < t.nx(); ++i) {
        const int k = j * t.nx() + i;
        EXPECT_EQ(t.deviation(k),
                  static_cast<float>(t.heights_d(k) -
                                     env.AtNode(t.i0() + i, t.j0() + j)));
        deepest = std::min(deepest, t.deviation(k));
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, 201 * 201);
  EXPECT_NEAR(deepest, -d.gouge_max(), 1e-6);
}

// A grid the server reads in two bands (1201 x 1201 nodes, bands of about
// 1 M nodes, whole tile rows): the figures are still the core's whole-grid
// comparison's, bit for bit.
TEST_F(DesignApiTest, BandedDeviationGivesTheWholeGridsFigures) {
  const StockSpec fine{0, 0, 20, 20, 0, 1200, 1200};
  CreateAndCut(stub_.get(), "fine", fine);
  const std::string stl = design::ToBinaryStl(Floor());
  pb::DesignInfo info;
  ASSERT_TRUE(Upload(stub_.get(), "fine", stl, 1 << 19, &info).ok());
  pb::Deviation d;
  ASSERT_TRUE(Deviation(stub_.get(), "fine", &d).ok());
  EXPECT_EQ(d.nodes(), 1201 * 1201);
  EXPECT_GT(d.gouge_moves_size(), 0);
  ExpectSame(d, Reference(*design::ParseStl(stl, "floor.stl"), fine));
}

// A DeviationRequest on the Simulate stream sees exactly the batches sent
// before it: after the first half of the raster nothing gouges, after the
// deep pass it does, with GetDeviation's figures.
TEST_F(DesignApiTest, DeviationOnTheStreamFollowsTheBatches) {
  Create(stub_.get(), "d3");
  pb::DesignInfo info;
  ASSERT_TRUE(Upload(stub_.get(), "d3", design::ToBinaryStl(Floor()), 65536,
                     &info).ok());
  const std::vector<Vec3> p = RasterPoints();
  auto batch = [&](uint64_t seq, size_t from, size_t to) {
    std::vector<double> xyz;
    for (size_t k = from; k < to; ++k) xyz.insert(xyz.end(), {p[k].x, p[k].y, p[k].z});
    return ::swarf::testing::MovesRequest(seq, kTool, xyz);
  };
  auto dev_request = [](uint64_t id) {
    pb::SimulateRequest r;
    r.mutable_deviation()->set_request_id(id);
    r.mutable_deviation()->mutable_tolerance()->set_value(0.05);
    return r;
  };
  SimStream s(stub_.get(), "d3");
  // Passes 0..8 (points 0..17), then the rest (the deep pass 9 is next).
  ASSERT_TRUE(s.Write(batch(1, 0, 18)));
  ASSERT_TRUE(s.Write(dev_request(101)));
  ASSERT_TRUE(s.Write(batch(2, 17, p.size())));
  ASSERT_TRUE(s.Write(dev_request(102)));
  ASSERT_TRUE(s.WaitForCount(4));
  ASSERT_TRUE(s.Finish().ok());
  const auto responses = s.responses();
  ASSERT_EQ(responses.size(), 4u);
  ASSERT_TRUE(responses[1].has_deviation()) << responses[1].DebugString();
  ASSERT_TRUE(responses[3].has_deviation()) << responses[3].DebugString();
  EXPECT_EQ(responses[1].deviation().request_id(), 101u);
  EXPECT_LT(responses[1].deviation().gouge_max(), 0.02);
  EXPECT_EQ(responses[1].deviation().gouge_moves_size(), 0);
  const pb::Deviation& last = responses[3].deviation();
  EXPECT_EQ(last.request_id(), 102u);
  pb::Deviation unary;
  ASSERT_TRUE(Deviation(stub_.get(), "d3", &unary).ok());
  pb::Deviation same = last;
  same.set_request_id(0);
  EXPECT_EQ(same.SerializeAsString(), unary.SerializeAsString());
  EXPECT_GT(last.gouge_max(), 0.2);
  // Without a design: that request's error, the stream goes on.
  Create(stub_.get(), "d4");
  SimStream s2(stub_.get(), "d4");
  ASSERT_TRUE(s2.Write(dev_request(7)));
  ASSERT_TRUE(s2.Write(batch(1, 0, 4)));
  ASSERT_TRUE(s2.WaitForCount(2));
  ASSERT_TRUE(s2.Finish().ok());
  const auto r2 = s2.responses();
  ASSERT_TRUE(r2[0].has_error());
  EXPECT_EQ(r2[0].error().request_id(), 7u);
  EXPECT_EQ(r2[0].error().kind(), pb::REQUEST_KIND_DEVIATION);
  EXPECT_EQ(r2[0].error().code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_TRUE(r2[1].has_ack());
}

TEST_F(DesignApiTest, BadUploadsAreRefusedAndLeaveTheDesign) {
  CreateAndCut(stub_.get(), "d2");
  const std::string stl = design::ToBinaryStl(Floor());
  pb::DesignInfo info;
  ASSERT_TRUE(Upload(stub_.get(), "d2", stl, 100000, &info).ok());
  pb::Deviation before;
  ASSERT_TRUE(Deviation(stub_.get(), "d2", &before).ok());
  auto code = [&](const std::string& bytes, size_t chunk) {
    pb::DesignInfo i;
    return Upload(stub_.get(), "d2", bytes, chunk, &i).error_code();
  };
  // Not STL or STEP; NaN; outside the stock; over --max_design_mb.
  EXPECT_EQ(code("G0 X1 Y2 Z3\nG1 Z-1\n", 8),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code("solid a\nfacet normal 0 0 1\nouter loop\nvertex 0 0 nan\n"
                 "vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid\n",
                 30),
            grpc::StatusCode::INVALID_ARGUMENT);
  std::vector<double> far = {100, 100, 0, 101, 100, 0, 100, 101, 0};
  EXPECT_EQ(code(design::ToBinaryStl(*design::MeshFromSoup(far, "far")), 50),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(code(std::string((1 << 20) + 1, 'x'), 1 << 19),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  // A chunk at the wrong offset.
  {
    pb::SetDesignRequest req;
    req.set_session_id("d2");
    req.set_offset(0);
    req.set_data("solid x\n");
    grpc::ClientContext c1;
    SetDeadline(&c1);
    ASSERT_TRUE(stub_->SetDesign(&c1, req, &info).ok());
    EXPECT_EQ(info.received(), 8u);
    req.set_offset(100);
    grpc::ClientContext c2;
    SetDeadline(&c2);
    grpc::Status st = stub_->SetDesign(&c2, req, &info);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_NE(st.error_message().find("holds 8 bytes"), std::string::npos)
        << st.error_message();
  }
  // The design and the deviation are as before.
  pb::Deviation after;
  ASSERT_TRUE(Deviation(stub_.get(), "d2", &after).ok());
  EXPECT_EQ(after.SerializeAsString(), before.SerializeAsString());
  // No such session; bad options.
  pb::Deviation d;
  EXPECT_EQ(Deviation(stub_.get(), "nope", &d).error_code(),
            grpc::StatusCode::NOT_FOUND);
  pb::GetDeviationRequest req;
  req.set_session_id("d2");
  req.mutable_options()->mutable_samples_per_edge()->set_value(65);
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  EXPECT_EQ(stub_->GetDeviation(&ctx, req, &d).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  pb::DeviationMove unused;
  (void)unused;
}

// A real swarfd, killed with SIGKILL after the design was set, restarted on
// its data directory.
TEST(DesignRestartTest, KilledServerRestoresTheDesignAndTheDeviation) {
  std::string tmpl = (std::filesystem::temp_directory_path() /
                      "swarf_design_restart_XXXXXX").string();
  const std::string dir = mkdtemp(tmpl.data());
  const std::string log = dir + "/swarfd.log";
  pb::Deviation before;
  {
    ::swarf::testing::SwarfdProcess p(dir + "/data", log, {});
    ASSERT_NE(p.port(), 0) << ::swarf::testing::ReadFileText(log);
    auto stub = pb::Swarf::NewStub(grpc::CreateChannel(
        "127.0.0.1:" + std::to_string(p.port()),
        grpc::InsecureChannelCredentials()));
    CreateAndCut(stub.get(), "r1");
    pb::DesignInfo info;
    ASSERT_TRUE(Upload(stub.get(), "r1", design::ToBinaryStl(Floor()), 20000,
                       &info).ok());
    ASSERT_TRUE(Deviation(stub.get(), "r1", &before).ok());
    p.Kill();
  }
  // A log of its own: the port is read back from it.
  const std::string log2 = dir + "/swarfd2.log";
  ::swarf::testing::SwarfdProcess p(dir + "/data", log2, {});
  ASSERT_NE(p.port(), 0) << ::swarf::testing::ReadFileText(log2);
  auto stub = pb::Swarf::NewStub(
      grpc::CreateChannel("127.0.0.1:" + std::to_string(p.port()),
                          grpc::InsecureChannelCredentials()));
  pb::Deviation after;
  grpc::Status st = Deviation(stub.get(), "r1", &after);
  ASSERT_TRUE(st.ok()) << st.error_message() << "\n"
                       << ::swarf::testing::ReadFileText(log2);
  EXPECT_EQ(after.SerializeAsString(), before.SerializeAsString());
  EXPECT_GT(after.gouge_max(), 0.2);
  p.Stop();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace swarf::server
