#include "secure/common/option_check.h"

#include <gtest/gtest.h>

#include <string>

#include "tests/test_util.h"

namespace secure {
namespace {

using secure::test::ErrorOf;

TEST(OptionCheckTest, MessageNamesOwnerFieldValueAndRule) {
  const double lr = -1;
  EXPECT_EQ(ErrorOf([&] { SECURE_CHECK_FIELD(lr > 0, "BarrierTrainerOptions", "lr", lr, "> 0"); }),
            "BarrierTrainerOptions::lr = -1, must be > 0");
}

TEST(OptionCheckTest, OwnerFieldAndRuleMayStreamSeveralPieces) {
  const std::string what = "model.pt";
  const int i = 2, width = 0, max = 4096;
  EXPECT_EQ(ErrorOf([&] {
              SECURE_CHECK_FIELD(width > 0, what << ": layout", "hidden[" << i << "]", width,
                                 "in [1, " << max << "]");
            }),
            "model.pt: layout::hidden[2] = 0, must be in [1, 4096]");
}

TEST(OptionCheckTest, PassingCheckEvaluatesNeitherValueNorRule) {
  int evaluated = 0;
  auto count = [&] { return ++evaluated; };
  SECURE_CHECK_FIELD(true, "Options", "field", count(), "> " << count());
  EXPECT_EQ(evaluated, 0);
}

}  // namespace
}  // namespace secure
