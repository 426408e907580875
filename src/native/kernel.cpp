// coopdyn._native: the hot path of coopdyn.dynamics in C++ (NativeDynamics).
//
// The same equations as the Python reference (coopdyn/dynamics/dynamics.py, tested equal to
// round-off):
//
//   H(q) q̈ + h(q, q̇) = S τ − B q̇ + Q,   Q = Σ_i Jr_iᵀ G_f_G,i,   Jr_i = J_G − Ad(T_M_G⁻¹) J_T,
//
// with LOCAL frame Jacobians of each link's frames T and G, and G_f_G,i the wrench its element
// (element.hpp; one header per element, registered in elements.hpp) puts on G at the relative
// pose T_M_G and relative twist ξ = Jr q̇. Implicit methods get K̃ = Σ Jrᵀ S_K Jr and
// D̃ = Σ Jrᵀ S_D Jr + B, and one factorisation of the step matrix S = M + γh D̃ + (γh)² K̃.
//
// The kernel works on the Python-owned pinocchio Model and Data (boost.python lvalues).

#include <cstring>

#include "kernel.hpp"
#include "loop.hpp"

namespace {

using coopdyn_native::Kernel;
using coopdyn_native::Loop;
using coopdyn_native::StepMatrixError;
namespace cn = coopdyn_native;

template <class T> T get(const bp::dict & cfg, const char * key) {
  if (!cfg.has_key(key)) throw std::invalid_argument(std::string("compiled loop: missing setting ") + key);
  return bp::extract<T>(cfg[key])();
}

std::vector<double> doubles(bp::object seq) {
  std::vector<double> out;
  for (bp::ssize_t i = 0; i < bp::len(seq); ++i) out.push_back(bp::extract<double>(seq[i]));
  return out;
}

std::unique_ptr<cn::Controller> make_controller(const Kernel & k, const bp::dict & c) {
  const std::string kind = get<std::string>(c, "kind");
  const Model & model = k.model();
  if (kind == "none") return std::make_unique<cn::NoTorque>();
  if (kind == "gravity_pd")
    return std::make_unique<cn::GravityPD>(model, k.actuated(), get<VectorXd>(c, "kp"), get<VectorXd>(c, "kd"),
                                           get<VectorXd>(c, "q_des"));
  if (kind == "computed_torque")
    return std::make_unique<cn::ComputedTorqueHold>(model, k.actuated(), get<Eigen::VectorXi>(c, "q_index"),
                                                    get<VectorXd>(c, "kp"), get<VectorXd>(c, "kd"),
                                                    get<VectorXd>(c, "q_d"));
  if (kind == "drives") {
    std::vector<MatrixXd> segments;
    bp::list drives = get<bp::list>(c, "segments");
    for (bp::ssize_t i = 0; i < bp::len(drives); ++i) segments.push_back(bp::extract<MatrixXd>(drives[i]));
    if (static_cast<Eigen::Index>(segments.size()) != k.actuated().size())
      throw std::invalid_argument("drives: one per actuated joint");
    return std::make_unique<cn::Drives>(std::move(segments));
  }
  if (kind == "object_impedance") {
    std::vector<cn::ObjectImpedanceC::Grasp> grasps;
    bp::list gl = get<bp::list>(c, "grasps");
    for (bp::ssize_t i = 0; i < bp::len(gl); ++i) {
      bp::tuple g = bp::extract<bp::tuple>(gl[i]);
      cn::ObjectImpedanceC::Grasp gr;
      gr.grasp = bp::extract<pinocchio::FrameIndex>(g[0]);
      gr.tip = bp::extract<pinocchio::FrameIndex>(g[1]);
      const Eigen::VectorXi vi = bp::extract<Eigen::VectorXi>(g[2]);
      gr.v_index.assign(vi.data(), vi.data() + vi.size());
      grasps.push_back(std::move(gr));
    }
    cn::ObjectTask task;
    bp::dict t = get<bp::dict>(c, "task");
    task.hold = get<bool>(t, "hold");
    task.start = get<VectorXd>(t, "start");
    task.R = get<MatrixXd>(t, "rotation");
    if (!task.hold) {
      task.axis = get<VectorXd>(t, "axis");
      for (const char * key : {"squeeze", "t_grip", "lift", "t_lift", "lift_duration", "amplitude", "frequency", "t_osc"}) {
        const double value = get<double>(t, key);
        if (!std::strcmp(key, "squeeze")) task.squeeze = value;
        else if (!std::strcmp(key, "t_grip")) task.t_grip = value;
        else if (!std::strcmp(key, "lift")) task.lift = value;
        else if (!std::strcmp(key, "t_lift")) task.t_lift = value;
        else if (!std::strcmp(key, "lift_duration")) task.lift_duration = value;
        else if (!std::strcmp(key, "amplitude")) task.amplitude = value;
        else if (!std::strcmp(key, "frequency")) task.frequency = value;
        else task.t_osc = value;
      }
      task.cycles = get<int>(t, "cycles");
    }
    return std::make_unique<cn::ObjectImpedanceC>(
      model, get<pinocchio::FrameIndex>(c, "object_frame"), std::move(grasps), std::move(task), get<double>(c, "mass"),
      get<VectorXd>(c, "com"), get<VectorXd>(c, "gravity"), get<VectorXd>(c, "Kp"), get<VectorXd>(c, "Kr"),
      get<VectorXd>(c, "Dp"), get<VectorXd>(c, "Dr"), get<double>(c, "joint_damping"), get<double>(c, "null_k"),
      get<double>(c, "null_d"), get<VectorXd>(c, "q0"));
  }
  throw std::invalid_argument("compiled loop: unknown controller kind " + kind);
}

// A compiled run of `kernel` as `cfg` describes it (coopdyn/compiled.py writes it).
std::shared_ptr<Loop> make_loop(Kernel & kernel, bp::dict cfg) {
  cn::Tableau tab;
  const std::string method = get<std::string>(cfg, "method");
  int m;
  if (method == "symplectic_euler") m = cn::SYMPLECTIC_EULER;
  else if (method == "rk") m = cn::RK;
  else if (method == "implicit_euler") m = cn::IMPLICIT_EULER;
  else if (method == "rosenbrock") m = cn::ROSENBROCK;
  else if (method == "exponential") m = cn::EXPONENTIAL;
  else throw std::invalid_argument("compiled loop: unknown method " + method);
  if (m == cn::RK) {
    bp::list A = get<bp::list>(cfg, "A");
    for (bp::ssize_t i = 0; i < bp::len(A); ++i) tab.A.push_back(doubles(A[i]));
    tab.b = doubles(cfg["b"]);
    tab.c = doubles(cfg["c"]);
    if (cfg.has_key("b_hat")) tab.b_hat = doubles(cfg["b_hat"]);
  }
  auto loop = std::make_shared<Loop>(
    kernel, make_controller(kernel, get<bp::dict>(cfg, "controller")), m, std::move(tab), get<bool>(cfg, "adaptive"),
    get<double>(cfg, "gamma"), get<int>(cfg, "jacobian_every"), get<int>(cfg, "error_order"), get<VectorXd>(cfg, "kp"),
    get<VectorXd>(cfg, "kd"), get<VectorXd>(cfg, "q0"), get<VectorXd>(cfg, "v0"), get<double>(cfg, "dt"),
    get<double>(cfg, "t_final"), get<long>(cfg, "n_steps"), get<long>(cfg, "save_every"), get<double>(cfg, "max_speed"),
    get<int>(cfg, "energy_mode"), get<long>(cfg, "energy_every"), get<double>(cfg, "energy_rtol"), get<double>(cfg, "rtol"), get<double>(cfg, "atol"),
    get<double>(cfg, "h_min"));
  loop->set_first_step(get<double>(cfg, "dt"));
  if (m == cn::EXPONENTIAL) {
    bp::list steps = get<bp::list>(cfg, "discretisations");
    for (bp::ssize_t i = 0; i < bp::len(steps); ++i) {
      bp::tuple d = bp::extract<bp::tuple>(steps[i]);
      cn::Discretisation x;
      x.h = bp::extract<double>(d[0]);
      x.step = bp::extract<MatrixXd>(d[1]);
      x.p = bp::extract<int>(d[4]);
      if (x.p > 0) {
        x.predictor = bp::extract<MatrixXd>(d[2]);
        x.inner = bp::extract<MatrixXd>(d[3]);
      }
      loop->add_discretisation(std::move(x));
    }
  }
  if (cfg.has_key("n_factor")) loop->set_factorisations(get<long>(cfg, "n_factor"));
  return loop;
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
  step_matrix_error_type = bp::import("coopdyn.errors").attr("StepMatrixError");
  bp::register_exception_translator<StepMatrixError>(&translate_step_matrix_error);
  bp::class_<Kernel, boost::noncopyable>(
    "Kernel", "The scene dynamics' hot path (see coopdyn.dynamics.native).",
    bp::init<bp::object, bp::object, bp::list, RefVec, Eigen::Ref<const Eigen::VectorXi>, FrameIndex>(
      bp::args("self", "model", "data", "links", "damping", "actuated", "object_frame")))
    .def("acceleration", &Kernel::acceleration, bp::args("self", "q", "v", "tau", "wrench"))
    .def("implicit_terms", &Kernel::implicit_terms, bp::args("self", "q", "v", "tau", "wrench"))
    .def("factor", &Kernel::factor, bp::args("self", "M", "K", "D", "gh", "kp", "kd"))
    .def("solve", &Kernel::solve, bp::args("self", "f_q", "Mf_v"))
    .def("implicit_euler_velocity", &Kernel::implicit_euler_velocity,
         bp::args("self", "q", "v", "tau", "h", "kp", "kd", "wrench"))
    .def("elastic_energies", &Kernel::elastic_energies, bp::args("self"))
    .def("spring_force", &Kernel::spring_force, bp::args("self", "q", "v"))
    .def("element_states", &Kernel::element_states, bp::args("self", "q", "v"))
    .def("readouts", &Kernel::readouts, bp::args("self", "Q", "V"))
    .def("clear_rotation_alarm", &Kernel::clear_rotation_alarm, bp::args("self"))
    .add_property("last_dissipation", &Kernel::last_dissipation)
    .add_property("rotation_alarm", &Kernel::rotation_alarm)
    .add_property("rotation_alarm_angle", &Kernel::rotation_alarm_angle);
  bp::class_<Loop, std::shared_ptr<Loop>, boost::noncopyable>(
    "Loop", "A compiled simulation run (see coopdyn.compiled).", bp::no_init)
    .def("advance", &Loop::advance, bp::args("self", "budget"))
    .def("samples", &Loop::samples, bp::args("self"))
    .def("take_events", &Loop::take_events, bp::args("self"))
    .def("counters", &Loop::counters, bp::args("self"))
    .def("failure", &Loop::failure, bp::args("self"))
    .add_property("t", &Loop::time);
  bp::def("make_loop", &make_loop, bp::with_custodian_and_ward_postcall<0, 1>(), bp::args("kernel", "config"));
}
