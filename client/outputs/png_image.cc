#include "client/outputs/png_image.h"

#include <png.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "core/thread_pool.h"

namespace swarf::cli {

Image::Image(int width, int height, int channels, Rgb fill)
    : width_(std::max(width, 0)),
      height_(std::max(height, 0)),
      channels_(channels == 4 ? 4 : 3),
      pixels_(static_cast<size_t>(width_) * height_ * channels_) {
  for (size_t k = 0; k < pixels_.size(); k += channels_) {
    pixels_[k] = fill.r;
    pixels_[k + 1] = fill.g;
    pixels_[k + 2] = fill.b;
    if (channels_ == 4) pixels_[k + 3] = 255;
  }
}

void Image::FillRect(int x0, int y0, int x1, int y1, Rgb c) {
  x0 = std::max(x0, 0);
  y0 = std::max(y0, 0);
  x1 = std::min(x1, width_);
  y1 = std::min(y1, height_);
  for (int y = y0; y < y1; ++y) {
    for (int x = x0; x < x1; ++x) Set(x, y, c);
  }
}

namespace {

// libpng reports errors through a callback that must not return; it jumps
// back to the setjmp in WritePng with the message kept here.
struct PngError {
  char message[256] = "";
};

void OnPngError(png_structp png, png_const_charp msg) {
  auto* err = static_cast<PngError*>(png_get_error_ptr(png));
  std::snprintf(err->message, sizeof err->message, "%s", msg);
  png_longjmp(png, 1);
}

void OnPngWarning(png_structp, png_const_charp) {}

// Everything between setjmp and the last libpng call lives in this function
// with only trivially destructible locals, so a longjmp skips no destructor.
// `rows` null: `next` gives each row (into `buffer`) instead.
bool WritePngFile(int width, int height, int channels, png_bytep* rows,
                  const std::function<void(int, uint8_t*)>* next,
                  png_bytep buffer, std::FILE* f, PngError* err) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, err,
                                            OnPngError, OnPngWarning);
  if (png == nullptr) {
    std::snprintf(err->message, sizeof err->message, "out of memory");
    return false;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr || setjmp(png_jmpbuf(png))) {
    if (err->message[0] == '\0') {
      std::snprintf(err->message, sizeof err->message, "out of memory");
    }
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_init_io(png, f);
  png_set_IHDR(png, info, width, height, 8,
               channels == 4 ? PNG_COLOR_TYPE_RGB_ALPHA : PNG_COLOR_TYPE_RGB,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  // Shaded reliefs compress poorly whatever the effort. Paeth rows coded as
  // runs (Z_RLE, no match search) take 30-40% less time than deflate at
  // level 3 and come out within a few percent of its size (smaller for
  // relief.png and error.png, 3% larger for marks.png on cameo.nc).
  png_set_compression_level(png, 3);
  png_set_compression_strategy(png, Z_RLE);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_PAETH);
  png_write_info(png, info);
  if (rows != nullptr) {
    png_write_image(png, rows);
  } else {
    // png_write_image writes row after row just so (no interlacing). A
    // block of rows is made on every thread (colouring rows one by one was
    // relief.png's longest serial step), then compressed in order.
    const size_t stride = static_cast<size_t>(width) * channels;
    for (int y0 = 0; y0 < height; y0 += kPngRowBlock) {
      const int n = std::min(kPngRowBlock, height - y0);
      ThreadPool::Default().ParallelFor(n, [&](int64_t k) {
        (*next)(y0 + static_cast<int>(k), buffer + k * stride);
      });
      for (int k = 0; k < n; ++k) png_write_row(png, buffer + k * stride);
    }
  }
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return true;
}

// WritePngFile to `path`: a file that cannot be written whole is removed.
absl::Status WritePngPath(int width, int height, int channels, png_bytep* rows,
                          const std::function<void(int, uint8_t*)>* row,
                          uint8_t* buffer, const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) {
    return absl::PermissionDeniedError(
        absl::StrCat("cannot open ", path, ": ", std::strerror(errno)));
  }
  PngError err;
  const bool ok =
      WritePngFile(width, height, channels, rows, row, buffer, f, &err);
  const bool io_error = std::ferror(f) != 0;
  const bool close_failed = std::fclose(f) != 0;
  if (!ok || io_error || close_failed) {
    std::remove(path.c_str());
    return absl::InternalError(absl::StrCat(
        "writing ", path,
        " failed: ", err.message[0] != '\0' ? err.message : "I/O error"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status WritePng(const Image& image, const std::string& path) {
  if (image.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot write an empty image to ", path));
  }
  if (image.pixels().size() !=
      static_cast<size_t>(image.width()) * image.height() * image.channels()) {
    return absl::InvalidArgumentError("image pixel buffer has the wrong size");
  }
  std::vector<png_bytep> rows(image.height());
  for (int y = 0; y < image.height(); ++y) {
    rows[y] = const_cast<png_bytep>(image.row(y));
  }
  return WritePngPath(image.width(), image.height(), image.channels(),
                      rows.data(), nullptr, nullptr, path);
}

absl::Status WritePngRows(int width, int height,
                          const std::function<void(int y, uint8_t* out)>& row,
                          const std::string& path) {
  if (width <= 0 || height <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot write an empty image to ", path));
  }
  std::vector<uint8_t> buffer(static_cast<size_t>(width) * 3 *
                              std::min(height, kPngRowBlock));
  return WritePngPath(width, height, 3, nullptr, &row, buffer.data(), path);
}

absl::StatusOr<Image> ReadPng(const std::string& path) {
  png_image png;
  std::memset(&png, 0, sizeof png);
  png.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&png, path.c_str())) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot read PNG ", path, ": ", png.message));
  }
  const bool alpha = (png.format & PNG_FORMAT_FLAG_ALPHA) != 0;
  png.format = alpha ? PNG_FORMAT_RGBA : PNG_FORMAT_RGB;
  Image image(png.width, png.height, alpha ? 4 : 3);
  if (!png_image_finish_read(&png, nullptr, image.pixels().data(), 0,
                             nullptr)) {
    png_image_free(&png);
    return absl::InvalidArgumentError(
        absl::StrCat("cannot decode PNG ", path, ": ", png.message));
  }
  return image;
}

}  // namespace swarf::cli
