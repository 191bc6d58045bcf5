#include "gcode/toolpath.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numbers>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/huge_pages.h"
#include "core/status_macros.h"
#include "core/thread_pool.h"
#include "gcode/text.h"

namespace swarf::gcode {
namespace {

constexpr double kMaxCoordinateMm = 1e9;

// The rank of an ignored word in the summary: G-codes, M-codes (by number),
// other letters, then the rest.
struct WordKey {
  int rank;
  double number;
  const std::string* word;
};

WordKey KeyOf(const std::string& w) {
  const char c = w.empty() ? 0 : w[0];
  int rank = c == 'G' ? 0 : c == 'M' ? 1 : (c >= 'A' && c <= 'Z') ? 2 : 3;
  double number = 0;
  if (rank < 2 && w.size() > 1) {
    std::from_chars(w.data() + 1, w.data() + w.size(), number);
  }
  return {rank, number, &w};
}

}  // namespace

int64_t CanonArc::Turns() const {
  const double t = std::fabs(sweep) / (2 * std::numbers::pi);
  const int64_t n = std::max<int64_t>(1, static_cast<int64_t>(std::ceil(t - 1e-9)));
  return sweep < 0 ? -n : n;
}

absl::Status ToolpathBuilder::TooManyPoints() const {
  return absl::InvalidArgumentError(
      absl::StrCat("more than ", max_points_, " points (max_points)"));
}

// Chords of angle `step` deviate from the arc by the sagitta
// r (1 - cos(step / 2)) = 2 r sin^2(step / 4) <= tolerance; asin form for
// accuracy when tolerance << r. At most a quarter turn per chord.
absl::Status ToolpathBuilder::ArcFeed(const CanonArc& a) {
  constexpr double kPi = std::numbers::pi;
  const double q = arc_tolerance_ / (2 * std::max(a.r0, a.r1));
  const double step =
      q >= 0.5 ? kPi / 2 : std::min(kPi / 2, 4 * std::asin(std::sqrt(q)));
  const double segments = std::ceil(std::fabs(a.sweep) / step);
  if (!(segments <= static_cast<double>(max_points_ - path_->point_count()))) {
    return absl::InvalidArgumentError(
        absl::StrCat("an arc needs ", segments,
                     " points: more than max_points (", max_points_, ")"));
  }
  const int64_t n = std::max<int64_t>(1, static_cast<int64_t>(segments));
  const double end[3] = {a.end.x, a.end.y, a.end.z};
  CanonStraight m;
  m.line = a.line;
  m.tool = a.tool;
  m.rapid = a.rapid;
  m.feed = a.feed;
  double pt[3];
  for (int64_t k = 1; k < n; ++k) {
    const double t = static_cast<double>(k) / static_cast<double>(n);
    const double ang = a.a0 + a.sweep * t;
    const double r = a.r0 + (a.r1 - a.r0) * t;
    pt[a.p0] = a.cx + r * std::cos(ang);
    pt[a.p1] = a.cy + r * std::sin(ang);
    pt[a.p2] = a.z0 + (end[a.p2] - a.z0) * t;
    // The arc may bulge past the bound its end points keep.
    if (!(std::fabs(pt[a.p0]) <= kMaxCoordinateMm &&
          std::fabs(pt[a.p1]) <= kMaxCoordinateMm)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "an arc leaves the range of +-", kMaxCoordinateMm, " mm at (",
          pt[0], ", ", pt[1], ", ", pt[2], ")"));
    }
    m.end = {pt[0], pt[1], pt[2]};
    SWARF_RETURN_IF_ERROR(Straight(m));
  }
  // The end, exactly.
  m.end = a.end;
  return Straight(m);
}

absl::StatusOr<std::vector<Vec3>> ChordArc(const Vec3& start,
                                           const CanonArc& arc,
                                           double arc_tolerance,
                                           int64_t max_points) {
  // Through the builder itself, from the start, so that the chords (and
  // the dropping of a repeated point) are the CLI's to the bit.
  Toolpath path;
  ToolpathPoint first;
  first.position = start;
  path.Append(first);
  ToolpathBuilder builder(&path, arc_tolerance, max_points + 1);
  SWARF_RETURN_IF_ERROR(builder.ArcFeed(arc));
  std::vector<Vec3> out;
  out.reserve(path.points().size() - 1);
  for (size_t k = 1; k < path.points().size(); ++k) {
    out.push_back(path.points()[k].position);
  }
  return out;
}

std::vector<ToolpathRun> SplitRuns(
    const Toolpath& path, const std::function<int32_t(int tool)>& tool_id) {
  std::vector<ToolpathRun> runs;
  const std::vector<ToolpathPoint>& points = path.points();
  for (size_t k = 0; k < points.size(); ++k) {
    const ToolpathPoint& p = points[k];
    const int32_t tool = tool_id(p.tool);
    const bool rapid = p.rapid || path.feed(static_cast<int64_t>(k)) == 0;
    if (runs.empty() || p.starts_run || runs.back().tool_id != tool ||
        runs.back().rapid != rapid) {
      ToolpathRun r;
      r.begin = static_cast<int64_t>(k);
      r.tool_id = tool;
      r.rapid = rapid;
      r.reposition = p.starts_run;
      runs.push_back(r);
    }
    runs.back().end = static_cast<int64_t>(k) + 1;
  }
  return runs;
}

void Toolpath::Reserve(int64_t points, int64_t expected) {
  points_.reserve(points);
  feeds_.reserve(points);
  const int64_t n = std::clamp<int64_t>(expected, 0, points);
  // Past what is held already; reserve() may have moved the storage.
  const size_t held = points_.size();
  if (static_cast<size_t>(n) <= held) return;
  ThreadPool& pool = ThreadPool::Default();
  PopulatePages(points_.data() + held, (n - held) * sizeof(ToolpathPoint),
                pool);
  PopulatePages(feeds_.data() + held, (n - held) * sizeof(float), pool);
}

void Toolpath::Append(const ToolpathPoint& p) { Append(p, -1); }

void Toolpath::Append(const ToolpathPoint& p, float feed) {
  ToolpathPoint pt = p;
  if (points_.empty()) {
    pt.starts_run = true;
    x_bounds_ = {pt.position.x, pt.position.x};
    y_bounds_ = {pt.position.y, pt.position.y};
    z_bounds_ = {pt.position.z, pt.position.z};
  } else {
    const Vec3& last = points_.back().position;
    if (!pt.starts_run && last.x == pt.position.x && last.y == pt.position.y &&
        last.z == pt.position.z) {
      return;
    }
    x_bounds_.lo = std::min(x_bounds_.lo, pt.position.x);
    x_bounds_.hi = std::max(x_bounds_.hi, pt.position.x);
    y_bounds_.lo = std::min(y_bounds_.lo, pt.position.y);
    y_bounds_.hi = std::max(y_bounds_.hi, pt.position.y);
    z_bounds_.lo = std::min(z_bounds_.lo, pt.position.z);
    z_bounds_.hi = std::max(z_bounds_.hi, pt.position.z);
  }
  if (pt.starts_run) ++runs_;
  if (points_.size() == points_.capacity()) {
    // Grow by a quarter, not twice: then Trim() keeps what it gets instead
    // of copying millions of points once more.
    points_.reserve(points_.size() + std::max<size_t>(points_.size() / 4, 1024));
  }
  points_.push_back(pt);
  feeds_.push_back(feed);
}

void Toolpath::AppendProgram(const Toolpath& next) {
  points_.reserve(points_.size() + next.points_.size());
  for (size_t k = 0; k < next.points_.size(); ++k) {
    ToolpathPoint p = next.points_[k];
    if (k == 0) p.starts_run = true;
    Append(p, next.feeds_[k]);
  }
  source_lines_ += next.source_lines_;
  blocks_executed_ += next.blocks_executed_;
  for (const auto& [word, n] : next.ignored_) ignored_[word] += n;
  notes_.insert(notes_.end(), next.notes_.begin(), next.notes_.end());
  tool_selected_.insert(next.tool_selected_.begin(), next.tool_selected_.end());
  dropped_moves_ += next.dropped_moves_;
  for (const DroppedMove& d : next.first_dropped_) {
    if (first_dropped_.size() < kFirstDropped) first_dropped_.push_back(d);
  }
}

void Toolpath::CountIgnored(const std::string& word, int64_t n) {
  ignored_[word] += n;
}

void Toolpath::AddDropped(int32_t line, unsigned missing_axes_mask) {
  ++dropped_moves_;
  if (first_dropped_.size() >= kFirstDropped) return;
  DroppedMove d;
  d.line = line;
  int n = 0;
  for (int a = 0; a < 3; ++a) {
    if (missing_axes_mask & (1u << a)) d.missing[n++] = "XYZ"[a];
  }
  first_dropped_.push_back(d);
}

std::string Toolpath::DroppedSummary() const {
  if (dropped_moves_ == 0) return "";
  std::string out = absl::StrCat(
      "dropped ", dropped_moves_, dropped_moves_ == 1 ? " feed move" : " feed moves",
      " with an unknown start or end (not simulated): ");
  for (size_t i = 0; i < first_dropped_.size(); ++i) {
    absl::StrAppend(&out, i == 0 ? "" : ", ", "line ", first_dropped_[i].line,
                    " (", first_dropped_[i].missing, " unknown)");
  }
  if (dropped_moves_ > static_cast<int64_t>(first_dropped_.size())) {
    absl::StrAppend(&out, ", ...");
  }
  return out;
}

int64_t Toolpath::ignored_total() const {
  int64_t total = 0;
  for (const auto& [word, n] : ignored_) total += n;
  return total;
}

std::optional<int32_t> Toolpath::ToolSelectedAt(int n) const {
  auto it = tool_selected_.find(n);
  if (it == tool_selected_.end()) return std::nullopt;
  return it->second;
}

std::vector<int> Toolpath::Tools() const {
  std::vector<int> tools;
  int last = -1;
  for (const ToolpathPoint& p : points_) {
    if (p.tool == last) continue;
    last = p.tool;
    if (std::find(tools.begin(), tools.end(), last) == tools.end()) {
      tools.push_back(last);
    }
  }
  return tools;
}

std::string Toolpath::IgnoredSummary() const {
  if (ignored_.empty()) return "";
  std::vector<WordKey> keys;
  for (const auto& [word, n] : ignored_) keys.push_back(KeyOf(word));
  std::sort(keys.begin(), keys.end(), [](const WordKey& a, const WordKey& b) {
    if (a.rank != b.rank) return a.rank < b.rank;
    if (a.number != b.number) return a.number < b.number;
    return *a.word < *b.word;
  });
  const int64_t total = ignored_total();
  std::string out =
      absl::StrCat("ignored ", total, total == 1 ? " word" : " words",
                   " that don't move the tool:");
  for (size_t i = 0; i < keys.size(); ++i) {
    absl::StrAppend(&out, i == 0 ? " " : ", ", *keys[i].word, " x",
                    ignored_.at(*keys[i].word));
  }
  return out;
}

absl::StatusOr<Toolpath> ParseXyz(std::string_view text, int64_t max_points) {
  static constexpr char kAxis[3] = {'x', 'y', 'z'};
  Toolpath path;
  // A point per line at most.
  const int64_t lines = std::min<int64_t>(
      std::count(text.begin(), text.end(), '\n') + 1, max_points);
  path.Reserve(lines, lines);
  const char* p = SkipBom(text.data(), text.data() + text.size());
  const char* const end = text.data() + text.size();
  int64_t line = 0;
  bool first_content = true;  // the line that may be a header
  while (p < end) {
    ++line;
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
    if (eol == nullptr) eol = end;
    const char* s = SkipBlanks(p, eol);
    p = eol < end ? eol + 1 : end;
    if (s == eol || *s == '#') continue;
    if (line > std::numeric_limits<int32_t>::max()) {
      return LineError(line, "too many lines");
    }
    double v[3];
    bool header = false;
    for (int k = 0; k < 3; ++k) {
      if (k > 0) {
        // Blanks and/or one comma between values.
        const char* before = s;
        s = SkipBlanks(s, eol);
        if (s < eol && *s == ',') s = SkipBlanks(s + 1, eol);
        if (s == before || s == eol || *s == '#') {
          return LineError(line, absl::StrCat("expected 3 values (x y z), "
                                              "got ",
                                              k));
        }
      }
      const char* t = s < eol && *s == '+' && s + 1 < eol && s[1] != '-'
                          ? s + 1
                          : s;  // from_chars rejects a leading '+'
      const auto r = std::from_chars(t, eol, v[k]);
      if (r.ec == std::errc::result_out_of_range) {
        return LineError(
            line, absl::StrCat(std::string(1, kAxis[k]), " is out of range"));
      }
      if (r.ec != std::errc()) {
        if (k == 0 && first_content) {
          header = true;
          break;
        }
        return LineError(
            line, absl::StrCat(std::string(1, kAxis[k]), " is not a number at ",
                               CharName(*s)));
      }
      if (!(std::fabs(v[k]) <= kMaxCoordinateMm)) {
        return LineError(line, absl::StrCat(std::string(1, kAxis[k]), " = ",
                                            v[k], " is out of range"));
      }
      s = r.ptr;
    }
    first_content = false;
    if (header) continue;
    s = SkipBlanks(s, eol);
    if (s < eol && *s == ',') s = SkipBlanks(s + 1, eol);
    if (s < eol && *s != '#') {
      return LineError(line, absl::StrCat("unexpected ", CharName(*s),
                                          " after x y z (3 values per "
                                          "line)"));
    }
    if (path.point_count() >= max_points) {
      return LineError(
          line, absl::StrCat("more than ", max_points, " points (max_points)"));
    }
    ToolpathPoint pt;
    pt.position = {v[0], v[1], v[2]};
    pt.line = static_cast<int32_t>(line);
    path.Append(pt);
  }
  path.set_source_lines(line);
  path.Trim();
  return path;
}

absl::StatusOr<ToolpathFormat> ToolpathFormatForPath(std::string_view path) {
  const size_t slash = path.find_last_of("/\\");
  const std::string_view name =
      slash == std::string_view::npos ? path : path.substr(slash + 1);
  const size_t dot = name.rfind('.');
  std::string ext;
  if (dot != std::string_view::npos) {
    for (char c : name.substr(dot + 1)) {
      ext += static_cast<char>(c >= 'A' && c <= 'Z' ? c + ('a' - 'A') : c);
    }
  }
  for (const char* g : {"nc", "ngc", "gcode", "tap", "cnc"}) {
    if (ext == g) return ToolpathFormat::kGcode;
  }
  for (const char* x : {"csv", "xyz", "txt"}) {
    if (ext == x) return ToolpathFormat::kXyz;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "unknown toolpath file extension '", ext,
      "': G-code is .nc .ngc .gcode .tap .cnc; tip positions are .csv .xyz "
      ".txt"));
}

absl::StatusOr<Toolpath> ParseToolpath(std::string_view text,
                                       ToolpathFormat format,
                                       const GcodeOptions& options) {
  if (format == ToolpathFormat::kXyz) return ParseXyz(text, options.max_points);
  return ParseGcode(text, options);
}

Excursion FarthestOutside(const Toolpath& path, double x0, double y0,
                          double x1, double y1, double top) {
  Excursion e;
  const std::vector<ToolpathPoint>& pts = path.points();
  for (size_t i = 0; i < pts.size(); ++i) {
    const ToolpathPoint& p = pts[i];
    if (p.rapid || p.starts_run || !(p.position.z < top)) continue;
    const double dx = std::max({x0 - p.position.x, p.position.x - x1, 0.0});
    const double dy = std::max({y0 - p.position.y, p.position.y - y1, 0.0});
    const double d = std::hypot(dx, dy);
    if (d > e.distance) {
      e.distance = d;
      e.index = static_cast<int64_t>(i);
    }
  }
  return e;
}

ToolpathFormat DetectToolpathFormat(std::string_view text) {
  const char* p = SkipBom(text.data(), text.data() + text.size());
  const char* const end = text.data() + text.size();
  while (p < end) {
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
    if (eol == nullptr) eol = end;
    const char* q = SkipBlanks(p, eol);
    p = eol < end ? eol + 1 : end;
    // Blank lines, G-code comments and XYZ '#' comments (but "#1=..." and
    // "#<x>=..." are G-code parameter settings).
    if (q == eol || OnlyComments(q, eol)) continue;
    if (*q == '#') {
      const char* r = SkipBlanks(q + 1, eol);
      if (r < eol && (IsDigit(*r) || *r == '<' || *r == '[' || *r == '#')) {
        return ToolpathFormat::kGcode;
      }
      continue;
    }
    if (IsDigit(*q) || *q == '-' || *q == '+' || *q == '.') {
      return ToolpathFormat::kXyz;
    }
    // A header: only x, y, z (any case) between blanks and commas.
    bool header = true, letters = false;
    for (const char* r = q; r < eol && header; ++r) {
      const char c = Lower(*r);
      if (c == 'x' || c == 'y' || c == 'z') {
        letters = true;
      } else if (!(IsBlank(c) || c == ',' || c == ';')) {
        header = false;
      }
    }
    // "X Y Z" alone is not a G-code block (words need numbers).
    return header && letters ? ToolpathFormat::kXyz : ToolpathFormat::kGcode;
  }
  return ToolpathFormat::kGcode;
}

absl::StatusOr<Toolpath> ReadToolpathFile(const std::string& path,
                                          const GcodeOptions& options,
                                          std::optional<ToolpathFormat> format,
                                          CanonSink* sink) {
  const auto prefixed = [&path](const absl::Status& st) {
    return absl::Status(st.code(), absl::StrCat(path, ": ", st.message()));
  };
  absl::StatusOr<std::string> data = ReadWholeFile(path);
  if (!data.ok()) return prefixed(data.status());
  GcodeOptions opt = options;
  if (opt.subroutine_dir.empty()) {
    const size_t slash = path.find_last_of('/');
    opt.subroutine_dir = slash == std::string::npos ? "." : path.substr(0, slash);
    // assign(1, '/'), not = "/": GCC 12 warns (-Wrestrict) on the latter
    // inlined here, a false positive (GCC bug 105329).
    if (opt.subroutine_dir.empty()) opt.subroutine_dir.assign(1, '/');
  }
  const ToolpathFormat f = format.value_or(DetectToolpathFormat(*data));
  absl::StatusOr<Toolpath> tp = f == ToolpathFormat::kGcode
                                    ? ParseGcode(*data, opt, sink)
                                    : ParseToolpath(*data, f, opt);
  if (!tp.ok()) return prefixed(tp.status());
  return tp;
}

}  // namespace swarf::gcode
