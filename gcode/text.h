// Character-level helpers shared by the G-code interpreter and the XYZ
// reader. Internal to gcode/.
#ifndef SWARF_GCODE_TEXT_H_
#define SWARF_GCODE_TEXT_H_

#include <cstdint>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace swarf::gcode {

inline bool IsBlank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}
inline bool IsDigit(char c) { return c >= '0' && c <= '9'; }
inline char Lower(char c) {
  return c >= 'A' && c <= 'Z' ? static_cast<char>(c + ('a' - 'A')) : c;
}

inline const char* SkipBlanks(const char* p, const char* end) {
  while (p < end && IsBlank(*p)) ++p;
  return p;
}

// Past a UTF-8 byte order mark, if any.
const char* SkipBom(const char* p, const char* end);

// "'x'" for printable ASCII, "byte 0xNN" otherwise.
std::string CharName(char c);

// InvalidArgument "line N: what".
absl::Status LineError(int64_t line, const std::string& what);

// A G-code number: [+-] digits [. digits] with at least one digit; blanks
// may precede it. No exponent: E is a word in G-code. Returns the end of
// the number, or null when there is none. Out of double range: +-infinity
// (callers range-check) or 0.
const char* ScanNumber(const char* p, const char* end, double* out);

// A G-code number kept x10 as a name: 901 -> "G90.1".
std::string GName(int32_t code10);

// A whole file. NotFound "cannot open: <reason>", DataLoss "read error".
absl::StatusOr<std::string> ReadWholeFile(const std::string& path);

// True when [p, end) holds only blanks and comments.
bool OnlyComments(const char* p, const char* end);

}  // namespace swarf::gcode

#endif  // SWARF_GCODE_TEXT_H_
