#include "client/run_outputs.h"

#include <chrono>

#include "absl/strings/str_cat.h"
#include "client/marks_files.h"
#include "client/png_image.h"

namespace swarf::cli {
namespace {

using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace

absl::StatusOr<std::vector<WrittenFile>> WriteRunOutputs(
    const std::string& dir, const SurfaceGrid& grid, const ErrorRaster* error,
    const std::vector<MarkPolyline>* marks, const RunOutputOptions& options,
    RunOutputSummary* summary) {
  std::vector<WrittenFile> written;
  const std::string base = dir.empty() || dir.back() == '/' ? dir : dir + "/";
  auto done = [&](const std::string& name, Clock::time_point t0) {
    written.push_back({base + name, Since(t0)});
  };
  auto t0 = Clock::now();
  absl::StatusOr<Image> relief = RenderRelief(grid, options.relief);
  if (!relief.ok()) return relief.status();
  if (absl::Status st = WritePng(*relief, base + "relief.png"); !st.ok()) {
    return st;
  }
  done("relief.png", t0);

  if (error != nullptr) {
    t0 = Clock::now();
    absl::StatusOr<Image> map = RenderErrorMap(*error, options.error);
    if (!map.ok()) return map.status();
    if (absl::Status st = WritePng(*map, base + "error.png"); !st.ok()) {
      return st;
    }
    done("error.png", t0);
  }

  if (marks != nullptr) {
    t0 = Clock::now();
    // The relief already drawn serves when the frames agree (grids of about
    // 1000 nodes and more per side).
    const PixelFrame frame = ReliefFrame(grid.spec, options.marks.relief);
    absl::StatusOr<Image> finer;
    if (!(frame == ReliefFrame(grid.spec, options.relief))) {
      finer = RenderRelief(grid, options.marks.relief);
      if (!finer.ok()) return finer.status();
    }
    absl::StatusOr<Image> picture = DrawMarks(
        finer.ok() ? *finer : *relief, frame, *marks, options.marks);
    if (!picture.ok()) return picture.status();
    if (absl::Status st = WritePng(*picture, base + "marks.png"); !st.ok()) {
      return st;
    }
    done("marks.png", t0);
    t0 = Clock::now();
    if (absl::Status st = WriteMarksSvg(grid.spec, *marks, base + "marks.svg");
        !st.ok()) {
      return st;
    }
    done("marks.svg", t0);
    t0 = Clock::now();
    if (absl::Status st = WriteMarksJson(*marks, base + "marks.json");
        !st.ok()) {
      return st;
    }
    done("marks.json", t0);
  }

  t0 = Clock::now();
  SurfaceMeshOptions full_options = options.mesh;
  full_options.tolerance = 0;
  absl::StatusOr<TriangleMesh> mesh = BuildSurfaceMesh(grid, full_options);
  if (!mesh.ok()) return mesh.status();
  const int64_t full_triangles = static_cast<int64_t>(mesh->triangles.size());
  if (options.mesh.tolerance != 0) {
    mesh = SimplifySurfaceMesh(*mesh, options.mesh.tolerance);
    if (!mesh.ok()) return mesh.status();
  }
  if (summary != nullptr) {
    summary->full_mesh_triangles = full_triangles;
    summary->mesh_triangles = static_cast<int64_t>(mesh->triangles.size());
    summary->mesh_deviation = mesh->max_deviation;
  }
  if (absl::Status st = WriteStl(*mesh, base + "surface.stl"); !st.ok()) {
    return st;
  }
  done("surface.stl", t0);
  t0 = Clock::now();
  const std::vector<Rgb> colors =
      options.vrml_colors ? SurfaceColors(*mesh, grid.spec.z_top)
                          : std::vector<Rgb>();
  if (absl::Status st = WriteVrml(*mesh, base + "surface.wrl", colors);
      !st.ok()) {
    return st;
  }
  done("surface.wrl", t0);
  return written;
}

}  // namespace swarf::cli
