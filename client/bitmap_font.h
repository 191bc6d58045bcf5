// A tiny built-in 5 x 7 bitmap font (with 2 rows of descenders) for the
// labels of the output pictures: digits, lower-case letters (upper case is
// drawn as lower case) and " .,:;-+=()/<>%|_*'". Other characters are drawn
// as a hollow box.
#ifndef SWARF_CLIENT_BITMAP_FONT_H_
#define SWARF_CLIENT_BITMAP_FONT_H_

#include <string_view>

#include "client/png_image.h"

namespace swarf::cli {

// Glyph cell in font pixels: 5 wide plus 1 of spacing; 7 above the baseline
// plus 2 below (descenders).
inline constexpr int kGlyphWidth = 5;
inline constexpr int kGlyphAdvance = 6;
inline constexpr int kGlyphAscent = 7;
inline constexpr int kGlyphHeight = 9;

// Whether `c` has a glyph of its own (not the box).
bool HasGlyph(char c);

// Width in image pixels of `text` at integer `scale` >= 1 (no trailing
// spacing).
int TextWidth(std::string_view text, int scale);

// Draws `text` with its top-left cell corner at (x, y) (the baseline is at
// y + kGlyphAscent * scale), clipped to the image. Each font pixel is a
// scale x scale block.
void DrawText(Image& image, int x, int y, std::string_view text, Rgb color,
              int scale);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_BITMAP_FONT_H_
