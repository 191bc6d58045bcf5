// Benchmarks of the core engine: node evaluations, short finishing moves,
// the paper's two instances at 1000x1000, and reads of a cut workpiece. Run: build/bin/swarf_bench
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <span>
#include <vector>

#include "core/cutter/ball_sweep.h"
#include "core/cutting_marks.h"
#include "core/instances.h"
#include "core/valuation.h"
#include "core/workpiece.h"

namespace swarf {
namespace {

// A counter of the wall time per iteration divided by `moves`.
benchmark::Counter TimePerMove(size_t moves) {
  return benchmark::Counter(static_cast<double>(moves),
                            benchmark::Counter::kIsIterationInvariantRate |
                                benchmark::Counter::kInvert);
}

// Sweep evaluation alone: a sloped move evaluated over the nodes of its
// footprint, height only (Locate) or with derivatives (Jet).
template <bool kJet>
void BM_NodeEvaluation(benchmark::State& state) {
  const BallSweep sweep({0, 0, -1}, {10, 3, -2}, 3);
  const BallSweep::Capsule cap = sweep.Footprint(0);
  std::vector<std::pair<double, double>> pts;
  for (double y = -4; y <= 7; y += 0.05) {
    const Interval span = cap.RowSpan(y);
    for (double x = std::floor(span.lo); x <= span.hi; x += 0.05) {
      pts.emplace_back(x, y);
    }
  }
  for (auto _ : state) {
    double acc = 0;
    for (const auto& [x, y] : pts) {
      const SweepPoint p = sweep.Locate(x, y);
      if constexpr (kJet) {
        if (p.piece != SweepPoint::kNone) acc += sweep.Jet(p).wxx;
      } else {
        acc += p.depth;
      }
    }
    benchmark::DoNotOptimize(acc);
  }
  state.SetItemsProcessed(state.iterations() * pts.size());
}
BENCHMARK(BM_NodeEvaluation<false>)->Name("NodeEvaluation/height");
BENCHMARK(BM_NodeEvaluation<true>)->Name("NodeEvaluation/height+derivatives");

// A paper instance at mesh x mesh: create the workpiece and apply its five
// moves (the paper's "time cost for computation").
void BM_Instance(benchmark::State& state, const char* name, SchemeKind scheme) {
  const Instance inst = *PaperInstance(name, static_cast<int>(state.range(0)));
  for (auto _ : state) {
    auto wp = *Workpiece::Create(inst.stock, scheme);
    auto r = wp->Apply(inst.moves);
    benchmark::DoNotOptimize(r->node_lowerings);
    state.PauseTiming();
    wp.reset();  // freeing is not part of the paper's figure
    state.ResumeTiming();
  }
}
BENCHMARK_CAPTURE(BM_Instance, five_balls_zmap, "five-balls", SchemeKind::kZmap)
    ->Arg(1000)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Instance, five_balls_taylor, "five-balls",
                  SchemeKind::kTaylor)
    ->Arg(1000)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Instance, five_cylinders_zmap, "five-cylinders",
                  SchemeKind::kZmap)
    ->Arg(1000)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Instance, five_cylinders_taylor, "five-cylinders",
                  SchemeKind::kTaylor)
    ->Arg(1000)->Unit(benchmark::kMillisecond)->UseRealTime();

// Short finishing moves: a 1 mm ball (r = 0.5) zig-zag raster of 0.2 mm
// moves, stepover 0.1 mm, over a 100 mm stock at 1000x1000, applied in
// batches of state.range(0) moves. Reports moves per second.
std::vector<Move> FinishingRaster(double step, double stepover, int rows) {
  std::vector<Move> moves;
  for (int k = 0; k < rows; ++k) {
    const double y = 5 + k * stepover;
    const bool fwd = k % 2 == 0;
    for (double s = 5; s < 95; s += step) {
      const double xa = fwd ? s : 100 - s, xb = fwd ? s + step : 100 - s - step;
      // A gentle wave so that moves are sloped, as in relief finishing.
      auto z = [&](double x) { return -1 + 0.3 * std::sin(x * 0.2 + y * 0.1); };
      moves.push_back({{xa, y, z(xa)}, {xb, y, z(xb)}, 0.5});
    }
  }
  return moves;
}

// Applies `moves` to a new workpiece of `stock` in batches of `batch`
// moves; with `cuts`, asking what each move cut (ApplyOptions::cuts and a
// flute length per move).
void ApplyInBatches(benchmark::State& state, const std::vector<Move>& moves,
                    const StockSpec& stock, SchemeKind scheme, size_t batch,
                    bool cuts) {
  const std::vector<double> flutes(batch, 10.0);
  for (auto _ : state) {
    state.PauseTiming();
    auto wp = *Workpiece::Create(stock, scheme);
    state.ResumeTiming();
    for (size_t k = 0; k < moves.size(); k += batch) {
      const size_t n = std::min(batch, moves.size() - k);
      const std::span<const Move> span(moves.data() + k, n);
      if (cuts) {
        ApplyOptions opts;
        opts.cuts = true;
        opts.drop_limit = std::span<const double>(flutes.data(), n);
        auto r = wp->Apply(span, opts);
        benchmark::DoNotOptimize(r->cuts.data());
      } else {
        auto r = wp->Apply(span);
        benchmark::DoNotOptimize(r->node_lowerings);
      }
    }
    state.PauseTiming();
    wp.reset();
    state.ResumeTiming();
  }
  state.SetItemsProcessed(state.iterations() * moves.size());
  state.counters["ns_per_move"] = TimePerMove(moves.size());
}

// The finishing raster in batches of state.range(0) moves.
void FinishingApply(benchmark::State& state, SchemeKind scheme, bool cuts) {
  ApplyInBatches(state, FinishingRaster(0.2, 0.1, 100),
                 {0, 0, 100, 100, 0, 1000, 1000}, scheme,
                 static_cast<size_t>(state.range(0)), cuts);
}

void BM_FinishingMoves(benchmark::State& state, SchemeKind scheme) {
  FinishingApply(state, scheme, /*cuts=*/false);
}
BENCHMARK_CAPTURE(BM_FinishingMoves, zmap, SchemeKind::kZmap)
    ->Arg(1000)->Arg(10000)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_FinishingMoves, taylor, SchemeKind::kTaylor)
    ->Arg(1000)->Arg(10000)->Unit(benchmark::kMillisecond)->UseRealTime();

// The same with what each move cut (issue 30's safety checks and process
// facts).
void BM_FinishingMovesCuts(benchmark::State& state, SchemeKind scheme) {
  FinishingApply(state, scheme, /*cuts=*/true);
}
BENCHMARK_CAPTURE(BM_FinishingMovesCuts, taylor, SchemeKind::kTaylor)
    ->Arg(10000)->Unit(benchmark::kMillisecond)->UseRealTime();

// The plate job's finishing (scripts/make-example --plate): a 4 mm ball
// (r = 2) raster of 0.5 mm moves over a wave, stepover 0.2 mm, on a 0.05 mm
// grid (60 x 30 mm, 1200 x 600 elements).
const StockSpec kPlateStock{0, 0, 60, 30, 0, 1200, 600};

std::vector<Move> PlateFinishingRaster() {
  std::vector<Move> moves;
  for (int k = 0; k < 100; ++k) {
    const double y = 5 + k * 0.2;
    const bool fwd = k % 2 == 0;
    for (double s = 5; s < 55; s += 0.5) {
      const double xa = fwd ? s : 60 - s, xb = fwd ? s + 0.5 : 60 - s - 0.5;
      auto z = [&](double x) { return -3 + std::sin(x * 0.3 + y * 0.2); };
      moves.push_back({{xa, y, z(xa)}, {xb, y, z(xb)}, 2.0});
    }
  }
  return moves;
}

// The plate's finishing applied in batches of 10000. A pass's footprint
// spans up to 80 nodes of a row, on rows the passes before it cut: the
// footprint narrowed row by row to each row's highest node.
void BM_PlateFinishing(benchmark::State& state) {
  ApplyInBatches(state, PlateFinishingRaster(), kPlateStock,
                 SchemeKind::kGuarded, 10000, /*cuts=*/false);
}
BENCHMARK(BM_PlateFinishing)->Unit(benchmark::kMillisecond)->UseRealTime();

// The same with what each move cut (ApplyOptions::cuts), as swarf run asks
// for its volumes and checks.
void BM_PlateFinishingCuts(benchmark::State& state) {
  ApplyInBatches(state, PlateFinishingRaster(), kPlateStock,
                 SchemeKind::kGuarded, 10000, /*cuts=*/true);
}
BENCHMARK(BM_PlateFinishingCuts)->Unit(benchmark::kMillisecond)->UseRealTime();

// Cutter shapes (issue 16): the same paths for the ball and each new shape,
// applied to a 100 mm stock at 1000x1000 (0.1 mm) in batches of 10000.
// - finishing: the zig-zag raster above (0.2 mm moves on a gentle wave,
//   stepover 0.1 mm, 45,000 sloped moves) with 1 mm tools;
// - roughing: 6 mm tools, three levels 1 mm apart, each entered by a 10 mm
//   ramp then cleared by passes along x at 40% stepover in 10 mm moves
//   (1,260 moves, mostly horizontal).
// Counters: ns per move, and nodes lowered per second (node_lowerings).
// The shape of `kind` with outer radius r, in the proportions of common
// tools: bull-nose corner 0.4 r, 90 degree V-bit with a flat tip of r / 6,
// tapered ball tip r / 3 with a 10 degree half angle.
Cutter ShapeCutter(CutterKind kind, double r) {
  switch (kind) {
    case CutterKind::kBall:
      return Cutter::Ball(r);
    case CutterKind::kFlat:
      return Cutter::Flat(r);
    case CutterKind::kBullNose:
      return Cutter::BullNose(r, 0.4 * r);
    case CutterKind::kCone:
      return Cutter::Cone(r, 45, r / 6);
    case CutterKind::kTaperedBall:
      return Cutter::TaperedBall(r, r / 3, 10);
  }
  return Cutter::Ball(r);
}

std::vector<Move> WithCutter(std::vector<Move> moves, const Cutter& c) {
  for (Move& m : moves) m.cutter = c;
  return moves;
}

std::vector<Move> RoughingPath(const Cutter& c) {
  std::vector<Move> moves;
  const double step = 0.8 * c.radius;
  for (int level = 1; level <= 3; ++level) {
    const double z = -1.0 * level;
    moves.push_back({{5, 5, z + 1}, {15, 5, z}, c});  // ramp in
    bool fwd = true;
    for (double y = 5; y <= 95; y += step, fwd = !fwd) {
      for (int k = 0; k < 9; ++k) {
        const double xa = fwd ? 5 + 10 * k : 95 - 10 * k;
        const double xb = fwd ? xa + 10 : xa - 10;
        moves.push_back({{xa, y, z}, {xb, y, z}, c});
      }
      const double x_end = fwd ? 95 : 5;
      moves.push_back({{x_end, y, z}, {x_end, y + step, z}, c});  // stepover
    }
  }
  return moves;
}

void BM_ShapePath(benchmark::State& state, CutterKind kind, bool finishing,
                  SchemeKind scheme) {
  const std::vector<Move> moves =
      finishing ? WithCutter(FinishingRaster(0.2, 0.1, 100),
                             ShapeCutter(kind, 0.5))
                : RoughingPath(ShapeCutter(kind, 3));
  constexpr size_t kBatch = 10000;
  int64_t lowered = 0;
  for (auto _ : state) {
    state.PauseTiming();
    auto wp = *Workpiece::Create({0, 0, 100, 100, 0, 1000, 1000}, scheme);
    state.ResumeTiming();
    for (size_t k = 0; k < moves.size(); k += kBatch) {
      const size_t n = std::min(kBatch, moves.size() - k);
      auto r = wp->Apply(std::span<const Move>(moves.data() + k, n));
      lowered += r->node_lowerings;
    }
    state.PauseTiming();
    wp.reset();
    state.ResumeTiming();
  }
  state.counters["ns_per_move"] = TimePerMove(moves.size());
  state.counters["nodes_per_s"] = benchmark::Counter(
      static_cast<double>(lowered), benchmark::Counter::kIsRate);
}
#define SWARF_SHAPE_BENCH(name, kind)                                      \
  BENCHMARK_CAPTURE(BM_ShapePath, name##_finishing_taylor, kind, true,     \
                    SchemeKind::kTaylor)                                   \
      ->Unit(benchmark::kMillisecond)->UseRealTime();                      \
  BENCHMARK_CAPTURE(BM_ShapePath, name##_finishing_zmap, kind, true,       \
                    SchemeKind::kZmap)                                     \
      ->Unit(benchmark::kMillisecond)->UseRealTime();                      \
  BENCHMARK_CAPTURE(BM_ShapePath, name##_roughing_taylor, kind, false,     \
                    SchemeKind::kTaylor)                                   \
      ->Unit(benchmark::kMillisecond)->UseRealTime();                      \
  BENCHMARK_CAPTURE(BM_ShapePath, name##_roughing_zmap, kind, false,       \
                    SchemeKind::kZmap)                                     \
      ->Unit(benchmark::kMillisecond)->UseRealTime()
SWARF_SHAPE_BENCH(ball, CutterKind::kBall);
SWARF_SHAPE_BENCH(flat, CutterKind::kFlat);
SWARF_SHAPE_BENCH(bull_nose, CutterKind::kBullNose);
SWARF_SHAPE_BENCH(cone, CutterKind::kCone);
SWARF_SHAPE_BENCH(tapered_ball, CutterKind::kTaperedBall);
#undef SWARF_SHAPE_BENCH

// Recording moves without cutting them (a restart from a snapshot): the
// same finishing raster (45,000 moves) in batches of 10000. Reports ns per
// move.
void BM_RecordMoves(benchmark::State& state) {
  const std::vector<Move> moves = FinishingRaster(0.2, 0.1, 100);
  for (auto _ : state) {
    state.PauseTiming();
    auto wp = *Workpiece::Create({0, 0, 100, 100, 0, 1000, 1000},
                                 SchemeKind::kTaylor);
    state.ResumeTiming();
    for (size_t k = 0; k < moves.size(); k += 10000) {
      const size_t n = std::min<size_t>(10000, moves.size() - k);
      benchmark::DoNotOptimize(
          wp->Record(std::span<const Move>(moves.data() + k, n)));
    }
    state.PauseTiming();
    wp.reset();
    state.ResumeTiming();
  }
  state.counters["ns_per_move"] = TimePerMove(moves.size());
}
BENCHMARK(BM_RecordMoves)->Unit(benchmark::kMillisecond)->UseRealTime();

// What reads cost once a job is cut: the finishing raster of
// BM_FinishingMoves cut on a taylor workpiece (unless a
// scheme is named: the same cut on its workpiece; 1000x1000), then every
// allocated tile read with derivatives (as the service answers GetTiles),
// the valuation (eq. 15, 21 samples per element, MeasureError), and the
// cutting marks (FindCuttingMarks, default options). Each read starts from a
// freshly cut workpiece, so that nothing computed for an earlier read is
// reused.
// `moves` cut on a new workpiece of `stock`, in batches of 10000.
std::unique_ptr<Workpiece> CutWorkpiece(const std::vector<Move>& moves,
                                        const StockSpec& stock,
                                        SchemeKind scheme) {
  auto wp = *Workpiece::Create(stock, scheme);
  for (size_t k = 0; k < moves.size(); k += 10000) {
    const size_t n = std::min<size_t>(10000, moves.size() - k);
    (void)wp->Apply(std::span<const Move>(moves.data() + k, n));
  }
  return wp;
}

std::unique_ptr<Workpiece> FinishedWorkpiece(SchemeKind scheme) {
  return CutWorkpiece(FinishingRaster(0.2, 0.1, 100),
                      {0, 0, 100, 100, 0, 1000, 1000}, scheme);
}

// kTiles reads as the service answers GetTiles: chunks of 16 tiles, each
// chunk's tiles read on the pool at once, each computing its derivatives
// straight into its buffers; kTilesSerial reads them one by one on the
// calling thread; kJetsOnly computes the derivatives into the cache
// (PrepareJets, chunks of 16 on the pool) and reads nothing.
enum class Read { kTiles, kTilesSerial, kJetsOnly, kValuation, kMarks };

void BM_Read(benchmark::State& state, Read what,
             SchemeKind scheme = SchemeKind::kTaylor) {
  std::vector<double> w(kTileNodes);
  std::vector<float> d(5 * kTileNodes);
  std::vector<int32_t> owner(kTileNodes);
  float* dp[5];
  for (int c = 0; c < 5; ++c) dp[c] = d.data() + c * kTileNodes;
  struct TileBuffers {
    std::vector<double> w;
    std::vector<float> d;
    std::vector<int32_t> owner;
  };
  constexpr size_t kChunk = 16;  // tiles read at once, as GetTiles does
  TileBuffers chunk_buffers[kChunk];
  for (auto _ : state) {
    state.PauseTiming();
    auto wp = FinishedWorkpiece(scheme);
    std::vector<int32_t> tiles;  // the allocated ones
    for (int32_t t = 0; t < wp->tile_count(); ++t) {
      if (wp->TileAllocated(t)) tiles.push_back(t);
    }
    state.ResumeTiming();
    switch (what) {
      case Read::kTiles: {
        for (size_t k = 0; k < tiles.size(); k += kChunk) {
          const size_t n = std::min(kChunk, tiles.size() - k);
          wp->pool().ParallelFor(static_cast<int64_t>(n), [&](int64_t q) {
            TileBuffers& b = chunk_buffers[q];
            b.w.resize(kTileNodes);
            b.d.resize(5 * kTileNodes);
            b.owner.resize(kTileNodes);
            float* const bd[5] = {b.d.data(), b.d.data() + kTileNodes,
                                  b.d.data() + 2 * kTileNodes,
                                  b.d.data() + 3 * kTileNodes,
                                  b.d.data() + 4 * kTileNodes};
            wp->ReadTile(tiles[k + q], b.w.data(), bd, b.owner.data());
            benchmark::DoNotOptimize(b.d.data());
          });
        }
        break;
      }
      case Read::kJetsOnly:
        for (size_t k = 0; k < tiles.size(); k += kChunk) {
          wp->PrepareJets(std::span<const int32_t>(
              tiles.data() + k, std::min(kChunk, tiles.size() - k)));
        }
        break;
      case Read::kTilesSerial:
        for (const int32_t t : tiles) {
          wp->ReadTile(t, w.data(), dp, owner.data());
          benchmark::DoNotOptimize(d.data());
        }
        break;
      case Read::kValuation:
        benchmark::DoNotOptimize(MeasureError(*wp)->max_error);
        break;
      case Read::kMarks:
        benchmark::DoNotOptimize(FindCuttingMarks(*wp, {})->size());
        break;
    }
    state.PauseTiming();
    wp.reset();
    state.ResumeTiming();
  }
}
BENCHMARK_CAPTURE(BM_Read, tiles_with_derivatives, Read::kTiles)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Read, tiles_with_derivatives_serial, Read::kTilesSerial)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Read, jets_only, Read::kJetsOnly)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Read, valuation, Read::kValuation)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Read, marks, Read::kMarks)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
// The same reads on the other schemes that reconstruct from the nodes' jets
// or the moves (the cut is the same; the surface inside elements differs).
BENCHMARK_CAPTURE(BM_Read, valuation_guarded, Read::kValuation,
                  SchemeKind::kGuarded)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Read, valuation_exact, Read::kValuation,
                  SchemeKind::kExact)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Read, valuation_zmap, Read::kValuation,
                  SchemeKind::kZmap)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Read, marks_guarded, Read::kMarks, SchemeKind::kGuarded)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Read, marks_exact, Read::kMarks, SchemeKind::kExact)
    ->Unit(benchmark::kMillisecond)->UseRealTime();

// The valuation of the plate's finishing (BM_PlateFinishing's cut, guarded)
// with an error map of a cell per 4 x 4 elements, as swarf run asks on a
// large plate (cells larger than elements): a ball's neighbouring passes
// reach most elements, where the rule-outs of the valuation's moves work.
void BM_PlateValuation(benchmark::State& state) {
  const std::vector<Move> moves = PlateFinishingRaster();
  ValuationOptions options;
  options.map_cols = kPlateStock.nx / 4;
  options.map_rows = kPlateStock.ny / 4;
  for (auto _ : state) {
    state.PauseTiming();
    auto wp = CutWorkpiece(moves, kPlateStock, SchemeKind::kGuarded);
    state.ResumeTiming();
    benchmark::DoNotOptimize(MeasureError(*wp, options)->max_error);
    state.PauseTiming();
    wp.reset();
    state.ResumeTiming();
  }
}
BENCHMARK(BM_PlateValuation)->Unit(benchmark::kMillisecond)->UseRealTime();

// The cutting marks of the plate's finishing (guarded): the creases between
// neighbouring passes, each vertex projected onto its exact crease and
// tested for a third surface below it (MoveSweeps::LowestAt).
void BM_PlateMarks(benchmark::State& state) {
  const auto wp =
      CutWorkpiece(PlateFinishingRaster(), kPlateStock, SchemeKind::kGuarded);
  for (auto _ : state) {
    benchmark::DoNotOptimize(FindCuttingMarks(*wp, {})->size());
  }
}
BENCHMARK(BM_PlateMarks)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace swarf

BENCHMARK_MAIN();
