#include "domains/franka/arm_shield_model.h"

#include <cmath>

#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"

namespace secure::domains::franka {

void EndEffectorGains::Validate(const char* o) const {
  SECURE_CHECK_FIELD(std::isfinite(position_gain) && position_gain >= 0, o, "position_gain",
                     position_gain, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(velocity_gain) && velocity_gain >= 0, o, "velocity_gain",
                     velocity_gain, ">= 0");
}

void EndEffectorGains::AddFields(YamlFields* fields) {
  fields->Field("position_gain", &position_gain).Field("velocity_gain", &velocity_gain);
}

void PersonShieldModelOptions::Validate(const char* o) const {
  EndEffectorGains::Validate(o);
  SECURE_CHECK_FIELD(std::isfinite(dt) && dt > 0, o, "dt", dt, "> 0 s");
}

void PersonShieldModelOptions::CheckControlPeriod(const char* owner, double control_period) const {
  SECURE_CHECK_FIELD(std::abs(dt - control_period) < 1e-12, owner, "shield_model.dt", dt,
                     "the control period (" << control_period << " s)");
}

YamlFields PersonShieldModelOptions::Fields() {
  YamlFields fields;
  AddFields(&fields);
  fields.Field("dt", &dt);
  return fields;
}

SECURE_YAML_JSON_FROM_FIELDS(PersonShieldModelOptions)

}  // namespace secure::domains::franka
