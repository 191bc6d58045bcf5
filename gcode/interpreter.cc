// The RS274/NGC interpreter behind ParseGcode (contract in toolpath.h): the
// loop over a program's lines, errors, counts. Its parts and their files:
// interpreter.h.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/status_macros.h"
#include "gcode/interpreter.h"

namespace swarf::gcode {
namespace interp {

absl::Status Interpreter::Err(const std::string& what) const {
  if (cur_.file == 0) return LineError(cur_.line, what);
  return absl::InvalidArgumentError(absl::StrCat(
      "line ", cur_.line, " of ", files_[cur_.file].name, " (called from line ",
      main_line_, "): ", what));
}

// ------------------------------------------------------------- the loop

absl::StatusOr<Toolpath> Interpreter::Run(std::string_view text) {
  if (!(options_.arc_tolerance >= 1e-6 && options_.arc_tolerance <= 10)) {
    return absl::InvalidArgumentError(
        absl::StrCat("arc tolerance must be in [1e-6, 10] mm, got ",
                     options_.arc_tolerance));
  }
  if (options_.max_points < 1 || options_.max_blocks < 1 ||
      options_.max_call_depth < 1) {
    return absl::InvalidArgumentError(
        "max_points, max_blocks and max_call_depth must be positive");
  }
  for (int k = 0; k < 2; ++k) {
    home_known_[k] = options_.home_known;
    for (int a = 0; a < 3; ++a) {
      if (!(std::fabs(options_.home[a]) <= kMaxCoordinateMm)) {
        return absl::InvalidArgumentError("home position out of range");
      }
      params_[(k == 0 ? kG28Home : kG30Home) + a] = options_.home[a];
    }
  }
  params_[kCoordSystem] = 1;  // G54
  for (int a = 0; a < 3; ++a) {
    if (!(std::fabs(options_.start[a]) <= kMaxCoordinateMm &&
          std::fabs(options_.tool_change_position[a]) <= kMaxCoordinateMm)) {
      return absl::InvalidArgumentError(
          "start or tool-change position out of range");
    }
  }
  if (options_.start_known) {
    for (int a = 0; a < 3; ++a) pos_[a] = options_.start[a];
    known_ = 7;
    start_pending_ = true;
  }
  const char* begin = SkipBom(text.data(), text.data() + text.size());
  files_.emplace_back();
  files_[0].text = text.substr(begin - text.data());
  frames_.emplace_back();
  // A guess at the point count: a point per line (straight-line CAM
  // output) and a fifth more for arcs, within what Trim() keeps, so that
  // neither a reallocation nor a trim copies the points (copies fault in
  // fresh pages: the slowest part of parsing, see docs/benchmarks.md);
  // loops and long arcs grow the vector past it.
  const int64_t lines = std::count(text.begin(), text.end(), '\n') + 1;
  path_.Reserve(std::min<int64_t>(lines + lines / 5, options_.max_points),
                std::min<int64_t>(lines, options_.max_points));

  Block& block = block_;
  bool seen_content = false;   // a non-blank line was read
  bool percent_start = false;  // the program starts with '%'
  int64_t end_line = 0;        // where reading stopped early (M2/M30, '%')
  for (;;) {
    const std::string_view src = files_[cur_.file].text;
    if (cur_.offset >= src.size()) {
      if (skipping_) {
        return Err(absl::StrCat("no ", OLabel(skip_label_),
                                " line to end the block that starts on line ",
                                skip_from_));
      }
      if (frames_.size() > 1) {
        return Err(absl::StrCat("subroutine ", OLabel(frame().label),
                                " ends without endsub or return"));
      }
      if (!frame().control.empty()) {
        const Control& c = frame().control.back();
        return LineError(c.line, absl::StrCat(OLabel(c.label), " ",
                                              OName(c.kind),
                                              " is never closed"));
      }
      SWARF_RETURN_IF_ERROR(CompFlush());
      break;
    }
    line_start_ = cur_;
    const char* p = src.data() + cur_.offset;
    const char* const end = src.data() + src.size();
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
    if (eol == nullptr) eol = end;
    cur_.offset = (eol < end ? eol + 1 : end) - src.data();
    ++cur_.line;
    if (cur_.file == 0) {
      main_line_ = cur_.line;
      max_main_line_ = std::max(max_main_line_, main_line_);
      if (cur_.line > std::numeric_limits<int32_t>::max()) {
        return Err("too many lines");
      }
    }
    const char* q = SkipBlanks(p, eol);
    if (q == eol) continue;
    if (*q == '%') {
      if (!OnlyComments(q + 1, eol)) return Err("'%' must be alone on its line");
      if (cur_.file != 0) continue;
      // As LinuxCNC: a program that starts with '%' ends at the next one.
      if (!seen_content) {
        percent_start = true;
      } else if (percent_start) {
        end_line = cur_.line;
        break;
      }
      seen_content = true;
      continue;
    }
    seen_content = true;
    if (*q == '$') {
      if (options_.dialect != Dialect::kGrbl) {
        return Err("'$' lines are Grbl settings: use --dialect grbl");
      }
      ++dollar_lines_;
      if (!grbl_noted_) {
        grbl_noted_ = true;
        path_.AddNote("Grbl '$' lines (settings, homing, ...) are ignored");
      }
      continue;
    }
    bool arrived = false;
    if (skipping_) {
      if (!SkipMatches(q, eol, &block)) continue;
      skipping_ = false;
      arrived = true;
    }
    arrived_ = arrived;
    if (++blocks_ > options_.max_blocks) {
      return Err(absl::StrCat("more than ", options_.max_blocks,
                              " blocks executed (max_blocks): an endless "
                              "loop?"));
    }
    SWARF_RETURN_IF_ERROR(ReadBlock(q, eol, &block));
    if (block.empty()) {
      if (block.block_delete) ++block_deletes_;
      continue;
    }
    SWARF_RETURN_IF_ERROR(ApplySettings(block));
    if (block.has_o) {
      SWARF_RETURN_IF_ERROR(ExecuteO(block, arrived));
    } else {
      SWARF_RETURN_IF_ERROR(Execute(block));
    }
    if (ended_) {
      end_line = cur_.file == 0 ? cur_.line : main_line_;
      break;
    }
  }
  path_.set_source_lines(max_main_line_);
  path_.set_blocks_executed(blocks_);
  if (end_line > 0 && cur_.file == 0) {
    // Say so when something that looks like program text was not read.
    int64_t unread = 0;
    const char* const end = files_[0].text.data() + files_[0].text.size();
    for (const char* p = files_[0].text.data() + cur_.offset; p < end;) {
      const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
      if (eol == nullptr) eol = end;
      const char* q = SkipBlanks(p, eol);
      if (q < eol && *q != '%' && !OnlyComments(q, eol)) ++unread;
      p = eol < end ? eol + 1 : end;
    }
    if (unread > 0 && frames_.size() == 1) {
      path_.AddNote(absl::StrCat("the program ends on line ", end_line, "; ",
                                 unread, " lines after it were not read"));
    }
  }
  FinishCounts();
  path_.Trim();  // the reserve above was a guess
  return std::move(path_);
}

void Interpreter::FinishCounts() {
  for (int32_t c = 0; c < kGCodeLimit; ++c) {
    if (g_ignored_[c] > 0) path_.CountIgnored(GName(c), g_ignored_[c]);
  }
  for (int32_t c = 0; c < kMCodeCounted; ++c) {
    if (m_ignored_[c] > 0) {
      path_.CountIgnored(absl::StrCat("M", c), m_ignored_[c]);
    }
  }
  for (int i = 0; i < 26; ++i) {
    if (letter_ignored_[i] > 0) {
      path_.CountIgnored(std::string(1, static_cast<char>('A' + i)),
                         letter_ignored_[i]);
    }
  }
  if (block_deletes_ > 0) path_.CountIgnored("/", block_deletes_);
  if (program_numbers_ > 0) path_.CountIgnored("O", program_numbers_);
  if (dollar_lines_ > 0) path_.CountIgnored("$", dollar_lines_);
}

}  // namespace interp

absl::StatusOr<Toolpath> ParseGcode(std::string_view text,
                                    const GcodeOptions& options,
                                    CanonSink* sink) {
  interp::Interpreter interpreter(options, sink);
  return interpreter.Run(text);
}

}  // namespace swarf::gcode
