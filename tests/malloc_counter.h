#pragma once
// A counting C allocator for the allocation tests (operator new and Eigen both allocate through
// malloc): malloc, calloc, realloc, memalign and aligned_alloc are replaced by versions that
// count their calls between BeginCountingMalloc() and EndCountingMalloc(), and forward to
// glibc's __libc_* entry points (glibc-specific, as the project). Counting is off otherwise.
// Not in an AddressSanitizer build, which owns malloc: there nothing is replaced and a test
// skips itself (`if (SECURE_TEST_ASAN) GTEST_SKIP()`, tests/sanitizers.h).
//
// This header DEFINES the C functions: include it in exactly one source file of a test
// executable (a second one fails to link). Used by tests/domains/domain_alloc_test.cc,
// domains/derby/tests/derby_test.cc and tests/shield/shield_alloc_test.cc (which adds
// posix_memalign and operator new).
#include <atomic>
#include <cstddef>

#include "tests/sanitizers.h"

namespace secure::test {

inline std::atomic<bool> malloc_counting{false};
inline std::atomic<long> malloc_calls{0};

/// Sets the count to 0 and starts counting.
inline void BeginCountingMalloc() {
  malloc_calls = 0;
  malloc_counting = true;
}

/// Stops counting; the calls counted since BeginCountingMalloc().
inline long EndCountingMalloc() {
  malloc_counting = false;
  return malloc_calls.load();
}

[[maybe_unused]] inline void CountMalloc() {  // unused where nothing is replaced (ASan)
  if (malloc_counting.load(std::memory_order_relaxed)) malloc_calls.fetch_add(1);
}

}  // namespace secure::test

#if !SECURE_TEST_ASAN
extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* pointer, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
void* malloc(std::size_t size) noexcept {
  secure::test::CountMalloc();
  return __libc_malloc(size);
}
void* calloc(std::size_t count, std::size_t size) noexcept {
  secure::test::CountMalloc();
  return __libc_calloc(count, size);
}
void* realloc(void* pointer, std::size_t size) noexcept {
  secure::test::CountMalloc();
  return __libc_realloc(pointer, size);
}
void* memalign(std::size_t alignment, std::size_t size) noexcept {
  secure::test::CountMalloc();
  return __libc_memalign(alignment, size);
}
void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
  secure::test::CountMalloc();
  return __libc_memalign(alignment, size);
}
}
#endif
