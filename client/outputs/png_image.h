// 8-bit RGB / RGBA raster images and their PNG files (written with zlib,
// read with libpng).
#ifndef SWARF_CLIENT_PNG_IMAGE_H_
#define SWARF_CLIENT_PNG_IMAGE_H_

#include <algorithm>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "core/unfilled_vector.h"

namespace swarf::cli {

struct Rgb {
  uint8_t r = 0, g = 0, b = 0;
  friend bool operator==(const Rgb&, const Rgb&) = default;
};

// Row-major pixels, row 0 at the top, `channels` bytes per pixel (3: RGB,
// 4: RGBA, alpha 255 = opaque). Coordinates passed to the accessors must lie
// inside the image.
class Image {
 public:
  Image() = default;
  // width, height >= 0; channels 3 or 4 (others are treated as 3). Every
  // pixel is `fill`, opaque.
  Image(int width, int height, int channels = 3, Rgb fill = {});

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  bool empty() const { return width_ == 0 || height_ == 0; }

  uint8_t* row(int y) { return pixels_.data() + Offset(0, y); }
  const uint8_t* row(int y) const { return pixels_.data() + Offset(0, y); }
  Rgb Get(int x, int y) const {
    const uint8_t* p = &pixels_[Offset(x, y)];
    return {p[0], p[1], p[2]};
  }
  uint8_t Alpha(int x, int y) const {
    return channels_ == 4 ? pixels_[Offset(x, y) + 3] : 255;
  }
  void Set(int x, int y, Rgb c) {
    uint8_t* p = &pixels_[Offset(x, y)];
    p[0] = c.r;
    p[1] = c.g;
    p[2] = c.b;
  }
  // Mixes `c` over the pixel with weight a in [0, 1] (clamped). Inline:
  // strokes call it per pixel.
  void Blend(int x, int y, Rgb c, double a) {
    a = std::clamp(a, 0.0, 1.0);
    uint8_t* p = &pixels_[Offset(x, y)];
    const uint8_t src[3] = {c.r, c.g, c.b};
    for (int k = 0; k < 3; ++k) {
      p[k] = static_cast<uint8_t>(p[k] + (src[k] - p[k]) * a + 0.5);
    }
  }
  // Fills [x0, x1) x [y0, y1), clipped to the image.
  void FillRect(int x0, int y0, int x1, int y1, Rgb c);

  UnfilledVector<uint8_t>& pixels() { return pixels_; }
  const UnfilledVector<uint8_t>& pixels() const { return pixels_; }

 private:
  size_t Offset(int x, int y) const {
    return (static_cast<size_t>(y) * width_ + x) * channels_;
  }
  int width_ = 0, height_ = 0, channels_ = 3;
  UnfilledVector<uint8_t> pixels_;
};

// Writes `image` as an 8-bit PNG (RGB or RGBA as the image has), replacing
// the file: every row Paeth-filtered, deflated (zlib level 3, Z_RLE) in
// blocks of kPngRowBlock rows on every thread of ThreadPool::Default().
// InvalidArgument for an empty image or pixel buffer of the wrong size;
// PermissionDenied (cannot open) or Internal (zlib or I/O failure) naming
// the path otherwise, and a partial file is removed.
absl::Status WritePng(const Image& image, const std::string& path);

// Writes a width x height 8-bit RGB PNG: `row(y, out)` fills the 3 * width
// bytes of row y, once for each y, from several threads at once (rows are
// made a few blocks of kPngRowBlock a thread at a time, then filtered and
// deflated a block a thread). The same bytes as WritePng of the image those
// rows make; errors as WritePng's. Holds those blocks, not the image.
inline constexpr int kPngRowBlock = 64;
absl::Status WritePngRows(int width, int height,
                          const std::function<void(int y, uint8_t* out)>& row,
                          const std::string& path);

// Reads any PNG libpng decodes, converted to 8-bit RGB (no alpha in the
// file) or RGBA. For tests and tools.
absl::StatusOr<Image> ReadPng(const std::string& path);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_PNG_IMAGE_H_
