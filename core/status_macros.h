// Early-return helpers for absl::Status, as in Abseil-based projects.
#ifndef SWARF_CORE_STATUS_MACROS_H_
#define SWARF_CORE_STATUS_MACROS_H_

#include "absl/status/status.h"

#define SWARF_RETURN_IF_ERROR(expr)        \
  do {                                     \
    ::absl::Status swarf_status_ = (expr); \
    if (!swarf_status_.ok()) return swarf_status_; \
  } while (0)

#endif  // SWARF_CORE_STATUS_MACROS_H_
