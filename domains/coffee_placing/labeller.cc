// CoffeePlacingDomain's labeller (experiments::Domain::Label): the mean participant, who made
// the domain's data, judges any state by their thresholds and answers with their label noise
// (ParticipantAnswersUnsafe, participants.h).
#include <sstream>

#include "domains/coffee_placing/domain.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"

namespace secure::domains::coffee_placing {
namespace {
// The label noise's stream (seed ^ salt): apart from the data's streams of the same seed.
constexpr std::uint64_t kLabelNoiseSalt = 0x1abe1'c0ffeeULL;
}  // namespace

std::vector<int> CoffeePlacingDomain::Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                            std::uint64_t seed) const {
  options_.Validate();
  experiments::CheckLabellerStates(name(), states, coffee_placing::ObservationFeatures());
  const coffee_placing::Participant person = MeanParticipant(options_.population);
  Rng noise(seed ^ kLabelNoiseSalt);
  std::vector<int> labels(static_cast<std::size_t>(states.cols()));
  for (long i = 0; i < states.cols(); ++i)
    labels[static_cast<std::size_t>(i)] =
        ParticipantAnswersUnsafe(options_.task.person, person, states.col(i), noise) ? 0 : 1;
  return labels;
}

std::string CoffeePlacingDomain::LabellerDescription() const {
  const coffee_placing::Participant p = MeanParticipant(options_.population);
  std::ostringstream s;
  s << "the mean participant (who made the data): unsafe if the robot's hand-and-cup is within "
    << p.thresholds.comfort_distance << " m of the arm (clearance recomputed from the positions) "
    << "or |tilt| > " << p.thresholds.max_tilt << " rad, else safe; answers flipped with "
    << "probability " << p.label_noise << " (their label noise)";
  return s.str();
}

}  // namespace secure::domains::coffee_placing
