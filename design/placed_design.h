// A design placed on a session's grid: its mesh, top envelope and
// closest-point index together, built once per design and grid.
//
// Contract: immutable once placed; shared (std::shared_ptr<const>) by the
// readers of a session, every method thread-safe.
#ifndef SWARF_DESIGN_PLACED_DESIGN_H_
#define SWARF_DESIGN_PLACED_DESIGN_H_

#include <memory>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "core/stock.h"
#include "design/closest_point.h"
#include "design/design_mesh.h"
#include "design/top_envelope.h"

namespace swarf::design {

class PlacedDesign {
 public:
  // The envelope on `grid` and the index; errors as TopEnvelope::Build and
  // ClosestPointIndex::Build, prefixed with `name`.
  static absl::StatusOr<std::shared_ptr<const PlacedDesign>> Place(
      DesignMesh mesh, const GridGeometry& grid, std::string name);

  const std::string& name() const { return name_; }
  const DesignMesh& mesh() const { return mesh_; }
  const TopEnvelope& envelope() const { return *envelope_; }
  const ClosestPointIndex& index() const { return *index_; }

 private:
  PlacedDesign() = default;
  std::string name_;
  DesignMesh mesh_;
  std::optional<TopEnvelope> envelope_;  // reads mesh_
  std::unique_ptr<ClosestPointIndex> index_;  // reads mesh_
};

}  // namespace swarf::design

#endif  // SWARF_DESIGN_PLACED_DESIGN_H_
