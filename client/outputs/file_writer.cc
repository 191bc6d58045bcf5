#include "client/outputs/file_writer.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <future>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/thread_pool.h"

namespace swarf::cli {
namespace {

// Large writes amortize the syscalls; meshes reach 100 MB.
constexpr size_t kBufferBytes = size_t{1} << 20;

}  // namespace

FileWriter::FileWriter(std::string path) : path_(std::move(path)) {
  file_ = std::fopen(path_.c_str(), "wb");
  if (file_ == nullptr) {
    status_ = absl::PermissionDeniedError(
        absl::StrCat("cannot open ", path_, ": ", std::strerror(errno)));
  }
  buffer_.reserve(kBufferBytes);
}

FileWriter::~FileWriter() {
  if (file_ != nullptr) {
    std::fclose(file_);
    std::remove(path_.c_str());
  }
}

void FileWriter::Write(std::string_view data) {
  if (!status_.ok()) return;
  if (data.size() >= kBufferBytes) {
    // Large pieces (WriteChunks') go out without a copy.
    Flush();
    WriteNow(data);
    return;
  }
  buffer_.append(data);
  if (buffer_.size() >= kBufferBytes) Flush();
}

namespace {

// FormatInOrder over `chunks` chunks, chunk c holding items [first_of(c),
// first_of(c + 1)).
void FormatChunksInOrder(
    int64_t chunks, const std::function<int64_t(int64_t)>& first_of,
    int64_t chunks_at_once,
    const std::function<void(int64_t, int64_t, std::string*)>& format,
    const std::function<void(std::string_view)>& put) {
  if (chunks <= 0) return;
  const int64_t group = std::min(chunks, std::max<int64_t>(chunks_at_once, 1));
  // Two groups' pieces: one is put, on a thread of its own, while the next
  // is made. Put after its group was made, a file's writes (serialised by
  // the kernel, on one thread) left the pool idle for this file, and the
  // next group waited for them.
  std::vector<std::string> pieces[2];
  std::future<void> putting;
  int made = 0;
  for (int64_t c0 = 0; c0 < chunks; c0 += group, made ^= 1) {
    const int64_t nc = std::min(group, chunks - c0);
    std::vector<std::string>& p = pieces[made];
    p.resize(group);
    ThreadPool::Default().ParallelFor(nc, [&](int64_t k) {
      // Formatted into a string of this thread's stack, its buffer (and
      // capacity) taken from the piece and handed back: the pieces' own
      // string objects share cache lines, and a writer's many small
      // appends, each storing the length, kept those lines moving between
      // the threads' cores (marks.json in single appends took 1.35 times
      // the time).
      std::string text = std::move(p[k]);
      text.clear();
      format(first_of(c0 + k), first_of(c0 + k + 1), &text);
      p[k] = std::move(text);
    });
    if (putting.valid()) putting.get();  // the other group is put
    if (c0 + nc == chunks) {
      for (int64_t k = 0; k < nc; ++k) put(p[k]);  // the last: here
      break;
    }
    putting = std::async(std::launch::async, [&put, &p, nc] {
      for (int64_t k = 0; k < nc; ++k) put(p[k]);
    });
  }
}

}  // namespace

void FormatInOrder(
    int64_t n, int64_t per_chunk, int64_t chunks_at_once,
    const std::function<void(int64_t, int64_t, std::string*)>& format,
    const std::function<void(std::string_view)>& put) {
  if (n <= 0) return;
  per_chunk = std::max<int64_t>(per_chunk, 1);
  FormatChunksInOrder(
      (n + per_chunk - 1) / per_chunk,
      [n, per_chunk](int64_t c) { return std::min(n, c * per_chunk); },
      chunks_at_once, format, put);
}

void FormatInOrder(
    std::span<const int64_t> first, int64_t chunks_at_once,
    const std::function<void(int64_t, int64_t, std::string*)>& format,
    const std::function<void(std::string_view)>& put) {
  if (first.size() < 2) return;
  FormatChunksInOrder(
      static_cast<int64_t>(first.size()) - 1,
      [first](int64_t c) { return first[c]; }, chunks_at_once, format, put);
}

void FileWriter::WriteChunks(
    int64_t n, int64_t per_chunk,
    const std::function<void(int64_t, int64_t, std::string*)>& format) {
  // Formatting (the meshes' floats and normals) was their files' serial
  // step; only the writes stay in order.
  FormatInOrder(n, per_chunk, 2 * ThreadPool::Default().size(), format,
                [this](std::string_view piece) { Write(piece); });
}

void FileWriter::WriteNow(std::string_view data) {
  if (!status_.ok() || data.empty()) return;
  if (std::fwrite(data.data(), 1, data.size(), file_) != data.size()) {
    status_ = absl::InternalError(
        absl::StrCat("writing ", path_, " failed: ", std::strerror(errno)));
  }
}

void FileWriter::Flush() {
  WriteNow(buffer_);
  buffer_.clear();
}

absl::Status FileWriter::Close() {
  if (file_ == nullptr) return status_;
  Flush();
  const bool close_failed = std::fclose(file_) != 0;
  file_ = nullptr;
  if (status_.ok() && close_failed) {
    status_ = absl::InternalError(
        absl::StrCat("closing ", path_, " failed: ", std::strerror(errno)));
  }
  if (!status_.ok()) std::remove(path_.c_str());
  return status_;
}

absl::Status WriteStringToFile(const std::string& path,
                               std::string_view data) {
  FileWriter f(path);
  f.Write(data);
  return f.Close();
}

}  // namespace swarf::cli
