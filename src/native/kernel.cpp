// coopdyn._native: the hot path of coopdyn.dynamics.Dynamics in C++.
//
// The same equations as the Python implementation in coopdyn/dynamics.py (which stays the
// reference; tests compare the two to round-off):
//
//   H(q) q̈ + h(q, q̇) = S τ − B q̇ + Q,   Q = −Σ_i A_iᵀ (K_i e_i + D_i ė_i),
//   A_i = Jlog6(T_M_G) (J_G − Ad(T_M_G⁻¹) J_T),   e_i = log6(T_M_G),   ė_i = A_i q̇,
//
// with LOCAL frame Jacobians of each link's tip frame T and grasp frame G. The kernel works on
// the Python-owned pinocchio Model and Data (boost.python lvalues), so everything Python reads
// from Data afterwards (frame placements, velocities) is what the Python path would leave there.

#include <pinocchio/multibody.hpp>
#include <pinocchio/spatial.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <eigenpy/eigenpy.hpp>
#include <boost/python.hpp>

#include <stdexcept>
#include <string>
#include <vector>

namespace bp = boost::python;
using pinocchio::Data;
using pinocchio::FrameIndex;
using pinocchio::Model;
using pinocchio::SE3;

using Matrix6 = Eigen::Matrix<double, 6, 6>;
using Vector6 = Eigen::Matrix<double, 6, 1>;
using Matrix6x = Eigen::Matrix<double, 6, Eigen::Dynamic>;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using RefVec = Eigen::Ref<const VectorXd>;

namespace {

struct Link {
  FrameIndex tip, grasp;
  Matrix6 K, D;
  bool has_damping;
};

void check_size(const RefVec & x, Eigen::Index n, const char * name) {
  if (x.size() != n)
    throw std::invalid_argument(
      std::string(name) + " has " + std::to_string(x.size()) + " entries, expected " + std::to_string(n));
}

class Kernel {
public:
  Kernel(bp::object model_obj, bp::object data_obj, bp::list links, const RefVec & damping,
         const Eigen::Ref<const Eigen::VectorXi> & actuated, FrameIndex object_frame)
    : model_obj_(model_obj), data_obj_(data_obj),
      model_(bp::extract<const Model &>(model_obj)), data_(bp::extract<Data &>(data_obj)),
      damping_(damping), actuated_(actuated), object_frame_(object_frame) {
    const auto nv = model_.nv;
    check_size(damping, nv, "damping");
    if (object_frame_ >= model_.frames.size()) throw std::invalid_argument("object_frame out of range");
    for (Eigen::Index i = 0; i < actuated_.size(); ++i)
      if (actuated_[i] < 0 || actuated_[i] >= nv) throw std::invalid_argument("actuated index out of range");
    for (bp::ssize_t i = 0; i < bp::len(links); ++i) {
      bp::tuple t = bp::extract<bp::tuple>(links[i]);
      Link lk;
      lk.tip = bp::extract<FrameIndex>(t[0]);
      lk.grasp = bp::extract<FrameIndex>(t[1]);
      lk.K = bp::extract<MatrixXd>(t[2])();
      lk.D = bp::extract<MatrixXd>(t[3])();
      if (lk.tip >= model_.frames.size() || lk.grasp >= model_.frames.size())
        throw std::invalid_argument("link frame index out of range");
      lk.has_damping = !lk.D.isZero(0.0);
      links_.push_back(lk);
    }
    has_damping_ = !damping_.isZero(0.0);
    J_G_.setZero(6, nv);
    J_T_.setZero(6, nv);
    A_.setZero(6, nv);
    Q_.setZero(nv);
    tau_full_.setZero(nv);
    K_t_.setZero(nv, nv);
    D_t_.setZero(nv, nv);
  }

  VectorXd acceleration(const RefVec & q, const RefVec & v, const RefVec & tau, bp::object wrench) {
    generalized_force(q, v, tau, wrench, false);
    return pinocchio::aba(model_, data_, q, v, tau_full_);
  }

  // (f, M, K̃, D̃): f = Sτ + Q − Bq̇ − b(q, q̇) = M q̈ and the stiffness matrices (without gains).
  bp::tuple implicit_terms(const RefVec & q, const RefVec & v, const RefVec & tau, bp::object wrench) {
    implicit_parts(q, v, tau, wrench);
    return bp::make_tuple(VectorXd(tau_full_), MatrixXd(data_.M), MatrixXd(K_t_), MatrixXd(D_t_));
  }

  // One linearly implicit Euler velocity update: v⁺ = v + h k with
  // (M + h(D̃ + Kd) + h²(K̃ + Kp)) k = f − h (K̃ + Kp) v, Kp and Kd (n_actuated,) the joint PD gains.
  VectorXd implicit_euler_velocity(const RefVec & q, const RefVec & v, const RefVec & tau, double h,
                                   const RefVec & kp, const RefVec & kd, bp::object wrench) {
    check_size(kp, actuated_.size(), "kp");
    check_size(kd, actuated_.size(), "kd");
    implicit_parts(q, v, tau, wrench);
    for (Eigen::Index i = 0; i < actuated_.size(); ++i) {
      K_t_(actuated_[i], actuated_[i]) += kp[i];
      D_t_(actuated_[i], actuated_[i]) += kd[i];
    }
    S_ = data_.M + h * D_t_ + (h * h) * K_t_;
    rhs_.noalias() = tau_full_ - h * (K_t_ * v);
    llt_.compute(S_);  // reads the upper triangle
    if (llt_.info() != Eigen::Success)
      throw std::runtime_error("implicit Euler: M + hD + h²K is not positive definite at this state");
    return v + h * llt_.solve(rhs_);
  }

  // ½ eᵀ K e of each link (n_links,) [J] at the frame placements of the last kinematics pass.
  VectorXd elastic_energies() {
    VectorXd out(links_.size());
    for (std::size_t i = 0; i < links_.size(); ++i) {
      const Link & lk = links_[i];
      const SE3 & oMT = pinocchio::updateFramePlacement(model_, data_, lk.tip);
      const SE3 & oMG = pinocchio::updateFramePlacement(model_, data_, lk.grasp);
      const Vector6 e = pinocchio::log6(oMT.actInv(oMG)).toVector();
      out[i] = 0.5 * e.dot(lk.K * e);
    }
    return out;
  }

  double last_dissipation() const { return last_dissipation_; }

private:
  // What the implicit methods need at (q, v): tau_full_ = f = Sτ + Q − Bq̇ − b(q, q̇), K_t_, D_t_
  // and data_.M = M(q) with both triangles (crba fills the upper one).
  void implicit_parts(const RefVec & q, const RefVec & v, const RefVec & tau, bp::object wrench) {
    generalized_force(q, v, tau, wrench, true);
    tau_full_ -= pinocchio::nonLinearEffects(model_, data_, q, v);
    pinocchio::crba(model_, data_, q);
    data_.M.triangularView<Eigen::StrictlyLower>() = data_.M.transpose().triangularView<Eigen::StrictlyLower>();
  }

  // Kinematics at q, then tau_full_ = Sτ + Q − Bq̇ (+ the object wrench); with `matrices`, also
  // K_t_ = Σ AᵀKA and D_t_ = Σ AᵀDA + B.
  void generalized_force(const RefVec & q, const RefVec & v, const RefVec & tau, bp::object wrench,
                         bool matrices) {
    const auto nv = model_.nv;
    check_size(q, model_.nq, "q");
    check_size(v, nv, "v");
    check_size(tau, actuated_.size(), "tau");
    pinocchio::computeJointJacobians(model_, data_, q);
    Q_.setZero();
    double p_diss = 0.0;
    if (matrices) {
      K_t_.setZero();
      D_t_.setZero();
      D_t_.diagonal() = damping_;
    }
    Matrix6 Jlog;
    for (const Link & lk : links_) {
      const SE3 & oMT = pinocchio::updateFramePlacement(model_, data_, lk.tip);
      const SE3 & oMG = pinocchio::updateFramePlacement(model_, data_, lk.grasp);
      const SE3 T_M_G = oMT.actInv(oMG);
      J_G_.setZero();
      J_T_.setZero();
      pinocchio::getFrameJacobian(model_, data_, lk.grasp, pinocchio::LOCAL, J_G_);
      pinocchio::getFrameJacobian(model_, data_, lk.tip, pinocchio::LOCAL, J_T_);
      J_G_ -= T_M_G.toActionMatrixInverse().lazyProduct(J_T_);  // lazy: cheaper than GEMM at 6 × nv
      pinocchio::Jlog6(T_M_G, Jlog);
      A_ = Jlog.lazyProduct(J_G_);
      Vector6 w = lk.K * pinocchio::log6(T_M_G).toVector();
      if (lk.has_damping) {
        const Vector6 e_dot = A_ * v;
        const Vector6 De = lk.D * e_dot;
        p_diss += e_dot.dot(De);
        w += De;
      }
      Q_.noalias() -= A_.transpose() * w;
      if (matrices) {
        KA_ = lk.K.lazyProduct(A_);
        K_t_ += A_.transpose().lazyProduct(KA_);
        if (lk.has_damping) {
          KA_ = lk.D.lazyProduct(A_);
          D_t_ += A_.transpose().lazyProduct(KA_);
        }
      }
    }
    if (!wrench.is_none()) {
      const VectorXd w = bp::extract<VectorXd>(wrench)();
      if (w.size() != 6) throw std::invalid_argument("object wrench must have 6 entries");
      const auto & R = pinocchio::updateFramePlacement(model_, data_, object_frame_).rotation();
      Vector6 local;
      local.head<3>().noalias() = R.transpose() * w.head<3>();
      local.tail<3>().noalias() = R.transpose() * w.tail<3>();
      J_G_.setZero();
      pinocchio::getFrameJacobian(model_, data_, object_frame_, pinocchio::LOCAL, J_G_);
      Q_.noalias() += J_G_.transpose() * local;
    }
    tau_full_ = Q_;
    for (Eigen::Index i = 0; i < actuated_.size(); ++i) tau_full_[actuated_[i]] += tau[i];
    if (has_damping_) {
      tau_full_.array() -= damping_.array() * v.array();
      p_diss += (damping_.array() * v.array().square()).sum();
    }
    last_dissipation_ = p_diss;
  }

  bp::object model_obj_, data_obj_;  // keep the Python objects alive
  const Model & model_;
  Data & data_;
  std::vector<Link> links_;
  VectorXd damping_;
  Eigen::VectorXi actuated_;
  FrameIndex object_frame_;
  bool has_damping_ = false;
  double last_dissipation_ = 0.0;
  Matrix6x J_G_, J_T_, A_, KA_;
  VectorXd Q_, tau_full_, rhs_;
  MatrixXd K_t_, D_t_, S_;
  Eigen::LLT<MatrixXd> llt_;
};

}  // namespace

BOOST_PYTHON_MODULE(_native) {
  eigenpy::enableEigenPy();
  eigenpy::enableEigenPySpecific<Eigen::VectorXi>();
  bp::scope().attr("PINOCCHIO_VERSION") = PINOCCHIO_VERSION;
  bp::class_<Kernel, boost::noncopyable>(
    "Kernel", "The scene dynamics' hot path (see coopdyn.dynamics.Dynamics).",
    bp::init<bp::object, bp::object, bp::list, RefVec, Eigen::Ref<const Eigen::VectorXi>, FrameIndex>(
      bp::args("self", "model", "data", "links", "damping", "actuated", "object_frame")))
    .def("acceleration", &Kernel::acceleration, bp::args("self", "q", "v", "tau", "wrench"))
    .def("implicit_terms", &Kernel::implicit_terms, bp::args("self", "q", "v", "tau", "wrench"))
    .def("implicit_euler_velocity", &Kernel::implicit_euler_velocity,
         bp::args("self", "q", "v", "tau", "h", "kp", "kd", "wrench"))
    .def("elastic_energies", &Kernel::elastic_energies, bp::args("self"))
    .add_property("last_dissipation", &Kernel::last_dissipation);
}
