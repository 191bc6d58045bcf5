// A std::vector whose resize() leaves the new elements as allocated, for
// large buffers that are then filled on every thread: value-initialising
// them first wrote (and page-faulted in) every byte on one thread, a serial
// step of each picture, band and batch of moves (issue 28).
//
// Contract: only for trivially copyable, trivially destructible types
// (scalars, aggregates such as SurfaceJet), whose objects the allocation
// itself creates; their values are indeterminate until written. The caller
// writes every element that resize() adds before reading it. Everything
// else (copies, insert, push_back with a value) behaves as std::vector.
#ifndef SWARF_CORE_UNFILLED_VECTOR_H_
#define SWARF_CORE_UNFILLED_VECTOR_H_

#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace swarf {

template <typename T>
struct UnfilledAllocator : std::allocator<T> {
  static_assert(std::is_trivially_copyable_v<T> &&
                std::is_trivially_destructible_v<T>);
  template <typename U>
  struct rebind {
    using other = UnfilledAllocator<U>;
  };
  UnfilledAllocator() = default;
  template <typename U>
  UnfilledAllocator(const UnfilledAllocator<U>&) noexcept {}

  // Default construction (resize, the sized constructor) writes nothing.
  template <typename U>
  void construct(U*) noexcept {}
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

template <typename T>
using UnfilledVector = std::vector<T, UnfilledAllocator<T>>;

// *v holding n elements, all to be written by the caller (a std::vector's
// still value-initialised, an UnfilledVector's not): when it must grow, the
// old ones are dropped, their storage given back first, rather than copied.
template <typename T, typename Alloc>
void ResizeForWriting(std::vector<T, Alloc>* v, size_t n) {
  if (n > v->capacity()) std::vector<T, Alloc>().swap(*v);
  v->resize(n);
}

}  // namespace swarf

#endif  // SWARF_CORE_UNFILLED_VECTOR_H_
