// What `swarf run` gathers from the server after the moves, and the files
// and summaries it writes.
#ifndef SWARF_CLIENT_RUN_REPORT_H_
#define SWARF_CLIENT_RUN_REPORT_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "client/cli/args.h"
#include "client/cli/connection.h"
#include "client/outputs/deviation.h"
#include "client/outputs/marks_files.h"
#include "client/outputs/run_outputs.h"
#include "core/cutting_marks.h"
#include "core/scheme.h"
#include "core/stock.h"
#include "core/workpiece.h"
#include "design/design_mesh.h"
#include "design/placed_design.h"

namespace swarf::cli {

struct RunReport {
  std::string file, server, ignored;
  // Feed moves the interpreter dropped (an axis unknown) and its summary
  // naming the first lines; how far (mm) the tip leaves the stock's XY
  // rectangle at worst, on which line, and the summary (empty: it doesn't).
  int64_t dropped_moves = 0;
  std::string dropped, outside_stock;
  double outside_mm = 0;
  int64_t outside_line = 0;
  int64_t moves = 0, lines = 0, node_lowerings = 0;
  // The tools used, by number: "ball d=3.175" (CutterSummary).
  std::vector<std::pair<int, std::string>> tools;
  StockSpec stock;
  SchemeKind scheme = SchemeKind::kGuarded;
  double parse_seconds = 0, simulate_seconds = 0, output_seconds = 0;
  // Error of the scheme against the exact surface (21 samples per element).
  pb::ErrorStats error;
  // Cutting marks (taylor only).
  std::optional<MarkSummary> marks;
  // The marks the files show (FilterMarks), with --out.
  std::optional<MarkSummary> marks_shown;
  MarkDisplayFilter marks_display;
  // The meshes written, with --out.
  double mesh_tolerance = 0;
  RunOutputSummary mesh;
  // The comparison with the design model (--design).
  std::string design;  // its path
  int64_t design_triangles = 0;
  std::optional<DeviationReport> deviation;
  std::optional<SourceLine> gouge_source;  // the deepest gouge's line
  std::vector<std::string> sources;  // the program files, SourceLine::file
  bool tolerance_gate = false;       // --tolerance given: exit 3 when not ok
  std::vector<std::string> files;    // written, in order
  // Each output step and its wall time (s), in order: the error statistics,
  // the marks and the tiles fetched, then every file built and written.
  std::vector<std::pair<std::string, double>> output_steps;
  // Objects computed elsewhere, by stats.json key: JSON text ("safety" and
  // "process", client/cli/safety_report.h).
  std::vector<std::pair<std::string, std::string>> json_sections;
};

// The design model of `swarf run --design`: read before the moves are sent
// (a bad file fails at once), placed on the grid once the stock is known.
struct DesignInput {
  std::string path;
  design::DesignReadOptions read;
  DeviationOptions deviation;
  bool tolerance_given = false;
  // Set by LoadDesign: the mesh, its envelope on the grid, its index.
  std::shared_ptr<const design::PlacedDesign> placed;
  // Each move's source line (by move id), and the files they index.
  std::vector<SourceLine> move_lines;
  std::vector<std::string> sources;
  double seconds = 0;  // reading and placing it
};

// The design flags (documented in `swarf run`'s usage); nullopt without
// --design. InvalidArgument naming the flag.
inline constexpr const char* kDesignFlags[] = {
    "design",    "design-units", "design-offset",
    "allowance", "tolerance",    "deviation-samples"};
absl::StatusOr<std::optional<DesignInput>> ParseDesignFlags(const Args& args);

// Reads the design (NotFound / InvalidArgument / ResourceExhausted naming
// the file) and places it on `stock`'s grid: its top envelope and
// closest-point index.
absl::Status LoadDesign(const StockSpec& stock, DesignInput* design);

// Sends the design file to session `id` (SetDesign, 1 MiB chunks), with
// its units and offset: the session then has it (deviation tiles for the
// viewer). Errors as the server gives them, naming the file.
absl::Status UploadDesign(Connection& conn, const std::string& id,
                          const DesignInput& design);

// --picture-size's default: pixels along a picture's longer side.
inline constexpr int kDefaultPictureSize = 4096;

struct OutputOptions {
  std::string dir;                // empty: no files, statistics only
  int subdivide = 1;              // STL: sub-elements per element side
  double mesh_tolerance = 0.005;  // mm; 0: the full lattice
  MarkDisplayFilter marks_display = kDefaultMarkDisplay;
  // Pixels along the pictures' longer side at most (--picture-size).
  int picture_size = kDefaultPictureSize;
  // The session's moves by id (SurfaceGrid::moves); may be null.
  std::shared_ptr<const MoveSource> moves;
  // Their sweeps already indexed over the stock (the embedded session's
  // own, pinned); null: indexed here where the scheme needs them.
  std::shared_ptr<const MoveSweeps> sweeps;
  // The embedded session's workpiece, pinned (Session::Pin): the passes
  // over the grid read its tiles straight from it, on its threads, instead
  // of through GetTiles (the same doubles, not serialized and parsed on
  // one thread), and its marks are found on it, not fetched. Null: GetTiles
  // and the marks requests.
  std::shared_ptr<const Workpiece> workpiece;
  // The design to compare with (LoadDesign done); not owned, may be null.
  const DesignInput* design = nullptr;
};

// The valued options ParseOutputFlags reads (documented in `swarf run`'s
// usage).
inline constexpr const char* kOutputFlags[] = {
    "mesh-tolerance", "marks-min-angle", "marks-min-length", "picture-size"};

// Whether swarf run asks for the marks as one message first (a
// MarksRequest: no thread wake-up per polyline) or streamed at once
// (GetCuttingMarks). A one-message answer over the server's limit is
// refused only once found, and the marks are then found again: the 300 mm
// plate's first try found 29 of its 47 windows of bands for nothing. The
// answer is about 32 bytes a vertex, and relief jobs have a vertex per 8
// to 10 nodes (cameo.nc at 0.05 mm: 1.5 M vertices on 11.7 M nodes, the
// 1000 mm plate 40 M on 400 M): expected over the limit (64 MiB, the
// client's and swarfd's default) past 16 M nodes.
inline constexpr int64_t kMarksBytesPerNode = 4;
inline constexpr int64_t kMarksMessageBytes = int64_t{64} << 20;
bool MarksFitOneMessage(const StockSpec& stock);

// The error map swarf run asks for: one cell per element, at most 1600
// along the longer side (cells then at least as large as elements).
void ErrorMapSize(const StockSpec& stock, int32_t* cols, int32_t* rows);

// Reads kOutputFlags into `out`; InvalidArgument naming the flag.
absl::Status ParseOutputFlags(const Args& args, OutputOptions* out);

// Fetches the error statistics (and, with a directory, the error map, the
// node grid and the marks) of session `id` and writes the files.
absl::Status CollectAndWrite(Connection& conn, const std::string& id,
                             const OutputOptions& options, RunReport* report);

// The stats document (stats.json) and the human summary.
std::string StatsJson(const RunReport& r);
absl::Status WriteStatsJson(const RunReport& r, const std::string& path);
std::string Summary(const RunReport& r);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_RUN_REPORT_H_
