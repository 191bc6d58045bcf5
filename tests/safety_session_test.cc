// The safety checks as a session applies batches (issue 30): events with
// the batch's move index, hand-computed depths and volumes.
#include <cmath>
#include <memory>
#include <numbers>
#include <vector>

#include "gtest/gtest.h"
#include "server/session.h"

namespace swarf::server {
namespace {

constexpr double kPi = std::numbers::pi;

// 100 x 100 mm, top 0, nodes every 0.1 mm; tool 1 a 6 mm flat end mill
// with 10 mm of flutes, a 40 mm holder 30 mm above the tip, not cutting at
// its centre; tool 2 the same cutter with nothing known.
std::shared_ptr<Session> MakeSession() {
  SessionSpec spec;
  spec.id = "safety";
  spec.stock = StockSpec{0, 0, 100, 100, 0, 1000, 1000};
  spec.scheme = SchemeKind::kTaylor;
  ToolSpec t1{1, Cutter::Flat(3), {}};
  t1.assembly.flute_length = 10;
  t1.assembly.holder_diameter = 40;
  t1.assembly.stickout = 30;
  t1.assembly.center_cutting = false;
  spec.tools = {t1, ToolSpec{2, Cutter::Flat(3), {}}};
  auto s = Session::Create(spec);
  EXPECT_TRUE(s.ok()) << s.status();
  return *s;
}

BatchOptions Opts(bool reposition, bool rapid) {
  BatchOptions o;
  o.reposition = reposition;
  o.rapid = rapid;
  o.report_cuts = true;
  return o;
}

TEST(SafetySessionTest, RapidThroughTheBlockAtAKnownDepthAndVolume) {
  auto s = MakeSession();
  // Tool 2 (no assembly): a rapid 2 mm deep over 30 mm, its edges between
  // node rows: 2 * (30 * 6 + pi 9) mm^3.
  const std::vector<double> xyz = {10.05, 20.05, 5,  10.05, 20.05, 5,
                                   10.05, 20.05, -2, 40.05, 20.05, -2};
  // First move: the plunge into the top, rapid too.
  auto r = s->ApplyBatch(1, 2, xyz, 1 << 20, Opts(true, true));
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->removed_mm3.size(), 3u);
  EXPECT_EQ(r->removed_mm3[0], 0);
  ASSERT_EQ(r->safety.size(), 2u);  // the plunge and the straight
  const SafetyFinding& f = r->safety[1];
  EXPECT_EQ(f.kind, SafetyFinding::kRapidCut);
  EXPECT_EQ(f.move_index, 2);
  EXPECT_EQ(f.move_id, 2);
  EXPECT_DOUBLE_EQ(f.depth, 2);
  EXPECT_DOUBLE_EQ(f.z, -2);
  // The plunge took the disc at the start (2 * pi 9), the straight the rest
  // of the slot 2 * (30 * 6 + pi 9): 360 mm^3.
  EXPECT_NEAR(r->safety[0].volume_mm3, 2 * kPi * 9, 0.01 * 2 * kPi * 9);
  EXPECT_NEAR(f.volume_mm3, 360, 0.005 * 360);
  EXPECT_NEAR(r->safety[0].volume_mm3 + f.volume_mm3, 2 * (30 * 6 + kPi * 9),
              0.005 * 2 * (30 * 6 + kPi * 9));
  EXPECT_EQ(f.volume_mm3, r->removed_mm3[2]);
  // The same moves as feeds (a new session): no event, the same volume.
  auto s2 = MakeSession();
  auto r2 = s2->ApplyBatch(1, 2, xyz, 1 << 20, Opts(true, false));
  ASSERT_TRUE(r2.ok());
  EXPECT_TRUE(r2->safety.empty());
  EXPECT_EQ(r2->removed_mm3[2], r->removed_mm3[2]);
}

// A rapid straight up from where a ball's cut ended removes nothing: its
// start sphere is the cut's end sphere, whose heights it may reproduce a
// few ulps lower (1.6e-15 mm at one node of this job, found on a 1000 mm
// stock). Rounding is not a rapid through material.
TEST(SafetySessionTest, RetractFromACutsEndIsNoRapidCut) {
  SessionSpec spec;
  spec.id = "retract";
  spec.stock = StockSpec{0, 0, 1000, 1000, 0, 20000, 20000};
  spec.scheme = SchemeKind::kGuarded;
  spec.tools = {ToolSpec{0, Cutter::Ball(2), {}}};
  auto s = Session::Create(spec);
  ASSERT_TRUE(s.ok()) << s.status();
  const std::vector<double> cut = {500, 500, 5, 500, 500, -1, 600, 520, -1};
  auto fed = (*s)->ApplyBatch(1, 0, cut, 1 << 20, Opts(true, false));
  ASSERT_TRUE(fed.ok()) << fed.status();
  const std::vector<double> retract = {600, 520, -1, 600, 520, 5};
  auto r = (*s)->ApplyBatch(2, 0, retract, 1 << 20, Opts(true, true));
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->removed_mm3.size(), 1u);  // the first point places it
  EXPECT_LT(r->removed_mm3[0], 1e-12);  // what rounding leaves, if any
  for (const SafetyFinding& f : r->safety) {
    ADD_FAILURE() << "finding of kind " << f.kind << ", depth " << f.depth;
  }
}

TEST(SafetySessionTest, SlotDeeperThanTheFlutesHolderAndPlunge) {
  auto s = MakeSession();
  // Tool 1 (flutes 10, holder 40 at 30, not centre cutting): a plunge at
  // (50, 50.05) to -12, then a slot along x at -12: both cut 2 mm deeper
  // than the flutes.
  const std::vector<double> xyz = {50.05, 50.05, 5,  50.05, 50.05, -12,
                                   80.05, 50.05, -12};
  auto r = s->ApplyBatch(1, 1, xyz, 1 << 20, Opts(true, false));
  ASSERT_TRUE(r.ok()) << r.status();
  int plunges = 0, shanks = 0, holders = 0;
  for (const SafetyFinding& f : r->safety) {
    if (f.kind == SafetyFinding::kPlunge) {
      ++plunges;
      EXPECT_EQ(f.move_index, 0);
      EXPECT_DOUBLE_EQ(f.depth, 12);
    } else if (f.kind == SafetyFinding::kShankContact) {
      ++shanks;
      EXPECT_DOUBLE_EQ(f.depth, 2);
      // 2 mm of each lowering, over the move's whole cut area.
      EXPECT_NEAR(f.volume_mm3, r->removed_mm3[f.move_index] / 12 * 2, 1e-6);
    } else if (f.kind == SafetyFinding::kHolderContact) {
      ++holders;
    }
  }
  EXPECT_EQ(plunges, 1);
  EXPECT_EQ(shanks, 2);
  EXPECT_EQ(holders, 0);  // the holder's face stays 18 mm above the top

  // 35 mm deep: the holder's face 5 mm into the top all around the hole.
  const std::vector<double> deep = {20.05, 20.05, 5, 20.05, 20.05, -35};
  auto d = s->ApplyBatch(2, 1, deep, 1 << 20, Opts(true, false));
  ASSERT_TRUE(d.ok()) << d.status();
  bool holder = false;
  for (const SafetyFinding& f : d->safety) {
    if (f.kind != SafetyFinding::kHolderContact) continue;
    holder = true;
    EXPECT_DOUBLE_EQ(f.depth, 5);
    EXPECT_EQ(f.move_index, 0);
  }
  EXPECT_TRUE(holder);
}

TEST(SafetySessionTest, FinishingPassesWithinTheFlutesRaiseNothing) {
  auto s = MakeSession();
  // A raster 1 mm deep (within the 10 mm flutes), fed: no event.
  std::vector<double> xyz = {5, 5, 5};
  for (int k = 0; k < 40; ++k) {
    const double y = 5 + 2 * k;
    xyz.insert(xyz.end(), {5, y, -1, 95, y, -1, 95, y + 2, -1});
  }
  auto r = s->ApplyBatch(1, 2, xyz, 1 << 20, Opts(true, false));
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r->safety.empty());
  BatchOptions o = Opts(false, false);
  std::vector<double> again;
  for (int k = 0; k < 40; ++k) {
    const double y = 85 - 2 * k;
    again.insert(again.end(), {5, y, -1.5, 95, y, -1.5});
  }
  auto r2 = s->ApplyBatch(2, 1, again, 1 << 20, o);
  ASSERT_TRUE(r2.ok());
  for (const SafetyFinding& f : r2->safety) {
    ADD_FAILURE() << "kind " << f.kind << " move " << f.move_index;
  }
}

TEST(SafetySessionTest, AMillionFinishingMovesRaiseNothing) {
  // A ball (1 mm radius, 5 mm flutes, a 20 mm holder 20 mm out) finishing
  // a wavy surface up to 1.5 mm deep in 1,000,000 moves of 0.1 mm
  // (zig-zag, 0.1 mm stepover): nothing it cuts with its flutes is a
  // contact, and the holder stays above the top.
  SessionSpec spec;
  spec.id = "million";
  spec.stock = StockSpec{0, 0, 100, 100, 0, 1000, 1000};
  spec.scheme = SchemeKind::kTaylor;
  ToolSpec ball{1, Cutter::Ball(1), {}};
  ball.assembly.flute_length = 5;
  ball.assembly.holder_diameter = 20;
  ball.assembly.stickout = 20;
  spec.tools = {ball};
  auto s = Session::Create(spec);
  ASSERT_TRUE(s.ok()) << s.status();
  auto z = [](double x, double y) {
    return -1 + 0.5 * std::sin(x / 7) * std::cos(y / 5);
  };
  std::vector<double> xyz;
  uint64_t seq = 0;
  int64_t moves = 0, events = 0;
  double removed = 0;
  bool first = true;
  for (int row = 0; row < 1000; ++row) {
    const double y = 0.05 + 0.1 * row;
    for (int k = 0; k <= 1000; ++k) {
      if (k == 0 && row > 0) continue;  // the row's start ended the last
      const double x = (row % 2 == 0) ? 0.1 * k : 100 - 0.1 * k;
      xyz.insert(xyz.end(), {x, y, z(x, y)});
      if (xyz.size() == 3 * 20000) {
        auto r = (*s)->ApplyBatch(++seq, 1, xyz, 1 << 20, Opts(first, false));
        ASSERT_TRUE(r.ok()) << r.status();
        first = false;
        events += static_cast<int64_t>(r->safety.size());
        for (double v : r->removed_mm3) removed += v;
        moves = r->moves_applied;
        xyz.clear();
      }
    }
    // Each row's end steps over to the next row's start.
    const double x_end = (row % 2 == 0) ? 100 : 0;
    xyz.insert(xyz.end(), {x_end, y + 0.1, z(x_end, y + 0.1)});
  }
  if (!xyz.empty()) {
    auto r = (*s)->ApplyBatch(++seq, 1, xyz, 1 << 20, Opts(false, false));
    ASSERT_TRUE(r.ok()) << r.status();
    events += static_cast<int64_t>(r->safety.size());
    for (double v : r->removed_mm3) removed += v;
    moves = r->moves_applied;
  }
  EXPECT_GE(moves, 1000000);
  EXPECT_EQ(events, 0);
  // The volumes add up to the stock's volume minus the nodes'.
  const double by_nodes = (*s)->Read([](const Workpiece& wp) {
    double sum = 0;
    for (int32_t j = 0; j <= wp.grid().ny(); ++j) {
      for (int32_t i = 0; i <= wp.grid().nx(); ++i) {
        sum += wp.spec().z_top - wp.HeightAt(i, j);
      }
    }
    return sum * wp.grid().dx() * wp.grid().dy();
  });
  EXPECT_NEAR(removed, by_nodes, 1e-9 * by_nodes);
}

}  // namespace
}  // namespace swarf::server
