// coopdyn._native: the hot path of coopdyn.dynamics in C++ (NativeDynamics).
//
// The same equations as the Python reference (coopdyn/dynamics/dynamics.py, tested equal to
// round-off):
//
//   H(q) q̈ + h(q, q̇) = S τ − B q̇ + Q,   Q = Σ_i Jr_iᵀ G_f_G,i,   Jr_i = J_G − Ad(T_M_G⁻¹) J_T,
//
// with LOCAL frame Jacobians of each link's frames T and G, and G_f_G,i the wrench its element
// (elements/: one header per element, each registering itself) puts on G at the relative
// pose T_M_G and relative twist ξ = Jr q̇. The explicit right-hand side applies each wrench to the
// joints carrying T and G as external forces of the articulated-body algorithm (Q without forming
// Jr; one kinematics pass also gives the gravity-compensating controller its g(q)). Implicit
// methods get K̃ = Σ Jrᵀ S_K Jr and D̃ = Σ Jrᵀ S_D Jr + B, and one factorisation of the step
// matrix S = M + γh D̃ + (γh)² K̃.
//
// The kernel works on the Python-owned pinocchio Model and Data (boost.python lvalues).


#include "kernel.hpp"
#include "loop.hpp"
#include "mujoco_bridge.hpp"
#include "sensitivity.hpp"
#include "registered_elements.hpp"  // every header of elements/ (CMakeLists.txt; controllers/ and methods/: registered.cpp)

namespace {

using coopdyn_native::Kernel;
using coopdyn_native::Loop;
using coopdyn_native::StepMatrixError;
namespace cn = coopdyn_native;

using cn::Settings;

// The controller `c` describes (its "kind" from the registry in controllers/, built from c).
std::unique_ptr<cn::Controller> make_controller(Kernel & k, const bp::dict & values) {
  const std::string kind = bp::extract<std::string>(values.get("kind", ""))();
  const auto found = cn::controller_registry().find(kind);
  if (found == cn::controller_registry().end()) {
    std::string known;
    for (const auto & entry : cn::controller_registry()) known += (known.empty() ? "" : ", ") + entry.first;
    throw std::invalid_argument("compiled loop: unknown controller kind " + kind + " (registered: " + known + ")");
  }
  Settings c("controller '" + kind + "'", values);
  c.get<std::string>("kind");
  std::unique_ptr<cn::Controller> out = found->second(c, k);
  c.check_all_read();
  return out;
}

// A compiled run of `kernel` as `values` describes it (coopdyn/compiled.py writes it): the method
// family named by values["method"] from the registry (methods/), built from the same settings;
// every setting given must be read by the loop, the method or the controller.
std::shared_ptr<Loop> make_loop(Kernel & kernel, bp::dict values) {
  Settings cfg("compiled loop", values);
  const std::string family = cfg.get<std::string>("method");
  const auto found = cn::method_registry().find(family);
  if (found == cn::method_registry().end()) {
    std::string known;
    for (const auto & entry : cn::method_registry()) known += (known.empty() ? "" : ", ") + entry.first;
    throw std::invalid_argument("compiled loop: unknown method " + family + " (registered: " + known + ")");
  }
  const Model & model = kernel.model();
  const Eigen::Index na = kernel.actuated().size();
  auto loop = std::make_shared<Loop>(
    kernel, make_controller(kernel, cfg.get<bp::dict>("controller")), found->second(cfg, model, na),
    cfg.get<bool>("adaptive"), cfg.get<int>("error_order"), cfg.vec("kp", na), cfg.vec("kd", na), cfg.vec("q0", model.nq),
    cfg.vec("v0", model.nv), cfg.get<double>("dt"), cfg.get<double>("t_final"), cfg.get<long>("n_steps"),
    cfg.get<long>("save_every"), cfg.get<double>("max_speed"), cfg.get<int>("energy_mode"), cfg.get<long>("energy_every"),
    cfg.get<double>("energy_rtol"), cfg.get<double>("rtol"), cfg.get<double>("atol"), cfg.get<double>("h_min"));
  loop->set_first_step(cfg.get<double>("dt"));
  loop->set_control_period(cfg.get<double>("control_dt"));
  if (cfg.has("n_factor")) loop->set_factorisations(cfg.get<long>("n_factor"));
  cfg.check_all_read();
  return loop;
}

// coopdyn's law (and a compiled controller, or None) as MuJoCo callbacks (mujoco_bridge.hpp;
// coopdyn/mujoco.py finds the layout and the index maps).
std::shared_ptr<cn::MujocoBridge> make_mujoco_bridge(bp::object kernel_object, bp::object controller, bp::tuple layout,
                                                     const Eigen::VectorXi & q_pin, const Eigen::VectorXi & q_mj,
                                                     const Eigen::VectorXi & v_pin, const Eigen::VectorXi & v_mj,
                                                     const Eigen::VectorXi & free, const Eigen::VectorXi & motor_ctrl,
                                                     const Eigen::VectorXi & motor_tau) {
  if (bp::len(layout) != 5 || free.size() != 4 || q_pin.size() != q_mj.size() || v_pin.size() != v_mj.size() ||
      motor_ctrl.size() != motor_tau.size())
    throw std::invalid_argument("make_mujoco_bridge: inconsistent layout or index maps");
  const cn::MjDataLayout offsets{bp::extract<long>(layout[0]), bp::extract<long>(layout[1]), bp::extract<long>(layout[2]),
                                 bp::extract<long>(layout[3]), bp::extract<long>(layout[4])};
  Kernel & kernel = bp::extract<Kernel &>(kernel_object);
  std::unique_ptr<cn::Controller> ctrl;
  if (!controller.is_none()) ctrl = make_controller(kernel, bp::extract<bp::dict>(controller));
  return std::make_shared<cn::MujocoBridge>(kernel_object, kernel, std::move(ctrl), offsets, q_pin, q_mj, v_pin, v_mj,
                                            Eigen::Vector4i(free), motor_ctrl, motor_tau);
}
// Install `bridge` (None: none); the bridge installed before, for the caller to put back.
std::shared_ptr<cn::MujocoBridge> install_mujoco_bridge(std::shared_ptr<cn::MujocoBridge> bridge) {
  std::shared_ptr<cn::MujocoBridge> previous;
  {
    const std::lock_guard<std::mutex> lock(cn::bridge_mutex());
    previous = std::move(cn::installed_bridge());
    cn::installed_bridge() = std::move(bridge);
  }
  return previous;  // (released after the lock: its Python kernel is let go with the GIL held)
}
// The callbacks' addresses, for ctypes (MuJoCo's mjfGeneric).
std::uintptr_t mujoco_passive_address() { return reinterpret_cast<std::uintptr_t>(&coopdyn_mjcb_passive); }
std::uintptr_t mujoco_control_address() { return reinterpret_cast<std::uintptr_t>(&coopdyn_mjcb_control); }

// One element built from its parameters as the kernel builds it, evaluated at the relative pose
// T_M_G (4x4) and twist xi: (energy, deformation, G_f_G, power, S_K, S_D, theta), as
// Element.evaluate gives them in Python (tests compare the twins through it).
bp::tuple evaluate_element(const std::string & kind, const bp::dict & parameters, const MatrixXd & T_M_G,
                           const VectorXd & xi, bool jacobians) {
  if (T_M_G.rows() != 4 || T_M_G.cols() != 4 || xi.size() != 6)
    throw std::invalid_argument("evaluate_element: T_M_G must be 4x4 and xi 6 values");
  const std::unique_ptr<coopdyn::Element> element = coopdyn::make_element(kind, parameters);
  const SE3 pose(Eigen::Matrix3d(T_M_G.topLeftCorner<3, 3>()), Eigen::Vector3d(T_M_G.topRightCorner<3, 1>()));
  coopdyn::ElementEval ev;
  ev.SK.setZero();
  ev.SD.setZero();
  element->evaluate(pose, Vector6(xi), jacobians, ev);
  return bp::make_tuple(ev.energy, Vector6(ev.deformation), Vector6(ev.f), ev.power, Matrix6(ev.SK), Matrix6(ev.SD),
                        ev.theta);
}

// The closed loop's controller for a Sensitivity (its compiled twin's settings, or a callback).
void sensitivity_controller(cn::Sensitivity & sensitivity, bp::object kernel_object, const bp::dict & controller) {
  sensitivity.set_controller(make_controller(bp::extract<Kernel &>(kernel_object), controller));
}

bp::object step_matrix_error_type;

void translate_step_matrix_error(const StepMatrixError & e) {
  PyErr_SetString(step_matrix_error_type.ptr(), e.what());
}

}  // namespace

BOOST_PYTHON_MODULE(_native) {
  eigenpy::enableEigenPy();
  eigenpy::enableEigenPySpecific<Eigen::VectorXi>();
  bp::scope().attr("PINOCCHIO_VERSION") = PINOCCHIO_VERSION;
  bp::scope().attr("ELEMENTS") = coopdyn::element_kinds();
  bp::list statuses;
  for (const char * name : cn::STATUS_NAMES) statuses.append(name);
  bp::scope().attr("STATUSES") = bp::tuple(statuses);
  bp::list controllers;  // the controllers of the compiled loop, by kind
  for (const auto & entry : cn::controller_registry()) controllers.append(entry.first);
  bp::scope().attr("CONTROLLERS") = bp::tuple(controllers);
  bp::list methods;  // the method families of the compiled loop, by name
  for (const auto & entry : cn::method_registry()) methods.append(entry.first);
  bp::scope().attr("METHODS") = bp::tuple(methods);
  step_matrix_error_type = bp::import("coopdyn.errors").attr("StepMatrixError");
  bp::register_exception_translator<StepMatrixError>(&translate_step_matrix_error);
  bp::class_<Kernel, boost::noncopyable>(
    "Kernel", "The scene dynamics' hot path (see coopdyn.dynamics.native).",
    bp::init<bp::object, bp::object, bp::list, RefVec, Eigen::Ref<const Eigen::VectorXi>, FrameIndex, RefVec, bp::object>(
      bp::args("self", "model", "data", "links", "damping", "actuated", "object_frame", "joint_springs", "link_model")))
    .def("acceleration", &Kernel::acceleration, bp::args("self", "q", "v", "tau", "wrench"))
    .def("implicit_terms", &Kernel::implicit_terms, bp::args("self", "q", "v", "tau", "wrench"))
    .def("factor", &Kernel::factor_given, bp::args("self", "M", "K", "D", "gh", "kp", "kd", "gh2"))
    .def("solve", &Kernel::solve, bp::args("self", "f_q", "Mf_v"))
    .def("implicit_euler_velocity", &Kernel::implicit_euler_velocity,
         bp::args("self", "q", "v", "tau", "h", "kp", "kd", "wrench"))
    .def("elastic_energies", &Kernel::elastic_energies_at, bp::args("self", "q"))
    .def("spring_force", &Kernel::spring_force, bp::args("self", "q", "v"))
    .def("gravity", &Kernel::gravity, bp::args("self", "q"))
    .def("element_states", &Kernel::element_states, bp::args("self", "q", "v"))
    .def("readouts", &Kernel::readouts, bp::args("self", "Q", "V"))
    .def("derivatives", &Kernel::derivatives, bp::args("self", "q", "v", "tau", "wrench"))
    .def("clear_rotation_alarm", &Kernel::clear_rotation_alarm, bp::args("self"))
    .def("damping_form", &Kernel::damping_form_given, bp::args("self", "dv"))
    .add_property("last_dissipation", &Kernel::last_dissipation)
    .add_property("rotation_alarm", &Kernel::rotation_alarm)
    .add_property("rotation_alarm_angle", &Kernel::rotation_alarm_angle)
    .add_property("sparse_step_matrix", &Kernel::sparse_step_matrix, &Kernel::set_sparse_step_matrix);
  bp::class_<cn::Sensitivity, boost::noncopyable>(
    "Sensitivity", "Exact sensitivities of a method's steps, open loop or closed (see coopdyn.sensitivity).",
    bp::init<bp::object, bp::list, bp::list, bool, bp::tuple, bp::list, bp::list>(
      bp::args("self", "kernel", "A", "b", "symplectic", "implicit", "charts", "parameters")))
    .def("run", &cn::Sensitivity::run, bp::args("self", "q0", "v0", "U", "per", "h", "dq0", "dv0", "dU", "dP", "end_wrench", "max_speed", "t0"))
    .def("set_controller", &sensitivity_controller, bp::args("self", "kernel", "controller"))
    .def("controller_gain", &cn::Sensitivity::controller_gain, bp::args("self", "t", "q", "v"));
  bp::class_<Loop, std::shared_ptr<Loop>, boost::noncopyable>(
    "Loop", "A compiled simulation run (see coopdyn.compiled).", bp::no_init)
    .def("advance", &Loop::advance, bp::args("self", "budget"))
    .def("restart", &Loop::restart, bp::args("self", "q0", "v0"))
    .def("samples", &Loop::samples, bp::args("self"))
    .def("take_samples", &Loop::take_samples, bp::args("self"))
    .def("take_events", &Loop::take_events, bp::args("self"))
    .def("counters", &Loop::counters, bp::args("self"))
    .def("failure", &Loop::failure, bp::args("self"))
    .add_property("t", &Loop::time);
  bp::class_<cn::MujocoBridge, std::shared_ptr<cn::MujocoBridge>, boost::noncopyable>(
    "MujocoBridge", "coopdyn's law as MuJoCo callbacks (see coopdyn.mujoco).", bp::no_init)
    .add_property("evaluations", &cn::MujocoBridge::evaluations)
    .def("take_error", &cn::MujocoBridge::take_error, bp::args("self"));
  bp::def("make_mujoco_bridge", &make_mujoco_bridge,
          bp::args("kernel", "controller", "layout", "q_pin", "q_mj", "v_pin", "v_mj", "free", "motor_ctrl", "motor_tau"));
  bp::def("install_mujoco_bridge", &install_mujoco_bridge, bp::args("bridge"));
  bp::def("mujoco_passive_address", &mujoco_passive_address);
  bp::def("mujoco_control_address", &mujoco_control_address);
  bp::def("evaluate_element", &evaluate_element, bp::args("kind", "parameters", "T_M_G", "xi", "jacobians"));
  bp::def("make_loop", &make_loop, bp::with_custodian_and_ward_postcall<0, 1>(), bp::args("kernel", "config"));
}
