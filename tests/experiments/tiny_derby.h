#pragma once
// The Derby domain on its quick profile, made smaller still, shared by the experiment tests (the
// domain's options are not changed by a test).
#include "domains/derby/domain.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::test {

inline const secure::domains::derby::DerbyDomain& TinyDerby() {
  static const secure::domains::derby::DerbyDomain domain = [] {
    secure::domains::derby::DerbyDomain d(experiments::Profile::kQuick);
    d.mutable_options().demonstrations.episodes = 12;
    d.mutable_options().safe_states = 200;
    d.mutable_options().near_dangerous.count = 200;
    return d;
  }();
  return domain;
}

/// Its preset with 4 episodes and one short AIRL iteration, quiet.
inline experiments::ExperimentOptions TinyDerbyOptions() {
  experiments::ExperimentOptions o = TinyDerby().Preset();
  o.episodes = 4;
  o.airl.iterations = 1;
  o.airl.steps_per_iteration = 400;
  o.verbose = false;
  return o;
}

}  // namespace secure::test
