#include "domains/franka/arm_domain.h"

namespace secure::domains::franka {

experiments::LabelCheckRow LabelRow(const std::string& set, const std::string& label, long states,
                                    long dangerous, long skipped) {
  return experiments::LabelCheckRow{set, label, states, dangerous, skipped};
}

data::StateSet SelectStates(const data::StateSet& from, const std::vector<long>& columns) {
  data::StateSet s;
  s.features = from.features;
  s.source = from.source;
  s.states = data::SelectColumns(from.states, columns);
  return s;
}

}  // namespace secure::domains::franka
