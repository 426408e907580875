// The exponential integrator (coopdyn/integrators/exponential.py): the scene linearised once and
// discretised exactly in Python, one discretisation per step size the run takes; each step
// x⁺ = step·(x, u₀, 1) + inner·(u₁ … u_p), the uᵢ the controller's torques at the states
// predictor·(x, u₀, 1).
#pragma once

#include "../loop.hpp"

#include <vector>

namespace coopdyn_native {

struct Discretisation {
  double h;
  MatrixXd step, predictor, inner;
  int p;
};

class Exponential final : public Method {
public:
  explicit Exponential(std::vector<Discretisation> steps) : steps_(std::move(steps)) {}

  double step(Loop & L, double t, const VectorXd & q, const VectorXd & v, double h, VectorXd & q_new,
              VectorXd & v_new) override {
    const Discretisation * d = nullptr;
    for (const Discretisation & x : steps_) if (x.h == h) d = &x;
    if (!d) throw std::runtime_error("no exponential discretisation for this step size");
    const Eigen::Index n = q.size(), na = L.n_actuated();
    L.torque(t, q, v);
    L.record_start_torque();
    z_.resize(2 * n + na + 1);
    z_ << q, v, L.tau(), 1.0;
    x_ = d->step * z_;
    L.count_rhs(1);
    if (d->p > 0 && na > 0) {
      X_ = d->predictor * z_;
      U_.resize(d->p * na);
      for (int i = 1; i <= d->p; ++i) {
        qi_ = X_.segment((i - 1) * 2 * n, n);
        vi_ = X_.segment((i - 1) * 2 * n + n, n);
        L.torque(t + h * i / d->p, qi_, vi_);
        U_.segment((i - 1) * na, na) = L.tau();
      }
      x_ += d->inner * U_;
      L.count_rhs(d->p);
    }
    q_new = x_.head(n);
    v_new = x_.tail(n);
    return 0.0;
  }

  // The discretisations of `settings`: (h, step, predictor, inner, p) each, shapes checked.
  static std::unique_ptr<Method> make(Settings & settings, const Model & model, Eigen::Index na) {
    std::vector<Discretisation> out;
    bp::list steps = settings.get<bp::list>("discretisations");
    for (bp::ssize_t i = 0; i < bp::len(steps); ++i) {
      bp::tuple d = bp::extract<bp::tuple>(steps[i]);
      Discretisation x;
      x.h = bp::extract<double>(d[0]);
      x.step = bp::extract<MatrixXd>(d[1]);
      x.p = bp::extract<int>(d[4]);
      const Eigen::Index nx = 2 * model.nv, nz = nx + na + 1;
      if (model.nq != model.nv || x.step.rows() != nx || x.step.cols() != nz || x.p < 0)
        throw std::invalid_argument("compiled loop: an exponential step must be (2nv, 2nv + n_actuated + 1)");
      if (x.p > 0) {
        x.predictor = bp::extract<MatrixXd>(d[2]);
        x.inner = bp::extract<MatrixXd>(d[3]);
        if (x.predictor.rows() != x.p * nx || x.predictor.cols() != nz || x.inner.rows() != nx || x.inner.cols() != x.p * na)
          throw std::invalid_argument("compiled loop: the exponential's predictor or inner matrix has the wrong shape");
      }
      out.push_back(std::move(x));
    }
    return std::make_unique<Exponential>(std::move(out));
  }

private:
  std::vector<Discretisation> steps_;
  VectorXd z_, x_, X_, U_, qi_, vi_;
};

inline const bool exponential_registered = register_method("exponential", &Exponential::make);

}  // namespace coopdyn_native
