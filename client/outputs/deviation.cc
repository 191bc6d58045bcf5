#include "client/outputs/deviation.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_format.h"
#include "client/outputs/text.h"

namespace swarf::cli {
namespace {

constexpr int32_t kBandRows = 8;  // node rows a task compares

uint64_t LineKey(const SourceLine& s) {
  return (uint64_t{static_cast<uint32_t>(s.file)} << 32) |
         static_cast<uint32_t>(s.line);
}

// What one task found; merged in task order so that the figures do not
// depend on the threads.
struct Partial {
  int64_t nodes = 0, samples = 0, queries = 0;
  double gouge_max = 0, gouge_x = 0, gouge_y = 0;
  int32_t gouge_move = -1;
  double excess_max = 0, excess_x = 0, excess_y = 0;
  double excess_sum = 0, gouge_volume = 0, excess_volume = 0;
  double normal_gouge_max = 0, normal_excess_max = 0;
  double out_area = 0;
  int64_t out_points = 0;
  absl::flat_hash_map<uint64_t, LineDeviation> gouge_lines, excess_lines;
};

void Note(absl::flat_hash_map<uint64_t, LineDeviation>& lines,
          const SourceLine& src, double depth, double x, double y,
          double area) {
  auto [it, added] = lines.try_emplace(LineKey(src));
  LineDeviation& l = it->second;
  if (added) {
    l.file = src.file;
    l.line = src.line;
  }
  if (added || depth > l.depth) {
    l.depth = depth;
    l.x = x;
    l.y = y;
  }
  l.area_mm2 += area;
}

class Comparer {
 public:
  Comparer(const design::ClosestPointIndex& index,
           const std::vector<SourceLine>& move_lines,
           const DeviationOptions& o)
      : index_(index), move_lines_(move_lines), o_(o) {}

  // Compares one point; returns the value deviation.png shows (the signed
  // normal deviation where it was queried, else dz). `area` > 0 for nodes.
  double Point(Partial& p, double x, double y, double z, double zd,
               int32_t owner, double area) const {
    const double dz = z - zd;
    const SourceLine* src =
        owner >= 0 && owner < static_cast<int32_t>(move_lines_.size())
            ? &move_lines_[owner]
            : nullptr;
    if (dz < 0 && -dz > p.gouge_max) {
      p.gouge_max = -dz;
      p.gouge_x = x;
      p.gouge_y = y;
      p.gouge_move = owner;
    } else if (dz > 0 && dz > p.excess_max) {
      p.excess_max = dz;
      p.excess_x = x;
      p.excess_y = y;
    }
    if (area > 0) {
      ++p.nodes;
      if (dz < 0) p.gouge_volume += -dz * area;
      if (dz > 0) {
        p.excess_volume += dz * area;
        p.excess_sum += dz;
      }
    } else {
      ++p.samples;
    }
    // The normal distance is at most |dz|: query only where it can raise a
    // maximum or break the tolerance.
    const double gouge_limit = o_.tolerance;
    const double excess_limit = o_.allowance + o_.tolerance;
    double v = dz;
    if (dz < 0 && (-dz > gouge_limit || -dz > p.normal_gouge_max)) {
      ++p.queries;
      v = -index_.Distance({x, y, z}, -dz);
      p.normal_gouge_max = std::max(p.normal_gouge_max, -v);
      if (-v > gouge_limit) {
        p.out_area += area;
        ++p.out_points;
        if (src != nullptr) Note(p.gouge_lines, *src, -v, x, y, area);
      }
    } else if (dz > 0 && (dz > excess_limit || dz > p.normal_excess_max)) {
      ++p.queries;
      v = index_.Distance({x, y, z}, dz);
      p.normal_excess_max = std::max(p.normal_excess_max, v);
      if (v > excess_limit) {
        p.out_area += area;
        ++p.out_points;
        if (src != nullptr) Note(p.excess_lines, *src, v, x, y, area);
      }
    }
    return v;
  }

 private:
  const design::ClosestPointIndex& index_;
  const std::vector<SourceLine>& move_lines_;
  const DeviationOptions& o_;
};

void Merge(Partial& a, Partial& b) {
  a.nodes += b.nodes;
  a.samples += b.samples;
  a.queries += b.queries;
  if (b.gouge_max > a.gouge_max) {
    a.gouge_max = b.gouge_max;
    a.gouge_x = b.gouge_x;
    a.gouge_y = b.gouge_y;
    a.gouge_move = b.gouge_move;
  }
  if (b.excess_max > a.excess_max) {
    a.excess_max = b.excess_max;
    a.excess_x = b.excess_x;
    a.excess_y = b.excess_y;
  }
  a.excess_sum += b.excess_sum;
  a.gouge_volume += b.gouge_volume;
  a.excess_volume += b.excess_volume;
  a.normal_gouge_max = std::max(a.normal_gouge_max, b.normal_gouge_max);
  a.normal_excess_max = std::max(a.normal_excess_max, b.normal_excess_max);
  a.out_area += b.out_area;
  a.out_points += b.out_points;
  using Lines = absl::flat_hash_map<uint64_t, LineDeviation>;
  for (Lines Partial::*which : {&Partial::gouge_lines, &Partial::excess_lines}) {
    for (const auto& [key, l] : b.*which) {
      Note(a.*which, {l.file, l.line}, l.depth, l.x, l.y, l.area_mm2);
    }
  }
}

std::vector<LineDeviation> Sorted(
    const absl::flat_hash_map<uint64_t, LineDeviation>& lines, int max) {
  std::vector<LineDeviation> v;
  v.reserve(lines.size());
  for (const auto& [key, l] : lines) v.push_back(l);
  std::sort(v.begin(), v.end(), [](const LineDeviation& a, const LineDeviation& b) {
    if (a.depth != b.depth) return a.depth > b.depth;
    if (a.file != b.file) return a.file < b.file;
    return a.line < b.line;
  });
  if (static_cast<int>(v.size()) > max) v.resize(std::max(0, max));
  return v;
}

}  // namespace

absl::StatusOr<DeviationReport> MeasureDeviation(
    const SurfaceGrid& grid, const design::TopEnvelope& envelope,
    const design::ClosestPointIndex& index,
    const std::vector<SourceLine>& move_lines,
    const DeviationOptions& options) {
  if (absl::Status s = grid.Validate(); !s.ok()) return s;
  InMemoryBands bands(grid);
  std::vector<float> values(static_cast<size_t>(grid.geometry().node_count()),
                            std::numeric_limits<float>::quiet_NaN());
  auto r = MeasureDeviation(
      bands, envelope, index, move_lines, options,
      [&](int32_t j0, int32_t j1, const float* v) {
        std::copy_n(v, static_cast<size_t>(j1 - j0) * grid.nodes_x(),
                    values.begin() + grid.Index(0, j0));
      });
  if (r.ok()) r->node_deviation = std::move(values);
  return r;
}

absl::StatusOr<DeviationReport> MeasureDeviation(
    GridBands& grid, const design::TopEnvelope& envelope,
    const design::ClosestPointIndex& index,
    const std::vector<SourceLine>& move_lines, const DeviationOptions& options,
    const std::function<void(int32_t, int32_t, const float*)>& node_rows) {
  if (absl::Status s = ValidateStock(grid.spec()); !s.ok()) return s;
  const GridGeometry g(grid.spec());
  if (envelope.grid().nodes_x() != g.nodes_x() ||
      envelope.grid().nodes_y() != g.nodes_y()) {
    return absl::InvalidArgumentError(
        "the design's envelope was built for another grid");
  }
  if (!(options.allowance >= 0) || !(options.tolerance >= 0) ||
      !std::isfinite(options.allowance) || !std::isfinite(options.tolerance)) {
    return absl::InvalidArgumentError(
        "the allowance and the tolerance must be finite numbers >= 0");
  }
  if (options.samples_per_edge > 64) {
    return absl::InvalidArgumentError("at most 64 samples per element edge");
  }
  ThreadPool& pool = options.pool != nullptr ? *options.pool
                                             : ThreadPool::Default();
  const Comparer cmp(index, move_lines, options);
  DeviationReport r;
  r.allowance = options.allowance;
  r.tolerance = options.tolerance;
  const int32_t nxn = g.nodes_x(), nyn = g.nodes_y();
  const int n = options.samples_per_edge;
  // The tasks: node rows kBandRows at a time, and element rows; a task cut
  // by a band's edge goes on in the next band with the same partial, in
  // the same order.
  std::vector<Partial> node_parts((nyn + kBandRows - 1) / kBandRows);
  std::vector<Partial> sample_parts(n >= 2 ? g.ny() : 0);
  std::vector<float> values;
  absl::Status pass = grid.ForEach([&](const SurfaceGrid& grid, int32_t e0,
                                       int32_t e1) {
    // This band's node rows: [e0, e1), and the last one in the last band.
    const int32_t r0 = e0, r1 = e1 == g.ny() ? nyn : e1;
    values.assign(static_cast<size_t>(r1 - r0) * nxn,
                  std::numeric_limits<float>::quiet_NaN());
    const int64_t c0 = r0 / kBandRows, c1 = (r1 - 1) / kBandRows;
    pool.ParallelFor(c1 - c0 + 1, [&](int64_t x) {
      const int64_t band = c0 + x;
      Partial& p = node_parts[band];
      const int32_t j0 = std::max(r0, static_cast<int32_t>(band * kBandRows));
      const int32_t j1 =
          std::min(r1, static_cast<int32_t>((band + 1) * kBandRows));
      for (int32_t j = j0; j < j1; ++j) {
        const double wy = (j == 0 || j == nyn - 1) ? 0.5 : 1.0;
        const double y = g.NodeY(j);
        for (int32_t i = 0; i < nxn; ++i) {
          const float zd = envelope.AtNode(i, j);
          if (std::isnan(zd)) continue;
          const double wx = (i == 0 || i == nxn - 1) ? 0.5 : 1.0;
          const double v =
              cmp.Point(p, g.NodeX(i), y, grid.jet(i, j).w, zd,
                        grid.owner(i, j), wx * wy * g.dx() * g.dy());
          values[static_cast<size_t>(j - r0) * nxn + i] =
              static_cast<float>(v);
        }
      }
    });

    // The samples between nodes, element row by element row (the sampler
    // keeps what neighbouring elements share).
    if (n >= 2) {
      pool.ParallelFor(e1 - e0, [&](int64_t x) {
        const int64_t ej = e0 + x;
        Partial& p = sample_parts[ej];
        SurfaceSampler sampler(grid);
        std::vector<int32_t> candidates;
        std::vector<double> xs(n * n), ys(n * n), zds(n * n), zs(n * n);
        const double y0 = g.NodeY(static_cast<int32_t>(ej));
        const double y1 = g.NodeY(static_cast<int32_t>(ej) + 1);
        for (int32_t ei = 0; ei < g.nx(); ++ei) {
          const double x0 = g.NodeX(ei);
          // The move that cut deepest in the element: its lowest corner's
          // owner (the nearest corner's may be a move whose cut ends
          // beside).
          int32_t owner = -1;
          double lowest = 0;
          for (int c = 0; c < 4; ++c) {
            const int32_t ci = ei + (c & 1);
            const int32_t cj = static_cast<int32_t>(ej) + (c >> 1);
            const double w = grid.jet(ci, cj).w;
            if (c == 0 || w < lowest) {
              lowest = w;
              owner = grid.owner(ci, cj);
            }
          }
          // The design's triangles over the element, for all its samples.
          const double x1 = g.NodeX(ei + 1);
          envelope.Candidates({x0, y0, x1, y1}, &candidates);
          if (candidates.empty()) continue;
          // The lattice, the design above it, then the points with design.
          int32_t m = 0;
          for (int t = 0; t < n; ++t) {
            const double y = t == n - 1 ? y1 : y0 + t * g.dy() / (n - 1);
            for (int s = 0; s < n; ++s) {
              if ((s == 0 || s == n - 1) && (t == 0 || t == n - 1)) continue;
              xs[m] = s == n - 1 ? x1 : x0 + s * g.dx() / (n - 1);
              ys[m] = y;
              ++m;
            }
          }
          envelope.AtManyAmong(candidates, xs.data(), ys.data(), m,
                               zds.data());
          int32_t kept = 0;
          for (int32_t q = 0; q < m; ++q) {
            if (std::isnan(zds[q])) continue;
            xs[kept] = xs[q];
            ys[kept] = ys[q];
            zds[kept] = zds[q];
            ++kept;
          }
          m = kept;
          if (m == 0) continue;
          sampler.ReconstructInElement(ei, static_cast<int32_t>(ej),
                                       xs.data(), ys.data(), m, zs.data());
          for (int32_t q = 0; q < m; ++q) {
            cmp.Point(p, xs[q], ys[q], zs[q], zds[q], owner, 0);
          }
        }
      });
    }
    node_rows(r0, r1, values.data());
    return absl::OkStatus();
  });
  if (!pass.ok()) return pass;

  Partial all;
  for (Partial& p : node_parts) Merge(all, p);
  for (Partial& p : sample_parts) Merge(all, p);
  r.nodes = all.nodes;
  r.samples = all.samples;
  r.normal_queries = all.queries;
  r.gouge_max = all.gouge_max;
  r.gouge_x = all.gouge_x;
  r.gouge_y = all.gouge_y;
  r.gouge_move = all.gouge_move;
  r.gouge_volume = all.gouge_volume;
  r.excess_max = all.excess_max;
  r.excess_x = all.excess_x;
  r.excess_y = all.excess_y;
  r.excess_mean = all.nodes > 0 ? all.excess_sum / all.nodes : 0;
  r.excess_volume = all.excess_volume;
  r.normal_gouge_max = all.normal_gouge_max;
  r.normal_excess_max = all.normal_excess_max;
  r.out_area_mm2 = all.out_area;
  r.ok = all.out_points == 0;
  r.gouge_lines = Sorted(all.gouge_lines, options.max_lines);
  r.excess_lines = Sorted(all.excess_lines, options.max_lines);
  return r;
}

DeviationPicture::DeviationPicture(int32_t nx, int32_t ny, int max_side)
    : nodes_x(nx), nodes_y(ny) {
  max_side = std::max(max_side, 16);
  // Nodes per pixel (a block), the same along both axes.
  block = std::max<int32_t>(1, (std::max(nx, ny) + max_side - 1) / max_side);
  width = (nx + block - 1) / block;
  height = (ny + block - 1) / block;
  worst.assign(static_cast<size_t>(width) * height,
               std::numeric_limits<float>::quiet_NaN());
}

void DeviationPicture::AddRows(int32_t j0, int32_t j1, const float* values) {
  // Each pixel keeps the largest magnitude, the first of equal ones in
  // row then column order (rows come in order).
  for (int32_t j = j0; j < j1; ++j) {
    float* out = &worst[static_cast<size_t>((nodes_y - 1 - j) / block) * width];
    const float* row = values + static_cast<size_t>(j - j0) * nodes_x;
    for (int32_t i = 0; i < nodes_x; ++i) {
      const double v = row[i];
      float& w = out[i / block];
      if (!std::isnan(v) && !(std::fabs(double{w}) >= std::fabs(v))) {
        w = static_cast<float>(v);
      }
    }
  }
}

absl::StatusOr<Image> RenderDeviationMap(const SurfaceGrid& grid,
                                         const DeviationReport& r,
                                         int max_side) {
  if (absl::Status s = grid.Validate(); !s.ok()) return s;
  const int32_t nxn = grid.nodes_x(), nyn = grid.nodes_y();
  if (r.node_deviation.size() != static_cast<size_t>(int64_t{nxn} * nyn)) {
    return absl::InvalidArgumentError("the deviation is for another grid");
  }
  DeviationPicture map(nxn, nyn, max_side);
  map.AddRows(0, nyn, r.node_deviation.data());
  return RenderDeviationMap(map, grid.spec, r);
}

absl::StatusOr<Image> RenderDeviationMap(const DeviationPicture& map,
                                         const StockSpec& spec,
                                         const DeviationReport& r) {
  const int32_t nyn = map.nodes_y;
  const int32_t block = map.block;
  const int mw = map.width, mh = map.height;
  constexpr int kScale = 2;
  const int legend_w = 150;
  const int width = mw + legend_w, height = std::max(mh, 260);
  Image img(width, height, 3, {255, 255, 255});
  const double gouge_limit = r.tolerance;
  const double excess_limit = r.allowance + r.tolerance;
  const double gouge_top = std::max(r.normal_gouge_max, gouge_limit * 2 + 1e-9);
  const double excess_top = std::max(r.normal_excess_max, excess_limit * 2 + 1e-9);
  auto lerp = [](Rgb a, Rgb b, double t) {
    t = std::clamp(t, 0.0, 1.0);
    return Rgb{static_cast<uint8_t>(a.r + (b.r - a.r) * t + 0.5),
               static_cast<uint8_t>(a.g + (b.g - a.g) * t + 0.5),
               static_cast<uint8_t>(a.b + (b.b - a.b) * t + 0.5)};
  };
  constexpr Rgb kNoDesign = {190, 190, 190}, kWhite = {255, 255, 255};
  constexpr Rgb kGougeLo = {250, 170, 150}, kGougeHi = {150, 0, 20};
  constexpr Rgb kExcessLo = {170, 200, 250}, kExcessHi = {10, 40, 150};
  auto color = [&](double v) -> Rgb {
    if (std::isnan(v)) return kNoDesign;
    if (v < 0 && -v > gouge_limit) {
      return lerp(kGougeLo, kGougeHi,
                  (-v - gouge_limit) / (gouge_top - gouge_limit));
    }
    if (v > 0 && v > excess_limit) {
      return lerp(kExcessLo, kExcessHi,
                  (v - excess_limit) / (excess_top - excess_limit));
    }
    return kWhite;
  };
  for (int py = 0; py < mh; ++py) {
    // North up: image row 0 holds the largest y.
    for (int px = 0; px < mw; ++px) {
      img.Set(px, py, color(map.worst[static_cast<size_t>(py) * mw + px]));
    }
  }
  const GridGeometry g(spec);
  // The worst gouging lines, marked where they are deepest.
  const Rgb kInk = {20, 20, 20};
  const int marks = std::min<int>(5, r.gouge_lines.size());
  for (int k = 0; k < marks; ++k) {
    const LineDeviation& l = r.gouge_lines[k];
    const int px = static_cast<int>((l.x - g.NodeX(0)) / g.dx() / block);
    const int py = static_cast<int>((g.NodeY(nyn - 1) - l.y) / g.dy() / block);
    for (int d = -4; d <= 4; ++d) {
      for (auto [x, y] : {std::pair{px + d, py}, std::pair{px, py + d}}) {
        if (x >= 0 && y >= 0 && x < mw && y < mh) img.Set(x, y, kInk);
      }
    }
    DrawText(img, std::min(px + 5, std::max(0, mw - 40)),
             std::clamp(py - 8, 0, std::max(0, mh - 20)),
             absl::StrFormat("L%d", l.line), kInk, kScale);
  }
  // The scale: excess on top, the tolerance band in white, gouge below.
  const int lx = mw + 12, bar_x0 = lx, bar_x1 = lx + 20;
  DrawText(img, lx, 4, "deviation mm", kInk, kScale);
  const int bar_y0 = 30, bar_y1 = height - 30, bar_h = bar_y1 - bar_y0;
  for (int y = bar_y0; y < bar_y1; ++y) {
    const double t = static_cast<double>(y - bar_y0) / (bar_h - 1);
    Rgb c;
    if (t < 0.4) {
      c = lerp(kExcessHi, kExcessLo, t / 0.4);
    } else if (t < 0.6) {
      c = kWhite;
    } else {
      c = lerp(kGougeLo, kGougeHi, (t - 0.6) / 0.4);
    }
    img.FillRect(bar_x0, y, bar_x1, y + 1, c);
  }
  img.FillRect(bar_x0 - 1, bar_y0, bar_x0, bar_y1, kInk);
  img.FillRect(bar_x1, bar_y0, bar_x1 + 1, bar_y1, kInk);
  auto label = [&](int y, const std::string& s) {
    DrawText(img, bar_x1 + 5, std::clamp(y - 9, 0, height - 20), s, kInk, 1);
  };
  label(bar_y0 + 8, absl::StrFormat("+%.3g excess", excess_top));
  label(bar_y0 + static_cast<int>(0.4 * bar_h), absl::StrFormat("+%.3g", excess_limit));
  label(bar_y0 + static_cast<int>(0.5 * bar_h), "in tolerance");
  label(bar_y0 + static_cast<int>(0.6 * bar_h), absl::StrFormat("-%.3g", gouge_limit));
  label(bar_y1 - 2, absl::StrFormat("-%.3g gouge", gouge_top));
  img.FillRect(bar_x0, height - 20, bar_x1, height - 6, kNoDesign);
  label(height - 6, "no design");
  return img;
}

}  // namespace swarf::cli
