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
#include "secure/common/error.h"

#define SECURE_CHECK_FIELD(cond, owner, field, value, rule) \
  SECURE_CHECK(cond, owner << "::" << field << " = " << value << ", must be " << rule)
