// The vectorized row kernels against the scalar sweep: bit-identical heights,
// points and derivatives; and the frame-form cylinder jet against eq. (14).
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "core/ball_sweep.h"
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

TEST(SweepKernelsTest, RowHeightsAndLocateRowMatchLocateBitForBit) {
  int rows = 0;
  for (const BallSweep& s : RandomSweeps(120, 7)) {
    const double x0 = -9.3, dx = 0.137;
    for (double y = -9; y < 9; y += 0.77) {
      for (int32_t i0 : {0, 5, 61}) {
        const int32_t n = BallSweep::RowPoints::kMax;
        double h[BallSweep::RowPoints::kMax];
        BallSweep::RowPoints row;
        s.RowHeights(y, x0, dx, i0, n, h);
        s.LocateRow(y, x0, dx, i0, n, &row);
        for (int32_t k = 0; k < n; ++k) {
          const SweepPoint p = s.Locate(x0 + (i0 + k) * dx, y);
          ASSERT_TRUE(SameBits(h[k], p.w)) << h[k] << " vs " << p.w;
          const SweepPoint q = row.At(k);
          ASSERT_TRUE(SameBits(q.w, p.w));
          ASSERT_EQ(q.piece, p.piece);
          if (p.piece != SweepPoint::kNone) {
            ASSERT_TRUE(SameBits(q.px, p.px));
            ASSERT_TRUE(SameBits(q.py, p.py));
            ASSERT_TRUE(SameBits(q.depth, p.depth));
          }
        }
        ++rows;
      }
    }
  }
  EXPECT_GT(rows, 1000);
}

TEST(SweepKernelsTest, RowJetsStoreJetAsFloatOnlyWhereMasked) {
  std::mt19937_64 rng(3);
  for (const BallSweep& s : RandomSweeps(60, 11)) {
    for (double y = -6; y < 6; y += 0.9) {
      const int32_t n = 50;
      BallSweep::RowPoints row;
      s.LocateRow(y, -6, 0.25, 0, n, &row);
      int32_t mask[64];
      for (int32_t k = 0; k < n; ++k) {
        mask[k] = row.piece[k] != SweepPoint::kNone && (rng() % 3 != 0);
      }
      constexpr float kUntouched = -12345.0f;
      std::vector<float> store(5 * 80, kUntouched);
      float* d[5];
      for (int c = 0; c < 5; ++c) d[c] = store.data() + c * 80;
      s.RowJets(row, mask, n, d, 7);
      for (int32_t k = 0; k < n; ++k) {
        const SurfaceJet j = s.Jet(s.Locate(-6 + k * 0.25, y));
        const double want[5] = {j.wx, j.wy, j.wxx, j.wxy, j.wyy};
        for (int c = 0; c < 5; ++c) {
          const float got = d[c][7 + k];
          if (mask[k]) {
            ASSERT_EQ(got, static_cast<float>(want[c])) << "k " << k;
          } else {
            ASSERT_EQ(got, kUntouched) << "k " << k;
          }
        }
      }
    }
  }
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
