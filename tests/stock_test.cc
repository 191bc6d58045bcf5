// ValidateStock and GridGeometry.
#include "core/stock.h"

#include <cmath>
#include <limits>
#include <string>

#include "absl/status/status.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace swarf {
namespace {

using ::testing::HasSubstr;

StockSpec Good() { return StockSpec{-5, 2, 7, 9, 3.25, 13, 11}; }

void ExpectInvalid(const StockSpec& s, const std::string& field) {
  const absl::Status st = ValidateStock(s);
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument) << field;
  EXPECT_THAT(st.message(), HasSubstr(field));
}

TEST(ValidateStockTest, AcceptsAGoodSpec) {
  EXPECT_TRUE(ValidateStock(Good()).ok());
  StockSpec one = Good();
  one.nx = one.ny = 1;
  EXPECT_TRUE(ValidateStock(one).ok());
  StockSpec big = Good();
  big.nx = kMaxElementsPerAxis;  // (2^20 + 1) * 12 nodes: under the limit
  EXPECT_TRUE(ValidateStock(big).ok());
}

TEST(ValidateStockTest, NonFiniteFieldsAreNamed) {
  const double nan = std::nan(""), inf = std::numeric_limits<double>::infinity();
  for (double bad : {nan, inf, -inf}) {
    StockSpec s = Good();
    s.x0 = bad;
    ExpectInvalid(s, "x0");
    s = Good();
    s.y0 = bad;
    ExpectInvalid(s, "y0");
    s = Good();
    s.x1 = bad;
    ExpectInvalid(s, "x1");
    s = Good();
    s.y1 = bad;
    ExpectInvalid(s, "y1");
    s = Good();
    s.z_top = bad;
    ExpectInvalid(s, "z_top");
  }
}

TEST(ValidateStockTest, EmptyRectangleIsNamed) {
  StockSpec s = Good();
  s.x1 = s.x0;
  ExpectInvalid(s, "x1");
  s.x1 = s.x0 - 1;
  ExpectInvalid(s, "x1");
  s = Good();
  s.y1 = s.y0;
  ExpectInvalid(s, "y1");
  s.y1 = s.y0 - 0.5;
  ExpectInvalid(s, "y1");
}

TEST(ValidateStockTest, ElementCountsAreNamed) {
  for (int32_t bad : {0, -1, kMaxElementsPerAxis + 1}) {
    StockSpec s = Good();
    s.nx = bad;
    ExpectInvalid(s, "nx");
    s = Good();
    s.ny = bad;
    ExpectInvalid(s, "ny");
  }
}

TEST(ValidateStockTest, TooManyNodes) {
  StockSpec s = Good();
  s.nx = s.ny = kMaxElementsPerAxis;  // about 2^40 nodes > kMaxNodes
  ExpectInvalid(s, "nodes");
  // Exactly at the limit is fine: (2^17 - 1 + 1) * (2^17 - 1 + 1) = 2^34.
  s.nx = s.ny = (1 << 17) - 1;
  EXPECT_TRUE(ValidateStock(s).ok());
  s.nx = 1 << 17;  // one column more
  ExpectInvalid(s, "nodes");
}

TEST(GridGeometryTest, NodesAndElements) {
  const GridGeometry g(Good());
  EXPECT_EQ(g.nodes_x(), 14);
  EXPECT_EQ(g.nodes_y(), 12);
  EXPECT_EQ(g.node_count(), 14 * 12);
  EXPECT_EQ(g.NodeX(0), -5);
  EXPECT_EQ(g.NodeY(0), 2);
  // The last node is x1 up to the rounding of x0 + nx * dx.
  EXPECT_NEAR(g.NodeX(13), 7, 4 * std::numeric_limits<double>::epsilon() * 7);
  EXPECT_NEAR(g.NodeY(11), 9, 4 * std::numeric_limits<double>::epsilon() * 9);
  EXPECT_DOUBLE_EQ(g.dx(), 12.0 / 13);
  EXPECT_DOUBLE_EQ(g.dy(), 7.0 / 11);
  for (int32_t i = 0; i < 13; ++i) {
    EXPECT_EQ(g.ElementX(g.NodeX(i) + 0.5 * g.dx()), i);
  }
  for (int32_t j = 0; j < 11; ++j) {
    EXPECT_EQ(g.ElementY(g.NodeY(j) + 0.5 * g.dy()), j);
  }
  // Clamped to the stock's elements.
  EXPECT_EQ(g.ElementX(-100), 0);
  EXPECT_EQ(g.ElementX(7), 12);
  EXPECT_EQ(g.ElementX(1e9), 12);
  EXPECT_EQ(g.ElementY(-1e9), 0);
  EXPECT_EQ(g.ElementY(9), 10);
  const Rect b = g.bounds();
  EXPECT_EQ(b.x0, -5);
  EXPECT_EQ(b.y1, 9);
}

}  // namespace
}  // namespace swarf
