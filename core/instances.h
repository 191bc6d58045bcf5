// Named jobs for `swarf table` and the tests: the paper's two instances
// (section 6; the paper gives no geometry, this project fixes it, see issue
// 2 / README) and one job per cutter shape (issue 16; README).
#ifndef SWARF_CORE_INSTANCES_H_
#define SWARF_CORE_INSTANCES_H_

#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "core/stock.h"
#include "core/workpiece.h"

namespace swarf {

struct Instance {
  std::string name;
  StockSpec stock;
  std::vector<Move> moves;
};

// "five-balls" or "five-cylinders" on a mesh x mesh grid; InvalidArgument for
// an unknown name or mesh < 1.
absl::StatusOr<Instance> PaperInstance(std::string_view name, int mesh);

inline constexpr std::string_view kPaperInstances[] = {"five-balls",
                                                       "five-cylinders"};

// One job per cutter shape (issue 16), the same toolpath for each, scaled
// to a depth D: two ramps along x, a diagonal ramp, a horizontal diagonal
// and two plunges into [0,100] x [0,100], top z = 0 (geometry in the
// README). "flat-ramps": flat end r = 5, D = 3; "bull-ramps": bull-nose
// r = 5, corner 2, D = 1.6; "cone-ramps": 90-degree V-bit r = 6 (half angle
// 45, sharp), D = 4; "taper-ramps": tapered ball r = 5, ball tip 1.5, half
// angle 10, D = 4.
inline constexpr std::string_view kShapeInstances[] = {
    "flat-ramps", "bull-ramps", "cone-ramps", "taper-ramps"};

// Any of the above by name; InvalidArgument naming the known ones for an
// unknown name, or for mesh < 1.
absl::StatusOr<Instance> NamedInstance(std::string_view name, int mesh);

}  // namespace swarf

#endif  // SWARF_CORE_INSTANCES_H_
