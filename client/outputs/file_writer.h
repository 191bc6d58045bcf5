// Buffered output files for the writers: errors name the path, and a file
// that could not be written completely is removed.
#ifndef SWARF_CLIENT_FILE_WRITER_H_
#define SWARF_CLIENT_FILE_WRITER_H_

#include <cstdint>
#include <cstdio>
#include <functional>
#include <span>
#include <string>
#include <string_view>

#include "absl/status/status.h"

namespace swarf::cli {

class FileWriter {
 public:
  // Opens (truncates) `path`; check status() before writing.
  explicit FileWriter(std::string path);
  ~FileWriter();  // an unclosed file is removed
  FileWriter(const FileWriter&) = delete;
  FileWriter& operator=(const FileWriter&) = delete;

  // Appends bytes (buffered). Errors are sticky and reported by Close.
  void Write(std::string_view data);
  // Appends the bytes of n items, made on every thread as FormatInOrder
  // makes them (two chunks a thread at a time) and written in order.
  void WriteChunks(int64_t n, int64_t per_chunk,
                   const std::function<void(int64_t first, int64_t last,
                                            std::string* out)>& format);
  // Flushes and closes; the first error naming the path, or OK.
  absl::Status Close();
  const absl::Status& status() const { return status_; }

 private:
  void Flush();
  // Writes `data` to the file past the buffer (a failure sets status_).
  void WriteNow(std::string_view data);
  std::string path_;
  std::FILE* file_ = nullptr;
  std::string buffer_;
  absl::Status status_;
};

// The bytes of n items, made in chunks of at most `per_chunk` items on every
// thread of ThreadPool::Default() and handed to put(piece) in order:
// format(first, last, out) appends the bytes of items [first, last) to *out
// (empty) and is called from several threads at once; `chunks_at_once`
// chunks (at least 1) are made at a time, and put (one call at a time, in
// order, on a thread of their own) while the next ones are made: at most
// twice that many chunks' bytes are held. Returns once every piece is put.
// The same pieces in order as formatting every item on one thread.
void FormatInOrder(int64_t n, int64_t per_chunk, int64_t chunks_at_once,
                   const std::function<void(int64_t first, int64_t last,
                                            std::string* out)>& format,
                   const std::function<void(std::string_view piece)>& put);

// The same with chunks of any sizes: chunk c holds items [first[c],
// first[c + 1]) (first ascending, first[0] = 0, first.back() = n; at least
// one chunk). For items of uneven cost (polylines of a few to thousands of
// vertices), chunks of even cost keep the threads evenly busy.
void FormatInOrder(std::span<const int64_t> first, int64_t chunks_at_once,
                   const std::function<void(int64_t first, int64_t last,
                                            std::string* out)>& format,
                   const std::function<void(std::string_view piece)>& put);

// Writes `data` to `path` whole.
absl::Status WriteStringToFile(const std::string& path, std::string_view data);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_FILE_WRITER_H_
