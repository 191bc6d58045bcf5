#include "client/outputs/colormap.h"

#include <algorithm>
#include <cmath>
#include <span>

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

Rgb Scale(Rgb c, double factor) {
  auto s = [factor](uint8_t v) {
    return static_cast<uint8_t>(std::clamp(std::lround(v * factor), 0L, 255L));
  };
  return {s(c.r), s(c.g), s(c.b)};
}

}  // namespace swarf::cli
