// A Python controller called from the compiled loop: a user's own callable (no compiled twin)
// no longer sends the run to the Python loop. The loop calls `callback(t, q, v)` — coopdyn's
// checked wrapper around the controller (coopdyn/compiled.py: PythonCallback, which calls
// System.torque: read-only q and v, shape and finiteness checks, the same messages) — with the
// GIL (the loop keeps it while it runs a Python controller). The wrapper returns None after recording
// what the controller raised; the loop then stops and Python re-raises it.
#pragma once

#include "controller.hpp"

#include <Python.h>

namespace coopdyn_native {

class PythonController : public Controller {
public:
  PythonController(bp::object callback, Eigen::Index n_actuated) : callback_(std::move(callback)), na_(n_actuated) {}

  bool calls_python() const override { return true; }

  void torque(double t, const VectorXd & q, const VectorXd & v, VectorXd & tau) override {
    const struct Gil {  // taken for the call (held already in the compiled loop), given back on every way out
      PyGILState_STATE state = PyGILState_Ensure();
      ~Gil() { PyGILState_Release(state); }
    } gil;
    VectorXd result;
    try {
      const bp::object out = callback_(t, q, v);
      if (out.is_none()) throw CallbackError("the Python controller raised (re-raised by Python)");
      result = bp::extract<VectorXd>(out);
    } catch (const bp::error_already_set &) {  // the wrapper keeps what the controller raises: a bug in it
      PyErr_Clear();
      throw std::runtime_error("coopdyn's Python-controller wrapper failed (a bug: please report it)");
    }
    if (result.size() != na_) throw std::runtime_error("coopdyn's Python-controller wrapper returned the wrong size (a bug)");
    tau = result;
  }

private:
  bp::object callback_;
  Eigen::Index na_;
};

// {callback: coopdyn.compiled.PythonCallback}
inline std::unique_ptr<Controller> make_python_controller(Settings & c, Kernel & k) {
  return std::make_unique<PythonController>(c.object("callback"), k.actuated().size());
}
inline const bool python_controller_registered = register_controller("python", &make_python_controller);

}  // namespace coopdyn_native
