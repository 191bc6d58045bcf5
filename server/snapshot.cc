#include "server/snapshot.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <cstring>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "server/journal.h"

namespace swarf::server {
namespace {

constexpr char kMagic[8] = {'S', 'W', 'A', 'R', 'F', 'S', 'N', 'P'};
constexpr uint32_t kFormat = 1;

struct Header {
  char magic[8];
  uint32_t format;
  uint32_t payload_crc;
  uint64_t seq;
  uint64_t payload_bytes;
  uint32_t header_crc;  // of the fields above
  uint32_t unused;
};
static_assert(sizeof(Header) == 40);

uint32_t HeaderCrc(const Header& h) {
  return Crc32c(&h, offsetof(Header, header_crc));
}

absl::Status Errno(const std::string& what, const std::string& path) {
  return absl::UnavailableError(
      absl::StrCat("snapshot: ", what, " ", path, ": ", std::strerror(errno)));
}

// Writes everything, retrying short writes.
bool WriteAll(int fd, const void* data, size_t size) {
  const char* p = static_cast<const char*>(data);
  while (size > 0) {
    const ssize_t n = ::write(fd, p, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    p += n;
    size -= static_cast<size_t>(n);
  }
  return true;
}

}  // namespace

std::string SnapshotPath(const std::string& journal_path) {
  return std::filesystem::path(journal_path).replace_extension(".snap");
}

absl::Status WriteSnapshot(const std::string& path, uint64_t seq,
                           const Workpiece& wp) {
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC,
                        0644);
  if (fd < 0) return Errno("cannot create", tmp);
  Header h{};
  std::memcpy(h.magic, kMagic, sizeof kMagic);
  h.format = kFormat;
  h.seq = seq;
  // The header is written last, once the payload's size and CRC are known.
  bool ok = ::lseek(fd, sizeof h, SEEK_SET) == sizeof h;
  std::string buffer;
  constexpr size_t kBuffer = size_t{1} << 20;
  buffer.reserve(kBuffer);
  auto flush = [&] {
    ok = ok && WriteAll(fd, buffer.data(), buffer.size());
    buffer.clear();
  };
  wp.SaveState([&](const void* data, size_t size) {
    h.payload_crc = Crc32c(data, size, h.payload_crc);
    h.payload_bytes += size;
    if (buffer.size() + size > kBuffer) flush();
    if (size >= kBuffer) {
      ok = ok && WriteAll(fd, data, size);
    } else {
      buffer.append(static_cast<const char*>(data), size);
    }
  });
  flush();
  h.header_crc = HeaderCrc(h);
  ok = ok && ::pwrite(fd, &h, sizeof h, 0) == sizeof h;
  if (::close(fd) != 0) ok = false;
  if (!ok) {
    absl::Status s = Errno("cannot write", tmp);
    std::filesystem::remove(tmp);
    return s;
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    absl::Status s = Errno("cannot rename over", path);
    std::filesystem::remove(tmp);
    return s;
  }
  return absl::OkStatus();
}

absl::StatusOr<SnapshotHeader> ReadSnapshotHeader(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return absl::NotFoundError("no snapshot");
    return absl::DataLossError(
        absl::StrCat("snapshot ", path, ": ", std::strerror(errno)));
  }
  Header h{};
  const off_t size = ::lseek(fd, 0, SEEK_END);
  const bool whole = ::pread(fd, &h, sizeof h, 0) == sizeof h;
  ::close(fd);
  std::string problem;
  if (!whole || std::memcmp(h.magic, kMagic, sizeof kMagic) != 0 ||
      h.header_crc != HeaderCrc(h)) {
    problem = "not a whole snapshot header";
  } else if (h.format != kFormat) {
    problem = absl::StrCat("format ", h.format, ", this swarfd reads ",
                           kFormat);
  } else if (h.seq == 0 || size < 0 ||
             h.payload_bytes != static_cast<uint64_t>(size) - sizeof h) {
    problem = absl::StrCat("truncated (", size, " bytes for a payload of ",
                           h.payload_bytes, ")");
  }
  if (!problem.empty()) {
    return absl::DataLossError(absl::StrCat("snapshot ", path, ": ", problem));
  }
  return SnapshotHeader{h.seq, h.payload_bytes, h.payload_crc};
}

absl::Status LoadSnapshot(const std::string& path,
                          const SnapshotHeader& header, Workpiece* wp) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    return absl::DataLossError(
        absl::StrCat("snapshot ", path, ": ", std::strerror(errno)));
  }
  // Reads the payload through a buffer, summing it as it goes.
  std::string buffer(size_t{1} << 20, '\0');
  size_t at = 0, have = 0;   // unread bytes: buffer[at, have)
  uint64_t offset = sizeof(Header), left = header.payload_bytes;
  uint32_t crc = 0;
  bool io_error = false;
  auto read = [&](void* out, size_t size) {
    char* dst = static_cast<char*>(out);
    while (size > 0) {
      if (at == have) {
        if (left == 0) return false;
        const size_t want = std::min<uint64_t>(buffer.size(), left);
        const ssize_t n = ::pread(fd, buffer.data(), want, offset);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
          io_error = true;
          return false;
        }
        crc = Crc32c(buffer.data(), static_cast<size_t>(n), crc);
        offset += n;
        left -= n;
        at = 0;
        have = static_cast<size_t>(n);
      }
      const size_t take = std::min(size, have - at);
      std::memcpy(dst, buffer.data() + at, take);
      at += take;
      dst += take;
      size -= take;
    }
    return true;
  };
  absl::Status s = wp->LoadState(read, [&] {
    if (io_error || left != 0 || crc != header.payload_crc) {
      return absl::DataLossError("damaged (checksum)");
    }
    return absl::OkStatus();
  });
  ::close(fd);
  if (!s.ok()) {
    return absl::DataLossError(
        absl::StrCat("snapshot ", path, ": ", s.message()));
  }
  return absl::OkStatus();
}

void DeleteSnapshot(const std::string& path) {
  std::error_code ec;
  std::filesystem::remove(path, ec);
  std::filesystem::remove(path + ".tmp", ec);
}

}  // namespace swarf::server
