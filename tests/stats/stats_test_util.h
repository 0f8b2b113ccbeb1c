#pragma once
// The reference samples and tolerances of the statistics tests (statistics_test.cc,
// within_subject_test.cc in the stats_test program).
// Each file: #include "tests/stats/stats_test_util.h", then `using namespace test;` in
// secure::stats.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "secure/stats/statistics.h"
#include "tests/test_util.h"

namespace secure::stats::test {

using secure::test::ErrorOf;

// Reference values in these files were computed with SciPy 1.10 (scipy.stats.mannwhitneyu,
// kruskal, rankdata, t, norm); Dunn and TOST by their textbook formulas on top of those.
inline const std::vector<double> kA = {0.49, 0.55, 0.42, 0.51, 0.47, 0.58, 0.44, 0.53, 0.50, 0.46};
inline const std::vector<double> kB = {0.47, 0.52, 0.41, 0.45, 0.49, 0.43, 0.50, 0.48, 0.39, 0.46};
inline const std::vector<double> kC = {0.31, 0.36, 0.29, 0.40, 0.33, 0.27, 0.35, 0.30, 0.38, 0.32};
inline const std::vector<double> kD = {0.28, 0.33, 0.30, 0.35, 0.31, 0.29, 0.34, 0.32, 0.36, 0.30};

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
inline constexpr double kInf = std::numeric_limits<double>::infinity();

inline constexpr double kStatTol = 1e-6;  // statistics: relative
inline constexpr double kPTol = 1e-5;     // p-values: relative

}  // namespace secure::stats::test

// |actual - expected| <= rel * |expected|, printed with both values.
#define EXPECT_REL(actual, expected, rel) \
  EXPECT_NEAR((actual), (expected), (rel)*std::abs(static_cast<double>(expected)))
