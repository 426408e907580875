// coopdyn._native: the hot path of coopdyn.dynamics in C++ (NativeDynamics).
//
// The same equations as the Python reference (coopdyn/dynamics/dynamics.py, tested equal to
// round-off):
//
//   H(q) q̈ + h(q, q̇) = S τ − B q̇ + Q,   Q = Σ_i Jr_iᵀ G_f_G,i,   Jr_i = J_G − Ad(T_M_G⁻¹) J_T,
//
// with LOCAL frame Jacobians of each link's frames T and G, and G_f_G,i the wrench its element
// (element.hpp; one header per element, registered in elements.hpp) puts on G at the relative
// pose T_M_G and relative twist ξ = Jr q̇. The explicit right-hand side applies each wrench to the
// joints carrying T and G as external forces of the articulated-body algorithm (Q without forming
// Jr; one kinematics pass also gives the gravity-compensating controller its g(q)). Implicit
// methods get K̃ = Σ Jrᵀ S_K Jr and D̃ = Σ Jrᵀ S_D Jr + B, and one factorisation of the step
// matrix S = M + γh D̃ + (γh)² K̃.
//
// The kernel works on the Python-owned pinocchio Model and Data (boost.python lvalues).


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

// A vector setting of exactly n entries (n < 0: any).
VectorXd vec(const bp::dict & cfg, const char * key, Eigen::Index n) {
  const VectorXd x = get<VectorXd>(cfg, key);
  if (n >= 0 && x.size() != n)
    throw std::invalid_argument(std::string("compiled loop: setting ") + key + " has " + std::to_string(x.size()) +
                                " entries, expected " + std::to_string(n));
  return x;
}

MatrixXd mat3(const bp::dict & cfg, const char * key) {
  const MatrixXd x = get<MatrixXd>(cfg, key);
  if (x.rows() != 3 || x.cols() != 3) throw std::invalid_argument(std::string("compiled loop: setting ") + key + " must be 3x3");
  return x;
}

std::vector<double> doubles(bp::object seq) {
  std::vector<double> out;
  for (bp::ssize_t i = 0; i < bp::len(seq); ++i) out.push_back(bp::extract<double>(seq[i]));
  return out;
}

std::unique_ptr<cn::Controller> make_controller(Kernel & k, const bp::dict & c) {
  const std::string kind = get<std::string>(c, "kind");
  const Model & model = k.model();
  if (kind == "none") return std::make_unique<cn::NoTorque>();
  const Eigen::Index na = k.actuated().size(), nq = model.nq, nv = model.nv;
  if (kind == "gravity_pd")
    return std::make_unique<cn::GravityPD>(k, vec(c, "kp", na), vec(c, "kd", na), vec(c, "q_des", nq));
  if (kind == "computed_torque") {
    const Eigen::VectorXi q_index = get<Eigen::VectorXi>(c, "q_index");
    if (q_index.size() != na || (na && (q_index.minCoeff() < 0 || q_index.maxCoeff() >= nq)))
      throw std::invalid_argument("compiled loop: q_index must hold one configuration index per actuated joint");
    return std::make_unique<cn::ComputedTorqueHold>(model, k.actuated(), q_index, vec(c, "kp", na), vec(c, "kd", na),
                                                    vec(c, "q_d", na));
  }
  if (kind == "drives") {
    std::vector<MatrixXd> segments;
    bp::list drives = get<bp::list>(c, "segments");
    for (bp::ssize_t i = 0; i < bp::len(drives); ++i) {
      segments.push_back(bp::extract<MatrixXd>(drives[i]));
      if (segments.back().cols() != 6 || segments.back().rows() < 1)
        throw std::invalid_argument("compiled loop: a drive is rows of (start, constant, ramp, amplitude, omega, phase)");
    }
    if (static_cast<Eigen::Index>(segments.size()) != na) throw std::invalid_argument("drives: one per actuated joint");
    return std::make_unique<cn::Drives>(std::move(segments));
  }
  if (kind == "object_impedance") {
    std::vector<cn::ObjectImpedanceLaw::Grasp> grasps;
    bp::list gl = get<bp::list>(c, "grasps");
    for (bp::ssize_t i = 0; i < bp::len(gl); ++i) {
      bp::tuple g = bp::extract<bp::tuple>(gl[i]);
      cn::ObjectImpedanceLaw::Grasp gr;
      gr.grasp = bp::extract<pinocchio::FrameIndex>(g[0]);
      gr.tip = bp::extract<pinocchio::FrameIndex>(g[1]);
      if (gr.grasp >= model.frames.size() || gr.tip >= model.frames.size())
        throw std::invalid_argument("compiled loop: grasp frame index out of range");
      const Eigen::VectorXi vi = bp::extract<Eigen::VectorXi>(g[2]);
      if (vi.size() && (vi.minCoeff() < 0 || vi.maxCoeff() >= nv))
        throw std::invalid_argument("compiled loop: arm velocity index out of range");
      gr.v_index.assign(vi.data(), vi.data() + vi.size());
      grasps.push_back(std::move(gr));
    }
    cn::ObjectTask task;
    bp::dict t = get<bp::dict>(c, "task");
    task.hold = get<bool>(t, "hold");
    task.start = vec(t, "start", 3);
    task.R = mat3(t, "rotation");
    if (!task.hold) {
      task.axis = vec(t, "axis", 3);
      task.squeeze = get<double>(t, "squeeze");
      task.t_grip = get<double>(t, "t_grip");
      task.lift = get<double>(t, "lift");
      task.t_lift = get<double>(t, "t_lift");
      task.lift_duration = get<double>(t, "lift_duration");
      task.amplitude = get<double>(t, "amplitude");
      task.frequency = get<double>(t, "frequency");
      task.t_osc = get<double>(t, "t_osc");
      task.cycles = get<double>(t, "cycles");
    }
    const pinocchio::FrameIndex object_frame = get<pinocchio::FrameIndex>(c, "object_frame");
    if (object_frame >= model.frames.size()) throw std::invalid_argument("compiled loop: object frame out of range");
    return std::make_unique<cn::ObjectImpedanceLaw>(
      model, object_frame, std::move(grasps), std::move(task), get<double>(c, "mass"), vec(c, "com", 3),
      vec(c, "gravity", 3), vec(c, "Kp", 3), vec(c, "Kr", 3), vec(c, "Dp", 3), vec(c, "Dr", 3),
      get<double>(c, "joint_damping"), get<double>(c, "null_k"), get<double>(c, "null_d"), vec(c, "q0", nq));
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
  else if (method == "generalized_alpha") m = cn::GENERALIZED_ALPHA;
  else throw std::invalid_argument("compiled loop: unknown method " + method);
  if (m == cn::RK) {
    bp::list A = get<bp::list>(cfg, "A");
    for (bp::ssize_t i = 0; i < bp::len(A); ++i) tab.A.push_back(doubles(A[i]));
    tab.b = doubles(cfg["b"]);
    tab.c = doubles(cfg["c"]);
    if (cfg.has_key("b_hat")) tab.b_hat = doubles(cfg["b_hat"]);
  }
  const Model & model = kernel.model();
  const Eigen::Index na = kernel.actuated().size();
  if (m == cn::RK && (tab.A.empty() || tab.b.size() != tab.A.size() || tab.c.size() != tab.A.size() ||
                      (get<bool>(cfg, "adaptive") && tab.b_hat.size() != tab.A.size())))
    throw std::invalid_argument("compiled loop: inconsistent Butcher tableau");
  for (std::size_t i = 0; i < tab.A.size(); ++i)
    if (tab.A[i].size() > i) throw std::invalid_argument("compiled loop: the tableau must be explicit");
  if (get<int>(cfg, "jacobian_every") < 1) throw std::invalid_argument("compiled loop: jacobian_every must be >= 1");
  auto loop = std::make_shared<Loop>(
    kernel, make_controller(kernel, get<bp::dict>(cfg, "controller")), m, std::move(tab), get<bool>(cfg, "adaptive"),
    get<double>(cfg, "gamma"), get<int>(cfg, "jacobian_every"), get<int>(cfg, "error_order"), vec(cfg, "kp", na),
    vec(cfg, "kd", na), vec(cfg, "q0", model.nq), vec(cfg, "v0", model.nv), get<double>(cfg, "dt"),
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
      const Eigen::Index nx = 2 * model.nv, nz = nx + na + 1;
      if (model.nq != model.nv || x.step.rows() != nx || x.step.cols() != nz || x.p < 0)
        throw std::invalid_argument("compiled loop: an exponential step must be (2nv, 2nv + n_actuated + 1)");
      if (x.p > 0) {
        x.predictor = bp::extract<MatrixXd>(d[2]);
        x.inner = bp::extract<MatrixXd>(d[3]);
        if (x.predictor.rows() != x.p * nx || x.predictor.cols() != nz || x.inner.rows() != nx || x.inner.cols() != x.p * na)
          throw std::invalid_argument("compiled loop: the exponential's predictor or inner matrix has the wrong shape");
      }
      loop->add_discretisation(std::move(x));
    }
  }
  if (m == cn::GENERALIZED_ALPHA) loop->set_alpha(doubles(cfg["alpha"]));
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
  bp::list statuses;
  for (const char * name : cn::STATUS_NAMES) statuses.append(name);
  bp::scope().attr("STATUSES") = bp::tuple(statuses);
  step_matrix_error_type = bp::import("coopdyn.errors").attr("StepMatrixError");
  bp::register_exception_translator<StepMatrixError>(&translate_step_matrix_error);
  bp::class_<Kernel, boost::noncopyable>(
    "Kernel", "The scene dynamics' hot path (see coopdyn.dynamics.native).",
    bp::init<bp::object, bp::object, bp::list, RefVec, Eigen::Ref<const Eigen::VectorXi>, FrameIndex>(
      bp::args("self", "model", "data", "links", "damping", "actuated", "object_frame")))
    .def("acceleration", &Kernel::acceleration, bp::args("self", "q", "v", "tau", "wrench"))
    .def("implicit_terms", &Kernel::implicit_terms, bp::args("self", "q", "v", "tau", "wrench"))
    .def("factor", &Kernel::factor, bp::args("self", "M", "K", "D", "gh", "kp", "kd", "gh2"))
    .def("solve", &Kernel::solve, bp::args("self", "f_q", "Mf_v"))
    .def("implicit_euler_velocity", &Kernel::implicit_euler_velocity,
         bp::args("self", "q", "v", "tau", "h", "kp", "kd", "wrench"))
    .def("elastic_energies", &Kernel::elastic_energies, bp::args("self"))
    .def("spring_force", &Kernel::spring_force, bp::args("self", "q", "v"))
    .def("gravity", &Kernel::gravity, bp::args("self", "q"))
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
    .def("take_samples", &Loop::take_samples, bp::args("self"))
    .def("take_events", &Loop::take_events, bp::args("self"))
    .def("counters", &Loop::counters, bp::args("self"))
    .def("failure", &Loop::failure, bp::args("self"))
    .add_property("t", &Loop::time);
  bp::def("make_loop", &make_loop, bp::with_custodian_and_ward_postcall<0, 1>(), bp::args("kernel", "config"));
}
