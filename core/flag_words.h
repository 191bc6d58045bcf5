// Flags as bytes (0 or 1), written by vectorized loops and read a word of 8
// at a time: sparse flags are found without a test per entry.
#ifndef SWARF_CORE_FLAG_WORDS_H_
#define SWARF_CORE_FLAG_WORDS_H_

#include <bit>
#include <cstdint>
#include <cstring>

namespace swarf {

// Bytes a flag array of n entries needs: n rounded up to whole words, the
// bytes past n zero (ClearFlagTail).
inline constexpr int32_t FlagBytes(int32_t n) { return (n + 7) & ~7; }

// Zeroes the bytes past n up to FlagBytes(n).
inline void ClearFlagTail(uint8_t* flag, int32_t n) {
  // Nothing past a whole word (an empty array may have no storage).
  if (FlagBytes(n) > n) std::memset(flag + n, 0, FlagBytes(n) - n);
}

// Calls f(q) for each q < n whose flag is 1, in ascending order. `flag`
// holds FlagBytes(n) bytes, each 0 or 1, zero past n.
template <class F>
inline void ForEachFlagged(const uint8_t* flag, int32_t n, F&& f) {
  for (int32_t q0 = 0; q0 < n; q0 += 8) {
    uint64_t word;
    std::memcpy(&word, flag + q0, sizeof(word));
    while (word != 0) {
      // Little-endian (x86): byte b of the word is flag[q0 + b].
      f(q0 + std::countr_zero(word) / 8);
      word &= word - 1;
    }
  }
}

}  // namespace swarf

#endif  // SWARF_CORE_FLAG_WORDS_H_
