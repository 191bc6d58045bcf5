#include "client/viewer/viewer.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <sys/socket.h>

#include <csignal>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <limits>
#include <thread>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "client/cli/args.h"
#include "client/outputs/json_writer.h"
#include "core/scheme.h"
#include "server/convert.h"
#include "httplib.h"

// The page (client/viewer/index.html), embedded by cmake/embed_file.cmake.
extern const unsigned char kViewerPage[];
extern const size_t kViewerPageSize;

namespace swarf::cli {
namespace {

using Clock = std::chrono::steady_clock;

// One tile as the page gets it: its nodes every `stride` (the relay's).
struct CachedTile {
  int32_t cols = 0, rows = 0;  // subsampled nodes
  int32_t c0 = 0, r0 = 0;      // first subsampled column/row in the grid
  uint64_t version = 0;
  std::vector<float> heights;  // row-major, cols x rows
};

absl::StatusOr<std::string> ReadWhole(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) return absl::NotFoundError(p.string());
  return std::string((std::istreambuf_iterator<char>(in)),
                     std::istreambuf_iterator<char>());
}

// Appends the bytes of a trivially copyable value (little-endian host).
template <typename T>
void Put(std::string* out, T v) {
  out->append(reinterpret_cast<const char*>(&v), sizeof(T));
}

std::optional<double> DoubleParam(const httplib::Request& req,
                                  const char* name) {
  double v;
  if (!req.has_param(name) ||
      !absl::SimpleAtod(req.get_param_value(name), &v) || !std::isfinite(v)) {
    return std::nullopt;
  }
  return v;
}

void SendError(httplib::Response& res, const absl::Status& s) {
  // gRPC/absl codes to the nearest HTTP status, the message as text.
  int http = 500;
  switch (s.code()) {
    case absl::StatusCode::kInvalidArgument: http = 400; break;
    case absl::StatusCode::kFailedPrecondition: http = 400; break;  // as AIP-193
    case absl::StatusCode::kNotFound: http = 404; break;
    case absl::StatusCode::kUnauthenticated: http = 401; break;
    case absl::StatusCode::kPermissionDenied: http = 403; break;
    case absl::StatusCode::kUnavailable: http = 503; break;
    case absl::StatusCode::kDeadlineExceeded: http = 504; break;
    default: break;
  }
  res.status = http;
  res.set_content(std::string(s.message()), "text/plain");
}

}  // namespace

class ViewerImpl {
 public:
  ViewerImpl(Connection* conn, std::string id, ViewerOptions options,
             ViewerPath path)
      : conn_(conn), id_(std::move(id)), options_(std::move(options)),
        path_(std::move(path)) {}

  ~ViewerImpl() {
    {
      absl::MutexLock l(&mu_);
      stopping_ = true;
    }
    http_.stop();
    if (http_thread_.joinable()) http_thread_.join();
    if (relay_thread_.joinable()) relay_thread_.join();
  }

  absl::Status Init() {
    auto three = LoadThree();
    if (!three.ok()) return three;
    auto session = GetSession();
    if (!session.ok()) return session.status();
    session_ = *session;
    const int32_t side = std::max(session_.nx(), session_.ny()) + 1;
    while (side > kMaxDisplayNodes * stride_ && stride_ < session_.tile_size()) {
      stride_ *= 2;
    }
    cols_ = session_.nx() / stride_ + 1;
    rows_ = session_.ny() / stride_ + 1;
    tiles_.resize(static_cast<size_t>(session_.tiles_x()) * session_.tiles_y());
    server_design_ = HasServerDesign();
    Routes();
    // SO_REUSEADDR only: cpp-httplib's default also sets SO_REUSEPORT, which
    // would let two viewers share a port silently.
    http_.set_socket_options([](socket_t sock) {
      int yes = 1;
      setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    });
    port_ = options_.port == 0
                ? http_.bind_to_any_port(options_.host)
                : (http_.bind_to_port(options_.host, options_.port)
                       ? options_.port
                       : -1);
    if (port_ <= 0) {
      return absl::UnavailableError(
          absl::StrCat("the viewer cannot listen on ", options_.host, ":",
                       options_.port, " (in use?)"));
    }
    // Fill the cache before the page can ask, so that it starts whole.
    Poll();
    http_thread_ = std::thread([this] { http_.listen_after_bind(); });
    // cpp-httplib's stop() does nothing until the listening thread has
    // marked itself running: a viewer destroyed before that would wait on
    // accept() for ever. Return only once it listens.
    const auto give_up =
        std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (!http_.is_running()) {
      if (std::chrono::steady_clock::now() > give_up) {
        return absl::UnavailableError("the viewer's HTTP server did not start");
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    relay_thread_ = std::thread([this] { Relay(); });
    return absl::OkStatus();
  }

  int port() const { return port_; }
  std::string url() const {
    return absl::StrCat("http://", options_.host, ":", port_, "/");
  }

  void WaitForPage() {
    absl::MutexLock l(&mu_);
    mu_.Await(absl::Condition(
        +[](int* pages) { return *pages > 0; }, &pages_));
  }

  void MarkFinished() {
    absl::MutexLock l(&mu_);
    finished_ = true;
    ++state_seq_;
  }

  void AddSafety(std::vector<ViewerMarker> markers,
                 std::vector<std::pair<Vec3, Vec3>> air) {
    if (markers.empty() && air.empty()) return;
    absl::MutexLock l(&mu_);
    for (ViewerMarker& m : markers) markers_.push_back(std::move(m));
    for (const auto& seg : air) air_.push_back(seg);
    ++state_seq_;
  }

  // {"markers": [{x, y, z, kind, file, line, depth, volume_mm3}], "air":
  // [x0, y0, z0, x1, y1, z1, ...]}.
  std::string SafetyJson() {
    absl::MutexLock l(&mu_);
    JsonWriter w;
    w.BeginObject();
    w.Key("markers").BeginArray();
    for (const ViewerMarker& m : markers_) {
      w.BeginObject();
      w.Key("x").Double(m.at.x).Key("y").Double(m.at.y).Key("z").Double(m.at.z);
      w.Key("kind").String(m.kind).Key("file").String(m.file);
      w.Key("line").Int(m.line);
      w.Key("depth").Double(m.depth).Key("volume_mm3").Double(m.volume_mm3);
      w.EndObject();
    }
    w.EndArray();
    w.Key("air").BeginArray();
    for (const auto& [a, b] : air_) {
      w.Double(a.x).Double(a.y).Double(a.z).Double(b.x).Double(b.y).Double(b.z);
    }
    w.EndArray();
    w.EndObject();
    return w.str();
  }

 private:
  absl::Status LoadThree() {
    std::vector<std::string> dirs;
    if (!options_.three_dir.empty()) dirs.push_back(options_.three_dir);
    if (const char* env = std::getenv("SWARF_THREE_DIR")) dirs.push_back(env);
#ifdef SWARF_THREE_DIR_DEFAULT
    dirs.push_back(SWARF_THREE_DIR_DEFAULT);
#endif
    dirs.push_back("/usr/share/javascript/three");
    for (const std::string& d : dirs) {
      const std::filesystem::path dir(d);
      auto three = ReadWhole(dir / "three.min.js");
      if (!three.ok()) three = ReadWhole(dir / "build" / "three.min.js");
      auto orbit =
          ReadWhole(dir / "examples" / "js" / "controls" / "OrbitControls.js");
      if (three.ok() && orbit.ok()) {
        three_js_ = *std::move(three);
        orbit_js_ = *std::move(orbit);
        return absl::OkStatus();
      }
    }
    return absl::FailedPreconditionError(
        "three.js not found: install Debian's libjs-three "
        "(scripts/install-deps) or set $SWARF_THREE_DIR");
  }

  absl::StatusOr<pb::Session> GetSession() {
    auto ctx = conn_->Context(id_, 10);
    pb::GetSessionRequest req;
    req.set_session_id(id_);
    pb::Session s;
    grpc::Status st = conn_->stub().GetSession(ctx.get(), req, &s);
    if (!st.ok()) {
      absl::Status e = FromGrpc(st);
      return absl::Status(e.code(),
                          absl::StrCat("session ", id_, ": ", e.message()));
    }
    return s;
  }

  // Whether the session holds a design (SetDesign): one tile with its
  // deviation answers.
  bool HasServerDesign() {
    auto ctx = conn_->Context(id_, 30);
    pb::GetTilesRequest req;
    req.set_session_id(id_);
    req.set_include_deviation(true);
    pb::TileIndex* t = req.mutable_selection()->add_tiles();
    t->set_tx(0);
    t->set_ty(0);
    auto reader = conn_->stub().GetTiles(ctx.get(), req);
    pb::Tile tile;
    while (reader->Read(&tile)) {
    }
    return reader->Finish().ok();
  }

  // Binary: u32 cols, rows; f32 allowance, tolerance, normal gouge max,
  // normal excess max, gouge max (vertical); u32 ok; f32 deviation[cols *
  // rows] (z - z_d at the display nodes, NaN without design above).
  absl::StatusOr<std::string> Deviation(double allowance, double tolerance) {
    pb::GetDeviationRequest dreq;
    dreq.set_session_id(id_);
    pb::DeviationRequest* o = dreq.mutable_options();
    o->set_allowance(allowance);
    o->mutable_tolerance()->set_value(tolerance);
    o->set_max_moves(1);
    // At the nodes (the page shows nodes): a pass the page may repeat
    // every 2 s while the job is cut.
    o->mutable_samples_per_edge()->set_value(0);
    pb::Deviation d;
    {
      auto ctx = conn_->Context(id_, 600);
      grpc::Status st = conn_->stub().GetDeviation(ctx.get(), dreq, &d);
      if (!st.ok()) return FromGrpc(st);
    }
    std::vector<float> grid(static_cast<size_t>(cols_) * rows_,
                            std::numeric_limits<float>::quiet_NaN());
    auto ctx = conn_->Context(id_, 600);
    pb::GetTilesRequest req;
    req.set_session_id(id_);
    req.set_precision(pb::PRECISION_FLOAT);
    req.set_include_deviation(true);
    auto reader = conn_->stub().GetTiles(ctx.get(), req);
    pb::Tile t;
    const int32_t s = stride_;
    while (reader->Read(&t)) {
      if (t.deviation_size() != t.nx() * t.ny()) continue;
      // Display nodes are every stride-th node; tiles start on multiples.
      for (int32_t j = 0; j < t.ny(); j += s) {
        for (int32_t i = 0; i < t.nx(); i += s) {
          const int32_t c = (t.i0() + i) / s, r = (t.j0() + j) / s;
          if (c < cols_ && r < rows_) {
            grid[static_cast<size_t>(r) * cols_ + c] =
                t.deviation(j * t.nx() + i);
          }
        }
      }
    }
    grpc::Status st = reader->Finish();
    if (!st.ok()) return FromGrpc(st);
    std::string out;
    Put<uint32_t>(&out, cols_);
    Put<uint32_t>(&out, rows_);
    Put<float>(&out, static_cast<float>(d.allowance()));
    Put<float>(&out, static_cast<float>(d.tolerance()));
    Put<float>(&out, static_cast<float>(d.normal_gouge_max()));
    Put<float>(&out, static_cast<float>(d.normal_excess_max()));
    Put<float>(&out, static_cast<float>(d.gouge_max()));
    Put<uint32_t>(&out, d.ok() ? 1 : 0);
    out.append(reinterpret_cast<const char*>(grid.data()),
               grid.size() * sizeof(float));
    return out;
  }

  // Binary: u32 triangles; f32 (x, y, z) x 3 per triangle.
  absl::StatusOr<std::string> DesignTriangles() const {
    const design::DesignMesh* m = path_.design;
    if (m == nullptr) {
      return absl::NotFoundError(
          "the viewer was not given the design's mesh (swarf run --design "
          "--view gives it)");
    }
    std::string out;
    out.reserve(4 + m->triangles.size() * 36);
    Put<uint32_t>(&out, static_cast<uint32_t>(m->triangles.size()));
    for (const auto& tri : m->triangles) {
      for (int k = 0; k < 3; ++k) {
        const Vec3& v = m->vertices[tri[k]];
        Put<float>(&out, static_cast<float>(v.x));
        Put<float>(&out, static_cast<float>(v.y));
        Put<float>(&out, static_cast<float>(v.z));
      }
    }
    return out;
  }

  // Tiles changed since `since` (0: all), subsampled; sets *any when the
  // stream ended early.
  absl::Status FetchTiles(uint64_t since) {
    auto ctx = conn_->Context(id_, 600);
    pb::GetTilesRequest req;
    req.set_session_id(id_);
    req.set_since_version(since);
    req.set_precision(pb::PRECISION_FLOAT);
    auto reader = conn_->stub().GetTiles(ctx.get(), req);
    pb::Tile t;
    const int32_t s = stride_;
    while (reader->Read(&t)) {
      const int32_t index = t.ty() * session_.tiles_x() + t.tx();
      if (t.tx() < 0 || t.ty() < 0 || t.tx() >= session_.tiles_x() ||
          t.ty() >= session_.tiles_y() ||
          t.heights_f_size() != t.nx() * t.ny()) {
        continue;  // not ours to draw
      }
      CachedTile c;
      // Tiles start at multiples of the tile size, which the stride divides.
      c.c0 = t.i0() / s;
      c.r0 = t.j0() / s;
      c.cols = (t.nx() + s - 1) / s;
      c.rows = (t.ny() + s - 1) / s;
      c.version = t.version();
      c.heights.resize(static_cast<size_t>(c.cols) * c.rows);
      for (int32_t r = 0; r < c.rows; ++r) {
        for (int32_t q = 0; q < c.cols; ++q) {
          c.heights[static_cast<size_t>(r) * c.cols + q] =
              t.heights_f(r * s * t.nx() + q * s);
        }
      }
      absl::MutexLock l(&mu_);
      tiles_[index] = std::move(c);
    }
    return FromGrpc(reader->Finish());
  }

  // One relay step: the session's state, and the tiles changed since.
  void Poll() {
    auto s = GetSession();
    if (!s.ok()) {
      absl::MutexLock l(&mu_);
      const std::string e(s.status().message());
      if (e != error_) ++state_seq_;
      error_ = e;
      return;
    }
    uint64_t since;
    bool have;
    {
      absl::MutexLock l(&mu_);
      since = cache_version_;
      have = have_tiles_;
    }
    if (!have || s->version() > since) {
      absl::Status f = FetchTiles(have ? since : 0);
      if (!f.ok()) {
        absl::MutexLock l(&mu_);
        error_ = absl::StrCat("tiles: ", f.message());
        ++state_seq_;
        return;
      }
    }
    const auto now = Clock::now();
    absl::MutexLock l(&mu_);
    // Every tile changed up to the version read before the fetch is in.
    const bool changed = !have || s->version() != cache_version_ ||
                         s->moves_applied() != moves_ || !error_.empty();
    cache_version_ = s->version();
    have_tiles_ = true;
    error_.clear();
    moves_ = s->moves_applied();
    samples_.push_back({now, moves_});
    while (samples_.size() > 2 &&
           now - samples_.front().first > std::chrono::seconds(1)) {
      samples_.pop_front();
    }
    const double dt =
        std::chrono::duration<double>(now - samples_.front().first).count();
    const double rate = dt > 0 ? (moves_ - samples_.front().second) / dt : 0;
    if (s->has_last_position()) {
      const Vec3 p{s->last_position().x(), s->last_position().y(),
                   s->last_position().z()};
      if (!has_position_ || p.x != position_.x || p.y != position_.y ||
          p.z != position_.z) {
        position_ = p;
        has_position_ = true;
        // Without the program, the path so far is where the tool was seen.
        if (path_.points.empty()) trail_.push_back(p);
      }
    }
    if (changed || rate != rate_) ++state_seq_;
    rate_ = rate;
  }

  void Relay() {
    for (;;) {
      {
        absl::MutexLock l(&mu_);
        if (mu_.AwaitWithTimeout(absl::Condition(&stopping_),
                                 absl::Seconds(options_.poll_seconds))) {
          return;
        }
      }
      Poll();
    }
  }

  // Points of the path reached so far.
  size_t PathAvailableLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    if (path_.points.empty()) return trail_.size();
    return std::upper_bound(path_.moves_at.begin(), path_.moves_at.end(),
                            moves_) -
           path_.moves_at.begin();
  }

  std::string StateJsonLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    JsonWriter w;
    w.BeginObject();
    w.Key("version").Int(static_cast<int64_t>(cache_version_));
    w.Key("moves").Int(moves_);
    w.Key("moves_total").Int(path_.moves_total);
    w.Key("rate").Double(rate_);
    w.Key("position");
    if (has_position_) {
      w.BeginArray().Double(position_.x).Double(position_.y)
          .Double(position_.z).EndArray();
    } else {
      w.BeginArray().EndArray();
    }
    const size_t reached = PathAvailableLocked();
    w.Key("path_points").Int(static_cast<int64_t>(reached));
    // The tool at the last point reached, when the program is known.
    w.Key("tool").Int(reached > 0 && reached <= path_.tools.size()
                          ? path_.tools[reached - 1]
                          : -1);
    w.Key("finished").Bool(finished_);
    // Safety markers and air segments so far (the page refetches on change).
    w.Key("safety").Int(static_cast<int64_t>(markers_.size() + air_.size()));
    w.Key("error").String(error_);
    w.EndObject();
    return w.str();
  }

  std::string SessionJson() const {
    const pb::Stock& st = session_.stock();
    JsonWriter w;
    w.BeginObject();
    w.Key("id").String(id_);
    w.Key("server").String(conn_->target());
    w.Key("stock").BeginObject();
    w.Key("x0").Double(st.x0()).Key("y0").Double(st.y0());
    w.Key("x1").Double(st.x1()).Key("y1").Double(st.y1());
    w.Key("z_top").Double(st.z_top());
    w.EndObject();
    w.Key("nx").Int(session_.nx()).Key("ny").Int(session_.ny());
    // The scheme's name, as --scheme spells it (unknown values: guarded,
    // what SCHEME_UNSPECIFIED means).
    const absl::StatusOr<SchemeKind> scheme =
        server::SchemeFromProto(session_.scheme(), "scheme");
    w.Key("scheme").String(std::string(
        GetScheme(scheme.ok() ? *scheme : SchemeKind::kGuarded).name()));
    w.Key("tile_size").Int(session_.tile_size());
    w.Key("tiles_x").Int(session_.tiles_x());
    w.Key("tiles_y").Int(session_.tiles_y());
    w.Key("stride").Int(stride_);
    w.Key("cols").Int(cols_).Key("rows").Int(rows_);
    w.Key("known_path").Bool(!path_.points.empty());
    // The session holds a design (deviation colouring), and the viewer its
    // mesh (the overlay), with the verdict's allowance and tolerance.
    w.Key("design").Bool(server_design_);
    w.Key("design_mesh").Bool(path_.design != nullptr);
    w.Key("allowance").Double(path_.allowance);
    w.Key("tolerance").Double(path_.tolerance);
    w.Key("path_total").Int(static_cast<int64_t>(path_.points.size()));
    w.Key("tools").BeginArray();
    for (const pb::Tool& t : session_.tools()) {
      w.BeginObject().Key("id").Int(t.id());
      if (t.has_ball()) {
        w.Key("shape").String("ball").Key("radius").Double(t.ball().radius());
      } else if (t.has_flat()) {
        w.Key("shape").String("flat").Key("radius").Double(t.flat().radius());
      } else if (t.has_bull_nose()) {
        w.Key("shape").String("bull_nose");
        w.Key("radius").Double(t.bull_nose().radius());
        w.Key("corner_radius").Double(t.bull_nose().corner_radius());
      } else if (t.has_cone()) {
        w.Key("shape").String("cone");
        w.Key("radius").Double(t.cone().radius());
        w.Key("half_angle_deg").Double(t.cone().half_angle_deg());
        w.Key("tip_radius").Double(t.cone().tip_radius());
      } else if (t.has_tapered_ball()) {
        w.Key("shape").String("tapered_ball");
        w.Key("radius").Double(t.tapered_ball().radius());
        w.Key("tip_radius").Double(t.tapered_ball().tip_radius());
        w.Key("half_angle_deg").Double(t.tapered_ball().half_angle_deg());
      }
      w.EndObject();
    }
    w.EndArray();
    w.EndObject();
    return w.str();
  }

  // Binary, little-endian: u32 count, u32 stride, f64 version; per tile
  // i32 c0, r0, cols, rows, f64 version, f32 heights[cols * rows].
  std::string TilesSince(std::optional<uint64_t> since) {
    std::string out;
    absl::MutexLock l(&mu_);
    uint32_t count = 0;
    Put<uint32_t>(&out, 0);
    Put<uint32_t>(&out, stride_);
    Put<double>(&out, static_cast<double>(cache_version_));
    for (const CachedTile& t : tiles_) {
      if (t.heights.empty() || (since.has_value() && t.version <= *since)) {
        continue;
      }
      ++count;
      Put<int32_t>(&out, t.c0);
      Put<int32_t>(&out, t.r0);
      Put<int32_t>(&out, t.cols);
      Put<int32_t>(&out, t.rows);
      Put<double>(&out, static_cast<double>(t.version));
      out.append(reinterpret_cast<const char*>(t.heights.data()),
                 t.heights.size() * sizeof(float));
    }
    std::memcpy(out.data(), &count, sizeof count);
    return out;
  }

  absl::StatusOr<std::string> Probe(double x, double y) {
    auto ctx = conn_->Context(id_, 30);
    pb::ProbeRequest req;
    req.set_session_id(id_);
    req.add_xy(x);
    req.add_xy(y);
    pb::ProbeResponse resp;
    grpc::Status st = conn_->stub().Probe(ctx.get(), req, &resp);
    if (!st.ok()) return FromGrpc(st);
    if (resp.heights_size() != 1 || resp.normals_size() != 3) {
      return absl::InternalError("Probe answered the wrong number of points");
    }
    JsonWriter w;
    w.BeginObject();
    w.Key("x").Double(x).Key("y").Double(y).Key("z").Double(resp.heights(0));
    w.Key("normal").BeginArray();
    for (double n : resp.normals()) w.Double(n);
    w.EndArray();
    const int64_t owner = resp.owners_size() ? resp.owners(0) : -1;
    w.Key("owner").Int(owner);
    // The program line of that move, when the program is known.
    if (owner >= 0 && owner < static_cast<int64_t>(path_.move_lines.size())) {
      const SourceLine& l = path_.move_lines[owner];
      w.Key("line").Int(l.line);
      w.Key("file").String(l.file >= 0 && l.file < static_cast<int32_t>(
                                                      path_.sources.size())
                               ? path_.sources[l.file]
                               : std::string());
    }
    w.EndObject();
    return w.str();
  }

  // Binary: u32 polylines; per polyline u32 n, f32 (x, y, z, angle)[n].
  absl::StatusOr<std::string> Marks(double min_angle) {
    auto ctx = conn_->Context(id_, 600);
    pb::GetCuttingMarksRequest req;
    req.set_session_id(id_);
    req.set_min_angle_deg(min_angle);
    auto reader = conn_->stub().GetCuttingMarks(ctx.get(), req);
    std::string out;
    Put<uint32_t>(&out, 0);
    uint32_t count = 0;
    pb::Polyline p;
    while (reader->Read(&p)) {
      const int n = std::min(p.xyz_size() / 3, p.angle_deg_size());
      if (n < 2) continue;
      ++count;
      Put<uint32_t>(&out, n);
      for (int k = 0; k < n; ++k) {
        Put<float>(&out, p.xyz(3 * k));
        Put<float>(&out, p.xyz(3 * k + 1));
        Put<float>(&out, p.xyz(3 * k + 2));
        Put<float>(&out, p.angle_deg(k));
      }
    }
    grpc::Status st = reader->Finish();
    if (!st.ok()) return FromGrpc(st);
    std::memcpy(out.data(), &count, sizeof count);
    return out;
  }

  // Binary: u32 cols, rows; f32 max, mean; f32 map[cols * rows] (mm).
  absl::StatusOr<std::string> ErrorMap(int32_t samples) {
    auto ctx = conn_->Context(id_, 600);
    pb::GetErrorStatsRequest req;
    req.set_session_id(id_);
    req.set_samples_per_edge(samples);
    req.set_map_cols(std::min(session_.nx(), kMaxDisplayNodes));
    req.set_map_rows(std::min(session_.ny(), kMaxDisplayNodes));
    pb::ErrorStats e;
    grpc::Status st = conn_->stub().GetErrorStats(ctx.get(), req, &e);
    if (!st.ok()) return FromGrpc(st);
    std::string out;
    Put<uint32_t>(&out, e.map_cols());
    Put<uint32_t>(&out, e.map_rows());
    Put<float>(&out, e.max_error());
    Put<float>(&out, e.mean_error());
    out.append(reinterpret_cast<const char*>(e.map_max_error().data()),
               e.map_max_error_size() * sizeof(float));
    return out;
  }

  // Binary: u32 from, u32 available; f32 (x, y, z)[available - from].
  std::string PathFrom(size_t from) {
    std::string out;
    absl::MutexLock l(&mu_);
    const std::vector<Vec3>& pts = path_.points.empty() ? trail_ : path_.points;
    const size_t n = PathAvailableLocked();
    from = std::min(from, n);
    Put<uint32_t>(&out, from);
    Put<uint32_t>(&out, n);
    for (size_t k = from; k < n; ++k) {
      Put<float>(&out, pts[k].x);
      Put<float>(&out, pts[k].y);
      Put<float>(&out, pts[k].z);
    }
    return out;
  }

  void Routes() {
    // Only requests addressed to this viewer by name: a web page elsewhere
    // cannot reach the session through a DNS name rebound to 127.0.0.1.
    http_.set_pre_routing_handler(
        [this](const httplib::Request& req, httplib::Response& res) {
          const std::string host = req.get_header_value("Host");
          const std::string port = absl::StrCat(":", port_);
          if (host == options_.host + port || host == "localhost" + port) {
            return httplib::Server::HandlerResponse::Unhandled;
          }
          res.status = 403;
          res.set_content("the viewer answers only to " + options_.host + port,
                          "text/plain");
          return httplib::Server::HandlerResponse::Handled;
        });
    http_.Get("/", [](const httplib::Request&, httplib::Response& res) {
      res.set_content(reinterpret_cast<const char*>(kViewerPage), kViewerPageSize, "text/html; charset=utf-8");
    });
    http_.Get("/three/three.min.js",
              [this](const httplib::Request&, httplib::Response& res) {
                res.set_content(three_js_, "text/javascript");
              });
    http_.Get("/three/OrbitControls.js",
              [this](const httplib::Request&, httplib::Response& res) {
                res.set_content(orbit_js_, "text/javascript");
              });
    http_.Get("/api/session",
              [this](const httplib::Request&, httplib::Response& res) {
                res.set_content(SessionJson(), "application/json");
              });
    http_.Get("/api/state",
              [this](const httplib::Request&, httplib::Response& res) {
                absl::MutexLock l(&mu_);
                res.set_content(StateJsonLocked(), "application/json");
              });
    http_.Get("/api/events", [this](const httplib::Request&,
                                    httplib::Response& res) {
      res.set_header("Cache-Control", "no-cache");
      auto last = std::make_shared<uint64_t>(~uint64_t{0});
      {
        absl::MutexLock l(&mu_);
        ++pages_;
      }
      res.set_chunked_content_provider(
          "text/event-stream", [this, last](size_t, httplib::DataSink& sink) {
            std::string msg;
            {
              absl::MutexLock l(&mu_);
              auto fresh = [&] { return stopping_ || state_seq_ != *last; };
              mu_.AwaitWithTimeout(absl::Condition(&fresh), absl::Seconds(1));
              if (stopping_) return false;
              if (state_seq_ != *last) {
                *last = state_seq_;
                msg = absl::StrCat("data: ", StateJsonLocked(), "\n\n");
              } else {
                msg = ": keep-alive\n\n";  // finds a page that has gone
              }
            }
            return sink.write(msg.data(), msg.size());
          },
          [this](bool) {
            absl::MutexLock l(&mu_);
            --pages_;
          });
    });
    http_.Get("/api/tiles", [this](const httplib::Request& req,
                                   httplib::Response& res) {
      std::optional<uint64_t> since;
      uint64_t v;
      if (req.has_param("since")) {
        if (!absl::SimpleAtoi(req.get_param_value("since"), &v)) {
          return SendError(res, absl::InvalidArgumentError("since: bad"));
        }
        since = v;
      }
      res.set_content(TilesSince(since), "application/octet-stream");
    });
    http_.Get("/api/probe", [this](const httplib::Request& req,
                                   httplib::Response& res) {
      auto x = DoubleParam(req, "x"), y = DoubleParam(req, "y");
      if (!x || !y) {
        return SendError(res, absl::InvalidArgumentError(
                                  "probe: give x and y (mm), finite numbers"));
      }
      auto r = Probe(*x, *y);
      if (!r.ok()) return SendError(res, r.status());
      res.set_content(*r, "application/json");
    });
    http_.Get("/api/marks", [this](const httplib::Request& req,
                                   httplib::Response& res) {
      auto r = Marks(DoubleParam(req, "min_angle").value_or(0));
      if (!r.ok()) return SendError(res, r.status());
      res.set_content(*r, "application/octet-stream");
    });
    http_.Get("/api/errormap", [this](const httplib::Request& req,
                                      httplib::Response& res) {
      auto r = ErrorMap(
          static_cast<int32_t>(DoubleParam(req, "samples").value_or(0)));
      if (!r.ok()) return SendError(res, r.status());
      res.set_content(*r, "application/octet-stream");
    });
    http_.Get("/api/deviation", [this](const httplib::Request& req,
                                       httplib::Response& res) {
      const double allowance =
          DoubleParam(req, "allowance").value_or(path_.allowance);
      const double tolerance =
          DoubleParam(req, "tolerance").value_or(path_.tolerance);
      auto r = Deviation(allowance, tolerance);
      if (!r.ok()) return SendError(res, r.status());
      res.set_content(*r, "application/octet-stream");
    });
    http_.Get("/api/safety", [this](const httplib::Request&,
                                    httplib::Response& res) {
      res.set_content(SafetyJson(), "application/json");
    });
    http_.Get("/api/design", [this](const httplib::Request&,
                                    httplib::Response& res) {
      auto r = DesignTriangles();
      if (!r.ok()) return SendError(res, r.status());
      res.set_content(*r, "application/octet-stream");
    });
    http_.Get("/api/path", [this](const httplib::Request& req,
                                  httplib::Response& res) {
      const double from = DoubleParam(req, "from").value_or(0);
      res.set_content(PathFrom(from > 0 ? static_cast<size_t>(from) : 0),
                      "application/octet-stream");
    });
  }

  Connection* const conn_;
  const std::string id_;
  const ViewerOptions options_;
  const ViewerPath path_;
  pb::Session session_;  // as at start: grid and tools
  bool server_design_ = false;  // the session held a design at start
  int32_t stride_ = 1;
  int32_t cols_ = 0, rows_ = 0;  // subsampled nodes
  std::string three_js_, orbit_js_;
  httplib::Server http_;
  int port_ = 0;
  std::thread http_thread_, relay_thread_;

  mutable absl::Mutex mu_;
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  std::vector<CachedTile> tiles_ ABSL_GUARDED_BY(mu_);
  bool have_tiles_ ABSL_GUARDED_BY(mu_) = false;
  // Every change up to this grid version is in tiles_.
  uint64_t cache_version_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t moves_ ABSL_GUARDED_BY(mu_) = 0;
  double rate_ ABSL_GUARDED_BY(mu_) = 0;
  std::deque<std::pair<Clock::time_point, int64_t>> samples_
      ABSL_GUARDED_BY(mu_);
  bool has_position_ ABSL_GUARDED_BY(mu_) = false;
  Vec3 position_ ABSL_GUARDED_BY(mu_);
  std::vector<Vec3> trail_ ABSL_GUARDED_BY(mu_);
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  std::vector<ViewerMarker> markers_ ABSL_GUARDED_BY(mu_);
  std::vector<std::pair<Vec3, Vec3>> air_ ABSL_GUARDED_BY(mu_);
  int pages_ ABSL_GUARDED_BY(mu_) = 0;  // with the event stream open
  std::string error_ ABSL_GUARDED_BY(mu_);
  // Bumps when the state the page sees changes (events are sent on change).
  uint64_t state_seq_ ABSL_GUARDED_BY(mu_) = 0;
};

absl::StatusOr<std::unique_ptr<Viewer>> Viewer::Start(
    Connection* conn, const std::string& session_id,
    const ViewerOptions& options, ViewerPath path) {
  auto impl = std::make_unique<ViewerImpl>(conn, session_id, options,
                                           std::move(path));
  absl::Status s = impl->Init();
  if (!s.ok()) return s;
  return std::unique_ptr<Viewer>(new Viewer(std::move(impl)));
}

Viewer::Viewer(std::unique_ptr<ViewerImpl> impl) : impl_(std::move(impl)) {}
Viewer::~Viewer() = default;
int Viewer::port() const { return impl_->port(); }
std::string Viewer::url() const { return impl_->url(); }
void Viewer::MarkFinished() { impl_->MarkFinished(); }
void Viewer::AddSafety(std::vector<ViewerMarker> markers,
                       std::vector<std::pair<Vec3, Vec3>> air) {
  impl_->AddSafety(std::move(markers), std::move(air));
}
void Viewer::WaitForPage() { impl_->WaitForPage(); }

namespace {
std::atomic<bool> interrupted{false};
extern "C" void OnInterrupt(int) { interrupted = true; }
}  // namespace

void Viewer::ServeUntilInterrupted() {
  interrupted = false;
  auto old_int = std::signal(SIGINT, OnInterrupt);
  auto old_term = std::signal(SIGTERM, OnInterrupt);
  while (!interrupted) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  std::signal(SIGINT, old_int);
  std::signal(SIGTERM, old_term);
}

absl::StatusOr<ViewerOptions> ViewerOptionsFrom(const Args& args) {
  ViewerOptions o;
  auto port = args.GetInt("view-port");
  if (!port.ok()) return port.status();
  if (port->has_value()) {
    if (**port < 0 || **port > 65535) {
      return absl::InvalidArgumentError("--view-port must be in [0, 65535]");
    }
    o.port = **port;
  }
  return o;
}

ViewerPath ViewerPathOf(const std::vector<PathRun>& runs) {
  ViewerPath p;
  int64_t moves = 0;
  bool started = false;
  for (const PathRun& run : runs) {
    for (int64_t k = 0; k < run.size(); ++k) {
      // As StreamPath counts: the first point, and a repositioning run's
      // first, only place the tool.
      if (started && !(run.reposition && k == 0)) ++moves;
      started = true;
      p.points.push_back(run.point(k));
      p.moves_at.push_back(moves);
      p.tools.push_back(run.tool_id);
    }
  }
  p.moves_total = moves;
  return p;
}

}  // namespace swarf::cli
