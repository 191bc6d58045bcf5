#include "core/safety.h"

#include <algorithm>
#include <cmath>

#include "core/workpiece.h"

namespace swarf {

Contact CylinderContact(const Workpiece& wp, const Vec3& from, const Vec3& to,
                        double radius, double offset) {
  Contact out;
  if (!(radius > 0)) return out;
  const double bottom_min = std::min(from.z, to.z) + offset;
  // Nodes never stand above the stock top.
  if (!(bottom_min < wp.spec().z_top)) return out;
  const GridGeometry& g = wp.grid();
  const double dx = g.dx(), dy = g.dy();
  const double bx0 = std::min(from.x, to.x) - radius;
  const double bx1 = std::max(from.x, to.x) + radius;
  const double by0 = std::min(from.y, to.y) - radius;
  const double by1 = std::max(from.y, to.y) + radius;
  const int32_t i_lo = std::max(0, static_cast<int32_t>(std::ceil((bx0 - wp.spec().x0) / dx)));
  const int32_t i_hi = std::min(g.nx(), static_cast<int32_t>(std::floor((bx1 - wp.spec().x0) / dx)));
  const int32_t j_lo = std::max(0, static_cast<int32_t>(std::ceil((by0 - wp.spec().y0) / dy)));
  const int32_t j_hi = std::min(g.ny(), static_cast<int32_t>(std::floor((by1 - wp.spec().y0) / dy)));
  if (i_lo > i_hi || j_lo > j_hi) return out;
  const double ux = to.x - from.x, uy = to.y - from.y, uz = to.z - from.z;
  const double a = ux * ux + uy * uy;
  const double r2 = radius * radius;
  for (int32_t tj = j_lo >> kTileBits; tj <= j_hi >> kTileBits; ++tj) {
    for (int32_t ti = i_lo >> kTileBits; ti <= i_hi >> kTileBits; ++ti) {
      if (!(wp.TileMax(tj * wp.tiles_x() + ti) > bottom_min)) continue;
      const int32_t j0 = std::max(j_lo, tj << kTileBits);
      const int32_t j1 = std::min(j_hi, (tj << kTileBits) + kTileSize - 1);
      const int32_t i0 = std::max(i_lo, ti << kTileBits);
      const int32_t i1 = std::min(i_hi, (ti << kTileBits) + kTileSize - 1);
      for (int32_t j = j0; j <= j1; ++j) {
        const double y = g.NodeY(j);
        for (int32_t i = i0; i <= i1; ++i) {
          const double w = wp.HeightAt(i, j);
          if (!(w > bottom_min)) continue;
          const double x = g.NodeX(i);
          // The tip's parameters t in [0, 1] where the node is covered:
          // |from + t u - node|^2 <= r^2 in XY.
          const double px = from.x - x, py = from.y - y;
          const double c = px * px + py * py - r2;
          double t0 = 0, t1 = 1;
          if (a > 0) {
            const double b = ux * px + uy * py;  // half the linear term
            const double disc = b * b - a * c;
            if (disc < 0) continue;
            const double s = std::sqrt(disc);
            t0 = std::max(0.0, (-b - s) / a);
            t1 = std::min(1.0, (-b + s) / a);
            if (t0 > t1) continue;
          } else if (c > 0) {
            continue;
          }
          // z is linear in t: the lowest bottom at an end of the interval.
          const double bottom =
              std::min(from.z + t0 * uz, from.z + t1 * uz) + offset;
          const double depth = w - bottom;
          if (!(depth > 0)) continue;
          out.volume_mm3 += depth * dx * dy;
          if (!out.hit || depth > out.depth) {
            out.hit = true;
            out.depth = depth;
            out.x = x;
            out.y = y;
            out.z = w;
          }
        }
      }
    }
  }
  return out;
}

}  // namespace swarf
