#include "core/common/check.h"

#include <cstdio>
#include <cstdlib>

namespace softid::internal {

void AbortWithMessage(const char* condition, const char* file, int line) {
  std::fprintf(stderr, "softid: internal invariant violated: %s at %s:%d\n", condition, file, line);
  std::abort();
}

void ThrowInvalidArgument(const char* condition, const std::string& message, const char* file,
                          int line) {
  throw std::invalid_argument(message + " (failed: " + condition + " at " + file + ":" +
                              std::to_string(line) + ")");
}

}  // namespace softid::internal
