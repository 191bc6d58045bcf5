// Closest-point queries on the design mesh, for the normal deviation: the
// shortest distance from a point of the machined surface to the design
// surface. Embree's BVH (Apache-2.0) finds the candidate triangles; the
// distance to each is computed here in double precision.
//
// Why Embree and not CGAL's AABB tree: CGAL's AABB_tree package is GPL-3
// (it would bind the binary), Embree is Apache-2.0 like swarf, and its BVH
// build and point queries are vectorized (docs/benchmarks.md has the
// figures).
//
// Only the surfaces a 3-axis tool can reach from above count: on a closed
// mesh (a solid) the triangles that face downwards are left out, so that a
// deep gouge in a thin part is not measured to the part's underside. An
// open mesh (a top surface) is taken whole, whatever its winding.
//
// Contract: millimetres. Build copies what it needs of the mesh (floats for
// Embree's BVH) but reads the mesh's double vertices at query time: the
// mesh must outlive the index. Distance() is thread-safe (Embree's point
// queries are); the index is immutable once built.
#ifndef SWARF_DESIGN_CLOSEST_POINT_H_
#define SWARF_DESIGN_CLOSEST_POINT_H_

#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry.h"
#include "design/design_mesh.h"

namespace swarf::design {

class ClosestPointIndex {
 public:
  // Internal on an Embree failure (its message).
  static absl::StatusOr<std::unique_ptr<ClosestPointIndex>> Build(
      const DesignMesh& mesh);
  ~ClosestPointIndex();
  ClosestPointIndex(const ClosestPointIndex&) = delete;
  ClosestPointIndex& operator=(const ClosestPointIndex&) = delete;

  // The distance from p to the mesh, if it is below max_distance (else
  // max_distance is returned, and `closest` is untouched). `closest`, if
  // given, receives the nearest point of the mesh.
  double Distance(const Vec3& p, double max_distance,
                  Vec3* closest = nullptr) const;

 private:
  struct Embree;
  explicit ClosestPointIndex(const DesignMesh& mesh);
  const DesignMesh& mesh_;
  std::vector<int32_t> triangle_of_;  // Embree's primitive -> triangle
  std::unique_ptr<Embree> embree_;
};

// The point of triangle (a, b, c) nearest to p (Ericson, Real-Time Collision
// Detection, 5.1.5: the Voronoi regions of the vertices, edges and face).
Vec3 ClosestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b,
                            const Vec3& c);

}  // namespace swarf::design

#endif  // SWARF_DESIGN_CLOSEST_POINT_H_
