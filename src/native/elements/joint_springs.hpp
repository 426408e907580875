// The elastic joints' transmissions (coopdyn/model/elements/joint_spring.py), the same equations:
// τ_s = K δ + D δ̇ on the link (+) and the motor (−), δ = θ ⊖ q, energy ½ K δ², power D δ̇².
#pragma once

#include <Eigen/Dense>

#include <cmath>
#include <stdexcept>
#include <vector>

namespace coopdyn {

struct JointSprings {
  struct Spring {
    Eigen::Index link_q, link_v, motor_q, motor_v;
    double K, D;
    bool continuous;  // q is a (cos, sin) pair
  };

  JointSprings() = default;
  // 7 values per spring, one after the other: (link q, link v, motor q, motor v, K, D, continuous)
  // (JointSprings.native_table).
  JointSprings(const Eigen::Ref<const Eigen::VectorXd> & table, Eigen::Index nq, Eigen::Index nv) {
    if (table.size() % 7) throw std::invalid_argument("joint springs: 7 values per spring");
    for (Eigen::Index i = 0; i < table.size(); i += 7) {
      const Spring s{static_cast<Eigen::Index>(table[i]), static_cast<Eigen::Index>(table[i + 1]),
                     static_cast<Eigen::Index>(table[i + 2]), static_cast<Eigen::Index>(table[i + 3]),
                     table[i + 4], table[i + 5], table[i + 6] != 0.0};
      const Eigen::Index width = s.continuous ? 2 : 1;
      if (s.link_q < 0 || s.motor_q < 0 || s.link_q + width > nq || s.motor_q + width > nq || s.link_v < 0 ||
          s.motor_v < 0 || s.link_v >= nv || s.motor_v >= nv)
        throw std::invalid_argument("joint springs: an index out of range");
      if (!(s.K > 0.0) || !(s.D >= 0.0) || !std::isfinite(s.K) || !std::isfinite(s.D))
        throw std::invalid_argument("joint springs: K > 0 and D >= 0, finite");
      springs.push_back(s);
    }
  }

  bool empty() const { return springs.empty(); }

  template <class Config>
  static double deflection(const Spring & s, const Config & q) {
    if (!s.continuous) return q[s.motor_q] - q[s.link_q];
    const double cm = q[s.motor_q], sm = q[s.motor_q + 1], cl = q[s.link_q], sl = q[s.link_q + 1];
    return std::atan2(sm * cl - cm * sl, cm * cl + sm * sl);
  }

  // Q += the springs' generalized force at (q, v); returns the power their damping dissipates [W].
  template <class Config, class Velocity>
  double add_force(const Config & q, const Velocity & v, Eigen::VectorXd & Q) const {
    double power = 0.0;
    for (const Spring & s : springs) {
      const double rate = v[s.motor_v] - v[s.link_v];
      const double tau = s.K * deflection(s, q) + s.D * rate;
      Q[s.link_v] += tau;
      Q[s.motor_v] -= tau;
      power += s.D * rate * rate;
    }
    return power;
  }

  // K += K Lᵀ L, D += D Lᵀ L (−∂Q/∂q, −∂Q/∂v; L = e_θ − e_q).
  void add_matrices(Eigen::MatrixXd & K, Eigen::MatrixXd & D) const {
    for (const Spring & s : springs) {
      K(s.link_v, s.link_v) += s.K;
      K(s.motor_v, s.motor_v) += s.K;
      K(s.link_v, s.motor_v) -= s.K;
      K(s.motor_v, s.link_v) -= s.K;
      D(s.link_v, s.link_v) += s.D;
      D(s.motor_v, s.motor_v) += s.D;
      D(s.link_v, s.motor_v) -= s.D;
      D(s.motor_v, s.link_v) -= s.D;
    }
  }

  // ½ Σ K δ² [J].
  template <class Config>
  double energy(const Config & q) const {
    double u = 0.0;
    for (const Spring & s : springs) {
      const double d = deflection(s, q);
      u += 0.5 * s.K * d * d;
    }
    return u;
  }

  std::vector<Spring> springs;
};

}  // namespace coopdyn
