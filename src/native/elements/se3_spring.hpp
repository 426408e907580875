// The SE(3) spring–damper: the C++ twin of coopdyn/model/elements/se3_spring.py.
#pragma once

#include "element.hpp"

namespace coopdyn {

class SE3Spring : public Element {
public:
  SE3Spring(const Matrix6 & K, const Matrix6 & D) : K_(K), D_(D), damped_(!D.isZero(0.0)) {}

  // K and D (6x6), by name.
  static std::unique_ptr<Element> make(Parameters & p) {
    return std::make_unique<SE3Spring>(p.matrix("K", 6, 6), p.matrix("D", 6, 6));
  }

  bool damped() const override { return damped_; }

  void evaluate(const pinocchio::SE3 & T_M_G, const Vector6 & xi, bool jacobians, ElementEval & out) const override {
    Vector6 e;
    out.theta = log6(T_M_G, e);
    jlog6(T_M_G, e, out.theta, J_);
    Vector6 w = K_ * e;
    out.power = 0.0;
    if (damped_) {
      const Vector6 e_dot = J_ * xi;
      const Vector6 De = D_ * e_dot;
      out.power = e_dot.dot(De);
      w += De;
    }
    out.energy = 0.5 * e.dot(K_ * e);
    out.deformation = e;
    out.f.noalias() = -J_.transpose() * w;
    if (jacobians) {
      out.SK.noalias() = J_.transpose() * (K_ * J_);
      if (damped_) out.SD.noalias() = J_.transpose() * (D_ * J_);
      else out.SD.setZero();
    }
  }

protected:
  Matrix6 K_, D_;
  bool damped_;
  mutable Matrix6 J_;  // scratch: Jlog6 at the last evaluation (hardening_spring.hpp reads it)
};

inline const bool se3_registered = register_element("se3", &SE3Spring::make);

}  // namespace coopdyn
