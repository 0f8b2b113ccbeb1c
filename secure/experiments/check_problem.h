#pragma once
// What every domain's barrier check problem (Domain::MakeCheckProblem; cbf/barrier_check.h) sets
// alike, written once for the plug-ins (double integrator, Derby, the Franka plug-ins, the toy
// cart): the checks of the held-out sets and the shield's options, the action box, dt and
// class-K from the shield, the held-out sets as (b)'s near-dangerous states and the held-out
// accuracy's, and the region "a held-out state perturbed". The domain adds its dynamics, its
// region's noise (or a region of its own), its unsafe test and the descriptions.
#include <Eigen/Core>
#include <functional>
#include <string>

#include "secure/cbf/barrier_check.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/shield/shield.h"

namespace secure::experiments {

/// The problem's common part:
///  - @throws secure::Error "the <domain> barrier check needs states of <state_dim> values; got
///    ..." unless both sets hold states of state_dim values; on an empty or non-finite set ("the
///    <domain> barrier check: safe states"); on invalid `shield` options;
///  - action box [-action_bound, action_bound]^action_dim; dt, class-K (shield::ClassKValue) and
///    its description from `shield`;
///  - near_dangerous = `near_dangerous`, held-out safe and near-dangerous = the two sets (copies).
/// The region, the unsafe test, project and the descriptions are left empty.
cbf::BarrierCheckProblem CheckProblemBase(const std::string& domain, int state_dim, int action_dim,
                                          double action_bound, const shield::ShieldOptions& shield,
                                          const data::StateSet& safe,
                                          const data::StateSet& near_dangerous);

/// A region sampler: a state of `safe` or of `near_dangerous` (each with probability 1/2, then
/// a uniform column; copies of the sets), perturbed in place by `perturb`, then `project` (if
/// set). Draws: the set, the column, then perturb's.
std::function<void(Rng&, Eigen::Ref<Eigen::VectorXf>)> PerturbedHeldOutRegion(
    const data::StateSet& safe, const data::StateSet& near_dangerous,
    std::function<void(Rng&, Eigen::Ref<Eigen::VectorXf>)> perturb,
    std::function<void(Eigen::Ref<Eigen::VectorXf>)> project = nullptr);

}  // namespace secure::experiments
