// The pictures of `swarf run`: relief.png (the machined surface, hill-shaded
// and tinted by height), error.png (where the scheme's error is, log scale
// with a legend) and marks.png (the cutting marks over the relief).
//
// Contract:
// - North up: image row 0 is the largest y, column 0 the smallest x.
// - Pixels are square in mm (up to rounding of the pixel counts).
// - Thread safety: the functions only read their inputs; they run their row
//   loops on ThreadPool::Default().
#ifndef SWARF_CLIENT_PICTURES_H_
#define SWARF_CLIENT_PICTURES_H_

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "absl/status/statusor.h"
#include "client/outputs/png_image.h"
#include "client/outputs/surface_grid.h"
#include "core/cutting_marks.h"
#include "core/geometry.h"
#include "core/stock.h"
#include "core/unfilled_vector.h"

namespace swarf::cli {

// Where pixel centres lie on the stock: pixel (px, py) samples
// (x0 + px * sx, y1 - py * sy), so the outer pixel centres sit on the stock
// edges and corners.
struct PixelFrame {
  int width = 0, height = 0;
  double x0 = 0, y1 = 0;  // mm, the centre of pixel (0, 0)
  double sx = 0, sy = 0;  // mm per pixel
  double X(double px) const { return x0 + px * sx; }
  double Y(double py) const { return y1 - py * sy; }
  double PixelX(double x) const { return (x - x0) / sx; }
  double PixelY(double y) const { return (y1 - y) / sy; }
  friend bool operator==(const PixelFrame&, const PixelFrame&) = default;
};

struct ReliefOptions {
  // Pixels along the stock's longer side: at most max_side; by default one
  // pixel per node spacing (never finer than the grid), or at least
  // min_side when that is larger (the reconstruction sampled between nodes;
  // still capped by max_side).
  int max_side = 1600;
  int min_side = 0;
};

// The frame RenderRelief uses. Needs a valid spec and max_side >= 2.
PixelFrame ReliefFrame(const StockSpec& spec, const ReliefOptions& options);

// InvalidArgument unless 0 <= min_side <= max_side and 2 <= max_side <=
// 32768.
absl::Status CheckPictureSides(int min_side, int max_side);

// RenderRelief's pixels sampled band by band (GridBands), then coloured:
// pixel row py samples element row ElementY(clamped Y(py)), so each row is
// sampled from the one band that lists it, as from the whole grid. Holds a
// height and a shade (float) per pixel: memory bounded by the frame, not
// the grid. AddBand runs its rows on ThreadPool::Default(); calls to it
// are not thread-safe. ColorRow is (the rows of a picture are coloured on
// every thread).
class ReliefSampler {
 public:
  ReliefSampler(const StockSpec& spec, const PixelFrame& frame);
  const PixelFrame& frame() const { return frame_; }
  // Samples the pixel rows of element rows [e0, e1) from `band`.
  void AddBand(const SurfaceGrid& band, int32_t e0, int32_t e1);
  // After every band: pixel row py as RGB (3 * width bytes), as
  // RenderRelief colours it. May be called from several threads at once.
  void ColorRow(int py, uint8_t* rgb) const;
  Image ToImage() const;

 private:
  StockSpec spec_;
  PixelFrame frame_;
  std::vector<int32_t> row_element_;  // per pixel row
  UnfilledVector<float> height_, shade_;
  double lowest_;  // the lowest sampled height, z_top at least
};

// Hill-shaded relief: the reconstruction's normal lit from the upper left
// (azimuth north-west, 45 degrees up; a flat surface keeps its colour), times
// a height tint from dark blue (lowest point) to pale cream (just below the
// top); untouched stock (height == z_top) is kStockColor. RGB.
// InvalidArgument for an invalid grid or options.
absl::StatusOr<Image> RenderRelief(const SurfaceGrid& grid,
                                   const ReliefOptions& options = {});

// The service's error map: cols x rows cells over `region`, row-major, cell
// (0, 0) at (region.x0, region.y0), each the max |w - w_exact| (mm) of the
// samples in it, 0 where none fell.
struct ErrorRaster {
  Rect region;
  int32_t cols = 0, rows = 0;
  std::vector<float> max_error;
};

struct ErrorMapOptions {
  // Bottom of the log colour scale (mm): smaller non-zero errors take its
  // colour. The top is the raster's max (10 min_error if smaller).
  double min_error = 1e-6;
  // Pixels along the region's longer side: the cell count clamped to
  // [min_side, max_side] (cells are blown up or max-pooled).
  int max_side = 1600;
  int min_side = 600;
};

// Colours of error.png: zero error, and cells with a non-finite or negative
// value.
inline constexpr Rgb kZeroErrorColor = {228, 228, 228};
inline constexpr Rgb kInvalidErrorColor = {255, 0, 255};

// The colour of an error value on a log scale [lo, hi] (viridis).
Rgb ErrorColor(double error, double lo, double hi);

// Where things are in error.png, for callers and tests. Boxes are
// [x0, x1) x [y0, y1) in image pixels.
struct ErrorMapLayout {
  int map_width = 0, map_height = 0;  // the map at the image's top-left
  int bar_x0 = 0, bar_y0 = 0, bar_x1 = 0, bar_y1 = 0;  // colour bar, hi on top
  int zero_x0 = 0, zero_y0 = 0, zero_x1 = 0, zero_y1 = 0;  // zero swatch
  int legend_x0 = 0;          // legend panel's left edge
  double lo = 0, hi = 0;      // the colour scale (mm)
  std::vector<double> ticks;  // labelled powers of ten (mm)
};

// The error map with its legend to the right: title "error mm", the max
// value, a vertical colour bar with power-of-ten tick labels ("1e-6") and a
// swatch for zero. InvalidArgument for a raster whose size does not match
// cols * rows, an empty or non-finite region, or bad options.
absl::StatusOr<Image> RenderErrorMap(const ErrorRaster& raster,
                                     const ErrorMapOptions& options = {},
                                     ErrorMapLayout* layout = nullptr);

struct MarksPictureOptions {
  // The relief under the marks; sampled finer than the grid by default so
  // that the lines read well on coarse grids.
  ReliefOptions relief = {.max_side = 1600, .min_side = 1000};
  // Stroke width in pixels; 0: about 1/600 of the longer side, at least 2.
  double line_width_px = 0;
  // Segments drawn at a time, whole polylines (bucketed by tiles of the
  // picture, the tiles drawn at once): memory, not the picture, depends on
  // it (>= 1; a longer polyline is drawn whole).
  size_t chunk_segments = size_t{1} << 16;
  // The tiles' size in pixels (>= 1): the work each thread takes, not the
  // picture, depends on it. Marks come in the order they were found (by
  // rows of the grid), so a chunk's segments are near each other in y:
  // tiles split its rows across the width too.
  int tile_rows = 32, tile_cols = 128;
};

// Polylines read in order: calls visit(p) on each, returning visit's first
// error (stopping there) or the source's own (a read error). May be called
// more than once; each call gives the same polylines.
using MarkSource = std::function<absl::Status(
    const std::function<absl::Status(const MarkPolyline&)>& visit)>;

// A MarkSource over `marks` (not copied: they must outlive it).
MarkSource MarksOf(const std::vector<MarkPolyline>& marks);

// The cutting marks drawn over a relief rendered in `frame` (anti-aliased,
// with a dark halo so that they read on light and dark ground), coloured by
// AngleColor of the angle interpolated along each segment, plus an angle
// legend to the right of the relief (relief at the image's top-left). Each
// polyline is blended once per pixel, at its distance from the polyline
// (vertices within 0.05 px of their neighbours' segment left out): the
// picture does not depend on how finely a mark is sampled.
// `relief` must have frame's size.
absl::StatusOr<Image> DrawMarks(const Image& relief, const PixelFrame& frame,
                                const std::vector<MarkPolyline>& marks,
                                const MarksPictureOptions& options = {});

// The same over a relief sampled (every band added), coloured straight
// into the picture (no copy of the relief).
absl::StatusOr<Image> DrawMarks(const ReliefSampler& relief,
                                const std::vector<MarkPolyline>& marks,
                                const MarksPictureOptions& options = {});

// The same from a source read in two passes (every halo, then every line),
// options.chunk_segments segments at a time: the marks are never held. The
// picture is the same whatever the chunk (a pixel's blends happen in the
// same order: all halos in polyline order, then all lines); the functions
// above are this over MarksOf. InvalidArgument for a polyline whose angles
// do not match its vertices (the first such), else for a non-finite vertex;
// or the source's error.
absl::StatusOr<Image> DrawMarks(const ReliefSampler& relief,
                                const MarkSource& marks,
                                const MarksPictureOptions& options = {});

// A mark polyline as marks.png strokes it, in its picture's pixels: the
// vertices kept (those within 0.05 px and 0.25 degrees of their kept
// neighbours' segment left out), their angles, and whether the last joins
// the first (a closed polyline of more than two vertices). A view: the
// arrays belong to whoever visits with it.
struct KeptPolyline {
  std::span<const double> x, y, angle;  // the same size
  bool wrap = false;
};

// Kept polylines read in order, as MarkSource.
using KeptMarkSource = std::function<absl::Status(
    const std::function<absl::Status(const KeptPolyline&)>& visit)>;

// Mark polylines made into the kept polylines of a picture in `frame`, a
// batch at a time, kept on every thread. The checks DrawMarks makes: a
// polyline whose angles do not match its vertices is refused at once; once
// a vertex is not finite, nothing more is kept (later polylines' angles
// are still checked). Not thread-safe.
class MarkKeeper {
 public:
  explicit MarkKeeper(const PixelFrame& frame) : frame_(frame) {}
  // InvalidArgument for a polyline whose angles do not match its vertices
  // (nothing added).
  absl::Status Add(const MarkPolyline& p);
  // Whether the batch is large enough to Take.
  bool full() const;
  // Keeps the batch's polylines and visits each in order (visit's first
  // error is returned); the batch is then empty.
  absl::Status Take(
      const std::function<absl::Status(const KeptPolyline&)>& visit);
  // OK, or DrawMarks's InvalidArgument once a vertex added was not finite.
  absl::Status finite_status() const;
  const PixelFrame& frame() const { return frame_; }

 private:
  // A batch's vertices, and a group's (polylines kept by one thread).
  static constexpr size_t kBatchVertices = size_t{1} << 18;
  static constexpr size_t kGroupVertices = size_t{1} << 12;
  struct Group {
    std::vector<double> x, y, angle;
  };
  PixelFrame frame_;
  bool finite_ = true;
  // The batch in pixels, flat: polyline q's vertices are
  // [first_[q], first_[q + 1]).
  std::vector<double> xs_, ys_, angles_;
  std::vector<size_t> first_ = {0};
  std::vector<uint8_t> closed_;
  // Each group's first polyline, then the end; each group's kept vertices
  // (flat, polyline after polyline) and each polyline's count of them.
  std::vector<size_t> group_first_;
  std::vector<Group> group_kept_;
  std::vector<size_t> kept_count_;
};

// DrawMarks from kept polylines (MarkKeeper's, for this relief's frame).
absl::StatusOr<Image> DrawKeptMarks(const ReliefSampler& relief,
                                    const KeptMarkSource& marks,
                                    const MarksPictureOptions& options = {});

// RenderRelief(grid, options.relief) then DrawMarks. A relief already
// rendered (`drawn`, by RenderRelief(grid, drawn_with)) serves instead when
// its frame is the same (with the defaults, grids of about 1000 nodes and
// more per side); not owned, may be null.
absl::StatusOr<Image> RenderMarks(const SurfaceGrid& grid,
                                  const std::vector<MarkPolyline>& marks,
                                  const MarksPictureOptions& options = {},
                                  const Image* drawn = nullptr,
                                  const ReliefOptions& drawn_with = {});

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_PICTURES_H_
