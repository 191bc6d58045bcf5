// Reconstruction schemes: eq. (16) bilinear interpolation and eq. (1)-(2)
// minimum of Taylor patches, alone and on a workpiece.
#include "core/scheme.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "absl/status/status.h"
#include "gtest/gtest.h"
#include "core/workpiece.h"

namespace swarf {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();

ElementCorners Element(double x0, double y0, double x1, double y1,
                       double z_top) {
  ElementCorners e;
  e.x0 = x0;
  e.y0 = y0;
  e.x1 = x1;
  e.y1 = y1;
  e.z_top = z_top;
  return e;
}

// Corner k of e: c[0] (x0,y0), c[1] (x1,y0), c[2] (x1,y1), c[3] (x0,y1).
double CornerX(const ElementCorners& e, int k) {
  return (k == 1 || k == 2) ? e.x1 : e.x0;
}
double CornerY(const ElementCorners& e, int k) { return k >= 2 ? e.y1 : e.y0; }

TEST(BilinearHeightTest, ReproducesCornersExactlyOnDyadicElement) {
  // xi, eta are exactly +-1 at the corners here, so no rounding at all.
  ElementCorners e = Element(1, -2, 3, 2, 100);
  const double w[4] = {0.3, -7.25, 4.125, 1e-3};
  for (int k = 0; k < 4; ++k) e.c[k].w = w[k];
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(BilinearHeight(e, CornerX(e, k), CornerY(e, k)), w[k]) << k;
  }
  // The centre is the mean of the corners.
  EXPECT_DOUBLE_EQ(BilinearHeight(e, 2, 0), (w[0] + w[1] + w[2] + w[3]) / 4);
}

TEST(BilinearHeightTest, ReproducesCornersOnAnyElement) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-50, 50), size(1e-3, 3);
  for (int it = 0; it < 1000; ++it) {
    const double x0 = u(rng), y0 = u(rng);
    ElementCorners e = Element(x0, y0, x0 + size(rng), y0 + size(rng), 100);
    double scale = 0;
    for (auto& c : e.c) {
      c.w = u(rng);
      scale = std::max(scale, std::fabs(c.w));
    }
    // xi = (x - xc) / a is +-1 only up to the rounding of x - xc, eps |x|,
    // relative to the half-width a; the weights pass that on to the corner
    // values, plus a few roundings of the sum itself.
    const double cond = 1 + (std::fabs(e.x0) + std::fabs(e.x1)) / (e.x1 - e.x0) +
                        (std::fabs(e.y0) + std::fabs(e.y1)) / (e.y1 - e.y0);
    for (int k = 0; k < 4; ++k) {
      EXPECT_NEAR(BilinearHeight(e, CornerX(e, k), CornerY(e, k)), e.c[k].w,
                  16 * kEps * scale * cond);
    }
  }
}

TEST(BilinearHeightTest, ExactForBilinearFunctions) {
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-10, 10), unit(0, 1),
      size(0.01, 4);
  for (int it = 0; it < 2000; ++it) {
    const double a = u(rng), b = u(rng), c = u(rng), d = u(rng);
    auto f = [&](double x, double y) { return a + b * x + c * y + d * x * y; };
    const double x0 = u(rng), y0 = u(rng);
    ElementCorners e = Element(x0, y0, x0 + size(rng), y0 + size(rng), 1e9);
    for (int k = 0; k < 4; ++k) e.c[k].w = f(CornerX(e, k), CornerY(e, k));
    const double x = e.x0 + (e.x1 - e.x0) * unit(rng);
    const double y = e.y0 + (e.y1 - e.y0) * unit(rng);
    // Exact in exact arithmetic; rounding is a few ulps of the largest term.
    const double scale = std::fabs(a) + std::fabs(b * x) + std::fabs(c * y) +
                         std::fabs(d * x * y) + 1;
    EXPECT_NEAR(BilinearHeight(e, x, y), f(x, y), 64 * kEps * scale);
  }
}

// Random corner jets, z_top high enough that the patches usually win.
ElementCorners RandomPatches(std::mt19937_64& rng, double z_top) {
  std::uniform_real_distribution<double> u(-5, 5), size(0.05, 2);
  const double x0 = u(rng), y0 = u(rng);
  ElementCorners e = Element(x0, y0, x0 + size(rng), y0 + size(rng), z_top);
  for (auto& c : e.c) c = {u(rng), u(rng), u(rng), u(rng), u(rng), u(rng)};
  return e;
}

TEST(MinOfPatchesTest, IsTheLowestPatchCappedByTheTop) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> unit(0, 1);
  int capped = 0, patched = 0;
  for (int it = 0; it < 5000; ++it) {
    const ElementCorners e =
        RandomPatches(rng, it % 3 == 0 ? 1e9 : it % 3 == 1 ? 1.0 : -40.0);
    const double x = e.x0 + (e.x1 - e.x0) * unit(rng);
    const double y = e.y0 + (e.y1 - e.y0) * unit(rng);
    double want = e.z_top;
    double scale = 0;
    for (int k = 0; k < 4; ++k) {
      want = std::min(want, EvaluatePatch(e.c[k], CornerX(e, k),
                                          CornerY(e, k), x, y));
      // |w| plus the five other terms: each at most 5 * 2 * 2 = 20.
      scale = std::max(scale, std::fabs(e.c[k].w) + 5 * 20);
    }
    const double got = MinOfPatches(e, x, y);
    // A patch is six terms; any evaluation order is within a few ulps of
    // their total size.
    EXPECT_NEAR(got, want, 16 * kEps * scale);
    EXPECT_LE(got, e.z_top);  // never above the stock top
    if (want == e.z_top) {
      EXPECT_EQ(got, e.z_top);
      ++capped;
    } else {
      ++patched;
    }
  }
  EXPECT_GT(capped, 1000);
  EXPECT_GT(patched, 1000);
}

TEST(MinOfPatchesTest, ExactForAQuadratic) {
  // Four Taylor jets of one quadratic: every patch is that quadratic.
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-3, 3), unit(0, 1);
  for (int it = 0; it < 1000; ++it) {
    const double q[6] = {u(rng), u(rng), u(rng), u(rng), u(rng), u(rng)};
    auto f = [&](double x, double y) {
      return q[0] + q[1] * x + q[2] * y + 0.5 * q[3] * x * x + q[4] * x * y +
             0.5 * q[5] * y * y;
    };
    ElementCorners e = Element(u(rng), u(rng), 0, 0, 1e9);
    e.x1 = e.x0 + 0.5;
    e.y1 = e.y0 + 0.25;
    for (int k = 0; k < 4; ++k) {
      const double x = CornerX(e, k), y = CornerY(e, k);
      e.c[k] = {f(x, y), q[1] + q[3] * x + q[4] * y, q[2] + q[4] * x + q[5] * y,
                q[3], q[4], q[5]};
    }
    const double x = e.x0 + 0.5 * unit(rng), y = e.y0 + 0.25 * unit(rng);
    EXPECT_NEAR(MinOfPatches(e, x, y), f(x, y), 1e-13);  // sums of O(10)
    e.z_top = f(x, y) - 1;
    EXPECT_EQ(MinOfPatches(e, x, y), e.z_top);
  }
}

TEST(MinOfPatchesTest, AtACornerNeverAboveItsNode) {
  std::mt19937_64 rng(5);
  for (int it = 0; it < 1000; ++it) {
    const ElementCorners e = RandomPatches(rng, 1e9);
    for (int k = 0; k < 4; ++k) {
      // The corner's own patch is exactly its node height there.
      EXPECT_LE(MinOfPatches(e, CornerX(e, k), CornerY(e, k)), e.c[k].w);
    }
  }
}

TEST(SchemeTest, Registry) {
  const Scheme& zmap = GetScheme(SchemeKind::kZmap);
  const Scheme& taylor = GetScheme(SchemeKind::kTaylor);
  EXPECT_EQ(zmap.kind(), SchemeKind::kZmap);
  EXPECT_EQ(taylor.kind(), SchemeKind::kTaylor);
  EXPECT_EQ(zmap.name(), "zmap");
  EXPECT_EQ(taylor.name(), "taylor");
  // Tables 1-2 of the paper: 1 and 6 parameters per node.
  EXPECT_EQ(zmap.parameters_per_node(), 1);
  EXPECT_EQ(taylor.parameters_per_node(), 6);
  EXPECT_FALSE(zmap.stores_derivatives());
  EXPECT_TRUE(taylor.stores_derivatives());
  EXPECT_GE(zmap.bytes_per_node(), 8 + 4);    // a double and the owner id
  // Derivatives are computed from the owner on demand, not stored.
  EXPECT_EQ(taylor.bytes_per_node(), zmap.bytes_per_node());
  EXPECT_EQ(*ParseScheme("zmap"), SchemeKind::kZmap);
  EXPECT_EQ(*ParseScheme("taylor"), SchemeKind::kTaylor);
  for (const char* bad : {"", "Zmap", "taylor ", "bilinear"}) {
    EXPECT_EQ(ParseScheme(bad).status().code(),
              absl::StatusCode::kInvalidArgument)
        << bad;
  }
  std::mt19937_64 rng(6);
  for (int it = 0; it < 100; ++it) {
    const ElementCorners e = RandomPatches(rng, 2.0);
    const double x = 0.5 * (e.x0 + e.x1), y = e.y0 + 0.3 * (e.y1 - e.y0);
    EXPECT_EQ(zmap.Reconstruct(e, x, y), BilinearHeight(e, x, y));
    EXPECT_EQ(taylor.Reconstruct(e, x, y), MinOfPatches(e, x, y));
  }
}

// On a cut workpiece, Reconstruct at a node: zmap gives the node height;
// taylor gives the minimum of the node height and its element's other
// patches there (eq. 2), hence never more than the node height.
TEST(SchemeTest, WorkpieceReconstructAtNodes) {
  const StockSpec spec{0, 0, 20, 12, 5, 37, 23};
  const std::vector<Move> moves = {
      {{2, 2, 7}, {2, 2, 3}, 2.5},      {{-1, 6, 4}, {22, 8, 2}, 3},
      {{10, 0, 4.5}, {14, 12, 3.8}, 1.5}, {{17, 9, 3}, {17, 9, 3}, 2},
  };
  for (SchemeKind kind : {SchemeKind::kZmap, SchemeKind::kTaylor}) {
    SCOPED_TRACE(GetScheme(kind).name());
    auto wp = Workpiece::Create(spec, kind);
    ASSERT_TRUE(wp.ok());
    ASSERT_TRUE((*wp)->Apply(moves).ok());
    const GridGeometry& g = (*wp)->grid();
    for (int32_t j = 0; j <= spec.ny; ++j) {
      for (int32_t i = 0; i <= spec.nx; ++i) {
        const double x = g.NodeX(i), y = g.NodeY(j);
        const double w = (*wp)->Node(i, j).jet.w;
        const double got = (*wp)->Reconstruct(x, y);
        if (kind == SchemeKind::kZmap) {
          // Exact but for the rounding of xi, eta = +-1 (see above).
          EXPECT_NEAR(got, w, 16 * kEps * 10) << i << "," << j;
        } else {
          EXPECT_LE(got, w) << i << "," << j;
          const ElementCorners e = (*wp)->Corners(g.ElementX(x), g.ElementY(y));
          EXPECT_EQ(got, MinOfPatches(e, x, y)) << i << "," << j;
        }
      }
    }
    // Untouched corners of the stock: exactly the top.
    EXPECT_EQ((*wp)->Reconstruct(20, 0), 5);
    EXPECT_EQ((*wp)->Reconstruct(0, 12), 5);
    // Points off the stock are clamped onto it.
    EXPECT_EQ((*wp)->Reconstruct(-3, -3), (*wp)->Reconstruct(0, 0));
    EXPECT_EQ((*wp)->Reconstruct(25, 6), (*wp)->Reconstruct(20, 6));
  }
}

}  // namespace
}  // namespace swarf
