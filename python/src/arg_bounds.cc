// Bounded arguments for every bound function (issue 34): a list nested 9 levels of shared
// references (`l = [0]; for _ in range(9): l = [l] * 9`) is 10 small objects but 9^9 values
// when walked. pybind11 2.10 walks it: when no overload takes the arguments, its TypeError
// message holds repr() of every argument ("Invoked with: ..."), which never ends. So every
// function, method, property and constructor of the module first counts the lists, tuples and
// dicts of its arguments as they would be walked (shared ones each time they occur), with the
// limits of a config file (secure/common/input_limits.h: 100,000 nodes, 64 levels), and raises
// ValueError naming the function and the argument past them. Numbers, strings and arrays are
// one value each and are not looked into; the count costs a pass over the containers only.
//
// An unbound method called with None for self is a TypeError there too.
//
// The check sits in front of pybind11's dispatcher: each function object's PyMethodDef is
// pointed at BoundedDispatcher, which calls pybind11's dispatcher after the check.
#include <Python.h>

#include <string>
#include <unordered_set>

#include "python/src/common.h"
#include "secure/common/input_limits.h"

namespace secure::python {
namespace {

using Dispatcher = PyObject* (*)(PyObject*, PyObject*, PyObject*);
Dispatcher pybind_dispatcher = nullptr;

struct Walk {
  long nodes = 0;
  long max_nodes = 0;
  int max_depth = 0;
};

// False if `o` holds more containers (walked with repetition) or levels than the limits.
bool Within(PyObject* o, Walk& walk, int depth) {
  const bool list = PyList_Check(o), tuple = PyTuple_Check(o), dict = PyDict_Check(o);
  if (!list && !tuple && !dict) return true;
  if (depth >= walk.max_depth || ++walk.nodes > walk.max_nodes) return false;
  if (dict) {
    PyObject *key = nullptr, *value = nullptr;
    Py_ssize_t pos = 0;
    while (PyDict_Next(o, &pos, &key, &value))
      if (!Within(key, walk, depth + 1) || !Within(value, walk, depth + 1)) return false;
    return true;
  }
  // No Python code runs during the walk (no __eq__, no __iter__): the containers cannot change.
  const Py_ssize_t n = list ? PyList_GET_SIZE(o) : PyTuple_GET_SIZE(o);
  for (Py_ssize_t i = 0; i < n; ++i)
    if (!Within(list ? PyList_GET_ITEM(o, i) : PyTuple_GET_ITEM(o, i), walk, depth + 1))
      return false;
  return true;
}

// "secure.Shield.decide": the function `rec` (its class, for a method).
std::string FunctionName(const py::detail::function_record* rec) {
  std::string where = "secure.";
  if (rec->scope && PyType_Check(rec->scope.ptr()))
    where += std::string(py::str(rec->scope.attr("__name__"))) + ".";
  return where + (rec->name != nullptr ? rec->name : "function");
}

py::detail::function_record* RecordOf(PyObject* capsule) {
  return static_cast<py::detail::function_record*>(
      PyCapsule_GetPointer(capsule, PyCapsule_GetName(capsule)));
}

// "secure.Shield.decide: argument 'obs'" for positional argument `index` or `keyword`
// ("argument 2" if unnamed).
std::string Describe(PyObject* capsule, Py_ssize_t index, PyObject* keyword) {
  const py::detail::function_record* rec = RecordOf(capsule);
  const std::string where = FunctionName(rec);
  if (keyword != nullptr) return where + ": argument '" + py::str(keyword).cast<std::string>() + "'";
  if (index >= 0 && static_cast<std::size_t>(index) < rec->args.size() &&
      rec->args[static_cast<std::size_t>(index)].name != nullptr)
    return where + ": argument '" + rec->args[static_cast<std::size_t>(index)].name + "'";
  return where + ": argument " + std::to_string(index + 1);
}

// " [key]": the entry of a dict `value` that is past the limits on its own (make_env(task=x)
// reaches the binding as options={'task': x}), or "".
std::string EntryPastTheLimits(PyObject* value, const Walk& limits) {
  if (!PyDict_Check(value)) return "";
  PyObject *key = nullptr, *item = nullptr;
  Py_ssize_t pos = 0;
  while (PyDict_Next(value, &pos, &key, &item)) {
    Walk walk{0, limits.max_nodes, limits.max_depth};
    if (!Within(item, walk, 1) && PyUnicode_Check(key))
      return " ['" + py::str(key).cast<std::string>() + "']";
  }
  return "";
}

PyObject* Refuse(PyObject* capsule, Py_ssize_t index, PyObject* keyword, PyObject* value,
                 const Walk& walk) {
  const std::string message =
      Describe(capsule, index, keyword) + EntryPastTheLimits(value, walk) + " holds more than " + std::to_string(walk.max_nodes) +
      " nodes (lists, tuples and dicts, counted with repetition) or is nested more than " +
      std::to_string(walk.max_depth) +
      " levels deep (shared references, or a container that contains itself; use a NumPy "
      "array for large data, or raise SECURE_MAX_CONFIG_NODES)";
  PyErr_SetString(PyExc_ValueError, message.c_str());
  return nullptr;
}

PyObject* BoundedDispatcher(PyObject* self, PyObject* args, PyObject* kwargs) {
  // An unbound method called with None for self (`secure.Rng.next_u64(None)`): pybind11 hands a
  // member function pointer a null object for it, which crashed the interpreter.
  const py::detail::function_record* rec = RecordOf(self);
  if (rec == nullptr) return nullptr;  // (PyCapsule_GetPointer set the error)
  if (rec->is_method && !rec->is_constructor && args != nullptr && PyTuple_GET_SIZE(args) > 0 &&
      PyTuple_GET_ITEM(args, 0) == Py_None) {
    const std::string message = FunctionName(rec) +
                                ": called on None (an unbound method needs an object of its "
                                "class as its first argument)";
    PyErr_SetString(PyExc_TypeError, message.c_str());
    return nullptr;
  }
  const InputLimits& limits = GetInputLimits();
  if (args != nullptr) {
    const Py_ssize_t n = PyTuple_GET_SIZE(args);
    for (Py_ssize_t i = 0; i < n; ++i) {
      Walk walk{0, limits.max_config_nodes, limits.max_config_depth};
      if (!Within(PyTuple_GET_ITEM(args, i), walk, 0))
        return Refuse(self, i, nullptr, PyTuple_GET_ITEM(args, i), walk);
    }
  }
  if (kwargs != nullptr) {
    PyObject *key = nullptr, *value = nullptr;
    Py_ssize_t pos = 0;
    while (PyDict_Next(kwargs, &pos, &key, &value)) {
      Walk walk{0, limits.max_config_nodes, limits.max_config_depth};
      if (!Within(value, walk, 0)) return Refuse(self, -1, key, value, walk);
    }
  }
  return pybind_dispatcher(self, args, kwargs);
}

// Points `f` (a function object, or one wrapped as a method, static method or property) at
// BoundedDispatcher if pybind11's dispatcher calls it.
void Patch(PyObject* f) {
  if (f == nullptr) return;
  if (PyInstanceMethod_Check(f)) f = PyInstanceMethod_GET_FUNCTION(f);
  if (!PyCFunction_Check(f)) return;
  PyMethodDef* def = reinterpret_cast<PyCFunctionObject*>(f)->m_ml;
  if (def == nullptr || def->ml_flags != (METH_VARARGS | METH_KEYWORDS)) return;
  auto meth = reinterpret_cast<Dispatcher>(reinterpret_cast<void (*)()>(def->ml_meth));
  if (meth != pybind_dispatcher) return;
  def->ml_meth = reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(&BoundedDispatcher));
}

// Every function of `ns` (a module's or a class's namespace), and of the classes in it.
void PatchAll(py::handle ns, std::unordered_set<PyObject*>& seen) {
  for (const auto& item : py::reinterpret_borrow<py::dict>(ns)) {
    PyObject* v = item.second.ptr();
    if (!seen.insert(v).second) continue;
    if (PyType_Check(v)) {
      // Classes of this module only (not `object`, NumPy's, ...).
      const py::object module = py::getattr(item.second, "__module__", py::none());
      if (py::isinstance<py::str>(module) &&
          module.cast<std::string>().rfind("secure", 0) == 0)
        PatchAll(py::handle(reinterpret_cast<PyTypeObject*>(v)->tp_dict), seen);
      continue;
    }
    Patch(v);
    for (const char* attr : {"__func__", "fget", "fset"}) {
      if (!py::hasattr(item.second, attr)) continue;
      const py::object inner = item.second.attr(attr);
      Patch(inner.ptr());
    }
  }
}

}  // namespace

void BoundArgumentSizes(py::module_& m, const char* any_function) {
  PyObject* probe = m.attr(any_function).ptr();
  if (PyInstanceMethod_Check(probe)) probe = PyInstanceMethod_GET_FUNCTION(probe);
  if (!PyCFunction_Check(probe))
    throw std::runtime_error("BoundArgumentSizes: secure." + std::string(any_function) +
                             " is no bound function");
  pybind_dispatcher = reinterpret_cast<Dispatcher>(
      reinterpret_cast<void (*)()>(reinterpret_cast<PyCFunctionObject*>(probe)->m_ml->ml_meth));
  std::unordered_set<PyObject*> seen;
  PatchAll(m.attr("__dict__"), seen);
}

}  // namespace secure::python
