// The labels of the output pictures: anti-aliased text drawn with cairo in
// DejaVu Sans (Debian's fonts-dejavu-core, found through fontconfig; any
// sans-serif face if it is missing).
//
// Sizes are in text units times an integer `scale` (pixels per unit): a line
// is kGlyphHeight units high with its baseline kGlyphAscent units below its
// top; digits are about 7 units high. Thread-safe (each call has its own
// cairo surface).
#ifndef SWARF_CLIENT_TEXT_H_
#define SWARF_CLIENT_TEXT_H_

#include <string_view>

#include "client/outputs/png_image.h"

namespace swarf::cli {

inline constexpr int kGlyphAscent = 7;
inline constexpr int kGlyphHeight = 9;

// Advance width in pixels of `text` (UTF-8) at `scale` >= 1.
int TextWidth(std::string_view text, int scale);

// Draws `text` with the top of its line at y and its start at x (the
// baseline at y + kGlyphAscent * scale), blended over the image by the
// glyphs' coverage, clipped to the image.
void DrawText(Image& image, int x, int y, std::string_view text, Rgb color,
              int scale);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_TEXT_H_
