#include "server/session.h"

#include <cmath>
#include <set>

#include "absl/strings/str_cat.h"

namespace swarf::server {

absl::Status Session::ValidateSpec(const SessionSpec& spec) {
  if (absl::Status s = ValidateStock(spec.stock); !s.ok()) return s;
  if (spec.tools.empty()) {
    return absl::InvalidArgumentError("tools: at least one tool is needed");
  }
  std::set<int32_t> ids;
  for (size_t k = 0; k < spec.tools.size(); ++k) {
    const ToolSpec& t = spec.tools[k];
    if (!ids.insert(t.id).second) {
      return absl::InvalidArgumentError(
          absl::StrCat("tools[", k, "].id ", t.id, " is used twice"));
    }
    if (!(t.radius >= kMinRadius && t.radius <= kMaxRadius)) {
      return absl::InvalidArgumentError(
          absl::StrCat("tools[", k, "].ball.radius must be in [", kMinRadius,
                       ", ", kMaxRadius, "] mm, got ", t.radius));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<Session>> Session::Create(SessionSpec spec) {
  if (absl::Status s = ValidateSpec(spec); !s.ok()) return s;
  auto wp = Workpiece::Create(spec.stock, spec.scheme);
  if (!wp.ok()) return wp.status();
  return std::shared_ptr<Session>(new Session(std::move(spec), *std::move(wp)));
}

int64_t Session::EstimateMemoryBytes(const StockSpec& stock,
                                     SchemeKind scheme) {
  const int64_t tiles_x = (int64_t{stock.nx} + kTileSize) / kTileSize;
  const int64_t tiles_y = (int64_t{stock.ny} + kTileSize) / kTileSize;
  const int64_t per_tile =
      int64_t{kTileNodes} * GetScheme(scheme).bytes_per_node() + 64;
  return tiles_x * tiles_y * per_tile;
}

absl::StatusOr<BatchResult> Session::ApplyBatch(uint64_t seq, int32_t tool_id,
                                                std::span<const double> xyz,
                                                int64_t max_points,
                                                bool reposition) {
  if (seq == 0) {
    return absl::InvalidArgumentError("moves.seq must start at 1");
  }
  if (xyz.size() % 3 != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("moves.xyz has ", xyz.size(),
                     " values, not a whole number of (x, y, z) points"));
  }
  const int64_t points = static_cast<int64_t>(xyz.size() / 3);
  if (points > max_points) {
    return absl::InvalidArgumentError(
        absl::StrCat("moves.xyz has ", points, " points, more than the limit ",
                     max_points, " per batch"));
  }
  const ToolSpec* tool = nullptr;
  for (const ToolSpec& t : spec_.tools) {
    if (t.id == tool_id) tool = &t;
  }
  if (tool == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat(
        "moves.tool_id ", tool_id, " is not a tool of session ", spec_.id));
  }
  static constexpr const char* kAxis[3] = {"x", "y", "z"};
  for (size_t k = 0; k < xyz.size(); ++k) {
    if (!std::isfinite(xyz[k]) || std::fabs(xyz[k]) > kMaxCoordinate) {
      return absl::InvalidArgumentError(absl::StrCat(
          "moves.xyz[", k, "] (point ", k / 3, " ", kAxis[k % 3],
          ") must be finite and within +-", kMaxCoordinate, " mm, got ",
          xyz[k]));
    }
  }

  absl::MutexLock l(&mu_);
  BatchResult r;
  r.seq = seq;
  if (seq <= last_seq_) {
    r.duplicate = true;
    r.moves_applied = wp_->move_count();
    r.version = wp_->version();
    return r;
  }
  if (seq != last_seq_ + 1) {
    return absl::FailedPreconditionError(
        absl::StrCat("moves.seq ", seq, " after ", last_seq_, ": batches ",
                     last_seq_ + 1, "..", seq - 1, " are missing"));
  }
  std::vector<Move> moves;
  moves.reserve(points);
  std::optional<Vec3> pos = reposition ? std::nullopt : last_position_;
  for (int64_t p = 0; p < points; ++p) {
    const Vec3 next{xyz[3 * p], xyz[3 * p + 1], xyz[3 * p + 2]};
    if (pos.has_value()) moves.push_back({*pos, next, tool->radius});
    pos = next;
  }
  auto applied = wp_->Apply(moves);
  if (!applied.ok()) return applied.status();
  last_seq_ = seq;
  last_position_ = pos;
  r.moves_applied = wp_->move_count();
  r.nodes_lowered = applied->nodes_lowered;
  r.version = applied->version;
  for (int32_t t : applied->changed_tiles) {
    r.changed_tiles.emplace_back(t, wp_->TileVersion(t));
  }
  return r;
}

SessionState Session::State() const {
  absl::ReaderMutexLock l(&mu_);
  SessionState s;
  s.last_seq = last_seq_;
  s.moves_applied = wp_->move_count();
  s.version = wp_->version();
  s.allocated_tiles = wp_->allocated_tiles();
  s.memory_bytes = wp_->allocated_node_bytes() +
                   wp_->move_count() * static_cast<int64_t>(sizeof(Move));
  s.last_position = last_position_;
  return s;
}

}  // namespace swarf::server
