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

  // Exact, by complex step through jlog6_of_log (se3_spring.py: SE3Spring.tangent).
  bool tangent(const pinocchio::SE3 & T_M_G, const Vector6 & xi, Matrix6 & F_d, Matrix6 & F_x) const override {
    using Complex = std::complex<double>;
    using Vector6c = Eigen::Matrix<Complex, 6, 1>;
    constexpr double h = 1e-30;  // far below round-off: no truncation error
    Vector6 e;
    const double theta = log6(T_M_G, e);
    Matrix6 J;
    jlog6(T_M_G, e, theta, J);
    const Vector6c xi_c = xi.cast<Complex>();
    for (int k = 0; k < 6; ++k) {
      const Vector6c e_c = e.cast<Complex>() + Complex(0.0, h) * J.col(k).cast<Complex>();
      const Eigen::Matrix<Complex, 6, 6> J_c = jlog6_of_log(e_c);
      Vector6c w = gradient(e_c);
      if (damped_) w += D_.cast<Complex>() * (J_c * xi_c);
      F_d.col(k) = -(J_c.transpose() * w).imag() / h;
    }
    F_x.noalias() = -J.transpose() * (D_ * J);
    return true;
  }

  // Exact, by complex step of Jlog6ᵀ (hessian(e) Jlog6 w_K + D Jlog6 w_D) along e + i·h·Jlog6 δ
  // (se3_spring.py: SE3Spring.matrix_tangent); nothing depends on ξ.
  bool matrix_tangent(const pinocchio::SE3 & T_M_G, const Vector6 & xi, const Vector6 & w_K, const Vector6 & w_D,
                      Matrix6 & G_d, Matrix6 & G_x) const override {
    using Complex = std::complex<double>;
    using Vector6c = Eigen::Matrix<Complex, 6, 1>;
    constexpr double h = 1e-30;
    Vector6 e;
    const double theta = log6(T_M_G, e);
    Matrix6 J;
    jlog6(T_M_G, e, theta, J);
    const Vector6c wK = w_K.cast<Complex>(), wD = w_D.cast<Complex>();
    for (int k = 0; k < 6; ++k) {
      const Vector6c e_c = e.cast<Complex>() + Complex(0.0, h) * J.col(k).cast<Complex>();
      const Eigen::Matrix<Complex, 6, 6> J_c = jlog6_of_log(e_c);
      Vector6c w = hessian(e_c) * (J_c * wK);
      if (damped_) w += D_.cast<Complex>() * (J_c * wD);
      G_d.col(k) = (J_c.transpose() * w).imag() / h;
    }
    G_x.setZero();
    return true;
  }

protected:
  // ∂²U/∂e² at a complex e (analytic in e): SK = Jlog6ᵀ·hessian·Jlog6.
  virtual Eigen::Matrix<std::complex<double>, 6, 6> hessian(const Eigen::Matrix<std::complex<double>, 6, 1> &) const {
    return K_.cast<std::complex<double>>();
  }

  // ∂U/∂e at a complex e (analytic in e).
  virtual Eigen::Matrix<std::complex<double>, 6, 1> gradient(const Eigen::Matrix<std::complex<double>, 6, 1> & e) const {
    return K_.cast<std::complex<double>>() * e;
  }

  Matrix6 K_, D_;
  bool damped_;
  mutable Matrix6 J_;  // scratch: Jlog6 at the last evaluation (hardening_spring.hpp reads it)
};

inline const bool se3_registered = register_element("se3", &SE3Spring::make);

}  // namespace coopdyn
