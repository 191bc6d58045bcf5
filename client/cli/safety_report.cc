#include "client/cli/safety_report.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "client/outputs/png_image.h"
#include "client/outputs/text.h"
#include "nlohmann/json.hpp"

namespace swarf::cli {

absl::StatusOr<SafetyOptions> ParseSafetyFlags(const Args& args) {
  SafetyOptions o;
  if (auto f = args.Get("floor")) {
    double z;
    if (!absl::SimpleAtod(*f, &z) || !std::isfinite(z)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--floor must be a height Z (mm), got \"", *f, "\""));
    }
    o.floor = z;
  }
  if (auto l = args.Get("limits")) {
    std::vector<std::string> parts = absl::StrSplit(*l, ',');
    std::array<double, 6> v{};
    bool ok = parts.size() == 6;
    for (size_t k = 0; ok && k < 6; ++k) {
      ok = absl::SimpleAtod(parts[k], &v[k]) && std::isfinite(v[k]);
    }
    if (!ok || !(v[0] < v[3] && v[1] < v[4] && v[2] < v[5])) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--limits must be x0,y0,z0,x1,y1,z1 (mm, each min below its max), "
          "got \"", *l, "\""));
    }
    o.limits = v;
  }
  if (auto r = args.Get("rapid-rate")) {
    if (!absl::SimpleAtod(*r, &o.rapid_rate) || !(o.rapid_rate > 0) ||
        !std::isfinite(o.rapid_rate)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--rapid-rate must be a speed > 0 (mm/min), got \"", *r, "\""));
    }
  }
  return o;
}

SafetyCollector::SafetyCollector(const gcode::Toolpath& path,
                                 const std::vector<int64_t>& file_starts,
                                 std::vector<std::string> files,
                                 std::map<int, ToolAssembly> assemblies,
                                 const SafetyOptions& options)
    : path_(path),
      file_starts_(file_starts),
      files_(std::move(files)),
      assemblies_(std::move(assemblies)),
      options_(options) {
  // Move ids as the session numbers them: every point but a run's first.
  const auto& points = path.points();
  for (size_t k = 0; k < points.size(); ++k) {
    if (k == 0 || points[k].starts_run) {
      run_starts_.push_back(static_cast<int64_t>(k) -
                            static_cast<int64_t>(run_starts_.size()));
    } else {
      ++move_count_;
    }
  }
  // The lines met again, and the program's time, in one pass over the moves.
  line_seen_.resize(std::max<size_t>(1, files_.size()));
  LineKey last{-1, -1};
  for (int64_t m = 0; m < move_count_; ++m) {
    const SafetyItem where = At(m);
    const LineKey key{where.file, where.line};
    const int64_t p = PointOf(m);
    load_total_ += Seconds(p, Length(p));
    if (key == last || key.first < 0 || key.second < 0) continue;
    last = key;
    if (static_cast<size_t>(key.first) >= line_seen_.size()) {
      line_seen_.resize(key.first + 1);
    }
    std::vector<uint8_t>& seen = line_seen_[key.first];
    if (static_cast<size_t>(key.second) >= seen.size()) {
      seen.resize(key.second + 1, 0);
    }
    seen[key.second] = std::min<uint8_t>(2, seen[key.second] + 1);
  }
  load_vol_.assign(kLoadPlotW, 0);
}

int64_t SafetyCollector::PointOf(int64_t move_id) const {
  return move_id + (std::upper_bound(run_starts_.begin(), run_starts_.end(),
                                     move_id) -
                    run_starts_.begin());
}

double SafetyCollector::Length(int64_t p) const {
  const auto& points = path_.points();
  const Vec3& a = points[p - 1].position;
  const Vec3& b = points[p].position;
  return std::sqrt((b.x - a.x) * (b.x - a.x) + (b.y - a.y) * (b.y - a.y) +
                   (b.z - a.z) * (b.z - a.z));
}

double SafetyCollector::Seconds(int64_t p, double len) const {
  const double feed = path_.feed(p);
  if (path_.points()[p].rapid || feed == 0) {
    return len / options_.rapid_rate * 60;
  }
  return feed > 0 ? len / feed * 60 : 0;
}

bool SafetyCollector::Repeated(const LineKey& key) const {
  if (key.first < 0 || static_cast<size_t>(key.first) >= line_seen_.size()) {
    return true;
  }
  const std::vector<uint8_t>& seen = line_seen_[key.first];
  return key.second < 0 || static_cast<size_t>(key.second) >= seen.size() ||
         seen[key.second] > 1;
}

void SafetyCollector::TopLines::Offer(const LineKey& key, const Amount& a) {
  constexpr size_t kTop = 10;
  const auto better = [&](const std::pair<LineKey, Amount>& x,
                          const std::pair<LineKey, Amount>& y) {
    if (x.second.*by != y.second.*by) return x.second.*by > y.second.*by;
    return x.first < y.first;
  };
  const std::pair<LineKey, Amount> e{key, a};
  if (best.size() == kTop && !better(e, best.back())) return;
  best.insert(std::upper_bound(best.begin(), best.end(), e, better), e);
  if (best.size() > kTop) best.pop_back();
}

void SafetyCollector::Flush(const Group& g, TopLines* lines, TopLines* air) {
  if (g.has_line) lines->Offer(g.key, g.line);
  if (g.has_air) air->Offer(g.key, g.air);
}

SafetyItem SafetyCollector::At(int64_t move_id) const {
  SafetyItem it;
  it.move_id = move_id;
  if (move_id < 0 || move_id >= move_count_) return it;
  const int64_t p = PointOf(move_id);
  it.line = path_.points()[p].line;
  const auto f = std::upper_bound(file_starts_.begin(), file_starts_.end(), p);
  it.file = std::max<int32_t>(0, static_cast<int32_t>(f - file_starts_.begin()) - 1);
  return it;
}

void SafetyCollector::Add(int kind, const SafetyItem& item) {
  ++counts_[kind];
  if (items_[kind].size() < kMaxItems) {
    items_[kind].push_back(item);
    if (follow_) new_.items.emplace_back(kind, item);
  }
}

SafetyCollector::NewFindings SafetyCollector::TakeNew() {
  NewFindings out;
  std::swap(out, new_);
  return out;
}

void SafetyCollector::OnAck(const pb::Ack& ack, int64_t first_move_id) {
  for (const pb::SafetyEvent& e : ack.safety()) {
    int kind;
    switch (e.kind()) {
      case pb::SafetyEvent::RAPID_CUT: kind = 0; break;
      case pb::SafetyEvent::SHANK_CONTACT: kind = 1; break;
      case pb::SafetyEvent::HOLDER_CONTACT: kind = 2; break;
      case pb::SafetyEvent::PLUNGE: kind = 3; break;
      default: continue;
    }
    SafetyItem it = At(e.move_id());
    it.x = e.x();
    it.y = e.y();
    it.z = e.z();
    it.depth = e.depth();
    it.volume_mm3 = e.volume_mm3();
    Add(kind, it);
  }
  const auto& points = path_.points();
  for (int k = 0; k < ack.removed_mm3_size(); ++k) {
    const int64_t id = first_move_id + k;
    if (id < 0 || id >= move_count_) break;
    const int64_t p = PointOf(id);
    const gcode::ToolpathPoint& to = points[p];
    const Vec3& a = points[p - 1].position;
    const Vec3& b = to.position;
    const double len = Length(p);
    const double v = ack.removed_mm3(k);
    const SafetyItem where = At(id);
    const LineKey key{where.file, where.line};
    // A line's moves sum in order either way: in its group, or in the map
    // for a line the program comes back to.
    const bool repeated = Repeated(key);
    if (!repeated && key != group_.key) {
      Flush(group_, &top_lines_, &top_air_);
      group_ = Group();
      group_.key = key;
    }
    removed_ += v;
    // The time at the programmed feed; rapids and feeds of F0 at the rapid
    // rate; none where the feed is not known (x,y,z files).
    const double feed = path_.feed(p);
    const double seconds = Seconds(p, len);
    if (to.rapid || feed == 0) {
      rapid_mm_ += len;
      rapid_s_ += seconds;
      if (!to.rapid) ++f0_moves_;
    } else {
      feed_mm_ += len;
      if (!(feed > 0)) unknown_feed_mm_ += len;
      if (v > 0) {
        ++cutting_moves_;
        cutting_s_ += seconds;
      } else {
        ++air_moves_;
        if (follow_ && air_taken_ < kMaxAirSegments) {
          new_.air.emplace_back(a, b);
          ++air_taken_;
        }
        air_mm_ += len;
        air_s_ += seconds;
        Amount& a = repeated ? air_by_line_[key] : group_.air;
        group_.has_air |= !repeated;
        a.mm += len;
        a.seconds += seconds;
      }
    }
    Amount& t = by_tool_[to.tool];
    t.volume += v;
    t.seconds += seconds;
    if (v > 0 || seconds > 0) {
      Amount& l = repeated ? by_line_[key] : group_.line;
      group_.has_line |= !repeated;
      l.volume += v;
      l.seconds += seconds;
    }
    // load.png's columns, as the moves come.
    if (load_moves_++ == 0) load_tool_ = to.tool;
    if (to.tool != load_tool_) {
      load_changes_.push_back({load_t_, to.tool});
      load_tool_ = to.tool;
    }
    if (load_total_ > 0 && seconds > 0 && v > 0) {
      const double dt = load_total_ / kLoadPlotW;
      const double a = load_t_ / dt, b = (load_t_ + seconds) / dt;
      for (int c = std::max(0, static_cast<int>(a));
           c < kLoadPlotW && c < static_cast<int>(std::ceil(b)); ++c) {
        const double overlap =
            std::min<double>(b, c + 1) - std::max<double>(a, c);
        if (overlap > 0) load_vol_[c] += v * overlap / (b - a);
      }
    }
    load_t_ += seconds;
    if (options_.floor && std::min(a.z, b.z) < *options_.floor) {
      SafetyItem it = where;
      const Vec3& low = a.z < b.z ? a : b;
      it.x = low.x;
      it.y = low.y;
      it.z = low.z;
      it.depth = *options_.floor - low.z;
      it.volume_mm3 = v;
      Add(4, it);
    }
    if (options_.limits) {
      const auto& l = *options_.limits;
      const double out = std::max(
          {l[0] - b.x, b.x - l[3], l[1] - b.y, b.y - l[4], l[2] - b.z, b.z - l[5]});
      if (out > 0) {
        SafetyItem it = where;
        it.x = b.x;
        it.y = b.y;
        it.z = b.z;
        it.depth = out;
        it.volume_mm3 = v;
        Add(5, it);
      }
    }
  }
}

int64_t SafetyCollector::total() const {
  int64_t n = 0;
  for (int64_t c : counts_) n += c;
  return n;
}

namespace {
const char* const kWords[SafetyCollector::kKinds] = {
    "rapid moves cut material", "the shank met material above the flutes",
    "the holder met material", "plunges of a tool not cutting at its centre",
    "moves went below the floor", "moves went outside the machine's limits"};
const char* const kDepthWords[SafetyCollector::kKinds] = {
    "deep", "above the flutes", "above the holder's face", "deep",
    "below the floor", "outside"};
}  // namespace

std::vector<std::string> SafetyCollector::Warnings() const {
  std::vector<std::string> out;
  std::vector<std::string> bare;
  for (const auto& [n, a] : assemblies_) {
    if (a.flute_length <= 0 && a.holder_diameter <= 0) bare.push_back(absl::StrCat("T", n));
  }
  if (!bare.empty()) {
    out.push_back(absl::StrCat(
        "note: ", absl::StrJoin(bare, ", "),
        bare.size() == 1 ? " has" : " have",
        " no flute length or holder: no shank or holder check (give "
        "--tool ...,flute=L,holder=D,stickout=S or the table's comment keys)"));
  }
  for (int k = 0; k < kKinds; ++k) {
    if (counts_[k] == 0) continue;
    const SafetyItem& f = items_[k].front();
    const std::string file =
        f.file < static_cast<int32_t>(files_.size()) ? files_[f.file] : "";
    out.push_back(absl::StrFormat(
        "warning: %s (%s): %d; the first: %s line %d, %.4g mm %s at "
        "(%.3f, %.3f, %.3f), %.4g mm^3",
        kWords[k], kKindNames[k], counts_[k], file, f.line, f.depth,
        kDepthWords[k], f.x, f.y, f.z, f.volume_mm3));
  }
  return out;
}

std::string SafetyCollector::SafetyJson() const {
  using Json = nlohmann::ordered_json;
  Json j = Json::object();
  for (int k = 0; k < kKinds; ++k) {
    Json a = Json::array();
    for (const SafetyItem& f : items_[k]) {
      a.push_back({{"file", f.file < static_cast<int32_t>(files_.size())
                                ? files_[f.file]
                                : std::string()},
                   {"line", f.line},
                   {"move", f.move_id},
                   {"x", f.x},
                   {"y", f.y},
                   {"z", f.z},
                   {"depth", f.depth},
                   {"volume_mm3", f.volume_mm3}});
    }
    j[kKindNames[k]] = a;
  }
  Json counts = Json::object();
  for (int k = 0; k < kKinds; ++k) counts[kKindNames[k]] = counts_[k];
  j["counts"] = counts;
  j["listed_at_most"] = kMaxItems;
  Json unchecked = Json::array();
  for (const auto& [n, a] : assemblies_) {
    if (a.flute_length <= 0 && a.holder_diameter <= 0) unchecked.push_back(n);
  }
  j["tools_without_assembly"] = unchecked;
  if (options_.floor) j["floor"] = *options_.floor;
  if (options_.limits) j["limits"] = *options_.limits;
  j["ok"] = total() == 0;
  return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}

std::string SafetyCollector::ProcessJson() const {
  using Json = nlohmann::ordered_json;
  // The ten largest by their amount (ties by file and line), each with its
  // volume or length and its time: the lines complete so far, the one still
  // open and those the program comes back to.
  TopLines lines = top_lines_, air_lines = top_air_;
  Flush(group_, &lines, &air_lines);
  for (const auto& [key, x] : by_line_) lines.Offer(key, x);
  for (const auto& [key, x] : air_by_line_) air_lines.Offer(key, x);
  auto top = [&](const TopLines& t, bool air) {
    Json a = Json::array();
    for (const auto& [key, x] : t.best) {
      const auto [file, line] = key;
      Json e = {{"file", file < static_cast<int32_t>(files_.size())
                             ? files_[file]
                             : std::string()},
                {"line", line}};
      if (air) {
        e["mm"] = x.mm;
      } else {
        e["volume_mm3"] = x.volume;
      }
      e["time_s"] = x.seconds;
      a.push_back(e);
    }
    return a;
  };
  Json by_tool = Json::object();
  for (const auto& [t, a] : by_tool_) {
    by_tool[absl::StrCat(t)] = {{"volume_mm3", a.volume}, {"time_s", a.seconds}};
  }
  Json j = {
      {"cycle_time_s", rapid_s_ + cutting_s_ + air_s_},
      {"cutting_s", cutting_s_},
      {"air_s", air_s_},
      {"rapid_s", rapid_s_},
      {"removed_mm3", removed_},
      {"by_tool", by_tool},
      {"lines", top(lines, false)},
      {"air_lines", top(air_lines, true)},
      {"rapid_mm", rapid_mm_},
      {"rapid_rate_mm_min", options_.rapid_rate},
      {"f0_moves", f0_moves_},
      {"feed_mm", feed_mm_},
      {"feed_unknown_mm", unknown_feed_mm_},
      {"cutting_moves", cutting_moves_},
      {"air_moves", air_moves_},
      {"air_mm", air_mm_},
  };
  return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}

absl::Status SafetyCollector::WriteLoadPng(const std::string& path) const {
  const double total = load_total_;
  if (!(total > 0) || load_moves_ == 0) {
    return absl::FailedPreconditionError(
        "load.png: the program's time is not known (no feeds)");
  }
  constexpr int kW = kLoadW, kH = 360, kLeft = kLoadLeft, kTop = 30,
                kBottom = 40;
  const int plot_w = kLoadPlotW, plot_h = kH - kTop - kBottom;
  // Volume per column of equal time, spread over the moves' durations
  // (OnAck).
  const std::vector<double>& vol = load_vol_;
  const double dt = total / plot_w;
  const std::vector<std::pair<double, int>>& changes = load_changes_;
  double peak = 0;
  for (double v : vol) peak = std::max(peak, v / dt * 60);  // mm^3/min
  Image img(kW, kH, 3, Rgb{255, 255, 255});
  const Rgb axis{60, 60, 60}, bar{40, 110, 190}, change{200, 60, 40};
  for (int c = 0; c < plot_w; ++c) {
    const double rate = vol[c] / dt * 60;
    const int h = peak > 0 ? static_cast<int>(std::lround(rate / peak * plot_h)) : 0;
    for (int y = 0; y < h; ++y) img.Set(kLeft + c, kTop + plot_h - 1 - y, bar);
  }
  for (int x = kLeft; x < kLeft + plot_w; ++x) img.Set(x, kTop + plot_h, axis);
  for (int y = kTop; y <= kTop + plot_h; ++y) img.Set(kLeft - 1, y, axis);
  for (const auto& [when, n] : changes) {
    const int x = kLeft + std::min(plot_w - 1, static_cast<int>(when / dt));
    for (int y = kTop; y < kTop + plot_h; y += 2) img.Set(x, y, change);
    DrawText(img, x + 2, kTop + 2, absl::StrCat("T", n), change, 1);
  }
  DrawText(img, kLeft, 8,
           absl::StrFormat("removal rate (mm3/min) over program time: peak "
                           "%.4g mm3/min, cycle %.1f s",
                           peak, total),
           axis, 1);
  DrawText(img, 4, kTop, absl::StrFormat("%.3g", peak), axis, 1);
  DrawText(img, 4, kTop + plot_h - 8, "0", axis, 1);
  DrawText(img, kLeft, kTop + plot_h + 6, "0 s", axis, 1);
  const std::string end = absl::StrFormat("%.1f s", total);
  DrawText(img, kLeft + plot_w - TextWidth(end, 1), kTop + plot_h + 6, end,
           axis, 1);
  return WritePng(img, path);
}

}  // namespace swarf::cli
