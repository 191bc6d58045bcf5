// Fuzz target: Workpiece::LoadState on arbitrary bytes, as a snapshot file
// gives them (server/snapshot.cc). The first byte picks the scheme (bit 0:
// taylor, else zmap) and the overload (bit 1: the streaming one, with a
// verify() that refuses); the rest is the state, loaded into a workpiece of
// a small stock (tests/fuzz/state_fuzz.h: 2 x 2 tiles, partial ones at the
// far edges) with a fixed set of moves recorded. Never a crash or undefined
// behaviour. A refused state is DataLoss and leaves the workpiece as it
// was; verify() is called exactly for the states the plain overload takes,
// and its refusal is returned. A taken state keeps what Apply guarantees:
// owners -1 (at the stock top) or a recorded move, heights finite and at
// most the top, derivatives within +-kMaxDerivative, a tile allocated
// exactly when its version is nonzero (at most the workpiece's); the
// reconstructed surface (sampled around each tile's lowest node) finite and
// at most the top, its gradient finite. Saved again it gives the bytes read
// (a version-1 state, which carried derivatives, saves as version 2
// without them), which a fresh workpiece loads and saves identically, and
// which goes on cutting with the same invariants.

#include "tests/fuzz/state_fuzz.h"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "absl/functional/function_ref.h"
#include "absl/status/status.h"
#include "core/thread_pool.h"
#include "core/workpiece.h"
#include "tests/fuzz/fuzz_check.h"

namespace swarf {
namespace {

// The state format (core/workpiece.cc): an 80-byte header ("SWARFWP2"),
// then per tile its index (u32), version (u64), w (f64) and owners (i32),
// kTileNodes each; in version 1 ("SWARFWP1") taylor tiles were followed by
// five derivatives (f32), kTileNodes each.
constexpr size_t kHeaderBytes = 80;
constexpr size_t kOwnersAt = 4 + 8 + kTileNodes * sizeof(double);
constexpr size_t kTileBytes = kOwnersAt + kTileNodes * sizeof(int32_t);
constexpr size_t kDerivativeBytes = 5 * kTileNodes * sizeof(float);

// One thread: the fuzz runs share the machine.
ThreadPool& Pool() {
  static ThreadPool* const pool = new ThreadPool(1);
  return *pool;
}

// A workpiece of the fuzz stock with the fixed moves recorded, uncut.
std::unique_ptr<Workpiece> NewWorkpiece(SchemeKind scheme) {
  auto wp = Workpiece::Create(state_fuzz::Stock(), scheme, &Pool());
  FUZZ_CHECK(wp.ok());
  FUZZ_CHECK((*wp)->Record(state_fuzz::Moves()).ok());
  return *std::move(wp);
}

// The workpiece each input loads into, per scheme, kept across inputs
// (LoadState replaces the whole nodal state, so inputs stay independent),
// and what its SaveState gives.
struct Target {
  std::unique_ptr<Workpiece> wp;
  std::string saved;
};

// Whether wp's SaveState gives exactly `bytes` (without a copy).
bool SavesAs(const Workpiece& wp, std::string_view bytes) {
  bool same = true;
  wp.SaveState([&](const void* data, size_t size) {
    same = same && size <= bytes.size() &&
           std::memcmp(data, bytes.data(), size) == 0;
    if (same) bytes.remove_prefix(size);
  });
  return same && bytes.empty();
}

Target& TargetFor(SchemeKind scheme) {
  static Target* const targets = [] {
    auto* t = new Target[2];
    for (SchemeKind s : {SchemeKind::kZmap, SchemeKind::kTaylor}) {
      Target& target = t[s == SchemeKind::kTaylor];
      target.wp = NewWorkpiece(s);
      target.wp->SaveState([&](const void* data, size_t size) {
        target.saved.append(static_cast<const char*>(data), size);
      });
    }
    return t;
  }();
  return targets[scheme == SchemeKind::kTaylor];
}

// LoadState through the streaming overload, reading `bytes`.
absl::Status LoadStreamed(Workpiece& wp, std::string_view bytes,
                          absl::FunctionRef<absl::Status()> verify) {
  return wp.LoadState(
      [&](void* data, size_t size) {
        if (bytes.size() < size) return false;
        std::memcpy(data, bytes.data(), size);
        bytes.remove_prefix(size);
        return true;
      },
      verify);
}

// The reconstructed surface and its gradient in the elements around node
// (i, j), and at the node.
void CheckSurfaceAround(const Workpiece& wp, int32_t i, int32_t j) {
  const GridGeometry& g = wp.grid();
  const double x = g.NodeX(i), y = g.NodeY(j);
  for (double fx : {-0.5, 0.0, 0.5}) {
    for (double fy : {-0.5, 0.0, 0.5}) {
      const double px = x + fx * g.dx(), py = y + fy * g.dy();
      const double r = wp.Reconstruct(px, py);
      FUZZ_CHECK(std::isfinite(r) && r <= wp.spec().z_top);
      double gx, gy;
      wp.ReconstructGradient(px, py, &gx, &gy);
      FUZZ_CHECK(std::isfinite(gx) && std::isfinite(gy));
    }
  }
}

void CheckInvariants(const Workpiece& wp) {
  const double top = wp.spec().z_top;
  // Derivatives as BallSweep bounds them, stored as float.
  const float max_d = static_cast<float>(kMaxDerivative);
  std::vector<double> w(kTileNodes);
  std::vector<float> d(5 * kTileNodes);
  std::vector<int32_t> owner(kTileNodes);
  float* dp[5];
  for (int c = 0; c < 5; ++c) dp[c] = d.data() + c * kTileNodes;
  for (int32_t t = 0; t < wp.tile_count(); ++t) {
    FUZZ_CHECK(wp.TileVersion(t) <= wp.version());
    FUZZ_CHECK(wp.TileAllocated(t) == (wp.TileVersion(t) > 0));
    const Workpiece::TileExtent e = wp.Extent(t);
    wp.ReadTile(t, w.data(), dp, owner.data());
    int32_t lowest = 0;
    for (int32_t k = 0; k < e.nx * e.ny; ++k) {
      FUZZ_CHECK(std::isfinite(w[k]) && w[k] <= top);
      FUZZ_CHECK(owner[k] >= -1 && owner[k] < wp.move_count());
      if (owner[k] == -1) FUZZ_CHECK(w[k] == top);
      for (int c = 0; c < 5; ++c) FUZZ_CHECK(std::fabs(dp[c][k]) <= max_d);
      if (w[k] < w[lowest]) lowest = k;
    }
    // Where the surface is most extreme, and at the tile's first node.
    CheckSurfaceAround(wp, e.i0 + lowest % e.nx, e.j0 + lowest / e.nx);
    CheckSurfaceAround(wp, e.i0, e.j0);
  }
}

// What SaveState writes for a state `bytes` that loaded, into *out: the
// same bytes, or for a version-1 state the version-2 bytes (its taylor
// tiles without their derivatives).
void Canonical(std::string_view bytes, SchemeKind scheme, std::string* out) {
  out->assign(bytes);
  if (bytes.size() < kHeaderBytes || bytes[7] != '1') return;
  (*out)[7] = '2';
  if (scheme != SchemeKind::kTaylor) return;
  out->resize(kHeaderBytes);
  for (size_t at = kHeaderBytes; at < bytes.size();
       at += kTileBytes + kDerivativeBytes) {
    FUZZ_CHECK(at + kTileBytes + kDerivativeBytes <= bytes.size());
    out->append(bytes.substr(at, kTileBytes));
  }
}

// An accepted state, now in target.wp: the invariants, the round trip, and
// a further cut.
void CheckLoaded(Target& target, std::string_view bytes, SchemeKind scheme) {
  const Workpiece& wp = *target.wp;
  CheckInvariants(wp);
  Canonical(bytes, scheme, &target.saved);
  FUZZ_CHECK(SavesAs(wp, target.saved));
  std::unique_ptr<Workpiece> fresh = NewWorkpiece(scheme);
  FUZZ_CHECK(fresh->LoadState(target.saved).ok());
  FUZZ_CHECK(SavesAs(*fresh, target.saved));
  // A groove through the corner where the four tiles meet.
  const Move cut = {{22, 23, 9}, {31, 31, 7}, 1.5};
  auto r = fresh->Apply({&cut, 1});
  FUZZ_CHECK(r.ok());
  FUZZ_CHECK(fresh->move_count() == wp.move_count() + 1);
  FUZZ_CHECK(fresh->version() == wp.version() + (r->node_lowerings > 0));
  CheckInvariants(*fresh);
}

}  // namespace
}  // namespace swarf

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace swarf;
  if (size < 1) return 0;
  const SchemeKind scheme = state_fuzz::SchemeOf(data[0]);
  const std::string_view state(reinterpret_cast<const char*>(data + 1),
                               size - 1);
  Target& target = TargetFor(scheme);
  if (data[0] & state_fuzz::kStreamed) {
    // Streamed, refused by verify(): never taken.
    bool verified = false;
    const absl::Status s = LoadStreamed(*target.wp, state, [&] {
      verified = true;
      return absl::DataLossError("fuzz: refused");
    });
    FUZZ_CHECK(s.code() == absl::StatusCode::kDataLoss);
    FUZZ_CHECK(verified == (s.message() == "fuzz: refused"));
    FUZZ_CHECK(SavesAs(*target.wp, target.saved));
    // verify() ran exactly when the state is valid.
    FUZZ_CHECK(NewWorkpiece(scheme)->LoadState(state).ok() == verified);
    return 0;
  }
  const absl::Status s = target.wp->LoadState(state);
  if (!s.ok()) {
    FUZZ_CHECK(s.code() == absl::StatusCode::kDataLoss);
    FUZZ_CHECK(SavesAs(*target.wp, target.saved));
    return 0;
  }
  CheckLoaded(target, state, scheme);
  return 0;
}
