#include "domains/franka/arm_tracking.h"

#include <cmath>

#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"

namespace secure::domains::franka {

void ArmTracking::Validate(const char* o) const {
  SECURE_CHECK_FIELD(std::isfinite(control_period) && control_period > 0 && control_period <= 1, o,
                     "control_period", control_period, "in (0, 1] s");
  SECURE_CHECK_FIELD(substeps >= 1 && substeps <= 1000, o, "substeps", substeps, "in [1, 1000]");
  SECURE_CHECK_FIELD(control_period / substeps <= 0.005, o, "substeps", substeps,
                     "large enough for a physics step <= 5 ms (control_period / substeps; "
                     "the contacts are unstable beyond)");
  SECURE_CHECK_FIELD(std::isfinite(tracking_omega) && tracking_omega > 0 &&
                         tracking_omega * control_period / substeps < 0.5,
                     o, "tracking_omega", tracking_omega,
                     "> 0 and < 0.5 / physics step (explicit integration stays stable)");
  SECURE_CHECK_FIELD(std::isfinite(ik_damping) && ik_damping > 0 && ik_damping < 1, o, "ik_damping",
                     ik_damping, "in (0, 1)");
}

void ArmTracking::AddFields(YamlFields* fields) {
  fields->Field("control_period", &control_period)
      .Field("substeps", &substeps)
      .Field("tracking_omega", &tracking_omega)
      .Field("ik_damping", &ik_damping);
}

void ArmTaskOptions::Validate(const char* o) const {
  SECURE_CHECK_FIELD(max_steps > 0 && max_steps <= 100000, o, "max_steps", max_steps,
                     "in [1, 100000]");
  tracking.Validate(o);
  SECURE_CHECK_FIELD(std::isfinite(action_scale) && action_scale > 0 && action_scale <= 0.2, o,
                     "action_scale", action_scale, "in (0, 0.2] m");
}

void ArmTaskOptions::AddFields(YamlFields* fields) {
  tracking.AddFields(fields);
  fields->Field("max_steps", &max_steps).Field("action_scale", &action_scale);
}

}  // namespace secure::domains::franka
