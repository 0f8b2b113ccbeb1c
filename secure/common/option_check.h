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

#include "secure/common/error.h"

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

}  // namespace secure
