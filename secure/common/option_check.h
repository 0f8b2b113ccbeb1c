#pragma once
// The one check every Validate() uses: an option field against its rule, with a message that
// names the options type, the field, the value and the rule.
//
//   SECURE_CHECK_FIELD(lr > 0, "BarrierTrainerOptions", "lr", lr, "> 0");
//   // throws secure::Error("BarrierTrainerOptions::lr = -1, must be > 0")
//   SECURE_CHECK_FIELD(n <= kMax, "ExperimentOptions", "seeds", n, "in [1, " << kMax << "]");
//
// `owner` is anything streamable (a type name, or "source: section" for a nested block); `rule`
// may stream several pieces.
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/limits.h"

#define SECURE_CHECK_FIELD(cond, owner, field, value, rule) \
  SECURE_CHECK(cond, owner << "::" << field << " = " << value << ", must be " << rule)

namespace secure {

/// An interval option [lo, hi] (e.g. a range a value is drawn from): finite, lo <= hi, within
/// [min, max]. Throws "Owner::field = [lo, hi], must be an interval [lo, hi] with lo <= hi
/// within [min, max]".
inline void CheckIntervalField(const std::array<double, 2>& r, const char* owner, const char* field,
                               double min, double max) {
  SECURE_CHECK_FIELD(
      std::isfinite(r[0]) && std::isfinite(r[1]) && r[0] <= r[1] && r[0] >= min && r[1] <= max,
      owner, field, "[" << r[0] << ", " << r[1] << "]",
      "an interval [lo, hi] with lo <= hi within [" << min << ", " << max << "]");
}

/// An MLP's hidden layer widths (the trainers' `hidden` fields): non-empty, each in
/// [1, kMaxLayerWidth]. Throws "Owner::field[i] = w, must be ..." for the first one out of range.
inline void CheckLayerWidths(const std::vector<int>& widths, const char* owner,
                             const std::string& field) {
  SECURE_CHECK_FIELD(!widths.empty(), owner, field, "[]", "a non-empty list of layer widths");
  for (std::size_t i = 0; i < widths.size(); ++i) {
    SECURE_CHECK_FIELD(widths[i] > 0, owner, field << "[" << i << "]", widths[i], "> 0");
    SECURE_CHECK_FIELD(widths[i] <= kMaxLayerWidth, owner, field << "[" << i << "]", widths[i],
                       "in [1, " << kMaxLayerWidth << "]");
  }
}

/// A list of feature names (the trainers' `input_features`): each non-empty and given once.
/// Throws "Owner::field[k] = 'name', must be ..." for the first one that is not.
inline void CheckFeatureNames(const std::vector<std::string>& names, const char* owner,
                              const std::string& field) {
  for (std::size_t k = 0; k < names.size(); ++k) {
    SECURE_CHECK_FIELD(!names[k].empty(), owner, field << "[" << k << "]", "''",
                       "a non-empty feature name");
    for (std::size_t i = 0; i < k; ++i)
      SECURE_CHECK_FIELD(names[i] != names[k], owner, field << "[" << k << "]",
                         "'" << names[k] << "'",
                         "a name not given before (it is also " << field << "[" << i << "])");
  }
}

}  // namespace secure
