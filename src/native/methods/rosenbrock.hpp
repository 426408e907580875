// Two-stage Rosenbrock methods on the Lie group (coopdyn/integrators/implicit.py): ROS2 and its
// adaptive variant at γ = 1 + 1/√2, the trapezoid at γ ∈ [½, 1 + 1/√2) — one Jacobian and one
// factorisation per step, the embedded first-order solution for step control.
#pragma once

#include "../loop.hpp"
#include "../mass_copy.hpp"

namespace coopdyn_native {

class Rosenbrock final : public Method {
public:
  Rosenbrock(double gamma, bool adaptive, Eigen::Index nq) : gamma_(gamma), adaptive_(adaptive) { qs_.setZero(nq); }

  double step(Loop & L, double t, const VectorXd & q, const VectorXd & v, double h, VectorXd & q_new,
              VectorXd & v_new) override {
    Kernel & k = L.kernel();
    L.implicit_terms(t, q, v);
    f1_ = k.f_terms();
    M_.take(k);
    L.factor(k.mass(), k.stiffness(), k.damping_matrix(), gamma_ * h, (gamma_ * h) * (gamma_ * h));
    k.solve_into(v, f1_, kq1_, kv1_);
    delta_ = h * kq1_;
    vs_ = v + h * kv1_;
    L.integrate(q, delta_, qs_);
    L.acceleration(t + h, qs_, vs_, tmp_);
    L.chart_velocity(q, delta_, vs_, tmp2_);
    tmp2_ -= 2.0 * kq1_;
    tmp_ -= 2.0 * kv1_;
    M_.times(tmp_, f1_);
    k.solve_into(tmp2_, f1_, kq2_, kv2_);
    L.integrate(q, h * (1.5 * kq1_ + 0.5 * kq2_), q_new);
    v_new = v + h * (1.5 * kv1_ + 0.5 * kv2_);
    if (!adaptive_) return 0.0;
    e_d_ = 0.5 * h * (kq1_ + kq2_);
    e_v_ = 0.5 * h * (kv1_ + kv2_);
    return L.error_norm(q, v, v_new, e_d_, e_v_);
  }

  static std::unique_ptr<Method> make(Settings & settings, const Model & model, Eigen::Index) {
    const double gamma = settings.get<double>("gamma");
    if (!(gamma >= 0.5 && gamma <= 2.0)) throw std::invalid_argument("compiled loop: a Rosenbrock gamma must lie in [0.5, 2]");
    return std::make_unique<Rosenbrock>(gamma, settings.get<bool>("adaptive"), model.nq);
  }

private:
  double gamma_;
  bool adaptive_;
  MassCopy M_;
  VectorXd f1_, kq1_, kv1_, kq2_, kv2_, delta_, vs_, qs_, tmp_, tmp2_, e_d_, e_v_;
};

inline const bool rosenbrock_registered = register_method("rosenbrock", &Rosenbrock::make);

}  // namespace coopdyn_native
