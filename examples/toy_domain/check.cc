// The toy cart's barrier check (Domain::HasCheck): what `secure cbf check --domain toy-cart` and
// an experiment with the check on run (cbf/barrier_check.h).
#include <algorithm>
#include <utility>

#include "examples/toy_domain/toy_cart.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/shield/shield.h"

namespace secure::examples::toy_cart {
namespace {
// The held-out states' stream: not the training data's for the same data seed.
constexpr std::uint64_t kCheckDataSalt = 0x70c7'c4ec'0000'0000ULL;
}  // namespace

void ToyCartDomain::CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                                 data::StateSet* near_dangerous) const {
  SECURE_CHECK(count > 0, "toy-cart barrier check: held-out count " << count << ", must be > 0");
  ToyCartDomain sized(*this);
  sized.options_.safe_states = count;
  sized.options_.near_dangerous = count;
  experiments::DomainData d = sized.GenerateData(data_seed ^ kCheckDataSalt);
  *safe = std::move(d.safe);
  *near_dangerous = std::move(d.near_dangerous);
  safe->source = "held-out safe states (data_seed " + std::to_string(data_seed) + ")";
  near_dangerous->source =
      "held-out near-dangerous states (data_seed " + std::to_string(data_seed) + ")";
}

cbf::BarrierCheckProblem ToyCartDomain::MakeCheckProblem(
    const shield::ShieldOptions& shield, const data::StateSet& safe,
    const data::StateSet& near_dangerous, std::unique_ptr<domains::DynamicsModel>* dynamics) const {
  SECURE_CHECK(safe.states.rows() == 2 && near_dangerous.states.rows() == 2,
               "the toy-cart barrier check needs observations (x, v); got "
                   << safe.states.rows() << " values (" << safe.source << ") and "
                   << near_dangerous.states.rows() << " (" << near_dangerous.source << ")");
  data::CheckNonEmptyFinite(safe, "toy-cart barrier check: safe states");
  data::CheckNonEmptyFinite(near_dangerous, "toy-cart barrier check: near-dangerous states");
  options_.Validate();
  shield.Validate();
  *dynamics = std::make_unique<ToyCartModel>(options_.dt, options_.accel_bound);
  cbf::BarrierCheckProblem p;
  p.action_lo = Eigen::VectorXf::Constant(1, -float(options_.accel_bound));
  p.action_hi = Eigen::VectorXf::Constant(1, float(options_.accel_bound));
  p.dt = shield.dt;
  p.class_k = [shield](double h) { return shield::ClassKValue(shield, h); };
  p.class_k_description = ToString(shield::kClassKNames, shield.class_k) + ", k = " +
                          std::to_string(shield.class_k_gain);
  p.near_dangerous = near_dangerous;
  p.held_out_safe = safe;
  p.held_out_near_dangerous = near_dangerous;
  const Eigen::MatrixXf safe_states = safe.states, nd_states = near_dangerous.states;
  p.sample_region = [safe_states, nd_states](Rng& rng, Eigen::Ref<Eigen::VectorXf> s) {
    const Eigen::MatrixXf& pool = rng.Uniform() < 0.5 ? safe_states : nd_states;
    s = pool.col(static_cast<long>(rng.UniformIndex(static_cast<std::uint64_t>(pool.cols()))));
    s[0] += static_cast<float>(0.05 * rng.Normal());
    s[1] += static_cast<float>(0.05 * rng.Normal());
  };
  // ToyCartGroundTruth's h, computed here: the predicate may run on several threads at once,
  // and a Barrier is an evaluator with scratch memory.
  const double wall = options_.wall, bound = options_.accel_bound;
  p.is_unsafe = [wall, bound](const Eigen::Ref<const Eigen::VectorXf>& s) {
    const double v = std::max(0.0, double(s[1]));
    return wall - double(s[0]) - v * v / (2.0 * bound) < 0.0;
  };
  p.is_unsafe_description = "ground truth h < 0";
  p.region_description = "safe and near-dangerous states, perturbed (sd 0.05 in x and v)";
  return p;
}

}  // namespace secure::examples::toy_cart
