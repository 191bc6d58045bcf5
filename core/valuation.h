// Precision valuation (paper section 5): the scheme's reconstruction against
// the exact machined surface at sample points inside every element.
#ifndef SWARF_CORE_VALUATION_H_
#define SWARF_CORE_VALUATION_H_

#include <cstdint>
#include <optional>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry.h"
#include "core/thread_pool.h"
#include "core/workpiece.h"

namespace swarf {

struct ErrorStats {
  double max_error = 0;   // mm
  double mean_error = 0;  // mm
  double rms_error = 0;   // mm
  double max_x = 0, max_y = 0;  // where the max error is (first found)
  int64_t samples = 0;
  // With ValuationOptions::map_cols/map_rows: the max error (mm) in each
  // cell of a map_cols x map_rows raster over the region, row-major, cell
  // (0, 0) at the region's (x0, y0); 0 where no sample fell.
  int32_t map_cols = 0, map_rows = 0;
  std::vector<float> map;
};

struct ValuationOptions {
  // Samples per element edge: an n x n lattice over each element minus its
  // four corners. 5 gives the paper's 21 samples (Fig. 5). In [2, 64].
  int samples_per_edge = 5;
  // Only samples inside this rectangle; the whole stock when absent.
  std::optional<Rect> region;
  // An error raster over the region (both 0: none). At most kMaxMapCells.
  int32_t map_cols = 0, map_rows = 0;
  // The threads to run on (not owned); null: the workpiece's pool. The
  // statistics and the map are bit-identical whatever the pool's size.
  ThreadPool* pool = nullptr;
};

inline constexpr int64_t kMaxMapCells = int64_t{1} << 24;

// Eq. (15): error = |w - w_exact| over every sample. InvalidArgument for bad
// options. Runs on options.pool (default: the workpiece's) over bins of
// MoveIndex::kBinElements^2 elements, each bin's sums taken in element and
// sample order and the bins' added in bin order, so the result does not
// depend on the threads. Must not overlap an Apply.
absl::StatusOr<ErrorStats> MeasureError(const Workpiece& wp,
                                        const ValuationOptions& options = {});

// Eq. (15) at one point.
inline double SampleError(double w, double w_exact) {
  return std::fabs(w - w_exact);
}

}  // namespace swarf

#endif  // SWARF_CORE_VALUATION_H_
