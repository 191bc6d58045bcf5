#include "server/convert.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "core/cutting_marks.h"
#include "core/valuation.h"

namespace swarf::server {
namespace {

absl::Status Finite(double v, const std::string& field) {
  if (!std::isfinite(v)) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, " must be finite, got ", v));
  }
  return absl::OkStatus();
}

// Element count for `length` at `spacing`, or InvalidArgument.
absl::StatusOr<int32_t> Elements(double length, double spacing,
                                 const char* axis) {
  const double n = std::ceil(length / spacing - 1e-9);
  if (!(n >= 1 && n <= kMaxElementsPerAxis)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "spacing ", spacing, " gives ", n, " elements along ", axis,
        "; at most ", kMaxElementsPerAxis));
  }
  return static_cast<int32_t>(n);
}

// ValidateStock but for the total node count: a grid over the server's node
// limit is RESOURCE_EXHAUSTED (the registry), even where it is also over the
// core's, which ValidateStock reports as bad input.
absl::Status ValidateStockShape(const StockSpec& stock) {
  StockSpec row = stock, column = stock;
  row.ny = 1;
  column.nx = 1;
  if (absl::Status s = ValidateStock(row); !s.ok()) return s;
  return ValidateStock(column);
}

}  // namespace

pb::Scheme SchemeToProto(SchemeKind kind) {
  switch (kind) {
    case SchemeKind::kZmap:
      return pb::SCHEME_ZMAP;
    case SchemeKind::kTaylor:
      return pb::SCHEME_TAYLOR;
    case SchemeKind::kExact:
      return pb::SCHEME_EXACT;
    case SchemeKind::kGuarded:
      break;
  }
  return pb::SCHEME_GUARDED;
}

absl::StatusOr<SchemeKind> SchemeFromProto(int value,
                                           const std::string& field) {
  switch (value) {
    case pb::SCHEME_ZMAP:
      return SchemeKind::kZmap;
    case pb::SCHEME_TAYLOR:
      return SchemeKind::kTaylor;
    case pb::SCHEME_EXACT:
      return SchemeKind::kExact;
    case pb::SCHEME_UNSPECIFIED:
    case pb::SCHEME_GUARDED:
      return SchemeKind::kGuarded;
    default:
      return absl::InvalidArgumentError(
          absl::StrCat(field, " ", value, " is unknown"));
  }
}

absl::Status ValidateTool(const ToolSpec& tool, int k) {
  const ToolAssembly& a = tool.assembly;
  const struct {
    const char* name;
    double v;
  } parts[] = {{"flute_length", a.flute_length},
               {"shank_diameter", a.shank_diameter},
               {"holder_diameter", a.holder_diameter},
               {"stickout", a.stickout}};
  for (const auto& p : parts) {
    if (!(p.v >= 0 && p.v <= 2 * kMaxRadius)) {
      return absl::InvalidArgumentError(
          absl::StrCat("tools[", k, "].", p.name, " must be in [0, ",
                       2 * kMaxRadius, "] mm (0: not known), got ", p.v));
    }
  }
  if ((a.holder_diameter > 0) != (a.stickout > 0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "tools[", k, "]: holder_diameter and stickout go together"));
  }
  return ValidateCutter(
      tool.cutter, absl::StrCat("tools[", k, "].",
                                std::string(CutterKindName(tool.cutter.kind))));
}

absl::StatusOr<ToolSpec> ToolFromProto(const pb::Tool& t, int k) {
  ToolSpec tool{t.id(), {}, {}};
  tool.assembly.flute_length = t.flute_length();
  tool.assembly.shank_diameter = t.shank_diameter();
  tool.assembly.holder_diameter = t.holder_diameter();
  tool.assembly.stickout = t.stickout();
  tool.assembly.center_cutting = !t.not_center_cutting();
  switch (t.shape_case()) {
    case pb::Tool::kBall:
      tool.cutter = Cutter::Ball(t.ball().radius());
      break;
    case pb::Tool::kFlat:
      tool.cutter = Cutter::Flat(t.flat().radius());
      break;
    case pb::Tool::kBullNose:
      tool.cutter = Cutter::BullNose(t.bull_nose().radius(),
                                     t.bull_nose().corner_radius());
      break;
    case pb::Tool::kCone:
      tool.cutter = Cutter::Cone(t.cone().radius(), t.cone().half_angle_deg(),
                                 t.cone().tip_radius());
      break;
    case pb::Tool::kTaperedBall:
      tool.cutter = Cutter::TaperedBall(t.tapered_ball().radius(),
                                        t.tapered_ball().tip_radius(),
                                        t.tapered_ball().half_angle_deg());
      break;
    case pb::Tool::SHAPE_NOT_SET:
      return absl::InvalidArgumentError(absl::StrCat(
          "tools[", k,
          "]: a shape is required (ball, flat, bull_nose, cone or "
          "tapered_ball)"));
  }
  if (absl::Status s = ValidateTool(tool, k); !s.ok()) return s;
  return tool;
}

void ToolToProto(const ToolSpec& t, pb::Tool* out) {
  out->set_id(t.id);
  out->set_flute_length(t.assembly.flute_length);
  out->set_shank_diameter(t.assembly.shank_diameter);
  out->set_holder_diameter(t.assembly.holder_diameter);
  out->set_stickout(t.assembly.stickout);
  out->set_not_center_cutting(!t.assembly.center_cutting);
  const Cutter& c = t.cutter;
  switch (c.kind) {
    case CutterKind::kBall:
      out->mutable_ball()->set_radius(c.radius);
      return;
    case CutterKind::kFlat:
      out->mutable_flat()->set_radius(c.radius);
      return;
    case CutterKind::kBullNose:
      out->mutable_bull_nose()->set_radius(c.radius);
      out->mutable_bull_nose()->set_corner_radius(c.corner_radius);
      return;
    case CutterKind::kCone:
      out->mutable_cone()->set_radius(c.radius);
      out->mutable_cone()->set_half_angle_deg(c.half_angle_deg);
      out->mutable_cone()->set_tip_radius(c.tip_radius);
      return;
    case CutterKind::kTaperedBall:
      out->mutable_tapered_ball()->set_radius(c.radius);
      out->mutable_tapered_ball()->set_tip_radius(c.tip_radius);
      out->mutable_tapered_ball()->set_half_angle_deg(c.half_angle_deg);
      return;
  }
}

absl::StatusOr<std::vector<ArcSpec>> ArcsFromProto(const pb::MoveBatch& b) {
  std::vector<ArcSpec> arcs;
  arcs.reserve(b.arcs_size());
  for (int k = 0; k < b.arcs_size(); ++k) {
    const pb::Arc& a = b.arcs(k);
    if (!a.has_centre()) {
      return absl::InvalidArgumentError(
          absl::StrCat("moves.arcs[", k, "].centre is required"));
    }
    ArcSpec s;
    s.end_index = a.end_index();
    s.centre = {a.centre().x(), a.centre().y(), a.centre().z()};
    switch (a.plane()) {
      case pb::ARC_PLANE_UNSPECIFIED:
      case pb::ARC_PLANE_XY:
        s.plane = 17;
        break;
      case pb::ARC_PLANE_XZ:
        s.plane = 18;
        break;
      case pb::ARC_PLANE_YZ:
        s.plane = 19;
        break;
      default:
        return absl::InvalidArgumentError(absl::StrCat(
            "moves.arcs[", k, "].plane ", a.plane(),
            " is not an ArcPlane (1 XY, 2 XZ, 3 YZ)"));
    }
    s.clockwise = a.clockwise();
    s.turns = a.turns();
    arcs.push_back(s);
  }
  return arcs;
}

absl::StatusOr<SessionSpec> SpecFromRequest(
    const pb::CreateSessionRequest& req) {
  SessionSpec spec;
  spec.id = req.session_id();
  if (!req.has_stock()) return absl::InvalidArgumentError("stock is required");
  const pb::Stock& st = req.stock();
  spec.stock = {st.x0(), st.y0(), st.x1(), st.y1(), st.z_top(), req.nx(),
                req.ny()};
  if (req.nx() != 0 || req.ny() != 0) {
    if (req.spacing() != 0) {
      return absl::InvalidArgumentError(
          "give either nx and ny, or spacing, not both");
    }
  } else {
    if (absl::Status s = Finite(req.spacing(), "spacing"); !s.ok()) return s;
    if (!(req.spacing() > 0)) {
      return absl::InvalidArgumentError(
          "nx and ny (element counts), or spacing > 0, are required");
    }
    // Validate the rectangle first so the counts below are meaningful.
    StockSpec probe = spec.stock;
    probe.nx = probe.ny = 1;
    if (absl::Status s = ValidateStock(probe); !s.ok()) return s;
    auto nx = Elements(st.x1() - st.x0(), req.spacing(), "x");
    if (!nx.ok()) return nx.status();
    auto ny = Elements(st.y1() - st.y0(), req.spacing(), "y");
    if (!ny.ok()) return ny.status();
    spec.stock.nx = *nx;
    spec.stock.ny = *ny;
  }
  if (absl::Status s = ValidateStockShape(spec.stock); !s.ok()) return s;
  auto scheme = SchemeFromProto(req.scheme(), "scheme");
  if (!scheme.ok()) return scheme.status();
  spec.scheme = *scheme;
  if (req.has_arc_tolerance()) {
    spec.arc_tolerance = req.arc_tolerance().value();
    if (!(spec.arc_tolerance >= kMinArcTolerance &&
          spec.arc_tolerance <= kMaxArcTolerance)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "arc_tolerance must be in [", kMinArcTolerance, ", ",
          kMaxArcTolerance, "] mm, got ", spec.arc_tolerance));
    }
  }
  for (int k = 0; k < req.tools_size(); ++k) {
    auto tool = ToolFromProto(req.tools(k), k);
    if (!tool.ok()) return tool.status();
    spec.tools.push_back(*tool);
  }
  return spec;
}

void FillSession(const Session& s, const std::string& replica,
                 pb::Session* out) {
  const SessionSpec& spec = s.spec();
  out->set_session_id(spec.id);
  pb::Stock* st = out->mutable_stock();
  st->set_x0(spec.stock.x0);
  st->set_y0(spec.stock.y0);
  st->set_x1(spec.stock.x1);
  st->set_y1(spec.stock.y1);
  st->set_z_top(spec.stock.z_top);
  out->set_nx(spec.stock.nx);
  out->set_ny(spec.stock.ny);
  out->set_scheme(SchemeToProto(spec.scheme));
  for (const ToolSpec& t : spec.tools) ToolToProto(t, out->add_tools());
  out->set_tile_size(kTileSize);
  // From the spec, as the workpiece computes them: an evicted session is
  // described without being reloaded.
  out->set_tiles_x((s.spec().stock.nx + kTileSize) / kTileSize);
  out->set_tiles_y((s.spec().stock.ny + kTileSize) / kTileSize);
  const SessionState state = s.State();
  out->set_last_seq(state.last_seq);
  out->set_moves_applied(state.moves_applied);
  out->set_version(state.version);
  out->set_allocated_tiles(state.allocated_tiles);
  out->set_memory_bytes(state.memory_bytes);
  if (state.last_position.has_value()) {
    out->mutable_last_position()->set_x(state.last_position->x);
    out->mutable_last_position()->set_y(state.last_position->y);
    out->mutable_last_position()->set_z(state.last_position->z);
  }
  out->set_replica(replica);
  out->set_recovery(s.recovery());
  out->set_snapshot_seq(state.snapshot_seq);
  out->set_arc_tolerance(spec.arc_tolerance);
}

absl::StatusOr<Rect> RectFromProto(const pb::Rect& r,
                                   const std::string& field) {
  const Rect out{r.x0(), r.y0(), r.x1(), r.y1()};
  if (!std::isfinite(out.x0) || !std::isfinite(out.y0) ||
      !std::isfinite(out.x1) || !std::isfinite(out.y1)) {
    return absl::InvalidArgumentError(absl::StrCat(field, " must be finite"));
  }
  if (out.x1 < out.x0 || out.y1 < out.y0) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, " must have x0 <= x1 and y0 <= y1"));
  }
  return out;
}

absl::StatusOr<std::vector<int32_t>> SelectTiles(
    const Workpiece& wp, const pb::TileSelection* sel) {
  std::vector<int32_t> out;
  if (sel != nullptr && sel->tiles_size() > 0) {
    for (int k = 0; k < sel->tiles_size(); ++k) {
      const pb::TileIndex& t = sel->tiles(k);
      if (t.tx() < 0 || t.tx() >= wp.tiles_x() || t.ty() < 0 ||
          t.ty() >= wp.tiles_y()) {
        return absl::InvalidArgumentError(absl::StrCat(
            "selection.tiles[", k, "] (", t.tx(), ", ", t.ty(),
            ") is outside the tiles [0, ", wp.tiles_x(), ") x [0, ",
            wp.tiles_y(), ")"));
      }
      out.push_back(t.ty() * wp.tiles_x() + t.tx());
    }
  } else if (sel != nullptr && sel->has_region()) {
    auto r = RectFromProto(sel->region(), "selection.region");
    if (!r.ok()) return r.status();
    const GridGeometry& g = wp.grid();
    // Nodes within the region, clamped to the grid, then their tiles.
    auto range = [](double a, double b, double origin, double step,
                    int32_t max) {
      const double lo = std::ceil((a - origin) / step);
      const double hi = std::floor((b - origin) / step);
      return std::pair{static_cast<int32_t>(std::clamp(lo, 0.0, 1.0 * max)),
                       static_cast<int32_t>(std::clamp(hi, -1.0, 1.0 * max))};
    };
    const auto [i0, i1] = range(r->x0, r->x1, g.spec().x0, g.dx(), g.nx());
    const auto [j0, j1] = range(r->y0, r->y1, g.spec().y0, g.dy(), g.ny());
    if (i0 <= i1 && j0 <= j1) {
      for (int32_t ty = j0 / kTileSize; ty <= j1 / kTileSize; ++ty) {
        for (int32_t tx = i0 / kTileSize; tx <= i1 / kTileSize; ++tx) {
          out.push_back(ty * wp.tiles_x() + tx);
        }
      }
    }
  } else {
    for (int32_t t = 0; t < wp.tile_count(); ++t) out.push_back(t);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

absl::StatusOr<TileOptions> TileOptionsFrom(const Workpiece& wp,
                                            uint64_t request_id,
                                            pb::Precision precision,
                                            bool derivatives, bool owners) {
  if (derivatives && !wp.scheme().stores_derivatives()) {
    return absl::FailedPreconditionError(absl::StrCat(
        "include_derivatives: the session's scheme ",
        std::string(wp.scheme().name()),
        " stores no derivatives (use taylor)"));
  }
  if (precision != pb::PRECISION_UNSPECIFIED &&
      precision != pb::PRECISION_FLOAT && precision != pb::PRECISION_DOUBLE) {
    return absl::InvalidArgumentError(
        absl::StrCat("precision ", precision, " is unknown"));
  }
  TileOptions o;
  o.request_id = request_id;
  o.doubles = precision == pb::PRECISION_DOUBLE;
  o.derivatives = derivatives;
  o.owners = owners;
  return o;
}

void FillTile(const Workpiece& wp, int32_t t, const TileOptions& opt,
              pb::Tile* out) {
  const Workpiece::TileExtent e = wp.Extent(t);
  const int32_t n = e.nx * e.ny;
  out->set_request_id(opt.request_id);
  out->set_tx(t % wp.tiles_x());
  out->set_ty(t / wp.tiles_x());
  out->set_version(wp.TileVersion(t));
  out->set_i0(e.i0);
  out->set_j0(e.j0);
  out->set_nx(e.nx);
  out->set_ny(e.ny);
  // Read straight into the message's fields: a tile is 28 bytes a node
  // with derivatives, and a copy through buffers cost as much as the read.
  auto fill = [n](auto* field) {
    field->Reserve(n);
    return field->AddNAlreadyReserved(n);
  };
  float* dp[5] = {};
  if (opt.derivatives) {
    dp[0] = fill(out->mutable_wx());
    dp[1] = fill(out->mutable_wy());
    dp[2] = fill(out->mutable_wxx());
    dp[3] = fill(out->mutable_wxy());
    dp[4] = fill(out->mutable_wyy());
  }
  int32_t* owner = opt.owners ? fill(out->mutable_owners()) : nullptr;
  if (opt.doubles) {
    wp.ReadTile(t, fill(out->mutable_heights_d()),
                opt.derivatives ? dp : nullptr, owner);
    return;
  }
  std::vector<double> w(n);
  wp.ReadTile(t, w.data(), opt.derivatives ? dp : nullptr, owner);
  float* h = fill(out->mutable_heights_f());
  for (int32_t k = 0; k < n; ++k) h[k] = static_cast<float>(w[k]);
}

void FillTiles(const Workpiece& wp, std::span<const int32_t> tiles,
               const TileOptions& opt, std::span<pb::Tile* const> out) {
  auto fill = [&](int64_t k) { FillTile(wp, tiles[k], opt, out[k]); };
  if (!opt.derivatives) {
    for (size_t k = 0; k < tiles.size(); ++k) fill(static_cast<int64_t>(k));
    return;
  }
  wp.pool().ParallelFor(static_cast<int64_t>(tiles.size()), fill);
}

absl::StatusOr<pb::ErrorStats> ComputeStats(const Workpiece& wp,
                                            const pb::Rect* region,
                                            int32_t samples_per_edge,
                                            int32_t map_cols,
                                            int32_t map_rows) {
  // Checked here as well as in MeasureError, to name the fields.
  if ((map_cols != 0 || map_rows != 0) &&
      (map_cols < 1 || map_rows < 1 ||
       int64_t{map_cols} * map_rows > kMaxMapCells)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "map_cols x map_rows must be 0 x 0 (no map) or at least 1 x 1 and "
        "at most ", kMaxMapCells, " cells, got ", map_cols, " x ", map_rows));
  }
  ValuationOptions opt;
  opt.samples_per_edge = samples_per_edge == 0 ? 5 : samples_per_edge;
  opt.map_cols = map_cols;
  opt.map_rows = map_rows;
  if (region != nullptr) {
    auto r = RectFromProto(*region, "region");
    if (!r.ok()) return r.status();
    opt.region = *r;
  }
  auto stats = MeasureError(wp, opt);
  if (!stats.ok()) return stats.status();
  pb::ErrorStats out;
  out.set_scheme(SchemeToProto(wp.scheme().kind()));
  out.set_max_error(stats->max_error);
  out.set_mean_error(stats->mean_error);
  out.set_rms_error(stats->rms_error);
  out.set_max_x(stats->max_x);
  out.set_max_y(stats->max_y);
  out.set_samples(stats->samples);
  if (!stats->map.empty()) {
    out.set_map_cols(stats->map_cols);
    out.set_map_rows(stats->map_rows);
    out.mutable_map_max_error()->Assign(stats->map.begin(), stats->map.end());
  }
  return out;
}

absl::Status StreamMarks(const Workpiece& wp, const pb::Rect* region,
                         double screening_threshold, double min_angle_deg,
                         absl::FunctionRef<absl::Status(pb::Polyline)> emit,
                         absl::FunctionRef<absl::Status()> poll) {
  MarkOptions opt;
  if (region != nullptr) {
    auto r = RectFromProto(*region, "region");
    if (!r.ok()) return r.status();
    opt.region = *r;
  }
  // Checked here as well as in FindCuttingMarks, to name the fields.
  if (!(std::isfinite(screening_threshold) && screening_threshold >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("screening_threshold must be finite and >= 0 (0: the "
                     "default), got ", screening_threshold));
  }
  if (!(min_angle_deg == 0 || (min_angle_deg > 0 && min_angle_deg < 90))) {
    return absl::InvalidArgumentError(absl::StrCat(
        "min_angle_deg must be in (0, 90) (0: the default), got ",
        min_angle_deg));
  }
  if (screening_threshold != 0) opt.screening_threshold = screening_threshold;
  if (min_angle_deg != 0) opt.t2_deg = min_angle_deg;
  // Each polyline converted as the core hands it on: the core's marks are
  // never all held beside their protobuf copies.
  return FindCuttingMarks(
      wp, opt,
      [&](MarkPolyline m) {
        pb::Polyline p;
        p.set_closed(m.closed);
        p.add_owners(m.owners[0]);
        p.add_owners(m.owners[1]);
        p.mutable_xyz()->Reserve(3 * m.vertices.size());
        for (const Vec3& v : m.vertices) {
          p.add_xyz(v.x);
          p.add_xyz(v.y);
          p.add_xyz(v.z);
        }
        p.mutable_angle_deg()->Assign(m.angle_deg.begin(), m.angle_deg.end());
        return emit(std::move(p));
      },
      poll);
}

absl::StatusOr<std::vector<pb::Polyline>> ComputeMarks(
    const Workpiece& wp, const pb::Rect* region, double screening_threshold,
    double min_angle_deg) {
  std::vector<pb::Polyline> out;
  absl::Status found = StreamMarks(
      wp, region, screening_threshold, min_angle_deg,
      [&](pb::Polyline p) {
        out.push_back(std::move(p));
        return absl::OkStatus();
      },
      [] { return absl::OkStatus(); });
  if (!found.ok()) return found;
  return out;
}

absl::StatusOr<pb::ProbeResponse> ComputeProbe(const Workpiece& wp,
                                               const pb::ProbeRequest& req) {
  if (req.xy_size() % 2 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "xy has ", req.xy_size(), " values, not a whole number of points"));
  }
  pb::ProbeResponse out;
  const GridGeometry& g = wp.grid();
  for (int k = 0; k + 1 < req.xy_size(); k += 2) {
    const double x = req.xy(k), y = req.xy(k + 1);
    if (!std::isfinite(x) || !std::isfinite(y)) {
      const int bad = std::isfinite(x) ? k + 1 : k;
      return absl::InvalidArgumentError(absl::StrCat(
          "xy[", bad, "] (point ", k / 2, " ", bad == k ? "x" : "y",
          ") must be finite, got ", req.xy(bad)));
    }
    double gx, gy;
    wp.ReconstructGradient(x, y, &gx, &gy);
    const double len = std::sqrt(gx * gx + gy * gy + 1);
    out.add_heights(wp.Reconstruct(x, y));
    out.add_normals(-gx / len);
    out.add_normals(-gy / len);
    out.add_normals(1 / len);
    const double fi = std::round((std::clamp(x, g.spec().x0, g.spec().x1) -
                                  g.spec().x0) / g.dx());
    const double fj = std::round((std::clamp(y, g.spec().y0, g.spec().y1) -
                                  g.spec().y0) / g.dy());
    out.add_owners(wp.Node(static_cast<int32_t>(std::min(fi, 1.0 * g.nx())),
                           static_cast<int32_t>(std::min(fj, 1.0 * g.ny())))
                       .owner);
  }
  return out;
}

}  // namespace swarf::server
