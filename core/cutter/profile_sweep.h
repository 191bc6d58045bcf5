// The exact sweep of one straight move of any cutter given by its profile:
// the engine behind FlatSweep, BullNoseSweep, ConeSweep and TaperedBallSweep
// (core/cutter/sweep.h lists the interface they provide).
//
// A cutter's lower surface is z = tip.z + f(rho), rho the horizontal distance
// from its axis, rho <= R; above f(R) a vertical wall (the cylindrical side).
// f is convex and nondecreasing, made of at most two smooth pieces:
//   flat  f = h0                                  (flat end, flat tip)
//   line  f = h0 + k (rho - rho0), k = cot(half angle)      (cone flank)
//   arc   f = hc - sqrt(rc^2 - (rho - rho_c)^2)   (sphere when rho_c = 0,
//                                                  torus corner otherwise)
// For the move tip(s) = P0 + s (h, m), s in [0, L] the horizontal distance
// travelled (h the unit XY direction, m = dz / L the slope), the swept height
// at (x, y) is min over s of g(s) = z0 + m s + f(|(x, y) - P0xy - s h|) where
// the distance is <= R. g is convex (f convex nondecreasing, |.| convex), so
// its minimum is one of: an end of the move (s = 0, L), a point where the
// distance crosses a kink circle rho = rho_k (a piece boundary, or the wall
// at R), or a stationary point of one smooth piece (g' = 0). Locate takes
// the least of all these candidates that are feasible: each is a value of g,
// and the minimizer is among them, so the result is exact. Convexity also
// prunes them: g rising from the start (or falling into the end) makes that
// end the minimum, and a torus contact (the bull-nose on a ramp) is needed,
// and then is the minimum, only where g falls at the start and rises at
// the end.
//
// With a = (q - P0) . h and n = (q - P0) . h_perp (q = (x, y)), the
// stationary points are in closed form for the flat (m = 0: any point; its
// boundary candidates cover it), the line (the wedge of eq. L below), the
// on-axis sphere (the ball's cylinder, paper eq. 12-13) and the torus on a
// horizontal move (u = 0); for the torus on a ramp, a bracketed Newton solve
// of the one-parameter envelope condition (see TorusContact in the .cc).
//
// Derivatives are analytic. Along the move, every envelope (stationary) piece
// is invariant under the translation (h, m), so w = m a + W(n) there and the
// Hessian is W''(n) h_perp h_perp^T (W'' from the implicit function theorem
// for the torus). At a move end the surface is the tool's own; on a kink
// circle w = z0 + m (a +- sqrt(rho_k^2 - n^2)) + f(rho_k).
// Vertical walls: where the surface turns vertical (the rim of an arc, the
// side of a kink circle crossing, the cone's apex) the derivatives are
// computed with the vanishing quantity clamped as the ball clamps its rim
// (kRimDepthFraction of the relevant radius: the arc's depth, the circle's
// half chord, the apex distance; for the torus on a ramp its contact angle
// from the equator to kRimDepthFraction of its range), then bounded with
// ClampedJet. The height is never clamped. Seams take one-sided limits: at
// a circle's side (half chord 0) the crossing the ramp descends to, where
// the move's reach of (x, y) shrinks to an end (the other crossing past
// it) that end's tool.
//
// A ProfileSweep is an immutable value; all methods are thread-safe.
#ifndef SWARF_CORE_CUTTER_PROFILE_SWEEP_H_
#define SWARF_CORE_CUTTER_PROFILE_SWEEP_H_

#include <cstdint>

#include "core/cutter/capsule.h"
#include "core/cutter/cutter.h"
#include "core/geometry.h"
#include "core/surface_jet.h"

namespace swarf {

// One smooth piece of a profile, on rho0 <= rho <= rho1.
struct ProfilePiece {
  enum Kind : int32_t { kFlat, kLine, kSphere, kTorus };
  Kind kind = kFlat;
  double rho0 = 0, rho1 = 0;
  double h0 = 0;     // flat, line: height at rho0
  double k = 0;      // line: slope cot(half angle)
  double rho_c = 0;  // arc: its centre's distance from the axis (0: sphere)
  double hc = 0;     // arc: its centre's height above the tip
  double rc = 0;     // arc: its radius
  double Height(double rho) const;  // f on this piece
  double Slope(double rho) const;   // f' on this piece (+inf at a rim)
};

// A cutter's lower surface as pieces, innermost first, ending at radius.
struct Profile {
  int32_t pieces = 0;
  ProfilePiece piece[2];
  double radius = 0;
  // The piece holding rho (the inner one on a boundary).
  int32_t PieceAt(double rho) const {
    return (pieces > 1 && rho > piece[0].rho1) ? 1 : 0;
  }
  double Height(double rho) const { return piece[PieceAt(rho)].Height(rho); }
  // Appends a piece of `kind` on [rho0, rho1] (its other fields zero).
  ProfilePiece& Add(ProfilePiece::Kind kind, double rho0, double rho1) {
    ProfilePiece& p = piece[pieces++];
    p = ProfilePiece{};
    p.kind = kind;
    p.rho0 = rho0;
    p.rho1 = rho1;
    return p;
  }
  double Slope(double rho) const { return piece[PieceAt(rho)].Slope(rho); }
};

// Where (x, y) lies on the swept surface: which candidate set the height.
struct ProfilePoint {
  enum Contact : int32_t {
    kNone,      // the tool never passes over (x, y): w = +inf
    kTool,      // the tool at a move end (or at the lowest point of a
                // vertical move): p0, p1 = (x, y) minus its axis
    kEnvelope,  // a stationary point of piece `index`: p0 = n; sphere:
                // p1 = sqrt(rc^2 - n^2); torus: p1, p2 = sin, cos of the
                // contact angle from the equator
    kKink,      // kink circle `index` (rho_k = piece[index].rho1, or 0 for
                // index -1: a sharp apex): p0 = n, p1 = +-half chord
  };
  Contact contact = kNone;
  int32_t index = 0;
  double w = kInf;
  double p0 = 0, p1 = 0, p2 = 0;
};

class ProfileSweep {
 public:
  // tip_from/tip_to: tool tips (finite, mm); `profile` of a valid cutter.
  ProfileSweep(const Vec3& tip_from, const Vec3& tip_to,
               const Cutter& cutter, const Profile& profile);

  double lowest() const { return z_low_; }
  // TipFootprint of the move (core/cutter/capsule.h).
  Capsule Footprint(double cap) const;
  double Height(double x, double y) const { return Locate(x, y).w; }
  // out[q] = Height(x[q], y[q]), bit-identical (the same function).
  void Heights(const double* x, const double* y, int32_t n,
               double* out) const;
  SurfaceJet JetAt(double x, double y) const { return Jet(Locate(x, y)); }

  ProfilePoint Locate(double x, double y) const;
  // Height and bounded analytic derivatives at a located point.
  SurfaceJet Jet(const ProfilePoint& p) const;

  const Profile& profile() const { return profile_; }

 private:
  enum Kind : uint8_t { kPoint, kVertical, kGeneral };

  // The tool's own surface with its axis at (vx, vy) from (x, y).
  SurfaceJet ToolJet(double w, double vx, double vy) const;

  Cutter cutter_;
  Profile profile_;
  Vec3 from_, to_;
  Kind kind_ = kPoint;
  double z_low_ = 0;
  double x_low_ = 0, y_low_ = 0;  // axis of the lowest tool (vertical, point)
  double len_ = 0;                // horizontal length L
  double h1_ = 0, h2_ = 0;        // unit XY direction
  double m_ = 0;                  // slope dz / L
  double g_ = 1, k3_ = 0;         // L / |move|, dz / |move|
};

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_PROFILE_SWEEP_H_
