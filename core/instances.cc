#include "core/instances.h"

#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace swarf {

absl::StatusOr<Instance> PaperInstance(std::string_view name, int mesh) {
  if (mesh < 1 || mesh > kMaxElementsPerAxis) {
    return absl::InvalidArgumentError(
        absl::StrCat("mesh must be in [1, ", kMaxElementsPerAxis, "], got ",
                     mesh));
  }
  Instance inst;
  inst.name = std::string(name);
  inst.stock = StockSpec{0, 0, 100, 100, 0, mesh, mesh};
  if (name == "five-balls") {
    // Ball r = 20 plunging vertically, tip z +5 -> -10.
    const double centres[5][2] = {
        {50, 50}, {30, 30}, {70, 30}, {30, 70}, {70, 70}};
    for (const auto& c : centres) {
      inst.moves.push_back({{c[0], c[1], 5}, {c[0], c[1], -10}, Cutter::Ball(20)});
    }
    return inst;
  }
  if (name == "five-cylinders") {
    // Ball r = 10, tip z = -4, grooves of length 80 through (50, 50).
    for (int k = 0; k < 5; ++k) {
      const double a = k * 36.0 * std::numbers::pi / 180.0;
      const double ux = std::cos(a), uy = std::sin(a);
      inst.moves.push_back(
          {{50 - 40 * ux, 50 - 40 * uy, -4}, {50 + 40 * ux, 50 + 40 * uy, -4},
           Cutter::Ball(10)});
    }
    return inst;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "unknown instance \"", std::string(name), "\" (expected five-balls or five-cylinders)"));
}

}  // namespace swarf
