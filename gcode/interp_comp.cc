// The interpreter's cutter radius compensation (see interpreter.h): G41/G42
// and G41.1/G42.1 in the plane of G17, G18 or G19, entry moves (lines and
// arcs), corners (convex: an arc; concave: where the offset moves meet),
// G40 and the exit.
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

// ------------------------------------------------------------ compensation
//
// As LinuxCNC: the tool runs at its radius left (G41) or right (G42) of the
// programmed path in the XY plane. The first move after G41/G42 (the entry,
// a straight line) ends at its programmed end offset perpendicular to it;
// the move after G40 (the exit) starts from the last offset point. At a
// convex corner the tool goes around the corner on an arc of its radius; at
// a concave corner both offset moves end where they meet, and a corner the
// tool cannot reach (a move shorter than the radius needs) is an error
// naming its line. Z follows each move linearly. Each move waits for the
// next to know its corner.

absl::Status Interpreter::CompStart(const Block& b, int code) {
  if (comp_side_ != 0) {
    return Err(absl::StrCat(GName(code),
                            " with cutter compensation already on (G40 "
                            "first)"));
  }
  // The plane's axes, as Arc() orders them (first to second counterclockwise
  // seen from the third's positive side).
  comp_axes_[0] = plane_ == 17 ? 0 : plane_ == 18 ? 2 : 1;
  comp_axes_[1] = plane_ == 17 ? 1 : plane_ == 18 ? 0 : 2;
  comp_axes_[2] = plane_ == 17 ? 2 : plane_ == 18 ? 1 : 0;
  if (known_ != 7) {
    return Err(absl::StrCat(GName(code),
                            " before the position is known (X, Y and Z)"));
  }
  double r;
  if (code == 411 || code == 421) {
    if (!(b.words & Bit('D'))) return Err(GName(code) + " needs D (diameter)");
    r = b.value['D' - 'A'] * scale() / 2;
  } else {
    int tool = tool_;
    if (b.words & Bit('D')) {
      const double d = b.value['D' - 'A'];
      if (!(d >= 0 && d <= 65535) || d != std::floor(d)) {
        return Err(absl::StrCat(GName(code), " D", d,
                                " is not a tool number"));
      }
      tool = static_cast<int>(d);
    }
    std::optional<double> known;
    if (tool == 0) {
      known = 0.0;  // D0: no compensation, as LinuxCNC
    } else if (options_.tool_radius) {
      known = options_.tool_radius(tool);
    }
    if (!known.has_value()) {
      return Err(absl::StrCat(GName(code), ": the radius of tool ", tool,
                              " is unknown (give --tool ", tool, "=...)"));
    }
    r = *known;
  }
  if (!(r >= 0 && r <= 1e4)) {
    return Err(absl::StrCat(GName(code), ": tool radius ", r,
                            " mm is out of range"));
  }
  ++letter_ignored_['D' - 'A'];  // counted: the word has no move of its own
  comp_side_ = code == 410 || code == 411 ? 1 : -1;
  comp_r_ = r;
  comp_entry_ = true;
  comp_pending_ = false;
  ++g_ignored_[code];
  return absl::OkStatus();
}

// An arc as the entry move, as LinuxCNC: it ends offset along the
// programmed arc's radius at its end, on an arc from where the tool is
// whose centre lies on that radius (so the tool leaves it along the
// programmed arc's end direction); a spiral-free arc, so its centre moves.
absl::Status Interpreter::CompArcEntry(CompSeg seg) {
  if (!(seg.tr >= kRadiusTolerance)) {
    return Err(absl::StrCat("arc of radius ", seg.radius,
                            " mm is too small for the compensated tool "
                            "radius ",
                            comp_r_, " mm on its inside"));
  }
  const double sign = seg.sweep > 0 ? 1 : -1;
  const double a1 = std::atan2(seg.e[1] - seg.c[1], seg.e[0] - seg.c[0]);
  seg.te[0] = seg.c[0] + seg.tr * std::cos(a1);
  seg.te[1] = seg.c[1] + seg.tr * std::sin(a1);
  // The new centre: te + t u, u towards the programmed centre, as far from
  // the start as from te.
  const double ux = -std::cos(a1), uy = -std::sin(a1);
  const double dx = seg.te[0] - seg.s[0], dy = seg.te[1] - seg.s[1];
  const double den = 2 * (ux * dx + uy * dy);
  if (!(std::fabs(den) > 1e-9)) {
    return Err("cutter compensation: the entry arc cannot start where the "
               "tool is (it is on the arc's end tangent)");
  }
  const double t = -(dx * dx + dy * dy) / den;
  seg.c[0] = seg.te[0] + t * ux;
  seg.c[1] = seg.te[1] + t * uy;
  seg.tr = std::fabs(t);
  seg.ts[0] = seg.s[0];
  seg.ts[1] = seg.s[1];
  seg.ta = std::atan2(seg.s[1] - seg.c[1], seg.s[0] - seg.c[0]);
  double sweep = std::atan2(seg.te[1] - seg.c[1], seg.te[0] - seg.c[0]) - seg.ta;
  const double whole =
      std::floor((std::fabs(seg.sweep) - 1e-9) / (2 * kPi)) * 2 * kPi;
  // The centre beyond te from the programmed one turns the other way.
  const double rot = t > 0 ? sign : -sign;
  if (rot > 0) {
    while (sweep <= 0) sweep += 2 * kPi;
    sweep += whole;
  } else {
    while (sweep >= 0) sweep -= 2 * kPi;
    sweep -= whole;
  }
  seg.tsweep = sweep;
  seg.dir_s[0] = -std::sin(seg.ta) * rot;
  seg.dir_s[1] = std::cos(seg.ta) * rot;
  // The end tangent is the programmed arc's (the centre is on its radius).
  seg.dir_e[0] = -std::sin(a1) * sign;
  seg.dir_e[1] = std::cos(a1) * sign;
  comp_entry_ = false;
  comp_seg_ = seg;
  comp_pending_ = true;
  return absl::OkStatus();
}

absl::Status Interpreter::CompAdd(CompSeg seg) {
  const double dx = seg.e[0] - seg.s[0], dy = seg.e[1] - seg.s[1];
  const double r = comp_r_ * comp_side_;  // signed: + left
  if (!seg.arc) {
    const double len = std::hypot(dx, dy);
    if (len < 1e-12) {
      // A move along Z only: the tool stays where it is in XY.
      SWARF_RETURN_IF_ERROR(CompFlush());
      double here[2] = {seg.s[0], seg.s[1]};
      if (emitted_) {
        here[0] = last_[comp_axes_[0]];
        here[1] = last_[comp_axes_[1]];
      }
      return EmitPlane(here[0], here[1], seg.e[2], seg.rapid);
    }
    seg.dir_s[0] = seg.dir_e[0] = dx / len;
    seg.dir_s[1] = seg.dir_e[1] = dy / len;
    const double nx = -dy / len * r, ny = dx / len * r;
    seg.ts[0] = seg.s[0] + nx;
    seg.ts[1] = seg.s[1] + ny;
    seg.te[0] = seg.e[0] + nx;
    seg.te[1] = seg.e[1] + ny;
    if (comp_entry_) {
      // The entry: from where the tool is to the offset end.
      seg.entry = true;
      seg.os[0] = seg.ts[0];
      seg.os[1] = seg.ts[1];
      seg.ts[0] = seg.s[0];
      seg.ts[1] = seg.s[1];
    }
  } else {
    const double sign = seg.sweep > 0 ? 1 : -1;
    seg.tr = seg.radius - r * sign;
    if (comp_entry_) return CompArcEntry(seg);
    if (std::fabs(seg.tr) < kRadiusTolerance) {
      // A tool as large as the arc, on its inside: its centre stays on the
      // arc's (LinuxCNC's arc of radius zero; a helix plunges).
      SWARF_RETURN_IF_ERROR(CompFlush());
      comp_entry_ = false;
      return EmitPlane(seg.c[0], seg.c[1], seg.e[2], seg.rapid);
    }
    if (!(seg.tr >= kRadiusTolerance)) {
      return Err(absl::StrCat("arc of radius ", seg.radius,
                              " mm is too small for the compensated tool "
                              "radius ",
                              comp_r_, " mm on its inside"));
    }
    seg.ta = std::atan2(seg.s[1] - seg.c[1], seg.s[0] - seg.c[0]);
    seg.tsweep = seg.sweep;
    const double a1 = seg.ta + seg.sweep;
    seg.ts[0] = seg.c[0] + seg.tr * std::cos(seg.ta);
    seg.ts[1] = seg.c[1] + seg.tr * std::sin(seg.ta);
    seg.te[0] = seg.c[0] + seg.tr * std::cos(a1);
    seg.te[1] = seg.c[1] + seg.tr * std::sin(a1);
    seg.dir_s[0] = -std::sin(seg.ta) * sign;
    seg.dir_s[1] = std::cos(seg.ta) * sign;
    seg.dir_e[0] = -std::sin(a1) * sign;
    seg.dir_e[1] = std::cos(a1) * sign;
  }
  comp_entry_ = false;
  if (comp_pending_) {
    SWARF_RETURN_IF_ERROR(CompJoin(&comp_seg_, &seg));
  }
  comp_seg_ = seg;
  comp_pending_ = true;
  return absl::OkStatus();
}

namespace {

// Intersections of the tool paths of a and b near the corner: lines as
// infinite lines, arcs as circles.
int Intersect(const CompSeg& a, const CompSeg& b, double out[2][2]) {
  if (!a.arc && !b.arc) {
    const double* as = a.LineStart();
    const double ux = a.te[0] - as[0], uy = a.te[1] - as[1];
    const double vx = b.te[0] - b.ts[0], vy = b.te[1] - b.ts[1];
    const double den = ux * vy - uy * vx;
    if (std::fabs(den) < 1e-300) return 0;
    const double t =
        ((b.ts[0] - as[0]) * vy - (b.ts[1] - as[1]) * vx) / den;
    out[0][0] = as[0] + t * ux;
    out[0][1] = as[1] + t * uy;
    return 1;
  }
  // A circle (c, r) against a line (p, d) or a circle.
  const CompSeg& circ = a.arc ? a : b;
  const CompSeg& other = a.arc ? b : a;
  if (!other.arc) {
    const double* os = other.LineStart();
    const double dx = other.te[0] - os[0], dy = other.te[1] - os[1];
    const double len = std::hypot(dx, dy);
    const double ux = dx / len, uy = dy / len;
    const double fx = os[0] - circ.c[0], fy = os[1] - circ.c[1];
    const double bq = fx * ux + fy * uy;
    const double cq = fx * fx + fy * fy - circ.tr * circ.tr;
    const double disc = bq * bq - cq;
    if (disc < 0) return 0;
    const double sq = std::sqrt(disc);
    for (int k = 0; k < 2; ++k) {
      const double t = -bq + (k == 0 ? -sq : sq);
      out[k][0] = os[0] + t * ux;
      out[k][1] = os[1] + t * uy;
    }
    return 2;
  }
  const double dx = b.c[0] - a.c[0], dy = b.c[1] - a.c[1];
  const double d = std::hypot(dx, dy);
  if (d < 1e-12 || d > a.tr + b.tr || d < std::fabs(a.tr - b.tr)) return 0;
  const double l = (a.tr * a.tr - b.tr * b.tr + d * d) / (2 * d);
  const double h = std::sqrt(std::max(0.0, a.tr * a.tr - l * l));
  const double mx = a.c[0] + l * dx / d, my = a.c[1] + l * dy / d;
  out[0][0] = mx - h * dy / d;
  out[0][1] = my + h * dx / d;
  out[1][0] = mx + h * dy / d;
  out[1][1] = my - h * dx / d;
  return 2;
}

// Where p lies along a segment's tool path: 0 at its start, 1 at its end
// (lines: the parameter; arcs: the fraction of the sweep). On an entry
// line, `offset_line` measures along its offset line instead.
double Along(const CompSeg& s, const double p[2], bool offset_line = false) {
  if (!s.arc) {
    const double* st = offset_line ? s.LineStart() : s.ts;
    const double ux = s.te[0] - st[0], uy = s.te[1] - st[1];
    const double len2 = ux * ux + uy * uy;
    return len2 > 0 ? ((p[0] - st[0]) * ux + (p[1] - st[1]) * uy) / len2
                    : 0;
  }
  double a = std::atan2(p[1] - s.c[1], p[0] - s.c[0]) - s.ta;
  // Into the sweep's direction, [0, 2 pi).
  if (s.tsweep > 0) {
    a = std::fmod(a, 2 * kPi);
    if (a < 0) a += 2 * kPi;
  } else {
    a = std::fmod(-a, 2 * kPi);
    if (a < 0) a += 2 * kPi;
  }
  return a / std::fabs(s.tsweep);
}

}  // namespace

absl::Status Interpreter::CompJoin(CompSeg* a, CompSeg* b) {
  const double cross = a->dir_e[0] * b->dir_s[1] - a->dir_e[1] * b->dir_s[0];
  const double dot = a->dir_e[0] * b->dir_s[0] + a->dir_e[1] * b->dir_s[1];
  const double gap = std::hypot(b->ts[0] - a->te[0], b->ts[1] - a->te[1]);
  if (gap < 1e-9 || (std::fabs(cross) < 1e-9 && dot > 0)) {
    return CompEmit(*a);  // tangent
  }
  if (comp_side_ * cross < 0 || (std::fabs(cross) < 1e-9 && dot < 0)) {
    // Convex: around the corner on an arc of the tool's radius.
    SWARF_RETURN_IF_ERROR(CompEmit(*a));
    const double px = a->e[0], py = a->e[1];
    const double a0 = std::atan2(a->te[1] - py, a->te[0] - px);
    const double a1 = std::atan2(b->ts[1] - py, b->ts[0] - px);
    double sweep = a1 - a0;
    if (comp_side_ > 0) {
      while (sweep > 0) sweep -= 2 * kPi;
    } else {
      while (sweep < 0) sweep += 2 * kPi;
    }
    const double end[3] = {b->ts[0], b->ts[1], a->e[2]};
    emit_line_ = b->line;  // the corner belongs to the move after it
    absl::Status st = ChordPlaneArc(px, py, comp_r_, a0, sweep, a->e[2], end,
                                    b->rapid);
    emit_line_ = -1;
    return st;
  }
  // Concave: both end where they meet, nearest the corner.
  double x[2][2];
  const int n = Intersect(*a, *b, x);
  int best = -1;
  double best_d = INFINITY;
  for (int k = 0; k < n; ++k) {
    const double ta = Along(*a, x[k], true), tb = Along(*b, x[k]);
    if (!(ta >= -1e-9 && ta <= 1 + 1e-9 && tb >= -1e-9 && tb <= 1 + 1e-9)) {
      continue;
    }
    const double d = std::hypot(x[k][0] - a->e[0], x[k][1] - a->e[1]);
    if (d < best_d) {
      best_d = d;
      best = k;
    }
  }
  if (best < 0 && dot > 0 && std::fabs(cross) < kNearlyTangent) {
    // Tangent but for rounding (a line into an arc with coordinates of
    // a few decimals): no corner to cut, as LinuxCNC.
    return CompEmit(*a);
  }
  if (best < 0) {
    return LineError(b->line,
                     absl::StrCat("cutter compensation: the tool (radius ",
                                  comp_r_,
                                  " mm) cannot reach the concave corner "
                                  "between line ",
                                  a->line, " and this one"));
  }
  const double* p = x[best];
  const double fa = std::clamp(Along(*a, p), 0.0, 1.0);
  const double fb = std::clamp(Along(*b, p), 0.0, 1.0);
  a->te[0] = p[0];
  a->te[1] = p[1];
  a->e[2] = a->s[2] + (a->e[2] - a->s[2]) * fa;
  if (a->arc) a->tsweep *= fa;
  b->ts[0] = p[0];
  b->ts[1] = p[1];
  if (b->arc) {
    b->ta += b->tsweep * fb;
    b->tsweep *= 1 - fb;
  }
  return CompEmit(*a);
}

// Emits a move's tool path; its points carry the move's line (it is
// emitted when the next move, on a later line, is known).
absl::Status Interpreter::CompEmit(const CompSeg& seg) {
  emit_line_ = seg.line;
  absl::Status st;
  if (!seg.arc) {
    st = EmitPlane(seg.te[0], seg.te[1], seg.e[2], seg.rapid);
  } else {
    const double end[3] = {seg.te[0], seg.te[1], seg.e[2]};
    const double z0 = emitted_ ? last_[comp_axes_[2]] : seg.s[2];
    st = ChordPlaneArc(seg.c[0], seg.c[1], seg.tr, seg.ta, seg.tsweep, z0,
                       end, seg.rapid);
  }
  emit_line_ = -1;
  return st;
}

absl::Status Interpreter::CompFlush() {
  if (!comp_pending_) return absl::OkStatus();
  comp_pending_ = false;
  return CompEmit(comp_seg_);
}

}  // namespace swarf::gcode::interp
