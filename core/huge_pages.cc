#include "core/huge_pages.h"

#include <algorithm>
#include <atomic>
#include <cstdint>

#include "core/thread_pool.h"

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace swarf {

bool AdviseHugePages(void* p, size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  const uintptr_t begin = reinterpret_cast<uintptr_t>(p);
  const uintptr_t first = (begin + kHugePageBytes - 1) & ~(kHugePageBytes - 1);
  const uintptr_t last = (begin + bytes) & ~(kHugePageBytes - 1);
  if (last <= first) return false;
  // Whole pages only: the ends may share their huge page with other
  // allocations, which did not ask.
  return madvise(reinterpret_cast<void*>(first), last - first, MADV_HUGEPAGE) ==
         0;
#else
  (void)p;
  (void)bytes;
  return false;
#endif
}

bool PopulatePages(void* p, size_t bytes, ThreadPool& pool) {
#if defined(__linux__) && defined(MADV_POPULATE_WRITE)
  // Whole 4 KiB pages covering the range (madvise takes an aligned start):
  // populating a page shared with another allocation leaves it as it is.
  constexpr uintptr_t kPage = 4096;
  // Pieces of whole huge pages, so that no huge page is split between two
  // threads' calls.
  constexpr uintptr_t kPiece = 8 * kHugePageBytes;
  if (bytes == 0) return true;
  const uintptr_t begin = reinterpret_cast<uintptr_t>(p) & ~(kPage - 1);
  const uintptr_t end = reinterpret_cast<uintptr_t>(p) + bytes;
  const uintptr_t first_piece = begin & ~(kPiece - 1);
  const int64_t pieces =
      static_cast<int64_t>((end - first_piece + kPiece - 1) / kPiece);
  std::atomic<bool> ok{true};
  pool.ParallelFor(pieces, [&](int64_t k) {
    const uintptr_t lo = std::max(begin, first_piece + k * kPiece);
    const uintptr_t hi = std::min(end, first_piece + (k + 1) * kPiece);
    if (madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_POPULATE_WRITE) !=
        0) {
      ok.store(false, std::memory_order_relaxed);
    }
  });
  return ok.load();
#else
  (void)p;
  (void)bytes;
  (void)pool;
  return false;
#endif
}

}  // namespace swarf
