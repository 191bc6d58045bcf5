// Tests that read files outside the repository (../shared/corpus: someone
// else's programs, read in place, never copied in) skip when a file is
// missing, naming it, so that a fresh clone passes on its own. Where the
// environment sets SWARF_REQUIRE_SHARED (to anything but "" or "0"; .ci/run
// does), a missing file fails the test instead: the corpus coverage cannot
// silently vanish from CI.
#ifndef SWARF_TESTS_SHARED_FILES_H_
#define SWARF_TESTS_SHARED_FILES_H_

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include "gtest/gtest.h"

namespace swarf::testing_shared {

inline bool SharedFilesRequired() {
  const char* v = std::getenv("SWARF_REQUIRE_SHARED");
  return v != nullptr && *v != '\0' && std::strcmp(v, "0") != 0;
}

}  // namespace swarf::testing_shared

// In a test body (it returns from it): skip, or fail where required, when
// `path` does not exist.
#define SWARF_SKIP_UNLESS_SHARED_FILE(path)                                  \
  do {                                                                       \
    const std::string swarf_shared_path_ = (path);                           \
    if (!std::filesystem::exists(swarf_shared_path_)) {                      \
      if (::swarf::testing_shared::SharedFilesRequired()) {                  \
        FAIL() << "missing " << swarf_shared_path_                           \
               << " (SWARF_REQUIRE_SHARED is set)";                          \
      }                                                                      \
      GTEST_SKIP() << "missing " << swarf_shared_path_;                      \
    }                                                                        \
  } while (0)

#endif  // SWARF_TESTS_SHARED_FILES_H_
