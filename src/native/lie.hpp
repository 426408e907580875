// The SE(3) logarithm and its Jacobian, accurate at every rotation angle: the C++ twin of
// coopdyn/model/elements/lie.py (same formulas, same series switch; see its docstring).
#pragma once

#include <pinocchio/spatial.hpp>

#include <cmath>
#include <complex>

namespace coopdyn {

using Matrix3 = Eigen::Matrix3d;
using Vector3 = Eigen::Vector3d;
using Matrix6 = Eigen::Matrix<double, 6, 6>;
using Vector6 = Eigen::Matrix<double, 6, 1>;

constexpr double SERIES_BELOW = 0.25;  // [rad]

// (a, β, β'/θ) of lie.py: a = (θ/2)cot(θ/2), β = (1 − a)/θ², β'/θ.
inline void log_coefficients(double t, double & a, double & beta, double & beta_dot) {
  const double t2 = t * t;
  if (t < SERIES_BELOW) {
    // (θ/2)cot(θ/2) = Σ (−1)ⁿ B₂ₙ θ²ⁿ/(2n)!, and β, β'/θ term by term
    static const double A[7] = {1.0, -1.0 / 12.0, -1.0 / 720.0, -1.0 / 30240.0, -1.0 / 1209600.0,
                                -1.0 / 47900160.0, -691.0 / 1307674368000.0};
    a = 0.0; beta = 0.0; beta_dot = 0.0;
    for (int k = 6; k >= 0; --k) a = a * t2 + A[k];
    for (int k = 6; k >= 1; --k) beta = beta * t2 - A[k];
    for (int k = 6; k >= 2; --k) beta_dot = beta_dot * t2 - 2.0 * (k - 1) * A[k];
    return;
  }
  const double st = std::sin(t), ct = std::cos(t);
  a = 0.5 * t * st / (1.0 - ct);
  const double inv_2_2ct = 1.0 / (2.0 * (1.0 - ct));
  beta = 1.0 / t2 - st / t * inv_2_2ct;
  beta_dot = -2.0 / (t2 * t2) + (1.0 + st / t) / t2 * inv_2_2ct;
}

inline Matrix3 skew(const Vector3 & x) {
  Matrix3 S;
  S << 0.0, -x[2], x[1], x[2], 0.0, -x[0], -x[1], x[0], 0.0;
  return S;
}

// e = log6(M) = [V⁻¹p; w]; returns the rotation angle θ.
inline double log6(const pinocchio::SE3 & M, Vector6 & e) {
  double theta;
  const Vector3 w = pinocchio::log3(M.rotation(), theta);
  theta = w.norm();  // as lie.py: the norm of log3
  double a, beta, beta_dot;
  log_coefficients(theta, a, beta, beta_dot);
  const Vector3 & p = M.translation();
  e.head<3>() = a * p - 0.5 * w.cross(p) + (beta * w.dot(p)) * w;
  e.tail<3>() = w;
  return theta;
}

// Jlog6(M) given (e, θ) = log6(M).
inline void jlog6(const pinocchio::SE3 & M, const Vector6 & e, double theta, Matrix6 & J) {
  const Vector3 w = e.tail<3>();
  const Vector3 & p = M.translation();
  double a, beta, beta_dot;
  log_coefficients(theta, a, beta, beta_dot);
  Matrix3 A = beta * w * w.transpose() + 0.5 * skew(w);
  A.diagonal().array() += a;
  const double wTp = w.dot(p);
  const Vector3 v = (beta_dot * wTp) * w - (theta * theta * beta_dot + 2.0 * beta) * p;
  Matrix3 C = v * w.transpose() + beta * w * p.transpose() + 0.5 * skew(p);
  C.diagonal().array() += wTp * beta;
  J.setZero();
  J.topLeftCorner<3, 3>() = A;
  J.bottomRightCorner<3, 3>() = A;
  J.topRightCorner<3, 3>() = C * A;
}

// Jlog6 as a function of e = log6(M) alone (lie.py: jlog6_of_log), for a real or a complex e:
// every operation is analytic in e (θ² is wᵀw, not |w|², and no dot product conjugates), so a
// complex e gives the complex-step derivative of Jlog6 — the elements' exact tangents.
template <typename S>
Eigen::Matrix<S, 6, 6> jlog6_of_log(const Eigen::Matrix<S, 6, 1> & e) {
  using V3 = Eigen::Matrix<S, 3, 1>;
  using M3 = Eigen::Matrix<S, 3, 3>;
  const V3 rho = e.template head<3>(), w = e.template tail<3>();
  const S t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
  S a, beta, beta_dot, b, c;
  if (std::abs(std::real(t2)) < SERIES_BELOW * SERIES_BELOW) {
    static const double A[7] = {1.0, -1.0 / 12.0, -1.0 / 720.0, -1.0 / 30240.0, -1.0 / 1209600.0,
                                -1.0 / 47900160.0, -691.0 / 1307674368000.0};
    a = beta = beta_dot = b = c = S(0.0);
    for (int k = 6; k >= 0; --k) a = a * t2 + A[k];
    for (int k = 6; k >= 1; --k) beta = beta * t2 - A[k];
    for (int k = 6; k >= 2; --k) beta_dot = beta_dot * t2 - 2.0 * (k - 1) * A[k];
    double fact_b = 1.0, fact_c = 1.0;  // (2k+2)! and (2k+3)!, k = 0
    double B[9], C[9];
    for (int k = 0; k < 9; ++k) {
      fact_b = k == 0 ? 2.0 : fact_b * (2 * k + 1) * (2 * k + 2);
      fact_c = k == 0 ? 6.0 : fact_c * (2 * k + 2) * (2 * k + 3);
      B[k] = (k % 2 ? -1.0 : 1.0) / fact_b;
      C[k] = (k % 2 ? -1.0 : 1.0) / fact_c;
    }
    for (int k = 8; k >= 0; --k) {
      b = b * t2 + B[k];
      c = c * t2 + C[k];
    }
  } else {
    const S th = std::sqrt(t2), st = std::sin(th), ct = std::cos(th);
    a = S(0.5) * th * st / (S(1.0) - ct);
    const S inv_2_2ct = S(1.0) / (S(2.0) * (S(1.0) - ct));
    beta = S(1.0) / t2 - st / th * inv_2_2ct;
    beta_dot = S(-2.0) / (t2 * t2) + (S(1.0) + st / th) / t2 * inv_2_2ct;
    b = (S(1.0) - ct) / t2;
    c = (th - st) / (t2 * th);
  }
  auto hat = [](const V3 & x) {
    M3 out;
    out << S(0.0), -x[2], x[1], x[2], S(0.0), -x[0], -x[1], x[0], S(0.0);
    return out;
  };
  const M3 W = hat(w);
  const V3 p = rho + b * (W * rho) + c * (W * (W * rho));  // the translation of M
  M3 A = beta * (w * w.transpose()) + S(0.5) * W;
  A.diagonal().array() += a;
  const S wTp = (w.transpose() * p)(0);
  const V3 v = (beta_dot * wTp) * w - (t2 * beta_dot + S(2.0) * beta) * p;
  M3 C = v * w.transpose() + beta * (w * p.transpose()) + S(0.5) * hat(p);
  C.diagonal().array() += wTp * beta;
  Eigen::Matrix<S, 6, 6> J = Eigen::Matrix<S, 6, 6>::Zero();
  J.template topLeftCorner<3, 3>() = A;
  J.template bottomRightCorner<3, 3>() = A;
  J.template topRightCorner<3, 3>() = C * A;
  return J;
}

}  // namespace coopdyn
