#include "core/scheme.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"

namespace swarf {

double BilinearHeight(const ElementCorners& e, double x, double y) {
  // Eq. (16) in the paper's local coordinates xi, eta in [-1, 1].
  const double xc = 0.5 * (e.x0 + e.x1), yc = 0.5 * (e.y0 + e.y1);
  const double a = 0.5 * (e.x1 - e.x0), b = 0.5 * (e.y1 - e.y0);
  const double xi = (x - xc) / a, eta = (y - yc) / b;
  return 0.25 * ((1 - xi) * (1 - eta) * e.c[0].w +
                 (1 + xi) * (1 - eta) * e.c[1].w +
                 (1 + xi) * (1 + eta) * e.c[2].w +
                 (1 - xi) * (1 + eta) * e.c[3].w);
}

double MinOfPatches(const ElementCorners& e, double x, double y) {
  const double xs[4] = {e.x0, e.x1, e.x1, e.x0};
  const double ys[4] = {e.y0, e.y0, e.y1, e.y1};
  double w = e.z_top;
  for (int k = 0; k < 4; ++k) {
    w = std::min(w, EvaluatePatch(e.c[k], xs[k], ys[k], x, y));
  }
  return w;
}

namespace {

class ZmapScheme final : public Scheme {
 public:
  SchemeKind kind() const override { return SchemeKind::kZmap; }
  std::string_view name() const override { return "zmap"; }
  int parameters_per_node() const override { return 1; }
  bool stores_derivatives() const override { return false; }
  int bytes_per_node() const override { return 12; }  // double w + int32 id
  double Reconstruct(const ElementCorners& e, double x,
                     double y) const override {
    return BilinearHeight(e, x, y);
  }
};

class TaylorScheme final : public Scheme {
 public:
  SchemeKind kind() const override { return SchemeKind::kTaylor; }
  std::string_view name() const override { return "taylor"; }
  int parameters_per_node() const override { return 6; }
  bool stores_derivatives() const override { return true; }
  // double w, five float derivatives, int32 id.
  int bytes_per_node() const override { return 32; }
  double Reconstruct(const ElementCorners& e, double x,
                     double y) const override {
    return MinOfPatches(e, x, y);
  }
};

}  // namespace

const Scheme& GetScheme(SchemeKind kind) {
  static const ZmapScheme* const zmap = new ZmapScheme;
  static const TaylorScheme* const taylor = new TaylorScheme;
  switch (kind) {
    case SchemeKind::kZmap:
      return *zmap;
    case SchemeKind::kTaylor:
      break;
  }
  return *taylor;
}

absl::StatusOr<SchemeKind> ParseScheme(std::string_view name) {
  if (name == "zmap") return SchemeKind::kZmap;
  if (name == "taylor") return SchemeKind::kTaylor;
  return absl::InvalidArgumentError(
      absl::StrCat("unknown scheme \"", std::string(name), "\" (expected zmap or taylor)"));
}

}  // namespace swarf
