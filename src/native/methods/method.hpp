// The compiled loop's integrators as a registry: each method family is one header in this folder
// that defines a Method and registers its factory under the name its Python twin's
// compiled_spec() names (coopdyn/_spec.py: MethodSpec.name); CMakeLists.txt includes every header of
// the folder, so a new family is a new file here. The loop (loop.hpp) steps through the Method
// it was given and knows no family.
#pragma once

#include "../kernel.hpp"
#include "../settings.hpp"

#include <map>
#include <memory>
#include <string>

namespace coopdyn_native {

class Loop;

class Method {
public:
  virtual ~Method() = default;
  // One step (fixed) or attempt (adaptive) of size h from (t, q, v) into q_new, v_new, evaluating
  // the closed loop through `loop`'s services; the attempt's error norm (0 for fixed steps).
  virtual double step(Loop & loop, double t, const VectorXd & q, const VectorXd & v, double h, VectorXd & q_new,
                      VectorXd & v_new) = 0;
  // Whether this attempt starts from the previous accepted attempt's last evaluation (first same
  // as last): the loop then takes that evaluation's torque and power for the step's start.
  virtual bool reuses_start() const { return false; }
  virtual void accepted() {}
  virtual void rejected() {}
  // The closed loop changed at this step's start (a new controller sample under a control_dt
  // hold): a derivative carried from the last step's end no longer holds.
  virtual void restart() {}
  // A new run from another state (Loop::restart): nothing carried from the last run survives
  // (a kept step matrix too), as in a method built afresh.
  virtual void new_run() { restart(); }
};

// A family's constructor from the run's settings (its compiled_spec() merged into the loop's).
using MethodFactory = std::unique_ptr<Method> (*)(Settings & settings, const Model & model, Eigen::Index n_actuated);

inline std::map<std::string, MethodFactory> & method_registry() {
  static std::map<std::string, MethodFactory> registry;
  return registry;
}

// One line in a family's header: `inline const bool registered = register_method("name", make);`
inline bool register_method(const char * name, MethodFactory make) {
  method_registry()[name] = make;
  return true;
}

}  // namespace coopdyn_native
