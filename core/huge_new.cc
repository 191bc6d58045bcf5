// The global operator new and delete of swarf's executables: malloc and
// free, with huge pages asked for every allocation of kHugeAllocationBytes
// or more (core/huge_pages.h). Every std::vector, string and buffer of a
// large job gets them, with no allocator in its type.
//
// Linked into the executables only (CMake's swarf_huge_new object library):
// a library must not replace the operators of the program that uses it.
// Sanitizer builds keep the sanitizer's own operators, which check that
// new pairs with delete.
#include <cstddef>
#include <cstdlib>
#include <new>

#include "core/huge_pages.h"

#if !defined(SWARF_SANITIZER_ALLOCATOR)

namespace {

// As the standard's operator new: the new-handler until it fails.
void* Allocate(std::size_t n) {
  if (n == 0) n = 1;
  for (;;) {
    if (void* p = std::malloc(n)) {
      if (n >= swarf::kHugeAllocationBytes) swarf::AdviseHugePages(p, n);
      return p;
    }
    std::new_handler handler = std::get_new_handler();
    if (handler == nullptr) throw std::bad_alloc();
    handler();
  }
}

void* AllocateOrNull(std::size_t n) noexcept {
  try {
    return Allocate(n);
  } catch (...) {
    return nullptr;
  }
}

}  // namespace

void* operator new(std::size_t n) { return Allocate(n); }
void* operator new[](std::size_t n) { return Allocate(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  return AllocateOrNull(n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  return AllocateOrNull(n);
}

// Every unaligned delete frees: the aligned forms stay the library's, as
// do their news (aligned_alloc and free).
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept {
  std::free(p);
}

#endif  // !SWARF_SANITIZER_ALLOCATOR
