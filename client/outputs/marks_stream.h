// The cutting marks of `swarf run --out` consumed as they arrive (issue 28):
// summarised, filtered for display, the shown pieces appended to marks.svg
// and marks.json and spooled to disk for marks.png, which needs the relief
// sampled later. No more than two batches of marks are held at a time: one
// filling while the last is written.
#ifndef SWARF_CLIENT_MARKS_STREAM_H_
#define SWARF_CLIENT_MARKS_STREAM_H_

#include <cstddef>
#include <future>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "client/outputs/marks_files.h"
#include "client/outputs/pictures.h"
#include "client/outputs/run_outputs.h"
#include "core/cutting_marks.h"
#include "core/stock.h"

namespace swarf::cli {

class FileWriter;

// Polylines kept on disk for marks.png, as it strokes them: the kept
// polylines of a picture in `frame` (MarkKeeper), in exact doubles. The
// file is removed when the spool goes (whatever happened). Not thread-safe.
class MarksSpool {
 public:
  MarksSpool(std::string path, const PixelFrame& frame);
  ~MarksSpool();
  MarksSpool(const MarksSpool&) = delete;
  MarksSpool& operator=(const MarksSpool&) = delete;

  // Keeps (on every thread) and appends (buffered). Errors are sticky: a
  // write error names the file; a polyline whose angles do not match its
  // vertices is DrawMarks's error.
  absl::Status Append(std::span<const MarkPolyline> batch);
  // After the last Append: flushes and closes.
  absl::Status Finish();
  // The kept polylines as appended, read from the file (after Finish): the
  // first error instead if there was one, else DrawMarks's error for a
  // vertex that is not finite. Valid while the spool lives.
  KeptMarkSource source() const;
  const PixelFrame& frame() const { return keeper_.frame(); }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  MarkKeeper keeper_;
  std::unique_ptr<FileWriter> file_;
  absl::Status status_;
  std::string bytes_;  // a kept polyline's, reused
};

// Consumes the marks one polyline at a time, in the order they come.
//
// Summary only (no `dir`): all() is Summarize of the polylines added.
// With `dir` (an existing directory): also shown() (Summarize of
// FilterMarks of them), and the shown pieces written to dir/marks.svg and
// dir/marks.json (the bytes WriteMarksSvg/WriteMarksJson write for
// FilterMarks of all of them) and spooled to dir/marks.png.spool as
// marks.png in `picture` strokes them (MarksSpool), a batch
// of `batch_vertices` shown vertices at a time (formatted in parallel, the
// three files at once on threads of the stream's own while the next batch
// is taken; memory, not the files, depends on it).
//
// Write errors do not stop the consumption (the summaries are still
// computed): they are kept, the first naming its file, and reported by
// streamed(). As the files are chained in WriteRunOutputs, there is no
// marks.json after an error in marks.svg (it stops a batch later and is
// not finished). Files not finished are removed when the stream goes, and
// the spool always. Not thread-safe.
struct MarksStreamOptions {
  size_t batch_vertices = size_t{1} << 18;  // >= 1
};

class MarksStream {
 public:
  MarksStream();
  MarksStream(const StockSpec& stock, const std::string& dir,
              const MarkDisplayFilter& filter, const PixelFrame& picture,
              const MarksStreamOptions& options = {});
  ~MarksStream();
  MarksStream(const MarksStream&) = delete;
  MarksStream& operator=(const MarksStream&) = delete;

  void Add(MarkPolyline p);
  // After the last Add: writes what is held, finishes the files.
  void Finish();

  MarkSummary all() const { return all_.summary(); }
  std::optional<MarkSummary> shown() const;
  // After Finish: marks.svg and marks.json as written (with the seconds
  // spent formatting and writing each), the first write error, and the
  // spooled shown marks for marks.png. The source is valid while the
  // stream lives.
  StreamedMarks streamed() const;

 private:
  // Hands the batch to the writing thread (after the last batch's write).
  void Flush();
  // Writes writing_ to the files and the spool (the writing thread).
  void WriteBatch();
  // Waits for the batch being written, if any.
  void WaitForWrite();

  const bool files_ = false;
  MarkDisplayFilter filter_;
  MarksStreamOptions options_;
  MarkSummarizer all_, shown_;
  std::unique_ptr<MarksSvgWriter> svg_;
  std::unique_ptr<MarksJsonWriter> json_;
  std::unique_ptr<MarksSpool> spool_;
  std::vector<MarkPolyline> batch_, pieces_;
  size_t batch_vertices_ = 0;
  // The batch being written and its write; the statuses and seconds below
  // are the writing threads' while they run (each file's its own).
  std::vector<MarkPolyline> writing_;
  std::future<void> write_;
  absl::Status svg_status_, json_status_;
  double svg_seconds_ = 0, json_seconds_ = 0;
  bool finished_ = false;
};

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_MARKS_STREAM_H_
