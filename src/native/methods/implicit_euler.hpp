// Linearly implicit Euler (coopdyn/integrators/implicit.py: LinearlyImplicitEuler): one kernel call
// per step, or with `jacobian_every` > 1 the step matrix kept for that many steps of one size.
#pragma once

#include "../loop.hpp"
#include "../mass_copy.hpp"

namespace coopdyn_native {

class ImplicitEuler final : public Method {
public:
  explicit ImplicitEuler(int jacobian_every) : jacobian_every_(jacobian_every) {}

  double step(Loop & L, double t, const VectorXd & q, const VectorXd & v, double h, VectorXd & q_new,
              VectorXd & v_new) override {
    if (jacobian_every_ == 1) {
      L.implicit_euler_velocity(t, q, v, h, v_new);
      L.integrate(q, h * v_new, q_new);
      return 0.0;
    }
    Kernel & k = L.kernel();
    if (!ready_ || count_ >= jacobian_every_ || h_ != h) {
      L.implicit_terms(t, q, v);
      f1_ = k.f_terms();
      M_.take(k);
      L.factor(k.mass(), k.stiffness(), k.damping_matrix(), h, h * h);
      count_ = 0;
      h_ = h;
      ready_ = true;
    } else {
      L.acceleration(t, q, v, tmp_);
      M_.times(tmp_, f1_);
    }
    ++count_;
    k.solve_into(v, f1_, kq_, kv_);
    v_new = v + h * kv_;
    L.integrate(q, h * v_new, q_new);
    return 0.0;
  }

  static std::unique_ptr<Method> make(Settings & settings, const Model &, Eigen::Index) {
    const int every = settings.get<int>("jacobian_every");
    if (every < 1) throw std::invalid_argument("compiled loop: jacobian_every must be >= 1");
    return std::make_unique<ImplicitEuler>(every);
  }

  void new_run() override {
    ready_ = false;
    count_ = 0;
    h_ = 0.0;
  }

private:
  int jacobian_every_;
  bool ready_ = false;  // a step matrix is factored, for steps of size h_, used count_ times
  int count_ = 0;
  double h_ = 0.0;
  MassCopy M_;
  VectorXd f1_, tmp_, kq_, kv_;
};

inline const bool implicit_euler_registered = register_method("implicit_euler", &ImplicitEuler::make);

}  // namespace coopdyn_native
