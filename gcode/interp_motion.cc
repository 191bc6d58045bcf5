// The interpreter's motion (see interpreter.h): end points (units, offsets,
// G53, polar '@'/'^'), straight moves, arcs, canned cycles, and the
// canonical commands they emit to the sink (gcode/canon.h).
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

// The programmed end of a move: axis words in the current units, distance
// mode and offsets (machine coordinates under G53); absent axes unchanged.
absl::Status Interpreter::EndPoint(const Block& b, bool machine,
                                   double end[3]) {
  if (!units_declared_) {
    units_declared_ = true;  // note once
    path_.AddNote("no G20/G21 before the first move: millimetres assumed");
  }
  const double s = scale();
  for (int a = 0; a < 3; ++a) {
    end[a] = pos_[a];
    const char name = kAxisName[a];
    if (!(b.words & Bit(name))) continue;
    double v = b.value[name - 'A'] * s;
    if (machine) {
      if (incremental_) return Err("G53 in incremental mode (G91)");
    } else if (incremental_) {
      if (!(known_ & (1u << a))) {
        return Err(absl::StrCat("incremental (G91) ", std::string(1, name),
                                " move while ", std::string(1, name),
                                " is unknown"));
      }
      v += pos_[a];
    } else {
      v += Offset(a);
    }
    if (!(std::fabs(v) <= kMaxCoordinateMm)) {
      return Err(absl::StrCat(std::string(1, name), " position ", v,
                              " mm is out of range"));
    }
    end[a] = v;
  }
  if (b.words & kPolarWords) return Polar(b, end);
  return absl::OkStatus();
}

// '@' (radius) and '^' (angle, degrees) give X and Y, as LinuxCNC: in G90
// about the origin of the program coordinates (a missing one from the
// current position), in G91 added to the current position's radius and
// angle. G17 only.
absl::Status Interpreter::Polar(const Block& b, double end[3]) {
  if (b.words & (Bit('X') | Bit('Y'))) {
    return Err("X or Y with polar coordinates (@, ^)");
  }
  if (plane_ != 17) {
    return Err("polar coordinates (@, ^) only in the XY plane (G17)");
  }
  const bool has_r = b.words & (uint32_t{1} << kRadiusWord);
  const bool has_a = b.words & (uint32_t{1} << kAngleWord);
  const bool need_here = incremental_ || !has_r || !has_a;
  if (need_here && (known_ & 3) != 3) {
    return Err("polar coordinates (@, ^) relative to an unknown X or Y");
  }
  const double px = need_here ? ProgramPosition(0) : 0;
  const double py = need_here ? ProgramPosition(1) : 0;
  if (incremental_ && px == 0 && py == 0) {
    return Err("incremental polar coordinates (@, ^) at the origin: the "
               "angle is undefined");
  }
  double radius = need_here ? std::hypot(py, px) : 0;
  double angle = need_here ? std::atan2(py, px) : 0;
  const double rv = b.value[kRadiusWord], av = b.value[kAngleWord] * kPi / 180;
  if (incremental_) {
    if (has_r) radius += rv;
    if (has_a) angle += av;
  } else {
    if (has_r) radius = rv;
    if (has_a) angle = av;
  }
  const double xy[2] = {radius * std::cos(angle), radius * std::sin(angle)};
  for (int a = 0; a < 2; ++a) {
    const double v = xy[a] * scale() + Offset(a);
    if (!(std::fabs(v) <= kMaxCoordinateMm)) {
      return Err(absl::StrCat(std::string(1, kAxisName[a]), " position ", v,
                              " mm is out of range"));
    }
    end[a] = v;
  }
  return absl::OkStatus();
}

// Rapids from an unknown position only position the machine (a program's
// first moves, the first after M6); a feed whose start or end is unknown
// cuts somewhere we can't know: it is dropped and counted.
absl::Status Interpreter::Linear(const Block& b, bool machine, bool rapid) {
  double end[3];
  SWARF_RETURN_IF_ERROR(EndPoint(b, machine, end));
  if (comp_side_ != 0) {
    CompSeg seg;
    seg.rapid = rapid;
    seg.line = main_line_;
    for (int a = 0; a < 3; ++a) {
      seg.s[a] = pos_[comp_axes_[a]];
      seg.e[a] = end[comp_axes_[a]];
    }
    for (int a = 0; a < 3; ++a) pos_[a] = end[a];
    return CompAdd(seg);
  }
  if (comp_exit_) {
    const int u = comp_axes_[0], v = comp_axes_[1], w = comp_axes_[2];
    const uint32_t in_plane = Bit(kAxisName[u]) | Bit(kAxisName[v]) |
                              (u + v == 1 ? kPolarWords : 0);
    if (!(b.words & in_plane) && known_ == 7 && blocks_ != comp_exit_block_) {
      pos_[w] = end[w];
      return EmitPlane(last_[u], last_[v], end[w], rapid);
    }
    comp_exit_ = false;
  }
  const unsigned before = known_;
  if (b.words & kPolarWords) known_ |= 3;
  for (int a = 0; a < 3; ++a) {
    if (b.words & Bit(kAxisName[a])) known_ |= 1u << a;
    pos_[a] = end[a];
  }
  if (known_ != 7 || before != 7) {
    if (!rapid) {
      path_.AddDropped(static_cast<int32_t>(main_line_),
                       known_ != 7 ? (~known_ & 7) : (~before & 7));
    }
    if (known_ != 7) return absl::OkStatus();
  }
  return Emit(end[0], end[1], end[2], rapid);
}

absl::Status Interpreter::MoveTo(double x, double y, double z, bool rapid) {
  pos_[0] = x;
  pos_[1] = y;
  pos_[2] = z;
  known_ = 7;
  return Emit(x, y, z, rapid);
}

// A known start (GcodeOptions::start) begins the first run: the first
// move starts there.
absl::Status Interpreter::BeginRun() {
  start_pending_ = false;
  if (in_run_) return absl::OkStatus();
  const double* s = options_.start;
  return Emit(s[0], s[1], s[2], true);
}

absl::Status Interpreter::Emit(double x, double y, double z, bool rapid) {
  if (start_pending_) SWARF_RETURN_IF_ERROR(BeginRun());
  CanonStraight m;
  m.end = {x, y, z};
  m.line = static_cast<int32_t>(emit_line_ >= 0 ? emit_line_ : main_line_);
  m.tool = tool_;
  m.rapid = rapid;
  m.feed = rapid ? 0 : feed_ * scale();
  m.starts_run = !in_run_;
  in_run_ = true;
  last_[0] = x, last_[1] = y, last_[2] = z;
  emitted_ = true;
  absl::Status st =
      sink_ == nullptr ? builder_.Straight(m) : sink_->Straight(m);
  if (!st.ok()) return Err(std::string(st.message()));
  return st;
}

absl::Status Interpreter::Arc(const Block& b) {
  comp_exit_ = false;
  const bool cw = motion_ == 20;
  const char* gname = cw ? "G2" : "G3";
  // The plane's axes (first, second, linear) and centre words; the first
  // to the second is counterclockwise seen from the normal's positive side.
  int p0 = 0, p1 = 1, p2 = 2;
  char w0 = 'I', w1 = 'J', bad = 'K';
  if (plane_ == 18) {
    p0 = 2, p1 = 0, p2 = 1, w0 = 'K', w1 = 'I', bad = 'J';
  } else if (plane_ == 19) {
    p0 = 1, p1 = 2, p2 = 0, w0 = 'J', w1 = 'K', bad = 'I';
  }
  const std::string plane_name = plane_ == 17   ? "XY-plane (G17)"
                                 : plane_ == 18 ? "XZ-plane (G18)"
                                                : "YZ-plane (G19)";
  if (b.words & Bit(bad)) {
    return Err(absl::StrCat(std::string(1, bad), " word in an ", plane_name,
                            " ", gname, " arc"));
  }
  if ((!in_run_ && !start_pending_) || known_ != 7) {
    return Err(absl::StrCat(gname,
                            " arc before the start position is known (X, Y "
                            "and Z must all be given first)"));
  }
  const bool has_ij = b.words & (Bit(w0) | Bit(w1));
  const bool has_r = b.words & Bit('R');
  if (has_ij && has_r) {
    return Err(absl::StrCat(gname, " arc with both ", std::string(1, w0), "/",
                            std::string(1, w1), " and R"));
  }
  if (!has_ij && !has_r) {
    return Err(absl::StrCat(gname, " arc without ", std::string(1, w0), "/",
                            std::string(1, w1), " or R"));
  }
  int64_t turns = 1;
  if (b.words & Bit('P')) {
    const double pv = b.value['P' - 'A'];
    if (!(pv >= 1 && pv <= 10000) || pv != std::floor(pv)) {
      return Err(absl::StrCat("P", pv, " in a ", gname,
                              " arc is not a turn count (1, 2, ...)"));
    }
    turns = static_cast<int64_t>(pv);
  }
  double end[3];
  SWARF_RETURN_IF_ERROR(EndPoint(b, false, end));
  const double s = scale();
  for (const char w : {w0, w1, 'R'}) {
    if ((b.words & Bit(w)) &&
        !(std::fabs(b.value[w - 'A'] * s) <= kMaxCoordinateMm)) {
      return Err(absl::StrCat(std::string(1, w), " value ", b.value[w - 'A'],
                              " is out of range"));
    }
  }
  const double x0 = pos_[p0], y0 = pos_[p1], z0 = pos_[p2];
  const double x1 = end[p0], y1 = end[p1], z1 = end[p2];

  double cx, cy;
  if (has_r) {
    const double r = b.value['R' - 'A'] * s;
    if (x1 == x0 && y1 == y0) {
      return Err(absl::StrCat(gname,
                              " full circle with R: the centre is undefined "
                              "(use ",
                              std::string(1, w0), "/", std::string(1, w1),
                              ")"));
    }
    const double dx = x1 - x0, dy = y1 - y0;
    const double d = std::hypot(dx, dy);
    const double half = d / 2, ar = std::fabs(r);
    if (half - ar > kRadiusTolerance) {
      return Err(absl::StrCat("R", b.value['R' - 'A'], " in ", gname,
                              " is too small to reach the end point (half "
                              "the chord is ",
                              half, " mm)"));
    }
    const double h = half >= ar ? 0.0 : std::sqrt(ar * ar - half * half);
    // The centre is on the chord's bisector, left of the chord's direction
    // for a G3 short arc (R > 0) or a G2 long arc (R < 0), right otherwise.
    const double side = (!cw) == (r > 0) ? 1.0 : -1.0;
    cx = (x0 + x1) / 2 - side * h * dy / d;
    cy = (y0 + y1) / 2 + side * h * dx / d;
  } else {
    const double i = (b.words & Bit(w0)) ? b.value[w0 - 'A'] * s : 0.0;
    const double j = (b.words & Bit(w1)) ? b.value[w1 - 'A'] * s : 0.0;
    cx = arc_absolute_ ? i + Offset(p0) : x0 + i;
    cy = arc_absolute_ ? j + Offset(p1) : y0 + j;
  }
  auto made = CentreArc({pos_[0], pos_[1], pos_[2]}, {end[0], end[1], end[2]},
                        cx, cy, plane_, cw, turns, gname);
  if (!made.ok()) return Err(std::string(made.status().message()));
  const double r0 = made->r0, r1 = made->r1, a0 = made->a0;
  const double sweep = made->sweep;
  if (comp_side_ != 0) {
    CompSeg seg;
    seg.arc = true;
    seg.line = main_line_;
    seg.s[0] = x0, seg.s[1] = y0, seg.s[2] = z0;
    seg.e[0] = x1, seg.e[1] = y1, seg.e[2] = z1;
    seg.c[0] = cx, seg.c[1] = cy;
    seg.radius = r0;
    seg.sweep = sweep;
    SWARF_RETURN_IF_ERROR(CompAdd(seg));
  } else {
    SWARF_RETURN_IF_ERROR(ChordArc(p0, p1, p2, cx, cy, r0, r1, a0, sweep, z0,
                                   end, false));
  }
  for (int a = 0; a < 3; ++a) pos_[a] = end[a];
  return absl::OkStatus();
}

// Emits an arc in the plane of axes (p0, p1) from angle a0 through `sweep`
// (radius r0 to r1, linear: a spiral when they differ; the third axis
// linear from z0), ending exactly at `end` (x, y, z): a CanonArc.
absl::Status Interpreter::ChordArc(int p0, int p1, int p2, double cx,
                                   double cy, double r0, double r1, double a0,
                                   double sweep, double z0, const double end[3],
                                   bool rapid) {
  if (start_pending_) SWARF_RETURN_IF_ERROR(BeginRun());
  CanonArc arc;
  arc.end = {end[0], end[1], end[2]};
  arc.p0 = p0, arc.p1 = p1, arc.p2 = p2;
  arc.cx = cx, arc.cy = cy;
  arc.r0 = r0, arc.r1 = r1;
  arc.a0 = a0, arc.sweep = sweep;
  arc.z0 = z0;
  arc.line = static_cast<int32_t>(emit_line_ >= 0 ? emit_line_ : main_line_);
  arc.tool = tool_;
  arc.rapid = rapid;
  arc.feed = rapid ? 0 : feed_ * scale();
  in_run_ = true;
  last_[0] = end[0], last_[1] = end[1], last_[2] = end[2];
  emitted_ = true;
  absl::Status st =
      sink_ == nullptr ? builder_.ArcFeed(arc) : sink_->ArcFeed(arc);
  if (!st.ok()) return Err(std::string(st.message()));
  return st;
}

// Canned cycles, after LinuxCNC (XY plane). A series of cycles (until G80
// or another motion mode) keeps its initial level: the height before its
// first cycle, raised to R when below it. Each hole: over to it (the
// series' first at the current height, the others at the clearance
// height: a straight rapid, diagonal when the height changes), down to R,
// the cycle's own moves, then back to the clearance height: R under G99,
// the initial level under G98. Under G91, R is relative to the initial
// level, Z to R, and X/Y (or @/^) step from hole to hole for L repeats.
absl::Status Interpreter::Cycle(const Block& b, uint32_t* used) {
  comp_exit_ = false;
  const std::string g = GName(motion_);
  *used |= Bit('R') | Bit('Q') | Bit('P') | Bit('L');
  const bool fanuc = options_.dialect == Dialect::kFanuc;
  if (motion_ == 870) {
    if (fanuc) {
      return Err("G87 in the Fanuc form (back boring with a Q shift) is not "
                 "supported");
    }
    *used |= Bit('I') | Bit('J') | Bit('K');
  }
  if (fanuc) *used |= Bit('K');
  if (plane_ != 17) {
    return Err(absl::StrCat(g, " in the ", plane_ == 18 ? "G18" : "G19",
                            " plane is not supported (canned cycles: G17 "
                            "only)"));
  }
  if (b.words & Bit('R')) cycle_r_ = b.value['R' - 'A'];
  if (b.words & Bit('Z')) cycle_z_ = b.value['Z' - 'A'];
  if (b.words & Bit('Q')) cycle_q_ = b.value['Q' - 'A'];
  if (std::isnan(cycle_r_)) return Err(g + " needs R (the retract height)");
  if (std::isnan(cycle_z_)) return Err(g + " needs Z (the hole bottom)");
  if (!(known_ & 4)) {
    return Err(g + " while Z is unknown (the cycle starts from the current "
                   "height)");
  }
  int64_t repeats = 1;
  if (b.words & Bit('L')) {
    const double l = b.value['L' - 'A'];
    if (!(l >= 1 && l <= 1e6) || l != std::floor(l)) {
      return Err(absl::StrCat(g, " L", l, " is not a repeat count"));
    }
    repeats = static_cast<int64_t>(l);
  }
  if (fanuc && (b.words & Bit('K'))) {
    // Fanuc's repeat count.
    const double k = b.value['K' - 'A'];
    if (!(k >= 1 && k <= 1e6) || k != std::floor(k)) {
      return Err(absl::StrCat(g, " K", k, " is not a repeat count"));
    }
    repeats = static_cast<int64_t>(k);
  }
  const double s = scale();
  double peck = 0;
  if (motion_ == 730 || motion_ == 830) {
    peck = cycle_q_ * s;
    if (!(peck > 0)) return Err(g + " needs Q > 0 (the peck depth)");
  }
  // The series' initial level: the height before its first cycle.
  if (!cycle_il_set_) {
    cycle_il_set_ = true;
    cycle_il_ = pos_[2];
  }
  double old_z = cycle_il_;
  double r, bottom;
  if (incremental_) {
    r = old_z + cycle_r_ * s;
    bottom = r + cycle_z_ * s;
  } else {
    r = cycle_r_ * s + Offset(2);
    bottom = cycle_z_ * s + Offset(2);
  }
  for (const double v : {r, bottom}) {
    if (!(std::fabs(v) <= kMaxCoordinateMm)) return Err(g + ": out of range");
  }
  if (bottom > r) {
    return Err(absl::StrCat(g, ": the hole bottom Z is above the retract "
                               "height R"));
  }
  // Below R at the initial level: straight up (or down) to R first.
  double current = pos_[2];
  if (old_z < r) {
    if ((known_ & 3) == 3) {
      SWARF_RETURN_IF_ERROR(MoveTo(pos_[0], pos_[1], r, true));
    } else {
      pos_[2] = r;
    }
    old_z = current = r;
  }
  const double clear = retract_r_ ? r : old_z;
  double middle = 0, off[2] = {0, 0};
  if (motion_ == 870) {
    if ((b.words & (Bit('I') | Bit('J') | Bit('K'))) !=
        (Bit('I') | Bit('J') | Bit('K'))) {
      return Err("G87 (back boring) needs I, J and K");
    }
    off[0] = b.value['I' - 'A'] * s;
    off[1] = b.value['J' - 'A'] * s;
    middle = b.value['K' - 'A'] * s + (incremental_ ? bottom : Offset(2));
    if (!(middle >= bottom && middle <= r)) {
      return Err("G87: K must lie between the hole bottom Z and R");
    }
  }
  const int64_t pecks =
      peck > 0 ? static_cast<int64_t>(std::min(
                     std::ceil((r - bottom) / peck), 1e15))
               : 0;
  if (pecks * repeats > options_.max_points) {
    return Err(absl::StrCat(g, " needs ", pecks, " pecks: more than "
                            "max_points"));
  }
  const auto feed = [&](double x, double y, double z) {
    return MoveTo(x, y, z, false);
  };
  const auto rapid = [&](double x, double y, double z) {
    return MoveTo(x, y, z, true);
  };
  for (int64_t k = 0; k < repeats; ++k) {
    double x = 0, y = 0;
    if (b.words & kPolarWords) {
      double e[3] = {pos_[0], pos_[1], pos_[2]};
      SWARF_RETURN_IF_ERROR(Polar(b, e));
      x = e[0], y = e[1];
    }
    for (int a = 0; a < 2 && !(b.words & kPolarWords); ++a) {
      const char name = kAxisName[a];
      const bool given = b.words & Bit(name);
      double v = pos_[a];
      if (given && !incremental_) {
        v = b.value[name - 'A'] * s + Offset(a);
      } else if (!(known_ & (1u << a))) {
        return Err(absl::StrCat(g, " while ", std::string(1, name),
                                " is unknown"));
      } else if (given) {
        v += b.value[name - 'A'] * s;
      }
      if (!(std::fabs(v) <= kMaxCoordinateMm)) return Err(g + ": out of range");
      (a == 0 ? x : y) = v;
    }
    // Over to the hole (the first at the current height, the others at the
    // clearance height) and down to R.
    const double over = k == 0 && current > r ? current : clear;
    SWARF_RETURN_IF_ERROR(rapid(x, y, over));
    SWARF_RETURN_IF_ERROR(rapid(x, y, r));
    switch (motion_) {
      case 730:  // chip-breaking pecks: a short retract after each
      case 830:  // deep-hole pecks: out to R after each
        for (int64_t i = 1; i < pecks; ++i) {
          const double depth = r - static_cast<double>(i) * peck;
          if (!(depth > bottom)) break;
          SWARF_RETURN_IF_ERROR(feed(x, y, depth));
          if (motion_ == 830) SWARF_RETURN_IF_ERROR(rapid(x, y, r));
          SWARF_RETURN_IF_ERROR(
              rapid(x, y, std::min(r, depth + kPeckClearanceMm)));
        }
        SWARF_RETURN_IF_ERROR(feed(x, y, bottom));
        break;
      case 760:
        // Fanuc fine boring: the Q shift away from the wall before the
        // rapid out touches no new material, so it is not simulated.
      case 810: case 820: case 860: case 880:
        // Drill (G81), with a dwell (G82); boring with a spindle stop and a
        // rapid out (G86) or a manual retract, taken as straight up (G88).
        SWARF_RETURN_IF_ERROR(feed(x, y, bottom));
        break;
      case 740: case 840: case 850: case 890:
        // Tapping (out at the feed, spindle reversed) and boring with a
        // feed out (G85, G89 with a dwell).
        SWARF_RETURN_IF_ERROR(feed(x, y, bottom));
        SWARF_RETURN_IF_ERROR(feed(x, y, r));
        break;
      case 870:
        // Back boring: past the hole offset by I/J, down to Z, centred, up
        // to K at the feed and back down, offset again and out.
        SWARF_RETURN_IF_ERROR(rapid(x + off[0], y + off[1], r));
        SWARF_RETURN_IF_ERROR(rapid(x + off[0], y + off[1], bottom));
        SWARF_RETURN_IF_ERROR(rapid(x, y, bottom));
        SWARF_RETURN_IF_ERROR(feed(x, y, middle));
        SWARF_RETURN_IF_ERROR(feed(x, y, bottom));
        SWARF_RETURN_IF_ERROR(rapid(x + off[0], y + off[1], bottom));
        SWARF_RETURN_IF_ERROR(rapid(x + off[0], y + off[1], clear));
        break;
      default:
        return Err(UnsupportedG(motion_));
    }
    SWARF_RETURN_IF_ERROR(rapid(x, y, clear));
  }
  return absl::OkStatus();
}

}  // namespace swarf::gcode::interp

namespace swarf::gcode {

absl::StatusOr<CanonArc> CentreArc(const Vec3& start, const Vec3& end,
                                   double cx, double cy, int plane, bool cw,
                                   int64_t turns, std::string_view name) {
  using interp::kPi;
  int p0 = 0, p1 = 1, p2 = 2;
  if (plane == 18) {
    p0 = 2, p1 = 0, p2 = 1;
  } else if (plane == 19) {
    p0 = 1, p1 = 2, p2 = 0;
  }
  const double s[3] = {start.x, start.y, start.z};
  const double e[3] = {end.x, end.y, end.z};
  const double x0 = s[p0], y0 = s[p1];
  const double x1 = e[p0], y1 = e[p1];
  const std::string gname(name);
  const double r0 = std::hypot(x0 - cx, y0 - cy);
  const double r1 = std::hypot(x1 - cx, y1 - cy);
  if (!(r0 >= interp::kRadiusTolerance && r1 >= interp::kRadiusTolerance)) {
    return absl::InvalidArgumentError(
        absl::StrCat(gname, " arc has a zero radius (", r0,
                     " mm at the start, ", r1, " mm at the end)"));
  }
  const double err = std::fabs(r1 - r0);
  if (err > interp::kSpiralAbsMax ||
      (err > interp::kSpiralAbsFloor &&
       err > interp::kSpiralRel * std::max(r0, r1))) {
    return absl::InvalidArgumentError(absl::StrCat(
        gname, " arc: the radius to the end (", r1,
        " mm) differs from the radius to the start (", r0, " mm) by ", err,
        " mm"));
  }
  const double a0 = std::atan2(y0 - cy, x0 - cx);
  const double a1 = std::atan2(y1 - cy, x1 - cx);
  // Signed sweep: G2 clockwise (negative), G3 counterclockwise; equal
  // angles (start == end) make a full circle; P adds whole turns.
  double sweep = a1 - a0;
  if (cw) {
    if (sweep >= 0) sweep -= 2 * kPi;
    sweep -= 2 * kPi * static_cast<double>(turns - 1);
  } else {
    if (sweep <= 0) sweep += 2 * kPi;
    sweep += 2 * kPi * static_cast<double>(turns - 1);
  }
  CanonArc arc;
  arc.end = end;
  arc.p0 = p0, arc.p1 = p1, arc.p2 = p2;
  arc.cx = cx, arc.cy = cy;
  arc.r0 = r0, arc.r1 = r1;
  arc.a0 = a0, arc.sweep = sweep;
  arc.z0 = s[p2];
  return arc;
}

}  // namespace swarf::gcode
