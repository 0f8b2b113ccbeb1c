#pragma once
// Defences of the binding against hostile Python (issue 34): a mutex that refuses re-entry from
// the thread that holds it (a shield called again from inside its own Python dynamics callback
// would otherwise deadlock), a check that an object was made by its __init__ (an object made by
// Cls.__new__(Cls) has no C++ value: a method bound as a member function pointer would call
// through a null pointer), and None checks of required object arguments.
#include <pybind11/pybind11.h>

#include <Eigen/Core>

#include <atomic>
#include <cmath>
#include <sstream>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>

namespace secure::python {

/// A std::mutex (BasicLockable) that throws std::runtime_error (Python: RuntimeError) instead
/// of deadlocking when the thread holding it locks it again. `what` names the object in the
/// message ("secure.Shield", "secure.Dynamics").
class GuardedMutex {
 public:
  explicit GuardedMutex(const char* what = "secure object") : what_(what) {}
  void lock() {
    if (owner_.load(std::memory_order_acquire) == std::this_thread::get_id()) {
      throw std::runtime_error(
          std::string(what_) +
          ": used again from inside its own dynamics callback while it is busy in this thread "
          "(re-entrancy; this would deadlock): do not call the shield or its dynamics model "
          "from the callback");
    }
    mutex_.lock();
    owner_.store(std::this_thread::get_id(), std::memory_order_release);
  }
  void unlock() {
    owner_.store(std::thread::id(), std::memory_order_release);
    mutex_.unlock();
  }

 private:
  const char* what_;
  std::mutex mutex_;
  std::atomic<std::thread::id> owner_{};
};

/// TypeError if `src` is an instance of T's Python class whose C++ value was never made: an
/// object made by Cls.__new__(Cls) without __init__. pybind11 would hand out uninitialised memory
/// for it (it allocates the value lazily), so any method would crash the interpreter.
template <typename T>
void CheckInitialised(pybind11::handle src) {
  namespace py = pybind11;
  if (!src || src.is_none()) return;
  const py::detail::type_info* info = py::detail::get_type_info(typeid(T));
  if (info == nullptr || !PyObject_TypeCheck(src.ptr(), info->type)) return;
  auto* instance = reinterpret_cast<py::detail::instance*>(src.ptr());
  const py::detail::value_and_holder vh =
      instance->get_value_and_holder(info, /*throw_if_missing=*/false);
  // Made by __new__: no value yet, or an owned instance without its holder. (An object returned
  // by reference, e.g. env.rng, owns nothing and has no holder: that is fine.)
  if (vh.inst != nullptr && !vh.holder_constructed() &&
      (vh.value_ptr() == nullptr || instance->owned)) {
    const std::string name =
        py::str(py::handle(reinterpret_cast<PyObject*>(info->type)).attr("__name__"));
    throw py::type_error("secure." + name + " object is not initialised (made by " + name +
                         ".__new__ without __init__)");
  }
}

/// The caster of a bound class T (by value, reference or pointer: also `self`) with that check
/// first; SECURE_PYTHON_CHECK_INITIALISED(T) installs it (at global scope, before T's first use
/// as an argument in the translation unit). The shared_ptr holder's caster checks by itself.
template <typename T>
class InitialisedCaster : public pybind11::detail::type_caster_base<T> {
 public:
  bool load(pybind11::handle src, bool convert) {
    CheckInitialised<T>(src);
    return pybind11::detail::type_caster_base<T>::load(src, convert);
  }
};

/// TypeError if a required object argument is None (pybind11 passes None as a null holder):
/// "Shield: barrier is None, expected a secure.Barrier".
template <typename T>
const T& Required(const std::shared_ptr<T>& p, const std::string& what,
                  const std::string& expected) {
  if (!p) throw pybind11::type_error(what + " is None, expected " + expected);
  return *p;
}

/// ValueError naming the first non-finite entry of `m` (one value per row, one state per
/// column, as States() maps it): "observation[1] = nan: observations must be finite" for one
/// (`one`), "states[2, 3] = nan: ..." (row 2 of the array, column 3) for a batch.
inline void CheckFinite(const Eigen::Ref<const Eigen::MatrixXf>& m, bool one,
                        const std::string& what, const std::string& plural) {
  if (m.allFinite()) return;
  for (Eigen::Index j = 0; j < m.cols(); ++j)
    for (Eigen::Index i = 0; i < m.rows(); ++i)
      if (!std::isfinite(m(i, j))) {
        std::ostringstream out;
        out << what << "[" << (one ? "" : std::to_string(j) + ", ") << i << "] = " << m(i, j)
            << ": " << plural << " must be finite";
        throw pybind11::value_error(out.str());
      }
}

}  // namespace secure::python

#define SECURE_PYTHON_CHECK_INITIALISED(T)                                       \
  namespace pybind11::detail {                                                   \
  template <>                                                                    \
  class type_caster<T> : public secure::python::InitialisedCaster<T> {};         \
  }                                                                              \
  static_assert(true, "")
