// swarf marks: the cutting marks of a paper instance (issue 3).
#include <chrono>
#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "client/cli/args.h"
#include "client/cli/commands.h"
#include "client/outputs/marks_files.h"
#include "core/cutting_marks.h"
#include "core/instances.h"
#include "core/workpiece.h"

namespace swarf::cli {
namespace {

constexpr char kUsage[] =
    "usage: swarf marks --instance five-balls|five-cylinders --mesh N\n"
    "                   [--region x0,y0,x1,y1] [--t2 DEG] [--threshold MM]\n"
    "                   [--scheme taylor|guarded|exact]\n"
    "                   [--json [--vertex-owners]] [--check]\n"
    "Finds the cutting marks (creases) of a paper instance simulated on an\n"
    "N x N mesh (with the paper's taylor scheme unless --scheme says\n"
    "otherwise) and prints a summary: polylines, total length, angle range\n"
    "between the meeting surfaces' normals.\n"
    "  --json           the polylines: {\"polylines\":[{\"closed\":..,\n"
    "                   \"owners\":[a,b],\"vertices\":[[x,y,z],..],\n"
    "                   \"angle_deg\":[..]}]}; owner -1 is the stock top\n"
    "  --vertex-owners  with --json, adds \"vertex_owners\":[[a,b],..]\n"
    "  --check          also the largest distance of a vertex from the exact\n"
    "                   crease of its two surfaces (mm and grid spacings)\n"
    "  --region         only marks inside this rectangle (mm)\n"
    "  --t2             eq. (5): smallest angle between the normals (degrees,\n"
    "                   default 1.65)\n"
    "  --threshold      eq. (3): screening threshold (mm; default t2 h / 4)\n";

absl::StatusOr<double> ParseDouble(const std::string& name,
                                   const std::string& v) {
  double d;
  if (!absl::SimpleAtod(v, &d) || !std::isfinite(d)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "--%s must be a finite number, got \"%s\"", name, v));
  }
  return d;
}

absl::StatusOr<Rect> ParseRegion(const std::string& v) {
  const std::vector<std::string> parts = absl::StrSplit(v, ',');
  double f[4];
  if (parts.size() != 4) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "--region must be x0,y0,x1,y1, got \"%s\"", v));
  }
  for (int k = 0; k < 4; ++k) {
    if (!absl::SimpleAtod(parts[k], &f[k]) || !std::isfinite(f[k])) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "--region must be four finite numbers x0,y0,x1,y1, got \"%s\"", v));
    }
  }
  return Rect{f[0], f[1], f[2], f[3]};
}

}  // namespace

int MarksCommand(const std::vector<std::string>& argv) {
  auto args = Args::Parse(argv,
                          {"instance", "mesh", "region", "t2", "threshold",
                           "scheme"},
                          {"json", "vertex-owners", "check", "help"});
  if (!args.ok()) {
    std::cerr << "swarf marks: " << args.status().message() << "\n" << kUsage;
    return 2;
  }
  if (args->Has("help")) {
    std::cout << kUsage;
    return 0;
  }
  auto fail = [](const absl::Status& st) {
    std::cerr << "swarf marks: " << st.message() << "\n";
    return 2;
  };
  if (!args->positional().empty()) {
    std::cerr << "swarf marks: unexpected argument \"" << args->positional()[0]
              << "\"\n" << kUsage;
    return 2;
  }
  const auto instance = args->Get("instance");
  if (!instance) {
    std::cerr << "swarf marks: --instance is required\n" << kUsage;
    return 2;
  }
  auto mesh = args->GetInt("mesh");
  if (!mesh.ok()) return fail(mesh.status());
  if (!mesh->has_value()) {
    std::cerr << "swarf marks: --mesh is required\n" << kUsage;
    return 2;
  }
  if (args->Has("vertex-owners") && !args->Has("json")) {
    std::cerr << "swarf marks: --vertex-owners needs --json\n";
    return 2;
  }
  MarkOptions options;
  if (auto v = args->Get("region")) {
    auto r = ParseRegion(*v);
    if (!r.ok()) return fail(r.status());
    options.region = *r;
  }
  if (auto v = args->Get("t2")) {
    auto d = ParseDouble("t2", *v);
    if (!d.ok()) return fail(d.status());
    if (!(*d > 0 && *d < 90)) {
      std::cerr << "swarf marks: --t2 must be in (0, 90) degrees, got " << *v
                << "\n";
      return 2;
    }
    options.t2_deg = *d;
  }
  if (auto v = args->Get("threshold")) {
    auto d = ParseDouble("threshold", *v);
    if (!d.ok()) return fail(d.status());
    if (*d < 0) {
      std::cerr << "swarf marks: --threshold must be >= 0, got " << *v << "\n";
      return 2;
    }
    options.screening_threshold = *d;
  }

  auto inst = PaperInstance(*instance, **mesh);
  if (!inst.ok()) {
    // Name the option: the core's message names the instance or mesh value.
    std::cerr << "swarf marks: --"
              << (inst.status().message().find("mesh") == 0 ? "mesh"
                                                             : "instance")
              << ": " << inst.status().message() << "\n";
    return 2;
  }
  SchemeKind scheme = SchemeKind::kTaylor;
  if (auto v = args->Get("scheme")) {
    auto k = ParseScheme(*v);
    if (!k.ok()) {
      return fail(absl::InvalidArgumentError(
          absl::StrCat("--scheme: ", k.status().message())));
    }
    scheme = *k;
  }
  auto wp = Workpiece::Create(inst->stock, scheme);
  if (!wp.ok()) {
    std::cerr << "swarf marks: " << wp.status().message() << "\n";
    return 1;
  }
  if (auto applied = (*wp)->Apply(inst->moves); !applied.ok()) {
    std::cerr << "swarf marks: " << applied.status().message() << "\n";
    return 1;
  }
  const auto t0 = std::chrono::steady_clock::now();
  auto marks = FindCuttingMarks(**wp, options);
  const auto t1 = std::chrono::steady_clock::now();
  if (!marks.ok()) {
    if (marks.status().code() == absl::StatusCode::kInvalidArgument) {
      // The other options are checked above; what is left is the region.
      std::cerr << "swarf marks: --region: " << marks.status().message()
                << "\n";
      return 2;
    }
    std::cerr << "swarf marks: " << marks.status().message() << "\n";
    return 1;
  }
  if (args->Has("json")) {
    std::cout << MarksJson(*marks, args->Has("vertex-owners")) << "\n";
  } else {
    const MarkSummary s = Summarize(*marks);
    std::cout << absl::StrFormat(
        "%s %dx%d: %d polylines (%d closed), %d vertices, total length "
        "%.4f mm, angle %.3f..%.3f deg, %.3f s\n",
        inst->name, **mesh, **mesh, s.polylines, s.closed, s.vertices,
        s.total_length, s.min_angle_deg, s.max_angle_deg,
        std::chrono::duration<double>(t1 - t0).count());
  }
  if (args->Has("check")) {
    const MarkAccuracy acc = MeasureMarkAccuracy(**wp, *marks);
    const double h = std::fmax((*wp)->grid().dx(), (*wp)->grid().dy());
    // On stderr with --json so that stdout stays one JSON document.
    std::ostream& os = args->Has("json") ? std::cerr : std::cout;
    os << absl::StrFormat(
        "check: max vertex distance from the exact crease %.3g mm = %.3g grid "
        "spacings (h = %g mm) at (%.4f, %.4f), over %d vertices\n",
        acc.max_distance, acc.max_distance / h, h, acc.max_x, acc.max_y,
        acc.vertices);
  }
  return 0;
}

}  // namespace swarf::cli
