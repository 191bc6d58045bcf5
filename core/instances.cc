#include "core/instances.h"

#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace swarf {

namespace {

absl::Status CheckMesh(int mesh) {
  if (mesh < 1 || mesh > kMaxElementsPerAxis) {
    return absl::InvalidArgumentError(
        absl::StrCat("mesh must be in [1, ", kMaxElementsPerAxis, "], got ",
                     mesh));
  }
  return absl::OkStatus();
}

// The toolpath of the shape instances (tool tips, mm), `depth` the
// deepest cut below the top: what a CAM job of one tool does besides
// horizontal raster passes.
void ShapeJob(const Cutter& c, double depth, std::vector<Move>* moves) {
  const double d = depth;
  const Vec3 path[][2] = {
      // Ramps along x: down at 0.8 d over 80 mm, and down the other way.
      {{10, 15, -0.1 * d}, {90, 15, -0.9 * d}},
      {{90, 32, -0.2 * d}, {10, 32, -0.6 * d}},
      // A diagonal ramp at 45 degrees and a horizontal diagonal.
      {{12, 48, -0.1 * d}, {52, 88, -0.7 * d}},
      {{90, 48, -0.5 * d}, {62, 90, -0.5 * d}},
      // Plunges from 3 mm above the top.
      {{25, 78, 3}, {25, 78, -d}},
      {{70, 40, 3}, {70, 40, -0.6 * d}},
  };
  for (const auto& m : path) moves->push_back({m[0], m[1], c});
}

}  // namespace

absl::StatusOr<Instance> NamedInstance(std::string_view name, int mesh) {
  // Depths as each tool is used: a flat end pockets 3 mm deep, a bull-nose
  // finishes within its corner, a V-bit and a tapered ball carve within
  // their flanks (4 mm: the V-bit reaches its radius at 6, the tapered
  // ball at 21.2).
  const struct {
    std::string_view name;
    Cutter cutter;
    double depth;
  } shapes[] = {{"flat-ramps", Cutter::Flat(5), 3},
                {"bull-ramps", Cutter::BullNose(5, 2), 1.6},
                {"cone-ramps", Cutter::Cone(6, 45, 0), 4},
                {"taper-ramps", Cutter::TaperedBall(5, 1.5, 10), 4}};
  for (const auto& s : shapes) {
    if (name != s.name) continue;
    if (absl::Status st = CheckMesh(mesh); !st.ok()) return st;
    Instance inst;
    inst.name = std::string(name);
    inst.stock = StockSpec{0, 0, 100, 100, 0, mesh, mesh};
    ShapeJob(s.cutter, s.depth, &inst.moves);
    return inst;
  }
  for (std::string_view paper : kPaperInstances) {
    if (name == paper) return PaperInstance(name, mesh);
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "unknown instance \"", std::string(name),
      "\" (expected five-balls, five-cylinders, flat-ramps, bull-ramps, "
      "cone-ramps or taper-ramps)"));
}

absl::StatusOr<Instance> PaperInstance(std::string_view name, int mesh) {
  if (absl::Status st = CheckMesh(mesh); !st.ok()) return st;
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
