// NumPy/YAML/JSON conversions, secure.Rng, the exception translation, and the module itself.
#include "python/src/common.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <new>
#include <sstream>

#include "secure/common/build_info.h"
#include "secure/common/error.h"
#include "secure/common/input_limits.h"
#include "secure/common/rng.h"
#include "secure/eval/policy_eval.h"

namespace secure::python {

namespace {

std::string ShapeOf(const py::array& a) {
  std::ostringstream out;
  out << "(";
  for (py::ssize_t k = 0; k < a.ndim(); ++k) out << (k ? ", " : "") << a.shape(k);
  out << (a.ndim() == 1 ? ",)" : ")");
  return out.str();
}

// repr() bounded in length and depth (reprlib): a message never expands a huge or cyclic value.
std::string ShortRepr(py::handle obj) {
  return py::str(py::module_::import("reprlib").attr("repr")(obj));
}

std::string TypeName(py::handle obj) {
  return py::str(py::type::handle_of(obj).attr("__name__"));
}

}  // namespace

FloatArray AsFloat32(py::handle obj, const std::string& what) {
  py::array array = py::array::ensure(obj);
  if (!array) {
    throw py::type_error(what + ": expected a NumPy array (or a nested list of numbers), got " +
                         std::string(py::str(py::type::handle_of(obj).attr("__name__"))));
  }
  const char kind = array.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u') {
    throw py::type_error(what + ": dtype " + std::string(py::str(array.dtype())) +
                         " is not a real number type (use float32; float64 and integer arrays "
                         "are converted)");
  }
  // A float64 (or wider) value beyond float32's range would become inf in the copy and be
  // reported as "inf": name it as given.
  if (kind == 'f' && array.itemsize() > 4) {
    using Doubles = py::array_t<double, py::array::c_style | py::array::forcecast>;
    const Doubles d = Doubles::ensure(array);
    if (d) {
      const double* v = d.data();
      for (py::ssize_t k = 0; k < d.size(); ++k) {
        if (std::isfinite(v[k]) && std::abs(v[k]) > std::numeric_limits<float>::max()) {
          std::ostringstream out;
          out.precision(17);
          out << what << ": value " << v[k] << " (flat index " << k
              << ") is outside float32's range (|x| <= 3.4028235e+38)";
          throw py::value_error(out.str());
        }
      }
    }
  }
  // float32 and C-contiguous: the same object, no copy. Otherwise a converted copy.
  FloatArray out = FloatArray::ensure(array);
  if (!out) throw py::error_already_set();
  return out;
}

StatesArg States(py::handle obj, int dim, const std::string& what, bool allow_1d) {
  StatesArg s;
  s.array = AsFloat32(obj, what);
  const py::ssize_t ndim = s.array.ndim();
  const std::string expected =
      "(N, " + (dim >= 0 ? std::to_string(dim) : std::string("d")) + ")" +
      (allow_1d ? " or (" + (dim >= 0 ? std::to_string(dim) : std::string("d")) + ",)" : "");
  if (ndim == 1 && allow_1d) {
    s.one = true;
    if (dim >= 0 && s.array.shape(0) != dim) {
      throw py::value_error(what + ": expected shape " + expected + ", got " + ShapeOf(s.array) +
                            " (" + std::to_string(dim) + " values per state)");
    }
    new (&s.map) Eigen::Map<const Eigen::MatrixXf>(s.array.data(), s.array.shape(0), 1);
    return s;
  }
  if (ndim != 2 || (dim >= 0 && s.array.shape(1) != dim)) {
    throw py::value_error(what + ": expected shape " + expected + ", got " + ShapeOf(s.array) +
                          (dim >= 0 ? " (" + std::to_string(dim) + " values per state)" : ""));
  }
  new (&s.map)
      Eigen::Map<const Eigen::MatrixXf>(s.array.data(), s.array.shape(1), s.array.shape(0));
  return s;
}

Eigen::VectorXf Vector(py::handle obj, int n, const std::string& what) {
  const FloatArray a = AsFloat32(obj, what);
  if (a.ndim() != 1 || (n >= 0 && a.shape(0) != n)) {
    throw py::value_error(what + ": expected shape (" + std::to_string(n) + ",), got " +
                          ShapeOf(a));
  }
  return Eigen::Map<const Eigen::VectorXf>(a.data(), a.shape(0));
}

Eigen::MatrixXf Matrix(py::handle obj, int rows, int cols, const std::string& what) {
  const FloatArray a = AsFloat32(obj, what);
  if (a.ndim() != 2 || (rows >= 0 && a.shape(0) != rows) || (cols >= 0 && a.shape(1) != cols)) {
    throw py::value_error(
        what + ": expected shape (" + (rows >= 0 ? std::to_string(rows) : std::string("rows")) +
        ", " + (cols >= 0 ? std::to_string(cols) : std::string("cols")) + "), got " + ShapeOf(a));
  }
  using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  return Eigen::Map<const RowMajor>(a.data(), a.shape(0), a.shape(1));
}

py::array_t<float> ToNumpy(const Eigen::Ref<const Eigen::VectorXf>& v) {
  py::array_t<float> out(v.size());
  std::memcpy(out.mutable_data(), v.data(), sizeof(float) * static_cast<std::size_t>(v.size()));
  return out;
}

py::array_t<float> StatesToNumpy(const Eigen::Ref<const Eigen::MatrixXf>& m) {
  py::array_t<float> out({m.cols(), m.rows()});
  float* data = out.mutable_data();
  for (Eigen::Index j = 0; j < m.cols(); ++j)
    for (Eigen::Index i = 0; i < m.rows(); ++i) data[j * m.rows() + i] = m(i, j);
  return out;
}

namespace {

// The walk of ToYaml: at most max_config_nodes values and max_config_depth levels (the limits of
// a config file, secure/common/input_limits.h), so that a list that contains itself or nine
// levels of shared references (9^9 values) fail at once instead of recursing without end.
struct YamlWalk {
  long nodes = 0;
  int depth = 0;
  const InputLimits limits = GetInputLimits();
};

YAML::Node ToYamlIn(py::handle obj, const std::string& where, YamlWalk& walk);

}  // namespace

YAML::Node ToYaml(py::handle obj, const std::string& where) {
  YamlWalk walk;
  return ToYamlIn(obj, where, walk);
}

namespace {

YAML::Node ToYamlIn(py::handle obj, const std::string& where, YamlWalk& walk) {
  if (++walk.nodes > walk.limits.max_config_nodes)
    throw py::value_error(where + ": more than " + std::to_string(walk.limits.max_config_nodes) +
                          " nodes in the options (nested or shared lists/dicts; raise the limit "
                          "with SECURE_MAX_CONFIG_NODES)");
  if (walk.depth > walk.limits.max_config_depth)
    throw py::value_error(where + ": options nested more than " +
                          std::to_string(walk.limits.max_config_depth) +
                          " levels deep (a list or dict that contains itself?)");
  struct Deeper {
    YamlWalk& w;
    explicit Deeper(YamlWalk& walk) : w(walk) { ++w.depth; }
    ~Deeper() { --w.depth; }
  } deeper(walk);
  if (obj.is_none()) return YAML::Node(YAML::NodeType::Null);
  if (py::isinstance<py::bool_>(obj)) return YAML::Node(obj.cast<bool>() ? "true" : "false");
  if (py::isinstance<py::dict>(obj)) {
    YAML::Node node(YAML::NodeType::Map);
    for (const auto& item : obj.cast<py::dict>()) {
      if (!py::isinstance<py::str>(item.first))
        throw py::type_error(where + ": option names must be strings, got " +
                             ShortRepr(item.first));
      const std::string key = item.first.cast<std::string>();
      node[key] = ToYamlIn(item.second, walk.depth < 8 ? where + " [" + key + "]" : where, walk);
    }
    return node;
  }
  if (py::isinstance<py::str>(obj)) return YAML::Node(obj.cast<std::string>());
  if (py::isinstance<py::list>(obj) || py::isinstance<py::tuple>(obj) ||
      py::isinstance<py::array>(obj)) {
    YAML::Node node(YAML::NodeType::Sequence);
    py::object seq = py::isinstance<py::array>(obj) ? obj.attr("tolist")()
                                                    : py::reinterpret_borrow<py::object>(obj);
    for (py::handle item : seq) node.push_back(ToYamlIn(item, where, walk));
    return node;
  }
  // Numbers (Python or NumPy scalars): integers as integers, others by repr (all digits).
  py::module_ numbers = py::module_::import("numbers");
  if (py::isinstance(obj, numbers.attr("Integral")))
    return YAML::Node(std::string(py::str(py::int_(py::reinterpret_borrow<py::object>(obj)))));
  if (py::isinstance(obj, numbers.attr("Real")))
    return YAML::Node(std::string(py::repr(py::float_(py::reinterpret_borrow<py::object>(obj)))));
  throw py::type_error(where + ": cannot use a value of type " +
                       std::string(py::str(py::type::handle_of(obj).attr("__name__"))) +
                       " as an option (use numbers, strings, booleans, lists or dicts)");
}

}  // namespace

py::object ToPython(const nlohmann::json& j) {
  switch (j.type()) {
    case nlohmann::json::value_t::null:
      return py::none();
    case nlohmann::json::value_t::boolean:
      return py::bool_(j.get<bool>());
    case nlohmann::json::value_t::number_integer:
      return py::int_(j.get<std::int64_t>());
    case nlohmann::json::value_t::number_unsigned:
      return py::int_(j.get<std::uint64_t>());
    case nlohmann::json::value_t::number_float:
      return py::float_(j.get<double>());
    case nlohmann::json::value_t::string:
      return py::str(j.get<std::string>());
    case nlohmann::json::value_t::array: {
      py::list list;
      for (const auto& item : j) list.append(ToPython(item));
      return list;
    }
    case nlohmann::json::value_t::object: {
      py::dict dict;
      for (const auto& [key, value] : j.items()) dict[py::str(key)] = ToPython(value);
      return dict;
    }
    default:
      return py::none();
  }
}

std::vector<std::string> FeatureNames(py::handle names, int dim, const std::string& prefix,
                                      const std::string& what) {
  std::vector<std::string> out;
  if (names.is_none()) {
    for (int k = 0; k < dim; ++k) out.push_back(prefix + std::to_string(k));
    return out;
  }
  if (py::isinstance<py::str>(names) || !py::isinstance<py::sequence>(names)) {
    throw py::type_error(what + ": expected a sequence of str (or None), got " +
                         TypeName(names));
  }
  try {
    out = names.cast<std::vector<std::string>>();
  } catch (const py::cast_error&) {
    throw py::type_error(what + ": expected a sequence of str, got " +
                         ShortRepr(names));
  }
  if (static_cast<int>(out.size()) != dim) {
    throw py::value_error(what + ": " + std::to_string(out.size()) + " names for " +
                          std::to_string(dim) + " columns");
  }
  // As the CLI: a model reads its columns by name, so a name twice could not be used.
  for (std::size_t i = 0; i < out.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (out[i] == out[j])
        throw py::value_error(what + ": duplicate name '" + out[i] + "' (columns " +
                              std::to_string(j) + " and " + std::to_string(i) +
                              "); every column needs its own name");
  return out;
}

void RequireFile(const std::string& path) {
  std::error_code error;
  if (std::filesystem::exists(path, error) || error) return;  // other problems: the loader's
  py::object e = py::module_::import("builtins")
                     .attr("FileNotFoundError")(ENOENT, std::strerror(ENOENT), path);
  PyErr_SetObject(PyExc_FileNotFoundError, e.ptr());
  throw py::error_already_set();
}

void CheckOptionTypes(py::handle options, const nlohmann::json& defaults,
                      const std::string& source) {
  if (!defaults.is_object() || !py::isinstance<py::dict>(options)) return;
  py::module_ numbers = py::module_::import("numbers");
  py::module_ numpy = py::module_::import("numpy");
  for (const auto& item : options.cast<py::dict>()) {
    if (!py::isinstance<py::str>(item.first)) continue;  // ToYaml names it
    const std::string key = item.first.cast<std::string>();
    const auto it = defaults.find(key);
    if (it == defaults.end() || it->is_null()) continue;  // unknown keys: the options' reader
    py::handle v = item.second;
    const bool is_bool = py::isinstance<py::bool_>(v) || py::isinstance(v, numpy.attr("bool_"));
    const bool is_sequence = py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v) ||
                             py::isinstance<py::array>(v);
    const char* expected = nullptr;
    switch (it->type()) {
      case nlohmann::json::value_t::boolean:
        if (!is_bool) expected = "a bool";
        break;
      case nlohmann::json::value_t::number_integer:
      case nlohmann::json::value_t::number_unsigned:
        if (is_bool || !py::isinstance(v, numbers.attr("Integral"))) expected = "an int";
        break;
      case nlohmann::json::value_t::number_float:
        if (is_bool || !py::isinstance(v, numbers.attr("Real"))) expected = "a number";
        break;
      case nlohmann::json::value_t::string:
        if (!py::isinstance<py::str>(v)) expected = "a str";
        break;
      case nlohmann::json::value_t::array:
        if (!is_sequence) expected = "a list";
        break;
      case nlohmann::json::value_t::object:
        if (!py::isinstance<py::dict>(v)) {
          expected = "a dict";
        } else {
          CheckOptionTypes(v, *it, source + " [" + key + "]");
        }
        break;
      default:
        break;
    }
    if (expected != nullptr) {
      throw py::type_error(source + ": option '" + key + "' = " + ShortRepr(v) +
                           " (" + TypeName(v) + "), expected " + expected);
    }
  }
}

std::shared_ptr<Barrier> MakeBarrier(std::string kind,
                                     std::function<std::unique_ptr<cbf::Barrier>()> factory) {
  auto b = std::make_shared<Barrier>();
  b->kind = std::move(kind);
  b->factory = std::move(factory);
  b->evaluator = b->factory();
  return b;
}

std::unique_ptr<cbf::Barrier> EvaluatorOn(const Barrier& barrier,
                                          const std::vector<std::string>& state_features) {
  // Rows by position, as always, where the dimensions agree (a barrier trained without feature
  // names, x0, x1, ..., keeps working on a domain's states); by name where they cannot.
  if (barrier.net == nullptr || state_features.empty() ||
      static_cast<std::size_t>(barrier.state_dim()) == state_features.size()) {
    return barrier.factory();
  }
  return barrier.net->MakeEvaluatorFor(state_features, "the dynamics model's states",
                                       "the barrier");
}

void RegisterCommon(py::module_& m) {
  // secure::Error (bad input, bad option, bad file) becomes ValueError with the library's
  // message; a failed conversion of a Python value TypeError; pybind11 maps std::bad_alloc to
  // MemoryError. (A missing file is a FileNotFoundError from RequireFile, before the loader.)
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const secure::Error& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const py::cast_error& e) {
      // A Python value of the wrong type reached a C++ conversion (pybind11 would say
      // RuntimeError): a TypeError, as Python's own conversions raise.
      PyErr_SetString(PyExc_TypeError, e.what());
    }
  });

  m.attr("__version__") = std::string(secure::Version());
  m.def(
      "build_info",
      [] {
        return std::map<std::string, std::string>{{"version", std::string(secure::Version())},
                                                  {"git_sha", std::string(secure::GitSha())}};
      },
      "The library's version and git sha.");

  py::class_<Rng>(m, "Rng", R"doc(
The library's random stream (xoshiro256++ with its own normal transform): the same numbers as
the C++ code for the same seed, so a Python loop can replay a C++ run.)doc")
      .def(py::init<std::uint64_t>(), py::arg("seed") = 0)
      .def("seed", &Rng::Seed, py::arg("seed"), "Restarts the stream from `seed`.")
      .def("next_u64", &Rng::NextU64, "The next raw 64-bit value.")
      .def("uniform", py::overload_cast<>(&Rng::Uniform), "Uniform in [0, 1).")
      .def("normal", &Rng::Normal, "Standard normal.");

  m.def("episode_seed", &eval::EpisodeSeed, py::arg("seed"), py::arg("episode"),
        "The stream of episode `episode` of an evaluation with `seed` (eval::EpisodeSeed).");
}

}  // namespace secure::python
