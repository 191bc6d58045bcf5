// Fuzz target: the server's validation and conversion of client requests
// into the core (server/convert.h, Session::ApplyBatch, Registry::Create),
// without gRPC. The first byte picks what the rest is (a serialized
// swarf.v1 message, parsed with ParseFromArray), by its low 3 bits:
//   0        CreateSessionRequest -> SpecFromRequest, Registry::Create
//            (small limits), FillSession, a small batch
//   1, 6, 7  SimulateRequests, each length-delimited, in order on a fresh
//            session (moves with their arcs -> ApplyBatch; tiles, stats,
//            marks, subscribe as the Simulate stream handles them)
//   2        GetTilesRequest -> TileOptionsFrom, SelectTiles, FillTile
//   3        GetErrorStatsRequest -> ComputeStats
//   4        GetCuttingMarksRequest -> ComputeMarks
//   5        ProbeRequest -> ComputeProbe
// Kinds 2-5 run on a prepared read-only session; bit 3 of the first byte
// picks the scheme (taylor or zmap). Errors must be statuses, never crashes
// or undefined behaviour; every accepted request keeps the invariants
// checked below. Work is bounded (grid sizes, points per batch, samples) so
// that each input runs in milliseconds.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "client/outputs/deviation.h"
#include "core/valuation.h"
#include "core/workpiece.h"
#include "google/protobuf/io/coded_stream.h"
#include "google/protobuf/io/zero_copy_stream_impl_lite.h"
#include "google/protobuf/stubs/logging.h"
#include "server/convert.h"
#include "server/program.h"
#include "server/registry.h"
#include "server/service.h"
#include "server/session.h"
#include "spdlog/spdlog.h"
#include "swarf/v1/swarf.pb.h"
#include "tests/fuzz/fuzz_check.h"
#include "tests/tile_copy.h"

namespace swarf::server {
namespace {

namespace pb = ::swarf::v1;

// Limits of the fuzzed registry: sessions up to 1 Mi nodes (every tile cut:
// 7 chunks of 2 MiB) are created (an empty workpiece is cheap); larger ones
// must be refused before.
Limits FuzzLimits() {
  Limits l;
  l.max_sessions = 4;
  l.max_session_memory_bytes = int64_t{16} << 20;
  l.max_total_memory_bytes = int64_t{64} << 20;
  l.max_batch_points = 256;
  return l;
}
// A created session is cut by a test batch only up to this many nodes.
constexpr int64_t kMaxCutNodes = int64_t{1} << 14;
constexpr int kMaxStreamRequests = 8;
// Valuation bounds: larger (valid) values are lowered to these. Sampling
// dominates the run time: 3 per edge (8 samples per element) for the
// GetErrorStats kind, 2 (none: the validation and the pass over the bins)
// in streams.
constexpr int32_t kMaxSamplesPerEdge = 3;
constexpr int32_t kMaxStreamSamplesPerEdge = 2;
constexpr int32_t kMaxMapSide = 64;
// Tiles filled per request (a session here has 4).
constexpr size_t kMaxFilledTiles = 4;

bool Finite(const Vec3& v) { return IsFinite(v); }

// A 10 x 10 mm session of nx x ny elements, tools 1 (r 1 mm) and 2
// (r 0.25 mm).
std::shared_ptr<Session> NewSession(SchemeKind scheme, int32_t nx,
                                    int32_t ny) {
  SessionSpec spec;
  spec.id = "fuzz";
  spec.stock = {0, 0, 10, 10, 0, nx, ny};
  spec.scheme = scheme;
  spec.tools = {{1, Cutter::Ball(1.0), {}}, {2, Cutter::Ball(0.25), {}}};
  auto s = Session::Create(std::move(spec));
  FUZZ_CHECK(s.ok());
  return *s;
}

// A read-only session of 80 x 80 elements (2 x 2 tiles) with cuts (a
// raster at two depths, both tools), made once per scheme.
const Session& Prepared(SchemeKind scheme) {
  static const auto make = [](SchemeKind k) {
    std::shared_ptr<Session> s = NewSession(k, 80, 80);
    std::vector<double> xyz;
    for (int line = 0; line < 6; ++line) {
      const double y = 1 + 1.6 * line;
      xyz.insert(xyz.end(), {line % 2 ? 9.0 : 1.0, y, -0.4 - 0.1 * line});
      xyz.insert(xyz.end(), {line % 2 ? 1.0 : 9.0, y, -0.4 - 0.1 * line});
    }
    FUZZ_CHECK(s->ApplyBatch(1, 1, xyz, 1 << 10).ok());
    const std::vector<double> groove = {2, 2, 1, 2, 2, -1.5, 8, 7, -0.7};
    FUZZ_CHECK(s->ApplyBatch(2, 2, groove, 1 << 10, true).ok());
    return s;
  };
  static const std::shared_ptr<Session> taylor = make(SchemeKind::kTaylor);
  static const std::shared_ptr<Session> zmap = make(SchemeKind::kZmap);
  return scheme == SchemeKind::kZmap ? *zmap : *taylor;
}

bool SameState(const SessionState& a, const SessionState& b) {
  const bool pos =
      a.last_position.has_value() == b.last_position.has_value() &&
      (!a.last_position.has_value() ||
       (a.last_position->x == b.last_position->x &&
        a.last_position->y == b.last_position->y &&
        a.last_position->z == b.last_position->z));
  return a.last_seq == b.last_seq && a.moves_applied == b.moves_applied &&
         a.version == b.version && a.allocated_tiles == b.allocated_tiles &&
         pos;
}

// Every node of tile t: finite, at or below the stock top, derivatives
// finite, owners valid move ids.
void CheckTile(const Workpiece& wp, int32_t t) {
  const TileCopy tile = CopyTile(wp, t);
  const Workpiece::TileExtent& e = tile.extent;
  FUZZ_CHECK(e.nx >= 1 && e.nx <= kTileSize && e.ny >= 1 &&
             e.ny <= kTileSize);
  for (size_t k = 0; k < tile.w.size(); ++k) {
    FUZZ_CHECK(std::isfinite(tile.w[k]) && tile.w[k] <= wp.spec().z_top);
    FUZZ_CHECK(tile.owner[k] >= -1 && tile.owner[k] < wp.move_count());
    if (tile.owner[k] == -1) FUZZ_CHECK(tile.w[k] == wp.spec().z_top);
  }
  for (float v : tile.d) FUZZ_CHECK(std::isfinite(v));
}

// ---------------------------------------------------------------- requests

void FuzzCreate(const pb::CreateSessionRequest& req) {
  auto spec = SpecFromRequest(req);
  if (!spec.ok()) {
    const absl::StatusCode c = spec.status().code();
    FUZZ_CHECK(c == absl::StatusCode::kInvalidArgument ||
               c == absl::StatusCode::kUnimplemented);
    return;
  }
  // A valid stock but maybe for its total node count, which the registry
  // checks against its limit.
  StockSpec row = spec->stock, column = spec->stock;
  row.ny = column.nx = 1;
  FUZZ_CHECK(ValidateStock(row).ok() && ValidateStock(column).ok());
  Registry registry(FuzzLimits());
  auto session = registry.Create(*spec);
  if (!session.ok()) {
    const absl::StatusCode c = session.status().code();
    FUZZ_CHECK(c == absl::StatusCode::kInvalidArgument ||
               c == absl::StatusCode::kResourceExhausted);
    FUZZ_CHECK(registry.List().empty());
    return;
  }
  const SessionSpec& got = (*session)->spec();
  const int64_t nodes =
      (int64_t{got.stock.nx} + 1) * (int64_t{got.stock.ny} + 1);
  FUZZ_CHECK(nodes <= kMaxNodes);
  FUZZ_CHECK(Session::EstimateMemoryBytes(got.stock, got.scheme) <=
             FuzzLimits().max_session_memory_bytes);
  FUZZ_CHECK(registry.Get(got.id).ok());

  // What the server reports describes the same session: as a request it
  // converts back to the same spec.
  pb::Session out;
  FillSession(**session, "fuzz", &out);
  pb::CreateSessionRequest again;
  again.set_session_id(out.session_id());
  *again.mutable_stock() = out.stock();
  again.set_nx(out.nx());
  again.set_ny(out.ny());
  again.set_scheme(out.scheme());
  *again.mutable_tools() = out.tools();
  auto spec2 = SpecFromRequest(again);
  FUZZ_CHECK(spec2.ok());
  FUZZ_CHECK(spec2->id == got.id && spec2->scheme == got.scheme);
  const StockSpec& a = spec2->stock;
  const StockSpec& b = got.stock;
  FUZZ_CHECK(a.x0 == b.x0 && a.y0 == b.y0 && a.x1 == b.x1 && a.y1 == b.y1 &&
             a.z_top == b.z_top && a.nx == b.nx && a.ny == b.ny);
  FUZZ_CHECK(spec2->tools.size() == got.tools.size());
  for (size_t k = 0; k < got.tools.size(); ++k) {
    FUZZ_CHECK(spec2->tools[k].id == got.tools[k].id &&
               spec2->tools[k].cutter == got.tools[k].cutter);
  }
  FUZZ_CHECK(out.tiles_x() * int64_t{out.tiles_y()} >= 1);

  // A diagonal plunge through the stock with the first tool; the memory
  // held stays within the admission estimate.
  if (nodes > kMaxCutNodes) return;
  const double z = b.z_top - 0.5 * got.tools[0].cutter.radius;
  const std::vector<double> xyz = {b.x0, b.y0, b.z_top + 1, b.x0, b.y0, z,
                                   b.x1, b.y1, z};
  auto r = (*session)->ApplyBatch(1, got.tools[0].id, xyz, 16);
  if (!r.ok()) {
    // Coordinates beyond the bound of moves (a stock near +-1e9 mm).
    FUZZ_CHECK(r.status().code() == absl::StatusCode::kInvalidArgument);
    return;
  }
  const SessionState st = (*session)->State();
  FUZZ_CHECK(st.last_seq == 1 && st.moves_applied == 2);
  const int64_t node_bytes =
      st.memory_bytes - st.moves_applied * static_cast<int64_t>(sizeof(Move));
  FUZZ_CHECK(node_bytes <= Session::EstimateMemoryBytes(got.stock, got.scheme));
  (*session)->Read([&](const Workpiece& wp) {
    for (const auto& [t, v] : r->changed_tiles) CheckTile(wp, t);
    return 0;
  });
}

// The moves a batch of `points` points (its arcs chorded) makes, as
// Session::ApplyBatch documents it.
int64_t ExpectedMoves(const pb::MoveBatch& b, int64_t points,
                      bool has_position) {
  if (points == 0) return 0;
  return (b.reposition() || !has_position) ? points - 1 : points;
}

void FuzzBatch(Session& s, const pb::MoveBatch& b) {
  const SessionState before = s.State();
  const std::span<const double> xyz(b.xyz().data(), b.xyz_size());
  // Arcs as the service reads them (ArcsFromProto), chorded by the session.
  auto arcs = ArcsFromProto(b);
  if (!arcs.ok()) {
    FUZZ_CHECK(arcs.status().code() == absl::StatusCode::kInvalidArgument);
    return;
  }
  BatchOptions options;
  options.reposition = b.reposition();
  options.arcs = *arcs;
  auto r = s.ApplyBatch(b.seq(), b.tool_id(), xyz,
                        FuzzLimits().max_batch_points, options);
  const SessionState after = s.State();
  if (!r.ok()) {
    // Rejected whole: nothing applied.
    FUZZ_CHECK(SameState(before, after));
    const absl::StatusCode c = r.status().code();
    FUZZ_CHECK(c == absl::StatusCode::kInvalidArgument ||
               c == absl::StatusCode::kFailedPrecondition ||
               c == absl::StatusCode::kAlreadyExists);
    if (c == absl::StatusCode::kFailedPrecondition) {
      FUZZ_CHECK(b.seq() > before.last_seq + 1);
    }
    // Another batch under an acknowledged seq.
    if (c == absl::StatusCode::kAlreadyExists) {
      FUZZ_CHECK(b.seq() >= 1 && b.seq() <= before.last_seq);
    }
    return;
  }
  FUZZ_CHECK(r->seq == b.seq());
  FUZZ_CHECK(b.xyz_size() % 3 == 0 &&
             b.xyz_size() / 3 <= FuzzLimits().max_batch_points);
  if (r->duplicate) {
    FUZZ_CHECK(b.seq() >= 1 && b.seq() <= before.last_seq);
    FUZZ_CHECK(SameState(before, after));
    FUZZ_CHECK(r->moves_applied == before.moves_applied &&
               r->changed_tiles.empty());
    return;
  }
  FUZZ_CHECK(b.seq() == before.last_seq + 1 && after.last_seq == b.seq());
  int64_t points = b.xyz_size() / 3;
  if (!arcs->empty()) {
    // Accepted arcs chord within the batch limit, ending at their points.
    auto chorded = ChordBatch(xyz, *arcs, s.spec().arc_tolerance,
                              FuzzLimits().max_batch_points);
    FUZZ_CHECK(chorded.ok() && chorded->size() % 3 == 0);
    points = static_cast<int64_t>(chorded->size() / 3);
    FUZZ_CHECK(points <= FuzzLimits().max_batch_points);
    FUZZ_CHECK(std::equal(xyz.end() - 3, xyz.end(), chorded->end() - 3));
  }
  FUZZ_CHECK(after.moves_applied ==
             before.moves_applied +
                 ExpectedMoves(b, points, before.last_position.has_value()));
  FUZZ_CHECK(r->moves_applied == after.moves_applied);
  FUZZ_CHECK(r->version == after.version && after.version >= before.version);
  FUZZ_CHECK(r->node_lowerings >= 0);
  FUZZ_CHECK((r->node_lowerings > 0) == !r->changed_tiles.empty());
  if (after.last_position.has_value()) {
    FUZZ_CHECK(Finite(*after.last_position));
  }
  int32_t prev = -1;
  s.Read([&](const Workpiece& wp) {
    for (const auto& [t, v] : r->changed_tiles) {
      FUZZ_CHECK(t > prev && t < wp.tile_count());
      FUZZ_CHECK(v == r->version);
      prev = t;
      CheckTile(wp, t);
    }
    return 0;
  });
}

// Tiles as a TileRequest, Subscribe or GetTiles selects and fills them.
void FuzzTiles(const Session& s, uint64_t id, const pb::TileSelection* sel,
               pb::Precision precision, bool derivatives, bool owners,
               bool fill) {
  s.Read([&](const Workpiece& wp) {
    auto options = TileOptionsFrom(wp, id, precision, derivatives, owners);
    if (!options.ok()) {
      const absl::StatusCode c = options.status().code();
      FUZZ_CHECK(c == absl::StatusCode::kInvalidArgument ||
                 c == absl::StatusCode::kFailedPrecondition);
      return 0;
    }
    auto tiles = SelectTiles(wp, sel);
    if (!tiles.ok()) {
      FUZZ_CHECK(tiles.status().code() == absl::StatusCode::kInvalidArgument);
      return 0;
    }
    int32_t prev = -1;
    for (int32_t t : *tiles) {
      FUZZ_CHECK(t > prev && t < wp.tile_count());
      prev = t;
    }
    if (sel == nullptr || (sel->tiles_size() == 0 && !sel->has_region())) {
      FUZZ_CHECK(static_cast<int32_t>(tiles->size()) == wp.tile_count());
    }
    for (size_t k = 0; fill && k < tiles->size() && k < kMaxFilledTiles;
         ++k) {
      pb::Tile tile;
      FillTile(wp, (*tiles)[k], *options, &tile);
      const int n = tile.nx() * tile.ny();
      FUZZ_CHECK(tile.request_id() == id);
      FUZZ_CHECK(tile.heights_f_size() + tile.heights_d_size() == n);
      FUZZ_CHECK(tile.wx_size() == (derivatives ? n : 0));
      FUZZ_CHECK(tile.owners_size() == (owners ? n : 0));
    }
    return 0;
  });
}

// Lowers valid but expensive valuation settings.
void Bound(int32_t max_samples, int32_t* samples_per_edge, int32_t* cols,
           int32_t* rows) {
  if (*samples_per_edge == 0 ||  // 5, the default
      (*samples_per_edge > max_samples && *samples_per_edge <= 64)) {
    *samples_per_edge = max_samples;
  }
  if (*cols > kMaxMapSide && *rows > 0 &&
      int64_t{*cols} * *rows <= kMaxMapCells) {
    *cols = kMaxMapSide;
  }
  if (*rows > kMaxMapSide && *cols > 0 &&
      int64_t{*cols} * *rows <= kMaxMapCells) {
    *rows = kMaxMapSide;
  }
}

void FuzzStats(const Session& s, int32_t max_samples, const pb::Rect* region,
               int32_t samples_per_edge, int32_t cols, int32_t rows) {
  Bound(max_samples, &samples_per_edge, &cols, &rows);
  auto stats = s.Read([&](const Workpiece& wp) {
    return ComputeStats(wp, region, samples_per_edge, cols, rows);
  });
  if (!stats.ok()) {
    FUZZ_CHECK(stats.status().code() == absl::StatusCode::kInvalidArgument);
    return;
  }
  FUZZ_CHECK(stats->samples() >= 0);
  FUZZ_CHECK(std::isfinite(stats->max_error()) && stats->max_error() >= 0);
  // The mean of equal errors may round a little above them.
  FUZZ_CHECK(std::isfinite(stats->mean_error()) && stats->mean_error() >= 0 &&
             stats->mean_error() <= stats->max_error() * (1 + 1e-9));
  FUZZ_CHECK(std::isfinite(stats->rms_error()) && stats->rms_error() >= 0);
  FUZZ_CHECK(stats->map_max_error_size() ==
             int64_t{stats->map_cols()} * stats->map_rows());
  for (float v : stats->map_max_error()) {
    FUZZ_CHECK(std::isfinite(v) && v >= 0);
  }
}

void FuzzMarks(const Session& s, const pb::Rect* region, double screening,
               double min_angle) {
  auto marks = s.Read([&](const Workpiece& wp) {
    return ComputeMarks(wp, region, screening, min_angle);
  });
  if (!marks.ok()) {
    const absl::StatusCode c = marks.status().code();
    FUZZ_CHECK(c == absl::StatusCode::kInvalidArgument ||
               c == absl::StatusCode::kFailedPrecondition);
    return;
  }
  for (const pb::Polyline& p : *marks) {
    FUZZ_CHECK(p.xyz_size() % 3 == 0);
    FUZZ_CHECK(p.angle_deg_size() == p.xyz_size() / 3);
    for (double v : p.xyz()) FUZZ_CHECK(std::isfinite(v));
  }
}

void FuzzProbe(const Session& s, const pb::ProbeRequest& req) {
  auto probe =
      s.Read([&](const Workpiece& wp) { return ComputeProbe(wp, req); });
  if (!probe.ok()) {
    FUZZ_CHECK(probe.status().code() == absl::StatusCode::kInvalidArgument);
    return;
  }
  const int n = req.xy_size() / 2;
  FUZZ_CHECK(probe->heights_size() == n && probe->normals_size() == 3 * n &&
             probe->owners_size() == n);
  // (A reconstructed height may overshoot the stock top near steep walls:
  // only finiteness is required of it.)
  for (int k = 0; k < n; ++k) {
    FUZZ_CHECK(std::isfinite(probe->heights(k)));
    const double nx = probe->normals(3 * k), ny = probe->normals(3 * k + 1),
                 nz = probe->normals(3 * k + 2);
    FUZZ_CHECK(std::isfinite(nx) && std::isfinite(ny) && nz > 0);
    FUZZ_CHECK(std::fabs(nx * nx + ny * ny + nz * nz - 1) < 1e-9);
    FUZZ_CHECK(probe->owners(k) >= -1);
  }
}

// A program chunk as its last: the options read, the program interpreted
// (work bounded: blocks and points) and cut into batches that cover its
// points in order, each within the batch limit and with a session tool.
void FuzzProgram(const Session& s, const pb::ProgramChunk& c) {
  pb::ProgramOptions o = c.options();
  if (o.max_blocks() <= 0 || o.max_blocks() > 20000) o.set_max_blocks(20000);
  const int64_t max_batch = FuzzLimits().max_batch_points;
  auto p = InterpretProgram(c.data(), o, s.spec(), max_batch, 4096);
  if (!p.ok()) {
    FUZZ_CHECK(p.status().code() == absl::StatusCode::kInvalidArgument);
    return;
  }
  int64_t next = 0, moves = 0;
  for (const ProgramBatch& b : p->batches) {
    FUZZ_CHECK(b.begin == next && b.end > b.begin &&
               b.end - b.begin <= std::max<int64_t>(o.batch_points(), 2));
    FUZZ_CHECK(b.tool_id == 1 || b.tool_id == 2);
    FUZZ_CHECK(b.moves == b.end - b.begin - (next == 0 || b.reposition));
    next = b.end;
    moves += b.moves;
  }
  FUZZ_CHECK(next == p->path.point_count());
  FUZZ_CHECK(moves == p->moves && moves == p->path.move_count());
}

// The design the streams' sessions get: a plane sloping along x from 0.2 to
// 0.7 mm below the top, a little larger than the stock (every node has
// design above it), so that the stream's cuts both gouge and leave excess.
constexpr char kStreamDesign[] =
    "solid fuzz\n"
    "facet normal 0 0 1\nouter loop\nvertex -1 -1 -0.15\n"
    "vertex 11 -1 -0.75\nvertex 11 11 -0.75\nendloop\nendfacet\n"
    "facet normal 0 0 1\nouter loop\nvertex -1 -1 -0.15\n"
    "vertex 11 11 -0.75\nvertex -1 11 -0.15\nendloop\nendfacet\n"
    "endsolid fuzz\n";

void FuzzDeviation(const Session& s, const pb::DeviationRequest& req) {
  auto d = ComputeDeviation(s, req, Limits{}.max_message_bytes);
  if (!d.ok()) {
    // The options only: the session has a design.
    FUZZ_CHECK(d.status().code() == absl::StatusCode::kInvalidArgument);
    return;
  }
  // Every node has design above it.
  const auto [nodes, moves] = s.Read([](const Workpiece& wp) {
    return std::pair<int64_t, int64_t>(
        int64_t{wp.grid().nodes_x()} * wp.grid().nodes_y(), wp.move_count());
  });
  FUZZ_CHECK(d->triangles() == 2);
  // Samples between nodes: an n x n lattice minus its corners per element,
  // none for n <= 2 (0 and 1 mean nodes only); from n = 3, 5 an element.
  const cli::DeviationOptions defaults;
  const int per_edge = req.has_samples_per_edge()
                           ? req.samples_per_edge().value()
                           : defaults.samples_per_edge;
  FUZZ_CHECK(d->nodes() == nodes);
  FUZZ_CHECK(per_edge >= 3 ? d->samples() >= d->nodes() : d->samples() == 0);
  for (double v :
       {d->gouge_max(), d->excess_max(), d->excess_mean(),
        d->gouge_volume_mm3(), d->excess_volume_mm3(), d->normal_gouge_max(),
        d->normal_excess_max(), d->out_of_tolerance_area_mm2()}) {
    FUZZ_CHECK(std::isfinite(v) && v >= 0);
  }
  FUZZ_CHECK(d->allowance() == req.allowance());
  FUZZ_CHECK(d->tolerance() == (req.has_tolerance() ? req.tolerance().value()
                                                    : defaults.tolerance));
  const int listed = req.max_moves() > 0 ? req.max_moves() : defaults.max_lines;
  for (const auto* list : {&d->gouge_moves(), &d->excess_moves()}) {
    FUZZ_CHECK(list->size() <= listed);
    double last = kInf;
    for (const pb::DeviationMove& m : *list) {
      FUZZ_CHECK(m.move() >= 0 && m.move() < moves);
      FUZZ_CHECK(m.depth() > 0 && m.depth() <= last);  // deepest first
      last = m.depth();
    }
  }
  FUZZ_CHECK(d->gouge_move() >= -1 && d->gouge_move() < moves);
}

void FuzzSimulate(Session& s, const pb::SimulateRequest& req) {
  switch (req.request_case()) {
    case pb::SimulateRequest::kMoves:
      return FuzzBatch(s, req.moves());
    case pb::SimulateRequest::kProgram:
      return FuzzProgram(s, req.program());
    case pb::SimulateRequest::kTiles: {
      const pb::TileRequest& r = req.tiles();
      return FuzzTiles(s, r.request_id(),
                       r.has_selection() ? &r.selection() : nullptr,
                       r.precision(), r.include_derivatives(),
                       r.include_owners(), /*fill=*/true);
    }
    case pb::SimulateRequest::kStats: {
      const pb::StatsRequest& r = req.stats();
      return FuzzStats(s, kMaxStreamSamplesPerEdge,
                       r.has_region() ? &r.region() : nullptr,
                       r.samples_per_edge(), r.map_cols(), r.map_rows());
    }
    case pb::SimulateRequest::kMarks: {
      const pb::MarksRequest& r = req.marks();
      return FuzzMarks(s, r.has_region() ? &r.region() : nullptr,
                       r.screening_threshold(), r.min_angle_deg());
    }
    case pb::SimulateRequest::kSubscribe: {
      const pb::Subscribe& r = req.subscribe();
      return FuzzTiles(s, r.request_id(),
                       r.has_selection() ? &r.selection() : nullptr,
                       r.precision(), r.include_derivatives(),
                       r.include_owners(), /*fill=*/false);
    }
    case pb::SimulateRequest::kDeviation:
      return FuzzDeviation(s, req.deviation());
    case pb::SimulateRequest::REQUEST_NOT_SET:
      return;
  }
}

void FuzzStream(SchemeKind scheme, const uint8_t* data, size_t size) {
  // 70 x 10 elements (2 x 1 tiles): the per-element passes of stats and
  // marks stay cheap.
  std::shared_ptr<Session> s = NewSession(scheme, 70, 10);
  DesignChunk design;
  design.data = kStreamDesign;
  design.last = true;
  FUZZ_CHECK(s->AddDesignChunk(design).ok());
  google::protobuf::io::ArrayInputStream in(data, static_cast<int>(size));
  google::protobuf::io::CodedInputStream coded(&in);
  for (int k = 0; k < kMaxStreamRequests; ++k) {
    uint32_t length = 0;
    if (!coded.ReadVarint32(&length)) return;
    const auto limit = coded.PushLimit(static_cast<int>(length));
    pb::SimulateRequest req;
    const bool parsed = req.ParseFromCodedStream(&coded) &&
                        coded.ConsumedEntireMessage();
    coded.PopLimit(limit);
    if (!parsed) return;
    FuzzSimulate(*s, req);
  }
}

template <typename M>
bool Parse(const uint8_t* data, size_t size, M* m) {
  return m->ParseFromArray(data, static_cast<int>(size));
}

}  // namespace
}  // namespace swarf::server

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace swarf::server;
  // Invalid UTF-8 in a string field fails the parse, with a log line each;
  // the streams' sessions log their design (info) on every input.
  static const bool quiet = [] {
    google::protobuf::SetLogHandler(nullptr);
    spdlog::set_level(spdlog::level::warn);
    return true;
  }();
  (void)quiet;
  if (size < 1 || size > (1 << 20)) return 0;
  const int kind = data[0] & 7;
  const swarf::SchemeKind scheme = (data[0] & 8) ? swarf::SchemeKind::kZmap
                                                 : swarf::SchemeKind::kTaylor;
  const uint8_t* body = data + 1;
  const size_t n = size - 1;
  switch (kind) {
    case 0: {
      pb::CreateSessionRequest r;
      if (Parse(body, n, &r)) FuzzCreate(r);
      break;
    }
    case 2: {
      pb::GetTilesRequest r;
      if (!Parse(body, n, &r)) break;
      const Session& s = Prepared(scheme);
      FuzzTiles(s, 0, r.has_selection() ? &r.selection() : nullptr,
                r.precision(), r.include_derivatives(), r.include_owners(),
                /*fill=*/true);
      break;
    }
    case 3: {
      pb::GetErrorStatsRequest r;
      if (!Parse(body, n, &r)) break;
      FuzzStats(Prepared(scheme), kMaxSamplesPerEdge,
                r.has_region() ? &r.region() : nullptr,
                r.samples_per_edge(), r.map_cols(), r.map_rows());
      break;
    }
    case 4: {
      pb::GetCuttingMarksRequest r;
      if (!Parse(body, n, &r)) break;
      FuzzMarks(Prepared(scheme), r.has_region() ? &r.region() : nullptr,
                r.screening_threshold(), r.min_angle_deg());
      break;
    }
    case 5: {
      pb::ProbeRequest r;
      if (Parse(body, n, &r)) FuzzProbe(Prepared(scheme), r);
      break;
    }
    default:  // 6, 7: streams, the richest kind
      FuzzStream(scheme, body, n);
      break;
  }
  return 0;
}
