// secure.Dynamics (built-in by domain, linear, Python callable), secure.Shield, secure.Decision.
#include <cmath>
#include <cstring>

#include "python/src/common.h"
#include "python/src/guard.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/domains/linear_dynamics.h"
#include "secure/dynamics/ensemble.h"
#include "secure/shield/shield.h"

namespace secure::python {
namespace {

// T(s, a) in Python: fn(state (d,), actions (M, n)) -> next_states (M, d). Each Step acquires
// the GIL, copies the state and actions into new float32 arrays, calls fn and copies its result
// (any real dtype, converted) back; an exception raised by fn propagates out of the shield.
class CallableDynamics final : public domains::DynamicsModel {
 public:
  CallableDynamics(py::object fn, int state_dim, int action_dim, std::string name)
      : fn_(std::move(fn)), state_dim_(state_dim), action_dim_(action_dim), name_(std::move(name)) {
    SECURE_CHECK(state_dim >= 1 && action_dim >= 1,
                 "Dynamics.from_callable: state_dim = " << state_dim << ", action_dim = "
                                                        << action_dim << ", must be >= 1");
  }
  ~CallableDynamics() override {
    py::gil_scoped_acquire gil;
    fn_ = py::object();
  }
  int state_dim() const override { return state_dim_; }
  int action_dim() const override { return action_dim_; }
  std::string Describe() const override { return name_; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override {
    py::gil_scoped_acquire gil;
    const py::ssize_t m = actions.cols();
    py::array_t<float> s = ToNumpy(state);
    py::array_t<float> a({m, static_cast<py::ssize_t>(action_dim_)});
    for (py::ssize_t j = 0; j < m; ++j)
      std::memcpy(a.mutable_data(j, 0), actions.col(j).data(), sizeof(float) * action_dim_);
    const py::object result = fn_(s, a);
    const FloatArray r = AsFloat32(result, name_ + ": the returned next states");
    if (r.ndim() != 2 || r.shape(0) != m || r.shape(1) != state_dim_) {
      std::ostringstream shape;
      for (py::ssize_t k = 0; k < r.ndim(); ++k) shape << (k ? ", " : "") << r.shape(k);
      throw py::value_error(name_ + ": returned next states of shape (" + shape.str() +
                            "), expected (" + std::to_string(m) + ", " +
                            std::to_string(state_dim_) + ") for " + std::to_string(m) + " actions");
    }
    // A NaN or inf next state would make every g NaN, and the shield would fall back silently
    // (issue 34): the callback's error, naming it and the entry.
    for (py::ssize_t j = 0; j < m; ++j)
      for (py::ssize_t i = 0; i < state_dim_; ++i)
        if (!std::isfinite(*r.data(j, i)))
          throw py::value_error(name_ + ": returned next states[" + std::to_string(j) + ", " +
                                std::to_string(i) + "] = " + std::to_string(*r.data(j, i)) +
                                ", which is not finite (the dynamics callback must return "
                                "finite next states)");
    for (py::ssize_t j = 0; j < m; ++j)
      std::memcpy(next_states.col(j).data(), r.data(j, 0), sizeof(float) * state_dim_);
  }

 private:
  py::object fn_;
  int state_dim_, action_dim_;
  std::string name_;
};

std::shared_ptr<Dynamics> Linear(ArrayLike a, ArrayLike b) {
  const Eigen::MatrixXf am = Matrix(a, -1, -1, "A");
  const Eigen::MatrixXf bm = Matrix(b, -1, -1, "B");
  auto model = std::make_shared<const domains::LinearDynamics>(am, bm);
  auto d = std::make_shared<Dynamics>();
  d->model = model.get();
  d->owner = model;
  d->kind = "linear";
  return d;
}

std::shared_ptr<Dynamics> Learned(const std::string& path, int max_batch,
                                  const std::string& pessimism, double pessimism_kappa,
                                  bool pessimism_linear, int hold) {
  // As `secure eval --dynamics M --pessimism ... --pessimism-kappa ... --pessimism-linear
  // --dynamics-hold ...`.
  dynamics::PessimismOptions how;
  how.aggregate = dynamics::PessimismOptions::ParseAggregate(pessimism, "pessimism");
  how.kappa = pessimism_kappa;
  how.linear = pessimism_linear;
  how.hold = hold;
  how.Validate();
  auto ensemble = std::make_shared<const dynamics::EnsembleDynamics>(
      dynamics::EnsembleDynamics::Load(path));
  auto model = std::make_shared<const dynamics::EnsembleModel>(
      ensemble, max_batch, nn::MatmulBackend::kAuto, how);
  auto d = std::make_shared<Dynamics>();
  d->model = model.get();
  d->owner = model;
  d->kind = "learned";
  d->state_features = ensemble->state_features;
  return d;
}

std::shared_ptr<Dynamics> FromCallable(DynamicsFunction fn, int state_dim, int action_dim,
                                       const std::string& name) {
  if (!PyCallable_Check(fn.ptr()))
    throw py::type_error("Dynamics.from_callable: fn is not callable");
  auto model = std::make_shared<const CallableDynamics>(std::move(fn), state_dim, action_dim, name);
  auto d = std::make_shared<Dynamics>();
  d->model = model.get();
  d->owner = model;
  d->kind = "python";
  d->python = true;
  return d;
}

py::array_t<float> Step(Dynamics& d, ArrayLike state, ArrayLike actions) {
  const Eigen::VectorXf s = Vector(state, d.model->state_dim(), "state");
  const StatesArg a = States(actions, d.model->action_dim(), "actions", false);
  Eigen::MatrixXf next(d.model->state_dim(), a.map.cols());
  {
    py::gil_scoped_release release;
    std::lock_guard<GuardedMutex> lock(d.mutex);
    d.model->Step(s, a.map, next);
  }
  return StatesToNumpy(next);
}

// ShieldOptions from keyword arguments, read by ShieldOptions::ApplyYaml (the experiment
// configuration's `shield:` section): the fields by name, enums by their names (class_k: linear |
// cubic, aggregation: mean | random-safe | policy-draw | top-q | policy-mean, resampling:
// adaptive | none, sampler: iid | antithetic | qmc); an unknown key is an error naming it and
// listing the valid keys.
}  // namespace

shield::ShieldOptions ShieldOptionsFrom(const py::dict& kwargs) {
  shield::ShieldOptions o;
  const std::string source = "Shield options";
  CheckOptionTypes(kwargs, o.ToJson(), source);
  o.ApplyYaml(ToYaml(kwargs, source), source);
  o.Validate();
  return o;
}

namespace {

class Shield {
 public:
  Shield(std::shared_ptr<Barrier> barrier, std::shared_ptr<Dynamics> dynamics,
         const shield::ShieldOptions& options, std::shared_ptr<AirlReward> task_value,
         py::handle action_low, py::handle action_high)
      : barrier_(std::move(barrier)), dynamics_(std::move(dynamics)) {
    Required(barrier_, "Shield: barrier", "a secure.Barrier");
    Required(dynamics_, "Shield: dynamics", "a secure.Dynamics");
    // The shield's own evaluator (it owns scratch memory), reading the barrier's features by
    // name from the model's states where the model names them.
    evaluator_ = EvaluatorOn(*barrier_, dynamics_->state_features);
    // A learned ensemble: h(s+) is the minimum over its members (secure/dynamics/README.md).
    evaluator_ = dynamics::ForShieldModel(std::move(evaluator_), *dynamics_->model);
    shield_ = std::make_unique<shield::Shield>(options, *evaluator_, *dynamics_->model);
    // The actuator box: the one given, else the builtin model's environment's, else none.
    if (action_low.is_none() != action_high.is_none())
      throw py::value_error("action_low and action_high: give both or neither");
    const int n = dynamics_->model->action_dim();
    if (!action_low.is_none()) {
      shield_->SetActionBounds(Vector(action_low, n, "action_low"),
                               Vector(action_high, n, "action_high"));
    } else if (dynamics_->action_low.size() == n) {
      shield_->SetActionBounds(dynamics_->action_low, dynamics_->action_high);
    }
    const bool top_q = options.aggregation == shield::Aggregation::kTopQ;
    if (top_q != (task_value != nullptr))
      throw py::value_error(top_q ? "aggregation='top-q' needs task_value=secure.AirlReward"
                                  : "task_value is used only with aggregation='top-q'");
    if (task_value) {
      const policy::AirlRewardModel& model = *task_value->model;
      if (model.observation_dim() != dynamics_->model->state_dim())
        throw py::value_error("task_value: the reward model reads " +
                              std::to_string(model.observation_dim()) +
                              "-D observations, the dynamics model maps " +
                              std::to_string(dynamics_->model->state_dim()) + "-D states");
      task_value_ = task_value;
      value_ = std::make_unique<policy::AirlActionValue>(
          model, model.observation_features, std::max(options.num_samples, options.num_probes));
      shield_->SetActionValue(value_.get());
    }
  }

  shield::Decision Decide(ArrayLike state, ArrayLike mu, ArrayLike sigma) {
    const Eigen::VectorXf s = Vector(state, shield_->state_dim(), "state");
    const Eigen::VectorXf m = Vector(mu, shield_->action_dim(), "mu");
    const Eigen::VectorXf sg = Vector(sigma, shield_->action_dim(), "sigma");
    // Without the GIL, then the lock (in this order: a Python dynamics model re-acquires the GIL
    // inside Decide, so no thread may wait for the lock while holding it).
    py::gil_scoped_release release;
    std::lock_guard<GuardedMutex> lock(mutex_);
    std::lock_guard<GuardedMutex> model_lock(dynamics_->mutex);
    return shield_->Decide(s, m, sg);
  }

  double EvaluateH(ArrayLike state) {
    const Eigen::VectorXf s = Vector(state, shield_->state_dim(), "state");
    py::gil_scoped_release release;
    std::lock_guard<GuardedMutex> lock(mutex_);
    return shield_->EvaluateH(s);
  }

  py::array_t<double> EvaluateG(ArrayLike state, ArrayLike actions) {
    const Eigen::VectorXf s = Vector(state, shield_->state_dim(), "state");
    const StatesArg a = States(actions, shield_->action_dim(), "actions", false);
    const long limit = std::max(shield_->options().num_samples, shield_->options().num_probes);
    if (a.map.cols() > limit)
      throw py::value_error(
          "actions: " + std::to_string(a.map.cols()) +
          " actions, at most max(num_samples, num_probes) = " + std::to_string(limit));
    py::array_t<double> g(a.map.cols());
    Eigen::Map<Eigen::VectorXd> out(g.mutable_data(), a.map.cols());
    py::gil_scoped_release release;
    std::lock_guard<GuardedMutex> lock(mutex_);
    std::lock_guard<GuardedMutex> model_lock(dynamics_->mutex);
    shield_->EvaluateG(s, shield_->EvaluateH(s), a.map, out);
    return g;
  }

  void SetBackup(OptionalArrayLike action) {
    if (action.is_none()) {
      py::gil_scoped_release release;  // never wait for the lock holding the GIL (see Decide)
      std::lock_guard<GuardedMutex> lock(mutex_);
      shield_->ClearBackupAction();
      return;
    }
    const Eigen::VectorXf a = Vector(action, shield_->action_dim(), "backup_action");
    py::gil_scoped_release release;
    std::lock_guard<GuardedMutex> lock(mutex_);
    shield_->SetBackupAction(a);
  }
  void Seed(std::uint64_t seed) {
    py::gil_scoped_release release;
    std::lock_guard<GuardedMutex> lock(mutex_);
    shield_->Seed(seed);
  }
  OptionalArray Bound(bool high) const {
    if (!shield_->has_action_bounds()) return OptionalArray(py::none());
    return OptionalArray(ToNumpy(high ? shield_->action_high() : shield_->action_low()));
  }
  const shield::Shield& get() const { return *shield_; }
  const Barrier& barrier() const { return *barrier_; }
  const Dynamics& dynamics() const { return *dynamics_; }

 private:
  std::shared_ptr<Barrier> barrier_;
  std::shared_ptr<Dynamics> dynamics_;
  std::unique_ptr<cbf::Barrier> evaluator_;
  std::shared_ptr<AirlReward> task_value_;
  std::unique_ptr<policy::AirlActionValue> value_;
  std::unique_ptr<shield::Shield> shield_;
  GuardedMutex mutex_{"secure.Shield"};
};

}  // namespace
}  // namespace secure::python
SECURE_PYTHON_CHECK_INITIALISED(secure::python::Shield);
namespace secure::python {

void RegisterDynamics(py::module_& m) {
  py::class_<Dynamics, std::shared_ptr<Dynamics>>(m, "Dynamics", R"doc(
A dynamics model T(s, a) the shield looks one step ahead with. Made by
  Dynamics.builtin(domain, **domain_options)  a domain's shield model (secure.domains())
  Dynamics.linear(A, B)                        next = A s + B a
  Dynamics.learned(path)                       a learned ensemble (`secure dynamics train`);
                                               a Shield on it is pessimistic over the members
  Dynamics.from_callable(fn, state_dim, action_dim)
                                               fn(state (d,), actions (M, n)) -> (M, d)
  env.dynamics                                 the shield model of an environment)doc")
      .def_static("linear", &Linear, py::arg("A"), py::arg("B"),
                  "next = A s + B a; A is (d, d), B is (d, n) (copied).")
      .def_static("learned", &Learned, py::arg("path"), py::arg("max_batch") = 1024,
                  py::kw_only(), py::arg("pessimism") = "min", py::arg("pessimism_kappa") = 1.0,
                  py::arg("pessimism_linear") = false, py::arg("hold") = 1, R"doc(
A learned dynamics ensemble from its model file (`secure dynamics train`): step() gives the
members' mean; a Shield on it scores an action pessimistically over the members' h(s+), so the
ensemble's disagreement makes the shield careful: pessimism='min' (the minimum over the members)
or 'mean-std' (their mean minus pessimism_kappa standard deviations); pessimism_linear=True takes
the members' h(s+) to first order through the barrier's gradient (h on M states instead of K M),
as `secure eval --pessimism --pessimism-kappa --pessimism-linear`. hold=H: one step() is H model
steps with the action held, each member on its own chain, the pessimism at the end (a model that
looks as far as a hand-written one holding the action; `--dynamics-hold`). max_batch bounds the
actions per step (the shield's max(num_samples, num_probes)). Inference only (no LibTorch).)doc")
      .def_static("from_callable", &FromCallable, py::arg("fn"), py::arg("state_dim"),
                  py::arg("action_dim"), py::arg("name") = "python dynamics", R"doc(
A model written in Python: fn(state, actions) gets a (state_dim,) float32 array and an
(M, action_dim) float32 array (M actions, one per row) and returns the (M, state_dim) next states.
Called with the GIL held, once per batch the shield evaluates (a few per decision); see
python/README.md for its cost.)doc")
      .def_property_readonly("state_dim", [](const Dynamics& d) { return d.model->state_dim(); })
      .def_property_readonly("action_dim", [](const Dynamics& d) { return d.model->action_dim(); })
      .def_property_readonly("kind", [](const Dynamics& d) { return d.kind; })
      .def("describe", [](const Dynamics& d) { return d.model->Describe(); })
      .def("__repr__",
           [](const Dynamics& d) { return "<secure.Dynamics " + d.model->Describe() + ">"; })
      .def("step", &Step, py::arg("state"), py::arg("actions"),
           "next states (M, state_dim) of one state under M actions (M, action_dim).");
}

void RegisterShield(py::module_& m) {
  py::class_<shield::Decision>(m, "Decision", "One shield decision with its diagnostics.")
      .def_property_readonly(
          "status",
          [](const shield::Decision& d) { return ToString(shield::kStatusNames, d.status); },
          "safe | safe_after_resampling | no_safe_action | invalid_input")
      .def_property_readonly("action", [](const shield::Decision& d) { return ToNumpy(d.action); })
      .def_readonly("g", &shield::Decision::g)
      .def_readonly("h", &shield::Decision::h)
      .def_readonly("iterations", &shield::Decision::iterations)
      .def_readonly("safe_ratio", &shield::Decision::safe_ratio)
      .def_readonly("intervened", &shield::Decision::intervened)
      .def_readonly("distance_to_mean", &shield::Decision::distance_to_mean)
      .def_readonly("bounded", &shield::Decision::bounded,
                    "the actuator box cut into this decision (an action outside it was clipped "
                    "or rejected)")
      .def_property_readonly(
          "fallback",
          [](const shield::Decision& d) { return ToString(shield::kFallbackNames, d.fallback); },
          "none | best_sample | backup_action | random_sample | qp_projection | refined_mean")
      .def_property_readonly(
          "qp", [](const shield::Decision& d) { return ToString(shield::kQpOutcomeNames, d.qp); },
          "the CBF-QP projection (proposal='qp' or 'qp-only') or the gradient refinement "
          "(proposal='refine'): not_tried | accepted | rejected | "
          "infeasible")
      .def_readonly("seconds", &shield::Decision::seconds)
      .def_property_readonly("safe", &shield::Decision::safe)
      .def(
          "to_dict", [](const shield::Decision& d) -> JsonDict { return ToPython(d.ToJson()); },
          "The whole record (shield::Decision::ToJson), as a dict.")
      .def("__repr__",
           [](const shield::Decision& d) { return "<secure.Decision " + d.ToJson().dump() + ">"; });

  py::class_<Shield, std::shared_ptr<Shield>>(m, "Shield", R"doc(
The CBF shield (Algorithms 1 and 2): Shield(barrier, dynamics, **options), the options being the
fields of shield::ShieldOptions (num_samples=64, safe_ratio=0.1, dt=0.1, class_k='linear',
class_k_gain=1.0, aggregation='mean', resampling='adaptive', num_probes=64, probe_extent=1.0,
sigma_step=0.5, max_iterations=20, time_budget_us=0, seed=0, sampler='iid' (or 'antithetic',
'qmc'), top_q_fraction=0.3, lookahead_steps=1, action_bounds='clip' (or 'reject', 'ignore'),
proposal='none' (or 'qp': the CBF-QP projection of the mean first, 'qp-only': the CBF-QP filter
alone, 'refine': gradient refinement of the mean alone), qp_iterations=1, qp_line_search=0
(proposal 'qp' / 'qp-only': secant steps on the exact g along a rejected projection's line),
qp_bisection=0 (proposal 'qp' / 'qp-only': bisection steps on the exact g back along the line of
an accepted projection that overshot), qp_target='boundary' (or 'safe-mean': the mean of the
policy's Gaussian over the linearised safe half-space; needs qp_metric='policy'),
qp_margin=0, qp_max_step=0 (proposal 'qp': a projection farther from the mean (with qp_bisection,
the bisected decision) falls back to sampling; 0: none),
qp_smoothing=0 (proposal 'qp': after failed projections, one more round on the slope of
the exact g at mu +- qp_smoothing sigma along each action; 0: off),
qp_metric='euclidean' (or 'policy': proposal 'qp' / 'qp-only' project in the policy's metric
(a - mu)^T diag(sigma)^-2 (a - mu); needs sigma > 0),
refine_steps=5); aggregation may also be 'first-safe' (the first-safe sampler).
The actuator box: action_low / action_high (arrays of action_dim; -inf / inf where unbounded),
else the box of the environment a builtin model (Dynamics.builtin, env.dynamics) came from, else
none. With a box every returned action lies in it: samples are clipped onto it
(action_bounds='clip') or rejected (counted unsafe, 'reject'); Decision.bounded says when the box
cut into a decision. aggregation='top-q' ranks the safe samples by a task value:
task_value=secure.AirlReward (AIRL's Q = g(s) + gamma V(T(s, a)), on the dynamics model's states,
which must be the reward model's observations). The shield keeps the barrier (with
its own evaluator), the dynamics model and the task value alive.)doc")
      .def(py::init([](std::shared_ptr<Barrier> barrier, std::shared_ptr<Dynamics> dynamics,
                       std::shared_ptr<AirlReward> task_value, OptionalArrayLike action_low,
                       OptionalArrayLike action_high, py::kwargs options) {
             return std::make_shared<Shield>(std::move(barrier), std::move(dynamics),
                                             ShieldOptionsFrom(options), std::move(task_value),
                                             action_low, action_high);
           }),
           py::arg("barrier"), py::arg("dynamics"), py::kw_only(), py::arg("task_value") = nullptr,
           py::arg("action_low") = py::none(), py::arg("action_high") = py::none())
      .def("decide", &Shield::Decide, py::arg("state"), py::arg("mu"), py::arg("sigma"), R"doc(
One shielded decision for the policy's Gaussian N(mu, diag(sigma^2)) at `state`: a Decision
(action, status, g, h, iterations, ...). Bad numbers (NaN) give status 'invalid_input'; wrong
shapes raise ValueError. Releases the GIL (a Python dynamics model re-acquires it).)doc")
      .def("evaluate_h", &Shield::EvaluateH, py::arg("state"), "h(state) through the shield.")
      .def("evaluate_g", &Shield::EvaluateG, py::arg("state"), py::arg("actions"),
           "g(a) of each row of `actions` (K, action_dim), K <= max(num_samples, num_probes).")
      .def("set_backup_action", &Shield::SetBackup, py::arg("action"),
           "The fallback action competing on g when no safe sample exists (None: clear).")
      .def("seed", &Shield::Seed, py::arg("seed"), "Re-seeds the shield's random stream.")
      .def_property_readonly(
          "options", [](const Shield& s) -> JsonDict { return ToPython(s.get().options().ToJson()); },
          "The shield's options (ShieldOptions::ToJson), as a dict.")
      .def_property_readonly(
          "action_low", [](const Shield& s) { return s.Bound(false); },
          "the actuator box's lower bounds, or None (no box)")
      .def_property_readonly(
          "action_high", [](const Shield& s) { return s.Bound(true); },
          "the actuator box's upper bounds, or None (no box)")
      .def_property_readonly("state_dim", [](const Shield& s) { return s.get().state_dim(); })
      .def_property_readonly("action_dim", [](const Shield& s) { return s.get().action_dim(); })
      .def_property_readonly("dynamics",
                             [](const Shield& s) { return s.dynamics().model->Describe(); })
      .def("__repr__", [](const Shield& s) {
        return "<secure.Shield barrier=" + s.barrier().evaluator->Describe() +
               " dynamics=" + s.dynamics().model->Describe() + ">";
      });
}

}  // namespace secure::python
