#include "client/outputs/text.h"

#include <cairo.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace swarf::cli {
namespace {

// Em size in pixels per unit of scale: DejaVu Sans digits are 0.73 em high,
// so they come out about kGlyphAscent units high.
constexpr double kEmPerScale = 9.6;

void SetFont(cairo_t* cr, int scale) {
  cairo_select_font_face(cr, "DejaVu Sans", CAIRO_FONT_SLANT_NORMAL,
                         CAIRO_FONT_WEIGHT_NORMAL);
  cairo_set_font_size(cr, kEmPerScale * scale);
}

}  // namespace

int TextWidth(std::string_view text, int scale) {
  if (text.empty()) return 0;
  cairo_surface_t* s = cairo_image_surface_create(CAIRO_FORMAT_A8, 1, 1);
  cairo_t* cr = cairo_create(s);
  SetFont(cr, scale);
  const std::string t(text);
  cairo_text_extents_t e;
  cairo_text_extents(cr, t.c_str(), &e);
  cairo_destroy(cr);
  cairo_surface_destroy(s);
  return static_cast<int>(std::ceil(std::max(e.x_advance, e.x_bearing + e.width)));
}

void DrawText(Image& image, int x, int y, std::string_view text, Rgb color,
              int scale) {
  if (text.empty()) return;
  // Coverage only (A8), then blended: works for RGB and RGBA images alike.
  const int pad = scale;
  const int w = TextWidth(text, scale) + 2 * pad;
  const int h = kGlyphHeight * scale + 2 * pad;
  cairo_surface_t* s = cairo_image_surface_create(CAIRO_FORMAT_A8, w, h);
  cairo_t* cr = cairo_create(s);
  SetFont(cr, scale);
  cairo_move_to(cr, pad, pad + kGlyphAscent * scale);
  const std::string t(text);
  cairo_show_text(cr, t.c_str());
  cairo_surface_flush(s);
  const unsigned char* data = cairo_image_surface_get_data(s);
  const int stride = cairo_image_surface_get_stride(s);
  for (int py = 0; py < h; ++py) {
    const int iy = y - pad + py;
    if (iy < 0 || iy >= image.height()) continue;
    for (int px = 0; px < w; ++px) {
      const int ix = x - pad + px;
      const unsigned char a = data[py * stride + px];
      if (a == 0 || ix < 0 || ix >= image.width()) continue;
      image.Blend(ix, iy, color, a / 255.0);
    }
  }
  cairo_destroy(cr);
  cairo_surface_destroy(s);
}

}  // namespace swarf::cli
