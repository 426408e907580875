// Explicit Runge–Kutta methods given by their Butcher tableau (coopdyn/integrators/explicit.py:
// rk4, and the embedded pairs dopri5 and dop853 with their error and first-same-as-last stage), stages taken in the
// chart around q.
#pragma once

#include "../loop.hpp"

#include <vector>

namespace coopdyn_native {

struct Tableau {
  std::vector<std::vector<double>> A;
  std::vector<double> b, c, b_hat;
};

class RungeKutta final : public Method {
public:
  RungeKutta(Tableau tab, bool adaptive, Eigen::Index nq) : tab_(std::move(tab)), adaptive_(adaptive) { qs_.setZero(nq); }

  double step(Loop & L, double t, const VectorXd & q, const VectorXd & v, double h, VectorXd & q_new,
              VectorXd & v_new) override {
    stages(L, t, q, v, h, adaptive_ && fsal_valid_);
    if (!adaptive_) {
      combine(tab_.b, sd_, sd_.size(), tmp_);
      L.integrate(q, h * tmp_, q_new);
      combine(tab_.b, sa_, sa_.size(), tmp_);
      v_new = v + h * tmp_;
      return 0.0;
    }
    q_new = qs_;  // the last stage is the solution (first same as last)
    v_new = vs_;
    std::vector<double> diff(tab_.b.size());
    for (std::size_t i = 0; i < diff.size(); ++i) diff[i] = tab_.b[i] - tab_.b_hat[i];
    combine(diff, sd_, sd_.size(), tmp_);
    e_d_ = h * tmp_;
    combine(diff, sa_, sa_.size(), tmp_);
    e_v_ = h * tmp_;
    a0_ = sa_.back();
    L.keep_last_record();
    return L.error_norm(q, v, v_new, e_d_, e_v_);
  }
  bool reuses_start() const override { return fsal_valid_; }
  void accepted() override { fsal_valid_ = true; }
  void rejected() override { fsal_valid_ = false; }
  void restart() override { fsal_valid_ = false; }

  // The tableau of `settings` (A, b, c, and b_hat when adaptive), checked explicit and consistent.
  static std::unique_ptr<Method> make(Settings & settings, const Model & model, Eigen::Index) {
    Tableau tab;
    bp::list A = settings.get<bp::list>("A");
    for (bp::ssize_t i = 0; i < bp::len(A); ++i) tab.A.push_back(to_doubles(A[i]));
    tab.b = settings.doubles("b");
    tab.c = settings.doubles("c");
    if (settings.has("b_hat")) tab.b_hat = settings.doubles("b_hat");
    const bool adaptive = settings.get<bool>("adaptive");
    if (tab.A.empty() || tab.b.size() != tab.A.size() || tab.c.size() != tab.A.size() ||
        (adaptive && tab.b_hat.size() != tab.A.size()))
      throw std::invalid_argument("compiled loop: inconsistent Butcher tableau");
    for (std::size_t i = 0; i < tab.A.size(); ++i)
      if (tab.A[i].size() > i) throw std::invalid_argument("compiled loop: the tableau must be explicit");
    // consistent, as explicit.py's ButcherTableau checks it: rows of A sum to c, weights to 1
    const auto sum = [](const std::vector<double> & x) {
      double s = 0.0;
      for (double v : x) s += v;
      return s;
    };
    for (std::size_t i = 0; i < tab.A.size(); ++i)
      if (std::abs(sum(tab.A[i]) - tab.c[i]) > 1e-12) throw std::invalid_argument("compiled loop: inconsistent tableau (a row of A does not sum to c)");
    if (std::abs(sum(tab.b) - 1.0) > 1e-12 || (!tab.b_hat.empty() && std::abs(sum(tab.b_hat) - 1.0) > 1e-12))
      throw std::invalid_argument("compiled loop: inconsistent tableau (weights do not sum to 1)");
    return std::make_unique<RungeKutta>(std::move(tab), adaptive, model.nq);
  }

private:
  // Σ cᵢ kᵢ over the first n stages' non-zero coefficients (explicit.py: combine).
  static void combine(const std::vector<double> & coeffs, const std::vector<VectorXd> & ks, std::size_t n,
                      VectorXd & out) {
    out.setZero(ks[0].size());
    for (std::size_t i = 0; i < coeffs.size() && i < n; ++i)
      if (coeffs[i] != 0.0) out += coeffs[i] * ks[i];
  }

  // The stages in the chart around q (explicit.py: _stages); with `fsal`, stage 0 is a0_.
  void stages(Loop & L, double t, const VectorXd & q, const VectorXd & v, double h, bool fsal) {
    const std::size_t s = tab_.A.size();
    sd_.resize(s);
    sa_.resize(s);
    for (std::size_t i = 0; i < s; ++i) {
      if (i == 0) {
        sd_[0] = v;
        if (fsal)
          sa_[0] = a0_;
        else
          L.acceleration(t, q, v, sa_[0]);
        continue;
      }
      combine(tab_.A[i], sd_, i, tmp_);
      delta_ = h * tmp_;
      combine(tab_.A[i], sa_, i, tmp_);
      vs_ = v + h * tmp_;
      L.integrate(q, delta_, qs_);
      L.chart_velocity(q, delta_, vs_, sd_[i]);
      L.acceleration(t + tab_.c[i] * h, qs_, vs_, sa_[i]);
    }
  }

  Tableau tab_;
  bool adaptive_, fsal_valid_ = false;
  std::vector<VectorXd> sd_, sa_;  // the stages' chart rates and accelerations
  VectorXd tmp_, delta_, vs_, qs_, a0_, e_d_, e_v_;
};

inline const bool runge_kutta_registered = register_method("rk", &RungeKutta::make);

}  // namespace coopdyn_native
