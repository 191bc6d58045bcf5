// What a move cuts (Workpiece::Apply with ApplyOptions::cuts) and what the
// tool's non-cutting parts meet (CylinderContact), against hand-computed
// answers.
#include "core/safety.h"

#include <cmath>
#include <memory>
#include <numbers>
#include <vector>

#include "core/workpiece.h"
#include "gtest/gtest.h"

namespace swarf {
namespace {

constexpr double kPi = std::numbers::pi;

// 100 x 100 mm, top 0, nodes every 0.1 mm.
std::unique_ptr<Workpiece> Block(SchemeKind scheme = SchemeKind::kTaylor) {
  auto wp = Workpiece::Create(StockSpec{0, 0, 100, 100, 0, 1000, 1000}, scheme);
  EXPECT_TRUE(wp.ok()) << wp.status();
  return std::move(*wp);
}

// The stock's volume minus the nodes' (each standing for dx * dy).
double RemovedByNodes(const Workpiece& wp) {
  double sum = 0;
  for (int32_t j = 0; j <= wp.grid().ny(); ++j) {
    for (int32_t i = 0; i <= wp.grid().nx(); ++i) {
      sum += wp.spec().z_top - wp.HeightAt(i, j);
    }
  }
  return sum * wp.grid().dx() * wp.grid().dy();
}

TEST(MoveCutTest, SlotThroughBlockHasItsAnalyticVolumeAndDepth) {
  auto wp = Block();
  // A flat 6 mm end mill 2 mm deep, 30 mm long: 2 * (30 * 6 + pi 3^2). Its
  // edges lie between node rows (a node on an edge would count whole).
  const std::vector<Move> moves = {
      Move({10.05, 20.05, -2}, {40.05, 20.05, -2}, Cutter::Flat(3))};
  ApplyOptions opts;
  opts.cuts = true;
  auto r = wp->Apply(moves, opts);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->cuts.size(), 1u);
  const MoveCut& c = r->cuts[0];
  const double analytic = 2 * (30 * 6 + kPi * 9);
  EXPECT_NEAR(c.removed_mm3, analytic, 0.005 * analytic);
  EXPECT_NEAR(c.removed_mm3, RemovedByNodes(*wp), 1e-9 * analytic);
  EXPECT_DOUBLE_EQ(c.max_drop, 2);
  EXPECT_DOUBLE_EQ(c.z, -2);
  EXPECT_EQ(c.over_limit_mm3, 0);
}

TEST(MoveCutTest, PlungeHasItsAnalyticVolume) {
  auto wp = Block();
  const std::vector<Move> moves = {
      Move({50, 50, 5}, {50, 50, -10}, Cutter::Flat(3))};
  ApplyOptions opts;
  opts.cuts = true;
  auto r = wp->Apply(moves, opts);
  ASSERT_TRUE(r.ok()) << r.status();
  const double analytic = 10 * kPi * 9;
  EXPECT_NEAR(r->cuts[0].removed_mm3, analytic, 0.01 * analytic);
  EXPECT_NEAR(r->cuts[0].removed_mm3, RemovedByNodes(*wp), 1e-9 * analytic);
}

TEST(MoveCutTest, SecondPassRemovesOnlyWhatIsLeftAndDropLimitCountsExcess) {
  auto wp = Block();
  // Pass 1 at -1, pass 2 at -3 in the same batch: pass 2 drops 2 mm; with a
  // flute length of 1.5 the excess is 0.5 mm over pass 2's whole area.
  const std::vector<Move> moves = {
      Move({10, 20, -1}, {40, 20, -1}, Cutter::Flat(3)),
      Move({10, 20, -3}, {40, 20, -3}, Cutter::Flat(3))};
  const std::vector<double> limits = {1.5, 1.5};
  ApplyOptions opts;
  opts.cuts = true;
  opts.drop_limit = limits;
  auto r = wp->Apply(moves, opts);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->cuts.size(), 2u);
  EXPECT_DOUBLE_EQ(r->cuts[0].max_drop, 1);
  EXPECT_EQ(r->cuts[0].over_limit_mm3, 0);
  EXPECT_DOUBLE_EQ(r->cuts[1].max_drop, 2);
  EXPECT_NEAR(r->cuts[1].removed_mm3, 2 * r->cuts[0].removed_mm3, 1e-9);
  EXPECT_NEAR(r->cuts[1].over_limit_mm3, 0.25 * r->cuts[1].removed_mm3, 1e-9);
  EXPECT_NEAR(r->cuts[0].removed_mm3 + r->cuts[1].removed_mm3,
              RemovedByNodes(*wp), 1e-9);
}

TEST(MoveCutTest, AMoveAboveTheStockCutsNothing) {
  auto wp = Block();
  const std::vector<Move> moves = {
      Move({10, 20, 5}, {90, 80, 5}, Cutter::Ball(3))};
  ApplyOptions opts;
  opts.cuts = true;
  auto r = wp->Apply(moves, opts);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->cuts[0].removed_mm3, 0);
  EXPECT_EQ(r->cuts[0].max_drop, 0);
  EXPECT_EQ(r->cuts[0].i, -1);
}

TEST(MoveCutTest, NodesBitIdenticalWithAndWithoutCuts) {
  for (SchemeKind scheme : {SchemeKind::kTaylor, SchemeKind::kZmap}) {
    auto a = Block(scheme), b = Block(scheme);
    std::vector<Move> moves;
    for (int k = 0; k < 200; ++k) {
      const double y = 10 + 0.4 * k;
      moves.emplace_back(Vec3{5, y, -1 - 0.01 * k}, Vec3{95, y + 0.2, -0.5},
                         Cutter::Ball(2));
    }
    ASSERT_TRUE(a->Apply(moves).ok());
    ApplyOptions opts;
    opts.cuts = true;
    ASSERT_TRUE(b->Apply(moves, opts).ok());
    for (int32_t j = 0; j <= 1000; j += 3) {
      for (int32_t i = 0; i <= 1000; i += 3) {
        ASSERT_EQ(a->HeightAt(i, j), b->HeightAt(i, j));
        ASSERT_EQ(a->OwnerAt(i, j), b->OwnerAt(i, j));
      }
    }
  }
}

TEST(MoveCutTest, DropLimitOfWrongSizeIsRefused) {
  auto wp = Block();
  const std::vector<Move> moves = {
      Move({10, 20, -1}, {40, 20, -1}, Cutter::Flat(3))};
  const std::vector<double> limits = {1, 2};
  ApplyOptions opts;
  opts.drop_limit = limits;
  EXPECT_EQ(wp->Apply(moves, opts).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(CylinderContactTest, HolderOverStockAtKnownDepthAndVolume) {
  auto wp = Block();
  // A 6 mm hole 35 deep; the holder (40 mm, stick-out 30) then stands 5 mm
  // into the top all around it.
  const std::vector<Move> moves = {
      Move({50, 50, 5}, {50, 50, -35}, Cutter::Flat(3))};
  ASSERT_TRUE(wp->Apply(moves).ok());
  const Contact c = CylinderContact(*wp, {50, 50, 5}, {50, 50, -35}, 20, 30);
  ASSERT_TRUE(c.hit);
  EXPECT_DOUBLE_EQ(c.depth, 5);
  EXPECT_DOUBLE_EQ(c.z, 0);
  const double analytic = 5 * kPi * (400 - 9);
  EXPECT_NEAR(c.volume_mm3, analytic, 0.005 * analytic);
  // 4 mm shallower, no contact.
  EXPECT_FALSE(CylinderContact(*wp, {50, 50, 5}, {50, 50, -29.9}, 20, 30).hit);
}

TEST(CylinderContactTest, SlopedMoveUsesTheLowestBottomOverEachNode) {
  auto wp = Block();
  // A wall: nodes x <= 30 stay at the top 0; x > 30 is cut to -20.
  std::vector<Move> moves;
  for (double y = 0; y <= 100; y += 5) {
    moves.emplace_back(Vec3{36, y, -20}, Vec3{100, y, -20}, Cutter::Flat(6));
  }
  ASSERT_TRUE(wp->Apply(moves).ok());
  // The tip ramps from z -10 at x 60 to -18 at x 40 (y 50); a 22 mm holder
  // (radius 11) from 10 above the tip reaches x 29 at the end: the wall's
  // nodes at x 29..30 under a bottom of -8 stand 8 mm into it.
  const Contact c = CylinderContact(*wp, {60, 50, -10}, {40, 50, -18}, 11, 10);
  ASSERT_TRUE(c.hit);
  EXPECT_NEAR(c.depth, 8, 1e-9);
  EXPECT_LE(c.x, 30 + 1e-9);
  EXPECT_LE(std::fabs(c.y - 50), std::sqrt(11.0 * 11 - 10 * 10) + 1e-9);
}

}  // namespace
}  // namespace swarf
