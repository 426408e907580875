// The hardening SE(3) spring: the C++ twin of coopdyn/model/elements/hardening_spring.py.
// U = ½ eᵀ K e + ¼ κ |p|⁴ with e = log6(T_M_G), p = e[:3].
#pragma once

#include "element.hpp"

namespace coopdyn {

class HardeningSpring : public Element {
public:
  HardeningSpring(const Matrix6 & K, const Matrix6 & D, double hardening)
    : K_(K), D_(D), kappa_(hardening), damped_(!D.isZero(0.0)) {}

  // K and D (6x6) and the hardening κ [N/m³], by name.
  static std::unique_ptr<Element> make(Parameters & p) {
    return std::make_unique<HardeningSpring>(p.matrix("K", 6, 6), p.matrix("D", 6, 6), p.number("hardening"));
  }

  bool damped() const override { return damped_; }

  void evaluate(const pinocchio::SE3 & T_M_G, const Vector6 & xi, bool jacobians, ElementEval & out) const override {
    Vector6 e;
    out.theta = log6(T_M_G, e);
    jlog6(T_M_G, e, out.theta, J_);
    const Vector3 p = e.head<3>();
    const double p2 = p.dot(p);
    Vector6 w = K_ * e;
    w.head<3>() += kappa_ * p2 * p;
    out.power = 0.0;
    if (damped_) {
      const Vector6 e_dot = J_ * xi;
      const Vector6 De = D_ * e_dot;
      out.power = e_dot.dot(De);
      w += De;
    }
    out.energy = 0.5 * e.dot(K_ * e) + 0.25 * kappa_ * p2 * p2;
    out.deformation = e;
    out.f.noalias() = -J_.transpose() * w;
    if (jacobians) {
      Matrix6 H = K_;
      H.topLeftCorner<3, 3>() += kappa_ * (p2 * Matrix3::Identity() + 2.0 * p * p.transpose());
      out.SK.noalias() = J_.transpose() * (H * J_);
      if (damped_) out.SD.noalias() = J_.transpose() * (D_ * J_);
      else out.SD.setZero();
    }
  }

private:
  Matrix6 K_, D_;
  double kappa_;
  bool damped_;
  mutable Matrix6 J_;  // scratch
};

inline const bool hardening_registered = register_element("hardening", &HardeningSpring::make);

}  // namespace coopdyn
