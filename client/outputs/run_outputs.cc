#include "client/outputs/run_outputs.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/outputs/marks_files.h"
#include "client/outputs/png_image.h"
#include "core/thread_pool.h"
#include "core/workpiece.h"

namespace swarf::cli {
namespace {

using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Files built and written one after the other, each timed; stops at the
// first error.
class Chain {
 public:
  explicit Chain(std::string base) : base_(std::move(base)) {}
  // `earlier`: seconds already spent on this file (its share of the pass
  // over the grid).
  void Then(const std::string& name,
            const std::function<absl::Status(const std::string&)>& write,
            double earlier = 0) {
    if (!status_.ok()) return;
    const auto t0 = Clock::now();
    status_ = write(base_ + name);
    if (status_.ok()) written_.push_back({base_ + name, earlier + Since(t0)});
  }
  absl::Status status() const { return status_; }
  const std::vector<WrittenFile>& written() const { return written_; }

 private:
  const std::string base_;
  absl::Status status_;
  std::vector<WrittenFile> written_;
};

// The lattice's heights at subdivision 1 (the nodes' heights, capped at the
// top, as FillLatticeRows sets them) read again from the grid's tile rows,
// heights only. The adaptive mesh asks for root rows in increasing order
// (a window is a tile row and the next one's first rows): the last tile
// rows read are kept, so a pass reads each tile row once.
class GridRows : public LatticeWindows {
 public:
  GridRows(GridBands& grid, SurfaceGrid band)
      : grid_(grid), band_(std::move(band)) {}
  absl::StatusOr<const double*> Rows(int64_t j0, int64_t j1) override {
    const int32_t nx = band_.nodes_x();
    // A window from a tile row's first row to at most kExtraRows rows into
    // the next (the meshes' windows: 64 to 66 rows) is served from the held
    // tile row, the next one's first rows put after its own: not copied
    // (the full plate's adaptive mesh read its 400 M heights about five
    // times).
    const int64_t tr = j0 / kTileSize;
    const int64_t extra = j1 - (j0 + kTileSize - 1);
    if (j0 == tr * kTileSize && j1 >= j0 && extra <= kExtraRows &&
        j1 < band_.nodes_y()) {
      const UnfilledVector<double>* next = nullptr;
      if (extra > 0) {
        absl::StatusOr<UnfilledVector<double>*> n = TileRow(tr + 1);
        if (!n.ok()) return n.status();
        next = *n;
      }
      // Held after the next one: the ring of three keeps both.
      absl::StatusOr<UnfilledVector<double>*> tile_row = TileRow(tr);
      if (!tile_row.ok()) return tile_row.status();
      UnfilledVector<double>& z = **tile_row;
      if (extra > 0) {
        const size_t own = static_cast<size_t>(kTileSize) * nx;
        z.resize(own + extra * nx);  // within its capacity (TileRow)
        std::copy_n(next->data(), extra * nx, z.data() + own);
      }
      return z.data();
    }
    z_.resize(static_cast<size_t>(j1 - j0 + 1) * nx);
    // Each tile row's part copied on every thread (on one, the copy was a
    // serial step of the mesh), before the next tile row is read.
    for (int64_t t = j0 / kTileSize; t <= j1 / kTileSize; ++t) {
      absl::StatusOr<const UnfilledVector<double>*> tile_row = TileRow(t);
      if (!tile_row.ok()) return tile_row.status();
      const int64_t a = std::max(j0, t * kTileSize);
      const int64_t b = std::min<int64_t>(j1, t * kTileSize + kTileSize - 1);
      const double* from = (*tile_row)->data() + (a - t * kTileSize) * nx;
      ThreadPool::Default().ParallelFor(b - a + 1, [&](int64_t r) {
        std::copy_n(from + r * nx, nx, z_.begin() + (a - j0 + r) * nx);
      });
    }
    return z_.data();
  }

 private:
  // Rows of the next tile row a window may take (Rows).
  static constexpr int64_t kExtraRows = 2;

  // Tile row t's node rows (held: the last three read), with room for
  // kExtraRows rows more (Rows).
  absl::StatusOr<UnfilledVector<double>*> TileRow(int64_t t) {
    for (auto& [held, z] : held_) {
      if (held == t) return &z;
    }
    const int32_t nx = band_.nodes_x();
    const int32_t j0 = static_cast<int32_t>(t * kTileSize);
    const int32_t j1 = std::min(band_.spec.ny, j0 + kTileSize - 1);
    auto& [held, z] = held_[next_];
    next_ = (next_ + 1) % held_.size();
    held = -1;
    z.reserve(static_cast<size_t>(kTileSize + kExtraRows) * nx);
    z.resize(static_cast<size_t>(j1 - j0 + 1) * nx);
    if (absl::Status st = grid_.ReadHeights(j0, j1, &band_, z.data());
        !st.ok()) {
      return st;
    }
    held = t;
    return &z;
  }

  GridBands& grid_;
  SurfaceGrid band_;
  UnfilledVector<double> z_;
  std::array<std::pair<int64_t, UnfilledVector<double>>, 3> held_ = {
      {{-1, {}}, {-1, {}}, {-1, {}}}};
  size_t next_ = 0;
};

}  // namespace

absl::StatusOr<std::vector<WrittenFile>> WriteRunOutputs(
    const std::string& dir, const SurfaceGrid& grid, const ErrorRaster* error,
    const std::vector<MarkPolyline>* marks, const RunOutputOptions& options,
    RunOutputSummary* summary) {
  if (absl::Status st = grid.Validate(); !st.ok()) return st;
  InMemoryBands bands(grid);
  return WriteRunOutputs(dir, bands, error, marks, options, summary);
}

namespace {

// WriteRunOutputs with the marks held (`marks`: marks.svg and marks.json
// written here) or streamed (`streamed`), or neither.
absl::StatusOr<std::vector<WrittenFile>> WriteAll(
    const std::string& dir, GridBands& grid, const ErrorRaster* error,
    const std::vector<MarkPolyline>* held, const StreamedMarks* streamed,
    const RunOutputOptions& options, RunOutputSummary* summary) {
  // Whether there is a marks.png to draw (its polylines held or streamed).
  const bool marks = held != nullptr || streamed != nullptr;
  const std::string base = dir.empty() || dir.back() == '/' ? dir : dir + "/";
  const StockSpec spec = grid.spec();
  if (absl::Status st = ValidateStock(spec); !st.ok()) return st;
  if (absl::Status st =
          CheckPictureSides(options.relief.min_side, options.relief.max_side);
      !st.ok()) {
    return st;
  }
  if (marks) {
    if (absl::Status st = CheckPictureSides(options.marks.relief.min_side,
                                            options.marks.relief.max_side);
        !st.ok()) {
      return st;
    }
  }
  // What the pass over the bands fills: the relief's pixels, the marks
  // picture's when its frame differs, the mesh lattice.
  std::optional<ReliefSampler> relief;
  relief.emplace(spec, ReliefFrame(spec, options.relief));
  std::optional<ReliefSampler> marks_relief;
  const PixelFrame marks_frame = ReliefFrame(spec, options.marks.relief);
  if (streamed != nullptr && !(streamed->frame == marks_frame)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the streamed marks were kept for a %d x %d picture, marks.png is "
        "%d x %d",
        streamed->frame.width, streamed->frame.height, marks_frame.width,
        marks_frame.height));
  }
  if (marks && !(marks_frame == relief->frame())) {
    marks_relief.emplace(spec, marks_frame);
  }
  // On the nodes (subdivision 1) the meshes read the lattice's heights
  // again from the grid (a root row, or 64 rows, at a time) instead of
  // holding them: 8 bytes a node less.
  const bool reread = options.mesh.subdivision == 1;
  absl::StatusOr<LatticeHeights> lattice =
      NewLattice(spec, options.mesh.subdivision, /*heights=*/!reread);
  if (!lattice.ok()) return lattice.status();
  std::optional<GridRows> rows;
  if (reread) {
    auto band = SurfaceGrid::Band(spec, grid.scheme(), 0, 1);
    if (!band.ok()) return band.status();
    rows.emplace(grid, *std::move(band));
  }
  double relief_s = 0, marks_relief_s = 0, lattice_s = 0;
  const auto pass0 = Clock::now();
  absl::Status pass =
      grid.ForEach([&](const SurfaceGrid& band, int32_t e0, int32_t e1) {
        auto t = Clock::now();
        relief->AddBand(band, e0, e1);
        relief_s += Since(t);
        if (marks_relief) {
          t = Clock::now();
          marks_relief->AddBand(band, e0, e1);
          marks_relief_s += Since(t);
        }
        t = Clock::now();
        FillLatticeRows(band, e0, e1, &*lattice);
        lattice_s += Since(t);
        return absl::OkStatus();
      });
  if (!pass.ok()) return pass;
  const double pass_s = Since(pass0);
  if (summary != nullptr) {
    summary->pass_seconds = pass_s;
    summary->read_seconds =
        std::max(0.0, pass_s - relief_s - marks_relief_s - lattice_s);
  }

  // Three independent chains at once (most writers are serial): the
  // pictures, the marks files, the meshes.
  auto meshes = std::async(std::launch::async, [&] {
    Chain c(base);
    if (options.mesh.tolerance == 0) {
      // The full lattice: written from its rows, never built (48 bytes a
      // node and more as a TriangleMesh).
      const LatticeHeights& l = *lattice;
      std::unique_ptr<LatticeWindows> held;
      LatticeWindows* source = rows ? &*rows : nullptr;
      if (source == nullptr) {
        held = HeldLatticeRows(l);
        source = held.get();
      }
      const double z_min =
          *std::min_element(l.row_min.begin(), l.row_min.end());
      const double z_bottom = options.mesh.z_bottom
                                  ? *options.mesh.z_bottom
                                  : DefaultZBottom(spec, z_min);
      c.Then(
          "surface.stl",
          [&](const std::string& path) {
            if (!std::isfinite(z_bottom) || !(z_bottom < z_min)) {
              return absl::InvalidArgumentError(
                  absl::StrFormat("z_bottom %g must be finite and below the "
                                  "lowest top vertex %g",
                                  z_bottom, z_min));
            }
            return WriteLatticeStl(*source, l, z_bottom, path);
          },
          lattice_s);
      c.Then("surface.wrl", [&](const std::string& path) {
        return WriteLatticeVrml(*source, l, z_bottom, spec.z_top,
                                options.vrml_colors, path);
      });
      if (c.status().ok() && summary != nullptr) {
        summary->full_mesh_triangles = FullMeshTriangles(l.nx, l.ny);
        summary->mesh_triangles = summary->full_mesh_triangles;
        summary->mesh_deviation = 0;
      }
      return c;
    }
    absl::StatusOr<TriangleMesh> mesh;
    c.Then(
        "surface.stl",
        [&](const std::string& path) {
          mesh = MeshFromLattice(*std::move(lattice), spec, options.mesh,
                                 rows ? &*rows : nullptr);
          if (!mesh.ok()) return mesh.status();
          return WriteStl(*mesh, path);
        },
        lattice_s);
    c.Then("surface.wrl", [&](const std::string& path) {
      const std::vector<Rgb> colors = options.vrml_colors
                                          ? SurfaceColors(*mesh, spec.z_top)
                                          : std::vector<Rgb>();
      return WriteVrml(*mesh, path, colors);
    });
    if (c.status().ok() && summary != nullptr) {
      const int64_t nx = mesh->lattice_nx, ny = mesh->lattice_ny;
      summary->full_mesh_triangles = 2 * nx * ny + 6 * (nx + ny) - 2;
      summary->mesh_triangles = static_cast<int64_t>(mesh->triangles.size());
      summary->mesh_deviation = mesh->max_deviation;
    }
    return c;
  });
  std::future<Chain> marks_files;
  if (held != nullptr) {
    marks_files = std::async(std::launch::async, [&] {
      Chain c(base);
      c.Then("marks.svg", [&](const std::string& path) {
        return WriteMarksSvg(spec, *held, path);
      });
      c.Then("marks.json", [&](const std::string& path) {
        return WriteMarksJson(*held, path);
      });
      return c;
    });
  }

  Chain pictures(base);
  pictures.Then(
      "relief.png",
      [&](const std::string& path) {
        // Row by row: the RGB picture is never held.
        absl::Status st = WritePngRows(
            relief->frame().width, relief->frame().height,
            [&](int y, uint8_t* out) { relief->ColorRow(y, out); }, path);
        // Sampled again at another size, or no marks: not needed any more.
        if (!marks || marks_relief) relief.reset();
        return st;
      },
      relief_s);
  if (error != nullptr) {
    pictures.Then("error.png", [&](const std::string& path) {
      absl::StatusOr<Image> map = RenderErrorMap(*error, options.error);
      if (!map.ok()) return map.status();
      return WritePng(*map, path);
    });
  }
  if (marks) {
    pictures.Then(
        "marks.png",
        [&](const std::string& path) {
          // The relief already sampled serves when the frames agree.
          const ReliefSampler& under = marks_relief ? *marks_relief : *relief;
          absl::StatusOr<Image> picture =
              held != nullptr
                  ? DrawMarks(under, *held, options.marks)
                  : DrawKeptMarks(under, streamed->source, options.marks);
          marks_relief.reset();
          relief.reset();
          if (!picture.ok()) return picture.status();
          return WritePng(*picture, path);
        },
        marks_relief_s);
  }

  std::vector<Chain> chains;
  chains.push_back(std::move(pictures));
  if (marks_files.valid()) chains.push_back(marks_files.get());
  Chain mesh_chain = meshes.get();
  std::vector<WrittenFile> written;
  for (const Chain& c : chains) {
    if (!c.status().ok()) return c.status();
    written.insert(written.end(), c.written().begin(), c.written().end());
  }
  // The streamed marks files in the marks chain's place.
  if (streamed != nullptr) {
    if (!streamed->status.ok()) return streamed->status;
    written.insert(written.end(), streamed->files.begin(),
                   streamed->files.end());
  }
  if (!mesh_chain.status().ok()) return mesh_chain.status();
  written.insert(written.end(), mesh_chain.written().begin(),
                 mesh_chain.written().end());
  return written;
}

}  // namespace

absl::StatusOr<std::vector<WrittenFile>> WriteRunOutputs(
    const std::string& dir, GridBands& grid, const ErrorRaster* error,
    const std::vector<MarkPolyline>* marks, const RunOutputOptions& options,
    RunOutputSummary* summary) {
  return WriteAll(dir, grid, error, marks, nullptr, options, summary);
}

absl::StatusOr<std::vector<WrittenFile>> WriteRunOutputsStreamed(
    const std::string& dir, GridBands& grid, const ErrorRaster* error,
    const StreamedMarks* marks, const RunOutputOptions& options,
    RunOutputSummary* summary) {
  return WriteAll(dir, grid, error, nullptr, marks, options, summary);
}

}  // namespace swarf::cli
