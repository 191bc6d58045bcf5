#include "client/run_outputs.h"

#include <chrono>
#include <functional>
#include <future>

#include "absl/strings/str_cat.h"
#include "client/marks_files.h"
#include "client/png_image.h"

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
  void Then(const std::string& name,
            const std::function<absl::Status(const std::string&)>& write) {
    if (!status_.ok()) return;
    const auto t0 = Clock::now();
    status_ = write(base_ + name);
    if (status_.ok()) written_.push_back({base_ + name, Since(t0)});
  }
  absl::Status status() const { return status_; }
  const std::vector<WrittenFile>& written() const { return written_; }

 private:
  const std::string base_;
  absl::Status status_;
  std::vector<WrittenFile> written_;
};

}  // namespace

absl::StatusOr<std::vector<WrittenFile>> WriteRunOutputs(
    const std::string& dir, const SurfaceGrid& grid, const ErrorRaster* error,
    const std::vector<MarkPolyline>* marks, const RunOutputOptions& options,
    RunOutputSummary* summary) {
  const std::string base = dir.empty() || dir.back() == '/' ? dir : dir + "/";
  // Three independent chains at once (most writers are serial): the
  // pictures, the marks files, the meshes.
  auto meshes = std::async(std::launch::async, [&] {
    Chain c(base);
    absl::StatusOr<TriangleMesh> mesh;
    c.Then("surface.stl", [&](const std::string& path) {
      mesh = BuildSurfaceMesh(grid, options.mesh);
      if (!mesh.ok()) return mesh.status();
      return WriteStl(*mesh, path);
    });
    c.Then("surface.wrl", [&](const std::string& path) {
      const std::vector<Rgb> colors =
          options.vrml_colors ? SurfaceColors(*mesh, grid.spec.z_top)
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
  if (marks != nullptr) {
    marks_files = std::async(std::launch::async, [&] {
      Chain c(base);
      c.Then("marks.svg", [&](const std::string& path) {
        return WriteMarksSvg(grid.spec, *marks, path);
      });
      c.Then("marks.json", [&](const std::string& path) {
        return WriteMarksJson(*marks, path);
      });
      return c;
    });
  }

  Chain pictures(base);
  absl::StatusOr<Image> relief;
  pictures.Then("relief.png", [&](const std::string& path) {
    relief = RenderRelief(grid, options.relief);
    if (!relief.ok()) return relief.status();
    return WritePng(*relief, path);
  });
  if (error != nullptr) {
    pictures.Then("error.png", [&](const std::string& path) {
      absl::StatusOr<Image> map = RenderErrorMap(*error, options.error);
      if (!map.ok()) return map.status();
      return WritePng(*map, path);
    });
  }
  if (marks != nullptr) {
    pictures.Then("marks.png", [&](const std::string& path) {
      // The relief already drawn serves when the frames agree.
      absl::StatusOr<Image> picture =
          RenderMarks(grid, *marks, options.marks, &*relief, options.relief);
      if (!picture.ok()) return picture.status();
      return WritePng(*picture, path);
    });
  }

  std::vector<Chain> chains;
  chains.push_back(std::move(pictures));
  if (marks_files.valid()) chains.push_back(marks_files.get());
  chains.push_back(meshes.get());
  std::vector<WrittenFile> written;
  for (const Chain& c : chains) {
    if (!c.status().ok()) return c.status();
    written.insert(written.end(), c.written().begin(), c.written().end());
  }
  return written;
}

}  // namespace swarf::cli
