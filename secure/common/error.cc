#include "secure/common/error.h"

#include <cstdio>
#include <cstdlib>

namespace secure::internal {

// User-facing errors carry only the message: the file/line of the check is an implementation
// detail that a user of the CLI does not need, and messages already name the file and field.
void ThrowError(const char* /*file*/, int /*line*/, const std::string& message) {
  throw Error(message);
}

void AbortInternal(const char* file, int line, const char* condition, const std::string& message) {
  std::fprintf(stderr, "secure: internal error at %s:%d: %s (%s)\n", file, line, message.c_str(),
               condition);
  std::abort();
}

}  // namespace secure::internal
