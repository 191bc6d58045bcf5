// swarf table: the paper's Tables 1 and 2 (both instances, every scheme),
// and the same table for the cutter-shape instances (issue 16).
#include <algorithm>
#include <bit>
#include <chrono>
#include <fstream>
#include <optional>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/args.h"
#include "client/cli/commands.h"
#include "client/outputs/json_writer.h"
#include "core/instances.h"
#include "core/valuation.h"
#include "core/workpiece.h"

namespace swarf::cli {
namespace {

constexpr char kUsage[] =
    "usage: swarf table [--instance NAME|paper|shapes|all] [--mesh N]\n"
    "                   [--runs N] [--json] [--heights DIR]\n"
    "Prints the paper's Tables 1 and 2 (--instance paper, the default:\n"
    "five-balls and five-cylinders) or the same rows for the cutter-shape\n"
    "jobs (--instance shapes: flat-ramps, bull-ramps, cone-ramps,\n"
    "taper-ramps; see the README): for each instance, mesh (default 100\n"
    "and 1000) and scheme, the nodes, parameters, error against the exact\n"
    "surface (21 samples per element) and the time to apply the moves\n"
    "(median of --runs runs; default 11 for meshes up to 200, else 5).\n"
    "--heights DIR also writes each grid's node heights, exactly as\n"
    "simulated, to DIR/<instance>-<mesh>-<scheme>.npy (float64, shape\n"
    "(mesh + 1, mesh + 1), indexed [j, i]): a reference for clients.\n";

struct Row {
  std::string instance;
  std::string cutter;  // CutterToString of the instance's tool
  int mesh;
  SchemeKind scheme;
  int64_t nodes, parameters;
  ErrorStats err;
  double seconds;
};

// Writes the node heights w[j][i] as a NumPy .npy file (format 1.0,
// little-endian float64, C order).
absl::Status WriteHeightsNpy(const Workpiece& wp, const std::string& path) {
  const int32_t rows = wp.grid().ny() + 1, cols = wp.grid().nx() + 1;
  std::string header = absl::StrCat(
      "{'descr': '<f8', 'fortran_order': False, 'shape': (", rows, ", ", cols,
      "), }");
  // Magic (6) + version (2) + length (2) + header + '\n', a multiple of 64.
  header.append(63 - (10 + header.size()) % 64, ' ');
  header.push_back('\n');
  std::ofstream out(path, std::ios::binary);
  const uint16_t len = static_cast<uint16_t>(header.size());
  out.write("\x93NUMPY\x01\x00", 8);
  const char len_le[2] = {static_cast<char>(len & 0xff),
                          static_cast<char>(len >> 8)};
  out.write(len_le, 2);
  out << header;
  static_assert(std::endian::native == std::endian::little);
  for (int32_t j = 0; j < rows; ++j) {
    for (int32_t i = 0; i < cols; ++i) {
      const double w = wp.Node(i, j).jet.w;
      out.write(reinterpret_cast<const char*>(&w), sizeof w);
    }
  }
  out.close();
  if (!out) return absl::UnavailableError(absl::StrCat("cannot write ", path));
  return absl::OkStatus();
}

absl::StatusOr<Row> MeasureRow(const Instance& inst, int mesh,
                               SchemeKind scheme, int runs,
                               const std::optional<std::string>& heights_dir) {
  std::vector<double> times;
  std::unique_ptr<Workpiece> wp;
  for (int k = 0; k < runs; ++k) {
    auto created = Workpiece::Create(inst.stock, scheme);
    if (!created.ok()) return created.status();
    wp = *std::move(created);
    const auto t0 = std::chrono::steady_clock::now();
    auto applied = wp->Apply(inst.moves);
    const auto t1 = std::chrono::steady_clock::now();
    if (!applied.ok()) return applied.status();
    times.push_back(std::chrono::duration<double>(t1 - t0).count());
  }
  std::sort(times.begin(), times.end());
  if (heights_dir.has_value()) {
    const std::string path =
        absl::StrCat(*heights_dir, "/", inst.name, "-", mesh, "-",
                     std::string(GetScheme(scheme).name()), ".npy");
    if (absl::Status s = WriteHeightsNpy(*wp, path); !s.ok()) return s;
  }
  auto err = MeasureError(*wp);
  if (!err.ok()) return err.status();
  Row row;
  row.instance = inst.name;
  row.cutter = inst.moves.empty() ? "" : CutterToString(inst.moves[0].cutter);
  row.mesh = mesh;
  row.scheme = scheme;
  row.nodes = wp->grid().node_count();
  row.parameters = row.nodes * wp->scheme().parameters_per_node();
  row.err = *err;
  row.seconds = times[times.size() / 2];
  return row;
}

void PrintJson(const std::vector<Row>& rows) {
  JsonWriter j;
  j.BeginObject().Key("rows").BeginArray();
  for (const Row& r : rows) {
    j.BeginObject()
        .Key("instance").String(r.instance)
        .Key("cutter").String(r.cutter)
        .Key("mesh").Int(r.mesh)
        .Key("scheme").String(GetScheme(r.scheme).name())
        .Key("nodes").Int(r.nodes)
        .Key("parameters").Int(r.parameters)
        .Key("max_error").Double(r.err.max_error)
        .Key("mean_error").Double(r.err.mean_error)
        .Key("rms_error").Double(r.err.rms_error)
        .Key("max_error_at").BeginArray()
        .Double(r.err.max_x).Double(r.err.max_y).EndArray()
        .Key("seconds").Double(r.seconds)
        .EndObject();
  }
  j.EndArray().EndObject();
  std::cout << j.str() << "\n";
}

void PrintText(const std::vector<Row>& rows) {
  std::string last;
  for (size_t start = 0; start < rows.size();) {
    size_t end = start;
    while (end < rows.size() && rows[end].instance == rows[start].instance) {
      ++end;
    }
    const std::string& name = rows[start].instance;
    if (name == "five-balls" || name == "five-cylinders") {
      std::cout << name << " (paper Table " << (name == "five-balls" ? 1 : 2)
                << ")\n";
    } else {
      std::cout << name << " (" << rows[start].cutter << ")\n";
    }
    auto line = [&](const std::string& label, auto cell) {
      std::cout << absl::StrFormat("  %-20s", label);
      for (size_t k = start; k < end; ++k) {
        std::cout << absl::StrFormat("%20s", cell(rows[k]));
      }
      std::cout << "\n";
    };
    line("", [](const Row& r) {
      return absl::StrCat(std::string(GetScheme(r.scheme).name()), " ", r.mesh, "x",
                          r.mesh);
    });
    line("nodes", [](const Row& r) { return absl::StrCat(r.nodes); });
    line("parameters", [](const Row& r) { return absl::StrCat(r.parameters); });
    line("max error (mm)",
         [](const Row& r) { return absl::StrFormat("%.3g", r.err.max_error); });
    line("mean error (mm)",
         [](const Row& r) { return absl::StrFormat("%.3g", r.err.mean_error); });
    line("rms error (mm)",
         [](const Row& r) { return absl::StrFormat("%.3g", r.err.rms_error); });
    line("max error at", [](const Row& r) {
      return absl::StrFormat("(%.2f, %.2f)", r.err.max_x, r.err.max_y);
    });
    line("time to apply (s)",
         [](const Row& r) { return absl::StrFormat("%.3g", r.seconds); });
    std::cout << "\n";
    start = end;
  }
}

}  // namespace

int TableCommand(const std::vector<std::string>& argv) {
  auto args = Args::Parse(argv, {"instance", "mesh", "runs", "heights"},
                          {"json", "help"});
  if (!args.ok()) {
    std::cerr << "swarf table: " << args.status().message() << "\n" << kUsage;
    return 2;
  }
  if (args->Has("help")) {
    std::cout << kUsage;
    return 0;
  }
  if (!args->positional().empty()) {
    std::cerr << "swarf table: unexpected argument \"" << args->positional()[0]
              << "\"\n" << kUsage;
    return 2;
  }
  std::vector<std::string> instances;
  const std::string which = args->Get("instance").value_or("paper");
  if (which == "paper" || which == "all") {
    instances.insert(instances.end(), std::begin(kPaperInstances),
                     std::end(kPaperInstances));
  }
  if (which == "shapes" || which == "all") {
    instances.insert(instances.end(), std::begin(kShapeInstances),
                     std::end(kShapeInstances));
  }
  if (instances.empty()) instances = {which};
  std::vector<int> meshes = {100, 1000};
  auto mesh = args->GetInt("mesh");
  auto runs = args->GetInt("runs");
  for (const auto* s : {&mesh, &runs}) {
    if (!s->ok()) {
      std::cerr << "swarf table: " << s->status().message() << "\n";
      return 2;
    }
  }
  if (mesh->has_value()) meshes = {**mesh};
  if (runs->has_value() && **runs < 1) {
    std::cerr << "swarf table: --runs must be at least 1\n";
    return 2;
  }

  std::vector<Row> rows;
  for (const std::string& name : instances) {
    for (SchemeKind scheme :
         {SchemeKind::kZmap, SchemeKind::kTaylor, SchemeKind::kGuarded,
          SchemeKind::kExact}) {
      for (int m : meshes) {
        auto inst = NamedInstance(name, m);
        if (!inst.ok()) {
          std::cerr << "swarf table: " << inst.status().message() << "\n";
          return 2;
        }
        const int n = runs->value_or(m <= 200 ? 11 : 5);
        auto row = MeasureRow(*inst, m, scheme, n, args->Get("heights"));
        if (!row.ok()) {
          std::cerr << "swarf table: " << row.status().message() << "\n";
          return 1;
        }
        rows.push_back(*std::move(row));
      }
    }
  }
  if (args->Has("json")) {
    PrintJson(rows);
  } else {
    PrintText(rows);
  }
  return 0;
}

}  // namespace swarf::cli
