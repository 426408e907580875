// The built-in controllers in C++ for the compiled step loop (loop.hpp): the same laws, in the
// same operation order, as their Python definitions (coopdyn/control.py, coopdyn/cooperative.py,
// coopdyn/problems/linear_book.py), tested equal to round-off (tests/test_compiled_loop.py) —
// except GravityPD's g(q), read off the kernel's kinematics pass (Kernel::actuated_gravity,
// equal to Pinocchio's RNEA to round-off, tests/test_native.py).
#pragma once

#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/spatial.hpp>

#include "kernel.hpp"

#include <Eigen/Cholesky>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

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
};

struct NoTorque : Controller {
  void torque(double, const VectorXd &, const VectorXd &, VectorXd & tau) override { tau.setZero(); }
};

// τ = g(q) + Kp (q_d ⊖ q) − Kd q̇ on the actuated joints (GravityCompensationPD), g(q) read off
// the kernel's kinematics pass when its joints allow (Kernel::actuated_gravity), else from
// Pinocchio's generalized gravity.
struct GravityPD : Controller {
  GravityPD(Kernel & kernel, VectorXd kp, VectorXd kd, VectorXd q_des)
    : kernel(kernel), model(kernel.model()), data(model), act(kernel.actuated()), kp(std::move(kp)), kd(std::move(kd)),
      q_des(std::move(q_des)), dq(model.nv), g_rnea(act.size()) {}
  bool reads_kernel() const override { return kernel.kinematic_gravity(); }
  void torque(double, const VectorXd & q, const VectorXd & v, VectorXd & tau) override {
    const VectorXd & g = kernel.kinematic_gravity() ? kernel.actuated_gravity(q) : rnea_gravity(q);
    pinocchio::difference(model, q, q_des, dq);
    for (Eigen::Index i = 0; i < act.size(); ++i) tau[i] = (g[i] + kp[i] * dq[act[i]]) - kd[i] * v[act[i]];
  }
  // g(q) on the actuated joints by Pinocchio's RNEA, for joints actuated_gravity does not take.
  const VectorXd & rnea_gravity(const VectorXd & q) {
    const VectorXd & full = pinocchio::computeGeneralizedGravity(model, data, q);
    for (Eigen::Index i = 0; i < act.size(); ++i) g_rnea[i] = full[act[i]];
    return g_rnea;
  }
  Kernel & kernel;
  const Model & model;
  Data data;
  Eigen::VectorXi act;
  VectorXd kp, kd, q_des, dq, g_rnea;
};

// τ = M(q)(Kp (q_d − q) − Kd q̇) + h(q, q̇), holding q_d (ComputedTorque with its default reference).
struct ComputedTorqueHold : Controller {
  ComputedTorqueHold(const Model & model, const Eigen::VectorXi & act, const Eigen::VectorXi & q_index, VectorXd kp,
                     VectorXd kd, VectorXd q_d)
    : model(model), data(model), act(act), q_index(q_index), kp(std::move(kp)), kd(std::move(kd)), q_d(std::move(q_d)),
      e(act.size()), M(act.size(), act.size()) {}
  void torque(double, const VectorXd & q, const VectorXd & v, VectorXd & tau) override {
    pinocchio::crba(model, data, q);
    data.M.triangularView<Eigen::StrictlyLower>() = data.M.transpose().triangularView<Eigen::StrictlyLower>();
    const VectorXd & h = pinocchio::nonLinearEffects(model, data, q, v);
    const Eigen::Index n = act.size();
    for (Eigen::Index i = 0; i < n; ++i) {
      e[i] = kp[i] * (q_d[i] - q[q_index[i]]) + kd[i] * (0.0 - v[act[i]]);
      for (Eigen::Index j = 0; j < n; ++j) M(i, j) = data.M(act[i], act[j]);
    }
    tau.noalias() = M * e;
    for (Eigen::Index i = 0; i < n; ++i) tau[i] += h[act[i]];
  }
  const Model & model;
  Data data;
  Eigen::VectorXi act, q_index;
  VectorXd kp, kd, q_d, e;
  MatrixXd M;
};

// Open-loop drives: τ_i = c + r s + A sin(ω s + φ), s = t − start of the segment in force.
struct Drives : Controller {
  // segments[i]: rows (start, constant, ramp, amplitude, omega, phase), increasing start, first at 0.
  explicit Drives(std::vector<MatrixXd> segments) : segments(std::move(segments)) {}
  void torque(double t, const VectorXd &, const VectorXd &, VectorXd & tau) override {
    for (std::size_t i = 0; i < segments.size(); ++i) {
      const MatrixXd & S = segments[i];
      Eigen::Index k = 0;  // bisect_right(starts, t) − 1, at least 0
      while (k + 1 < S.rows() && S(k + 1, 0) <= t) ++k;
      const double s = t - S(k, 0);
      tau[i] = S(k, 1) + S(k, 2) * s + S(k, 3) * std::sin(S(k, 4) * s + S(k, 5));
    }
  }
  std::vector<MatrixXd> segments;
};

// The desired object motion of GripLiftOscillate (or a hold of the initial pose).
struct ObjectTask {
  bool hold = true;
  Vector3 start = Vector3::Zero(), axis = Vector3::UnitY();
  Matrix3 R = Matrix3::Identity();
  double squeeze = 0, t_grip = 1, lift = 0, t_lift = 0, lift_duration = 1, amplitude = 0, frequency = 1, t_osc = 0;
  double cycles = 0;

  void at(double t, Vector3 & pos, Vector3 & vel, Vector3 & acc, double & sq) const {
    pos = start;
    vel.setZero();
    acc.setZero();
    sq = 0.0;
    if (hold) return;
    const double s = std::min(std::max(t / t_grip, 0.0), 1.0);
    sq = squeeze * (3 * s * s - 2 * s * s * s);
    const double u = std::min(std::max((t - t_lift) / lift_duration, 0.0), 1.0);
    const double shape = 10 * std::pow(u, 3) - 15 * std::pow(u, 4) + 6 * std::pow(u, 5);
    const bool inside = 0 < u && u < 1;
    const double dshape = inside ? (30 * u * u - 60 * std::pow(u, 3) + 30 * std::pow(u, 4)) / lift_duration : 0.0;
    const double ddshape =
      inside ? (60 * u - 180 * u * u + 120 * std::pow(u, 3)) / (lift_duration * lift_duration) : 0.0;
    pos[2] += lift * shape;
    vel[2] += lift * dshape;
    acc[2] += lift * ddshape;
    const double duration = cycles / frequency, s_osc = t - t_osc;
    if (0.0 < s_osc && s_osc < duration) {
      const double w = 2 * M_PI * frequency, W = M_PI / duration;
      const double env = std::pow(std::sin(W * s_osc), 2), denv = W * std::sin(2 * W * s_osc),
                   ddenv = 2 * W * W * std::cos(2 * W * s_osc);
      const double osc = std::sin(w * s_osc), dosc = w * std::cos(w * s_osc), ddosc = -(w * w) * std::sin(w * s_osc);
      pos += (amplitude * env * osc) * axis;
      vel += (amplitude * (denv * osc + env * dosc)) * axis;
      acc += (amplitude * (ddenv * osc + 2 * denv * dosc + env * ddosc)) * axis;
    }
  }
};

// ObjectImpedance: object impedance, closed-form non-squeezing distribution G⁺F plus the
// commanded squeeze's internal part, tool wrenches through the tip Jacobians, the arms' own
// nonlinear effects, joint damping and a posture task in the tip Jacobians' null space.
// A grasp geometry the law cannot use (translated to coopdyn.errors.SceneError).
struct GraspGeometryError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct ObjectImpedanceLaw : Controller {
  struct Grasp {
    pinocchio::FrameIndex grasp, tip;
    std::vector<int> v_index;
  };

  ObjectImpedanceLaw(const Model & model, pinocchio::FrameIndex object_frame, std::vector<Grasp> grasps, ObjectTask task,
                   double mass, Vector3 com, Vector3 gravity, Vector3 Kp, Vector3 Kr, Vector3 Dp, Vector3 Dr,
                   double joint_damping, double null_k, double null_d, VectorXd q0)
    : model(model), data(model), object_frame(object_frame), grasps(std::move(grasps)), task(std::move(task)),
      mass(mass), com(com), gravity(gravity), Kp(Kp), Kr(Kr), Dp(Dp), Dr(Dr), joint_damping(joint_damping),
      null_k(null_k), null_d(null_d), q0(std::move(q0)), J6(6, model.nv), posture(model.nv) {}

  void torque(double t, const VectorXd & q, const VectorXd & v, VectorXd & tau) override {
    pinocchio::forwardKinematics(model, data, q, v);
    pinocchio::updateFramePlacements(model, data);
    // the object wrench (world axes, at the object frame origin)
    Vector3 p_d, v_d, a_d;
    double squeeze;
    task.at(t, p_d, v_d, a_d, squeeze);
    const pinocchio::SE3 & oMo = data.oMf[object_frame];
    const pinocchio::Motion V = pinocchio::getFrameVelocity(model, data, object_frame, pinocchio::LOCAL_WORLD_ALIGNED);
    const Vector3 e_p = p_d - oMo.translation();
    const Matrix3 Rerr = task.R * oMo.rotation().transpose();
    const Vector3 e_r = pinocchio::log3(Rerr);
    Eigen::Matrix<double, 6, 1> F;
    F.head<3>() = mass * (a_d - gravity) + Kp.cwiseProduct(e_p) + Dp.cwiseProduct(v_d - V.linear());
    const Vector3 com_w = oMo.rotation() * com;
    F.tail<3>() = Kr.cwiseProduct(e_r) + Dr.cwiseProduct(-V.angular()) + com_w.cross(-mass * gravity);
    // distribution over the grasps, moments about their centroid
    const std::size_t n = grasps.size();
    auto & r = r_;  // per-call scratch kept as members: no allocation on the hot path
    r.resize(n, 3);
    Vector3 c = Vector3::Zero();
    for (std::size_t i = 0; i < n; ++i) r.row(i) = data.oMf[grasps[i].grasp].translation().transpose();
    c = r.colwise().sum().transpose() / double(n);
    r.rowwise() -= c.transpose();
    Eigen::Matrix<double, 6, 1> F_c = F;
    F_c.tail<3>() += (oMo.translation() - c).cross(F.head<3>());
    const Matrix3 A = (double(n) + r.squaredNorm()) * Matrix3::Identity() - r.transpose() * r;
    const Matrix3 A_inv = A.inverse();
    f.resize(n, 6);
    distribute(r, A_inv, F_c, f);
    if (squeeze != 0.0 && n > 1) {
      auto & inward = inward_;
      inward.setZero(n, 6);
      Eigen::Matrix<double, 6, 1> resultant = Eigen::Matrix<double, 6, 1>::Zero();
      for (std::size_t i = 0; i < n; ++i) {
        const Vector3 d = -r.row(i).transpose();
        const double norm = d.norm();
        if (norm < 1e-9) throw GraspGeometryError("grasp points coincide with their centroid: no squeeze direction");
        inward.block<1, 3>(i, 0) = (squeeze * d / norm).transpose();
      }
      for (std::size_t i = 0; i < n; ++i) resultant.head<3>() += inward.block<1, 3>(i, 0).transpose();
      for (std::size_t i = 0; i < n; ++i)
        resultant.tail<3>() += Vector3(r.row(i).transpose()).cross(Vector3(inward.block<1, 3>(i, 0).transpose()));
      auto & g = internal_;
      g.resize(n, 6);
      distribute(r, A_inv, resultant, g);
      f += inward - g;
    }
    // joint torques
    pinocchio::computeJointJacobians(model, data, q);
    const VectorXd & nle = pinocchio::nonLinearEffects(model, data, q, v);  // data.nle, untouched below
    pinocchio::difference(model, q, q0, posture);
    Eigen::Index offset = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const Grasp & gr = grasps[i];
      J6.setZero();
      pinocchio::getFrameJacobian(model, data, gr.tip, pinocchio::LOCAL_WORLD_ALIGNED, J6);
      const Eigen::Index m = static_cast<Eigen::Index>(gr.v_index.size());
      auto & J = J_;
      auto & vi = vi_;
      auto & x = x_;
      J.resize(6, m);
      vi.resize(m);
      x.resize(m);
      for (Eigen::Index j = 0; j < m; ++j) {
        J.col(j) = J6.col(gr.v_index[j]);
        vi[j] = v[gr.v_index[j]];
        x[j] = null_k * posture[gr.v_index[j]] - null_d * vi[j];
      }
      const Vector3 rr = data.oMf[gr.grasp].translation() - data.oMf[gr.tip].translation();
      Eigen::Matrix<double, 6, 1> w = f.row(i).transpose();
      w.tail<3>() += rr.cross(Vector3(f.block<1, 3>(i, 0).transpose()));
      auto & ti = ti_;
      ti.noalias() = J.transpose() * w;
      for (Eigen::Index j = 0; j < m; ++j) ti[j] = (ti[j] + nle[gr.v_index[j]]) - joint_damping * vi[j];
      add_null_space_part(J, x, ti);
      tau.segment(offset, m) = ti;
      offset += m;
    }
  }

  // G⁺F as rows: y = (G Gᵀ)⁻¹F = (F_f / N, A⁻¹ F_m), f_i = [y_f − r_i × y_m; y_m].
  static void distribute(const Eigen::Matrix<double, Eigen::Dynamic, 3> & r, const Matrix3 & A_inv,
                         const Eigen::Matrix<double, 6, 1> & F, Eigen::Matrix<double, Eigen::Dynamic, 6> & out) {
    const Vector3 y_f = F.head<3>() / double(r.rows());
    const Vector3 y_m = A_inv * F.tail<3>();
    for (Eigen::Index i = 0; i < r.rows(); ++i) {
      out.block<1, 3>(i, 0) = (y_f - Vector3(r.row(i).transpose()).cross(y_m)).transpose();
      out.block<1, 3>(i, 3) = y_m.transpose();
    }
  }

  // out += (I − J⁺J) x: closed form at full rank (redundant arm: x − Jᵀ(J Jᵀ)⁻¹J x; otherwise
  // J⁺J = I, nothing to add); a complete orthogonal decomposition near a singularity.
  void add_null_space_part(const MatrixXd & J, const VectorXd & x, VectorXd & out) {
    const auto well_conditioned = [](const auto & llt) {  // diag(L) spans less than 1e7: condition ≲ 1e14
      const auto d = llt.matrixLLT().diagonal();
      return llt.info() == Eigen::Success && d.minCoeff() >= 1e-7 * d.maxCoeff();
    };
    if (J.cols() > 6) {
      llt6_.compute(J * J.transpose());
      if (well_conditioned(llt6_)) {
        out.noalias() += x - J.transpose() * llt6_.solve(J * x);
        return;
      }
    } else {
      llt_.compute(J.transpose() * J);
      if (well_conditioned(llt_)) return;
    }
    out.noalias() += x - J.completeOrthogonalDecomposition().pseudoInverse() * (J * x);
  }

  const Model & model;
  Data data;
  pinocchio::FrameIndex object_frame;
  std::vector<Grasp> grasps;
  ObjectTask task;
  double mass;
  Vector3 com, gravity, Kp, Kr, Dp, Dr;
  double joint_damping, null_k, null_d;
  VectorXd q0;
  Eigen::Matrix<double, 6, Eigen::Dynamic> J6;
  VectorXd posture;
  Eigen::Matrix<double, Eigen::Dynamic, 6> f, inward_, internal_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> r_;
  MatrixXd J_;
  VectorXd vi_, x_, ti_;
  Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt6_;
  Eigen::LLT<MatrixXd> llt_;
};

}  // namespace coopdyn_native
