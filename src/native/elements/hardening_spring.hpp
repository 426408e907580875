// The hardening SE(3) spring: the C++ twin of coopdyn/model/elements/hardening_spring.py.
// U = ½ eᵀ K e + ¼ κ |p|⁴ with e = log6(T_M_G), p = e[:3]: the SE(3) spring's evaluation plus the
// κ term's energy, wrench and Gauss–Newton stiffness.
#pragma once

#include "element.hpp"
#include "se3_spring.hpp"

namespace coopdyn {

class HardeningSpring : public SE3Spring {
public:
  HardeningSpring(const Matrix6 & K, const Matrix6 & D, double hardening) : SE3Spring(K, D), kappa_(hardening) {}

  // K and D (6x6) and the hardening κ [N/m³], by name.
  static std::unique_ptr<Element> make(Parameters & p) {
    return std::make_unique<HardeningSpring>(p.matrix("K", 6, 6), p.matrix("D", 6, 6), p.number("hardening"));
  }

  void evaluate(const pinocchio::SE3 & T_M_G, const Vector6 & xi, bool jacobians, ElementEval & out) const override {
    SE3Spring::evaluate(T_M_G, xi, jacobians, out);  // leaves Jlog6 in J_
    if (kappa_ == 0.0) return;
    const Vector3 p = out.deformation.head<3>();
    const double p2 = p.dot(p);
    const auto Jp = J_.topRows<3>();  // dp/dξ
    out.energy += 0.25 * kappa_ * p2 * p2;
    out.f.noalias() -= Jp.transpose() * (kappa_ * p2 * p);
    if (jacobians) out.SK.noalias() += Jp.transpose() * (kappa_ * (p2 * Matrix3::Identity() + 2.0 * p * p.transpose())) * Jp;
  }

protected:
  // K e + κ |p|² [p; 0] at a complex e (|p|² = pᵀp, no conjugate).
  Eigen::Matrix<std::complex<double>, 6, 1> gradient(const Eigen::Matrix<std::complex<double>, 6, 1> & e) const override {
    Eigen::Matrix<std::complex<double>, 6, 1> g = SE3Spring::gradient(e);
    const std::complex<double> p2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
    g.head<3>() += (kappa_ * p2) * e.head<3>();
    return g;
  }

  // K + κ (|p|² I₃ + 2 p pᵀ) ⊕ 0₃ at a complex e (hardening_spring.py: HardeningSpring.hessian).
  Eigen::Matrix<std::complex<double>, 6, 6> hessian(const Eigen::Matrix<std::complex<double>, 6, 1> & e) const override {
    Eigen::Matrix<std::complex<double>, 6, 6> H = SE3Spring::hessian(e);
    const Eigen::Matrix<std::complex<double>, 3, 1> p = e.head<3>();
    const std::complex<double> p2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
    H.topLeftCorner<3, 3>() += kappa_ * (p2 * Eigen::Matrix<std::complex<double>, 3, 3>::Identity() + 2.0 * p * p.transpose());
    return H;
  }

private:
  double kappa_;
};

inline const bool hardening_registered = register_element("hardening", &HardeningSpring::make);

}  // namespace coopdyn
