#include "client/cli/run_report.h"

#include <malloc.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <iterator>
#include <memory>
#include <nlohmann/json.hpp>
#include <system_error>
#include <thread>
#include <utility>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "client/outputs/grid_bands.h"
#include "client/outputs/marks_stream.h"
#include "client/outputs/run_outputs.h"
#include "client/outputs/surface_grid.h"
#include "core/cutting_marks.h"
#include "core/workpiece.h"

namespace swarf::cli {
namespace {

MarkPolyline MarkFromProto(const pb::Polyline& p) {
  MarkPolyline m;
  m.closed = p.closed();
  for (int k = 0; k < p.owners_size() && k < 2; ++k) {
    m.owners[k] = static_cast<int32_t>(p.owners(k));
  }
  m.vertices.reserve(p.xyz_size() / 3);
  for (int k = 0; k + 2 < p.xyz_size(); k += 3) {
    m.vertices.push_back({p.xyz(k), p.xyz(k + 1), p.xyz(k + 2)});
  }
  m.angle_deg.assign(p.angle_deg().begin(), p.angle_deg().end());
  return m;
}

// Gives each fetched polyline to consume(p) as soon as it is converted
// (the marks are never all held here); restart() comes before a fetch's
// first polyline, so that a consumer begins again when the marks are asked
// again (a retry, or the fallback below).
struct MarksConsumer {
  std::function<void()> restart;
  std::function<void(MarkPolyline)> consume;
};

// One polyline per message (GetCuttingMarks): any number of marks.
absl::Status FetchMarksStreamed(Connection& conn, const std::string& id,
                                const MarksConsumer& to) {
  auto ctx = conn.Context(id, 3600);
  pb::GetCuttingMarksRequest req;
  req.set_session_id(id);
  auto reader = conn.stub().GetCuttingMarks(ctx.get(), req);
  to.restart();
  pb::Polyline p;
  while (reader->Read(&p)) to.consume(MarkFromProto(p));
  grpc::Status st = reader->Finish();
  if (!st.ok()) return FromGrpc(st);
  return absl::OkStatus();
}

// The marks as one Polylines message (a MarksRequest on a Simulate stream):
// a message per polyline costs the client and the server a thread wake-up
// each (cameo.nc: 91k). Marks beyond the server's message limit are
// RESOURCE_EXHAUSTED; then they come one per message. The same marks
// either way (ComputeMarks).
absl::Status FetchMarks(Connection& conn, const std::string& id,
                        const MarksConsumer& to) {
  auto ctx = conn.Context(id, 3600);
  auto stream = conn.stub().Simulate(ctx.get());
  pb::SimulateRequest req;
  req.mutable_marks()->set_request_id(1);
  stream->Write(req);
  stream->WritesDone();
  to.restart();
  absl::Status request_error;
  bool answered = false;
  pb::SimulateResponse resp;
  while (stream->Read(&resp)) {
    if (resp.has_polylines() && resp.polylines().request_id() == 1) {
      answered = true;
      // Each polyline's message freed once converted and consumed: the
      // marks are not held twice.
      for (pb::Polyline& p : *resp.mutable_polylines()->mutable_polylines()) {
        to.consume(MarkFromProto(p));
        pb::Polyline().Swap(&p);
      }
      resp.Clear();
    } else if (resp.has_error() && resp.error().request_id() == 1) {
      request_error =
          absl::Status(static_cast<absl::StatusCode>(resp.error().code()),
                       resp.error().message());
    }
  }
  grpc::Status st = stream->Finish();
  if (!st.ok()) return FromGrpc(st);
  if (request_error.code() == absl::StatusCode::kResourceExhausted) {
    return FetchMarksStreamed(conn, id, to);
  }
  if (!request_error.ok()) return request_error;
  if (!answered) {
    return absl::DataLossError("the marks request got no answer");
  }
  return absl::OkStatus();
}

// The embedded session's marks, found on its pinned workpiece and handed to
// `to` as the core finds them: the polylines GetCuttingMarks would send
// (StreamMarks with the default options), in the same order, without
// their protobuf copies, each serialized and parsed on one thread (on
// cameo.nc the transfer was most of the marks' serial CPU). The API's
// Polyline has no per-vertex owners: they are dropped, so that the files
// are those a remote server's marks give.
absl::Status FindEmbeddedMarks(const Workpiece& wp, const MarksConsumer& to) {
  to.restart();
  return FindCuttingMarks(wp, MarkOptions(), [&](MarkPolyline m) {
    std::vector<std::array<int32_t, 2>>().swap(m.vertex_owners);
    to.consume(std::move(m));
  });
}

// Sets tile rows [t0, t1) of `band` from the session's tiles (every tile
// of those rows, asked by index).
absl::Status FetchTileRows(Connection& conn, const std::string& id, int32_t t0,
                           int32_t t1, bool heights_only, SurfaceGrid* band) {
  auto ctx = conn.Context(id, 3600);
  pb::GetTilesRequest req;
  req.set_session_id(id);
  req.set_precision(pb::PRECISION_DOUBLE);
  req.set_include_derivatives(!heights_only &&
                              GetScheme(band->scheme).stores_derivatives());
  req.set_include_owners(!heights_only);
  req.set_since_version(0);
  const int32_t tiles_x = (band->nodes_x() + kTileSize - 1) / kTileSize;
  for (int32_t ty = t0; ty < t1; ++ty) {
    for (int32_t tx = 0; tx < tiles_x; ++tx) {
      pb::TileIndex* t = req.mutable_selection()->add_tiles();
      t->set_tx(tx);
      t->set_ty(ty);
    }
  }
  auto reader = conn.stub().GetTiles(ctx.get(), req);
  pb::Tile t;
  absl::Status status;
  while (reader->Read(&t)) {
    if (!status.ok()) continue;  // read to the end, then Finish
    const float* d[5] = {t.wx().data(), t.wy().data(), t.wxx().data(),
                         t.wxy().data(), t.wyy().data()};
    status =
        band->SetNodes(t.i0(), t.j0(), t.nx(), t.ny(), t.heights_d().data(),
                       req.include_derivatives() ? d : nullptr,
                       req.include_owners() ? t.owners().data() : nullptr);
  }
  grpc::Status st = reader->Finish();
  if (!st.ok()) return FromGrpc(st);
  return status;
}

// Runs `fetch` again while the server is unavailable (restarting): its
// sessions come back from their journals. Gives up after two minutes.
template <typename T>
absl::StatusOr<T> Retrying(const char* what,
                           const std::function<absl::StatusOr<T>()>& fetch) {
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::seconds(120);
  for (int attempt = 0;; ++attempt) {
    absl::StatusOr<T> r = fetch();
    if (r.ok() || r.status().code() != absl::StatusCode::kUnavailable ||
        std::chrono::steady_clock::now() > deadline) {
      return r;
    }
    if (attempt == 0) {
      std::fprintf(stderr,
                   "swarf: the server is unavailable (%s); retrying "
                   "%s\n",
                   std::string(r.status().message()).c_str(), what);
    }
    std::this_thread::sleep_for(
        std::chrono::milliseconds(std::min(2000, 100 << std::min(attempt, 4))));
  }
}

std::string Rate(double per_s) {
  return per_s >= 1e5 ? absl::StrFormat("%.2fM moves/s", per_s / 1e6)
                      : absl::StrFormat("%.0f moves/s", per_s);
}

}  // namespace

bool MarksFitOneMessage(const StockSpec& s) {
  const int64_t nodes = (int64_t{s.nx} + 1) * (int64_t{s.ny} + 1);
  return nodes * kMarksBytesPerNode <= kMarksMessageBytes;
}

void ErrorMapSize(const StockSpec& s, int32_t* cols, int32_t* rows) {
  // Cells, not pixels: a raster of more would not fit one message.
  constexpr int32_t kMaxSide = 1600;
  const double scale =
      std::min(1.0, static_cast<double>(kMaxSide) / std::max(s.nx, s.ny));
  *cols = std::max(1, static_cast<int32_t>(s.nx * scale));
  *rows = std::max(1, static_cast<int32_t>(s.ny * scale));
}

absl::Status ParseOutputFlags(const Args& args, OutputOptions* out) {
  auto number = [&](const char* flag, double* v) -> absl::Status {
    const auto text = args.Get(flag);
    if (!text) return absl::OkStatus();
    if (!absl::SimpleAtod(*text, v) || !std::isfinite(*v) || *v < 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--", flag, " must be a number >= 0, got \"", *text, "\""));
    }
    return absl::OkStatus();
  };
  if (absl::Status s = number("mesh-tolerance", &out->mesh_tolerance);
      !s.ok()) {
    return s;
  }
  if (absl::Status s =
          number("marks-min-angle", &out->marks_display.min_angle_deg);
      !s.ok()) {
    return s;
  }
  if (absl::Status s =
          number("marks-min-length", &out->marks_display.min_length);
      !s.ok()) {
    return s;
  }
  if (const auto text = args.Get("picture-size")) {
    int v = 0;
    if (!absl::SimpleAtoi(*text, &v) || v < 2 || v > 32768) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--picture-size must be an integer in [2, 32768] (pixels), got \"",
          *text, "\""));
    }
    out->picture_size = v;
  }
  return absl::OkStatus();
}

absl::StatusOr<std::optional<DesignInput>> ParseDesignFlags(const Args& args) {
  const auto path = args.Get("design");
  for (const char* f : kDesignFlags) {
    if (!path && args.Has(f)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--", f, " needs --design FILE"));
    }
  }
  if (!path) return std::optional<DesignInput>();
  DesignInput d;
  d.path = *path;
  const std::string units = args.Get("design-units").value_or("mm");
  if (units != "mm" && units != "inch") {
    return absl::InvalidArgumentError("--design-units must be mm or inch");
  }
  d.read.scale = units == "inch" ? 25.4 : 1.0;
  if (auto o = args.Get("design-offset")) {
    std::vector<std::string> parts = absl::StrSplit(*o, ',');
    double v[3];
    bool good = parts.size() == 3;
    for (int k = 0; good && k < 3; ++k) {
      good = absl::SimpleAtod(parts[k], &v[k]) && std::isfinite(v[k]);
    }
    if (!good) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--design-offset must be x,y,z in mm, got \"", *o, "\""));
    }
    d.read.offset = {v[0], v[1], v[2]};
  }
  auto number = [&](const char* flag, double* out) -> absl::Status {
    const auto text = args.Get(flag);
    if (!text) return absl::OkStatus();
    if (!absl::SimpleAtod(*text, out) || !std::isfinite(*out) || *out < 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--", flag, " must be a number >= 0 (mm), got \"", *text, "\""));
    }
    return absl::OkStatus();
  };
  if (absl::Status s = number("allowance", &d.deviation.allowance); !s.ok()) {
    return s;
  }
  if (absl::Status s = number("tolerance", &d.deviation.tolerance); !s.ok()) {
    return s;
  }
  d.tolerance_given = args.Has("tolerance");
  if (auto n = args.Get("deviation-samples")) {
    int v = 0;
    if (!absl::SimpleAtoi(*n, &v) || v < 0 || v > 64) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--deviation-samples must be an integer in [0, 64], got \"", *n,
          "\""));
    }
    d.deviation.samples_per_edge = v;
  }
  return std::optional<DesignInput>(std::move(d));
}

absl::Status LoadDesign(const StockSpec& stock, DesignInput* d) {
  const auto t0 = std::chrono::steady_clock::now();
  auto mesh = design::ReadDesignFile(d->path, d->read);
  if (!mesh.ok()) return mesh.status();
  auto placed = design::PlacedDesign::Place(*std::move(mesh),
                                            GridGeometry(stock), d->path);
  if (!placed.ok()) return placed.status();
  d->placed = *std::move(placed);
  d->seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0)
          .count();
  return absl::OkStatus();
}

absl::Status UploadDesign(Connection& conn, const std::string& id,
                          const DesignInput& d) {
  std::ifstream in(d.path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open ", d.path));
  const std::string bytes((std::istreambuf_iterator<char>(in)),
                          std::istreambuf_iterator<char>());
  constexpr size_t kChunk = size_t{1} << 20;
  for (size_t off = 0; off < bytes.size() || off == 0; off += kChunk) {
    pb::SetDesignRequest req;
    req.set_session_id(id);
    req.set_offset(off);
    req.set_data(bytes.substr(off, kChunk));
    req.set_last(off + kChunk >= bytes.size());
    req.set_scale(d.read.scale);
    req.mutable_translation()->set_x(d.read.offset.x);
    req.mutable_translation()->set_y(d.read.offset.y);
    req.mutable_translation()->set_z(d.read.offset.z);
    req.set_name(d.path);
    pb::DesignInfo info;
    auto ctx = conn.Context(id, 600);
    grpc::Status st = conn.stub().SetDesign(ctx.get(), req, &info);
    if (!st.ok()) return FromGrpc(st);
    if (req.last()) break;
  }
  return absl::OkStatus();
}

absl::Status CollectAndWrite(Connection& conn, const std::string& id,
                             const OutputOptions& options, RunReport* report) {
  const bool files = !options.dir.empty();
  const StockSpec& stock = report->stock;
  using Clock = std::chrono::steady_clock;
  auto seconds = [](Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
  };
  // The output directory is made first: the marks files are written as the
  // marks arrive. Its error is returned where it was before the marks were
  // streamed (after the statistics, the marks and the deviation).
  std::error_code dir_error;
  bool dir_made = false;
  if (files)
    dir_made = std::filesystem::create_directories(options.dir, dir_error);
  // A directory made here and left empty by an error goes again.
  struct RemoveIfEmpty {
    std::string dir;
    bool armed = false;
    ~RemoveIfEmpty() {
      std::error_code ec;
      if (armed) std::filesystem::remove(dir, ec);  // only if empty
    }
  } remove_dir{options.dir, dir_made};
  // The marks, consumed as they come (summarised; with --out filtered,
  // written to marks.svg and marks.json and spooled for marks.png); the
  // stream removes its spool and any unfinished file when it goes.
  std::unique_ptr<MarksStream> marks_stream;
  // marks.png's relief; the marks are spooled as it strokes them in its
  // frame.
  ReliefOptions marks_relief = MarksPictureOptions().relief;
  marks_relief.max_side = options.picture_size;
  marks_relief.min_side = std::min(marks_relief.min_side, options.picture_size);
  const MarksConsumer to_stream{
      [&] {
        marks_stream.reset();
        marks_stream = files && !dir_error
                           ? std::make_unique<MarksStream>(
                                 stock, options.dir, options.marks_display,
                                 ReliefFrame(stock, marks_relief))
                           : std::make_unique<MarksStream>();
      },
      [&](MarkPolyline p) { marks_stream->Add(std::move(p)); }};
  // The marks and the tiles are fetched while the server measures the
  // error (each step's own time is reported; they overlap).
  std::future<std::pair<absl::Status, double>> marks_fetch;
  if (GetScheme(report->scheme).stores_derivatives()) {
    marks_fetch = std::async(std::launch::async, [&] {
      const auto t0 = Clock::now();
      auto m =
          Retrying<bool>("the cutting marks", [&]() -> absl::StatusOr<bool> {
            absl::Status s =
                options.workpiece != nullptr
                    ? FindEmbeddedMarks(*options.workpiece, to_stream)
                : MarksFitOneMessage(stock)
                    ? FetchMarks(conn, id, to_stream)
                    : FetchMarksStreamed(conn, id, to_stream);
            if (!s.ok()) return s;
            marks_stream->Finish();
            return true;
          });
      return std::make_pair(m.status(), seconds(t0));
    });
  }
  const DesignInput* design = options.design;
  // The session's grid, read band by band (tile rows) for each pass over it
  // (the deviation, the files): never a whole-grid copy.
  auto session_bands = [&] {
    auto bands = std::make_unique<TileRowBands>(
        stock, report->scheme,
        [&](SurfaceGrid* band, int32_t t0, int32_t t1, bool heights_only) {
          if (options.workpiece != nullptr) {
            return band->SetTileRows(*options.workpiece, t0, t1, heights_only);
          }
          return Retrying<bool>("the tiles",
                                [&]() -> absl::StatusOr<bool> {
                                  absl::Status s = FetchTileRows(
                                      conn, id, t0, t1, heights_only, band);
                                  if (!s.ok()) return s;
                                  return true;
                                })
              .status();
        },
        options.moves, options.sweeps);
    if (options.workpiece != nullptr) {
      bands->SetFillWritesEveryNode();  // SetTileRows
      bands->SetHeightsFill([&](int32_t j0, int32_t j1, double* z) {
        ReadNodeHeights(*options.workpiece, j0, j1, z);
        return absl::OkStatus();
      });
    }
    return bands;
  };
  const auto t0 = Clock::now();
  auto stats = Retrying<pb::ErrorStats>(
      "the error statistics", [&]() -> absl::StatusOr<pb::ErrorStats> {
        auto ctx = conn.Context(id, 3600);
        pb::GetErrorStatsRequest req;
        req.set_session_id(id);
        if (files) {
          int32_t cols, rows;
          ErrorMapSize(stock, &cols, &rows);
          req.set_map_cols(cols);
          req.set_map_rows(rows);
        }
        pb::ErrorStats out;
        grpc::Status st = conn.stub().GetErrorStats(ctx.get(), req, &out);
        if (!st.ok()) return FromGrpc(st);
        return out;
      });
  report->output_steps.emplace_back("error_stats", seconds(t0));
  absl::Status marks_status;
  if (marks_fetch.valid()) {
    auto [m, s] = marks_fetch.get();
    // Their fetch, with marks.svg's and marks.json's writing (also given
    // on their own, below).
    report->output_steps.emplace_back("marks", s);
    if (m.ok()) report->marks = marks_stream->all();
    marks_status = m;
  }
  if (!stats.ok()) return stats.status();
  report->error = *std::move(stats);
  if (!marks_status.ok()) return marks_status;
  if (!files && design == nullptr) return absl::OkStatus();
  std::optional<Image> deviation_map;
  if (design != nullptr) {
    const auto td = Clock::now();
    const design::PlacedDesign& placed = *design->placed;
    std::unique_ptr<TileRowBands> bands = session_bands();
    DeviationPicture map(stock.nx + 1, stock.ny + 1);
    auto dev = MeasureDeviation(*bands, placed.envelope(), placed.index(),
                                design->move_lines, design->deviation,
                                [&](int32_t j0, int32_t j1, const float* v) {
                                  if (files) map.AddRows(j0, j1, v);
                                });
    if (!dev.ok()) return dev.status();
    report->design = design->path;
    report->design_triangles =
        static_cast<int64_t>(placed.mesh().triangles.size());
    report->sources = design->sources;
    report->tolerance_gate = design->tolerance_given;
    report->output_steps.emplace_back("deviation", seconds(td));
    if (files) {
      auto img = RenderDeviationMap(map, stock, *dev);
      if (!img.ok()) return img.status();
      deviation_map = *std::move(img);
    }
    if (dev->gouge_move >= 0 &&
        dev->gouge_move < static_cast<int32_t>(design->move_lines.size())) {
      report->gouge_source = design->move_lines[dev->gouge_move];
    }
    report->deviation = *std::move(dev);
  }
  if (!files) return absl::OkStatus();

  if (dir_error) {
    return absl::FailedPreconditionError(absl::StrCat(
        "cannot create --out ", options.dir, ": ", dir_error.message()));
  }
  if (deviation_map.has_value()) {
    const auto tw = Clock::now();
    const std::string path =
        (std::filesystem::path(options.dir) / "deviation.png").string();
    if (absl::Status s = WritePng(*deviation_map, path); !s.ok()) return s;
    report->files.push_back(path);
    report->output_steps.emplace_back("deviation.png", seconds(tw));
  }
  ErrorRaster raster;
  raster.region = {stock.x0, stock.y0, stock.x1, stock.y1};
  raster.cols = report->error.map_cols();
  raster.rows = report->error.map_rows();
  raster.max_error.assign(report->error.map_max_error().begin(),
                          report->error.map_max_error().end());
  RunOutputOptions out;
  out.mesh.subdivision = std::max(1, options.subdivide);
  out.mesh.tolerance = options.mesh_tolerance;
  report->mesh_tolerance = options.mesh_tolerance;
  report->marks_display = options.marks_display;
  StreamedMarks streamed;
  if (report->marks) {
    report->marks_shown = marks_stream->shown();
    streamed = marks_stream->streamed();
  }
  out.relief.max_side = options.picture_size;
  out.marks.relief = marks_relief;
  out.error.max_side = options.picture_size;
  out.error.min_side = std::min(out.error.min_side, options.picture_size);
  // The statistics' and the marks' transient memory (freed, on the
  // threads' malloc arenas) goes back to the system before the outputs
  // take theirs: freed pages would otherwise still count in the peak.
  malloc_trim(0);
  std::unique_ptr<TileRowBands> bands = session_bands();
  auto written = WriteRunOutputsStreamed(
      options.dir, *bands, raster.cols > 0 ? &raster : nullptr,
      report->marks ? &streamed : nullptr, out, &report->mesh);
  if (!written.ok()) return written.status();
  remove_dir.armed = false;
  // Reading the session's tiles, band by band, during the pass.
  report->output_steps.emplace_back("tiles", report->mesh.read_seconds);
  for (const WrittenFile& f : *written) {
    report->files.push_back(f.path);
    report->output_steps.emplace_back(
        std::filesystem::path(f.path).filename().string(), f.seconds);
  }
  report->files.push_back(
      (std::filesystem::path(options.dir) / "stats.json").string());
  return absl::OkStatus();
}

std::string StatsJson(const RunReport& r) {
  using Json = nlohmann::ordered_json;
  Json steps = Json::object();
  for (const auto& [name, seconds] : r.output_steps) steps[name] = seconds;
  Json tools = Json::object();
  for (const auto& [n, summary] : r.tools) tools[absl::StrCat(n)] = summary;
  Json j = {
      {"file", r.file},
      {"server", r.server},
      {"moves", r.moves},
      {"source_lines", r.lines},
      {"node_lowerings", r.node_lowerings},
      {"scheme", std::string(GetScheme(r.scheme).name())},
      {"tools", tools},
      {"stock",
       {{"x0", r.stock.x0},
        {"y0", r.stock.y0},
        {"x1", r.stock.x1},
        {"y1", r.stock.y1},
        {"top", r.stock.z_top},
        {"nx", r.stock.nx},
        {"ny", r.stock.ny}}},
      {"seconds",
       {{"parse", r.parse_seconds},
        {"simulate", r.simulate_seconds},
        {"outputs", r.output_seconds},
        {"output_steps", steps}}},
      {"moves_per_second",
       r.simulate_seconds > 0 ? r.moves / r.simulate_seconds : 0},
      {"error",
       {{"max", r.error.max_error()},
        {"mean", r.error.mean_error()},
        {"rms", r.error.rms_error()},
        {"max_at", {r.error.max_x(), r.error.max_y()}},
        {"samples", r.error.samples()}}},
  };
  if (r.marks) {
    Json& m = j["marks"] = {
        {"polylines", r.marks->polylines},
        {"vertices", r.marks->vertices},
        {"total_length", r.marks->total_length},
        {"angle_deg", {r.marks->min_angle_deg, r.marks->max_angle_deg}}};
    if (r.marks_shown) {
      // What marks.json/svg/png show (FilterMarks).
      m["shown"] = {{"min_angle_deg", r.marks_display.min_angle_deg},
                    {"min_length", r.marks_display.min_length},
                    {"polylines", r.marks_shown->polylines},
                    {"vertices", r.marks_shown->vertices},
                    {"total_length", r.marks_shown->total_length}};
    }
  }
  if (r.mesh.mesh_triangles > 0) {
    j["mesh"] = {{"tolerance", r.mesh_tolerance},
                 {"max_deviation", r.mesh.mesh_deviation},
                 {"triangles", r.mesh.mesh_triangles},
                 {"full_triangles", r.mesh.full_mesh_triangles}};
  }
  if (r.deviation) {
    const DeviationReport& d = *r.deviation;
    auto source = [&](int32_t file) -> std::string {
      return file >= 0 && file < static_cast<int32_t>(r.sources.size())
                 ? r.sources[file]
                 : std::string();
    };
    auto lines = [&](const std::vector<LineDeviation>& v, const char* depth) {
      Json a = Json::array();
      for (const LineDeviation& l : v) {
        a.push_back({{"file", source(l.file)},
                     {"line", l.line},
                     {depth, l.depth},
                     {"x", l.x},
                     {"y", l.y},
                     {"area_mm2", l.area_mm2}});
      }
      return a;
    };
    Json gouge = {{"max", d.gouge_max}, {"x", d.gouge_x},
                  {"y", d.gouge_y},     {"file", nullptr},
                  {"line", nullptr},    {"volume_mm3", d.gouge_volume}};
    if (r.gouge_source) {
      gouge["file"] = source(r.gouge_source->file);
      gouge["line"] = r.gouge_source->line;
    }
    j["deviation"] = {{"design", r.design},
                      {"triangles", r.design_triangles},
                      {"nodes", d.nodes},
                      {"samples", d.samples},
                      {"gouge", gouge},
                      {"excess",
                       {{"max", d.excess_max},
                        {"x", d.excess_x},
                        {"y", d.excess_y},
                        {"mean", d.excess_mean},
                        {"volume_mm3", d.excess_volume},
                        {"lines", lines(d.excess_lines, "excess_max")}}},
                      {"normal",
                       {{"gouge_max", d.normal_gouge_max},
                        {"excess_max", d.normal_excess_max}}},
                      {"allowance", d.allowance},
                      {"tolerance", d.tolerance},
                      {"out_of_tolerance",
                       {{"area_mm2", d.out_area_mm2},
                        {"lines", lines(d.gouge_lines, "gouge_max")}}},
                      {"ok", d.ok}};
  }
  if (!r.ignored.empty()) j["ignored"] = r.ignored;
  j["dropped_moves"] = r.dropped_moves;
  if (!r.dropped.empty()) j["dropped"] = r.dropped;
  if (!r.outside_stock.empty()) {
    j["outside_stock"] = {{"mm", r.outside_mm},
                          {"line", r.outside_line},
                          {"message", r.outside_stock}};
  }
  for (const auto& [key, text] : r.json_sections) j[key] = Json::parse(text);
  j["files"] = r.files;
  // Paths and G-code words are not always UTF-8: replaced, not thrown on.
  return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}

absl::Status WriteStatsJson(const RunReport& r, const std::string& path) {
  std::ofstream out(path, std::ios::binary);
  out << StatsJson(r) << "\n";
  out.close();
  if (!out) return absl::InternalError(absl::StrCat("cannot write ", path));
  return absl::OkStatus();
}

std::string Summary(const RunReport& r) {
  std::string s = absl::StrFormat(
      "%s: %d moves simulated (%s, %d x %d elements) on the %s\n"
      "  time     parse %.2f s, simulate %.2f s (%s), outputs %.2f s\n"
      "  error    max %.3g mm at (%.3f, %.3f), mean %.3g mm, rms %.3g mm "
      "(%d samples)\n",
      r.file, r.moves, GetScheme(r.scheme).name(), r.stock.nx, r.stock.ny,
      r.server, r.parse_seconds, r.simulate_seconds,
      Rate(r.simulate_seconds > 0 ? r.moves / r.simulate_seconds : 0),
      r.output_seconds, r.error.max_error(), r.error.max_x(), r.error.max_y(),
      r.error.mean_error(), r.error.rms_error(), r.error.samples());
  if (r.marks) {
    absl::StrAppendFormat(&s,
                          "  marks    %d polylines, %.1f mm long, %.1f..%.1f "
                          "degrees between the surfaces\n",
                          r.marks->polylines, r.marks->total_length,
                          r.marks->min_angle_deg, r.marks->max_angle_deg);
  }
  if (r.marks_shown) {
    absl::StrAppendFormat(&s,
                          "  shown    %d marks polylines (%.1f mm) at %g "
                          "degrees and %g mm or more\n",
                          r.marks_shown->polylines, r.marks_shown->total_length,
                          r.marks_display.min_angle_deg,
                          r.marks_display.min_length);
  }
  if (r.mesh.mesh_triangles > 0) {
    absl::StrAppendFormat(&s,
                          "  mesh     %d triangles (full lattice %d), max "
                          "vertical deviation %.3g mm (tolerance %g mm)\n",
                          r.mesh.mesh_triangles, r.mesh.full_mesh_triangles,
                          r.mesh.mesh_deviation, r.mesh_tolerance);
  }
  if (r.deviation) {
    const DeviationReport& d = *r.deviation;
    auto where = [&](const LineDeviation& l) {
      const std::string f =
          l.file >= 0 && l.file < static_cast<int32_t>(r.sources.size())
              ? r.sources[l.file]
              : std::string("?");
      return absl::StrFormat("%s line %d", f, l.line);
    };
    absl::StrAppendFormat(
        &s,
        "  design   %s: %s (tolerance %g mm, allowance %g mm): gouge max %.4g "
        "mm, excess max %.4g mm (normal: gouge %.4g, excess %.4g)%s\n",
        r.design, d.ok ? "IN TOLERANCE" : "OUT OF TOLERANCE", d.tolerance,
        d.allowance, d.gouge_max, d.excess_max, d.normal_gouge_max,
        d.normal_excess_max,
        d.ok ? "" : absl::StrFormat(", %.4g mm2 out", d.out_area_mm2));
    const size_t shown = std::min<size_t>(5, d.gouge_lines.size());
    for (size_t k = 0; k < shown; ++k) {
      const LineDeviation& l = d.gouge_lines[k];
      absl::StrAppendFormat(
          &s, "    gouge %.4g mm by %s at (%.3f, %.3f), %.4g mm2\n", l.depth,
          where(l), l.x, l.y, l.area_mm2);
    }
    if (d.gouge_lines.size() > shown) {
      absl::StrAppendFormat(&s, "    ... %d more lines gouge (stats.json)\n",
                            d.gouge_lines.size() - shown);
    }
  }
  if (!r.files.empty()) {
    absl::StrAppend(&s, "  wrote   ");
    for (const std::string& f : r.files) absl::StrAppend(&s, " ", f);
    absl::StrAppend(&s, "\n");
  }
  return s;
}

}  // namespace swarf::cli
