// Colour scales shared by the output pictures and meshes.
#ifndef SWARF_CLIENT_COLORMAP_H_
#define SWARF_CLIENT_COLORMAP_H_

#include <cstdint>

#include "client/outputs/png_image.h"

namespace swarf::cli {

// Untouched stock top in the relief and mesh colours: neutral grey, outside
// the height tint's hues.
inline constexpr Rgb kStockColor = {196, 196, 196};

// Perceptual scale (matplotlib's viridis, piecewise linear through 11 of its
// entries): t = 0 dark purple ... 1 yellow; t is clamped to [0, 1].
Rgb Viridis(double t);

// Height tint of machined surface: t = 0 at the lowest point (dark blue)
// through blue and teal to pale cream at t = 1 (just below the stock top).
Rgb HeightTint(double t);

// Angle between the two surfaces' normals at a cutting mark, as sharpness:
// yellow (shallow) through orange and red to magenta at kAngleScaleMaxDeg
// and above (a wall meeting the stock top is about 90 degrees).
inline constexpr double kAngleScaleMaxDeg = 90;
Rgb AngleColor(double angle_deg);

// `c` times `factor` per channel, rounded and clamped to [0, 255].
Rgb Scale(Rgb c, double factor);

// A relief row: for q < n, rgb[3 q .. 3 q + 2] = Scale(base, s) with base
// HeightTint(1 + height[q] / depth) where height[q] < 0, else kStockColor,
// and s shade[q] where finite, else 1. The same bytes as those calls
// wherever a channel times s is below 2^63 in magnitude (relief shades are
// about 0.25 to 1.3), a row at a time (vectorized: one pixel at a time, the
// calls were a tenth of relief.png's and marks.png's time).
void ShadedTintRow(const float* height, const float* shade, int32_t n,
                   double depth, uint8_t* rgb);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_COLORMAP_H_
