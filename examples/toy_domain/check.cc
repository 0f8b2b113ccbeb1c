// The toy cart's barrier check (Domain::HasCheck): what `secure cbf check --domain toy-cart` and
// an experiment with the check on run (cbf/barrier_check.h).
#include <algorithm>
#include <utility>

#include "examples/toy_domain/toy_cart.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/experiments/check_problem.h"
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
  options_.Validate();
  cbf::BarrierCheckProblem p = experiments::CheckProblemBase("toy-cart", 2, 1, options_.accel_bound,
                                                             shield, safe, near_dangerous);
  *dynamics = std::make_unique<ToyCartModel>(options_.dt, options_.accel_bound);
  p.sample_region = experiments::PerturbedHeldOutRegion(
      safe, near_dangerous, [](Rng& rng, Eigen::Ref<Eigen::VectorXf> s) {
        s[0] += static_cast<float>(0.05 * rng.Normal());
        s[1] += static_cast<float>(0.05 * rng.Normal());
      });
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
