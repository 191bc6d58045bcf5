// Precision valuation (paper section 5): the scheme's reconstruction against
// the exact machined surface at sample points inside every element.
#ifndef SWARF_CORE_VALUATION_H_
#define SWARF_CORE_VALUATION_H_

#include <cstdint>
#include <optional>

#include "absl/status/statusor.h"
#include "core/geometry.h"
#include "core/workpiece.h"

namespace swarf {

struct ErrorStats {
  double max_error = 0;   // mm
  double mean_error = 0;  // mm
  double rms_error = 0;   // mm
  double max_x = 0, max_y = 0;  // where the max error is (first found)
  int64_t samples = 0;
};

struct ValuationOptions {
  // Samples per element edge: an n x n lattice over each element minus its
  // four corners. 5 gives the paper's 21 samples (Fig. 5). In [2, 64].
  int samples_per_edge = 5;
  // Only samples inside this rectangle; the whole stock when absent.
  std::optional<Rect> region;
};

// Eq. (15): error = |w - w_exact| over every sample. InvalidArgument for bad
// options. Runs on the workpiece's pool; must not overlap an Apply.
absl::StatusOr<ErrorStats> MeasureError(const Workpiece& wp,
                                        const ValuationOptions& options = {});

// Eq. (15) at one point.
inline double SampleError(double w, double w_exact) {
  return std::fabs(w - w_exact);
}

}  // namespace swarf

#endif  // SWARF_CORE_VALUATION_H_
