// A node grid visited band by band, so that the output writers never hold a
// whole-grid copy: `swarf run` streams the session's tiles (rows of tiles at
// a time), tests slice an in-memory grid.
//
// Contract:
// - ForEach calls `visit(band, e0, e1)` for consecutive element rows
//   [e0, e1), from 0 to ny, each once, in order; `band` holds node rows
//   [e0, e1] at least (SurfaceGrid::row0), with the same moves for every
//   band. The band is valid only during the call.
// - Every node is what the whole grid holds, bit for bit, so a writer that
//   reads element (ei, ej) only from the band that lists ej gives the
//   whole-grid path's result.
// - Not thread-safe: one ForEach at a time; visitors may use the pool.
#ifndef SWARF_CLIENT_GRID_BANDS_H_
#define SWARF_CLIENT_GRID_BANDS_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "client/outputs/surface_grid.h"
#include "core/scheme.h"
#include "core/stock.h"

namespace swarf::cli {

using BandVisitor = std::function<absl::Status(const SurfaceGrid& band,
                                               int32_t e0, int32_t e1)>;

class GridBands {
 public:
  virtual ~GridBands() = default;
  virtual const StockSpec& spec() const = 0;
  virtual SchemeKind scheme() const = 0;
  // Stops at the first error (of the source or of `visit`) and returns it.
  virtual absl::Status ForEach(const BandVisitor& visit) = 0;
  // Makes `band` (a SurfaceGrid::Band of this grid) hold node rows
  // [j0, j1] with their nodes (moves not set), read again: for writers that
  // come back to rows (the adaptive mesh). With `heights_only` the
  // derivatives and owners may be left out (zero, -1).
  virtual absl::Status ReadRows(int32_t j0, int32_t j1, SurfaceGrid* band,
                                bool heights_only = false) = 0;
  // The heights of node rows [j0, j1], each min(w, the stock top),
  // row-major (nx + 1 a row) into z: ReadRows(j0, j1, band, true)'s
  // heights, bit for bit. This reads them through `scratch` (a band of
  // this grid, left holding anything); sources that can read the heights
  // alone (8 bytes a node, not a band's 52) do so.
  virtual absl::Status ReadHeights(int32_t j0, int32_t j1, SurfaceGrid* scratch,
                                   double* z);
};

// An in-memory whole grid: one band (band_rows 0), or bands of `band_rows`
// element rows copied out of it (to prove the bands give the same files).
// `grid` is not owned and must outlive this.
class InMemoryBands : public GridBands {
 public:
  explicit InMemoryBands(const SurfaceGrid& grid, int32_t band_rows = 0)
      : grid_(grid), band_rows_(band_rows) {}
  const StockSpec& spec() const override { return grid_.spec; }
  SchemeKind scheme() const override { return grid_.scheme; }
  absl::Status ForEach(const BandVisitor& visit) override;
  absl::Status ReadRows(int32_t j0, int32_t j1, SurfaceGrid* band,
                        bool heights_only = false) override;

 private:
  const SurfaceGrid& grid_;
  const int32_t band_rows_;
};

// Bands of whole tile rows (kTileSize node rows), filled by `fill(band, t0,
// t1, heights_only)`, which must set every node of tile rows [t0, t1) that
// the band holds (SurfaceGrid::SetNodes; nodes it leaves are untouched
// stock), the heights only where `heights_only` says so. Each band
// holds the last node row of the previous one (carried over, not fetched
// again) and at most about `max_band_nodes` nodes (at least one tile row).
// The band's moves are set once from `moves` (SurfaceGrid::SetMoves), with
// `sweeps` where given: the same moves' sweeps already indexed over `spec`
// (the session's own, Workpiece::sweeps), so that they are not indexed
// again.
class TileRowBands : public GridBands {
 public:
  using Fill = std::function<absl::Status(SurfaceGrid* band, int32_t t0,
                                          int32_t t1, bool heights_only)>;
  TileRowBands(const StockSpec& spec, SchemeKind scheme, Fill fill,
               std::shared_ptr<const MoveSource> moves,
               int64_t max_band_nodes = 1 << 20);
  TileRowBands(const StockSpec& spec, SchemeKind scheme, Fill fill,
               std::shared_ptr<const MoveSource> moves,
               std::shared_ptr<const MoveSweeps> sweeps,
               int64_t max_band_nodes = 1 << 20);
  const StockSpec& spec() const override { return spec_; }
  SchemeKind scheme() const override { return scheme_; }
  absl::Status ForEach(const BandVisitor& visit) override;
  // The tile rows over [j0, j1], filled.
  absl::Status ReadRows(int32_t j0, int32_t j1, SurfaceGrid* band,
                        bool heights_only = false) override;
  // Heights read by `heights(j0, j1, z)` where set (SetHeightsFill), which
  // must write what ReadHeights' contract says; else through a band.
  using HeightsFill =
      std::function<absl::Status(int32_t j0, int32_t j1, double* z)>;
  void SetHeightsFill(HeightsFill heights) { heights_ = std::move(heights); }
  // Says that the fill writes every node of the tile rows it is given that
  // the band holds (as SurfaceGrid::SetTileRows does): the bands are then
  // resized for it (ResizeBand), not filled with untouched stock first.
  void SetFillWritesEveryNode() { fill_writes_every_node_ = true; }
  absl::Status ReadHeights(int32_t j0, int32_t j1, SurfaceGrid* scratch,
                           double* z) override;

 private:
  StockSpec spec_;
  SchemeKind scheme_;
  Fill fill_;
  std::shared_ptr<const MoveSource> moves_;
  std::shared_ptr<const MoveSweeps> sweeps_;  // null: the band indexes them
  int64_t max_band_nodes_;
  HeightsFill heights_;
  bool fill_writes_every_node_ = false;
};

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_GRID_BANDS_H_
