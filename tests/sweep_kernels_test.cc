// The vectorized row kernels against the scalar sweep: bit-identical heights,
// points and derivatives, also for many sweeps at once (MakeFrames,
// JetsOfFrames); Hypot against the C library's; and the frame-form cylinder
// jet against eq. (14).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "core/cutter/ball_sweep.h"
#include "core/cutter/capsule.h"
#include "core/cutter/hypot.h"
#include "gtest/gtest.h"

namespace swarf {
namespace {

struct BallMove {
  Vec3 from, to;
  double radius;
};

// Random moves of every kind a toolpath contains.
std::vector<BallMove> RandomMoves(int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-5, 5), r(0.2, 4);
  std::vector<BallMove> out;
  for (int k = 0; k < count; ++k) {
    const Vec3 a{u(rng), u(rng), u(rng) - 3};
    Vec3 b{u(rng), u(rng), u(rng) - 3};
    switch (k % 8) {
      case 0: b = {a.x, a.y, b.z}; break;             // plunge or retract
      case 1: b = a; break;                           // zero length
      case 2: b.z = a.z; break;                       // horizontal
      case 3: b = {a.x + 1e-7, a.y, a.z - 4}; break;  // near vertical
      case 4: b = {a.x + 1e-12, a.y, a.z - 4}; break;  // vertical to 1e-12
      case 5: b = {a.x + 0.2, a.y, a.z - 1e-3}; break;  // finishing step
      default: break;                                 // sloped
    }
    out.push_back({a, b, r(rng)});
  }
  return out;
}

std::vector<BallSweep> RandomSweeps(int count, uint64_t seed) {
  std::vector<BallSweep> out;
  for (const BallMove& m : RandomMoves(count, seed)) {
    out.emplace_back(m.from, m.to, m.radius);
  }
  return out;
}

bool SameBits(double a, double b) { return std::memcmp(&a, &b, 8) == 0; }
bool SameBits(float a, float b) { return std::memcmp(&a, &b, 4) == 0; }

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

// Capsule k of a test's: along x, along y, diagonal or a point (k % 4), its
// ends from `pos`, its direction filled.
Capsule TestCapsule(int k, double radius, std::mt19937_64& rng,
                    std::uniform_real_distribution<double>& pos) {
  Capsule c;
  c.empty = false;
  c.x0 = pos(rng);
  c.y0 = pos(rng);
  switch (k % 4) {
    case 0:
      c.x1 = pos(rng), c.y1 = pos(rng);
      break;  // diagonal
    case 1:
      c.x1 = c.x0, c.y1 = pos(rng);
      break;  // along y
    case 2:
      c.x1 = pos(rng), c.y1 = c.y0;
      break;  // along x
    default:
      c.x1 = c.x0, c.y1 = c.y0;
      break;  // a point
  }
  c.radius = radius;
  FillDirection(&c);
  return c;
}

// The grid of the row-range tests: nodes kX0 + i * kDx, 0 <= i <= kIMax,
// on rows kY0 + j * kDy.
constexpr double kX0 = 0.05, kDx = 0.1, kY0 = -0.3, kDy = 0.07;
constexpr int32_t kIMax = 100;

// That [lo, hi] is NodeRange of c.RowSpan(y) (lo > hi where the span is
// empty or holds no node), counting the row as hit or missed.
void ExpectRowSpanNodes(const Capsule& c, double y, int32_t lo, int32_t hi,
                        int32_t* rows_hit, int32_t* rows_missed) {
  const Interval span = c.RowSpan(y);
  auto [want_lo, want_hi] = NodeRange(span.lo, span.hi, kX0, 1 / kDx, kIMax);
  if (span.empty() || want_lo > want_hi) {
    ++*rows_missed;
    EXPECT_GT(lo, hi) << "row at y " << y << ", radius " << c.radius;
  } else {
    ++*rows_hit;
    EXPECT_EQ(lo, want_lo) << "row at y " << y << ", radius " << c.radius;
    EXPECT_EQ(hi, want_hi) << "row at y " << y << ", radius " << c.radius;
  }
}

// CutTile's rows: RowNodeRanges is RowSpan and NodeRange, row by row, for
// capsules in every direction (along x, along y, diagonal, points), rows
// that miss, and spans clipped at the grid's ends.
TEST(SweepKernelsTest, RowNodeRangesMatchRowSpanAndNodeRange) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> pos(-2, 12), rad(0.01, 3);
  int32_t rows_hit = 0, rows_missed = 0;
  for (int k = 0; k < 4000; ++k) {
    const Capsule c = TestCapsule(k, rad(rng), rng, pos);
    const int32_t j0 = static_cast<int32_t>(rng() % 40) - 5;
    const int32_t n = 1 + static_cast<int32_t>(rng() % 200);
    std::vector<int32_t> lo(n), hi(n);
    RowNodeRanges(c, kY0, kDy, j0, n, kX0, 1 / kDx, kIMax, lo.data(),
                  hi.data());
    for (int32_t q = 0; q < n; ++q) {
      ExpectRowSpanNodes(c, kY0 + (j0 + q) * kDy, lo[q], hi[q], &rows_hit,
                         &rows_missed);
    }
  }
  EXPECT_GT(rows_hit, 10000);
  EXPECT_GT(rows_missed, 10000);
}

// CutTile's narrowed rows: RowNodeRangesAt is RowSpan and NodeRange of the
// capsule with each row's own radius, for rows in any order (repeated ones
// too), capsules in every direction, radii that miss the row and radii of
// zero.
TEST(SweepKernelsTest, RowNodeRangesAtMatchRowSpanWithEachRowsRadius) {
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> pos(-2, 12), rad(0.0, 3);
  int32_t rows_hit = 0, rows_missed = 0;
  for (int k = 0; k < 4000; ++k) {
    const Capsule c = TestCapsule(k, 3, rng, pos);
    const int32_t m = 1 + static_cast<int32_t>(rng() % 130);
    std::vector<int32_t> j(m), lo(m), hi(m);
    std::vector<double> radii(m);
    for (int32_t q = 0; q < m; ++q) {
      j[q] = static_cast<int32_t>(rng() % 240);  // rows -20 + j[q]
      radii[q] = q % 9 == 0 ? 0.0 : rad(rng);
    }
    RowNodeRangesAt(c, radii.data(), -20, j.data(), m, kY0, kDy, kX0, 1 / kDx,
                    kIMax, lo.data(), hi.data());
    for (int32_t q = 0; q < m; ++q) {
      Capsule narrow = c;
      narrow.radius = radii[q];
      ExpectRowSpanNodes(narrow, kY0 + (-20 + j[q]) * kDy, lo[q], hi[q],
                         &rows_hit, &rows_missed);
    }
  }
  EXPECT_GT(rows_hit, 10000);
  EXPECT_GT(rows_missed, 10000);
}

// FootprintRadii is FootprintRadius, bit for bit, at caps above, at and
// below the lowest ball centre and below the whole ball.
TEST(SweepKernelsTest, FootprintRadiiMatchFootprintRadius) {
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> cap(-10, 6);
  int32_t checked = 0;
  for (const BallSweep& s : RandomSweeps(200, 13)) {
    std::vector<double> caps(67), radii(caps.size());
    for (double& c : caps) c = cap(rng);
    caps[0] = s.lowest();
    caps[1] = s.lowest() + s.radius();  // the lowest centre
    s.FootprintRadii(caps.data(), static_cast<int32_t>(caps.size()),
                     radii.data());
    for (size_t q = 0; q < caps.size(); ++q) {
      const double want = s.FootprintRadius(caps[q]);
      EXPECT_EQ(std::memcmp(&radii[q], &want, sizeof want), 0)
          << "cap " << caps[q] << ": " << radii[q] << " against " << want;
      ++checked;
    }
  }
  EXPECT_EQ(checked, 200 * 67);
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

// Many moves' frames at once are each move's own, bit for bit.
TEST(SweepKernelsTest, MakeFramesMatchTheConstructor) {
  const std::vector<BallMove> moves = RandomMoves(1000, 13);
  const int32_t n = static_cast<int32_t>(moves.size());
  std::vector<Vec3> from, to;
  std::vector<double> radius;
  for (const BallMove& m : moves) {
    from.push_back(m.from);
    to.push_back(m.to);
    radius.push_back(m.radius);
  }
  // Counts that leave remainders in the kernel's blocks and vectors.
  for (const int32_t count : {n, int32_t{67}, int32_t{1}}) {
    // Written from frame 3 on, into a table with room to spare.
    const int32_t stride = count + 3 + BallSweep::kFramePadding;
    std::vector<double> data(BallSweep::kFrameValues * stride);
    const BallSweep::FrameTable table{data.data(), stride};
    std::vector<uint8_t> general(count);
    BallSweep::MakeFrames(count, from.data(), to.data(), radius.data(), table,
                          3, general.data());
    int generals = 0;
    for (int32_t q = 0; q < count; ++q) {
      const BallSweep s(from[q], to[q], radius[q]);
      ASSERT_EQ(general[q] != 0, s.general()) << "move " << q;
      generals += s.general();
      const BallSweep::Frame want = s.frame(), got = table.Get(3 + q);
      ASSERT_EQ(std::memcmp(&got, &want, sizeof want), 0) << "move " << q;
    }
    if (count == n) {
      EXPECT_GT(generals, n / 2);
    }
  }
}

// Rows whose nodes belong to different sweeps, and to none (NoFrame()):
// each lane is its sweep's JetAt, bit for bit, and zeros off every sweep.
TEST(SweepKernelsTest, JetsOfFramesMatchJetAt) {
  std::vector<BallSweep> sweeps;
  for (const BallSweep& s : RandomSweeps(400, 17)) {
    if (s.general()) sweeps.push_back(s);
  }
  const int32_t stride =
      static_cast<int32_t>(sweeps.size()) + 1 + BallSweep::kFramePadding;
  std::vector<double> data(BallSweep::kFrameValues * stride);
  const BallSweep::FrameTable table{data.data(), stride};
  table.Set(0, BallSweep::NoFrame());
  for (size_t k = 0; k < sweeps.size(); ++k) {
    table.Set(static_cast<int32_t>(k) + 1, sweeps[k].frame());
  }
  std::mt19937_64 rng(19);
  std::vector<double> xs, ys;
  int on_surface = 0, off = 0;
  for (double y = -8; y < 8; y += 0.11) {
    RowPoints(y, &xs, &ys);
    const int32_t n = static_cast<int32_t>(xs.size());
    // Runs of one sweep of 1 to 4 nodes, an uncut node now and then; the
    // sweeps of one row far apart in the table, or (as a tile's rows
    // number them) consecutive.
    std::vector<int32_t> frame_of(n);
    const bool consecutive = rng() % 2 == 0;
    int32_t next = 1 + rng() % (sweeps.size() - n);
    for (int32_t q = 0; q < n;) {
      const int32_t f = rng() % 9 == 0 ? 0
                        : consecutive  ? next++
                                       : 1 + rng() % sweeps.size();
      for (int32_t len = 1 + rng() % 4; len > 0 && q < n; --len) {
        frame_of[q++] = f;
      }
    }
    for (int32_t count : {n, int32_t{37}, int32_t{1}}) {
      std::vector<float> store(5 * count, 7.0f);
      float* d[5];
      for (int c = 0; c < 5; ++c) d[c] = store.data() + c * count;
      BallSweep::JetsOfFrames(table, frame_of.data(), xs.data(), y, count,
                              d);
      for (int32_t q = 0; q < count; ++q) {
        SurfaceJet j;  // zeros
        if (frame_of[q] > 0) j = sweeps[frame_of[q] - 1].JetAt(xs[q], y);
        const double want[5] = {j.wx, j.wy, j.wxx, j.wxy, j.wyy};
        for (int c = 0; c < 5; ++c) {
          ASSERT_TRUE(SameBits(d[c][q], static_cast<float>(want[c])))
              << "lane " << q << " component " << c << ": " << d[c][q]
              << " vs " << want[c];
        }
        const bool on = frame_of[q] > 0 && std::isfinite(j.w);
        on_surface += on;
        off += !on;
      }
    }
  }
  EXPECT_GT(on_surface, 1500);
  EXPECT_GT(off, 1500);
}

// Hypot is the C library's hypot where that is glibc 2.35 or later (the
// same algorithm), bit for bit; elsewhere within an ulp of it. Random bit
// patterns, inputs a few binades apart (the scaled and negligible regimes
// included), coordinate differences, and the special values.
TEST(SweepKernelsTest, HypotIsTheLibraryHypot) {
#if defined(__GLIBC__) && (__GLIBC__ > 2 || __GLIBC_MINOR__ >= 35)
  constexpr bool kSameAlgorithm = true;
#else
  constexpr bool kSameAlgorithm = false;
#endif
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> mantissa(1, 2), coord(-1e3, 1e3);
  std::uniform_int_distribution<int> exponent(-1074, 1023), apart(-60, 60);
  int checked = 0;
  auto check = [&](double x, double y) {
    const double mine = Hypot(x, y), libm = std::hypot(x, y);
    ++checked;
    if (std::isnan(libm)) {
      ASSERT_TRUE(std::isnan(mine)) << x << ", " << y;
    } else if (kSameAlgorithm) {
      ASSERT_TRUE(SameBits(mine, libm))
          << std::hexfloat << x << ", " << y << ": " << mine << " vs " << libm;
    } else {
      ASSERT_LE(std::fabs(mine - libm),
                std::nextafter(libm, std::numeric_limits<double>::infinity()) -
                    libm)
          << x << ", " << y;
    }
  };
  for (int k = 0; k < 300000; ++k) {
    uint64_t bits[2] = {rng(), rng()};
    double v[2];
    std::memcpy(v, bits, sizeof v);
    check(v[0], v[1]);
    const int e = exponent(rng);
    const double a = std::ldexp(mantissa(rng), e);
    const double b = std::ldexp(mantissa(rng),
                                std::clamp(e + apart(rng), -1074, 1023));
    check(k % 2 ? -a : a, b);
    check(coord(rng), coord(rng) * (k % 3 ? 1 : 1e-7));
  }
  const double inf = std::numeric_limits<double>::infinity();
  const double special[] = {0.0,     -0.0,    4.9e-324, 0x1p-1022, 0x1p-459,
                            0x1p-460, 1.0,     3.0,      4.0,       0x1p511,
                            0x1.0000000000001p511, 1.7976931348623157e308,
                            inf,     -inf,    std::numeric_limits<double>::quiet_NaN()};
  for (double x : special) {
    for (double y : special) check(x, y);
  }
  EXPECT_GT(checked, 900000);
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
