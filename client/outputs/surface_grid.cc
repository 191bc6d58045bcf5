#include "client/outputs/surface_grid.h"

#include <algorithm>
#include <span>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/thread_pool.h"

namespace swarf::cli {

absl::StatusOr<SurfaceGrid> SurfaceGrid::Uncut(const StockSpec& spec,
                                               SchemeKind scheme) {
  if (absl::Status st = ValidateStock(spec); !st.ok()) return st;
  const int64_t n = (int64_t{spec.nx} + 1) * (int64_t{spec.ny} + 1);
  if (n > kMaxGridNodes) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "grid of %d nodes exceeds the writers' limit of %d", n, kMaxGridNodes));
  }
  SurfaceGrid g;
  g.spec = spec;
  g.scheme = scheme;
  g.ResetBand(0, spec.ny + 1);
  return g;
}

absl::StatusOr<SurfaceGrid> SurfaceGrid::Band(const StockSpec& spec,
                                              SchemeKind scheme, int32_t row0,
                                              int32_t rows) {
  if (absl::Status st = ValidateStock(spec); !st.ok()) return st;
  if (row0 < 0 || rows < 1 || row0 > spec.ny) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "band of %d node rows from row %d leaves the grid's %d rows", rows,
        row0, spec.ny + 1));
  }
  SurfaceGrid g;
  g.spec = spec;
  g.scheme = scheme;
  g.ResetBand(row0, rows);
  return g;
}

void SurfaceGrid::ResizeBand(int32_t first, int32_t rows) {
  row0 = first;
  rows = std::max(0, std::min(rows, nodes_y() - first));
  const size_t n = static_cast<size_t>(nodes_x()) * rows;
  // Not copied when it grows: the caller writes every node.
  ResizeForWriting(&jets, n);
  ResizeForWriting(&owners, n);
}

void SurfaceGrid::ResetBand(int32_t first, int32_t rows) {
  ResizeBand(first, rows);
  const size_t n = jets.size();
  SurfaceJet top;
  top.w = spec.z_top;
  // A tile row of a wide grid is tens of MB (52 bytes a node): filled (and
  // faulted in) on every thread, as the rows read into it are.
  constexpr size_t kPiece = size_t{1} << 16;
  ThreadPool::Default().ParallelFor(
      static_cast<int64_t>((n + kPiece - 1) / kPiece), [&](int64_t p) {
        const size_t a = p * kPiece, b = std::min(n, a + kPiece);
        std::fill(jets.begin() + a, jets.begin() + b, top);
        std::fill(owners.begin() + a, owners.begin() + b, -1);
      });
}

void SurfaceGrid::ReserveRows(int32_t rows) {
  const size_t n =
      static_cast<size_t>(nodes_x()) * std::clamp(rows, 0, nodes_y());
  jets.reserve(n);
  owners.reserve(n);
}

absl::StatusOr<SurfaceGrid> SurfaceGrid::FromWorkpiece(const Workpiece& wp) {
  absl::StatusOr<SurfaceGrid> g = Uncut(wp.spec(), wp.scheme().kind());
  if (!g.ok()) return g.status();
  g->SetMoves(wp.moves().ToVector());
  if (absl::Status st = g->SetTileRows(wp, 0, wp.tiles_y()); !st.ok()) {
    return st;
  }
  return g;
}

absl::Status SurfaceGrid::SetTileRows(const Workpiece& wp, int32_t t0,
                                      int32_t t1, bool heights_only) {
  // Unallocated tiles are untouched stock: their held nodes are set to the
  // top here, on the workpiece's threads (a band need not be filled first).
  if (wp.grid().nodes_x() != nodes_x() || wp.grid().nodes_y() != nodes_y()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the workpiece's %d x %d nodes are not this grid's %d x %d",
        wp.grid().nodes_x(), wp.grid().nodes_y(), nodes_x(), nodes_y()));
  }
  std::vector<int32_t> tiles, untouched;
  t0 = std::max(t0, 0);
  t1 = std::min(t1, wp.tiles_y());
  for (int32_t t = t0 * wp.tiles_x(); t < t1 * wp.tiles_x(); ++t) {
    (wp.TileAllocated(t) ? tiles : untouched).push_back(t);
  }
  if (!untouched.empty()) {
    SurfaceJet top;
    top.w = spec.z_top;
    wp.pool().ParallelFor(
        static_cast<int64_t>(untouched.size()), [&](int64_t k) {
          const Workpiece::TileExtent e = wp.Extent(untouched[k]);
          // Only the rows this band holds, as SetNodes.
          const int32_t ja = std::max(e.j0, row0);
          const int32_t jb = std::min(e.j0 + e.ny, row0 + held_rows());
          for (int32_t j = ja; j < jb; ++j) {
            const int64_t at = Index(e.i0, j);
            std::fill_n(jets.begin() + at, e.nx, top);
            std::fill_n(owners.begin() + at, e.nx, -1);
          }
        });
  }
  // A chunk's derivatives on the workpiece's threads, then its reads, also
  // on its threads: a buffer a tile of the chunk (a row of a wide grid
  // read on one thread was most of the adaptive mesh's time), and the
  // tiles' nodes are disjoint, so each is set where it was read.
  constexpr size_t kChunk = 64;
  static_assert(kChunk <= Workpiece::kJetCacheTiles);
  const size_t chunk_max = std::min(kChunk, tiles.size());
  // Written by ReadTile before they are read: not zeroed first (8 MiB on
  // one thread for each band).
  UnfilledVector<double> w(chunk_max * kTileNodes);
  UnfilledVector<float> dbuf(heights_only ? 0 : 5 * chunk_max * kTileNodes);
  UnfilledVector<int32_t> owner(heights_only ? 0 : chunk_max * kTileNodes);
  std::vector<absl::Status> status(chunk_max);
  for (size_t c = 0; c < tiles.size(); c += kChunk) {
    const std::span<const int32_t> chunk(tiles.data() + c,
                                         std::min(kChunk, tiles.size() - c));
    if (!heights_only) wp.PrepareJets(chunk);
    wp.pool().ParallelFor(static_cast<int64_t>(chunk.size()), [&](int64_t k) {
      const int32_t t = chunk[k];
      const Workpiece::TileExtent e = wp.Extent(t);
      double* const tw = w.data() + k * kTileNodes;
      float* d[5] = {};
      int32_t* to = nullptr;
      if (!heights_only) {
        for (int q = 0; q < 5; ++q) {
          d[q] = dbuf.data() + (5 * k + q) * kTileNodes;
        }
        to = owner.data() + k * kTileNodes;
      }
      wp.ReadTile(t, tw, heights_only ? nullptr : d, to);
      status[k] =
          SetNodes(e.i0, e.j0, e.nx, e.ny, tw, heights_only ? nullptr : d, to);
    });
    for (size_t k = 0; k < chunk.size(); ++k) {
      if (!status[k].ok()) return status[k];
    }
  }
  return absl::OkStatus();
}

void ReadNodeHeights(const Workpiece& wp, int32_t j0, int32_t j1, double* z) {
  const int32_t nx = wp.grid().nodes_x();
  const double z_top = wp.spec().z_top;
  const int32_t ty0 = j0 / kTileSize, ty1 = j1 / kTileSize;
  const int32_t tiles_x = wp.tiles_x();
  wp.pool().ParallelFor(int64_t{ty1 - ty0 + 1} * tiles_x, [&](int64_t k) {
    const int32_t t = (ty0 + static_cast<int32_t>(k / tiles_x)) * tiles_x +
                      static_cast<int32_t>(k % tiles_x);
    const Workpiece::TileExtent e = wp.Extent(t);
    const int32_t ja = std::max(j0, e.j0);
    const int32_t jb = std::min(j1, e.j0 + e.ny - 1);
    if (!wp.TileAllocated(t)) {  // untouched stock
      for (int32_t j = ja; j <= jb; ++j) {
        std::fill_n(z + int64_t{j - j0} * nx + e.i0, e.nx, z_top);
      }
      return;
    }
    // The rows wanted alone, straight into z (no tile-sized copy first, for
    // the rows of a band that start or end inside a tile), then held to the
    // top in place.
    double* const first = z + int64_t{ja - j0} * nx + e.i0;
    wp.ReadTileHeights(t, ja, jb, first, nx);
    for (int32_t j = ja; j <= jb; ++j) {
      double* const row = first + int64_t{j - ja} * nx;
      for (int32_t i = 0; i < e.nx; ++i) row[i] = std::min(row[i], z_top);
    }
  });
}

void SurfaceGrid::SetMoves(std::shared_ptr<const MoveSource> list) {
  moves = std::move(list);
  surfaces = nullptr;
  if (moves == nullptr) return;
  // Reaches are computed per corner from each thread's cache of owners (no
  // table of every move's). Only the schemes that look at the sweeps need
  // them, indexed by bin.
  const Scheme& s = GetScheme(scheme);
  if (s.uses_reach() || s.uses_candidates()) {
    surfaces = std::make_shared<const MoveSweeps>(moves, spec);
  }
}

void SurfaceGrid::SetMoves(std::shared_ptr<const MoveSource> list,
                           std::shared_ptr<const MoveSweeps> sweeps) {
  moves = std::move(list);
  const Scheme& s = GetScheme(scheme);
  surfaces = moves != nullptr && (s.uses_reach() || s.uses_candidates())
                 ? std::move(sweeps)
                 : nullptr;
}

void SurfaceGrid::SetMoves(std::span<const Move> list) {
  SetMoves(std::make_shared<const MoveList>(list));
}

absl::Status SurfaceGrid::SetNodes(int32_t i0, int32_t j0, int32_t nx,
                                   int32_t ny, const double* w,
                                   const float* const d[5],
                                   const int32_t* owner) {
  if (i0 < 0 || j0 < 0 || nx < 0 || ny < 0 || int64_t{i0} + nx > nodes_x() ||
      int64_t{j0} + ny > nodes_y()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "node block at (%d, %d) of %d x %d nodes leaves the %d x %d grid", i0,
        j0, nx, ny, nodes_x(), nodes_y()));
  }
  if (w == nullptr && (nx > 0 && ny > 0)) {
    return absl::InvalidArgumentError("node block without heights");
  }
  // Only the rows this band holds.
  const int32_t ja = std::max(0, row0 - j0);
  const int32_t jb = std::min(ny, row0 + held_rows() - j0);
  // A row at a time through pointers, the null tests outside the loops (at
  // -O2 they were taken for every node).
  for (int32_t j = ja; j < jb; ++j) {
    const int64_t in = int64_t{j} * nx;
    SurfaceJet* const row = jets.data() + Index(i0, j0 + j);
    int32_t* const row_owner = owners.data() + Index(i0, j0 + j);
    const double* const w_in = w + in;
    if (d != nullptr) {
      const float *const d0 = d[0] + in, *const d1 = d[1] + in,
                         *const d2 = d[2] + in, *const d3 = d[3] + in,
                         *const d4 = d[4] + in;
      for (int32_t i = 0; i < nx; ++i) {
        row[i] = SurfaceJet{w_in[i], d0[i], d1[i], d2[i], d3[i], d4[i]};
      }
    } else {
      for (int32_t i = 0; i < nx; ++i) row[i] = SurfaceJet{w_in[i]};
    }
    if (owner != nullptr) {
      std::copy_n(owner + in, nx, row_owner);
    } else {
      std::fill_n(row_owner, nx, -1);
    }
  }
  return absl::OkStatus();
}

absl::Status SurfaceGrid::Validate() const {
  if (absl::Status st = ValidateStock(spec); !st.ok()) return st;
  const int64_t n = (int64_t{spec.nx} + 1) * (int64_t{spec.ny} + 1);
  if (static_cast<int64_t>(jets.size()) != n ||
      static_cast<int64_t>(owners.size()) != n || row0 != 0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "grid holds %d jets and %d owners from row %d, the spec needs %d "
        "nodes",
        jets.size(), owners.size(), row0, n));
  }
  return absl::OkStatus();
}

ElementCorners SurfaceGrid::Corners(int32_t ei, int32_t ej,
                                    bool prepare) const {
  ElementCorners e;
  FillCorners(ei, ej, &e);
  if (prepare) GetScheme(scheme).Prepare(&e);
  return e;
}

void SurfaceGrid::FillCorners(int32_t ei, int32_t ej, ElementCorners* e) const {
  // Same construction as Workpiece::Corners so that reconstructions agree
  // bit for bit.
  SetElementFrame(GridGeometry(spec), spec.z_top, ei, ej, e);
  const int32_t is[4] = {ei, ei + 1, ei + 1, ei};
  const int32_t js[4] = {ej, ej, ej + 1, ej + 1};
  // Looked up once: an element a pixel, the lookups cost a fifth of this.
  const Scheme& s = GetScheme(scheme);
  const bool uses_reach = s.uses_reach();
  const int64_t moves = move_count();
  for (int k = 0; k < 4; ++k) {
    e->c[k] = jet(is[k], js[k]);
    const int32_t o = owner(is[k], js[k]);
    e->owner[k] = o;
    if (o >= 0 && o < moves && uses_reach) {
      // A reach is its owner's: neighbouring nodes mostly share one.
      e->reach[k] = k > 0 && e->owner[k - 1] == o
                        ? e->reach[k - 1]
                        : surfaces->Reach(o, spec.z_top);
    } else {
      e->reach[k] = CornerReach{};
    }
  }
  e->surfaces = nullptr;
  e->candidates.clear();
  if (s.uses_candidates() && surfaces != nullptr) {
    surfaces->FillCandidates(e);
  }
  if (uses_reach) e->surfaces = surfaces.get();
}

double SurfaceGrid::Height(double x, double y) const {
  const GridGeometry g(spec);
  x = std::clamp(x, spec.x0, spec.x1);
  y = std::clamp(y, spec.y0, spec.y1);
  return GetScheme(scheme).Reconstruct(Corners(g.ElementX(x), g.ElementY(y)), x,
                                       y);
}

void SurfaceGrid::Gradient(double x, double y, double* gx, double* gy) const {
  HeightAndGradient(x, y, gx, gy);
}

double SurfaceGrid::HeightAndGradient(double x, double y, double* gx,
                                      double* gy) const {
  const GridGeometry g(spec);
  x = std::clamp(x, spec.x0, spec.x1);
  y = std::clamp(y, spec.y0, spec.y1);
  return GetScheme(scheme).HeightAndGradient(
      Corners(g.ElementX(x), g.ElementY(y)), x, y, gx, gy);
}

SurfaceSampler::SurfaceSampler(const SurfaceGrid& grid)
    : SurfaceSampler(grid, 0, grid.nodes_x() - 1) {}

SurfaceSampler::SurfaceSampler(const SurfaceGrid& grid, int32_t i0, int32_t i1)
    : grid_(grid), scheme_(GetScheme(grid.scheme)) {
  i0_ = std::clamp(i0, 0, grid.nodes_x() - 1);
  columns_ = std::clamp(i1, i0_, grid.nodes_x() - 1) - i0_ + 1;
  const GridGeometry g(grid.spec);
  for (int32_t i = i0_; i + 1 < i0_ + columns_; ++i) {
    widest_ = std::max(widest_, g.NodeX(i + 1) - g.NodeX(i));
  }
}

const PatchTrustRegion* SurfaceSampler::Region(int32_t i, int32_t j,
                                               bool* sure) {
  int k = 0;
  while (k < kRows && row_[k] != j) ++k;
  if (k == kRows) {
    // A new row replaces the oldest.
    k = next_;
    next_ = (next_ + 1) % kRows;
    row_[k] = j;
    regions_[k].resize(columns_);
    has_[k].assign(columns_, kNotYet);
    // The taller of the row's (up to two) rows of elements.
    const GridGeometry g(grid_.spec);
    double hy = 0;
    if (j > 0) hy = std::max(hy, g.NodeY(j) - g.NodeY(j - 1));
    if (j < g.ny()) hy = std::max(hy, g.NodeY(j + 1) - g.NodeY(j));
    tallest_[k] = hy;
  }
  const int32_t c = i - i0_;
  if (has_[k][c] == kNotYet) {
    // A region is a function of the jet's shape alone: along a straight
    // move's cylinder neighbouring nodes mostly share theirs, and a region
    // costs four transcendental functions. Whether it surely holds the
    // node's elements is taken at the widest and tallest of them in the
    // sampler's columns and the node's row (PrepareGuarded's `sure`), so
    // it is the same for a copy.
    const SurfaceJet& jet = grid_.jet(i, j);
    if (c > 0 && has_[k][c - 1] != kNotYet &&
        SameShape(grid_.jet(i - 1, j), jet)) {
      regions_[k][c] = regions_[k][c - 1];
      has_[k][c] = has_[k][c - 1];
    } else {
      regions_[k][c] = TrustRegion(jet);
      has_[k][c] =
          SurelyTrusted(regions_[k][c], widest_, tallest_[k]) ? kSure : kTested;
    }
  }
  *sure = has_[k][c] == kSure;
  return &regions_[k][c];
}

double SurfaceSampler::HeightAndGradient(double x, double y, double* gx,
                                         double* gy) {
  // As SurfaceGrid::HeightAndGradient.
  const GridGeometry g(grid_.spec);
  x = std::clamp(x, grid_.spec.x0, grid_.spec.x1);
  y = std::clamp(y, grid_.spec.y0, grid_.spec.y1);
  Select(g.ElementX(x), g.ElementY(y));
  return scheme_.HeightAndGradient(e_, x, y, gx, gy);
}

void SurfaceSampler::Select(int32_t ei, int32_t ej) {
  if (ei == ei_ && ej == ej_) return;
  if (scheme_.kind() == SchemeKind::kGuarded) {
    // Prepared from the nodes' regions (a node serves four elements);
    // PrepareGuarded reads them for cut corners only.
    // Filled in place (an element a pixel: a copy of the corners cost a
    // sixth of this); PrepareGuarded writes every field of the guard.
    grid_.FillCorners(ei, ej, &e_);
    const int32_t is[4] = {ei, ei + 1, ei + 1, ei};
    const int32_t js[4] = {ej, ej, ej + 1, ej + 1};
    static const PatchTrustRegion kNone;
    const PatchTrustRegion* trust[4];
    bool sure[4];
    for (int k = 0; k < 4; ++k) {
      sure[k] = false;
      trust[k] = e_.owner[k] >= 0 ? Region(is[k], js[k], &sure[k]) : &kNone;
    }
    PrepareGuarded(&e_, trust, sure);
  } else {
    e_ = grid_.Corners(ei, ej);
  }
  ei_ = ei;
  ej_ = ej;
}

void SurfaceSampler::ReconstructInElement(int32_t ei, int32_t ej,
                                          const double* x, const double* y,
                                          int32_t n, double* out) {
  Select(ei, ej);
  scheme_.ReconstructMany(e_, x, y, n, out);
}

double SurfaceGrid::MinNodeHeight() const {
  double lo = spec.z_top;
  for (const SurfaceJet& j : jets) lo = std::min(lo, j.w);
  return lo;
}

}  // namespace swarf::cli
