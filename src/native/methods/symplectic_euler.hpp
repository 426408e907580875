// Symplectic Euler (coopdyn/integrators/explicit.py: SymplecticEuler): v⁺ = v + h q̈, q⁺ = q ⊕ h v⁺.
#pragma once

#include "../loop.hpp"

namespace coopdyn_native {

class SymplecticEuler final : public Method {
public:
  double step(Loop & L, double t, const VectorXd & q, const VectorXd & v, double h, VectorXd & q_new,
              VectorXd & v_new) override {
    L.acceleration(t, q, v, a_);
    v_new = v + h * a_;
    L.integrate(q, h * v_new, q_new);
    return 0.0;
  }

  static std::unique_ptr<Method> make(Settings &, const Model &, Eigen::Index) {
    return std::make_unique<SymplecticEuler>();
  }

private:
  VectorXd a_;
};

inline const bool symplectic_euler_registered = register_method("symplectic_euler", &SymplecticEuler::make);

}  // namespace coopdyn_native
