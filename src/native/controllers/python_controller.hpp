// A Python controller called from the compiled loop: a user's own callable (no compiled twin)
// no longer sends the run to the Python loop. The loop (which keeps the GIL while it runs a
// Python controller) calls the user's callable itself, `controller(t, q, v)`, with q and v as
// fresh read-only float64 arrays, as System.torque shows them. A float64 vector of the right size
// with finite entries is taken as it is: one call, no Python frame of coopdyn's in between. Any
// other output goes through coopdyn's checked wrapper (coopdyn/compiled.py: PythonCallback.check,
// System's conversions and messages), and what the controller raises through
// PythonCallback.raised, which keeps the error coopdyn raises for it; the loop then stops and
// Python re-raises it.
#pragma once

#include "controller.hpp"

#include <Python.h>

#include <cstring>

namespace coopdyn_native {

class PythonController : public Controller {
public:
  // callback: a coopdyn.compiled.PythonCallback (its controller, raised and check)
  PythonController(const bp::object & callback, Eigen::Index n_actuated)
      : controller_(callback.attr("controller")), raised_(callback.attr("raised")), check_(callback.attr("check")), na_(n_actuated) {}

  bool calls_python() const override { return true; }

  void torque(double t, const VectorXd & q, const VectorXd & v, VectorXd & tau) override {
    const struct Gil {  // taken for the call (held already in the compiled loop), given back on every way out
      PyGILState_STATE state = PyGILState_Ensure();
      ~Gil() { PyGILState_Release(state); }
    } gil;
    const bp::object q_seen = read_only(q), v_seen = read_only(v);
    bp::object out;
    try {
      out = controller_(t, q_seen, v_seen);
    } catch (const bp::error_already_set &) {  // the user's code raised: PythonCallback keeps coopdyn's error for it
      PyObject *type = nullptr, *value = nullptr, *trace = nullptr;
      PyErr_Fetch(&type, &value, &trace);
      PyErr_NormalizeException(&type, &value, &trace);
      if (trace != nullptr && value != nullptr) PyException_SetTraceback(value, trace);
      const bp::object exc{bp::handle<>(bp::allow_null(value))};
      Py_XDECREF(type);
      Py_XDECREF(trace);
      bool geometry = false;  // the grasps' geometry (a trial stage flung them together): the C++ error, which an
      std::string what;       // adaptive loop takes as a rejected attempt (loop.hpp: run_adaptive)
      wrapper([&] {
        geometry = bp::extract<bool>(raised_(t, exc));
        if (geometry) what = bp::extract<std::string>(bp::str(exc));
      });
      if (geometry) throw GraspGeometryError(what);
      throw CallbackError("the Python controller raised (re-raised by Python)");
    }
    if (take(out, tau, true)) return;
    // not a finite float64 vector of the right size: converted and checked by coopdyn's wrapper
    // (lists and other dtypes are converted; a wrong shape or non-finite torques are named, except
    // at a runaway state, whose overflowing torques the loop then handles as any method's)
    wrapper([&] { out = check_(t, q_seen, v_seen, out); });
    if (out.is_none()) throw CallbackError("the Python controller's output was refused (re-raised by Python)");
    if (!take(out, tau, false)) throw std::runtime_error("coopdyn's Python-controller wrapper returned the wrong type or size (a bug)");
  }

private:
  // A new read-only float64 array holding x: what the controller sees (it cannot change the state).
  static bp::object read_only(const VectorXd & x) {
    npy_intp n = x.size();
    PyObject * array = PyArray_SimpleNew(1, &n, NPY_DOUBLE);
    if (array == nullptr) bp::throw_error_already_set();
    if (n > 0) std::memcpy(PyArray_DATA(reinterpret_cast<PyArrayObject *>(array)), x.data(), sizeof(double) * std::size_t(n));
    PyArray_CLEARFLAGS(reinterpret_cast<PyArrayObject *>(array), NPY_ARRAY_WRITEABLE);
    return bp::object(bp::handle<>(array));
  }

  // Copies out into tau when it is a float64 ndarray in this machine's byte order (not a subclass)
  // of shape (na,); false when it is not, or (if `finite`) when an entry is not finite.
  bool take(const bp::object & out, VectorXd & tau, bool finite) const {
    PyObject * p = out.ptr();
    if (!PyArray_CheckExact(p)) return false;
    auto * a = reinterpret_cast<PyArrayObject *>(p);
    if (PyArray_TYPE(a) != NPY_DOUBLE || !PyArray_ISNOTSWAPPED(a) || PyArray_NDIM(a) != 1 || PyArray_DIM(a, 0) != na_)
      return false;  // (a '>f8' array has NPY_DOUBLE's type number too: its bytes are swapped)
    const char * data = static_cast<const char *>(PyArray_DATA(a));
    const npy_intp stride = PyArray_STRIDE(a, 0);
    tau.resize(na_);
    for (Eigen::Index i = 0; i < na_; ++i) std::memcpy(&tau[i], data + i * stride, sizeof(double));  // any stride, any alignment
    return !finite || tau.allFinite();
  }

  // Runs a call into coopdyn's own wrapper, whose errors are bugs (it keeps the user's errors).
  template <class F>
  static void wrapper(F && call) {
    try {
      call();
    } catch (const bp::error_already_set &) {
      PyErr_Clear();
      throw std::runtime_error("coopdyn's Python-controller wrapper failed (a bug: please report it)");
    }
  }

  bp::object controller_, raised_, check_;
  Eigen::Index na_;
};

// {callback: coopdyn.compiled.PythonCallback}
inline std::unique_ptr<Controller> make_python_controller(Settings & c, Kernel & k) {
  return std::make_unique<PythonController>(c.object("callback"), k.actuated().size());
}
inline const bool python_controller_registered = register_controller("python", &make_python_controller);

}  // namespace coopdyn_native
