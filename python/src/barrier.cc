// secure.Barrier (load, h, save) and secure.train_barrier.
#include <cmath>
#include <limits>
#include <optional>
#include <sstream>

#include "python/src/common.h"
#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/car_barrier_trainer.h"
#include "secure/common/error.h"
#include "secure/data/data.h"
#include "secure/experiments/experiment.h"
#include "secure/nn/model_file.h"

namespace secure::python {
namespace {

std::shared_ptr<Barrier> FromNet(cbf::BarrierNet net) {
  auto shared = std::make_shared<const cbf::BarrierNet>(std::move(net));
  const char* kind =
      shared->more_members.empty() ? cbf::kBarrierModelKind : cbf::kBarrierEnsembleModelKind;
  auto b = MakeBarrier(kind, [shared] { return shared->MakeEvaluator(); });
  b->net = shared;
  return b;
}

std::shared_ptr<Barrier> FromCar(cbf::CarBarrierNet net) {
  auto shared = std::make_shared<const cbf::CarBarrierNet>(std::move(net));
  auto b = MakeBarrier(cbf::kCarBarrierModelKind, [shared] { return shared->MakeEvaluator(); });
  b->car = shared;
  return b;
}

std::shared_ptr<Barrier> Load(const std::string& path) {
  RequireFile(path);
  std::string kind;
  {
    py::gil_scoped_release release;
    kind = nn::ReadModelFile(path).kind;
  }
  if (cbf::IsFlatBarrierKind(kind)) return FromNet(cbf::BarrierNet::Load(path));
  if (kind == cbf::kCarBarrierModelKind) return FromCar(cbf::CarBarrierNet::Load(path));
  SECURE_THROW(path << ": a model of kind '" << kind << "', not a barrier (kinds "
                    << cbf::kBarrierModelKind << ", " << cbf::kBarrierEnsembleModelKind << ", "
                    << cbf::kCarBarrierModelKind << ")");
}

// A non-finite entry of the states: a ValueError naming the row and column.
void CheckFinite(const StatesArg& s, const std::string& what) {
  const Eigen::Map<const Eigen::MatrixXf>& m = s.map;
  if (m.allFinite()) return;
  for (Eigen::Index j = 0; j < m.cols(); ++j)
    for (Eigen::Index i = 0; i < m.rows(); ++i)
      if (!std::isfinite(m(i, j))) {
        std::ostringstream out;
        out << what << "[" << (s.one ? "" : std::to_string(j) + ", ") << i << "] = " << m(i, j)
            << ": states must be finite";
        throw py::value_error(out.str());
      }
}

FloatOrArray H(Barrier& b, ArrayLike states) {
  const StatesArg s = States(states, b.state_dim(), "states");
  CheckFinite(s, "states");
  py::array_t<float> h(s.map.cols());
  Eigen::Map<Eigen::VectorXf> out(h.mutable_data(), s.map.cols());
  {
    py::gil_scoped_release release;
    std::lock_guard<std::mutex> lock(b.mutex);
    b.evaluator->Evaluate(s.map, out);
  }
  if (s.one) return FloatOrArray(py::float_(static_cast<double>(out[0])));
  return FloatOrArray(std::move(h));
}

data::StateSet StateSetOf(py::handle states, int dim, const std::vector<std::string>* features,
                          const std::string& what) {
  const StatesArg s = States(states, dim, what, /*allow_1d=*/false);
  data::StateSet set;
  set.source = what + " (NumPy array)";
  set.features = features != nullptr
                     ? *features
                     : FeatureNames(py::none(), static_cast<int>(s.map.rows()), "x", what);
  set.states = s.map;  // a copy: the library keeps its own
  return set;
}

// A trainer's two labelled sets: `safe` and `near_dangerous`, (N, d) arrays of one width d, their
// columns named by `features` (default: `domain_features` when it has d names, else x0, x1, ...).
struct LabelledSets {
  data::StateSet safe, near_dangerous;
};
LabelledSets LabelledSetsOf(py::handle safe, py::handle near_dangerous, py::handle features,
                            const std::vector<std::string>& domain_features = {}) {
  const int dim = static_cast<int>(States(safe, -1, "safe", false).map.rows());
  const std::vector<std::string> names =
      features.is_none() && static_cast<int>(domain_features.size()) == dim
          ? domain_features
          : FeatureNames(features, dim, "x", "features");
  return {StateSetOf(safe, dim, &names, "safe"),
          StateSetOf(near_dangerous, dim, &names, "near_dangerous")};
}

}  // namespace

void RegisterBarrier(py::module_& m) {
  py::class_<Barrier, std::shared_ptr<Barrier>>(m, "Barrier", R"doc(
A control barrier function h(s): h >= 0 on the safe set. Load one with Barrier.load(path) (a
`secure cbf train` model, flat or per-obstacle), train one with secure.train_barrier, or take a
domain's analytic ground truth with Barrier.ground_truth(domain).)doc")
      .def_static("load", &Load, py::arg("path"), R"doc(
Loads a barrier model file (any barrier kind: a `secure cbf train` model, flat or per-obstacle).
Raises FileNotFoundError if there is no such file, ValueError (naming the file) if it is not a
barrier model or is corrupt.)doc")
      .def_property_readonly(
          "kind", [](const Barrier& b) { return b.kind; },
          "'barrier_mlp' (flat), 'barrier_ensemble' (flat, the minimum over K MLPs: "
          "train_barrier(ensemble=K)), 'car_barrier' (per-obstacle) or 'ground_truth'.")
      .def_property_readonly("state_dim", &Barrier::state_dim,
                             "The width of a state: the columns of h's input.")
      .def_property_readonly(
          "features",
          [](const Barrier& b) -> std::vector<std::string> {
            if (b.net) return b.net->features;
            if (b.car) return b.car->features;
            return {};
          },
          "Names of the state rows the model reads (empty if unknown).")
      .def_property_readonly(
          "provenance",
          [](const Barrier& b) -> JsonDict {
            if (b.net) return ToPython(b.net->provenance);
            if (b.car) return ToPython(b.car->provenance);
            return py::dict();
          },
          "The training options, summary and data the model file records.")
      .def(
          "describe", [](const Barrier& b) { return b.evaluator->Describe(); },
          "One line: the model's kind and layers (e.g. 'barrier_mlp 4-64-64-1 tanh'), or the "
          "ground truth's parameters.")
      .def("__repr__",
           [](const Barrier& b) { return "<secure.Barrier " + b.evaluator->Describe() + ">"; })
      .def("h", &H, py::arg("states"), R"doc(
h(s) of a batch of states, an (N, state_dim) array -> (N,) float32 array; or of one state, a
(state_dim,) array -> float. C-contiguous float32 input is read in place; other real dtypes are
converted. Raises ValueError on a wrong shape or a non-finite entry, TypeError on a bool,
complex, object or string array. Releases the GIL.)doc")
      .def(
          "save",
          [](const Barrier& b, const std::string& path) {
            py::gil_scoped_release release;
            if (b.net) return b.net->Save(path);
            if (b.car) return b.car->Save(path);
            SECURE_THROW("a " << b.kind << " barrier has no model file to save");
          },
          py::arg("path"),
          "Writes the model file (atomically). A ground-truth barrier has none: ValueError.");

  m.def(
      "train_barrier",
      [](ArrayLike safe, ArrayLike near_dangerous, FeatureNamesArg features,
         py::kwargs options) -> BarrierAndSummary {
        cbf::BarrierTrainerOptions o;
        CheckOptionTypes(options, o.ToJson(), "train_barrier options");
        o.ApplyYaml(ToYaml(options, "train_barrier"), "train_barrier options");
        const LabelledSets sets = LabelledSetsOf(safe, near_dangerous, features);
        cbf::BarrierTrainingSummary summary;
        cbf::BarrierNet net;
        {
          py::gil_scoped_release release;
          net = cbf::TrainBarrier(o, sets.safe, sets.near_dangerous, &summary);
        }
        return py::make_tuple(FromNet(std::move(net)), ToPython(summary.ToJson()));
      },
      py::arg("safe"), py::arg("near_dangerous"), py::arg("features") = py::none(), R"doc(
Trains a flat barrier (an MLP, paper Eq. 4) on safe and near-dangerous states, two (N, d)
arrays with the same d. `features` names the d columns (default x0, x1, ...); the keyword
arguments are the trainer's options, the keys of `secure cbf train`'s config section `trainer`
(hidden=[64, 64], max_epochs=400, seed=0, ...): an unknown key is a ValueError naming it and
listing the valid ones, a value of the wrong type (max_epochs='many') a TypeError, a value out of
range (batch_size=0) a ValueError naming the field and the rule. Returns (barrier, summary
dict). Releases the GIL while training.)doc");

  m.def(
      "train_car_barrier",
      [](ArrayLike safe, ArrayLike near_dangerous, std::optional<std::string> domain,
         FeatureNamesArg features, py::kwargs options) -> BarrierAndSummary {
        // The domain's preset (its obstacle layout, radii and trainer settings), or the defaults
        // (then `layout` must be given), with the keyword arguments on top.
        cbf::CarBarrierTrainerOptions o;
        std::vector<std::string> domain_features;
        if (domain) {
          const std::unique_ptr<experiments::Domain> d = MakeDomain(*domain, "full", py::dict());
          o = d->Preset().per_obstacle_barrier;
          domain_features = d->MakeEnvironment()->ObservationFeatures();
        }
        CheckOptionTypes(options, o.ToJson(), "train_car_barrier options");
        o.ApplyYaml(ToYaml(options, "train_car_barrier"), "train_car_barrier options");
        const LabelledSets sets = LabelledSetsOf(safe, near_dangerous, features, domain_features);
        cbf::CarBarrierTrainingSummary summary;
        cbf::CarBarrierNet net;
        {
          py::gil_scoped_release release;
          net = cbf::TrainCarBarrier(o, sets.safe, sets.near_dangerous, &summary);
        }
        return py::make_tuple(FromCar(std::move(net)), ToPython(summary.ToJson()));
      },
      py::arg("safe"), py::arg("near_dangerous"), py::arg("domain") = py::none(),
      py::arg("features") = py::none(), R"doc(
Trains a per-obstacle barrier (cbf::CarBarrierNet: one MLP per car, min over the cars in range)
on observations, two (N, obs_dim) arrays. `domain` (e.g. 'derby') starts from that domain's
preset (its obstacle layout and trainer settings) and names the columns with its observation
features; the keyword arguments are the car barrier trainer's options (the keys of a config's
`per_obstacle_barrier` section: hidden, max_epochs, seed, layout={...}, ...; errors as for
train_barrier). Returns (barrier, summary dict). Releases the GIL while training.)doc");
}

}  // namespace secure::python
