#include "design/top_envelope.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_format.h"

namespace swarf::design {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// HeightAt's margin on the barycentric coordinates: a point on an edge is
// inside whatever the rounding.
constexpr double kEdge = 1e-12;
// Node rows a rasterizing task owns: tasks never write the same node.
constexpr int32_t kBandRows = 16;
// Nodes of a row a triangle is tested against at once before its nodes.
constexpr int32_t kRasterRun = 16;

// Lists of items per bucket, compressed: bucket b holds
// items[start[b] .. start[b + 1]), in item order. visit(t, add) calls
// add(bucket) for each bucket of item t; it runs twice (count, then fill).
template <typename Visit>
void BuildBuckets(int64_t buckets, int32_t n, const Visit& visit,
                  std::vector<int64_t>* start, std::vector<int32_t>* items) {
  start->assign(buckets + 1, 0);
  for (int32_t t = 0; t < n; ++t) {
    visit(t, [&](int64_t b) { ++(*start)[b + 1]; });
  }
  for (int64_t b = 1; b <= buckets; ++b) (*start)[b] += (*start)[b - 1];
  items->resize(start->back());
  std::vector<int64_t> fill(start->begin(), start->end() - 1);
  for (int32_t t = 0; t < n; ++t) {
    visit(t, [&](int64_t b) { (*items)[fill[b]++] = t; });
  }
}

// True when no point of r is inside p's triangle as HeightAt tests it
// (with its 1e-12 margin). The barycentric coordinates are affine, so over
// r they are extreme at the corners their coefficients' signs pick; those
// values are widened by 1e-9 of their scale, where rounding (at a point of
// r and here) moves them by about 1e-15 of it. A NaN fails every
// comparison: such a triangle is kept.
bool SurelyOutside(const TopEnvelope::Plane& p, const Rect& r) {
  const double x0 = r.x0 - p.xa, x1 = r.x1 - p.xa;
  const double y0 = r.y0 - p.ya, y1 = r.y1 - p.ya;
  const double max_b =
      p.m00 * (p.m00 > 0 ? x1 : x0) + p.m01 * (p.m01 > 0 ? y1 : y0);
  const double max_c =
      p.m10 * (p.m10 > 0 ? x1 : x0) + p.m11 * (p.m11 > 0 ? y1 : y0);
  const double sx = p.m00 + p.m10, sy = p.m01 + p.m11;
  const double min_sum = sx * (sx > 0 ? x0 : x1) + sy * (sy > 0 ? y0 : y1);
  const double reach = std::max(std::max(std::fabs(x0), std::fabs(x1)),
                                std::max(std::fabs(y0), std::fabs(y1)));
  const double slack_b =
      1e-9 * ((std::fabs(p.m00) + std::fabs(p.m01)) * reach + 1);
  const double slack_c =
      1e-9 * ((std::fabs(p.m10) + std::fabs(p.m11)) * reach + 1);
  return max_b < -kEdge - slack_b || max_c < -kEdge - slack_c ||
         min_sum > 1 + kEdge + slack_b + slack_c;
}

}  // namespace

TopEnvelope::Plane TopEnvelope::PlaneOf(const DesignMesh& mesh, int32_t t) {
  const auto& tri = mesh.triangles[t];
  const Vec3& a = mesh.vertices[tri[0]];
  const Vec3& b = mesh.vertices[tri[1]];
  const Vec3& c = mesh.vertices[tri[2]];
  const double ux = b.x - a.x, uy = b.y - a.y, vx = c.x - a.x, vy = c.y - a.y;
  // Twice the signed XY area; next to nothing: the triangle is vertical.
  const double d = ux * vy - uy * vx;
  const double span =
      std::max({std::fabs(ux), std::fabs(uy), std::fabs(vx), std::fabs(vy)});
  if (!(std::fabs(d) > 1e-12 * span * span)) {
    return {kNaN, kNaN, kNaN, 0, 0, 0, 0, 0, 0, 0, 0};
  }
  // The inverse of [u v]: (x - xa, y - ya) = wb u + wc v.
  return {a.x,       a.y,       a.z,       vy / d,
          -vx / d,   -uy / d,   ux / d,    b.z - a.z,
          c.z - a.z, std::min({a.z, b.z, c.z}), std::max({a.z, b.z, c.z})};
}

double TopEnvelope::HeightAt(const Plane& p, double x, double y) {
  const double rx = x - p.xa, ry = y - p.ya;
  const double wb = p.m00 * rx + p.m01 * ry;
  const double wc = p.m10 * rx + p.m11 * ry;
  // NaN (a vertical triangle) fails every comparison.
  if (!(wb >= -kEdge && wc >= -kEdge && wb + wc <= 1 + kEdge)) return kNaN;
  return std::min(std::max(p.za + wb * p.dzb + wc * p.dzc, p.zlo), p.zhi);
}

absl::StatusOr<TopEnvelope> TopEnvelope::Build(const DesignMesh& mesh,
                                               const GridGeometry& grid,
                                               ThreadPool* pool) {
  const Rect stock = grid.bounds();
  if (mesh.x.empty() || mesh.x.hi < stock.x0 || mesh.x.lo > stock.x1 ||
      mesh.y.hi < stock.y0 || mesh.y.lo > stock.y1) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "the design [%.4g, %.4g] x [%.4g, %.4g] lies outside the stock "
        "[%.4g, %.4g] x [%.4g, %.4g] (check --design-offset and "
        "--design-units)",
        mesh.x.lo, mesh.x.hi, mesh.y.lo, mesh.y.hi, stock.x0, stock.x1,
        stock.y0, stock.y1));
  }
  if (pool == nullptr) pool = &ThreadPool::Default();
  TopEnvelope env(mesh, grid);
  const int32_t nxn = grid.nodes_x(), nyn = grid.nodes_y();
  env.nodes_.assign(static_cast<size_t>(grid.node_count()),
                    std::numeric_limits<float>::quiet_NaN());

  // Each triangle's plane and XY bounds, read once.
  const int32_t ntri = static_cast<int32_t>(mesh.triangles.size());
  env.planes_.resize(ntri);
  env.bounds_.resize(ntri);
  std::vector<Rect> xy(ntri);
  for (int32_t t = 0; t < ntri; ++t) {
    env.planes_[t] = PlaneOf(mesh, t);
    const auto& tri = mesh.triangles[t];
    const Vec3& a = mesh.vertices[tri[0]];
    const Vec3& b = mesh.vertices[tri[1]];
    const Vec3& c = mesh.vertices[tri[2]];
    xy[t] = {std::min({a.x, b.x, c.x}), std::min({a.y, b.y, c.y}),
             std::max({a.x, b.x, c.x}), std::max({a.y, b.y, c.y})};
    // HeightAt's 1e-12 margin holds points up to about 2e-12 of the
    // triangle's extent beyond its bounds: widened by twice that, the
    // bins, the candidates and the nodes keep them (a triangle 1e-19 mm
    // across beside the origin held a point its float bounds left out).
    const double pad =
        4e-12 * std::max(xy[t].x1 - xy[t].x0, xy[t].y1 - xy[t].y0);
    xy[t] = {xy[t].x0 - pad, xy[t].y0 - pad, xy[t].x1 + pad, xy[t].y1 + pad};
    auto down = [](double v) {
      return std::nextafter(static_cast<float>(v), -HUGE_VALF);
    };
    auto up = [](double v) {
      return std::nextafter(static_cast<float>(v), HUGE_VALF);
    };
    env.bounds_[t] = {down(xy[t].x0), down(xy[t].y0), up(xy[t].x1),
                      up(xy[t].y1)};
  }
  auto vertical = [&](int32_t t) { return std::isnan(env.planes_[t].xa); };

  // Each non-vertical triangle's node rectangle (clamped to the grid; empty:
  // none), listed in the bands of node rows it meets.
  struct NodeBox {
    int32_t i0, i1, j0, j1;
  };
  std::vector<NodeBox> boxes(ntri);
  const double dx = grid.dx(), dy = grid.dy();
  auto lo_index = [](double v, double origin, double step, int32_t n) {
    return static_cast<int32_t>(
        std::clamp(std::ceil((v - origin) / step - 1e-9), 0.0, double(n)));
  };
  auto hi_index = [](double v, double origin, double step, int32_t n) {
    return static_cast<int32_t>(
        std::clamp(std::floor((v - origin) / step + 1e-9), -1.0, double(n - 1)));
  };
  for (int32_t t = 0; t < ntri; ++t) {
    boxes[t] = vertical(t)
                   ? NodeBox{1, 0, 1, 0}
                   : NodeBox{lo_index(xy[t].x0, stock.x0, dx, nxn),
                             hi_index(xy[t].x1, stock.x0, dx, nxn),
                             lo_index(xy[t].y0, stock.y0, dy, nyn),
                             hi_index(xy[t].y1, stock.y0, dy, nyn)};
  }
  std::vector<int64_t> band_count;
  std::vector<int32_t> band_tris;
  BuildBuckets((nyn + kBandRows - 1) / kBandRows, ntri,
               [&](int32_t t, const auto& add) {
                 const NodeBox& nb = boxes[t];
                 if (nb.i0 > nb.i1 || nb.j0 > nb.j1) return;
                 for (int32_t band = nb.j0 / kBandRows;
                      band <= nb.j1 / kBandRows; ++band) {
                   add(band);
                 }
               },
               &band_count, &band_tris);
  const int64_t bands = static_cast<int64_t>(band_count.size()) - 1;
  std::vector<int64_t> band_covered(bands, 0);
  pool->ParallelFor(bands, [&](int64_t band) {
    const int32_t jb0 = static_cast<int32_t>(band * kBandRows);
    const int32_t jb1 = std::min(nyn - 1, jb0 + kBandRows - 1);
    for (int64_t k = band_count[band]; k < band_count[band + 1]; ++k) {
      const int32_t t = band_tris[k];
      const NodeBox& nb = boxes[t];
      const Plane& plane = env.planes_[t];
      for (int32_t j = std::max(jb0, nb.j0); j <= std::min(jb1, nb.j1); ++j) {
        const double y = grid.NodeY(j);
        float* row = &env.nodes_[int64_t{j} * nxn];
        // The row's nodes kRasterRun at a time, passing over the runs the
        // triangle surely misses (a long thin triangle's box holds many).
        for (int32_t r0 = nb.i0; r0 <= nb.i1; r0 += kRasterRun) {
          const int32_t r1 = std::min(nb.i1, r0 + kRasterRun - 1);
          if (nb.i1 - nb.i0 >= kRasterRun &&
              SurelyOutside(plane,
                            Rect{grid.NodeX(r0), y, grid.NodeX(r1), y})) {
            continue;
          }
          for (int32_t i = r0; i <= r1; ++i) {
            const double z = HeightAt(plane, grid.NodeX(i), y);
            if (std::isnan(z)) continue;
            const float zf = static_cast<float>(z);
            if (!(row[i] >= zf)) row[i] = zf;  // NaN or lower
          }
        }
      }
    }
    int64_t covered = 0;
    for (int32_t j = jb0; j <= jb1; ++j) {
      const float* row = &env.nodes_[int64_t{j} * nxn];
      for (int32_t i = 0; i < nxn; ++i) covered += !std::isnan(row[i]);
    }
    band_covered[band] = covered;
  });
  for (int64_t c : band_covered) env.covered_ += c;

  // Bins for At(): about two triangles a bin, at most 4 M bins.
  const double w = std::max(mesh.x.hi - mesh.x.lo, 1e-9);
  const double h = std::max(mesh.y.hi - mesh.y.lo, 1e-9);
  env.bsize_ = std::max(std::sqrt(w * h / std::max(1, ntri / 2)),
                        std::sqrt(w * h / 4e6));
  env.bx0_ = mesh.x.lo;
  env.by0_ = mesh.y.lo;
  env.bnx_ = std::max(1, static_cast<int32_t>(std::ceil(w / env.bsize_)));
  env.bny_ = std::max(1, static_cast<int32_t>(std::ceil(h / env.bsize_)));
  const int64_t nbins = int64_t{env.bnx_} * env.bny_;
  auto cell = [&](double v, double o, int32_t n) {
    return std::clamp(static_cast<int32_t>(std::floor((v - o) / env.bsize_)),
                      0, n - 1);
  };
  // The points At and Candidates look up in bin (bx, by): its square,
  // widened against the rounding of the bin's floor, and by a bin more
  // beyond the first and last rows and columns (points outside the bounds
  // are clamped into them).
  const double bin_slack = 1e-6 * env.bsize_;
  auto bin_rect = [&](int32_t bx, int32_t by) {
    return Rect{
        env.bx0_ + (bx - (bx == 0 ? 1 : 0)) * env.bsize_ - bin_slack,
        env.by0_ + (by - (by == 0 ? 1 : 0)) * env.bsize_ - bin_slack,
        env.bx0_ + (bx + (bx == env.bnx_ - 1 ? 2 : 1)) * env.bsize_ + bin_slack,
        env.by0_ + (by + (by == env.bny_ - 1 ? 2 : 1)) * env.bsize_ +
            bin_slack};
  };
  // A triangle goes in the bins its XY bounds meet, less those it surely
  // misses: a long thin one (a fan's, as CAD exports planar faces) would
  // be in every bin of its bounds, and scanned there for every point.
  BuildBuckets(nbins, ntri,
               [&](int32_t t, const auto& add) {
                 if (vertical(t)) return;
                 const int32_t bx0 = cell(xy[t].x0, env.bx0_, env.bnx_);
                 const int32_t bx1 = cell(xy[t].x1, env.bx0_, env.bnx_);
                 const int32_t by0 = cell(xy[t].y0, env.by0_, env.bny_);
                 const int32_t by1 = cell(xy[t].y1, env.by0_, env.bny_);
                 // A triangle whose bounds span 16 bins or fewer goes in
                 // all of them: a mesh of small triangles has many that
                 // span a few, and the tests (serial here, twice a bin)
                 // would cost more than the few bins they leave out.
                 const bool few =
                     int64_t{bx1 - bx0 + 1} * (by1 - by0 + 1) <= 16;
                 for (int32_t by = by0; by <= by1; ++by) {
                   for (int32_t bx = bx0; bx <= bx1; ++bx) {
                     if (!few &&
                         SurelyOutside(env.planes_[t], bin_rect(bx, by))) {
                       continue;
                     }
                     add(int64_t{by} * env.bnx_ + bx);
                   }
                 }
               },
               &env.bin_start_, &env.bin_tris_);
  return env;
}

void TopEnvelope::Candidates(const Rect& r, std::vector<int32_t>* out) const {
  out->clear();
  const double fx0 = std::floor((r.x0 - bx0_) / bsize_);
  const double fx1 = std::floor((r.x1 - bx0_) / bsize_);
  const double fy0 = std::floor((r.y0 - by0_) / bsize_);
  const double fy1 = std::floor((r.y1 - by0_) / bsize_);
  if (!(fx1 >= -1 && fx0 <= bnx_ && fy1 >= -1 && fy0 <= bny_)) return;
  const int32_t bx0 = std::clamp(static_cast<int32_t>(std::max(fx0, -1.0)), 0, bnx_ - 1);
  const int32_t bx1 = std::clamp(static_cast<int32_t>(std::min(fx1, double(bnx_))), 0, bnx_ - 1);
  const int32_t by0 = std::clamp(static_cast<int32_t>(std::max(fy0, -1.0)), 0, bny_ - 1);
  const int32_t by1 = std::clamp(static_cast<int32_t>(std::min(fy1, double(bny_))), 0, bny_ - 1);
  for (int32_t by = by0; by <= by1; ++by) {
    for (int32_t bx = bx0; bx <= bx1; ++bx) {
      const int64_t b = int64_t{by} * bnx_ + bx;
      for (int64_t k = bin_start_[b]; k < bin_start_[b + 1]; ++k) {
        const int32_t t = bin_tris_[k];
        const auto& bb = bounds_[t];
        if (bb[0] > r.x1 || bb[2] < r.x0 || bb[1] > r.y1 || bb[3] < r.y0) {
          continue;
        }
        // A long thin triangle (a fan's) meets many rectangles' bounds
        // that it misses.
        if (SurelyOutside(planes_[t], r)) continue;
        if (std::find(out->begin(), out->end(), t) == out->end()) {
          out->push_back(t);
        }
      }
    }
  }
}

void TopEnvelope::AtManyAmong(const std::vector<int32_t>& candidates,
                              const double* x, const double* y, int32_t n,
                              double* out) const {
  for (int32_t q = 0; q < n; ++q) out[q] = kNaN;
  for (int32_t t : candidates) {
    const Plane& p = planes_[t];
    // HeightAt, branch-free: the same arithmetic, so the same bits. The
    // tests joined by & (with &&, GCC 12 does not vectorize the loop).
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) {
      const double rx = x[q] - p.xa, ry = y[q] - p.ya;
      const double wb = p.m00 * rx + p.m01 * ry;
      const double wc = p.m10 * rx + p.m11 * ry;
      const bool inside =
          (wb >= -kEdge) & (wc >= -kEdge) & (wb + wc <= 1 + kEdge);
      const double z =
          std::min(std::max(p.za + wb * p.dzb + wc * p.dzc, p.zlo), p.zhi);
      out[q] = (inside & !(out[q] >= z)) ? z : out[q];
    }
  }
}

double TopEnvelope::At(double x, double y) const {
  const double fx = std::floor((x - bx0_) / bsize_);
  const double fy = std::floor((y - by0_) / bsize_);
  // A point on the bounds' far edge belongs to the last bin.
  if (!(fx >= -1 && fx <= bnx_ && fy >= -1 && fy <= bny_)) return kNaN;
  const int32_t bx = std::clamp(static_cast<int32_t>(fx), 0, bnx_ - 1);
  const int32_t by = std::clamp(static_cast<int32_t>(fy), 0, bny_ - 1);
  const int64_t b = int64_t{by} * bnx_ + bx;
  double best = kNaN;
  for (int64_t k = bin_start_[b]; k < bin_start_[b + 1]; ++k) {
    const double z = HeightAt(planes_[bin_tris_[k]], x, y);
    if (!std::isnan(z) && !(best >= z)) best = z;
  }
  return best;
}

}  // namespace swarf::design
