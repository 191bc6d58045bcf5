// swarf run FILE: simulate a real toolpath (G-code or XYZ) on a server (an
// embedded one unless --server is given) and write pictures and meshes.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "client/cli/args.h"
#include "client/cli/commands.h"
#include "client/cli/connection.h"
#include "client/cli/run_report.h"
#include "client/cli/safety_report.h"
#include "client/cli/server_program.h"
#include "client/cli/tool_table.h"
#include "client/cli/toolpath_flags.h"
#include "client/outputs/json_writer.h"
#include "client/viewer/viewer.h"
#include "core/cutter/sweep.h"
#include "core/move_index.h"
#include "core/thread_pool.h"
#include "gcode/text.h"
#include "gcode/toolpath.h"
#include "server/convert.h"
#include "server/session.h"

namespace swarf::cli {

using gcode::GcodeOptions;
using gcode::ReadToolpathFile;
using gcode::Toolpath;
using gcode::ToolpathPoint;

namespace {

const std::string kUsage =
    "usage: swarf run FILE [options]\n"
    "       swarf run --project JOB.camotics [options]\n"
    "Simulates a toolpath (G-code, RS274/NGC as LinuxCNC runs it, or x,y,z\n"
    "lines; the format by content; positions are the tool tip, mm) and\n"
    "reports the result.\n"
    "options:\n"
    "  --tool SHAPE:KEYS            the cutter (mm; d a diameter, angle the\n"
    "                               INCLUDED angle): ball:d=6, flat:d=6,\n"
    "                               bull:d=6,r=1 (corner radius),\n"
    "                               vbit:d=6,angle=90[,tip=0.2] (tip: flat\n"
    "                               tip diameter), taper:d=6,tip=1,angle=10\n"
    "                               (ball tip diameter, taper angle); one per\n"
    "                               tool number: --tool T2=flat:d=6 (the\n"
    "                               program selects them with T and M6)\n"
    "  --tools FILE                 a tool table: LinuxCNC .tbl (T, D, the\n"
    "                               shape in the comment, else flat) or a\n"
    "                               CAMotics .camotics project's tools\n"
    "  --tools-units mm|inch        units of a .tbl's D (default mm)\n"
    "  --project FILE.camotics      a CAMotics project: its tools, workpiece\n"
    "                               and G-code files (run in order)\n"
    "  --stock x0,y0,x1,y1,top      stock (mm); default: the project's\n"
    "                               workpiece, else the toolpath's XY\n"
    "                               bounds plus the tool radius, top 0\n"
    "  --spacing S | --mesh N       grid spacing (mm), or N elements along "
    "the\n"
    "                               longer side, kept at any size when the\n"
    "                               memory is there; default 0.1 mm (coarser\n"
    "                               if the grid would pass 16M nodes)\n"
    "  --max-memory MB              memory the run may take (MiB; default:\n"
    "                               the machine's available memory); a grid\n"
    "                               that cannot fit is refused at once\n"
    "  --scheme guarded|exact|taylor|zmap\n"
    "                               default guarded (README, \"The model\")\n"
    "  --arc-tolerance T            chord tolerance for arcs, default 0.001\n"
    "  --server HOST:PORT           a running swarfd (default: embedded)\n"
    "  --token T                    its bearer token (or $SWARF_TOKEN)\n"
    "  --tls-ca FILE                use TLS, trusting this PEM CA\n"
    "  --tls-cert FILE --tls-key FILE   a client certificate for TLS\n"
    "  --out DIR                    write relief.png, error.png, marks.png,\n"
    "                               marks.svg, marks.json, surface.stl,\n"
    "                               surface.wrl, stats.json\n"
    "  --subdivide N                STL: split each element N x N using the\n"
    "                               scheme's patches (default 1)\n"
    "  --batch N                    moves per batch sent (default 20000)\n"
    "  --interpret client|server    who interprets the G-code: this client\n"
    "                               sends the moves (default), or the server\n"
    "                               is sent the program (the same result)\n"
    "  --mesh-tolerance T           STL/VRML: largest vertical distance to\n"
    "                               the full-resolution surface (mm,\n"
    "                               default 0.005; 0: every element)\n"
    "  --marks-min-angle A          marks files: drop vertices where the\n"
    "                               surfaces meet under A degrees (default\n"
    "                               1; rims on the stock top always stay)\n"
    "  --marks-min-length L         ...and pieces shorter than L mm\n"
    "                               (default 0.2)\n"
    "  --picture-size N             pictures: at most N pixels along the\n"
    "                               longer side (default 4096), sampled\n"
    "                               from the surface at that size\n"
    "  --design FILE                the part as designed (STL or STEP, in\n"
    "                               the stock's coordinates): stats.json\n"
    "                               gets a deviation (gouge and excess by\n"
    "                               program line), --out a deviation.png\n"
    "  --design-units mm|inch       the design file's units (default mm)\n"
    "  --design-offset x,y,z        moves the design (mm)\n"
    "  --allowance A                stock to leave (mm, default 0)\n"
    "  --tolerance T                out of tolerance: gouge > T or excess >\n"
    "                               A + T (mm, default 0.01); given, an\n"
    "                               out-of-tolerance part exits with 3\n"
    "  --deviation-samples N        per element edge, as the valuation\n"
    "                               (default 5; 0: nodes only)\n"
    "  --floor Z                    report moves whose tip goes below Z (a\n"
    "                               fixture, the table)\n"
    "  --limits x0,y0,z0,x1,y1,z1   report moves ending outside the\n"
    "                               machine's travel\n"
    "  --rapid-rate R               G0 speed for the rapid time (mm/min,\n"
    "                               default 5000)\n"
    "  --check                      exit with 3 when a rapid cuts, the\n"
    "                               shank or holder meets material, a tool\n"
    "                               not cutting at its centre plunges, or a\n"
    "                               move passes --floor or --limits (the\n"
    "                               tool keys flute=, holder=, stickout=,\n"
    "                               shank=, center=0 give the assembly)\n"
    "  --json                       print the stats document instead\n"
    "  --view                       show the part live in a browser (a page\n"
    "                               on 127.0.0.1, kept up until Ctrl-C)\n"
    "  --view-port N                the page's port (default: a free one)\n"
    "  --view-wait                  start cutting once a page is open\n"
    "G-code:\n" +
    std::string(kToolpathUsage);

// The tool numbers a program uses, each with where it is first selected
// (its T word or M6; with no T word, the first move): "FILE line N".
void AddToolUses(const Toolpath& path, const std::string& file,
                 std::vector<ToolUse>* uses) {
  int last = -1;
  for (const ToolpathPoint& p : path.points()) {
    if (p.tool == last) continue;
    last = p.tool;
    const bool seen =
        std::any_of(uses->begin(), uses->end(),
                    [&](const ToolUse& u) { return u.number == p.tool; });
    if (seen) continue;
    const int32_t line = path.ToolSelectedAt(p.tool).value_or(p.line);
    uses->push_back({p.tool, absl::StrCat(file, " line ", line)});
  }
}

absl::StatusOr<StockSpec> ChooseStock(const Args& args, const Toolpath& path,
                                      double max_radius,
                                      const CamoticsProject* project) {
  StockSpec s;
  if (auto v = args.Get("stock")) {
    std::vector<std::string> f = absl::StrSplit(*v, ',');
    double d[5];
    if (f.size() != 5 || !absl::SimpleAtod(f[0], &d[0]) ||
        !absl::SimpleAtod(f[1], &d[1]) || !absl::SimpleAtod(f[2], &d[2]) ||
        !absl::SimpleAtod(f[3], &d[3]) || !absl::SimpleAtod(f[4], &d[4])) {
      return absl::InvalidArgumentError(
          "--stock must be x0,y0,x1,y1,top (five numbers, mm)");
    }
    s = {d[0], d[1], d[2], d[3], d[4], 0, 0};
  } else if (project != nullptr && !project->automatic) {
    // The project's workpiece as given (CAMotics ignores the margin then).
    s = {project->min[0],
         project->min[1],
         project->max[0],
         project->max[1],
         project->max[2],
         0,
         0};
  } else {
    // As CAMotics' automatic workpiece: the path's XY bounds, top at 0,
    // grown by a project's margin (percent of the size) on every side.
    const double m = max_radius;
    s = {path.x_bounds().lo - m,
         path.y_bounds().lo - m,
         path.x_bounds().hi + m,
         path.y_bounds().hi + m,
         0,
         0,
         0};
    if (project != nullptr) {
      const double mx = (s.x1 - s.x0) * project->margin_percent / 100;
      const double my = (s.y1 - s.y0) * project->margin_percent / 100;
      s.x0 -= mx;
      s.x1 += mx;
      s.y0 -= my;
      s.y1 += my;
    }
  }
  const double w = s.x1 - s.x0, h = s.y1 - s.y0;
  if (!(w > 0) || !(h > 0)) {
    return absl::InvalidArgumentError(
        "the stock is empty (x1 <= x0 or y1 <= y0)");
  }
  double spacing = 0;
  auto mesh = args.GetInt("mesh");
  if (!mesh.ok()) return mesh.status();
  if (auto sp = args.Get("spacing")) {
    if (!absl::SimpleAtod(*sp, &spacing) || !(spacing > 0)) {
      return absl::InvalidArgumentError("--spacing must be a number > 0 (mm)");
    }
  } else if (mesh->has_value()) {
    if (**mesh < 1) return absl::InvalidArgumentError("--mesh must be >= 1");
    spacing = std::max(w, h) / **mesh;
  } else {
    constexpr double kMaxNodes = 16e6;
    spacing = std::max(0.1, std::sqrt(w * h / kMaxNodes));
  }
  const double nx = std::ceil(w / spacing - 1e-9),
               ny = std::ceil(h / spacing - 1e-9);
  if (nx > kMaxElementsPerAxis || ny > kMaxElementsPerAxis) {
    return absl::InvalidArgumentError(
        absl::StrCat("spacing ", spacing, " mm makes a grid of ", nx, " x ", ny,
                     " elements: too many"));
  }
  s.nx = static_cast<int32_t>(std::max(1.0, nx));
  s.ny = static_cast<int32_t>(std::max(1.0, ny));
  return s;
}

// Memory this machine can give a run (bytes): /proc/meminfo's MemAvailable
// (free memory plus what the kernel can reclaim), else the free pages.
int64_t AvailableMemoryBytes() {
  std::ifstream in("/proc/meminfo");
  std::string line;
  while (std::getline(in, line)) {
    long long kb = 0;
    if (std::sscanf(line.c_str(), "MemAvailable: %lld kB", &kb) == 1) {
      return int64_t{kb} * 1024;
    }
  }
  return static_cast<int64_t>(sysconf(_SC_AVPHYS_PAGES)) *
         sysconf(_SC_PAGESIZE);
}

// What the moves of a run take at least (bytes): the server keeps each in
// its MoveList and lists it in the bins of its move index that the move's
// footprint below the top reaches (its bytes tallied here as the server's
// index grows, without holding the ids: MoveIndexTally); the client keeps
// the parsed point and its feed until the last batch is acknowledged, and
// its outputs read the embedded session's index (pinned), not one of their
// own. Sets *index_bytes to the index's part.
int64_t MovesMemoryBytes(const Toolpath& path,
                         const std::map<int, Cutter>& tools,
                         const StockSpec& stock, int64_t* index_bytes) {
  const GridGeometry grid(stock);
  MoveIndexTally index(grid);
  const auto& points = path.points();
  // A chunk of moves at a time, their bins found on every thread and added
  // as the server adds a batch (AddAll): on one thread this was a serial
  // step of seconds before a 20 M-move job started.
  constexpr size_t kChunk = size_t{1} << 20;
  ThreadPool& pool = ThreadPool::Default();
  std::vector<uint32_t> at;  // the chunk's moves' points
  std::vector<MoveIndex::BinRect> bins;
  uint32_t first_id = 0;
  for (size_t k0 = 1; k0 < points.size();) {
    at.clear();
    for (; k0 < points.size() && at.size() < kChunk; ++k0) {
      if (!points[k0].starts_run) at.push_back(static_cast<uint32_t>(k0));
    }
    bins.resize(at.size());
    constexpr int64_t kPiece = 1024;
    const int64_t n = static_cast<int64_t>(at.size());
    pool.ParallelFor((n + kPiece - 1) / kPiece, [&](int64_t p) {
      for (int64_t m = p * kPiece; m < std::min(n, (p + 1) * kPiece); ++m) {
        const size_t k = at[m];
        bins[m] = IndexedBins(Move(points[k - 1].position, points[k].position,
                                   tools.at(points[k].tool)),
                              stock.z_top, grid);
      }
    });
    index.AddAll(first_id, bins, pool);
    first_id += static_cast<uint32_t>(at.size());
  }
  *index_bytes = index.MemoryBytes();
  constexpr int64_t kPerMove =
      MoveList::kBytesPerMove + sizeof(ToolpathPoint) + sizeof(float);
  return path.move_count() * kPerMove + *index_bytes;
}

// The memory a run may take (--max-memory MiB, else what is available);
// ResourceExhausted naming both when the session's grid (every tile cut,
// as swarfd admits it) and the moves cannot fit, so that a job too large
// is refused before anything runs.
absl::StatusOr<int64_t> CheckRunMemory(const Args& args, const StockSpec& stock,
                                       SchemeKind scheme, const Toolpath& path,
                                       const std::map<int, Cutter>& tools) {
  int64_t allowed = 0;
  std::string source;
  if (args.Has("max-memory")) {
    auto mb = args.GetInt("max-memory");
    if (!mb.ok()) return mb.status();
    if (**mb < 1) {
      return absl::InvalidArgumentError("--max-memory must be >= 1 (MiB)");
    }
    allowed = int64_t{**mb} << 20;
    source = absl::StrCat("--max-memory allows ", allowed >> 20, " MiB");
  } else {
    allowed = AvailableMemoryBytes();
    source = absl::StrCat("this machine has ", allowed >> 20, " MiB available");
  }
  const int64_t grid = server::Session::EstimateMemoryBytes(stock, scheme);
  int64_t index = 0;
  const int64_t moves = MovesMemoryBytes(path, tools, stock, &index);
  const int64_t needed = grid + moves;
  if (needed > allowed) {
    const int64_t nodes = (int64_t{stock.nx} + 1) * (stock.ny + 1);
    return absl::ResourceExhaustedError(absl::StrFormat(
        "the grid of %d x %d elements (%d nodes, %.4g mm) and %d moves need "
        "at least %d MiB (%d bytes: %d for the grid, every tile at %d bytes "
        "a node, and %d for the moves, of which %d their index); %s; give a "
        "coarser --spacing or --mesh",
        stock.nx, stock.ny, nodes, (stock.x1 - stock.x0) / stock.nx,
        path.move_count(), (needed + (1 << 20) - 1) >> 20, needed, grid,
        GetScheme(scheme).bytes_per_node(), moves, index, source));
  }
  return allowed;
}

// Runs of points with one tool and one kind of feed (the protocol's batches
// carry one of each); a tool change starts a repositioning run. Split by
// gcode::SplitRuns, as swarfd splits a program it interprets.
std::vector<PathRun> Runs(const Toolpath& path,
                          const std::map<int, int32_t>& tool_ids) {
  std::vector<PathRun> runs;
  for (const gcode::ToolpathRun& r :
       gcode::SplitRuns(path, [&](int t) { return tool_ids.at(t); })) {
    PathRun run;
    run.tool_id = r.tool_id;
    run.rapid = r.rapid;
    run.reposition = r.reposition;
    run.path = path.points().data();
    run.begin = r.begin;
    run.end = r.end;
    runs.push_back(std::move(run));
  }
  return runs;
}

// Progress on a terminal: one line redrawn at most 10 times a second. Not on
// a terminal: a line at every quarter.
class ProgressBar {
 public:
  explicit ProgressBar(bool quiet)
      : tty_(!quiet && isatty(STDERR_FILENO)),
        quiet_(quiet),
        start_(std::chrono::steady_clock::now()) {}

  void Update(const StreamProgress& p) {
    const auto now = std::chrono::steady_clock::now();
    const double t = std::chrono::duration<double>(now - start_).count();
    const double frac = p.moves_total > 0
                            ? static_cast<double>(p.moves_done) / p.moves_total
                            : 1;
    const double rate = t > 0 ? p.moves_done / t : 0;
    const double eta = rate > 0 ? (p.moves_total - p.moves_done) / rate : 0;
    if (tty_) {
      if (p.moves_done < p.moves_total &&
          std::chrono::duration<double>(now - last_).count() < 0.1) {
        return;
      }
      last_ = now;
      constexpr int kWidth = 30;
      const int filled = static_cast<int>(frac * kWidth);
      std::string bar(filled, '=');
      if (filled < kWidth) bar += '>' + std::string(kWidth - filled - 1, ' ');
      std::fprintf(
          stderr, "\r%3.0f%% [%s] %lld/%lld moves  %.2fM moves/s  ETA %.0fs ",
          100 * frac, bar.c_str(), static_cast<long long>(p.moves_done),
          static_cast<long long>(p.moves_total), rate / 1e6, eta);
      if (p.moves_done >= p.moves_total) std::fprintf(stderr, "\n");
    } else if (!quiet_) {
      const int quarter = static_cast<int>(frac * 4);
      if (quarter > last_quarter_) {
        last_quarter_ = quarter;
        std::fprintf(stderr,
                     "swarf: %d%% (%lld of %lld moves, %.2fM moves/s)\n",
                     quarter * 25, static_cast<long long>(p.moves_done),
                     static_cast<long long>(p.moves_total), rate / 1e6);
      }
    }
  }

 private:
  const bool tty_, quiet_;
  const std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_;
  int last_quarter_ = 0;
};

// --interpret client|server: whether the server is sent the program.
absl::StatusOr<bool> InterpretOnServer(const Args& args) {
  const std::string v = args.Get("interpret").value_or("client");
  if (v != "client" && v != "server") {
    return absl::InvalidArgumentError("--interpret must be client or server");
  }
  return v == "server";
}

// --interpret server: each program file sent to the session's server, which
// interprets it with the same options and applies the batches StreamPath
// would have sent (each file starting from an unknown position, as
// Toolpath::AppendProgram joins them).
absl::Status StreamPrograms(
    Connection& conn, const std::string& session_id,
    const std::vector<std::string>& files, const GcodeOptions& options,
    bool strict, int64_t batch_points, int64_t moves_total,
    const std::function<void(const StreamProgress&)>& progress,
    const std::function<void(const pb::Ack&, int64_t)>& on_ack) {
  StreamProgress p;
  p.moves_total = moves_total;
  uint64_t first_seq = 1;
  for (const std::string& f : files) {
    auto text = gcode::ReadWholeFile(f);
    if (!text.ok()) {
      return absl::Status(text.status().code(),
                          absl::StrCat(f, ": ", text.status().message()));
    }
    if (gcode::DetectToolpathFormat(*text) != gcode::ToolpathFormat::kGcode) {
      return absl::InvalidArgumentError(absl::StrCat(
          f, ": --interpret server needs G-code (this is x,y,z points)"));
    }
    pb::ProgramOptions o = ProgramOptionsFor(options, strict, batch_points, f);
    o.set_first_seq(first_seq);
    pb::ProgramDone done;
    if (absl::Status s = StreamProgram(conn, session_id, *text, o, &p, progress,
                                       on_ack, &done);
        !s.ok()) {
      return s;
    }
    first_seq = done.last_seq() + 1;
  }
  return absl::OkStatus();
}

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0)
      .count();
}

std::string NewSessionId() {
  std::mt19937_64 rng(std::random_device{}());
  return absl::StrFormat("run-%016x", rng());
}

}  // namespace

int RunCommand(const std::vector<std::string>& argv) {
  std::set<std::string> valued = {
      "tool",    "tools",     "tools-units", "project",       "stock",
      "spacing", "mesh",      "scheme",      "arc-tolerance", "server",
      "out",     "subdivide", "batch",       "max-memory"};
  valued.insert("interpret");
  valued.insert(std::begin(kConnectionFlags), std::end(kConnectionFlags));
  valued.insert(std::begin(kToolpathFlags), std::end(kToolpathFlags));
  valued.insert(std::begin(kOutputFlags), std::end(kOutputFlags));
  valued.insert(std::begin(kViewerFlags), std::end(kViewerFlags));
  valued.insert(std::begin(kDesignFlags), std::end(kDesignFlags));
  valued.insert(std::begin(kSafetyFlags), std::end(kSafetyFlags));
  auto args = Args::Parse(argv, valued,
                          {"json", "help", "quiet", kStrictFlag, kM6ForgetsFlag,
                           "view", "view-wait", kCheckFlag});
  auto fail = [](const absl::Status& s, int code) {
    std::cerr << "swarf run: " << s.message() << "\n";
    return code;
  };
  if (!args.ok()) {
    std::cerr << "swarf run: " << args.status().message() << "\n" << kUsage;
    return 2;
  }
  if (args->Has("help")) {
    std::cout << kUsage;
    return 0;
  }
  // The program(s) and the tools: a FILE, or a CAMotics project's files.
  std::optional<CamoticsProject> project;
  std::vector<std::string> files = args->positional();
  if (auto p = args->Get("project")) {
    if (!files.empty()) {
      std::cerr << "swarf run: give a toolpath FILE or --project, not both\n";
      return 2;
    }
    auto read = ReadCamoticsProject(*p);
    if (!read.ok()) return fail(read.status(), 2);
    project = *std::move(read);
    files = project->files;
    if (files.empty()) {
      return fail(absl::InvalidArgumentError(
                      absl::StrCat(*p, ": the project lists no files")),
                  2);
    }
  } else if (files.size() != 1) {
    std::cerr << "swarf run: give one toolpath FILE\n" << kUsage;
    return 2;
  }
  const std::string file =
      project.has_value() ? *args->Get("project") : files[0];
  const bool json = args->Has("json");
  std::optional<ToolTable> table;
  if (project.has_value()) table = project->tools;
  auto tools_flag = ReadToolsFlags(*args);
  if (!tools_flag.ok()) return fail(tools_flag.status(), 2);
  if (tools_flag->has_value()) table = **std::move(tools_flag);
  if (!table.has_value() && !args->Has("tool")) {
    return fail(absl::InvalidArgumentError(
                    "--tool (or --tools FILE) is required, e.g. --tool "
                    "ball:d=3.175"),
                2);
  }
  auto choices = ParseToolChoices(args->All("tool"), std::move(table));
  if (!choices.ok()) return fail(choices.status(), 2);

  // Parse.
  ToolpathFlags tflags;
  if (absl::Status st = ReadToolpathFlags(*args, &tflags); !st.ok()) {
    return fail(st, 2);
  }
  GcodeOptions& gopt = tflags.options;
  // Cutter compensation (G41/G42) needs the radius of the tool it names.
  gopt.tool_radius = [&c = *choices](int t) -> std::optional<double> {
    const std::optional<Cutter> cutter = KnownTool(c, t);
    if (!cutter.has_value()) return std::nullopt;
    return cutter->radius;
  };
  if (auto t = args->Get("arc-tolerance")) {
    if (!absl::SimpleAtod(*t, &gopt.arc_tolerance) ||
        !(gopt.arc_tolerance > 0)) {
      return fail(absl::InvalidArgumentError(
                      "--arc-tolerance must be a number > 0 (mm)"),
                  2);
    }
  }
  SchemeKind scheme = SchemeKind::kGuarded;
  if (auto s = args->Get("scheme")) {
    auto k = ParseScheme(*s);
    if (!k.ok()) return fail(k.status(), 2);
    scheme = *k;
  }
  const absl::StatusOr<bool> interpret_server = InterpretOnServer(*args);
  if (!interpret_server.ok()) return fail(interpret_server.status(), 2);
  auto batch = args->GetInt("batch");
  auto subdivide = args->GetInt("subdivide");
  if (!batch.ok()) return fail(batch.status(), 2);
  if (!subdivide.ok()) return fail(subdivide.status(), 2);
  const int64_t batch_points = batch->value_or(20000);
  if (batch_points < 2)
    return fail(absl::InvalidArgumentError("--batch must be >= 2"), 2);
  OutputOptions output_flags;
  if (absl::Status s = ParseOutputFlags(*args, &output_flags); !s.ok()) {
    return fail(s, 2);
  }
  auto design = ParseDesignFlags(*args);
  if (!design.ok()) return fail(design.status(), 2);

  const auto t_parse = std::chrono::steady_clock::now();
  absl::StatusOr<Toolpath> path;
  std::vector<ToolUse> uses;
  // Where each program's points start (the moves' source files).
  std::vector<int64_t> file_starts;
  for (const std::string& f : files) {
    auto one = ReadToolpathFile(f, gopt, tflags.format);
    if (!one.ok()) return fail(one.status(), 1);  // names the file
    AddToolUses(*one, f, &uses);
    file_starts.push_back(path.ok() ? path->point_count() : 0);
    if (path.ok()) {
      path->AppendProgram(*one);
    } else {
      path = *std::move(one);
    }
  }
  const double parse_s = Since(t_parse);
  if (path->move_count() < 1) {
    std::cerr << "swarf run: " << file << ": no moves";
    if (path->dropped_moves() > 0) std::cerr << "; " << path->DroppedSummary();
    std::cerr << "\n";
    return 1;
  }
  if (!json) {
    for (const std::string& note : path->notes()) {
      std::cerr << "swarf run: note: " << note << "\n";
    }
    if (!path->IgnoredSummary().empty()) {
      std::cerr << "swarf run: " << path->IgnoredSummary() << "\n";
    }
  }
  auto tools = ChooseTools(*choices, uses);
  if (!tools.ok()) return fail(tools.status(), 2);
  auto safety_options = ParseSafetyFlags(*args);
  if (!safety_options.ok()) return fail(safety_options.status(), 2);
  std::map<int, ToolAssembly> assemblies;
  for (const auto& [t, c] : *tools) assemblies[t] = KnownAssembly(*choices, t);
  double max_radius = 0;
  for (const auto& [t, c] : *tools) max_radius = std::max(max_radius, c.radius);
  auto stock = ChooseStock(*args, *path, max_radius,
                           project.has_value() ? &*project : nullptr);
  if (!stock.ok()) return fail(stock.status(), 2);
  if (design->has_value()) {
    DesignInput& d = **design;
    if (absl::Status s = LoadDesign(*stock, &d); !s.ok()) return fail(s, 2);
    d.sources = files;
    // Move ids as RunMoveSource numbers them: every point but a run's first.
    const auto& points = path->points();
    d.move_lines.reserve(path->move_count());
    int32_t f = 0;
    for (size_t k = 0; k < points.size(); ++k) {
      while (f + 1 < static_cast<int32_t>(file_starts.size()) &&
             static_cast<int64_t>(k) >= file_starts[f + 1]) {
        ++f;
      }
      if (k > 0 && !points[k].starts_run) {
        d.move_lines.push_back({f, points[k].line});
      }
    }
    if (!json) {
      std::cerr << absl::StrFormat(
          "swarf run: design %s: %d triangles, over %d nodes of the grid "
          "(%.2f s)\n",
          d.path, d.placed->mesh().triangles.size(),
          d.placed->envelope().covered_nodes(), d.seconds);
    }
  }
  RunReport report;
  {
    std::vector<std::string> warnings;
    absl::Status checked = CheckToolpath(*path, tflags.strict,
                                         args->Has("stock") ? &*stock : nullptr,
                                         &report, &warnings);
    if (!checked.ok()) {
      return fail(
          absl::InvalidArgumentError(absl::StrCat(
              files.size() == 1 ? files[0] : file, ": ", checked.message())),
          1);
    }
    if (!json) {
      for (const std::string& w : warnings)
        std::cerr << "swarf run: " << w << "\n";
    }
  }

  // Session.
  auto copt = ConnectionOptionsFrom(*args);
  if (!copt.ok()) return fail(copt.status(), 2);
  if (!args->Has("server")) {
    // The embedded server holds this session only: no node cap, its memory
    // what the machine (or --max-memory) gives.
    auto allowed = CheckRunMemory(*args, *stock, scheme, *path, *tools);
    if (!allowed.ok()) return fail(allowed.status(), 2);
    server::Limits limits;
    limits.max_total_memory_bytes = *allowed;
    copt->embedded_limits = limits;
  }
  auto conn = Connection::Open(args->Get("server").value_or(""), *copt);
  if (!conn.ok()) return fail(conn.status(), 1);
  const std::string id = NewSessionId();
  pb::CreateSessionRequest create;
  create.set_session_id(id);
  create.mutable_stock()->set_x0(stock->x0);
  create.mutable_stock()->set_y0(stock->y0);
  create.mutable_stock()->set_x1(stock->x1);
  create.mutable_stock()->set_y1(stock->y1);
  create.mutable_stock()->set_z_top(stock->z_top);
  create.set_nx(stock->nx);
  create.set_ny(stock->ny);
  create.set_scheme(server::SchemeToProto(scheme));
  std::map<int, int32_t> tool_ids;
  for (const auto& [t, c] : *tools) {
    server::ToolToProto({t, c, assemblies[t]}, create.add_tools());
    tool_ids[t] = t;
  }
  pb::Session session;
  {
    auto ctx = (*conn)->Context(id, 60);
    grpc::Status st =
        (*conn)->stub().CreateSession(ctx.get(), create, &session);
    if (!st.ok()) return fail(FromGrpc(st), 1);
  }
  if (!json) {
    std::cerr << absl::StrFormat(
        "swarf run: %s: %d moves, stock [%.3f, %.3f] x [%.3f, %.3f] top %.3f, "
        "%d x %d elements (%.4g mm), %s, on the %s\n",
        file, path->move_count(), stock->x0, stock->x1, stock->y0, stock->y1,
        stock->z_top, stock->nx, stock->ny, (stock->x1 - stock->x0) / stock->nx,
        GetScheme(scheme).name(), (*conn)->target());
    for (const auto& [t, c] : *tools) {
      std::cerr << "swarf run: tool " << t << (t == 0 ? " (no T word)" : "")
                << ": " << CutterSummary(c) << "\n";
    }
  }

  std::vector<PathRun> runs = Runs(*path, tool_ids);
  std::unique_ptr<Viewer> viewer;
  if (args->Has("view") || args->Has("view-port") || args->Has("view-wait")) {
    auto vopt = ViewerOptionsFrom(*args);
    if (!vopt.ok()) return fail(vopt.status(), 2);
    ViewerPath vpath = ViewerPathOf(runs);
    if (design->has_value()) {
      // The page colours by the deviation the session computes, names the
      // line under the pointer and overlays the design.
      const DesignInput& d = **design;
      if (absl::Status s = UploadDesign(**conn, id, d); !s.ok()) {
        return fail(s, 1);
      }
      vpath.move_lines = d.move_lines;
      vpath.sources = d.sources;
      vpath.design = &d.placed->mesh();
      vpath.allowance = d.deviation.allowance;
      vpath.tolerance = d.deviation.tolerance;
    }
    auto v = Viewer::Start(conn->get(), id, *vopt, std::move(vpath));
    if (!v.ok()) return fail(v.status(), 1);
    viewer = *std::move(v);
    std::cerr << "swarf run: viewer at " << viewer->url() << std::endl;
    if (args->Has("view-wait")) {
      std::cerr << "swarf run: waiting for the page to open" << std::endl;
      viewer->WaitForPage();
    }
  }

  // Simulate.
  const auto t_sim = std::chrono::steady_clock::now();
  ProgressBar bar(json || args->Has("quiet"));
  StreamProgress last;
  SafetyCollector safety(*path, file_starts, files, assemblies,
                         *safety_options);
  safety.Follow(viewer != nullptr);
  const auto on_progress = [&](const StreamProgress& p) {
    last = p;
    bar.Update(p);
  };
  const auto on_ack = [&](const pb::Ack& a, int64_t first) {
    safety.OnAck(a, first);
    if (viewer) {
      // The page marks the findings and dashes the air moves as the
      // batches are acknowledged.
      SafetyCollector::NewFindings found = safety.TakeNew();
      std::vector<ViewerMarker> markers;
      for (const auto& [kind, it] : found.items) {
        const auto& files = safety.files();
        markers.push_back(
            {{it.x, it.y, it.z},
             SafetyCollector::kKindNames[kind],
             it.file >= 0 && it.file < static_cast<int32_t>(files.size())
                 ? files[it.file]
                 : std::string(),
             it.line,
             it.depth,
             it.volume_mm3});
      }
      viewer->AddSafety(std::move(markers), std::move(found.air));
    }
  };
  absl::Status streamed =
      *interpret_server
          ? StreamPrograms(**conn, id, files, gopt, tflags.strict, batch_points,
                           path->move_count(), on_progress, on_ack)
          : StreamPath(**conn, id, runs, batch_points, on_progress, on_ack);
  const double sim_s = Since(t_sim);
  if (viewer) viewer->MarkFinished();
  if (!streamed.ok()) return fail(streamed, 1);
  if (!json) {
    for (const std::string& w : safety.Warnings()) {
      std::cerr << "swarf run: " << w << "\n";
    }
  }
  report.json_sections.emplace_back("safety", safety.SafetyJson());
  report.json_sections.emplace_back("process", safety.ProcessJson());

  // Outputs.
  report.file = file;
  report.moves = path->move_count();
  report.lines = path->source_lines();
  report.parse_seconds = parse_s;
  report.simulate_seconds = sim_s;
  report.node_lowerings = last.node_lowerings;
  report.stock = *stock;
  report.scheme = scheme;
  report.server = (*conn)->target();
  report.ignored = path->IgnoredSummary();
  const auto t_out = std::chrono::steady_clock::now();
  OutputOptions oopt = output_flags;
  if (auto out = args->Get("out")) oopt.dir = *out;
  oopt.subdivide = subdivide->value_or(1);
  std::map<int32_t, Cutter> cutter_by_tool;
  for (const auto& [t, c] : *tools) {
    cutter_by_tool[tool_ids.at(t)] = c;
    report.tools.emplace_back(t, CutterSummary(c));
  }
  if ((*conn)->embedded()) {
    // The outputs read the session's own moves and their index (pinned: no
    // batch can come meanwhile), so the program's points are not needed
    // any more: on the 1000 mm plate, 640 MB of points and a 237 MB index
    // that the outputs would have built again.
    auto pinned = (*conn)->PinEmbeddedSession(id);
    if (!pinned.ok()) return fail(pinned.status(), 1);
    oopt.moves =
        std::shared_ptr<const MoveSource>(*pinned, &(*pinned)->moves());
    oopt.sweeps =
        std::shared_ptr<const MoveSweeps>(*pinned, &(*pinned)->sweeps());
    oopt.workpiece = *pinned;
    runs.clear();
    runs.shrink_to_fit();
    *path = gcode::Toolpath();
  } else {
    oopt.moves = std::make_shared<const RunMoveSource>(runs, cutter_by_tool);
  }
  if (design->has_value()) oopt.design = &**design;
  absl::Status written = CollectAndWrite(**conn, id, oopt, &report);
  // The pin goes before the session does.
  oopt.moves.reset();
  oopt.sweeps.reset();
  oopt.workpiece.reset();
  report.output_seconds = Since(t_out);
  if (!written.ok()) return fail(written, 1);
  if (!oopt.dir.empty()) {
    if (safety.WriteLoadPng(oopt.dir + "/load.png").ok()) {
      report.files.push_back(oopt.dir + "/load.png");
    }
    absl::Status s = WriteStatsJson(report, oopt.dir + "/stats.json");
    if (!s.ok()) return fail(s, 1);
  }
  if (json) {
    std::cout << StatsJson(report) << "\n";
  } else {
    std::cout << Summary(report);
  }
  if (viewer) {
    std::cerr << "swarf run: the viewer stays at " << viewer->url()
              << " (Ctrl-C to stop)" << std::endl;
    viewer->ServeUntilInterrupted();
    viewer.reset();
  }
  if (!(*conn)->embedded()) {
    // A remote session served this run only.
    auto ctx = (*conn)->Context(id, 30);
    pb::DeleteSessionRequest del;
    del.set_session_id(id);
    pb::DeleteSessionResponse resp;
    (*conn)->stub().DeleteSession(ctx.get(), del, &resp);
  }
  // A shop's CI gates programs on this: 3 = out of tolerance (1 = error).
  if (report.deviation && report.tolerance_gate && !report.deviation->ok) {
    return 3;
  }
  if (args->Has(kCheckFlag) &&
      (safety.total() > 0 || (report.deviation && !report.deviation->ok))) {
    return 3;
  }
  return 0;
}

}  // namespace swarf::cli
