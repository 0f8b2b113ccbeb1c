#pragma once
// Errors and checks. Three tiers (see docs/ARCHITECTURE.md):
//   SECURE_CHECK(cond, msg)          user-facing: bad file, bad option, wrong size. Throws
//   secure::Error. SECURE_INTERNAL_CHECK(cond, msg) a broken invariant of our own code. Prints and
//   aborts. SECURE_DCHECK(cond)              debug-only assertion, free in Release.
// Messages are built with operator<<, e.g.
//   SECURE_CHECK(x.size() == n, "state has " << x.size() << " values, expected " << n);

#include <sstream>
#include <stdexcept>
#include <string>

namespace secure {

/// The one exception type the library throws for misuse and bad input.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

namespace internal {
[[noreturn]] void ThrowError(const char* file, int line, const std::string& message);
[[noreturn]] void AbortInternal(const char* file, int line, const char* condition,
                                const std::string& message);
}  // namespace internal

}  // namespace secure

#define SECURE_CHECK(cond, msg)                                                       \
  do {                                                                                \
    if (!(cond)) {                                                                    \
      std::ostringstream secure_check_stream_;                                        \
      secure_check_stream_ << msg;                                                    \
      ::secure::internal::ThrowError(__FILE__, __LINE__, secure_check_stream_.str()); \
    }                                                                                 \
  } while (false)

#define SECURE_THROW(msg) SECURE_CHECK(false, msg)

#define SECURE_INTERNAL_CHECK(cond, msg)                                                        \
  do {                                                                                          \
    if (!(cond)) {                                                                              \
      std::ostringstream secure_check_stream_;                                                  \
      secure_check_stream_ << msg;                                                              \
      ::secure::internal::AbortInternal(__FILE__, __LINE__, #cond, secure_check_stream_.str()); \
    }                                                                                           \
  } while (false)

#ifdef NDEBUG
#define SECURE_DCHECK(cond) \
  do {                      \
  } while (false)
#else
#define SECURE_DCHECK(cond) SECURE_INTERNAL_CHECK(cond, "debug check")
#endif
