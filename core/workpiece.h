// A workpiece: stock, the aligned-line grid with one scheme's nodal
// parameters, and the moves applied to it.
//
// Nodes live in kTileSize x kTileSize tiles allocated on first cut; an
// unallocated tile is untouched stock (height z_top, flat, owner -1). Every
// tile has a version: the workpiece version of the last batch that changed
// one of its nodes (0: never changed).
//
// A node is lowered only where a sweep is strictly below it (on an exact tie
// the lower move id wins); it then takes that sweep's height and records the
// move id as its owner. Its derivatives (schemes that use them) are a pure
// function of (owner's sweep, node position): they are computed when read,
// once per tile version, and never stored (12 bytes per node, any scheme). The state is therefore a function of
// the set of moves, bit-identical whatever their order and batching.
//
// Thread safety: Apply must not run concurrently with anything else on the
// same workpiece; const methods may run concurrently with each other.
#ifndef SWARF_CORE_WORKPIECE_H_
#define SWARF_CORE_WORKPIECE_H_

#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "absl/functional/function_ref.h"
#include "absl/status/statusor.h"
#include "core/cutter/cutter.h"
#include "core/cutter/sweep.h"
#include "core/geometry.h"
#include "core/move_index.h"
#include "core/move_list.h"
#include "core/scheme.h"
#include "core/stock.h"
#include "core/thread_pool.h"
#include "core/tile_arena.h"
#include "core/unfilled_vector.h"

namespace swarf {

inline constexpr int32_t kTileBits = 6;
inline constexpr int32_t kTileSize = 1 << kTileBits;  // nodes per tile side
inline constexpr int32_t kTileNodes = kTileSize * kTileSize;

// Where the swept surface of `move` exists and how low it goes (for the
// guarded scheme): the XY capsule where it goes below z_top (the sweep's
// Footprint, at the footprint's exact radius) and its lowest tip.
CornerReach ReachOf(const Move& move, double z_top);

struct MoveBinReach;  // a bin's moves as LowestAt first tests them
struct ReachLanes;    // their lanes

// The moves of one bin that may be below a cap somewhere in a box, as
// LowestAt first tests them (MoveSweeps::MovesNear): for the points of a
// short stretch of a crease, that test taken once instead of at every
// point. Reused from box to box by one thread (its arrays only grow).
class NearMoves {
 public:
  NearMoves();
  ~NearMoves();
  NearMoves(const NearMoves&) = delete;
  NearMoves& operator=(const NearMoves&) = delete;
  // The bin, box and cap given to MovesNear (bin -1: none yet).
  int32_t bin() const { return bin_; }
  const Rect& box() const { return box_; }
  double cap() const { return cap_; }

 private:
  friend class MoveSweeps;
  int32_t bin_ = -1;
  Rect box_;
  double cap_ = 0;
  bool whole_bin_ = false;  // a bin too large to keep: every move is tried
  std::unique_ptr<ReachLanes> lanes_;
  std::vector<uint32_t> ids_;
};

// The exact swept surfaces of a list of moves, by index, and where each
// can reach: the exact scheme's MoveSurfaces. Thread-safe (each thread keeps
// the sweeps it built last, and the moves of the last bins LowestAt read:
// at most 8 bins of 2^14 moves, 32 bytes each). `moves` and `index` (not
// owned) must outlive it; they may grow between calls, not during them.
class MoveSweeps final : public MoveSurfaces {
 public:
  // `index` lists the moves by the bins their footprints reach (as
  // Workpiece indexes them).
  MoveSweeps(const MoveSource* moves, const MoveIndex* index);
  // Sharing `moves` (immutable while shared), indexed over the grid of
  // `spec` (validated) as a workpiece of that stock indexes them.
  MoveSweeps(std::shared_ptr<const MoveSource> moves, const StockSpec& spec);
  // The same over a MoveList of `moves`.
  MoveSweeps(std::span<const Move> moves, const StockSpec& spec);
  MoveSweeps(const MoveSweeps&) = delete;
  MoveSweeps& operator=(const MoveSweeps&) = delete;
  // +inf (and a zero jet) for an id outside the list.
  double Height(int32_t id, double x, double y) const override;
  SurfaceJet Jet(int32_t id, double x, double y) const override;
  double LowestAt(int32_t ei, int32_t ej, double x, double y, double cap,
                  int32_t* id = nullptr) const override;
  // The moves of `bin` that LowestAt's first test passes anywhere in `box`
  // below `cap`, into *near (for the box's points: LowestNear).
  void MovesNear(int32_t bin, const Rect& box, double cap,
                 NearMoves* near) const;
  // LowestAt(ei, ej, x, y, cap, id), bit for bit (the same moves tried in
  // the same order), for an element (ei, ej) of near.bin(), (x, y) in
  // near.box() and cap <= near.cap(), the moves unchanged since MovesNear.
  double LowestNear(const NearMoves& near, double x, double y, double cap,
                    int32_t* id = nullptr) const;
  // ReachOf(move id, z_top), kept per thread for the owners met last (a
  // node is a corner of four elements, an owner of many nodes).
  CornerReach Reach(int32_t id, double z_top) const;

  // Fills e->candidates (and e->surfaces) for element (e->ei, e->ej) of the
  // index's grid, whose corners e->c[k] are owned by e->owner[k] (-1:
  // uncut): the corners' owners, and every other move of the element's bin
  // that can dip below their surfaces somewhere in the element. Each sweep
  // is convex (the lower surface of a convex tool swept along a segment),
  // so over the element's rectangle it is highest at a corner: the least
  // of the owners' highest corner values bounds the machined surface over
  // the element from above (cap), and a move whose footprint below cap
  // (FootprintBounds) misses the rectangle cannot lower it. So the minimum
  // over the candidates is the exact surface everywhere in the element.
  void FillCandidates(ElementCorners* e) const override;

 private:
  const Sweep* SweepOf(int32_t id) const;
  // This thread's MoveBinReach of `bin`, filled on first use; null for a
  // bin too large to keep.
  const MoveBinReach* BinReachOf(int32_t bin) const;
  // LowestAt's exact tests of move k at (x, y): where it is below *w,
  // *w becomes its height and *lowest k.
  void TryLower(uint32_t k, double x, double y, double* w, int32_t* lowest,
                Move* scratch) const;
  // Move `id`: through MoveList's inline Get where the source is one (the
  // workpiece's own), without a virtual call per candidate.
  Move MoveAt(int64_t id) const {
    return list_ != nullptr ? list_->Get(id) : moves_->Get(id);
  }
  // The same without a copy where the source is a MoveList (else a copy
  // into *scratch).
  MoveView ViewAt(int64_t id, Move* scratch) const {
    if (list_ != nullptr) return list_->View(id);
    *scratch = moves_->Get(id);
    return {&scratch->from, &scratch->to, &scratch->cutter};
  }
  std::shared_ptr<const MoveSource> owned_;
  const MoveSource* moves_;
  const MoveList* list_;  // moves_ when it is a MoveList, else null
  std::unique_ptr<MoveIndex> owned_index_;
  const MoveIndex* index_;
  uint64_t serial_;  // tells this list's cached sweeps from others'
};

// Indexes move `id` in `index` when its footprint below z_top reaches the
// index's grid; returns the footprint's bounds then (nullopt: above the
// top or beside the stock).
std::optional<Rect> IndexMove(uint32_t id, const Move& move, double z_top,
                              MoveIndex* index);
// The bins IndexMove(id, move, z_top, &index) records the move under (an
// empty BinRect: none), for MoveIndex::AddAll. Thread-safe.
MoveIndex::BinRect IndexedBins(const Move& move, double z_top,
                               const MoveIndex& index);
// The same for an index over `grid` (a MoveIndexTally's).
MoveIndex::BinRect IndexedBins(const Move& move, double z_top,
                               const GridGeometry& grid);

// Physical bounds on moves (mm). With kMinRadius and kMaxRadius
// (core/cutter/cutter.h) they keep every intermediate value of the sweep
// finite (squares of coordinates, 1 / (1e-4 r)^3 at a rim).
inline constexpr double kMaxCoordinate = 1e9;

// Moves per workpiece are numbered from 0; ids are stored in int32.
inline constexpr int64_t kMaxMoves = (int64_t{1} << 31) - 1;

struct NodeValue {
  SurfaceJet jet;      // w and, for schemes that store them, derivatives
  int32_t owner = -1;  // id of the move that set the node, -1: stock top
};

// What one move of a batch cut (Workpiece::Apply with ApplyOptions::cuts):
// the node lowerings it made, in move order (the lowering of a node by a
// move is its height before that move, after the batch's earlier ones,
// minus the sweep's height there). Exact to the grid: summed over every
// move of a workpiece, removed_mm3 is the stock's volume minus the nodes'
// (each node standing for dx * dy).
struct MoveCut {
  double removed_mm3 = 0;  // sum of the lowerings times dx * dy
  double max_drop = 0;     // the largest lowering (mm), 0: cut nothing
  int32_t i = -1, j = -1;  // its node (-1: none)
  double z = 0;            // the node's height after that lowering
  // Sum of (lowering - drop_limit) times dx * dy over the lowerings deeper
  // than the move's ApplyOptions::drop_limit (0 without one).
  double over_limit_mm3 = 0;
};

struct ApplyOptions {
  bool cuts = false;  // fill ApplyResult::cuts
  // Per move of the batch (or empty): lowerings deeper than this are summed
  // into MoveCut::over_limit_mm3 (a flute length: the shank rubs).
  std::span<const double> drop_limit;
};

struct ApplyResult {
  int64_t first_move_id = 0;  // id of the batch's first move
  int64_t moves = 0;          // moves in the batch
  int64_t node_lowerings = 0;  // node updates (a node lowered twice counts 2)
  uint64_t version = 0;       // workpiece version after the batch
  std::vector<int32_t> changed_tiles;  // ascending tile indices
  UnfilledVector<MoveCut> cuts;        // per move, with ApplyOptions::cuts
};

class Workpiece {
 public:
  // `pool` (not owned, may be null for ThreadPool::Default()) must outlive
  // the workpiece.
  static absl::StatusOr<std::unique_ptr<Workpiece>> Create(
      const StockSpec& spec, SchemeKind scheme, ThreadPool* pool = nullptr);

  // InvalidArgument naming the move index and field for a coordinate that
  // is not finite or beyond kMaxCoordinate, or a cutter ValidateCutter
  // refuses ("moves[k].cutter.radius ...").
  static absl::Status ValidateMoves(std::span<const Move> moves);

  // Applies a batch whole, or nothing on error. Move ids continue from the
  // previous batch.
  absl::StatusOr<ApplyResult> Apply(std::span<const Move> moves);
  // The same, and what each move cut (options.cuts); the nodes end
  // bit-identical to Apply(moves).
  absl::StatusOr<ApplyResult> Apply(std::span<const Move> moves,
                                    const ApplyOptions& options);

  // Snapshots: restoring a workpiece without redoing every cut.
  //
  // SaveState writes the nodal state (the allocated tiles' parameters and
  // owners, the tile versions and the workpiece version; not the moves) to
  // `sink`, piece by piece, in a little-endian format LoadState reads.
  // Only heights and owners: derivatives follow from the owners' moves.
  void SaveState(
      absl::FunctionRef<void(const void* data, size_t size)> sink) const;
  // Appends moves whose cuts the nodal state already holds (as LoadState
  // restores it): they get ids and are indexed, and nothing is cut.
  // Validated as Apply validates.
  absl::Status Record(std::span<const Move> moves);
  // Replaces the nodal state by a saved one. The workpiece must have the
  // saved one's stock and scheme and exactly as many moves (the same moves,
  // re-added with Record); it is then bit-identical to the saved workpiece,
  // and so is every later Apply. DataLoss naming the problem for bytes that
  // are not such a state; the workpiece is then unchanged.
  absl::Status LoadState(std::string_view bytes);
  // The same, reading the state piece by piece: read(data, size) fills
  // `data` with the next `size` bytes, or returns false at the end (the
  // state must be followed by the end). Once all is read and found valid,
  // verify() may still refuse it (a checksum over what was read): its error
  // is returned and the workpiece is unchanged.
  absl::Status LoadState(absl::FunctionRef<bool(void* data, size_t size)> read,
                         absl::FunctionRef<absl::Status()> verify);

  const GridGeometry& grid() const { return grid_; }
  const StockSpec& spec() const { return grid_.spec(); }
  const Scheme& scheme() const { return *scheme_; }

  int64_t move_count() const { return moves_.size(); }
  // Move `id` (0 <= id < move_count()), by value: MoveList keeps moves
  // compactly.
  Move move(int64_t id) const { return moves_.Get(id); }
  const MoveList& moves() const { return moves_; }
  // Bytes the moves and their index hold.
  int64_t move_bytes() const {
    return moves_.MemoryBytes() + index_.MemoryBytes();
  }
  uint64_t version() const { return version_; }

 private:
  struct TileJets;

 public:
  // Tile jets kept for one traversal of the nodes (MeasureError's bins,
  // FindCuttingMarks' bands): its own tiles, so that traversals running at
  // once do not evict each other's, sized for how far the traversal reaches
  // back. Holds at most `tiles` tiles (80 KiB each), evicting the oldest
  // computed first. Thread-safe: the threads of one traversal share it.
  // Made by NewJetCache or TraversalJetCache for one workpiece, used only
  // with it and only while it does not change (no Apply, no LoadState).
  class JetCache {
   public:
    JetCache(const JetCache&) = delete;
    JetCache& operator=(const JetCache&) = delete;
    ~JetCache();
    size_t capacity() const { return capacity_; }

   private:
    friend class Workpiece;
    JetCache(int32_t tile_count, size_t tiles);
    // Tile t's jets if they are of `serial` and `version`, else null.
    std::shared_ptr<const TileJets> Find(int32_t t, uint64_t serial,
                                         uint64_t version) const;
    void Insert(int32_t t, std::shared_ptr<const TileJets> jets);
    const size_t capacity_;
    mutable std::mutex mu_;
    std::vector<std::shared_ptr<const TileJets>> jets_;  // per tile
    std::deque<int32_t> order_;  // cached tiles, oldest first
  };
  // A cache of at most `tiles` tiles (at least 1).
  std::unique_ptr<JetCache> NewJetCache(size_t tiles) const;
  // A cache for a traversal that goes over the grid in order of rows of
  // tiles and reads each node row of a tile row several times (by bins or
  // bands a fraction of a tile high), or a node row past it, its threads
  // reading up to `rows_at_once` consecutive node rows at a time (all its
  // threads' bands together): the tile rows those span, two at least, and
  // some, so that each tile's jets are computed once; at most
  // kTraversalJetBytes (a grid wider than that allows computes a tile's
  // jets once per pass of the traversal over its tile row instead).
  std::unique_ptr<JetCache> TraversalJetCache(
      int32_t rows_at_once = kTileSize) const;
  static constexpr size_t kTraversalJetBytes = size_t{256} << 20;

  // Node (i, j), 0 <= i <= nx, 0 <= j <= ny.
  NodeValue Node(int32_t i, int32_t j) const;
  // The same, the jets kept in `cache` (from this workpiece's
  // NewJetCache or TraversalJetCache) instead of the workpiece's own
  // cache (kJetCacheTiles).
  NodeValue Node(int32_t i, int32_t j, JetCache* cache) const;
  // Node (i, j)'s owner (-1: uncut), without its jet: Node(i, j).owner.
  int32_t OwnerAt(int32_t i, int32_t j) const;
  // Node (i, j)'s height alone (no derivatives): Node(i, j).jet.w.
  double HeightAt(int32_t i, int32_t j) const;
  // An upper bound on the heights of tile t's nodes (z_top when uncut).
  double TileMax(int32_t t) const;
  // Element (ei, ej), 0 <= ei < nx, 0 <= ej < ny, with the corners'
  // owners, each cut corner's reach (ReachOf its owner), the candidates and
  // the moves' surfaces where the scheme uses them, prepared by the scheme
  // (Scheme::Prepare) unless `prepare` is false (the caller prepares it).
  ElementCorners Corners(int32_t ei, int32_t ej, bool prepare = true) const;
  // The same from the element's four nodes already read (Node(), in the
  // order of ElementCorners::c): for callers that visit each node of a
  // region once instead of once per element it belongs to.
  ElementCorners CornersOf(int32_t ei, int32_t ej,
                           const NodeValue* const nodes[4],
                           bool prepare = true) const;
  // CornersOf(ei, ej, nodes, false) written over *e (every field), for a
  // caller that reuses one ElementCorners from element to element. `reaches`
  // (may be null): the corners' reaches already taken (read only for cut
  // corners, where the scheme uses_reach()), as sweeps().Reach gives them.
  void FillCorners(int32_t ei, int32_t ej, const NodeValue* const nodes[4],
                   const CornerReach* const reaches[4],
                   ElementCorners* e) const;
  // The scheme's reconstructed surface at a point of the stock (clamped to
  // the stock rectangle).
  double Reconstruct(double x, double y) const;
  // The one exact-surface entry point: the sweep of move `id`
  // (0 <= id < move_count()), its height at (x, y) (+inf where the tool
  // never passes), and its height and derivatives there (as the taylor
  // scheme stores them, before float rounding). The valuation, the cutting
  // marks and the exact-height queries all go through these.
  Sweep MoveSweep(int64_t id) const;
  double MoveHeight(int64_t id, double x, double y) const;
  SurfaceJet MoveJet(int64_t id, double x, double y) const;
  // The true machined surface: the minimum of the stock top and of every
  // sweep at (x, y).
  double ExactHeight(double x, double y) const;
  // Minimum of the top and the sweeps of the given move ids at (x, y).
  double ExactHeightOver(std::span<const uint32_t> ids, double x,
                         double y) const;

  // The nodes of tile t: columns [i0, i0 + nx), rows [j0, j0 + ny) (fewer
  // than kTileSize at the grid's far edges).
  struct TileExtent {
    int32_t i0 = 0, j0 = 0, nx = 0, ny = 0;
  };
  TileExtent Extent(int32_t t) const;
  // Copies tile t's nodes, row-major ((j - j0) * nx + (i - i0)), into the
  // non-null outputs of nx * ny entries each: heights, the five
  // derivatives (zeros for schemes without them, and for uncut nodes), and
  // owners (-1 for uncut nodes).
  // Derivatives are copied from the cache when PrepareJets (or another
  // reader: Node, the valuation) computed them for this tile version, else
  // computed from the owners' sweeps straight into d on the calling thread
  // (not cached). Thread-safe: a reader of many tiles (GetTiles) reads
  // them on the pool's threads at once.
  void ReadTile(int32_t t, double* w, float* const d[5], int32_t* owner) const;
  // Copies the heights of grid rows [j0, j1] (inclusive, within tile t's
  // extent) of tile t, its nx = Extent(t).nx nodes a row, to out + (j - j0)
  // * stride: the same values as ReadTile's, straight into a caller's rows
  // (a reader of a few rows of many tiles needs no tile-sized copy first).
  // Thread-safe as ReadTile.
  void ReadTileHeights(int32_t t, int32_t j0, int32_t j1, double* out,
                       int64_t stride) const;
  // Computes the derivatives of the listed tiles (any order; unallocated
  // tiles and those already cached are skipped) in parallel on the pool,
  // and caches them for the reads that follow (ReadTile copies them, Node
  // and the valuation read them). Keeps at most kJetCacheTiles of them (the
  // first ones listed), and the cache keeps the last kJetCacheTiles tiles
  // computed: list fewer than that. A no-op for schemes without
  // derivatives. Thread-safe.
  void PrepareJets(std::span<const int32_t> tiles) const;

  // The reconstructed surface's gradient at (x, y) (clamped to the stock):
  // of the lowest patch for taylor, of the bilinear function for zmap.
  void ReconstructGradient(double x, double y, double* gx, double* gy) const;

  int32_t tiles_x() const { return tiles_x_; }
  int32_t tiles_y() const { return tiles_y_; }
  int32_t tile_count() const { return tiles_x_ * tiles_y_; }
  bool TileAllocated(int32_t t) const { return tiles_[t] != nullptr; }
  // Tiles whose jets are kept for reads (80 KiB each): bounded, so that
  // memory per node stays the 12 bytes of height and owner.
  static constexpr size_t kJetCacheTiles = 128;
  uint64_t TileVersion(int32_t t) const { return tile_version_[t]; }
  int64_t allocated_tiles() const;
  // Bytes held by allocated tiles' nodal parameters.
  int64_t allocated_node_bytes() const;

  const MoveIndex& index() const { return index_; }
  // The moves' exact surfaces, by id (the exact scheme's).
  const MoveSurfaces& surfaces() const { return surfaces_; }
  // The same, as the concrete type (its Reach, for a reader of the
  // workpiece's own moves outside it).
  const MoveSweeps& sweeps() const { return surfaces_; }
  ThreadPool& pool() const { return *pool_; }

  ~Workpiece();

 private:
  struct Tile;
  Workpiece(const StockSpec& spec, const Scheme& scheme, ThreadPool* pool);
  std::unique_ptr<Tile> NewTile() const;
  // ValidateMoves, and ResourceExhausted past kMaxMoves (Apply and Record).
  absl::Status AdmitMoves(std::span<const Move> moves) const;
  // The highest node of tile t (what CutTile caps cuts with).
  double TileTop(int32_t t, const Tile& tile) const;
  // With `cuts` non-null, appends (batch move, what it cut here) for every
  // move that lowered a node of the tile, in move order.
  struct TileCut {
    uint32_t m;
    MoveCut cut;
  };
  int64_t CutTile(int32_t t, Tile* tile, std::span<const Sweep> sweeps,
                  std::span<const uint32_t> batch_moves, int64_t first_id,
                  std::span<const double> drop_limit = {},
                  std::vector<TileCut>* cuts = nullptr) const;

  // The derivatives of tile t's nodes at its current version, computed from
  // the owners' sweeps once and cached in `cache` (thread-safe). The
  // reference stays valid until this thread's next call (the thread keeps
  // the last one).
  const TileJets& Jets(int32_t t, JetCache* cache) const;
  // Jets() past its hit test.
  const TileJets& JetsMiss(int32_t t, JetCache* cache) const;
  // Tile t's jets in the workpiece's cache if they are of `version` (and
  // this state), else null.
  std::shared_ptr<const TileJets> CachedJets(int32_t t,
                                             uint64_t version) const;
  // Computes tile t's jets (at `version`, its current one) and caches them
  // in `cache`.
  std::shared_ptr<const TileJets> NewJets(int32_t t, uint64_t version,
                                          JetCache* cache) const;
  // Tile t's jets into d[c] (row j at d[c] + j * stride, only its cut
  // columns [lo[j], hi[j]] written). With nx = Extent(t).nx: 0 <= lo[j] <=
  // nx and hi[j] < nx; a row with no cut node has lo[j] = nx, hi[j] = nx - 1.
  void ComputeJets(int32_t t, const Tile& tile, int32_t stride, int8_t* lo,
                   int8_t* hi, float* const d[5]) const;

  const GridGeometry grid_;
  const Scheme* scheme_;
  ThreadPool* pool_;
  int32_t tiles_x_, tiles_y_;
  std::vector<std::unique_ptr<Tile>> tiles_;
  std::vector<uint64_t> tile_version_;
  std::unique_ptr<TileArena> arena_;
  uint64_t version_ = 0;
  MoveList moves_;
  MoveIndex index_;
  uint64_t serial_;  // changes when LoadState replaces the nodes
  const bool derivatives_;  // scheme_->stores_derivatives()
  MoveSweeps surfaces_{&moves_, &index_};
  // The workpiece's own cache (Node, PrepareJets, ReadTile).
  mutable JetCache jets_;
  // Apply's arrays for a batch, kept from batch to batch (Apply only).
  struct ApplyScratch;
  std::unique_ptr<ApplyScratch> apply_scratch_;
};

}  // namespace swarf

#endif  // SWARF_CORE_WORKPIECE_H_
