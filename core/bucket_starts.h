// The placing step of a parallel counting sort: chunks of a list count
// their items per bucket on every thread, then each chunk moves its items
// to where BucketStarts says (issue 28: the marks' incidences, the mesh's
// leaves by row).
#ifndef SWARF_CORE_BUCKET_STARTS_H_
#define SWARF_CORE_BUCKET_STARTS_H_

#include <cstdint>

namespace swarf {

// at[c * buckets + b] holds chunk c's count of bucket b's items; each
// becomes where those items start in the list sorted by bucket, the
// chunks in order within a bucket (a stable sort when each chunk keeps its
// order). bounds[b] (buckets + 1 entries) is where bucket b starts,
// bounds[buckets] the total. Single-threaded: chunks * buckets steps.
template <typename T>
void BucketStarts(int64_t chunks, int64_t buckets, T* at, T* bounds) {
  T total = 0;
  for (int64_t b = 0; b < buckets; ++b) {
    bounds[b] = total;
    for (int64_t c = 0; c < chunks; ++c) {
      const T count = at[c * buckets + b];
      at[c * buckets + b] = total;
      total += count;
    }
  }
  bounds[buckets] = total;
}

}  // namespace swarf

#endif  // SWARF_CORE_BUCKET_STARTS_H_
