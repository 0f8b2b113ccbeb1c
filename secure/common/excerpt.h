#pragma once
// Text from files (a CSV header, a cell, a YAML key) quoted in error messages, made safe to print:
// bounded in length and with control and invalid bytes escaped, so that a binary file cannot
// dump itself into a message and a NUL byte cannot cut one short.

#include <cstddef>
#include <string>
#include <string_view>

namespace secure {

/// Default bound on an excerpt: characters shown before the "…".
inline constexpr std::size_t kExcerptMaxChars = 80;

/// `text` for a message: control bytes become escapes (\n, \r, \t, \0, \xNN; a backslash stays
/// as is), bytes that are not valid UTF-8 become \xNN, valid UTF-8 is kept; after
/// `max_chars` shown characters (an escape counts its length) the rest is cut and "…" appended.
std::string Excerpt(std::string_view text, std::size_t max_chars = kExcerptMaxChars);

}  // namespace secure
