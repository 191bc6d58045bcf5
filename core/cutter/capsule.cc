#include "core/cutter/capsule.h"

#include <algorithm>
#include <cmath>

namespace swarf {
namespace {

// As the ball sweep's: keeps the footprint conservative under rounding, so
// that results do not depend on batching.
constexpr double kFootprintMargin = 1e-9;

}  // namespace

void FillDirection(Capsule* c) {
  c->length = std::hypot(c->x1 - c->x0, c->y1 - c->y0);
  if (c->length > 0) {
    c->ux = (c->x1 - c->x0) / c->length;
    c->uy = (c->y1 - c->y0) / c->length;
    c->inv_ux = c->ux != 0 ? 1 / c->ux : 0;
    c->inv_uy = c->uy != 0 ? 1 / c->uy : 0;
  }
}

Capsule TipFootprint(const Vec3& a, const Vec3& b, const Cutter& cutter,
                     double cap) {
  Capsule c;
  // Only tips below the cap put the tool below it.
  const double z_lim = cap + kFootprintMargin;
  double t0 = 0, t1 = 1;
  if (a.z >= z_lim && b.z >= z_lim) return c;
  if (a.z >= z_lim || b.z >= z_lim) {
    const double t = (z_lim - a.z) / (b.z - a.z);
    if (a.z < z_lim) {
      t1 = std::min(1.0, t + 1e-12);
    } else {
      t0 = std::max(0.0, t - 1e-12);
    }
  }
  // The widest reach below the cap is at the lowest tip.
  const double rho =
      FootprintRadius(cutter, std::min(a.z, b.z), cap);
  c.empty = false;
  c.x0 = a.x + t0 * (b.x - a.x);
  c.y0 = a.y + t0 * (b.y - a.y);
  c.x1 = a.x + t1 * (b.x - a.x);
  c.y1 = a.y + t1 * (b.y - a.y);
  c.radius = rho * (1 + 1e-12) + kFootprintMargin;
  FillDirection(&c);
  return c;
}

}  // namespace swarf
