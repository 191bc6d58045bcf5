// Fuzz target: the design readers (ParseStl, binary and ASCII) on arbitrary
// bytes, and the top envelope of what they accept. They must never crash,
// hang or hit undefined behaviour; an error is InvalidArgument (or
// ResourceExhausted over the limit) naming the input; an accepted mesh has
// finite welded vertices, valid non-degenerate triangles and bounds that
// cover the vertices, and its envelope is finite or NaN at every node and
// is every triangle's at the nodes and at points of some elements (the
// bins, candidates and rasterized runs skip only triangles that miss).

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <vector>

#include "absl/strings/match.h"
#include "design/design_mesh.h"
#include "design/top_envelope.h"
#include "tests/fuzz/fuzz_check.h"

namespace swarf::design {
namespace {

constexpr int64_t kMaxTriangles = 1 << 12;

bool Within(const Interval& b, double v) { return b.lo <= v && v <= b.hi; }

void CheckMesh(const DesignMesh& m) {
  FUZZ_CHECK(!m.triangles.empty());
  FUZZ_CHECK(static_cast<int64_t>(m.triangles.size()) <= kMaxTriangles);
  for (const Vec3& v : m.vertices) {
    FUZZ_CHECK(std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z));
    FUZZ_CHECK(Within(m.x, v.x) && Within(m.y, v.y) && Within(m.z, v.z));
  }
  const int32_t n = static_cast<int32_t>(m.vertices.size());
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) FUZZ_CHECK(t[k] >= 0 && t[k] < n);
    FUZZ_CHECK(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
  }
}

bool Same(double a, double b) {
  return (std::isnan(a) && std::isnan(b)) || a == b;
}

// The envelope must be every triangle's (AtAmong over all of them, as
// HeightAt tests each) at the nodes and at points of elements: the bins,
// the candidates and the rasterized runs skip only triangles that surely
// miss. == rather than the bits: triangles tied at +0 and -0 may come in
// another order.
void CheckEnvelope(const DesignMesh& m, const TopEnvelope& env,
                   const GridGeometry& g) {
  std::vector<int32_t> every(m.triangles.size());
  std::iota(every.begin(), every.end(), 0);
  for (int32_t j = 0; j < g.nodes_y(); ++j) {
    for (int32_t i = 0; i < g.nodes_x(); ++i) {
      const double want = env.AtAmong(every, g.NodeX(i), g.NodeY(j));
      FUZZ_CHECK(Same(env.AtNode(i, j), static_cast<float>(want)));
    }
  }
  // Elements along the diagonal, a 4 x 4 lattice in each.
  std::vector<int32_t> candidates;
  for (int32_t e = 0; e < std::min(g.nx(), g.ny()); e += 3) {
    const Rect r{g.NodeX(e), g.NodeY(e), g.NodeX(e + 1), g.NodeY(e + 1)};
    env.Candidates(r, &candidates);
    double xs[16], ys[16], zs[16];
    for (int q = 0; q < 16; ++q) {
      xs[q] = q % 4 == 3 ? r.x1 : r.x0 + (q % 4) * (r.x1 - r.x0) / 3;
      ys[q] = q / 4 == 3 ? r.y1 : r.y0 + (q / 4) * (r.y1 - r.y0) / 3;
    }
    env.AtManyAmong(candidates, xs, ys, 16, zs);
    for (int q = 0; q < 16; ++q) {
      const double want = env.AtAmong(every, xs[q], ys[q]);
      FUZZ_CHECK(Same(zs[q], want));
      FUZZ_CHECK(Same(env.At(xs[q], ys[q]), want));
    }
  }
}

}  // namespace
}  // namespace swarf::design

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace swarf;
  using namespace swarf::design;
  const absl::string_view bytes(reinterpret_cast<const char*>(data), size);
  DesignReadOptions o;
  o.max_triangles = kMaxTriangles;
  auto m = ParseStl(bytes, "fuzz.stl", o);
  if (!m.ok()) {
    FUZZ_CHECK(m.status().code() == absl::StatusCode::kInvalidArgument ||
               m.status().code() == absl::StatusCode::kResourceExhausted);
    FUZZ_CHECK(absl::StartsWith(m.status().message(), "fuzz.stl: "));
    return 0;
  }
  CheckMesh(*m);
  // Its envelope on a small grid over its bounds (when they are sane).
  if (m->x.hi - m->x.lo > 1e-6 && m->y.hi - m->y.lo > 1e-6 &&
      std::fabs(m->x.lo) < 1e6 && std::fabs(m->x.hi) < 1e6 &&
      std::fabs(m->y.lo) < 1e6 && std::fabs(m->y.hi) < 1e6) {
    const StockSpec spec{m->x.lo, m->y.lo, m->x.hi, m->y.hi, 0, 16, 16};
    ThreadPool pool(1);
    auto env = TopEnvelope::Build(*m, GridGeometry(spec), &pool);
    FUZZ_CHECK(env.ok());
    for (float z : env->nodes()) {
      FUZZ_CHECK(std::isnan(z) || (z >= m->z.lo - 1e-3 * (1 + std::fabs(m->z.lo)) &&
                                   z <= m->z.hi + 1e-3 * (1 + std::fabs(m->z.hi))));
    }
    const double at = env->At(0.5 * (m->x.lo + m->x.hi), 0.5 * (m->y.lo + m->y.hi));
    FUZZ_CHECK(std::isnan(at) || std::isfinite(at));
    CheckEnvelope(*m, *env, GridGeometry(spec));
  }
  return 0;
}
