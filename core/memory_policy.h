// Process-wide allocator settings for long runs on many threads.
#ifndef SWARF_CORE_MEMORY_POLICY_H_
#define SWARF_CORE_MEMORY_POLICY_H_

#include <cstddef>

namespace swarf {

// Buffers of at least `bytes` (default 4 MiB: a band's nodes, a chunk of
// segments, a tile row) are mapped on their own and unmapped when freed,
// instead of being carved from a thread's malloc arena, where glibc keeps
// them after free: with a thread per core each arena would hold its
// largest buffers until the process ends. Call once, at the start of
// main, before any thread starts. A no-op off glibc.
void ReturnLargeBuffersOnFree(size_t bytes = size_t{4} << 20);

// An arena keeps up to `bytes` (default 8 MiB) free at its top instead of
// giving it back to the kernel at once: glibc's default (128 KiB) returned
// the top of a thread's arena each time a bin's or a tile's scratch was
// freed, and its next use faulted every page in again, zeroed (on the
// 300 mm plate about 130,000 of 340,000 page faults, with 16 threads). At
// most `bytes` more held per arena. Call once, at the start of main, before
// any thread starts. A no-op off glibc.
void KeepFreedArenaTops(size_t bytes = size_t{8} << 20);

}  // namespace swarf

#endif  // SWARF_CORE_MEMORY_POLICY_H_
