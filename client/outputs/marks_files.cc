#include "client/outputs/marks_files.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <span>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/outputs/colormap.h"
#include "client/outputs/file_writer.h"
#include "client/outputs/json_writer.h"
#include "core/thread_pool.h"

namespace swarf::cli {

void FilterMark(MarkPolyline p, const MarkDisplayFilter& filter,
                std::vector<MarkPolyline>* out) {
  const size_t n = p.vertices.size();
  const bool rim = p.owners[0] == kStockTopOwner;
  auto keep = [&](size_t k) {
    return rim || (k < p.angle_deg.size() &&
                   p.angle_deg[k] >= filter.min_angle_deg);
  };
  auto emit = [&](MarkPolyline piece) {
    if (piece.vertices.size() >= 2 &&
        PolylineLength(piece) >= filter.min_length) {
      out->push_back(std::move(piece));
    }
  };
  // Start after a dropped vertex, so that a closed polyline's run over
  // its first vertex stays whole.
  size_t start = 0;
  bool all = true;
  for (size_t k = 0; k < n; ++k) {
    if (!keep(k)) {
      all = false;
      start = p.closed ? k + 1 : 0;
      break;
    }
  }
  if (all) {
    emit(std::move(p));
    return;
  }
  MarkPolyline piece;
  auto flush = [&] {
    if (!piece.vertices.empty()) emit(std::move(piece));
    piece = MarkPolyline();
  };
  for (size_t q = 0; q < n; ++q) {
    const size_t k = (start + q) % n;
    if (!keep(k)) {
      flush();
      continue;
    }
    if (piece.vertices.empty()) {
      piece.owners = k < p.vertex_owners.size() ? p.vertex_owners[k]
                                                : p.owners;
    }
    piece.vertices.push_back(p.vertices[k]);
    if (k < p.angle_deg.size()) piece.angle_deg.push_back(p.angle_deg[k]);
    if (k < p.vertex_owners.size()) {
      piece.vertex_owners.push_back(p.vertex_owners[k]);
    }
  }
  flush();
}

std::vector<MarkPolyline> FilterMarks(std::vector<MarkPolyline> marks,
                                      const MarkDisplayFilter& filter) {
  std::vector<MarkPolyline> out;
  for (MarkPolyline& item : marks) {
    // Moved out, so that it is freed at the end of its turn.
    FilterMark(std::move(item), filter, &out);
  }
  return out;
}

namespace {

// A polyline's formatting cost in vertices: its own text (colour,
// owners, tags) counted as this many more.
constexpr int64_t kPolylineWeight = 4;
// The most vertices a chunk is cut for (a polyline longer than that is
// a chunk of its own): with ChunksAtOnce, it bounds the text held at a
// time (about 0.7 MB a chunk), whatever the number of marks.
constexpr int64_t kChunkWeight = 16384;

// Chunks formatted at once before they are written: ChunkBounds' four a
// thread, so that a batch is one group (each group waits for its slowest
// chunk), and at least 32.
int64_t ChunksAtOnce() {
  return std::max<int64_t>(32, 4 * ThreadPool::Default().size());
}

// The first polyline of each chunk, then n: chunks of about even cost
// (vertices_of(k) + kPolylineWeight a polyline), about four a thread, so
// that polylines of a few to thousands of vertices (a plate's passes)
// still keep every thread evenly busy. Each polyline's text is its own
// whatever the chunk, so the bytes are the same.
std::vector<int64_t> ChunkBounds(
    size_t n, const std::function<size_t(size_t)>& vertices_of) {
  int64_t total = 0;
  for (size_t k = 0; k < n; ++k) {
    total += static_cast<int64_t>(vertices_of(k)) + kPolylineWeight;
  }
  const int64_t threads = ThreadPool::Default().size();
  const int64_t target =
      std::clamp<int64_t>(total / (4 * threads), 1, kChunkWeight);
  std::vector<int64_t> first = {0};
  int64_t weight = 0;
  for (size_t k = 0; k < n; ++k) {
    if (weight >= target) {
      first.push_back(static_cast<int64_t>(k));
      weight = 0;
    }
    weight += static_cast<int64_t>(vertices_of(k)) + kPolylineWeight;
  }
  first.push_back(static_cast<int64_t>(n));
  return first;
}

// format(k, &text) appends polyline k's text; chunks of polylines
// (ChunkBounds), ChunksAtOnce() at a time, are formatted on
// ThreadPool::Default(), then put in order and dropped.
void EmitChunks(std::span<const MarkPolyline> marks,
                const std::function<void(size_t, std::string*)>& format,
                const std::function<void(std::string_view)>& put) {
  if (marks.empty()) return;
  const std::vector<int64_t> bounds = ChunkBounds(
      marks.size(), [&](size_t k) { return marks[k].vertices.size(); });
  FormatInOrder(
      bounds, ChunksAtOnce(),
      [&](int64_t first, int64_t last, std::string* out) {
        for (int64_t k = first; k < last; ++k) {
          format(static_cast<size_t>(k), out);
        }
      },
      put);
}

// One polyline object as JsonWriter writes it inside the array (its
// members do not depend on what comes before it), preceded by the array's
// comma after the first. Written straight into `out`: a JsonWriter built
// each object in a string of its own (its nesting kept in a vector<bool>),
// then copied; bear at 0.2 mm: 476 -> 373 M instructions, 271 M of them
// the numbers' to_chars. MarksTest.JsonAndSvgInChunksAreOneDocument
// compares it with JsonWriter.
void AppendMarkJson(const MarkPolyline& p, bool vertex_owners, bool first,
                    std::string* out) {
  if (!first) *out += ',';
  *out += p.closed ? "{\"closed\":true,\"owners\":["
                   : "{\"closed\":false,\"owners\":[";
  AppendJsonInt(p.owners[0], out);
  *out += ',';
  AppendJsonInt(p.owners[1], out);
  *out += "],\"vertices\":[";
  for (size_t k = 0; k < p.vertices.size(); ++k) {
    const Vec3& v = p.vertices[k];
    *out += k == 0 ? "[" : ",[";
    AppendJsonDouble(v.x, out);
    *out += ',';
    AppendJsonDouble(v.y, out);
    *out += ',';
    AppendJsonDouble(v.z, out);
    *out += ']';
  }
  *out += "],\"angle_deg\":[";
  for (size_t k = 0; k < p.angle_deg.size(); ++k) {
    if (k != 0) *out += ',';
    AppendJsonDouble(p.angle_deg[k], out);
  }
  *out += ']';
  if (vertex_owners) {
    *out += ",\"vertex_owners\":[";
    for (size_t k = 0; k < p.vertex_owners.size(); ++k) {
      *out += k == 0 ? "[" : ",[";
      AppendJsonInt(p.vertex_owners[k][0], out);
      *out += ',';
      AppendJsonInt(p.vertex_owners[k][1], out);
      *out += ']';
    }
    *out += ']';
  }
  *out += '}';
}

constexpr std::string_view kMarksJsonHead = "{\"polylines\":[";
constexpr std::string_view kMarksJsonTail = "]}";

// The marks.json document piece by piece, in order, to put(piece).
void EmitMarksJson(const std::vector<MarkPolyline>& marks, bool vertex_owners,
                   const std::function<void(std::string_view)>& put) {
  put(kMarksJsonHead);
  EmitChunks(
      marks,
      [&](size_t k, std::string* out) {
        AppendMarkJson(marks[k], vertex_owners, k == 0, out);
      },
      put);
  put(kMarksJsonTail);
}

}  // namespace

std::string MarksJson(const std::vector<MarkPolyline>& marks,
                      bool vertex_owners) {
  std::string s;
  EmitMarksJson(marks, vertex_owners, [&](std::string_view p) { s += p; });
  return s;
}

absl::Status WriteMarksJson(const std::vector<MarkPolyline>& marks,
                            const std::string& path) {
  // Chunk by chunk: no copy of the whole document.
  FileWriter f(path);
  if (!f.status().ok()) return f.status();
  EmitMarksJson(marks, false, [&](std::string_view p) { f.Write(p); });
  f.Write("\n");
  return f.Close();
}

MarksJsonWriter::MarksJsonWriter(std::string path)
    : path_(std::move(path)), file_(std::make_unique<FileWriter>(path_)) {
  file_->Write(kMarksJsonHead);
}

MarksJsonWriter::~MarksJsonWriter() = default;

absl::Status MarksJsonWriter::Append(std::span<const MarkPolyline> batch) {
  if (!file_->status().ok()) return file_->status();
  EmitChunks(
      batch,
      [&](size_t k, std::string* out) {
        AppendMarkJson(batch[k], false, count_ + k == 0, out);
      },
      [&](std::string_view p) { file_->Write(p); });
  count_ += batch.size();
  return file_->status();
}

absl::Status MarksJsonWriter::Finish() {
  file_->Write(kMarksJsonTail);
  file_->Write("\n");
  return file_->Close();
}

namespace {

// 7 significant digits: 1e-5 mm on a 100 mm stock, well below any grid.
// printf's "%.7g" (std::to_chars with a precision converts as printf
// does), appended without a string per number.
void AppendNum(double v, std::string* s) {
  char buf[32];
  const std::to_chars_result r =
      std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 7);
  s->append(buf, r.ptr);
}

std::string Num(double v) {
  std::string s;
  AppendNum(v, &s);
  return s;
}

std::string MarksSvgHead(const StockSpec& stock, size_t polylines,
                         double stroke) {
  const double w = stock.x1 - stock.x0, h = stock.y1 - stock.y0;
  return absl::StrCat(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<svg xmlns=\"http://www.w3.org/2000/svg\" version=\"1.1\" width=\"",
      Num(w), "mm\" height=\"", Num(h), "mm\" viewBox=\"", Num(stock.x0), " ",
      Num(-stock.y1), " ", Num(w), " ", Num(h), "\">\n",
      "<title>swarf cutting marks: ", polylines,
      " polylines, mm, y up</title>\n",
      "<g transform=\"scale(1,-1)\" fill=\"none\" stroke-linecap=\"round\" "
      "stroke-linejoin=\"round\">\n",
      "<rect x=\"", Num(stock.x0), "\" y=\"", Num(stock.y0), "\" width=\"",
      Num(w), "\" height=\"", Num(h), "\" stroke=\"#000000\" stroke-width=\"",
      Num(stroke * 0.6), "\"/>\n");
}

constexpr std::string_view kMarksSvgTail = "</g>\n</svg>\n";

void AppendMarkSvg(const MarkPolyline& p, double stroke, std::string* s) {
  double mean = 0;
  for (double a : p.angle_deg) mean += a;
  if (!p.angle_deg.empty()) mean /= p.angle_deg.size();
  const Rgb c = AngleColor(mean);
  absl::StrAppend(s, "<path stroke=\"",
                  absl::StrFormat("#%02x%02x%02x", c.r, c.g, c.b),
                  "\" stroke-width=\"", Num(stroke), "\" data-owners=\"",
                  p.owners[0], " ", p.owners[1], "\" data-angle-deg=\"",
                  Num(mean), "\" d=\"");
  for (size_t k = 0; k < p.vertices.size(); ++k) {
    s->append(k == 0 ? "M" : " L");
    AppendNum(p.vertices[k].x, s);
    s->push_back(' ');
    AppendNum(p.vertices[k].y, s);
  }
  if (p.closed) *s += " Z";
  absl::StrAppend(s, "\"><title>owners ", p.owners[0], " ", p.owners[1],
                  ", mean angle ", absl::StrFormat("%.2f", mean),
                  " deg</title></path>\n");
}

// Strokes scale with the stock so that the drawing looks the same at any
// size: 1/400 of the longer side, the outline a little thinner.
double SvgStroke(const StockSpec& stock) {
  return std::max(stock.x1 - stock.x0, stock.y1 - stock.y0) / 400;
}

// The marks.svg document piece by piece, in order, to put(piece).
void EmitMarksSvg(const StockSpec& stock,
                  const std::vector<MarkPolyline>& marks,
                  const std::function<void(std::string_view)>& put) {
  const double stroke = SvgStroke(stock);
  put(MarksSvgHead(stock, marks.size(), stroke));
  EmitChunks(
      marks,
      [&](size_t k, std::string* out) { AppendMarkSvg(marks[k], stroke, out); },
      put);
  put(kMarksSvgTail);
}

}  // namespace

std::string MarksSvg(const StockSpec& stock,
                     const std::vector<MarkPolyline>& marks) {
  std::string s;
  EmitMarksSvg(stock, marks, [&](std::string_view p) { s += p; });
  return s;
}

absl::Status WriteMarksSvg(const StockSpec& stock,
                           const std::vector<MarkPolyline>& marks,
                           const std::string& path) {
  // Chunk by chunk: no copy of the whole document.
  FileWriter f(path);
  if (!f.status().ok()) return f.status();
  EmitMarksSvg(stock, marks, [&](std::string_view p) { f.Write(p); });
  return f.Close();
}

MarksSvgWriter::MarksSvgWriter(const StockSpec& stock, std::string path)
    : stock_(stock),
      path_(std::move(path)),
      body_(std::make_unique<FileWriter>(body_path())) {}

// An unclosed body is removed by its FileWriter; Finish removes a closed
// one.
MarksSvgWriter::~MarksSvgWriter() = default;

absl::Status MarksSvgWriter::Append(std::span<const MarkPolyline> batch) {
  if (!body_->status().ok()) return body_->status();
  const double stroke = SvgStroke(stock_);
  EmitChunks(
      batch,
      [&](size_t k, std::string* out) { AppendMarkSvg(batch[k], stroke, out); },
      [&](std::string_view p) { body_->Write(p); });
  count_ += batch.size();
  return body_->status();
}

absl::Status MarksSvgWriter::Finish() {
  const std::string body = body_path();
  if (absl::Status st = body_->Close(); !st.ok()) return st;
  absl::Status status;
  {
    FileWriter out(path_);
    out.Write(MarksSvgHead(stock_, count_, SvgStroke(stock_)));
    std::FILE* in = std::fopen(body.c_str(), "rb");
    if (in == nullptr) {
      status = absl::InternalError(absl::StrCat(
          "cannot read ", body, " back: ", std::strerror(errno)));
    } else {
      std::string block(size_t{1} << 20, '\0');
      size_t got;
      while ((got = std::fread(block.data(), 1, block.size(), in)) > 0) {
        out.Write(std::string_view(block.data(), got));
      }
      if (std::ferror(in)) {
        status = absl::InternalError(absl::StrCat(
            "reading ", body, " back failed: ", std::strerror(errno)));
      }
      std::fclose(in);
    }
    if (status.ok()) {
      out.Write(kMarksSvgTail);
      status = out.Close();
    }
    // Otherwise `out`, unclosed, is removed.
  }
  std::remove(body.c_str());
  return status;
}

}  // namespace swarf::cli
