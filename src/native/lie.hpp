// The SE(3) logarithm and its Jacobian, accurate at every rotation angle: the C++ twin of
// coopdyn/model/elements/lie.py (same formulas, same series switch; see its docstring).
#pragma once

#include <pinocchio/spatial.hpp>

#include <cmath>

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

}  // namespace coopdyn
