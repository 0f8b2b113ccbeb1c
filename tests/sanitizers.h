#pragma once
// SECURE_TEST_ASAN is 1 in an AddressSanitizer build (scripts/check.sh): tests that replace
// malloc cannot run there (ASan owns malloc and calls it before any static initialiser).
#if defined(__SANITIZE_ADDRESS__)
#define SECURE_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SECURE_TEST_ASAN 1
#endif
#endif
#ifndef SECURE_TEST_ASAN
#define SECURE_TEST_ASAN 0
#endif
