// The design's top envelope z_d(x, y): the highest design surface above each
// point of the XY plane (NaN where no triangle lies above it: nothing to
// keep there). For 3-axis milling this is what must remain of the stock.
//
// Contract:
// - Units: millimetres; the grid is the session's (GridGeometry), node (i, j)
//   at NodeX(i), NodeY(j) exactly as in the core.
// - The node raster is one float per node (4 bytes a node), computed once
//   per design and grid. At() answers between nodes from the triangles
//   themselves (a bin index over the design's XY projection), exact to the
//   double arithmetic of one plane through three points.
// - Immutable once built: every const method is thread-safe. Keeps a
//   reference to the mesh, which must outlive it.
#ifndef SWARF_DESIGN_TOP_ENVELOPE_H_
#define SWARF_DESIGN_TOP_ENVELOPE_H_

#include <cmath>
#include <array>
#include <cstdint>
#include <limits>
#include <vector>

#include "absl/status/statusor.h"
#include "core/stock.h"
#include "core/thread_pool.h"
#include "design/design_mesh.h"

namespace swarf::design {

class TopEnvelope {
 public:
  // Rasterizes every non-vertical triangle onto the grid's nodes (on
  // `pool`, default ThreadPool::Default(); the same floats whatever its
  // size) and indexes the triangles by XY bins. InvalidArgument when the
  // design's XY bounds miss the stock rectangle entirely.
  static absl::StatusOr<TopEnvelope> Build(const DesignMesh& mesh,
                                           const GridGeometry& grid,
                                           ThreadPool* pool = nullptr);

  // z_d at node (i, j), NaN where no design lies above it.
  float AtNode(int32_t i, int32_t j) const {
    return nodes_[int64_t{j} * grid_.nodes_x() + i];
  }
  const std::vector<float>& nodes() const { return nodes_; }
  // z_d at any point, NaN where no design lies above it.
  double At(double x, double y) const;
  // The same for points of a small rectangle r, from its candidates: the
  // non-vertical triangles whose XY bounds meet r, less those that surely
  // hold no point of r, in bin order (Candidates replaces `out`'s
  // contents), then AtAmong(out, x, y) == At(x, y) for (x, y) in r.
  void Candidates(const Rect& r, std::vector<int32_t>* out) const;
  // AtAmong at n points at once: out[q] for (x[q], y[q]), bit for bit the
  // same (a loop over the points per triangle, which vectorizes).
  void AtManyAmong(const std::vector<int32_t>& candidates, const double* x,
                   const double* y, int32_t n, double* out) const;
  double AtAmong(const std::vector<int32_t>& candidates, double x,
                 double y) const {
    double best = std::numeric_limits<double>::quiet_NaN();
    for (int32_t t : candidates) {
      const double z = HeightAt(planes_[t], x, y);
      if (!std::isnan(z) && !(best >= z)) best = z;
    }
    return best;
  }

  const GridGeometry& grid() const { return grid_; }
  const DesignMesh& mesh() const { return *mesh_; }
  // Nodes with design above them.
  int64_t covered_nodes() const { return covered_; }

  // A non-vertical triangle as its barycentric map from vertex a:
  // (wb, wc) = m * (x - xa, y - ya), inside when wb, wc >= 0 and
  // wb + wc <= 1 (with a 1e-12 margin), z = za + wb dzb + wc dzc clamped
  // to the triangle's [zlo, zhi] (inside a near-vertical sliver rounding
  // may not extrapolate far). xa is NaN for a vertical triangle.
  struct Plane {
    double xa, ya, za, m00, m01, m10, m11, dzb, dzc, zlo, zhi;
  };
  static Plane PlaneOf(const DesignMesh& mesh, int32_t t);
  static double HeightAt(const Plane& p, double x, double y);

 private:
  TopEnvelope(const DesignMesh& mesh, const GridGeometry& grid)
      : mesh_(&mesh), grid_(grid) {}

  const DesignMesh* mesh_;
  GridGeometry grid_;
  std::vector<Plane> planes_;  // one per triangle
  // Each triangle's XY bounds (x0, y0, x1, y1), rounded outwards to floats.
  std::vector<std::array<float, 4>> bounds_;
  std::vector<float> nodes_;
  int64_t covered_ = 0;
  // Bins over the design's XY bounds: bin (bx, by) holds the non-vertical
  // triangles whose XY bounds meet it, bin_start_[b] .. bin_start_[b + 1]
  // in bin_tris_.
  double bx0_ = 0, by0_ = 0, bsize_ = 1;
  int32_t bnx_ = 1, bny_ = 1;
  std::vector<int64_t> bin_start_;
  std::vector<int32_t> bin_tris_;
};

}  // namespace swarf::design

#endif  // SWARF_DESIGN_TOP_ENVELOPE_H_
