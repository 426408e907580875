// Generalized-α (coopdyn/integrators/implicit.py: GeneralizedAlpha, the same operations): one
// linearised Newton iteration per step, the algorithmic acceleration carried between steps.
#pragma once

#include "../alpha.hpp"
#include "../loop.hpp"
#include "../mass_copy.hpp"

#include <vector>

namespace coopdyn_native {

class GeneralizedAlpha final : public Method {
public:
  GeneralizedAlpha(double am, double af, double g, double b, Eigen::Index nq) : am_(am), af_(af), g_(g), b_(b) {
    qs_.setZero(nq);
  }

  double step(Loop & L, double t, const VectorXd & q, const VectorXd & v, double h, VectorXd & q_new,
              VectorXd & v_new) override {
    const double am = am_, af = af_, g = g_, b = b_;
    Kernel & k = L.kernel();
    L.implicit_terms(t, q, v);
    f1_ = k.f_terms();
    M_.take(k);
    // The run's steps follow one another, so a carries over from the previous step (Python
    // checks that the state is the one it left; here it always is).
    if (!ready_) {  // a fresh start: a = q̈
      a_ = M_.solve(f1_);
      ready_ = true;
    }
    const AlphaCoefficients co = alpha_coefficients(am, af, g, b, h);
    const double c = co.c, gp = co.gp, bp = co.bp;
    dv0_ = co.dv_a * a_;
    dq0_ = h * v + co.dq_a * a_;
    L.factor(k.mass(), k.stiffness(), k.damping_matrix(), gp, bp);
    kq1_ = (1.0 - af) * (dq0_ - (bp / gp) * dv0_);
    M_.times(dv0_, tmp_);
    tmp_ = (1.0 - af) * tmp_ + gp * f1_;
    k.solve_into(kq1_, tmp_, kq2_, kv1_);
    xh_ = (kv1_ - (1.0 - af) * dv0_) / gp;
    L.integrate(q, dq0_ + (b * h * c) * xh_, qs_);
    vs_ = v + dv0_ + (g * c) * xh_;
    L.acceleration(t + h, qs_, vs_, tmp_);  // the Newton correction's residual
    tmp_ = (1.0 - af) * tmp_ - xh_;
    M_.times(tmp_, kv2_);
    kv2_ += af * f1_;
    kq1_.setZero(v.size());
    k.solve_into(kq1_, kv2_, kq2_, kv1_);
    xh_ += kv1_;
    L.integrate(q, dq0_ + (b * h * c) * xh_, q_new);
    v_new = v + dv0_ + (g * c) * xh_;
    a_ = (xh_ - am * a_) / (1.0 - am);
    return 0.0;
  }

  // (α_m < 1, α_f, γ > 0, β > 0) from settings["alpha"].
  static std::unique_ptr<Method> make(Settings & settings, const Model & model, Eigen::Index) {
    const std::vector<double> alpha = settings.doubles("alpha");
    if (alpha.size() != 4 || !(alpha[0] < 1.0) || !(alpha[2] > 0.0) || !(alpha[3] > 0.0))
      throw std::invalid_argument("compiled loop: generalized-alpha needs (alpha_m < 1, alpha_f, gamma > 0, beta > 0)");
    return std::make_unique<GeneralizedAlpha>(alpha[0], alpha[1], alpha[2], alpha[3], model.nq);
  }

  // A new held torque at this step's start (control_dt): start afresh from a = q̈ there, as at
  // t = 0 — the carried acceleration is the old load's, and keeping it costs the method its order.
  void restart() override { ready_ = false; }

private:
  double am_, af_, g_, b_;
  bool ready_ = false;
  MassCopy M_;
  VectorXd a_, xh_;      // the algorithmic acceleration, carried between steps, and x̂
  VectorXd dv0_, dq0_;  // the parts of v⁺ − v and q⁺ ⊖ q known at the step's start
  VectorXd f1_, kq1_, kv1_, kq2_, kv2_, qs_, vs_, tmp_;
};

inline const bool generalized_alpha_registered = register_method("generalized_alpha", &GeneralizedAlpha::make);

}  // namespace coopdyn_native
