// Conversions between the public API (swarf.v1 protos) and the core, with
// the validation of every field a client sends (errors name the field).
#ifndef SWARF_SERVER_CONVERT_H_
#define SWARF_SERVER_CONVERT_H_

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/functional/function_ref.h"
#include "absl/status/statusor.h"
#include "core/geometry.h"
#include "core/workpiece.h"
#include "server/session.h"
#include "swarf/v1/swarf.pb.h"

namespace swarf::server {

namespace pb = ::swarf::v1;

// The API's scheme for a core scheme, and back (SCHEME_UNSPECIFIED is
// SCHEME_GUARDED; InvalidArgument naming `field` for an unknown value).
pb::Scheme SchemeToProto(SchemeKind kind);
absl::StatusOr<SchemeKind> SchemeFromProto(int value, const std::string& field);

// Tools. The API's shape oneof names the core's CutterKind one to one
// (CutterKindName: ball, flat, bull_nose, cone, tapered_ball), so a field
// is "tools[k].<shape>.<dimension>".
//
// ValidateCutter with the field prefix "tools[k].<shape>": the one
// validation of a tool, used by ToolFromProto and Session::ValidateSpec.
absl::Status ValidateTool(const ToolSpec& tool, int k);
// The tool `tools[k]` of a request (or a journal's definition): its cutter,
// validated. InvalidArgument naming "tools[k]" when it has no shape, or the
// bad field.
absl::StatusOr<ToolSpec> ToolFromProto(const pb::Tool& t, int k);
// The inverse: ToolFromProto(ToolToProto(t)) == t for a valid tool (a ball
// is written exactly as before cutters had kinds, so old journals restore).
void ToolToProto(const ToolSpec& t, pb::Tool* out);

// A batch's arcs (MoveBatch.arcs): InvalidArgument naming
// "moves.arcs[k].<field>" for a missing centre or an unknown plane (the
// rest is checked by ChordBatch, which knows the points).
absl::StatusOr<std::vector<ArcSpec>> ArcsFromProto(const pb::MoveBatch& b);

absl::StatusOr<SessionSpec> SpecFromRequest(
    const pb::CreateSessionRequest& req);
void FillSession(const Session& s, const std::string& replica,
                 pb::Session* out);

// A rectangle from the API: finite, x0 <= x1, y0 <= y1. `field` names it.
absl::StatusOr<Rect> RectFromProto(const pb::Rect& r, const std::string& field);

// Tiles selected by a region or explicit indices (all when `sel` is null or
// empty), ascending.
absl::StatusOr<std::vector<int32_t>> SelectTiles(const Workpiece& wp,
                                                 const pb::TileSelection* sel);

struct TileOptions {
  uint64_t request_id = 0;
  bool doubles = false;
  bool derivatives = false;
  bool owners = false;
};
// FAILED_PRECONDITION when derivatives are asked of a scheme without them.
absl::StatusOr<TileOptions> TileOptionsFrom(const Workpiece& wp,
                                            uint64_t request_id,
                                            pb::Precision precision,
                                            bool derivatives, bool owners);
void FillTile(const Workpiece& wp, int32_t t, const TileOptions& opt,
              pb::Tile* out);
// FillTile(wp, tiles[k], opt, out[k]) for every k (out.size() ==
// tiles.size()). With derivatives, which the read computes, the tiles are
// filled at once on the workpiece's pool.
void FillTiles(const Workpiece& wp, std::span<const int32_t> tiles,
               const TileOptions& opt, std::span<pb::Tile* const> out);

absl::StatusOr<pb::ErrorStats> ComputeStats(const Workpiece& wp,
                                            const pb::Rect* region,
                                            int32_t samples_per_edge,
                                            int32_t map_cols = 0,
                                            int32_t map_rows = 0);

// The cutting marks (GetCuttingMarksRequest's fields), every one held.
absl::StatusOr<std::vector<pb::Polyline>> ComputeMarks(
    const Workpiece& wp, const pb::Rect* region, double screening_threshold,
    double min_angle_deg);
// The same marks in the same order, one at a time as the core completes
// them (FindCuttingMarks with emit and poll): only the open creases are
// held. A non-OK status from `emit` or `poll` stops the search and is
// returned. Both run on the calling thread and may block.
absl::Status StreamMarks(const Workpiece& wp, const pb::Rect* region,
                         double screening_threshold, double min_angle_deg,
                         absl::FunctionRef<absl::Status(pb::Polyline)> emit,
                         absl::FunctionRef<absl::Status()> poll);

absl::StatusOr<pb::ProbeResponse> ComputeProbe(const Workpiece& wp,
                                               const pb::ProbeRequest& req);

}  // namespace swarf::server

#endif  // SWARF_SERVER_CONVERT_H_
