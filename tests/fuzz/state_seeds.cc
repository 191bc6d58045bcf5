// Writes the seed corpus of state_fuzz into the directory given: valid
// states of its workpiece (tests/fuzz/state_fuzz.h), each after the byte
// that picks the scheme, per scheme: uncut, partly cut (the other moves
// recorded): the first rows (the near tiles), the corner plunge (the far
// corner tile, partial on both axes); wholly cut, also for the streaming
// overload, and in the version-1 format. Run at build time, so the
// seeds follow the state format.

#include <algorithm>
#include <cstdlib>
#include <span>
#include <string>
#include <vector>

#include "core/workpiece.h"
#include "tests/fuzz/seed_dir.h"
#include "tests/fuzz/state_fuzz.h"
#include "tests/state_v1.h"

namespace {

using swarf::Move;
using swarf::SchemeKind;
using swarf::Workpiece;

// The state of the fuzz workpiece with the moves [begin, end) applied (in
// batches of 10) and the others recorded; in the version-1 format (with
// derivatives) when v1.
std::string State(SchemeKind scheme, size_t begin, size_t end,
                  bool v1 = false) {
  const std::vector<Move> moves = swarf::state_fuzz::Moves();
  auto wp = Workpiece::Create(swarf::state_fuzz::Stock(), scheme);
  if (!wp.ok()) std::abort();
  const std::span<const Move> all(moves);
  if (!(*wp)->Record(all.subspan(0, begin)).ok()) std::abort();
  for (size_t k = begin; k < end; k += 10) {
    if (!(*wp)->Apply(all.subspan(k, std::min<size_t>(10, end - k))).ok()) {
      std::abort();
    }
  }
  if (!(*wp)->Record(all.subspan(end)).ok()) std::abort();
  if (v1) return swarf::StateV1(**wp);
  std::string out;
  (*wp)->SaveState([&](const void* data, size_t size) {
    out.append(static_cast<const char*>(data), size);
  });
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  swarf::fuzz::SeedDir seeds(argc, argv);
  using swarf::state_fuzz::kCornerPlunge;
  const size_t all = swarf::state_fuzz::Moves().size();
  for (SchemeKind scheme : {SchemeKind::kZmap, SchemeKind::kTaylor}) {
    const std::string name = scheme == SchemeKind::kTaylor ? "taylor" : "zmap";
    const char first = swarf::state_fuzz::FirstByte(scheme);
    seeds.Write(name + "_uncut", first, State(scheme, 0, 0));
    seeds.Write(name + "_partial", first, State(scheme, 0, 7));
    seeds.Write(name + "_corner", first,
                State(scheme, kCornerPlunge, kCornerPlunge + 1));
    const std::string cut = State(scheme, 0, all);
    seeds.Write(name + "_cut", first, cut);
    seeds.Write(name + "_cut_streamed", first | swarf::state_fuzz::kStreamed,
                cut);
    seeds.Write(name + "_cut_v1", first, State(scheme, 0, all, true));
  }
  return seeds.Done();
}
