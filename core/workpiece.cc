#include "core/workpiece.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "core/flag_words.h"
#include "core/status_macros.h"
#include "core/target_clones.h"
#include "core/value_minmax.h"

namespace swarf {

// Nodal parameters of one tile, structure-of-arrays, row-major (j, i), in
// one arena block: height and owner, for every scheme (12 bytes a node).
// Both are initialised to the stock top.
struct Workpiece::Tile {
  explicit Tile(TileArena* arena)
      : arena(arena),
        w(static_cast<double*>(arena->Allocate())),
        owner(reinterpret_cast<int32_t*>(w + kTileNodes)) {}
  ~Tile() { arena->Free(w); }
  Tile(const Tile&) = delete;
  Tile& operator=(const Tile&) = delete;

  TileArena* arena;
  double* w;
  int32_t* owner;
  double zmax = 0;   // upper bound on w over the tile's grid nodes
};

// The derivatives of a tile's cut nodes at one tile version, computed from
// their owners' sweeps (eq. 8-9, 14 and the other shapes' jets), rounded to
// float as the paper's nodal parameters are kept; zeros for uncut nodes.
struct Workpiece::TileJets {
  uint64_t serial = 0;   // the workpiece state they were computed from
  uint64_t version = 0;  // the tile's version then
  // Per row, the first and last cut column (lo > hi: none). d holds the
  // nodes of [lo, hi] only; the rest are uncut, their jets zeros.
  int8_t lo[kTileSize], hi[kTileSize];
  float d[5][kTileNodes];  // wx, wy, wxx, wxy, wyy
};

namespace {

// The highest of w[0..8) (heights, never NaN): two vectors of 4 and their
// lanes, not a reduction loop, which the vectorizer takes for doubles only
// with finite math.
[[gnu::always_inline]] inline double BlockTop(const double* __restrict w) {
  double m[4];
#pragma omp simd
  for (int32_t q = 0; q < 4; ++q) m[q] = std::max(w[q], w[q + 4]);
  return MaxOf(MaxOf(m[0], m[1]), MaxOf(m[2], m[3]));
}

// The highest of w[0..n) (heights, never NaN), or a value at or above cap
// as soon as a block of 8 reaches it: callers need the exact top only
// below cap. Without NaNs, maxima in any order are the same.
SWARF_TARGET_CLONES
double SpanTop(const double* __restrict w, int32_t n, double cap) {
  double top = -kInf;
  int32_t i = 0;
  for (; i + 8 <= n; i += 8) {
    top = MaxOf(top, BlockTop(w + i));
    if (!(top < cap)) return top;
  }
  if (i == n) return top;
  if (n < 8) {
    for (; i < n; ++i) top = MaxOf(top, w[i]);
    return top;
  }
  // The rest as the block of 8 that ends at n: its first nodes were taken
  // already, and a maximum does not change for a value taken twice (one by
  // one, the rest cost a sixth of the function's instructions on the 30 mm
  // plate).
  return MaxOf(top, BlockTop(w + n - 8));
}

// A row's nodes i_lo .. i_lo + count - 1 into a chunk: their coordinates
// (x as GridGeometry::NodeX: the same bits), tile index k0 + i and height.
SWARF_TARGET_CLONES
void GatherRow(double x0, double dx, int32_t i_lo, int32_t count, double y,
               int32_t k0, const double* __restrict w, double* __restrict px,
               double* __restrict py, int32_t* __restrict pk,
               double* __restrict pw) {
#pragma omp simd
  for (int32_t q = 0; q < count; ++q) {
    px[q] = x0 + (i_lo + q) * dx;
    py[q] = y;
    pk[q] = k0 + i_lo + q;
    pw[q] = w[k0 + i_lo + q];
  }
}

// flag[q] = 1 where h[q] <= old[q], else 0 (q < n): the nodes a move may
// lower (below, or level with a later owner). Vectorized; the caller
// decides each flagged node exactly.
SWARF_TARGET_CLONES
void MayLower(const double* __restrict h, const double* __restrict old,
              int32_t n, uint8_t* __restrict flag) {
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) flag[q] = h[q] <= old[q] ? 1 : 0;
}

// Distinct for every workpiece state that jets may be cached for.
uint64_t NextSerial() {
  static std::atomic<uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

Workpiece::Workpiece(const StockSpec& spec, const Scheme& scheme,
                     ThreadPool* pool)
    : grid_(spec),
      scheme_(&scheme),
      pool_(pool != nullptr ? pool : &ThreadPool::Default()),
      tiles_x_((grid_.nodes_x() + kTileSize - 1) / kTileSize),
      tiles_y_((grid_.nodes_y() + kTileSize - 1) / kTileSize),
      tiles_(static_cast<size_t>(tiles_x_) * tiles_y_),
      tile_version_(tiles_.size(), 0),
      arena_(std::make_unique<TileArena>(size_t{kTileNodes} *
                                         scheme.bytes_per_node())),
      index_(grid_),
      serial_(NextSerial()),
      derivatives_(scheme.stores_derivatives()),
      jets_(static_cast<int32_t>(tiles_.size()), kJetCacheTiles) {}

Workpiece::~Workpiece() {
  tiles_.clear();  // blocks go back to the arena before it goes
}

absl::StatusOr<std::unique_ptr<Workpiece>> Workpiece::Create(
    const StockSpec& spec, SchemeKind scheme, ThreadPool* pool) {
  SWARF_RETURN_IF_ERROR(ValidateStock(spec));
  return std::unique_ptr<Workpiece>(
      new Workpiece(spec, GetScheme(scheme), pool));
}

absl::Status Workpiece::ValidateMoves(std::span<const Move> moves) {
  // Consecutive moves mostly share a cutter: validated once per run (the
  // field name is a string built per call; it was 3% of a finishing batch).
  const Cutter* valid = nullptr;
  for (size_t k = 0; k < moves.size(); ++k) {
    const Move& m = moves[k];
    const struct {
      const char* name;
      double v;
    } fields[] = {{"from.x", m.from.x}, {"from.y", m.from.y},
                  {"from.z", m.from.z}, {"to.x", m.to.x},
                  {"to.y", m.to.y},     {"to.z", m.to.z}};
    for (const auto& f : fields) {
      if (!std::isfinite(f.v)) {
        return absl::InvalidArgumentError(absl::StrCat(
            "moves[", k, "].", f.name, " must be finite, got ", f.v));
      }
      if (std::fabs(f.v) > kMaxCoordinate) {
        return absl::InvalidArgumentError(
            absl::StrCat("moves[", k, "].", f.name, " must be within +-",
                         kMaxCoordinate, " mm, got ", f.v));
      }
    }
    if (valid != nullptr && m.cutter == *valid) continue;
    SWARF_RETURN_IF_ERROR(
        ValidateCutter(m.cutter, absl::StrCat("moves[", k, "].cutter")));
    valid = &m.cutter;
  }
  return absl::OkStatus();
}

std::unique_ptr<Workpiece::Tile> Workpiece::NewTile() const {
  auto tile = std::make_unique<Tile>(arena_.get());
  std::fill_n(tile->w, kTileNodes, spec().z_top);
  std::fill_n(tile->owner, kTileNodes, -1);
  tile->zmax = spec().z_top;
  return tile;
}

int64_t Workpiece::CutTile(int32_t t, Tile* tile,
                           std::span<const Sweep> sweeps,
                           std::span<const uint32_t> batch_moves,
                           int64_t first_id,
                           std::span<const double> drop_limit,
                           std::vector<TileCut>* cuts) const {
  const int32_t ti = t % tiles_x_, tj = t / tiles_x_;
  const int32_t i_base = ti * kTileSize, j_base = tj * kTileSize;
  const int32_t i_max = std::min(i_base + kTileSize - 1, grid_.nx());
  const int32_t j_max = std::min(j_base + kTileSize - 1, grid_.ny());
  const double x0 = spec().x0, y0 = spec().y0;
  const double dx = grid_.dx(), dy = grid_.dy();
  const double inv_dx = 1 / dx, inv_dy = 1 / dy;
  // Restrict-qualified, and the sweep copied to a local below: otherwise
  // every store to w[] could alias the sweep's and the grid's doubles, and
  // the compiler would reload them after each lowered node.
  double* __restrict const w = tile->w;
  int32_t* __restrict const owner = tile->owner;
  int64_t lowered = 0;

  // Candidate nodes are gathered across rows into chunks, so that short
  // moves (a few nodes per row) still fill the vector units.
  constexpr int32_t kChunk = 256;
  static_assert(kChunk >= kTileSize);
  alignas(64) double cx[kChunk], cy[kChunk], h[kChunk], cw[kChunk];
  int32_t ck[kChunk];
  alignas(8) uint8_t flag[FlagBytes(kChunk)];  // MayLower's
  // Spans of a row at least this long are narrowed to the span's top.
  constexpr int32_t kNarrowSpan = 16;

  // One move of one shape: S is the shape's sweep class (chosen once per
  // move), so that its row loops are inlined and vectorized. Only heights
  // and owners are stored: derivatives are a function of (owner, node) and
  // are computed when read (TileJets).
  auto cut_move = [&]<class S>(const S& shape_sweep, uint32_t m) {
    const S sweep = shape_sweep;
    // Nodes only go down: the tile's highest node caps what can be cut.
    if (!(sweep.lowest() < tile->zmax)) return;
    const Capsule cap = sweep.Footprint(tile->zmax);
    if (cap.empty) return;
    const int32_t id = static_cast<int32_t>(first_id + m);
    int32_t n = 0;
    // The nodes gathered for the chunk, and those passed over in the
    // shadow of the previous move (below): the chunks end where they
    // would with every node gathered, so that the drops are summed in the
    // same groups, bit for bit.
    int32_t vn = 0;
    // What the move cut here (with `cuts`): drop sums, the deepest node.
    double drop_sum = 0, max_drop = 0, max_z = 0, over = 0;
    int32_t max_k = -1;
    const double limit = drop_limit.empty() ? kInf : drop_limit[m];
    // The chunk's sweep heights (vectorized), then lowering: the nodes a
    // move lowers are a fraction of its chunks (about 1 in 7 on a raster
    // of short moves), so they are flagged in a vectorized pass against
    // the heights copied at gathering (cw: no node is in a move's chunks
    // twice), and only the flagged ones, in order, are decided and lowered
    // (a word of 8 flags at a time: most words are zero).
    auto for_each_flagged = [&](auto&& lower_at) {
      MayLower(h, cw, n, flag);
      ClearFlagTail(flag, n);
      ForEachFlagged(flag, n, lower_at);
    };
    auto flush = [&] {
      vn = 0;
      if (n == 0) return;  // only shadowed nodes: none lowered
      sweep.Heights(cx, cy, n, h);
      int32_t low = 0;
      if (cuts != nullptr) {
        // Lowering as below, summing the drops of the nodes lowered in
        // chunk order as they go.
        double sum = 0, top = 0, excess = 0;
        int32_t top_q = -1;
        for_each_flagged([&](int32_t q) {
          const int32_t k = ck[q];
          const double old = w[k];
          const bool lower = h[q] < old || (h[q] == old && id < owner[k]);
          if (lower) {
            const double d = old - h[q];
            sum += d;
            if (d > top) {
              top = d;
              top_q = q;
            }
            if (d > limit) excess += d - limit;
            w[k] = h[q];
            owner[k] = id;
            ++low;
          }
        });
        drop_sum += sum;
        over += excess;
        if (top > max_drop) {
          max_drop = top;
          max_k = ck[top_q];
          max_z = h[top_q];
        }
        lowered += low;
        n = 0;
        return;
      }
      for_each_flagged([&](int32_t q) {
        const int32_t k = ck[q];
        const bool lower = h[q] < w[k] || (h[q] == w[k] && id < owner[k]);
        if (lower) {
          w[k] = h[q];
          owner[k] = id;
          ++low;
        }
      });
      lowered += low;
      n = 0;
    };
    const Rect b = cap.Bounds();
    auto [j_lo, j_hi] = NodeRange(b.y0, b.y1, y0, inv_dy, j_max);
    j_lo = std::max(j_lo, j_base);
    const double lowest = sweep.lowest();
    const double zmax = tile->zmax;
    // The footprint's node range on each row, rows at a time (j_lo is in
    // the tile: at most a tile's rows).
    int32_t row_lo[kTileSize], row_hi[kTileSize];
    const int32_t rows = j_hi - j_lo + 1;
    if (rows > 0) {
      RowNodeRanges(cap, y0, dy, j_lo, rows, x0, inv_dx, i_max, row_lo, row_hi);
    }
    // On a long span, the highest node of the span caps what the move can
    // cut there, as zmax does for the tile but much lower on the rows a
    // raster's passes have cut: nothing where the sweep's lowest point is
    // not below it, and a ball's footprint shrinks to it (over the
    // narrower span, the nodes it leaves out are at or below the span's
    // top, and the sweep is not below it there). A short span is evaluated
    // whole: the test would cost more than it saves. Heights are never
    // NaN: a vectorized max, in any order. The tops are taken for every
    // row before any is cut: a row's nodes are lowered only after it is
    // gathered, so each top is the one its row would see then. The narrow
    // rows' radii and ranges are then taken together, in vectorized loops.
    int32_t narrow_q[kTileSize];
    double narrow_top[kTileSize];
    int32_t narrowed = 0;
    for (int32_t q = 0; q < rows; ++q) {
      int32_t& i_lo = row_lo[q];
      const int32_t i_hi = row_hi[q];
      i_lo = std::max(i_lo, i_base);
      if (i_lo > i_hi || i_hi - i_lo + 1 < kNarrowSpan) continue;
      const int32_t k0 = (j_lo + q - j_base) * kTileSize - i_base;
      // Blocks of 8 until one reaches the tile's top (uncut stock, the
      // rows ahead of a raster: the first block).
      const double top = SpanTop(w + k0 + i_lo, i_hi - i_lo + 1, zmax);
      if (!(lowest < top)) {
        i_lo = i_hi + 1;  // none
        continue;
      }
      if constexpr (std::is_same_v<S, BallSweep>) {
        if (top < zmax) {
          narrow_q[narrowed] = q;
          narrow_top[narrowed++] = top;
        }
      }
    }
    if constexpr (std::is_same_v<S, BallSweep>) {
      if (narrowed > 0) {
        double radii[kTileSize];
        int32_t n_lo[kTileSize], n_hi[kTileSize];
        sweep.FootprintRadii(narrow_top, narrowed, radii);
        for (int32_t k = 0; k < narrowed; ++k) {
          radii[k] = std::min(cap.radius, radii[k]);
        }
        RowNodeRangesAt(cap, radii, j_lo, narrow_q, narrowed, y0, dy, x0,
                        inv_dx, i_max, n_lo, n_hi);
        for (int32_t k = 0; k < narrowed; ++k) {
          const int32_t q = narrow_q[k];
          if (n_lo[k] > n_hi[k]) {
            row_lo[q] = row_hi[q] + 1;  // the narrow footprint misses it
          } else {
            row_lo[q] = std::max(row_lo[q], n_lo[k]);
            row_hi[q] = std::min(row_hi[q], n_hi[k]);
          }
        }
      }
    }
    // A ball move that starts where the path's previous move ended leaves
    // the nodes of its shadow (BallSweep::ShadowAfter) as they are: that
    // move was applied before it, and it is surely above them there (on a
    // raster of short moves, about a third of a move's nodes).
    std::optional<BallSweep::Shadow> shadow;
    if constexpr (std::is_same_v<S, BallSweep>) {
      if (m > 0) {
        if (const BallSweep* prev = sweeps[m - 1].ball()) {
          shadow = sweep.ShadowAfter(*prev);
        }
      }
    }
    int32_t shadow_lo[kTileSize], shadow_hi[kTileSize];
    if (shadow.has_value() && rows > 0) {
      BallSweep::ShadowRows(*shadow, y0, dy, j_lo, rows, x0, inv_dx, i_max,
                            shadow_lo, shadow_hi);
    }
    for (int32_t q = 0; q < rows; ++q) {
      const int32_t i_lo = row_lo[q], i_hi = row_hi[q];
      if (i_lo > i_hi) continue;
      const int32_t j = j_lo + q;
      const double y = y0 + j * dy;  // as GridGeometry::NodeY
      const int32_t k0 = (j - j_base) * kTileSize - i_base;  // node i's: k0 + i
      const int32_t count = i_hi - i_lo + 1;
      if (vn + count > kChunk) flush();
      // The shadow's nodes [s0, s1] of the span are passed over (none:
      // s0 = i_hi + 1, s1 = i_hi): the span is gathered in up to two parts.
      int32_t s0 = i_hi + 1, s1 = i_hi;
      if (shadow.has_value() && shadow_lo[q] <= i_hi && shadow_hi[q] >= i_lo &&
          shadow_lo[q] <= shadow_hi[q]) {
        s0 = std::max(i_lo, shadow_lo[q]);
        s1 = std::min(i_hi, shadow_hi[q]);
      }
      if (s0 > i_lo) {
        GatherRow(x0, dx, i_lo, s0 - i_lo, y, k0, w, cx + n, cy + n, ck + n,
                  cw + n);
        n += s0 - i_lo;
      }
      if (s1 < i_hi) {
        GatherRow(x0, dx, s1 + 1, i_hi - s1, y, k0, w, cx + n, cy + n, ck + n,
                  cw + n);
        n += i_hi - s1;
      }
      vn += count;
    }
    if (vn > 0) flush();
    if (cuts != nullptr && max_k >= 0) {
      MoveCut c;
      const double area = dx * dy;
      c.removed_mm3 = drop_sum * area;
      c.max_drop = max_drop;
      c.i = i_base + (max_k & (kTileSize - 1));
      c.j = j_base + (max_k >> kTileBits);
      c.z = max_z;
      c.over_limit_mm3 = over * area;
      cuts->push_back({m, c});
    }
  };
  for (uint32_t m : batch_moves) {
    sweeps[m].Visit([&](const auto& s) { cut_move(s, m); });
  }
  if (lowered > 0) tile->zmax = TileTop(t, *tile);  // tighter for later
  return lowered;
}

double Workpiece::TileTop(int32_t t, const Tile& tile) const {
  const TileExtent e = Extent(t);
  double zmax = -kInf;
  for (int32_t j = 0; j < e.ny; ++j) {
    const double* row = tile.w + j * kTileSize;
    for (int32_t i = 0; i < e.nx; ++i) zmax = std::max(zmax, row[i]);
  }
  return zmax;
}

namespace {

// The footprint IndexMove indexes (nullopt: above the top, or beside the
// stock).
std::optional<Rect> IndexedFootprint(const Move& move, double z_top,
                                     const GridGeometry& grid) {
  const std::optional<Rect> b =
      FootprintBounds(move.from, move.to, move.cutter, z_top);
  if (!b.has_value() || !b->Intersects(grid.bounds())) {
    return std::nullopt;
  }
  return b;
}

// Storage for a batch's sweeps (Sweep has no empty state: they are
// constructed in place), kept from batch to batch (ApplyScratch, up to its
// kKeptMoves): built in new storage, every batch's sweeps were faulted in
// afresh, about a tenth of a plate job's page faults.
class SweepStorage {
 public:
  SweepStorage() = default;
  ~SweepStorage() { Release(); }
  SweepStorage(const SweepStorage&) = delete;
  SweepStorage& operator=(const SweepStorage&) = delete;

  // Room for n sweeps (none constructed).
  Sweep* Reserve(size_t n) {
    if (n > capacity_) {
      Release();
      p_ = alloc_.allocate(n);
      capacity_ = n;
    }
    return p_;
  }
  // Gives the storage back when it is larger than kept sweeps.
  void Trim(size_t kept) {
    if (capacity_ > kept) Release();
  }

 private:
  void Release() {
    if (p_ != nullptr) alloc_.deallocate(p_, capacity_);
    p_ = nullptr;
    capacity_ = 0;
  }
  std::allocator<Sweep> alloc_;
  Sweep* p_ = nullptr;
  size_t capacity_ = 0;
};

// A batch's sweeps, built on every thread in `storage`; destroyed with the
// batch.
class BatchSweeps {
 public:
  BatchSweeps(SweepStorage* storage, size_t n)
      : n_(n), p_(storage->Reserve(n)) {}
  ~BatchSweeps() { std::destroy_n(p_, n_); }
  BatchSweeps(const BatchSweeps&) = delete;
  BatchSweeps& operator=(const BatchSweeps&) = delete;

  // Once for each m before span() is read; any thread.
  void Build(size_t m, const Move& move) {
    std::construct_at(p_ + m, move.from, move.to, move.cutter);
  }
  std::span<const Sweep> span() const { return {p_, n_}; }

 private:
  size_t n_;
  Sweep* p_;
};

// A move's tiles (Apply).
struct TileRange {
  int32_t ti0 = 0, ti1 = -1, tj0 = 0, tj1 = -1;  // empty by default
};

// Gives *v's storage back when it holds room for more than `keep`.
template <typename T>
void TrimVector(std::vector<T>* v, size_t keep) {
  if (v->capacity() > keep) std::vector<T>().swap(*v);
}

}  // namespace

// Kept from batch to batch for batches of up to kKeptMoves moves (a larger
// batch's are given back after it).
struct Workpiece::ApplyScratch {
  static constexpr size_t kKeptMoves = size_t{1} << 15;
  SweepStorage sweeps;
  std::vector<MoveIndex::BinRect> bins;
  std::vector<TileRange> ranges;
  std::vector<std::pair<int32_t, uint32_t>> pairs;  // (tile, move)
  std::vector<uint32_t> tile_moves;
  void Trim() {
    sweeps.Trim(kKeptMoves);
    TrimVector(&bins, kKeptMoves);
    TrimVector(&ranges, kKeptMoves);
    TrimVector(&pairs, 4 * kKeptMoves);
    TrimVector(&tile_moves, 4 * kKeptMoves);
  }
};

std::optional<Rect> IndexMove(uint32_t id, const Move& move, double z_top,
                              MoveIndex* index) {
  const std::optional<Rect> b = IndexedFootprint(move, z_top, index->grid());
  // Indexed even when it cuts no node: the exact surface still sees it.
  if (b.has_value()) index->Add(id, *b);
  return b;
}

MoveIndex::BinRect IndexedBins(const Move& move, double z_top,
                               const MoveIndex& index) {
  return IndexedBins(move, z_top, index.grid());
}

MoveIndex::BinRect IndexedBins(const Move& move, double z_top,
                               const GridGeometry& grid) {
  const std::optional<Rect> b = IndexedFootprint(move, z_top, grid);
  return b.has_value() ? MoveIndex::BinsOf(grid, *b) : MoveIndex::BinRect{};
}

absl::Status Workpiece::AdmitMoves(std::span<const Move> moves) const {
  SWARF_RETURN_IF_ERROR(ValidateMoves(moves));
  if (move_count() + static_cast<int64_t>(moves.size()) > kMaxMoves) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "a workpiece holds at most ", kMaxMoves, " moves; it has ",
        move_count(), " and the batch adds ", moves.size()));
  }
  return absl::OkStatus();
}

absl::StatusOr<ApplyResult> Workpiece::Apply(std::span<const Move> moves) {
  return Apply(moves, ApplyOptions{});
}

absl::StatusOr<ApplyResult> Workpiece::Apply(std::span<const Move> moves,
                                             const ApplyOptions& options) {
  SWARF_RETURN_IF_ERROR(AdmitMoves(moves));
  if (!options.drop_limit.empty() && options.drop_limit.size() != moves.size()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "drop_limit has ", options.drop_limit.size(), " entries for ",
        moves.size(), " moves"));
  }
  ApplyResult result;
  result.first_move_id = move_count();
  result.moves = static_cast<int64_t>(moves.size());

  // The sweeps, footprints' bins and tile ranges on every thread: done on
  // one they were the serial part of each batch (about 5% of a plate's
  // simulation on 2 cores, which held 16 cores to under 5x). The index
  // takes the moves in order, each bin on one thread.
  const size_t n_moves = moves.size();
  if (apply_scratch_ == nullptr)
    apply_scratch_ = std::make_unique<ApplyScratch>();
  ApplyScratch& scratch = *apply_scratch_;
  // Trimmed once the batch's sweeps are destroyed (declared after this).
  struct TrimAfter {
    ApplyScratch* scratch;
    ~TrimAfter() { scratch->Trim(); }
  } trim_after{&scratch};
  BatchSweeps batch(&scratch.sweeps, n_moves);
  // Empty where not indexed; indexed even when it cuts no node: the exact
  // surface still sees it.
  std::vector<MoveIndex::BinRect>& bins = scratch.bins;
  bins.assign(n_moves, {});
  std::vector<TileRange>& ranges = scratch.ranges;
  ranges.assign(n_moves, {});
  constexpr int64_t kPrepChunk = 256;
  const int64_t prep_chunks =
      (static_cast<int64_t>(n_moves) + kPrepChunk - 1) / kPrepChunk;
  // Each chunk's count of (tile, move) pairs at [c + 1], then their offsets.
  std::vector<size_t> pair_at(prep_chunks + 1, 0);
  pool_->ParallelFor(prep_chunks, [&](int64_t c) {
    const size_t m1 =
        std::min(n_moves, static_cast<size_t>((c + 1) * kPrepChunk));
    size_t pairs_here = 0;
    for (size_t m = static_cast<size_t>(c * kPrepChunk); m < m1; ++m) {
      batch.Build(m, moves[m]);
      const std::optional<Rect> footprint =
          IndexedFootprint(moves[m], spec().z_top, grid_);
      if (!footprint.has_value()) continue;
      const Rect& b = *footprint;
      bins[m] = index_.BinsOf(b);
      const auto [i_lo, i_hi] =
          NodeRange(b.x0, b.x1, spec().x0, 1 / grid_.dx(), grid_.nx());
      const auto [j_lo, j_hi] =
          NodeRange(b.y0, b.y1, spec().y0, 1 / grid_.dy(), grid_.ny());
      if (i_lo > i_hi || j_lo > j_hi) continue;  // between nodes
      const TileRange r = {i_lo >> kTileBits, i_hi >> kTileBits,
                           j_lo >> kTileBits, j_hi >> kTileBits};
      ranges[m] = r;
      pairs_here +=
          static_cast<size_t>(r.ti1 - r.ti0 + 1) * (r.tj1 - r.tj0 + 1);
    }
    pair_at[c + 1] = pairs_here;
  });
  const std::span<const Sweep> sweeps = batch.span();
  index_.AddAll(static_cast<uint32_t>(result.first_move_id), bins, *pool_);
  // (tile, move) pairs for every tile a move's footprint may touch, in
  // move order.
  for (int64_t c = 0; c < prep_chunks; ++c) pair_at[c + 1] += pair_at[c];
  std::vector<std::pair<int32_t, uint32_t>>& pairs = scratch.pairs;
  ResizeForWriting(&pairs, pair_at[prep_chunks]);
  pool_->ParallelFor(prep_chunks, [&](int64_t c) {
    const size_t m1 =
        std::min(n_moves, static_cast<size_t>((c + 1) * kPrepChunk));
    size_t k = pair_at[c];
    for (size_t m = static_cast<size_t>(c * kPrepChunk); m < m1; ++m) {
      const TileRange& r = ranges[m];
      for (int32_t tj = r.tj0; tj <= r.tj1; ++tj) {
        for (int32_t ti = r.ti0; ti <= r.ti1; ++ti) {
          pairs[k++] = {tj * tiles_x_ + ti, static_cast<uint32_t>(m)};
        }
      }
    }
  });
  moves_.Append(moves);

  // Group by tile, keeping move order within a tile: counted per tile
  // (a stable sort of the pairs took 7% of each batch on 16 cores).
  // `count` is the thread's, all zero between batches.
  thread_local std::vector<uint32_t> count;
  if (count.size() < tiles_.size()) count.resize(tiles_.size(), 0);
  std::vector<std::pair<int32_t, size_t>> touched;  // tile, start offset
  for (const auto& [t, m] : pairs) {
    if (count[t]++ == 0) touched.emplace_back(t, 0);
  }
  std::sort(touched.begin(), touched.end());
  size_t at = 0;
  for (auto& [t, start] : touched) {
    start = at;
    at += count[t];
    count[t] = static_cast<uint32_t>(start);  // the tile's next slot
  }
  std::vector<uint32_t>& tile_moves = scratch.tile_moves;
  ResizeForWriting(&tile_moves, pairs.size());
  for (const auto& [t, m] : pairs) tile_moves[count[t]++] = m;
  for (const auto& [t, start] : touched) count[t] = 0;
  touched.emplace_back(-1, pairs.size());  // sentinel end
  const int64_t n_touched = static_cast<int64_t>(touched.size()) - 1;

  std::vector<int64_t> lowered(n_touched, 0);
  std::vector<std::vector<TileCut>> tile_cuts(options.cuts ? n_touched : 0);
  pool_->ParallelFor(n_touched, [&](int64_t k) {
    const int32_t t = touched[k].first;
    std::span<const uint32_t> list(tile_moves.data() + touched[k].second,
                                   touched[k + 1].second - touched[k].second);
    std::unique_ptr<Tile> fresh;
    Tile* tile = tiles_[t].get();
    if (tile == nullptr) {
      fresh = NewTile();
      tile = fresh.get();
    }
    lowered[k] = CutTile(t, tile, sweeps, list, result.first_move_id,
                         options.drop_limit,
                         options.cuts ? &tile_cuts[k] : nullptr);
    // Only a tile that was really cut stays allocated.
    if (fresh != nullptr && lowered[k] > 0) tiles_[t] = std::move(fresh);
  });

  bool changed = false;
  for (int64_t k = 0; k < n_touched; ++k) changed |= lowered[k] > 0;
  if (changed) ++version_;
  for (int64_t k = 0; k < n_touched; ++k) {
    if (lowered[k] == 0) continue;
    result.node_lowerings += lowered[k];
    result.changed_tiles.push_back(touched[k].first);
    tile_version_[touched[k].first] = version_;
  }
  result.version = version_;
  if (options.cuts) {
    // Each move's cuts merged in tile order: the same sums whatever the
    // threads did. A range of moves a task, each finding its moves in every
    // tile's list (in move order) by bisection: merged on one thread, with
    // the array's zeroing and faults, this was a serial step of each batch.
    result.cuts.resize(moves.size());
    // At least 1,024 moves a range, at most four ranges a thread: each range
    // bisects every tile's list.
    const int64_t n_moves = static_cast<int64_t>(moves.size());
    const int64_t ranges = std::clamp<int64_t>(
        n_moves / 1024, 1, 4 * static_cast<int64_t>(pool_->size()));
    const int64_t per_range = (n_moves + ranges - 1) / ranges;
    pool_->ParallelFor(ranges, [&](int64_t r) {
      const uint32_t m0 =
          static_cast<uint32_t>(std::min(n_moves, r * per_range));
      const uint32_t m1 =
          static_cast<uint32_t>(std::min(n_moves, (r + 1) * per_range));
      std::fill(result.cuts.begin() + m0, result.cuts.begin() + m1, MoveCut{});
      auto by_move = [](const TileCut& tc, uint32_t m) { return tc.m < m; };
      for (const std::vector<TileCut>& list : tile_cuts) {
        for (auto it = std::lower_bound(list.begin(), list.end(), m0, by_move);
             it != list.end() && it->m < m1; ++it) {
          MoveCut& c = result.cuts[it->m];
          c.removed_mm3 += it->cut.removed_mm3;
          c.over_limit_mm3 += it->cut.over_limit_mm3;
          if (it->cut.max_drop > c.max_drop) {
            c.max_drop = it->cut.max_drop;
            c.i = it->cut.i;
            c.j = it->cut.j;
            c.z = it->cut.z;
          }
        }
      }
    });
  }
  return result;
}

namespace {

// ComputeJets' working memory, one per thread that computes jets (about
// 0.6 MB: too large for a stack, too costly to allocate per tile).
struct JetScratch {
  // The frames of recent owners, direct-mapped: (tag << 32 | owner) -> frame
  // index, the tag distinct per tile computed, so that the table needs no
  // clearing (but when the tag wraps). An owner whose entry was taken by
  // another gets a second frame: harmless.
  static constexpr int32_t kRecentBits = 10;
  uint64_t recent_key[1 << kRecentBits] = {};  // 0: none (tags start at 1)
  int32_t recent_frame[1 << kRecentBits];
  uint32_t tag = 0;
  // Runs of one owner in row-major order: each node's run, each run's owner
  // and frame index.
  int32_t run_of[kTileNodes];
  int32_t run_owner[kTileNodes];
  int32_t run_frame[kTileNodes];
  // Per node: the index into `frames` of its owner (0: uncut).
  alignas(64) int32_t frame_of[kTileNodes];
  // Per distinct owner f >= 1: its move id, its ball frame (NoFrame() for
  // the rest, and for f = 0), and the index into `others` of a sweep
  // evaluated on its own (-1: none).
  int32_t owner_of[kTileNodes + 1];
  static constexpr int32_t kFrameStride =
      kTileNodes + 1 + BallSweep::kFramePadding;
  alignas(64) double frame_data[BallSweep::kFrameValues * kFrameStride] = {};
  BallSweep::FrameTable frames{frame_data, kFrameStride};
  uint8_t general[kTileNodes + 1];
  bool ball[kTileNodes + 1];  // SweptAsBall(its cutter)
  int32_t other[kTileNodes + 1];
  std::vector<Sweep> others;
  // MakeFrames' input, a block of owners at a time.
  static constexpr int32_t kBlock = 256;
  Vec3 from[kBlock], to[kBlock];
  double radius[kBlock];
  alignas(64) double xs[kTileSize];
  alignas(64) double ys[kTileSize];
  BallSweep::Points points;
};

}  // namespace

void Workpiece::ComputeJets(int32_t t, const Tile& tile, int32_t stride,
                            int8_t* row_lo, int8_t* row_hi,
                            float* const jets[5]) const {
  thread_local std::unique_ptr<JetScratch> scratch;
  if (scratch == nullptr) scratch = std::make_unique<JetScratch>();
  JetScratch& s = *scratch;
  const TileExtent e = Extent(t);
  const int32_t* owner = tile.owner;

  // Each distinct owner's sweep is built once per tile: owners change every
  // few nodes along a finishing pass, and building a sweep costs more than
  // evaluating it. First which columns of each row are cut, then the runs
  // of one owner along them (branch-free: run ends are as frequent as they
  // are irregular).
  for (int32_t j = 0; j < e.ny; ++j) {
    const int32_t* row = owner + j * kTileSize;
    int32_t lo = 0, hi = e.nx - 1;  // nodes past the grid are never cut
    while (lo < e.nx && row[lo] < 0) ++lo;
    while (hi >= lo && row[hi] < 0) --hi;
    row_lo[j] = static_cast<int8_t>(lo);
    row_hi[j] = static_cast<int8_t>(hi);
  }
  int32_t run = -1, prev = -2;  // -2: no owner
  for (int32_t j = 0; j < e.ny; ++j) {
    const int32_t k0 = j * kTileSize;
    for (int32_t k = k0 + row_lo[j]; k <= k0 + row_hi[j]; ++k) {
      const int32_t o = owner[k];
      run += o != prev;
      s.run_owner[run] = o;
      s.run_of[k] = run;
      prev = o;
    }
  }
  const int32_t runs = run + 1;
  // Frame indices from 1, per distinct owner (nearly).
  if (++s.tag == 0) {
    std::fill_n(s.recent_key, 1 << JetScratch::kRecentBits, 0);
    s.tag = 1;
  }
  const uint64_t tag = uint64_t{s.tag} << 32;
  int32_t owners = 0;
  for (int32_t r = 0; r < runs; ++r) {
    const int32_t o = s.run_owner[r];
    if (o < 0) {
      s.run_frame[r] = 0;
      continue;
    }
    const uint32_t h = static_cast<uint32_t>(o) &
                       ((1u << JetScratch::kRecentBits) - 1);
    const uint64_t key = tag | static_cast<uint32_t>(o);
    if (s.recent_key[h] != key) {
      s.recent_key[h] = key;
      s.recent_frame[h] = ++owners;
      s.owner_of[owners] = o;
    }
    s.run_frame[r] = s.recent_frame[h];
  }
  for (int32_t j = 0; j < e.ny; ++j) {
    const int32_t k0 = j * kTileSize;
#pragma omp simd
    for (int32_t k = k0 + row_lo[j]; k <= k0 + row_hi[j]; ++k) {
      s.frame_of[k] = s.run_frame[s.run_of[k]];
    }
  }

  // The owners' frames, as if each were a BallSweep (the others' are
  // replaced below): general ball moves are evaluated a row at a time with
  // each lane its own sweep; points, vertical moves and other shapes (few
  // nodes, or many of one owner) on their own.
  s.frames.Set(0, BallSweep::NoFrame());
  s.other[0] = -1;
  s.others.clear();
  for (int32_t f0 = 1; f0 <= owners; f0 += JetScratch::kBlock) {
    const int32_t m = std::min(JetScratch::kBlock, owners + 1 - f0);
    for (int32_t q = 0; q < m; ++q) {
      // Owners are scattered over the moves: fetch ahead.
      moves_.Prefetch(s.owner_of[std::min(f0 + q + 16, owners)]);
      const Move move = moves_.Get(s.owner_of[f0 + q]);
      s.from[q] = move.from;
      s.to[q] = move.to;
      s.radius[q] = move.cutter.radius;
      s.ball[f0 + q] = SweptAsBall(move.cutter);
    }
    BallSweep::MakeFrames(m, s.from, s.to, s.radius, s.frames, f0,
                          s.general + f0);
  }
  for (int32_t f = 1; f <= owners; ++f) {
    s.other[f] = -1;
    if (s.general[f] && s.ball[f]) continue;
    const Move& move = moves_[s.owner_of[f]];
    s.frames.Set(f, BallSweep::NoFrame());
    s.other[f] = static_cast<int32_t>(s.others.size());
    s.others.emplace_back(move.from, move.to, move.cutter);
  }

  // The jets, a row at a time over its cut columns (uncut nodes between
  // them get NoFrame()'s zeros).
  for (int32_t i = 0; i < kTileSize; ++i) s.xs[i] = grid_.NodeX(e.i0 + i);
  for (int32_t j = 0; j < e.ny; ++j) {
    const int32_t lo = row_lo[j], hi = row_hi[j];
    if (lo > hi) continue;
    const int32_t k = j * kTileSize + lo, o = j * stride + lo;
    float* const d[5] = {jets[0] + o, jets[1] + o, jets[2] + o, jets[3] + o,
                         jets[4] + o};
    BallSweep::JetsOfFrames(s.frames, s.frame_of + k, s.xs + lo,
                            grid_.NodeY(e.j0 + j), hi - lo + 1, d);
  }
  if (s.others.empty()) return;

  // The other owners' nodes, a run of one owner along a row at a time.
  for (int32_t j = 0; j < e.ny; ++j) {
    const double y = grid_.NodeY(e.j0 + j);
    const int32_t k0 = j * kTileSize;
    for (int32_t i = row_lo[j]; i <= row_hi[j];) {
      const int32_t f = s.frame_of[k0 + i];
      int32_t end = i + 1;
      while (end <= row_hi[j] && s.frame_of[k0 + end] == f) ++end;
      if (s.other[f] >= 0) {
        const int32_t n = end - i, o = j * stride + i;
        float* const d[5] = {jets[0] + o, jets[1] + o, jets[2] + o, jets[3] + o,
                             jets[4] + o};
        s.others[s.other[f]].Visit([&](const auto& shape) {
          if constexpr (std::is_same_v<std::decay_t<decltype(shape)>,
                                       BallSweep>) {
            // A point or vertical move: its own vectorized kernels,
            // bit-identical to JetAt.
            std::fill_n(s.ys, n, y);
            shape.Locate(s.xs + i, s.ys, n, &s.points);
            shape.Jets(s.points, n, d);
          } else {
            for (int32_t q = 0; q < n; ++q) {
              const SurfaceJet jet = shape.JetAt(s.xs[i + q], y);
              d[0][q] = static_cast<float>(jet.wx);
              d[1][q] = static_cast<float>(jet.wy);
              d[2][q] = static_cast<float>(jet.wxx);
              d[3][q] = static_cast<float>(jet.wxy);
              d[4][q] = static_cast<float>(jet.wyy);
            }
          }
        });
      }
      i = end;
    }
  }
}

Workpiece::JetCache::JetCache(int32_t tile_count, size_t tiles)
    : capacity_(std::max<size_t>(tiles, 1)), jets_(tile_count) {}

Workpiece::JetCache::~JetCache() = default;

std::shared_ptr<const Workpiece::TileJets> Workpiece::JetCache::Find(
    int32_t t, uint64_t serial, uint64_t version) const {
  std::lock_guard<std::mutex> lock(mu_);
  const auto& cached = jets_[t];
  if (cached != nullptr && cached->serial == serial &&
      cached->version == version) {
    return cached;
  }
  return nullptr;
}

void Workpiece::JetCache::Insert(int32_t t,
                                 std::shared_ptr<const TileJets> jets) {
  std::lock_guard<std::mutex> lock(mu_);
  if (jets_[t] == nullptr) {
    order_.push_back(t);
    if (order_.size() > capacity_) {
      jets_[order_.front()] = nullptr;
      order_.pop_front();
    }
  }
  jets_[t] = std::move(jets);
}

std::unique_ptr<Workpiece::JetCache> Workpiece::NewJetCache(
    size_t tiles) const {
  return std::unique_ptr<JetCache>(new JetCache(tile_count(), tiles));
}

std::unique_ptr<Workpiece::JetCache> Workpiece::TraversalJetCache(
    int32_t rows_at_once) const {
  // A traversal in order of rows of tiles first computes a tile when it
  // reaches the node row above its tile row (or its own first row), and
  // last reads it about a tile row of tiles later: two rows, or as many as
  // the node rows read at once can span (fewer evict each tile before its
  // next node row is read: sixteen threads' bands of 16 rows over four
  // tile rows computed each tile about seven times), and room for the
  // threads working ahead of the slowest one.
  const int64_t at_once = std::max(rows_at_once, 1);
  const int64_t tile_rows =
      std::max<int64_t>(2, (at_once - 1 + kTileSize - 1) / kTileSize + 1);
  const size_t rows = static_cast<size_t>(tile_rows * tiles_x_ + 64);
  return NewJetCache(std::min({rows, static_cast<size_t>(tile_count()),
                               kTraversalJetBytes / sizeof(TileJets)}));
}

std::shared_ptr<const Workpiece::TileJets> Workpiece::CachedJets(
    int32_t t, uint64_t version) const {
  return jets_.Find(t, serial_, version);
}

std::shared_ptr<const Workpiece::TileJets> Workpiece::NewJets(
    int32_t t, uint64_t version, JetCache* cache) const {
  // Not value-initialised: ComputeJets writes every node of the tile's
  // rows.
  std::shared_ptr<TileJets> fresh(new TileJets);
  fresh->serial = serial_;
  fresh->version = version;
  float* const d[5] = {fresh->d[0], fresh->d[1], fresh->d[2], fresh->d[3],
                       fresh->d[4]};
  ComputeJets(t, *tiles_[t], kTileSize, fresh->lo, fresh->hi, d);
  cache->Insert(t, fresh);
  return fresh;
}

namespace {

// The tile jets this thread read last (Workpiece::Jets), whichever cache
// they came from: most reads stay in one tile. Plain values,
// constant-initialised, so that the hit test costs no TLS guard; `holder`
// (touched on misses only) keeps `jets` alive.
struct LastJets {
  const void* jets = nullptr;
  int32_t tile = -1;
  uint64_t serial = 0, version = 0;
};
thread_local LastJets last_jets;
thread_local std::shared_ptr<const void> last_jets_holder;

}  // namespace

inline const Workpiece::TileJets& Workpiece::Jets(int32_t t,
                                                  JetCache* cache) const {
  const LastJets& last = last_jets;
  if (last.tile == t && last.serial == serial_ &&
      last.version == tile_version_[t] && last.jets != nullptr) {
    return *static_cast<const TileJets*>(last.jets);
  }
  return JetsMiss(t, cache);
}

const Workpiece::TileJets& Workpiece::JetsMiss(int32_t t,
                                               JetCache* cache) const {
  const uint64_t version = tile_version_[t];
  std::shared_ptr<const TileJets> jets = cache->Find(t, serial_, version);
  // Computed outside the lock; two threads may both compute a tile, with
  // the same result.
  if (jets == nullptr) jets = NewJets(t, version, cache);
  const TileJets* p = jets.get();
  last_jets_holder = std::move(jets);
  last_jets = {p, t, serial_, version};
  return *p;
}

void Workpiece::PrepareJets(std::span<const int32_t> tiles) const {
  if (!derivatives_) return;
  std::vector<int32_t> todo;
  for (const int32_t t : tiles) {
    if (todo.size() == kJetCacheTiles) break;
    if (t < 0 || t >= tile_count() || tiles_[t] == nullptr) continue;
    if (CachedJets(t, tile_version_[t]) == nullptr) todo.push_back(t);
  }
  if (todo.size() < 2) {
    for (const int32_t t : todo) NewJets(t, tile_version_[t], &jets_);
    return;
  }
  pool_->ParallelFor(static_cast<int64_t>(todo.size()), [&](int64_t k) {
    NewJets(todo[k], tile_version_[todo[k]], &jets_);
  });
}

int32_t Workpiece::OwnerAt(int32_t i, int32_t j) const {
  const Tile* tile =
      tiles_[(j >> kTileBits) * tiles_x_ + (i >> kTileBits)].get();
  if (tile == nullptr) return -1;
  return tile->owner[(j & (kTileSize - 1)) * kTileSize + (i & (kTileSize - 1))];
}

double Workpiece::HeightAt(int32_t i, int32_t j) const {
  const Tile* tile =
      tiles_[(j >> kTileBits) * tiles_x_ + (i >> kTileBits)].get();
  if (tile == nullptr) return spec().z_top;
  return tile->w[(j & (kTileSize - 1)) * kTileSize + (i & (kTileSize - 1))];
}

double Workpiece::TileMax(int32_t t) const {
  const Tile* tile = tiles_[t].get();
  return tile == nullptr ? spec().z_top : tile->zmax;
}

NodeValue Workpiece::Node(int32_t i, int32_t j) const {
  return Node(i, j, &jets_);
}

NodeValue Workpiece::Node(int32_t i, int32_t j, JetCache* cache) const {
  NodeValue v;
  const int32_t t = (j >> kTileBits) * tiles_x_ + (i >> kTileBits);
  const Tile* tile = tiles_[t].get();
  if (tile == nullptr) {
    v.jet.w = spec().z_top;
    return v;
  }
  const int32_t k = (j & (kTileSize - 1)) * kTileSize + (i & (kTileSize - 1));
  v.jet.w = tile->w[k];
  v.owner = tile->owner[k];
  if (v.owner >= 0 && derivatives_) {
    const TileJets& jets = Jets(t, cache);
    v.jet.wx = jets.d[0][k];
    v.jet.wy = jets.d[1][k];
    v.jet.wxx = jets.d[2][k];
    v.jet.wxy = jets.d[3][k];
    v.jet.wyy = jets.d[4][k];
  }
  return v;
}

Workpiece::TileExtent Workpiece::Extent(int32_t t) const {
  TileExtent e;
  e.i0 = (t % tiles_x_) * kTileSize;
  e.j0 = (t / tiles_x_) * kTileSize;
  e.nx = std::min(kTileSize, grid_.nodes_x() - e.i0);
  e.ny = std::min(kTileSize, grid_.nodes_y() - e.j0);
  return e;
}

void Workpiece::ReadTileHeights(int32_t t, int32_t j0, int32_t j1,
                                double* out, int64_t stride) const {
  const TileExtent e = Extent(t);
  const Tile* tile = tiles_[t].get();
  for (int32_t j = j0; j <= j1; ++j) {
    double* const row = out + int64_t{j - j0} * stride;
    if (tile == nullptr) {
      std::fill_n(row, e.nx, spec().z_top);
    } else {
      std::memcpy(row, tile->w + (j - e.j0) * kTileSize,
                  e.nx * sizeof(double));
    }
  }
}

void Workpiece::ReadTile(int32_t t, double* w, float* const d[5],
                         int32_t* owner) const {
  const TileExtent e = Extent(t);
  const Tile* tile = tiles_[t].get();
  const int32_t n = e.nx * e.ny;
  if (tile == nullptr) {
    if (w != nullptr) std::fill_n(w, n, spec().z_top);
    if (owner != nullptr) std::fill_n(owner, n, -1);
    for (int c = 0; d != nullptr && c < 5; ++c) std::fill_n(d[c], n, 0.0f);
    return;
  }
  // Uncut nodes hold the top and owner -1: rows are copied whole.
  for (int32_t j = 0; j < e.ny; ++j) {
    const int32_t out = j * e.nx, k = j * kTileSize;
    if (w != nullptr) std::memcpy(w + out, tile->w + k, e.nx * sizeof(double));
    if (owner != nullptr) {
      std::memcpy(owner + out, tile->owner + k, e.nx * sizeof(int32_t));
    }
  }
  if (d == nullptr) return;
  if (!derivatives_) {
    for (int c = 0; c < 5; ++c) std::fill_n(d[c], n, 0.0f);
    return;
  }
  // Jets of each row's cut columns [lo, hi], zeros around them: copied
  // when cached, else computed straight into d and not cached (GetTiles
  // is faster without the cache entries' allocation and copy:
  // docs/benchmarks.md, issue 12).
  int8_t computed_lo[kTileSize], computed_hi[kTileSize];
  const int8_t *lo_of = computed_lo, *hi_of = computed_hi;
  const std::shared_ptr<const TileJets> cached =
      CachedJets(t, tile_version_[t]);
  if (cached != nullptr) {
    lo_of = cached->lo;
    hi_of = cached->hi;
    for (int32_t j = 0; j < e.ny; ++j) {
      const int32_t lo = lo_of[j], hi = hi_of[j];
      for (int c = 0; c < 5 && lo <= hi; ++c) {
        std::memcpy(d[c] + j * e.nx + lo, cached->d[c] + j * kTileSize + lo,
                    (hi - lo + 1) * sizeof(float));
      }
    }
  } else {
    ComputeJets(t, *tile, e.nx, computed_lo, computed_hi, d);
  }
  for (int32_t j = 0; j < e.ny; ++j) {
    const int32_t lo = lo_of[j], hi = hi_of[j];  // a row uncut: hi = lo - 1
    for (int c = 0; c < 5; ++c) {
      float* row = d[c] + j * e.nx;
      std::fill_n(row, lo, 0.0f);
      std::fill_n(row + hi + 1, e.nx - 1 - hi, 0.0f);
    }
  }
}

void Workpiece::ReconstructGradient(double x, double y, double* gx,
                                    double* gy) const {
  const Rect r = grid_.bounds();
  x = std::clamp(x, r.x0, r.x1);
  y = std::clamp(y, r.y0, r.y1);
  scheme_->Gradient(Corners(grid_.ElementX(x), grid_.ElementY(y)), x, y, gx,
                    gy);
}

CornerReach ReachOf(const Move& m, double z_top) {
  CornerReach r;
  r.bounded = true;
  r.z_low = std::min(m.from.z, m.to.z);
  // Where the sweep is below the top (beyond, the top is lower anyway).
  const Capsule c = FootprintCapsuleEnds(m.from, m.to, m.cutter, z_top);
  if (c.empty) {
    r.empty = true;
    return r;
  }
  // The footprint's exact radius (Footprint widens it by a margin for the
  // cut; here a point just outside must stay outside, as for the exact
  // surface).
  const double rho = FootprintRadius(m.cutter, r.z_low, z_top);
  r.capsule = {c.x0, c.y0, c.x1, c.y1, rho};
  return r;
}

MoveSweeps::MoveSweeps(const MoveSource* moves, const MoveIndex* index)
    : moves_(moves),
      list_(dynamic_cast<const MoveList*>(moves)),
      index_(index),
      serial_(NextSerial()) {}

MoveSweeps::MoveSweeps(std::shared_ptr<const MoveSource> moves,
                       const StockSpec& spec)
    : owned_(std::move(moves)),
      moves_(owned_.get()),
      list_(dynamic_cast<const MoveList*>(moves_)),
      owned_index_(std::make_unique<MoveIndex>(GridGeometry(spec))),
      index_(owned_index_.get()),
      serial_(NextSerial()) {
  for (int64_t id = 0; id < owned_->size(); ++id) {
    IndexMove(static_cast<uint32_t>(id), owned_->Get(id), spec.z_top,
              owned_index_.get());
  }
}

MoveSweeps::MoveSweeps(std::span<const Move> moves, const StockSpec& spec)
    : MoveSweeps(std::make_shared<const MoveList>(moves), spec) {}

const Sweep* MoveSweeps::SweepOf(int32_t id) const {
  if (id < 0 || id >= moves_->size()) return nullptr;
  // An element's candidates come back for every sample of it and for its
  // neighbours; they are mostly consecutive ids, which a direct-mapped
  // cache keeps apart.
  struct Entry {
    uint64_t serial = 0;
    int32_t id = -1;
    std::optional<Sweep> sweep;
  };
  constexpr int kEntries = 256;
  thread_local Entry cache[kEntries];
  Entry& e = cache[id & (kEntries - 1)];
  if (e.id == id && e.serial == serial_) return &*e.sweep;
  const Move m = MoveAt(id);
  e.sweep.emplace(m.from, m.to, m.cutter);
  e.id = id;
  e.serial = serial_;
  return &*e.sweep;
}

CornerReach MoveSweeps::Reach(int32_t id, double z_top) const {
  struct Entry {
    uint64_t serial = 0;
    int32_t id = -1;
    double z_top = 0;
    CornerReach reach;
  };
  constexpr int kEntries = 256;
  thread_local Entry cache[kEntries];
  Entry& e = cache[id & (kEntries - 1)];
  if (e.id != id || e.serial != serial_ || e.z_top != z_top) {
    e.reach = ReachOf(MoveAt(id), z_top);
    e.id = id;
    e.serial = serial_;
    e.z_top = z_top;
  }
  return e.reach;
}

// Lanes of moves as LowestAt first tests them, rounded outwards to float
// (4-byte lanes, half the bytes): each move's tips' XY box, its lowest tip,
// and FootprintGap's z_r and r2 (for other shapes than the ball, z_r is
// -inf and r2 the square of the cutter's radius, widened: their footprint
// lies within it of the move).
struct ReachLanes {
  std::vector<float> x0, x1, y0, y1, low, z_r, r2;
  // n lanes, each written before it is read. The arrays only grow: a
  // thread refills them bin after bin.
  void Resize(size_t n) {
    if (n > x0.size()) {
      for (auto* v : {&x0, &x1, &y0, &y1, &low, &z_r, &r2}) {
        v->resize(std::max<size_t>(1024, 2 * n));
      }
    }
    n_ = n;
  }
  size_t size() const { return n_; }

 private:
  size_t n_ = 0;
};

// A bin's moves in its order, and blocks of kReachBlock of them, each the
// union of its moves' lanes (box hull, least z_r and low, largest r2): a
// block the test rejects holds no move it passes. A bin's moves follow the
// path, so a block is a short stretch of it.
struct MoveBinReach {
  uint64_t serial = 0;
  int32_t bin = -1;
  int64_t moves = -1;  // the list's size when filled: the bins grow with it
  ReachLanes move, block;
  std::vector<uint32_t> ids;
};

namespace {

// Bins whose reach is kept, per thread: a crease's vertices come in runs
// that cross a few neighbouring bins. Larger bins are scanned as they are.
constexpr int kReachBins = 8;
constexpr size_t kMaxReachMoves = size_t{1} << 14;
constexpr size_t kReachBlock = 16;

// v rounded to a float not above (FloatDown) or below (FloatUp) it: moved
// by 2^-22 of itself first, more than the half float ulp that rounding to
// nearest can add (and 1e-30 for v near 0), without a call to nextafter.
[[gnu::always_inline]] inline float FloatDown(double v) {
  return static_cast<float>(v - (std::fabs(v) * 0x1p-22 + 1e-30));
}
[[gnu::always_inline]] inline float FloatUp(double v) {
  return static_cast<float>(v + (std::fabs(v) * 0x1p-22 + 1e-30));
}

// pass[q] = 0 where lane q0 + q surely is not below cap at (x, y): its
// lowest tip is not, or the point lies beyond its reach below cap. Below
// cap, a ball reaches within sqrt(r2 - h^2) of its centres' XY segment
// (h = z_r - cap > 0: its lowest centre above cap; else within r), another
// shape within r2's root (FootprintGap's reach), and that segment lies in
// the tips' XY box: a point farther than the reach from the box is beyond
// it (FootprintGap::Misses). The point is widened by FootprintGap's slack
// (and Misses takes each gap less it again), against the rounding of these
// float values. So no move this rejects is below cap at the point, nor
// below any w <= cap: the exact tests would find none of them lower
// (ExactSchemeTest.LowestAtAtTheEdgeOfTheFootprint). A block's union passes
// where any of its moves does: its box holds theirs, its z_r is no larger and
// its r2 no smaller, so its reach no smaller.
// `area` is the point so widened (SlackAbout), or for MovesNear its box. Each
// comparison only passes more lanes for a larger area or a higher cap (the
// gaps shrink, the reach grows), so a lane that passes at a point of a box
// below a cap no higher passes over the box.
SWARF_TARGET_CLONES
void MayBeBelowIn(const ReachLanes& b, size_t q0, size_t n, const Rect& area,
                  double cap, uint8_t* __restrict pass) {
  // A copy: read through the reference, the loop did not vectorize.
  const Rect point = area;
  const float* __restrict x0 = b.x0.data() + q0;
  const float* __restrict x1 = b.x1.data() + q0;
  const float* __restrict y0 = b.y0.data() + q0;
  const float* __restrict y1 = b.y1.data() + q0;
  const float* __restrict low = b.low.data() + q0;
  const float* __restrict z_r = b.z_r.data() + q0;
  const float* __restrict r2 = b.r2.data() + q0;
#pragma omp simd
  for (size_t q = 0; q < n; ++q) {
    // z_r -inf (not a ball) makes the reach r2 itself: every lane is
    // tested as a ball.
    const double beyond = FootprintGap::Misses(
        1.0, double{x0[q]}, double{x1[q]}, double{y0[q]}, double{y1[q]},
        double{z_r[q]}, double{r2[q]}, point, cap);
    // && (not &): GCC 12 vectorizes this form, not the other.
    pass[q] = (beyond == 0 && double{low[q]} < cap) ? 1 : 0;
  }
}

// The area MayBeBelowIn tests for the points of r: r widened by
// FootprintGap's slack.
Rect SlackAbout(const Rect& r) {
  constexpr double kSlack = FootprintGap::kSlack;
  return Rect{r.x0 - kSlack, r.y0 - kSlack, r.x1 + kSlack, r.y1 + kSlack};
}

// at(q) for each of reach's moves whose lane MayBeBelowIn passes in `area`
// below cap, in the bin's order: blocks first, then the moves of each run
// of passing blocks in one call (a stretch of the path near the area; a
// call a block cost more than its lanes). A move passes only where its
// block does (the block's union).
template <typename At>
[[gnu::always_inline]] inline void ForEachLaneBelow(const MoveBinReach& reach,
                                                    const Rect& area,
                                                    double cap, At&& at) {
  constexpr size_t kChunk = 256;
  uint8_t block_pass[kChunk], pass[kChunk * kReachBlock];
  const size_t blocks = reach.block.size();
  for (size_t b0 = 0; b0 < blocks; b0 += kChunk) {
    const size_t c = std::min(kChunk, blocks - b0);
    MayBeBelowIn(reach.block, b0, c, area, cap, block_pass);
    for (size_t b = 0, e; b < c; b = e) {
      e = b + 1;
      if (block_pass[b] == 0) continue;
      while (e < c && block_pass[e] != 0) ++e;
      const size_t q0 = (b0 + b) * kReachBlock;
      const size_t n = std::min((e - b) * kReachBlock, reach.ids.size() - q0);
      MayBeBelowIn(reach.move, q0, n, area, cap, pass);
      for (size_t q = 0; q < n; ++q) {
        if (pass[q] != 0) at(q0 + q);
      }
    }
  }
}

// Moves' tips, radii and whether each is swept as a ball (1 or 0), a chunk
// of a bin's at a time.
struct MoveChunk {
  static constexpr size_t kSize = 64;
  double px[kSize], py[kSize], pz[kSize], qx[kSize], qy[kSize], qz[kSize],
      r[kSize], ball[kSize];
};

// Lanes at..at + n - 1 of *out from the chunk's first n moves: for a ball,
// z_r its lowest centre and r2 its radius squared; for another shape, z_r
// -inf and r2 the square of its radius widened as FootprintBounds widens
// it (the footprint's axis is a part of the move). Both forms are computed
// and one selected, so that the loop vectorizes.
SWARF_TARGET_CLONES
void FillReachLanes(const MoveChunk& c, size_t n, size_t at, ReachLanes* out) {
  float* __restrict x0 = out->x0.data() + at;
  float* __restrict x1 = out->x1.data() + at;
  float* __restrict y0 = out->y0.data() + at;
  float* __restrict y1 = out->y1.data() + at;
  float* __restrict low = out->low.data() + at;
  float* __restrict z_r = out->z_r.data() + at;
  float* __restrict r2 = out->r2.data() + at;
  constexpr float kNoBall = -std::numeric_limits<float>::infinity();
#pragma omp simd
  for (size_t q = 0; q < n; ++q) {
    const double r = c.r[q];
    const double z_min = MinOf(c.pz[q], c.qz[q]);
    const double reach = r * (1 + 1e-9) + 1e-6;
    const bool ball = c.ball[q] != 0;
    const float ball_z_r = FloatDown(z_min + r);
    const float ball_r2 = FloatUp(r * r);
    const float other_r2 = FloatUp(reach * reach);
    z_r[q] = ball ? ball_z_r : kNoBall;
    r2[q] = ball ? ball_r2 : other_r2;
    x0[q] = FloatDown(MinOf(c.px[q], c.qx[q]));
    x1[q] = FloatUp(MaxOf(c.px[q], c.qx[q]));
    y0[q] = FloatDown(MinOf(c.py[q], c.qy[q]));
    y1[q] = FloatUp(MaxOf(c.py[q], c.qy[q]));
    low[q] = FloatDown(z_min);
  }
}

// Each block of kReachBlock of m's lanes (the last may be shorter) into its
// lane of *blocks (sized for them): the union of its moves' lanes, as the
// moves come (std::min and std::max keep the first of equal values).
void BlockUnions(const ReachLanes& m, ReachLanes* blocks) {
  const size_t n = m.size();
  const float* __restrict x0 = m.x0.data();
  const float* __restrict x1 = m.x1.data();
  const float* __restrict y0 = m.y0.data();
  const float* __restrict y1 = m.y1.data();
  const float* __restrict low = m.low.data();
  const float* __restrict z_r = m.z_r.data();
  const float* __restrict r2 = m.r2.data();
  float* __restrict bx0 = blocks->x0.data();
  float* __restrict bx1 = blocks->x1.data();
  float* __restrict by0 = blocks->y0.data();
  float* __restrict by1 = blocks->y1.data();
  float* __restrict blow = blocks->low.data();
  float* __restrict bz_r = blocks->z_r.data();
  float* __restrict br2 = blocks->r2.data();
  for (size_t k = 0, q0 = 0; q0 < n; ++k, q0 += kReachBlock) {
    const size_t q1 = std::min(n, q0 + kReachBlock);
    float ux0 = x0[q0], ux1 = x1[q0], uy0 = y0[q0], uy1 = y1[q0],
          ulow = low[q0], uz_r = z_r[q0], ur2 = r2[q0];
    for (size_t q = q0 + 1; q < q1; ++q) {
      ux0 = std::min(ux0, x0[q]);
      ux1 = std::max(ux1, x1[q]);
      uy0 = std::min(uy0, y0[q]);
      uy1 = std::max(uy1, y1[q]);
      ulow = std::min(ulow, low[q]);
      uz_r = std::min(uz_r, z_r[q]);
      ur2 = std::max(ur2, r2[q]);
    }
    bx0[k] = ux0;
    bx1[k] = ux1;
    by0[k] = uy0;
    by1[k] = uy1;
    blow[k] = ulow;
    bz_r[k] = uz_r;
    br2[k] = ur2;
  }
}

}  // namespace

const MoveBinReach* MoveSweeps::BinReachOf(int32_t bin) const {
  thread_local MoveBinReach cache[kReachBins];
  thread_local int next = 0;
  const int64_t moves = moves_->size();
  for (MoveBinReach& b : cache) {
    if (b.bin == bin && b.serial == serial_ && b.moves == moves) return &b;
  }
  MoveBinReach& b = cache[next];
  next = (next + 1) % kReachBins;
  b.serial = 0;  // not valid until filled
  b.ids.clear();
  for (const uint32_t k : index_->Bin(bin)) {
    if (b.ids.size() == kMaxReachMoves) {
      b.bin = -1;
      return nullptr;
    }
    b.ids.push_back(k);
  }
  const size_t n = b.ids.size();
  b.move.Resize(n);
  // The moves' values a chunk at a time, then their lanes in one
  // vectorized pass: built move by move, a lane cost about 180
  // instructions (the marks' junction test fills a bin's lanes about once
  // for each bin a crease crosses).
  MoveChunk chunk;
  Move scratch;
  for (size_t q0 = 0; q0 < n; q0 += MoveChunk::kSize) {
    const size_t c = std::min(MoveChunk::kSize, n - q0);
    for (size_t q = 0; q < c; ++q) {
      const MoveView m = ViewAt(b.ids[q0 + q], &scratch);
      chunk.px[q] = m.from->x;
      chunk.py[q] = m.from->y;
      chunk.pz[q] = m.from->z;
      chunk.qx[q] = m.to->x;
      chunk.qy[q] = m.to->y;
      chunk.qz[q] = m.to->z;
      chunk.r[q] = m.cutter->radius;
      chunk.ball[q] = SweptAsBall(*m.cutter) ? 1.0 : 0.0;
    }
    FillReachLanes(chunk, c, q0, &b.move);
  }
  b.block.Resize((n + kReachBlock - 1) / kReachBlock);
  BlockUnions(b.move, &b.block);
  b.serial = serial_;
  b.bin = bin;
  b.moves = moves;
  return &b;
}

// Inlined: a call a move passed cost about 4% of LowestAt on
// BM_PlateMarks.
[[gnu::always_inline]] inline void MoveSweeps::TryLower(uint32_t k, double x,
                                                        double y, double* w,
                                                        int32_t* lowest,
                                                        Move* scratch) const {
  const MoveView m = ViewAt(k, scratch);
  if (!(std::min(m.from->z, m.to->z) < *w)) return;
  // A ball's height is at least this bound (a projection and two roots,
  // from the move alone): on the 30 mm plate it rules out 5 in 6 of the
  // moves the reach passes, for less than half of what their footprints
  // and heights cost. Not below w, the height is not either.
  if (SweptAsBall(*m.cutter) &&
      !(BallHeightLowerBound(*m.from, *m.to, m.cutter->radius, x, y) < *w)) {
    return;
  }
  // Beyond its footprint below w a move is not below w.
  if (FootprintSurelyMisses(*m.from, *m.to, *m.cutter, {x, y, x, y}, *w)) {
    return;
  }
  const std::optional<Rect> b = FootprintBounds(*m.from, *m.to, *m.cutter, *w);
  if (!b.has_value() || !b->Contains(x, y)) return;
  const double h = Height(static_cast<int32_t>(k), x, y);
  if (h < *w) {
    *w = h;
    *lowest = static_cast<int32_t>(k);
  }
}

double MoveSweeps::LowestAt(int32_t ei, int32_t ej, double x, double y,
                            double cap, int32_t* id) const {
  double w = cap;
  int32_t lowest = -1;
  Move scratch;
  // The exact tests, in the bin's order.
  const int32_t bin = index_->BinOfElement(ei, ej);
  const MoveBinReach* reach = BinReachOf(bin);
  if (reach == nullptr) {
    for (const uint32_t k : index_->Bin(bin)) {
      TryLower(k, x, y, &w, &lowest, &scratch);
    }
  } else {
    // Only the moves the widened boxes pass (w <= cap: no other is below
    // it here), in the same order: the same result.
    ForEachLaneBelow(*reach, SlackAbout({x, y, x, y}), cap, [&](size_t q) {
      TryLower(reach->ids[q], x, y, &w, &lowest, &scratch);
    });
  }
  if (id != nullptr) *id = lowest;
  return w;
}

NearMoves::NearMoves() : lanes_(std::make_unique<ReachLanes>()) {}
NearMoves::~NearMoves() = default;

void MoveSweeps::MovesNear(int32_t bin, const Rect& box, double cap,
                           NearMoves* near) const {
  near->bin_ = bin;
  near->box_ = box;
  near->cap_ = cap;
  near->ids_.clear();
  const MoveBinReach* reach = BinReachOf(bin);
  near->whole_bin_ = reach == nullptr;
  if (reach == nullptr) return;
  // LowestAt's blocks and lanes over the box widened as it widens a point:
  // a lane that passes at a point of the box below a cap <= this one
  // passes here (MayBeBelowIn), so these hold every move LowestAt tries
  // there, in the bin's order.
  const Rect area = SlackAbout(box);
  ReachLanes& lanes = *near->lanes_;
  const ReachLanes& from = reach->move;
  lanes.Resize(reach->ids.size());  // room for all; trimmed below
  size_t kept = 0;
  ForEachLaneBelow(*reach, area, cap, [&](size_t at) {
    lanes.x0[kept] = from.x0[at];
    lanes.x1[kept] = from.x1[at];
    lanes.y0[kept] = from.y0[at];
    lanes.y1[kept] = from.y1[at];
    lanes.low[kept] = from.low[at];
    lanes.z_r[kept] = from.z_r[at];
    lanes.r2[kept] = from.r2[at];
    near->ids_.push_back(reach->ids[at]);
    ++kept;
  });
  lanes.Resize(kept);
}

double MoveSweeps::LowestNear(const NearMoves& near, double x, double y,
                              double cap, int32_t* id) const {
  double w = cap;
  int32_t lowest = -1;
  Move scratch;
  if (near.whole_bin_) {
    for (const uint32_t k : index_->Bin(near.bin_)) {
      TryLower(k, x, y, &w, &lowest, &scratch);
    }
  } else {
    // The lanes LowestAt's test passes at the point, among those it passed
    // over the box: the same moves, in the same order.
    constexpr size_t kChunk = 256;
    uint8_t pass[kChunk];
    const Rect point = SlackAbout({x, y, x, y});
    const size_t n = near.ids_.size();
    for (size_t q0 = 0; q0 < n; q0 += kChunk) {
      const size_t c = std::min(kChunk, n - q0);
      MayBeBelowIn(*near.lanes_, q0, c, point, cap, pass);
      for (size_t q = 0; q < c; ++q) {
        if (pass[q] != 0) {
          TryLower(near.ids_[q0 + q], x, y, &w, &lowest, &scratch);
        }
      }
    }
  }
  if (id != nullptr) *id = lowest;
  return w;
}

void MoveSweeps::FillCandidates(ElementCorners* e) const {
  const int32_t ei = e->ei, ej = e->ej;
  const int32_t* corner_owner = e->owner;
  e->surfaces = this;
  e->candidates.clear();
  const double xs[4] = {e->x0, e->x1, e->x1, e->x0};
  const double ys[4] = {e->y0, e->y0, e->y1, e->y1};
  double cap = e->z_top;
  for (int k = 0; k < 4; ++k) {
    const int32_t o = corner_owner[k];
    if (o < 0 || o >= moves_->size()) continue;
    bool seen = false;
    for (int q = 0; q < k && !seen; ++q) seen = corner_owner[q] == o;
    if (seen) continue;
    e->candidates.push_back(o);
    double highest = -kInf;
    for (int q = 0; q < 4; ++q) {
      highest = std::max(highest, Height(o, xs[q], ys[q]));
    }
    cap = std::min(cap, highest);
  }
  const size_t owners = e->candidates.size();
  const Rect box{e->x0, e->y0, e->x1, e->y1};
  Move scratch;
  for (const uint32_t id : index_->Bin(index_->BinOfElement(ei, ej))) {
    const MoveView m = ViewAt(id, &scratch);
    if (!(std::min(m.from->z, m.to->z) < cap)) continue;
    bool owner = false;
    for (size_t q = 0; q < owners && !owner; ++q) {
      owner = e->candidates[q] == static_cast<int32_t>(id);
    }
    if (owner) continue;
    if (FootprintSurelyMisses(*m.from, *m.to, *m.cutter, box, cap)) continue;
    const std::optional<Rect> b =
        FootprintBounds(*m.from, *m.to, *m.cutter, cap);
    if (b.has_value() && b->Intersects(box)) {
      e->candidates.push_back(static_cast<int32_t>(id));
    }
  }
  std::sort(e->candidates.begin(), e->candidates.end());
}

double MoveSweeps::Height(int32_t id, double x, double y) const {
  const Sweep* s = SweepOf(id);
  return s != nullptr ? s->Height(x, y) : kInf;
}

SurfaceJet MoveSweeps::Jet(int32_t id, double x, double y) const {
  const Sweep* s = SweepOf(id);
  if (s == nullptr) return {kInf, 0, 0, 0, 0, 0};
  return s->JetAt(x, y);
}

ElementCorners Workpiece::Corners(int32_t ei, int32_t ej,
                                  bool prepare) const {
  const NodeValue n[4] = {Node(ei, ej), Node(ei + 1, ej), Node(ei + 1, ej + 1),
                          Node(ei, ej + 1)};
  const NodeValue* const nodes[4] = {&n[0], &n[1], &n[2], &n[3]};
  return CornersOf(ei, ej, nodes, prepare);
}

ElementCorners Workpiece::CornersOf(int32_t ei, int32_t ej,
                                    const NodeValue* const nodes[4],
                                    bool prepare) const {
  ElementCorners e;
  FillCorners(ei, ej, nodes, nullptr, &e);
  if (prepare) scheme_->Prepare(&e);
  return e;
}

void Workpiece::FillCorners(int32_t ei, int32_t ej,
                            const NodeValue* const nodes[4],
                            const CornerReach* const reaches[4],
                            ElementCorners* e) const {
  SetElementFrame(grid_, spec().z_top, ei, ej, e);
  const bool reach = scheme_->uses_reach();
  for (int k = 0; k < 4; ++k) {
    const NodeValue& n = *nodes[k];
    e->c[k] = n.jet;
    e->owner[k] = n.owner;
    if (n.owner >= 0 && reach) {
      e->reach[k] =
          reaches != nullptr ? *reaches[k] : surfaces_.Reach(n.owner, e->z_top);
    } else {
      e->reach[k] = CornerReach();
    }
  }
  e->candidates.clear();
  e->surfaces = nullptr;
  e->guard = ElementCorners::Guard();
  if (scheme_->uses_candidates()) surfaces_.FillCandidates(e);
  if (reach) e->surfaces = &surfaces_;
}

double Workpiece::Reconstruct(double x, double y) const {
  const Rect r = grid_.bounds();
  x = std::clamp(x, r.x0, r.x1);
  y = std::clamp(y, r.y0, r.y1);
  return scheme_->Reconstruct(Corners(grid_.ElementX(x), grid_.ElementY(y)),
                              x, y);
}

Sweep Workpiece::MoveSweep(int64_t id) const {
  const Move m = moves_.Get(id);
  return Sweep(m.from, m.to, m.cutter);
}

double Workpiece::MoveHeight(int64_t id, double x, double y) const {
  return MoveSweep(id).Height(x, y);
}

SurfaceJet Workpiece::MoveJet(int64_t id, double x, double y) const {
  return MoveSweep(id).JetAt(x, y);
}

double Workpiece::ExactHeightOver(std::span<const uint32_t> ids, double x,
                                  double y) const {
  double w = spec().z_top;
  for (uint32_t id : ids) w = std::min(w, MoveHeight(id, x, y));
  return w;
}

double Workpiece::ExactHeight(double x, double y) const {
  const Rect r = grid_.bounds();
  if (!r.Contains(x, y)) {
    // Outside the stock the index has no bins; look at every move.
    double w = spec().z_top;
    for (int64_t id = 0; id < move_count(); ++id) {
      w = std::min(w, MoveHeight(id, x, y));
    }
    return w;
  }
  double w = spec().z_top;
  for (const uint32_t id : index_.Bin(
           index_.BinOfElement(grid_.ElementX(x), grid_.ElementY(y)))) {
    w = std::min(w, MoveHeight(id, x, y));
  }
  return w;
}

int64_t Workpiece::allocated_tiles() const {
  return std::count_if(tiles_.begin(), tiles_.end(),
                       [](const auto& t) { return t != nullptr; });
}

int64_t Workpiece::allocated_node_bytes() const {
  return allocated_tiles() * kTileNodes * scheme_->bytes_per_node();
}

// The state format: a header, then each allocated tile in ascending order.
// header: "SWARFWP2", scheme kind (u32), nx, ny (i32), x0, y0, x1, y1, z_top
// (f64), version (u64), moves (u64), allocated tiles (u32)
// tile: index (u32), version (u64), w (f64 x kTileNodes), owner (i32 x
// kTileNodes).
// "SWARFWP1" states (written when derivatives were stored) are read too:
// their tiles of schemes with derivatives carry wx, wy, wxx, wxy, wyy
// (f32 x kTileNodes each) after the owners, which are checked and dropped
// (the owners' sweeps give them again, bit for bit).
namespace {

constexpr char kStateMagic[8] = {'S', 'W', 'A', 'R', 'F', 'W', 'P', '2'};
constexpr char kStateMagicV1[8] = {'S', 'W', 'A', 'R', 'F', 'W', 'P', '1'};

struct StateHeader {
  uint32_t scheme;
  int32_t nx, ny;
  double x0, y0, x1, y1, z_top;
  uint64_t version, moves;
  uint32_t tiles;
};

// Reads fixed-size values from a source of bytes.
class StateReader {
 public:
  explicit StateReader(absl::FunctionRef<bool(void*, size_t)> read)
      : read_(read) {}
  bool Read(void* out, size_t size) { return read_(out, size); }
  template <typename T>
  bool Read(T* out) {
    return Read(out, sizeof(T));
  }

 private:
  absl::FunctionRef<bool(void*, size_t)> read_;
};

// kMaxDerivative as a float: the largest derivative Apply stores.
constexpr float kMaxStoredDerivative = static_cast<float>(kMaxDerivative);
// Far below any cut (tool tips are above -kMaxCoordinate; the margin covers
// the sweep's rounding), and high enough that height differences divided by
// a grid step stay finite.
constexpr double kMinCutHeight = -2 * kMaxCoordinate;

}  // namespace

void Workpiece::SaveState(
    absl::FunctionRef<void(const void* data, size_t size)> sink) const {
  const StockSpec& st = spec();
  sink(kStateMagic, sizeof kStateMagic);
  const uint32_t scheme = static_cast<uint32_t>(scheme_->kind());
  sink(&scheme, 4);
  sink(&st.nx, 4);
  sink(&st.ny, 4);
  for (const double* v : {&st.x0, &st.y0, &st.x1, &st.y1, &st.z_top}) {
    sink(v, 8);
  }
  const uint64_t moves = moves_.size();
  sink(&version_, 8);
  sink(&moves, 8);
  const uint32_t tiles = static_cast<uint32_t>(allocated_tiles());
  sink(&tiles, 4);
  for (int32_t t = 0; t < tile_count(); ++t) {
    const Tile* tile = tiles_[t].get();
    if (tile == nullptr) continue;
    const uint32_t index = static_cast<uint32_t>(t);
    sink(&index, 4);
    sink(&tile_version_[t], 8);
    sink(tile->w, kTileNodes * sizeof(double));
    sink(tile->owner, kTileNodes * sizeof(int32_t));
  }
}

absl::Status Workpiece::Record(std::span<const Move> moves) {
  SWARF_RETURN_IF_ERROR(AdmitMoves(moves));
  for (size_t m = 0; m < moves.size(); ++m) {
    IndexMove(static_cast<uint32_t>(move_count() + m), moves[m], spec().z_top,
              &index_);
  }
  moves_.Append(moves);
  return absl::OkStatus();
}

absl::Status Workpiece::LoadState(std::string_view bytes) {
  return LoadState(
      [&](void* data, size_t size) {
        if (bytes.size() < size) return false;
        std::memcpy(data, bytes.data(), size);
        bytes.remove_prefix(size);
        return true;
      },
      [] { return absl::OkStatus(); });
}

absl::Status Workpiece::LoadState(
    absl::FunctionRef<bool(void* data, size_t size)> read,
    absl::FunctionRef<absl::Status()> verify) {
  StateReader in(read);
  char magic[8];
  StateHeader h;
  const bool v1 = in.Read(magic, 8) && std::memcmp(magic, kStateMagicV1, 8) == 0;
  if ((!v1 && std::memcmp(magic, kStateMagic, 8) != 0) ||
      !in.Read(&h.scheme) || !in.Read(&h.nx) || !in.Read(&h.ny) ||
      !in.Read(&h.x0) || !in.Read(&h.y0) || !in.Read(&h.x1) ||
      !in.Read(&h.y1) || !in.Read(&h.z_top) || !in.Read(&h.version) ||
      !in.Read(&h.moves) || !in.Read(&h.tiles)) {
    return absl::DataLossError("state: not a workpiece state (header)");
  }
  const StockSpec& st = spec();
  if (h.scheme != static_cast<uint32_t>(scheme_->kind()) || h.nx != st.nx ||
      h.ny != st.ny || !SameBits(h.x0, st.x0) || !SameBits(h.y0, st.y0) ||
      !SameBits(h.x1, st.x1) || !SameBits(h.y1, st.y1) ||
      !SameBits(h.z_top, st.z_top)) {
    return absl::DataLossError(
        "state: saved for another stock or scheme than this workpiece's");
  }
  if (h.moves != static_cast<uint64_t>(moves_.size())) {
    return absl::DataLossError(
        absl::StrCat("state: saved after ", h.moves,
                     " moves, the workpiece has ", moves_.size()));
  }
  // Each batch that cuts bumps the version once and holds at least one
  // move: a larger version is damage (and near 2^64 it would wrap to 0, the
  // version of a tile never cut, as the workpiece goes on cutting).
  if (h.version > h.moves) {
    return absl::DataLossError(absl::StrCat("state: version ", h.version,
                                            " after only ", h.moves,
                                            " moves"));
  }
  if (h.tiles > static_cast<uint32_t>(tile_count())) {
    return absl::DataLossError(absl::StrCat(
        "state: ", h.tiles, " tiles, the grid has ", tile_count()));
  }
  std::vector<std::unique_ptr<Tile>> tiles(tiles_.size());
  std::vector<uint64_t> tile_version(tiles_.size(), 0);
  const bool derivs = v1 && scheme_->stores_derivatives();
  std::vector<float> d[5];  // a v1 state's derivatives, checked, dropped
  const int32_t moves = static_cast<int32_t>(moves_.size());
  int64_t last = -1;
  for (uint32_t n = 0; n < h.tiles; ++n) {
    uint32_t t = 0;
    uint64_t version = 0;
    if (!in.Read(&t) || !in.Read(&version)) {
      return absl::DataLossError("state: truncated");
    }
    if (static_cast<int64_t>(t) <= last ||
        t >= static_cast<uint32_t>(tile_count()) || version == 0 ||
        version > h.version) {
      return absl::DataLossError(absl::StrCat(
          "state: tile ", t, " (version ", version, ") out of order or range"));
    }
    last = t;
    auto tile = std::make_unique<Tile>(arena_.get());  // derivs);
    if (!in.Read(tile->w, kTileNodes * sizeof(double)) ||
        !in.Read(tile->owner, kTileNodes * sizeof(int32_t))) {
      return absl::DataLossError("state: truncated");
    }
    if (derivs) {
      for (int c = 0; c < 5; ++c) {
        d[c].resize(kTileNodes);
        if (!in.Read(d[c].data(), kTileNodes * sizeof(float))) {
          return absl::DataLossError("state: truncated");
        }
      }
    }
    // What Apply guarantees: a node is uncut at the top, or cut strictly
    // below it (but not below what a move reaches) by a move of the
    // workpiece, with derivatives that BallSweep bounds (those of uncut
    // nodes are never read).
    for (int32_t k = 0; k < kTileNodes; ++k) {
      const int32_t o = tile->owner[k];
      const double w = tile->w[k];
      const bool ok = o == -1 ? SameBits(w, st.z_top)
                              : o >= 0 && o < moves && w >= kMinCutHeight &&
                                    w < st.z_top;
      if (!ok) {
        return absl::DataLossError(absl::StrCat(
            "state: tile ", t, " node ", k, " has height ", w,
            " and owner ", o));
      }
      for (int c = 0; derivs && o >= 0 && c < 5; ++c) {
        if (!(std::fabs(d[c][k]) <= kMaxStoredDerivative)) {
          return absl::DataLossError(absl::StrCat(
              "state: tile ", t, " node ", k, " has derivative ", d[c][k]));
        }
      }
    }
    tile->zmax = TileTop(static_cast<int32_t>(t), *tile);
    tile_version[t] = version;
    tiles[t] = std::move(tile);
  }
  char extra;
  if (in.Read(&extra, 1)) return absl::DataLossError("state: trailing bytes");
  SWARF_RETURN_IF_ERROR(verify());
  tiles_.swap(tiles);
  tile_version_.swap(tile_version);
  version_ = h.version;
  serial_ = NextSerial();  // cached jets were of the state replaced
  return absl::OkStatus();
}

}  // namespace swarf
