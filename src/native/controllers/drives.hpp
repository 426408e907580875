// Open-loop drives (coopdyn/problems/linear_book.py: drives_controller) in C++.
#pragma once

#include "controller.hpp"

#include <cmath>
#include <vector>

namespace coopdyn_native {

// Open-loop drives: τ_i = c + r s + A sin(ω s + φ), s = t − start of the segment in force.
struct Drives : Controller {
  // segments[i]: rows (start, constant, ramp, amplitude, omega, phase), increasing start, first at 0.
  explicit Drives(std::vector<MatrixXd> segments) : segments(std::move(segments)) {}
  void torque(double t, const VectorXd &, const VectorXd &, VectorXd & tau) override {
    for (std::size_t i = 0; i < segments.size(); ++i) {
      const MatrixXd & S = segments[i];
      Eigen::Index k = 0;  // bisect_right(starts, t) − 1, at least 0
      while (k + 1 < S.rows() && S(k + 1, 0) <= t) ++k;
      const double s = t - S(k, 0);
      tau[i] = S(k, 1) + S(k, 2) * s + S(k, 3) * std::sin(S(k, 4) * s + S(k, 5));
    }
  }
  std::vector<MatrixXd> segments;
};

// {segments: one (rows, 6) matrix per actuated joint}
inline std::unique_ptr<Controller> make_drives(Settings & c, Kernel & k) {
  std::vector<MatrixXd> segments;
  bp::list drives = c.get<bp::list>("segments");
  for (bp::ssize_t i = 0; i < bp::len(drives); ++i) {
    segments.push_back(bp::extract<MatrixXd>(drives[i]));
    if (segments.back().cols() != 6 || segments.back().rows() < 1)
      throw std::invalid_argument("compiled loop: a drive is rows of (start, constant, ramp, amplitude, omega, phase)");
  }
  if (static_cast<Eigen::Index>(segments.size()) != k.actuated().size())
    throw std::invalid_argument("drives: one per actuated joint");
  return std::make_unique<Drives>(std::move(segments));
}

inline const bool drives_registered = register_controller("drives", &make_drives);

}  // namespace coopdyn_native
