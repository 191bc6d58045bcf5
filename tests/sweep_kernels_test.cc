// The vectorized row kernels against the scalar sweep: bit-identical heights,
// points and derivatives; and the frame-form cylinder jet against eq. (14).
#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <vector>

#include "core/cutter/ball_sweep.h"
#include "gtest/gtest.h"

namespace swarf {
namespace {

// Random moves of every kind a toolpath contains.
std::vector<BallSweep> RandomSweeps(int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-5, 5), r(0.2, 4);
  std::vector<BallSweep> out;
  for (int k = 0; k < count; ++k) {
    const Vec3 a{u(rng), u(rng), u(rng) - 3};
    Vec3 b{u(rng), u(rng), u(rng) - 3};
    switch (k % 6) {
      case 0: b = {a.x, a.y, b.z}; break;             // plunge or retract
      case 1: b = a; break;                           // zero length
      case 2: b.z = a.z; break;                       // horizontal
      case 3: b = {a.x + 1e-7, a.y, a.z - 4}; break;  // near vertical
      default: break;                                 // sloped
    }
    out.emplace_back(a, b, r(rng));
  }
  return out;
}

bool SameBits(double a, double b) { return std::memcmp(&a, &b, 8) == 0; }

// Grid-like points: rows of nodes, as the tile kernel sends them.
void RowPoints(double y, std::vector<double>* xs, std::vector<double>* ys) {
  xs->clear();
  ys->clear();
  for (int32_t i = 0; i < 150; ++i) {
    xs->push_back(-9.3 + i * 0.137);
    ys->push_back(y);
  }
}

TEST(SweepKernelsTest, HeightsMatchHeightBitForBit) {
  int points = 0;
  std::vector<double> xs, ys;
  for (const BallSweep& s : RandomSweeps(120, 7)) {
    for (double y = -9; y < 9; y += 0.77) {
      RowPoints(y, &xs, &ys);
      // Odd counts exercise the vector loops' remainders.
      for (int32_t n : {int32_t{150}, int32_t{37}, int32_t{1}}) {
        std::vector<double> h(n);
        s.Heights(xs.data(), ys.data(), n, h.data());
        for (int32_t q = 0; q < n; ++q) {
          ASSERT_TRUE(SameBits(h[q], s.Height(xs[q], ys[q])))
              << h[q] << " vs " << s.Height(xs[q], ys[q]);
          ++points;
        }
      }
    }
  }
  EXPECT_GT(points, 100000);
}

TEST(SweepKernelsTest, LocateAndJetsMatchTheScalarPath) {
  std::vector<double> xs, ys;
  int checked = 0;
  auto pts = std::make_unique<BallSweep::Points>();
  for (const BallSweep& s : RandomSweeps(60, 11)) {
    for (double y = -6; y < 6; y += 0.9) {
      RowPoints(y, &xs, &ys);
      const int32_t n = static_cast<int32_t>(xs.size());
      s.Locate(xs.data(), ys.data(), n, pts.get());
      std::vector<float> store(5 * n);
      float* d[5];
      for (int c = 0; c < 5; ++c) d[c] = store.data() + c * n;
      s.Jets(*pts, n, d);
      for (int32_t q = 0; q < n; ++q) {
        const SweepPoint p = s.Locate(xs[q], ys[q]);
        const SweepPoint v = pts->At(q);
        ASSERT_TRUE(SameBits(v.w, p.w));
        ASSERT_EQ(v.piece, p.piece);
        if (p.piece != SweepPoint::kNone) {
          ASSERT_TRUE(SameBits(v.px, p.px));
          ASSERT_TRUE(SameBits(v.py, p.py));
          ASSERT_TRUE(SameBits(v.depth, p.depth));
        }
        const SurfaceJet j = s.Jet(p);
        const double want[5] = {j.wx, j.wy, j.wxx, j.wxy, j.wyy};
        for (int c = 0; c < 5; ++c) {
          ASSERT_EQ(d[c][q], static_cast<float>(want[c])) << "q " << q;
        }
        checked += p.piece != SweepPoint::kNone;
      }
    }
  }
  EXPECT_GT(checked, 10000);
}

TEST(SweepKernelsTest, FrameFormCylinderJetEqualsEquation14) {
  // Both are exact expressions of the same derivatives; they differ only by
  // rounding, a few ulps of the largest term (slope^2 / depth at most 1e3
  // here since points within 5% of the rim are skipped).
  int checked = 0;
  for (const BallSweep& s : RandomSweeps(300, 5)) {
    for (double y = -9; y < 9; y += 0.31) {
      for (double x = -9; x < 9; x += 0.29) {
        const SweepPoint p = s.Locate(x, y);
        if (p.piece != SweepPoint::kCylinder) continue;
        if (p.depth < 0.05 * s.radius()) continue;
        const SurfaceJet a = s.Jet(p), b = s.CylinderJetEq14(p);
        const double scale1 = 1 + std::fabs(b.wx) + std::fabs(b.wy);
        const double scale2 = 1 + std::fabs(b.wxx) + std::fabs(b.wxy) +
                              std::fabs(b.wyy);
        ASSERT_NEAR(a.wx, b.wx, 1e-12 * scale1);
        ASSERT_NEAR(a.wy, b.wy, 1e-12 * scale1);
        ASSERT_NEAR(a.wxx, b.wxx, 1e-11 * scale2);
        ASSERT_NEAR(a.wxy, b.wxy, 1e-11 * scale2);
        ASSERT_NEAR(a.wyy, b.wyy, 1e-11 * scale2);
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 5000);
}

}  // namespace
}  // namespace swarf
