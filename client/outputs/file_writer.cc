#include "client/outputs/file_writer.h"

#include <cerrno>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"

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
  buffer_.append(data);
  if (buffer_.size() >= kBufferBytes) Flush();
}

void FileWriter::Flush() {
  if (!status_.ok() || buffer_.empty()) return;
  if (std::fwrite(buffer_.data(), 1, buffer_.size(), file_) !=
      buffer_.size()) {
    status_ = absl::InternalError(
        absl::StrCat("writing ", path_, " failed: ", std::strerror(errno)));
  }
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
