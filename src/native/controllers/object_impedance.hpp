// ObjectImpedance with its task, hold or GripLiftOscillate (coopdyn/control/cooperative.py), in C++.
#pragma once

#include "controller.hpp"

#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/spatial.hpp>

#include <Eigen/Cholesky>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <vector>

namespace coopdyn_native {

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
struct ObjectImpedanceLaw : Controller {
  struct Grasp {
    pinocchio::FrameIndex grasp, tip;
    std::vector<int> v_index;
  };

  ObjectImpedanceLaw(const Model & model, Kernel::LentData lent, pinocchio::FrameIndex object_frame, std::vector<Grasp> grasps, ObjectTask task,
                   double mass, Vector3 com, Vector3 gravity, Vector3 Kp, Vector3 Kr, Vector3 Dp, Vector3 Dr,
                   double joint_damping, double null_k, double null_d, VectorXd q0, bool collocated,
                   std::vector<pinocchio::SE3> tip_offsets, Vector3 Ki, Vector3 Di, VectorXd transmissions)
    : model(model), lent(std::move(lent)), data(*this->lent), object_frame(object_frame), grasps(std::move(grasps)), task(std::move(task)),
      mass(mass), com(com), gravity(gravity), Kp(Kp), Kr(Kr), Dp(Dp), Dr(Dr), joint_damping(joint_damping),
      null_k(null_k), null_d(null_d), q0(q0.head(model.nq)), J6(6, model.nv), posture(model.nv), collocated(collocated), Ki(Ki), Di(Di),
      transmissions(std::move(transmissions)) {
    for (const pinocchio::SE3 & o_M_T : tip_offsets) T_M_o.push_back(o_M_T.inverse());
  }

  // The object frame's position, rotation, origin velocity and angular velocity (world axes) as
  // the law reads them (ObjectImpedance.object_state): the object frame itself, or (collocated)
  // each tool frame carried to it by its offset at the start, averaged.
  void object_state(Vector3 & p, Matrix3 & R, Vector3 & lin, Vector3 & ang) {
    if (!collocated) {
      const pinocchio::SE3 & oMo = data.oMf[object_frame];
      const pinocchio::Motion V = pinocchio::getFrameVelocity(model, data, object_frame, pinocchio::LOCAL_WORLD_ALIGNED);
      p = oMo.translation();
      R = oMo.rotation();
      lin = V.linear();
      ang = V.angular();
      return;
    }
    const std::size_t n = grasps.size();
    tip_R.resize(n);
    tip_w.resize(n);
    p.setZero();
    Vector3 mean_log = Vector3::Zero();
    for (std::size_t i = 0; i < n; ++i) {
      const pinocchio::SE3 estimate = data.oMf[grasps[i].tip] * T_M_o[i];
      p += estimate.translation();
      tip_R[i] = estimate.rotation();
      mean_log += pinocchio::log3(Matrix3(tip_R[0].transpose() * tip_R[i]));
    }
    p /= double(n);
    R = tip_R[0] * pinocchio::exp3(Vector3(mean_log / double(n)));
    lin.setZero();
    ang.setZero();
    for (std::size_t i = 0; i < n; ++i) {
      const pinocchio::Motion V = pinocchio::getFrameVelocity(model, data, grasps[i].tip, pinocchio::LOCAL_WORLD_ALIGNED);
      lin += V.linear() + V.angular().cross(p - data.oMf[grasps[i].tip].translation());
      ang += V.angular();
      tip_w[i] = V.angular();
    }
    lin /= double(n);
    ang /= double(n);
  }

  // ObjectImpedance.internal_moments (collocated): each tool's estimate of the object's
  // orientation held to their mean R̄, −Ki ⊙ R̄ log3(R̄ᵀ Rᵢ) − Di ⊙ (ωᵢ − ω̄), added to f's moments.
  void add_internal_moments(const Matrix3 & R_mean, const Vector3 & w_mean) {
    if (!collocated || (Ki.isZero(0.0) && Di.isZero(0.0))) return;
    for (std::size_t i = 0; i < grasps.size(); ++i) {
      const Vector3 e = R_mean * pinocchio::log3(Matrix3(R_mean.transpose() * tip_R[i]));
      f.block<1, 3>(static_cast<Eigen::Index>(i), 3) -= (Ki.cwiseProduct(e) + Di.cwiseProduct(tip_w[i] - w_mean)).transpose();
    }
  }

  // `model` is the kernel's link_model(): the links read the head of q and v (an elastic joint's
  // motor only gets the fast term, at the end).
  void torque(double t, const VectorXd & q_all, const VectorXd & v_all, VectorXd & tau) override {
    const auto q = q_all.head(model.nq);
    const auto v = v_all.head(model.nv);
    pinocchio::forwardKinematics(model, data, q, v);
    pinocchio::updateFramePlacements(model, data);
    // the object wrench (world axes, at the object frame origin)
    Vector3 p_d, v_d, a_d;
    double squeeze;
    task.at(t, p_d, v_d, a_d, squeeze);
    Vector3 p_o, lin, ang;
    Matrix3 R_o;
    object_state(p_o, R_o, lin, ang);
    const Vector3 e_p = p_d - p_o;
    const Matrix3 Rerr = task.R * R_o.transpose();
    const Vector3 e_r = pinocchio::log3(Rerr);
    Eigen::Matrix<double, 6, 1> F;
    F.head<3>() = mass * (a_d - gravity) + Kp.cwiseProduct(e_p) + Dp.cwiseProduct(v_d - lin);
    const Vector3 com_w = R_o * com;
    F.tail<3>() = Kr.cwiseProduct(e_r) + Dr.cwiseProduct(-ang) + com_w.cross(-mass * gravity);
    // distribution over the grasps, moments about their centroid
    const std::size_t n = grasps.size();
    auto & r = r_;  // per-call scratch kept as members: no allocation on the hot path
    r.resize(n, 3);
    Vector3 c = Vector3::Zero();
    for (std::size_t i = 0; i < n; ++i)  // the grasp points, or the tool frames' origins (collocated)
      r.row(i) = data.oMf[collocated ? grasps[i].tip : grasps[i].grasp].translation().transpose();
    c = r.colwise().sum().transpose() / double(n);
    r.rowwise() -= c.transpose();
    Eigen::Matrix<double, 6, 1> F_c = F;
    F_c.tail<3>() += (p_o - c).cross(F.head<3>());
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
    add_internal_moments(R_o, ang);
    // joint torques
    pinocchio::computeJointJacobians(model, data, q);
    const VectorXd & nle = pinocchio::nonLinearEffects(model, data, q, v);  // data.nle, untouched below
    q_links = q;  // (a vector: the type Pinocchio's compiled difference takes)
    pinocchio::difference(model, q_links, q0, posture);
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
      Eigen::Matrix<double, 6, 1> w = f.row(i).transpose();
      if (!collocated) {  // the wrench is about the grasp point: moved to the tip
        const Vector3 rr = data.oMf[gr.grasp].translation() - data.oMf[gr.tip].translation();
        w.tail<3>() += rr.cross(Vector3(f.block<1, 3>(i, 0).transpose()));
      }
      auto & ti = ti_;
      ti.noalias() = J.transpose() * w;
      for (Eigen::Index j = 0; j < m; ++j) ti[j] = (ti[j] + nle[gr.v_index[j]]) - joint_damping * vi[j];
      add_null_space_part(J, x, ti);
      tau.segment(offset, m) = ti;
      offset += m;
    }
    for (Eigen::Index i = 0; i < transmissions.size(); i += 4) {  // Spong's fast term: K_v (q̇ − θ̇)
      const auto entry = static_cast<Eigen::Index>(transmissions[i]);
      tau[entry] += transmissions[i + 3] * (v_all[static_cast<Eigen::Index>(transmissions[i + 1])] -
                                            v_all[static_cast<Eigen::Index>(transmissions[i + 2])]);
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
  Kernel::LentData lent;
  Data & data;
  pinocchio::FrameIndex object_frame;
  std::vector<Grasp> grasps;
  ObjectTask task;
  double mass;
  Vector3 com, gravity, Kp, Kr, Dp, Dr;
  double joint_damping, null_k, null_d;
  VectorXd q0;
  Eigen::Matrix<double, 6, Eigen::Dynamic> J6;
  VectorXd posture, q_links;
  Eigen::Matrix<double, Eigen::Dynamic, 6> f, inward_, internal_;
  Eigen::Matrix<double, Eigen::Dynamic, 3> r_;
  MatrixXd J_;
  VectorXd vi_, x_, ti_;
  Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt6_;
  Eigen::LLT<MatrixXd> llt_;
  bool collocated;
  Vector3 Ki, Di;
  std::vector<pinocchio::SE3> T_M_o;  // each tool frame's inverse offset from the object frame at the start
  std::vector<Matrix3> tip_R;  // (collocated) each tool's estimate of the object's rotation, at the last torque()
  std::vector<Vector3> tip_w;  // and each tool's angular velocity, world axes
  VectorXd transmissions;  // the elastic joints' fast damping: (entry in τ, link v, motor v, K_v) each
};

// {grasps: (grasp frame, tip frame, arm velocity indices) each, task: {hold, start, rotation, and
// for GripLiftOscillate its timings}, object_frame, mass, com, gravity, Kp, Kr, Dp, Dr,
// joint_damping, null_k, null_d, q0}
inline std::unique_ptr<Controller> make_object_impedance(Settings & c, Kernel & k) {
  const Model & model = k.link_model();  // (the grasps' frames and the arms' joints are its)
  const Eigen::Index nq = k.model().nq, nv = model.nv;
  std::vector<ObjectImpedanceLaw::Grasp> grasps;
  bp::list gl = c.get<bp::list>("grasps");
  for (bp::ssize_t i = 0; i < bp::len(gl); ++i) {
    bp::tuple g = bp::extract<bp::tuple>(gl[i]);
    ObjectImpedanceLaw::Grasp gr;
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
  ObjectTask task;
  Settings t = c.sub("task");
  task.hold = t.get<bool>("hold");
  task.start = t.vec("start", 3);
  task.R = t.mat3("rotation");
  if (!task.hold) {
    task.axis = t.vec("axis", 3);
    task.squeeze = t.get<double>("squeeze");
    task.t_grip = t.get<double>("t_grip");
    task.lift = t.get<double>("lift");
    task.t_lift = t.get<double>("t_lift");
    task.lift_duration = t.get<double>("lift_duration");
    task.amplitude = t.get<double>("amplitude");
    task.frequency = t.get<double>("frequency");
    task.t_osc = t.get<double>("t_osc");
    task.cycles = t.get<double>("cycles");
  }
  t.check_all_read();
  const pinocchio::FrameIndex object_frame = c.get<pinocchio::FrameIndex>("object_frame");
  const MatrixXd stacked = c.matrix("tip_offsets", 4 * static_cast<Eigen::Index>(grasps.size()), 4);
  std::vector<pinocchio::SE3> offsets;
  for (std::size_t i = 0; i < grasps.size(); ++i) {
    const Eigen::Matrix4d M = stacked.middleRows<4>(4 * static_cast<Eigen::Index>(i));
    offsets.emplace_back(Matrix3(M.topLeftCorner<3, 3>()), Vector3(M.topRightCorner<3, 1>()));
  }
  if (object_frame >= model.frames.size()) throw std::invalid_argument("compiled loop: object frame out of range");
  const VectorXd transmissions = c.get<VectorXd>("transmissions");
  const Eigen::Index na = k.actuated().size();
  const Eigen::Index nv_all = k.model().nv;  // (the motors come after the links' model's coordinates)
  for (Eigen::Index i = 0; i + 3 < transmissions.size(); i += 4)
    if (transmissions[i] < 0 || transmissions[i] >= na || transmissions[i + 1] < 0 || transmissions[i + 1] >= nv ||
        transmissions[i + 2] < nv || transmissions[i + 2] >= nv_all)
      throw std::invalid_argument("compiled loop: a transmission's index is out of range");
  if (transmissions.size() % 4) throw std::invalid_argument("compiled loop: transmissions are 4 values each");
  return std::make_unique<ObjectImpedanceLaw>(
    k.link_model(), k.lend_data(true), object_frame, std::move(grasps), std::move(task), c.get<double>("mass"), c.vec("com", 3),
    c.vec("gravity", 3), c.vec("Kp", 3), c.vec("Kr", 3), c.vec("Dp", 3), c.vec("Dr", 3),
    c.get<double>("joint_damping"), c.get<double>("null_k"), c.get<double>("null_d"), c.vec("q0", nq),
    c.get<bool>("collocated"), offsets, c.vec("Ki", 3), c.vec("Di", 3), transmissions);
}

inline const bool object_impedance_registered = register_controller("object_impedance", &make_object_impedance);

}  // namespace coopdyn_native
