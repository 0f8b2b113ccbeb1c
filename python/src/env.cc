// secure.domains(), secure._secure.EnvCore (a domain's environment; python/secure/env.py wraps it
// as secure.Env in Gymnasium's API), Dynamics.builtin, Barrier.ground_truth, secure.generate_data,
// secure.read_config_section.
#include <algorithm>
#include <optional>

#include "python/src/common.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/experiments/config_section.h"
#include "secure/experiments/domain.h"

namespace secure::python {

std::unique_ptr<experiments::Domain> MakeDomain(const std::string& name, const std::string& profile,
                                                const py::dict& options) {
  SECURE_CHECK(profile == "full" || profile == "quick",
               "profile = '" << profile << "', must be full or quick");
  std::unique_ptr<experiments::Domain> d = experiments::DomainRegistry::Global().Make(
      name, profile == "quick" ? experiments::Profile::kQuick : experiments::Profile::kFull);
  if (!options.empty()) {
    const std::string source = "domain '" + name + "' options";
    CheckOptionTypes(options, d->OptionsJson(), source);
    d->ApplyYaml(ToYaml(options, source), source);
  }
  d->Validate();
  return d;
}

namespace {

// A domain's environment with an episode stream: the C++ half of secure.Env (env.py adds the
// spaces, np_random, reset's options and render_mode).
class Env {
 public:
  Env(const std::string& name, const std::string& profile, bool terminate_on_collision,
      const py::dict& options)
      : name_(name), terminate_on_collision_(terminate_on_collision) {
    domain_ = MakeDomain(name, profile, options);
    env_ = std::shared_ptr<domains::Environment>(domain_->MakeEnvironment());
    observation_.setZero(env_->observation_dim());
    dynamics_ = std::make_shared<Dynamics>();
    dynamics_->owner = env_;
    dynamics_->model = &env_->ShieldModel();
    dynamics_->kind = "builtin:" + name;
    dynamics_->state_features = env_->ObservationFeatures();
    dynamics_->action_low.resize(env_->action_dim());
    dynamics_->action_high.resize(env_->action_dim());
    env_->ActionBounds(dynamics_->action_low, dynamics_->action_high);
  }

  ResetResult Reset(std::optional<std::uint64_t> seed) {
    if (seed) rng_.Seed(*seed);
    {
      std::lock_guard<GuardedMutex> lock(dynamics_->mutex);
      env_->Reset(rng_, observation_);
    }
    steps_ = 0;
    started_ = true;
    return py::make_tuple(ToNumpy(observation_), py::dict());
  }

  StepResult Step(ArrayLike action) {
    if (!started_) throw std::runtime_error(name_ + ": call reset() before step()");
    const Eigen::VectorXf a = Vector(action, env_->action_dim(), "action");
    domains::StepOutcome outcome;
    {
      std::lock_guard<GuardedMutex> lock(dynamics_->mutex);
      outcome = env_->Step(a, observation_);
    }
    ++steps_;
    const bool terminated = outcome.reached_goal || (outcome.collided && terminate_on_collision_);
    const bool truncated = !terminated && steps_ >= env_->max_steps();
    // Per step (python/README.md): +1 for reaching the goal, -1 for being in danger after it
    // (every step of a contact, as eval's collision_events counts), else 0.
    const double reward = (outcome.reached_goal ? 1.0 : 0.0) - (outcome.collided ? 1.0 : 0.0);
    py::dict info;
    info["reached_goal"] = outcome.reached_goal;
    info["collided"] = outcome.collided;
    info["collisions"] = outcome.collisions;
    info["step"] = steps_;
    return py::make_tuple(ToNumpy(observation_), reward, terminated, truncated, info);
  }

  // The current state drawn offscreen: a (height, width, 3) uint8 array, rows top to bottom.
  py::array_t<std::uint8_t> Render(int width, int height) {
    SECURE_CHECK(env_->CanRender(), "the " << name_
                                           << " domain cannot render (no offscreen renderer)");
    if (!started_) throw std::runtime_error(name_ + ": call reset() before render()");
    SECURE_CHECK(width > 0 && height > 0,
                 "render size = " << width << " x " << height << ", must be positive");
    {
      py::gil_scoped_release release;
      std::lock_guard<GuardedMutex> lock(dynamics_->mutex);
      env_->Render(width, height, &frame_);
    }
    SECURE_CHECK(frame_.width == width && frame_.height == height &&
                     frame_.rgb.size() == 3u * static_cast<std::size_t>(width) * height,
                 "the " << name_ << " renderer returned a " << frame_.width << " x "
                        << frame_.height << " frame for " << width << " x " << height);
    py::array_t<std::uint8_t> out({height, width, 3});
    std::copy(frame_.rgb.begin(), frame_.rgb.end(), out.mutable_data());
    return out;
  }

  std::pair<py::array_t<float>, py::array_t<float>> ActionBounds() const {
    Eigen::VectorXf low(env_->action_dim()), high(env_->action_dim());
    env_->ActionBounds(low, high);
    return {ToNumpy(low), ToNumpy(high)};
  }

  OptionalArray Backup(ArrayLike observation) const {
    const Eigen::VectorXf o = Vector(observation, env_->observation_dim(), "observation");
    Eigen::VectorXf a(env_->action_dim());
    if (!env_->BackupAction(o, a)) return py::none();
    return OptionalArray(ToNumpy(a));
  }

  const std::string& name() const { return name_; }
  const domains::Environment& env() const { return *env_; }
  std::shared_ptr<const domains::Environment> shared_env() const { return env_; }
  const experiments::Domain& domain() const { return *domain_; }
  std::shared_ptr<Dynamics> dynamics() const { return dynamics_; }
  Rng& rng() { return rng_; }

 private:
  std::string name_;
  bool terminate_on_collision_;
  std::shared_ptr<experiments::Domain> domain_;
  std::shared_ptr<domains::Environment> env_;
  std::shared_ptr<Dynamics> dynamics_;
  Rng rng_;
  Eigen::VectorXf observation_;
  domains::Frame frame_;
  int steps_ = 0;
  bool started_ = false;
};

}  // namespace
}  // namespace secure::python
SECURE_PYTHON_CHECK_INITIALISED(secure::python::Env);
namespace secure::python {

std::shared_ptr<const domains::Environment> EnvironmentOf(py::handle env) {
  if (py::isinstance<py::str>(env)) {
    std::shared_ptr<experiments::Domain> d =
        MakeDomain(env.cast<std::string>(), "full", py::dict());
    return std::shared_ptr<const domains::Environment>(d->MakeEnvironment());
  }
  // A secure.Env (env.py) holds its EnvCore as `_core`; through Gymnasium's wrappers (gymnasium
  // .make) it is env.unwrapped.
  py::object core = py::reinterpret_borrow<py::object>(env);
  if (!py::isinstance<Env>(core) && py::hasattr(core, "unwrapped"))
    core = core.attr("unwrapped");
  if (!py::isinstance<Env>(core) && py::hasattr(core, "_core")) core = core.attr("_core");
  if (core.is_none()) throw std::runtime_error("env: the environment is closed");
  if (!py::isinstance<Env>(core))
    throw py::type_error("env: expected a secure.Env or a domain name (str), got " +
                         py::str(py::type::of(env)).cast<std::string>());
  return core.cast<Env&>().shared_env();
}

void RegisterEnvironment(py::module_& m) {
  m.def(
      "domains", [] { return experiments::DomainRegistry::Global().Names(); },
      "The registered domains (names for make_env, Dynamics.builtin, ...).");

  py::class_<Env, std::shared_ptr<Env>>(m, "EnvCore", R"doc(
The C++ half of secure.Env (use secure.make_env / secure.Env, which add Gymnasium's spaces,
np_random, reset options and render_mode): reset(seed) -> (obs, {}), step(action) -> (obs,
reward, terminated, truncated, info), render(width, height) -> (height, width, 3) uint8.
Per step: reward +1 when the goal is reached, -1 when the new state is dangerous, else 0;
info: reached_goal, collided (this step ends in danger), collisions (a contact begins in this
step), step.)doc")
      .def(py::init([](const std::string& name, const std::string& profile,
                       bool terminate_on_collision, OptionalJsonDict options) {
             return std::make_shared<Env>(name, profile, terminate_on_collision,
                                          options.is_none() ? py::dict() : py::dict(options));
           }),
           py::arg("name"), py::arg("profile") = "full",
           py::arg("terminate_on_collision") = false, py::arg("options") = py::none())
      .def("reset", &Env::Reset, py::arg("seed") = py::none(), R"doc(
Starts an episode. With a seed, the episode stream (env.rng) is re-seeded first; without one the
stream continues. Returns (observation float32 (observation_dim,), {}).)doc")
      .def("step", &Env::Step, py::arg("action"),
           "Applies the action (clipped to the actuator bounds by the domain).")
      .def("render", &Env::Render, py::arg("width"), py::arg("height"),
           "The current state drawn offscreen: (height, width, 3) uint8 (rendering domains).")
      .def_property_readonly("can_render", [](const Env& e) { return e.env().CanRender(); })
      .def_property_readonly("action_bounds", &Env::ActionBounds,
                             "(low, high): the actuator box Step() clips actions to.")
      .def_property_readonly("step_seconds", [](const Env& e) { return e.env().control_period(); },
                             "Simulated seconds per step (0: the task has no clock).")
      .def("backup_action", &Env::Backup, py::arg("observation"),
           "The domain's safe fallback action at `observation` (e.g. braking), or None.")
      .def_property_readonly("name", &Env::name)
      .def_property_readonly("observation_dim",
                             [](const Env& e) { return e.env().observation_dim(); })
      .def_property_readonly("action_dim", [](const Env& e) { return e.env().action_dim(); })
      .def_property_readonly("observation_features",
                             [](const Env& e) { return e.env().ObservationFeatures(); })
      .def_property_readonly("action_features",
                             [](const Env& e) { return e.env().ActionFeatures(); })
      .def_property_readonly("max_steps", [](const Env& e) { return e.env().max_steps(); })
      .def_property_readonly("dynamics", &Env::dynamics,
                             "The shield's model of this environment (a secure.Dynamics).")
      .def_property_readonly("shield_model_is_exact",
                             [](const Env& e) { return e.env().ShieldModelIsExact(); })
      .def_property_readonly("rng", &Env::rng, py::return_value_policy::reference_internal,
                             "The episode stream (a secure.Rng): reset() draws the start from it.")
      .def_property_readonly(
          "options", [](const Env& e) -> JsonDict { return ToPython(e.domain().OptionsJson()); },
          "The domain's options in force (its config-file keys), as a dict.")
      .def("describe", [](const Env& e) { return e.env().Describe(); })
      .def("__repr__",
           [](const Env& e) { return "<secure.EnvCore " + e.env().Describe() + ">"; });

  // Dynamics.builtin and Barrier.ground_truth live on the classes registered elsewhere.
  py::reinterpret_borrow<py::class_<Dynamics, std::shared_ptr<Dynamics>>>(m.attr("Dynamics"))
      .def_static(
          "builtin",
          [](const std::string& name, const std::string& profile, py::kwargs options) {
            Env env(name, profile, false, options);
            return env.dynamics();  // keeps the environment that owns the model alive
          },
          py::arg("domain"), py::arg("profile") = "full",
          "The shield model of a domain (the one its environment hands out), with its options.");

  py::reinterpret_borrow<py::class_<Barrier, std::shared_ptr<Barrier>>>(m.attr("Barrier"))
      .def_static(
          "ground_truth",
          [](const std::string& name, const std::string& profile,
             py::kwargs options) -> OptionalBarrier {
            std::shared_ptr<experiments::Domain> d = MakeDomain(name, profile, options);
            if (!d->MakeGroundTruth()) return py::none();
            return py::cast(MakeBarrier("ground_truth", [d] { return d->MakeGroundTruth(); }));
          },
          py::arg("domain"), py::arg("profile") = "full",
          "The domain's analytic ground-truth barrier, or None if it has none.");

  m.def(
      "read_config_section",
      [](const std::string& path, const std::string& name, const std::string& profile) -> JsonDict {
        RequireFile(path);
        std::unique_ptr<experiments::Domain> d = MakeDomain(name, profile, py::dict());
        const experiments::ExperimentOptions options =
            experiments::ReadSection(experiments::LoadConfigFile(path), path, *d);
        py::dict out;
        out["section"] = d->ConfigSection();
        out["domain"] = ToPython(d->OptionsJson());
        out["experiment"] = ToPython(options.ToJson());
        return out;
      },
      py::arg("path"), py::arg("domain"), py::arg("profile") = "full", R"doc(
A domain's section of a config file, read as every `secure` command reads it
(experiments::ReadSection): its `domain:` key into the domain's options, then the domain's preset,
then the other keys (shield, bc, airl, barrier, check, closed_loop) over it. Returns {'section':
its name, 'domain': the domain's options in force (as make_env(..., **options) takes them),
'experiment': the experiment options (e.g. ['shield'] for secure.Shield(**...))}. Errors name
the file, the section and the field (ValueError; a missing file: FileNotFoundError).)doc");

  m.def(
      "generate_data",
      [](const std::string& name, std::uint64_t seed, const std::string& profile,
         py::kwargs options) -> JsonDict {
        std::shared_ptr<experiments::Domain> d = MakeDomain(name, profile, options);
        experiments::DomainData data;
        {
          py::gil_scoped_release release;
          data = d->GenerateData(seed);
        }
        py::dict out;
        out["features"] = data.safe.features;
        out["safe"] = StatesToNumpy(data.safe.states);
        out["near_dangerous"] = StatesToNumpy(data.near_dangerous.states);
        out["demonstrations"] = py::cast(std::move(data.demonstrations));
        return out;
      },
      py::arg("domain"), py::arg("seed") = 0, py::arg("profile") = "quick", R"doc(
A domain's experiment data from a data seed: {'features', 'safe' (N, d), 'near_dangerous'
(M, d), 'demonstrations' (secure.Demonstrations)}; profile 'quick' (default) is small.)doc");
}

}  // namespace secure::python
