// Output writers of `swarf run`: every file is written to a temporary
// directory and read back (PNG decoded, STL parsed, VRML/SVG/JSON scanned).
#include <stdlib.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/outputs/colormap.h"
#include "client/outputs/file_writer.h"
#include "client/outputs/json_writer.h"
#include "client/outputs/marks_files.h"
#include "client/outputs/pictures.h"
#include "client/outputs/png_image.h"
#include "client/outputs/run_outputs.h"
#include "client/outputs/surface_grid.h"
#include "client/outputs/surface_mesh.h"
#include "client/outputs/text.h"
#include "core/cutting_marks.h"
#include "core/valuation.h"
#include "core/workpiece.h"
#include "google/protobuf/struct.pb.h"
#include "google/protobuf/util/json_util.h"
#include "gtest/gtest.h"

namespace swarf::cli {
namespace {

constexpr SchemeKind kSchemes[] = {SchemeKind::kZmap, SchemeKind::kTaylor};

// 50 x 30 mm, top at 10, 0.5 mm spacing: 101 x 61 nodes.
StockSpec TestStock() { return StockSpec{0, 0, 50, 30, 10, 100, 60}; }

// Two overlapping parallel grooves in the north half (a crease between
// them and edges against the top) and a crater in the south-west.
std::vector<Move> TestMoves() {
  return {
      {{5, 22, 8.5}, {45, 22, 8.5}, 2},
      {{5, 23.5, 8.5}, {45, 23.5, 8.5}, 2},
      {{15, 8, 8}, {15, 8, 8}, 3},
  };
}

std::unique_ptr<Workpiece> Cut(SchemeKind scheme,
                               const StockSpec& spec = TestStock(),
                               const std::vector<Move>& moves = TestMoves()) {
  auto wp = Workpiece::Create(spec, scheme);
  EXPECT_TRUE(wp.ok()) << wp.status();
  auto applied = (*wp)->Apply(moves);
  EXPECT_TRUE(applied.ok()) << applied.status();
  return *std::move(wp);
}

SurfaceGrid GridOf(const Workpiece& wp) {
  auto g = SurfaceGrid::FromWorkpiece(wp);
  EXPECT_TRUE(g.ok()) << g.status();
  return *std::move(g);
}

// A fresh directory, removed with its files at the end of the test.
class TempDir {
 public:
  TempDir() {
    std::string tmpl =
        (std::filesystem::temp_directory_path() / "swarf_outputs_XXXXXX")
            .string();
    EXPECT_NE(mkdtemp(tmpl.data()), nullptr);
    path_ = tmpl;
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string File(const std::string& name) const { return path_ + "/" + name; }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

int Luma(Rgb c) { return (299 * c.r + 587 * c.g + 114 * c.b) / 1000; }

int MaxChannelDiff(Rgb a, Rgb b) {
  return std::max({std::abs(a.r - b.r), std::abs(a.g - b.g),
                   std::abs(a.b - b.b)});
}

size_t CountOf(const std::string& s, const std::string& needle) {
  size_t n = 0;
  for (size_t p = s.find(needle); p != std::string::npos;
       p = s.find(needle, p + needle.size())) {
    ++n;
  }
  return n;
}

// ------------------------------------------------------------ SurfaceGrid

TEST(SurfaceGridTest, MatchesTheWorkpieceBitForBit) {
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(GetScheme(scheme).name());
    auto wp = Cut(scheme);
    const SurfaceGrid g = GridOf(*wp);
    ASSERT_TRUE(g.Validate().ok());
    EXPECT_EQ(g.scheme, scheme);
    int64_t cut = 0;
    for (int32_t j = 0; j < g.nodes_y(); ++j) {
      for (int32_t i = 0; i < g.nodes_x(); ++i) {
        const NodeValue v = wp->Node(i, j);
        ASSERT_EQ(g.jet(i, j).w, v.jet.w) << i << "," << j;
        ASSERT_EQ(g.jet(i, j).wx, v.jet.wx);
        ASSERT_EQ(g.jet(i, j).wyy, v.jet.wyy);
        ASSERT_EQ(g.owner(i, j), v.owner);
        cut += v.owner >= 0;
      }
    }
    EXPECT_GT(cut, 100);
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> ux(-1, 51), uy(-1, 31);
    for (int k = 0; k < 5000; ++k) {
      const double x = ux(rng), y = uy(rng);
      ASSERT_EQ(g.Height(x, y), wp->Reconstruct(x, y)) << x << "," << y;
      double gx, gy, wx, wy;
      g.Gradient(x, y, &gx, &gy);
      wp->ReconstructGradient(x, y, &wx, &wy);
      ASSERT_EQ(gx, wx);
      ASSERT_EQ(gy, wy);
    }
    // Node positions themselves.
    EXPECT_EQ(g.Height(25, 22), wp->Reconstruct(25, 22));
    EXPECT_LT(g.Height(25, 22), 8.6);
  }
}

// A band reset is untouched stock in every node, whatever it held, when it
// keeps its storage, grows past what was reserved or shrinks.
TEST(SurfaceGridTest, ResetBandIsUntouchedStockWhateverItHeld) {
  const StockSpec spec = TestStock();
  auto band = SurfaceGrid::Band(spec, SchemeKind::kTaylor, 0, 3);
  ASSERT_TRUE(band.ok());
  band->ReserveRows(12);
  const size_t room = band->jets.capacity();
  EXPECT_GE(room, static_cast<size_t>(band->nodes_x()) * 12);
  auto dirty = [&] {
    for (size_t k = 0; k < band->jets.size(); ++k) {
      band->jets[k] = SurfaceJet{1, 2, 3, 4, 5, 6};
      band->owners[k] = 7;
    }
  };
  auto expect_stock = [&](int32_t row0, int32_t rows) {
    EXPECT_EQ(band->row0, row0);
    ASSERT_EQ(band->held_rows(), rows);
    ASSERT_EQ(band->owners.size(), band->jets.size());
    for (size_t k = 0; k < band->jets.size(); ++k) {
      const SurfaceJet& j = band->jets[k];
      ASSERT_TRUE(j.w == spec.z_top && j.wx == 0 && j.wy == 0 && j.wxx == 0 &&
                  j.wxy == 0 && j.wyy == 0 && band->owners[k] == -1)
          << "node " << k;
    }
  };
  dirty();
  band->ResetBand(5, 12);  // within the room reserved
  expect_stock(5, 12);
  EXPECT_EQ(band->jets.capacity(), room);
  dirty();
  band->ResetBand(0, 40);  // grows past it
  expect_stock(0, 40);
  dirty();
  band->ResetBand(2, 4);  // shrinks
  expect_stock(2, 4);
  dirty();
  band->ResetBand(50, 40);  // clamped to the grid's last rows
  expect_stock(50, spec.ny + 1 - 50);
}

TEST(SurfaceGridTest, SetNodesChecksTheBlock) {
  auto g = SurfaceGrid::Uncut(TestStock(), SchemeKind::kTaylor);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->MinNodeHeight(), 10);
  const double w[4] = {9, 8, 7, 6};
  const int32_t owner[4] = {3, 3, 4, 4};
  EXPECT_FALSE(g->SetNodes(100, 0, 2, 2, w, nullptr, owner).ok());
  EXPECT_FALSE(g->SetNodes(-1, 0, 2, 2, w, nullptr, owner).ok());
  EXPECT_FALSE(g->SetNodes(0, 60, 2, 2, w, nullptr, owner).ok());
  ASSERT_TRUE(g->SetNodes(99, 59, 2, 2, w, nullptr, owner).ok());
  EXPECT_EQ(g->jet(100, 59).w, 8);
  EXPECT_EQ(g->jet(99, 60).w, 7);
  EXPECT_EQ(g->owner(100, 60), 4);
  EXPECT_EQ(g->MinNodeHeight(), 6);
  EXPECT_FALSE(SurfaceGrid::Uncut(StockSpec{0, 0, 0, 1, 0, 1, 1},
                                  SchemeKind::kZmap)
                   .ok());
  g->jets.pop_back();
  EXPECT_FALSE(g->Validate().ok());
}

// -------------------------------------------------------------------- PNG

// A picture is its fill everywhere, filled a band of rows a task when it
// spans several (1 MiB each), alpha opaque.
// FormatInOrder puts the pieces in order, one call at a time (a group is
// put while the next is made), and they join into the serial text: many
// groups, one group, one partial chunk, none.
TEST(FormatInOrderTest, PiecesComeInOrderOneAtATime) {
  auto item = [](int64_t k) {
    return absl::StrCat(k, k % 7 == 0 ? "\n" : ",");
  };
  for (const auto& [n, per_chunk, at_once] :
       std::vector<std::array<int64_t, 3>>{{10000, 37, 3},
                                           {10000, 64, 1},
                                           {500, 1000, 4},
                                           {90, 10, 9},
                                           {0, 5, 2}}) {
    std::string serial;
    for (int64_t k = 0; k < n; ++k) serial += item(k);
    std::string text;
    int64_t pieces = 0;
    std::atomic<int> in_put{0};
    bool overlapped = false;
    FormatInOrder(
        n, per_chunk, at_once,
        // per_chunk by copy: clang 14 (the sanitizer build's compiler)
        // can't capture a structured binding by reference.
        [&, per_chunk = per_chunk](int64_t first, int64_t last,
                                   std::string* out) {
          EXPECT_TRUE(out->empty());
          EXPECT_EQ(first % per_chunk, 0);
          for (int64_t k = first; k < last; ++k) *out += item(k);
        },
        [&](std::string_view piece) {
          overlapped |= in_put.fetch_add(1) != 0;
          text += piece;
          ++pieces;
          in_put.fetch_sub(1);
        });
    EXPECT_FALSE(overlapped) << n;
    EXPECT_EQ(pieces, (n + per_chunk - 1) / per_chunk) << n;
    EXPECT_EQ(text, serial) << n << " " << per_chunk << " " << at_once;
  }
}

// With chunks of any sizes (the marks files' chunks of even cost), each
// chunk is formatted once, with its own items, and the pieces join into
// the serial text: one item, uneven chunks over several groups.
TEST(FormatInOrderTest, ChunksOfAnySizeComeInOrder) {
  auto item = [](int64_t k) { return absl::StrCat(k, ";"); };
  for (const auto& [first, at_once] :
       std::vector<std::pair<std::vector<int64_t>, int64_t>>{
           {{0, 1}, 1},
           {{0, 1, 2, 50, 51, 400, 401, 1000}, 2},
           {{0, 300, 301, 302, 1000}, 32}}) {
    const int64_t n = first.back();
    std::string serial;
    for (int64_t k = 0; k < n; ++k) serial += item(k);
    std::string text;
    std::vector<std::pair<int64_t, int64_t>> made;
    std::mutex mu;
    FormatInOrder(
        first, at_once,
        [&](int64_t a, int64_t b, std::string* out) {
          EXPECT_TRUE(out->empty());
          {
            std::lock_guard<std::mutex> lock(mu);
            made.emplace_back(a, b);
          }
          for (int64_t k = a; k < b; ++k) *out += item(k);
        },
        [&](std::string_view piece) { text += piece; });
    std::sort(made.begin(), made.end());
    std::vector<std::pair<int64_t, int64_t>> want;
    for (size_t c = 0; c + 1 < first.size(); ++c) {
      want.emplace_back(first[c], first[c + 1]);
    }
    EXPECT_EQ(made, want) << n;
    EXPECT_EQ(text, serial) << n;
  }
}

TEST(ImageTest, EveryPixelIsTheFill) {
  const Rgb fill{12, 34, 56};
  for (const auto& [w, h, channels] : std::vector<std::array<int, 3>>{
           {1200, 1001, 3}, {700, 999, 4}, {5, 3, 3}, {0, 7, 3}}) {
    SCOPED_TRACE(absl::StrCat(w, " x ", h, " x ", channels));
    const Image im(w, h, channels, fill);
    ASSERT_EQ(im.pixels().size(), static_cast<size_t>(w) * h * channels);
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const Rgb c = im.Get(x, y);
        ASSERT_TRUE(c.r == fill.r && c.g == fill.g && c.b == fill.b &&
                    im.Alpha(x, y) == 255)
            << "pixel " << x << ", " << y;
      }
    }
  }
}

// The vectorized row against the calls it stands for, pixel by pixel: the
// ramp's stops and the halves between them, t at and beyond both ends,
// untouched stock (height 0), shades of every kind, a row longer than its
// chunks and not a multiple of the vector lanes.
TEST(ColormapTest, ShadedTintRowIsTheCallsByteForByte) {
  const double depth = 2.5;
  std::vector<float> height, shade;
  for (double t : {-0.5, 0.0, 1e-12, 0.125, 0.25, 0.375, 0.5, 0.75, 1.0, 1.5}) {
    for (double s : {0.25, 0.5, 1.0, 1.3, 0.0, -0.5}) {
      height.push_back(static_cast<float>((t - 1) * depth));
      shade.push_back(static_cast<float>(s));
    }
  }
  const float kInfF = std::numeric_limits<float>::infinity();
  for (float s : {std::nanf(""), kInfF, -kInfF}) {
    height.push_back(-1.0f);
    shade.push_back(s);
    height.push_back(0.0f);
    shade.push_back(s);
  }
  // Heights whose channels land half way between two integers, or next to.
  for (int k = 0; k < 4; ++k) {
    for (double u = 0; u <= 1; u += 1.0 / 64) {
      height.push_back(static_cast<float>(((k + u) / 4 - 1) * depth));
      shade.push_back(1.0f);
    }
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> h(-3.0f, 0.2f), s(0.2f, 1.4f);
  while (height.size() < 1003) {
    const float z = h(rng);
    height.push_back(z > 0 ? 0.0f : z);
    shade.push_back(s(rng));
  }
  const int32_t n = static_cast<int32_t>(height.size());
  std::vector<uint8_t> row(3 * static_cast<size_t>(n));
  ShadedTintRow(height.data(), shade.data(), n, depth, row.data());
  for (int32_t q = 0; q < n; ++q) {
    const Rgb base =
        height[q] < 0 ? HeightTint(1 + height[q] / depth) : kStockColor;
    const Rgb want = Scale(base, std::isfinite(shade[q]) ? shade[q] : 1.0);
    ASSERT_EQ((Rgb{row[3 * q], row[3 * q + 1], row[3 * q + 2]}), want)
        << "pixel " << q << ": height " << height[q] << ", shade " << shade[q];
  }
}

TEST(PngTest, RoundTripsRgbAndRgba) {
  TempDir dir;
  for (int channels : {3, 4}) {
    Image im(37, 11, channels, {1, 2, 3});
    for (int y = 0; y < im.height(); ++y) {
      for (int x = 0; x < im.width(); ++x) {
        im.Set(x, y, {uint8_t(x * 7), uint8_t(y * 23), uint8_t(x ^ y)});
      }
    }
    if (channels == 4) im.pixels()[3] = 17;  // one translucent pixel
    const std::string path = dir.File("rt.png");
    ASSERT_TRUE(WritePng(im, path).ok());
    auto back = ReadPng(path);
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_EQ(back->width(), 37);
    EXPECT_EQ(back->height(), 11);
    EXPECT_EQ(back->channels(), channels);
    EXPECT_EQ(back->pixels(), im.pixels());
  }
}

// The file itself, read without libpng: the signature, IHDR first and
// IEND last, every chunk's CRC, one zlib stream over the IDAT chunks (its
// Adler-32 checked by zlib) whose rows are all Paeth-filtered and unfilter
// to the pixels. Tall enough for many blocks of rows and several groups of
// blocks; WritePngRows writes the same bytes.
TEST(PngTest, FileIsValidWithoutLibpng) {
  TempDir dir;
  std::mt19937 rng(5);
  for (int channels : {3, 4}) {
    const int w = 53, h = 40 * kPngRowBlock + 7;
    Image im(w, h, channels);
    for (uint8_t& v : im.pixels()) v = rng() % 4 == 0 ? rng() : 200;
    const std::string path = dir.File("v.png");
    ASSERT_TRUE(WritePng(im, path).ok());
    std::ifstream in(path, std::ios::binary);
    const std::string f((std::istreambuf_iterator<char>(in)), {});
    const auto* b = reinterpret_cast<const uint8_t*>(f.data());
    auto u32 = [&](size_t at) {
      return uint32_t{b[at]} << 24 | uint32_t{b[at + 1]} << 16 |
             uint32_t{b[at + 2]} << 8 | b[at + 3];
    };
    ASSERT_EQ(f.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
    std::vector<std::string> types;
    std::string idat;
    size_t at = 8;
    while (at + 12 <= f.size()) {
      const uint32_t n = u32(at);
      ASSERT_LE(at + 12 + n, f.size());
      types.push_back(f.substr(at + 4, 4));
      EXPECT_EQ(crc32(0, b + at + 4, 4 + n), u32(at + 8 + n)) << types.back();
      if (types.back() == "IHDR") {
        ASSERT_EQ(n, 13u);
        EXPECT_EQ(u32(at + 8), uint32_t(w));
        EXPECT_EQ(u32(at + 12), uint32_t(h));
        EXPECT_EQ(b[at + 16], 8);
        EXPECT_EQ(b[at + 17], channels == 4 ? 6 : 2);
      }
      if (types.back() == "IDAT") idat += f.substr(at + 8, n);
      at += 12 + n;
    }
    EXPECT_EQ(at, f.size());
    ASSERT_GE(types.size(), 3u);
    EXPECT_EQ(types.front(), "IHDR");
    EXPECT_EQ(types.back(), "IEND");
    const size_t stride = size_t(w) * channels;
    std::vector<uint8_t> raw(h * (stride + 1));
    uLongf raw_size = raw.size();
    ASSERT_EQ(
        uncompress(raw.data(), &raw_size,
                   reinterpret_cast<const Bytef*>(idat.data()), idat.size()),
        Z_OK);
    ASSERT_EQ(raw_size, raw.size());
    std::vector<uint8_t> pixels, prev(stride, 0), line(stride);
    for (int y = 0; y < h; ++y) {
      const uint8_t* r = raw.data() + y * (stride + 1);
      ASSERT_EQ(r[0], 4) << "row " << y;
      for (size_t i = 0; i < stride; ++i) {
        const int a = i >= size_t(channels) ? line[i - channels] : 0;
        const int c = i >= size_t(channels) ? prev[i - channels] : 0;
        const int p = a + prev[i] - c;
        const int pa = std::abs(p - a), pb = std::abs(p - prev[i]),
                  pc = std::abs(p - c);
        const int pred = pa <= pb && pa <= pc ? a : pb <= pc ? prev[i] : c;
        line[i] = uint8_t(r[1 + i] + pred);
      }
      pixels.insert(pixels.end(), line.begin(), line.end());
      prev = line;
    }
    EXPECT_TRUE(std::equal(pixels.begin(), pixels.end(), im.pixels().begin(),
                           im.pixels().end()));
    if (channels == 3) {
      const std::string rows_path = dir.File("rows.png");
      ASSERT_TRUE(
          WritePngRows(
              w, h,
              [&](int y, uint8_t* out) { std::memcpy(out, im.row(y), stride); },
              rows_path)
              .ok());
      std::ifstream in2(rows_path, std::ios::binary);
      EXPECT_EQ(std::string((std::istreambuf_iterator<char>(in2)), {}), f);
    }
  }
}

// WriteChunks: the items' bytes in order, whatever the chunking (one item
// a chunk, many groups of chunks, one chunk for all), as one thread would
// write them; items of varying length, chunks formatted at once.
TEST(FileWriterTest, ChunksAreWrittenInOrder) {
  TempDir dir;
  auto item = [](int64_t k) { return std::string(k % 7, 'a' + k % 26) + "|"; };
  const int64_t n = 100003;
  std::string serial;
  for (int64_t k = 0; k < n; ++k) serial += item(k);
  for (int64_t per_chunk : {int64_t{1}, int64_t{7}, int64_t{1000}, n, 2 * n}) {
    const std::string path = dir.File("chunks.txt");
    FileWriter out(path);
    out.Write("head|");
    out.WriteChunks(n, per_chunk,
                    [&](int64_t first, int64_t last, std::string* piece) {
                      EXPECT_TRUE(piece->empty());
                      EXPECT_LE(last - first, per_chunk);
                      for (int64_t k = first; k < last; ++k) *piece += item(k);
                    });
    out.WriteChunks(0, per_chunk, [](int64_t, int64_t, std::string*) {
      ADD_FAILURE() << "no items, no chunks";
    });
    out.Write("tail");
    ASSERT_TRUE(out.Close().ok());
    std::ifstream in(path, std::ios::binary);
    EXPECT_EQ(std::string((std::istreambuf_iterator<char>(in)), {}),
              "head|" + serial + "tail")
        << per_chunk;
  }
}

TEST(PngTest, ReportsErrors) {
  TempDir dir;
  EXPECT_FALSE(WritePng(Image(3, 3), dir.File("no/such/dir.png")).ok());
  EXPECT_FALSE(std::filesystem::exists(dir.File("no/such/dir.png")));
  EXPECT_FALSE(WritePng(Image(), dir.File("empty.png")).ok());
  std::ofstream(dir.File("fake.png")) << "not a png";
  EXPECT_FALSE(ReadPng(dir.File("fake.png")).ok());
  EXPECT_FALSE(ReadPng(dir.File("missing.png")).ok());
}

// ------------------------------------------------------------------- font

TEST(TextTest, DrawsAntiAliasedDistinctLabels) {
  auto draw = [](const std::string& text, int scale) {
    Image im(TextWidth(text, scale) + 8, kGlyphHeight * scale + 8, 3,
             {255, 255, 255});
    DrawText(im, 4, 4, text, {0, 0, 0}, scale);
    return im;
  };
  auto ink = [](const Image& im) {
    std::vector<uint8_t> v;
    for (int y = 0; y < im.height(); ++y) {
      for (int x = 0; x < im.width(); ++x) v.push_back(im.Get(x, y).r);
    }
    return v;
  };
  // Widths grow with the text and the scale.
  EXPECT_GT(TextWidth("1e-6", 1), 10);
  EXPECT_GT(TextWidth("1e-6 mm", 2), TextWidth("1e-6", 2));
  EXPECT_NEAR(TextWidth("1e-6", 3), 3 * TextWidth("1e-6", 1), 4);
  EXPECT_EQ(TextWidth("", 2), 0);
  const std::string chars = "0123456789abcdefghijklmnopqrstuvwxyzM.-+()@";
  std::vector<std::vector<uint8_t>> seen;
  for (char c : chars) {
    const Image im = draw(std::string(1, c), 2);
    const std::vector<uint8_t> m = ink(im);
    // Dark ink and anti-aliased edges (grey levels between).
    EXPECT_LT(*std::min_element(m.begin(), m.end()), 100) << c;
    EXPECT_TRUE(std::any_of(m.begin(), m.end(),
                            [](uint8_t v) { return v > 40 && v < 215; }))
        << c;
    for (const auto& other : seen) EXPECT_NE(m, other) << c;
    seen.push_back(m);
    // Ink stays on its line: within the line box, one pixel of margin.
    for (int y = 0; y < im.height(); ++y) {
      for (int x = 0; x < im.width(); ++x) {
        if (y < 3 || y > 4 + kGlyphHeight * 2) {
          EXPECT_EQ(im.Get(x, y).r, 255) << c << " at " << x << "," << y;
        }
      }
    }
  }
  const std::vector<uint8_t> blank = ink(draw(" ", 2));
  EXPECT_EQ(std::count(blank.begin(), blank.end(), 255),
            static_cast<long>(blank.size()));
  // Clipped at the image's edges.
  Image small(5, 5, 3, {255, 255, 255});
  DrawText(small, -3, -6, "8888", {0, 0, 0}, 3);
  DrawText(small, 3, 3, "8888", {0, 0, 0}, 3);
}

// ----------------------------------------------------------------- relief

TEST(ReliefTest, SizeFollowsTheGrid) {
  const StockSpec spec = TestStock();
  PixelFrame f = ReliefFrame(spec, {});
  EXPECT_EQ(f.width, 101);
  EXPECT_EQ(f.height, 61);
  EXPECT_DOUBLE_EQ(f.X(100), 50);
  EXPECT_DOUBLE_EQ(f.Y(60), 0);
  f = ReliefFrame(spec, {.max_side = 51});
  EXPECT_EQ(f.width, 51);
  EXPECT_EQ(f.height, 31);
  f = ReliefFrame(spec, {.max_side = 1600, .min_side = 1000});
  EXPECT_EQ(f.width, 1000);
  EXPECT_EQ(f.height, 600);
  // A 1000 x 1000 grid gets one pixel per node, capped at max_side.
  const StockSpec big{0, 0, 100, 100, 0, 1000, 1000};
  EXPECT_EQ(ReliefFrame(big, {}).width, 1001);
  EXPECT_EQ(ReliefFrame(big, {.max_side = 800}).width, 800);
}

TEST(ReliefTest, ShowsCutsShadedFromTheUpperLeft) {
  TempDir dir;
  for (SchemeKind scheme : kSchemes) {
    SCOPED_TRACE(GetScheme(scheme).name());
    auto wp = Cut(scheme);
    const SurfaceGrid g = GridOf(*wp);
    auto relief = RenderRelief(g);
    ASSERT_TRUE(relief.ok()) << relief.status();
    ASSERT_TRUE(WritePng(*relief, dir.File("relief.png")).ok());
    auto im = ReadPng(dir.File("relief.png"));
    ASSERT_TRUE(im.ok());
    ASSERT_EQ(im->width(), 101);
    ASSERT_EQ(im->height(), 61);
    const PixelFrame f = ReliefFrame(g.spec, {});
    auto at = [&](double x, double y) {
      return im->Get(static_cast<int>(std::lround(f.PixelX(x))),
                     static_cast<int>(std::lround(f.PixelY(y))));
    };
    // Untouched stock: the neutral colour, in every corner.
    EXPECT_EQ(at(0, 0), kStockColor);
    EXPECT_EQ(at(50, 30), kStockColor);
    EXPECT_EQ(at(48, 2), kStockColor);
    // Groove bottom (north half, so near the top of the picture): bluish
    // and darker than the stock.
    const Rgb groove = at(25, 22);
    EXPECT_GT(groove.b, groove.r);
    EXPECT_LT(Luma(groove), Luma(kStockColor) - 40);
    // Its mirror image in y is untouched: y is up.
    EXPECT_EQ(at(25, 30 - 22), kStockColor);
    // The crater's centre is the lowest point: darker than the groove; for
    // taylor (exact normal there: flat) exactly the tint's bottom.
    EXPECT_LT(Luma(at(15, 8)), Luma(groove) - 20);
    if (scheme == SchemeKind::kTaylor) {
      EXPECT_EQ(at(15, 8), HeightTint(0));
    }
    // Its inner wall facing the light (south-east side, rising towards the
    // south-east) is brighter than the one facing away (north-west).
    const Rgb lit = at(16.5, 6.5), shadow = at(13.5, 9.5);
    EXPECT_GT(Luma(lit), Luma(shadow) + 30);
  }
}

// -------------------------------------------------------------- error map

TEST(ErrorMapTest, LogScaleColoursAndLegend) {
  ErrorRaster r;
  r.region = {0, 0, 40, 20};
  r.cols = 4;
  r.rows = 2;
  r.max_error = {0, 1e-6f, 1e-4f, 1e-2f,            // row 0 (south)
                 1e-3f, std::nanf(""), 5e-7f, 1e-2f};  // row 1 (north)
  ErrorMapLayout layout;
  auto im = RenderErrorMap(r, {.min_side = 400}, &layout);
  ASSERT_TRUE(im.ok()) << im.status();
  TempDir dir;
  ASSERT_TRUE(WritePng(*im, dir.File("error.png")).ok());
  auto back = ReadPng(dir.File("error.png"));
  ASSERT_TRUE(back.ok());
  ASSERT_EQ(back->width(), im->width());
  ASSERT_EQ(back->height(), im->height());
  EXPECT_EQ(layout.map_width, 400);
  EXPECT_EQ(layout.map_height, 200);
  EXPECT_GT(back->width(), 400 + 40);  // the legend beside the map
  EXPECT_DOUBLE_EQ(layout.lo, 1e-6);
  EXPECT_NEAR(layout.hi, 1e-2, 1e-9);
  ASSERT_EQ(layout.ticks.size(), 5u);
  EXPECT_NEAR(layout.ticks.front(), 1e-6, 1e-12);
  EXPECT_NEAR(layout.ticks.back(), 1e-2, 1e-8);

  auto cell = [&](int c, int row) {
    return back->Get(c * 100 + 50, layout.map_height - 1 - (row * 100 + 50));
  };
  EXPECT_EQ(cell(0, 0), kZeroErrorColor);
  EXPECT_EQ(cell(1, 0), Viridis(0));
  EXPECT_EQ(cell(2, 0), ErrorColor(1e-4f, 1e-6, layout.hi));
  EXPECT_LE(MaxChannelDiff(cell(2, 0), Viridis(0.5)), 2);
  EXPECT_EQ(cell(3, 0), Viridis(1));
  EXPECT_EQ(cell(0, 1), ErrorColor(1e-3f, 1e-6, layout.hi));  // north-west
  EXPECT_EQ(cell(1, 1), kInvalidErrorColor);
  EXPECT_EQ(cell(2, 1), Viridis(0));  // below the scale: clamped

  // Legend: the bar runs from the bottom colour to the top one, the zero
  // swatch, and labels (ink) beside the bar and in the title.
  EXPECT_EQ(back->Get(layout.bar_x0 + 2, layout.bar_y0), Viridis(1));
  EXPECT_EQ(back->Get(layout.bar_x0 + 2, layout.bar_y1 - 1), Viridis(0));
  EXPECT_EQ(back->Get((layout.zero_x0 + layout.zero_x1) / 2,
                      (layout.zero_y0 + layout.zero_y1) / 2),
            kZeroErrorColor);
  // Ink in pixels' worth of full coverage (the text is anti-aliased).
  auto ink_in = [&](int x0, int y0, int x1, int y1) {
    double n = 0;
    for (int y = y0; y < y1; ++y) {
      for (int x = x0; x < x1; ++x) {
        n += std::max(0.0, 1 - Luma(back->Get(x, y)) / 200.0);
      }
    }
    return n;
  };
  EXPECT_GT(ink_in(layout.bar_x1 + 2, layout.bar_y0 - 10, back->width(),
                   layout.bar_y1 + 10),
            5 * 100);  // five tick labels ("1e-2": about 110 px of ink)
  EXPECT_GT(ink_in(layout.legend_x0, 0, back->width(), layout.bar_y0 - 12),
            300);  // "error (mm)", "max 1.00e-2"
  EXPECT_EQ(ink_in(layout.bar_x1 + 2, layout.zero_y1 + 12, back->width(),
                   back->height()),
            0);  // nothing below the swatch's label
}

TEST(ErrorMapTest, MaxPoolingKeepsASingleSpike) {
  ErrorRaster r;
  r.region = {0, 0, 300, 1};
  r.cols = 3000;
  r.rows = 10;
  r.max_error.assign(r.cols * r.rows, 1e-6f);
  r.max_error[7 * r.cols + 1234] = 5e-3f;
  ErrorMapLayout layout;
  auto im = RenderErrorMap(r, {.max_side = 1000}, &layout);
  ASSERT_TRUE(im.ok());
  EXPECT_EQ(layout.map_width, 1000);
  EXPECT_EQ(layout.map_height, 3);
  int spikes = 0;
  for (int y = 0; y < layout.map_height; ++y) {
    for (int x = 0; x < layout.map_width; ++x) {
      spikes += im->Get(x, y) == Viridis(1);
    }
  }
  EXPECT_EQ(spikes, 1);
  // Tall enough for the legend even though the map is 3 pixels high.
  EXPECT_GT(im->height(), 100);
}

TEST(ErrorMapTest, FromTheValuation) {
  auto wp = Cut(SchemeKind::kZmap);
  ValuationOptions vo;
  vo.map_cols = 100;
  vo.map_rows = 60;
  auto stats = MeasureError(*wp, vo);
  ASSERT_TRUE(stats.ok());
  ErrorRaster r{{0, 0, 50, 30}, stats->map_cols, stats->map_rows, stats->map};
  auto im = RenderErrorMap(r);
  ASSERT_TRUE(im.ok());
  // 600 x 360 map: cells of 6 pixels. Untouched stock has no error, the
  // worst cell is the top colour.
  EXPECT_EQ(im->Get(3, 359 - 3), kZeroErrorColor);  // cell (0, 0)
  bool top = false;
  for (int y = 0; y < 360 && !top; ++y) {
    for (int x = 0; x < 600 && !top; ++x) top = im->Get(x, y) == Viridis(1);
  }
  EXPECT_TRUE(top);
  r.max_error.pop_back();
  EXPECT_FALSE(RenderErrorMap(r).ok());
  r.max_error.push_back(0);
  EXPECT_FALSE(RenderErrorMap(r, {.min_error = 0}).ok());
  r.region.x1 = r.region.x0;
  EXPECT_FALSE(RenderErrorMap(r).ok());
}

// ------------------------------------------------------------------ marks

std::vector<MarkPolyline> TestMarks(const Workpiece& wp) {
  auto marks = FindCuttingMarks(wp);
  EXPECT_TRUE(marks.ok()) << marks.status();
  return *std::move(marks);
}

TEST(MarksTest, PictureDrawsThePolylinesOverTheRelief) {
  auto wp = Cut(SchemeKind::kTaylor);
  const SurfaceGrid g = GridOf(*wp);
  const std::vector<MarkPolyline> marks = TestMarks(*wp);
  ASSERT_GE(marks.size(), 3u);
  const MarksPictureOptions opt;
  const PixelFrame f = ReliefFrame(g.spec, opt.relief);
  ASSERT_EQ(f.width, 1000);
  auto relief = RenderRelief(g, opt.relief);
  ASSERT_TRUE(relief.ok());
  auto drawn = RenderMarks(g, marks, opt);
  ASSERT_TRUE(drawn.ok());
  TempDir dir;
  ASSERT_TRUE(WritePng(*drawn, dir.File("marks.png")).ok());
  auto im = ReadPng(dir.File("marks.png"));
  ASSERT_TRUE(im.ok());
  ASSERT_GT(im->width(), f.width);  // the angle legend
  ASSERT_GE(im->height(), f.height);

  struct Seg {
    double ax, ay, bx, by;
  };
  std::vector<Seg> segs;
  for (const MarkPolyline& p : marks) {
    for (size_t k = 0; k + 1 < p.vertices.size(); ++k) {
      segs.push_back({f.PixelX(p.vertices[k].x), f.PixelY(p.vertices[k].y),
                      f.PixelX(p.vertices[k + 1].x),
                      f.PixelY(p.vertices[k + 1].y)});
    }
    if (p.closed) {
      segs.push_back({f.PixelX(p.vertices.back().x),
                      f.PixelY(p.vertices.back().y),
                      f.PixelX(p.vertices[0].x), f.PixelY(p.vertices[0].y)});
    }
  }
  auto dist = [&](double px, double py) {
    double best = 1e300;
    for (const Seg& s : segs) {
      const double dx = s.bx - s.ax, dy = s.by - s.ay;
      const double l2 = dx * dx + dy * dy;
      double t = l2 > 0 ? ((px - s.ax) * dx + (py - s.ay) * dy) / l2 : 0;
      t = std::clamp(t, 0.0, 1.0);
      best = std::min(best, std::hypot(s.ax + t * dx - px, s.ay + t * dy - py));
    }
    return best;
  };
  // Only pixels near a mark changed, and there are many.
  int changed = 0;
  for (int y = 0; y < f.height; ++y) {
    for (int x = 0; x < f.width; ++x) {
      if (im->Get(x, y) == relief->Get(x, y)) continue;
      ++changed;
      // Halo width 2 + 2 px, plus the half pixel of anti-aliasing.
      ASSERT_LE(dist(x, y), 2.51) << x << "," << y;
    }
  }
  EXPECT_GT(changed, 1000);
  // On the line, the pixel takes the angle's colour.
  int checked = 0;
  for (const MarkPolyline& p : marks) {
    for (size_t k = 1; k + 1 < p.vertices.size(); k += 5) {
      const int x = static_cast<int>(std::lround(f.PixelX(p.vertices[k].x)));
      const int y = static_cast<int>(std::lround(f.PixelY(p.vertices[k].y)));
      EXPECT_LE(MaxChannelDiff(im->Get(x, y), AngleColor(p.angle_deg[k])), 60)
          << x << "," << y;
      ++checked;
    }
  }
  EXPECT_GT(checked, 10);
}

// A polyline is blended once per pixel, with the largest coverage of its
// segments (its distance from the polyline): the picture does not depend
// on how finely a mark is sampled. A line retraced over itself is the line
// drawn once; one of 400 vertices 0.1 px apart is the line of its two ends;
// an arc sampled 20 times finer is the same arc within 0.05 px (vertices
// that close are dropped). Blending segment by segment darkened the edges
// once per segment passing near.
// The vertices a picture keeps, against the rule written out one vertex at
// a time (the first and last kept; each run as long as every vertex inside
// lies within 0.05 px of its chord, its angle within 0.25 degrees of the
// chord's, and at most 32 vertices): straight lines, a tight arc, and
// vertices jittered about both limits.
TEST(MarksTest, KeeperKeepsTheVerticesOfTheRule) {
  auto rule = [](const std::vector<double>& xs, const std::vector<double>& ys,
                 const std::vector<double>& an) {
    auto spans = [&](size_t a, size_t b) {
      const double dx = xs[b] - xs[a], dy = ys[b] - ys[a];
      const double len2 = dx * dx + dy * dy;
      for (size_t i = a + 1; i < b; ++i) {
        double t =
            len2 > 0 ? ((xs[i] - xs[a]) * dx + (ys[i] - ys[a]) * dy) / len2 : 0;
        t = std::clamp(t, 0.0, 1.0);
        const double ex = xs[a] + t * dx - xs[i], ey = ys[a] + t * dy - ys[i];
        if (!(ex * ex + ey * ey <= 0.05 * 0.05)) return false;
        const double angle = an[a] + t * (an[b] - an[a]);
        if (!(std::fabs(an[i] - angle) <= 0.25)) return false;
      }
      return true;
    };
    std::vector<size_t> kept = {0};
    for (size_t a = 0; a + 1 < xs.size();) {
      size_t b = a + 1;
      while (b + 1 < xs.size() && b + 1 - a <= 32 && spans(a, b + 1)) ++b;
      kept.push_back(b);
      a = b;
    }
    return kept;
  };
  // One mm a pixel, y down: pixel (x, -y).
  const PixelFrame frame{400, 400, 0, 0, 1, 1};
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> jitter(-1, 1);
  std::vector<MarkPolyline> lines;
  for (int kind = 0; kind < 6; ++kind) {
    MarkPolyline p;
    const int n = 40 + 37 * kind;
    for (int k = 0; k < n; ++k) {
      double x = 10 + 0.1 * k, y = -20 - 5 * kind, angle = 30;
      if (kind == 1) {  // an arc of radius 3 px
        x = 50 + 3 * std::cos(0.02 * k);
        y = -50 - 3 * std::sin(0.02 * k);
      } else if (kind == 2) {  // about the distance limit
        y += 0.05 * jitter(rng);
      } else if (kind == 3) {  // about the angle limit
        angle += 0.25 * jitter(rng);
      } else if (kind == 4) {  // both, and repeated points
        x = 10 + 0.1 * (k / 3);
        y += 0.06 * jitter(rng);
        angle += 0.3 * jitter(rng);
      } else if (kind == 5) {  // a turn, angles rising
        x = k < n / 2 ? 10 + 0.2 * k : 10 + 0.2 * (n / 2);
        y = k < n / 2 ? -100 : -100 - 0.2 * (k - n / 2);
        angle = 10 + 0.01 * k;
      }
      p.vertices.push_back({x, y, 0});
      p.angle_deg.push_back(angle);
    }
    lines.push_back(std::move(p));
  }
  MarkKeeper keeper(frame);
  for (const MarkPolyline& p : lines) ASSERT_TRUE(keeper.Add(p).ok());
  size_t q = 0;
  ASSERT_TRUE(keeper
                  .Take([&](const KeptPolyline& kept) {
                    const MarkPolyline& p = lines[q++];
                    std::vector<double> xs, ys, an;
                    for (size_t k = 0; k < p.vertices.size(); ++k) {
                      xs.push_back(frame.PixelX(p.vertices[k].x));
                      ys.push_back(frame.PixelY(p.vertices[k].y));
                      an.push_back(p.angle_deg[k]);
                    }
                    const std::vector<size_t> want = rule(xs, ys, an);
                    EXPECT_EQ(kept.x.size(), want.size()) << "polyline " << q;
                    for (size_t k = 0; k < std::min(want.size(), kept.x.size());
                         ++k) {
                      EXPECT_EQ(kept.x[k], xs[want[k]]);
                      EXPECT_EQ(kept.y[k], ys[want[k]]);
                      EXPECT_EQ(kept.angle[k], an[want[k]]);
                    }
                    return absl::OkStatus();
                  })
                  .ok());
  EXPECT_EQ(q, lines.size());
}

TEST(MarksTest, PolylineIsBlendedOncePerPixel) {
  PixelFrame f;
  f.width = 120;
  f.height = 80;
  f.x0 = 0;
  f.y1 = 80;
  f.sx = f.sy = 1;  // a pixel a millimetre, y up
  const Image ground(f.width, f.height, 3, Rgb{200, 200, 200});
  MarksPictureOptions mo;
  mo.line_width_px = 4;
  auto draw = [&](const std::vector<MarkPolyline>& marks) {
    auto im = DrawMarks(ground, f, marks, mo);
    EXPECT_TRUE(im.ok()) << im.status();
    return *std::move(im);
  };
  auto line = [](std::vector<Vec3> v) {
    MarkPolyline p;
    p.angle_deg.assign(v.size(), 30);
    p.vertices = std::move(v);
    return p;
  };
  auto max_diff = [&](const Image& a, const Image& b) {
    int d = 0;
    for (int y = 0; y < f.height; ++y) {
      for (int x = 0; x < f.width; ++x) {
        d = std::max(d, MaxChannelDiff(a.Get(x, y), b.Get(x, y)));
      }
    }
    return d;
  };
  const Vec3 a{10.3, 20.7, 0}, b{100.6, 57.2, 0};
  const Image once = draw({line({a, b})});
  EXPECT_EQ(max_diff(once, draw({line({a, b, a})})), 0);
  std::vector<Vec3> fine;
  for (int k = 0; k <= 400; ++k) {
    const double t = k / 400.0;
    fine.push_back({a.x + t * (b.x - a.x), a.y + t * (b.y - a.y), 0});
  }
  EXPECT_EQ(max_diff(once, draw({line(fine)})), 0);
  // The edge is anti-aliased: some pixels only partly take the line's
  // colour over the halo.
  int partial = 0;
  for (int y = 0; y < f.height; ++y) {
    for (int x = 0; x < f.width; ++x) {
      const Rgb c = once.Get(x, y);
      partial += MaxChannelDiff(c, AngleColor(30)) > 40 &&
                 MaxChannelDiff(c, Rgb{200, 200, 200}) > 40 &&
                 MaxChannelDiff(c, Rgb{0, 0, 0}) > 40;
    }
  }
  EXPECT_GT(partial, 50);
  auto arc = [&](int n) {
    std::vector<Vec3> v;
    for (int k = 0; k <= n; ++k) {
      const double t = std::numbers::pi * k / n;
      v.push_back({60 + 35 * std::cos(t), 20 + 35 * std::sin(t), 0});
    }
    return line(v);
  };
  // 100 vertices: 1.1 px apart; 2000: 0.055 px.
  EXPECT_LE(max_diff(draw({arc(100)}), draw({arc(2000)})), 16);
  EXPECT_GT(max_diff(once, draw({arc(100)})), 100);  // a different picture
}

TEST(MarksTest, SvgHasOnePathPerPolyline) {
  auto wp = Cut(SchemeKind::kTaylor);
  const std::vector<MarkPolyline> marks = TestMarks(*wp);
  ASSERT_FALSE(marks.empty());
  TempDir dir;
  ASSERT_TRUE(WriteMarksSvg(TestStock(), marks, dir.File("marks.svg")).ok());
  const std::string svg = ReadAll(dir.File("marks.svg"));
  EXPECT_EQ(svg.rfind("<?xml", 0), 0u);
  EXPECT_NE(svg.find("viewBox=\"0 -30 50 30\""), std::string::npos);
  EXPECT_NE(svg.find("scale(1,-1)"), std::string::npos);
  EXPECT_EQ(CountOf(svg, "<rect "), 1u);
  EXPECT_EQ(CountOf(svg, "<path "), marks.size());
  size_t segments = 0, closed = 0;
  for (const MarkPolyline& p : marks) {
    segments += p.vertices.size() - 1;
    closed += p.closed;
  }
  EXPECT_EQ(CountOf(svg, " L"), segments);
  EXPECT_EQ(CountOf(svg, " Z\""), closed);
  // First vertex of the first polyline, y not flipped in the data.
  const Vec3 v = marks[0].vertices[0];
  char first[64];
  std::snprintf(first, sizeof first, "d=\"M%.7g %.7g", v.x, v.y);
  EXPECT_NE(svg.find(first), std::string::npos) << first;
  EXPECT_EQ(svg.substr(svg.size() - 7), "</svg>\n");
}

TEST(MarksTest, JsonRoundTrips) {
  auto wp = Cut(SchemeKind::kTaylor);
  const std::vector<MarkPolyline> marks = TestMarks(*wp);
  ASSERT_FALSE(marks.empty());
  TempDir dir;
  ASSERT_TRUE(WriteMarksJson(marks, dir.File("marks.json")).ok());
  const std::string text = ReadAll(dir.File("marks.json"));
  ASSERT_EQ(text.back(), '\n');
  EXPECT_EQ(text, MarksJson(marks) + "\n");
  google::protobuf::Struct doc;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(text, &doc).ok());
  ASSERT_EQ(doc.fields().size(), 1u);
  const auto& list = doc.fields().at("polylines").list_value();
  ASSERT_EQ(static_cast<size_t>(list.values_size()), marks.size());
  for (size_t k = 0; k < marks.size(); ++k) {
    const auto& p = list.values(k).struct_value().fields();
    EXPECT_EQ(p.size(), 4u);  // closed, owners, vertices, angle_deg
    EXPECT_EQ(p.at("closed").bool_value(), marks[k].closed);
    EXPECT_EQ(p.at("owners").list_value().values(0).number_value(),
              marks[k].owners[0]);
    EXPECT_EQ(p.at("owners").list_value().values(1).number_value(),
              marks[k].owners[1]);
    const auto& verts = p.at("vertices").list_value();
    ASSERT_EQ(static_cast<size_t>(verts.values_size()),
              marks[k].vertices.size());
    ASSERT_EQ(static_cast<size_t>(p.at("angle_deg").list_value().values_size()),
              marks[k].angle_deg.size());
    for (int i = 0; i < verts.values_size(); ++i) {
      const auto& xyz = verts.values(i).list_value();
      ASSERT_EQ(xyz.values_size(), 3);
      // Shortest round-trip doubles: exact.
      EXPECT_EQ(xyz.values(0).number_value(), marks[k].vertices[i].x);
      EXPECT_EQ(xyz.values(1).number_value(), marks[k].vertices[i].y);
      EXPECT_EQ(xyz.values(2).number_value(), marks[k].vertices[i].z);
    }
  }
  // With vertex owners: one more key per polyline.
  google::protobuf::Struct with;
  ASSERT_TRUE(
      google::protobuf::util::JsonStringToMessage(MarksJson(marks, true), &with)
          .ok());
  EXPECT_EQ(with.fields()
                .at("polylines")
                .list_value()
                .values(0)
                .struct_value()
                .fields()
                .size(),
            5u);
}

TEST(MarksTest, FilterKeepsRimsAndCreasesAndDropsSeams) {
  auto line = [](bool closed, std::array<int32_t, 2> owners,
                 std::vector<Vec3> v, std::vector<double> angles) {
    MarkPolyline p;
    p.closed = closed;
    p.owners = owners;
    p.vertices = std::move(v);
    p.angle_deg = std::move(angles);
    for (size_t k = 0; k < p.vertices.size(); ++k) {
      p.vertex_owners.push_back({owners[0], owners[1] + static_cast<int>(k)});
    }
    return p;
  };
  const std::vector<Vec3> row = {{0, 0, 0},   {0.1, 0, 0}, {0.2, 0, 0},
                                 {0.3, 0, 0}, {0.4, 0, 0}, {0.5, 0, 0}};
  const std::vector<Vec3> ring = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0},
                                  {0.5, 1.5, 0}, {0, 1, 0}};
  const std::vector<MarkPolyline> marks = {
      line(false, {3, 4}, row, {5, 5, 0.3, 5, 5, 5}),  // a seam vertex
      line(true, {5, 6}, ring, {2, 2, 2, 2, 2}),        // a crease
      line(true, {5, 8}, ring, {2, 2, 0.5, 2, 2}),      // one seam vertex
      line(false, {-1, 7}, row, {0.1, 0.1, 0.1, 0.1, 0.1, 0.1}),  // a rim
      line(false, {9, 10}, row, {0.2, 0.9, 0.5, 0.1, 0.1, 0.1}),  // a seam
  };
  const std::vector<MarkPolyline> shown =
      FilterMarks(marks, MarkDisplayFilter{1, 0.15});
  ASSERT_EQ(shown.size(), 4u);
  // The seam vertex cuts the first: [0, 0.1] is too short, [0.3, 0.5] stays.
  EXPECT_FALSE(shown[0].closed);
  ASSERT_EQ(shown[0].vertices.size(), 3u);
  EXPECT_EQ(shown[0].vertices[0].x, 0.3);
  EXPECT_EQ(shown[0].owners, (std::array<int32_t, 2>{3, 7}));
  EXPECT_EQ(shown[0].angle_deg, (std::vector<double>{5, 5, 5}));
  ASSERT_EQ(shown[0].vertex_owners.size(), 3u);
  EXPECT_EQ(shown[0].vertex_owners[2], (std::array<int32_t, 2>{3, 9}));
  // The whole crease, still closed.
  EXPECT_TRUE(shown[1].closed);
  EXPECT_EQ(shown[1].vertices.size(), 5u);
  // Opened at its seam vertex, whole across its first vertex: 3, 4, 0, 1.
  EXPECT_FALSE(shown[2].closed);
  ASSERT_EQ(shown[2].vertices.size(), 4u);
  EXPECT_EQ(shown[2].vertices[0].x, 0.5);
  EXPECT_EQ(shown[2].vertices[2].x, 0);
  EXPECT_EQ(shown[2].vertices[3].x, 1);
  // The rim, whatever its angle.
  EXPECT_EQ(shown[3].owners[0], -1);
  EXPECT_EQ(shown[3].vertices.size(), 6u);
  // Nothing dropped with both bounds at 0.
  const std::vector<MarkPolyline> all = FilterMarks(marks, {0, 0});
  ASSERT_EQ(all.size(), marks.size());
  for (size_t k = 0; k < all.size(); ++k) {
    EXPECT_EQ(all[k].vertices.size(), marks[k].vertices.size());
    EXPECT_EQ(all[k].closed, marks[k].closed);
  }
}

// ------------------------------------------------------------------- mesh

struct StlFile {
  uint32_t count = 0;
  std::vector<std::array<float, 3>> normals;
  std::vector<std::array<std::array<float, 3>, 3>> tris;
};

StlFile ParseStl(const std::string& bytes) {
  StlFile f;
  EXPECT_GE(bytes.size(), 84u);
  if (bytes.size() < 84) return f;
  EXPECT_NE(bytes.rfind("solid", 0), 0u);  // would read as ASCII STL
  std::memcpy(&f.count, bytes.data() + 80, 4);
  EXPECT_EQ(bytes.size(), 84 + 50 * size_t{f.count});
  if (bytes.size() != 84 + 50 * size_t{f.count}) return f;
  for (uint32_t t = 0; t < f.count; ++t) {
    float v[12];
    std::memcpy(v, bytes.data() + 84 + 50 * size_t{t}, 48);
    f.normals.push_back({v[0], v[1], v[2]});
    f.tris.push_back({{{v[3], v[4], v[5]}, {v[6], v[7], v[8]},
                       {v[9], v[10], v[11]}}});
  }
  return f;
}

// Checks a parsed STL: closed, oriented, outward normals, bounds; returns
// the enclosed volume.
double CheckClosedMesh(const StlFile& f, const StockSpec& spec,
                       double z_bottom) {
  std::map<std::array<float, 3>, int> ids;
  std::map<std::pair<int, int>, int> directed;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  double volume = 0, prism_volume = 0;
  int flat_bottom = 0;
  for (size_t t = 0; t < f.tris.size(); ++t) {
    int id[3];
    for (int k = 0; k < 3; ++k) {
      const auto& p = f.tris[t][k];
      id[k] = ids.emplace(p, static_cast<int>(ids.size())).first->second;
      for (int c = 0; c < 3; ++c) {
        lo[c] = std::min(lo[c], double{p[c]});
        hi[c] = std::max(hi[c], double{p[c]});
      }
    }
    for (int k = 0; k < 3; ++k) ++directed[{id[k], id[(k + 1) % 3]}];
    const auto& a = f.tris[t][0];
    const auto& b = f.tris[t][1];
    const auto& c = f.tris[t][2];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                         u[0] * v[1] - u[1] * v[0]};
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    EXPECT_GT(len, 0) << "degenerate triangle " << t;
    const auto& sn = f.normals[t];
    EXPECT_NEAR(std::hypot(sn[0], sn[1], sn[2]), 1, 1e-5);
    EXPECT_GT((sn[0] * n[0] + sn[1] * n[1] + sn[2] * n[2]) / len, 0.999)
        << "normal of triangle " << t << " disagrees with its winding";
    // Divergence theorem with the winding, against the prism volume of the
    // upward faces over the bottom plane.
    volume += (a[0] * (b[1] * c[2] - b[2] * c[1]) -
               a[1] * (b[0] * c[2] - b[2] * c[0]) +
               a[2] * (b[0] * c[1] - b[1] * c[0])) /
              6;
    if (n[2] > 0) {
      prism_volume += n[2] / 2 * ((a[2] + b[2] + c[2]) / 3 - z_bottom);
    }
    if (sn[2] == -1) ++flat_bottom;
  }
  EXPECT_GT(flat_bottom, 0);
  for (const auto& [edge, n] : directed) {
    EXPECT_EQ(n, 1) << "directed edge " << edge.first << "->" << edge.second;
    const auto rev = directed.find({edge.second, edge.first});
    EXPECT_TRUE(rev != directed.end())
        << "open edge " << edge.first << "-" << edge.second;
  }
  EXPECT_FLOAT_EQ(lo[0], spec.x0);
  EXPECT_FLOAT_EQ(hi[0], spec.x1);
  EXPECT_FLOAT_EQ(lo[1], spec.y0);
  EXPECT_FLOAT_EQ(hi[1], spec.y1);
  EXPECT_FLOAT_EQ(lo[2], z_bottom);
  EXPECT_FLOAT_EQ(hi[2], spec.z_top);
  EXPECT_GT(volume, 0);
  EXPECT_NEAR(volume, prism_volume, 1e-4 * prism_volume);
  return volume;
}

SurfaceMeshOptions MeshOptions(int subdivision,
                               std::optional<double> z_bottom = {}) {
  SurfaceMeshOptions o;
  o.subdivision = subdivision;
  o.z_bottom = z_bottom;
  return o;
}

int64_t ExpectedTriangles(int64_t nx, int64_t ny) {
  return 2 * nx * ny + 6 * (nx + ny) - 2;
}

TEST(MeshTest, StlIsClosedAndFollowsTheReconstruction) {
  TempDir dir;
  for (SchemeKind scheme : kSchemes) {
    auto wp = Cut(scheme);
    const SurfaceGrid g = GridOf(*wp);
    for (int s : {1, 3}) {
      SCOPED_TRACE(std::string(GetScheme(scheme).name()) + " s=" +
                   std::to_string(s));
      auto mesh = BuildSurfaceMesh(g, MeshOptions(s));
      ASSERT_TRUE(mesh.ok()) << mesh.status();
      const int64_t nx = 100 * s, ny = 60 * s;
      EXPECT_EQ(mesh->lattice_nx, nx);
      EXPECT_EQ(static_cast<int64_t>(mesh->triangles.size()),
                ExpectedTriangles(nx, ny));
      EXPECT_EQ(static_cast<int64_t>(mesh->vertices.size()),
                (nx + 1) * (ny + 1) + 2 * (nx + ny));
      // Lowest cut: 8 (crater bottom); default bottom 2% of 50 mm below.
      EXPECT_NEAR(mesh->z_bottom, 8 - 1, 1e-3);
      // Top vertices: the node's own height at nodes, the scheme on the
      // stated element in between.
      const GridGeometry geo = g.geometry();
      for (int64_t j = 0; j <= ny; j += 7) {
        for (int64_t i = 0; i <= nx; i += 5) {
          const Vec3& v = mesh->vertices[j * (nx + 1) + i];
          const int32_t ei = static_cast<int32_t>(std::min<int64_t>(i / s, 99));
          const int32_t ej = static_cast<int32_t>(std::min<int64_t>(j / s, 59));
          ASSERT_EQ(v.x, geo.NodeX(static_cast<int32_t>(i / s)) +
                             (i % s) * (geo.dx() / s));
          if (i % s == 0 && j % s == 0) {
            const double w = g.jet(static_cast<int32_t>(i / s),
                                   static_cast<int32_t>(j / s)).w;
            ASSERT_EQ(v.z, std::min(w, g.spec.z_top));
          } else {
            ASSERT_EQ(v.z, GetScheme(scheme).Reconstruct(g.Corners(ei, ej),
                                                          v.x, v.y));
          }
        }
      }
      // Top triangles come first, two per lattice cell, split along the
      // diagonal with the smaller height change.
      int64_t along_00_11 = 0;
      for (int64_t c = 0; c < nx * ny; ++c) {
        const auto& t0 = mesh->triangles[2 * c];
        const auto& t1 = mesh->triangles[2 * c + 1];
        std::vector<int32_t> shared;
        for (int32_t v : t0) {
          if (std::find(t1.begin(), t1.end(), v) != t1.end()) {
            shared.push_back(v);
          }
        }
        ASSERT_EQ(shared.size(), 2u);
        const int64_t i = c % nx, j = c / nx;
        auto z = [&](int64_t di, int64_t dj) {
          return mesh->vertices[(j + dj) * (nx + 1) + i + di].z;
        };
        const double d_00_11 = std::fabs(z(0, 0) - z(1, 1));
        const double d_10_01 = std::fabs(z(1, 0) - z(0, 1));
        const bool main_diag = std::abs(shared[0] - shared[1]) == nx + 2;
        along_00_11 += main_diag;
        ASSERT_LE(main_diag ? d_00_11 : d_10_01, main_diag ? d_10_01 : d_00_11)
            << "cell " << i << "," << j;
      }
      EXPECT_GT(along_00_11, 0);
      EXPECT_LT(along_00_11, nx * ny);  // both diagonals occur
      ASSERT_TRUE(WriteStl(*mesh, dir.File("surface.stl")).ok());
      const StlFile f = ParseStl(ReadAll(dir.File("surface.stl")));
      ASSERT_EQ(f.count, mesh->triangles.size());
      const double volume = CheckClosedMesh(f, g.spec, mesh->z_bottom);
      // Stock block minus what was cut: the grooves and crater take a few
      // hundred mm^3 out of 50 x 30 x 3.
      EXPECT_LT(volume, 50.0 * 30 * 3);
      EXPECT_GT(volume, 50.0 * 30 * 3 - 600);
    }
  }
}

TEST(MeshTest, ThinGridsAndOptions) {
  TempDir dir;
  // One element along an axis takes the other bottom triangulation.
  for (auto [nx, ny] : {std::pair{1, 1}, {1, 4}, {2, 1}, {3, 5}, {7, 2}}) {
    SCOPED_TRACE(std::to_string(nx) + "x" + std::to_string(ny));
    const StockSpec spec{-3, 2, 5, 4, 1, nx, ny};
    auto wp = Cut(SchemeKind::kTaylor, spec, {{{0, 3, 0.8}, {2, 3, 0.9}, 1}});
    const SurfaceGrid g = GridOf(*wp);
    for (int s : {1, 2}) {
      auto mesh = BuildSurfaceMesh(g, MeshOptions(s, -2));
      ASSERT_TRUE(mesh.ok());
      EXPECT_EQ(static_cast<int64_t>(mesh->triangles.size()),
                ExpectedTriangles(nx * s, ny * s));
      ASSERT_TRUE(WriteStl(*mesh, dir.File("thin.stl")).ok());
      CheckClosedMesh(ParseStl(ReadAll(dir.File("thin.stl"))), spec, -2);
    }
  }
  auto wp = Cut(SchemeKind::kZmap);
  const SurfaceGrid g = GridOf(*wp);
  EXPECT_FALSE(BuildSurfaceMesh(g, MeshOptions(0)).ok());
  EXPECT_FALSE(BuildSurfaceMesh(g, MeshOptions(1, 8)).ok());  // = lowest point
  EXPECT_FALSE(BuildSurfaceMesh(g, MeshOptions(1, std::nan(""))).ok());
  EXPECT_TRUE(BuildSurfaceMesh(g, MeshOptions(1, 7.999)).ok());
  EXPECT_FALSE(BuildSurfaceMesh(g, MeshOptions(300)).ok());  // too many
}

TEST(MeshTest, VrmlHasTheSameMesh) {
  auto wp = Cut(SchemeKind::kTaylor);
  const SurfaceGrid g = GridOf(*wp);
  auto mesh = BuildSurfaceMesh(g, MeshOptions(2));
  ASSERT_TRUE(mesh.ok());
  TempDir dir;
  const std::vector<Rgb> colors = SurfaceColors(*mesh, g.spec.z_top);
  ASSERT_TRUE(WriteVrml(*mesh, dir.File("surface.wrl"), colors).ok());
  EXPECT_FALSE(WriteVrml(*mesh, dir.File("bad.wrl"),
                         std::span<const Rgb>(colors).first(3))
                   .ok());
  const std::string text = ReadAll(dir.File("surface.wrl"));
  ASSERT_EQ(text.rfind("#VRML V2.0 utf8\n", 0), 0u);
  // The numbers inside "point [ ... ]", "color [ ... ]", "coordIndex [ ... ]".
  auto block = [&](const std::string& key) {
    const size_t open = text.find(key + " [");
    EXPECT_NE(open, std::string::npos) << key;
    const size_t close = text.find(']', open);
    std::istringstream in(text.substr(open + key.size() + 2,
                                      close - open - key.size() - 2));
    std::vector<double> v;
    for (double d; in >> d;) v.push_back(d);
    EXPECT_TRUE(in.eof()) << key << " holds a non-number";
    return v;
  };
  const std::vector<double> points = block("point");
  const std::vector<double> cols = block("color");
  const std::vector<double> index = block("coordIndex");
  ASSERT_EQ(points.size(), 3 * mesh->vertices.size());
  ASSERT_EQ(cols.size(), 3 * mesh->vertices.size());
  ASSERT_EQ(index.size(), 4 * mesh->triangles.size());
  for (size_t t = 0; t < mesh->triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(index[4 * t + k], mesh->triangles[t][k]);
    }
    ASSERT_EQ(index[4 * t + 3], -1);
  }
  for (size_t v = 0; v < mesh->vertices.size(); v += 97) {
    // Shortest float text: the same float back.
    EXPECT_EQ(static_cast<float>(points[3 * v + 2]),
              static_cast<float>(mesh->vertices[v].z));
  }
  // Uncut corner vertex: stock colour; walls darker.
  EXPECT_NEAR(cols[0], kStockColor.r / 255.0, 1e-3);
  const size_t wall = mesh->vertices.size() - 1;
  EXPECT_LT(cols[3 * wall], kStockColor.r / 255.0 - 0.1);
}

// The height of a mesh's top (its first top_vertices vertices' triangles)
// at (x, y), by barycentric interpolation in the triangle holding it.
class TopSurface {
 public:
  explicit TopSurface(const TriangleMesh& m) : m_(m) {
    for (const auto& t : m.triangles) {
      if (t[0] < m.top_vertices && t[1] < m.top_vertices &&
          t[2] < m.top_vertices) {
        top_.push_back(t);
      }
    }
  }
  size_t triangles() const { return top_.size(); }
  double Height(double x, double y) const {
    for (const auto& t : top_) {
      const Vec3 &a = m_.vertices[t[0]], &b = m_.vertices[t[1]],
                 &c = m_.vertices[t[2]];
      if (x < std::min({a.x, b.x, c.x}) - 1e-9 ||
          x > std::max({a.x, b.x, c.x}) + 1e-9 ||
          y < std::min({a.y, b.y, c.y}) - 1e-9 ||
          y > std::max({a.y, b.y, c.y}) + 1e-9) {
        continue;
      }
      const double d = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
      const double u = ((b.x - x) * (c.y - y) - (b.y - y) * (c.x - x)) / d;
      const double v = ((c.x - x) * (a.y - y) - (c.y - y) * (a.x - x)) / d;
      const double w = 1 - u - v;
      if (u < -1e-9 || v < -1e-9 || w < -1e-9) continue;
      return u * a.z + v * b.z + w * c.z;
    }
    ADD_FAILURE() << "no top triangle holds " << x << "," << y;
    return NAN;
  }

 private:
  const TriangleMesh& m_;
  std::vector<std::array<int32_t, 3>> top_;
};

TEST(MeshTest, AdaptiveMeshStaysWithinTheTolerance) {
  TempDir dir;
  for (SchemeKind scheme : kSchemes) {
    auto wp = Cut(scheme);
    const SurfaceGrid g = GridOf(*wp);
    auto full = BuildSurfaceMesh(g, MeshOptions(1));
    ASSERT_TRUE(full.ok());
    const TopSurface fine(*full);
    for (double tol : {0.05, 0.2}) {
      SCOPED_TRACE(std::string(GetScheme(scheme).name()) + " tolerance " +
                   std::to_string(tol));
      SurfaceMeshOptions o = MeshOptions(1);
      o.tolerance = tol;
      auto mesh = BuildSurfaceMesh(g, o);
      ASSERT_TRUE(mesh.ok()) << mesh.status();
      EXPECT_LE(mesh->max_deviation, tol);
      EXPECT_GT(mesh->max_deviation, tol / 4);  // it does use the room
      EXPECT_EQ(mesh->z_bottom, full->z_bottom);
      // Far fewer triangles: the uncut top is flat, the grooves are long.
      EXPECT_LT(4 * mesh->triangles.size(), full->triangles.size());
      // Its vertices are lattice vertices, at their heights.
      for (int64_t k = 0; k < mesh->top_vertices; ++k) {
        const Vec3& v = mesh->vertices[k];
        EXPECT_EQ(v.z, fine.Height(v.x, v.y));
      }
      // The distance to the full-resolution top, at every lattice vertex,
      // every cell centre and random points, is within the tolerance and
      // the measured maximum.
      const TopSurface coarse(*mesh);
      std::vector<std::pair<double, double>> points;
      const GridGeometry geo = g.geometry();
      for (int32_t j = 0; j <= 60; ++j) {
        for (int32_t i = 0; i <= 100; ++i) {
          points.push_back({geo.NodeX(i), geo.NodeY(j)});
          if (i < 100 && j < 60) {
            points.push_back({geo.NodeX(i) + 0.25, geo.NodeY(j) + 0.25});
          }
        }
      }
      std::mt19937 rng(3);
      std::uniform_real_distribution<double> ux(0, 50), uy(0, 30);
      for (int k = 0; k < 3000; ++k) points.push_back({ux(rng), uy(rng)});
      double seen = 0;
      for (const auto& [x, y] : points) {
        seen = std::max(seen, std::fabs(fine.Height(x, y) -
                                        coarse.Height(x, y)));
      }
      EXPECT_LE(seen, mesh->max_deviation + 1e-9);
      EXPECT_GT(seen, 0.5 * mesh->max_deviation);
      // Closed and oriented, the same volume as the full mesh within the
      // tolerance over the top's area.
      ASSERT_TRUE(WriteStl(*mesh, dir.File("adaptive.stl")).ok());
      const double volume = CheckClosedMesh(
          ParseStl(ReadAll(dir.File("adaptive.stl"))), g.spec, mesh->z_bottom);
      ASSERT_TRUE(WriteStl(*full, dir.File("full.stl")).ok());
      const double full_volume = CheckClosedMesh(
          ParseStl(ReadAll(dir.File("full.stl"))), g.spec, full->z_bottom);
      EXPECT_NEAR(volume, full_volume, tol * 50 * 30 + 1e-3);
    }
  }
}

TEST(MeshTest, AdaptiveMeshOfUncutStockIsTwoTrianglesPerSide) {
  auto wp = Cut(SchemeKind::kTaylor, TestStock(), {});
  auto full = BuildSurfaceMesh(GridOf(*wp), MeshOptions(1, 5));
  ASSERT_TRUE(full.ok());
  auto mesh = SimplifySurfaceMesh(*full, 0);
  ASSERT_TRUE(mesh.ok());
  EXPECT_EQ(mesh->max_deviation, 0);
  // 64-cell blocks: a 100 x 60 top is 2 x 1 blocks split to fit the
  // lattice (64 + 32 + 4 across, 32 + 16 + 8 + 4 up): 12 rectangles.
  EXPECT_LE(mesh->top_vertices, 30);
  EXPECT_LE(mesh->triangles.size(), 80u);
  EXPECT_EQ(SimplifySurfaceMesh(*full, -1).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(SimplifySurfaceMesh(*full, std::nan("")).status().code(),
            absl::StatusCode::kInvalidArgument);
  TempDir dir;
  ASSERT_TRUE(WriteStl(*mesh, dir.File("flat.stl")).ok());
  const double volume = CheckClosedMesh(ParseStl(ReadAll(dir.File("flat.stl"))),
                                        TestStock(), 5);
  EXPECT_NEAR(volume, 50.0 * 30 * 5, 1e-6 * volume);
}

// ------------------------------------------------------------ all outputs

TEST(RunOutputsTest, WritesEveryFile) {
  auto wp = Cut(SchemeKind::kTaylor);
  const SurfaceGrid g = GridOf(*wp);
  const std::vector<MarkPolyline> marks = TestMarks(*wp);
  ValuationOptions vo;
  vo.map_cols = 50;
  vo.map_rows = 30;
  auto stats = MeasureError(*wp, vo);
  ASSERT_TRUE(stats.ok());
  const ErrorRaster raster{{0, 0, 50, 30}, 50, 30, stats->map};
  TempDir dir;
  auto written = WriteRunOutputs(dir.path(), g, &raster, &marks);
  ASSERT_TRUE(written.ok()) << written.status();
  std::vector<std::string> names;
  for (const WrittenFile& w : *written) {
    names.push_back(std::filesystem::path(w.path).filename());
    EXPECT_GT(std::filesystem::file_size(w.path), 100u) << w.path;
  }
  EXPECT_EQ(names, (std::vector<std::string>{
                       "relief.png", "error.png", "marks.png", "marks.svg",
                       "marks.json", "surface.stl", "surface.wrl"}));
  for (const char* png : {"relief.png", "error.png", "marks.png"}) {
    EXPECT_TRUE(ReadPng(dir.File(png)).ok()) << png;
  }
  EXPECT_EQ(ParseStl(ReadAll(dir.File("surface.stl"))).count,
            ExpectedTriangles(100, 60));
  // Without error map and marks: only the surface files.
  TempDir dir2;
  written = WriteRunOutputs(dir2.path(), g, nullptr, nullptr);
  ASSERT_TRUE(written.ok());
  EXPECT_EQ(written->size(), 3u);
  EXPECT_FALSE(std::filesystem::exists(dir2.File("marks.json")));
  EXPECT_FALSE(WriteRunOutputs(dir.File("missing"), g, nullptr, nullptr).ok());
}

// The performance figure: every file for a 1000 x 1000 grid.
TEST(RunOutputsTest, LargeGridTiming) {
  const StockSpec spec{0, 0, 100, 100, 20, 1000, 1000};
  std::vector<Move> moves;
  for (int k = 0; k < 40; ++k) {  // raster passes, 2 mm apart, ball r = 3
    const double y = 10 + 2 * k;
    moves.push_back({{10, y, 17}, {90, y, 17 + 0.02 * k}, 3});
  }
  moves.push_back({{50, 50, 14}, {50, 50, 14}, 10});  // a deep crater
  auto wp = Cut(SchemeKind::kTaylor, spec, moves);
  const SurfaceGrid g = GridOf(*wp);
  const std::vector<MarkPolyline> marks = TestMarks(*wp);
  ValuationOptions vo;
  vo.map_cols = 1000;
  vo.map_rows = 1000;
  auto stats = MeasureError(*wp, vo);
  ASSERT_TRUE(stats.ok());
  const ErrorRaster raster{{0, 0, 100, 100}, 1000, 1000, stats->map};
  TempDir dir;
  const auto t0 = std::chrono::steady_clock::now();
  auto written = WriteRunOutputs(dir.path(), g, &raster, &marks);
  const double total =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0)
          .count();
  ASSERT_TRUE(written.ok()) << written.status();
  for (const WrittenFile& w : *written) {
    std::printf("  %-12s %7.3f s %10ju bytes\n",
                std::filesystem::path(w.path).filename().c_str(), w.seconds,
                static_cast<uintmax_t>(std::filesystem::file_size(w.path)));
  }
  std::printf("  all files for 1001 x 1001 nodes, %zu marks: %.3f s\n",
              marks.size(), total);
  RecordProperty("seconds", std::to_string(total));
  EXPECT_LT(total, 30);  // a sanity bound; the figure is in the output
}

// ------------------------------------------------ the same figures, faster

uint64_t Fnv(const void* p, size_t n, uint64_t h = 1469598103934665603ull) {
  const unsigned char* b = static_cast<const unsigned char*>(p);
  for (size_t k = 0; k < n; ++k) {
    h ^= b[k];
    h *= 1099511628211ull;
  }
  return h;
}

// Ball passes at several depths over a 12 x 9 mm stock (guarded, 0.1 mm),
// a diagonal ramp and a plunge: creases, rims and detail everywhere.
std::vector<Move> GoldenMoves() {
  std::vector<Move> m;
  for (int k = 0; k < 14; ++k) {
    const double y = 1.5 + 0.55 * k, z = -0.4 - 0.15 * (k % 4);
    m.push_back({{-1, y, z}, {13, y + 0.3 * (k % 2), z - 0.2}, 0.8});
  }
  m.push_back({{2, 2, 1}, {11, 8, -1.1}, 1.2});
  m.push_back({{6.3, 4.1, 0.5}, {6.3, 4.1, -1.7}, 0.6});
  return m;
}

// The writers' figures and bytes on a fixed scene, as they were before
// issue 14's speed-ups (main at 4627b2d: serial strokes, one JSON/SVG
// string, measuring every leaf again, ...) and after: the
// adaptive mesh (triangles, measured deviation, every vertex and index),
// the relief and marks pictures' pixels, marks.json and marks.svg.
TEST(OutputsGoldenTest, GuardedSceneFiguresAreUnchanged) {
  const StockSpec spec{0, 0, 12, 9, 0, 120, 90};
  auto wp = Cut(SchemeKind::kGuarded, spec, GoldenMoves());
  const SurfaceGrid g = GridOf(*wp);
  SurfaceMeshOptions o;
  o.tolerance = 0.005;
  auto mesh = BuildSurfaceMesh(g, o);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(mesh->triangles.size(), 2868u);
  EXPECT_EQ(mesh->max_deviation, 0.0048927818058065453);
  uint64_t h = Fnv(mesh->vertices.data(), mesh->vertices.size() * sizeof(Vec3));
  h = Fnv(mesh->triangles.data(),
          mesh->triangles.size() * sizeof(mesh->triangles[0]), h);
  EXPECT_EQ(h, 0x493636f244403715u);

  auto relief = RenderRelief(g, {});
  ASSERT_TRUE(relief.ok());
  // Changed on purpose (the guarded lift folded into its patch, Guard::
  // lift_uv: the same quadric, rounded otherwise): 72 of its 11,011 pixels
  // by at most 5 levels. Its pixels lie on nodes, where the four lifted
  // patches meet at the node's height to a rounding with different slopes:
  // the rounding picks the patch whose slope shades the pixel.
  EXPECT_EQ(Fnv(relief->pixels().data(), relief->pixels().size()),
            0x47914857c4534032u);

  auto found = FindCuttingMarks(*wp, {});
  ASSERT_TRUE(found.ok());
  const std::vector<MarkPolyline> marks =
      FilterMarks(*found, kDefaultMarkDisplay);
  EXPECT_EQ(marks.size(), 22u);
  const MarksPictureOptions mo;
  auto fine = RenderRelief(g, mo.relief);
  ASSERT_TRUE(fine.ok());
  auto picture = DrawMarks(*fine, ReliefFrame(g.spec, mo.relief), marks, mo);
  ASSERT_TRUE(picture.ok());
  EXPECT_EQ(picture->width(), 1141);
  EXPECT_EQ(picture->height(), 750);  // 24 bands of rows drawn at once
  // Changed on purpose (each polyline blended once per pixel, sub-pixel
  // vertices dropped: MarksTest.PolylineIsBlendedOncePerPixel).
  EXPECT_EQ(Fnv(picture->pixels().data(), picture->pixels().size()),
            0xcf3756e8ca484bc4u);

  const std::string json = MarksJson(marks), svg = MarksSvg(spec, marks);
  EXPECT_EQ(Fnv(json.data(), json.size()), 0xf8e7a3c03ce96293u);
  EXPECT_EQ(Fnv(svg.data(), svg.size()), 0xe7f7c6ba389e333cu);
}

// The relief's sampler (corners and trust frames kept between points) is
// SurfaceGrid::HeightAndGradient bit for bit, in rows and at random, also
// with its caches over a window of node columns.
TEST(SurfaceSamplerTest, MatchesHeightAndGradientBitForBit) {
  for (SchemeKind scheme : {SchemeKind::kGuarded, SchemeKind::kTaylor,
                            SchemeKind::kZmap, SchemeKind::kExact}) {
    SCOPED_TRACE(GetScheme(scheme).name());
    const StockSpec spec{0, 0, 12, 9, 0, 60, 45};
    auto wp = Cut(scheme, spec, GoldenMoves());
    const SurfaceGrid g = GridOf(*wp);
    SurfaceSampler sampler(g);
    std::mt19937_64 rng(8);
    std::uniform_real_distribution<double> ux(-0.5, 12.5), uy(-0.5, 9.5);
    std::vector<std::pair<double, double>> points;
    for (int j = 0; j <= 100; ++j) {
      for (int i = 0; i <= 130; ++i) points.push_back({i * 0.093, j * 0.09});
    }
    for (int k = 0; k < 5000; ++k) points.push_back({ux(rng), uy(rng)});
    // The points in [x0, x1] through `s`, against the grid.
    auto expect_same = [&](SurfaceSampler& s, double x0, double x1) {
      for (const auto& [x, y] : points) {
        if (x < x0 || x > x1) continue;
        double gx, gy, hx, hy;
        const double z = s.HeightAndGradient(x, y, &gx, &gy);
        const double w = g.HeightAndGradient(x, y, &hx, &hy);
        ASSERT_EQ(std::memcmp(&z, &w, 8), 0) << x << ", " << y;
        ASSERT_EQ(gx, hx) << x << ", " << y;
        ASSERT_EQ(gy, hy) << x << ", " << y;
        ASSERT_EQ(w, g.Height(x, y));
      }
    };
    expect_same(sampler, -1, 13);
    // A sampler whose caches span a few node columns (the relief's chunks
    // of pixel columns), for points in those columns' elements.
    const GridGeometry geometry(spec);
    const int32_t i0 = geometry.ElementX(3.0), i1 = geometry.ElementX(7.0) + 1;
    SurfaceSampler window(g, i0, i1);
    expect_same(window, 3.0, 7.0);
  }
}

// marks.json and marks.svg are formatted in chunks of polylines at once:
// the same bytes as one writer over all of them (here as the files were
// written before), across several chunks, in memory and in the files.
TEST(MarksTest, JsonAndSvgInChunksAreOneDocument) {
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-50, 50);
  std::vector<MarkPolyline> marks(2600);
  for (size_t k = 0; k < marks.size(); ++k) {
    MarkPolyline& p = marks[k];
    p.closed = k % 7 == 0;
    p.owners = {static_cast<int32_t>(k % 5) - 1, static_cast<int32_t>(k)};
    for (size_t v = 0; v < 1 + k % 4; ++v) {
      p.vertices.push_back({u(rng), u(rng), u(rng) / 1e3});
      p.angle_deg.push_back(std::fabs(u(rng)));
      p.vertex_owners.push_back({static_cast<int32_t>(v), -1});
    }
  }
  // marks.json's own writer against JsonWriter's edges: no vertices, the
  // numbers JsonWriter writes as null or in exponent form, -0, the ends of
  // the owners' range.
  const double inf = std::numeric_limits<double>::infinity();
  MarkPolyline& empty = marks.emplace_back();
  empty.owners = {std::numeric_limits<int32_t>::min(),
                  std::numeric_limits<int32_t>::max()};
  MarkPolyline& odd = marks.emplace_back();
  odd.closed = true;
  odd.vertices = {{std::nan(""), inf, -inf},
                  {-0.0, 1e300, 5e-324},
                  {123456789.125, -1e-7, 0.1}};
  odd.angle_deg = {std::nan(""), -0.0, inf};
  odd.vertex_owners = {{-7, 0}, {2147483647, -2147483647}, {1, 2}};
  for (bool vertex_owners : {false, true}) {
    JsonWriter j;
    j.BeginObject().Key("polylines").BeginArray();
    for (const MarkPolyline& p : marks) {
      j.BeginObject().Key("closed").Bool(p.closed);
      j.Key("owners").BeginArray().Int(p.owners[0]).Int(p.owners[1]).EndArray();
      j.Key("vertices").BeginArray();
      for (const Vec3& v : p.vertices) {
        j.BeginArray().Double(v.x).Double(v.y).Double(v.z).EndArray();
      }
      j.EndArray().Key("angle_deg").BeginArray();
      for (double a : p.angle_deg) j.Double(a);
      j.EndArray();
      if (vertex_owners) {
        j.Key("vertex_owners").BeginArray();
        for (const auto& o : p.vertex_owners) {
          j.BeginArray().Int(o[0]).Int(o[1]).EndArray();
        }
        j.EndArray();
      }
      j.EndObject();
    }
    j.EndArray().EndObject();
    EXPECT_EQ(MarksJson(marks, vertex_owners), j.str());
  }
  const StockSpec stock{-50, -50, 50, 50, 0, 100, 100};
  auto num = [](double v) { return absl::StrFormat("%.7g", v); };
  const double stroke = 100.0 / 400;
  std::string svg = absl::StrCat(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"",
      num(100), "mm\" height=\"", num(100), "mm\" viewBox=\"", num(-50), " ",
      num(-50), " ", num(100), " ", num(100), "\">\n",
      "<title>swarf cutting marks: ", marks.size(),
      " polylines, mm, y up</title>\n",
      "<g transform=\"scale(1,-1)\" fill=\"none\" stroke-linecap=\"round\" "
      "stroke-linejoin=\"round\">\n",
      "<rect x=\"", num(-50), "\" y=\"", num(-50), "\" width=\"", num(100),
      "\" height=\"", num(100), "\" stroke=\"#000000\" stroke-width=\"",
      num(stroke * 0.6), "\"/>\n");
  for (const MarkPolyline& p : marks) {
    double mean = 0;
    for (double a : p.angle_deg) mean += a;
    if (!p.angle_deg.empty()) mean /= p.angle_deg.size();
    const Rgb c = AngleColor(mean);
    absl::StrAppend(&svg, "<path stroke=\"",
                    absl::StrFormat("#%02x%02x%02x", c.r, c.g, c.b),
                    "\" stroke-width=\"", num(stroke), "\" data-owners=\"",
                    p.owners[0], " ", p.owners[1], "\" data-angle-deg=\"",
                    num(mean), "\" d=\"");
    for (size_t k = 0; k < p.vertices.size(); ++k) {
      absl::StrAppend(&svg, k == 0 ? "M" : " L", num(p.vertices[k].x), " ",
                      num(p.vertices[k].y));
    }
    if (p.closed) svg += " Z";
    absl::StrAppend(&svg, "\"><title>owners ", p.owners[0], " ", p.owners[1],
                    ", mean angle ", absl::StrFormat("%.2f", mean),
                    " deg</title></path>\n");
  }
  svg += "</g>\n</svg>\n";
  EXPECT_EQ(MarksSvg(stock, marks), svg);
  TempDir dir;
  ASSERT_TRUE(WriteMarksJson(marks, dir.File("m.json")).ok());
  ASSERT_TRUE(WriteMarksSvg(stock, marks, dir.File("m.svg")).ok());
  EXPECT_EQ(ReadAll(dir.File("m.json")), MarksJson(marks) + "\n");
  EXPECT_EQ(ReadAll(dir.File("m.svg")), svg);
}

}  // namespace
}  // namespace swarf::cli
