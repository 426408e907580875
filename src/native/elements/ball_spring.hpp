// The translational (ball) spring–damper: the C++ twin of coopdyn/model/elements/ball_spring.py.
#pragma once

#include "element.hpp"

namespace coopdyn {

class BallSpring : public Element {
public:
  BallSpring(const Matrix3 & K, const Matrix3 & D) : K_(K), D_(D), damped_(!D.isZero(0.0)) {}

  // K and D (3x3), by name.
  static std::unique_ptr<Element> make(Parameters & p) {
    return std::make_unique<BallSpring>(p.matrix("K", 3, 3), p.matrix("D", 3, 3));
  }

  bool damped() const override { return damped_; }

  void evaluate(const pinocchio::SE3 & T_M_G, const Vector6 & xi, bool jacobians, ElementEval & out) const override {
    const Matrix3 & R = T_M_G.rotation();
    const Vector3 & p = T_M_G.translation();
    Vector3 f = K_ * p;
    out.power = 0.0;
    if (damped_) {
      const Vector3 p_dot = R * xi.head<3>();
      const Vector3 Dp = D_ * p_dot;
      out.power = p_dot.dot(Dp);
      f += Dp;
    }
    out.energy = 0.5 * p.dot(K_ * p);
    out.deformation.setZero();
    out.deformation.head<3>() = p;
    out.f.setZero();
    out.f.head<3>().noalias() = -R.transpose() * f;
    if (jacobians) {
      out.SK.setZero();
      out.SD.setZero();
      out.SK.topLeftCorner<3, 3>().noalias() = R.transpose() * (K_ * R);
      out.SD.topLeftCorner<3, 3>().noalias() = R.transpose() * (D_ * R);
    }
    out.theta = pinocchio::log3(R).norm();
  }

  // Exact, closed form (ball_spring.py: BallSpring.tangent).
  bool tangent(const pinocchio::SE3 & T_M_G, const Vector6 & xi, Matrix6 & F_d, Matrix6 & F_x) const override {
    const Matrix3 & R = T_M_G.rotation();
    Vector3 f = K_ * T_M_G.translation();
    if (damped_) f += D_ * (R * xi.head<3>());
    const Vector3 f_G = -R.transpose() * f;
    const Matrix3 RDR = R.transpose() * D_ * R;
    F_d.setZero();
    F_x.setZero();
    F_d.topLeftCorner<3, 3>().noalias() = -R.transpose() * K_ * R;
    F_d.topRightCorner<3, 3>() = skew(f_G) + RDR * skew(Vector3(xi.head<3>()));
    F_x.topLeftCorner<3, 3>() = -RDR;
    return true;
  }

  // Exact, closed form (ball_spring.py: BallSpring.matrix_tangent): R → R·exp(δ_ω^) turns P w
  // (P = Rᵀ K R) by [P w]^ δ_ω − P [w]^ δ_ω.
  bool matrix_tangent(const pinocchio::SE3 & T_M_G, const Vector6 &, const Vector6 & w_K, const Vector6 & w_D,
                      Matrix6 & G_d, Matrix6 & G_x) const override {
    const Matrix3 & R = T_M_G.rotation();
    G_d.setZero();
    G_x.setZero();
    const Matrix3 PK = R.transpose() * K_ * R, PD = R.transpose() * D_ * R;
    const Vector3 wK = w_K.head<3>(), wD = w_D.head<3>();
    G_d.topRightCorner<3, 3>() = skew(Vector3(PK * wK)) - PK * skew(wK) + skew(Vector3(PD * wD)) - PD * skew(wD);
    return true;
  }

private:
  Matrix3 K_, D_;
  bool damped_;
};

inline const bool ball_registered = register_element("ball", &BallSpring::make);

}  // namespace coopdyn
