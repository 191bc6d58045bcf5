// The interpreter's control flow (see interpreter.h): O-words (if/elseif/
// else, while/do/repeat with break and continue, sub/endsub, call and return
// with values, labelled returns), Fanuc M98/M99 subprograms, and external
// subroutine files.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/status_macros.h"
#include "gcode/interpreter.h"

namespace swarf::gcode::interp {

// ------------------------------------------------------------- control flow

void Interpreter::SkipTo(const std::string& label, uint32_t kinds) {
  skipping_ = true;
  skip_label_ = label;
  skip_kinds_ = kinds;
  skip_from_ = cur_.line;
}

// While skipping: true when the line is the awaited O-word.
bool Interpreter::SkipMatches(const char* q, const char* eol, Block* b) {
  const char* o = Prelude(q, eol);
  if (o >= eol || (*o != 'O' && *o != 'o')) return false;
  const char* rest;
  OKind kind;
  if (!ReadOWord(o, eol, &b->o_label, &kind, &rest).ok()) return false;
  if (b->o_label != skip_label_) return false;
  return (skip_kinds_ & KBit(kind)) != 0;
}

Control* Interpreter::TopControl(OKind kind, const std::string& label) {
  std::vector<Control>& c = frame().control;
  if (c.empty() || c.back().kind != kind || c.back().label != label) {
    return nullptr;
  }
  return &c.back();
}

absl::Status Interpreter::ExecuteO(const Block& b, bool arrived) {
  const std::string& label = b.o_label;
  const std::string name = absl::StrCat(OLabel(label), " ", OName(b.o_kind));
  std::vector<Control>& control = frame().control;
  if (control.size() >= kMaxControlDepth) {
    return Err(absl::StrCat("control structures nested deeper than ",
                            kMaxControlDepth));
  }
  const auto need_value = [&]() -> absl::Status {
    if (!b.o_has_value) return Err(name + " needs a [condition]");
    return absl::OkStatus();
  };
  const auto push = [&](OKind kind, Cursor start, int64_t remaining) {
    control.push_back({kind, label, start, remaining, cur_.line});
  };
  switch (b.o_kind) {
    case OKind::kProgramNumber:
      // A program number ("O1234 (NAME)"): its subprogram body, when
      // reached in sequence, runs as part of the program.
      ++program_numbers_;
      return absl::OkStatus();
    case OKind::kSub:
      files_[cur_.file].subs[label] = cur_;
      SkipTo(label, KBit(OKind::kEndsub));
      return absl::OkStatus();
    case OKind::kEndsub:
    case OKind::kReturn:
      if (arrived) return absl::OkStatus();  // the end of a definition
      if (frames_.size() == 1 || frame().fanuc) {
        return Err(name + " outside a subroutine");
      }
      if (frame().label != label) {
        // As LinuxCNC: a return may carry the label of a structure it is
        // in ("o1010 return" inside "o1010 if" in "o1000 sub").
        bool enclosing = false;
        if (b.o_kind == OKind::kReturn) {
          for (const Control& c : control) enclosing |= c.label == label;
        }
        if (!enclosing) {
          return Err(absl::StrCat(name, " inside subroutine ",
                                  OLabel(frame().label)));
        }
      }
      return Return(b.o_has_value, b.o_value);
    case OKind::kCall:
      return Call(b);
    case OKind::kIf:
      SWARF_RETURN_IF_ERROR(need_value());
      push(OKind::kIf, cur_, 0);
      if (b.o_value == 0) {
        SkipTo(label, KBit(OKind::kElseif) | KBit(OKind::kElse) |
                          KBit(OKind::kEndif));
      }
      return absl::OkStatus();
    case OKind::kElseif:
    case OKind::kElse:
      if (TopControl(OKind::kIf, label) == nullptr) {
        return Err(absl::StrCat(name, " without ", OLabel(label), " if"));
      }
      if (!arrived) {
        // A branch ran: on to the endif.
        SkipTo(label, KBit(OKind::kEndif));
        return absl::OkStatus();
      }
      if (b.o_kind == OKind::kElseif) {
        SWARF_RETURN_IF_ERROR(need_value());
        if (b.o_value == 0) {
          SkipTo(label, KBit(OKind::kElseif) | KBit(OKind::kElse) |
                            KBit(OKind::kEndif));
        }
      }
      return absl::OkStatus();
    case OKind::kEndif:
      if (TopControl(OKind::kIf, label) == nullptr) {
        return Err(absl::StrCat(name, " without ", OLabel(label), " if"));
      }
      control.pop_back();
      return absl::OkStatus();
    case OKind::kDo:
      push(OKind::kDo, cur_, 0);
      return absl::OkStatus();
    case OKind::kWhile: {
      if (Control* top = TopControl(OKind::kDo, label)) {
        // The end of a do-while loop (also reached by continue).
        SWARF_RETURN_IF_ERROR(need_value());
        if (b.o_value != 0) {
          cur_ = top->start;
        } else {
          control.pop_back();
        }
        return absl::OkStatus();
      }
      if (arrived) return absl::OkStatus();  // after a break out of a do
      SWARF_RETURN_IF_ERROR(need_value());
      if (b.o_value != 0) {
        push(OKind::kWhile, line_start_, 0);
      } else {
        SkipTo(label, KBit(OKind::kEndwhile));
      }
      return absl::OkStatus();
    }
    case OKind::kEndwhile: {
      Control* top = TopControl(OKind::kWhile, label);
      if (top == nullptr) {
        if (arrived) return absl::OkStatus();  // a false while, or a break
        return Err(absl::StrCat(name, " without ", OLabel(label), " while"));
      }
      const Cursor start = top->start;
      control.pop_back();
      cur_ = start;  // the while line evaluates its condition again
      return absl::OkStatus();
    }
    case OKind::kRepeat: {
      SWARF_RETURN_IF_ERROR(need_value());
      const double n = std::round(b.o_value);
      if (n >= 1) {
        push(OKind::kRepeat, cur_, static_cast<int64_t>(std::min(n, 9e18)));
      } else {
        SkipTo(label, KBit(OKind::kEndrepeat));
      }
      return absl::OkStatus();
    }
    case OKind::kEndrepeat: {
      Control* top = TopControl(OKind::kRepeat, label);
      if (top == nullptr) {
        if (arrived) return absl::OkStatus();
        return Err(absl::StrCat(name, " without ", OLabel(label), " repeat"));
      }
      if (--top->remaining > 0) {
        cur_ = top->start;
      } else {
        control.pop_back();
      }
      return absl::OkStatus();
    }
    case OKind::kBreak:
    case OKind::kContinue: {
      // The loop with this label; conditionals inside it end here.
      size_t k = control.size();
      while (k > 0 && !(control[k - 1].label == label &&
                        control[k - 1].kind != OKind::kIf)) {
        --k;
      }
      if (k == 0) {
        return Err(absl::StrCat(name, " outside an ", OLabel(label), " loop"));
      }
      const Control loop = control[k - 1];
      const bool brk = b.o_kind == OKind::kBreak;
      control.resize(brk ? k - 1 : k);
      const OKind end = loop.kind == OKind::kWhile ? OKind::kEndwhile
                        : loop.kind == OKind::kDo  ? OKind::kWhile
                                                   : OKind::kEndrepeat;
      if (!brk && loop.kind == OKind::kWhile) {
        control.pop_back();
        cur_ = loop.start;
        return absl::OkStatus();
      }
      SkipTo(label, KBit(end));
      return absl::OkStatus();
    }
  }
  return absl::OkStatus();
}

void Interpreter::ScanSubs(int file) {
  Source& s = files_[file];
  s.subs_scanned = true;
  const char* const base = s.text.data();
  const char* const end = base + s.text.size();
  int64_t line = 0;
  std::string label;
  for (const char* p = base; p < end;) {
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
    if (eol == nullptr) eol = end;
    const char* next = eol < end ? eol + 1 : end;
    ++line;
    const char* o = Prelude(p, eol);
    if (o < eol && (*o == 'O' || *o == 'o')) {
      OKind kind;
      const char* rest;
      if (ReadOWord(o, eol, &label, &kind, &rest).ok()) {
        const Cursor after{file, static_cast<size_t>(next - base), line};
        if (kind == OKind::kSub) s.subs.emplace(label, after);
        if (kind == OKind::kProgramNumber) s.programs.emplace(label, after);
      }
    }
    p = next;
  }
}

absl::Status Interpreter::FindSub(const std::string& label, bool fanuc,
                                  Cursor* body) {
  const std::string what =
      fanuc ? absl::StrCat("subprogram O", label)
            : absl::StrCat("subroutine ", OLabel(label));
  for (const int f : {cur_.file, 0}) {
    if (!files_[f].subs_scanned) ScanSubs(f);
    const auto& map = fanuc ? files_[f].programs : files_[f].subs;
    auto it = map.find(label);
    if (it != map.end()) {
      *body = it->second;
      return absl::OkStatus();
    }
  }
  if (options_.subroutine_dir.empty()) {
    return Err(what + " is not defined");
  }
  // As LinuxCNC: o<name> call reads name.ngc from the subroutine path.
  const std::string file = absl::StrCat(
      options_.subroutine_dir, "/",
      label[0] == '<' ? label.substr(1) : label, fanuc ? ".nc" : ".ngc");
  for (size_t f = 1; f < files_.size(); ++f) {
    if (files_[f].name == file) {
      return Err(absl::StrCat(file, " has no ", OLabel(label), " sub"));
    }
  }
  if (files_.size() >= kMaxFiles) {
    return Err(absl::StrCat("more than ", kMaxFiles, " subroutine files"));
  }
  absl::StatusOr<std::string> text = ReadWholeFile(file);
  if (!text.ok()) {
    return Err(absl::StrCat(what, " is not defined in the program, and ",
                            file, ": ", text.status().message()));
  }
  Source& s = files_.emplace_back();
  s.name = file;
  s.owned = std::move(*text);
  s.text = s.owned;
  const int index = static_cast<int>(files_.size() - 1);
  ScanSubs(index);
  const auto& map = fanuc ? s.programs : s.subs;
  auto it = map.find(label);
  if (it == map.end()) {
    if (fanuc) {
      *body = Cursor{index, 0, 0};  // the whole file
      return absl::OkStatus();
    }
    return Err(absl::StrCat(file, " has no ", OLabel(label), " sub"));
  }
  *body = it->second;
  return absl::OkStatus();
}

absl::Status Interpreter::Call(const Block& b) {
  if (static_cast<int>(frames_.size()) > options_.max_call_depth) {
    return Err(absl::StrCat("subroutine calls nested deeper than ",
                            options_.max_call_depth, " (endless recursion?)"));
  }
  Cursor body;
  SWARF_RETURN_IF_ERROR(FindSub(b.o_label, false, &body));
  Frame& f = frames_.emplace_back();
  f.label = b.o_label;
  f.ret = cur_;
  f.call_line = cur_.line;
  for (int i = 1; i <= 30; ++i) {
    f.saved[i] = params_[i];
    params_[i] = i <= static_cast<int>(b.o_args.size()) ? b.o_args[i - 1] : 0;
  }
  cur_ = body;
  return absl::OkStatus();
}

absl::Status Interpreter::Return(bool has_value, double value) {
  Frame& f = frame();
  if (!f.fanuc) {
    for (int i = 1; i <= 30; ++i) params_[i] = f.saved[i];
  }
  if (f.autorestore.valid) RestoreModal(f.autorestore);
  globals_["_value"] = has_value ? value : 0;
  globals_["_value_returned"] = has_value ? 1 : 0;
  const Cursor ret = f.ret;
  frames_.pop_back();
  cur_ = ret;
  return absl::OkStatus();
}

// Fanuc: M98 P<program> [L<repeats>] runs O<program>; M99 returns.
absl::Status Interpreter::FanucCall(const Block& b) {
  if (!(b.words & Bit('P'))) return Err("M98 needs P (the program number)");
  const double pv = b.value['P' - 'A'];
  if (!(pv >= 0 && pv < 1e9) || pv != std::floor(pv)) {
    return Err(absl::StrCat("M98 P", pv, " is not a program number"));
  }
  int64_t repeats = 1;
  if (b.words & Bit('L')) {
    const double l = b.value['L' - 'A'];
    if (!(l >= 1 && l <= 1e9) || l != std::floor(l)) {
      return Err(absl::StrCat("M98 L", l, " is not a repeat count"));
    }
    repeats = static_cast<int64_t>(l);
  }
  if (static_cast<int>(frames_.size()) > options_.max_call_depth) {
    return Err(absl::StrCat("subprogram calls nested deeper than ",
                            options_.max_call_depth, " (endless recursion?)"));
  }
  const std::string label = absl::StrCat(static_cast<int64_t>(pv));
  Cursor body;
  SWARF_RETURN_IF_ERROR(FindSub(label, true, &body));
  Frame& f = frames_.emplace_back();
  f.label = label;
  f.ret = cur_;
  f.call_line = cur_.line;
  f.fanuc = true;
  f.fanuc_start = body;
  f.repeats_left = repeats;
  cur_ = body;
  return absl::OkStatus();
}

absl::Status Interpreter::FanucReturn() {
  if (frames_.size() == 1 || !frame().fanuc) {
    // M99 in a main program repeats it forever on a Fanuc control; here
    // the program ends.
    path_.AddNote(absl::StrCat("M99 on line ", cur_.line,
                               " outside a subprogram: the program ends"));
    ended_ = true;
    return absl::OkStatus();
  }
  if (--frame().repeats_left > 0) {
    cur_ = frame().fanuc_start;
    return absl::OkStatus();
  }
  return Return(false, 0);
}

}  // namespace swarf::gcode::interp
