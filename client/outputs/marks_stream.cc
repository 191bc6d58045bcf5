#include "client/outputs/marks_stream.h"

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <utility>

#include "absl/strings/str_cat.h"
#include "client/outputs/file_writer.h"

namespace swarf::cli {
namespace {

using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// A spooled kept polyline: this head, then its x, y and angle arrays of
// `vertices` doubles each, in the machine's byte order (the file never
// leaves the run).
struct SpoolHead {
  uint64_t vertices = 0;
  uint8_t wrap = 0;
  uint8_t pad[7] = {};
};

template <typename T>
void Put(std::string* s, const T& v) {
  s->append(reinterpret_cast<const char*>(&v), sizeof v);
}

void PutAll(std::string* s, std::span<const double> v) {
  s->append(reinterpret_cast<const char*>(v.data()), v.size_bytes());
}

}  // namespace

MarksSpool::MarksSpool(std::string path, const PixelFrame& frame)
    : path_(std::move(path)),
      keeper_(frame),
      file_(std::make_unique<FileWriter>(path_)) {
  status_ = file_->status();
}

MarksSpool::~MarksSpool() {
  file_.reset();  // removed if unclosed
  std::remove(path_.c_str());
}

absl::Status MarksSpool::Append(std::span<const MarkPolyline> batch) {
  if (!status_.ok()) return status_;
  // Kept here, once, as the marks arrive: marks.png reads the file twice
  // (the halos, then the lines), and the kept vertices are a small part of
  // a fine grid's (a few a pixel of a mark's length instead of tens).
  auto write = [&](const KeptPolyline& p) {
    bytes_.clear();
    SpoolHead h;
    h.vertices = p.x.size();
    h.wrap = p.wrap ? 1 : 0;
    Put(&bytes_, h);
    PutAll(&bytes_, p.x);
    PutAll(&bytes_, p.y);
    PutAll(&bytes_, p.angle);
    file_->Write(bytes_);
    return absl::OkStatus();
  };
  for (const MarkPolyline& p : batch) {
    status_ = keeper_.Add(p);
    if (status_.ok() && keeper_.full()) status_ = keeper_.Take(write);
    if (!status_.ok()) return status_;
  }
  status_ = keeper_.Take(write);
  if (status_.ok()) status_ = file_->status();
  return status_;
}

absl::Status MarksSpool::Finish() {
  if (!status_.ok()) return status_;
  status_ = file_->Close();
  return status_;
}

KeptMarkSource MarksSpool::source() const {
  return [this](const std::function<absl::Status(const KeptPolyline&)>& visit)
             -> absl::Status {
    if (!status_.ok()) return status_;
    if (absl::Status st = keeper_.finite_status(); !st.ok()) return st;
    std::FILE* in = std::fopen(path_.c_str(), "rb");
    if (in == nullptr) {
      return absl::InternalError(absl::StrCat("cannot read ", path_, " back: ",
                                              std::strerror(errno)));
    }
    // 1 MiB reads instead of the default few KiB.
    std::vector<char> buffer(size_t{1} << 20);
    std::setvbuf(in, buffer.data(), _IOFBF, buffer.size());
    absl::Status st;
    std::vector<double> v;  // x, y, angle
    SpoolHead h;
    while (st.ok() && std::fread(&h, sizeof h, 1, in) == 1) {
      const size_t n = h.vertices;
      v.resize(3 * n);
      if (std::fread(v.data(), sizeof(double), v.size(), in) != v.size()) {
        st = absl::DataLossError(absl::StrCat(path_, " is truncated"));
        break;
      }
      st = visit(KeptPolyline{{v.data(), n},
                              {v.data() + n, n},
                              {v.data() + 2 * n, n},
                              h.wrap != 0});
    }
    if (st.ok() && std::ferror(in)) {
      st = absl::InternalError(absl::StrCat("reading ", path_, " back failed: ",
                                            std::strerror(errno)));
    }
    std::fclose(in);
    return st;
  };
}

MarksStream::MarksStream() = default;

MarksStream::MarksStream(const StockSpec& stock, const std::string& dir,
                         const MarkDisplayFilter& filter,
                         const PixelFrame& picture,
                         const MarksStreamOptions& options)
    : files_(true), filter_(filter), options_(options) {
  const std::filesystem::path d(dir);
  const auto t0 = Clock::now();
  svg_ = std::make_unique<MarksSvgWriter>(stock, (d / "marks.svg").string());
  svg_seconds_ += Since(t0);
  const auto t1 = Clock::now();
  json_ = std::make_unique<MarksJsonWriter>((d / "marks.json").string());
  json_seconds_ += Since(t1);
  spool_ =
      std::make_unique<MarksSpool>((d / "marks.png.spool").string(), picture);
}

// The writers' destructors remove unfinished files; the spool's its file.
MarksStream::~MarksStream() { WaitForWrite(); }

void MarksStream::WaitForWrite() {
  if (write_.valid()) write_.get();
}

void MarksStream::Add(MarkPolyline p) {
  all_.Add(p);
  if (!files_) return;
  pieces_.clear();
  FilterMark(std::move(p), filter_, &pieces_);
  for (MarkPolyline& piece : pieces_) {
    shown_.Add(piece);
    batch_vertices_ += piece.vertices.size();
    batch_.push_back(std::move(piece));
  }
  if (batch_vertices_ >= options_.batch_vertices) Flush();
}

void MarksStream::Flush() {
  if (batch_.empty()) return;
  // The reader goes on taking marks while a batch is formatted and
  // written: written in its turn, the server's search waited for it.
  WaitForWrite();
  writing_.swap(batch_);
  batch_.clear();
  batch_vertices_ = 0;
  write_ = std::async(std::launch::async, [this] { WriteBatch(); });
}

void MarksStream::WriteBatch() {
  // The three files at once: each one's writes copy the text into the page
  // cache on one thread (a file's writes are serialised by the kernel),
  // and one after another they bounded the marks' stream. As the files
  // were chained, marks.json stops at marks.svg's error (a batch later:
  // marks.json is then not finished, and removed).
  const bool json = svg_status_.ok() && json_status_.ok();
  std::future<void> json_write;
  if (json) {
    json_write = std::async(std::launch::async, [this] {
      const auto t0 = Clock::now();
      json_status_ = json_->Append(writing_);
      json_seconds_ += Since(t0);
    });
  }
  // Its error is marks.png's, when it is drawn.
  std::future<void> spool_write = std::async(
      std::launch::async, [this] { (void)spool_->Append(writing_); });
  if (svg_status_.ok()) {
    const auto t0 = Clock::now();
    svg_status_ = svg_->Append(writing_);
    svg_seconds_ += Since(t0);
  }
  spool_write.get();
  if (json_write.valid()) json_write.get();
}

void MarksStream::Finish() {
  if (!files_ || finished_) return;
  finished_ = true;
  Flush();
  WaitForWrite();
  if (svg_status_.ok()) {
    const auto t0 = Clock::now();
    svg_status_ = svg_->Finish();
    svg_seconds_ += Since(t0);
  }
  if (svg_status_.ok() && json_status_.ok()) {
    const auto t0 = Clock::now();
    json_status_ = json_->Finish();
    json_seconds_ += Since(t0);
  }
  (void)spool_->Finish();
  // Not needed any more: their buffers go.
  batch_ = std::vector<MarkPolyline>();
  pieces_ = std::vector<MarkPolyline>();
  writing_ = std::vector<MarkPolyline>();
}

std::optional<MarkSummary> MarksStream::shown() const {
  if (!files_) return std::nullopt;
  return shown_.summary();
}

StreamedMarks MarksStream::streamed() const {
  StreamedMarks s;
  if (!files_) return s;
  s.source = spool_->source();
  s.frame = spool_->frame();
  if (svg_status_.ok()) s.files.push_back({svg_->path(), svg_seconds_});
  if (svg_status_.ok() && json_status_.ok()) {
    s.files.push_back({json_->path(), json_seconds_});
  }
  s.status = !svg_status_.ok() ? svg_status_ : json_status_;
  return s;
}

}  // namespace swarf::cli
