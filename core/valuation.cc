#include "core/valuation.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/cutter/sweep.h"
#include "core/target_clones.h"
#include "core/value_minmax.h"

namespace swarf {
namespace {

// Elements of a row (at most MoveIndex::kBinElements) whose near moves are
// taken together before each element's own test.
constexpr int32_t kBlockElements = 4;
// Rows of a bin whose moves are taken together before each row's own test
// (on the 30 mm plate: 4 rows 7,882 M instructions, 8 rows 7,849 M, 16
// rows 7,858 M).
constexpr int32_t kBandRows = 8;

struct Partial {
  double sum = 0, sum_sq = 0, max = -1, max_x = 0, max_y = 0;
  int64_t n = 0;
};

// The largest of eight lanes (none NaN: in any order).
[[gnu::always_inline]] inline double LanesMax(const double m[8]) {
  return MaxOf(MaxOf(MaxOf(m[0], m[1]), MaxOf(m[2], m[3])),
               MaxOf(MaxOf(m[4], m[5]), MaxOf(m[6], m[7])));
}

// The largest of v[0..n), n a positive multiple of 8. Heights are never
// NaN (minima that start at the stock top), so the order of comparison
// does not matter: eight lanes, in registers (an omp simd reduction over
// any n took its remainder and its lanes through the stack).
SWARF_TARGET_CLONES
double Highest(const double* v, int32_t n) {
  double m[8];
  for (int32_t q = 0; q < 8; ++q) m[q] = v[q];
  for (int32_t q0 = 8; q0 < n; q0 += 8) {
#pragma omp simd
    for (int32_t q = 0; q < 8; ++q) m[q] = MaxOf(m[q], v[q0 + q]);
  }
  return LanesMax(m);
}

// err[q] = SampleError(rec[q], est[q]) for q < n, and the largest of them
// and 0 (a NaN error is passed over, as std::max(m, err) passes it over:
// the largest of the rest in any order).
SWARF_TARGET_CLONES
double ErrorsOf(const double* __restrict rec, const double* __restrict est,
                int32_t n, double* __restrict err) {
  double m = 0;
#pragma omp simd reduction(max : m)
  for (int32_t q = 0; q < n; ++q) {
    err[q] = SampleError(rec[q], est[q]);
    m = MaxOf(m, err[q]);
  }
  return m;
}

// The largest of err[q] and 0 for q < n in each quarter of an element's
// lattice, m[(si >= sx) + 2 (sj >= sy)], the points' si and sj given as
// doubles. A NaN error is passed over, as std::max(m, err) passes it over.
SWARF_TARGET_CLONES
void QuarterMaxima(const double* __restrict err, const double* __restrict si,
                   const double* __restrict sj, int32_t n, double sx, double sy,
                   double m[4]) {
  double m0 = 0, m1 = 0, m2 = 0, m3 = 0;
#pragma omp simd reduction(max : m0, m1, m2, m3)
  for (int32_t q = 0; q < n; ++q) {
    const double e = err[q];
    const bool right = si[q] >= sx, up = sj[q] >= sy;
    m0 = MaxOf(m0, (!right & !up) ? e : 0.0);
    m1 = MaxOf(m1, (right & !up) ? e : 0.0);
    m2 = MaxOf(m2, (!right & up) ? e : 0.0);
    m3 = MaxOf(m3, (right & up) ? e : 0.0);
  }
  m[0] = m0;
  m[1] = m1;
  m[2] = m2;
  m[3] = m3;
}

// At least n entries in *v (the existing ones kept, not zeroed).
template <typename T>
void Grow(std::vector<T>* v, size_t n) {
  if (v->size() < n) v->resize(n);
}

// est[q] = std::min(est[q], h[q]) for q < n: cloned (in the traversal's
// lambda the loop took two lanes at a time).
SWARF_TARGET_CLONES
void LowerTo(const double* __restrict h, int32_t n, double* __restrict est) {
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) est[q] = MinOf(est[q], h[q]);
}

// est[q] = MinOf(top, est[q]) for q < n: in place, the values LowerTo(est,
// n, t) gives an array t that holds top.
SWARF_TARGET_CLONES
void HoldTo(double top, int32_t n, double* __restrict est) {
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) est[q] = MinOf(top, est[q]);
}

// dx[q] = x[q] - xc and dy[q] = y[q] - yc for q < n (n >= 1), and their
// ranges: range = {min dx, max dx, min dy, max dy}. The coordinates are
// finite and a difference is never -0, so the order of the comparisons
// does not matter: vectorized reductions.
SWARF_TARGET_CLONES
void OffsetsFrom(const double* __restrict x, const double* __restrict y,
                 int32_t n, double xc, double yc, double* __restrict dx,
                 double* __restrict dy, double range[4]) {
  double dx_lo = x[0] - xc, dx_hi = dx_lo;
  double dy_lo = y[0] - yc, dy_hi = dy_lo;
#pragma omp simd reduction(min : dx_lo, dy_lo) reduction(max : dx_hi, dy_hi)
  for (int32_t q = 0; q < n; ++q) {
    dx[q] = x[q] - xc;
    dy[q] = y[q] - yc;
    dx_lo = MinOf(dx_lo, dx[q]);
    dx_hi = MaxOf(dx_hi, dx[q]);
    dy_lo = MinOf(dy_lo, dy[q]);
    dy_hi = MaxOf(dy_hi, dy[q]);
  }
  range[0] = dx_lo;
  range[1] = dx_hi;
  range[2] = dy_lo;
  range[3] = dy_hi;
}

// Adds err[0..n) to the sums in sample order (the same additions as one
// loop over the samples). Not inlined: inlined into the element loop, the
// sums were spilled to the stack, one store and load a sample on the chain
// of additions.
[[gnu::noinline]] void Accumulate(const double* err, int32_t n, double* sum,
                                  double* sum_sq) {
  double s = *sum, s2 = *sum_sq;
  for (int32_t q = 0; q < n; ++q) {
    s += err[q];
    s2 += err[q] * err[q];
  }
  *sum = s;
  *sum_sq = s2;
}

// The first s in [1, n) with cells[s] != cells[0], n if none: where a
// column's or a row's lattice points enter their second map cell.
int32_t SecondCell(const int64_t* cells, int32_t n) {
  int32_t s = 1;
  while (s < n && cells[s] == cells[0]) ++s;
  return s;
}

// The first q < n with err[q] == top, -1 if none (top NaN, or not among
// them).
int32_t FirstOf(const double* err, int32_t n, double top) {
  for (int32_t q = 0; q < n; ++q) {
    if (err[q] == top) return q;
  }
  return -1;
}

// Moves of a bin, in bin order, as arrays: where each reaches below a cap
// (a box and FootprintGap's reach: for a ball the tips' box, z_r and r2;
// for another shape its footprint's box below the top, z_r -inf and r2 0,
// so that the reach is the box itself) and its lowest point; `k` its index
// in the bin. Holds at most `capacity` moves (Reset: arrays of at least
// that size rounded up to 8, written in place: no push_back on eight
// arrays a move). The entries from size() to padded() hold stale values:
// vector loops run over them (no scalar remainder) and their results are
// ignored.
struct RowMoves {
  std::vector<double> x0, x1, y0, y1, z_r, r2, lowest;
  std::vector<int32_t> k;
  int32_t n = 0;
  // Empty, with room for `capacity` moves. The arrays only grow: a thread
  // reuses them from bin to bin instead of allocating and zeroing them.
  void Reset(int32_t capacity) {
    n = 0;
    const int32_t size = Padded(capacity);
    if (static_cast<int32_t>(k.size()) >= size) return;
    for (std::vector<double>* v : {&x0, &x1, &y0, &y1, &z_r, &r2, &lowest}) {
      v->resize(size);
    }
    k.resize(size);
  }
  static int32_t Padded(int32_t n) { return (n + 7) & ~7; }
  // Gives the arrays back where they grew past `keep` moves.
  void Trim(int32_t keep) {
    if (static_cast<int32_t>(k.size()) > keep) *this = RowMoves();
  }
  void Clear() { n = 0; }
  [[gnu::always_inline]] void Add(const Rect& box, double reach_z_r,
                                  double reach_r2, double low, int32_t at) {
    x0[n] = box.x0;
    x1[n] = box.x1;
    y0[n] = box.y0;
    y1[n] = box.y1;
    z_r[n] = reach_z_r;
    r2[n] = reach_r2;
    lowest[n] = low;
    k[n++] = at;
  }
  // Appends move q to *to. Inlined: the calls cost more than the copies.
  [[gnu::always_inline]] void CopyFrom(int32_t q, RowMoves* to) const {
    to->Add(Rect{x0[q], y0[q], x1[q], y1[q]}, z_r[q], r2[q], lowest[q], k[q]);
  }
  int32_t size() const { return n; }
  int32_t padded() const { return Padded(n); }
};

// Whether plane (touching its surface at (xc, yc)) less its slack is at or
// above est[q] at each point q < n (a positive multiple of 8), given as
// its offsets from (xc, yc) (dx[q], dy[q]): then that surface lowers none
// of them. Eight lanes, in registers, as Highest.
SWARF_TARGET_CLONES
bool PlaneAtOrAbove(const BallSweep::SupportPlane& plane,
                    const double* __restrict dx, const double* __restrict dy,
                    int32_t n, const double* __restrict est) {
  const double w = plane.w - plane.slack, wx = plane.wx, wy = plane.wy;
  double below[8] = {};
  for (int32_t q0 = 0; q0 < n; q0 += 8) {
#pragma omp simd
    for (int32_t q = 0; q < 8; ++q) {
      const double l = w + wx * dx[q0 + q] + wy * dy[q0 + q];
      below[q] = MaxOf(below[q], l >= est[q0 + q] ? 0.0 : 1.0);
    }
  }
  return LanesMax(below) == 0;
}

// pass[q] = 1 where move q may cut into `box` below `cap`: its reach below
// cap (FootprintGap::Misses over its box, z_r and r2) meets it and its
// lowest point is below cap; else 0. Each test only passes more moves for
// a larger box or a higher cap. Selects only: one vectorized loop, over
// row.padded() entries (those past size() to be ignored).
SWARF_TARGET_CLONES
void MovesThatMayCut(const RowMoves& row, const Rect& element, double cap,
                     double* __restrict pass) {
  const int32_t n = row.padded();
  // A copy: read through the reference, the loop did not vectorize.
  const Rect box = element;
  const double* __restrict x0 = row.x0.data();
  const double* __restrict x1 = row.x1.data();
  const double* __restrict y0 = row.y0.data();
  const double* __restrict y1 = row.y1.data();
  const double* __restrict z_r = row.z_r.data();
  const double* __restrict r2 = row.r2.data();
  const double* __restrict lowest = row.lowest.data();
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    const double misses = FootprintGap::Misses(1.0, x0[q], x1[q], y0[q], y1[q],
                                               z_r[q], r2[q], box, cap);
    pass[q] = misses == 0 && lowest[q] < cap ? 1.0 : 0.0;
  }
}

// The q < n with pass[q] != 0, in order, into at[0..count), returning the
// count. Without a branch: a row's moves pass at about one in six, and a
// mispredicted branch costs more than the store for a move that fails.
int32_t Passing(const double* __restrict pass, int32_t n,
                int32_t* __restrict at) {
  int32_t count = 0;
  for (int32_t q = 0; q < n; ++q) {
    at[count] = q;
    count += pass[q] != 0 ? 1 : 0;
  }
  return count;
}

// *to = the moves of `from` that may cut into `box` below `cap`
// (MovesThatMayCut), in order. Scratch: pass of from.padded() entries,
// passing of from.size().
void KeepMovesThatMayCut(const RowMoves& from, const Rect& box, double cap,
                         double* pass, int32_t* passing, RowMoves* to) {
  MovesThatMayCut(from, box, cap, pass);
  to->Clear();
  const int32_t count = Passing(pass, from.size(), passing);
  for (int32_t u = 0; u < count; ++u) from.CopyFrom(passing[u], to);
}

}  // namespace

absl::StatusOr<ErrorStats> MeasureError(const Workpiece& wp,
                                        const ValuationOptions& options) {
  const int n = options.samples_per_edge;
  if (n < 2 || n > 64) {
    return absl::InvalidArgumentError(
        absl::StrCat("samples_per_edge must be in [2, 64], got ", n));
  }
  const GridGeometry& grid = wp.grid();
  Rect region = grid.bounds();
  if (options.region.has_value()) {
    const Rect& r = *options.region;
    if (!std::isfinite(r.x0) || !std::isfinite(r.y0) ||
        !std::isfinite(r.x1) || !std::isfinite(r.y1)) {
      return absl::InvalidArgumentError("region must be finite");
    }
    if (r.x1 < r.x0 || r.y1 < r.y0) {
      return absl::InvalidArgumentError(
          "region must have x0 <= x1 and y0 <= y1");
    }
    region = r;
  }
  const bool mapped = options.map_cols != 0 || options.map_rows != 0;
  if (mapped && (options.map_cols < 1 || options.map_rows < 1 ||
                 int64_t{options.map_cols} * options.map_rows > kMaxMapCells)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "map size must be at least 1 x 1 and at most ", kMaxMapCells,
        " cells, got ", options.map_cols, " x ", options.map_rows));
  }
  std::vector<float> map(mapped ? size_t{1} * options.map_cols * options.map_rows
                                : 0, 0.0f);
  const double cell_x = (region.x1 - region.x0) / std::max(1, options.map_cols);
  const double cell_y = (region.y1 - region.y0) / std::max(1, options.map_rows);
  // The cell of offset f (in cells) among n, clamped before the conversion:
  // a region of zero width makes f 0/0 (NaN), and converting NaN or an
  // out-of-range double to int is undefined.
  auto cell_index = [](double f, int32_t n) {
    return f >= n - 1 ? n - 1 : f > 0 ? static_cast<int32_t>(f) : 0;
  };
  // Samples of different bins can share a cell: a lock-free max.
  auto map_max = [&](int64_t c, float e) {
    std::atomic_ref<float> cell(map[c]);
    float cur = cell.load(std::memory_order_relaxed);
    while (e > cur && !cell.compare_exchange_weak(cur, e)) {
    }
  };
  const MoveIndex& index = wp.index();
  const int32_t bins = index.bins_x() * index.bins_y();
  std::vector<Partial> partials(bins);

  ThreadPool& pool = options.pool != nullptr ? *options.pool : wp.pool();
  // The lattice's coordinates along one axis, per element (e * n + s, a
  // division each, once per grid line instead of once per element), and
  // their map cells (a row's premultiplied by map_cols).
  auto lattice_lines = [&](bool along_x, std::vector<double>* coord,
                           std::vector<int64_t>* cell) {
    const int32_t elements = along_x ? grid.nx() : grid.ny();
    const double origin = along_x ? region.x0 : region.y0;
    const double size = along_x ? cell_x : cell_y;
    const int32_t cells = along_x ? options.map_cols : options.map_rows;
    const int64_t stride = along_x ? 1 : options.map_cols;
    coord->resize(static_cast<size_t>(elements) * n);
    if (mapped) cell->resize(coord->size());
    for (int32_t e = 0; e < elements; ++e) {
      const double a = along_x ? grid.NodeX(e) : grid.NodeY(e);
      const double b = along_x ? grid.NodeX(e + 1) : grid.NodeY(e + 1);
      for (int32_t s = 0; s < n; ++s) {
        const size_t at = static_cast<size_t>(e) * n + s;
        (*coord)[at] = a + (b - a) * s / (n - 1);
        if (mapped) {
          (*cell)[at] =
              int64_t{cell_index(((*coord)[at] - origin) / size, cells)} *
              stride;
        }
      }
    }
  };
  std::vector<double> lattice_x, lattice_y;
  std::vector<int64_t> cell_of_x, cell_of_y;
  lattice_lines(/*along_x=*/true, &lattice_x, &cell_of_x);
  lattice_lines(/*along_x=*/false, &lattice_y, &cell_of_y);
  const double z_top = wp.spec().z_top;
  const Scheme& scheme = wp.scheme();
  // The bins are claimed in order, a row of bins at a time: the nodes'
  // jets in a cache of this traversal's own, of two rows of tiles (the
  // workpiece's, shared with other readers such as the cutting marks,
  // holds less than a row of a wide grid: each tile was computed up to
  // once per row of bins).
  // An element's lattice points in the region, row by row, the corners
  // left out: the order the sums are taken in. `all_in`: every point is in
  // (no test). point(si, sj) for each.
  auto for_each_point = [&region, n](const double* col_x, const double* row_y,
                                     bool all_in, auto&& point) {
    for (int32_t sj = 0; sj < n; ++sj) {
      const bool end_row = sj == 0 || sj == n - 1;
      const int32_t si1 = end_row ? n - 1 : n;
      for (int32_t si = end_row ? 1 : 0; si < si1; ++si) {
        if (!all_in && !region.Contains(col_x[si], row_y[sj])) continue;
        point(si, sj);
      }
    }
  };
  const std::unique_ptr<Workpiece::JetCache> jets = wp.TraversalJetCache();
  // In the all-in order of for_each_point: the bottom edge's points are
  // 0..n-3, row sj (1..n-2) starts at n - 2 + (sj - 1) * n with its left
  // edge's point, and the top edge's starts at `top`. An element's own
  // points (those it evaluates), by whether it shares its left edge (1)
  // and its bottom edge (2); 0: all of them, also the first `count` of a
  // clipped element's.
  const int32_t edge = n - 2;
  const int32_t top = edge + edge * n;
  std::vector<int32_t> own_lists[4];
  for (int32_t c = 0; c < 4; ++c) {
    for (int32_t q = 0; q < n * n - 4; ++q) {
      const bool left = q >= edge && q < top && (q - edge) % n == 0;
      if (((c & 1) && left) || ((c & 2) && q < edge)) continue;
      own_lists[c].push_back(q);
    }
  }
  // Each point's column and row in the lattice, in the all-in order, as
  // doubles (QuarterMaxima) and as indices (an all-in element's points are
  // gathered through them: the nested loop's tests cost more than the
  // copies).
  std::vector<double> point_si, point_sj;
  std::vector<int32_t> point_i, point_j;
  for_each_point(lattice_x.data(), lattice_y.data(), /*all_in=*/true,
                 [&](int32_t si, int32_t sj) {
                   point_si.push_back(si);
                   point_sj.push_back(sj);
                   point_i.push_back(si);
                   point_j.push_back(sj);
                 });
  pool.ParallelFor(bins, [&](int64_t b) {
    const int32_t bx = static_cast<int32_t>(b % index.bins_x());
    const int32_t by = static_cast<int32_t>(b / index.bins_x());
    const int32_t ei0 = bx * MoveIndex::kBinElements;
    const int32_t ej0 = by * MoveIndex::kBinElements;
    const int32_t ei1 = std::min(ei0 + MoveIndex::kBinElements, grid.nx());
    const int32_t ej1 = std::min(ej0 + MoveIndex::kBinElements, grid.ny());
    // Skip bins outside the region.
    if (grid.NodeX(ei0) > region.x1 || grid.NodeX(ei1) < region.x0 ||
        grid.NodeY(ej0) > region.y1 || grid.NodeY(ej1) < region.y0) {
      return;
    }
    std::vector<uint32_t> ids;
    index.BinIds(static_cast<int32_t>(b), &ids);
    // Untouched stock: no move reaches the bin and its nodes' tiles were
    // never cut (flat at z_top, owner -1). Every sample's reconstruction
    // and exact height are then z_top, its error exactly 0: only the
    // samples are counted (adding zeros changes no sum, maximum or map
    // cell), so the figures are the same, bit for bit, without sampling
    // the large uncut parts of a big stock.
    if (ids.empty()) {
      bool untouched = true;
      for (int32_t ty = ej0 / kTileSize; ty <= ej1 / kTileSize && untouched;
           ++ty) {
        for (int32_t tx = ei0 / kTileSize; tx <= ei1 / kTileSize; ++tx) {
          if (wp.TileAllocated(ty * wp.tiles_x() + tx)) {
            untouched = false;
            break;
          }
        }
      }
      if (untouched) {
        Partial p = partials[b];
        for (int32_t ej = ej0; ej < ej1; ++ej) {
          const double ey0 = grid.NodeY(ej), ey1 = grid.NodeY(ej + 1);
          if (ey0 > region.y1 || ey1 < region.y0) continue;
          const double* const row_y = &lattice_y[static_cast<size_t>(ej) * n];
          for (int32_t ei = ei0; ei < ei1; ++ei) {
            const double ex0 = grid.NodeX(ei), ex1 = grid.NodeX(ei + 1);
            if (ex0 > region.x1 || ex1 < region.x0) continue;
            const double* const col_x = &lattice_x[static_cast<size_t>(ei) * n];
            if (region.Contains(col_x[0], row_y[0]) &&
                region.Contains(col_x[n - 1], row_y[n - 1])) {
              p.n += n * n - 4;
              continue;
            }
            for_each_point(col_x, row_y, false,
                           [&p](int32_t, int32_t) { ++p.n; });
          }
        }
        partials[b] = p;
        return;
      }
    }
    // The bin's moves, in bin order, with the XY box where each can cut
    // below the top, its lowest point and FootprintGap parts: the tests
    // read these arrays alone, apart from the sweeps (over 300 bytes each),
    // so that the scan stays in cache. `near`: those that may cut into a
    // row.
    const int32_t bin_size = static_cast<int32_t>(ids.size());
    // This thread's, reused (a bin's moves are about 1,250 on the plate
    // job; larger arrays are given back once the bin is done).
    thread_local RowMoves bin_moves, band, near, block;
    bin_moves.Reset(bin_size);
    band.Reset(bin_size);
    near.Reset(bin_size);
    block.Reset(bin_size);
    for (int32_t k = 0; k < bin_size; ++k) {
      const Move m = wp.move(static_cast<int32_t>(ids[k]));
      const FootprintGap gap = FootprintGap::Of(m.from, m.to, m.cutter);
      // A ball's footprint below a cap lies within its reach there (at most
      // its radius) of the tips' box (FootprintGap): the tips' box widened
      // by the radius, once tested beside the reach, ruled out no move the
      // reach passes. Another shape: its footprint's box below the top,
      // with a reach of 0 (z_r -inf: ReachSquared gives r2, 0).
      const bool ball = gap.ball != 0;
      bin_moves.Add(
          ball ? Rect{gap.x0, gap.y0, gap.x1, gap.y1}
               : FootprintCapsuleEnds(m.from, m.to, m.cutter, z_top).Bounds(),
          ball ? gap.z_r : -std::numeric_limits<double>::infinity(),
          ball ? gap.r2 : 0.0, SweepLowest(m.from, m.to, m.cutter), k);
    }
    // A bin move's sweep, built when an element first needs its heights
    // (on the plate job about 1 in 8 of the bin's moves is).
    std::vector<Sweep> sweeps;
    sweeps.reserve(ids.size());  // no reallocation: references stay valid
    std::vector<int32_t> sweep_of(ids.size(), -1);
    auto bin_sweep = [&](int32_t k) -> const Sweep& {
      if (sweep_of[k] < 0) {
        sweep_of[k] = static_cast<int32_t>(sweeps.size());
        sweeps.emplace_back(wp.MoveSweep(ids[k]));
      }
      return sweeps[sweep_of[k]];
    };
    // The bin's nodes, each read once instead of once per element it is a
    // corner of, and the guarded scheme's trust regions (TrustRegion, a
    // function of each node's jet) and reaches (its owner's) likewise.
    const bool guarded = scheme.kind() == SchemeKind::kGuarded;
    const int32_t region_w = ei1 - ei0 + 1;
    const size_t region_nodes = static_cast<size_t>(region_w) * (ej1 - ej0 + 1);
    // This thread's scratch arrays, like the rest below, reused from bin to
    // bin (Grow): each entry is written before it is read, and zeroing them
    // for each bin cost more than the elements' own steps.
    thread_local std::vector<NodeValue> nodes;
    thread_local std::vector<PatchTrustRegion> regions;
    thread_local std::vector<CornerReach> reaches;
    // Whether a node's region surely holds any element of the bin
    // (SurelyTrusted at the bin's widest and tallest element), once a node.
    thread_local std::vector<char> sure_trust;
    Grow(&nodes, region_nodes);
    double widest = 0, tallest = 0;
    if (guarded) {
      Grow(&regions, region_nodes);
      Grow(&reaches, region_nodes);
      Grow(&sure_trust, region_nodes);
      for (int32_t i = ei0; i < ei1; ++i) {
        widest = std::max(widest, grid.NodeX(i + 1) - grid.NodeX(i));
      }
      for (int32_t j = ej0; j < ej1; ++j) {
        tallest = std::max(tallest, grid.NodeY(j + 1) - grid.NodeY(j));
      }
    }
    // A tile's columns at a time: a bin's last column may be the next
    // tile's first, and a row's reads alternating between the two would
    // each look the tile up in the cache.
    for (int32_t c0 = ei0; c0 <= ei1;) {
      const int32_t c1 = std::min(ei1, (c0 / kTileSize + 1) * kTileSize - 1);
      for (int32_t j = ej0; j <= ej1; ++j) {
        // The row's last node with an owner: a trust region depends on the
        // jet's slopes and curvatures alone (not w), a reach on the owner
        // alone, and along a straight pass neighbouring nodes of one move
        // mostly have the same ones, bit for bit (a raster along x: every
        // node of a cylinder's row). Those are copied, not computed again.
        size_t last = SIZE_MAX;
        for (int32_t i = c0; i <= c1; ++i) {
          const size_t at =
              static_cast<size_t>(j - ej0) * region_w + (i - ei0);
          nodes[at] = wp.Node(i, j, jets.get());
          if (guarded && nodes[at].owner >= 0) {
            const NodeValue& node = nodes[at];
            if (last != SIZE_MAX && SameShape(nodes[last].jet, node.jet)) {
              regions[at] = regions[last];
              sure_trust[at] = sure_trust[last];
            } else {
              regions[at] = TrustRegion(node.jet);
              sure_trust[at] = SurelyTrusted(regions[at], widest, tallest);
            }
            reaches[at] = last != SIZE_MAX && nodes[last].owner == node.owner
                              ? reaches[last]
                              : wp.sweeps().Reach(node.owner, z_top);
            last = at;
          }
        }
      }
      c0 = c1 + 1;
    }
    // The sweeps of recent corner owners: neighbouring elements share most.
    // An owner is mostly one of the bin's moves (it reached the bin's
    // nodes), whose sweep the bin builds once; else the slot holds it.
    struct Owner {
      int32_t id = -1;
      const Sweep* sweep = nullptr;
      std::optional<Sweep> own;
    };
    constexpr int kOwnerCache = 8;
    Owner cache[kOwnerCache];
    int next_slot = 0;
    auto owner_sweep = [&](int32_t id) -> const Sweep& {
      for (Owner& o : cache) {
        if (o.id == id) return *o.sweep;
      }
      Owner& o = cache[next_slot];
      next_slot = (next_slot + 1) % kOwnerCache;
      o.id = id;
      // The bin's ids ascend (moves are indexed in order); were they not,
      // the search could only miss, and the slot would build the sweep.
      const auto it =
          std::lower_bound(ids.begin(), ids.end(), static_cast<uint32_t>(id));
      if (it != ids.end() && *it == static_cast<uint32_t>(id)) {
        o.sweep = &bin_sweep(static_cast<int32_t>(it - ids.begin()));
      } else {
        o.own.emplace(wp.MoveSweep(id));
        o.sweep = &*o.own;
      }
      return *o.sweep;
    };
    // The points of an element's lattice: n x n but the corners.
    const size_t lattice = static_cast<size_t>(n) * n - 4;
    // A row of the bin's elements is taken in two passes: each element's
    // points and the upper bound of the exact surface its corners' owners
    // give (its cap), then the moves that may cut below the highest cap
    // anywhere in the row (from its band's, below), once, and each
    // element's own test among those alone. A move that may cut into an
    // element below its cap may cut into the row below the row's cap (the
    // tests only widen with the box and the cap): the same moves lower each
    // element as when every element tested the whole bin (on the plate
    // job, about 400 moves an element, of which 5 passed).
    // An element's points on its left edge are its left neighbour's on its
    // right edge, and those on its bottom edge the lower neighbour's on its
    // top edge (n - 2 on each edge, of n * n - 4): where the coordinates
    // are the same bits, the exact surface there is the same value (the
    // smallest height of the bin's moves; each element's tests pass every
    // move below its cap), taken from the neighbour instead of evaluated
    // again. The rest, its own points, are packed for the heights.
    struct RowElement {
      ElementCorners e;
      Rect box;
      double cap = 0;
      int32_t ei = 0, count = 0, own = 0, own_padded = 0;
      const int32_t* own_list = nullptr;  // own_lists[...]
      // Its points' coordinates (count) and its own points' (own_padded):
      // the bin's lines' for an all-in element, else the band's arrays.
      const double *xs = nullptr, *ys = nullptr, *oxs = nullptr, *oys = nullptr;
      bool quarters = false, all_in = false, from_left = false,
           from_below = false;
    };
    // The own points are padded to a multiple of 8 (copies of the last,
    // their heights then the last's): the vector loops over them have no
    // scalar remainder, which cost as much as the rest of a call.
    const size_t padded = (lattice + 7) & ~size_t{7};
    thread_local std::vector<RowElement> elements;
    Grow(&elements, kBandRows * MoveIndex::kBinElements);
    // Every per-element array of a band's rows has `padded` entries an
    // element.
    const size_t row_size = kBandRows * MoveIndex::kBinElements * padded;
    thread_local std::vector<double> row_xs, row_ys, row_est, row_oest;
    for (std::vector<double>* v : {&row_xs, &row_ys, &row_est, &row_oest}) {
      Grow(v, row_size);
    }
    // An all-in element's x coordinates depend on its column alone, and its
    // y coordinates on its row alone: they are laid out once a bin for each
    // column and row (its points in for_each_point's order, then its own
    // points for each own_lists[c], padded with copies of the last), not
    // gathered for every element (on the 30 mm plate, a sixth of the
    // traversal's own instructions).
    const size_t line_size = (1 + std::size(own_lists)) * padded;
    thread_local std::vector<double> line_xs, line_ys;
    Grow(&line_xs, MoveIndex::kBinElements * line_size);
    Grow(&line_ys, MoveIndex::kBinElements * line_size);
    auto lay_out_lines = [&](const std::vector<double>& lattice_line,
                             int32_t e0, int32_t e1,
                             const std::vector<int32_t>& point_index,
                             double* out) {
      for (int32_t e = e0; e < e1; ++e) {
        const double* const line = &lattice_line[static_cast<size_t>(e) * n];
        double* const points = out + static_cast<size_t>(e - e0) * line_size;
        for (size_t q = 0; q < lattice; ++q) points[q] = line[point_index[q]];
        // Padded with copies of the last (Scheme::ReconstructManyPadded;
        // 2 samples an edge give no points).
        if (lattice > 0) {
          std::fill(points + lattice, points + padded, points[lattice - 1]);
        }
        for (size_t c = 0; c < std::size(own_lists); ++c) {
          const std::vector<int32_t>& list = own_lists[c];
          double* const own = points + (1 + c) * padded;
          const size_t count = list.size();
          for (size_t q = 0; q < count; ++q) own[q] = points[list[q]];
          if (count > 0) {
            std::fill(own + count, own + ((count + 7) & ~size_t{7}),
                      own[count - 1]);
          }
        }
      }
    };
    lay_out_lines(lattice_x, ei0, ei1, point_i, line_xs.data());
    lay_out_lines(lattice_y, ej0, ej1, point_j, line_ys.data());
    // Each column's SecondCell, once a bin (taken an element, it was a
    // sixth of the map's instructions); each row's is its BandRow's.
    thread_local std::vector<int32_t> second_x;
    if (mapped) {
      Grow(&second_x, ei1 - ei0);
      for (int32_t ei = ei0; ei < ei1; ++ei) {
        second_x[ei - ei0] =
            SecondCell(&cell_of_x[static_cast<size_t>(ei) * n], n);
      }
    }
    // The top edges' exact heights of the last row evaluated, per element
    // of the bin's row; top_ok where the elements of the last row set up
    // (row `top_row`, evaluated before the next row) were all in.
    thread_local std::vector<double> top_est;
    thread_local std::vector<char> top_ok;
    Grow(&top_est, static_cast<size_t>(ei1 - ei0) * edge);
    Grow(&top_ok, ei1 - ei0);
    // None yet (on the grid's first row ej - 1 is top_row's -1: a previous
    // bin's flags must not pass there).
    std::fill_n(top_ok.begin(), ei1 - ei0, 0);
    int32_t top_row = -1;
    thread_local std::vector<int64_t> row_cells;
    if (mapped) Grow(&row_cells, row_size);
    thread_local std::vector<double> h, rec, err, offset_x, offset_y;
    for (std::vector<double>* v : {&h, &rec, &err, &offset_x, &offset_y}) {
      Grow(v, padded);
    }
    // est[q] = min(est[q], the sweep's height at (x[q], y[q])), q < n.
    double* const heights = h.data();
    auto lower_by = [heights](const Sweep& sweep, const double* x,
                              const double* y, int32_t n, double* est) {
      sweep.Heights(x, y, n, heights);
      LowerTo(heights, n, est);
    };
    thread_local std::vector<double> pass;
    Grow(&pass, bin_moves.padded());
    // The indices of those that pass (Passing).
    thread_local std::vector<int32_t> passing;
    Grow(&passing, bin_moves.size());
    // The tangent plane last taken for each of the bin's moves (by index in
    // the bin), and the point it touches. A plane is below the whole sweep
    // (SupportingPlane's contract), so it serves the next elements too, moved
    // to their centres, until it fails to show the move above one: about a
    // third of the planes are taken on the plate job. Held from row to row
    // (a row's first elements then start from the last row's planes, not
    // from new ones: the bins 0.3% fewer instructions on the 30 mm plate);
    // none is held from another bin's moves.
    struct HeldPlane {
      double x = 0, y = 0;
      BallSweep::SupportPlane plane{};
      bool held = false;
    };
    thread_local std::vector<HeldPlane> held;
    Grow(&held, bin_moves.size());
    for (int32_t k = 0; k < bin_size; ++k) held[k].held = false;
    // The bin's sums in locals (registers), stored once at the end.
    Partial p = partials[b];
    // The rows are taken in bands of kBandRows: each row's elements are
    // set up (points, corners, caps), then the bin's moves that may cut
    // into the band below its highest cap are taken once, then each row
    // takes its near moves from those and its elements are evaluated, in
    // row order. A move that may cut into a row below the row's cap may cut
    // into the band below the band's (the tests only widen with the box
    // and the cap): the same near moves, in the same order, as when each
    // row tested the whole bin (about 1,250 moves on the plate job, of
    // which about 220 are near a row).
    struct BandRow {
      double ey0 = 0, ey1 = 0, cap = 0;
      const int64_t* cell = nullptr;
      int32_t elements = 0;
      Rect box;
      int32_t second_cell = 1;  // SecondCell of the row's cells (mapped)
    };
    BandRow band_row[kBandRows];
    for (int32_t band_j0 = ej0; band_j0 < ej1; band_j0 += kBandRows) {
      const int32_t band_j1 = std::min(band_j0 + kBandRows, ej1);
      int32_t band_rows = 0;
      for (int32_t ej = band_j0; ej < band_j1; ++ej) {
        const double ey0 = grid.NodeY(ej), ey1 = grid.NodeY(ej + 1);
        if (ey0 > region.y1 || ey1 < region.y0) continue;
        const double* const row_y = &lattice_y[static_cast<size_t>(ej) * n];
        const int64_t* const row_cell =
            mapped ? &cell_of_y[static_cast<size_t>(ej) * n] : nullptr;
        // This row's elements and their arrays follow the band's earlier
        // rows'.
        const size_t base =
            static_cast<size_t>(band_rows) * MoveIndex::kBinElements;
        int32_t row_elements = 0;
        double row_cap = -std::numeric_limits<double>::infinity();
        for (int32_t ei = ei0; ei < ei1; ++ei) {
          const double ex0 = grid.NodeX(ei), ex1 = grid.NodeX(ei + 1);
          if (ex0 > region.x1 || ex1 < region.x0) continue;
          const size_t at =
              static_cast<size_t>(ej - ej0) * region_w + (ei - ei0);
          const NodeValue* const corner[4] = {&nodes[at], &nodes[at + 1],
                                              &nodes[at + region_w + 1],
                                              &nodes[at + region_w]};
          const double* const col_x = &lattice_x[static_cast<size_t>(ei) * n];
          const int64_t* const col_cell =
              mapped ? &cell_of_x[static_cast<size_t>(ei) * n] : nullptr;
          // The coordinates grow with si and sj, so the first and last
          // lattice points bound them all.
          const bool all_in = region.Contains(col_x[0], row_y[0]) &&
                              region.Contains(col_x[n - 1], row_y[n - 1]);
          const size_t off = (base + row_elements) * padded;
          // With every point in and at most two map cells across and two
          // down (cells at least as large as elements, as swarf run asks),
          // the max of each of the four quarters they make; else a cell per
          // point.
          const bool quarters =
              mapped && all_in && col_cell[n - 1] - col_cell[0] <= 1 &&
              row_cell[n - 1] - row_cell[0] <= options.map_cols;
          const bool per_point = mapped && !quarters;
          int32_t count = 0;
          // The column's and the row's laid-out lines (lay_out_lines).
          const double* const col_line =
              line_xs.data() + static_cast<size_t>(ei - ei0) * line_size;
          const double* const row_line =
              line_ys.data() + static_cast<size_t>(ej - ej0) * line_size;
          if (all_in) {
            // for_each_point's order, every point in.
            count = static_cast<int32_t>(lattice);
            if (per_point) {
              const int32_t* const pi = point_i.data();
              const int32_t* const pj = point_j.data();
              int64_t* const cells = row_cells.data() + off;
              for (int32_t q = 0; q < count; ++q) {
                cells[q] = row_cell[pj[q]] + col_cell[pi[q]];
              }
            }
          } else {
            double* const xs = row_xs.data() + off;
            double* const ys = row_ys.data() + off;
            for_each_point(col_x, row_y, false, [&](int32_t si, int32_t sj) {
              xs[count] = col_x[si];
              ys[count] = row_y[sj];
              if (per_point) {
                row_cells[off + count] = row_cell[sj] + col_cell[si];
              }
              ++count;
            });
          }
          if (count == 0) continue;
          RowElement& el = elements[base + row_elements++];
          el.all_in = all_in;
          el.from_left = all_in && row_elements > 1 &&
                         elements[base + row_elements - 2].all_in &&
                         elements[base + row_elements - 2].ei == ei - 1 &&
                         col_x[0] == lattice_x[static_cast<size_t>(ei) * n - 1];
          el.from_below =
              all_in && top_row == ej - 1 && top_ok[ei - ei0] &&
              row_y[0] == lattice_y[static_cast<size_t>(ej) * n - 1];
          const int32_t variant =
              (el.from_left ? 1 : 0) | (el.from_below ? 2 : 0);
          const std::vector<int32_t>& list = own_lists[variant];
          el.own_list = list.data();
          const int32_t own =
              all_in ? static_cast<int32_t>(list.size()) : count;
          el.own = own;
          // own >= 1: the right edge and the inside are never shared.
          el.own_padded = (own + 7) & ~7;
          if (all_in) {
            el.xs = col_line;
            el.ys = row_line;
            el.oxs = col_line + (1 + variant) * padded;
            el.oys = row_line + (1 + variant) * padded;
          } else {
            // Every point is its own (own_lists[0] lists them in order):
            // the points, padded, serve as the own points.
            double* const xs = row_xs.data() + off;
            double* const ys = row_ys.data() + off;
            std::fill(xs + own, xs + el.own_padded, xs[own - 1]);
            std::fill(ys + own, ys + el.own_padded, ys[own - 1]);
            el.xs = el.oxs = xs;
            el.ys = el.oys = ys;
          }
          const double* const oxs = el.oxs;
          const double* const oys = el.oys;
          if (guarded) {
            const CornerReach* r = &reaches[at];
            const CornerReach* const reach[4] = {r, r + 1, r + region_w + 1,
                                                 r + region_w};
            wp.FillCorners(ei, ej, corner, reach, &el.e);
            const PatchTrustRegion* t = &regions[at];
            const PatchTrustRegion* const trust[4] = {
                t, t + 1, t + region_w + 1, t + region_w};
            const bool sure[4] = {sure_trust[at] != 0, sure_trust[at + 1] != 0,
                                  sure_trust[at + region_w + 1] != 0,
                                  sure_trust[at + region_w] != 0};
            ClassifyGuarded(&el.e, trust, sure);
            // Not smooth: there the guarded reconstruction is the exact
            // surface (the minimum over the element's candidates, every
            // move that can be the lowest in it, by the same heights as
            // the exact surface below), so every sample's error is exactly
            // 0: counted, not sampled, as in untouched stock (no sum,
            // maximum or map cell changes for a 0). Its neighbours take
            // none of its points (it is not among the row's elements).
            if (GuardedIsExact(el.e)) {
              p.n += count;
              --row_elements;
              continue;
            }
          } else {
            el.e = wp.CornersOf(ei, ej, corner);
          }
          el.ei = ei;
          el.count = count;
          el.quarters = quarters;
          // An upper bound of the exact surface at each sample: the sweeps
          // that own the corners (exact heights of real moves). Only moves
          // that dip below the element's highest bound inside the element
          // can lower a sample further; the rest of the bin is skipped.
          // Heights() is bit-identical to Height(), several samples at once.
          // Own points only: the cap bounds the surface where this element
          // evaluates it.
          // The first owner's heights go straight into est, then held to
          // the top: the same values as lowering a top-filled est.
          double* const oest = row_oest.data() + off;
          const int32_t* owners = el.e.owner;
          bool first = true;
          for (int k = 0; k < 4; ++k) {
            bool seen = owners[k] < 0;
            for (int q = 0; q < k && !seen; ++q) seen = owners[q] == owners[k];
            if (seen) continue;
            const Sweep& sweep = owner_sweep(owners[k]);
            if (first) {
              sweep.Heights(oxs, oys, el.own_padded, oest);
              HoldTo(z_top, el.own_padded, oest);
              first = false;
            } else {
              lower_by(sweep, oxs, oys, el.own_padded, oest);
            }
          }
          if (first) std::fill_n(oest, el.own_padded, z_top);
          // The padding's est is the last own point's.
          el.cap = Highest(oest, el.own_padded);
          el.box = Rect{el.e.x0, el.e.y0, el.e.x1, el.e.y1};
          row_cap = std::max(row_cap, el.cap);
        }
        if (row_elements == 0) continue;
        // The elements' boxes share the row's y0 and y1.
        band_row[band_rows++] = {
            ey0,
            ey1,
            row_cap,
            row_cell,
            row_elements,
            Rect{elements[base].box.x0, ey0,
                 elements[base + row_elements - 1].box.x1, ey1},
            mapped ? SecondCell(row_cell, n) : 1};
        // The next row's elements take their bottom edges' points from
        // this row's that are all in.
        std::fill_n(top_ok.begin(), ei1 - ei0, 0);
        for (int32_t w = 0; w < row_elements; ++w) {
          if (elements[base + w].all_in)
            top_ok[elements[base + w].ei - ei0] = 1;
        }
        top_row = ej;
      }
      if (band_rows == 0) continue;
      double band_cap = band_row[0].cap;
      Rect band_box = band_row[0].box;
      for (int32_t r = 1; r < band_rows; ++r) {
        band_cap = std::max(band_cap, band_row[r].cap);
        band_box.x0 = std::min(band_box.x0, band_row[r].box.x0);
        band_box.x1 = std::max(band_box.x1, band_row[r].box.x1);
        band_box.y1 = band_row[r].box.y1;
      }
      KeepMovesThatMayCut(bin_moves, band_box, band_cap, pass.data(),
                          passing.data(), &band);
      for (int32_t r = 0; r < band_rows; ++r) {
        const BandRow& row = band_row[r];
        const double ey0 = row.ey0, ey1 = row.ey1;
        const int64_t* const row_cell = row.cell;
        const int32_t row_elements = row.elements;
        const size_t base = static_cast<size_t>(r) * MoveIndex::kBinElements;
        KeepMovesThatMayCut(band, row.box, row.cap, pass.data(), passing.data(),
                            &near);
        // The cell of the row's last one-cell elements and their max (-1:
        // none), put in the map when the cell changes and at the row's end.
        int64_t one_cell = -1;
        float one_cell_max = 0;
        for (int32_t w = 0; w < row_elements; ++w) {
          // A block of the row's elements takes the near moves that may cut
          // into it below its highest cap, and each element tests those alone
          // (the tests only widen with the box and the cap, so the same moves
          // pass an element's own test; a row's near moves are about 220 on
          // the plate job).
          if (w % kBlockElements == 0) {
            const int32_t w1 = std::min(w + kBlockElements, row_elements);
            double block_cap = elements[base + w].cap;
            for (int32_t v = w + 1; v < w1; ++v) {
              block_cap = std::max(block_cap, elements[base + v].cap);
            }
            const Rect block_box{elements[base + w].box.x0, ey0,
                                 elements[base + w1 - 1].box.x1, ey1};
            KeepMovesThatMayCut(near, block_box, block_cap, pass.data(),
                                passing.data(), &block);
          }
          RowElement& el = elements[base + w];
          const ElementCorners& e = el.e;
          const int32_t count = el.count;
          const size_t off = (base + w) * padded;
          const double* const xs = el.xs;
          const double* const ys = el.ys;
          const double* const oxs = el.oxs;
          const double* const oys = el.oys;
          double* const oest = row_oest.data() + off;
          const int32_t own = el.own;
          double* const est = row_est.data() + off;
          const int32_t* owners = e.owner;
          const double cap = el.cap;
          const Rect& box = el.box;
          const double xc = 0.5 * (box.x0 + box.x1),
                       yc = 0.5 * (box.y0 + box.y1);
          // The own points' offsets from the centre, for the tangent planes
          // there (taken once, not for every plane).
          double* const odx = offset_x.data();
          double* const ody = offset_y.data();
          double range[4];
          OffsetsFrom(oxs, oys, el.own_padded, xc, yc, odx, ody, range);
          const double dx_lo = range[0], dx_hi = range[1], dy_lo = range[2],
                       dy_hi = range[3];
          // Whether a plane through (xc, yc) is at or above every own point's
          // est. First at the corners of the offsets' box, where it is lowest
          // (products and sums round monotonically; any other rounding is far
          // inside the slack), against the cap, which no est exceeds (they
          // only go down): about half the planes on the plate job are shown
          // above there, without the points.
          auto plane_above = [&](const BallSweep::SupportPlane& plane) {
            const double lowest = plane.w - plane.slack +
                                  std::min(plane.wx * dx_lo, plane.wx * dx_hi) +
                                  std::min(plane.wy * dy_lo, plane.wy * dy_hi);
            return lowest >= cap ||
                   PlaneAtOrAbove(plane, odx, ody, el.own_padded, oest);
          };
          MovesThatMayCut(block, box, cap, pass.data());
          const int32_t element_count =
              Passing(pass.data(), block.size(), passing.data());
          for (int32_t u = 0; u < element_count; ++u) {
            const int32_t ck = block.k[passing[u]];
            // A corner's owner is in est already.
            const int32_t id = static_cast<int32_t>(ids[ck]);
            if (id == owners[0] || id == owners[1] || id == owners[2] ||
                id == owners[3]) {
              continue;
            }
            // Not tested against its footprint below cap (FootprintBounds):
            // that ruled out 0.2% (the 100 mm plate) to 5% (cameo) of the
            // moves that pass here, for more than their heights cost. A move
            // it rules out is nowhere in the box below cap, so not below est
            // at any sample: its heights change none.
            // A ball's tangent plane at the element's centre is below its
            // surface: where that plane is above est at every own point, so
            // are its heights (about 9 of 10 moves that pass here on the
            // plate job, 8 of 10 on cameo; a point and a plane take a third
            // of the heights' instructions, but two roots and two divisions
            // in a row: fewer of their cycles).
            // A held plane is a ball's: tested before the sweep is looked
            // up (most moves end here, and the sweep's lookup is a chain of
            // loads).
            HeldPlane& hp = held[ck];
            if (hp.held) {
              // Its height at this element's centre (rounding far inside
              // the slack).
              BallSweep::SupportPlane moved = hp.plane;
              moved.w += moved.wx * (xc - hp.x) + moved.wy * (yc - hp.y);
              if (plane_above(moved)) continue;
            }
            const Sweep& sweep = bin_sweep(ck);
            if (const BallSweep* ball = sweep.ball()) {
              const std::optional<BallSweep::SupportPlane> plane =
                  ball->SupportingPlane(xc, yc);
              if (plane.has_value()) {
                hp = {xc, yc, *plane, true};
                if (plane_above(*plane)) continue;
              }
            }
            lower_by(sweep, oxs, oys, el.own_padded, oest);
          }
          for (int32_t q = 0; q < own; ++q) est[el.own_list[q]] = oest[q];
          if (el.from_left) {
            const double* const left = est - padded;  // element w - 1
            for (int32_t sj = 1; sj <= edge; ++sj) {
              const int32_t q = edge + (sj - 1) * n;
              est[q] = left[q + n - 1];
            }
          }
          double* const top_of =
              &top_est[static_cast<size_t>(el.ei - ei0) * edge];
          if (el.from_below) std::copy_n(top_of, edge, est);
          if (el.all_in) std::copy_n(est + top, edge, top_of);
          // xs and ys are padded: an all-in element's lines
          // (lay_out_lines), another's own points.
          scheme.ReconstructManyPadded(e, xs, ys, count, rec.data());
          const double element_max =
              ErrorsOf(rec.data(), est, count, err.data());
          const int64_t* const col_cell =
              mapped ? &cell_of_x[static_cast<size_t>(el.ei) * n] : nullptr;
          // The first column and row in the second cell (n: none).
          int32_t sx = 1, sy = 1;
          if (el.quarters) {
            sx = second_x[el.ei - ei0];
            sy = row.second_cell;
          }
          if (el.quarters && sx == n && sy == n) {
            // One cell (the usual case: cells larger than elements), mostly
            // the last element's too: the row's run of one cell goes in once
            // (the same max in any order), not an atomic an element.
            const int64_t c = row_cell[0] + col_cell[0];
            const float m = static_cast<float>(element_max);
            if (c != one_cell) {
              if (one_cell >= 0) map_max(one_cell, one_cell_max);
              one_cell = c;
              one_cell_max = m;
            } else if (m > one_cell_max) {
              one_cell_max = m;
            }
          } else if (el.quarters) {
            double q_max[4];
            QuarterMaxima(err.data(), point_si.data(), point_sj.data(), count,
                          sx, sy, q_max);
            // The float of the largest error is the largest of the floats
            // (the conversion keeps the order).
            const float m[4] = {
                static_cast<float>(q_max[0]), static_cast<float>(q_max[1]),
                static_cast<float>(q_max[2]), static_cast<float>(q_max[3])};
            map_max(row_cell[0] + col_cell[0], m[0]);
            if (sx < n) map_max(row_cell[0] + col_cell[sx], m[1]);
            if (sy < n) map_max(row_cell[sy] + col_cell[0], m[2]);
            if (sx < n && sy < n) map_max(row_cell[sy] + col_cell[sx], m[3]);
          } else if (mapped) {
            // An element's samples mostly share a map cell: their max goes
            // in once per run of one cell (the same max: cells start at 0
            // and take only larger values).
            const int64_t* const cells = row_cells.data() + off;
            int64_t run_cell = -1;
            float run_max = 0;
            for (int32_t q = 0; q < count; ++q) {
              const int64_t c = cells[q];
              if (c != run_cell) {
                if (run_cell >= 0) map_max(run_cell, run_max);
                run_cell = c;
                run_max = 0;
              }
              const float ef = static_cast<float>(err[q]);
              if (ef > run_max) run_max = ef;
            }
            if (run_cell >= 0) map_max(run_cell, run_max);
          }
          Accumulate(err.data(), count, &p.sum, &p.sum_sq);
          p.n += count;
          // The bin's largest error so far and its first point: taking
          // each error above the largest in sample order ends at the first
          // point of the element's largest (ErrorsOf's, which passes NaNs
          // over as that comparison does) where that is above it; else
          // nothing changes. Mostly it is not above.
          if (element_max > p.max) {
            const int32_t max_q = FirstOf(err.data(), count, element_max);
            if (max_q >= 0) {
              p.max = element_max;
              p.max_x = xs[max_q];
              p.max_y = ys[max_q];
            }
          }
        }
        if (one_cell >= 0) map_max(one_cell, one_cell_max);
      }
    }
    partials[b] = p;
    constexpr int32_t kKeptMoves = 1 << 16;
    bin_moves.Trim(kKeptMoves);
    band.Trim(kKeptMoves);
    near.Trim(kKeptMoves);
    block.Trim(kKeptMoves);
    if (bin_size > kKeptMoves) {
      pass = std::vector<double>();
      passing = std::vector<int32_t>();
      held = std::vector<HeldPlane>();
    }
  });

  ErrorStats stats;
  double sum = 0, sum_sq = 0;
  for (const Partial& p : partials) {
    sum += p.sum;
    sum_sq += p.sum_sq;
    stats.samples += p.n;
    if (p.n > 0 && p.max > stats.max_error) {
      stats.max_error = p.max;
      stats.max_x = p.max_x;
      stats.max_y = p.max_y;
    }
  }
  if (mapped) {
    stats.map_cols = options.map_cols;
    stats.map_rows = options.map_rows;
    stats.map = std::move(map);
  }
  if (stats.samples > 0) {
    stats.mean_error = sum / stats.samples;
    stats.rms_error = std::sqrt(sum_sq / stats.samples);
  }
  return stats;
}

}  // namespace swarf
