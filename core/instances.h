// The paper's two instances (section 6). The paper gives no geometry; this
// project fixes it (see issue 2 / README).
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

}  // namespace swarf

#endif  // SWARF_CORE_INSTANCES_H_
