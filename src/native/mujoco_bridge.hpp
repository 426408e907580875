// coopdyn's interconnection law and compiled controllers as MuJoCo callbacks (coopdyn/mujoco.py):
// C functions MuJoCo calls as mjcb_passive and mjcb_control through ctypes function pointers —
// no Python, no GIL per evaluation, as MuJoCo's experts run custom forces. The passive callback
// reads MuJoCo's state, converts it to Pinocchio's (q, v), evaluates the kernel's kinematics,
// the controller's torque (kept for mjcb_control, which MuJoCo calls after it in the same
// mj_forward) and the elements' generalized force Q = Σ Jrᵀ f (Kernel::passive_force), and adds
// Q to qfrc_passive; the control callback writes the torques to ctrl (one motor per actuated
// joint, gear 1).
//
// No MuJoCo header is needed to build the kernel: Python finds where mjData keeps time, qpos,
// qvel, ctrl and qfrc_passive in the installed MuJoCo (byte offsets, verified there with known
// values) and hands them over. MuJoCo's callbacks are process-global: one bridge is installed
// at a time; the callbacks serialise on a mutex (MuJoCo may call them from rollout threads).
#pragma once

#include "controllers/controller.hpp"
#include "kernel.hpp"

#include <Eigen/Geometry>

#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <string>

namespace coopdyn_native {

// Byte offsets in mjData of `mjtNum time` and of the pointers `mjtNum* qpos, qvel, ctrl,
// qfrc_passive`.
struct MjDataLayout {
  long time, qpos, qvel, ctrl, qfrc_passive;
};

class MujocoBridge {
public:
  // q_pin/q_mj, v_pin/v_mj: the 1-DOF joints' coordinates in Pinocchio and MuJoCo; free: the
  // free flyer's (pin idx_q, pin idx_v, mj qposadr, mj dofadr) or all −1; motor k is MuJoCo's
  // actuator motor_ctrl[k] and applies τ[motor_tau[k]].
  MujocoBridge(Kernel & kernel, std::unique_ptr<Controller> controller, MjDataLayout layout, Eigen::VectorXi q_pin,
               Eigen::VectorXi q_mj, Eigen::VectorXi v_pin, Eigen::VectorXi v_mj, Eigen::Vector4i free,
               Eigen::VectorXi motor_ctrl, Eigen::VectorXi motor_tau)
    : k_(kernel), ctrl_(std::move(controller)), layout_(layout), q_pin_(std::move(q_pin)), q_mj_(std::move(q_mj)),
      v_pin_(std::move(v_pin)), v_mj_(std::move(v_mj)), free_(free), motor_ctrl_(std::move(motor_ctrl)),
      motor_tau_(std::move(motor_tau)) {
    q_ = pinocchio::neutral(k_.model());
    v_.setZero(k_.model().nv);
    tau_.setZero(k_.actuated().size());
  }

  // mjcb_passive: Q added to qfrc_passive (and τ computed, for control()).
  void passive(void * d) {
    try {
      read_state(d);
      k_.kinematics(q_, v_, false);
      if (ctrl_) {
        ctrl_->torque(time(d), q_, v_, tau_);
        have_tau_ = true;
      }
      const VectorXd & Q = k_.passive_force();
      double * out = field(d, layout_.qfrc_passive);
      for (Eigen::Index i = 0; i < v_pin_.size(); ++i) out[v_mj_[i]] += Q[v_pin_[i]];
      if (free_[0] >= 0) {
        const int iv = free_[1], da = free_[3];
        const Eigen::Vector3d linear = R_ * Q.segment<3>(iv);  // Q·v = (R Q_lin)·ṗ + Q_ang·ω
        for (int k = 0; k < 3; ++k) {
          out[da + k] += linear[k];
          out[da + 3 + k] += Q[iv + 3 + k];
        }
      }
      ++evaluations_;
    } catch (const std::exception & e) {
      fail(d, e.what());
    }
  }

  // mjcb_control: τ to ctrl (computed by passive() at this state, or here when passive did not run).
  void control(void * d) {
    if (!ctrl_) return;
    try {
      if (!have_tau_) {
        read_state(d);
        if (ctrl_->reads_kernel()) k_.kinematics(q_, v_, false);
        ctrl_->torque(time(d), q_, v_, tau_);
      }
      have_tau_ = false;
      double * ctrl = field(d, layout_.ctrl);
      for (Eigen::Index k = 0; k < motor_tau_.size(); ++k) ctrl[motor_ctrl_[k]] = tau_[motor_tau_[k]];
    } catch (const std::exception & e) {
      fail(d, e.what());
    }
  }

  long evaluations() const { return evaluations_; }
  // The first error a callback met (empty: none); cleared by take_error().
  std::string take_error() {
    std::string out;
    out.swap(error_);
    return out;
  }

private:
  double time(void * d) const { return *reinterpret_cast<const double *>(static_cast<const char *>(d) + layout_.time); }
  static double * field(void * d, long offset) { return *reinterpret_cast<double **>(static_cast<char *>(d) + offset); }

  // (q, v) in Pinocchio's convention from mjData: MuJoCo's free joint has (p, w x y z) and
  // (ṗ in world axes, ω in body axes); Pinocchio's (p, x y z w) and (Rᵀṗ, ω).
  void read_state(void * d) {
    const double * qpos = field(d, layout_.qpos);
    const double * qvel = field(d, layout_.qvel);
    for (Eigen::Index i = 0; i < q_pin_.size(); ++i) q_[q_pin_[i]] = qpos[q_mj_[i]];
    for (Eigen::Index i = 0; i < v_pin_.size(); ++i) v_[v_pin_[i]] = qvel[v_mj_[i]];
    if (free_[0] >= 0) {
      const int iq = free_[0], iv = free_[1], qa = free_[2], da = free_[3];
      const double w = qpos[qa + 3], x = qpos[qa + 4], y = qpos[qa + 5], z = qpos[qa + 6];
      for (int k = 0; k < 3; ++k) q_[iq + k] = qpos[qa + k];
      q_[iq + 3] = x;
      q_[iq + 4] = y;
      q_[iq + 5] = z;
      q_[iq + 6] = w;
      R_ << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),  //
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),     //
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
      const Eigen::Vector3d pdot(qvel[da], qvel[da + 1], qvel[da + 2]);
      v_.segment<3>(iv) = R_.transpose() * pdot;
      for (int k = 0; k < 3; ++k) v_[iv + 3 + k] = qvel[da + 3 + k];
    }
  }

  // A callback cannot raise into MuJoCo: keep the message for Python, make the state NaN so
  // that MuJoCo's own check stops the step (its "bad qacc" warning), and coopdyn.mujoco raises.
  void fail(void * d, const char * what) {
    if (error_.empty()) error_ = what;
    double * out = field(d, layout_.qfrc_passive);
    for (Eigen::Index i = 0; i < v_mj_.size(); ++i) out[v_mj_[i]] = std::numeric_limits<double>::quiet_NaN();
    if (free_[0] >= 0)
      for (int k = 0; k < 6; ++k) out[free_[3] + k] = std::numeric_limits<double>::quiet_NaN();
    have_tau_ = false;
  }

  Kernel & k_;
  std::unique_ptr<Controller> ctrl_;
  MjDataLayout layout_;
  Eigen::VectorXi q_pin_, q_mj_, v_pin_, v_mj_;
  Eigen::Vector4i free_;
  Eigen::VectorXi motor_ctrl_, motor_tau_;
  VectorXd q_, v_, tau_;
  Eigen::Matrix3d R_ = Eigen::Matrix3d::Identity();
  bool have_tau_ = false;
  long evaluations_ = 0;
  std::string error_;
};

// The installed bridge (none: the callbacks do nothing) and the lock its callbacks take.
inline std::shared_ptr<MujocoBridge> & installed_bridge() {
  static std::shared_ptr<MujocoBridge> bridge;
  return bridge;
}
inline std::mutex & bridge_mutex() {
  static std::mutex mutex;
  return mutex;
}

}  // namespace coopdyn_native

// The callbacks, with MuJoCo's signature void (*)(const mjModel*, mjData*).
extern "C" inline void coopdyn_mjcb_passive(const void *, void * d) {
  const std::lock_guard<std::mutex> lock(coopdyn_native::bridge_mutex());
  if (const auto & bridge = coopdyn_native::installed_bridge()) bridge->passive(d);
}
extern "C" inline void coopdyn_mjcb_control(const void *, void * d) {
  const std::lock_guard<std::mutex> lock(coopdyn_native::bridge_mutex());
  if (const auto & bridge = coopdyn_native::installed_bridge()) bridge->control(d);
}
