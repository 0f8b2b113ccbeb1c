// CSV reading and writing for numeric tables (see data.h for the contract).
//
// The reader parses the whole file from one buffer with string_views, so a cell costs no heap
// allocation; numbers go through std::from_chars, which ignores the C locale (a German locale
// would otherwise turn "0.5" into 0).

#include "secure/data/data.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <string>
#include <string_view>
#include <system_error>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/excerpt.h"
#include "secure/common/filesystem.h"
#include "secure/common/strings.h"

namespace secure::data {
namespace {

constexpr std::string_view kUtf8Bom = "\xEF\xBB\xBF";

std::string_view TrimBlanks(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) {
    s.remove_suffix(1);
  }
  return s;
}

// Values are quoted in messages; a runaway cell (e.g. a binary file) is cut to stay readable and
// control bytes (a NUL would cut the message short) are escaped.
std::string Shown(std::string_view value) { return Excerpt(value); }

// The header as listed in a message: names joined, the whole bounded like a cell.
std::string ShownHeader(const std::vector<std::string>& header) { return Excerpt(Join(header)); }

// Splits `line` at commas into `cells` (reused across rows so that it allocates only once).
void SplitCells(std::string_view line, std::vector<std::string_view>& cells) {
  cells.clear();
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    if (comma == std::string_view::npos) {
      cells.push_back(line.substr(start));
      return;
    }
    cells.push_back(line.substr(start, comma - start));
    start = comma + 1;
  }
}

// Decimal order of magnitude of a number that from_chars reported out of range; only its sign
// matters (positive: overflow, otherwise underflow), since such values are near 1e±308.
long OrderOfMagnitude(std::string_view s) {
  std::size_t i = 0;
  if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
  long order = 0;
  bool seen_nonzero = false;
  for (; i < s.size() && s[i] >= '0' && s[i] <= '9'; ++i) {
    if (s[i] != '0') seen_nonzero = true;
    if (seen_nonzero) ++order;
  }
  if (i < s.size() && s[i] == '.') {
    for (++i; i < s.size() && s[i] >= '0' && s[i] <= '9'; ++i) {
      if (!seen_nonzero) {
        if (s[i] != '0') {
          seen_nonzero = true;
        } else {
          --order;
        }
      }
    }
  }
  if (i < s.size() && (s[i] == 'e' || s[i] == 'E')) {
    ++i;
    bool negative = false;
    if (i < s.size() && (s[i] == '+' || s[i] == '-')) negative = s[i++] == '-';
    long exponent = 0;
    for (; i < s.size() && s[i] >= '0' && s[i] <= '9'; ++i) {
      if (exponent < 1000000) exponent = exponent * 10 + (s[i] - '0');  // saturate
    }
    order += negative ? -exponent : exponent;
  }
  return order;
}

enum class ParseResult { kOk, kNotANumber, kNotFinite };

// Parses a whole (already trimmed) cell as a finite double.
ParseResult ParseDouble(std::string_view cell, double& value) {
  std::string_view digits = cell;
  // from_chars rejects a leading '+', which other tools write for exponents and signed data.
  if (digits.size() >= 2 && digits[0] == '+' && digits[1] != '-' && digits[1] != '+') {
    digits.remove_prefix(1);
  }
  if (digits.empty()) return ParseResult::kNotANumber;
  const char* end = digits.data() + digits.size();
  const auto [ptr, ec] = std::from_chars(digits.data(), end, value);
  if (ptr != end) return ParseResult::kNotANumber;
  if (ec == std::errc::result_out_of_range) {
    if (OrderOfMagnitude(digits) > 0) return ParseResult::kNotFinite;
    value = digits.front() == '-' ? -0.0 : 0.0;  // underflow: as strtod, round to zero
    return ParseResult::kOk;
  }
  if (ec != std::errc()) return ParseResult::kNotANumber;
  return std::isfinite(value) ? ParseResult::kOk : ParseResult::kNotFinite;
}

bool IsBlank(std::string_view line) { return TrimBlanks(line).empty(); }

// Cuts the next line (without its '\n') from `rest`.
std::string_view NextLine(std::string_view& rest) {
  const std::size_t newline = rest.find('\n');
  std::string_view line = rest.substr(0, newline);
  rest.remove_prefix(newline == std::string_view::npos ? rest.size() : newline + 1);
  return line;
}

}  // namespace

NumericTable ReadCsv(const std::string& path, const std::vector<std::string>& select) {
  for (std::size_t k = 0; k < select.size(); ++k) {
    for (std::size_t i = 0; i < k; ++i) {
      SECURE_CHECK(select[i] != select[k],
                   path << ": column '" << Shown(select[k])
                        << "' is selected twice (selection: " << ShownHeader(select) << ")");
    }
  }
  CheckNotADirectory(path);
  const std::string content = ReadFile(path);
  std::string_view rest = content;
  if (rest.substr(0, kUtf8Bom.size()) == kUtf8Bom) rest.remove_prefix(kUtf8Bom.size());

  // Trailing blank lines (an editor's extra newline) are dropped here; any blank line left
  // before the last non-blank one is a data row with the wrong number of cells.
  while (!rest.empty()) {
    const std::size_t last_newline = rest.rfind('\n');
    const std::size_t start = last_newline == std::string_view::npos ? 0 : last_newline + 1;
    if (!IsBlank(rest.substr(start))) break;
    rest = rest.substr(0, last_newline == std::string_view::npos ? 0 : last_newline);
  }
  SECURE_CHECK(!rest.empty(), path << ": file is empty (no header row)");

  // Header. A name may be wrapped in double quotes (spreadsheet exports); commas inside quotes
  // are not supported since the files are numeric.
  std::vector<std::string_view> cells;
  SplitCells(NextLine(rest), cells);
  std::vector<std::string> header;
  header.reserve(cells.size());
  std::unordered_map<std::string_view, std::size_t> index_of;
  for (std::size_t j = 0; j < cells.size(); ++j) {
    std::string_view name = TrimBlanks(cells[j]);
    if (name.size() >= 2 && name.front() == '"' && name.back() == '"') {
      name = TrimBlanks(name.substr(1, name.size() - 2));
    }
    SECURE_CHECK(!name.empty(), path << ":1: header column " << j + 1 << " is empty");
    SECURE_CHECK(name.find('\0') == std::string_view::npos,
                 path << ":1: header column " << j + 1 << " '" << Shown(name)
                      << "' contains a NUL byte (is this a binary file?)");
    header.emplace_back(name);
  }
  for (std::size_t j = 0; j < header.size(); ++j) {
    const auto [it, inserted] = index_of.emplace(header[j], j);
    SECURE_CHECK(inserted, path << ":1: header column " << j + 1 << " '" << Shown(header[j])
                                << "' duplicates column " << it->second + 1);
  }

  NumericTable table;
  table.source = path;
  std::vector<std::size_t> selected;  // file column of each selected column
  if (select.empty()) {
    table.columns = header;
    for (std::size_t j = 0; j < header.size(); ++j) selected.push_back(j);
  } else {
    table.columns = select;
    for (const std::string& name : select) {
      const auto it = index_of.find(name);
      SECURE_CHECK(it != index_of.end(),
                   path << ": column '" << Shown(name)
                        << "' not found; the header has: " << ShownHeader(header));
      selected.push_back(it->second);
    }
  }

  // Rows. Only the selected cells are parsed: other columns may hold anything (labels, notes)
  // as long as each row has the header's number of cells.
  const std::size_t num_cells = header.size();
  const std::size_t num_selected = selected.size();
  const std::size_t max_rows =
      static_cast<std::size_t>(std::count(rest.begin(), rest.end(), '\n') + (rest.empty() ? 0 : 1));
  std::vector<double> values;  // row-major rows x selected == column-major selected x rows
  values.reserve(max_rows * num_selected);
  table.lines.reserve(max_rows);
  long line_number = 1;
  while (!rest.empty()) {
    const std::string_view line = NextLine(rest);
    ++line_number;
    SplitCells(line, cells);
    SECURE_CHECK(cells.size() == num_cells, path << ":" << line_number << ": expected " << num_cells
                                                 << " cells (as in the header), found "
                                                 << cells.size());
    for (std::size_t k = 0; k < num_selected; ++k) {
      const std::string_view cell = TrimBlanks(cells[selected[k]]);
      double value = 0.0;
      const ParseResult result = ParseDouble(cell, value);
      SECURE_CHECK(result != ParseResult::kNotANumber, path << ":" << line_number << ": column '"
                                                            << table.columns[k] << "': value '"
                                                            << Shown(cell) << "' is not a number");
      SECURE_CHECK(result != ParseResult::kNotFinite, path << ":" << line_number << ": column '"
                                                           << table.columns[k] << "': value '"
                                                           << Shown(cell) << "' is not finite");
      values.push_back(value);
    }
    table.lines.push_back(line_number);
  }
  SECURE_CHECK(!table.lines.empty(), path << ": no data rows");

  const Eigen::Index rows = static_cast<Eigen::Index>(table.lines.size());
  table.values = Eigen::Map<const Eigen::MatrixXd>(values.data(),
                                                   static_cast<Eigen::Index>(num_selected), rows);
  return table;
}

void WriteCsv(const std::string& path, const std::vector<std::string>& columns,
              const Eigen::Ref<const Eigen::MatrixXd>& values) {
  SECURE_CHECK(!columns.empty(), "cannot write '" << path << "': no columns");
  SECURE_CHECK(static_cast<Eigen::Index>(columns.size()) == values.rows(),
               "cannot write '" << path << "': " << columns.size() << " column names for "
                                << values.rows() << " value rows");
  std::string out;
  for (std::size_t j = 0; j < columns.size(); ++j) {
    const std::string& name = columns[j];
    // Such a name would not read back as the same header.
    SECURE_CHECK(!name.empty() && name.find_first_of(",\"\r\n") == std::string::npos &&
                     TrimBlanks(name) == name,
                 "cannot write '" << path << "': column name " << j + 1 << " '" << name
                                  << "' is empty, has surrounding blanks or contains a comma, "
                                     "quote or newline");
    if (j > 0) out += ',';
    out += name;
  }
  out += '\n';

  // Shortest round-trip formatting: reads back bit-exactly and is at most 24 characters.
  out.reserve(out.size() + static_cast<std::size_t>(values.size()) * 24);
  char buffer[32];
  for (Eigen::Index row = 0; row < values.cols(); ++row) {
    for (Eigen::Index j = 0; j < values.rows(); ++j) {
      const double value = values(j, row);
      SECURE_CHECK(std::isfinite(value),
                   "cannot write '" << path << "': value " << value << " in column '" << columns[j]
                                    << "', row " << row << " (0-based) is not finite");
      if (j > 0) out += ',';
      const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
      SECURE_INTERNAL_CHECK(result.ec == std::errc(), "to_chars failed");
      out.append(buffer, result.ptr);
    }
    out += '\n';
  }
  WriteFileAtomically(path, out);
}

}  // namespace secure::data
