// FUZZ_CHECK: an invariant of a fuzz target. A failure aborts, which both
// libFuzzer (saves the input as a crash) and the corpus replay (fails the
// test) report with the input.
#ifndef SWARF_TESTS_FUZZ_FUZZ_CHECK_H_
#define SWARF_TESTS_FUZZ_FUZZ_CHECK_H_

#include <cstdio>
#include <cstdlib>

#define FUZZ_CHECK(cond)                                               \
  do {                                                                 \
    if (!(cond)) {                                                     \
      std::fprintf(stderr, "%s:%d: FUZZ_CHECK failed: %s\n", __FILE__, \
                   __LINE__, #cond);                                   \
      std::abort();                                                    \
    }                                                                  \
  } while (0)

#endif  // SWARF_TESTS_FUZZ_FUZZ_CHECK_H_
