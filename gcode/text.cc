#include "gcode/text.h"

#include <sys/stat.h>

#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <iterator>
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

namespace {

// Digits (leading zeros too) that an integer mantissa takes exactly
// (10^19 < 2^64): past this many, from_chars.
constexpr int kMaxMantissaDigits = 19;

// 10^k for k in [0, kMaxMantissaDigits]: each exact in a double (up to
// 10^22: 5^22 < 2^53).
constexpr double kExactPow10[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,
                                  1e7,  1e8,  1e9,  1e10, 1e11, 1e12, 1e13,
                                  1e14, 1e15, 1e16, 1e17, 1e18, 1e19};
static_assert(std::size(kExactPow10) == kMaxMantissaDigits + 1);

}  // namespace

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
  // The digits as an integer m as they are scanned (modulo 2^64: exact
  // while there are at most kMaxMantissaDigits of them).
  uint64_t m = 0;
  const auto digits = [&m](const char* d, const char* end) {
    for (; d < end; ++d) {
      const auto v =
          static_cast<uint64_t>(static_cast<unsigned char>(*d)) - uint64_t{'0'};
      if (v > 9) break;
      m = m * 10 + v;
    }
    return d;
  };
  const char* first = p;
  p = digits(p, end);
  const char* int_end = p;
  const char* frac = p;
  if (p < end && *p == '.') {
    frac = ++p;
    p = digits(p, end);
  }
  const int64_t int_digits = int_end - first, frac_digits = p - frac;
  if (int_digits + frac_digits == 0) return nullptr;
  // Clinger's fast path: with at most kMaxMantissaDigits digits, m is the
  // digits' integer exactly; when it is an exact double (at most 2^53), as
  // 10^frac_digits is, one IEEE division rounds their quotient correctly:
  // the double from_chars gives, bit for bit, at a fraction of its cost
  // (from_chars was 11-17% of the 1000 mm plate's parse). Nearly every
  // number a CAM post writes takes this path.
  if (int_digits + frac_digits <= kMaxMantissaDigits &&
      m <= (uint64_t{1} << 53)) {
    *out = static_cast<double>(m) / kExactPow10[frac_digits];
    if (negative) *out = -*out;
    return p;
  }
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
