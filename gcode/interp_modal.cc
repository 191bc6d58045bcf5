// The interpreter's execution of a block (see interpreter.h): modal
// settings (G-code groups, units, plane, distance modes, work and G92
// offsets, G10, G28/G30, tool length), M-codes and tool changes, and the
// dispatch to motion (interp_motion.cc) and compensation (interp_comp.cc).
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

// ------------------------------------------------------------- execution

// In LinuxCNC's order of execution within a line: feed, speed, tool
// select, tool change, plane, units, tool length, coordinate system,
// distance mode, retract mode, non-modal codes (G10, G28, G92, ...),
// motion, stop.
absl::Status Interpreter::Execute(const Block& b) {
  if (b.block_delete) ++block_deletes_;
  if (b.words & Bit('F')) feed_ = b.value['F' - 'A'];

  int new_motion = -1, nonmodal = -1, length_code = -1;
  bool g53 = false, motion_given = false;
  if (b.ng > 0) {
    SWARF_RETURN_IF_ERROR(ApplyGCodes(b, &new_motion, &nonmodal, &g53,
                                      &length_code, &motion_given));
  }
  uint32_t used = 0;  // letters a code consumed
  if (b.words & Bit('T')) {
    const double t = b.value['T' - 'A'];
    if (!(t >= 0 && t <= 65535) || t != std::floor(t)) {
      return Err(absl::StrCat("T", t, " is not a tool number (0-65535)"));
    }
    last_t_ = static_cast<int32_t>(t);
    if (!had_m6_) {
      tool_ = static_cast<uint16_t>(last_t_);
      path_.NoteToolSelected(tool_, static_cast<int32_t>(main_line_));
    }
    used |= Bit('T');
  }
  bool m6 = false, end = false, m98 = false, m99 = false;
  for (int i = 0; i < b.nm; ++i) {
    const int32_t m = b.m[i];
    switch (m) {
      case 6: m6 = true; break;
      case 2: case 30: end = true; break;
      case 61: {
        // Set the current tool number without a change.
        if (!(b.words & Bit('Q'))) return Err("M61 needs Q (the tool number)");
        const double q = b.value['Q' - 'A'];
        if (!(q >= 0 && q <= 65535) || q != std::floor(q)) {
          return Err(absl::StrCat("M61 Q", q, " is not a tool number"));
        }
        tool_ = static_cast<uint16_t>(q);
        path_.NoteToolSelected(tool_, static_cast<int32_t>(main_line_));
        had_m6_ = true;
        used |= Bit('Q');
        break;
      }
      case 70: SaveModal(&saved_modal_); break;
      case 71: saved_modal_.valid = false; break;
      case 72:
        if (!saved_modal_.valid) return Err("M72 without a state saved by M70");
        RestoreModal(saved_modal_);
        break;
      case 73:
        if (frames_.size() == 1) return Err("M73 outside a subroutine");
        SaveModal(&frame().autorestore);
        break;
      case 98: case 99:
        if (options_.dialect != Dialect::kFanuc) {
          return Err(absl::StrCat("M", m, " (Fanuc subprogram ",
                                  m == 98 ? "call" : "return",
                                  ") needs --dialect fanuc"));
        }
        (m == 98 ? m98 : m99) = true;
        used |= Bit('P') | Bit('L');
        break;
      default:
        // Spindle, coolant, stops, I/O, machine-specific codes: no tip motion.
        if (m < kMCodeCounted) {
          ++m_ignored_[m];
        } else {
          path_.CountIgnored(absl::StrCat("M", m));
        }
    }
    if (m >= 70 && m <= 73) ++m_ignored_[m];
  }
  if (m6) {
    if (comp_side_ != 0) {
      return Err("M6 with cutter compensation on (G40 first)");
    }
    SWARF_RETURN_IF_ERROR(ToolChange());
  }
  if (length_code >= 0) SWARF_RETURN_IF_ERROR(ToolLength(b, length_code, &used));
  if (new_motion >= 0) {
    motion_ = new_motion;
    if (!IsCycle(motion_)) cycle_il_set_ = false;  // a series ends
  }

  const uint32_t axes = b.words & (kAxisWords | kPolarWords);
  if (nonmodal >= 0) {
    if (comp_side_ != 0 && (nonmodal == 280 || nonmodal == 300)) {
      return Err(absl::StrCat(GName(nonmodal),
                              " with cutter compensation on (G40 first)"));
    }
    SWARF_RETURN_IF_ERROR(NonModal(b, nonmodal, &used));
  }
  const bool axes_taken = (used & kAxisWords) != 0;
  if (axes_taken && (b.words & kPolarWords)) {
    return Err(absl::StrCat("@/^ (polar coordinates) with ",
                            GName(nonmodal >= 0 ? nonmodal : 431)));
  }
  if (axes_taken && motion_given) {
    return Err(absl::StrCat(GName(nonmodal >= 0 ? nonmodal : 431),
                            " and a motion code on one line both use the "
                            "axis words"));
  }
  const uint32_t arc_words = b.words & kArcWords & ~used;
  if (!axes_taken && (axes != 0 || (arc_words != 0 && !IsCycle(motion_)) ||
                      (motion_given && IsCycle(motion_)))) {
    if (motion_ < 0 || motion_ == 800) {
      return Err(absl::StrCat(
          "axis words with no motion mode in effect (",
          motion_ < 0 ? "no G0, G1, G2 or G3 yet" : "G80 cancelled it", ")"));
    }
    if (comp_side_ != 0 && (g53 || IsCycle(motion_))) {
      return Err(absl::StrCat(g53 ? "G53" : GName(motion_),
                              " with cutter compensation on (G40 first)"));
    }
    if (g53 && motion_ > 10) {
      return Err("G53 needs G0 or G1 (machine-coordinate straight moves)");
    }
    if (motion_ == 20 || motion_ == 30) {
      SWARF_RETURN_IF_ERROR(Arc(b));
      used |= kArcWords | Bit('P');
    } else if (IsCycle(motion_)) {
      if (axes == 0) {
        return Err(absl::StrCat(GName(motion_), " without X, Y or Z"));
      }
      SWARF_RETURN_IF_ERROR(Cycle(b, &used));
    } else {
      if (arc_words != 0) {
        const char w = static_cast<char>('A' + __builtin_ctz(arc_words));
        return Err(absl::StrCat(std::string(1, w),
                                " word without a G2/G3 arc"));
      }
      SWARF_RETURN_IF_ERROR(Linear(b, g53, motion_ == 0));
    }
  } else if (g53 && !axes_taken) {
    return Err("G53 without axis words");
  }
  for (uint32_t w = b.words & kIgnoredLetters & ~used; w != 0; w &= w - 1) {
    ++letter_ignored_[__builtin_ctz(w)];
  }
  if (m98) SWARF_RETURN_IF_ERROR(FanucCall(b));
  if (m99) SWARF_RETURN_IF_ERROR(FanucReturn());
  if (end) {
    SWARF_RETURN_IF_ERROR(CompFlush());
    ended_ = true;
  }
  return absl::OkStatus();
}

absl::Status Interpreter::ApplyGCodes(const Block& b, int* new_motion,
                                      int* nonmodal, bool* g53,
                                      int* length_code, bool* motion_given) {
  // The common case first: "G1 X.. Y.." (CAM output repeats the code).
  if (b.ng == 1 && (b.g[0] == 0 || b.g[0] == 10)) {
    *new_motion = b.g[0];
    *motion_given = true;
    return absl::OkStatus();
  }
  // Two codes of one modal group on a line contradict each other.
  enum Group {
    kMotion, kPlane, kUnits, kDistance, kArcDistance, kOffset, kLength,
    kNonModal, kRetract, kComp, kN
  };
  int32_t group_code[kN];
  std::fill(group_code, group_code + kN, -1);
  int coord = -1, plane = -1, units = -1, distance = -1, arc_distance = -1,
      retract = -1;
  bool g80 = false;
  int comp_code = -1;
  for (int i = 0; i < b.ng; ++i) {
    const int32_t c = b.g[i];
    Group group = kN;
    // clang-format off
    switch (c) {
      case 800:
        // Cancels a cycle; beside another motion code (as in "G0 G80",
        // common in post headers) that code wins.
        g80 = true;
        ++g_ignored_[c];
        break;
      case 760:
        // LinuxCNC: lathe threading; Fanuc mills: fine boring.
        if (options_.dialect != Dialect::kFanuc) return Err(UnsupportedG(c));
        group = kMotion;
        *new_motion = c;
        *motion_given = true;
        break;
      case 0: case 10: case 20: case 30:
      case 730: case 740: case 810: case 820: case 830: case 840: case 850:
      case 860: case 870: case 880: case 890:
        group = kMotion;
        *new_motion = c;
        *motion_given = true;
        break;
      case 170: case 180: case 190:
        group = kPlane;
        plane = c / 10;
        ++g_ignored_[c];
        break;
      case 200: case 210:
        group = kUnits;
        units = c;
        break;
      case 900: case 910:
        group = kDistance;
        distance = c;
        break;
      case 901: case 911:
        group = kArcDistance;
        arc_distance = c;
        break;
      case 540: case 550: case 560: case 570: case 580: case 590:
      case 591: case 592: case 593:
        group = kOffset;
        coord = c;
        ++g_ignored_[c];
        break;
      case 430: case 431: case 432: case 490:
        group = kLength;
        *length_code = c;
        ++g_ignored_[c];
        break;
      case 40: case 100: case 280: case 281: case 300: case 301: case 520:
      case 920: case 921: case 922: case 923:
        group = kNonModal;
        *nonmodal = c;
        if (c == 40) ++g_ignored_[c];  // dwell: no motion
        break;
      case 530:
        *g53 = true;
        ++g_ignored_[c];
        break;
      case 980: case 990:
        group = kRetract;
        retract = c;
        ++g_ignored_[c];
        break;
      case 400:
        group = kComp;
        comp_code = c;
        break;
      case 410: case 420: case 411: case 421:
        group = kComp;
        comp_code = c;
        break;
      // State that doesn't move the tip.
      case 80:   // lathe radius mode
      case 150:  // polar coordinates off
      case 500: case 501:  // scaling / mirroring off
      case 610: case 611: case 640:  // exact stop / blending
      case 690:  // rotation off
      case 930: case 940: case 950:  // feed modes
      case 960: case 970:  // spindle speed modes
        ++g_ignored_[c];
        break;
      default:
        return Err(UnsupportedG(c));
    }
    // clang-format on
    if (group != kN) {
      if (group_code[group] >= 0) {
        return Err(absl::StrCat(GName(group_code[group]), " and ", GName(c),
                                " on one line contradict each other"));
      }
      group_code[group] = c;
    }
  }
  if (g80 && *new_motion < 0) *new_motion = 800;
  if (comp_code == 400) {
    SWARF_RETURN_IF_ERROR(CompFlush());
    if (comp_side_ != 0) comp_exit_ = emitted_, comp_exit_block_ = blocks_;
    comp_side_ = 0;
    ++g_ignored_[400];
  } else if (comp_code >= 0) {
    SWARF_RETURN_IF_ERROR(CompStart(b, comp_code));
  }
  if (plane >= 0 && plane != plane_ && comp_side_ != 0) {
    return Err(absl::StrCat("G", plane,
                            " with cutter compensation on (G40 first)"));
  }
  if (plane >= 0) plane_ = plane;
  if (units >= 0) {
    inches_ = units == 200;
    units_declared_ = true;
  }
  if (coord >= 0) {
    const int cs = coord <= 590 ? coord / 10 - 53 : 6 + coord % 10;
    if (cs != static_cast<int>(params_[kCoordSystem])) {
      bool set = false;
      for (int a = 0; a < 3; ++a) set |= params_[kCoordBase + 20 * cs + a] != 0;
      if (!set && !offset_noted_) {
        offset_noted_ = true;
        path_.AddNote(absl::StrCat(
            GName(coord), " on line ", cur_.line,
            " selects a work offset the program never set: taken as zero "
            "(outputs are machine coordinates with all offsets zero unless "
            "the program sets them with G10)"));
      }
    }
    params_[kCoordSystem] = cs;
    offsets_dirty_ = true;
  }
  if (distance >= 0) incremental_ = distance == 910;
  if (arc_distance >= 0) arc_absolute_ = arc_distance == 901;
  if (retract >= 0) retract_r_ = retract == 990;
  if (*motion_given && IsCycle(*new_motion) && !IsCycle(motion_)) {
    // A new cycle sequence: its Z, R and Q must be given again.
    cycle_r_ = cycle_z_ = cycle_q_ = std::nan("");
  }
  return absl::OkStatus();
}

// The tip stays the controlled point under G43 (the tool table is unknown:
// the program's positions are taken as the tip, as everywhere); G43.1 Z
// offsets it by the given length and G43.2 Z adds to that; G49 cancels.
absl::Status Interpreter::ToolLength(const Block& b, int code,
                                     uint32_t* used) {
  offsets_dirty_ = true;
  if (code == 430 || code == 490) {
    params_[kToolLength] = 0;
    return absl::OkStatus();
  }
  if (b.words & (Bit('X') | Bit('Y'))) {
    return Err(absl::StrCat(GName(code),
                            " with X or Y: only a Z length offset is "
                            "supported"));
  }
  *used |= kAxisWords | Bit('H');
  double z = 0;
  if (b.words & Bit('Z')) z = b.value['Z' - 'A'] * scale();
  if (!(std::fabs(z) <= kMaxCoordinateMm)) return Err("tool length out of range");
  params_[kToolLength] = code == 431 ? z : params_[kToolLength] + z;
  return absl::OkStatus();
}

absl::Status Interpreter::NonModal(const Block& b, int code, uint32_t* used) {
  offsets_dirty_ = true;
  const double s = scale();
  const auto given = [&](int a) { return (b.words & Bit(kAxisName[a])) != 0; };
  const auto value = [&](int a) { return b.value[kAxisName[a] - 'A'] * s; };
  const auto in_range = [&](int a) -> absl::Status {
    if (given(a) && !(std::fabs(value(a)) <= kMaxCoordinateMm)) {
      return Err(absl::StrCat(std::string(1, kAxisName[a]), " value ",
                              b.value[kAxisName[a] - 'A'], " is out of range"));
    }
    return absl::OkStatus();
  };
  for (int a = 0; a < 3; ++a) SWARF_RETURN_IF_ERROR(in_range(a));
  const auto need_known = [&](int a, const char* what) -> absl::Status {
    if (!(known_ & (1u << a))) {
      return Err(absl::StrCat(what, " ", std::string(1, kAxisName[a]),
                              " while ", std::string(1, kAxisName[a]),
                              " is unknown"));
    }
    return absl::OkStatus();
  };
  switch (code) {
    case 40:  // dwell: its P is counted as ignored
      if (sink_ != nullptr) {
        sink_->Dwell(static_cast<int32_t>(main_line_),
                     (b.words & Bit('P')) ? b.value['P' - 'A'] : 0);
      }
      return absl::OkStatus();
    case 100: {
      *used |= kAxisWords | Bit('L') | Bit('P') | Bit('R');
      if (!(b.words & Bit('L'))) return Err("G10 needs L");
      const double l = b.value['L' - 'A'];
      if (l == 1 || l == 10 || l == 11) {
        // Tool table entries: lengths don't move the tip (see G43).
        ++letter_ignored_['L' - 'A'];
        return absl::OkStatus();
      }
      if (l != 2 && l != 20) {
        return Err(absl::StrCat("G10 L", l, " is not supported (L1, L2, L10, "
                                "L11, L20 are)"));
      }
      if ((b.words & Bit('R')) && b.value['R' - 'A'] != 0) {
        return Err("G10 R (coordinate system rotation) is not supported");
      }
      const double pv = (b.words & Bit('P')) ? b.value['P' - 'A'] : -1;
      if (!(pv >= 0 && pv <= 9) || pv != std::floor(pv)) {
        return Err("G10 L2/L20 needs P0..P9 (P0: the current system, P1: "
                   "G54 ... P9: G59.3)");
      }
      const int cs = pv == 0 ? static_cast<int>(params_[kCoordSystem])
                             : static_cast<int>(pv);
      for (int a = 0; a < 3; ++a) {
        if (!given(a)) continue;
        double o = value(a);
        if (l == 20) {
          // The current position gets the given coordinate in system cs.
          SWARF_RETURN_IF_ERROR(need_known(a, "G10 L20"));
          double other = params_[kG92On] != 0 ? params_[kG92 + a] : 0;
          if (a == 2) other += params_[kToolLength];
          o = pos_[a] - other - value(a);
        }
        params_[kCoordBase + 20 * cs + a] = o;
      }
      return absl::OkStatus();
    }
    case 280: case 300: {
      *used |= kAxisWords;
      const uint32_t axes = b.words & kAxisWords;
      // First the intermediate point (program coordinates).
      if (axes != 0) SWARF_RETURN_IF_ERROR(Linear(b, false, true));
      const int k = code == 280 ? 0 : 1;
      const int base = k == 0 ? kG28Home : kG30Home;
      const unsigned move = axes == 0 ? 7u : axes >> ('X' - 'A');
      if (!home_known_[k]) {
        // Like a tool change: the machine goes where we can't follow.
        known_ &= ~move;
        in_run_ = false;
        start_pending_ = false;
        if (!home_noted_) {
          home_noted_ = true;
          path_.AddNote(absl::StrCat(
              GName(code), " on line ", cur_.line,
              ": the home position is unknown (give --home X,Y,Z or set it "
              "with G28.1/G30.1); the axes it moves are unknown until given "
              "again"));
        }
        return absl::OkStatus();
      }
      const unsigned before = known_;
      for (int a = 0; a < 3; ++a) {
        if (move & (1u << a)) pos_[a] = params_[base + a];
      }
      known_ |= move;
      if (known_ != 7) return absl::OkStatus();
      if (before != 7) in_run_ = false, start_pending_ = false;
      return Emit(pos_[0], pos_[1], pos_[2], true);
    }
    case 281: case 301: {
      const int k = code == 281 ? 0 : 1;
      for (int a = 0; a < 3; ++a) {
        SWARF_RETURN_IF_ERROR(need_known(a, GName(code).c_str()));
      }
      for (int a = 0; a < 3; ++a) {
        params_[(k == 0 ? kG28Home : kG30Home) + a] = pos_[a];
      }
      home_known_[k] = true;
      return absl::OkStatus();
    }
    case 520: case 920: {
      *used |= kAxisWords;
      if ((b.words & kAxisWords) == 0) {
        return Err(absl::StrCat(GName(code), " without axis words"));
      }
      if (params_[kG92On] == 0) {
        for (int a = 0; a < 3; ++a) params_[kG92 + a] = 0;
      }
      for (int a = 0; a < 3; ++a) {
        if (!given(a)) continue;
        if (code == 520) {
          params_[kG92 + a] = value(a);  // a local offset of the origin
          continue;
        }
        SWARF_RETURN_IF_ERROR(need_known(a, "G92"));
        // The current position gets the given coordinate.
        double other = params_[kCoordBase +
                               20 * static_cast<int>(params_[kCoordSystem]) + a];
        if (a == 2) other += params_[kToolLength];
        params_[kG92 + a] = pos_[a] - other - value(a);
      }
      params_[kG92On] = 1;
      return absl::OkStatus();
    }
    case 921:
      for (int a = 0; a < 3; ++a) params_[kG92 + a] = 0;
      params_[kG92On] = 0;
      return absl::OkStatus();
    case 922:
      params_[kG92On] = 0;
      return absl::OkStatus();
    case 923:
      params_[kG92On] = 1;
      return absl::OkStatus();
    default:
      return Err(UnsupportedG(code));
  }
}

// M6: as LinuxCNC, the position stays (a rapid to the tool-change position
// first when one is given); with m6_forgets_position every axis becomes
// unknown and the next known position starts a new run.
absl::Status Interpreter::ToolChange() {
  if (options_.tool_change_position_known) {
    const double* t = options_.tool_change_position;
    SWARF_RETURN_IF_ERROR(MoveTo(t[0], t[1], t[2], true));  // the old tool
  }
  if (last_t_ >= 0) {
    tool_ = static_cast<uint16_t>(last_t_);
    path_.NoteToolSelected(tool_, static_cast<int32_t>(main_line_));
  }
  had_m6_ = true;
  if (options_.m6_forgets_position) {
    known_ = 0;
    in_run_ = false;
    start_pending_ = false;
  }
  if (sink_ != nullptr) sink_->ToolChange(static_cast<int32_t>(main_line_), tool_);
  return absl::OkStatus();
}

}  // namespace swarf::gcode::interp
