#include "client/outputs/pictures.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/outputs/colormap.h"
#include "client/outputs/text.h"
#include "core/target_clones.h"
#include "core/thread_pool.h"
#include "core/value_minmax.h"

namespace swarf::cli {
namespace {

constexpr Rgb kWhite = {255, 255, 255};
constexpr Rgb kInk = {30, 30, 30};
constexpr Rgb kHalo = {0, 0, 0};

// Towards the light: azimuth north-west (upper left of the picture), 45
// degrees above the horizon.
constexpr double kLightX = -0.5, kLightY = 0.5, kLightZ = 0.70710678118654752;
// Fraction of light a surface facing away from the light still gets, so
// that shadowed walls keep their tint.
constexpr double kAmbient = 0.25;

// "3.21e-3" (three significant digits), "0" for zero.
std::string FormatSci(double v) {
  if (v == 0) return "0";
  int e = static_cast<int>(std::floor(std::log10(std::fabs(v))));
  double m = v / std::pow(10.0, e);
  if (std::fabs(std::round(m * 100) / 100) >= 10) {
    m /= 10;
    ++e;
  }
  return absl::StrFormat("%.2fe%d", m, e);
}

std::string PowerOfTenLabel(int k) {
  return k == 0 ? std::string("1") : absl::StrCat("1e", k);
}

struct Box {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

// A vertical colour bar with tick labels, a title and optionally a swatch
// for a special value below it.
struct Legend {
  std::vector<std::string> title;
  std::function<Rgb(double)> color;  // t in [0, 1], bottom to top
  std::vector<std::pair<double, std::string>> ticks;  // t, label
  bool swatch = false;
  Rgb swatch_color;
  std::string swatch_label;
};

struct LegendMetrics {
  int s, pad, line_h, bar_w, tick_len, label_gap, swatch_h;
  explicit LegendMetrics(int scale)
      : s(scale),
        pad(6 * scale),
        line_h((kGlyphHeight + 2) * scale),
        bar_w(10 * scale),
        tick_len(3 * scale),
        label_gap(3 * scale),
        swatch_h(10 * scale) {}
};

int LegendWidth(const Legend& l, int scale) {
  const LegendMetrics m(scale);
  int labels = 0;
  for (const auto& [t, label] : l.ticks) {
    labels = std::max(labels, TextWidth(label, scale));
  }
  if (l.swatch) labels = std::max(labels, TextWidth(l.swatch_label, scale));
  int w = m.bar_w + m.tick_len + m.label_gap + labels;
  for (const std::string& line : l.title) {
    w = std::max(w, TextWidth(line, scale));
  }
  return m.pad + w + m.pad;
}

int LegendMinHeight(const Legend& l, int scale) {
  const LegendMetrics m(scale);
  return m.pad + static_cast<int>(l.title.size()) * m.line_h + m.pad +
         m.line_h + 60 * scale + (l.swatch ? m.pad + m.swatch_h : 0) + m.pad;
}

// Draws the legend in the column [x0, x0 + LegendWidth) of `image`, over
// rows [0, height).
void DrawLegend(Image& image, int x0, int height, const Legend& l, int scale,
                Box* bar_out, Box* swatch_out) {
  const LegendMetrics m(scale);
  int y = m.pad;
  for (const std::string& line : l.title) {
    DrawText(image, x0 + m.pad, y, line, kInk, scale);
    y += m.line_h;
  }
  // Half a label above the top tick and below the bottom one.
  Box bar;
  bar.x0 = x0 + m.pad;
  bar.x1 = bar.x0 + m.bar_w;
  bar.y0 = y + m.pad + m.line_h / 2;
  bar.y1 = height - m.pad - m.line_h / 2 - (l.swatch ? m.pad + m.swatch_h : 0);
  const int h = bar.y1 - bar.y0;
  for (int py = bar.y0; py < bar.y1; ++py) {
    const double t = h > 1 ? double(bar.y1 - 1 - py) / (h - 1) : 0.5;
    image.FillRect(bar.x0, py, bar.x1, py + 1, l.color(t));
  }
  // Frame around the bar, outside it.
  image.FillRect(bar.x0 - 1, bar.y0 - 1, bar.x1 + 1, bar.y0, kInk);
  image.FillRect(bar.x0 - 1, bar.y1, bar.x1 + 1, bar.y1 + 1, kInk);
  image.FillRect(bar.x0 - 1, bar.y0, bar.x0, bar.y1, kInk);
  image.FillRect(bar.x1, bar.y0, bar.x1 + 1, bar.y1, kInk);
  // Every tick gets a mark; labels are thinned so that they do not overlap.
  int last_label_y = 1 << 30;
  for (size_t k = 0; k < l.ticks.size(); ++k) {
    const double t = l.ticks[k].first;
    const int ty = bar.y1 - 1 - static_cast<int>(std::lround(t * (h - 1)));
    image.FillRect(bar.x1, ty - scale / 2, bar.x1 + m.tick_len,
                   ty - scale / 2 + scale, kInk);
    if (last_label_y - ty < m.line_h) continue;
    DrawText(image, bar.x1 + m.tick_len + m.label_gap,
             ty - kGlyphAscent * scale / 2, l.ticks[k].second, kInk, scale);
    last_label_y = ty;
  }
  Box sw;
  if (l.swatch) {
    sw.x0 = bar.x0;
    sw.x1 = bar.x1;
    sw.y0 = bar.y1 + m.pad + m.line_h / 2;
    sw.y1 = sw.y0 + m.swatch_h;
    image.FillRect(sw.x0 - 1, sw.y0 - 1, sw.x1 + 1, sw.y1 + 1, kInk);
    image.FillRect(sw.x0, sw.y0, sw.x1, sw.y1, l.swatch_color);
    DrawText(image, sw.x1 + m.tick_len + m.label_gap,
             (sw.y0 + sw.y1) / 2 - kGlyphAscent * scale / 2, l.swatch_label,
             kInk, scale);
  }
  if (bar_out != nullptr) *bar_out = bar;
  if (swatch_out != nullptr) *swatch_out = sw;
}

// Font scale for a picture whose longer side is `side` pixels: labels stay
// about 1-2% of the picture.
int FontScale(int side) { return std::clamp((side + 300) / 600, 2, 5); }

absl::Status CheckSides(int min_side, int max_side) {
  if (max_side < 2 || max_side > (1 << 15) || min_side < 0 ||
      min_side > max_side) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "image sides must satisfy 0 <= min_side <= max_side, 2 <= max_side "
        "<= 32768; got min_side %d, max_side %d",
        min_side, max_side));
  }
  return absl::OkStatus();
}

}  // namespace

PixelFrame ReliefFrame(const StockSpec& spec, const ReliefOptions& options) {
  const GridGeometry g(spec);
  const double w = spec.x1 - spec.x0, h = spec.y1 - spec.y0;
  const double longer = std::max(w, h);
  // Square pixels of one node spacing (the finer one), then clamped so the
  // longer side has between min_side and max_side pixels.
  double p = std::min(g.dx(), g.dy());
  if (options.min_side >= 2) p = std::min(p, longer / (options.min_side - 1));
  p = std::max(p, longer / (std::max(options.max_side, 2) - 1));
  PixelFrame f;
  f.width = std::max(2, static_cast<int>(std::lround(w / p)) + 1);
  f.height = std::max(2, static_cast<int>(std::lround(h / p)) + 1);
  f.x0 = spec.x0;
  f.y1 = spec.y1;
  f.sx = w / (f.width - 1);
  f.sy = h / (f.height - 1);
  return f;
}

absl::Status CheckPictureSides(int min_side, int max_side) {
  return CheckSides(min_side, max_side);
}

ReliefSampler::ReliefSampler(const StockSpec& spec, const PixelFrame& frame)
    : spec_(spec), frame_(frame) {
  const GridGeometry g(spec);
  row_element_.resize(frame.height);
  for (int py = 0; py < frame.height; ++py) {
    // As SurfaceGrid::HeightAndGradient clamps and looks up.
    row_element_[py] = g.ElementY(std::clamp(frame.Y(py), spec.y0, spec.y1));
  }
  // Up to 4096 x 4096 pixels (128 MiB): filled, and faulted in, on every
  // thread.
  const size_t w = static_cast<size_t>(frame.width);
  height_.resize(w * frame.height);
  shade_.resize(w * frame.height);
  ThreadPool::Default().ParallelFor(frame.height, [&](int64_t py) {
    std::fill_n(height_.begin() + py * w, w, 0.0f);
    std::fill_n(shade_.begin() + py * w, w, 1.0f);
  });
  lowest_ = spec.z_top;
}

void ReliefSampler::AddBand(const SurfaceGrid& band, int32_t e0, int32_t e1) {
  const PixelFrame& f = frame_;
  const double z_top = spec_.z_top;
  std::vector<int> rows;
  for (int py = 0; py < f.height; ++py) {
    if (row_element_[py] >= e0 && row_element_[py] < e1) rows.push_back(py);
  }
  // Blocks of rows by chunks of columns, each with one sampler:
  // neighbouring rows share nodes. A band of tile rows has only a few
  // blocks of rows (four at a pixel a node): whole rows left most of a
  // many-core machine idle. Where a band has fewer than four items a
  // thread (a picture coarser than the grid: the full plate's band is one
  // block, 8 chunks of 512 columns for 16 threads), the chunks are
  // narrower, down to 64 columns. A pixel's value does not depend on its
  // chunk (SurfaceSampler is SurfaceGrid::HeightAndGradient bit for bit).
  constexpr int kBlockRows = 16;
  constexpr int kChunkColumns = 512;
  constexpr int kMinChunkColumns = 64;
  const int64_t blocks =
      (static_cast<int64_t>(rows.size()) + kBlockRows - 1) / kBlockRows;
  const int64_t wanted = 4 * static_cast<int64_t>(ThreadPool::Default().size());
  int chunk_columns = kChunkColumns;
  if (blocks > 0 &&
      blocks * ((f.width + chunk_columns - 1) / chunk_columns) < wanted) {
    const int64_t chunks_wanted = (wanted + blocks - 1) / blocks;
    chunk_columns = static_cast<int>(std::max<int64_t>(
        kMinChunkColumns, (f.width + chunks_wanted - 1) / chunks_wanted));
  }
  const int chunks = (f.width + chunk_columns - 1) / chunk_columns;
  const GridGeometry g(band.spec);
  auto node_column = [&](int px) {  // as SurfaceSampler finds the element
    return g.ElementX(std::clamp(f.X(px), band.spec.x0, band.spec.x1));
  };
  // Per row and chunk, the lowest height there.
  std::vector<double> chunk_min(rows.size() * chunks, z_top);
  ThreadPool::Default().ParallelFor(blocks * chunks, [&](int64_t item) {
    const int64_t block = item / chunks;
    const int chunk = static_cast<int>(item % chunks);
    const int px0 = chunk * chunk_columns;
    const int px1 = std::min(f.width, px0 + chunk_columns);
    SurfaceSampler sampler(band, node_column(px0), node_column(px1 - 1) + 1);
    const size_t r0 = static_cast<size_t>(block) * kBlockRows;
    const size_t r1 = std::min(rows.size(), r0 + kBlockRows);
    double lo[kBlockRows];
    std::fill_n(lo, kBlockRows, z_top);
    // Rows in one row of elements are taken a column at a time: where
    // pixels are finer than the grid (the marks picture of a small job), an
    // element is prepared once for all its pixels, not once per row.
    for (size_t g0 = r0, g1; g0 < r1; g0 = g1) {
      g1 = g0 + 1;
      while (g1 < r1 && row_element_[rows[g1]] == row_element_[rows[g0]]) {
        ++g1;
      }
      for (int px = px0; px < px1; ++px) {
        const double x = f.X(px);
        for (size_t r = g0; r < g1; ++r) {
          const int py = rows[r];
          double gx, gy;
          const double z = sampler.HeightAndGradient(x, f.Y(py), &gx, &gy);
          const double dot = (-gx * kLightX - gy * kLightY + kLightZ) /
                             std::sqrt(gx * gx + gy * gy + 1);
          const size_t k = static_cast<size_t>(py) * f.width + px;
          // Stored relative to the top in float: depth resolution ~1e-7
          // of it.
          height_[k] = static_cast<float>(z - z_top);
          shade_[k] = static_cast<float>(
              kAmbient + (1 - kAmbient) * std::max(dot, 0.0) / kLightZ);
          lo[r - r0] = std::min(lo[r - r0], z);
        }
      }
    }
    for (size_t r = r0; r < r1; ++r) {
      chunk_min[r * chunks + chunk] = lo[r - r0];
    }
  });
  // The tint needs the lowest height. Kept as the bands come, not found on
  // the first ColorRow: rows are coloured on every thread.
  for (const double lo : chunk_min) lowest_ = std::min(lowest_, lo);
}

void ReliefSampler::ColorRow(int py, uint8_t* rgb) const {
  // Only what lies exactly at the top (height 0) is untouched stock.
  const size_t k = static_cast<size_t>(py) * frame_.width;
  ShadedTintRow(&height_[k], &shade_[k], frame_.width, spec_.z_top - lowest_,
                rgb);
}

Image ReliefSampler::ToImage() const {
  Image image(frame_.width, frame_.height, 3);
  ThreadPool::Default().ParallelFor(frame_.height, [&](int64_t py) {
    ColorRow(static_cast<int>(py), image.row(static_cast<int>(py)));
  });
  return image;
}

absl::StatusOr<Image> RenderRelief(const SurfaceGrid& grid,
                                   const ReliefOptions& options) {
  if (absl::Status st = grid.Validate(); !st.ok()) return st;
  if (absl::Status st = CheckSides(options.min_side, options.max_side);
      !st.ok()) {
    return st;
  }
  ReliefSampler sampler(grid.spec, ReliefFrame(grid.spec, options));
  sampler.AddBand(grid, 0, grid.spec.ny);
  return sampler.ToImage();
}

Rgb ErrorColor(double error, double lo, double hi) {
  if (!std::isfinite(error) || error < 0) return kInvalidErrorColor;
  if (error == 0) return kZeroErrorColor;
  return Viridis(std::log(error / lo) / std::log(hi / lo));
}

absl::StatusOr<Image> RenderErrorMap(const ErrorRaster& raster,
                                     const ErrorMapOptions& options,
                                     ErrorMapLayout* layout) {
  const Rect& r = raster.region;
  if (raster.cols <= 0 || raster.rows <= 0 ||
      static_cast<int64_t>(raster.max_error.size()) !=
          int64_t{raster.cols} * raster.rows) {
    return absl::InvalidArgumentError(
        absl::StrFormat("error raster of %d x %d cells holds %d values",
                        raster.cols, raster.rows, raster.max_error.size()));
  }
  if (!(std::isfinite(r.x0) && std::isfinite(r.x1) && std::isfinite(r.y0) &&
        std::isfinite(r.y1) && r.x1 > r.x0 && r.y1 > r.y0)) {
    return absl::InvalidArgumentError(
        "error raster region must be finite and non-empty");
  }
  if (!(options.min_error > 0 && std::isfinite(options.min_error))) {
    return absl::InvalidArgumentError("min_error must be finite and > 0");
  }
  if (absl::Status st = CheckSides(options.min_side, options.max_side);
      !st.ok()) {
    return st;
  }
  double max_error = 0;
  for (float v : raster.max_error) {
    if (std::isfinite(v)) max_error = std::max(max_error, double{v});
  }
  const double lo = options.min_error;
  const double hi = std::max(max_error, 10 * lo);

  // Map size: square pixels, the longer side's cell count clamped.
  const double w = r.x1 - r.x0, h = r.y1 - r.y0;
  const int cells_long = w >= h ? raster.cols : raster.rows;
  const int n_long =
      std::clamp(cells_long, std::max(options.min_side, 1), options.max_side);
  const double p = std::max(w, h) / n_long;
  const int mw = std::max(1, static_cast<int>(std::lround(w / p)));
  const int mh = std::max(1, static_cast<int>(std::lround(h / p)));

  Legend legend;
  legend.title = {"error (mm)", "max " + FormatSci(max_error)};
  legend.color = [](double t) { return Viridis(t); };
  const double span = std::log(hi / lo);
  // The tolerance keeps a decade whose bound is a float's rounding of it.
  for (int k = static_cast<int>(std::ceil(std::log10(lo) - 1e-6));
       k <= static_cast<int>(std::floor(std::log10(hi) + 1e-6)); ++k) {
    const double t =
        std::clamp(std::log(std::pow(10.0, k) / lo) / span, 0.0, 1.0);
    legend.ticks.emplace_back(t, PowerOfTenLabel(k));
  }
  legend.swatch = true;
  legend.swatch_color = kZeroErrorColor;
  legend.swatch_label = "0";
  const int scale = FontScale(std::max(mw, mh));
  const int gap = 4 * scale;
  const int legend_x0 = mw + gap;
  const int width = legend_x0 + LegendWidth(legend, scale);
  const int height = std::max(mh, LegendMinHeight(legend, scale));

  Image image(width, height, 3, kWhite);
  // Each pixel takes the max over the cells it overlaps: blown up when the
  // raster is coarse, max-pooled (so no peak is lost) when it is fine.
  const int64_t cols = raster.cols, rows = raster.rows;
  ThreadPool::Default().ParallelFor(mh, [&](int64_t py) {
    const int64_t q = mh - 1 - py;  // rows count from the bottom
    const int64_t r0 = q * rows / mh;
    const int64_t r1 = std::max(r0 + 1, ((q + 1) * rows + mh - 1) / mh);
    for (int64_t px = 0; px < mw; ++px) {
      const int64_t c0 = px * cols / mw;
      const int64_t c1 = std::max(c0 + 1, ((px + 1) * cols + mw - 1) / mw);
      double v = 0;
      for (int64_t rr = r0; rr < r1; ++rr) {
        for (int64_t c = c0; c < c1; ++c) {
          const double e = raster.max_error[rr * cols + c];
          // An invalid value must show: it wins over every valid one.
          if (!(std::isfinite(e) && e >= 0)) {
            v = e;
            rr = r1;
            break;
          }
          v = std::max(v, e);
        }
      }
      image.Set(static_cast<int>(px), static_cast<int>(py),
                ErrorColor(v, lo, hi));
    }
  });
  Box bar, sw;
  DrawLegend(image, legend_x0, height, legend, scale, &bar, &sw);
  if (layout != nullptr) {
    layout->map_width = mw;
    layout->map_height = mh;
    layout->bar_x0 = bar.x0;
    layout->bar_y0 = bar.y0;
    layout->bar_x1 = bar.x1;
    layout->bar_y1 = bar.y1;
    layout->zero_x0 = sw.x0;
    layout->zero_y0 = sw.y0;
    layout->zero_x1 = sw.x1;
    layout->zero_y1 = sw.y1;
    layout->legend_x0 = legend_x0;
    layout->lo = lo;
    layout->hi = hi;
    layout->ticks.clear();
    for (const auto& [t, label] : legend.ticks) {
      layout->ticks.push_back(lo * std::exp(t * span));
    }
  }
  return image;
}

namespace {

// A segment in pixel coordinates with the mark angle at both ends, and the
// polyline it belongs to (a serial number of the pass).
struct PixelSegment {
  double ax, ay, bx, by;
  double angle_a, angle_b;
  uint32_t polyline;
};

// The rows a stroke of `width` may touch, [*y0, *y1] within [0, max_y).
void StrokeRows(const PixelSegment& s, double width, int max_y, int* y0,
                int* y1) {
  const double half = width / 2;
  *y0 = std::max(0,
                 static_cast<int>(std::floor(std::min(s.ay, s.by) - half - 1)));
  *y1 = std::min(max_y - 1,
                 static_cast<int>(std::ceil(std::max(s.ay, s.by) + half + 1)));
}

// The columns, likewise, [*x0, *x1] within [0, max_x).
void StrokeColumns(const PixelSegment& s, double width, int max_x, int* x0,
                   int* x1) {
  const double half = width / 2;
  *x0 = std::max(0,
                 static_cast<int>(std::floor(std::min(s.ax, s.bx) - half - 1)));
  *x1 = std::min(max_x - 1,
                 static_cast<int>(std::ceil(std::max(s.ax, s.bx) + half + 1)));
}

// A rectangle of pixels: columns [col0, col1), rows [row0, row1).
struct PixelTile {
  int col0, col1, row0, row1;
};

// Calls cover(px, py, coverage, angle) for each pixel of the stroke within
// `tile`: coverage is how far the pixel's centre lies inside the stroke's
// edge (a one-pixel ramp, > 0), angle the mark's angle interpolated at the
// segment's point nearest to it.
template <class Cover>
void StrokeCoverage(int max_x, int max_y, const PixelSegment& s, double width,
                    const PixelTile& tile, Cover&& cover) {
  const double half = width / 2;
  int x0, x1, y0, y1;
  StrokeColumns(s, width, max_x, &x0, &x1);
  x0 = std::max(x0, tile.col0);
  x1 = std::min(x1, tile.col1 - 1);
  StrokeRows(s, width, max_y, &y0, &y1);
  y0 = std::max(y0, tile.row0);
  y1 = std::min(y1, tile.row1 - 1);
  const double dx = s.bx - s.ax, dy = s.by - s.ay;
  const double len2 = dx * dx + dy * dy;
  // Pixels at squared distance r2 or more have no coverage: sqrt is
  // monotonic and sqrt(fl(r * r)) == r, so sqrt(d2) >= r there.
  const double r = half + 0.5, r2 = r * r;
  const double seg_x0 = std::min(s.ax, s.bx), seg_x1 = std::max(s.ax, s.bx);
  const double seg_y0 = std::min(s.ay, s.by), seg_y1 = std::max(s.ay, s.by);
  const double len = std::sqrt(len2);
  for (int py = y0; py <= y1; ++py) {
    // The row's pixels that can be within r of the segment: within r of
    // its box, and of its line. A pixel more off than that fails the test
    // below anyway; the bounds are widened by a pixel against rounding, so
    // the same pixels are covered with fewer tests.
    const double off_y = std::max({0.0, seg_y0 - py, py - seg_y1});
    if (off_y > r + 1) continue;
    const double reach = std::sqrt(std::max(0.0, r2 - off_y * off_y));
    double lo = seg_x0 - reach, hi = seg_x1 + reach;
    if (std::fabs(dy) * 8 > len) {
      // |cross((px, py) - a, d)| < r len: px within r len / |dy| of where
      // the line crosses the row.
      const double at = s.ax + (py - s.ay) * dx / dy;
      const double w = r * len / std::fabs(dy);
      lo = std::max(lo, at - w);
      hi = std::min(hi, at + w);
    }
    const int row_x0 = std::max(x0, static_cast<int>(std::floor(lo)) - 1);
    const int row_x1 = std::min(x1, static_cast<int>(std::ceil(hi)) + 1);
    for (int px = row_x0; px <= row_x1; ++px) {
      double t = len2 > 0 ? ((px - s.ax) * dx + (py - s.ay) * dy) / len2 : 0;
      t = std::clamp(t, 0.0, 1.0);
      const double ex = s.ax + t * dx - px, ey = s.ay + t * dy - py;
      const double d2 = ex * ex + ey * ey;
      if (d2 >= r2) continue;
      const double coverage = r - std::sqrt(d2);
      if (coverage <= 0) continue;
      cover(px, py, coverage, s.angle_a + t * (s.angle_b - s.angle_a));
    }
  }
}

// A polyline's strokes within a tile, blended once per pixel: each pixel
// takes the largest coverage of any of the polyline's segments (its
// distance from the polyline), with the angle where that is. Blending each
// segment in turn darkened a pixel as many times as segments passed near
// it: the line's edge depended on how finely the marks were sampled.
class PolylineStroke {
 public:
  explicit PolylineStroke(const PixelTile& tile)
      : tile_(tile), width_(tile.col1 - tile.col0), b_(buffers_) {
    const size_t area =
        static_cast<size_t>(width_) * std::max(0, tile.row1 - tile.row0);
    // Zero past what earlier tiles used (every entry they touched was
    // cleared by Blend or the destructor); angles are written before read.
    if (b_.coverage.size() < area) {
      b_.coverage.resize(area, 0);
      b_.angle.resize(area);
    }
  }
  ~PolylineStroke() { Clear(); }
  PolylineStroke(const PolylineStroke&) = delete;
  PolylineStroke& operator=(const PolylineStroke&) = delete;

  void Add(int max_x, int max_y, const PixelSegment& s, double width) {
    double* const coverage_of = b_.coverage.data();
    double* const angle_of = b_.angle.data();
    StrokeCoverage(max_x, max_y, s, width, tile_,
                   [&](int px, int py, double coverage, double angle) {
                     const size_t k =
                         static_cast<size_t>(py - tile_.row0) * width_ +
                         (px - tile_.col0);
                     if (coverage_of[k] == 0) b_.touched.push_back(k);
                     // The first of equal coverages: the segments' order.
                     if (coverage > coverage_of[k]) {
                       coverage_of[k] = coverage;
                       angle_of[k] = angle;
                     }
                   });
  }
  // Blends the polyline's pixels (in the order first covered) and clears
  // them for the next polyline.
  void Blend(Image& image, bool halo) {
    for (const size_t k : b_.touched) {
      const int px = tile_.col0 + static_cast<int>(k % width_);
      const int py = tile_.row0 + static_cast<int>(k / width_);
      const double c = b_.coverage[k];
      if (halo) {
        image.Blend(px, py, kHalo, 0.75 * std::min(c, 1.0));
      } else {
        image.Blend(px, py, AngleColor(b_.angle[k]), c);
      }
    }
    Clear();
  }

 private:
  // Per pixel of the tile, row-major: this thread's, reused from tile to
  // tile (allocated and zeroed for each, they were a sixth of the strokes'
  // instructions), all coverages 0 between tiles.
  struct Buffers {
    std::vector<double> coverage, angle;
    std::vector<size_t> touched;
  };
  void Clear() {
    for (const size_t k : b_.touched) b_.coverage[k] = 0;
    b_.touched.clear();
  }
  static thread_local Buffers buffers_;

  const PixelTile tile_;
  const int width_;
  Buffers& b_;
};
thread_local PolylineStroke::Buffers PolylineStroke::buffers_;

// The vertices of a polyline of n vertices (in pixels: xs, ys, angles) to
// stroke: each vertex dropped that lies within kDropPx of the segment
// between the kept ones around it, with its angle within kDropDeg of the
// angle interpolated there. A fine grid's marks have vertices a fraction of
// a pixel apart in a picture of a few thousand pixels: each cost a stroke
// and changed nothing to be seen. The first and last are kept; a vertex is
// kept at least every kMaxRun. Into *kept (its old entries dropped).
SWARF_TARGET_CLONES
void KeptVertices(std::span<const double> xs, std::span<const double> ys,
                  std::span<const double> angles, std::vector<size_t>* kept) {
  constexpr double kDropPx = 0.05, kDropDeg = 0.25;
  constexpr size_t kMaxRun = 32;
  const size_t n = xs.size();
  kept->clear();
  if (n == 0) return;
  kept->push_back(0);
  // Whether every vertex strictly between a and b lies near segment a-b.
  // Every vertex is tested, in vector lanes (one by one, stopping at the
  // first that fails, this was most of keeping the marks' vertices: most
  // runs pass, and each is tested again as it grows).
  const double* __restrict x = xs.data();
  const double* __restrict y = ys.data();
  const double* __restrict ang = angles.data();
  auto spans = [&](size_t a, size_t b) __attribute__((always_inline)) {
    const double ax = x[a], ay = y[a], aa = ang[a];
    const double dx = x[b] - ax, dy = y[b] - ay, da = ang[b] - aa;
    const double len2 = dx * dx + dy * dy;
    double fails = 0;
#pragma omp simd reduction(max : fails)
    for (size_t i = a + 1; i < b; ++i) {
      double t = len2 > 0 ? ((x[i] - ax) * dx + (y[i] - ay) * dy) / len2 : 0;
      t = MinOf(MaxOf(t, 0.0), 1.0);  // std::clamp, NaN kept as it keeps it
      const double ex = ax + t * dx - x[i], ey = ay + t * dy - y[i];
      const double angle = aa + t * da;
      const bool near = (ex * ex + ey * ey <= kDropPx * kDropPx) &
                        (std::fabs(ang[i] - angle) <= kDropDeg);
      fails = MaxOf(fails, near ? 0.0 : 1.0);
    }
    return fails == 0;
  };
  size_t a = 0;
  while (a + 1 < n) {
    size_t b = a + 1;
    while (b + 1 < n && b + 1 - a <= kMaxRun && spans(a, b + 1)) ++b;
    kept->push_back(b);
    a = b;
  }
}

}  // namespace

namespace {

// DrawMarks with the relief's pixel rows from relief_row(y, rgb), called
// from several threads at once.
absl::StatusOr<Image> DrawMarksOver(
    const std::function<void(int, uint8_t*)>& relief_row,
    const PixelFrame& frame, const KeptMarkSource& marks,
    const MarksPictureOptions& options) {
  if (!(options.line_width_px >= 0 && options.line_width_px <= 100)) {
    return absl::InvalidArgumentError("line_width_px must be in [0, 100]");
  }
  if (options.chunk_segments < 1) {
    return absl::InvalidArgumentError("chunk_segments must be >= 1");
  }
  if (options.tile_rows < 1 || options.tile_cols < 1) {
    return absl::InvalidArgumentError("tile_rows and tile_cols must be >= 1");
  }
  const int side = std::max(frame.width, frame.height);
  const double width = options.line_width_px > 0 ? options.line_width_px
                                                 : std::max(2.0, side / 600.0);
  Legend legend;
  legend.title = {"mark angle", "(deg)"};
  legend.color = [](double t) { return AngleColor(t * kAngleScaleMaxDeg); };
  for (int a = 0; a <= kAngleScaleMaxDeg; a += 15) {
    legend.ticks.emplace_back(a / kAngleScaleMaxDeg, a == kAngleScaleMaxDeg
                                                         ? absl::StrCat(a, "+")
                                                         : absl::StrCat(a));
  }
  const int scale = FontScale(side);
  const int legend_x0 = frame.width + 4 * scale;
  Image image(legend_x0 + LegendWidth(legend, scale),
              std::max(frame.height, LegendMinHeight(legend, scale)), 3,
              kWhite);
  // The relief's rows on every thread: coloured one by one they were the
  // picture's longest serial step.
  ThreadPool::Default().ParallelFor(frame.height, [&](int64_t y) {
    relief_row(static_cast<int>(y), image.row(static_cast<int>(y)));
  });
  // All halos first, so that no halo covers an earlier line's colour: two
  // passes over the marks. Each pass takes a chunk of segments at a time,
  // bucketed by tiles of the picture drawn at once, each tile's segments in
  // their order (a pixel's blends happen in segment order whichever tile
  // and chunk draws it). Bands of rows alone left one or two threads
  // drawing: a chunk's segments are near each other in y.
  const int tile_rows = options.tile_rows, tile_cols = options.tile_cols;
  const int tiles_y = (frame.height + tile_rows - 1) / tile_rows;
  const int tiles_x = (frame.width + tile_cols - 1) / tile_cols;
  std::vector<PixelSegment> chunk;
  chunk.reserve(std::min<size_t>(options.chunk_segments, 1 << 16));
  std::vector<std::vector<uint32_t>> tile_segments(
      static_cast<size_t>(tiles_x) * tiles_y);
  std::vector<int32_t> busy;  // the tiles with segments, ascending
  auto draw_chunk = [&](bool halo) {
    const double w = halo ? width + 2 : width;
    for (int32_t t : busy) tile_segments[t].clear();
    busy.clear();
    for (size_t k = 0; k < chunk.size(); ++k) {
      int x0, x1, y0, y1;
      StrokeColumns(chunk[k], w, frame.width, &x0, &x1);
      StrokeRows(chunk[k], w, frame.height, &y0, &y1);
      for (int ty = y0 / tile_rows; ty <= y1 / tile_rows && ty < tiles_y;
           ++ty) {
        for (int tx = x0 / tile_cols; tx <= x1 / tile_cols && tx < tiles_x;
             ++tx) {
          std::vector<uint32_t>& list = tile_segments[ty * tiles_x + tx];
          if (list.empty()) busy.push_back(ty * tiles_x + tx);
          list.push_back(static_cast<uint32_t>(k));
        }
      }
    }
    ThreadPool::Default().ParallelFor(
        static_cast<int64_t>(busy.size()), [&](int64_t i) {
          const int32_t t = busy[i];
          const int tx = t % tiles_x, ty = t / tiles_x;
          const PixelTile tile{
              tx * tile_cols, std::min(frame.width, (tx + 1) * tile_cols),
              ty * tile_rows, std::min(frame.height, (ty + 1) * tile_rows)};
          // A chunk holds whole polylines, and a tile's segments are in
          // their order: each polyline's run of them is blended at once.
          PolylineStroke stroke(tile);
          const std::vector<uint32_t>& list = tile_segments[t];
          for (size_t q = 0; q < list.size();) {
            const uint32_t polyline = chunk[list[q]].polyline;
            for (; q < list.size() && chunk[list[q]].polyline == polyline;
                 ++q) {
              stroke.Add(frame.width, frame.height, chunk[list[q]], w);
            }
            stroke.Blend(image, halo);
          }
        });
    chunk.clear();
  };
  // Each pass adds each polyline's segments (between its kept vertices) to
  // the chunk, whole polylines at a time.
  for (const bool halo : {true, false}) {
    uint32_t polyline = 0;
    absl::Status st = marks([&](const KeptPolyline& p) -> absl::Status {
      const size_t m = p.x.size();
      const size_t ends = p.wrap ? m : (m > 0 ? m - 1 : 0);
      for (size_t k = 0; k < ends || (m == 1 && k == 0); ++k) {
        const size_t a = k, b = m == 1 ? 0 : (k + 1) % m;
        chunk.push_back(
            {p.x[a], p.y[a], p.x[b], p.y[b], p.angle[a], p.angle[b], polyline});
      }
      ++polyline;
      // Whole polylines only: each is blended at once within a chunk.
      if (chunk.size() >= options.chunk_segments) draw_chunk(halo);
      return absl::OkStatus();
    });
    if (!st.ok()) return st;
    draw_chunk(halo);
  }
  DrawLegend(image, legend_x0, image.height(), legend, scale, nullptr, nullptr);
  return image;
}

// The kept polylines of `marks` in `frame` (MarkKeeper), read as the
// marks are: the first polyline whose angles do not match fails at once; a
// non-finite vertex fails after the pass (a later polyline's angles take
// precedence).
KeptMarkSource Kept(const PixelFrame& frame, MarkSource marks) {
  return [frame, marks = std::move(marks)](
             const std::function<absl::Status(const KeptPolyline&)>& visit)
             -> absl::Status {
    MarkKeeper keeper(frame);
    absl::Status st = marks([&](const MarkPolyline& p) -> absl::Status {
      if (absl::Status added = keeper.Add(p); !added.ok()) return added;
      return keeper.full() ? keeper.Take(visit) : absl::OkStatus();
    });
    if (st.ok()) st = keeper.Take(visit);
    if (!st.ok()) return st;
    return keeper.finite_status();
  };
}

}  // namespace

absl::Status MarkKeeper::Add(const MarkPolyline& p) {
  const size_t n = p.vertices.size();
  if (p.angle_deg.size() != n) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "mark polyline with %d vertices has %d angles", n, p.angle_deg.size()));
  }
  // Nothing more is kept once a vertex is not finite.
  if (!finite_) return absl::OkStatus();
  for (size_t k = 0; k < n; ++k) {
    const double x = frame_.PixelX(p.vertices[k].x);
    const double y = frame_.PixelY(p.vertices[k].y);
    if (!(std::isfinite(x) && std::isfinite(y))) {
      finite_ = false;
      xs_.resize(first_.back());
      ys_.resize(first_.back());
      return absl::OkStatus();
    }
    xs_.push_back(x);
    ys_.push_back(y);
  }
  angles_.insert(angles_.end(), p.angle_deg.begin(), p.angle_deg.end());
  first_.push_back(xs_.size());
  closed_.push_back(p.closed ? 1 : 0);
  return absl::OkStatus();
}

bool MarkKeeper::full() const { return xs_.size() >= kBatchVertices; }

absl::Status MarkKeeper::finite_status() const {
  return finite_ ? absl::OkStatus()
                 : absl::InvalidArgumentError("mark vertex is not finite");
}

absl::Status MarkKeeper::Take(
    const std::function<absl::Status(const KeptPolyline&)>& visit) {
  // The batch's polylines are kept on every thread, in groups of whole
  // polylines, then visited in order: kept one polyline at a time, on one
  // thread, they were most of the picture's time on a large job (tens of
  // millions of vertices, a few thousand pixels across) on a many-core
  // machine.
  const size_t polylines = closed_.size();
  group_first_.clear();
  for (size_t q = 0, since = kGroupVertices; q < polylines; ++q) {
    if (since >= kGroupVertices) {
      group_first_.push_back(q);
      since = 0;
    }
    since += first_[q + 1] - first_[q];
  }
  group_first_.push_back(polylines);
  const size_t groups = group_first_.size() - 1;
  if (group_kept_.size() < groups) group_kept_.resize(groups);
  kept_count_.resize(polylines);
  ThreadPool::Default().ParallelFor(
      static_cast<int64_t>(groups), [&](int64_t g) {
        thread_local std::vector<size_t> kept;
        Group& out = group_kept_[g];
        out.x.clear();
        out.y.clear();
        out.angle.clear();
        for (size_t q = group_first_[g]; q < group_first_[g + 1]; ++q) {
          const size_t v0 = first_[q], n = first_[q + 1] - v0;
          KeptVertices({xs_.data() + v0, n}, {ys_.data() + v0, n},
                       {angles_.data() + v0, n}, &kept);
          for (const size_t k : kept) {
            out.x.push_back(xs_[v0 + k]);
            out.y.push_back(ys_[v0 + k]);
            out.angle.push_back(angles_[v0 + k]);
          }
          kept_count_[q] = kept.size();
        }
      });
  absl::Status st;
  for (size_t g = 0; g < groups && st.ok(); ++g) {
    const Group& kept = group_kept_[g];
    size_t at = 0;
    for (size_t q = group_first_[g]; q < group_first_[g + 1] && st.ok(); ++q) {
      const size_t m = kept_count_[q];
      const size_t n = first_[q + 1] - first_[q];
      st = visit(KeptPolyline{{kept.x.data() + at, m},
                              {kept.y.data() + at, m},
                              {kept.angle.data() + at, m},
                              closed_[q] != 0 && n > 2});
      at += m;
    }
  }
  xs_.clear();
  ys_.clear();
  angles_.clear();
  first_.assign(1, 0);
  closed_.clear();
  return st;
}

absl::StatusOr<Image> DrawKeptMarks(const ReliefSampler& relief,
                                    const KeptMarkSource& marks,
                                    const MarksPictureOptions& options) {
  return DrawMarksOver([&](int y, uint8_t* out) { relief.ColorRow(y, out); },
                       relief.frame(), marks, options);
}

absl::StatusOr<Image> DrawMarks(const Image& relief, const PixelFrame& frame,
                                const std::vector<MarkPolyline>& marks,
                                const MarksPictureOptions& options) {
  if (relief.width() != frame.width || relief.height() != frame.height ||
      relief.channels() != 3) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "relief of %d x %d (%d channels) does not match the %d x %d RGB frame",
        relief.width(), relief.height(), relief.channels(), frame.width,
        frame.height));
  }
  return DrawMarksOver(
      [&](int y, uint8_t* out) {
        std::copy(relief.row(y), relief.row(y) + 3 * frame.width, out);
      },
      frame, Kept(frame, MarksOf(marks)), options);
}

absl::StatusOr<Image> DrawMarks(const ReliefSampler& relief,
                                const std::vector<MarkPolyline>& marks,
                                const MarksPictureOptions& options) {
  return DrawMarks(relief, MarksOf(marks), options);
}

absl::StatusOr<Image> DrawMarks(const ReliefSampler& relief,
                                const MarkSource& marks,
                                const MarksPictureOptions& options) {
  return DrawKeptMarks(relief, Kept(relief.frame(), marks), options);
}

MarkSource MarksOf(const std::vector<MarkPolyline>& marks) {
  return [&marks](const std::function<absl::Status(const MarkPolyline&)>& visit)
             -> absl::Status {
    for (const MarkPolyline& p : marks) {
      if (absl::Status st = visit(p); !st.ok()) return st;
    }
    return absl::OkStatus();
  };
}

absl::StatusOr<Image> RenderMarks(const SurfaceGrid& grid,
                                  const std::vector<MarkPolyline>& marks,
                                  const MarksPictureOptions& options,
                                  const Image* drawn,
                                  const ReliefOptions& drawn_with) {
  const PixelFrame frame = ReliefFrame(grid.spec, options.relief);
  if (drawn != nullptr && frame == ReliefFrame(grid.spec, drawn_with)) {
    return DrawMarks(*drawn, frame, marks, options);
  }
  absl::StatusOr<Image> relief = RenderRelief(grid, options.relief);
  if (!relief.ok()) return relief.status();
  return DrawMarks(*relief, frame, marks, options);
}

}  // namespace swarf::cli
