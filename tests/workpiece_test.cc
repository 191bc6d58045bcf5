// Workpiece: nodes against a brute force over all moves, independence of
// order and batching, lazy tiles and versions, and rejection of bad batches.
#include "core/workpiece.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <numeric>
#include <random>
#include <set>
#include <span>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/flag_words.h"
#include "core/thread_pool.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/state_v1.h"

namespace swarf {
namespace {

using ::testing::HasSubstr;

constexpr SchemeKind kSchemes[] = {SchemeKind::kZmap, SchemeKind::kTaylor};

std::string SchemeName(SchemeKind s) {
  return std::string(GetScheme(s).name());
}

// 98 x 72 nodes: a 2 x 2 tile grid with partial tiles on both axes.
StockSpec MixedStock() { return StockSpec{0, 0, 40, 30, 10, 97, 71}; }

std::unique_ptr<Workpiece> MakeWorkpiece(const StockSpec& spec,
                                         SchemeKind scheme,
                                         ThreadPool* pool = nullptr) {
  auto wp = Workpiece::Create(spec, scheme, pool);
  EXPECT_TRUE(wp.ok()) << wp.status();
  return *std::move(wp);
}

bool SameMove(const Move& a, const Move& b) {
  return std::memcmp(&a, &b, sizeof(Move)) == 0;
}

// A few hundred moves of every kind over MixedStock(): plunges, retracts,
// sloped, horizontal and zero-length moves, moves above the stock (one
// exactly touching its top) or beside it, and exact duplicates (exact ties).
std::vector<Move> MixedMoves(uint64_t seed, int count) {
  const StockSpec s = MixedStock();
  const double top = s.z_top;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ux(s.x0 - 3, s.x1 + 3),
      uy(s.y0 - 3, s.y1 + 3), unit(0, 1), rad(0.4, 3);
  std::vector<Move> moves;
  for (int k = 0; k < count; ++k) {
    const double r = rad(rng);
    const double x = ux(rng), y = uy(rng);
    Move m;
    m.cutter.radius = r;
    switch (k % 9) {
      case 0:  // plunge
        m = {{x, y, top + 5 * unit(rng)}, {x, y, top - 0.1 - 4 * unit(rng)}, r};
        break;
      case 1:  // retract
        m = {{x, y, top - 4 * unit(rng)}, {x, y, top + 2 * unit(rng)}, r};
        break;
      case 2:  // sloped
        m = {{x, y, top - 5 * unit(rng) + 1},
             {ux(rng), uy(rng), top - 5 * unit(rng) + 1}, r};
        break;
      case 3: {  // horizontal
        const double z = top - 3 * unit(rng);
        m = {{x, y, z}, {x + 20 * (unit(rng) - 0.5), y + 20 * (unit(rng) - 0.5), z}, r};
        break;
      }
      case 4: {  // zero length
        const Vec3 p{x, y, top - 2 * unit(rng)};
        m = {p, p, r};
        break;
      }
      case 5:  // above the stock; every 4th one touches the top exactly
        m = {{x, y, (k % 4 == 1) ? top : top + 3 * unit(rng)},
             {ux(rng), uy(rng), top + 3 * unit(rng)}, r};
        break;
      case 6:  // beside the stock, deep
        m = {{s.x1 + r + 0.5 + 5 * unit(rng), y, top - 3},
             {s.x1 + r + 0.5 + 5 * unit(rng), uy(rng), top - 2}, r};
        break;
      default:  // exact duplicates of earlier moves
        m = moves.empty() ? Move{{x, y, top - 1}, {x, y, top - 1}, r}
                          : moves[static_cast<size_t>(unit(rng) * moves.size())];
        break;
    }
    moves.push_back(m);
  }
  return moves;
}

std::vector<NodeValue> Snapshot(const Workpiece& wp) {
  std::vector<NodeValue> out;
  for (int32_t j = 0; j < wp.grid().nodes_y(); ++j) {
    for (int32_t i = 0; i < wp.grid().nodes_x(); ++i) {
      out.push_back(wp.Node(i, j));
    }
  }
  return out;
}

bool SameJet(const SurfaceJet& a, const SurfaceJet& b) {
  return std::memcmp(&a, &b, sizeof(SurfaceJet)) == 0;
}

int32_t TileOfNode(const Workpiece& wp, int32_t i, int32_t j) {
  return (j / kTileSize) * wp.tiles_x() + i / kTileSize;
}

// Applies moves[order[0]], moves[order[1]], ... in batches of the given
// sizes (the last batch takes the rest).
std::unique_ptr<Workpiece> ApplyInBatches(const std::vector<Move>& moves,
                                          const std::vector<int>& order,
                                          const std::vector<int>& sizes,
                                          SchemeKind scheme, ThreadPool* pool) {
  auto wp = MakeWorkpiece(MixedStock(), scheme, pool);
  size_t next = 0;
  for (size_t b = 0; next < order.size(); ++b) {
    const size_t n = b < sizes.size() ? std::min<size_t>(sizes[b], order.size() - next)
                                      : order.size() - next;
    std::vector<Move> batch;
    for (size_t k = 0; k < n; ++k) batch.push_back(moves[order[next + k]]);
    auto res = wp->Apply(batch);
    EXPECT_TRUE(res.ok()) << res.status();
    EXPECT_EQ(res->first_move_id, static_cast<int64_t>(next));
    EXPECT_EQ(res->moves, static_cast<int64_t>(n));
    next += n;
  }
  EXPECT_EQ(wp->move_count(), static_cast<int64_t>(moves.size()));
  return wp;
}

// The lowest of `top` and every sweep at (x, y), and the lowest id giving
// it (-1: the top).
template <class S>
std::pair<double, int32_t> LowestSweep(const std::vector<S>& sweeps, double top,
                                       double x, double y) {
  double w = top;
  int32_t owner = -1;
  for (size_t m = 0; m < sweeps.size(); ++m) {
    const double h = sweeps[m].Height(x, y);
    if (h < w) {
      w = h;
      owner = static_cast<int32_t>(m);
    }
  }
  return {w, owner};
}

// Every node is the lowest of the stock top and every sweep at that node;
// the owner is the lowest id reaching it; taylor nodes hold the owner's
// derivatives in float.
TEST(WorkpieceTest, NodesAreTheLowestSweep) {
  const std::vector<Move> moves = MixedMoves(1, 300);
  std::vector<BallSweep> sweeps;
  for (const Move& m : moves) sweeps.emplace_back(m.from, m.to, m.cutter.radius);
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto wp = MakeWorkpiece(MixedStock(), scheme);
    ASSERT_TRUE(wp->Apply(moves).ok());
    const GridGeometry& g = wp->grid();
    int cut = 0;
    for (int32_t j = 0; j < g.nodes_y(); ++j) {
      for (int32_t i = 0; i < g.nodes_x(); ++i) {
        const double x = g.NodeX(i), y = g.NodeY(j);
        const auto [w, owner] = LowestSweep(sweeps, MixedStock().z_top, x, y);
        const NodeValue v = wp->Node(i, j);
        ASSERT_EQ(v.jet.w, w) << "node " << i << "," << j;
        ASSERT_EQ(v.owner, owner) << "node " << i << "," << j;
        SurfaceJet want;  // untouched or zmap: derivatives zero
        want.w = w;
        if (owner >= 0 && wp->scheme().stores_derivatives()) {
          const SurfaceJet jet = sweeps[owner].Jet(sweeps[owner].Locate(x, y));
          want.wx = static_cast<float>(jet.wx);
          want.wy = static_cast<float>(jet.wy);
          want.wxx = static_cast<float>(jet.wxx);
          want.wxy = static_cast<float>(jet.wxy);
          want.wyy = static_cast<float>(jet.wyy);
        }
        ASSERT_TRUE(SameJet(v.jet, want)) << "node " << i << "," << j;
        cut += owner >= 0;
      }
    }
    EXPECT_GT(cut, 1000);  // the mix really cuts
  }
}

// A finishing raster of short moves over a wavy floor, after a facing pass
// and with a second raster across it, in batches of several sizes, on a
// fine grid (a ball's row spans 60 nodes long): the rows a pass has cut lie
// below the tile's highest node, where a move's row is skipped or its ball
// footprint narrowed to the span's highest node. Every node is still the
// lowest sweep and its owner the lowest id there, for balls and for the
// other shapes (whose rows are only skipped).
TEST(WorkpieceTest, RasterRowsAreTheLowestSweep) {
  // 241 x 181 nodes, 0.05 mm apart: 4 x 3 tiles, the last ones partial.
  const StockSpec spec{0, 0, 12, 9, 10, 240, 180};
  auto floor = [](double x, double y) {
    return 8.6 + 0.5 * std::sin(x / 2) * std::cos(y / 3);
  };
  for (const Cutter& cutter :
       {Cutter::Ball(1.5), Cutter::BullNose(1.5, 0.5), Cutter::Flat(1.0)}) {
    std::vector<Move> moves;
    moves.push_back({{-2, 4.5, 9.5}, {14, 4.5, 9.5}, Cutter::Flat(8)});
    for (double y = -1; y <= 10; y += 0.3) {  // along x
      for (double x = -2; x < 14; x += 0.4) {
        moves.push_back(
            {{x, y, floor(x, y)}, {x + 0.4, y, floor(x + 0.4, y)}, cutter});
      }
    }
    for (double x = -1; x <= 13; x += 1.3) {  // along y, shallower
      for (double y = -2; y < 11; y += 0.5) {
        moves.push_back({{x, y, floor(x, y) + 0.01},
                         {x, y + 0.5, floor(x, y + 0.5) + 0.01},
                         cutter});
      }
    }
    std::vector<Sweep> sweeps;
    for (const Move& m : moves) sweeps.emplace_back(m.from, m.to, m.cutter);
    const GridGeometry grid(spec);
    std::vector<double> want_w;
    std::vector<int32_t> want_owner;
    int64_t raster_owned = 0;
    for (int32_t j = 0; j < grid.nodes_y(); ++j) {
      for (int32_t i = 0; i < grid.nodes_x(); ++i) {
        const double x = grid.NodeX(i), y = grid.NodeY(j);
        const auto [w, owner] = LowestSweep(sweeps, spec.z_top, x, y);
        want_w.push_back(w);
        want_owner.push_back(owner);
        raster_owned += owner > 0;
      }
    }
    // The raster, not the facing, set nearly every node.
    EXPECT_GT(raster_owned, int64_t{grid.nodes_x()} * grid.nodes_y() * 9 / 10);
    for (const size_t batch : {size_t{1}, size_t{57}, moves.size()}) {
      SCOPED_TRACE(absl::StrCat("cutter kind ", static_cast<int>(cutter.kind),
                                ", batches of ", batch));
      auto wp = MakeWorkpiece(spec, SchemeKind::kTaylor);
      for (size_t k = 0; k < moves.size(); k += batch) {
        const size_t n = std::min(batch, moves.size() - k);
        ASSERT_TRUE(wp->Apply(std::span<const Move>(moves.data() + k, n)).ok());
      }
      size_t at = 0;
      for (int32_t j = 0; j < grid.nodes_y(); ++j) {
        for (int32_t i = 0; i < grid.nodes_x(); ++i, ++at) {
          const NodeValue v = wp->Node(i, j);
          ASSERT_EQ(v.jet.w, want_w[at]) << "node " << i << "," << j;
          ASSERT_EQ(v.owner, want_owner[at]) << "node " << i << "," << j;
        }
      }
    }
  }
}

// The state is a function of the set of moves: one batch, reversed one by
// one, shuffled in random batches and in-order random batches all give
// bit-identical nodes. Owners are compared as moves (the id differs with the
// order); an exact duplicate maps to its first copy.
TEST(WorkpieceTest, OrderAndBatchIndependent) {
  const std::vector<Move> moves = MixedMoves(2, 320);
  const int n = static_cast<int>(moves.size());
  std::vector<int> canon(n);
  int duplicates = 0;
  for (int k = 0; k < n; ++k) {
    canon[k] = k;
    for (int e = 0; e < k; ++e) {
      if (SameMove(moves[e], moves[k])) {
        canon[k] = e;
        ++duplicates;
        break;
      }
    }
  }
  ASSERT_GT(duplicates, 20);
  std::vector<int> in_order(n);
  std::iota(in_order.begin(), in_order.end(), 0);
  std::vector<int> reversed(in_order.rbegin(), in_order.rend());
  std::vector<int> shuffled = in_order;
  std::mt19937_64 rng(3);
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  std::vector<int> random_sizes;
  for (int total = 0; total < n;) {
    random_sizes.push_back(1 + static_cast<int>(rng() % 40));
    total += random_sizes.back();
  }
  ThreadPool pool(3);
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto one_batch = ApplyInBatches(moves, in_order, {n}, scheme, &pool);
    const std::vector<NodeValue> want = Snapshot(*one_batch);
    struct Run {
      std::string name;
      const std::vector<int>* order;
      std::vector<int> sizes;
      ThreadPool* pool;
    };
    const std::vector<Run> runs = {
        {"reversed one by one", &reversed, std::vector<int>(n, 1), &pool},
        {"shuffled random batches", &shuffled, random_sizes, &pool},
        {"in order random batches", &in_order, random_sizes, &pool},
        {"shuffled one batch, default pool", &shuffled, {n}, nullptr},
    };
    for (const Run& run : runs) {
      SCOPED_TRACE(run.name);
      auto wp = ApplyInBatches(moves, *run.order, run.sizes, scheme, run.pool);
      const std::vector<NodeValue> got = Snapshot(*wp);
      ASSERT_EQ(got.size(), want.size());
      int mismatches = 0;
      for (size_t k = 0; k < got.size(); ++k) {
        const bool same_owner =
            (got[k].owner < 0 && want[k].owner < 0) ||
            (got[k].owner >= 0 && want[k].owner >= 0 &&
             canon[(*run.order)[got[k].owner]] == canon[want[k].owner]);
        if (!SameJet(got[k].jet, want[k].jet) || !same_owner) {
          if (++mismatches <= 5) {
            ADD_FAILURE() << "node " << k % wp->grid().nodes_x() << ","
                          << k / wp->grid().nodes_x() << " w " << got[k].jet.w
                          << " vs " << want[k].jet.w << " owner "
                          << got[k].owner << " vs " << want[k].owner;
          }
        }
        // In the original order ids coincide: owners must be equal.
        if (run.order == &in_order) {
          EXPECT_EQ(got[k].owner, want[k].owner);
        }
      }
      EXPECT_EQ(mismatches, 0);
      for (int32_t t = 0; t < wp->tile_count(); ++t) {
        EXPECT_EQ(wp->TileAllocated(t), one_batch->TileAllocated(t));
      }
    }
  }
}

// Exact ties: the same move applied twice keeps the lower id as owner,
// whether the copies share a batch or not, and a batch that changes nothing
// leaves versions alone.
// CutTile lowers only the nodes ForEachFlagged visits: each set flag once,
// in order, at every length and density (words of 8, partial words).
TEST(FlagWordsTest, VisitsEachSetFlagInOrder) {
  std::mt19937 rng(7);
  for (int32_t n : {0, 1, 7, 8, 9, 63, 64, 65, 256}) {
    for (double density : {0.0, 0.05, 0.5, 1.0}) {
      std::vector<uint8_t> flag(FlagBytes(n), 0xff);
      std::vector<int32_t> want;
      std::bernoulli_distribution set(density);
      for (int32_t q = 0; q < n; ++q) {
        flag[q] = set(rng) ? 1 : 0;
        if (flag[q] != 0) want.push_back(q);
      }
      ClearFlagTail(flag.data(), n);
      std::vector<int32_t> got;
      ForEachFlagged(flag.data(), n, [&](int32_t q) { got.push_back(q); });
      EXPECT_EQ(got, want) << "n " << n << ", density " << density;
    }
  }
}

TEST(WorkpieceTest, ExactTieKeepsLowerId) {
  const Move groove{{2, 3, 8.5}, {30, 20, 9}, 2};
  const Move other{{35, 5, 9.5}, {35, 5, 9.5}, 1};
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto wp = MakeWorkpiece(MixedStock(), scheme);
    ASSERT_TRUE(wp->Apply(std::vector<Move>{groove, groove}).ok());
    const std::vector<NodeValue> after_first = Snapshot(*wp);
    const uint64_t version = wp->version();
    EXPECT_EQ(version, 1u);
    auto res = wp->Apply(std::vector<Move>{other, groove});
    ASSERT_TRUE(res.ok());
    int groove_nodes = 0;
    const std::vector<NodeValue> after = Snapshot(*wp);
    for (size_t k = 0; k < after.size(); ++k) {
      if (after_first[k].owner == 0) {
        ++groove_nodes;
        EXPECT_EQ(after[k].owner, 0) << "node " << k;  // not 1, not 3
        EXPECT_TRUE(SameJet(after[k].jet, after_first[k].jet));
      }
      EXPECT_NE(after[k].owner, 1);
      EXPECT_NE(after[k].owner, 3);
    }
    EXPECT_GT(groove_nodes, 100);
    // A batch of nothing but a repeat lowers nothing.
    const uint64_t v2 = wp->version();
    auto again = wp->Apply(std::vector<Move>{groove});
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(again->node_lowerings, 0);
    EXPECT_TRUE(again->changed_tiles.empty());
    EXPECT_EQ(again->version, v2);
    EXPECT_EQ(wp->version(), v2);
    EXPECT_EQ(wp->move_count(), 5);
  }
}

// 256 x 256 nodes: 4 x 4 full tiles, unit spacing, node (i, j) at (i, j).
StockSpec UnitStock() { return StockSpec{0, 0, 255, 255, 0, 255, 255}; }

TEST(WorkpieceTilesTest, SmallCornerCutAllocatesOnlyItsTile) {
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto wp = MakeWorkpiece(UnitStock(), scheme);
    ASSERT_EQ(wp->tile_count(), 16);
    EXPECT_EQ(wp->allocated_tiles(), 0);
    EXPECT_EQ(wp->allocated_node_bytes(), 0);
    auto res = wp->Apply(std::vector<Move>{{{3, 4, 1}, {3, 4, -1}, 2}});
    ASSERT_TRUE(res.ok());
    EXPECT_EQ(res->changed_tiles, std::vector<int32_t>{0});
    EXPECT_EQ(wp->allocated_tiles(), 1);
    EXPECT_TRUE(wp->TileAllocated(0));
    EXPECT_EQ(wp->allocated_node_bytes(),
              int64_t{kTileNodes} * wp->scheme().bytes_per_node());
    for (int32_t t = 1; t < 16; ++t) {
      EXPECT_FALSE(wp->TileAllocated(t)) << t;
      EXPECT_EQ(wp->TileVersion(t), 0u) << t;
    }
    EXPECT_EQ(wp->TileVersion(0), 1u);
    EXPECT_EQ(wp->Node(3, 4).jet.w, -1);
    EXPECT_EQ(wp->Node(3, 4).owner, 0);
  }
}

// ReadTileHeights gives ReadTile's heights of the rows asked for, bit for
// bit, at the caller's stride, and writes nothing between the rows; an
// unallocated tile's rows are the top.
TEST(WorkpieceTilesTest, TileRowHeightsAreReadTilesRows) {
  auto wp = MakeWorkpiece(UnitStock(), SchemeKind::kGuarded);
  // Inside tile 5 (nodes 64..127 both ways): rows offset from the tile's.
  ASSERT_TRUE(
      wp->Apply(std::vector<Move>{{{70, 80, 1}, {100, 90, -1}, 2}}).ok());
  ASSERT_TRUE(wp->TileAllocated(5));
  ASSERT_FALSE(wp->TileAllocated(wp->tile_count() - 1));
  for (int32_t t : {5, wp->tile_count() - 1}) {
    SCOPED_TRACE(t);
    const Workpiece::TileExtent e = wp->Extent(t);
    std::vector<double> whole(static_cast<size_t>(e.nx) * e.ny);
    wp->ReadTile(t, whole.data(), nullptr, nullptr);
    const int32_t j0 = e.j0 + 3, j1 = e.j0 + std::min(e.ny - 1, 40);
    const int64_t stride = e.nx + 5;
    const double kUnwritten = 12345.5;
    std::vector<double> rows(static_cast<size_t>(j1 - j0 + 1) * stride,
                             kUnwritten);
    wp->ReadTileHeights(t, j0, j1, rows.data(), stride);
    bool cut = false;
    for (int32_t j = j0; j <= j1; ++j) {
      for (int32_t i = 0; i < stride; ++i) {
        const double got = rows[(j - j0) * stride + i];
        if (i >= e.nx) {
          EXPECT_EQ(got, kUnwritten) << i << " " << j;
          continue;
        }
        const double want = whole[(j - e.j0) * e.nx + i];
        EXPECT_EQ(std::bit_cast<uint64_t>(got), std::bit_cast<uint64_t>(want))
            << i << " " << j;
        cut = cut || want < UnitStock().z_top;
      }
    }
    EXPECT_EQ(cut, t == 5);  // the cut tile's rows are not all the top
  }
}

// A ball near a tile corner whose footprint's bounding box reaches nodes of
// the next tile but whose disc does not: only the tile really cut is kept.
TEST(WorkpieceTilesTest, BoundingBoxOverlapDoesNotAllocate) {
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto wp = MakeWorkpiece(UnitStock(), scheme);
    // r = 1, 0.29 deep: cuts within 0.704 of (63.45, 62.5): nodes (63, 62)
    // and (63, 63) at 0.673; not (64, 62) or (64, 63) at 0.743, though the
    // box reaches x = 64.15 (tile 1).
    const Move m{{63.45, 62.5, -0.29}, {63.45, 62.5, -0.29}, 1};
    auto res = wp->Apply(std::vector<Move>{m});
    ASSERT_TRUE(res.ok());
    EXPECT_EQ(res->changed_tiles, std::vector<int32_t>{0});
    EXPECT_EQ(res->node_lowerings, 2);
    EXPECT_EQ(wp->allocated_tiles(), 1);
    EXPECT_FALSE(wp->TileAllocated(1));
    EXPECT_EQ(wp->Node(63, 62).owner, 0);
    EXPECT_EQ(wp->Node(63, 63).owner, 0);
    EXPECT_EQ(wp->Node(64, 62).owner, -1);
    EXPECT_EQ(wp->Node(64, 63).owner, -1);
  }
}

TEST(WorkpieceTilesTest, MovesAboveOrBesideChangeNothing) {
  const std::vector<Move> harmless = {
      {{10, 10, 0}, {200, 100, 0}, 5},    // tip exactly on the top
      {{10, 10, 3}, {10, 10, 0.5}, 5},    // plunge stopping above the top
      {{50, 50, 1}, {50, 50, 1}, 40},     // big ball above
      {{-10, 10, -5}, {-10, 240, -5}, 9},  // beside, deep: misses by 1
      {{300, 300, -2}, {400, -50, -9}, 3},  // far away
      {{128, 270, -1}, {128, 270, -1}, 14.5},  // reaches y = 264.7 only
  };
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto wp = MakeWorkpiece(UnitStock(), scheme);
    for (const Move& m : harmless) {
      auto res = wp->Apply(std::vector<Move>{m});
      ASSERT_TRUE(res.ok());
      EXPECT_EQ(res->node_lowerings, 0);
      EXPECT_TRUE(res->changed_tiles.empty());
      EXPECT_EQ(res->version, 0u);
    }
    auto all = wp->Apply(harmless);
    ASSERT_TRUE(all.ok());
    EXPECT_EQ(all->node_lowerings, 0);
    EXPECT_EQ(wp->version(), 0u);
    EXPECT_EQ(wp->allocated_tiles(), 0);
    EXPECT_EQ(wp->move_count(), 2 * static_cast<int64_t>(harmless.size()));
    for (int32_t j = 0; j <= 255; j += 5) {
      for (int32_t i = 0; i <= 255; i += 5) {
        ASSERT_EQ(wp->Node(i, j).jet.w, 0);
        ASSERT_EQ(wp->Node(i, j).owner, -1);
      }
    }
  }
}

// After every batch of a random sequence: changed_tiles lists exactly the
// tiles whose nodes changed, only those get the new version, the version
// moves iff something changed, and a tile is allocated iff it holds a cut
// node.
TEST(WorkpieceTilesTest, VersionsAndChangedTilesFollowTheNodes) {
  const StockSpec spec{0, 0, 40, 30, 10, 150, 140};  // 3 x 3 tiles
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> unit(0, 1);
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto wp = MakeWorkpiece(spec, scheme);
    const std::vector<Move> pool_of_moves = MixedMoves(4, 200);
    std::vector<NodeValue> before = Snapshot(*wp);
    std::vector<uint64_t> versions(wp->tile_count(), 0);
    size_t next = 0;
    int changing_batches = 0, idle_batches = 0;
    while (next < pool_of_moves.size()) {
      const size_t n = std::min<size_t>(1 + rng() % 6, pool_of_moves.size() - next);
      std::vector<Move> batch(pool_of_moves.begin() + next,
                              pool_of_moves.begin() + next + n);
      next += n;
      const uint64_t v0 = wp->version();
      auto res = wp->Apply(batch);
      ASSERT_TRUE(res.ok());
      const std::vector<NodeValue> after = Snapshot(*wp);
      std::set<int32_t> changed;
      int64_t changed_nodes = 0;
      std::vector<bool> holds_cut(wp->tile_count(), false);
      for (int32_t j = 0; j < wp->grid().nodes_y(); ++j) {
        for (int32_t i = 0; i < wp->grid().nodes_x(); ++i) {
          const size_t k = static_cast<size_t>(j) * wp->grid().nodes_x() + i;
          const int32_t t = TileOfNode(*wp, i, j);
          if (!SameJet(before[k].jet, after[k].jet) ||
              before[k].owner != after[k].owner) {
            changed.insert(t);
            ++changed_nodes;
            // Heights only go down.
            EXPECT_LT(after[k].jet.w, before[k].jet.w);
          }
          if (after[k].owner >= 0) holds_cut[t] = true;
        }
      }
      EXPECT_EQ(res->changed_tiles,
                std::vector<int32_t>(changed.begin(), changed.end()));
      EXPECT_TRUE(std::is_sorted(res->changed_tiles.begin(),
                                 res->changed_tiles.end()));
      EXPECT_GE(res->node_lowerings, changed_nodes);
      EXPECT_EQ(res->node_lowerings == 0, changed_nodes == 0);
      EXPECT_EQ(wp->version(), v0 + (changed.empty() ? 0 : 1));
      EXPECT_EQ(res->version, wp->version());
      for (int32_t t = 0; t < wp->tile_count(); ++t) {
        if (changed.count(t)) versions[t] = wp->version();
        EXPECT_EQ(wp->TileVersion(t), versions[t]) << "tile " << t;
        EXPECT_EQ(wp->TileAllocated(t), holds_cut[t]) << "tile " << t;
      }
      (changed.empty() ? idle_batches : changing_batches)++;
      before = after;
    }
    EXPECT_GT(changing_batches, 10);
    EXPECT_GT(idle_batches, 1);
  }
}

// A bad move anywhere in a batch rejects the whole batch with
// InvalidArgument naming the move's index and field, and nothing changes.
// Apply keeps its batch arrays from batch to batch up to 32 Ki moves, and
// gives a larger batch's back after it: batches above and below that size,
// in turn (a smaller one after a larger, its moves above the stock, not
// indexed, where the last batch's were), give the nodes and the index of
// one batch, bit for bit.
TEST(WorkpieceTest, BatchesAroundTheKeptScratchSize) {
  const std::vector<Move> moves = MixedMoves(5, 70000);
  const int n = static_cast<int>(moves.size());
  std::vector<int> in_order(n);
  std::iota(in_order.begin(), in_order.end(), 0);
  ThreadPool pool(2);
  auto one = ApplyInBatches(moves, in_order, {n}, SchemeKind::kTaylor, &pool);
  const std::vector<NodeValue> want = Snapshot(*one);
  auto turns = ApplyInBatches(moves, in_order, {7, 30000, 5000, 34000, 990},
                              SchemeKind::kTaylor, &pool);
  const std::vector<NodeValue> got = Snapshot(*turns);
  ASSERT_EQ(got.size(), want.size());
  for (size_t k = 0; k < got.size(); ++k) {
    ASSERT_TRUE(SameJet(got[k].jet, want[k].jet)) << "node " << k;
    ASSERT_EQ(got[k].owner, want[k].owner) << "node " << k;
  }
  // The same moves indexed in every bin (a move above the stock is in none).
  const MoveIndex& a = one->index();
  const MoveIndex& b = turns->index();
  ASSERT_EQ(a.bins_x() * a.bins_y(), b.bins_x() * b.bins_y());
  std::vector<uint32_t> ids_a, ids_b;
  for (int32_t bin = 0; bin < a.bins_x() * a.bins_y(); ++bin) {
    a.BinIds(bin, &ids_a);
    b.BinIds(bin, &ids_b);
    ASSERT_EQ(ids_a, ids_b) << "bin " << bin;
  }
}

// What each move of a batch cut (merged from its tiles a range of moves at
// a time, on several threads): the same bits on one thread as on three, and
// what the move cut applied alone after the same moves (each tile's sum in
// its own order: to 1e-12), across the ranges' edges, with and without a
// drop limit.
TEST(WorkpieceTest, CutsOfABatchAreEachMovesOwn) {
  const std::vector<Move> moves = MixedMoves(7, 3000);
  const std::vector<double> limits(moves.size(), 0.3);
  auto same_bits = [](double a, double b) {
    return std::bit_cast<uint64_t>(a) == std::bit_cast<uint64_t>(b);
  };
  for (bool limited : {false, true}) {
    SCOPED_TRACE(limited ? "with a drop limit" : "without");
    ApplyOptions options;
    options.cuts = true;
    if (limited) options.drop_limit = limits;
    ThreadPool pool1(1), pool3(3);
    auto batch = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor, &pool3);
    auto applied = batch->Apply(moves, options);
    ASSERT_TRUE(applied.ok()) << applied.status();
    ASSERT_EQ(applied->cuts.size(), moves.size());
    auto batch1 = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor, &pool1);
    auto applied1 = batch1->Apply(moves, options);
    ASSERT_TRUE(applied1.ok()) << applied1.status();
    auto alone = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor, &pool3);
    int cutting = 0, over = 0;
    double removed = 0;
    for (size_t k = 0; k < moves.size(); ++k) {
      const MoveCut& got = applied->cuts[k];
      const MoveCut& one_thread = applied1->cuts[k];
      ASSERT_TRUE(same_bits(got.removed_mm3, one_thread.removed_mm3) &&
                  same_bits(got.over_limit_mm3, one_thread.over_limit_mm3) &&
                  same_bits(got.max_drop, one_thread.max_drop) &&
                  same_bits(got.z, one_thread.z) && got.i == one_thread.i &&
                  got.j == one_thread.j)
          << "move " << k;
      ApplyOptions one = options;
      if (limited) one.drop_limit = std::span<const double>(&limits[k], 1);
      auto r = alone->Apply(std::span<const Move>(&moves[k], 1), one);
      ASSERT_TRUE(r.ok()) << r.status();
      const MoveCut& want = r->cuts[0];
      ASSERT_NEAR(got.removed_mm3, want.removed_mm3, 1e-12 * want.removed_mm3)
          << "move " << k;
      ASSERT_NEAR(got.over_limit_mm3, want.over_limit_mm3,
                  1e-12 * want.over_limit_mm3)
          << "move " << k;
      ASSERT_TRUE(got.max_drop == want.max_drop && got.i == want.i &&
                  got.j == want.j && got.z == want.z)
          << "move " << k;
      cutting += want.max_drop > 0;
      over += want.over_limit_mm3 > 0;
      removed += got.removed_mm3;
    }
    EXPECT_GT(cutting, 500);  // the mix really cuts (564 moves)
    if (limited) {
      EXPECT_GT(over, 100);
    }
    double by_nodes = 0;  // the stock's volume minus the nodes'
    for (int32_t j = 0; j <= batch->grid().ny(); ++j) {
      for (int32_t i = 0; i <= batch->grid().nx(); ++i) {
        by_nodes += batch->spec().z_top - batch->HeightAt(i, j);
      }
    }
    by_nodes *= batch->grid().dx() * batch->grid().dy();
    EXPECT_NEAR(removed, by_nodes, 1e-9 * removed);
  }
}

TEST(WorkpieceValidationTest, BadBatchIsRejectedWhole) {
  const double nan = std::nan(""), inf = kInf;
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto wp = MakeWorkpiece(MixedStock(), scheme);
    ASSERT_TRUE(wp->Apply(MixedMoves(5, 40)).ok());
    const std::vector<NodeValue> before = Snapshot(*wp);
    const uint64_t version = wp->version();
    const int64_t count = wp->move_count();
    std::vector<uint64_t> tile_versions;
    for (int32_t t = 0; t < wp->tile_count(); ++t) {
      tile_versions.push_back(wp->TileVersion(t));
    }
    const std::vector<Move> good = MixedMoves(6, 6);  // all valid, cutting
    const char* names[] = {"from.x", "from.y", "from.z",
                           "to.x",   "to.y",   "to.z"};
    auto expect_rejected = [&](std::vector<Move> batch, int index,
                               const std::string& field) {
      SCOPED_TRACE("moves[" + std::to_string(index) + "]." + field);
      const absl::Status st = Workpiece::ValidateMoves(batch);
      EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
      auto res = wp->Apply(batch);
      ASSERT_FALSE(res.ok());
      EXPECT_EQ(res.status().code(), absl::StatusCode::kInvalidArgument);
      EXPECT_THAT(res.status().message(),
                  HasSubstr("moves[" + std::to_string(index) + "]"));
      EXPECT_THAT(res.status().message(), HasSubstr(field));
      EXPECT_EQ(wp->move_count(), count);
      EXPECT_EQ(wp->version(), version);
      const std::vector<NodeValue> after = Snapshot(*wp);
      for (size_t k = 0; k < after.size(); ++k) {
        ASSERT_TRUE(SameJet(after[k].jet, before[k].jet) &&
                    after[k].owner == before[k].owner)
            << "node " << k;
      }
      for (int32_t t = 0; t < wp->tile_count(); ++t) {
        EXPECT_EQ(wp->TileVersion(t), tile_versions[t]);
      }
    };
    for (int f = 0; f < 6; ++f) {
      for (double bad : {nan, inf, -inf}) {
        for (int index : {0, 3, 5}) {
          std::vector<Move> batch = good;
          Vec3& v = f < 3 ? batch[index].from : batch[index].to;
          (f % 3 == 0 ? v.x : f % 3 == 1 ? v.y : v.z) = bad;
          expect_rejected(batch, index, names[f]);
        }
      }
    }
    for (double bad : {0.0, -0.0, -1.0, -1e-300, nan, inf, -inf}) {
      std::vector<Move> batch = good;
      batch[4].cutter.radius = bad;
      expect_rejected(batch, 4, "radius");
    }
    // The first bad move is the one named.
    std::vector<Move> two_bad = good;
    two_bad[2].to.y = nan;
    two_bad[4].cutter.radius = 0;
    expect_rejected(two_bad, 2, "to.y");
    // And a clean batch still applies afterwards.
    auto ok = wp->Apply(good);
    ASSERT_TRUE(ok.ok()) << ok.status();
    EXPECT_EQ(ok->first_move_id, count);
    EXPECT_TRUE(Workpiece::ValidateMoves(good).ok());
    EXPECT_TRUE(Workpiece::ValidateMoves({}).ok());
  }
}

// Radii at the ends of the double range: r^2 and 1 / (1e-4 r) overflow or
// underflow. Either the batch is refused (InvalidArgument naming the radius)
// or every stored parameter stays finite; a NaN or infinite node is never
// acceptable (derivatives are stored as float, heights feed every scheme).
StockSpec UnitStockForRadii() { return StockSpec{0, 0, 8, 8, 0, 8, 8}; }

void ExpectRejectedOrFinite(double r, SchemeKind scheme) {
  std::ostringstream what;
  what << "r " << r << " " << SchemeName(scheme);
  SCOPED_TRACE(what.str());
  auto wp = MakeWorkpiece(UnitStockForRadii(), scheme);
  // A plunge and a sloped move with a ball centre right over a node.
  const std::vector<Move> batch = {
      {{4, 4, 3}, {4, 4, -1}, r},
      {{2, 6, -1}, {6, 6, -2}, r},
  };
  auto res = wp->Apply(batch);
  if (!res.ok()) {
    EXPECT_EQ(res.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(res.status().message(), HasSubstr("radius"));
    return;
  }
  for (int32_t j = 0; j < wp->grid().nodes_y(); ++j) {
    for (int32_t i = 0; i < wp->grid().nodes_x(); ++i) {
      const SurfaceJet v = wp->Node(i, j).jet;
      const double d[6] = {v.w, v.wx, v.wy, v.wxx, v.wxy, v.wyy};
      for (double x : d) {
        ASSERT_TRUE(std::isfinite(x))
            << "node " << i << "," << j << ": w " << v.w << " wx " << v.wx
            << " wy " << v.wy << " wxx " << v.wxx << " wxy " << v.wxy
            << " wyy " << v.wyy;
      }
    }
  }
}

TEST(WorkpieceValidationTest, AbsurdRadiiAreRejectedOrStayFinite) {
  for (double r : {5e-324, 1e-310, 1e160}) {
    for (SchemeKind scheme : kSchemes) ExpectRejectedOrFinite(r, scheme);
  }
}

TEST(WorkpieceValidationTest, CreateRejectsBadStock) {
  auto wp = Workpiece::Create(StockSpec{0, 0, 0, 1, 0, 4, 4}, SchemeKind::kZmap);
  EXPECT_EQ(wp.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(wp.status().message(), HasSubstr("x1"));
}

TEST(WorkpieceTest, UntouchedNodesAreTheStockTop) {
  for (SchemeKind scheme : kSchemes) {
    auto wp = MakeWorkpiece(StockSpec{-5, 2, 7, 9, 3.25, 13, 11}, scheme);
    EXPECT_EQ(wp->move_count(), 0);
    EXPECT_EQ(wp->version(), 0u);
    for (int32_t j = 0; j <= 11; ++j) {
      for (int32_t i = 0; i <= 13; ++i) {
        const NodeValue v = wp->Node(i, j);
        SurfaceJet flat;
        flat.w = 3.25;
        EXPECT_TRUE(SameJet(v.jet, flat));
        EXPECT_EQ(v.owner, -1);
      }
    }
    const ElementCorners e = wp->Corners(2, 3);
    EXPECT_EQ(e.x0, wp->grid().NodeX(2));
    EXPECT_EQ(e.x1, wp->grid().NodeX(3));
    EXPECT_EQ(e.y0, wp->grid().NodeY(3));
    EXPECT_EQ(e.y1, wp->grid().NodeY(4));
    EXPECT_EQ(e.z_top, 3.25);
  }
}

// ExactHeight is the minimum of the top and of every sweep, wherever the
// point lies relative to the nodes.
TEST(WorkpieceExactHeightTest, MatchesAllSweepsAtRandomPoints) {
  const std::vector<Move> moves = MixedMoves(7, 300);
  auto wp = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor);
  ASSERT_TRUE(wp->Apply(moves).ok());
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> ux(-4, 44), uy(-4, 34);
  for (int k = 0; k < 5000; ++k) {
    const double x = ux(rng), y = uy(rng);
    double w = MixedStock().z_top;
    for (const Move& m : moves) {
      w = std::min(w, BallSweep(m.from, m.to, m.cutter.radius).Height(x, y));
    }
    ASSERT_EQ(wp->ExactHeight(x, y), w) << "at " << x << "," << y;
  }
}

// A cut that reaches no node still belongs to the machined surface.
TEST(WorkpieceExactHeightTest, SeesCutsBetweenNodes) {
  // Nodes every 5 mm; a small ball dips 1 mm between them.
  const StockSpec spec{0, 0, 10, 10, 0, 2, 2};
  const Move m{{2.5, 2.5, -1}, {2.5, 2.5, -1}, 0.5};
  auto wp = MakeWorkpiece(spec, SchemeKind::kZmap);
  ASSERT_TRUE(wp->Apply(std::vector<Move>{m}).ok());
  EXPECT_EQ(wp->allocated_tiles(), 0);  // no node is cut
  EXPECT_EQ(wp->ExactHeight(2.5, 2.5), -1);
  EXPECT_EQ(wp->ExactHeight(2.5, 2.8),
            BallSweep(m.from, m.to, m.cutter.radius).Height(2.5, 2.8));
  EXPECT_EQ(wp->ExactHeight(7.5, 7.5), 0);
}

std::string SavedState(const Workpiece& wp) {
  std::string out;
  wp.SaveState([&](const void* data, size_t size) {
    out.append(static_cast<const char*>(data), size);
  });
  return out;
}

// Everything observable of two workpieces is bit-identical: nodes (heights,
// derivatives, owners), versions, tiles and the exact surface.
void ExpectSameWorkpiece(const Workpiece& a, const Workpiece& b) {
  ASSERT_EQ(a.move_count(), b.move_count());
  EXPECT_EQ(a.version(), b.version());
  EXPECT_EQ(a.allocated_tiles(), b.allocated_tiles());
  for (int32_t t = 0; t < a.tile_count(); ++t) {
    EXPECT_EQ(a.TileAllocated(t), b.TileAllocated(t)) << "tile " << t;
    EXPECT_EQ(a.TileVersion(t), b.TileVersion(t)) << "tile " << t;
  }
  const std::vector<NodeValue> na = Snapshot(a), nb = Snapshot(b);
  for (size_t k = 0; k < na.size(); ++k) {
    ASSERT_TRUE(SameJet(na[k].jet, nb[k].jet)) << "node " << k;
    ASSERT_EQ(na[k].owner, nb[k].owner) << "node " << k;
  }
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> ux(-4, 44), uy(-4, 34);
  for (int k = 0; k < 2000; ++k) {
    const double x = ux(rng), y = uy(rng);
    ASSERT_EQ(a.ExactHeight(x, y), b.ExactHeight(x, y)) << x << "," << y;
  }
}

// A workpiece rebuilt from a saved state (its moves recorded, not cut) is
// the saved one bit for bit, and stays so as both go on cutting.
TEST(WorkpieceStateTest, RestoredStateIsBitIdenticalAndContinues) {
  const std::vector<Move> moves = MixedMoves(21, 600);
  const std::span<const Move> first(moves.data(), 350),
      rest(moves.data() + 350, 250);
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(SchemeName(scheme));
    auto original = MakeWorkpiece(MixedStock(), scheme);
    for (size_t k = 0; k < first.size(); k += 50) {
      ASSERT_TRUE(original->Apply(first.subspan(k, 50)).ok());
    }
    const std::string state = SavedState(*original);

    auto restored = MakeWorkpiece(MixedStock(), scheme);
    ASSERT_TRUE(restored->Record(first.subspan(0, 100)).ok());
    ASSERT_TRUE(restored->Record(first.subspan(100)).ok());
    ASSERT_TRUE(restored->LoadState(state).ok());
    ExpectSameWorkpiece(*original, *restored);
    // Saving again gives the same bytes (uncut derivatives are zeros).
    EXPECT_EQ(SavedState(*restored), state);

    for (size_t k = 0; k < rest.size(); k += 50) {
      auto a = original->Apply(rest.subspan(k, 50));
      auto b = restored->Apply(rest.subspan(k, 50));
      ASSERT_TRUE(a.ok() && b.ok());
      EXPECT_EQ(a->changed_tiles, b->changed_tiles);
      EXPECT_EQ(a->node_lowerings, b->node_lowerings);
    }
    ExpectSameWorkpiece(*original, *restored);
    EXPECT_EQ(SavedState(*restored), SavedState(*original));
  }
}

// An empty workpiece's state restores to an empty workpiece.
TEST(WorkpieceStateTest, UncutStateRoundTrips) {
  auto a = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor);
  auto b = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor);
  ASSERT_TRUE(b->LoadState(SavedState(*a)).ok());
  EXPECT_EQ(b->allocated_tiles(), 0);
  EXPECT_EQ(b->version(), 0u);
}

// Bytes that are not the state of this workpiece are DataLoss, and the
// workpiece is left as it was.
TEST(WorkpieceStateTest, ForeignOrDamagedStatesAreRejected) {
  const std::vector<Move> moves = MixedMoves(5, 200);
  auto original = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor);
  ASSERT_TRUE(original->Apply(moves).ok());
  const std::string state = SavedState(*original);
  ASSERT_GT(original->allocated_tiles(), 0);

  auto expect_rejected = [&](const std::string& bytes,
                             const std::string& what) {
    auto target = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor);
    ASSERT_TRUE(target->Record(moves).ok());
    const std::string before = SavedState(*target);
    const absl::Status s = target->LoadState(bytes);
    EXPECT_EQ(s.code(), absl::StatusCode::kDataLoss) << what << ": " << s;
    EXPECT_THAT(std::string(s.message()), HasSubstr(what));
    EXPECT_EQ(SavedState(*target), before) << what;
  };
  // Fewer moves recorded than were saved.
  auto fewer = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor);
  ASSERT_TRUE(fewer->Record(std::span<const Move>(moves.data(), 199)).ok());
  EXPECT_EQ(fewer->LoadState(state).code(), absl::StatusCode::kDataLoss);
  // Another scheme, another stock.
  auto zmap = MakeWorkpiece(MixedStock(), SchemeKind::kZmap);
  ASSERT_TRUE(zmap->Record(moves).ok());
  EXPECT_THAT(std::string(zmap->LoadState(state).message()),
              HasSubstr("another stock or scheme"));
  StockSpec other = MixedStock();
  other.z_top = std::nextafter(other.z_top, 100.0);
  auto moved = MakeWorkpiece(other, SchemeKind::kTaylor);
  ASSERT_TRUE(moved->Record(moves).ok());
  EXPECT_EQ(moved->LoadState(state).code(), absl::StatusCode::kDataLoss);

  expect_rejected(state.substr(0, 20), "header");
  expect_rejected(state.substr(0, state.size() - 1), "truncated");
  expect_rejected(state + "x", "trailing bytes");
  std::string bad_magic = state;
  bad_magic[0] = 'X';
  expect_rejected(bad_magic, "header");
  // The first tile's first owner (after the header, index and version, and
  // the tile's heights) set to a move that does not exist.
  const size_t header = 8 + 4 + 8 + 5 * 8 + 8 + 8 + 4;
  const size_t owner0 = header + 4 + 8 + kTileNodes * sizeof(double);
  std::string bad_owner = state;
  const int32_t absent = 200;
  std::memcpy(bad_owner.data() + owner0, &absent, 4);
  expect_rejected(bad_owner, "owner 200");
  // A height above the top.
  std::string bad_height = state;
  const double high = MixedStock().z_top + 1;
  std::memcpy(bad_height.data() + header + 12, &high, 8);
  expect_rejected(bad_height, "height");
  // A version beyond the moves (each batch that cuts has one): at 2^64 - 1
  // it would wrap to 0 with the next cut.
  // (after the magic, the scheme, nx, ny and five f64s).
  const size_t version_at = 8 + 4 + 8 + 5 * 8;
  std::string bad_version = state;
  const uint64_t last_version = ~uint64_t{0};
  std::memcpy(bad_version.data() + version_at, &last_version, 8);
  expect_rejected(bad_version, "version 18446744073709551615 after only 200");
  const uint64_t one_too_many = 201;
  std::memcpy(bad_version.data() + version_at, &one_too_many, 8);
  expect_rejected(bad_version, "version 201 after only 200 moves");
  // A tile index beyond the grid.
  std::string bad_tile = state;
  const uint32_t far = 1000;
  std::memcpy(bad_tile.data() + header, &far, 4);
  expect_rejected(bad_tile, "out of order or range");
  // The first tile's first cut node: a height below anything a move cuts
  // (differences of it overflow), an infinite derivative (wx).
  auto owner_of = [&](int32_t k) {
    int32_t o;
    std::memcpy(&o, state.data() + owner0 + 4 * k, 4);
    return o;
  };
  int32_t cut = 0;
  while (owner_of(cut) < 0) ++cut;
  std::string too_deep = state;
  const double deep = -1e300;
  std::memcpy(too_deep.data() + header + 12 + 8 * cut, &deep, 8);
  expect_rejected(too_deep, "height -1e+300");
  // A version-1 state (derivatives stored after the owners) with an
  // infinite derivative (wx).
  std::string bad_derivative = StateV1(*original);
  const float inf = std::numeric_limits<float>::infinity();
  std::memcpy(bad_derivative.data() + owner0 + kTileNodes * 4 + 4 * cut, &inf,
              4);
  expect_rejected(bad_derivative, "derivative inf");

  // Read piece by piece, a whole state is still refused by verify() (a
  // checksum over it), and then not taken.
  auto target = MakeWorkpiece(MixedStock(), SchemeKind::kTaylor);
  ASSERT_TRUE(target->Record(moves).ok());
  const std::string before = SavedState(*target);
  std::string_view rest = state;
  auto read = [&](void* data, size_t size) {
    if (rest.size() < size) return false;
    std::memcpy(data, rest.data(), size);
    rest.remove_prefix(size);
    return true;
  };
  const absl::Status refused = target->LoadState(
      read, [] { return absl::DataLossError("checksum refused"); });
  EXPECT_EQ(refused.message(), "checksum refused");
  EXPECT_TRUE(rest.empty());
  EXPECT_EQ(SavedState(*target), before);
  rest = state;
  ASSERT_TRUE(target->LoadState(read, [] { return absl::OkStatus(); }).ok());
  EXPECT_EQ(SavedState(*target), state);
}

// A version-1 state (snapshots written when derivatives were stored) loads
// into the same workpiece as the current format: the derivatives it carries
// are the ones computed on demand, bit for bit, and it saves as version 2.
TEST(WorkpieceStateTest, VersionOneStatesStillLoad) {
  const std::vector<Move> moves = MixedMoves(11, 150);
  for (SchemeKind scheme :
       {SchemeKind::kZmap, SchemeKind::kTaylor, SchemeKind::kGuarded}) {
    auto original = MakeWorkpiece(MixedStock(), scheme);
    ASSERT_TRUE(original->Apply(moves).ok());
    const std::string v1 = StateV1(*original);
    ASSERT_EQ(v1.substr(0, 8), "SWARFWP1");
    auto target = MakeWorkpiece(MixedStock(), scheme);
    ASSERT_TRUE(target->Record(moves).ok());
    ASSERT_TRUE(target->LoadState(v1).ok());
    EXPECT_EQ(SavedState(*target), SavedState(*original));
    EXPECT_EQ(StateV1(*target), v1);
  }
}

// Record indexes moves as Apply does: the exact surface sees them.
TEST(WorkpieceStateTest, RecordedMovesAreIndexedAndValidated) {
  const std::vector<Move> moves = MixedMoves(9, 300);
  auto cut = MakeWorkpiece(MixedStock(), SchemeKind::kZmap);
  auto recorded = MakeWorkpiece(MixedStock(), SchemeKind::kZmap);
  ASSERT_TRUE(cut->Apply(moves).ok());
  ASSERT_TRUE(recorded->Record(moves).ok());
  EXPECT_EQ(recorded->allocated_tiles(), 0);  // nothing cut
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> ux(-4, 44), uy(-4, 34);
  for (int k = 0; k < 2000; ++k) {
    const double x = ux(rng), y = uy(rng);
    ASSERT_EQ(cut->ExactHeight(x, y), recorded->ExactHeight(x, y));
  }
  Move bad = moves[0];
  bad.to.y = std::nan("");
  const absl::Status s = recorded->Record(std::vector<Move>{moves[1], bad});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("moves[1].to.y"));
  EXPECT_EQ(recorded->move_count(), 300);
}

// Derivatives on demand. Every shape and kind of move in one workpiece of
// 225 tiles (more than the jet cache keeps): a finishing raster of short
// ball moves (owners change every two nodes), bull-noses swept as the ball,
// the other shapes, plunges and zero-length moves (one sphere), and a
// coarse raster reaching every tile.
std::vector<Move> JetMixMoves() {
  std::vector<Move> moves;
  for (double y = 2.5; y < 95; y += 5) {  // every tile
    moves.push_back({{-5, y, 9.5}, {95, y, 9.5}, Cutter::Ball(3)});
  }
  moves.push_back({{-5, 89.8, 9.5}, {95, 89.8, 9.5}, Cutter::Ball(3)});
  for (int k = 0; k < 60; ++k) {  // finishing raster, rows of 0.2 mm moves
    const double y = 30 + 0.1 * k;
    for (double x = 20; x < 50; x += 0.2) {
      auto z = [&](double u) { return 9 + 0.3 * std::sin(0.2 * u + y); };
      moves.push_back({{x, y, z(x)}, {x + 0.2, y, z(x + 0.2)},
                       Cutter::Ball(0.5)});
    }
  }
  const Cutter shapes[] = {Cutter::BullNose(1, 1),   Cutter::Flat(1),
                           Cutter::BullNose(1, 0.4), Cutter::Cone(1, 45, 0.2),
                           Cutter::TaperedBall(1, 0.3, 10), Cutter::Ball(1)};
  for (int k = 0; k < 240; ++k) {  // short moves of every shape, interleaved
    const double x = 55 + 0.3 * (k % 40), y = 60 + 1.5 * (k / 40);
    moves.push_back(
        {{x, y, 9.2 + 0.01 * (k % 7)}, {x + 0.4, y + 0.1, 9.1}, shapes[k % 6]});
  }
  moves.push_back({{70, 20, 12}, {70, 20, 6}, Cutter::Ball(4)});    // plunge
  moves.push_back({{80, 30, 8}, {80, 30, 8}, Cutter::Ball(2)});     // a point
  moves.push_back({{75, 75, 9}, {75, 75, 5}, Cutter::BullNose(2, 2)});
  moves.push_back({{60, 80, 8}, {60, 80, 6}, Cutter::Flat(2)});
  return moves;
}

// Every node's derivatives, as ReadTile and Node give them, are its
// owner's JetAt rounded to float, bit for bit; zeros for uncut nodes.
void ExpectJetsOfOwners(const Workpiece& wp) {
  const GridGeometry& g = wp.grid();
  std::vector<double> w(kTileNodes);
  std::vector<float> d(5 * kTileNodes);
  std::vector<int32_t> owner(kTileNodes);
  float* dp[5];
  for (int c = 0; c < 5; ++c) dp[c] = d.data() + c * kTileNodes;
  int64_t cut = 0;
  for (int32_t t = 0; t < wp.tile_count(); ++t) {
    // Every output value written: what the last tile left is no zero.
    std::fill(d.begin(), d.end(), std::nanf(""));
    wp.ReadTile(t, w.data(), dp, owner.data());
    const Workpiece::TileExtent e = wp.Extent(t);
    for (int32_t j = 0; j < e.ny; ++j) {
      for (int32_t i = 0; i < e.nx; ++i) {
        const int32_t q = j * e.nx + i, o = owner[q];
        const double x = g.NodeX(e.i0 + i), y = g.NodeY(e.j0 + j);
        SurfaceJet want;
        if (o >= 0) want = wp.MoveJet(o, x, y);
        const double wd[5] = {want.wx, want.wy, want.wxx, want.wxy, want.wyy};
        for (int c = 0; c < 5; ++c) {
          const float f = static_cast<float>(wd[c]);
          ASSERT_EQ(std::memcmp(&dp[c][q], &f, sizeof f), 0)
              << "tile " << t << " node " << i << "," << j << " owner " << o
              << (o >= 0 ? CutterToString(wp.move(o).cutter) : "") << " component "
              << c << ": " << dp[c][q] << " vs " << f;
        }
        ASSERT_EQ(o, wp.Node(e.i0 + i, e.j0 + j).owner);
        if (o >= 0) {
          const SurfaceJet stored = {w[q],
                                     static_cast<float>(wd[0]),
                                     static_cast<float>(wd[1]),
                                     static_cast<float>(wd[2]),
                                     static_cast<float>(wd[3]),
                                     static_cast<float>(wd[4])};
          ASSERT_TRUE(SameJet(wp.Node(e.i0 + i, e.j0 + j).jet, stored));
        }
        cut += o >= 0;
      }
    }
  }
  EXPECT_GT(cut, 100000);
}

TEST(WorkpieceJetsTest, EveryNodeHasItsOwnersJet) {
  const StockSpec spec{0, 0, 90, 90, 10, 900, 900};
  const std::vector<Move> moves = JetMixMoves();
  ThreadPool pool(4);
  auto wp = MakeWorkpiece(spec, SchemeKind::kTaylor, &pool);
  ASSERT_TRUE(wp->Apply(moves).ok());
  ASSERT_EQ(wp->allocated_tiles(), wp->tile_count());
  ASSERT_GT(wp->tile_count(), static_cast<int>(Workpiece::kJetCacheTiles));
  {
    // Nothing cached: each read computes its jets straight into the
    // buffers (Node, called after it, caches them).
    SCOPED_TRACE("read one by one");
    ExpectJetsOfOwners(*wp);
  }
  {
    // Chunks computed on the pool from two threads at once, then read.
    SCOPED_TRACE("prepared");
    std::vector<int32_t> all(wp->tile_count());
    std::iota(all.begin(), all.end(), 0);
    std::thread other([&] { wp->PrepareJets(std::span(all).subspan(64, 100)); });
    wp->PrepareJets(std::span(all).subspan(0, 100));
    other.join();
    ExpectJetsOfOwners(*wp);
  }
  {
    // Tiles cut again have new versions: their jets are computed anew.
    SCOPED_TRACE("after more cuts");
    ASSERT_TRUE(wp->Apply(std::vector<Move>{
                          {{10, 10, 9}, {40, 35, 8.5}, Cutter::Ball(1.5)},
                          {{30, 31, 9}, {31, 31, 8}, Cutter::Cone(1, 30, 0)}})
                    .ok());
    ExpectJetsOfOwners(*wp);
  }
  {
    // A restored state: the same nodes, jets computed from its moves.
    SCOPED_TRACE("restored");
    auto restored = MakeWorkpiece(spec, SchemeKind::kTaylor, &pool);
    ASSERT_TRUE(restored->Record(wp->moves().ToVector()).ok());
    ASSERT_TRUE(restored->LoadState(SavedState(*wp)).ok());
    ExpectJetsOfOwners(*restored);
  }
}

// A traversal's own jet cache gives every node what Node gives it, bit for
// bit, whatever its capacity (one tile: each change of tile evicts), read
// from two threads at once, one of them interleaving the workpiece's own
// cache.
TEST(WorkpieceJetsTest, TraversalCachesReadTheSameNodes) {
  const StockSpec spec{0, 0, 90, 90, 10, 900, 900};
  ThreadPool pool(4);
  auto wp = MakeWorkpiece(spec, SchemeKind::kTaylor, &pool);
  ASSERT_TRUE(wp->Apply(JetMixMoves()).ok());
  ASSERT_EQ(wp->allocated_tiles(), wp->tile_count());
  const int32_t nx = spec.nx + 1, ny = spec.ny + 1;
  std::vector<NodeValue> want(static_cast<size_t>(nx) * ny);
  for (int32_t j = 0; j < ny; ++j) {
    for (int32_t i = 0; i < nx; ++i) want[size_t(j) * nx + i] = wp->Node(i, j);
  }
  const std::unique_ptr<Workpiece::JetCache> traversal =
      wp->TraversalJetCache();
  // Two rows of 15 tiles and 64 more, fewer than the grid's 225.
  EXPECT_EQ(wp->tiles_x(), 15);
  EXPECT_EQ(traversal->capacity(), size_t{2 * 15 + 64});
  // Node rows read at once: 257 (sixteen threads' bands of 16 rows and the
  // row past them) can span five tile rows (63 to 319), 66 three and 65
  // two; fewer, two; the whole grid at most.
  EXPECT_EQ(wp->TraversalJetCache(257)->capacity(), size_t{5 * 15 + 64});
  EXPECT_EQ(wp->TraversalJetCache(66)->capacity(), size_t{3 * 15 + 64});
  EXPECT_EQ(wp->TraversalJetCache(65)->capacity(), size_t{2 * 15 + 64});
  EXPECT_EQ(wp->TraversalJetCache(1)->capacity(), size_t{2 * 15 + 64});
  EXPECT_EQ(wp->TraversalJetCache(1 << 20)->capacity(),
            static_cast<size_t>(wp->tile_count()));
  const std::unique_ptr<Workpiece::JetCache> one = wp->NewJetCache(1);
  EXPECT_EQ(one->capacity(), 1u);
  EXPECT_EQ(wp->NewJetCache(0)->capacity(), 1u);
  for (Workpiece::JetCache* cache : {traversal.get(), one.get()}) {
    SCOPED_TRACE(cache->capacity());
    const int32_t step = cache == one.get() ? 7 : 1;  // rows read
    auto read = [&](bool down, bool mixed, int64_t* bad) {
      for (int32_t r = 0; r < ny; r += step) {
        const int32_t j = down ? ny - 1 - r : r;
        for (int32_t i = 0; i < nx; ++i) {
          const NodeValue v = mixed && i % 3 == 0 ? wp->Node(nx - 1 - i, j)
                                                  : wp->Node(i, j, cache);
          const NodeValue& w =
              want[size_t(j) * nx + (mixed && i % 3 == 0 ? nx - 1 - i : i)];
          *bad += !SameJet(v.jet, w.jet) || v.owner != w.owner;
        }
      }
    };
    int64_t bad_up = 0, bad_down = 0;
    std::thread other([&] { read(/*down=*/true, /*mixed=*/true, &bad_down); });
    read(/*down=*/false, /*mixed=*/false, &bad_up);
    other.join();
    EXPECT_EQ(bad_up, 0);
    EXPECT_EQ(bad_down, 0);
  }
}

// The z-map has no derivatives: zeros, and PrepareJets does nothing.
TEST(WorkpieceJetsTest, ZmapReadsZeros) {
  auto wp = MakeWorkpiece(MixedStock(), SchemeKind::kZmap);
  ASSERT_TRUE(wp->Apply(MixedMoves(4, 200)).ok());
  std::vector<int32_t> all(wp->tile_count());
  std::iota(all.begin(), all.end(), 0);
  wp->PrepareJets(all);
  std::vector<float> d(5 * kTileNodes, 1.0f);
  float* dp[5];
  for (int c = 0; c < 5; ++c) dp[c] = d.data() + c * kTileNodes;
  for (int32_t t = 0; t < wp->tile_count(); ++t) {
    wp->ReadTile(t, nullptr, dp, nullptr);
    const Workpiece::TileExtent e = wp->Extent(t);
    for (int c = 0; c < 5; ++c) {
      for (int32_t q = 0; q < e.nx * e.ny; ++q) ASSERT_EQ(dp[c][q], 0.0f);
    }
  }
}

}  // namespace
}  // namespace swarf
