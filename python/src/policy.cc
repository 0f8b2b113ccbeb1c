// secure.Demonstrations, secure.Policy (load, mean, sample), secure.train_bc, secure.train_airl.
#include <cstdint>
#include <optional>
#include <vector>

#include "python/src/common.h"
#include "python/src/guard.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/eval/policy_eval.h"
#include "secure/nn/torch_threads.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"
#include "secure/policy/gaussian_policy.h"

namespace secure::python {

namespace {

// SeedResult::episode_outcomes as columns: name -> int64 array (one entry per episode).
py::dict EpisodeOutcomesToNumpy(const std::vector<eval::EpisodeOutcome>& outcomes) {
  const auto column = [&](auto value) {
    py::array_t<std::int64_t> a(static_cast<py::ssize_t>(outcomes.size()));
    auto view = a.mutable_unchecked<1>();
    for (std::size_t i = 0; i < outcomes.size(); ++i)
      view(static_cast<py::ssize_t>(i)) = static_cast<std::int64_t>(value(outcomes[i]));
    return a;
  };
  using E = const eval::EpisodeOutcome&;
  py::dict d;
  d["episode"] = column([](E e) { return e.episode; });
  d["success"] = column([](E e) { return e.success ? 1 : 0; });
  d["dangerous"] = column([](E e) { return e.dangerous ? 1 : 0; });
  d["steps"] = column([](E e) { return e.steps; });
  d["first_dangerous_step"] = column([](E e) { return e.first_dangerous_step; });
  d["collision_events"] = column([](E e) { return e.collision_events; });
  d["interventions"] = column([](E e) { return e.interventions; });
  d["no_safe_action_decisions"] = column([](E e) { return e.no_safe_action_decisions; });
  return d;
}

}  // namespace
namespace {

// Demonstrations from arrays: states (T, d), actions (T, n), episode (T,) labels (adjacent equal
// labels form one episode, as the CSV's `episode` column).
data::TrajectorySet DemosFromArrays(ArrayLike states, ArrayLike actions, OptionalArrayLike episode,
                                    FeatureNamesArg state_features,
                                    FeatureNamesArg action_features) {
  const StatesArg s = States(states, -1, "states", false);
  const StatesArg a = States(actions, -1, "actions", false);
  const long t = static_cast<long>(s.map.cols());
  if (a.map.cols() != t)
    throw py::value_error("actions: " + std::to_string(a.map.cols()) + " rows, states have " +
                          std::to_string(t));
  data::TrajectorySet d;
  d.source = "demonstrations (NumPy arrays)";
  d.state_features =
      FeatureNames(state_features, static_cast<int>(s.map.rows()), "s", "state_features");
  d.action_features =
      FeatureNames(action_features, static_cast<int>(a.map.rows()), "a", "action_features");
  CheckFinite(s.map, false, "states", "states");
  CheckFinite(a.map, false, "actions", "actions");
  d.states = s.map;
  d.actions = a.map;
  d.episode_begin.push_back(0);
  if (!episode.is_none()) {
    py::array_t<long long, py::array::c_style | py::array::forcecast> e =
        py::array_t<long long, py::array::c_style | py::array::forcecast>::ensure(episode);
    if (!e || e.ndim() != 1 || e.shape(0) != t)
      throw py::value_error("episode: expected " + std::to_string(t) +
                            " integer labels (one per row), got another shape");
    for (long i = 1; i < t; ++i)
      if (e.data()[i] != e.data()[i - 1]) d.episode_begin.push_back(i);
  }
  d.episode_begin.push_back(t);
  if (t == 0) throw py::value_error("states: no rows (demonstrations need at least one step)");
  return d;
}

class Policy {
 public:
  explicit Policy(policy::GaussianPolicy p)
      : model_(std::make_shared<const policy::GaussianPolicy>(std::move(p))), evaluator_(*model_) {}

  py::array_t<float> Mean(ArrayLike observation) {
    const StatesArg o = States(observation, model_->observation_dim(), "observation");
    CheckFinite(o.map, o.one, "observation", "observations");
    Eigen::MatrixXf mu(model_->action_dim(), o.map.cols());
    {
      py::gil_scoped_release release;
      std::lock_guard<std::mutex> lock(mutex_);
      if (o.one) {
        evaluator_.Mean(o.map.col(0), mu.col(0));  // what the C++ episode loop calls
      } else {
        evaluator_.Means(o.map, mu);
      }
    }
    if (o.one) return ToNumpy(mu.col(0));
    return StatesToNumpy(mu);
  }

  py::array_t<float> Sample(ArrayLike observation, RngOrSeed rng) {
    const Eigen::VectorXf o = Vector(observation, model_->observation_dim(), "observation");
    CheckFinite(o, true, "observation", "observations");
    if (!py::isinstance<Rng>(rng) &&
        (py::isinstance<py::bool_>(rng) || !py::isinstance<py::int_>(rng))) {
      throw py::type_error("rng: expected a secure.Rng or an int seed, got " +
                           std::string(py::str(py::module_::import("reprlib").attr("repr")(rng))));
    }
    if (!py::isinstance<Rng>(rng) &&
        (rng < py::int_(0) || rng >= py::int_(1).attr("__lshift__")(64))) {
      throw py::value_error("rng: seed " + std::string(py::str(py::module_::import("reprlib").attr("repr")(rng))) +
                            " is out of range, expected a secure.Rng or an int in [0, 2**64)");
    }
    Eigen::VectorXf a(model_->action_dim());
    std::lock_guard<std::mutex> lock(mutex_);
    if (py::isinstance<Rng>(rng)) {
      evaluator_.Sample(o, rng.cast<Rng&>(), a);
    } else {
      Rng r(rng.cast<std::uint64_t>());
      evaluator_.Sample(o, r, a);
    }
    return ToNumpy(a);
  }

  double LogProb(ArrayLike observation, ArrayLike action) {
    const Eigen::VectorXf o = Vector(observation, model_->observation_dim(), "observation");
    const Eigen::VectorXf a = Vector(action, model_->action_dim(), "action");
    CheckFinite(o, true, "observation", "observations");
    CheckFinite(a, true, "action", "actions");
    std::lock_guard<std::mutex> lock(mutex_);
    return evaluator_.LogProb(o, a);
  }

  const policy::GaussianPolicy& model() const { return *model_; }

 private:
  std::shared_ptr<const policy::GaussianPolicy> model_;
  policy::PolicyEvaluator evaluator_;
  std::mutex mutex_;
};

template <typename Options>
Options OptionsFrom(const py::kwargs& kwargs, const std::string& source) {
  Options o;
  CheckOptionTypes(kwargs, o.ToJson(), source);
  o.ApplyYaml(ToYaml(kwargs, source), source);
  return o;
}

}  // namespace
}  // namespace secure::python
SECURE_PYTHON_CHECK_INITIALISED(secure::python::Policy);
namespace secure::python {

void RegisterPolicy(py::module_& m) {
  py::class_<data::TrajectorySet>(m, "Demonstrations", R"doc(
Task demonstrations: state/action pairs grouped into episodes.
  Demonstrations(states (T, d), actions (T, n), episode=None (T,) labels,
                 state_features=None, action_features=None)
  Demonstrations.load(path, state_features, action_features, episode_column='episode'))doc")
      .def(py::init(&DemosFromArrays), py::arg("states"), py::arg("actions"),
           py::arg("episode") = py::none(), py::arg("state_features") = py::none(),
           py::arg("action_features") = py::none())
      .def_static(
          "load",
          [](const std::string& path, const std::vector<std::string>& state_features,
             const std::vector<std::string>& action_features, const std::string& column) {
            RequireFile(path);
            return data::ReadTrajectories(path, state_features, action_features, column);
          },
          py::arg("path"), py::arg("state_features"), py::arg("action_features"),
          py::arg("episode_column") = "episode", R"doc(
Reads demonstrations from a CSV file (a header row; the episode column and the named state and
action columns) or an HDF5 file in robomimic's layout (.h5, .hdf5). Raises FileNotFoundError if
there is no such file, ValueError (naming the file, column and row) if it is malformed.)doc")
      .def(
          "save",
          [](const data::TrajectorySet& d, const std::string& path, const std::string& column) {
            data::WriteTrajectories(path, d, column);
          },
          py::arg("path"), py::arg("episode_column") = "episode",
          "Writes the demonstrations as CSV (atomically), or HDF5 for a .h5 / .hdf5 path.")
      .def_property_readonly("states",
                             [](const data::TrajectorySet& d) { return StatesToNumpy(d.states); })
      .def_property_readonly("actions",
                             [](const data::TrajectorySet& d) { return StatesToNumpy(d.actions); })
      .def_readonly("state_features", &data::TrajectorySet::state_features)
      .def_readonly("action_features", &data::TrajectorySet::action_features)
      .def_readonly("episode_begin", &data::TrajectorySet::episode_begin)
      .def_property_readonly("num_episodes", &data::TrajectorySet::num_episodes)
      .def_property_readonly("num_steps", &data::TrajectorySet::num_steps)
      .def("__repr__", [](const data::TrajectorySet& d) {
        return "<secure.Demonstrations " + std::to_string(d.num_episodes()) + " episodes, " +
               std::to_string(d.num_steps()) + " steps>";
      });

  py::class_<Policy, std::shared_ptr<Policy>>(m, "Policy", R"doc(
A Gaussian policy N(mu(o), diag(sigma^2)) (a `secure policy train` model): Policy.load(path),
mean(obs), sample(obs, rng_or_seed), log_prob(obs, action), save(path).)doc")
      .def_static(
          "load",
          [](const std::string& path) {
            RequireFile(path);
            return std::make_shared<Policy>(policy::GaussianPolicy::Load(path));
          },
          py::arg("path"), R"doc(
Loads a policy model file (`secure policy train`, BC or AIRL). Raises FileNotFoundError if there
is no such file, ValueError (naming the file) if it is not a policy model or is corrupt.)doc")
      .def("mean", &Policy::Mean, py::arg("observation"),
           "mu(o) of one (observation_dim,) observation -> (action_dim,), or of a batch (N, "
           "observation_dim) -> (N, action_dim). Releases the GIL.")
      .def("sample", &Policy::Sample, py::arg("observation"), py::arg("rng"),
           "a ~ N(mu(o), sigma): `rng` is a secure.Rng (advanced by action_dim normals) or an "
           "integer seed.")
      .def("log_prob", &Policy::LogProb, py::arg("observation"), py::arg("action"),
           "log N(action; mu(observation), diag(sigma^2)) of one observation and action.")
      .def(
          "save", [](const Policy& p, const std::string& path) { p.model().Save(path); },
          py::arg("path"), "Writes the model file (atomically).")
      .def_property_readonly(
          "sigma",
          [](const Policy& p) { return ToNumpy(p.model().log_std.array().exp().matrix()); })
      .def_property_readonly("log_std", [](const Policy& p) { return ToNumpy(p.model().log_std); })
      .def_property_readonly("observation_dim",
                             [](const Policy& p) { return p.model().observation_dim(); })
      .def_property_readonly("action_dim", [](const Policy& p) { return p.model().action_dim(); })
      .def_property_readonly("observation_features",
                             [](const Policy& p) { return p.model().observation_features; })
      .def_property_readonly("input_features",
                             [](const Policy& p) {
                               const policy::GaussianPolicy& m = p.model();
                               return m.input_features.empty() ? m.observation_features
                                                               : m.input_features;
                             })
      .def_property_readonly("action_features",
                             [](const Policy& p) { return p.model().action_features; })
      .def_property_readonly(
          "provenance", [](const Policy& p) -> JsonDict { return ToPython(p.model().provenance); },
          "The training options, summary and data the model file records.")
      .def("__repr__", [](const Policy& p) {
        return "<secure.Policy " + std::to_string(p.model().observation_dim()) + " -> " +
               std::to_string(p.model().action_dim()) + ">";
      });

  m.def(
      "train_bc",
      [](const data::TrajectorySet& demos, py::kwargs options) -> PolicyAndSummary {
        const auto o = OptionsFrom<policy::BcOptions>(options, "train_bc options");
        policy::BcSummary summary;
        policy::GaussianPolicy p;
        {
          py::gil_scoped_release release;
          nn::SetTorchThreads(1);
          p = policy::TrainBc(o, demos, &summary);
        }
        return py::make_tuple(std::make_shared<Policy>(std::move(p)), ToPython(summary.ToJson()));
      },
      py::arg("demonstrations"), R"doc(
Behaviour cloning on secure.Demonstrations; keyword arguments are BcOptions (the `bc` section of
a config: hidden, epochs, seed, ...; an unknown key is a ValueError listing the valid ones, a
value of the wrong type a TypeError). Returns (policy, summary dict). Releases the GIL.)doc");

  py::class_<AirlReward, std::shared_ptr<AirlReward>>(m, "AirlReward", R"doc(
AIRL's learned reward g(s) and shaping V(s) (an `airl_reward.model` of a run directory, or
train_airl(..., with_reward=True)): the task value Q(s, a) = g(s) + gamma V(T(s, a)) of a shield
with aggregation='top-q' (Shield(..., task_value=reward)).)doc")
      .def_static(
          "load",
          [](const std::string& path) {
            RequireFile(path);
            return std::make_shared<AirlReward>(
                AirlReward{std::make_shared<const policy::AirlRewardModel>(
                    policy::AirlRewardModel::Load(path))});
          },
          py::arg("path"),
          "Loads an AIRL reward model file. Raises FileNotFoundError if there is no such file.")
      .def(
          "save", [](const AirlReward& r, const std::string& path) { r.model->Save(path); },
          py::arg("path"), "Writes the model file (atomically).")
      .def(
          "q",
          [](const AirlReward& r, ArrayLike state, ArrayLike next_states) {
            const int dim = r.model->observation_dim();
            const Eigen::VectorXf s = Vector(state, dim, "state");
            const StatesArg next = States(next_states, dim, "next_states", false);
            policy::AirlActionValue value(
                *r.model, r.model->observation_features,
                static_cast<int>(std::max<Eigen::Index>(1, next.map.cols())));
            py::array_t<double> q(next.map.cols());
            Eigen::Map<Eigen::VectorXd> out(q.mutable_data(), next.map.cols());
            value.Evaluate(s, next.map, out);
            return q;
          },
          py::arg("state"), py::arg("next_states"),
          "Q = g(state) + gamma V(s+) for each row of next_states (K, observation_dim).")
      .def_property_readonly("discount", [](const AirlReward& r) { return r.model->discount; })
      .def_property_readonly("observation_features",
                             [](const AirlReward& r) { return r.model->observation_features; })
      .def_property_readonly("input_features",
                             [](const AirlReward& r) { return r.model->input_features; })
      .def("__repr__", [](const AirlReward& r) {
        return "<secure.AirlReward on " + std::to_string(r.model->observation_dim()) +
               " observation features, discount " + std::to_string(r.model->discount) + ">";
      });

  m.def(
      "train_airl",
      [](const data::TrajectorySet& demos, EnvOrName env, std::shared_ptr<Policy> warm_start,
         bool with_reward, py::kwargs options) -> AirlResult {
        auto o = OptionsFrom<policy::AirlOptions>(options, "train_airl options");
        const std::shared_ptr<const domains::Environment> e = EnvironmentOf(env);
        policy::AirlSummary summary;
        policy::GaussianPolicy p;
        policy::AirlRewardModel reward;
        {
          py::gil_scoped_release release;
          nn::SetTorchThreads(1);
          p = policy::TrainAirl(o, demos, *e, warm_start ? &warm_start->model() : nullptr, &summary,
                                nullptr, with_reward ? &reward : nullptr);
        }
        if (with_reward)
          return py::make_tuple(
              std::make_shared<Policy>(std::move(p)), ToPython(summary.ToJson()),
              std::make_shared<AirlReward>(
                  AirlReward{std::make_shared<const policy::AirlRewardModel>(std::move(reward))}));
        return py::make_tuple(std::make_shared<Policy>(std::move(p)), ToPython(summary.ToJson()));
      },
      py::arg("demonstrations"), py::arg("env"), py::arg("warm_start") = nullptr, py::kw_only(),
      py::arg("with_reward") = false, R"doc(
AIRL (discriminator + PPO) on secure.Demonstrations, rolling out in `env` (a secure.Env or a
domain name); keyword arguments are AirlOptions (the `airl` section of a config: iterations,
steps_per_iteration, seed, ...; errors as for train_bc). Returns (policy, summary dict), and
with with_reward=True (policy, summary, secure.AirlReward). Releases the GIL.)doc");

  m.def(
      "run_episodes",
      [](EnvOrName env, std::shared_ptr<Policy> policy, std::shared_ptr<Barrier> barrier,
         long episodes, std::uint64_t seed, bool stop_on_collision,
         std::shared_ptr<AirlReward> task_value, py::kwargs shield_options) -> JsonDict {
        Required(policy, "run_episodes: policy", "a secure.Policy");
        const std::unique_ptr<domains::Environment> e = EnvironmentOf(env)->Clone();
        const shield::ShieldOptions options = ShieldOptionsFrom(shield_options);
        const bool top_q = options.aggregation == shield::Aggregation::kTopQ;
        if (barrier && top_q != (task_value != nullptr))
          throw py::value_error(top_q ? "aggregation='top-q' needs task_value=secure.AirlReward"
                                      : "task_value is used only with aggregation='top-q'");
        std::unique_ptr<cbf::Barrier> evaluator;
        std::optional<shield::Shield> shield;
        std::optional<policy::AirlActionValue> value;
        if (barrier) {
          evaluator = EvaluatorOn(*barrier, e->ObservationFeatures());
          shield.emplace(options, *evaluator, e->ShieldModel());
          shield->SetActionBounds(*e);  // the environment's actuator box
          if (task_value) {
            value.emplace(*task_value->model, e->ObservationFeatures(),
                          std::max(options.num_samples, options.num_probes));
            shield->SetActionValue(&*value);
          }
        }
        policy::PolicyEvaluator evaluate(policy->model());
        eval::EpisodeRunnerOptions runner_options;
        runner_options.stop_on_collision = stop_on_collision;
        eval::EpisodeRunner runner(*e, runner_options);
        eval::SeedResult result;
        {
          py::gil_scoped_release release;
          result = runner.Run(evaluate, shield ? &*shield : nullptr, episodes, seed);
        }
        py::dict out = ToPython(result.ToJson());
        out["episode_outcomes"] = EpisodeOutcomesToNumpy(result.episode_outcomes);
        return out;
      },
      py::arg("env"), py::arg("policy"), py::arg("barrier") = nullptr, py::arg("episodes") = 1,
      py::arg("seed") = 0, py::arg("stop_on_collision") = false, py::kw_only(),
      py::arg("task_value") = nullptr, R"doc(
Runs `episodes` episodes of `policy` in (a fresh copy of) `env` (a secure.Env or a domain name)
with the library's episode loop (eval::EpisodeRunner, as `secure eval` runs a method): shielded
by `barrier` with the environment's shield model when given (keyword arguments: the shield's
options; aggregation='top-q' with task_value=secure.AirlReward), else sampling the policy.
Episode i draws from secure.episode_seed(seed, i). Returns
the counts as a dict (successes, dangerous, steps, decisions, interventions, latency_us, ...,
dangerous_episodes and failed_episodes: the indices), with "episode_outcomes": a dict of int64
NumPy arrays, one entry per episode (episode, success, dangerous, steps, first_dangerous_step
(-1: none), collision_events, interventions, no_safe_action_decisions; summed they give the
counts). Releases the GIL.)doc");
}

}  // namespace secure::python
