#include "client/outputs/png_image.h"

#include <png.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "core/thread_pool.h"

namespace swarf::cli {

Image::Image(int width, int height, int channels, Rgb fill)
    : width_(std::max(width, 0)),
      height_(std::max(height, 0)),
      channels_(channels == 4 ? 4 : 3),
      pixels_(static_cast<size_t>(width_) * height_ * channels_) {
  // Filled (and faulted in) a band of rows a task: a picture of 4096 x 4096
  // pixels is 48 MiB, which one thread zeroed and then filled.
  const size_t row_bytes = static_cast<size_t>(width_) * channels_;
  constexpr size_t kBandBytes = size_t{1} << 20;
  const int band_rows = static_cast<int>(
      std::max<size_t>(1, kBandBytes / std::max<size_t>(row_bytes, 1)));
  const int bands = (height_ + band_rows - 1) / band_rows;
  auto fill_band = [&](int64_t b) {
    const size_t k1 =
        std::min<size_t>(pixels_.size(), (b + 1) * band_rows * row_bytes);
    for (size_t k = b * band_rows * row_bytes; k < k1; k += channels_) {
      pixels_[k] = fill.r;
      pixels_[k + 1] = fill.g;
      pixels_[k + 2] = fill.b;
      if (channels_ == 4) pixels_[k + 3] = 255;
    }
  };
  if (bands > 1) {
    ThreadPool::Default().ParallelFor(bands, fill_band);
  } else if (bands == 1) {
    fill_band(0);
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

// The PNG file is written here around zlib rather than by libpng, which
// filters and deflates the whole picture on one thread: on many cores that
// was the pictures' longest serial step. Blocks of kPngRowBlock rows are
// filtered and deflated on every thread, each as a piece of the one zlib
// stream that ends in a sync flush (a byte boundary, as pigz does), and
// written in order.

constexpr uint8_t kPngSignature[8] = {0x89, 'P',  'N',  'G',
                                      '\r', '\n', 0x1a, '\n'};
// Paeth-filtered rows coded as runs (Z_RLE, no match search) take 30-40%
// less time than deflate at level 3 and come out within a few percent of
// its size (smaller for relief.png and error.png, 3% larger for marks.png on
// cameo.nc). With Z_RLE, matches reach back one pixel at most: a block
// loses nothing by not seeing the previous one.
constexpr int kZlibLevel = 3;
constexpr uint8_t kPaethFilter = 4;

void PutU32(uint32_t v, uint8_t* out) {
  out[0] = static_cast<uint8_t>(v >> 24);
  out[1] = static_cast<uint8_t>(v >> 16);
  out[2] = static_cast<uint8_t>(v >> 8);
  out[3] = static_cast<uint8_t>(v);
}

// Appends a chunk: its length, type, data and the CRC of type and data.
void AppendChunk(const char type[4], const uint8_t* data, size_t n,
                 std::vector<uint8_t>* out) {
  uint8_t head[8];
  PutU32(static_cast<uint32_t>(n), head);
  std::memcpy(head + 4, type, 4);
  out->insert(out->end(), head, head + 8);
  if (n > 0) out->insert(out->end(), data, data + n);
  uLong crc = crc32(0, head + 4, 4);
  // (crc32_z of a null buffer returns the initial value, not `crc`.)
  if (n > 0) crc = crc32_z(crc, data, n);
  uint8_t tail[4];
  PutU32(static_cast<uint32_t>(crc), tail);
  out->insert(out->end(), tail, tail + 4);
}

uint8_t Paeth(int a, int b, int c) {
  const int p = a + b - c;
  const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return static_cast<uint8_t>(a);
  return static_cast<uint8_t>(pb <= pc ? b : c);
}

// Row `row` (stride bytes, bpp bytes a pixel) filtered with Paeth against
// `prev` (the row above; null for the first row: zeros), with its filter
// type byte first: stride + 1 bytes to `out`.
void PaethRow(const uint8_t* row, const uint8_t* prev, size_t stride, int bpp,
              uint8_t* out) {
  out[0] = kPaethFilter;
  ++out;
  for (size_t i = 0; i < stride; ++i) {
    const int a = i >= static_cast<size_t>(bpp) ? row[i - bpp] : 0;
    const int b = prev != nullptr ? prev[i] : 0;
    const int c =
        prev != nullptr && i >= static_cast<size_t>(bpp) ? prev[i - bpp] : 0;
    out[i] = static_cast<uint8_t>(row[i] - Paeth(a, b, c));
  }
}

// Deflates `n` bytes as a piece of a raw deflate stream: ended by a sync
// flush, or by the stream's end when `last`. False when zlib fails.
bool DeflatePiece(const uint8_t* data, size_t n, bool last,
                  std::vector<uint8_t>* out) {
  z_stream z{};
  if (deflateInit2(&z, kZlibLevel, Z_DEFLATED, -15, 8, Z_RLE) != Z_OK) {
    return false;
  }
  // deflateBound covers the stream's end; a sync flush adds 5 bytes more.
  out->resize(deflateBound(&z, n) + 16);
  z.next_in = const_cast<uint8_t*>(data);
  z.avail_in = static_cast<uInt>(n);
  z.next_out = out->data();
  z.avail_out = static_cast<uInt>(out->size());
  const int rc = deflate(&z, last ? Z_FINISH : Z_SYNC_FLUSH);
  const bool ok = (last ? rc == Z_STREAM_END : rc == Z_OK) && z.avail_in == 0;
  out->resize(out->size() - z.avail_out);
  deflateEnd(&z);
  return ok;
}

// A block's rows, filtered and deflated: its IDAT chunk (whole, CRC
// included) and the Adler-32 of its filtered bytes.
struct PngPiece {
  std::vector<uint8_t> chunk;
  uLong adler = 1;
  size_t filtered_bytes = 0;
  bool ok = false;
};

bool WriteAll(std::FILE* f, const std::vector<uint8_t>& bytes) {
  return bytes.empty() ||
         std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size();
}

// Writes the PNG of width x height pixels of `channels` (3 or 4) bytes, row
// y made by row(y, out) on any thread. False (with `error` set) when zlib
// fails or a write does.
bool WritePngFile(int width, int height, int channels,
                  const std::function<void(int, uint8_t*)>& row, std::FILE* f,
                  std::string* error) {
  const size_t stride = static_cast<size_t>(width) * channels;
  std::vector<uint8_t> head(kPngSignature, kPngSignature + 8);
  uint8_t ihdr[13];
  PutU32(static_cast<uint32_t>(width), ihdr);
  PutU32(static_cast<uint32_t>(height), ihdr + 4);
  ihdr[8] = 8;                      // bit depth
  ihdr[9] = channels == 4 ? 6 : 2;  // RGBA or RGB
  ihdr[10] = ihdr[11] = ihdr[12] =
      0;  // deflate, adaptive filtering, no interlace
  AppendChunk("IHDR", ihdr, sizeof ihdr, &head);
  // The zlib header: deflate with a 32 KiB window, FLEVEL 0 (what zlib
  // writes for Z_RLE), the check bits making it a multiple of 31.
  const uint8_t zlib_head[2] = {0x78, 0x01};
  AppendChunk("IDAT", zlib_head, 2, &head);
  if (!WriteAll(f, head)) {
    *error = "I/O error";
    return false;
  }

  ThreadPool& pool = ThreadPool::Default();
  const int blocks = (height + kPngRowBlock - 1) / kPngRowBlock;
  // Blocks made at once: enough for every thread, few enough that the rows
  // held stay small (2 x 64 rows a thread).
  const int group = std::max(2, 2 * pool.size());
  // The group's raw rows, after the row above its first (the last row of
  // the group before), and each block's filtered rows.
  std::vector<uint8_t> raw((static_cast<size_t>(group) * kPngRowBlock + 1) *
                           stride);
  std::vector<std::vector<uint8_t>> filtered(group);
  std::vector<PngPiece> pieces(group);
  uLong adler = adler32(0, nullptr, 0);
  for (int b0 = 0; b0 < blocks; b0 += group) {
    const int nb = std::min(group, blocks - b0);
    const int y0 = b0 * kPngRowBlock;
    const int y1 = std::min(height, (b0 + nb) * kPngRowBlock);
    uint8_t* rows = raw.data() + stride;  // row y0; the row above before it
    pool.ParallelFor(y1 - y0, [&](int64_t k) {
      row(y0 + static_cast<int>(k), rows + k * stride);
    });
    pool.ParallelFor(nb, [&](int64_t k) {
      const int r0 = static_cast<int>(k) * kPngRowBlock;
      const int r1 = std::min(y1 - y0, r0 + kPngRowBlock);
      std::vector<uint8_t>& fb = filtered[k];
      fb.resize(static_cast<size_t>(r1 - r0) * (stride + 1));
      for (int r = r0; r < r1; ++r) {
        // The row above: before `rows` for r = 0 (the last row of the
        // group before), so a signed offset (a size_t one wraps).
        const uint8_t* prev =
            y0 + r > 0 ? rows + (static_cast<ptrdiff_t>(r) - 1) *
                                    static_cast<ptrdiff_t>(stride)
                       : nullptr;
        PaethRow(rows + r * stride, prev, stride, channels,
                 fb.data() + (r - r0) * (stride + 1));
      }
      PngPiece& piece = pieces[k];
      std::vector<uint8_t> deflated;
      piece.ok =
          DeflatePiece(fb.data(), fb.size(),
                       b0 + static_cast<int>(k) == blocks - 1, &deflated);
      piece.adler = adler32_z(adler32(0, nullptr, 0), fb.data(), fb.size());
      piece.filtered_bytes = fb.size();
      piece.chunk.clear();
      AppendChunk("IDAT", deflated.data(), deflated.size(), &piece.chunk);
    });
    for (int k = 0; k < nb; ++k) {
      if (!pieces[k].ok) {
        *error = "zlib failed to deflate";
        return false;
      }
      if (!WriteAll(f, pieces[k].chunk)) {
        *error = "I/O error";
        return false;
      }
      adler = adler32_combine(adler, pieces[k].adler,
                              static_cast<z_off_t>(pieces[k].filtered_bytes));
    }
    // The next group's first row is filtered against this one's last.
    std::memcpy(raw.data(), rows + static_cast<size_t>(y1 - y0 - 1) * stride,
                stride);
  }
  std::vector<uint8_t> tail;
  uint8_t adler_bytes[4];
  PutU32(static_cast<uint32_t>(adler), adler_bytes);
  AppendChunk("IDAT", adler_bytes, 4, &tail);
  AppendChunk("IEND", nullptr, 0, &tail);
  if (!WriteAll(f, tail)) {
    *error = "I/O error";
    return false;
  }
  return true;
}

// WritePngFile to `path`: a file that cannot be written whole is removed.
absl::Status WritePngPath(int width, int height, int channels,
                          const std::function<void(int, uint8_t*)>& row,
                          const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) {
    return absl::PermissionDeniedError(
        absl::StrCat("cannot open ", path, ": ", std::strerror(errno)));
  }
  std::string error;
  const bool ok = WritePngFile(width, height, channels, row, f, &error);
  const bool io_error = std::ferror(f) != 0;
  const bool close_failed = std::fclose(f) != 0;
  if (!ok || io_error || close_failed) {
    std::remove(path.c_str());
    return absl::InternalError(absl::StrCat(
        "writing ", path, " failed: ", !error.empty() ? error : "I/O error"));
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
  const size_t stride = static_cast<size_t>(image.width()) * image.channels();
  return WritePngPath(
      image.width(), image.height(), image.channels(),
      [&](int y, uint8_t* out) { std::memcpy(out, image.row(y), stride); },
      path);
}

absl::Status WritePngRows(int width, int height,
                          const std::function<void(int y, uint8_t* out)>& row,
                          const std::string& path) {
  if (width <= 0 || height <= 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot write an empty image to ", path));
  }
  return WritePngPath(width, height, 3, row, path);
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
