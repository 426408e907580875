// ComputedTorque holding q0 (coopdyn/control/joint.py) in C++.
#pragma once

#include "controller.hpp"

#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/rnea.hpp>

namespace coopdyn_native {

// τ = M(q)(Kp (q_d − q) − Kd q̇) + h(q, q̇), holding q_d (ComputedTorque with its default reference).
struct ComputedTorqueHold : Controller {
  ComputedTorqueHold(const Model & model, Kernel::LentData lent, const Eigen::VectorXi & act, const Eigen::VectorXi & q_index, VectorXd kp,
                     VectorXd kd, VectorXd q_d)
    : model(model), lent(std::move(lent)), data(*this->lent), act(act), q_index(q_index), kp(std::move(kp)), kd(std::move(kd)), q_d(std::move(q_d)),
      e(act.size()), M(act.size(), act.size()) {}
  void torque(double, const VectorXd & q, const VectorXd & v, VectorXd & tau) override {
    pinocchio::crba(model, data, RefVec(q));  // (a Ref: the type Pinocchio's compiled crba takes)
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
  Kernel::LentData lent;
  Data & data;
  Eigen::VectorXi act, q_index;
  VectorXd kp, kd, q_d, e;
  MatrixXd M;
};

// {q_index (one configuration index per actuated joint), kp, kd, q_d (n_actuated)}
inline std::unique_ptr<Controller> make_computed_torque(Settings & c, Kernel & k) {
  const Model & model = k.model();
  const Eigen::Index na = k.actuated().size();
  const Eigen::VectorXi q_index = c.get<Eigen::VectorXi>("q_index");
  if (q_index.size() != na || (na && (q_index.minCoeff() < 0 || q_index.maxCoeff() >= model.nq)))
    throw std::invalid_argument("compiled loop: q_index must hold one configuration index per actuated joint");
  return std::make_unique<ComputedTorqueHold>(model, k.lend_data(), k.actuated(), q_index, c.vec("kp", na), c.vec("kd", na),
                                              c.vec("q_d", na));
}

inline const bool computed_torque_registered = register_controller("computed_torque", &make_computed_torque);

}  // namespace coopdyn_native
