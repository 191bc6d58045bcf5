// Is the part right: the machined surface against the design's top envelope
// z_d, at every node and at the valuation's samples between nodes (through
// the session's scheme), each gouge attributed to the program line of the
// move that cut it last (the node's owner).
//
// Contract:
// - Units: millimetres. Vertical deviation dz = z_machined - z_d: positive
//   is excess (material left), negative is gouge (cut into the part).
//   Where no design lies above a point there is nothing to keep and
//   nothing is compared. Depths in the result are positive.
// - The normal deviation is the distance from the machined point to the
//   design surface, with dz's sign; it never exceeds |dz| (the design point
//   straight above or below is at that distance), so it is queried only
//   where |dz| could change a maximum or the verdict.
// - The verdict uses the normal deviation: a point is out of tolerance when
//   its normal gouge > tolerance or its normal excess > allowance +
//   tolerance.
// - Runs on options.pool (default ThreadPool::Default()); the figures do not
//   depend on its size. Reads the grid, envelope and index only.
#ifndef SWARF_CLIENT_DEVIATION_H_
#define SWARF_CLIENT_DEVIATION_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include <functional>

#include "client/outputs/grid_bands.h"
#include "client/outputs/png_image.h"
#include "client/outputs/surface_grid.h"
#include "core/thread_pool.h"
#include "design/closest_point.h"
#include "design/top_envelope.h"

namespace swarf::cli {

// Where a move came from: files[file] line `line` (1-based).
struct SourceLine {
  int32_t file = 0;
  int32_t line = 0;
};

struct DeviationOptions {
  double allowance = 0;     // mm of stock to leave (excess expected)
  double tolerance = 0.01;  // mm
  // Samples per element edge, as ValuationOptions: an n x n lattice over
  // each element minus its corners (5: the valuation's 21). 0 or 1: nodes
  // only.
  int samples_per_edge = 5;
  int max_lines = 50;  // lines listed, each list
  ThreadPool* pool = nullptr;
};

// One program line's share.
struct LineDeviation {
  int32_t file = 0, line = 0;
  double depth = 0;        // its worst gouge (or excess), mm, positive
  double x = 0, y = 0;     // where
  double area_mm2 = 0;     // nodes it owns out of tolerance, x cell area
};

struct DeviationReport {
  int64_t nodes = 0, samples = 0;  // compared (design above them)
  // Vertical.
  double gouge_max = 0, gouge_x = 0, gouge_y = 0;
  int32_t gouge_move = -1;  // the owner there (-1: none)
  double gouge_volume = 0;  // mm^3, node cells
  double excess_max = 0, excess_x = 0, excess_y = 0;
  double excess_mean = 0;  // mean of max(dz, 0) over the nodes compared
  double excess_volume = 0;
  // Normal.
  double normal_gouge_max = 0, normal_excess_max = 0;
  int64_t normal_queries = 0;
  // The verdict.
  double allowance = 0, tolerance = 0;
  double out_area_mm2 = 0;  // nodes out of tolerance x cell area
  bool ok = true;
  // Lines whose gouges are out of tolerance, deepest first.
  std::vector<LineDeviation> gouge_lines;
  // Lines that left excess out of tolerance where they cut last (normal
  // excess > allowance + tolerance), largest first.
  std::vector<LineDeviation> excess_lines;
  // Per node (row-major as the grid), for deviation.png: the signed normal
  // deviation where it was queried, else dz (then within tolerance); NaN
  // where no design lies above.
  std::vector<float> node_deviation;
};

// `move_lines[id]` is move id's source (moves beyond it: no line).
absl::StatusOr<DeviationReport> MeasureDeviation(
    const SurfaceGrid& grid, const design::TopEnvelope& envelope,
    const design::ClosestPointIndex& index,
    const std::vector<SourceLine>& move_lines,
    const DeviationOptions& options = {});

// The same figures from a grid read band by band (GridBands; the report's
// node_deviation stays empty): each band's node rows [j0, j1), their
// values as node_deviation would hold them (row-major, NaN where no design
// lies above), go to node_rows in order, once. Bit for bit the whole-grid
// function's figures (the same tasks, merged in the same order).
absl::StatusOr<DeviationReport> MeasureDeviation(
    GridBands& grid, const design::TopEnvelope& envelope,
    const design::ClosestPointIndex& index,
    const std::vector<SourceLine>& move_lines, const DeviationOptions& options,
    const std::function<void(int32_t j0, int32_t j1, const float* values)>&
        node_rows);

// deviation.png's map: the node deviations max-pooled by magnitude over
// blocks of nodes (at most max_side pixels along the longer side), fed
// node rows in order (AddRows), bounded by the picture's size.
struct DeviationPicture {
  DeviationPicture(int32_t nodes_x, int32_t nodes_y, int max_side = 1600);
  void AddRows(int32_t j0, int32_t j1, const float* values);
  int32_t nodes_x, nodes_y, block;
  int width, height;  // the map's pixels
  std::vector<float> worst;  // per pixel, row 0 north; NaN: none
};

// deviation.png from the pooled map.
absl::StatusOr<Image> RenderDeviationMap(const DeviationPicture& map,
                                         const StockSpec& spec,
                                         const DeviationReport& report);

// deviation.png: the node deviations (max-pooled by magnitude to at most
// max_side pixels along the longer side), white within tolerance, gouge in
// reds and excess in blues (darker = larger, up to the report's maxima),
// grey where there is no design; a labelled scale to the right; the worst
// gouging lines marked with their numbers ("L123").
absl::StatusOr<Image> RenderDeviationMap(const SurfaceGrid& grid,
                                         const DeviationReport& report,
                                         int max_side = 1600);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_DEVIATION_H_
