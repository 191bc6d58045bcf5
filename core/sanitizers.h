// The sanitizer a build runs under, for GCC (__SANITIZE_*__) and clang
// (__has_feature), named once for the whole tree:
//   SWARF_ASAN       AddressSanitizer;
//   SWARF_TSAN       ThreadSanitizer;
//   SWARF_SANITIZED  either: the sanitizer brings its own allocator and
//                    shadow memory, so resident-memory figures and the
//                    allocator's policy are not the program's own.
// Macros only: no code.
#ifndef SWARF_CORE_SANITIZERS_H_
#define SWARF_CORE_SANITIZERS_H_

#if defined(__SANITIZE_ADDRESS__)
#define SWARF_ASAN 1
#endif
#if defined(__SANITIZE_THREAD__)
#define SWARF_TSAN 1
#endif
#if defined(__has_feature)
#if __has_feature(address_sanitizer) && !defined(SWARF_ASAN)
#define SWARF_ASAN 1
#endif
#if __has_feature(thread_sanitizer) && !defined(SWARF_TSAN)
#define SWARF_TSAN 1
#endif
#endif

#if defined(SWARF_ASAN) || defined(SWARF_TSAN)
#define SWARF_SANITIZED 1
#endif

#endif  // SWARF_CORE_SANITIZERS_H_
