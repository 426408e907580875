// MotorPD (coopdyn/control/joint.py) in C++: motor-side PD with constant or online gravity
// compensation for arms with elastic joints.
#pragma once

#include "controller.hpp"

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/rnea.hpp>

namespace coopdyn_native {

// τ = Kp (θ_d ⊖ θ) − Kd θ̇ + g_c on the drive coordinates (kernel.actuated(): an elastic joint's
// motor, a rigid joint itself); g_c = g(q_d), or with `online` g(θ̄) on the arm joints at θ̄ =
// θ − K⁻¹ g(q_d) in each elastic joint's link coordinates (rigid ones keep q).
struct MotorPD : Controller {
  MotorPD(Kernel & kernel, VectorXd kp, VectorXd kd, VectorXd target, VectorXd g_d, bool online,
          Eigen::VectorXi arm_joints, MatrixXd elastic)
    : kernel(kernel), model(kernel.model()), links(kernel.link_model()), act(kernel.actuated()), kp(std::move(kp)),
      kd(std::move(kd)), target(std::move(target)), g_d(std::move(g_d)), online(online),
      arm_joints(std::move(arm_joints)), elastic(std::move(elastic)), dq(model.nv), q_bar(links.nq), q_turned(links.nq),
      bias(VectorXd::Zero(links.nv)) {
    for (Eigen::Index i = 0; i < this->elastic.rows(); ++i)
      bias[static_cast<Eigen::Index>(this->elastic(i, 1))] = -this->elastic(i, 4);
    if (online) data = kernel.lend_data(true);
  }
  void torque(double, const VectorXd & q, const VectorXd & v, VectorXd & tau) override {
    pinocchio::difference(model, q, target, dq);
    for (Eigen::Index i = 0; i < act.size(); ++i) tau[i] = kp[i] * dq[act[i]] - kd[i] * v[act[i]];
    if (!online) {
      tau += g_d;
      return;
    }
    q_bar = q.head(links.nq);  // (the gravity term reads the links: their model, the head of q)
    for (Eigen::Index i = 0; i < elastic.rows(); ++i) {  // the link at its motor's angle
      const auto link_q = static_cast<Eigen::Index>(elastic(i, 0)), motor_q = static_cast<Eigen::Index>(elastic(i, 2));
      const Eigen::Index width = elastic(i, 3) != 0.0 ? 2 : 1;
      q_bar.segment(link_q, width) = q.segment(motor_q, width);
    }
    pinocchio::integrate(links, q_bar, bias, q_turned);  // θ̄ = θ − K⁻¹ g(q_d)
    const VectorXd & g = pinocchio::computeGeneralizedGravity(links, *data, q_turned);
    for (Eigen::Index i = 0; i < act.size(); ++i) tau[i] += g[arm_joints[i]];
  }
  Kernel & kernel;
  const Model & model, & links;  // the scene's (the PD on the motors), the links' (the gravity term)
  Kernel::LentData data;
  Eigen::VectorXi act;
  VectorXd kp, kd, target, g_d;
  bool online;
  Eigen::VectorXi arm_joints;
  MatrixXd elastic;  // rows (link q, link v, motor q, continuous, K⁻¹ g(q_d))
  VectorXd dq, q_bar, q_turned, bias;
};

// {kp, kd, g_d (n_actuated), target (nq), online, arm_joints (n_actuated), elastic (m, 5)}
inline std::unique_ptr<Controller> make_motor_pd(Settings & c, Kernel & k) {
  const Eigen::Index na = k.actuated().size(), nq = k.model().nq, nv = k.model().nv;
  const Eigen::VectorXi arm_joints = c.get<Eigen::VectorXi>("arm_joints");
  if (arm_joints.size() != na || (na && (arm_joints.minCoeff() < 0 || arm_joints.maxCoeff() >= k.link_model().nv)))
    throw std::invalid_argument("motor_pd: arm_joints must hold one v index per actuated joint");
  const MatrixXd elastic = c.get<MatrixXd>("elastic");
  if (elastic.size() && elastic.cols() != 5) throw std::invalid_argument("motor_pd: elastic must be (m, 5)");
  for (Eigen::Index i = 0; i < elastic.rows(); ++i) {
    const Eigen::Index width = elastic(i, 3) != 0.0 ? 2 : 1;
    if (elastic(i, 0) < 0 || elastic(i, 2) < 0 || elastic(i, 0) + width > k.link_model().nq || elastic(i, 2) + width > nq ||
        elastic(i, 1) < 0 || elastic(i, 1) >= k.link_model().nv)
      throw std::invalid_argument("motor_pd: an elastic joint's index is out of range");
  }
  return std::make_unique<MotorPD>(k, c.vec("kp", na), c.vec("kd", na), c.vec("target", nq), c.vec("g_d", na),
                                   c.get<bool>("online"), arm_joints, elastic);
}

inline const bool motor_pd_registered = register_controller("motor_pd", &make_motor_pd);

}  // namespace coopdyn_native
