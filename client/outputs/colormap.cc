#include "client/outputs/colormap.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>

#include "core/target_clones.h"
#include "core/value_minmax.h"

namespace swarf::cli {
namespace {

// Piecewise linear through equally spaced stops.
Rgb Ramp(std::span<const Rgb> stops, double t) {
  if (!(t > 0)) return stops.front();  // also NaN
  if (t >= 1) return stops.back();
  const double f = t * (stops.size() - 1);
  const size_t k = static_cast<size_t>(f);
  const double u = f - k;
  const Rgb a = stops[k], b = stops[k + 1];
  auto mix = [u](uint8_t p, uint8_t q) {
    return static_cast<uint8_t>(std::lround(p + (q - p) * u));
  };
  return {mix(a.r, b.r), mix(a.g, b.g), mix(a.b, b.b)};
}

constexpr Rgb kViridis[] = {
    {68, 1, 84},    {72, 36, 117},  {65, 68, 135},   {53, 95, 141},
    {42, 120, 142}, {33, 145, 140}, {34, 168, 132},  {68, 191, 112},
    {122, 209, 81}, {189, 223, 38}, {253, 231, 37},
};

constexpr Rgb kHeight[] = {
    {14, 28, 84}, {28, 84, 164}, {52, 150, 180}, {150, 205, 175},
    {244, 238, 210},
};

constexpr Rgb kAngle[] = {
    {255, 236, 40}, {255, 150, 0}, {230, 30, 20}, {200, 0, 170},
};

}  // namespace

Rgb Viridis(double t) { return Ramp(kViridis, t); }

Rgb HeightTint(double t) { return Ramp(kHeight, t); }

Rgb AngleColor(double angle_deg) {
  return Ramp(kAngle, angle_deg / kAngleScaleMaxDeg);
}

namespace {

// std::lround(v) as GCC expands it with -fno-math-errno (v plus the largest
// double below 0.5, with v's sign, truncated), as a double: exact for
// |v| < 2^52, and in vector lanes.
[[gnu::always_inline]] inline double RoundHalfAway(double v) {
  return std::trunc(v + std::copysign(0.49999999999999994, v));
}

// kHeight's stops per channel: stop k (of the four that start a segment)
// and the step to stop k + 1, as Ramp's mix takes them.
struct RampLanes {
  double p[3][4], d[3][4];
};
constexpr RampLanes HeightLanes() {
  RampLanes l{};
  for (int k = 0; k < 4; ++k) {
    const Rgb a = kHeight[k], b = kHeight[k + 1];
    l.p[0][k] = a.r;
    l.p[1][k] = a.g;
    l.p[2][k] = a.b;
    l.d[0][k] = b.r - a.r;
    l.d[1][k] = b.g - a.g;
    l.d[2][k] = b.b - a.b;
  }
  return l;
}
static_assert(std::size(kHeight) == 5);
constexpr RampLanes kHeightLanes = HeightLanes();

// The channels of n <= kRowChunk pixels of ShadedTintRow, one array each.
constexpr int32_t kRowChunk = 256;
SWARF_TARGET_CLONES
void ShadedTintChannels(const float* __restrict height,
                        const float* __restrict shade, int32_t n, double depth,
                        int32_t* __restrict out_r, int32_t* __restrict out_g,
                        int32_t* __restrict out_b) {
  constexpr double kLastStop = std::size(kHeight) - 1;
  // Channel c of a pixel: its tint (segment k's mix, picked by selects,
  // not loaded by index: every lane takes one, k in range whatever t is) or
  // the stock's, then Scale's rounding and clamp.
  auto channel = [](int c, bool cut, double k, double u, double stock,
                    double s) {
    const double* p = kHeightLanes.p[c];
    const double* d = kHeightLanes.d[c];
    const double pk = k < 1 ? p[0] : k < 2 ? p[1] : k < 3 ? p[2] : p[3];
    const double dk = k < 1 ? d[0] : k < 2 ? d[1] : k < 3 ? d[2] : d[3];
    const double tint = RoundHalfAway(pk + dk * u);
    const double v = (cut ? tint : stock) * s;
    return static_cast<int32_t>(MinOf(MaxOf(RoundHalfAway(v), 0.0), 255.0));
  };
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    const double h = height[q];
    const double t = 1 + h / depth;
    // Ramp's cases as one segment: t <= 0 (or NaN) is segment 0 at u = 0,
    // t >= 1 segment 3 at u = 1 (p + (q - p) * 1 is q, exactly).
    const double f = t > 0 ? (t < 1 ? t * kLastStop : kLastStop) : 0.0;
    const double k = static_cast<double>(static_cast<int32_t>(MinOf(f, 3.0)));
    const double u = f - k;
    const double sh = shade[q];
    const double s =
        std::fabs(sh) <= std::numeric_limits<double>::max() ? sh : 1.0;
    const bool cut = h < 0;
    out_r[q] = channel(0, cut, k, u, kStockColor.r, s);
    out_g[q] = channel(1, cut, k, u, kStockColor.g, s);
    out_b[q] = channel(2, cut, k, u, kStockColor.b, s);
  }
}

}  // namespace

void ShadedTintRow(const float* height, const float* shade, int32_t n,
                   double depth, uint8_t* rgb) {
  int32_t r[kRowChunk], g[kRowChunk], b[kRowChunk];
  for (int32_t q0 = 0; q0 < n; q0 += kRowChunk) {
    const int32_t m = std::min(kRowChunk, n - q0);
    ShadedTintChannels(height + q0, shade + q0, m, depth, r, g, b);
    uint8_t* const row = rgb + 3 * static_cast<ptrdiff_t>(q0);
    for (int32_t q = 0; q < m; ++q) {
      row[3 * q] = static_cast<uint8_t>(r[q]);
      row[3 * q + 1] = static_cast<uint8_t>(g[q]);
      row[3 * q + 2] = static_cast<uint8_t>(b[q]);
    }
  }
}

Rgb Scale(Rgb c, double factor) {
  auto s = [factor](uint8_t v) {
    return static_cast<uint8_t>(std::clamp(std::lround(v * factor), 0L, 255L));
  };
  return {s(c.r), s(c.g), s(c.b)};
}

}  // namespace swarf::cli
