// TorqueSequence (coopdyn/control/joint.py) in C++: torques given in advance, each held for one
// period (zero-order hold), the last one to the end.
#pragma once

#include "controller.hpp"

#include <algorithm>
#include <cmath>

namespace coopdyn_native {

// τ(t) = torques[k], k = ⌊t / period + 1e-9⌋ clamped to the rows (the same floor as the Python
// twin: an instant within 1e-9 period of a boundary is the next period's, as the loop's samples are).
struct TorqueSequence : Controller {
  TorqueSequence(MatrixXd torques, double period) : torques(std::move(torques)), period(period) {}
  void torque(double t, const VectorXd &, const VectorXd &, VectorXd & tau) override {
    const double k = std::floor(t / period + 1e-9);
    const Eigen::Index row =
      k <= 0.0 ? 0 : std::min<Eigen::Index>(torques.rows() - 1, static_cast<Eigen::Index>(std::min(k, 1e15)));
    tau = torques.row(row).transpose();
  }
  MatrixXd torques;
  double period;
};

// {torques (N, n_actuated), period [s]}
inline std::unique_ptr<Controller> make_torque_sequence(Settings & c, Kernel & k) {
  const MatrixXd torques = c.get<MatrixXd>("torques");
  const double period = c.get<double>("period");
  if (torques.rows() < 1 || torques.cols() != k.actuated().size() || !torques.allFinite())
    throw std::invalid_argument("torque_sequence: torques must be (N >= 1, n_actuated), finite");
  if (!(period > 0.0) || !std::isfinite(period)) throw std::invalid_argument("torque_sequence: period must be > 0");
  return std::make_unique<TorqueSequence>(torques, period);
}

inline const bool torque_sequence_registered = register_controller("torque_sequence", &make_torque_sequence);

}  // namespace coopdyn_native
