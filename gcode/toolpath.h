// Toolpath input: G-code for 3-axis mills, run by an RS274/NGC interpreter
// (the LinuxCNC dialect; gcode/interpreter.cc), and CSV/XYZ files of
// tool-tip positions, parsed into a polyline of tool-tip points in mm.
//
// G-code rules (every G, M and O word: the README's G-code table):
// - Start position. A program starts from an unknown machine position
//   unless GcodeOptions::start is given. Each axis is unknown until a word
//   gives it; moves before X, Y and Z are all known only set the known axes
//   and produce no point. The polyline starts at the first position where
//   all three are known. Incremental moves (G91) of an unknown axis and arcs
//   before the start are errors. A feed move whose start or end is unknown
//   is dropped and counted (Toolpath::dropped_moves); rapids from an unknown
//   position only position the machine.
// - Tool changes. M6 keeps the position, as LinuxCNC (optionally after a
//   rapid to GcodeOptions::tool_change_position); with
//   m6_forgets_position, and after G28/G30 to an unknown home, the axes
//   become unknown and the next fully known position starts a new run
//   (ToolpathPoint::starts_run). No move joins two runs.
// - Parity with LinuxCNC's rs274 is checked by scripts/linuxcnc-diff (the
//   README's G-code section lists where they differ and why).
// - Units: G21 mm (the default when neither G20 nor G21 is given, with a
//   note), G20 inches (x25.4). G90/G91, G90.1/G91.1.
// - Parameters, expressions (gcode/expression.h), O-word subroutines and
//   control flow (external o<name> files from
//   GcodeOptions::subroutine_dir), offsets (G10 L2/L20, G52, G54-G59.3,
//   G92.x, G53, G43.1), G28/G30, canned cycles G73 G74 G81-G89 with
//   G98/G99, arcs in G17/G18/G19 (I/J/K or R, helical, P turns; chords
//   within GcodeOptions::arc_tolerance, the last point the programmed end
//   bit for bit), polar coordinates (@, ^), cutter compensation G41/G42 in
//   G17. The interpreter emits canonical commands (gcode/canon.h) to a
//   sink: ToolpathBuilder unless ParseGcode is given another.
// - Words that don't move the tool (F, S, H, M3, M8, G17, G40, G43, G49,
//   G54, G80, G94, ...) are counted in Toolpath::ignored(). Anything that
//   would change the tool's path and isn't simulated (G33, G38.x, G76 in
//   the LinuxCNC dialect, A/B/C axes, ...) is an InvalidArgument error
//   "line N: ..." naming the word: never a guess. Errors in an external
//   subroutine file read "line N of FILE (called from line M): ...".
// - Reading stops at M2/M30, or at the second '%' when the program starts
//   with one. Executing more than GcodeOptions::max_blocks blocks, or
//   nesting calls deeper than max_call_depth, is an error.
// - A move that doesn't change the position (in either format) adds no
//   point.
//
// Positions are the tool tip in machine coordinates; every offset is zero
// until the program sets one, so a program without offsets gets its own
// coordinates.
//
// Thread safety: the functions are reentrant; a Toolpath is a value (const
// methods may run concurrently).
#ifndef SWARF_GCODE_TOOLPATH_H_
#define SWARF_GCODE_TOOLPATH_H_

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry.h"
#include "gcode/canon.h"

namespace swarf::gcode {

// One tool-tip position. 32 bytes: toolpaths hold millions of points.
struct ToolpathPoint {
  Vec3 position;       // tool tip, mm, absolute program coordinates
  int32_t line = 0;    // 1-based source line that produced the point
  uint16_t tool = 0;   // tool in effect (see ParseGcode); 0: none selected
  bool rapid = false;  // the move ending here is a rapid (G0)
  // No move reaches this point: the first point, or the first after a tool
  // change. The move to point i (i > 0) is points[i-1] -> points[i] unless
  // points[i].starts_run.
  bool starts_run = false;
};
static_assert(sizeof(ToolpathPoint) == 32);

// A parsed toolpath: points in program order plus what the parser ignored.
class Toolpath {
 public:
  const std::vector<ToolpathPoint>& points() const { return points_; }
  int64_t point_count() const { return static_cast<int64_t>(points_.size()); }
  // Straight moves: consecutive points within a run.
  int64_t move_count() const { return point_count() - runs_; }
  int64_t run_count() const { return runs_; }

  // Bounds of all points, rapids and retracts included (mm); empty
  // intervals when there are no points.
  const Interval& x_bounds() const { return x_bounds_; }
  const Interval& y_bounds() const { return y_bounds_; }
  const Interval& z_bounds() const { return z_bounds_; }

  // Distinct tool numbers of the points, in order of first use.
  std::vector<int> Tools() const;
  // The line where tool number n was first selected (a T word before any
  // M6, M6, M61), nullopt if never (tool 0 when no T word is given).
  std::optional<int32_t> ToolSelectedAt(int n) const;

  // Source lines read (up to the program end).
  int64_t source_lines() const { return source_lines_; }
  // Blocks executed (G-code: lines with words, loops and calls unrolled).
  int64_t blocks_executed() const { return blocks_executed_; }
  void set_blocks_executed(int64_t n) { blocks_executed_ = n; }

  // Words accepted without effect on the tool path, by word: "F", "S",
  // "H", "M3" (M03 counts as M3), "G43", "G90.1"-style codes, "O" (program
  // number), "/" (block delete mark, the block is executed).
  const std::map<std::string, int64_t>& ignored() const { return ignored_; }
  int64_t ignored_total() const;
  // One line for the user, e.g. "ignored 5 words that don't move the tool:
  // G17 x1, M3 x1, F x2, S x1"; empty when nothing was ignored.
  std::string IgnoredSummary() const;

  // Remarks to show once, e.g. "no G20/G21: millimetres assumed".
  const std::vector<std::string>& notes() const { return notes_; }

  // Moves the interpreter could not simulate because an axis was unknown
  // (feeds after M6 or G28 to an unknown home before X, Y and Z are known
  // again, or with an axis never given), and the first of them.
  struct DroppedMove {
    int32_t line = 0;
    char missing[4] = {};  // the unknown axes, e.g. "Z" or "XYZ"
  };
  int64_t dropped_moves() const { return dropped_moves_; }
  const std::vector<DroppedMove>& first_dropped() const {
    return first_dropped_;
  }
  // "dropped 3 feed moves with an unknown axis: line 4 (Z unknown), ...";
  // empty when none.
  std::string DroppedSummary() const;

  // Appends the program run after this one (CAMotics projects run several
  // files in order): its points, the first starting a run (each program
  // starts from an unknown position), and its counts, notes and dropped
  // moves (whose lines are its own file's).
  void AppendProgram(const Toolpath& next);

  // Building (the parsers; tests). Append drops a point that repeats the
  // previous point's position within a run: a zero-length move sweeps
  // nothing.
  void Append(const ToolpathPoint& p);
  // With the feed of the move ending at p (mm/min; see feed()).
  void Append(const ToolpathPoint& p, float feed);
  // The programmed feed of the move ending at point k (mm/min): > 0 a
  // feed, 0 a feed of F0 (or before any F) or a rapid, < 0 not known (x,y,z
  // files).
  float feed(int64_t k) const { return feeds_[k]; }
  void CountIgnored(const std::string& word, int64_t n = 1);
  void AddNote(std::string note) { notes_.push_back(std::move(note)); }
  void set_source_lines(int64_t n) { source_lines_ = n; }
  // Keeps the first kFirstDropped.
  static constexpr size_t kFirstDropped = 10;
  void AddDropped(int32_t line, unsigned missing_axes_mask);
  // Keeps the first line per tool.
  void NoteToolSelected(int tool, int32_t line) {
    tool_selected_.emplace(tool, line);
  }
  // Room for `points` points, the pages of the first `expected` of them
  // (at most `points`) faulted in on every thread (PopulatePages): written
  // one by one as a program is read, their page faults were the slowest
  // part of reading a large one.
  void Reserve(int64_t points, int64_t expected = 0);
  // Gives back capacity beyond half the size over it (a trim copies every
  // point into freshly faulted memory: slow, so only for a large waste).
  void Trim() {
    if (points_.capacity() > points_.size() + points_.size() / 2) {
      points_.shrink_to_fit();
      feeds_.shrink_to_fit();
    }
  }

 private:
  std::vector<ToolpathPoint> points_;
  std::vector<float> feeds_;  // per point, feed()
  int64_t runs_ = 0;
  Interval x_bounds_, y_bounds_, z_bounds_;
  int64_t source_lines_ = 0;
  int64_t blocks_executed_ = 0;
  std::map<std::string, int64_t> ignored_;
  std::vector<std::string> notes_;
  int64_t dropped_moves_ = 0;
  std::vector<DroppedMove> first_dropped_;
  std::map<int, int32_t> tool_selected_;
};

enum class Dialect {
  kLinuxCnc,  // RS274/NGC as LinuxCNC documents it (the default)
  kFanuc,     // + M98/M99 subprograms (O-numbered programs in the file)
  kGrbl,      // + '$' setting lines ignored with a note
};

struct GcodeOptions {
  // Largest distance between an arc and its chords (mm); in [1e-6, 10].
  double arc_tolerance = 0.001;
  // More points is an error (memory: 32 bytes per point).
  int64_t max_points = 100'000'000;
  // More executed blocks (lines, loops and calls unrolled) is an error: a
  // program that loops forever stops here.
  int64_t max_blocks = 200'000'000;
  // Deeper subroutine nesting is an error.
  int max_call_depth = 100;
  // The G28 and G30 positions (machine coordinates, mm) until the program
  // sets them with G28.1/G30.1; unknown when unset (G28/G30 then make the
  // axes they move unknown, like a tool change).
  bool home_known = false;
  double home[3] = {0, 0, 0};
  // Where external subroutine files (o<name> call -> name.ngc) are looked
  // up: the program's directory. Empty: none (calls of undefined
  // subroutines are errors).
  std::string subroutine_dir;
  Dialect dialect = Dialect::kLinuxCnc;
  // The radius (mm) of tool number n, for cutter compensation (G41/G42
  // D n, or the current tool); nullopt or unset: unknown (then G41/G42
  // are errors; G41.1/G42.1 give the diameter themselves).
  std::function<std::optional<double>(int tool)> tool_radius;
  // Where the machine is when the program starts (machine mm), as LinuxCNC
  // starts where the machine stands; unknown when unset (every axis unknown
  // until a word gives it; incremental moves of an unknown axis are
  // errors). Known, the first move starts a run at it.
  bool start_known = false;
  double start[3] = {0, 0, 0};
  // M6 keeps the position (LinuxCNC without a tool-change position). With
  // tool_change_position_known, M6 first rapids there (one straight
  // traverse in machine coordinates, with the old tool). With
  // m6_forgets_position (swarf before issue 27), M6 makes every axis
  // unknown instead.
  bool m6_forgets_position = false;
  bool tool_change_position_known = false;
  double tool_change_position[3] = {0, 0, 0};
};

// The canonical-command sink that makes a Toolpath: straight moves are
// points, arcs chords within the arc tolerance (the last point the arc's
// end, bit for bit). What ParseGcode uses unless given another sink.
class ToolpathBuilder final : public CanonSink {
 public:
  ToolpathBuilder(Toolpath* path, double arc_tolerance, int64_t max_points)
      : path_(path), arc_tolerance_(arc_tolerance), max_points_(max_points) {}
  absl::Status Straight(const CanonStraight& m) override {
    if (path_->point_count() >= max_points_) return TooManyPoints();
    ToolpathPoint p;
    p.position = m.end;
    p.line = m.line;
    p.tool = m.tool;
    p.rapid = m.rapid;
    p.starts_run = m.starts_run;
    path_->Append(p, static_cast<float>(m.feed));
    return absl::OkStatus();
  }
  absl::Status ArcFeed(const CanonArc& a) override;

 private:
  absl::Status TooManyPoints() const;
  Toolpath* path_;
  double arc_tolerance_;
  int64_t max_points_;
};

// An arc given by its centre, as G2/G3 with I/J/K give it: from `start` to
// `end` about the centre (cx, cy) in the plane `plane` (17 XY, 18 XZ, 19
// YZ, as G17/G18/G19: cx, cy are the plane's first and second axes, X/Y,
// Z/X, Y/Z), clockwise (G2) or not, `turns` >= 1 (P). The interpreter's
// checks: a radius under 0.00127 mm is a zero-radius arc, and the radii to
// start and end may differ only as the interpreter accepts (then it is a
// spiral). Errors are InvalidArgument with a plain message that names the
// arc as `name` (the interpreter passes "G2"/"G3"); the caller adds where.
// The one construction of a centre arc: the interpreter's I/J/K arcs and
// the API's arcs (server/session.cc) both use it.
absl::StatusOr<CanonArc> CentreArc(const Vec3& start, const Vec3& end,
                                   double cx, double cy, int plane, bool cw,
                                   int64_t turns, std::string_view name);

// The chords of an arc from `start` exactly as ToolpathBuilder makes them
// (the points after the start, the last the arc's end bit for bit); more
// than max_points is InvalidArgument.
absl::StatusOr<std::vector<Vec3>> ChordArc(const Vec3& start,
                                           const CanonArc& arc,
                                           double arc_tolerance,
                                           int64_t max_points);

// A run of a toolpath's points cut with one tool at one kind of move: what
// `swarf run` streams as the batches of one MoveBatch kind (the CLI, and
// swarfd interpreting a program, split the same way).
struct ToolpathRun {
  int64_t begin = 0, end = 0;  // points [begin, end)
  int32_t tool_id = 0;         // tool_id(the points' tool number)
  // G0, or a feed at F0 (it moves as fast as the machine goes: checked as
  // a rapid).
  bool rapid = false;
  bool reposition = false;  // points[begin] starts a run: no move reaches it
};
// A new run starts where a point starts a run, or its tool's id or its kind
// of move changes.
std::vector<ToolpathRun> SplitRuns(
    const Toolpath& path, const std::function<int32_t(int tool)>& tool_id);

// Parses a G-code program (rules above). Tool numbers: the T of the last
// M6, or, before any M6, the last T word (programs that select tools with T
// alone); 0 when none; T above 65535 is an error. InvalidArgument
// "line N: ..." on any error, or for bad options.
// With a sink, the canonical commands go to it instead: the Toolpath
// returned has the counts, notes and dropped moves but no points.
absl::StatusOr<Toolpath> ParseGcode(std::string_view text,
                                    const GcodeOptions& options = {},
                                    CanonSink* sink = nullptr);

// Parses tool-tip positions in mm, one "x y z" per line, separated by
// commas and/or blanks (spaces, tabs). Blank lines and '#' comments (whole
// or trailing) are skipped; the first non-comment line may be a header
// (when it doesn't start with a number). One run, tool 0, no rapids.
// InvalidArgument "line N: ..." for anything else.
absl::StatusOr<Toolpath> ParseXyz(std::string_view text,
                                  int64_t max_points = 100'000'000);

// Where a toolpath's cut leaves a stock's XY rectangle [x0, x1] x [y0, y1]:
// over the ends of feed moves below `top`, the largest XY distance outside
// the rectangle (mm) and that point's index; {0, -1} when none is outside.
struct Excursion {
  double distance = 0;
  int64_t index = -1;
};
Excursion FarthestOutside(const Toolpath& path, double x0, double y0,
                          double x1, double y1, double top);

enum class ToolpathFormat { kGcode, kXyz };

// By extension, case-insensitive: .nc .ngc .gcode .tap .cnc -> kGcode;
// .csv .xyz .txt -> kXyz. InvalidArgument naming the supported ones else.
absl::StatusOr<ToolpathFormat> ToolpathFormatForPath(std::string_view path);

// By content: the first line that is neither blank nor a comment decides.
// Numbers ("1.5, 2, -0.3"), or a header of letters x, y, z between
// separators, make kXyz; anything else (words such as G0, N10, %, O100,
// #1=2) kGcode. An empty or comment-only text: kGcode.
ToolpathFormat DetectToolpathFormat(std::string_view text);

absl::StatusOr<Toolpath> ParseToolpath(std::string_view text,
                                       ToolpathFormat format,
                                       const GcodeOptions& options = {});

// Reads and parses a file, the format from `format` when given, else from
// its content (DetectToolpathFormat). External subroutines are looked up in
// the file's directory unless options.subroutine_dir is set. Errors are
// prefixed with the path once: "<path>: line N: ...". NotFound when the file
// can't be opened.
// With a sink, G-code's canonical commands go to it (see ParseGcode; an
// XYZ file is parsed as usual).
absl::StatusOr<Toolpath> ReadToolpathFile(
    const std::string& path, const GcodeOptions& options = {},
    std::optional<ToolpathFormat> format = std::nullopt,
    CanonSink* sink = nullptr);

}  // namespace swarf::gcode

#endif  // SWARF_GCODE_TOOLPATH_H_
