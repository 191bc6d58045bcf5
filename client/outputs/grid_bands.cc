#include "client/outputs/grid_bands.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_format.h"
#include "core/thread_pool.h"
#include "core/workpiece.h"

namespace swarf::cli {

namespace {

// The check every row read starts with: node rows [j0, j1] of the grid.
absl::Status CheckNodeRows(const StockSpec& spec, int32_t j0, int32_t j1) {
  if (j0 < 0 || j1 < j0 || j1 > spec.ny) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "node rows [%d, %d] leave the grid's %d rows", j0, j1, spec.ny + 1));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status InMemoryBands::ForEach(const BandVisitor& visit) {
  if (absl::Status st = grid_.Validate(); !st.ok()) return st;
  const int32_t ny = grid_.spec.ny;
  if (band_rows_ <= 0 || band_rows_ >= ny) return visit(grid_, 0, ny);
  auto band = SurfaceGrid::Band(grid_.spec, grid_.scheme, 0, 1);
  if (!band.ok()) return band.status();
  band->moves = grid_.moves;
  band->surfaces = grid_.surfaces;
  const size_t nx = static_cast<size_t>(grid_.nodes_x());
  for (int32_t e0 = 0; e0 < ny; e0 += band_rows_) {
    const int32_t e1 = std::min(ny, e0 + band_rows_);
    band->ResizeBand(e0, e1 - e0 + 1);  // every node copied in
    std::copy_n(grid_.jets.begin() + grid_.Index(0, e0), band->jets.size(),
                band->jets.begin());
    std::copy_n(grid_.owners.begin() + grid_.Index(0, e0), band->owners.size(),
                band->owners.begin());
    (void)nx;
    if (absl::Status st = visit(*band, e0, e1); !st.ok()) return st;
  }
  return absl::OkStatus();
}

absl::Status GridBands::ReadHeights(int32_t j0, int32_t j1,
                                    SurfaceGrid* scratch, double* z) {
  if (absl::Status st = ReadRows(j0, j1, scratch, /*heights_only=*/true);
      !st.ok()) {
    return st;
  }
  const int32_t nx = scratch->nodes_x();
  const double z_top = scratch->spec.z_top;
  ThreadPool::Default().ParallelFor(j1 - j0 + 1, [&](int64_t r) {
    const int32_t j = j0 + static_cast<int32_t>(r);
    for (int32_t i = 0; i < nx; ++i) {
      z[r * nx + i] = std::min(scratch->jet(i, j).w, z_top);
    }
  });
  return absl::OkStatus();
}

absl::Status TileRowBands::ReadHeights(int32_t j0, int32_t j1,
                                       SurfaceGrid* scratch, double* z) {
  if (heights_ == nullptr) return GridBands::ReadHeights(j0, j1, scratch, z);
  if (absl::Status st = CheckNodeRows(spec_, j0, j1); !st.ok()) return st;
  return heights_(j0, j1, z);
}

absl::Status InMemoryBands::ReadRows(int32_t j0, int32_t j1, SurfaceGrid* band,
                                     bool) {
  if (absl::Status st = CheckNodeRows(grid_.spec, j0, j1); !st.ok()) {
    return st;
  }
  band->ResizeBand(j0, j1 - j0 + 1);  // every node copied in
  std::copy_n(grid_.jets.begin() + grid_.Index(0, j0), band->jets.size(),
              band->jets.begin());
  std::copy_n(grid_.owners.begin() + grid_.Index(0, j0), band->owners.size(),
              band->owners.begin());
  return absl::OkStatus();
}

absl::Status TileRowBands::ReadRows(int32_t j0, int32_t j1, SurfaceGrid* band,
                                    bool heights_only) {
  if (absl::Status st = CheckNodeRows(spec_, j0, j1); !st.ok()) return st;
  if (fill_writes_every_node_) {
    band->ResizeBand(j0, j1 - j0 + 1);
  } else {
    band->ResetBand(j0, j1 - j0 + 1);
  }
  return fill_(band, j0 / kTileSize, j1 / kTileSize + 1, heights_only);
}

TileRowBands::TileRowBands(const StockSpec& spec, SchemeKind scheme, Fill fill,
                           std::shared_ptr<const MoveSource> moves,
                           int64_t max_band_nodes)
    : TileRowBands(spec, scheme, std::move(fill), std::move(moves), nullptr,
                   max_band_nodes) {}

TileRowBands::TileRowBands(const StockSpec& spec, SchemeKind scheme, Fill fill,
                           std::shared_ptr<const MoveSource> moves,
                           std::shared_ptr<const MoveSweeps> sweeps,
                           int64_t max_band_nodes)
    : spec_(spec),
      scheme_(scheme),
      fill_(std::move(fill)),
      moves_(std::move(moves)),
      sweeps_(std::move(sweeps)),
      max_band_nodes_(max_band_nodes) {}

absl::Status TileRowBands::ForEach(const BandVisitor& visit) {
  auto made = SurfaceGrid::Band(spec_, scheme_, 0, 1);
  if (!made.ok()) return made.status();
  SurfaceGrid& band = *made;
  if (sweeps_ != nullptr) {
    band.SetMoves(moves_, sweeps_);
  } else {
    band.SetMoves(moves_);
  }
  const int32_t ny = spec_.ny, nodes_x = spec_.nx + 1;
  const int32_t tiles_y = (ny + 1 + kTileSize - 1) / kTileSize;
  const int64_t tile_row_nodes = int64_t{kTileSize} * nodes_x;
  const int32_t per_band = static_cast<int32_t>(
      std::clamp<int64_t>(max_band_nodes_ / tile_row_nodes, 1, tiles_y));
  // Room for the largest band (its tile rows and the row before them) at
  // once: the second band, a row longer, allocated it all again.
  band.ReserveRows(per_band * kTileSize + 1);
  std::vector<SurfaceJet> carry_jets;
  std::vector<int32_t> carry_owners;
  int32_t e0 = 0;
  absl::Status status;
  for (int32_t t0 = 0; t0 < tiles_y && status.ok(); t0 += per_band) {
    const int32_t t1 = std::min(tiles_y, t0 + per_band);
    // Node rows [first, last]: the previous band's last row, then the
    // tile rows fetched.
    const int32_t first = t0 == 0 ? 0 : t0 * kTileSize - 1;
    const int32_t last = std::min(ny, t1 * kTileSize - 1);
    // The previous band's last row is copied in, the rest filled.
    if (fill_writes_every_node_) {
      band.ResizeBand(first, last - first + 1);
    } else {
      band.ResetBand(first, last - first + 1);
    }
    if (t0 > 0) {
      std::copy(carry_jets.begin(), carry_jets.end(), band.jets.begin());
      std::copy(carry_owners.begin(), carry_owners.end(), band.owners.begin());
    }
    status = fill_(&band, t0, t1, /*heights_only=*/false);
    if (!status.ok()) break;
    const int32_t e1 = t1 == tiles_y ? ny : last;
    if (e1 > e0) status = visit(band, e0, e1);
    e0 = e1;
    const int64_t at = band.Index(0, last);
    carry_jets.assign(band.jets.begin() + at, band.jets.begin() + at + nodes_x);
    carry_owners.assign(band.owners.begin() + at,
                        band.owners.begin() + at + nodes_x);
  }
  if (status.ok() && e0 != ny) {
    return absl::InternalError(
        absl::StrFormat("the bands ended at element row %d of %d", e0, ny));
  }
  return status;
}

}  // namespace swarf::cli
