// Huge pages for large allocations: AdviseHugePages marks the whole
// aligned pages inside a range, and the executables' operator new
// (core/huge_new.cc, linked into this test as into swarf and swarfd)
// advises every allocation of kHugeAllocationBytes or more. The advice is
// read back from the kernel: the "hg" flag of the mapping in
// /proc/self/smaps. PopulatePages faults a range in (read back with
// mincore) and leaves its contents as they were.
#include "core/huge_pages.h"

#include <gtest/gtest.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <fstream>
#include <memory>
#include <new>
#include <sstream>
#include <string>
#include <vector>

#include "core/thread_pool.h"

namespace swarf {
namespace {

bool ThpSupported() {
  return std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled").good();
}

// The VmFlags of the mapping that holds address a ("" when none does).
std::string VmFlagsAt(const void* a) {
  const auto at = reinterpret_cast<uintptr_t>(a);
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    uintptr_t lo = 0, hi = 0;
    char dash = 0;
    std::istringstream head(line);
    if (head >> std::hex >> lo >> dash >> hi && dash == '-' &&
        line.find(':') > line.find(' ')) {
      inside = lo <= at && at < hi;
      continue;
    }
    if (inside && line.rfind("VmFlags:", 0) == 0) return line.substr(8);
  }
  return "";
}

bool Advised(const void* a) {
  std::istringstream flags(VmFlagsAt(a));
  std::string f;
  while (flags >> f) {
    if (f == "hg") return true;
  }
  return false;
}

const char* AlignedInside(const void* p) {
  const auto b = reinterpret_cast<uintptr_t>(p);
  return reinterpret_cast<const char*>((b + kHugePageBytes - 1) &
                                       ~(kHugePageBytes - 1));
}

class HugePagesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!ThpSupported()) GTEST_SKIP() << "no transparent huge pages here";
  }
};

TEST_F(HugePagesTest, AdvisesTheWholeAlignedPagesInside) {
  const size_t bytes = 4 * kHugePageBytes;
  void* m = mmap(nullptr, bytes, PROT_READ | PROT_WRITE,
                 MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  ASSERT_NE(m, MAP_FAILED);
  char* const aligned = const_cast<char*>(AlignedInside(m));
  // From 4 KiB into one huge page to the end of the next: only the next.
  ASSERT_TRUE(AdviseHugePages(aligned + 4096, 2 * kHugePageBytes - 4096));
  EXPECT_FALSE(Advised(aligned));
  EXPECT_TRUE(Advised(aligned + kHugePageBytes));
  EXPECT_TRUE(Advised(aligned + 2 * kHugePageBytes - 1));
  EXPECT_FALSE(Advised(aligned + 2 * kHugePageBytes));
  // No whole page inside: nothing asked.
  EXPECT_FALSE(AdviseHugePages(aligned + 4096, kHugePageBytes));
  EXPECT_FALSE(AdviseHugePages(aligned, kHugePageBytes - 1));
  EXPECT_FALSE(Advised(aligned));
  // The memory works as before.
  std::memset(aligned, 7, 2 * kHugePageBytes);
  EXPECT_EQ(aligned[kHugePageBytes + 5], 7);
  munmap(m, bytes);
}

TEST_F(HugePagesTest, LargeAllocationsOfEveryFormAreAdvised) {
#if defined(SWARF_SANITIZER_ALLOCATOR)
  GTEST_SKIP() << "sanitizer builds keep the sanitizer's operator new";
#else
  const size_t big = 64 << 20;
  {
    std::vector<char> v(big, 1);  // std::allocator: operator new
    EXPECT_TRUE(Advised(AlignedInside(v.data())));
    EXPECT_EQ(v[big - 1], 1);
  }
  {
    std::unique_ptr<char[]> a(new char[big]);
    EXPECT_TRUE(Advised(AlignedInside(a.get())));
  }
  {
    std::unique_ptr<char[]> n(new (std::nothrow) char[big]);
    ASSERT_NE(n, nullptr);
    EXPECT_TRUE(Advised(AlignedInside(n.get())));
  }
  {
    std::string s(kHugeAllocationBytes, 'x');
    EXPECT_TRUE(Advised(AlignedInside(s.data())));
  }
  // Allocations of every size on both sides of the threshold, written and
  // freed by each form of delete.
  for (size_t n : {size_t{0}, size_t{1}, size_t{4096}, kHugePageBytes,
                   kHugeAllocationBytes - 1, kHugeAllocationBytes,
                   kHugeAllocationBytes + 12345}) {
    char* p = static_cast<char*>(::operator new(n));
    std::memset(p, 3, n);
    ::operator delete(p, n);
    p = new char[n + 1];
    p[n] = 1;
    delete[] p;
    p = static_cast<char*>(::operator new(n, std::nothrow));
    ASSERT_NE(p, nullptr);
    ::operator delete(p);
  }
#endif
}

TEST_F(HugePagesTest, FailedAllocationsStillThrowOrReturnNull) {
#if defined(SWARF_SANITIZER_ALLOCATOR)
  GTEST_SKIP() << "sanitizer builds keep the sanitizer's operator new";
#else
  // More than any address space: malloc fails, no new-handler is set.
  const size_t absurd = size_t{1} << 62;
  EXPECT_THROW((void)::operator new(absurd), std::bad_alloc);
  EXPECT_EQ(::operator new(absurd, std::nothrow), nullptr);
  // A new-handler is called until it gives up (here by removing itself).
  static int calls = 0;
  calls = 0;
  std::set_new_handler([] {
    if (++calls == 3) std::set_new_handler(nullptr);
  });
  EXPECT_THROW((void)::operator new[](absurd), std::bad_alloc);
  EXPECT_EQ(calls, 3);
  std::set_new_handler(nullptr);
#endif
}

// Whether each 4 KiB page of [p, p + bytes) is resident.
std::vector<bool> Resident(const char* p, size_t bytes) {
  std::vector<unsigned char> v(bytes / 4096);
  EXPECT_EQ(mincore(const_cast<char*>(p), bytes, v.data()), 0);
  std::vector<bool> out;
  for (const unsigned char c : v) out.push_back((c & 1) != 0);
  return out;
}

// The pages a range touches are faulted in, over several threads' pieces,
// and no others; what was written stays, the rest reads zero.
TEST(PopulatePagesTest, FaultsInTheRangesPagesKeepingTheirContents) {
  constexpr size_t kPage = 4096;
  const size_t bytes = 40 << 20;  // several pieces of 16 MiB
  char* m = static_cast<char*>(mmap(nullptr, bytes, PROT_READ | PROT_WRITE,
                                    MAP_PRIVATE | MAP_ANONYMOUS, -1, 0));
  ASSERT_NE(m, MAP_FAILED);
  // 4 KiB pages whatever the machine's huge page setting: residency is
  // then counted page by page.
  madvise(m, bytes, MADV_NOHUGEPAGE);
  std::memset(m + 5 * kPage, 0x5a, 3 * kPage);
  m[bytes - 3 * kPage + 7] = 9;
  std::vector<bool> before = Resident(m, bytes);
  EXPECT_TRUE(before[5]);
  EXPECT_FALSE(before[100]);
  ThreadPool pool(3);
  // From the middle of page 1 to the middle of the third page from the end.
  const size_t lo = kPage + 100, hi = bytes - 3 * kPage + 100;
  EXPECT_TRUE(PopulatePages(m, 0, pool));
  if (!PopulatePages(m + lo, hi - lo, pool)) {
    munmap(m, bytes);
    GTEST_SKIP() << "this kernel has no MADV_POPULATE_WRITE (Linux 5.14)";
  }
  const std::vector<bool> after = Resident(m, bytes);
  const size_t pages = bytes / kPage;
  EXPECT_FALSE(after[0]);
  for (size_t k = 1; k <= (hi - 1) / kPage; ++k) {
    ASSERT_TRUE(after[k]) << "page " << k;
  }
  for (size_t k = (hi - 1) / kPage + 1; k < pages; ++k) {
    EXPECT_EQ(after[k], before[k]) << "page " << k;
  }
  for (size_t k = 0; k < bytes; k += 997) {
    const bool written = (k >= 5 * kPage && k < 8 * kPage);
    ASSERT_EQ(m[k], written ? 0x5a : 0) << "byte " << k;
  }
  EXPECT_EQ(m[bytes - 3 * kPage + 7], 9);
  munmap(m, bytes);
}

}  // namespace
}  // namespace swarf
