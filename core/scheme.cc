#include "core/scheme.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"

namespace swarf {

double BilinearHeight(const ElementCorners& e, double x, double y) {
  // Eq. (16). With s = (1 + xi) / 2 and t = (1 + eta) / 2 in [0, 1] its four
  // shape functions are the nested linear interpolation below: the same
  // polynomial, but std::lerp is exact at s, t = 0 and 1 and for equal ends,
  // so corners and flat (untouched) elements reconstruct exactly.
  const double s = (x - e.x0) / (e.x1 - e.x0);
  const double t = (y - e.y0) / (e.y1 - e.y0);
  return std::lerp(std::lerp(e.c[0].w, e.c[1].w, s),
                   std::lerp(e.c[3].w, e.c[2].w, s), t);
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
  void Gradient(const ElementCorners& e, double x, double y, double* gx,
                double* gy) const override {
    const double lx = e.x1 - e.x0, ly = e.y1 - e.y0;
    const double s = (x - e.x0) / lx, t = (y - e.y0) / ly;
    const double w0 = e.c[0].w, w1 = e.c[1].w, w2 = e.c[2].w, w3 = e.c[3].w;
    *gx = ((1 - t) * (w1 - w0) + t * (w2 - w3)) / lx;
    *gy = ((1 - s) * (w3 - w0) + s * (w2 - w1)) / ly;
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
  void Gradient(const ElementCorners& e, double x, double y, double* gx,
                double* gy) const override {
    const double xs[4] = {e.x0, e.x1, e.x1, e.x0};
    const double ys[4] = {e.y0, e.y0, e.y1, e.y1};
    double w = e.z_top;
    *gx = *gy = 0;  // the stock top
    for (int k = 0; k < 4; ++k) {
      const double wk = EvaluatePatch(e.c[k], xs[k], ys[k], x, y);
      if (wk < w) {
        w = wk;
        PatchGradient(e.c[k], xs[k], ys[k], x, y, gx, gy);
      }
    }
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
