// Writes the seed corpus of request_fuzz into the directory given: one file
// per seed, the kind byte then the serialized message(s) (see
// request_fuzz.cc). Run at build time, so the seeds follow the proto.

#include <limits>
#include <string>
#include <vector>

#include "google/protobuf/io/coded_stream.h"
#include "google/protobuf/io/zero_copy_stream_impl_lite.h"
#include "swarf/v1/swarf.pb.h"
#include "tests/fuzz/seed_dir.h"

namespace {

namespace pb = ::swarf::v1;

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// Kind bytes (request_fuzz.cc); +8 selects the zmap scheme.
constexpr char kCreate = 0, kStream = 1, kTiles = 2, kStats = 3, kMarks = 4,
               kProbe = 5, kZmap = 8;

std::string Stream(const std::vector<pb::SimulateRequest>& reqs) {
  std::string out;
  {
    google::protobuf::io::StringOutputStream s(&out);
    google::protobuf::io::CodedOutputStream c(&s);
    for (const auto& r : reqs) {
      c.WriteVarint32(static_cast<uint32_t>(r.ByteSizeLong()));
      r.SerializeToCodedStream(&c);
    }
  }
  return out;
}

pb::CreateSessionRequest Create(double x1, double y1, int nx, int ny) {
  pb::CreateSessionRequest r;
  r.set_session_id("seed");
  r.mutable_stock()->set_x1(x1);
  r.mutable_stock()->set_y1(y1);
  r.set_nx(nx);
  r.set_ny(ny);
  pb::Tool* t = r.add_tools();
  t->set_id(1);
  t->mutable_ball()->set_radius(1);
  return r;
}

pb::SimulateRequest Batch(uint64_t seq, int tool, std::vector<double> xyz,
                          bool reposition = false) {
  pb::SimulateRequest r;
  r.mutable_moves()->set_seq(seq);
  r.mutable_moves()->set_tool_id(tool);
  r.mutable_moves()->set_reposition(reposition);
  for (double v : xyz) r.mutable_moves()->add_xyz(v);
  return r;
}

pb::SimulateRequest Tiles(uint64_t id, bool region, bool derivatives) {
  pb::SimulateRequest r;
  pb::TileRequest* t = r.mutable_tiles();
  t->set_request_id(id);
  t->set_precision(pb::PRECISION_DOUBLE);
  t->set_include_derivatives(derivatives);
  t->set_include_owners(true);
  if (region) {
    pb::Rect* g = t->mutable_selection()->mutable_region();
    g->set_x0(2);
    g->set_y0(2);
    g->set_x1(9);
    g->set_y1(3);
  } else {
    pb::TileIndex* i = t->mutable_selection()->add_tiles();
    i->set_tx(1);
    i->set_ty(0);
  }
  return r;
}

pb::SimulateRequest Stats(uint64_t id, int cols, int rows) {
  pb::SimulateRequest r;
  r.mutable_stats()->set_request_id(id);
  r.mutable_stats()->set_samples_per_edge(3);
  r.mutable_stats()->set_map_cols(cols);
  r.mutable_stats()->set_map_rows(rows);
  return r;
}

pb::SimulateRequest Marks(uint64_t id) {
  pb::SimulateRequest r;
  r.mutable_marks()->set_request_id(id);
  r.mutable_marks()->set_min_angle_deg(10);
  return r;
}

pb::SimulateRequest Deviation(uint64_t id, double allowance, int samples,
                              int max_moves) {
  pb::SimulateRequest r;
  pb::DeviationRequest* d = r.mutable_deviation();
  d->set_request_id(id);
  d->set_allowance(allowance);
  d->mutable_tolerance()->set_value(0.02);
  d->mutable_samples_per_edge()->set_value(samples);
  d->set_max_moves(max_moves);
  return r;
}

pb::SimulateRequest Subscribe(uint64_t id) {
  pb::SimulateRequest r;
  r.mutable_subscribe()->set_request_id(id);
  r.mutable_subscribe()->set_include_owners(true);
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  swarf::fuzz::SeedDir seeds(argc, argv);

  // CreateSessionRequest.
  seeds.Write("create_ok", kCreate, Create(10, 10, 20, 20).SerializeAsString());
  {
    pb::CreateSessionRequest r = Create(50, 30, 0, 0);
    r.set_spacing(0.5);
    r.set_scheme(pb::SCHEME_ZMAP);
    r.add_tools()->set_id(2);
    r.mutable_tools(1)->mutable_ball()->set_radius(3);
    seeds.Write("create_spacing", kCreate, r.SerializeAsString());
  }
  {
    pb::CreateSessionRequest r = Create(10, 10, 20, 20);
    r.mutable_stock()->set_z_top(kNan);
    seeds.Write("create_nan", kCreate, r.SerializeAsString());
    r.mutable_stock()->set_z_top(0);
    r.mutable_tools(0)->mutable_ball()->set_radius(-kInf);
    seeds.Write("create_inf_radius", kCreate, r.SerializeAsString());
  }
  {
    // One tool of every shape, then inconsistent dimensions.
    pb::CreateSessionRequest r = Create(10, 10, 20, 20);
    r.add_tools()->set_id(2);
    r.mutable_tools(1)->mutable_flat()->set_radius(1);
    r.add_tools()->set_id(3);
    r.mutable_tools(2)->mutable_bull_nose()->set_radius(2);
    r.mutable_tools(2)->mutable_bull_nose()->set_corner_radius(0.5);
    r.add_tools()->set_id(4);
    r.mutable_tools(3)->mutable_cone()->set_radius(1);
    r.mutable_tools(3)->mutable_cone()->set_half_angle_deg(45);
    r.mutable_tools(3)->mutable_cone()->set_tip_radius(0.1);
    r.add_tools()->set_id(5);
    r.mutable_tools(4)->mutable_tapered_ball()->set_radius(3);
    r.mutable_tools(4)->mutable_tapered_ball()->set_tip_radius(0.5);
    r.mutable_tools(4)->mutable_tapered_ball()->set_half_angle_deg(5);
    seeds.Write("create_shapes", kCreate, r.SerializeAsString());
    r.mutable_tools(3)->mutable_cone()->set_half_angle_deg(90);
    seeds.Write("create_flat_cone", kCreate, r.SerializeAsString());
    r.mutable_tools(3)->mutable_cone()->set_half_angle_deg(45);
    r.mutable_tools(2)->mutable_bull_nose()->set_corner_radius(2.5);
    seeds.Write("create_bad_corner", kCreate, r.SerializeAsString());
  }
  seeds.Write("create_huge", kCreate,
              Create(1e4, 1e4, 1000000, 1000000).SerializeAsString());
  seeds.Write("create_limit", kCreate,
              Create(1, 1, 1023, 1023).SerializeAsString());
  seeds.Write("create_negative", kCreate,
              Create(-5, 10, -3, 7).SerializeAsString());
  {
    pb::CreateSessionRequest r = Create(10, 10, 8, 8);
    r.mutable_tools(0)->mutable_flat()->set_radius(2);
    seeds.Write("create_flat", kCreate, r.SerializeAsString());
  }

  // Streams.
  const std::vector<double> line = {1, 1, 1, 1, 1, -0.5, 9, 5, -0.5, 5, 9, -1};
  seeds.Write("stream_ok", kStream,
              Stream({Subscribe(5), Batch(1, 1, line), Tiles(2, false, true),
                      Batch(2, 2, {3, 3, -2, 7, 7, -0.1}, true), Stats(3, 4, 4),
                      Marks(4), Tiles(6, true, false)}));
  seeds.Write(
      "stream_zmap", kStream + kZmap,
      Stream({Batch(1, 1, line), Tiles(2, true, true), Stats(3, 0, 0)}));
  // The deviation from the streams' design: answered, then a negative
  // allowance, too many samples and a negative move count (each refused).
  seeds.Write("stream_deviation", kStream,
              Stream({Batch(1, 1, line), Deviation(2, 0.1, 3, 1),
                      Deviation(3, -1, 3, 0), Deviation(4, 0, 65, 0),
                      Deviation(5, 0, 0, -1)}));
  seeds.Write("stream_gap_dup", kStream,
              Stream({Batch(1, 1, line), Batch(1, 1, line), Batch(3, 1, line),
                      Batch(2, 1, {2, 2, -1})}));
  {
    std::vector<double> bad = line;
    bad[4] = kNan;
    seeds.Write("stream_nan", kStream,
                Stream({Batch(1, 1, bad), Batch(1, 9, line), Batch(0, 1, line),
                        Batch(1, 1, {1, 2})}));
  }
  {
    // Arcs: a half circle and a helix about (5, 5), resent; then a radius
    // mismatch, a turn count of 0 and an index past the end under seq 2.
    pb::SimulateRequest a =
        Batch(1, 1, {2, 5, 1, 2, 5, -1, 8, 5, -1, 8, 5, -2});
    for (int k : {2, 3}) {
      pb::Arc* arc = a.mutable_moves()->add_arcs();
      arc->set_end_index(k);
      arc->mutable_centre()->set_x(5);
      arc->mutable_centre()->set_y(5);
      arc->set_clockwise(k == 2);
      arc->set_turns(1);
    }
    pb::SimulateRequest mismatch = a, turns = a, past = a;
    for (pb::SimulateRequest* r : {&mismatch, &turns, &past}) {
      r->mutable_moves()->set_seq(2);
    }
    mismatch.mutable_moves()->mutable_arcs(0)->mutable_centre()->set_x(4.5);
    turns.mutable_moves()->mutable_arcs(1)->set_turns(0);
    past.mutable_moves()->mutable_arcs(1)->set_end_index(4);
    seeds.Write("stream_arcs", kStream, Stream({a, a, mismatch, turns, past}));
  }
  {
    // Programs: one that runs (two tools, an arc, a canned cycle, batches of
    // 8 points), one with an error on its line 3.
    pb::SimulateRequest ok, bad;
    pb::ProgramChunk* c = ok.mutable_program();
    c->set_last(true);
    c->set_data(
        "G21 G90 T1 M6\nG0 X1 Y1 Z1\nG1 Z-0.5 F100\nG2 X9 Y1 I4 J0\n"
        "T2 M6\nG81 X5 Y5 Z-1 R1\nG80\nG1 X2 Y8\nM2\n");
    c->mutable_options()->set_batch_points(8);
    c->mutable_options()->set_name("seed.nc");
    *bad.mutable_program() = *c;
    bad.mutable_program()->set_data("G21 G90\nG0 X1 Y1 Z1\nG1 X2 A1\n");
    seeds.Write("stream_program", kStream, Stream({ok, bad}));
  }

  // Unary reads on the prepared session.
  {
    pb::GetTilesRequest r;
    r.set_precision(pb::PRECISION_FLOAT);
    r.set_include_derivatives(true);
    r.set_since_version(1);
    pb::Rect* g = r.mutable_selection()->mutable_region();
    g->set_x0(-1);
    g->set_y0(4);
    g->set_x1(20);
    g->set_y1(1e300);
    seeds.Write("tiles_region", kTiles, r.SerializeAsString());
    r.clear_selection();
    r.mutable_selection()->add_tiles()->set_tx(-1);
    seeds.Write("tiles_bad_index", kTiles + kZmap, r.SerializeAsString());
  }
  {
    pb::GetErrorStatsRequest r;
    r.set_samples_per_edge(4);
    r.set_map_cols(10);
    r.set_map_rows(3);
    pb::Rect* g = r.mutable_region();
    g->set_x0(1);
    g->set_y0(1);
    g->set_x1(6);
    g->set_y1(4);
    seeds.Write("stats_region", kStats, r.SerializeAsString());
    g->set_x1(kInf);
    seeds.Write("stats_inf", kStats + kZmap, r.SerializeAsString());
  }
  {
    pb::GetCuttingMarksRequest r;
    r.set_screening_threshold(0.01);
    seeds.Write("marks", kMarks, r.SerializeAsString());
    r.set_min_angle_deg(95);
    seeds.Write("marks_bad_angle", kMarks, r.SerializeAsString());
  }
  {
    pb::ProbeRequest r;
    for (double v : {1.0, 1.0, 5.0, 5.0, -3.0, 20.0, 9.99, 0.01}) r.add_xy(v);
    seeds.Write("probe", kProbe, r.SerializeAsString());
    r.add_xy(kNan);
    r.add_xy(2);
    seeds.Write("probe_nan", kProbe + kZmap, r.SerializeAsString());
  }
  return seeds.Done();
}
