// ReturnLargeBuffersOnFree: a large buffer freed and asked for again is
// mapped again (and so was unmapped when freed), where glibc's sliding
// threshold would have served the second one from an arena, which keeps
// it after free.
#include "core/memory_policy.h"

#include <cstdlib>
#include <cstring>

#include "gtest/gtest.h"
#include "core/sanitizers.h"

#ifdef __GLIBC__
#include <malloc.h>
#endif

namespace swarf {
namespace {

// glibc's allocator only: ASan brings its own.
#if defined(__GLIBC__) && !defined(SWARF_SANITIZED)
// Bytes held in mapped chunks while a buffer of `bytes` is held, after one
// of the same size was allocated and freed.
size_t MappedWhileHeldAgain(size_t bytes) {
  // Through volatile pointers: the compiler may drop a malloc and free
  // pair it sees whole.
  void* (*volatile alloc)(size_t) = std::malloc;
  void (*volatile release)(void*) = std::free;
  void* first = alloc(bytes);
  std::memset(first, 1, bytes);
  release(first);  // glibc's threshold now rises to `bytes`
  void* again = alloc(bytes);
  std::memset(again, 2, bytes);
  const size_t mapped = mallinfo2().hblkhd;
  release(again);
  return mapped;
}

TEST(MemoryPolicyTest, LargeBuffersAreMappedEveryTime) {
  constexpr size_t kBytes = size_t{24} << 20;
  ReturnLargeBuffersOnFree();
  EXPECT_GE(MappedWhileHeldAgain(kBytes), kBytes);
}

// The default (what the policy changes): the second buffer comes from an
// arena. In a process of its own (each test runs alone under ctest), and
// run first by name order only there, so it is a death test's child.
TEST(MemoryPolicyDeathTest, WithoutItTheSecondBufferIsNotMapped) {
  constexpr size_t kBytes = size_t{24} << 20;
  EXPECT_EXIT(
      {
        std::exit(MappedWhileHeldAgain(kBytes) < kBytes ? 0 : 1);
      },
      ::testing::ExitedWithCode(0), "");
}

// KeepFreedArenaTops: a buffer freed at the top of the main arena stays
// there (mallinfo2's keepcost, the releasable top) instead of going back to
// the kernel. 2 MiB: under ReturnLargeBuffersOnFree's 4 MiB, so carved from
// the arena.
size_t TopKeptAfterFree(size_t bytes) {
  void* (*volatile alloc)(size_t) = std::malloc;
  void (*volatile release)(void*) = std::free;
  void* buffer = alloc(bytes);
  std::memset(buffer, 1, bytes);
  release(buffer);
  return mallinfo2().keepcost;
}

TEST(MemoryPolicyTest, FreedArenaTopIsKept) {
  constexpr size_t kBytes = size_t{2} << 20;
  ReturnLargeBuffersOnFree();
  KeepFreedArenaTops();
  EXPECT_GE(TopKeptAfterFree(kBytes), kBytes);
}

// The default it changes: with the mmap threshold fixed at 4 MiB, glibc's
// trim threshold is 128 KiB, and the freed top goes back.
TEST(MemoryPolicyDeathTest, WithoutItTheFreedTopIsReturned) {
  constexpr size_t kBytes = size_t{2} << 20;
  EXPECT_EXIT(
      {
        ReturnLargeBuffersOnFree();
        std::exit(TopKeptAfterFree(kBytes) < kBytes ? 0 : 1);
      },
      ::testing::ExitedWithCode(0), "");
}
#endif

}  // namespace
}  // namespace swarf
