#include "client/cli/tool_table.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <set>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "nlohmann/json.hpp"

namespace swarf::cli {
namespace {

constexpr double kRadToDeg = 180 / std::numbers::pi;

absl::Status Bad(absl::string_view where, absl::string_view what) {
  return absl::InvalidArgumentError(absl::StrCat(where, ": ", what));
}

// The --tool shape for a name or alias (lowercase), "" when none. The same
// words name shapes in LinuxCNC tool table comments.
std::string ShapeOf(absl::string_view word) {
  static const std::map<absl::string_view, absl::string_view> kAliases = {
      {"ball", "ball"},       {"ballnose", "ball"},   {"ball-nose", "ball"},
      {"flat", "flat"},       {"endmill", "flat"},    {"end-mill", "flat"},
      {"bull", "bull"},       {"bullnose", "bull"},   {"bull-nose", "bull"},
      {"vbit", "vbit"},       {"v-bit", "vbit"},      {"cone", "vbit"},
      {"taper", "taper"},     {"tapered", "taper"},
  };
  auto it = kAliases.find(word);
  return it == kAliases.end() ? "" : std::string(it->second);
}

// What each shape takes: required keys, then optional ones.
struct ShapeKeys {
  std::vector<absl::string_view> required, optional;
  absl::string_view usage;
};
const ShapeKeys* KeysOf(absl::string_view shape) {
  static const std::map<absl::string_view, ShapeKeys> kKeys = {
      {"ball", {{}, {"d", "r"}, "ball:d=DIAMETER or ball:r=RADIUS"}},
      {"flat", {{"d"}, {}, "flat:d=DIAMETER"}},
      {"bull", {{"d", "r"}, {}, "bull:d=DIAMETER,r=CORNER_RADIUS"}},
      {"vbit",
       {{"d", "angle"}, {"tip"}, "vbit:d=DIAMETER,angle=INCLUDED[,tip=TIP_D]"}},
      {"taper",
       {{"d", "tip", "angle"}, {}, "taper:d=DIAMETER,tip=TIP_D,angle=INCLUDED"}},
  };
  auto it = kKeys.find(shape);
  return it == kKeys.end() ? nullptr : &it->second;
}

std::string Format(double v) { return absl::StrCat(v); }

}  // namespace

absl::Status TakeAssemblyKeys(
    std::vector<std::pair<std::string, std::string>>* keys, ToolAssembly* out,
    absl::string_view where) {
  std::set<std::string> seen;
  std::vector<std::pair<std::string, std::string>> rest;
  for (auto& [key, text] : *keys) {
    double* field = key == "flute"      ? &out->flute_length
                    : key == "shank"    ? &out->shank_diameter
                    : key == "holder"   ? &out->holder_diameter
                    : key == "stickout" ? &out->stickout
                                        : nullptr;
    if (field == nullptr && key != "center") {
      rest.emplace_back(std::move(key), std::move(text));
      continue;
    }
    if (!seen.insert(key).second) return Bad(where, absl::StrCat(key, " is given twice"));
    double x;
    const bool number = absl::SimpleAtod(text, &x) && std::isfinite(x);
    if (key == "center") {
      if (!number || (x != 0 && x != 1)) {
        return Bad(where, absl::StrCat("center must be 0 or 1 (does the tool cut "
                                       "at its centre), got \"", text, "\""));
      }
      out->center_cutting = x == 1;
      continue;
    }
    if (!number || !(x > 0) || x > 2 * kMaxRadius) {
      return Bad(where, absl::StrCat(key, " must be a length in (0, ",
                                     Format(2 * kMaxRadius), "] mm, got \"",
                                     text, "\""));
    }
    *field = x;
  }
  if ((out->holder_diameter > 0) != (out->stickout > 0)) {
    return Bad(where, "holder= and stickout= go together (the holder's "
                      "diameter and its face's height above the tip)");
  }
  *keys = std::move(rest);
  return absl::OkStatus();
}

std::string AssemblySummary(const ToolAssembly& a) {
  std::vector<std::string> parts;
  if (a.flute_length > 0) parts.push_back(absl::StrCat("flute=", Format(a.flute_length)));
  if (a.shank_diameter > 0) parts.push_back(absl::StrCat("shank=", Format(a.shank_diameter)));
  if (a.holder_diameter > 0) {
    parts.push_back(absl::StrCat("holder=", Format(a.holder_diameter)));
    parts.push_back(absl::StrCat("stickout=", Format(a.stickout)));
  }
  if (!a.center_cutting) parts.push_back("center=0");
  return absl::StrJoin(parts, " ");
}

absl::StatusOr<Cutter> CutterFromKeys(
    absl::string_view shape_name,
    const std::vector<std::pair<std::string, std::string>>& keys,
    absl::string_view where) {
  const std::string shape = ShapeOf(absl::AsciiStrToLower(shape_name));
  const ShapeKeys* spec = KeysOf(shape);
  if (spec == nullptr) {
    return Bad(where, absl::StrCat("unknown shape \"", shape_name,
                                   "\" (ball, flat, bull, vbit or taper)"));
  }
  std::map<std::string, double> v;
  for (const auto& [key, text] : keys) {
    const bool known =
        std::count(spec->required.begin(), spec->required.end(), key) +
            std::count(spec->optional.begin(), spec->optional.end(), key) >
        0;
    if (!known) {
      return Bad(where, absl::StrCat("unknown key \"", key, "\" for ", shape,
                                     " (", spec->usage, ")"));
    }
    if (v.count(key)) return Bad(where, absl::StrCat(key, " is given twice"));
    double x;
    if (!absl::SimpleAtod(text, &x) || !std::isfinite(x)) {
      return Bad(where, absl::StrCat(key, " must be a number, got \"", text,
                                     "\""));
    }
    v[key] = x;
  }
  for (absl::string_view key : spec->required) {
    if (!v.count(std::string(key))) {
      return Bad(where, absl::StrCat("missing ", key, "= (", spec->usage, ")"));
    }
  }
  if (shape == "ball" && v.count("d") == v.count("r")) {
    return Bad(where, absl::StrCat("give one of d= and r= (", spec->usage, ")"));
  }
  const double d = v.count("d") ? v["d"] : 2 * v["r"];
  // In the user's terms: diameters (mm) and included angles (degrees).
  struct Range {
    absl::string_view shape, key;
    double lo, hi;
    bool lo_open, hi_open;
    absl::string_view unit;
  };
  const Range ranges[] = {
      {"", "d", 2 * kMinRadius, 2 * kMaxRadius, false, false, "mm"},
      {"ball", "r", kMinRadius, kMaxRadius, false, false, "mm"},
      {"bull", "r", 0, d / 2, false, false, "mm (up to d/2)"},
      {"", "angle", 0, 180, true, true, "degrees (the included angle)"},
      {"vbit", "tip", 0, d, false, false, "mm (a diameter, up to d)"},
      {"taper", "tip", 0, d, true, false, "mm (a diameter, up to d)"},
  };
  for (const Range& r : ranges) {
    auto it = v.find(std::string(r.key));
    if ((!r.shape.empty() && r.shape != shape) || it == v.end()) continue;
    const double x = it->second;
    if ((r.lo_open ? x > r.lo : x >= r.lo) &&
        (r.hi_open ? x < r.hi : x <= r.hi)) {
      continue;
    }
    return Bad(where, absl::StrCat(r.key, " must be in ", r.lo_open ? "(" : "[",
                                   Format(r.lo), ", ", Format(r.hi),
                                   r.hi_open ? ")" : "]", " ", r.unit,
                                   ", got ", Format(x)));
  }
  Cutter c;
  if (shape == "ball") {
    c = Cutter::Ball(d / 2);
  } else if (shape == "flat") {
    c = Cutter::Flat(d / 2);
  } else if (shape == "bull") {
    c = Cutter::BullNose(d / 2, v["r"]);
  } else if (shape == "vbit") {
    c = Cutter::Cone(d / 2, v["angle"] / 2, v.count("tip") ? v["tip"] / 2 : 0);
  } else {
    c = Cutter::TaperedBall(d / 2, v["tip"] / 2, v["angle"] / 2);
  }
  // The one validation of a cutter; the checks above only name the keys.
  if (absl::Status valid = ValidateCutter(c, std::string(where)); !valid.ok()) return valid;
  return c;
}

absl::StatusOr<ToolOption> ParseToolOption(absl::string_view value) {
  const std::string where = absl::StrCat("--tool \"", value, "\"");
  ToolOption out;
  absl::string_view spec = value;
  const size_t eq = spec.find('='), colon = spec.find(':');
  if (eq != absl::string_view::npos &&
      (colon == absl::string_view::npos || eq < colon)) {
    absl::string_view number = spec.substr(0, eq);
    if (!absl::ConsumePrefix(&number, "T")) absl::ConsumePrefix(&number, "t");
    int n;
    if (!absl::SimpleAtoi(number, &n) || n < 0 || n > 65535) {
      return Bad(where, absl::StrCat("bad tool number \"", spec.substr(0, eq),
                                     "\" (T0-T65535)"));
    }
    out.number = n;
    spec = spec.substr(eq + 1);
  }
  const size_t sep = spec.find(':');
  if (sep == absl::string_view::npos) {
    return Bad(where,
               "expected SHAPE:KEY=VALUE,... e.g. ball:d=6, flat:d=6, "
               "bull:d=6,r=1, vbit:d=6,angle=90, taper:d=6,tip=1,angle=10");
  }
  std::vector<std::pair<std::string, std::string>> keys;
  for (absl::string_view kv :
       absl::StrSplit(spec.substr(sep + 1), ',', absl::SkipEmpty())) {
    const size_t e = kv.find('=');
    if (e == absl::string_view::npos) {
      return Bad(where, absl::StrCat("\"", kv, "\" is not KEY=VALUE"));
    }
    keys.emplace_back(absl::AsciiStrToLower(absl::StripAsciiWhitespace(kv.substr(0, e))),
                      std::string(absl::StripAsciiWhitespace(kv.substr(e + 1))));
  }
  if (absl::Status s = TakeAssemblyKeys(&keys, &out.assembly, where); !s.ok()) {
    return s;
  }
  auto c = CutterFromKeys(spec.substr(0, sep), keys, where);
  if (!c.ok()) return c.status();
  out.cutter = *c;
  return out;
}

std::string CutterSummary(const Cutter& c) {
  const std::string d = absl::StrCat("d=", Format(2 * c.radius));
  switch (c.kind) {
    case CutterKind::kBall:
      return absl::StrCat("ball ", d);
    case CutterKind::kFlat:
      return absl::StrCat("flat ", d);
    case CutterKind::kBullNose:
      return absl::StrCat("bull ", d, " r=", Format(c.corner_radius));
    case CutterKind::kCone: {
      std::string s = absl::StrCat("vbit ", d, " angle=",
                                   Format(2 * c.half_angle_deg));
      if (c.tip_radius > 0) absl::StrAppend(&s, " tip=", Format(2 * c.tip_radius));
      return s;
    }
    case CutterKind::kTaperedBall:
      return absl::StrCat("taper ", d, " tip=", Format(2 * c.tip_radius),
                          " angle=", Format(2 * c.half_angle_deg));
  }
  return CutterToString(c);
}

// ------------------------------------------------------------ LinuxCNC .tbl

namespace {

// The cutter a .tbl line describes: D and the shape in its comment.
// The assembly keys (flute=15 ...) anywhere in the comment go to
// `assembly`.
absl::StatusOr<Cutter> TableLineCutter(std::optional<double> diameter,
                                       absl::string_view comment,
                                       absl::string_view where,
                                       ToolAssembly* assembly) {
  std::vector<std::string> words = absl::StrSplit(
      absl::AsciiStrToLower(comment), absl::ByAnyChar(" \t,"), absl::SkipEmpty());
  {
    std::vector<std::pair<std::string, std::string>> parts;
    std::vector<std::string> others;
    for (const std::string& w : words) {
      const size_t e = w.find('=');
      const std::string key = w.substr(0, e);
      if (e != std::string::npos &&
          (key == "flute" || key == "shank" || key == "holder" ||
           key == "stickout" || key == "center")) {
        parts.emplace_back(key, w.substr(e + 1));
      } else {
        others.push_back(w);
      }
    }
    if (absl::Status s = TakeAssemblyKeys(&parts, assembly, where); !s.ok()) return s;
    words = std::move(others);
  }
  std::string shape = "flat";
  std::vector<std::pair<std::string, std::string>> keys;
  if (diameter.has_value()) keys.emplace_back("d", absl::StrFormat("%.17g", *diameter));
  for (size_t w = 0; w < words.size(); ++w) {
    const std::string s = ShapeOf(words[w]);
    if (s.empty()) continue;
    shape = s;
    for (size_t k = w + 1; k < words.size(); ++k) {
      const size_t e = words[k].find('=');
      if (e != std::string::npos) {
        keys.emplace_back(words[k].substr(0, e), words[k].substr(e + 1));
        continue;
      }
      // "vbit 90", "vbit 60deg": the included angle.
      absl::string_view bare = words[k];
      if (!absl::ConsumeSuffix(&bare, "deg")) {
        absl::ConsumeSuffix(&bare, "\xc2\xb0");  // a degree sign
      }
      double angle;
      if (s == "vbit" && k == w + 1 && absl::SimpleAtod(bare, &angle)) {
        keys.emplace_back("angle", std::string(bare));
      }
    }
    break;
  }
  if (!diameter.has_value() || !(*diameter > 0)) {
    return Bad(where, "the tool has no diameter (D)");
  }
  return CutterFromKeys(shape, keys, where);
}

}  // namespace

absl::StatusOr<ToolTable> ParseLinuxCncToolTable(absl::string_view text,
                                                 const std::string& file,
                                                 double inch_scale) {
  ToolTable table;
  table.file = file;
  int line_no = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_no;
    const std::string where = absl::StrCat(file, " line ", line_no);
    absl::string_view comment;
    if (const size_t semi = line.find(';'); semi != absl::string_view::npos) {
      comment = line.substr(semi + 1);
      line = line.substr(0, semi);
    }
    std::vector<absl::string_view> words =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (words.empty()) continue;
    std::optional<int> number;
    std::optional<double> diameter;
    std::set<char> seen;
    for (absl::string_view w : words) {
      const char letter = absl::ascii_toupper(w[0]);
      double x;
      if (absl::string_view("TPXYZABCUVWDIJQ").find(letter) ==
              absl::string_view::npos ||
          !absl::SimpleAtod(w.substr(1), &x) || !std::isfinite(x)) {
        return Bad(where, absl::StrCat("\"", w,
                                       "\" is not a tool table word (T, P, "
                                       "X Y Z A B C U V W, D, I J Q and a "
                                       "number)"));
      }
      if (!seen.insert(letter).second) {
        return Bad(where, absl::StrCat(std::string(1, letter), " is given twice"));
      }
      if (letter == 'T') {
        if (x != std::floor(x) || x < 0 || x > 65535) {
          return Bad(where, absl::StrCat("T must be a tool number 0-65535, got ",
                                         w.substr(1)));
        }
        number = static_cast<int>(x);
      } else if (letter == 'D') {
        diameter = x * inch_scale;
      }
    }
    if (!number.has_value()) return Bad(where, "no tool number (T)");
    if (table.tools.count(*number)) {
      return Bad(where, absl::StrCat("T", *number, " is given twice (also ",
                                     table.tools[*number].source, ")"));
    }
    const std::string source = absl::StrCat(where, " (T", *number, ")");
    TableTool tool;
    tool.cutter = TableLineCutter(diameter, comment, source, &tool.assembly);
    tool.source = where;
    table.tools[*number] = std::move(tool);
  }
  return table;
}

// ------------------------------------------------------------- CAMotics

namespace {

using Json = nlohmann::json;

absl::StatusOr<double> NumberAt(const Json& obj, const char* key,
                                double fallback, absl::string_view where) {
  auto it = obj.find(key);
  if (it == obj.end()) return fallback;
  if (!it->is_number() || !std::isfinite(it->get<double>())) {
    return Bad(where, absl::StrCat("\"", key, "\" must be a number"));
  }
  return it->get<double>();
}

// One CAMotics tool; its shape's error (e.g. a spheroid) as the cutter.
absl::StatusOr<TableTool> CamoticsTool(const Json& t, absl::string_view where) {
  if (!t.is_object()) return Bad(where, "must be an object");
  std::string units = "metric", shape = "cylindrical";
  for (auto [key, out] : {std::pair{"units", &units}, {"shape", &shape}}) {
    auto it = t.find(key);
    if (it == t.end()) continue;
    if (!it->is_string()) {
      return Bad(where, absl::StrCat("\"", key, "\" must be a string"));
    }
    *out = absl::AsciiStrToLower(it->get<std::string>());
  }
  if (units != "metric" && units != "imperial") {
    return Bad(where, absl::StrCat("\"units\" must be metric or imperial, got \"",
                                   units, "\""));
  }
  const double scale = units == "imperial" ? 25.4 : 1;
  // CAMotics' defaults for a tool without dimensions (mm).
  auto diameter = NumberAt(t, "diameter", 2 / scale, where);
  auto length = NumberAt(t, "length", 10 / scale, where);
  auto snub = NumberAt(t, "snub_diameter", 0, where);
  for (const auto* s : {&diameter, &length, &snub}) {
    if (!s->ok()) return s->status();
  }
  const double d = *diameter * scale, len = *length * scale, sd = *snub * scale;
  TableTool out;
  out.source = std::string(where);
  // CAMotics' length: the flutes' (only when given; its default is not a
  // fact about the tool).
  if (t.contains("length") && len > 0) out.assembly.flute_length = len;
  auto dims = [&](absl::string_view what) {
    return Bad(where, absl::StrCat(shape, ": ", what));
  };
  if (!(d > 0)) {
    out.cutter = dims(absl::StrCat("\"diameter\" must be > 0, got ", Format(d)));
  } else if (shape == "cylindrical") {
    out.cutter = Cutter::Flat(d / 2);
  } else if (shape == "ballnose") {
    out.cutter = Cutter::Ball(d / 2);
  } else if (shape == "conical" || shape == "snubnose") {
    const double tip = shape == "snubnose" ? sd / 2 : 0;
    if (!(len > 0)) {
      out.cutter = dims(absl::StrCat("\"length\" must be > 0, got ", Format(len)));
    } else if (!(tip >= 0 && tip <= d / 2)) {
      out.cutter = dims(absl::StrCat(
          "\"snub_diameter\" must be in [0, diameter ", Format(d), "], got ",
          Format(sd)));
    } else if (tip == d / 2) {
      out.cutter = Cutter::Flat(d / 2);  // no taper: a cylinder
    } else {
      out.cutter = Cutter::Cone(d / 2, std::atan((d / 2 - tip) / len) * kRadToDeg,
                                tip);
    }
  } else {
    out.cutter = dims(
        "this shape can't be simulated (swarf simulates cylindrical, "
        "ballnose, conical and snubnose tools)");
  }
  if (out.cutter.ok()) {
    if (absl::Status s = ValidateCutter(*out.cutter, std::string(where)); !s.ok()) {
      out.cutter = s;
    }
  }
  return out;
}

}  // namespace

absl::StatusOr<CamoticsProject> ParseCamoticsProject(absl::string_view text,
                                                     const std::string& file) {
  const Json doc = Json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded() || !doc.is_object()) {
    return Bad(file, "not a CAMotics project (a JSON object)");
  }
  CamoticsProject p;
  p.tools.file = file;
  if (auto tools = doc.find("tools"); tools != doc.end()) {
    if (!tools->is_object()) return Bad(file, "\"tools\" must be an object");
    for (const auto& [key, value] : tools->items()) {
      const std::string where = absl::StrCat(file, " tool \"", key, "\"");
      int n;
      if (!absl::SimpleAtoi(key, &n) || n < 0 || n > 65535) {
        return Bad(where, "the key must be a tool number 0-65535");
      }
      auto tool = CamoticsTool(value, where);
      if (!tool.ok()) return tool.status();
      p.tools.tools[n] = *std::move(tool);
    }
  }
  if (auto wp = doc.find("workpiece"); wp != doc.end()) {
    const std::string where = absl::StrCat(file, " workpiece");
    if (!wp->is_object()) return Bad(where, "must be an object");
    if (auto a = wp->find("automatic"); a != wp->end()) {
      if (!a->is_boolean()) return Bad(where, "\"automatic\" must be true or false");
      p.automatic = a->get<bool>();
    }
    auto margin = NumberAt(*wp, "margin", 0, where);
    if (!margin.ok()) return margin.status();
    p.margin_percent = *margin;
    if (auto b = wp->find("bounds"); b != wp->end()) {
      auto corner = [&](const char* key, double* out) -> absl::Status {
        auto c = b->is_object() ? b->find(key) : b->end();
        if (c == b->end() || !c->is_array() || c->size() != 3) {
          return Bad(where, absl::StrCat("bounds.", key, " must be [x, y, z]"));
        }
        for (int i = 0; i < 3; ++i) {
          if (!(*c)[i].is_number() || !std::isfinite((*c)[i].get<double>())) {
            return Bad(where, absl::StrCat("bounds.", key, "[", i,
                                           "] must be a number"));
          }
          out[i] = (*c)[i].get<double>();
        }
        return absl::OkStatus();
      };
      if (absl::Status s = corner("min", p.min); !s.ok()) return s;
      if (absl::Status s = corner("max", p.max); !s.ok()) return s;
      if (!(p.min[0] < p.max[0] && p.min[1] < p.max[1])) {
        return Bad(where, "bounds: min must be below max in x and y");
      }
      p.has_bounds = true;
    }
    if (!p.automatic && !p.has_bounds) {
      return Bad(where, "\"automatic\" is false but there are no bounds");
    }
  }
  const std::filesystem::path dir =
      std::filesystem::path(file).parent_path();
  if (auto files = doc.find("files"); files != doc.end()) {
    if (!files->is_array()) return Bad(file, "\"files\" must be a list");
    for (const Json& f : *files) {
      if (!f.is_string()) return Bad(file, "\"files\" must hold file names");
      const std::filesystem::path path(f.get<std::string>());
      p.files.push_back((path.is_absolute() ? path : dir / path).string());
    }
  }
  return p;
}

namespace {

absl::StatusOr<std::string> ReadText(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(file, ": can't be read"));
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

}  // namespace

absl::StatusOr<CamoticsProject> ReadCamoticsProject(const std::string& file) {
  auto text = ReadText(file);
  if (!text.ok()) return text.status();
  return ParseCamoticsProject(*text, file);
}

absl::StatusOr<ToolTable> ReadToolTableFile(const std::string& file,
                                            double inch_scale) {
  auto text = ReadText(file);
  if (!text.ok()) return text.status();
  const absl::string_view start = absl::StripLeadingAsciiWhitespace(*text);
  if (absl::EndsWithIgnoreCase(file, ".camotics") || absl::StartsWith(start, "{")) {
    auto p = ParseCamoticsProject(*text, file);
    if (!p.ok()) return p.status();
    return std::move(p->tools);
  }
  return ParseLinuxCncToolTable(*text, file, inch_scale);
}

// ------------------------------------------------------------- choosing

absl::StatusOr<ToolChoices> ParseToolChoices(
    const std::vector<std::string>& tool_options,
    std::optional<ToolTable> table) {
  ToolChoices c;
  c.table = std::move(table);
  std::set<std::optional<int>> given;
  for (const std::string& v : tool_options) {
    auto o = ParseToolOption(v);
    if (!o.ok()) return o.status();
    if (!given.insert(o->number).second) {
      return absl::InvalidArgumentError(
          o->number.has_value()
              ? absl::StrCat("--tool: tool ", *o->number, " is given twice")
              : std::string("--tool: give one tool without a number (the "
                            "others as N=SHAPE:...)"));
    }
    c.options.push_back(*o);
  }
  return c;
}

namespace {

// Rules 1-3 of ChooseTools; nullptr when nothing serves `n`.
const absl::StatusOr<Cutter>* Find(const ToolChoices& c, int n,
                                   absl::StatusOr<Cutter>* scratch) {
  const ToolOption* any = nullptr;
  for (const ToolOption& o : c.options) {
    if (o.number == n) return &(*scratch = o.cutter);
    if (!o.number.has_value()) any = &o;
  }
  const bool has_table = c.table.has_value();
  if (n == 0) {
    if (any != nullptr) return &(*scratch = any->cutter);
    if (has_table && c.table->tools.size() == 1) {
      return &c.table->tools.begin()->second.cutter;
    }
    return nullptr;
  }
  if (has_table) {
    auto it = c.table->tools.find(n);
    return it == c.table->tools.end() ? nullptr : &it->second.cutter;
  }
  return any != nullptr ? &(*scratch = any->cutter) : nullptr;
}

std::string TableNumbers(const ToolTable& t) {
  std::vector<std::string> n;
  for (const auto& [k, v] : t.tools) n.push_back(absl::StrCat("T", k));
  return n.empty() ? "none" : absl::StrJoin(n, ", ");
}

}  // namespace

absl::StatusOr<std::map<int, Cutter>> ChooseTools(
    const ToolChoices& choices, const std::vector<ToolUse>& uses) {
  std::map<int, Cutter> out;
  for (const ToolUse& u : uses) {
    absl::StatusOr<Cutter> scratch;
    const absl::StatusOr<Cutter>* c = Find(choices, u.number, &scratch);
    if (c == nullptr) {
      std::string why;
      if (u.number == 0) {
        why = choices.table.has_value()
                  ? absl::StrCat("the program selects no tool (no T word) and "
                                 "the tool table ", choices.table->file,
                                 " has ", choices.table->tools.size(),
                                 " tools (", TableNumbers(*choices.table),
                                 "): give --tool SHAPE:...")
                  : "the program selects no tool: give --tool SHAPE:..., "
                    "e.g. --tool ball:d=3.175";
      } else if (choices.table.has_value()) {
        why = absl::StrCat("T", u.number, " is not in the tool table ",
                           choices.table->file, " (",
                           TableNumbers(*choices.table), "); give --tool ",
                           u.number, "=SHAPE:...");
      } else {
        why = absl::StrCat("the program uses tool T", u.number, ": give --tool ",
                           u.number, "=SHAPE:... (or --tools FILE)");
      }
      return absl::InvalidArgumentError(
          u.where.empty() ? why : absl::StrCat(u.where, ": ", why));
    }
    if (!c->ok()) {
      return absl::InvalidArgumentError(absl::StrCat(
          u.where.empty() ? "" : absl::StrCat(u.where, ": T", u.number, ": "),
          c->status().message()));
    }
    out[u.number] = **c;
  }
  return out;
}

ToolAssembly KnownAssembly(const ToolChoices& c, int n) {
  const ToolOption* any = nullptr;
  for (const ToolOption& o : c.options) {
    if (o.number == n) return o.assembly;
    if (!o.number.has_value()) any = &o;
  }
  const bool has_table = c.table.has_value();
  if (n == 0) {
    if (any != nullptr) return any->assembly;
    if (has_table && c.table->tools.size() == 1) {
      return c.table->tools.begin()->second.assembly;
    }
    return {};
  }
  if (has_table) {
    auto it = c.table->tools.find(n);
    return it == c.table->tools.end() ? ToolAssembly{} : it->second.assembly;
  }
  return any != nullptr ? any->assembly : ToolAssembly{};
}

std::optional<Cutter> KnownTool(const ToolChoices& choices, int n) {
  absl::StatusOr<Cutter> scratch;
  const absl::StatusOr<Cutter>* c = Find(choices, n, &scratch);
  if (c == nullptr || !c->ok()) return std::nullopt;
  return **c;
}

}  // namespace swarf::cli
