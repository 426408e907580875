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

#include "kernel.hpp"

namespace {

using coopdyn_native::Kernel;
using coopdyn_native::StepMatrixError;

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
    .def("element_states", &Kernel::element_states, bp::args("self", "q", "v"))
    .def("readouts", &Kernel::readouts, bp::args("self", "Q", "V"))
    .def("clear_rotation_alarm", &Kernel::clear_rotation_alarm, bp::args("self"))
    .add_property("last_dissipation", &Kernel::last_dissipation)
    .add_property("rotation_alarm", &Kernel::rotation_alarm)
    .add_property("rotation_alarm_angle", &Kernel::rotation_alarm_angle);
}
