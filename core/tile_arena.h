// Memory for tiles: fixed-size blocks carved from 2 MiB chunks that the
// kernel may back with huge pages, so that cutting N tiles costs a few page
// faults instead of one per 4 KiB. Chunks outlive their arena in a bounded
// process-wide cache, so workpieces created one after the other reuse warm
// memory. Blocks are uninitialised.
//
// Thread-safe (a mutex: tiles are allocated once each, off the hot path).
#ifndef SWARF_CORE_TILE_ARENA_H_
#define SWARF_CORE_TILE_ARENA_H_

#include <cstddef>
#include <mutex>
#include <vector>

namespace swarf {

class TileArena {
 public:
  static constexpr size_t kChunkBytes = size_t{2} << 20;
  // Chunks kept for reuse after their arena is gone, at most.
  static constexpr size_t kCachedChunks = 64;

  // block_bytes <= kChunkBytes.
  explicit TileArena(size_t block_bytes);
  ~TileArena();
  TileArena(const TileArena&) = delete;
  TileArena& operator=(const TileArena&) = delete;

  void* Allocate();
  // `block` must come from this arena's Allocate().
  void Free(void* block);

  size_t block_bytes() const { return block_; }
  // Bytes of chunks held (what the arena costs the process).
  size_t chunk_bytes() const;

 private:
  const size_t block_;
  mutable std::mutex mu_;
  std::vector<void*> chunks_;  // guarded by mu_
  std::vector<void*> free_;    // guarded by mu_
  char* next_ = nullptr;       // guarded by mu_: unused part of the last chunk
  char* end_ = nullptr;        // guarded by mu_
};

}  // namespace swarf

#endif  // SWARF_CORE_TILE_ARENA_H_
