#include "core/memory_policy.h"

#ifdef __GLIBC__
#include <malloc.h>
#endif

namespace swarf {

void ReturnLargeBuffersOnFree(size_t bytes) {
#ifdef __GLIBC__
  // A fixed threshold also turns off glibc's sliding one, which rises to
  // the largest buffer freed (up to 32 MiB) and then serves such buffers
  // from the arenas.
  mallopt(M_MMAP_THRESHOLD, static_cast<int>(bytes));
#else
  (void)bytes;
#endif
}

void KeepFreedArenaTops(size_t bytes) {
#ifdef __GLIBC__
  mallopt(M_TRIM_THRESHOLD, static_cast<int>(bytes));
#else
  (void)bytes;
#endif
}

}  // namespace swarf
