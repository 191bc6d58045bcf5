// SWARF_TESTS_SANITIZED: defined where the build runs under ASan or TSan,
// with GCC (__SANITIZE_*__) or clang (__has_feature): the sanitizer brings
// its own allocator and shadow memory, so tests of the allocator's policy
// or of resident memory skip there.
#ifndef SWARF_TESTS_SANITIZERS_H_
#define SWARF_TESTS_SANITIZERS_H_

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define SWARF_TESTS_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define SWARF_TESTS_SANITIZED 1
#endif
#endif

#endif  // SWARF_TESTS_SANITIZERS_H_
