// KitchenCuttingDomain's labeller (experiments::Domain::Label): the person who made the
// near-dangerous states judges any state by the same rule (JudgeKitchenState, data.h).
#include <sstream>

#include "domains/kitchen_cutting/domain.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"

namespace secure::domains::kitchen_cutting {
namespace {
// The label noise's stream (seed ^ salt): apart from the data's streams of the same seed.
constexpr std::uint64_t kLabelNoiseSalt = 0x1abe1'c0770ULL;
}  // namespace

std::vector<int> KitchenCuttingDomain::Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                             std::uint64_t seed) const {
  options_.Validate();
  experiments::CheckLabellerStates(name(), states, kitchen_cutting::ObservationFeatures());
  const KitchenNearDangerousOptions& rule = options_.near_dangerous;
  Rng noise(seed ^ kLabelNoiseSalt);
  std::vector<int> labels(static_cast<std::size_t>(states.cols()));
  for (long i = 0; i < states.cols(); ++i) {
    const bool safe =
        JudgeKitchenState(options_.task, rule, states.col(i)) == KitchenJudgement::kSafe;
    const bool flip = noise.Uniform() < rule.label_noise;  // one draw per state, always
    labels[static_cast<std::size_t>(i)] = safe != flip ? 1 : 0;
  }
  return labels;
}

std::string KitchenCuttingDomain::LabellerDescription() const {
  const KitchenNearDangerousOptions& rule = options_.near_dangerous;
  std::ostringstream s;
  s << "the person who made the near-dangerous states: near-dangerous if the blade's edge is "
       "within "
    << options_.task.contact_distance
    << " m of the arm, or comes within it when a stroke (down at >= " << rule.stroke_vz[0]
    << " m/s) continues to the board, the arm moves on at its velocity for " << rule.look_ahead
    << " s, or the knife moves on at its velocity for " << rule.look_ahead
    << " s; else safe; answers flipped with probability " << rule.label_noise;
  return s.str();
}

}  // namespace secure::domains::kitchen_cutting
