// Colour scales shared by the output pictures and meshes.
#ifndef SWARF_CLIENT_COLORMAP_H_
#define SWARF_CLIENT_COLORMAP_H_

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

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_COLORMAP_H_
