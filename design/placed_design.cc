#include "design/placed_design.h"

#include "absl/strings/str_cat.h"

namespace swarf::design {

absl::StatusOr<std::shared_ptr<const PlacedDesign>> PlacedDesign::Place(
    DesignMesh mesh, const GridGeometry& grid, std::string name) {
  // Built in place: the envelope and the index point at mesh_.
  std::shared_ptr<PlacedDesign> d(new PlacedDesign);
  d->name_ = std::move(name);
  d->mesh_ = std::move(mesh);
  auto env = TopEnvelope::Build(d->mesh_, grid);
  if (!env.ok()) {
    return absl::Status(env.status().code(),
                        absl::StrCat(d->name_, ": ", env.status().message()));
  }
  d->envelope_.emplace(*std::move(env));
  auto index = ClosestPointIndex::Build(d->mesh_);
  if (!index.ok()) {
    return absl::Status(index.status().code(),
                        absl::StrCat(d->name_, ": ", index.status().message()));
  }
  d->index_ = *std::move(index);
  return std::shared_ptr<const PlacedDesign>(std::move(d));
}

}  // namespace swarf::design
