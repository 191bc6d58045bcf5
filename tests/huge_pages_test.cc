// Huge pages for large allocations: AdviseHugePages marks the whole
// aligned pages inside a range, and the executables' operator new
// (core/huge_new.cc, linked into this test as into swarf and swarfd)
// advises every allocation of kHugeAllocationBytes or more. The advice is
// read back from the kernel: the "hg" flag of the mapping in
// /proc/self/smaps.
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

}  // namespace
}  // namespace swarf
