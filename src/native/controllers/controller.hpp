// The built-in controllers in C++ for the compiled step loop (loop.hpp): the same laws, in the
// same operation order, as their Python definitions (coopdyn/control/joint.py, control/cooperative.py,
// coopdyn/problems/linear_book.py), tested equal to round-off (tests/test_compiled_loop.py).
// This header is the protocol and the registry: each other header in this folder defines one
// controller and registers its factory under the "kind" its Python class's compiled_spec()
// gives (CMakeLists.txt includes every header of the folder).
#pragma once

#include "../kernel.hpp"
#include "../settings.hpp"

#include <map>
#include <memory>
#include <stdexcept>
#include <string>

namespace coopdyn_native {

using Eigen::MatrixXd;
using Eigen::VectorXd;
using pinocchio::Data;
using pinocchio::Model;
using Vector3 = Eigen::Vector3d;
using Matrix3 = Eigen::Matrix3d;

struct Controller {
  virtual ~Controller() = default;
  // τ (n_actuated) at (t, q, v).
  virtual void torque(double t, const VectorXd & q, const VectorXd & v, VectorXd & tau) = 0;
  // Whether torque() reads the kernel's kinematics at (q, v) (Kernel::kinematics first).
  virtual bool reads_kernel() const { return false; }
  // Whether torque() calls Python (and takes the GIL for it): the loop then keeps the GIL.
  virtual bool calls_python() const { return false; }
};

struct NoTorque : Controller {
  void torque(double, const VectorXd &, const VectorXd &, VectorXd & tau) override { tau.setZero(); }
};

struct GraspGeometryError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A Python controller failed (python_controller.hpp): Python holds its exception and re-raises it.
struct CallbackError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A controller's constructor from its settings (its compiled_spec()) and the run's kernel.
using ControllerFactory = std::unique_ptr<Controller> (*)(Settings & settings, Kernel & kernel);

inline std::map<std::string, ControllerFactory> & controller_registry() {
  static std::map<std::string, ControllerFactory> registry;
  return registry;
}

// One line in a controller's header: `inline const bool registered = register_controller("kind", make);`
inline bool register_controller(const char * kind, ControllerFactory make) {
  controller_registry()[kind] = make;
  return true;
}

inline std::unique_ptr<Controller> make_no_torque(Settings &, Kernel &) { return std::make_unique<NoTorque>(); }
inline const bool no_torque_registered = register_controller("none", &make_no_torque);

}  // namespace coopdyn_native
