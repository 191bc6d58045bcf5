// Benchmarks of the design comparison (issue "Is the part right?"):
// - loading and placing a 1 M-triangle design on a 16 M-node grid: the STL
//   read (welding, manifold check), the top envelope, Embree's BVH;
// - the deviation over a cut workpiece against the valuation (MeasureError,
//   21 samples per element) of the same workpiece.
// Run: build/bin/swarf_design_bench
#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "client/outputs/deviation.h"
#include "client/outputs/surface_grid.h"
#include "core/valuation.h"
#include "core/workpiece.h"
#include "design/closest_point.h"
#include "design/design_mesh.h"
#include "design/top_envelope.h"

namespace swarf {
namespace {

// The part: a wavy surface over [0, size]^2.
double PartZ(double x, double y) {
  return -3 + std::sin(x / 7) * std::cos(y / 5);
}

// A height-field mesh of the part, q x q quads (2 q^2 triangles), as a
// binary STL.
std::string PartStl(double size, int q) {
  std::vector<double> soup;
  soup.reserve(size_t{18} * q * q);
  const double h = size / q;
  auto add = [&](double x, double y) {
    soup.insert(soup.end(), {x, y, PartZ(x, y)});
  };
  for (int j = 0; j < q; ++j) {
    for (int i = 0; i < q; ++i) {
      const double x0 = i * h, y0 = j * h, x1 = x0 + h, y1 = y0 + h;
      add(x0, y0), add(x1, y0), add(x1, y1);
      add(x0, y0), add(x1, y1), add(x0, y1);
    }
  }
  auto m = design::MeshFromSoup(soup, "part");
  return design::ToBinaryStl(*m);
}

// 708 x 708 quads: 1.0 M triangles over 200 x 200 mm.
const std::string& MillionTriangles() {
  static const std::string* stl = new std::string(PartStl(200, 708));
  return *stl;
}

// 4000 x 4000 elements over the same 200 mm: 16 M nodes.
GridGeometry SixteenMillionNodes() {
  return GridGeometry(StockSpec{0, 0, 200, 200, 0, 3999, 3999});
}

void BM_DesignReadStl(benchmark::State& state) {
  const std::string& stl = MillionTriangles();
  for (auto _ : state) {
    auto m = design::ParseStl(stl, "part.stl");
    benchmark::DoNotOptimize(m->triangles.size());
  }
  state.counters["triangles"] = static_cast<double>((stl.size() - 84) / 50);
}
BENCHMARK(BM_DesignReadStl)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_DesignEnvelope(benchmark::State& state) {
  auto m = design::ParseStl(MillionTriangles(), "part.stl");
  const GridGeometry g = SixteenMillionNodes();
  for (auto _ : state) {
    auto env = design::TopEnvelope::Build(*m, g);
    benchmark::DoNotOptimize(env->covered_nodes());
  }
  state.counters["nodes"] = static_cast<double>(g.node_count());
}
BENCHMARK(BM_DesignEnvelope)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_DesignClosestIndex(benchmark::State& state) {
  auto m = design::ParseStl(MillionTriangles(), "part.stl");
  for (auto _ : state) {
    auto index = design::ClosestPointIndex::Build(*m);
    benchmark::DoNotOptimize(index->get());
  }
}
BENCHMARK(BM_DesignClosestIndex)->Unit(benchmark::kMillisecond)->UseRealTime();

// All three: what `swarf run --design` does before the moves are sent.
void BM_DesignLoadAndPlace(benchmark::State& state) {
  const std::string& stl = MillionTriangles();
  const GridGeometry g = SixteenMillionNodes();
  for (auto _ : state) {
    auto m = design::ParseStl(stl, "part.stl");
    auto env = design::TopEnvelope::Build(*m, g);
    auto index = design::ClosestPointIndex::Build(*m);
    benchmark::DoNotOptimize(env->covered_nodes());
    benchmark::DoNotOptimize(index->get());
  }
}
BENCHMARK(BM_DesignLoadAndPlace)->Unit(benchmark::kMillisecond)->UseRealTime();

// A finishing job over 60 x 60 mm of the part at 0.1 mm (361 k nodes): a
// 1 mm ball, tip on the surface every 0.5 mm, 0.25 mm stepover.
struct Job {
  std::unique_ptr<Workpiece> wp;
  cli::SurfaceGrid grid;
  design::DesignMesh mesh;
  std::optional<design::TopEnvelope> env;
  std::unique_ptr<design::ClosestPointIndex> index;
  std::vector<cli::SourceLine> lines;
};

const Job& FinishingJob() {
  static Job* job = [] {
    auto* j = new Job;
    const StockSpec spec{20, 20, 80, 80, 0, 600, 600};
    j->wp = *Workpiece::Create(spec, SchemeKind::kGuarded);
    std::vector<Move> moves;
    const Cutter ball = Cutter::Ball(1);
    for (double y = 19; y <= 81; y += 0.25) {
      for (double x = 19; x < 81; x += 0.5) {
        moves.emplace_back(Vec3{x, y, PartZ(x, y)},
                           Vec3{x + 0.5, y, PartZ(x + 0.5, y)}, ball);
      }
    }
    (void)j->wp->Apply(moves);
    j->grid = *cli::SurfaceGrid::FromWorkpiece(*j->wp);
    j->grid.SetMoves(moves);
    for (size_t k = 0; k < moves.size(); ++k) {
      j->lines.push_back({0, static_cast<int32_t>(k + 1)});
    }
    j->mesh = *design::ParseStl(PartStl(100, 400), "part.stl");
    j->env.emplace(*design::TopEnvelope::Build(j->mesh, GridGeometry(spec)));
    j->index = *design::ClosestPointIndex::Build(j->mesh);
    return j;
  }();
  return *job;
}

void BM_JobValuation(benchmark::State& state) {
  const Job& job = FinishingJob();
  for (auto _ : state) {
    benchmark::DoNotOptimize(MeasureError(*job.wp)->max_error);
  }
}
BENCHMARK(BM_JobValuation)->Unit(benchmark::kMillisecond)->UseRealTime();

// samples_per_edge 5 (the valuation's 21 samples an element) or 0 (nodes);
// tolerance 0.01 (the default: most scallops are out, so most points get a
// normal query) or 1 (none is).
void BM_JobDeviation(benchmark::State& state) {
  const Job& job = FinishingJob();
  cli::DeviationOptions o;
  o.samples_per_edge = static_cast<int>(state.range(0));
  o.tolerance = state.range(1) / 100.0;
  int64_t queries = 0, points = 0;
  for (auto _ : state) {
    auto r = cli::MeasureDeviation(job.grid, *job.env, *job.index, job.lines, o);
    queries = r->normal_queries;
    points = r->nodes + r->samples;
    benchmark::DoNotOptimize(r->gouge_max);
  }
  state.counters["points"] = static_cast<double>(points);
  state.counters["normal_queries"] = static_cast<double>(queries);
}
BENCHMARK(BM_JobDeviation)
    ->ArgNames({"samples", "tol_cmm"})
    ->Args({5, 1})
    ->Args({5, 100})
    ->Args({0, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace swarf

BENCHMARK_MAIN();
