// The node grid of a simulated workpiece as plain data: what `swarf run`
// fetches from the server (tiles of heights, derivatives and owners), or a
// copy of an in-process Workpiece. The output writers work on this.
//
// Contract:
// - Units: millimetres. Node (i, j) lies at GridGeometry(spec).NodeX(i),
//   NodeY(j), exactly as in the core, so reconstructions are bit-identical to
//   Workpiece::Reconstruct for the same nodes.
// - jets and owners are row-major: index (j - row0) * (nx + 1) + i. Untouched
//   nodes are flat at z_top with owner -1. For zmap only jets[].w is used.
// - A band (Band) holds node rows [row0, row0 + held_rows()) only: the
//   writers stream a session's grid band by band (grid_bands.h) and
//   element (ei, ej) is readable where node rows ej and ej + 1 are held. A
//   whole grid has row0 0 and every row.
#ifndef SWARF_CLIENT_SURFACE_GRID_H_
#define SWARF_CLIENT_SURFACE_GRID_H_

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/scheme.h"
#include "core/stock.h"
#include "core/surface_jet.h"
#include "core/unfilled_vector.h"
#include "core/workpiece.h"

namespace swarf::cli {

struct SurfaceGrid {
  StockSpec spec;
  SchemeKind scheme = SchemeKind::kGuarded;
  UnfilledVector<SurfaceJet> jets;  // (nx + 1) * held rows, row-major
  UnfilledVector<int32_t> owners;   // same size; -1: stock top
  int32_t row0 = 0;              // first node row held
  // The session's moves by id (null: none), for the guarded scheme's
  // reach of each owner (ReachOf). Owners beyond them have an unbounded
  // reach. Immutable, shared by copies: the client's program (cli::
  // RunMoveSource) rather than a copy of each move.
  std::shared_ptr<const MoveSource> moves;
  // The same moves' sweeps, indexed by bin, for the schemes that use them
  // (guarded: each owner's reach, kept per thread; exact): null for the
  // others or without moves. Immutable, shared by copies.
  std::shared_ptr<const MoveSweeps> surfaces;

  // Sets moves and surfaces.
  void SetMoves(std::shared_ptr<const MoveSource> moves);
  // The same over a MoveList of `moves`.
  void SetMoves(std::span<const Move> moves);
  // Sets moves and, where the scheme uses them, `sweeps`: the same moves'
  // sweeps already indexed over this grid's stock (a session's own,
  // Workpiece::sweeps), instead of indexing them again.
  void SetMoves(std::shared_ptr<const MoveSource> moves,
                std::shared_ptr<const MoveSweeps> sweeps);
  int64_t move_count() const { return moves != nullptr ? moves->size() : 0; }

  // Untouched stock: every node at z_top, flat, owner -1. InvalidArgument
  // for a spec ValidateStock rejects, or more than kMaxGridNodes nodes.
  static absl::StatusOr<SurfaceGrid> Uncut(const StockSpec& spec,
                                           SchemeKind scheme);
  // Node rows [row0, row0 + rows) of untouched stock (rows clamped to the
  // grid), for streaming; InvalidArgument as Uncut or for rows outside it.
  static absl::StatusOr<SurfaceGrid> Band(const StockSpec& spec,
                                          SchemeKind scheme, int32_t row0,
                                          int32_t rows);
  // Makes this band hold node rows [row0, row0 + rows) (clamped to the
  // grid), untouched stock, keeping the moves and the storage's capacity.
  void ResetBand(int32_t row0, int32_t rows);
  // The same rows with their nodes unset (whatever the storage held): for a
  // caller that then writes every node, as SetTileRows does for its tile
  // rows, without a pass over 52 bytes a node first.
  void ResizeBand(int32_t row0, int32_t rows);
  // Room for `rows` node rows (clamped to the grid), so that ResetBand up
  // to that many allocates nothing; the rows held are unchanged.
  void ReserveRows(int32_t rows);

  // A copy of every node of `wp` (derivatives widened from the core's
  // floats, as ReadTile gives them).
  static absl::StatusOr<SurfaceGrid> FromWorkpiece(const Workpiece& wp);
  // Copies the nodes of wp's tile rows [t0, t1) that this grid or band
  // holds, as FromWorkpiece does (heights only, zero derivatives and owner
  // -1, with `heights_only`), and sets those of unallocated tiles to
  // untouched stock: every node of those rows that it holds is written
  // (after ResizeBand too). wp must have this grid's stock. Uses wp's
  // threads and jet cache.
  absl::Status SetTileRows(const Workpiece& wp, int32_t t0, int32_t t1,
                           bool heights_only = false);

  // Copies a block of nx x ny nodes with first node (i0, j0), row-major
  // ((j - j0) * nx + (i - i0)), as in Workpiece::ReadTile and the service's
  // Tile message. `d` (wx, wy, wxx, wxy, wyy) and `owner` may be null: zero
  // derivatives, owner -1. InvalidArgument if the block leaves the grid;
  // rows the band does not hold are skipped.
  absl::Status SetNodes(int32_t i0, int32_t j0, int32_t nx, int32_t ny,
                        const double* w, const float* const d[5],
                        const int32_t* owner);

  // Sizes consistent with the spec, spec valid.
  absl::Status Validate() const;

  GridGeometry geometry() const { return GridGeometry(spec); }
  int32_t nodes_x() const { return spec.nx + 1; }
  int32_t nodes_y() const { return spec.ny + 1; }
  int32_t held_rows() const {
    return nodes_x() > 0 ? static_cast<int32_t>(jets.size() / nodes_x()) : 0;
  }
  int64_t Index(int32_t i, int32_t j) const {
    return int64_t{j - row0} * nodes_x() + i;
  }
  const SurfaceJet& jet(int32_t i, int32_t j) const {
    return jets[Index(i, j)];
  }
  int32_t owner(int32_t i, int32_t j) const { return owners[Index(i, j)]; }

  // Element (ei, ej), 0 <= ei < nx, 0 <= ej < ny; prepared
  // (Scheme::Prepare) unless `prepare` is false (the caller prepares it).
  ElementCorners Corners(int32_t ei, int32_t ej, bool prepare = true) const;
  // Corners(ei, ej, false) into *e, which may hold another element's:
  // every field but e->guard is written (Scheme::Prepare writes that).
  void FillCorners(int32_t ei, int32_t ej, ElementCorners* e) const;
  // The scheme's reconstruction at any point of the stock (clamped to the
  // stock rectangle), as Workpiece::Reconstruct.
  double Height(double x, double y) const;
  // Its gradient there, as Workpiece::ReconstructGradient: for taylor the
  // lowest patch's (exact normals of the patches), for zmap the bilinear's.
  void Gradient(double x, double y, double* gx, double* gy) const;
  // Both at once (one element lookup).
  double HeightAndGradient(double x, double y, double* gx, double* gy) const;
  // Lowest node height held (z_top if uncut).
  double MinNodeHeight() const;
};

// The node heights of rows [j0, j1] of wp's grid, each min(w, the stock
// top), row-major (nx + 1 a row) into z: what SetTileRows(wp, ...,
// heights_only) and min(jet(i, j).w, spec.z_top) give, bit for bit, without
// a band (8 bytes a node, not 52). The tiles are read on wp's threads.
void ReadNodeHeights(const Workpiece& wp, int32_t j0, int32_t j1, double* z);

// Reconstructs a grid at many points for one thread, as
// SurfaceGrid::HeightAndGradient does bit for bit, keeping what neighbouring
// points share: the last element's corners (prepared, Scheme::Prepare) for
// the next points in it, and for the guarded scheme the trust regions
// (TrustRegion) of the cut nodes of the last few node rows, from which
// elements are prepared (PrepareGuarded). Cheapest when points come row by
// row. Not thread-safe; `grid` must outlive it and stay unchanged.
class SurfaceSampler {
 public:
  explicit SurfaceSampler(const SurfaceGrid& grid);
  // Only for points whose elements' nodes lie in node columns [i0, i1]
  // (clamped to the grid): its caches span those columns, not a row.
  SurfaceSampler(const SurfaceGrid& grid, int32_t i0, int32_t i1);
  double HeightAndGradient(double x, double y, double* gx, double* gy);
  // The reconstruction of element (ei, ej) at n points of it (its closed
  // rectangle: points on its edges are taken from this element), as
  // Scheme::ReconstructMany on the element prepared as above.
  void ReconstructInElement(int32_t ei, int32_t ej, const double* x,
                            const double* y, int32_t n, double* out);

 private:
  void Select(int32_t ei, int32_t ej);
  // Node (i, j)'s trust region, and in *sure whether it surely holds each
  // of the node's elements that Select may take (SurelyTrusted).
  const PatchTrustRegion* Region(int32_t i, int32_t j, bool* sure);

  const SurfaceGrid& grid_;
  const Scheme& scheme_;
  int32_t i0_ = 0, columns_ = 0;  // the node columns the caches span
  int32_t ei_ = -1, ej_ = -1;     // the element e_ holds
  ElementCorners e_;
  // Regions of node rows row_[k] (-1: none), computed where has_[k] says.
  static constexpr int kRows = 4;
  int32_t row_[kRows] = {-1, -1, -1, -1};
  std::vector<PatchTrustRegion> regions_[kRows];
  enum : uint8_t { kNotYet, kTested, kSure };
  std::vector<uint8_t> has_[kRows];
  double tallest_[kRows] = {};  // the row's taller element row
  double widest_ = 0;           // the widest element in the columns
  int next_ = 0;
};

// Largest grid the writers accept (nodes): 16 Ki x 16 Ki.
inline constexpr int64_t kMaxGridNodes = int64_t{1} << 28;

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_SURFACE_GRID_H_
