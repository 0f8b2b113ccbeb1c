// CreateDirectories and CheckNotADirectory: errors name the path and the reason; Excerpt: text
// from files quoted in messages is bounded and printable; CheckNoDuplicateKeys: YAML duplicates.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "secure/common/error.h"
#include "secure/common/excerpt.h"
#include "secure/common/filesystem.h"
#include "secure/common/yaml_keys.h"
#include "secure/common/yaml_value.h"
#include "tests/test_util.h"

namespace secure {
namespace {

namespace fs = std::filesystem;
using test::ErrorOf;

class FilesystemTest : public test::TempDirTest {};

TEST_F(FilesystemTest, CreateDirectoriesMakesParentsAndAcceptsAnExistingDirectory) {
  const std::string dir = PathOf("a/b/c");
  CreateDirectories(dir);
  EXPECT_TRUE(fs::is_directory(dir));
  CreateDirectories(dir);  // again: fine
  CreateDirectories("");   // nothing to do
}

TEST_F(FilesystemTest, CreateDirectoriesOnAFileNamesThePathAndTheReason) {
  const std::string file = PathOf("file");
  std::ofstream(file) << "x";
  EXPECT_EQ(ErrorOf([&] { CreateDirectories(file); }),
            "cannot create directory '" + file + "': File exists (not a directory)");
  const std::string below = file + "/sub/dir";
  EXPECT_EQ(ErrorOf([&] { CreateDirectories(below); }),
            "cannot create directory '" + below + "': '" + file + "' is not a directory");
  EXPECT_TRUE(fs::is_regular_file(file));  // untouched
}

TEST_F(FilesystemTest, CreateDirectoriesWhereNothingCanBeCreatedIsAnError) {
  // /proc refuses new directories even to root.
  const std::string message = ErrorOf([] { CreateDirectories("/proc/secure-test/x"); });
  EXPECT_NE(message.find("cannot create directory '/proc/secure-test/x': "), std::string::npos)
      << message;
}

TEST_F(FilesystemTest, CheckNotADirectory) {
  EXPECT_EQ(ErrorOf([&] { CheckNotADirectory(dir_.string()); }),
            "cannot read '" + dir_.string() + "': is a directory, not a file");
  const std::string file = PathOf("f.csv");
  std::ofstream(file) << "x";
  CheckNotADirectory(file);
  CheckNotADirectory(PathOf("missing.csv"));  // opening it reports that
}

TEST(ExcerptTest, ShortPrintableTextIsUnchanged) {
  EXPECT_EQ(Excerpt("x,y,vx"), "x,y,vx");
  EXPECT_EQ(Excerpt(""), "");
  EXPECT_EQ(Excerpt("température"), "température");  // valid UTF-8 is kept
}

TEST(ExcerptTest, ControlAndInvalidBytesAreEscaped) {
  EXPECT_EQ(Excerpt(std::string("a\0b", 3)), "a\\0b");
  EXPECT_EQ(Excerpt("a\nb\tc\r"), "a\\nb\\tc\\r");
  EXPECT_EQ(Excerpt("\x01\x7f"), "\\x01\\x7F");
  EXPECT_EQ(Excerpt("\xff\xfe"), "\\xFF\\xFE");
  EXPECT_EQ(Excerpt("\xc3"), "\\xC3");  // a cut UTF-8 sequence
}

TEST(ExcerptTest, LongTextIsCutWithAnEllipsis) {
  const std::string long_text(1000, 'a');
  EXPECT_EQ(Excerpt(long_text), std::string(kExcerptMaxChars, 'a') + "\u2026");
  EXPECT_EQ(Excerpt(std::string(kExcerptMaxChars, 'b')), std::string(kExcerptMaxChars, 'b'));
  // Escapes count with their length, so binary input stays within the bound too.
  const std::string binary(1000, '\0');
  const std::string shown = Excerpt(binary, 10);
  EXPECT_EQ(shown, "\\0\\0\\0\\0\\0\u2026");
}

TEST(YamlKeysTest, DuplicateKeysAtAnyDepthNameTheLines) {
  EXPECT_EQ(ErrorOf([] {
              CheckNoDuplicateKeys(YAML::Load("trainer:\n  hidden: [4]\ntrainer:\n  x: 1\n"),
                                   "c.yaml");
            }),
            "c.yaml:3: duplicate key 'trainer' (first at line 1)");
  EXPECT_EQ(ErrorOf([] {
              CheckNoDuplicateKeys(YAML::Load("pipeline:\n  bc:\n    epochs: 1\n    epochs: 2\n"),
                                   "c.yaml");
            }),
            "c.yaml:4: duplicate key 'epochs' (first at line 3)");
  EXPECT_EQ(ErrorOf([] { CheckNoDuplicateKeys(YAML::Load("a:\n  - {k: 1, k: 2}\n"), "c.yaml"); }),
            "c.yaml:2: duplicate key 'k' (first at line 2)");
  // The same key in different mappings is fine.
  CheckNoDuplicateKeys(YAML::Load("a:\n  k: 1\nb:\n  k: 2\n"), "c.yaml");
}

// Found by yaml_options_fuzz (corpus/yaml_options_fuzz/complex_key.yaml): a sequence used as a
// key made every ApplyYaml throw yaml-cpp's TypedBadConversion instead of secure::Error.
TEST(YamlKeysTest, AKeyThatIsNotAPlainNameIsAnErrorNamingTheLine) {
  const YAML::Node root = YAML::Load("derby:\n  ? [a, b]\n  : 1\n");
  for (const auto& item : root["derby"]) {
    EXPECT_EQ(ErrorOf([&] { YamlKey(item.first, "c.yaml"); }),
              "c.yaml:2: a key must be a plain name, not a sequence");
  }
  EXPECT_EQ(YamlKey(YAML::Load("{epochs: 3}").begin()->first, "c.yaml"), "epochs");
}

}  // namespace
}  // namespace secure
