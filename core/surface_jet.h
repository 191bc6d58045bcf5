// Second-order local description of a height function z = w(x, y).
#ifndef SWARF_CORE_SURFACE_JET_H_
#define SWARF_CORE_SURFACE_JET_H_

#include <bit>
#include <cstdint>

namespace swarf {

// Height (mm) and its first (dimensionless) and second (1/mm) partial
// derivatives at one point: the paper's nodal parameters w, wx, wy, wxx, wxy,
// wyy.
struct SurfaceJet {
  double w = 0;
  double wx = 0, wy = 0;
  double wxx = 0, wxy = 0, wyy = 0;
};

// Eq. (1): the second-order Taylor patch of node jet `n` at (xn, yn),
// evaluated at (x, y).
inline double EvaluatePatch(const SurfaceJet& n, double xn, double yn,
                            double x, double y) {
  const double u = x - xn, v = y - yn;
  return n.w + n.wx * u + n.wy * v +
         0.5 * n.wxx * u * u + n.wxy * u * v + 0.5 * n.wyy * v * v;
}

// Gradient of the patch of eq. (1) at (x, y).
inline void PatchGradient(const SurfaceJet& n, double xn, double yn, double x,
                          double y, double* gx, double* gy) {
  const double u = x - xn, v = y - yn;
  *gx = n.wx + n.wxx * u + n.wxy * v;
  *gy = n.wy + n.wxy * u + n.wyy * v;
}

// Whether a and b have the same slopes and curvatures, bit for bit (their
// heights aside): then every function of those alone (TrustRegion) agrees
// on them.
inline bool SameShape(const SurfaceJet& a, const SurfaceJet& b) {
  return std::bit_cast<uint64_t>(a.wx) == std::bit_cast<uint64_t>(b.wx) &&
         std::bit_cast<uint64_t>(a.wy) == std::bit_cast<uint64_t>(b.wy) &&
         std::bit_cast<uint64_t>(a.wxx) == std::bit_cast<uint64_t>(b.wxx) &&
         std::bit_cast<uint64_t>(a.wxy) == std::bit_cast<uint64_t>(b.wxy) &&
         std::bit_cast<uint64_t>(a.wyy) == std::bit_cast<uint64_t>(b.wyy);
}

}  // namespace swarf

#endif  // SWARF_CORE_SURFACE_JET_H_
