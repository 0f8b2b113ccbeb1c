// Tests of ReadCsv and WriteCsv: round trips, column selection, and one test per rejection,
// each checking that the message names the file, line, column and value.

#include <unistd.h>

#include <chrono>
#include <clocale>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "tests/test_util.h"

namespace secure::data {
namespace {

namespace fs = std::filesystem;

class CsvTest : public secure::test::TempDirTest {};

using secure::test::ErrorOf;
using secure::test::ExpectContainsAll;

constexpr char kHeader[] = "x,y,vx,vy\n";

TEST_F(CsvTest, RoundTripIsBitExactForDoubles) {
  Rng rng(7);
  Eigen::MatrixXd values(3, 50);
  for (Eigen::Index i = 0; i < values.size(); ++i) {
    values(i) = rng.Normal() * std::pow(10.0, rng.Uniform(-30.0, 30.0));
  }
  values(0, 0) = 0.1;
  values(1, 0) = 1.0 / 3.0;
  values(2, 0) = -0.0;
  values(0, 1) = std::numeric_limits<double>::max();
  values(1, 1) = std::numeric_limits<double>::denorm_min();
  values(2, 1) = -std::numeric_limits<double>::min();
  values(0, 2) = static_cast<double>(0.1f);
  const std::string path = PathOf("round_trip.csv");
  WriteCsv(path, {"a", "b", "c"}, values);

  const NumericTable table = ReadCsv(path);
  EXPECT_EQ(table.source, path);
  EXPECT_EQ(table.columns, (std::vector<std::string>{"a", "b", "c"}));
  ASSERT_EQ(table.values.rows(), 3);
  ASSERT_EQ(table.values.cols(), 50);
  for (Eigen::Index i = 0; i < values.size(); ++i) {
    EXPECT_EQ(table.values(i), values(i)) << "entry " << i;
    EXPECT_EQ(std::signbit(table.values(i)), std::signbit(values(i))) << "entry " << i;
  }
  EXPECT_EQ(table.lines.front(), 2);
  EXPECT_EQ(table.lines.back(), 51);
}

TEST_F(CsvTest, WriteCsvWritesHeaderThenOneRowPerColumn) {
  Eigen::MatrixXd values(2, 3);
  values << 1, 2.5, -3, 0.25, 1e-7, 100;
  const std::string path = PathOf("out.csv");
  WriteCsv(path, {"p", "q"}, values);
  EXPECT_EQ(ReadFile(path), "p,q\n1,0.25\n2.5,1e-07\n-3,100\n");
}

TEST_F(CsvTest, ReadsAllColumnsInFileOrderWithLineNumbers) {
  const std::string path = Write("data.csv", "a,b\n1,2\n3,4\n5,6\n");
  const NumericTable table = ReadCsv(path);
  EXPECT_EQ(table.columns, (std::vector<std::string>{"a", "b"}));
  Eigen::MatrixXd expected(2, 3);
  expected << 1, 3, 5, 2, 4, 6;
  EXPECT_EQ(table.values, expected);
  EXPECT_EQ(table.lines, (std::vector<long>{2, 3, 4}));
}

TEST_F(CsvTest, SelectionPicksAndReordersColumns) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2,3,4\n5,6,7,8\n");
  const NumericTable table = ReadCsv(path, {"vy", "x"});
  EXPECT_EQ(table.columns, (std::vector<std::string>{"vy", "x"}));
  Eigen::MatrixXd expected(2, 2);
  expected << 4, 8, 1, 5;
  EXPECT_EQ(table.values, expected);
}

TEST_F(CsvTest, UnselectedColumnsNeedNotBeNumeric) {
  const std::string path = Write("data.csv", "label,x\nsafe,1\nunsafe,2\n");
  const NumericTable table = ReadCsv(path, {"x"});
  EXPECT_EQ(table.values, (Eigen::MatrixXd(1, 2) << 1, 2).finished());
  EXPECT_NE(ErrorOf([&] { ReadCsv(path); }).find("'safe'"), std::string::npos);
}

TEST_F(CsvTest, AcceptsBlanksAroundCellsPlusSignAndExponents) {
  const std::string path = Write("data.csv", " a ,\tb\n  1.5 ,\t+2e3 \n-.5,1E-2\n");
  const NumericTable table = ReadCsv(path);
  EXPECT_EQ(table.columns, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(table.values, (Eigen::MatrixXd(2, 2) << 1.5, -0.5, 2000, 0.01).finished());
}

TEST_F(CsvTest, AcceptsCrlfLineEndings) {
  const std::string path = Write("crlf.csv", "a,b\r\n1,2\r\n3,4\r\n");
  const NumericTable table = ReadCsv(path);
  EXPECT_EQ(table.columns, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(table.values, (Eigen::MatrixXd(2, 2) << 1, 3, 2, 4).finished());
}

TEST_F(CsvTest, AcceptsUtf8ByteOrderMark) {
  const std::string path = Write("bom.csv",
                                 "\xEF\xBB\xBF"
                                 "a,b\r\n1,2\r\n");
  const NumericTable table = ReadCsv(path, {"a"});
  EXPECT_EQ(table.columns, (std::vector<std::string>{"a"}));
  EXPECT_EQ(table.values, (Eigen::MatrixXd(1, 1) << 1).finished());
}

TEST_F(CsvTest, StripsQuotesAroundHeaderNames) {
  const std::string path = Write("quoted.csv", "\"a\", \"b c\"\n1,2\n");
  EXPECT_EQ(ReadCsv(path).columns, (std::vector<std::string>{"a", "b c"}));
}

TEST_F(CsvTest, IgnoresTrailingBlankLinesAndMissingFinalNewline) {
  EXPECT_EQ(ReadCsv(Write("trailing.csv", "a\n1\n2\n\n \r\n\n")).values.cols(), 2);
  EXPECT_EQ(ReadCsv(Write("no_newline.csv", "a,b\n1,2")).values.cols(), 1);
}

TEST_F(CsvTest, UnderflowReadsAsZero) {
  const NumericTable table = ReadCsv(Write("tiny.csv", "a,b\n1e-400,-1e-999\n"));
  EXPECT_EQ(table.values(0, 0), 0.0);
  EXPECT_EQ(table.values(1, 0), 0.0);
  EXPECT_TRUE(std::signbit(table.values(1, 0)));
}

TEST_F(CsvTest, ParsingIgnoresTheCLocale) {
  const char* previous = std::setlocale(LC_NUMERIC, nullptr);
  const std::string saved = previous ? previous : "C";
  if (std::setlocale(LC_NUMERIC, "de_DE.UTF-8") == nullptr &&
      std::setlocale(LC_NUMERIC, "fr_FR.UTF-8") == nullptr) {
    GTEST_SKIP() << "no locale with a decimal comma installed";
  }
  const std::string path = Write("data.csv", "a\n0.5\n");
  double value = 0.0;
  EXPECT_NO_THROW(value = ReadCsv(path).values(0, 0));
  std::setlocale(LC_NUMERIC, saved.c_str());
  EXPECT_EQ(value, 0.5);
}

TEST_F(CsvTest, RejectsNonNumericCell) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2,3,4\n1,2,abc,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":3:", "column 'vx'", "value 'abc'", "is not a number"});
}

TEST_F(CsvTest, RejectsCellWithTrailingGarbage) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2.5x,3,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":2:", "column 'y'", "value '2.5x'", "is not a number"});
}

TEST_F(CsvTest, RejectsEmptySelectedCell) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2,3,4\n1,,3,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":3:", "column 'y'", "value ''", "is not a number"});
}

TEST_F(CsvTest, RejectsNan) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2,nan,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":2:", "column 'vx'", "value 'nan'", "is not finite"});
}

TEST_F(CsvTest, RejectsInf) {
  const std::string path =
      Write("data.csv", std::string(kHeader) + "1,2,3,4\n5,6,7,8\ninf,2,3,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":4:", "column 'x'", "value 'inf'", "is not finite"});
}

TEST_F(CsvTest, RejectsNegativeInf) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,-inf,3,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":2:", "column 'y'", "value '-inf'", "is not finite"});
}

TEST_F(CsvTest, RejectsOverflow) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2,3,1e999\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":2:", "column 'vy'", "value '1e999'", "is not finite"});
}

TEST_F(CsvTest, RejectsRowWithTooFewCells) {
  const std::string path =
      Write("data.csv", std::string(kHeader) + "1,2,3,4\n1,2,3,4\n1,2,3,4\n1,2,3\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":5:", "expected 4 cells (as in the header), found 3"});
}

TEST_F(CsvTest, RejectsRowWithTooManyCells) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2,3,4,5\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path, {"x"}); }),
                    {path + ":2:", "expected 4 cells (as in the header), found 5"});
}

TEST_F(CsvTest, RejectsBlankLineBetweenRows) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2,3,4\n\n1,2,3,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":3:", "expected 4 cells (as in the header), found 1"});
}

TEST_F(CsvTest, RejectsUnknownColumnListingTheHeader) {
  const std::string path = Write("data.csv", std::string(kHeader) + "1,2,3,4\n");
  ExpectContainsAll(ErrorOf([&] {
                      ReadCsv(path, {"x", "vz"});
                    }),
                    {path + ": column 'vz' not found; the header has: x, y, vx, vy"});
}

TEST_F(CsvTest, RejectsEmptyFile) {
  const std::string path = Write("empty.csv", "");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }), {path + ": file is empty (no header row)"});
  const std::string blank = Write("blank.csv", "\n \r\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(blank); }), {blank + ": file is empty"});
}

TEST_F(CsvTest, RejectsHeaderWithoutRows) {
  const std::string path = Write("data.csv", kHeader);
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }), {path + ": no data rows"});
}

TEST_F(CsvTest, RejectsEmptyHeaderName) {
  const std::string path = Write("data.csv", "x,y,,vy\n1,2,3,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }), {path + ":1: header column 3 is empty"});
}

TEST_F(CsvTest, RejectsDuplicateHeaderName) {
  const std::string path = Write("data.csv", "x,y,vx,y\n1,2,3,4\n");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }),
                    {path + ":1:", "header column 4 'y'", "duplicates column 2"});
}

TEST_F(CsvTest, RejectsMissingFile) {
  const std::string path = PathOf("missing.csv");
  ExpectContainsAll(ErrorOf([&] { ReadCsv(path); }), {path});
}

TEST_F(CsvTest, RejectsADirectoryAsSuch) {
  const std::string dir = PathOf("states.csv");
  fs::create_directories(dir);
  const std::string message = ErrorOf([&] { ReadCsv(dir); });
  ExpectContainsAll(message, {dir, "is a directory"});
  EXPECT_EQ(message.find("empty"), std::string::npos) << message;
}

TEST_F(CsvTest, RejectsAColumnSelectedTwice) {
  const std::string path = Write("twice.csv", std::string(kHeader) + "1,2,3,4\n");
  ExpectContainsAll(ErrorOf([&] {
                      ReadCsv(path, {"x", "x", "vx", "vy"});
                    }),
                    {path + ": column 'x' is selected twice (selection: x, x, vx, vy)"});
}

TEST_F(CsvTest, QuotedFileContentIsBoundedAndPrintable) {
  // A binary file: one long "header line" with control bytes and a NUL.
  std::string binary =
      "\x7f"
      "ELF\x02\x01";
  binary += std::string("\0\0\0", 3);
  binary += std::string(5000, 'A') + "\n1\n";
  const std::string path = Write("binary.bin", binary);
  const std::string message = ErrorOf([&] { ReadCsv(path, {"x"}); });
  ExpectContainsAll(message, {path + ":1: header column 1 '\\x7FELF\\x02\\x01\\0\\0\\0AAA",
                              "\u2026' contains a NUL byte"});
  EXPECT_LT(message.size(), path.size() + 200) << message;
  // A long header without a NUL: the listed header is bounded too.
  const std::string wide = Write("wide.csv", std::string(5000, 'B') + "\x01,y\n1,2\n");
  const std::string m1 = ErrorOf([&] { ReadCsv(wide, {"x"}); });
  ExpectContainsAll(m1, {wide + ": column 'x' not found; the header has: BBBB", "\u2026"});
  EXPECT_LT(m1.size(), wide.size() + 200) << m1;

  // A long cell and a NUL inside a cell.
  const std::string cell = Write("cell.csv", "x\n" + std::string(500, '7') + "z\n");
  const std::string m2 = ErrorOf([&] { ReadCsv(cell); });
  ExpectContainsAll(m2, {cell + ":2: column 'x': value '7777", "\u2026' is not a number"});
  EXPECT_LT(m2.size(), cell.size() + 200) << m2;
  const std::string nul = Write("nul.csv", std::string("x\n1\0"
                                                       "2\n",
                                                       6));
  ExpectContainsAll(ErrorOf([&] { ReadCsv(nul); }), {"value '1\\02' is not a number"});
}

TEST_F(CsvTest, WriteRejectsNonFiniteValueNamingColumnAndRow) {
  Eigen::MatrixXd values = Eigen::MatrixXd::Zero(2, 4);
  values(1, 2) = std::numeric_limits<double>::quiet_NaN();
  const std::string path = PathOf("out.csv");
  ExpectContainsAll(ErrorOf([&] {
                      WriteCsv(path, {"a", "b"}, values);
                    }),
                    {path, "column 'b'", "row 2", "not finite"});
  EXPECT_FALSE(fs::exists(path));
  values(1, 2) = -std::numeric_limits<double>::infinity();
  ExpectContainsAll(ErrorOf([&] {
                      WriteCsv(path, {"a", "b"}, values);
                    }),
                    {"-inf", "column 'b'", "row 2"});
}

TEST_F(CsvTest, WriteRejectsColumnCountMismatch) {
  const std::string path = PathOf("out.csv");
  ExpectContainsAll(ErrorOf([&] {
                      WriteCsv(path, {"a", "b", "c"}, Eigen::MatrixXd::Zero(2, 4));
                    }),
                    {path, "3 column names for 2 value rows"});
}

TEST_F(CsvTest, WriteRejectsNamesThatWouldNotReadBack) {
  const std::string path = PathOf("out.csv");
  const Eigen::MatrixXd values = Eigen::MatrixXd::Zero(2, 1);
  ExpectContainsAll(ErrorOf([&] { WriteCsv(path, {"a", "b,c"}, values); }), {path, "'b,c'"});
  ExpectContainsAll(ErrorOf([&] { WriteCsv(path, {"a", ""}, values); }), {path, "name 2"});
  ExpectContainsAll(ErrorOf([&] { WriteCsv(path, {}, Eigen::MatrixXd(0, 1)); }),
                    {path, "no columns"});
}

TEST_F(CsvTest, ReadsRealNearDangerousStates) {
  const std::string path = SECURE_SHARED_DIR "/data/panda_push/near_dangerous_states.csv";
  if (!fs::exists(path)) GTEST_SKIP() << path << " not found";
  const std::vector<std::string> select = {"ee_x",  "ee_y",    "ee_z",    "ee_vx",  "ee_vy",
                                           "ee_vz", "block_x", "block_y", "block_z"};
  const auto start = std::chrono::steady_clock::now();
  const NumericTable table = ReadCsv(path, select);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  std::printf("read %ld rows of %s in %.2f ms\n", static_cast<long>(table.values.cols()),
              path.c_str(), ms);
  EXPECT_EQ(table.columns, select);
  EXPECT_EQ(table.values.rows(), 9);
  EXPECT_EQ(table.values.cols(), 4381);
  EXPECT_EQ(table.lines.back(), 4382);
  EXPECT_DOUBLE_EQ(table.values(0, 0), 0.31184911727905273);
  EXPECT_TRUE(table.values.allFinite());

  const NumericTable all = ReadCsv(path);
  EXPECT_EQ(all.values.rows(), 18);
  EXPECT_EQ(all.values.topRows(9), table.values);
}

}  // namespace
}  // namespace secure::data
