#include "gcode/text.h"

#include <sys/stat.h>

#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <limits>
#include <system_error>

#include "absl/strings/str_cat.h"

namespace swarf::gcode {

const char* SkipBom(const char* p, const char* end) {
  if (end - p >= 3 && std::memcmp(p, "\xEF\xBB\xBF", 3) == 0) return p + 3;
  return p;
}

absl::Status LineError(int64_t line, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat("line ", line, ": ", what));
}

std::string CharName(char c) {
  const auto u = static_cast<unsigned char>(c);
  if (u >= 0x21 && u < 0x7F) return std::string("'") + c + "'";
  char buf[16];
  std::snprintf(buf, sizeof buf, "byte 0x%02X", u);
  return buf;
}

std::string GName(int32_t code10) {
  return code10 % 10 == 0 ? absl::StrCat("G", code10 / 10)
                          : absl::StrCat("G", code10 / 10, ".", code10 % 10);
}

// A G-code number: [+-] digits [. digits] with at least one digit; blanks
// may separate it from its letter. No exponent: E is a word in G-code.
// Returns the end of the number, or null when there is none.
const char* ScanNumber(const char* p, const char* end, double* out) {
  while (p < end && (*p == ' ' || *p == '\t')) ++p;
  bool negative = false;
  if (p < end && (*p == '+' || *p == '-')) {
    negative = *p == '-';
    ++p;
  }
  const char* first = p;
  while (p < end && IsDigit(*p)) ++p;
  bool digits = p != first;
  if (p < end && *p == '.') {
    const char* frac = ++p;
    while (p < end && IsDigit(*p)) ++p;
    digits = digits || p != frac;
  }
  if (!digits) return nullptr;
  // from_chars: no locale, no allocation, correctly rounded (fast_float in
  // libstdc++ 12); it rejects a leading '+', hence the sign is ours.
  const auto r = std::from_chars(first, p, *out, std::chars_format::fixed);
  if (r.ec == std::errc::result_out_of_range) {
    // Too large for a double when the integer part isn't zero (every user
    // of a value range-checks it, so an infinity makes the right error);
    // else too small: zero.
    bool large = false;
    for (const char* d = first; d < p && *d != '.'; ++d) large |= *d != '0';
    *out = large ? std::numeric_limits<double>::infinity() : 0.0;
    if (negative) *out = -*out;
    return p;
  }
  if (r.ec != std::errc() || r.ptr != p) return nullptr;
  if (negative) *out = -*out;
  return p;
}

// True when [p, end) holds only blanks and comments.
bool OnlyComments(const char* p, const char* end) {
  for (p = SkipBlanks(p, end); p < end; p = SkipBlanks(p, end)) {
    if (*p == ';') return true;
    if (*p != '(') return false;
    const void* close = std::memchr(p, ')', end - p);
    if (close == nullptr) return false;
    p = static_cast<const char*>(close) + 1;
  }
  return true;
}

absl::StatusOr<std::string> ReadWholeFile(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) {
    const int e = errno;
    return absl::NotFoundError(absl::StrCat("cannot open: ", std::strerror(e)));
  }
  std::string data;
  // A regular file is read straight into a string of its size: appended a
  // buffer at a time, a 350 MB program was copied again at each doubling.
  struct stat st;
  if (fstat(fileno(f), &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0) {
    data.resize(static_cast<size_t>(st.st_size));
    data.resize(std::fread(data.data(), 1, data.size(), f));
  }
  char buf[1 << 16];
  size_t n;
  // The rest of a file that grew, or all of a pipe's.
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) data.append(buf, n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) return absl::DataLossError("read error");
  return data;
}

}  // namespace swarf::gcode
