// Toolpath parsing speed in source lines per second: the corpus programs
// (read in place from ../shared/corpus) and synthetic 1M-line G-code and
// XYZ files. Run: build/bin/swarf_parser_bench
#include <benchmark/benchmark.h>

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "gcode/toolpath.h"

namespace swarf::gcode {
namespace {

std::string ReadFile(const std::string& path) {
  std::string data;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return data;
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) data.append(buf, n);
  std::fclose(f);
  return data;
}

int64_t CountLines(const std::string& text) {
  int64_t n = 0;
  for (char c : text) n += c == '\n';
  return n;
}

// A finishing program as CAM posts write it: N numbers, mostly modal axis
// words, a feed now and then, and every 500 lines a helical R arc and a
// full I/J circle.
std::string SyntheticGcode(int64_t lines) {
  std::string s =
      "%\nO1000 (SYNTHETIC)\nG21 G17 G40 G49 G80 G90\nT1 M6\n"
      "S12000 M3\nG0 X0 Y0 Z5 M8\nG1 Z0 F800\n";
  char buf[96];
  double y = 0;
  for (int64_t i = 7; i < lines - 2; ++i) {
    const double x = (i % 400) * 0.25;
    const double z = -1 - 0.001 * (i % 997);
    if (i % 500 == 0) {
      // From the previous point, 0.25 mm along X: within reach of R5.
      const double px = ((i - 1) % 400) * 0.25;
      std::snprintf(buf, sizeof buf, "N%lld G2 X%.3f Y%.3f Z%.3f R5.\n",
                    static_cast<long long>(i), px + 0.25, y, z);
    } else if (i % 500 == 1) {
      std::snprintf(buf, sizeof buf, "N%lld G3 I-2.5 J0.\n",
                    static_cast<long long>(i));  // full circle
    } else if (i % 500 == 2) {
      std::snprintf(buf, sizeof buf, "N%lld G1 X%.3f Y%.3f Z%.3f F1500.\n",
                    static_cast<long long>(i), x, y, z);
    } else if (i % 400 == 0) {
      y += 0.25;
      std::snprintf(buf, sizeof buf, "N%lld Y%.3f\n", static_cast<long long>(i),
                    y);
    } else {
      std::snprintf(buf, sizeof buf, "N%lld X%.3f Z%.3f\n",
                    static_cast<long long>(i), x, z);
    }
    s += buf;
  }
  s += "M30\n%\n";
  return s;
}

// A raster of tip positions, 400 per row 0.25 mm apart, the depth varying:
// `header`, then one line per point from index `first`, printed by `format`
// from x, y, z.
std::string Raster(int64_t lines, const char* header, const char* format,
                   int64_t first) {
  std::string s = header;
  char buf[96];
  for (int64_t i = first; i < lines; ++i) {
    std::snprintf(buf, sizeof buf, format, (i % 400) * 0.25, (i / 400) * 0.25,
                  -1 - 0.001 * (i % 997));
    s += buf;
  }
  return s;
}

// Straight-line CAM output: one G1 then modal X Y Z words, 3 decimals.
std::string StraightGcode(int64_t lines) {
  return Raster(lines, "G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F1000\n",
                "X%.3f Y%.3f Z%.3f\n", 3);
}

// A parameter-heavy program: the same kind of raster computed by nested
// while loops with named parameters and expressions (a sine relief), 400 x
// 400 points: 3 blocks per point.
constexpr char kParametricRaster[] =
    "G21 G90 G17\n"
    "#<step> = 0.25\n"
    "#<y> = 0\n"
    "G0 X0 Y0 Z5\n"
    "o1 while [#<y> LT 100]\n"
    "  #<x> = 0\n"
    "  o2 while [#<x> LT 100]\n"
    "    G1 X#<x> Y#<y> Z[-1 - 0.5 * sin[#<x> * 3.6] * cos[#<y> * 3.6]]\n"
    "    #<x> = [#<x> + #<step>]\n"
    "  o2 endwhile\n"
    "  #<y> = [#<y> + #<step>]\n"
    "o1 endwhile\n"
    "M2\n";

std::string SyntheticXyz(int64_t lines) {
  return Raster(lines, "x,y,z\n", "%.4f,%.4f,%.4f\n", 1);
}

void Run(benchmark::State& state, const std::string& text, bool gcode) {
  if (text.empty()) {
    state.SkipWithError("input not found");
    return;
  }
  const int64_t lines = CountLines(text);
  int64_t points = 0, blocks = 0;
  for (auto _ : state) {
    absl::StatusOr<Toolpath> tp = gcode ? ParseGcode(text) : ParseXyz(text);
    if (!tp.ok()) {
      state.SkipWithError(std::string(tp.status().message()).c_str());
      return;
    }
    points = tp->point_count();
    blocks = tp->blocks_executed();
    benchmark::DoNotOptimize(tp);
  }
  state.counters["lines/s"] =
      benchmark::Counter(static_cast<double>(lines * state.iterations()),
                         benchmark::Counter::kIsRate);
  state.counters["lines"] = static_cast<double>(lines);
  state.counters["blocks/s"] = benchmark::Counter(
      static_cast<double>(blocks * state.iterations()),
      benchmark::Counter::kIsRate);
  state.counters["points"] = static_cast<double>(points);
  state.SetBytesProcessed(static_cast<int64_t>(text.size()) *
                          state.iterations());
}

void BM_Corpus(benchmark::State& state, const char* name) {
  static const std::string kDir = SWARF_CORPUS_DIR;
  const std::string text = ReadFile(kDir + "/" + name);
  Run(state, text, true);
}
BENCHMARK_CAPTURE(BM_Corpus, bear, "bear.nc")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Corpus, cameo, "cameo.nc")->Unit(benchmark::kMillisecond);

void BM_SyntheticGcode(benchmark::State& state) {
  static const std::string text = SyntheticGcode(1'000'000);
  Run(state, text, true);
}
BENCHMARK(BM_SyntheticGcode)
    ->Name("Synthetic/gcode_1M_lines")
    ->Unit(benchmark::kMillisecond);

void BM_StraightGcode(benchmark::State& state) {
  static const std::string text = StraightGcode(1'000'000);
  Run(state, text, true);
}
BENCHMARK(BM_StraightGcode)
    ->Name("Synthetic/gcode_straight_1M_lines")
    ->Unit(benchmark::kMillisecond);

void BM_Parametric(benchmark::State& state) {
  Run(state, kParametricRaster, true);
}
BENCHMARK(BM_Parametric)
    ->Name("Synthetic/gcode_parametric_400x400")
    ->Unit(benchmark::kMillisecond);

void BM_SyntheticXyz(benchmark::State& state) {
  static const std::string text = SyntheticXyz(1'000'000);
  Run(state, text, false);
}
BENCHMARK(BM_SyntheticXyz)
    ->Name("Synthetic/xyz_1M_lines")
    ->Unit(benchmark::kMillisecond);

// A program as `swarf run` takes it: read from a file, then parsed
// (ReadToolpathFile). 4M straight lines (about 100 MB, as a tenth of the
// 1000 mm plate's), written once to a temporary file; the file stays in the
// page cache, as a program just written by a CAM post does.
// SWARF_PARSER_BENCH_FILE=path reads that program instead (the plate's
// plate.nc, a corpus job).
void BM_StraightGcodeFile(benchmark::State& state) {
  static const std::string path = [] {
    if (const char* given = std::getenv("SWARF_PARSER_BENCH_FILE")) {
      return std::string(given);
    }
    char name[] = "/tmp/swarf_parser_bench_XXXXXX";
    const int fd = mkstemp(name);
    if (fd < 0) return std::string();
    const std::string text = StraightGcode(4'000'000);
    const bool ok =
        write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
    close(fd);
    if (!ok) return std::string();
    static const std::string kept = name;
    std::atexit([] { std::remove(kept.c_str()); });
    return kept;
  }();
  if (path.empty()) {
    state.SkipWithError("cannot write the temporary program");
    return;
  }
  int64_t points = 0;
  for (auto _ : state) {
    absl::StatusOr<Toolpath> tp = ReadToolpathFile(path);
    if (!tp.ok()) {
      state.SkipWithError(std::string(tp.status().message()).c_str());
      return;
    }
    points = tp->point_count();
    benchmark::DoNotOptimize(tp);
  }
  state.counters["points/s"] = benchmark::Counter(
      static_cast<double>(points) * static_cast<double>(state.iterations()),
      benchmark::Counter::kIsRate);
  state.counters["points"] = static_cast<double>(points);
}
BENCHMARK(BM_StraightGcodeFile)
    ->Name("File/gcode_straight_4M_lines")
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime();

}  // namespace
}  // namespace swarf::gcode

BENCHMARK_MAIN();
