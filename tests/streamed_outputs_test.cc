// Issue 28, outputs streamed: `swarf run --out`'s files written band by
// band from the grid (GridBands) are byte for byte those of the whole-grid
// path, whatever the bands; and a run on a grid larger than the old caps
// (more than 16 M nodes) stays within 16 bytes a node plus 1 GiB of peak
// resident memory (the swarf binary as a child, its ru_maxrss).
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "client/outputs/grid_bands.h"
#include "client/outputs/marks_files.h"
#include "client/outputs/marks_stream.h"
#include "client/outputs/pictures.h"
#include "client/outputs/png_image.h"
#include "client/outputs/run_outputs.h"
#include "client/outputs/surface_grid.h"
#include "client/outputs/surface_mesh.h"
#include "core/cutting_marks.h"
#include "core/valuation.h"
#include "core/workpiece.h"
#include "gtest/gtest.h"
#include "core/sanitizers.h"

namespace swarf::cli {
namespace {

namespace fs = std::filesystem;

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)),
                     std::istreambuf_iterator<char>());
}

// A fresh directory, removed at the end.
struct TempDir {
  TempDir() {
    std::string tmpl = (fs::temp_directory_path() / "swarf-bands-XXXXXX");
    path = mkdtemp(tmpl.data());
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  std::string path;
};

// 40 x 33 mm at 0.25 mm: 161 x 133 nodes (3 tile rows, the last partial).
// Crossing ball grooves, a crater and a diagonal: marks, walls, scallops.
StockSpec Stock() { return StockSpec{0, 0, 40, 33, 5, 160, 132}; }

std::vector<Move> Moves() {
  return {
      {{2, 10, 3.5}, {38, 10, 3.5}, 3},  {{2, 11.5, 3.5}, {38, 11.5, 3.5}, 3},
      {{20, 1, 3.8}, {20, 31, 3.8}, 2},  {{10, 25, 2.5}, {10, 25, 2.5}, 4},
      {{3, 3, 4.2}, {37, 30, 3.9}, 1.5}, {{30, 20, 4.0}, {34, 28, 3.0}, 2},
  };
}

struct Written {
  std::vector<std::string> names, bytes;
  RunOutputSummary summary;
};

Written Write(GridBands& bands, const ErrorRaster* error,
              const std::vector<MarkPolyline>* marks,
              const RunOutputOptions& options) {
  TempDir dir;
  Written w;
  auto files =
      WriteRunOutputs(dir.path, bands, error, marks, options, &w.summary);
  EXPECT_TRUE(files.ok()) << files.status();
  if (!files.ok()) return w;
  for (const WrittenFile& f : *files) {
    w.names.push_back(fs::path(f.path).filename().string());
    w.bytes.push_back(ReadAll(f.path));
  }
  return w;
}

void ExpectSame(const Written& a, const Written& b, const std::string& what) {
  ASSERT_EQ(a.names, b.names) << what;
  for (size_t k = 0; k < a.names.size(); ++k) {
    EXPECT_FALSE(a.bytes[k].empty()) << what << " " << a.names[k];
    EXPECT_TRUE(a.bytes[k] == b.bytes[k])
        << what << ": " << a.names[k] << " differs";
  }
  EXPECT_EQ(a.summary.mesh_triangles, b.summary.mesh_triangles) << what;
  EXPECT_EQ(a.summary.full_mesh_triangles, b.summary.full_mesh_triangles)
      << what;
  EXPECT_EQ(a.summary.mesh_deviation, b.summary.mesh_deviation) << what;
}

// Stock() cut by Moves() with `scheme`, and its grid copied whole
// (SurfaceGrid::FromWorkpiece).
struct CutJob {
  std::unique_ptr<Workpiece> wp;
  SurfaceGrid grid;
};
absl::StatusOr<CutJob> CutStock(SchemeKind scheme) {
  auto wp = Workpiece::Create(Stock(), scheme);
  if (!wp.ok()) return wp.status();
  if (auto applied = (*wp)->Apply(Moves()); !applied.ok()) {
    return applied.status();
  }
  auto grid = SurfaceGrid::FromWorkpiece(**wp);
  if (!grid.ok()) return grid.status();
  return CutJob{*std::move(wp), *std::move(grid)};
}

// The tiles of wp that no move cut.
int UntouchedTiles(const Workpiece& wp) {
  int untouched = 0;
  for (int32_t t = 0; t < wp.tiles_x() * wp.tiles_y(); ++t) {
    untouched += !wp.TileAllocated(t);
  }
  return untouched;
}

// Tile rows of the workpiece, as the session's GetTiles gives them
// (Workpiece::ReadTile of every tile of those rows).
TileRowBands::Fill FillFrom(const Workpiece& wp) {
  return
      [&wp](SurfaceGrid* band, int32_t t0, int32_t t1, bool) -> absl::Status {
        std::vector<double> w(kTileNodes);
        std::vector<float> dbuf(5 * kTileNodes);
        std::vector<int32_t> owner(kTileNodes);
        float* const d[5] = {&dbuf[0], &dbuf[kTileNodes], &dbuf[2 * kTileNodes],
                             &dbuf[3 * kTileNodes], &dbuf[4 * kTileNodes]};
        for (int32_t ty = t0; ty < t1; ++ty) {
          for (int32_t tx = 0; tx < wp.tiles_x(); ++tx) {
            const int32_t t = ty * wp.tiles_x() + tx;
            if (!wp.TileAllocated(t)) continue;  // untouched: the band has it
            const int32_t one[1] = {t};
            wp.PrepareJets(one);
            const Workpiece::TileExtent e = wp.Extent(t);
            wp.ReadTile(t, w.data(), d, owner.data());
            if (absl::Status st = band->SetNodes(e.i0, e.j0, e.nx, e.ny,
                                                 w.data(), d, owner.data());
                !st.ok()) {
              return st;
            }
          }
        }
        return absl::OkStatus();
      };
}

TEST(StreamedOutputsTest, BandsWriteTheWholeGridsFilesByteForByte) {
  for (SchemeKind scheme : {SchemeKind::kTaylor, SchemeKind::kGuarded,
                            SchemeKind::kExact, SchemeKind::kZmap}) {
    const std::string name(GetScheme(scheme).name());
    auto wp = Workpiece::Create(Stock(), scheme);
    ASSERT_TRUE(wp.ok()) << wp.status();
    ASSERT_TRUE((*wp)->Apply(Moves()).ok());
    auto grid = SurfaceGrid::FromWorkpiece(**wp);
    ASSERT_TRUE(grid.ok()) << grid.status();
    ValuationOptions vopt;
    vopt.map_cols = 80;
    vopt.map_rows = 66;
    auto valued = MeasureError(**wp, vopt);
    ASSERT_TRUE(valued.ok()) << valued.status();
    ErrorRaster raster{{0, 0, 40, 33}, 80, 66, valued->map};
    std::vector<MarkPolyline> marks;
    if (GetScheme(scheme).stores_derivatives()) {
      auto m = FindCuttingMarks(**wp, {});
      ASSERT_TRUE(m.ok()) << m.status();
      marks = *std::move(m);
      ASSERT_FALSE(marks.empty()) << name;
    }
    const std::vector<MarkPolyline>* mp = marks.empty() ? nullptr : &marks;
    for (double tolerance : {0.005, 0.0}) {
      RunOutputOptions options;
      options.mesh.tolerance = tolerance;
      // The marks picture at another size than the relief: two samplers.
      options.marks.relief = {.max_side = 300, .min_side = 200};
      InMemoryBands whole(*grid);
      const Written want = Write(whole, &raster, mp, options);
      ASSERT_FALSE(want.names.empty());
      for (int32_t rows : {1, 5, 64}) {
        InMemoryBands sliced(*grid, rows);
        ExpectSame(Write(sliced, &raster, mp, options), want,
                   absl::StrCat(name, " bands of ", rows, " rows"));
      }
      // Tile rows with the carried row, one and two tile rows a band.
      for (int64_t nodes : {int64_t{1}, int64_t{2} * 64 * 161}) {
        TileRowBands tiles(
            Stock(), scheme, FillFrom(**wp),
            std::make_shared<const MoveList>((*wp)->moves().ToVector()), nodes);
        ExpectSame(Write(tiles, &raster, mp, options), want,
                   absl::StrCat(name, " tile rows, ", nodes, " nodes"));
      }
      // The workpiece's own moves and index (as swarf run reads its
      // embedded session's, pinned) instead of a copy indexed again.
      const Workpiece& own = **wp;
      TileRowBands shared(Stock(), scheme, FillFrom(own),
                          std::shared_ptr<const MoveSource>(
                              std::shared_ptr<void>(), &own.moves()),
                          std::shared_ptr<const MoveSweeps>(
                              std::shared_ptr<void>(), &own.sweeps()),
                          int64_t{2} * 64 * 161);
      ExpectSame(Write(shared, &raster, mp, options), want,
                 absl::StrCat(name, " tile rows, the workpiece's sweeps"));
      // As swarf run reads its embedded session: the tiles set on the
      // workpiece's threads (SetTileRows), the mesh's heights read alone
      // (ReadNodeHeights), the bands not filled first (SetFillWritesEveryNode:
      // a node left unset would hold the last band's or a fresh
      // allocation's bytes).
      for (bool every : {false, true}) {
        TileRowBands direct(
            Stock(), scheme,
            [&own](SurfaceGrid* band, int32_t t0, int32_t t1,
                   bool heights_only) {
              return band->SetTileRows(own, t0, t1, heights_only);
            },
            std::shared_ptr<const MoveSource>(std::shared_ptr<void>(),
                                              &own.moves()),
            std::shared_ptr<const MoveSweeps>(std::shared_ptr<void>(),
                                              &own.sweeps()),
            int64_t{2} * 64 * 161);
        direct.SetHeightsFill([&own](int32_t j0, int32_t j1, double* z) {
          ReadNodeHeights(own, j0, j1, z);
          return absl::OkStatus();
        });
        if (every) direct.SetFillWritesEveryNode();
        ExpectSame(Write(direct, &raster, mp, options), want,
                   absl::StrCat(name, " tiles read from the workpiece",
                                every ? ", bands resized" : ""));
      }
    }
  }
}

// SetTileRows writes every node of its tile rows that a band holds, those
// of untouched tiles too: a band resized over any bytes (ResizeBand) then
// holds what the whole grid copied from the workpiece holds, with and
// without the derivatives.
TEST(StreamedOutputsTest, SetTileRowsWritesEveryNodeOfAResizedBand) {
  for (SchemeKind scheme : {SchemeKind::kTaylor, SchemeKind::kGuarded}) {
    auto job = CutStock(scheme);
    ASSERT_TRUE(job.ok()) << job.status();
    const Workpiece& own = *job->wp;
    const SurfaceGrid* const grid = &job->grid;
    EXPECT_GT(UntouchedTiles(own), 0) << "the test wants untouched tiles too";
    auto band = SurfaceGrid::Band(Stock(), scheme, 0, 1);
    ASSERT_TRUE(band.ok());
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const int32_t ny = Stock().ny;
    for (bool heights_only : {false, true}) {
      for (const auto& [j0, j1] : std::vector<std::pair<int32_t, int32_t>>{
               {0, ny}, {3, 70}, {64, 64}, {63, 128}, {ny - 1, ny}}) {
        // Whatever the storage held: not the top, not a number.
        band->ResizeBand(0, ny + 1);
        std::fill(band->jets.begin(), band->jets.end(),
                  SurfaceJet{nan, nan, nan, nan, nan, nan});
        std::fill(band->owners.begin(), band->owners.end(), 7);
        band->ResizeBand(j0, j1 - j0 + 1);
        ASSERT_TRUE(band->SetTileRows(own, j0 / kTileSize, j1 / kTileSize + 1,
                                      heights_only)
                        .ok());
        ASSERT_EQ(band->held_rows(), j1 - j0 + 1);
        for (int32_t j = j0; j <= j1; ++j) {
          for (int32_t i = 0; i < grid->nodes_x(); ++i) {
            const SurfaceJet& got = band->jet(i, j);
            const SurfaceJet& want = grid->jet(i, j);
            const bool same =
                heights_only ? got.w == want.w && got.wx == 0 && got.wy == 0 &&
                                   got.wxx == 0 && got.wxy == 0 &&
                                   got.wyy == 0 && band->owner(i, j) == -1
                             : got.w == want.w && got.wx == want.wx &&
                                   got.wy == want.wy && got.wxx == want.wxx &&
                                   got.wxy == want.wxy && got.wyy == want.wyy &&
                                   band->owner(i, j) == grid->owner(i, j);
            ASSERT_TRUE(same)
                << "node (" << i << ", " << j << ") of rows " << j0 << ".."
                << j1 << (heights_only ? ", heights only" : "");
          }
        }
      }
    }
    // Another workpiece's grid is refused, not written past the band.
    auto other =
        SurfaceGrid::Band(StockSpec{0, 0, 40, 33, 5, 80, 66}, scheme, 0, 1);
    ASSERT_TRUE(other.ok());
    EXPECT_EQ(other->SetTileRows(own, 0, 1).code(),
              absl::StatusCode::kInvalidArgument);
  }
}

// ReadNodeHeights against the heights read through a band, over row ranges
// within a tile, across tiles and of the whole grid, untouched tiles too.
TEST(StreamedOutputsTest, NodeHeightsAreTheBandsHeights) {
  for (SchemeKind scheme : {SchemeKind::kTaylor, SchemeKind::kGuarded}) {
    auto job = CutStock(scheme);
    ASSERT_TRUE(job.ok()) << job.status();
    const Workpiece& own = *job->wp;
    const SurfaceGrid* const grid = &job->grid;
    InMemoryBands whole(*grid);
    auto scratch = SurfaceGrid::Band(Stock(), scheme, 0, 1);
    ASSERT_TRUE(scratch.ok());
    const int32_t nx = grid->nodes_x(), ny = Stock().ny;
    ASSERT_GT(ny, 2 * kTileSize);
    for (const auto& [j0, j1] : std::vector<std::pair<int32_t, int32_t>>{
             {0, ny}, {3, 70}, {64, 64}, {63, 128}, {ny - 1, ny}}) {
      const size_t n = static_cast<size_t>(j1 - j0 + 1) * nx;
      std::vector<double> want(n, -1), got(n, -2);
      ASSERT_TRUE(whole.ReadHeights(j0, j1, &*scratch, want.data()).ok());
      ReadNodeHeights(own, j0, j1, got.data());
      EXPECT_TRUE(got == want) << "rows " << j0 << ".." << j1;
    }
    EXPECT_GT(UntouchedTiles(own), 0) << "the test wants untouched tiles too";
  }
}

// The meshes written from the lattice's rows (the full lattice never
// built; the adaptive one from heights read again) against the mesh built
// whole (BuildSurfaceMesh) and written (WriteStl, WriteVrml with
// SurfaceColors): the same bytes, for both tolerances and subdivisions.
TEST(StreamedOutputsTest, MeshesFromRowsAreTheBuiltMeshesFiles) {
  for (SchemeKind scheme : {SchemeKind::kTaylor, SchemeKind::kGuarded}) {
    auto wp = Workpiece::Create(Stock(), scheme);
    ASSERT_TRUE(wp.ok());
    ASSERT_TRUE((*wp)->Apply(Moves()).ok());
    auto grid = SurfaceGrid::FromWorkpiece(**wp);
    ASSERT_TRUE(grid.ok());
    for (int s : {1, 2}) {
      for (double tolerance : {0.0, 0.005}) {
        const std::string what =
            absl::StrCat(std::string(GetScheme(scheme).name()), " s ", s,
                         " tol ", tolerance);
        SurfaceMeshOptions mopt;
        mopt.subdivision = s;
        mopt.tolerance = tolerance;
        auto mesh = BuildSurfaceMesh(*grid, mopt);
        ASSERT_TRUE(mesh.ok()) << mesh.status();
        TempDir built;
        ASSERT_TRUE(WriteStl(*mesh, built.path + "/surface.stl").ok());
        ASSERT_TRUE(WriteVrml(*mesh, built.path + "/surface.wrl",
                              SurfaceColors(*mesh, Stock().z_top))
                        .ok());
        RunOutputOptions options;
        options.mesh = mopt;
        InMemoryBands bands(*grid, 9);
        const Written w = Write(bands, nullptr, nullptr, options);
        ASSERT_EQ(w.names.size(), 3u) << what;
        EXPECT_TRUE(w.bytes[1] == ReadAll(built.path + "/surface.stl")) << what;
        EXPECT_TRUE(w.bytes[2] == ReadAll(built.path + "/surface.wrl")) << what;
        EXPECT_EQ(w.summary.mesh_triangles,
                  static_cast<int64_t>(mesh->triangles.size()))
            << what;
        EXPECT_EQ(w.summary.mesh_deviation, mesh->max_deviation) << what;
      }
    }
  }
}

// Thin and tiny grids (one element across, fewer rows than a tile or a
// root): the same files from the rows as from the built mesh.
TEST(StreamedOutputsTest, ThinGridsFromRowsAreTheBuiltMeshesFiles) {
  const StockSpec specs[] = {
      {0, 0, 1, 40, 5, 1, 80},   {0, 0, 40, 1, 5, 80, 1},
      {0, 0, 2, 2, 5, 1, 1},     {0, 0, 30, 20, 5, 2, 130},
      {0, 0, 33, 9, 5, 130, 65},
  };
  for (const StockSpec& spec : specs) {
    auto wp = Workpiece::Create(spec, SchemeKind::kTaylor);
    ASSERT_TRUE(wp.ok()) << wp.status();
    const std::vector<Move> moves = {
        {{0.2, 0.2, 4.5}, {spec.x1 - 0.2, spec.y1 - 0.2, 4.2}, 0.8},
        {{spec.x1 / 2, 0, 4.6}, {spec.x1 / 2, spec.y1, 4.6}, 0.5}};
    ASSERT_TRUE((*wp)->Apply(moves).ok());
    auto grid = SurfaceGrid::FromWorkpiece(**wp);
    ASSERT_TRUE(grid.ok());
    for (double tolerance : {0.0, 0.005}) {
      const std::string what =
          absl::StrCat(spec.nx, " x ", spec.ny, " tol ", tolerance);
      SurfaceMeshOptions mopt;
      mopt.tolerance = tolerance;
      auto mesh = BuildSurfaceMesh(*grid, mopt);
      ASSERT_TRUE(mesh.ok()) << mesh.status();
      TempDir built;
      ASSERT_TRUE(WriteStl(*mesh, built.path + "/surface.stl").ok());
      ASSERT_TRUE(WriteVrml(*mesh, built.path + "/surface.wrl",
                            SurfaceColors(*mesh, spec.z_top))
                      .ok());
      RunOutputOptions options;
      options.mesh = mopt;
      TileRowBands bands(
          spec, SchemeKind::kTaylor, FillFrom(**wp),
          std::make_shared<const MoveList>((*wp)->moves().ToVector()), 1);
      const Written w = Write(bands, nullptr, nullptr, options);
      ASSERT_EQ(w.names.size(), 3u) << what;
      EXPECT_TRUE(w.bytes[1] == ReadAll(built.path + "/surface.stl")) << what;
      EXPECT_TRUE(w.bytes[2] == ReadAll(built.path + "/surface.wrl")) << what;
    }
  }
}

// The full 1000 mm plate at 0.05 mm (400 M nodes): its lattice is read
// again from the grid, never held, so only held lattices (8 bytes a
// vertex) keep the 2^28-vertex cap; the streamed ones go up to 2^31 - 1.
TEST(StreamedOutputsTest, LatticesReadAgainAreNotCappedAtHeldOnes) {
  const StockSpec plate{0, 0, 1000, 1000, 0, 20000, 20000};
  auto streamed = NewLattice(plate, 1, /*heights=*/false);
  ASSERT_TRUE(streamed.ok()) << streamed.status();
  EXPECT_EQ(streamed->nx, 20000);
  EXPECT_EQ(streamed->ny, 20000);
  EXPECT_TRUE(streamed->z.empty());
  EXPECT_EQ(streamed->xs.size(), 20001u);
  EXPECT_EQ(streamed->xs[20000], 1000.0);
  EXPECT_EQ(streamed->row_min.size(), 20001u);
  auto held = NewLattice(plate, 1, /*heights=*/true);
  EXPECT_EQ(held.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(held.status().message().find("exceeds 268435456 vertices"),
            std::string::npos)
      << held.status();
  // Subdivision 3 of the plate: 60000^2 > 2^31 - 1 even when streamed.
  auto too_many = NewLattice(plate, 3, /*heights=*/false);
  EXPECT_EQ(too_many.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(too_many.status().message().find("exceeds 2147483647"),
            std::string::npos)
      << too_many.status();
}

TEST(StreamedOutputsTest, PictureSizeBoundsThePictures) {
  auto wp = Workpiece::Create(Stock(), SchemeKind::kTaylor);
  ASSERT_TRUE(wp.ok());
  ASSERT_TRUE((*wp)->Apply(Moves()).ok());
  auto grid = SurfaceGrid::FromWorkpiece(**wp);
  ASSERT_TRUE(grid.ok());
  RunOutputOptions options;
  options.relief.max_side = 64;
  InMemoryBands bands(*grid, 7);
  TempDir dir;
  auto files = WriteRunOutputs(dir.path, bands, nullptr, nullptr, options);
  ASSERT_TRUE(files.ok()) << files.status();
  auto relief = ReadPng(dir.path + "/relief.png");
  ASSERT_TRUE(relief.ok()) << relief.status();
  // 40 x 33 mm: 64 pixels along x, 63 pixel steps of 40/63 mm; along y
  // 33 mm is 51.975 of them: 53 pixels.
  EXPECT_EQ(relief->width(), 64);
  EXPECT_EQ(relief->height(), 53);
  // What RenderRelief draws at that size, pixel for pixel.
  auto drawn = RenderRelief(*grid, options.relief);
  ASSERT_TRUE(drawn.ok());
  EXPECT_EQ(relief->pixels(), drawn->pixels());
}

// ------------------------------------------------------ the marks streamed

// The scene's cutting marks (taylor) and many more made up over the stock:
// open and closed, rims (owner -1), angles on both sides of the display
// threshold (so polylines are cut into pieces), vertex owners, a few
// vertices to a hundred.
std::vector<MarkPolyline> ManyMarks(const Workpiece& wp) {
  auto found = FindCuttingMarks(wp, {});
  EXPECT_TRUE(found.ok()) << found.status();
  std::vector<MarkPolyline> marks =
      found.ok() ? *found : std::vector<MarkPolyline>();
  EXPECT_GT(marks.size(), 5u);
  std::mt19937_64 rng(28);
  std::uniform_real_distribution<double> ux(0.5, 39.5), uy(0.5, 32.5),
      step(-0.6, 0.6), angle(0, 4), z(3, 5);
  for (int q = 0; q < 3000; ++q) {
    MarkPolyline p;
    p.closed = q % 9 == 0;
    p.owners = {q % 13 == 0 ? kStockTopOwner : q % 7, 7 + q % 5};
    const int n = 1 + static_cast<int>(rng() % (q % 50 == 0 ? 100 : 12));
    double x = ux(rng), y = uy(rng);
    for (int k = 0; k < n; ++k) {
      p.vertices.push_back({x, y, z(rng)});
      p.angle_deg.push_back(q % 4 == 0 ? 30 + angle(rng) : angle(rng));
      p.vertex_owners.push_back({k % 3, 7 + q % 5});
      x = std::clamp(x + step(rng), 0.0, 40.0);
      y = std::clamp(y + step(rng), 0.0, 33.0);
    }
    marks.push_back(std::move(p));
  }
  return marks;
}

void ExpectSameSummary(const MarkSummary& a, const MarkSummary& b,
                       const std::string& what) {
  EXPECT_EQ(a.polylines, b.polylines) << what;
  EXPECT_EQ(a.closed, b.closed) << what;
  EXPECT_EQ(a.vertices, b.vertices) << what;
  // Bit for bit: summed in the same order.
  EXPECT_EQ(std::memcmp(&a.total_length, &b.total_length, sizeof(double)), 0)
      << what << ": " << a.total_length << " vs " << b.total_length;
  EXPECT_EQ(a.min_angle_deg, b.min_angle_deg) << what;
  EXPECT_EQ(a.max_angle_deg, b.max_angle_deg) << what;
}

// What `swarf run` wrote from the marks held whole (Summarize,
// FilterMarks, WriteRunOutputs) against the marks consumed one at a time
// (MarksStream, WriteRunOutputsStreamed): the same summaries, and every
// file the same bytes, with batches and drawn chunks small enough that
// their boundaries fall everywhere. The spool and the SVG body go.
TEST(StreamedMarksTest, StreamedMarksWriteTheHeldMarksFilesByteForByte) {
  auto wp = Workpiece::Create(Stock(), SchemeKind::kTaylor);
  ASSERT_TRUE(wp.ok()) << wp.status();
  ASSERT_TRUE((*wp)->Apply(Moves()).ok());
  auto grid = SurfaceGrid::FromWorkpiece(**wp);
  ASSERT_TRUE(grid.ok()) << grid.status();
  const std::vector<MarkPolyline> marks = ManyMarks(**wp);
  const MarkDisplayFilter filter = kDefaultMarkDisplay;
  const MarkSummary all = Summarize(marks);
  const std::vector<MarkPolyline> shown = FilterMarks(marks, filter);
  const MarkSummary shown_summary = Summarize(shown);
  ASSERT_GT(shown.size(), 1000u);
  ASSERT_LT(shown_summary.vertices, all.vertices);  // some were cut away
  RunOutputOptions options;
  options.mesh.tolerance = 0.005;
  options.marks.relief = {.max_side = 400, .min_side = 300};
  InMemoryBands whole(*grid, 16);
  const Written want = Write(whole, nullptr, &shown, options);
  ASSERT_EQ(want.names, (std::vector<std::string>{
                            "relief.png", "marks.png", "marks.svg",
                            "marks.json", "surface.stl", "surface.wrl"}));
  EXPECT_TRUE(want.bytes[2] == MarksSvg(Stock(), shown) &&
              want.bytes[3] == MarksJson(shown) + "\n");

  struct Sizes {
    size_t batch_vertices, chunk_segments;
  };
  for (const Sizes sizes : {Sizes{1, 1}, Sizes{7, 13}, Sizes{1000, 4096},
                            Sizes{size_t{1} << 18, size_t{1} << 16}}) {
    const std::string what = absl::StrCat("batch ", sizes.batch_vertices,
                                          " chunk ", sizes.chunk_segments);
    TempDir dir;
    const std::string spool = dir.path + "/marks.png.spool";
    Written got;
    {
      MarksStream stream(Stock(), dir.path, filter,
                         ReliefFrame(Stock(), options.marks.relief),
                         {.batch_vertices = sizes.batch_vertices});
      for (const MarkPolyline& p : marks) stream.Add(p);
      stream.Finish();
      ExpectSameSummary(stream.all(), all, what + " all");
      ASSERT_TRUE(stream.shown().has_value());
      ExpectSameSummary(*stream.shown(), shown_summary, what + " shown");
      EXPECT_TRUE(fs::exists(spool)) << what;
      EXPECT_FALSE(fs::exists(dir.path + "/marks.svg.body")) << what;
      const StreamedMarks streamed = stream.streamed();
      ASSERT_TRUE(streamed.status.ok()) << streamed.status;
      RunOutputOptions o = options;
      o.marks.chunk_segments = sizes.chunk_segments;
      auto files = WriteRunOutputsStreamed(dir.path, whole, nullptr, &streamed,
                                           o, &got.summary);
      ASSERT_TRUE(files.ok()) << files.status();
      for (const WrittenFile& f : *files) {
        got.names.push_back(fs::path(f.path).filename().string());
        got.bytes.push_back(ReadAll(f.path));
      }
    }
    ExpectSame(got, want, what);
    EXPECT_FALSE(fs::exists(spool)) << what;
    EXPECT_EQ(std::distance(fs::directory_iterator(dir.path),
                            fs::directory_iterator()),
              6)
        << what;
  }
  // Without --out: the summary only, nothing written.
  MarksStream summary_only;
  for (const MarkPolyline& p : marks) summary_only.Add(p);
  summary_only.Finish();
  ExpectSameSummary(summary_only.all(), all, "summary only");
  EXPECT_FALSE(summary_only.shown().has_value());
}

// The marks drawn a chunk at a time from a source against the held marks'
// picture, and the errors: the first polyline whose angles do not match
// wins over an earlier non-finite vertex, as when they were all checked
// before drawing.
TEST(StreamedMarksTest, ChunkedDrawingIsTheHeldDrawing) {
  auto wp = Workpiece::Create(Stock(), SchemeKind::kTaylor);
  ASSERT_TRUE(wp.ok());
  ASSERT_TRUE((*wp)->Apply(Moves()).ok());
  auto grid = SurfaceGrid::FromWorkpiece(**wp);
  ASSERT_TRUE(grid.ok());
  const std::vector<MarkPolyline> marks = ManyMarks(**wp);
  MarksPictureOptions mo;
  mo.relief = {.max_side = 500, .min_side = 300};
  ReliefSampler relief(Stock(), ReliefFrame(Stock(), mo.relief));
  relief.AddBand(*grid, 0, Stock().ny);
  auto want = DrawMarks(relief, marks, mo);
  ASSERT_TRUE(want.ok()) << want.status();
  for (size_t chunk : {size_t{1}, size_t{3}, size_t{250}}) {
    mo.chunk_segments = chunk;
    auto got = DrawMarks(relief, MarksOf(marks), mo);
    ASSERT_TRUE(got.ok()) << got.status();
    EXPECT_TRUE(got->pixels() == want->pixels()) << "chunk " << chunk;
  }
  // Tiles of any size, down to a pixel, and one tile of the whole picture
  // (every segment drawn on one thread, in order): the same pixels.
  mo.chunk_segments = 1000;
  for (const auto& [rows, cols] : std::vector<std::pair<int, int>>{
           {1, 1}, {7, 3}, {32, 1}, {1000, 1000}}) {
    mo.tile_rows = rows;
    mo.tile_cols = cols;
    auto got = DrawMarks(relief, MarksOf(marks), mo);
    ASSERT_TRUE(got.ok()) << got.status();
    EXPECT_TRUE(got->pixels() == want->pixels())
        << "tiles " << rows << " x " << cols;
  }
  mo.tile_cols = 0;
  EXPECT_EQ(DrawMarks(relief, MarksOf(marks), mo).status().message(),
            "tile_rows and tile_cols must be >= 1");
  mo.tile_rows = mo.tile_cols = 32;
  std::vector<MarkPolyline> bad = {marks[0], marks[1], marks[2]};
  bad[0].vertices[0].x = std::nan("");
  EXPECT_EQ(DrawMarks(relief, MarksOf(bad), mo).status().message(),
            "mark vertex is not finite");
  bad[2].angle_deg.push_back(1);
  EXPECT_EQ(DrawMarks(relief, MarksOf(bad), mo).status().message(),
            absl::StrCat("mark polyline with ", bad[2].vertices.size(),
                         " vertices has ", bad[2].angle_deg.size(), " angles"));
  // The same errors through a spool, the marks kept as they arrive (the
  // angles of a later batch's polyline win over an earlier vertex that is
  // not finite).
  std::vector<MarkPolyline> not_finite = {marks[0], marks[1], marks[2]};
  not_finite[1].vertices[0].y = std::numeric_limits<double>::infinity();
  for (const std::vector<MarkPolyline>* batch : {&not_finite, &bad}) {
    TempDir dir;
    MarksSpool spool(dir.path + "/spool", relief.frame());
    const std::span<const MarkPolyline> all(*batch);
    (void)spool.Append(all.first(1));
    (void)spool.Append(all.subspan(1));
    (void)spool.Finish();
    const absl::Status want_error =
        DrawMarks(relief, MarksOf(*batch), mo).status();
    EXPECT_FALSE(want_error.ok());
    EXPECT_EQ(DrawKeptMarks(relief, spool.source(), mo).status(), want_error);
  }
  mo.chunk_segments = 0;
  EXPECT_EQ(DrawMarks(relief, MarksOf(marks), mo).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// Errors: a marks file that cannot be written is the held path's error
// (naming the file), returned in the marks files' place; a stream that
// stops before Finish (a failed fetch) leaves no marks file; the spool is
// gone after a failure too.
TEST(StreamedMarksTest, ErrorsNameTheFileAndLeaveNoSpool) {
  auto wp = Workpiece::Create(Stock(), SchemeKind::kTaylor);
  ASSERT_TRUE(wp.ok());
  ASSERT_TRUE((*wp)->Apply(Moves()).ok());
  auto grid = SurfaceGrid::FromWorkpiece(**wp);
  ASSERT_TRUE(grid.ok());
  const std::vector<MarkPolyline> marks = ManyMarks(**wp);
  const std::vector<MarkPolyline> shown =
      FilterMarks(marks, kDefaultMarkDisplay);
  RunOutputOptions options;
  options.relief.max_side = 100;
  options.marks.relief = {.max_side = 100, .min_side = 100};
  InMemoryBands bands(*grid, 32);
  for (const char* blocked : {"marks.svg", "marks.json"}) {
    SCOPED_TRACE(blocked);
    // A directory where the file should be.
    TempDir held_dir, dir;
    fs::create_directory(held_dir.path + "/" + blocked);
    fs::create_directory(dir.path + "/" + blocked);
    auto held = WriteRunOutputs(held_dir.path, bands, nullptr, &shown, options);
    ASSERT_FALSE(held.ok());
    {
      MarksStream stream(Stock(), dir.path, kDefaultMarkDisplay,
                         ReliefFrame(Stock(), options.marks.relief),
                         {.batch_vertices = 100});
      for (const MarkPolyline& p : marks) stream.Add(p);
      stream.Finish();
      const StreamedMarks streamed = stream.streamed();
      EXPECT_FALSE(streamed.status.ok());
      auto got =
          WriteRunOutputsStreamed(dir.path, bands, nullptr, &streamed, options);
      ASSERT_FALSE(got.ok());
      EXPECT_EQ(got.status().code(), held.status().code());
      EXPECT_NE(got.status().message().find(dir.path + "/" + blocked),
                std::string::npos)
          << got.status();
      EXPECT_EQ(
          absl::StrReplaceAll(got.status().message(), {{dir.path, "D"}}),
          absl::StrReplaceAll(held.status().message(), {{held_dir.path, "D"}}));
    }
    EXPECT_FALSE(fs::exists(dir.path + "/marks.png.spool"));
    EXPECT_FALSE(fs::exists(dir.path + "/marks.svg.body"));
    // As the chained files: no marks.json after marks.svg failed; marks.svg
    // written before marks.json failed.
    EXPECT_EQ(fs::is_regular_file(dir.path + "/marks.json"),
              fs::is_regular_file(held_dir.path + "/marks.json"));
    EXPECT_EQ(fs::is_regular_file(dir.path + "/marks.svg"),
              fs::is_regular_file(held_dir.path + "/marks.svg"));
  }
  {
    // Marks spooled for another picture than marks.png's.
    TempDir dir;
    MarksStream stream(Stock(), dir.path, kDefaultMarkDisplay,
                       ReliefFrame(Stock(), {.max_side = 50, .min_side = 50}));
    for (const MarkPolyline& p : marks) stream.Add(p);
    stream.Finish();
    const StreamedMarks streamed = stream.streamed();
    ASSERT_TRUE(streamed.status.ok()) << streamed.status;
    auto got =
        WriteRunOutputsStreamed(dir.path, bands, nullptr, &streamed, options);
    EXPECT_EQ(got.status(),
              absl::InvalidArgumentError("the streamed marks were kept for a "
                                         "50 x 41 picture, marks.png is 100 x "
                                         "83"));
  }
  {
    // A fetch that fails half way: the stream goes unfinished.
    TempDir dir;
    {
      MarksStream stream(Stock(), dir.path, kDefaultMarkDisplay,
                         ReliefFrame(Stock(), options.marks.relief),
                         {.batch_vertices = 10});
      for (size_t k = 0; k < marks.size() / 2; ++k) stream.Add(marks[k]);
      EXPECT_TRUE(fs::exists(dir.path + "/marks.png.spool"));
    }
    EXPECT_TRUE(fs::is_empty(dir.path));
  }
  {
    // marks.png fails (a bad stroke width): the spool still goes.
    TempDir dir;
    {
      MarksStream stream(Stock(), dir.path, kDefaultMarkDisplay,
                         ReliefFrame(Stock(), options.marks.relief));
      for (const MarkPolyline& p : marks) stream.Add(p);
      stream.Finish();
      const StreamedMarks streamed = stream.streamed();
      RunOutputOptions o = options;
      o.marks.line_width_px = 1000;
      auto got =
          WriteRunOutputsStreamed(dir.path, bands, nullptr, &streamed, o);
      EXPECT_EQ(got.status().code(), absl::StatusCode::kInvalidArgument);
    }
    EXPECT_FALSE(fs::exists(dir.path + "/marks.png.spool"));
  }
}

// Resident memory of `swarf run` on 4101 x 4101 nodes (16.8 M, past the old
// 16 M-node default cap), every output: within 16 bytes a node + 1 GiB.
// Skipped under the sanitizers (their shadow memory is not the program's).
TEST(StreamedOutputsTest, LargeGridRunStaysWithinTheMemoryBound) {
#if defined(SWARF_SANITIZED)
  GTEST_SKIP() << "peak memory is not measured under the sanitizers";
#endif
  TempDir dir;
  const std::string job = dir.path + "/job.nc";
  {
    // A few ball passes across the stock, crossing (marks) and leaving it.
    std::ofstream f(job);
    f << "G21 G90\nG0 Z5\nG0 X-5 Y20\nG1 Z-2 F1000\nG1 X415 Y390\n"
         "G1 X415 Y200\nG1 X-5 Y200\nG1 X200 Y-5\nG1 X200 Y415\n"
         "G1 X-5 Y395\nG0 Z5\nM2\n";
  }
  const std::string out = dir.path + "/out";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int null = open("/dev/null", O_WRONLY);
    if (null >= 0) {
      dup2(null, 1);
      dup2(null, 2);
    }
    execl(SWARF_CLI, SWARF_CLI, "run", job.c_str(), "--tool", "ball:d=6",
          "--stock", "0,0,410,410,0", "--spacing", "0.1", "--scheme", "taylor",
          "--picture-size", "1024", "--out", out.c_str(), "--quiet",
          static_cast<char*>(nullptr));
    _exit(127);
  }
  int status = 0;
  struct rusage ru {};
  ASSERT_EQ(wait4(pid, &status, 0, &ru), pid);
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 0);
  const nlohmann::json stats =
      nlohmann::json::parse(ReadAll(out + "/stats.json"));
  ASSERT_EQ(stats["stock"]["nx"], 4100);
  ASSERT_EQ(stats["stock"]["ny"], 4100);
  const int64_t nodes = int64_t{4101} * 4101;
  ASSERT_GT(nodes, int64_t{16} << 20);
  // Every output was written: the mesh and the marks are there.
  EXPECT_GT(stats["mesh"]["triangles"].get<int64_t>(), 0);
  EXPECT_GT(stats["marks"]["polylines"].get<int64_t>(), 0);
  for (const char* f : {"relief.png", "error.png", "marks.png", "marks.svg",
                        "marks.json", "surface.stl", "surface.wrl"}) {
    EXPECT_TRUE(fs::exists(out + "/" + f)) << f;
  }
  const int64_t peak = int64_t{ru.ru_maxrss} * 1024;  // KiB on Linux
  const int64_t bound = 16 * nodes + (int64_t{1} << 30);
  EXPECT_LE(peak, bound) << "peak " << peak / (1 << 20) << " MiB, bound "
                         << bound / (1 << 20) << " MiB";
  std::printf(
      "swarf run on %lld nodes: peak resident %lld MiB (bound %lld "
      "MiB)\n",
      static_cast<long long>(nodes), static_cast<long long>(peak >> 20),
      static_cast<long long>(bound >> 20));
}

}  // namespace
}  // namespace swarf::cli
