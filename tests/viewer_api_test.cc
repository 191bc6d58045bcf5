// The viewer's HTTP side without a browser (client/viewer/viewer.h): what it
// relays equals what the gRPC API answers (tiles, subsampled by its stride;
// only changed tiles after a version; Probe; marks; error map; the path),
// and bad requests get clear errors.
#include <cstring>
#include <map>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "client/cli/connection.h"
#include "client/viewer/viewer.h"
#include "design/design_mesh.h"
#include "google/protobuf/struct.pb.h"
#include "google/protobuf/util/json_util.h"
#include "gtest/gtest.h"
#include "httplib.h"

namespace swarf::cli {
namespace {

// A decoded /api/tiles tile.
struct PageTile {
  int32_t c0, r0, cols, rows;
  double version;
  std::vector<float> heights;
};

template <typename T>
T Take(const std::string& b, size_t* off) {
  T v;
  EXPECT_LE(*off + sizeof(T), b.size());
  std::memcpy(&v, b.data() + *off, sizeof(T));
  *off += sizeof(T);
  return v;
}

std::vector<PageTile> DecodeTiles(const std::string& b, uint32_t* stride) {
  size_t off = 0;
  const uint32_t count = Take<uint32_t>(b, &off);
  *stride = Take<uint32_t>(b, &off);
  Take<double>(b, &off);
  std::vector<PageTile> out(count);
  for (PageTile& t : out) {
    t.c0 = Take<int32_t>(b, &off);
    t.r0 = Take<int32_t>(b, &off);
    t.cols = Take<int32_t>(b, &off);
    t.rows = Take<int32_t>(b, &off);
    t.version = Take<double>(b, &off);
    t.heights.resize(static_cast<size_t>(t.cols) * t.rows);
    for (float& h : t.heights) h = Take<float>(b, &off);
  }
  EXPECT_EQ(off, b.size());
  return out;
}

google::protobuf::Struct Json(const std::string& text) {
  google::protobuf::Struct s;
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(text, &s).ok())
      << text;
  return s;
}

class ViewerApiTest : public ::testing::Test {
 protected:
  // A taylor session of nx x ny elements over [0, 150] x [0, 60].
  void SetUp() override {
    auto conn = Connection::Open("");
    ASSERT_TRUE(conn.ok());
    conn_ = *std::move(conn);
    pb::CreateSessionRequest req;
    req.set_session_id(id_);
    req.mutable_stock()->set_x1(150);
    req.mutable_stock()->set_y1(60);
    req.set_nx(1500);
    req.set_ny(600);
    req.add_tools()->set_id(1);
    req.mutable_tools(0)->mutable_ball()->set_radius(2);
    pb::Session s;
    auto ctx = conn_->Context(id_);
    ASSERT_TRUE(conn_->stub().CreateSession(ctx.get(), req, &s).ok());
  }

  // Streams a zigzag over y in [y0, y1] as one batch (continuing the path).
  void Cut(double y0, double y1) {
    PathRun run;
    run.tool_id = 1;
    run.reposition = !started_;
    pb::SimulateRequest req;
    pb::MoveBatch* b = req.mutable_moves();
    b->set_seq(++seq_);
    b->set_tool_id(1);
    b->set_reposition(run.reposition);
    for (double y = y0; y <= y1; y += 3) {
      run.points.push_back({5, y, -1 - y / 60});
      run.points.push_back({145, y + 1.5, -1.5});
    }
    for (const Vec3& p : run.points) {
      b->add_xyz(p.x);
      b->add_xyz(p.y);
      b->add_xyz(p.z);
    }
    auto ctx = conn_->Context(id_);
    auto stream = conn_->stub().Simulate(ctx.get());
    ASSERT_TRUE(stream->Write(req));
    pb::SimulateResponse resp;
    ASSERT_TRUE(stream->Read(&resp));
    ASSERT_TRUE(resp.has_ack()) << resp.DebugString();
    stream->WritesDone();
    ASSERT_TRUE(stream->Finish().ok());
    runs_.push_back(run);
    started_ = true;
  }

  pb::Session Session() {
    pb::GetSessionRequest req;
    req.set_session_id(id_);
    pb::Session s;
    auto ctx = conn_->Context(id_);
    EXPECT_TRUE(conn_->stub().GetSession(ctx.get(), req, &s).ok());
    return s;
  }

  std::unique_ptr<Viewer> StartViewer(ViewerPath path = {}) {
    ViewerOptions o;
    o.poll_seconds = 0.01;
    auto v = Viewer::Start(conn_.get(), id_, o, std::move(path));
    EXPECT_TRUE(v.ok()) << v.status();
    return v.ok() ? *std::move(v) : nullptr;
  }

  // Waits until the viewer holds the session's current version.
  void AwaitVersion(httplib::Client& http, uint64_t version) {
    for (int i = 0; i < 500; ++i) {
      auto r = http.Get("/api/state");
      if (r && r->status == 200 &&
          Json(r->body).fields().at("version").number_value() ==
              static_cast<double>(version)) {
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    FAIL() << "the viewer never reached version " << version;
  }

  // GetTiles (float heights) as tile index -> tile.
  std::map<std::pair<int, int>, pb::Tile> ApiTiles(uint64_t since) {
    pb::GetTilesRequest req;
    req.set_session_id(id_);
    req.set_since_version(since);
    auto ctx = conn_->Context(id_);
    auto reader = conn_->stub().GetTiles(ctx.get(), req);
    std::map<std::pair<int, int>, pb::Tile> out;
    pb::Tile t;
    while (reader->Read(&t)) out[{t.tx(), t.ty()}] = t;
    EXPECT_TRUE(reader->Finish().ok());
    return out;
  }

  const std::string id_ = "viewer-api";
  std::unique_ptr<Connection> conn_;
  std::vector<PathRun> runs_;
  bool started_ = false;
  uint64_t seq_ = 0;
};

TEST_F(ViewerApiTest, TilesAreTheApisSubsampledAndOnlyChangedOnesAfter) {
  Cut(5, 20);
  auto viewer = StartViewer();
  ASSERT_TRUE(viewer);
  httplib::Client http("127.0.0.1", viewer->port());
  const uint64_t v1 = Session().version();
  AwaitVersion(http, v1);

  auto all = http.Get("/api/tiles");
  ASSERT_TRUE(all && all->status == 200);
  uint32_t stride = 0;
  const std::vector<PageTile> tiles = DecodeTiles(all->body, &stride);
  // 1501 nodes along x: every 2nd node keeps the page under 1024 a side.
  EXPECT_EQ(stride, 2u);
  const auto api = ApiTiles(0);
  ASSERT_EQ(tiles.size(), api.size());
  for (const PageTile& t : tiles) {
    const int tx = t.c0 * 2 / 64, ty = t.r0 * 2 / 64;
    const pb::Tile& a = api.at({tx, ty});
    EXPECT_EQ(t.version, a.version());
    EXPECT_EQ(t.c0 * 2, a.i0());
    EXPECT_EQ(t.cols, (a.nx() + 1) / 2);
    EXPECT_EQ(t.rows, (a.ny() + 1) / 2);
    for (int r = 0; r < t.rows; ++r) {
      for (int c = 0; c < t.cols; ++c) {
        ASSERT_EQ(t.heights[r * t.cols + c], a.heights_f(2 * r * a.nx() + 2 * c))
            << "tile " << tx << "," << ty << " node " << c << "," << r;
      }
    }
  }

  // After more moves: exactly the tiles they changed.
  Cut(40, 50);
  const uint64_t v2 = Session().version();
  ASSERT_GT(v2, v1);
  AwaitVersion(http, v2);
  auto since = http.Get(("/api/tiles?since=" + std::to_string(v1)).c_str());
  ASSERT_TRUE(since && since->status == 200);
  std::set<std::pair<int, int>> got, want;
  for (const PageTile& t : DecodeTiles(since->body, &stride)) {
    got.insert({t.c0 * 2 / 64, t.r0 * 2 / 64});
  }
  for (const auto& [k, t] : ApiTiles(v1)) want.insert(k);
  EXPECT_FALSE(want.empty());
  EXPECT_LT(want.size(), api.size());
  EXPECT_EQ(got, want);
  auto none = http.Get(("/api/tiles?since=" + std::to_string(v2)).c_str());
  ASSERT_TRUE(none && none->status == 200);
  EXPECT_TRUE(DecodeTiles(none->body, &stride).empty());
}

TEST_F(ViewerApiTest, ProbeMarksErrorMapAndPathAreTheApis) {
  Cut(5, 30);
  ViewerPath path = ViewerPathOf(runs_);
  const int64_t moves = path.moves_total;
  auto viewer = StartViewer(path);
  ASSERT_TRUE(viewer);
  httplib::Client http("127.0.0.1", viewer->port());
  AwaitVersion(http, Session().version());

  for (const auto& [x, y] : std::vector<std::pair<double, double>>{
           {75.123456789, 12.5}, {5, 5}, {149.99, 59.99}, {100.25, 100}}) {
    pb::ProbeRequest req;
    req.set_session_id(id_);
    req.add_xy(x);
    req.add_xy(y);
    pb::ProbeResponse want;
    auto ctx = conn_->Context(id_);
    const grpc::Status st = conn_->stub().Probe(ctx.get(), req, &want);
    char q[128];
    std::snprintf(q, sizeof q, "/api/probe?x=%.17g&y=%.17g", x, y);
    auto r = http.Get(q);
    ASSERT_TRUE(r);
    if (!st.ok()) {  // outside the stock: the API's error, as HTTP
      EXPECT_EQ(r->status, 400) << r->body;
      EXPECT_EQ(r->body, st.error_message());
      continue;
    }
    ASSERT_EQ(r->status, 200) << r->body;
    const auto j = Json(r->body);
    EXPECT_EQ(j.fields().at("z").number_value(), want.heights(0));
    EXPECT_EQ(j.fields().at("owner").number_value(), want.owners(0));
  }
  for (const char* bad : {"/api/probe?x=1", "/api/probe?x=nan&y=1",
                          "/api/probe?x=abc&y=1", "/api/tiles?since=-1",
                          "/api/tiles?since=x"}) {
    auto r = http.Get(bad);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 400) << bad;
    EXPECT_FALSE(r->body.empty()) << bad;
  }

  // Marks: as many polylines (of 2+ vertices) as GetCuttingMarks gives.
  auto m = http.Get("/api/marks?min_angle=1");
  ASSERT_TRUE(m && m->status == 200);
  uint32_t count;
  std::memcpy(&count, m->body.data(), 4);
  {
    pb::GetCuttingMarksRequest req;
    req.set_session_id(id_);
    req.set_min_angle_deg(1);
    auto ctx = conn_->Context(id_);
    auto reader = conn_->stub().GetCuttingMarks(ctx.get(), req);
    uint32_t want = 0;
    pb::Polyline p;
    while (reader->Read(&p)) want += p.xyz_size() >= 6;
    ASSERT_TRUE(reader->Finish().ok());
    EXPECT_GT(want, 0u);
    EXPECT_EQ(count, want);
  }

  auto e = http.Get("/api/errormap?samples=3");
  ASSERT_TRUE(e && e->status == 200);
  size_t off = 0;
  const uint32_t cols = Take<uint32_t>(e->body, &off);
  const uint32_t rows = Take<uint32_t>(e->body, &off);
  EXPECT_EQ(cols, 1024u);
  EXPECT_EQ(rows, 600u);
  EXPECT_EQ(e->body.size(), 16 + 4ull * cols * rows);
  auto bad_samples = http.Get("/api/errormap?samples=1000");
  ASSERT_TRUE(bad_samples);
  EXPECT_EQ(bad_samples->status, 400);

  // The path: every point once all moves are in, as floats.
  auto p = http.Get("/api/path?from=3");
  ASSERT_TRUE(p && p->status == 200);
  off = 0;
  const uint32_t from = Take<uint32_t>(p->body, &off);
  const uint32_t n = Take<uint32_t>(p->body, &off);
  EXPECT_EQ(from, 3u);
  ASSERT_EQ(n, path.points.size());
  ASSERT_EQ(p->body.size(), 8 + 12ull * (n - from));
  for (uint32_t k = from; k < n; ++k) {
    EXPECT_EQ(Take<float>(p->body, &off), static_cast<float>(path.points[k].x));
    EXPECT_EQ(Take<float>(p->body, &off), static_cast<float>(path.points[k].y));
    EXPECT_EQ(Take<float>(p->body, &off), static_cast<float>(path.points[k].z));
  }
  const auto state = Json(http.Get("/api/state")->body);
  EXPECT_EQ(state.fields().at("moves").number_value(), moves);
  EXPECT_EQ(state.fields().at("moves_total").number_value(), moves);
  EXPECT_FALSE(state.fields().at("finished").bool_value());
  EXPECT_EQ(state.fields().at("tool").number_value(), 1);
  viewer->MarkFinished();
  EXPECT_TRUE(Json(http.Get("/api/state")->body)
                  .fields().at("finished").bool_value());

  // The page and three.js, served from here.
  auto page = http.Get("/");
  ASSERT_TRUE(page && page->status == 200);
  EXPECT_NE(page->body.find("three/three.min.js"), std::string::npos);
  auto three = http.Get("/three/three.min.js");
  ASSERT_TRUE(three && three->status == 200);
  EXPECT_NE(three->body.find("REVISION"), std::string::npos);
  auto orbit = http.Get("/three/OrbitControls.js");
  ASSERT_TRUE(orbit && orbit->status == 200);
  EXPECT_NE(orbit->body.find("OrbitControls"), std::string::npos);
  // Addressed by another name (DNS rebinding): refused.
  auto rebound = http.Get("/api/state", {{"Host", "evil.example:80"}});
  ASSERT_TRUE(rebound);
  EXPECT_EQ(rebound->status, 403);
  httplib::Client by_name("localhost", viewer->port());
  auto local = by_name.Get("/api/state");
  ASSERT_TRUE(local);
  EXPECT_EQ(local->status, 200);
}

// The page draws every tool from /api/session: each shape with its
// dimensions, as the API gives them.
// The design: the session's deviation tiles at the display nodes, the
// verdict, the mesh for the overlay, and the line under the pointer.
TEST_F(ViewerApiTest, DeviationDesignAndLineAreTheApis) {
  Cut(5, 30);
  // Without a design: no deviation colouring offered, the layer refused.
  {
    auto plain = StartViewer(ViewerPathOf(runs_));
    ASSERT_TRUE(plain);
    httplib::Client http("127.0.0.1", plain->port());
    auto s = http.Get("/api/session");
    ASSERT_TRUE(s);
    EXPECT_FALSE(Json(s->body).fields().at("design").bool_value());
    auto d = http.Get("/api/deviation");
    ASSERT_TRUE(d);
    EXPECT_EQ(d->status, 400) << d->body;  // FAILED_PRECONDITION
    auto m = http.Get("/api/design");
    ASSERT_TRUE(m);
    EXPECT_EQ(m->status, 404) << m->body;
  }
  // A level design at z = -1.25 over the stock, set on the session.
  std::vector<double> soup = {-1, -1, -1.25, 151, -1, -1.25, 151, 61, -1.25,
                              -1, -1, -1.25, 151, 61, -1.25, -1, 61, -1.25};
  const design::DesignMesh mesh = *design::MeshFromSoup(soup, "level");
  pb::SetDesignRequest up;
  up.set_session_id(id_);
  up.set_data(design::ToBinaryStl(mesh));
  up.set_last(true);
  pb::DesignInfo info;
  {
    auto ctx = conn_->Context(id_);
    ASSERT_TRUE(conn_->stub().SetDesign(ctx.get(), up, &info).ok());
  }
  ViewerPath path = ViewerPathOf(runs_);
  for (int64_t k = 0; k < path.moves_total; ++k) {
    path.move_lines.push_back({0, static_cast<int32_t>(1000 + k)});
  }
  path.sources = {"prog.nc"};
  path.design = &mesh;
  path.tolerance = 0.05;
  auto viewer = StartViewer(path);
  ASSERT_TRUE(viewer);
  httplib::Client http("127.0.0.1", viewer->port());
  AwaitVersion(http, Session().version());
  auto s = http.Get("/api/session");
  ASSERT_TRUE(s);
  const auto session = Json(s->body);
  EXPECT_TRUE(session.fields().at("design").bool_value());
  EXPECT_TRUE(session.fields().at("design_mesh").bool_value());
  const int stride = session.fields().at("stride").number_value();
  const int cols = session.fields().at("cols").number_value();
  const int rows = session.fields().at("rows").number_value();

  auto d = http.Get("/api/deviation");
  ASSERT_TRUE(d);
  ASSERT_EQ(d->status, 200) << d->body;
  size_t off = 0;
  EXPECT_EQ(Take<uint32_t>(d->body, &off), static_cast<uint32_t>(cols));
  EXPECT_EQ(Take<uint32_t>(d->body, &off), static_cast<uint32_t>(rows));
  EXPECT_EQ(Take<float>(d->body, &off), 0.0f);    // allowance
  EXPECT_EQ(Take<float>(d->body, &off), 0.05f);   // tolerance
  Take<float>(d->body, &off);
  Take<float>(d->body, &off);
  const float gouge = Take<float>(d->body, &off);
  pb::GetDeviationRequest dreq;
  dreq.set_session_id(id_);
  dreq.mutable_options()->mutable_tolerance()->set_value(0.05);
  // As the viewer asks: at the nodes.
  dreq.mutable_options()->mutable_samples_per_edge()->set_value(0);
  pb::Deviation want;
  {
    auto ctx = conn_->Context(id_);
    ASSERT_TRUE(conn_->stub().GetDeviation(ctx.get(), dreq, &want).ok());
  }
  EXPECT_EQ(gouge, static_cast<float>(want.gouge_max()));
  EXPECT_EQ(Take<uint32_t>(d->body, &off), want.ok() ? 1u : 0u);
  ASSERT_EQ(d->body.size(), off + sizeof(float) * cols * rows);
  // Every display node is the API's deviation at node (c, r) * stride.
  pb::GetTilesRequest treq;
  treq.set_session_id(id_);
  treq.set_precision(pb::PRECISION_FLOAT);
  treq.set_include_deviation(true);
  std::map<std::pair<int, int>, float> api;
  {
    auto ctx = conn_->Context(id_);
    auto reader = conn_->stub().GetTiles(ctx.get(), treq);
    pb::Tile t;
    while (reader->Read(&t)) {
      for (int j = 0; j < t.ny(); ++j) {
        for (int i = 0; i < t.nx(); ++i) {
          api[{t.i0() + i, t.j0() + j}] = t.deviation(j * t.nx() + i);
        }
      }
    }
    ASSERT_TRUE(reader->Finish().ok());
  }
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      EXPECT_EQ(Take<float>(d->body, &off), (api[{c * stride, r * stride}]))
          << c << "," << r;
    }
  }
  // The overlay's triangles.
  auto m = http.Get("/api/design");
  ASSERT_TRUE(m);
  ASSERT_EQ(m->status, 200);
  ASSERT_EQ(m->body.size(), 4u + 2 * 36);
  size_t moff = 0;
  EXPECT_EQ(Take<uint32_t>(m->body, &moff), 2u);
  // The line under the pointer: the owner's line.
  auto p = http.Get("/api/probe?x=75&y=12");
  ASSERT_TRUE(p);
  ASSERT_EQ(p->status, 200) << p->body;
  const auto probe = Json(p->body);
  const double owner = probe.fields().at("owner").number_value();
  ASSERT_GE(owner, 0);
  EXPECT_EQ(probe.fields().at("line").number_value(), 1000 + owner);
  EXPECT_EQ(probe.fields().at("file").string_value(), "prog.nc");
}

// Safety findings and air moves handed to the viewer come back to the page
// as they were, and the state counts them.
TEST_F(ViewerApiTest, SafetyMarkersAndAirMovesReachThePage) {
  Cut(5, 10);
  auto viewer = StartViewer(ViewerPathOf(runs_));
  ASSERT_TRUE(viewer);
  httplib::Client http("127.0.0.1", viewer->port());
  viewer->AddSafety({{{1.5, 2.5, -0.25}, "rapid_cuts", "prog.nc", 42, 0.25, 3.5}},
                    {{{0, 0, -1}, {10, 0, -1}}});
  auto st = http.Get("/api/state");
  ASSERT_TRUE(st);
  EXPECT_EQ(Json(st->body).fields().at("safety").number_value(), 2);
  auto r = http.Get("/api/safety");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200);
  const auto j = Json(r->body);
  const auto& markers = j.fields().at("markers").list_value();
  ASSERT_EQ(markers.values_size(), 1);
  const auto& m = markers.values(0).struct_value().fields();
  EXPECT_EQ(m.at("kind").string_value(), "rapid_cuts");
  EXPECT_EQ(m.at("file").string_value(), "prog.nc");
  EXPECT_EQ(m.at("line").number_value(), 42);
  EXPECT_EQ(m.at("x").number_value(), 1.5);
  EXPECT_EQ(m.at("depth").number_value(), 0.25);
  const auto& air = j.fields().at("air").list_value();
  ASSERT_EQ(air.values_size(), 6);
  EXPECT_EQ(air.values(3).number_value(), 10);
}

TEST_F(ViewerApiTest, SessionListsEveryCutterShape) {
  pb::CreateSessionRequest req;
  req.set_session_id("viewer-shapes");
  req.mutable_stock()->set_x1(10);
  req.mutable_stock()->set_y1(10);
  req.set_nx(10);
  req.set_ny(10);
  for (int k = 1; k <= 5; ++k) req.add_tools()->set_id(k);
  req.mutable_tools(0)->mutable_ball()->set_radius(2);
  req.mutable_tools(1)->mutable_flat()->set_radius(1.5);
  req.mutable_tools(2)->mutable_bull_nose()->set_radius(3);
  req.mutable_tools(2)->mutable_bull_nose()->set_corner_radius(0.5);
  req.mutable_tools(3)->mutable_cone()->set_radius(3);
  req.mutable_tools(3)->mutable_cone()->set_half_angle_deg(45);
  req.mutable_tools(3)->mutable_cone()->set_tip_radius(0.1);
  req.mutable_tools(4)->mutable_tapered_ball()->set_radius(2);
  req.mutable_tools(4)->mutable_tapered_ball()->set_tip_radius(0.25);
  req.mutable_tools(4)->mutable_tapered_ball()->set_half_angle_deg(5);
  {
    pb::Session s;
    auto ctx = conn_->Context("viewer-shapes");
    ASSERT_TRUE(conn_->stub().CreateSession(ctx.get(), req, &s).ok());
  }
  ViewerOptions o;
  auto viewer = Viewer::Start(conn_.get(), "viewer-shapes", o);
  ASSERT_TRUE(viewer.ok()) << viewer.status();
  httplib::Client http("127.0.0.1", (*viewer)->port());
  auto r = http.Get("/api/session");
  ASSERT_TRUE(r && r->status == 200);
  const auto session = Json(r->body);
  const auto& tools = session.fields().at("tools").list_value().values();
  ASSERT_EQ(tools.size(), 5);
  auto field = [&](int k, const char* name) {
    return tools[k].struct_value().fields().at(name);
  };
  const char* shapes[] = {"ball", "flat", "bull_nose", "cone", "tapered_ball"};
  for (int k = 0; k < 5; ++k) {
    EXPECT_EQ(field(k, "id").number_value(), k + 1);
    EXPECT_EQ(field(k, "shape").string_value(), shapes[k]);
  }
  EXPECT_EQ(field(0, "radius").number_value(), 2);
  EXPECT_EQ(field(1, "radius").number_value(), 1.5);
  EXPECT_EQ(field(2, "corner_radius").number_value(), 0.5);
  EXPECT_EQ(field(3, "half_angle_deg").number_value(), 45);
  EXPECT_EQ(field(3, "tip_radius").number_value(), 0.1);
  EXPECT_EQ(field(4, "radius").number_value(), 2);
  EXPECT_EQ(field(4, "tip_radius").number_value(), 0.25);
  EXPECT_EQ(field(4, "half_angle_deg").number_value(), 5);
}

TEST_F(ViewerApiTest, StartErrorsNameWhatIsWrong) {
  ViewerOptions o;
  auto missing = Viewer::Start(conn_.get(), "no-such-session", o);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("no-such-session"),
            std::string::npos);
  auto first = StartViewer();
  ASSERT_TRUE(first);
  o.port = first->port();
  auto taken = Viewer::Start(conn_.get(), id_, o);
  ASSERT_FALSE(taken.ok());
  EXPECT_EQ(taken.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_NE(taken.status().message().find(std::to_string(o.port)),
            std::string::npos);
}

}  // namespace
}  // namespace swarf::cli
