#include "secure/common/enum_strings.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <string>

#include "secure/common/error.h"
#include "secure/nn/mlp.h"  // header only: kActivationNames is an inline constexpr table

namespace secure {
namespace {

using nn::Activation;
using nn::kActivationNames;

using secure::test::ErrorOf;

enum class Color { kRed, kGreen, kBlue };
constexpr EnumTable<Color, 3> kColorNames{{
    {Color::kRed, "red"},
    {Color::kGreen, "green"},
    {Color::kBlue, "blue"},
}};

TEST(EnumStringsTest, ActivationNamesAreTheDocumentedStrings) {
  EXPECT_EQ(ToString(kActivationNames, Activation::kRelu), "relu");
  EXPECT_EQ(ToString(kActivationNames, Activation::kTanh), "tanh");
}

TEST(EnumStringsTest, ActivationRoundTripsThroughItsName) {
  for (const auto& entry : kActivationNames) {
    const Activation a = entry.first;
    EXPECT_EQ(FromString(kActivationNames, ToString(kActivationNames, a), "activation"), a);
  }
  EXPECT_EQ(FromString(kActivationNames, "relu", "activation"), Activation::kRelu);
  EXPECT_EQ(FromString(kActivationNames, "tanh", "activation"), Activation::kTanh);
}

TEST(EnumStringsTest, EveryEntryOfALargerTableRoundTrips) {
  for (Color c : {Color::kRed, Color::kGreen, Color::kBlue})
    EXPECT_EQ(FromString(kColorNames, ToString(kColorNames, c), "color"), c);
  EXPECT_EQ(ToString(kColorNames, Color::kBlue), "blue");  // last entry, not the first
}

TEST(EnumStringsTest, UnknownNameThrowsListingFieldValueAndChoices) {
  const std::string message =
      ErrorOf([] { FromString(kActivationNames, "sigmoid", "activation"); });
  EXPECT_HAS(message, "activation");
  EXPECT_HAS(message, "sigmoid");
  EXPECT_HAS(message, "relu");
  EXPECT_HAS(message, "tanh");
  EXPECT_HAS(message, "relu, tanh");
}

TEST(EnumStringsTest, MatchingIsExactAndCaseSensitive) {
  for (const char* bad : {"Relu", "RELU", "relu ", " tanh", "rel", "tanhh", ""}) {
    const std::string message = ErrorOf([&] { FromString(kActivationNames, bad, "activation"); });
    EXPECT_HAS(message, std::string("'") + bad + "'");
  }
}

TEST(EnumStringsTest, ErrorListsEveryChoiceOfTheTable) {
  const std::string message = ErrorOf([] { FromString(kColorNames, "purple", "net.color"); });
  EXPECT_HAS(message, "net.color = 'purple'");
  EXPECT_HAS(message, "red, green, blue");
}

TEST(EnumStringsTest, NameOfIsTheTablesNameAsACStringElseTheUnknownText) {
  EXPECT_STREQ(NameOf(kColorNames, Color::kGreen), "green");
  EXPECT_STREQ(NameOf(kColorNames, Color::kBlue), "blue");
  EXPECT_STREQ(NameOf(kColorNames, static_cast<Color>(42)), "?");
  EXPECT_STREQ(NameOf(kColorNames, static_cast<Color>(42), "none"), "none");
}

TEST(EnumStringsDeathTest, ToStringOfAValueMissingFromTheTableAborts) {
  // A value outside the table is a bug in our code (an internal check), not a user error.
  EXPECT_DEATH(ToString(kActivationNames, static_cast<Activation>(42)), "missing from its name");
}

}  // namespace
}  // namespace secure
