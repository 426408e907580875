// GravityCompensationPD (coopdyn/control/joint.py) in C++.
#pragma once

#include "controller.hpp"

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>

namespace coopdyn_native {

// τ = g(q) + Kp (q_d ⊖ q) − Kd q̇ on the actuated joints (GravityCompensationPD), g(q) read off
// the kernel's kinematics pass when its joints allow (Kernel::actuated_gravity), else from
// Pinocchio's generalized gravity.
struct GravityPD : Controller {
  GravityPD(Kernel & kernel, VectorXd kp, VectorXd kd, VectorXd q_des)
    : kernel(kernel), model(kernel.model()), act(kernel.actuated()), kp(std::move(kp)), kd(std::move(kd)),
      q_des(std::move(q_des)), dq(model.nv), g_rnea(act.size()) {}
  bool reads_kernel() const override { return kernel.kinematic_gravity(); }
  void torque(double, const VectorXd & q, const VectorXd & v, VectorXd & tau) override {
    const VectorXd & g = kernel.kinematic_gravity() ? kernel.actuated_gravity(q) : rnea_gravity(q);
    pinocchio::difference(model, q, q_des, dq);
    for (Eigen::Index i = 0; i < act.size(); ++i) tau[i] = (g[i] + kp[i] * dq[act[i]]) - kd[i] * v[act[i]];
  }
  // g(q) on the actuated joints by Pinocchio's RNEA, for joints actuated_gravity does not take.
  const VectorXd & rnea_gravity(const VectorXd & q) {
    if (!data) data = kernel.lend_data();  // (only for joints actuated_gravity does not take)
    const VectorXd & full = pinocchio::computeGeneralizedGravity(model, *data, q);
    for (Eigen::Index i = 0; i < act.size(); ++i) g_rnea[i] = full[act[i]];
    return g_rnea;
  }
  Kernel & kernel;
  const Model & model;
  Kernel::LentData data;
  Eigen::VectorXi act;
  VectorXd kp, kd, q_des, dq, g_rnea;
};

// {kp, kd (n_actuated), q_des (nq)}
inline std::unique_ptr<Controller> make_gravity_pd(Settings & c, Kernel & k) {
  const Eigen::Index na = k.actuated().size();
  return std::make_unique<GravityPD>(k, c.vec("kp", na), c.vec("kd", na), c.vec("q_des", k.model().nq));
}

inline const bool gravity_pd_registered = register_controller("gravity_pd", &make_gravity_pd);

}  // namespace coopdyn_native
