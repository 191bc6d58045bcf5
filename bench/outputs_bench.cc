// Each output of `swarf run --out` alone, on the corpus jobs as swarf run
// simulates them (ball d=3.175, 0.1 mm, guarded), against the simulation
// itself: build/bin/swarf_outputs_bench. The steps are the --json report's
// (seconds.output_steps), without the transport: no gRPC, one process, the
// core and the writers called directly, each step on both cores as in
// swarf run but alone (swarf run overlaps them). Process CPU time and wall
// time per step; the job's error and mesh figures as counters, to check
// against stats.json.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "client/cli/run_report.h"
#include "client/outputs/grid_bands.h"
#include "client/outputs/marks_files.h"
#include "client/outputs/pictures.h"
#include "client/outputs/png_image.h"
#include "client/outputs/surface_grid.h"
#include "client/outputs/surface_mesh.h"
#include "core/cutting_marks.h"
#include "core/valuation.h"
#include "core/workpiece.h"
#include "gcode/text.h"
#include "gcode/toolpath.h"

namespace swarf::cli {
namespace {

constexpr double kRadius = 3.175 / 2;
constexpr double kSpacing = 0.1;

// A corpus job simulated once, and each output's inputs built on first use.
struct Job {
  StockSpec stock;
  std::vector<Move> moves;
  std::unique_ptr<Workpiece> wp;
  std::unique_ptr<SurfaceGrid> grid;
  std::unique_ptr<std::vector<MarkPolyline>> shown;  // FilterMarks'
  std::unique_ptr<ErrorRaster> raster;
  std::unique_ptr<ReliefSampler> sampler;  // relief.png's, as swarf run's
  std::unique_ptr<TriangleMesh> mesh;
  std::string dir;
};

// The stock as swarf run chooses it without --stock: the path's XY bounds
// grown by the tool's radius, top at 0.
absl::StatusOr<Job> Load(const std::string& name) {
  auto text = gcode::ReadWholeFile(std::string(SWARF_CORPUS_DIR) + "/" + name);
  if (!text.ok()) return text.status();
  auto path = gcode::ParseGcode(*text, gcode::GcodeOptions{});
  if (!path.ok()) return path.status();
  Job job;
  const Cutter ball = Cutter::Ball(kRadius);
  const auto& points = path->points();
  for (size_t i = 1; i < points.size(); ++i) {
    if (points[i].starts_run) continue;
    job.moves.emplace_back(points[i - 1].position, points[i].position, ball);
  }
  StockSpec& s = job.stock;
  s = {path->x_bounds().lo - kRadius,
       path->y_bounds().lo - kRadius,
       path->x_bounds().hi + kRadius,
       path->y_bounds().hi + kRadius,
       0,
       0,
       0};
  s.nx = static_cast<int32_t>(std::ceil((s.x1 - s.x0) / kSpacing - 1e-9));
  s.ny = static_cast<int32_t>(std::ceil((s.y1 - s.y0) / kSpacing - 1e-9));
  job.dir =
      (std::filesystem::temp_directory_path() / ("swarf-outputs-bench-" + name))
          .string();
  std::filesystem::create_directories(job.dir);
  return job;
}

Job* GetJob(benchmark::State& state, const std::string& name) {
  static std::map<std::string, Job> jobs;
  auto it = jobs.find(name);
  if (it == jobs.end()) {
    auto job = Load(name);
    if (!job.ok()) {
      state.SkipWithError(std::string(job.status().message()).c_str());
      return nullptr;
    }
    it = jobs.emplace(name, *std::move(job)).first;
  }
  return &it->second;
}

absl::StatusOr<std::unique_ptr<Workpiece>> Simulate(const Job& job) {
  auto wp = Workpiece::Create(job.stock, SchemeKind::kGuarded);
  if (!wp.ok()) return wp.status();
  if (auto applied = (*wp)->Apply(job.moves); !applied.ok()) {
    return applied.status();
  }
  return wp;
}

SurfaceMeshOptions SwarfRunMesh() {
  SurfaceMeshOptions m;
  m.tolerance = OutputOptions{}.mesh_tolerance;
  return m;
}

ValuationOptions SwarfRunValuation(const StockSpec& stock) {
  ValuationOptions v;
  ErrorMapSize(stock, &v.map_cols, &v.map_rows);
  return v;
}

// What each step needs, built outside the timed loop.
absl::Status Prepare(Job& job) {
  if (job.wp == nullptr) {
    auto wp = Simulate(job);
    if (!wp.ok()) return wp.status();
    job.wp = *std::move(wp);
  }
  if (job.grid == nullptr) {
    auto grid = SurfaceGrid::FromWorkpiece(*job.wp);
    if (!grid.ok()) return grid.status();
    grid->SetMoves(job.moves);
    job.grid = std::make_unique<SurfaceGrid>(*std::move(grid));
  }
  if (job.shown == nullptr) {
    auto marks = FindCuttingMarks(*job.wp);
    if (!marks.ok()) return marks.status();
    job.shown = std::make_unique<std::vector<MarkPolyline>>(
        FilterMarks(*marks, kDefaultMarkDisplay));
  }
  if (job.raster == nullptr) {
    const ValuationOptions v = SwarfRunValuation(job.stock);
    auto stats = MeasureError(*job.wp, v);
    if (!stats.ok()) return stats.status();
    job.raster = std::make_unique<ErrorRaster>(
        ErrorRaster{{job.stock.x0, job.stock.y0, job.stock.x1, job.stock.y1},
                    stats->map_cols,
                    stats->map_rows,
                    std::move(stats->map)});
  }
  if (job.sampler == nullptr) {
    const RunOutputOptions out;
    job.sampler = std::make_unique<ReliefSampler>(
        job.grid->spec, ReliefFrame(job.grid->spec, out.relief));
    job.sampler->AddBand(*job.grid, 0, job.grid->spec.ny);
  }
  if (job.mesh == nullptr) {
    auto mesh = BuildSurfaceMesh(*job.grid, SwarfRunMesh());
    if (!mesh.ok()) return mesh.status();
    job.mesh = std::make_unique<TriangleMesh>(*std::move(mesh));
  }
  return absl::OkStatus();
}

enum class Step {
  kSimulate,
  kErrorStats,
  kMarks,
  kReliefPng,
  kErrorPng,
  kMarksPng,
  kMarksSvg,
  kMarksJson,
  kSurfaceStl,
  kSurfaceWrl,
  kLatticeRows,
  kTileRows,
};

// One step as swarf run does it (run_outputs.cc, run_report.cc).
absl::Status RunStep(Step step, Job& job, benchmark::State& state) {
  const std::string base = job.dir + "/";
  const RunOutputOptions out;
  switch (step) {
    case Step::kSimulate: {
      auto wp = Simulate(job);
      return wp.status();
    }
    case Step::kErrorStats: {
      auto stats = MeasureError(*job.wp, SwarfRunValuation(job.stock));
      if (!stats.ok()) return stats.status();
      state.counters["samples"] = static_cast<double>(stats->samples);
      state.counters["max_error_mm"] = stats->max_error;
      return absl::OkStatus();
    }
    case Step::kMarks: {
      auto marks = FindCuttingMarks(*job.wp);
      if (!marks.ok()) return marks.status();
      state.counters["polylines"] = static_cast<double>(marks->size());
      return absl::OkStatus();
    }
    case Step::kReliefPng: {
      // Sampled, then its rows coloured as they are written (run_outputs).
      ReliefSampler sampler(job.grid->spec,
                            ReliefFrame(job.grid->spec, out.relief));
      sampler.AddBand(*job.grid, 0, job.grid->spec.ny);
      return WritePngRows(
          sampler.frame().width, sampler.frame().height,
          [&](int y, uint8_t* rgb) { sampler.ColorRow(y, rgb); },
          base + "relief.png");
    }
    case Step::kErrorPng: {
      auto map = RenderErrorMap(*job.raster, out.error);
      if (!map.ok()) return map.status();
      return WritePng(*map, base + "error.png");
    }
    case Step::kMarksPng: {
      // Over relief.png's sampled relief, as swarf run draws it.
      auto picture = DrawMarks(*job.sampler, *job.shown, out.marks);
      if (!picture.ok()) return picture.status();
      return WritePng(*picture, base + "marks.png");
    }
    case Step::kMarksSvg:
      return WriteMarksSvg(job.stock, *job.shown, base + "marks.svg");
    case Step::kMarksJson:
      return WriteMarksJson(*job.shown, base + "marks.json");
    case Step::kSurfaceStl: {
      auto mesh = BuildSurfaceMesh(*job.grid, SwarfRunMesh());
      if (!mesh.ok()) return mesh.status();
      state.counters["triangles"] = static_cast<double>(mesh->triangles.size());
      state.counters["deviation_mm"] = mesh->max_deviation;
      return WriteStl(*mesh, base + "surface.stl");
    }
    case Step::kSurfaceWrl:
      return WriteVrml(*job.mesh, base + "surface.wrl",
                       SurfaceColors(*job.mesh, job.stock.z_top));
    case Step::kLatticeRows: {
      // The meshes' share of swarf run's pass over the grid (subdivision 1,
      // the heights read again later: each lattice row's lowest height).
      auto lattice = NewLattice(job.grid->spec, 1, /*heights=*/false);
      if (!lattice.ok()) return lattice.status();
      FillLatticeRows(*job.grid, 0, job.grid->spec.ny, &*lattice);
      benchmark::DoNotOptimize(lattice->row_min.data());
      return absl::OkStatus();
    }
    case Step::kTileRows: {
      // swarf run's pass over its embedded session's grid, band by band
      // (TileRowBands over SetTileRows), without the visitors' work: the
      // "tiles" of stats.json's output steps.
      const Workpiece& wp = *job.wp;
      TileRowBands bands(
          wp.spec(), wp.scheme().kind(),
          [&wp](SurfaceGrid* band, int32_t t0, int32_t t1, bool heights_only) {
            return band->SetTileRows(wp, t0, t1, heights_only);
          },
          std::shared_ptr<const MoveSource>(std::shared_ptr<void>(),
                                            &wp.moves()),
          std::shared_ptr<const MoveSweeps>(std::shared_ptr<void>(),
                                            &wp.sweeps()));
      bands.SetFillWritesEveryNode();  // as swarf run's
      double lowest = wp.spec().z_top;
      return bands.ForEach([&](const SurfaceGrid& band, int32_t, int32_t) {
        lowest = std::min(lowest, band.jets.back().w);
        benchmark::DoNotOptimize(lowest);
        return absl::OkStatus();
      });
    }
  }
  return absl::InternalError("unknown step");
}

void BM_Output(benchmark::State& state, const char* job_name, Step step) {
  Job* job = GetJob(state, job_name);
  if (job == nullptr) return;
  if (absl::Status s = Prepare(*job); !s.ok()) {
    state.SkipWithError(std::string(s.message()).c_str());
    return;
  }
  for (auto _ : state) {
    if (absl::Status s = RunStep(step, *job, state); !s.ok()) {
      state.SkipWithError(std::string(s.message()).c_str());
      return;
    }
  }
}

#define SWARF_OUTPUT_BENCH(job, file, step)                       \
  BENCHMARK_CAPTURE(BM_Output, job##_##step, file, Step::k##step) \
      ->Unit(benchmark::kMillisecond)                             \
      ->MeasureProcessCPUTime()                                   \
      ->UseRealTime()

#define SWARF_OUTPUT_BENCHES(job, file)       \
  SWARF_OUTPUT_BENCH(job, file, Simulate);    \
  SWARF_OUTPUT_BENCH(job, file, ErrorStats);  \
  SWARF_OUTPUT_BENCH(job, file, Marks);       \
  SWARF_OUTPUT_BENCH(job, file, ReliefPng);   \
  SWARF_OUTPUT_BENCH(job, file, ErrorPng);    \
  SWARF_OUTPUT_BENCH(job, file, MarksPng);    \
  SWARF_OUTPUT_BENCH(job, file, MarksSvg);    \
  SWARF_OUTPUT_BENCH(job, file, MarksJson);   \
  SWARF_OUTPUT_BENCH(job, file, SurfaceStl);  \
  SWARF_OUTPUT_BENCH(job, file, SurfaceWrl);  \
  SWARF_OUTPUT_BENCH(job, file, LatticeRows); \
  SWARF_OUTPUT_BENCH(job, file, TileRows)

SWARF_OUTPUT_BENCHES(bear, "bear.nc");
SWARF_OUTPUT_BENCHES(cameo, "cameo.nc");

}  // namespace
}  // namespace swarf::cli

BENCHMARK_MAIN();
