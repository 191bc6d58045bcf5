#include "core/tile_arena.h"

#include <cstdint>
#include <cstdlib>
#include <new>

#include "core/huge_pages.h"

namespace swarf {
namespace {

std::mutex cache_mu;
std::vector<void*>& Cache() {  // guarded by cache_mu
  static auto* const cache = new std::vector<void*>;
  return *cache;
}

void* NewChunk() {
  {
    std::lock_guard<std::mutex> l(cache_mu);
    if (!Cache().empty()) {
      void* c = Cache().back();
      Cache().pop_back();
      return c;
    }
  }
  void* c = std::aligned_alloc(TileArena::kChunkBytes, TileArena::kChunkBytes);
  if (c == nullptr) throw std::bad_alloc();
  AdviseHugePages(c, TileArena::kChunkBytes);
  return c;
}

void ReleaseChunk(void* c) {
  {
    std::lock_guard<std::mutex> l(cache_mu);
    if (Cache().size() < TileArena::kCachedChunks) {
      Cache().push_back(c);
      return;
    }
  }
  std::free(c);
}

}  // namespace

TileArena::TileArena(size_t block_bytes) : block_(block_bytes) {}

TileArena::~TileArena() {
  for (void* c : chunks_) ReleaseChunk(c);
}

void* TileArena::Allocate() {
  std::lock_guard<std::mutex> l(mu_);
  if (!free_.empty()) {
    void* b = free_.back();
    free_.pop_back();
    return b;
  }
  if (next_ == nullptr || static_cast<size_t>(end_ - next_) < block_) {
    char* c = static_cast<char*>(NewChunk());
    chunks_.push_back(c);
    next_ = c;
    end_ = c + kChunkBytes;
  }
  void* b = next_;
  next_ += block_;
  return b;
}

void TileArena::Free(void* block) {
  std::lock_guard<std::mutex> l(mu_);
  free_.push_back(block);
}

size_t TileArena::chunk_bytes() const {
  std::lock_guard<std::mutex> l(mu_);
  return chunks_.size() * kChunkBytes;
}

}  // namespace swarf
