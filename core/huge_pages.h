// Transparent huge pages for large allocations (Linux; elsewhere no-ops).
//
// A large job touches gigabytes: its program's points, the moves, the
// index, the outputs' bands and buffers. On 4 KiB pages each 4 KiB costs a
// page fault when first written (a trap into the kernel: dear in a virtual
// machine, and the kernel's page-table work serialises threads) and the
// hot loops miss the TLB. On 2 MiB pages there are 512 times fewer of both.
// Kernels set to "madvise" (Debian's default) give them only to memory that
// asks: this header asks. Advice only: without it memory works the same.
//
// Thread-safe.
#ifndef SWARF_CORE_HUGE_PAGES_H_
#define SWARF_CORE_HUGE_PAGES_H_

#include <cstddef>

#include "core/sanitizers.h"

// Defined in sanitizer (ASan) builds, which keep the sanitizer's operator
// new and delete: core/huge_new.cc then replaces nothing.
#if defined(SWARF_ASAN)
#define SWARF_SANITIZER_ALLOCATOR 1
#endif

namespace swarf {

class ThreadPool;

inline constexpr size_t kHugePageBytes = size_t{2} << 20;
// The smallest allocation the global operator new of core/huge_new.cc
// advises: one that holds at least one whole aligned huge page.
inline constexpr size_t kHugeAllocationBytes = size_t{4} << 20;

// Asks for huge pages for the kHugePageBytes-aligned pages that lie wholly
// inside [p, p + bytes) (madvise MADV_HUGEPAGE); the partial pages at
// either end are left as they are. Returns whether the kernel took the
// advice (false: no whole page inside, no THP support, or not Linux).
bool AdviseHugePages(void* p, size_t bytes);

// Faults in the pages of [p, p + bytes) as if written (madvise
// MADV_POPULATE_WRITE: contents unchanged), a piece on each of the pool's
// threads: for memory that one thread is about to fill, whose page faults
// (each zeroing a page, 2 MiB at once on huge pages) would otherwise be a
// serial step. The memory must be this process's own, private and
// writable. Returns whether the kernel took it all (false: before Linux
// 5.14, or not Linux; memory works the same). Blocks until done.
bool PopulatePages(void* p, size_t bytes, ThreadPool& pool);

}  // namespace swarf

#endif  // SWARF_CORE_HUGE_PAGES_H_
