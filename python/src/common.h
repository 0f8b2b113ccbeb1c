#pragma once
// Shared by the binding's translation units: NumPy <-> Eigen conversion with the module's dtype
// rule, Python values -> YAML (the options' field tables read them), JSON -> Python, and the
// wrapper types that cross translation units (a barrier goes into a shield, an environment hands
// out its dynamics model). No <torch/torch.h> here: the binding never includes it.
//
// The dtype rule (python/README.md): arrays of states, actions and matrices are float32. A
// C-contiguous float32 array is read in place (no copy); any other floating or integer array
// (float64, int64, a strided view, ...) is converted to a C-contiguous float32 copy; bool,
// complex, object and string arrays are a TypeError. Wrong shapes are a ValueError naming the
// expected and the given shape.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <functional>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"
#include "secure/experiments/domain.h"
#include "secure/policy/airl_reward.h"
#include "secure/shield/shield.h"
#include "python/src/guard.h"

namespace secure::python {

namespace py = pybind11;

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;

// ---------------------------------------------------------------------------------------------
// Python type names for signatures. pybind11 2.10 calls a py::handle / py::object argument
// "handle" / "object" in help() and in the stubs; a Typed<Name> is a py::object that accepts any
// value (the conversions below check it, raising TypeError / ValueError with our messages) and is
// called Name::name there. python/tools/make_stub.py turns these names into the stub's types, and
// refuses "handle" and "object": every argument and result of the module has a real type.
inline int AnyPythonObject(PyObject* /*object*/) { return 1; }

template <typename Name>
class Typed : public py::object {
 public:
  PYBIND11_OBJECT_DEFAULT(Typed, py::object, AnyPythonObject)
};

#define SECURE_PYTHON_TYPE(Alias, text)                              \
  struct Alias##TypeName {                                           \
    static constexpr auto name = pybind11::detail::const_name(text); \
  };                                                                 \
  using Alias = Typed<Alias##TypeName>

SECURE_PYTHON_TYPE(ArrayLike, "numpy.typing.ArrayLike");
SECURE_PYTHON_TYPE(OptionalArrayLike, "Optional[numpy.typing.ArrayLike]");
SECURE_PYTHON_TYPE(FloatOrArray, "Union[float, numpy.typing.NDArray[numpy.float32]]");
SECURE_PYTHON_TYPE(OptionalArray, "Optional[numpy.typing.NDArray[numpy.float32]]");
SECURE_PYTHON_TYPE(FeatureNamesArg, "Optional[Sequence[str]]");
SECURE_PYTHON_TYPE(JsonDict, "Dict[str, Any]");
// A secure.Env (the Python class of env.py, or a Gymnasium wrapper of one) or a domain name.
SECURE_PYTHON_TYPE(EnvOrName, "Union[str, Any]");
SECURE_PYTHON_TYPE(OptionalJsonDict, "Optional[Dict[str, Any]]");
SECURE_PYTHON_TYPE(RngOrSeed, "Union[Rng, int]");
SECURE_PYTHON_TYPE(DynamicsFunction,
                   "Callable[[numpy.typing.NDArray[numpy.float32], "
                   "numpy.typing.NDArray[numpy.float32]], numpy.typing.ArrayLike]");
SECURE_PYTHON_TYPE(OptionalBarrier, "Optional[Barrier]");
SECURE_PYTHON_TYPE(BarrierAndSummary, "Tuple[Barrier, Dict[str, Any]]");
SECURE_PYTHON_TYPE(PolicyAndSummary, "Tuple[Policy, Dict[str, Any]]");
SECURE_PYTHON_TYPE(
    AirlResult, "Union[Tuple[Policy, Dict[str, Any]], Tuple[Policy, Dict[str, Any], AirlReward]]");
SECURE_PYTHON_TYPE(ResetResult, "Tuple[numpy.typing.NDArray[numpy.float32], Dict[str, Any]]");
SECURE_PYTHON_TYPE(StepResult,
                   "Tuple[numpy.typing.NDArray[numpy.float32], float, bool, bool, Dict[str, Any]]");

/// TypeError if a keyword option's Python type does not fit the type of its default in
/// `defaults` (an options object's ToJson(): a bool for a bool, an int for an integer, a real
/// number for a float, a str for a string, a list/tuple/array for a list, a dict for a section,
/// checked inside); keys not in `defaults` or with a null default are left to the options' reader.
/// "train_barrier options: option 'max_epochs' = 'many' (str), expected an int".
void CheckOptionTypes(py::handle options, const nlohmann::json& defaults,
                      const std::string& source);

/// FileNotFoundError (errno ENOENT, the path as `filename`) if `path` does not exist, before a
/// loader reads it (the library's own error for a missing file is a secure::Error, ValueError).
void RequireFile(const std::string& path);

/// `obj` as a C-contiguous float32 array: the same object when it already is one, else a
/// converted copy (dtype rule above). `what` names the argument in messages.
FloatArray AsFloat32(py::handle obj, const std::string& what);

/// A batch of states: a (N, dim) array (or, with allow_1d, one (dim,) state: N = 1). The map
/// views the array's buffer as the library's (dim x N) column-major matrix (one state per
/// column): the same bytes, no copy. `array` keeps the buffer alive.
struct StatesArg {
  FloatArray array;
  Eigen::Map<const Eigen::MatrixXf> map{nullptr, 0, 0};
  bool one = false;  // a single (dim,) state was given
};
/// dim < 0: any width. @throws ValueError "states: expected shape (N, 4), got (10, 3)".
StatesArg States(py::handle obj, int dim, const std::string& what, bool allow_1d = true);

/// A (n,) vector, copied. @throws ValueError naming `what`, expected and given shapes.
Eigen::VectorXf Vector(py::handle obj, int n, const std::string& what);

/// A (rows, cols) matrix, copied into a column-major Eigen matrix; rows/cols < 0: any.
Eigen::MatrixXf Matrix(py::handle obj, int rows, int cols, const std::string& what);

/// A (n,) float32 NumPy array copied from `v`.
py::array_t<float> ToNumpy(const Eigen::Ref<const Eigen::VectorXf>& v);
/// The (d x N) column-major matrix `m` as a (N, d) float32 NumPy array (copied).
py::array_t<float> StatesToNumpy(const Eigen::Ref<const Eigen::MatrixXf>& m);

/// A Python value (dict, list/tuple, bool, int, float, str, None, NumPy scalar) as YAML, for the
/// options' ApplyYaml field tables (floats keep all their digits: repr()).
YAML::Node ToYaml(py::handle obj, const std::string& where);
/// A JSON value as Python (dict, list, int, float, str, bool, None).
py::object ToPython(const nlohmann::json& json);

/// Feature names: `names` if not None (length `dim`), else x0, x1, ... (`prefix` + index).
std::vector<std::string> FeatureNames(py::handle names, int dim, const std::string& prefix,
                                      const std::string& what);

// ---------------------------------------------------------------------------------------------
// Wrapper types shared between translation units.

/// A barrier model (immutable, shared) and this Python object's own evaluator. Evaluations lock
/// `mutex` (after releasing the GIL), so two Python threads never share the scratch memory.
struct Barrier {
  std::string kind;  // "barrier_mlp", "barrier_ensemble", "car_barrier", or "ground_truth"
  std::shared_ptr<const cbf::BarrierNet> net;
  std::shared_ptr<const cbf::CarBarrierNet> car;
  std::function<std::unique_ptr<cbf::Barrier>()> factory;  // a fresh evaluator
  std::unique_ptr<cbf::Barrier> evaluator;
  std::mutex mutex;

  int state_dim() const { return evaluator->state_dim(); }
};
std::shared_ptr<Barrier> MakeBarrier(std::string kind,
                                     std::function<std::unique_ptr<cbf::Barrier>()> factory);

/// A fresh evaluator of `barrier` on states whose rows are `state_features` (a domain's
/// observation): a flat barrier with fewer inputs than the states (e.g. Panda's 9 of 18) reads
/// its features by name (BarrierNet::MakeEvaluatorFor). Otherwise (as many inputs as rows, empty
/// `state_features` for a linear or Python model, a per-obstacle barrier): barrier.factory(),
/// rows by position.
/// @throws secure::Error naming the first feature of the barrier that the states lack.
std::unique_ptr<cbf::Barrier> EvaluatorOn(const Barrier& barrier,
                                          const std::vector<std::string>& state_features);

/// A dynamics model T(s, a) with whatever keeps it alive (an environment owns its shield model).
/// `python`: the model calls back into Python (each Step re-acquires the GIL).
struct Dynamics {
  std::shared_ptr<const void> owner;
  const domains::DynamicsModel* model = nullptr;
  std::string kind;                         // "builtin:<domain>", "linear", "python"
  std::vector<std::string> state_features;  // the state's rows by name (builtin), else empty
  // The actuator box of the environment the model came from (builtin), else empty: a Shield on
  // this model keeps its decisions inside it unless given another box.
  Eigen::VectorXf action_low, action_high;
  bool python = false;
  // Held while the model steps (models keep scratch memory: one caller at a time). Shields lock
  // it after their own lock; an environment locks it while it steps (its model may be its own).
  // Locking it again from the thread holding it (a callback stepping its own model) raises.
  GuardedMutex mutex{"secure.Dynamics"};
};

/// A domain from the registry with its options for a profile ("full" | "quick") and the keyword
/// arguments applied over them (the domain's config-file keys; unknown keys are a ValueError).
std::unique_ptr<experiments::Domain> MakeDomain(const std::string& name, const std::string& profile,
                                                const py::dict& options);

/// The environment an AIRL trainer rolls out in: a secure.Env, or a domain name.
std::shared_ptr<const domains::Environment> EnvironmentOf(py::handle env);

/// ShieldOptions from keyword arguments (the fields by name, enums by their names); validated.
/// @throws secure::Error naming an unknown key (and the valid ones) or a bad value.
shield::ShieldOptions ShieldOptionsFrom(const py::dict& kwargs);

/// AIRL's reward model (secure.AirlReward): the task value of a shield with aggregation='top-q'.
struct AirlReward {
  std::shared_ptr<const policy::AirlRewardModel> model;
};

/// Registration, one per translation unit.
void RegisterCommon(py::module_& m);
void RegisterBarrier(py::module_& m);
void RegisterDynamics(py::module_& m);
void RegisterShield(py::module_& m);
void RegisterPolicy(py::module_& m);
void RegisterEnvironment(py::module_& m);
void RegisterRender(py::module_& m);

}  // namespace secure::python

// Objects made without __init__ are a TypeError, not a crash (guard.h); Shield, Policy and
// EnvCore, defined in their own files, install the same check there.
SECURE_PYTHON_CHECK_INITIALISED(secure::Rng);
SECURE_PYTHON_CHECK_INITIALISED(secure::python::Barrier);
SECURE_PYTHON_CHECK_INITIALISED(secure::python::Dynamics);
SECURE_PYTHON_CHECK_INITIALISED(secure::python::AirlReward);
SECURE_PYTHON_CHECK_INITIALISED(secure::shield::Decision);
SECURE_PYTHON_CHECK_INITIALISED(secure::data::TrajectorySet);

namespace pybind11::detail {
template <typename Name>
struct handle_type_name<secure::python::Typed<Name>> {
  static constexpr auto name = Name::name;
};
}  // namespace pybind11::detail
