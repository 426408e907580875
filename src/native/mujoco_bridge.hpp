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
// at a time; the callbacks serialise on a mutex (MuJoCo may call them from rollout threads), and
// the torque passive() computes is reused by control() only for the same mjData at the same
// time and state (else control() computes it afresh). The bridge keeps the Python kernel object
// alive while it is installed.
#pragma once

#include "controllers/controller.hpp"
#include "kernel.hpp"

#include <Eigen/Geometry>

#include <cstdint>
#include <cstdio>
#include <limits>
#include <memory>
#include <mutex>
#include <string>

namespace coopdyn_native {

// Byte offsets in mjData of `mjtNum time` and of the pointers `mjtNum* qpos, qvel, ctrl,
// qfrc_passive`.
// The lock every callback and take_error() take.
inline std::mutex & bridge_mutex() {
  static std::mutex mutex;
  return mutex;
}

struct MjDataLayout {
  long time, qpos, qvel, ctrl, qfrc_passive;
};

class MujocoBridge {
public:
  // q_pin/q_mj, v_pin/v_mj: the 1-DOF joints' coordinates in Pinocchio and MuJoCo; free: the
  // free flyer's (pin idx_q, pin idx_v, mj qposadr, mj dofadr) or all −1; motor k is MuJoCo's
  // actuator motor_ctrl[k] and applies τ[motor_tau[k]].
  MujocoBridge(bp::object kernel_owner, Kernel & kernel, std::unique_ptr<Controller> controller, MjDataLayout layout,
               Eigen::VectorXi q_pin,
               Eigen::VectorXi q_mj, Eigen::VectorXi v_pin, Eigen::VectorXi v_mj, Eigen::Vector4i free,
               Eigen::VectorXi motor_ctrl, Eigen::VectorXi motor_tau)
    : owner_(std::move(kernel_owner)), k_(kernel), ctrl_(std::move(controller)), layout_(layout), q_pin_(std::move(q_pin)), q_mj_(std::move(q_mj)),
      v_pin_(std::move(v_pin)), v_mj_(std::move(v_mj)), free_(free), motor_ctrl_(std::move(motor_ctrl)),
      motor_tau_(std::move(motor_tau)) {
    q_ = pinocchio::neutral(k_.model());
    v_.setZero(k_.model().nv);
    q_now_ = q_;
    v_now_ = v_;
    tau_.setZero(k_.actuated().size());
  }

  // mjcb_passive: Q [N, N·m] added to qfrc_passive (and τ computed, for control()).
  void passive(void * d) noexcept {
    try {
      read_state(d, q_, v_);
      k_.kinematics(q_, v_, false);
      if (ctrl_) {
        ctrl_->torque(time(d), q_, v_, tau_);
        tau_for_ = d;
        tau_time_ = time(d);
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
    } catch (...) {
      fail(d, "unknown C++ exception");
    }
  }

  // mjcb_control: τ [N·m or N] to ctrl: passive()'s, when it was computed for this mjData at its
  // time and state; else computed here (mj_forwardSkip past the velocity stage, another mjData).
  void control(void * d) noexcept {
    if (!ctrl_) return;
    try {
      read_state(d, q_now_, v_now_);
      const bool same = tau_for_ == d && tau_time_ == time(d) && q_now_ == q_ && v_now_ == v_;
      if (!same) {
        q_.swap(q_now_);
        v_.swap(v_now_);
        if (ctrl_->reads_kernel()) k_.kinematics(q_, v_, false);
        ctrl_->torque(time(d), q_, v_, tau_);
        tau_for_ = d;
        tau_time_ = time(d);
      }
      double * ctrl = field(d, layout_.ctrl);
      for (Eigen::Index k = 0; k < motor_tau_.size(); ++k) ctrl[motor_ctrl_[k]] = tau_[motor_tau_[k]];
    } catch (const std::exception & e) {
      fail(d, e.what());
    } catch (...) {
      fail(d, "unknown C++ exception");
    }
  }

  long evaluations() const { return evaluations_; }
  // The first error a callback met (empty: none); cleared by take_error().
  std::string take_error() {
    const std::lock_guard<std::mutex> lock(bridge_mutex());
    std::string out = failed_ ? std::string(error_) : std::string();
    failed_ = false;
    return out;
  }

private:
  double time(void * d) const { return *reinterpret_cast<const double *>(static_cast<const char *>(d) + layout_.time); }
  static double * field(void * d, long offset) { return *reinterpret_cast<double **>(static_cast<char *>(d) + offset); }

  // (q, v) in Pinocchio's convention from mjData: MuJoCo's free joint has (p, w x y z) and
  // (ṗ in world axes, ω in body axes); Pinocchio's (p, x y z w) and (Rᵀṗ, ω).
  void read_state(void * d, VectorXd & q, VectorXd & v) {
    const double * qpos = field(d, layout_.qpos);
    const double * qvel = field(d, layout_.qvel);
    for (Eigen::Index i = 0; i < q_pin_.size(); ++i) q[q_pin_[i]] = qpos[q_mj_[i]];
    for (Eigen::Index i = 0; i < v_pin_.size(); ++i) v[v_pin_[i]] = qvel[v_mj_[i]];
    if (free_[0] >= 0) {
      const int iq = free_[0], iv = free_[1], qa = free_[2], da = free_[3];
      const double w = qpos[qa + 3], x = qpos[qa + 4], y = qpos[qa + 5], z = qpos[qa + 6];
      for (int k = 0; k < 3; ++k) q[iq + k] = qpos[qa + k];
      q[iq + 3] = x;
      q[iq + 4] = y;
      q[iq + 5] = z;
      q[iq + 6] = w;
      R_ << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),  //
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),     //
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
      const Eigen::Vector3d pdot(qvel[da], qvel[da + 1], qvel[da + 2]);
      v.segment<3>(iv) = R_.transpose() * pdot;
      for (int k = 0; k < 3; ++k) v[iv + 3 + k] = qvel[da + 3 + k];
    }
  }

  // A callback cannot raise into MuJoCo: keep the message for Python, make the state NaN so
  // that MuJoCo's own check stops the step (its "bad qacc" warning), and coopdyn.mujoco raises.
  void fail(void * d, const char * what) noexcept {
    if (!failed_) {
      failed_ = true;
      std::snprintf(error_, sizeof(error_), "%s", what);  // (no allocation here)
    }
    tau_for_ = nullptr;
    double * out = field(d, layout_.qfrc_passive);
    for (Eigen::Index i = 0; i < v_mj_.size(); ++i) out[v_mj_[i]] = std::numeric_limits<double>::quiet_NaN();
    if (free_[0] >= 0)
      for (int k = 0; k < 6; ++k) out[free_[3] + k] = std::numeric_limits<double>::quiet_NaN();
  }

  bp::object owner_;  // the Python Kernel (k_ lives in it)
  Kernel & k_;
  std::unique_ptr<Controller> ctrl_;
  MjDataLayout layout_;
  Eigen::VectorXi q_pin_, q_mj_, v_pin_, v_mj_;
  Eigen::Vector4i free_;
  Eigen::VectorXi motor_ctrl_, motor_tau_;
  VectorXd q_, v_, tau_, q_now_, v_now_;
  Eigen::Matrix3d R_ = Eigen::Matrix3d::Identity();
  const void * tau_for_ = nullptr;  // the mjData and time τ was computed for (at q_, v_)
  double tau_time_ = 0.0;
  long evaluations_ = 0;
  bool failed_ = false;
  char error_[512] = {};
};



// The installed bridge (none: the callbacks do nothing).
inline std::shared_ptr<MujocoBridge> & installed_bridge() {
  static std::shared_ptr<MujocoBridge> bridge;
  return bridge;
}
}  // namespace coopdyn_native

// The callbacks, with MuJoCo's signature void (*)(const mjModel*, mjData*).
extern "C" inline void coopdyn_mjcb_passive(const void *, void * d) noexcept {
  const std::lock_guard<std::mutex> lock(coopdyn_native::bridge_mutex());
  if (const auto & bridge = coopdyn_native::installed_bridge()) bridge->passive(d);
}
extern "C" inline void coopdyn_mjcb_control(const void *, void * d) noexcept {
  const std::lock_guard<std::mutex> lock(coopdyn_native::bridge_mutex());
  if (const auto & bridge = coopdyn_native::installed_bridge()) bridge->control(d);
}
