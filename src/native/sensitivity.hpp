// Exact sensitivities of a method's steps, open loop or closed under a sampled controller: the
// C++ twin of coopdyn/sensitivity.py and coopdyn/step_derivative.py (same recursion, see their
// docstrings) for the explicit Runge–Kutta methods, symplectic Euler and the linearly implicit
// methods (implicit Euler, the two-stage Rosenbrock-W scheme, generalized-α). Each stage's
// derivatives come from Kernel::compute_derivatives; an implicit stage's solve is differentiated
// with the step matrix plus the Gauss–Newton matrices' own variation (matrix_derivatives:
// derivatives.py's MatrixDerivatives);
// a parameter's ∂q̈/∂p is M⁻¹ ∂Q/∂p, ∂Q/∂p the generalized force of a unit law (an element
// built from the Python side's unit K or D: the law is linear in them) or, for the object's
// mass, −J_jᵀ (I·a_gf + v ×* I v)/m with the object's body inertia I (RNEA's body force of the
// object joint, linear in the inertia), for a grasp position the wrench's variation as G moves
// along δ on the object; the chart rate dexp⁻¹(δ)v is differentiated by complex
// step of jlog6_of_log (exact to round-off).
#pragma once

#include "alpha.hpp"
#include "controllers/controller.hpp"
#include "kernel.hpp"

#include <pinocchio/algorithm/rnea-derivatives.hpp>

#include <complex>
#include <iomanip>
#include <sstream>
#include <limits>

namespace coopdyn_native {

class Sensitivity {
public:
  // kernel: the scene's (coopdyn.dynamics.native); A, b: an explicit tableau (rows of A below the
  // diagonal), or `symplectic` for symplectic Euler; charts: (idx_v, size) of the free-flyer (6)
  // and spherical (3) blocks; parameters: one tuple per parameter, ("element", link, kind,
  // {K, D, ...}) for a unit law, ("offset", link, δ (6)) for a grasp position (G's right
  // perturbation per metre), or ("mass", joint, mass) for the object's mass.
  // implicit: () for an explicit method, (γ, stages) for a linearly implicit one (1: implicit
  // Euler, 2: ROS2 or the trapezoid), (α_m, α_f, γ, β) for generalized-α.
  Sensitivity(bp::object kernel_obj, bp::list A, bp::list b, bool symplectic, bp::tuple implicit, bp::list charts,
              bp::list parameters)
    : kernel_obj_(kernel_obj), kernel_(bp::extract<Kernel &>(kernel_obj)), model_(kernel_.model()),
      symplectic_(symplectic) {
    for (bp::ssize_t i = 0; i < bp::len(A); ++i) A_.push_back(to_doubles(A[i]));
    b_ = to_doubles(b);
    const std::vector<double> c = to_doubles(implicit);
    if (c.size() == 2) {
      gamma_ = c[0];
      stages_ = static_cast<int>(c[1]);
      if (!(gamma_ > 0.0) || (stages_ != 1 && stages_ != 2)) throw std::invalid_argument("Sensitivity: bad implicit method");
    } else if (c.size() == 4) {
      alpha_ = true;
      am_ = c[0], af_ = c[1], ag_ = c[2], ab_ = c[3];
    } else if (!c.empty())
      throw std::invalid_argument("Sensitivity: bad implicit method");
    if (implicit_method()) {  // (a Data is O(nv³): only what the method needs)
      free_model_ = std::make_unique<Model>(model_);
      free_model_->gravity.setZero();
      free_data_ = std::make_unique<Data>(*free_model_);
      mdata_ = std::make_unique<Data>(model_);
    } else if (!symplectic_ && (A_.empty() || b_.size() != A_.size()))
      throw std::invalid_argument("Sensitivity: inconsistent tableau");
    for (bp::ssize_t i = 0; i < bp::len(charts); ++i)
      charts_.emplace_back(bp::extract<Eigen::Index>(charts[i][0]), bp::extract<int>(charts[i][1]));
    for (bp::ssize_t i = 0; i < bp::len(parameters); ++i) {
      bp::tuple p = bp::extract<bp::tuple>(parameters[i]);
      const std::string kind = bp::extract<std::string>(p[0]);
      Param out;
      if (kind == "element") {
        out.link = bp::extract<std::size_t>(p[1]);
        if (out.link >= kernel_.links().size()) throw std::invalid_argument("Sensitivity: no such link");
        out.law = coopdyn::make_element(bp::extract<std::string>(p[2]), bp::extract<bp::dict>(p[3]));
      } else if (kind == "offset") {  // a grasp position: ("offset", link, δ (6): G's right perturbation per metre)
        out.link = bp::extract<std::size_t>(p[1]);
        if (out.link >= kernel_.links().size()) throw std::invalid_argument("Sensitivity: no such link");
        const std::vector<double> delta = to_doubles(p[2]);
        if (delta.size() != 6) throw std::invalid_argument("Sensitivity: an offset's direction has 6 entries");
        out.offset = true;
        out.delta = Eigen::Map<const Vector6>(delta.data());
      } else if (kind == "mass") {
        out.joint = bp::extract<pinocchio::JointIndex>(p[1]);
        const double mass = bp::extract<double>(p[2]);
        if (out.joint < 1 || out.joint >= model_.joints.size() || !(mass > 0.0))
          throw std::invalid_argument("Sensitivity: bad object joint or mass");
        const pinocchio::Inertia & I = model_.inertias[out.joint];
        const Eigen::Matrix<double, 10, 1> pi = I.toDynamicParameters() / mass;  // (linear in them)
        out.unit_inertia = pinocchio::Inertia::FromDynamicParameters(pi);
        if (!data_) data_ = std::make_unique<Data>(model_);
      } else
        throw std::invalid_argument("Sensitivity: unknown parameter kind " + kind);
      params_.push_back(std::move(out));
    }
  }

  // The closed loop's controller, sampled at every period's start and held (a zero-order hold);
  // its gain ∂τ/∂x there by central differences (linearize.py: controller_gain, same steps).
  void set_controller(std::unique_ptr<Controller> controller) { ctrl_ = std::move(controller); }

  // τ at (t, q, v) and the controller's whole gain ∂τ/∂(δq, v) (na, 2nv) by central differences
  // (controller_probe's steps, linearize.py's controller_gain's): the loop check of a run under a
  // built-in controller (coopdyn/compiled.py: controller_gain) in microseconds.
  bp::tuple controller_gain(double t, const RefVec & q, const RefVec & v) {
    if (!ctrl_) throw std::invalid_argument("Sensitivity: controller_gain needs a controller (set_controller)");
    const Eigen::Index nv = model_.nv;
    check_size(q, model_.nq, "q");
    check_size(v, nv, "v");
    const VectorXd q0 = q, v0 = v;
    MatrixXd dq = MatrixXd::Zero(nv, 2 * nv), dv = MatrixXd::Zero(nv, 2 * nv), G;
    dq.leftCols(nv).setIdentity();
    dv.rightCols(nv).setIdentity();
    VectorXd tau;
    controller_probe(t, q0, v0, dq, dv, tau, G);
    return bp::make_tuple(tau, G);
  }

  // N periods of `per` steps of h [s] from (q0, v0) under U (N, na) — with a controller, under
  // its torque sampled at t = k·per·h (U is then added to it) —, the derivatives carried along the
  // seed columns (dq0, dv0: (nv, m); dU: (na, m), the same at every step; dP: (np, m)).
  // Returns (Q (N+1, nq), V (N+1, nv), W (N+1, 6L), dX ((N+1)·2nv, m), dW ((N+1)·6L, m), exact,
  // the torques applied (N, na)):
  // the samples at every period's start and the end, the wrenches and derivatives there (at the
  // end only with `end_wrench`: one more evaluation of the derivatives).
  // (The matrices are taken as copies, not Eigen::Ref: eigenpy maps a (1, n) array through a Ref
  // with its row stride as the column stride — one period, one parameter — and reads past its end.)
  // A step whose speed passes max_speed [rad/s or m/s] stops the run as diverged (t0 [s]: the
  // run's start, for the message).
  bp::tuple run(const RefVec & q0, const RefVec & v0, const MatrixXd & U, long per, double h, const MatrixXd & dq0,
                const MatrixXd & dv0, const MatrixXd & dU, const MatrixXd & dP, bool end_wrench, double max_speed,
                double t0) {
    const Eigen::Index nq = model_.nq, nv = model_.nv, na = kernel_.actuated().size();
    const Eigen::Index L = static_cast<Eigen::Index>(kernel_.links().size()), np = static_cast<Eigen::Index>(params_.size());
    const Eigen::Index m = dq0.cols(), N = U.rows();
    check_size(q0, nq, "q0");
    check_size(v0, nv, "v0");
    if (U.cols() != na || N < 1 || per < 1 || !(h > 0.0) || dq0.rows() != nv || dv0.rows() != nv || dv0.cols() != m ||
        dU.rows() != na || dU.cols() != m || dP.rows() != np || dP.cols() != m)
      throw std::invalid_argument("Sensitivity.run: inconsistent shapes");
    MatrixXd Q(N + 1, nq), V(N + 1, nv), W(N + 1, 6 * L), dX((N + 1) * 2 * nv, m), dW((N + 1) * 6 * L, m);
    VectorXd q = q0, v = v0, q1, v1;
    MatrixXd dq = dq0, dv = dv0, dq1, dv1;
    exact_ = true;
    MatrixXd applied = U, dUk = dU;
    VectorXd u;
    for (Eigen::Index k = 0; k < N; ++k) {
      u = U.row(k).transpose();
      if (ctrl_) {
        VectorXd tau;
        controller_sample(double(k * per) * h, q, v, dq, dv, tau, dUk);
        u += tau;
        applied.row(k) = u.transpose();
        dUk += dU;
      }
      carried_ = false;  // (a new held torque: generalized-α starts afresh, as the integrators do)
      for (long s = 0; s < per; ++s) {
        const double t_step = t0 + double(k * per + s) * h;
        if (PyErr_CheckSignals() != 0) throw bp::error_already_set();  // (Ctrl-C: the run holds the GIL)
        // A divergence's message starts with "diverged" (coopdyn/sensitivity.py reads it so).
        try {
          step(q, v, u, h, dq, dv, dUk, dP, s == 0, q1, v1, dq1, dv1);
        } catch (const StepMatrixError & e) {  // (an implicit step's matrix: no longer finite, or not definite)
          throw std::runtime_error("diverged in the step from t = " + number(t_step, 6) + " s (" + e.what() + ")");
        } catch (const NotFiniteError & e) {
          throw std::runtime_error("diverged in the step from t = " + number(t_step, 6) + " s (" + e.what() + ")");
        }
        if (s == 0) sample(k, q, v, dq, dv, dP, Q, V, W, dX, dW);
        if (!q1.allFinite() || !v1.allFinite() || !dq1.allFinite() || !dv1.allFinite())
          throw std::runtime_error("diverged: the state is not finite at t = " + number(t_step + h, 6) + " s");
        if (v1.cwiseAbs().maxCoeff() > max_speed)
          throw std::runtime_error("diverged: a speed of " + number(v1.cwiseAbs().maxCoeff(), 3) + " rad/s or m/s (above " +
                                   number(max_speed, 6) + ") after the step from t = " + number(t_step, 6) + " s");
        q.swap(q1);
        v.swap(v1);
        dq.swap(dq1);
        dv.swap(dv1);
      }
    }
    if (end_wrench) stage(q, v, U.row(N - 1).transpose());  // (else the last row's W and dW are NaN)
    sample(N, q, v, dq, dv, dP, Q, V, W, dX, dW, end_wrench);
    return bp::make_tuple(Q, V, W, dX, dW, exact_ && !ctrl_, applied);
  }

private:
  // x with `digits` significant digits, as Python's format "{:.<digits>g}".
  static std::string number(double x, int digits) {
    std::ostringstream out;
    out << std::setprecision(digits) << x;
    return out.str();
  }

  struct Param {
    std::size_t link = 0;
    std::unique_ptr<coopdyn::Element> law;  // null for the mass and a grasp position
    bool offset = false;                     // a grasp position, moving G by exp6(delta) per metre
    Vector6 delta = Vector6::Zero();
    pinocchio::JointIndex joint = 0;
    pinocchio::Inertia unit_inertia = pinocchio::Inertia::Zero();  // the object's inertia per kg of its mass
  };

  // τ at (t, q, v) and its derivative along the seed columns, du = ∂τ/∂(δq, v)·[dq; dv] (na, m),
  // by central differences: along each column (2m calls; a step of 1e-6 on its largest entry)
  // when m < 2nv, else through the whole gain (4nv calls: steps 1e-6 in δq, 1e-6·max(1, |v|∞) in v,
  // as linearize.py's controller_gain). Then τ once more at (t, q, v): a controller that keeps
  // state between calls answers differently, and the probes have changed its trajectory — an
  // error that starts with "stateful controller" (coopdyn/sensitivity.py words it).
  void controller_sample(double t, const VectorXd & q, const VectorXd & v, const MatrixXd & dq, const MatrixXd & dv,
                         VectorXd & tau, MatrixXd & du) {
    controller_probe(t, q, v, dq, dv, tau, du);
    VectorXd again(tau.size());
    if (ctrl_->reads_kernel()) kernel_.kinematics(q, v, false);
    ctrl_->torque(t, q, v, again);
    const double scale = std::max(1.0, tau.size() ? tau.cwiseAbs().maxCoeff() : 0.0);
    if (!again.allFinite() || (again - tau).cwiseAbs().maxCoeff() > 1e-9 * scale)
      throw std::runtime_error("stateful controller at t = " + number(t, 6) + " s: " + number(tau.norm(), 6) + " then " +
                               number(again.norm(), 6));
  }

  void controller_probe(double t, const VectorXd & q, const VectorXd & v, const MatrixXd & dq, const MatrixXd & dv,
                         VectorXd & tau, MatrixXd & du) {
    const Eigen::Index nv = model_.nv, na = kernel_.actuated().size(), m = dq.cols();
    auto torque = [&](const VectorXd & qq, const VectorXd & vv, VectorXd & out) {
      out.resize(na);
      if (ctrl_->reads_kernel()) kernel_.kinematics(qq, vv, false);
      ctrl_->torque(t, qq, vv, out);
      if (!out.allFinite()) throw std::runtime_error("the controller's torque is not finite at t = " + number(t, 6) + " s");
    };
    torque(q, v, tau);
    VectorXd qq(model_.nq), vv, e, plus, minus;
    du.setZero(na, m);
    if (m < 2 * nv) {
      for (Eigen::Index j = 0; j < m; ++j) {
        const double size = std::max(dq.col(j).cwiseAbs().maxCoeff(), dv.col(j).cwiseAbs().maxCoeff());
        if (size == 0.0) continue;
        const double eps = 1e-6 / size;
        e = eps * dq.col(j);
        pinocchio::integrate(model_, q, e, qq);
        torque(qq, v + eps * dv.col(j), plus);
        e = -e;
        pinocchio::integrate(model_, q, e, qq);
        torque(qq, v - eps * dv.col(j), minus);
        du.col(j) = (plus - minus) / (2.0 * eps);
      }
      return;
    }
    const double h_q = 1e-6, h_v = 1e-6 * std::max(1.0, v.cwiseAbs().maxCoeff());
    G_.resize(na, 2 * nv);
    e = VectorXd::Zero(nv);
    for (Eigen::Index j = 0; j < nv; ++j) {
      e[j] = h_q;
      pinocchio::integrate(model_, q, e, qq);
      torque(qq, v, plus);
      e[j] = -h_q;
      pinocchio::integrate(model_, q, e, qq);
      torque(qq, v, minus);
      e[j] = 0.0;
      G_.col(j) = (plus - minus) / (2.0 * h_q);
      vv = v;
      vv[j] += h_v;
      torque(q, vv, plus);
      vv[j] = v[j] - h_v;
      torque(q, vv, minus);
      G_.col(nv + j) = (plus - minus) / (2.0 * h_v);
    }
    du.noalias() = G_.leftCols(nv) * dq;
    du.noalias() += G_.rightCols(nv) * dv;
  }

  // The derivatives at (q, v, u) into d_, and ∂q̈/∂p (nv, np) into da_dp_, ∂W/∂p (6L, np) into dW_dp_.
  void stage(const VectorXd & q, const VectorXd & v, const VectorXd & u) {
    kernel_.compute_derivatives(q, v, u, nullptr, d_);
    exact_ = exact_ && d_.exact;
    const Eigen::Index nv = model_.nv, np = static_cast<Eigen::Index>(params_.size());
    const Eigen::Index L = static_cast<Eigen::Index>(kernel_.links().size());
    dW_dp_.setZero(6 * L, np);
    if (np == 0) {
      da_dp_.resize(nv, 0);
      return;
    }
    Data & data = kernel_.full_data();  // (placements and joint Jacobians at q: compute_derivatives)
    MatrixXd dQ = MatrixXd::Zero(nv, np);
    Matrix6x J_G(6, nv), J_T(6, nv);
    bool kinematics = false;
    for (Eigen::Index k = 0; k < np; ++k) {
      const Param & p = params_[static_cast<std::size_t>(k)];
      if (!p.law && !p.offset) {  // the object's mass: −J_jᵀ (I a_gf + v ×* I v) per kg
        if (!kinematics) pinocchio::forwardKinematics(model_, *data_, q, v, d_.a);
        kinematics = true;
        const pinocchio::Motion a_gf = data_->a[p.joint] - data_->oMi[p.joint].actInv(model_.gravity);
        const pinocchio::Force f = p.unit_inertia * a_gf + data_->v[p.joint].cross(p.unit_inertia * data_->v[p.joint]);
        J_G.setZero();
        pinocchio::getJointJacobian(model_, data, p.joint, pinocchio::LOCAL, J_G);
        dQ.col(k) = -J_G.transpose() * f.toVector();
        continue;
      }
      const Link & lk = kernel_.links()[p.link];
      const SE3 X = data.oMf[lk.tip].actInv(data.oMf[lk.grasp]);
      J_G.setZero();
      J_T.setZero();
      pinocchio::getFrameJacobian(model_, data, lk.grasp, pinocchio::LOCAL, J_G);
      pinocchio::getFrameJacobian(model_, data, lk.tip, pinocchio::LOCAL, J_T);
      const Matrix6x Jr = J_G - X.toActionMatrixInverse() * J_T;
      if (p.offset) {  // X·exp6(δ), ξ by −ad(δ)ξ, Jr by −ad(δ)Jr (step_derivative.py: _offset_force)
        const Vector6 xi = Jr * v;
        lk.element->evaluate(X, xi, false, ev_);
        Matrix6 F_d, F_x;
        exact_ = lk.element->tangent(X, xi, F_d, F_x) && exact_;
        const Matrix6 ad = Kernel::motion_cross(p.delta);
        const Vector6 df = F_d * p.delta - F_x * (ad * xi);
        dQ.col(k) = Jr.transpose() * df - (ad * Jr).transpose() * ev_.f;
        dW_dp_.block(6 * static_cast<Eigen::Index>(p.link), k, 6, 1) = df;
        continue;
      }
      p.law->evaluate(X, Jr * v, false, ev_);
      dQ.col(k) = Jr.transpose() * ev_.f;
      dW_dp_.block(6 * static_cast<Eigen::Index>(p.link), k, 6, 1) = ev_.f;
    }
    da_dp_.noalias() = d_.Minv * dQ;
  }

  // One step with the derivatives of its end along the seed columns; with `sampled`, the start's
  // wrenches and their derivatives are kept for sample() (keep_start).
  void step(const VectorXd & q, const VectorXd & v, const VectorXd & u, double h, const MatrixXd & dq0,
            const MatrixXd & dv0, const RefMat & dU, const RefMat & dP, bool sampled, VectorXd & q1, VectorXd & v1,
            MatrixXd & dq1, MatrixXd & dv1) {
    const Eigen::Index nv = model_.nv;
    if (alpha_) {
      alpha_step(q, v, u, h, dq0, dv0, dU, dP, sampled, q1, v1, dq1, dv1);
      return;
    }
    if (stages_ > 0) {
      implicit_step(q, v, u, h, dq0, dv0, dU, dP, sampled, q1, v1, dq1, dv1);
      return;
    }
    if (symplectic_) {  // v⁺ = v + h a(q, v), q⁺ = q ⊕ h v⁺
      stage(q, v, u);
      if (sampled) keep_start();
      v1 = v + h * d_.a;
      acceleration_derivative(dq0, dv0, dU, dP, dka0_);
      dv1 = dv0 + h * dka0_;
      integrate(q, h * v1, dq0, h * dv1, q1, dq1);
      return;
    }
    const std::size_t s = A_.size();
    kd_.resize(s);
    ka_.resize(s);
    dkd_.resize(s);
    dka_.resize(s);
    VectorXd delta(nv), vs(nv), qs;
    MatrixXd ddelta, dvs, dqs;
    for (std::size_t i = 0; i < s; ++i) {
      if (i == 0) {
        stage(q, v, u);
        if (sampled) keep_start();
        kd_[0] = v;
        dkd_[0] = dv0;
        dqs = dq0;
        dvs = dv0;
      } else {
        delta.setZero();
        vs = v;
        ddelta.setZero(nv, dq0.cols());
        dvs = dv0;
        for (std::size_t j = 0; j < i; ++j) {
          const double c = j < A_[i].size() ? A_[i][j] : 0.0;
          if (c == 0.0) continue;
          delta += (h * c) * kd_[j];
          vs += (h * c) * ka_[j];
          ddelta += (h * c) * dkd_[j];
          dvs += (h * c) * dka_[j];
        }
        integrate(q, delta, dq0, ddelta, qs, dqs);
        chart(delta, vs, ddelta, dvs, kd_[i], dkd_[i]);
        stage(qs, vs, u);
      }
      ka_[i] = d_.a;
      acceleration_derivative(dqs, dvs, dU, dP, dka_[i]);
    }
    VectorXd Delta = VectorXd::Zero(nv);
    MatrixXd dDelta = MatrixXd::Zero(nv, dq0.cols());
    v1 = v;
    dv1 = dv0;
    for (std::size_t i = 0; i < s; ++i) {
      if (b_[i] == 0.0) continue;
      Delta += (h * b_[i]) * kd_[i];
      dDelta += (h * b_[i]) * dkd_[i];
      v1 += (h * b_[i]) * ka_[i];
      dv1 += (h * b_[i]) * dka_[i];
    }
    integrate(q, Delta, dq0, dDelta, q1, dq1);
  }

  bool implicit_method() const { return stages_ > 0 || alpha_; }

  // f = M q̈, M, K̃, D̃ at the step's start (copies: later stages reuse the kernel's buffers), the
  // kernel's factorisation of S = M + gp D̃ + bp K̃ (no gains: the torque is held) for the forward
  // solves, and S's own Cholesky factor for the derivatives' many right-hand sides.
  void start_matrices(const VectorXd & q, const VectorXd & v, const VectorXd & u, double gp, double bp) {
    kernel_.kinematics(q, v, true);
    kernel_.terms(q, v, u);
    f_ = kernel_.f_terms();
    M_ = kernel_.mass();
    K_ = kernel_.stiffness();
    D_ = kernel_.damping_matrix();
    const VectorXd gains = VectorXd::Zero(kernel_.actuated().size());
    kernel_.factor(M_, K_, D_, gp, gains, gains, bp);
    llt_S_.compute(M_ + gp * D_ + bp * K_);
    at_v_current_ = false;
  }

  // A linearly implicit step (step_derivative.py: _implicit_step): implicit Euler is the first
  // stage at γ = 1; the two-stage scheme adds (I − γhJ) k₂ = f(q ⊕ hk_q1, v + hk_v1) − 2k₁.
  void implicit_step(const VectorXd & q, const VectorXd & v, const VectorXd & u, double h, const MatrixXd & dq0,
                     const MatrixXd & dv0, const RefMat & dU, const RefMat & dP, bool sampled, VectorXd & q1, VectorXd & v1,
                     MatrixXd & dq1, MatrixXd & dv1) {
    const double gh = gamma_ * h;
    stage(q, v, u);
    if (sampled) keep_start();
    const VectorXd a1 = d_.a;
    MatrixXd da1;
    acceleration_derivative(dq0, dv0, dU, dP, da1);
    start_matrices(q, v, u, gh, gh * gh);
    VectorXd kq1, kv1;
    kernel_.solve_into(v, f_, kq1, kv1);
    MatrixXd dkv1;
    solve_derivative(q, v, gh, gh * gh, v, kv1, a1, da1, dv0, dq0, dv0, dP, dkv1);
    const MatrixXd dkq1 = dv0 + gh * dkv1;
    if (stages_ == 1) {
      integrate(q, h * kq1, dq0, h * dkq1, q1, dq1);
      v1 = v + h * kv1;
      dv1 = dv0 + h * dkv1;
      return;
    }
    const VectorXd d2 = h * kq1, v2 = v + h * kv1;
    const MatrixXd dd2 = h * dkq1, dv2 = dv0 + h * dkv1;
    VectorXd q2, rate;
    MatrixXd dq2, drate, da2;
    integrate(q, d2, dq0, dd2, q2, dq2);
    stage(q2, v2, u);
    acceleration_derivative(dq2, dv2, dU, dP, da2);
    chart(d2, v2, dd2, dv2, rate, drate);
    const VectorXd fq2 = rate - 2.0 * kq1, y2 = d_.a - 2.0 * kv1;
    const MatrixXd dfq2 = drate - 2.0 * dkq1, dy2 = da2 - 2.0 * dkv1;
    VectorXd kq2, kv2;
    kernel_.solve_into(fq2, M_ * y2, kq2, kv2);
    MatrixXd dkv2;
    solve_derivative(q, v, gh, gh * gh, fq2, kv2, y2, dy2, dfq2, dq0, dv0, dP, dkv2);
    const MatrixXd dkq2 = dfq2 + gh * dkv2;
    integrate(q, h * (1.5 * kq1 + 0.5 * kq2), dq0, h * (1.5 * dkq1 + 0.5 * dkq2), q1, dq1);
    v1 = v + h * (1.5 * kv1 + 0.5 * kv2);
    dv1 = dv0 + h * (1.5 * dkv1 + 0.5 * dkv2);
  }

  // A generalized-α step (step_derivative.py: _alpha_step; implicit.py: GeneralizedAlpha.step):
  // the algorithmic acceleration and its derivative are carried from step to step within a
  // period (a_carry_, da_carry_; carried_ false: a fresh start, a = q̈).
  void alpha_step(const VectorXd & q, const VectorXd & v, const VectorXd & u, double h, const MatrixXd & dq,
                  const MatrixXd & dv, const RefMat & dU, const RefMat & dP, bool sampled, VectorXd & q1, VectorXd & v1,
                  MatrixXd & dq1, MatrixXd & dv1) {
    const AlphaCoefficients co = alpha_coefficients(am_, af_, ag_, ab_, h);
    const double c = co.c, dq_a = co.dq_a, dv_a = co.dv_a, gp = co.gp, bp = co.bp;
    stage(q, v, u);
    if (sampled) keep_start();
    MatrixXd da_true;
    acceleration_derivative(dq, dv, dU, dP, da_true);
    start_matrices(q, v, u, gp, bp);
    const VectorXd a_true = M_.llt().solve(f_);  // q̈ at the start, as the integrator's fresh start takes it
    const VectorXd a = carried_ ? a_carry_ : a_true;
    const MatrixXd da = carried_ ? da_carry_ : da_true;
    const VectorXd A0 = dv_a * a, B0 = h * v + dq_a * a;
    const MatrixXd dA0 = dv_a * da, dB0 = h * dv + dq_a * da;
    const VectorXd f_q = (1.0 - af_) * (B0 - (bp / gp) * A0);
    const MatrixXd df_q = (1.0 - af_) * (dB0 - (bp / gp) * dA0);
    VectorXd k_q, y;
    kernel_.solve_into(f_q, (1.0 - af_) * (M_ * A0) + gp * f_, k_q, y);
    MatrixXd dy;
    solve_derivative(q, v, gp, bp, f_q, y, (1.0 - af_) * A0 + gp * a_true, (1.0 - af_) * dA0 + gp * da_true, df_q, dq, dv,
                     dP, dy);
    VectorXd xh = (y - (1.0 - af_) * A0) / gp;
    MatrixXd dxh = (dy - (1.0 - af_) * dA0) / gp;
    integrate(q, B0 + (ab_ * h * c) * xh, dq, dB0 + (ab_ * h * c) * dxh, q1, dq1);
    v1 = v + A0 + (ag_ * c) * xh;
    dv1 = dv + dA0 + (ag_ * c) * dxh;
    stage(q1, v1, u);  // the Newton correction: S dx = M((1 − α_f) q̈(q⁺, v⁺) − x̂) + α_f f
    MatrixXd da1;
    acceleration_derivative(dq1, dv1, dU, dP, da1);
    const VectorXd zero = VectorXd::Zero(model_.nv);
    VectorXd k_q2, dx;
    kernel_.solve_into(zero, M_ * ((1.0 - af_) * d_.a - xh) + af_ * f_, k_q2, dx);
    MatrixXd ddx;
    solve_derivative(q, v, gp, bp, zero, dx, (1.0 - af_) * d_.a - xh + af_ * a_true, (1.0 - af_) * da1 - dxh + af_ * da_true,
                     MatrixXd::Zero(model_.nv, dq.cols()), dq, dv, dP, ddx);
    xh += dx;
    dxh += ddx;
    integrate(q, B0 + (ab_ * h * c) * xh, dq, dB0 + (ab_ * h * c) * dxh, q1, dq1);
    v1 = v + A0 + (ag_ * c) * xh;
    dv1 = dv + dA0 + (ag_ * c) * dxh;
    a_carry_ = (xh - am_ * a) / (1.0 - am_);
    da_carry_ = (dxh - am_ * da) / (1.0 - am_);
    carried_ = true;
  }

  // dk_v of a stage solve S k_v = M y − gp K̃ f_q (the step's start's matrices, S = M + gp D̃ +
  // bp K̃) given dy and df_q (step_derivative.py: _solve_derivative):
  // S dk_v = M dy − gp K̃ df_q − dG, G = M (k_v − y) + gp D̃ k_v + K̃ (bp k_v + gp f_q).
  void solve_derivative(const VectorXd & q, const VectorXd & v, double gp, double bp, const VectorXd & f_q,
                        const VectorXd & k_v, const VectorXd & y, const MatrixXd & dy, const MatrixXd & df_q,
                        const MatrixXd & dq0, const MatrixXd & dv0, const RefMat & dP, MatrixXd & dk_v) {
    const VectorXd w_M = k_v - y, w_D = gp * k_v, w_K = bp * k_v + gp * f_q;
    matrix_derivatives(q, v, w_M, w_D, w_K);
    MatrixXd rhs = M_ * dy;
    rhs.noalias() -= gp * (K_ * df_q);
    rhs.noalias() -= dG_dq_ * dq0;
    rhs.noalias() -= dG_dv_ * dv0;
    if (dP.size() && !dP.isZero(0.0)) rhs.noalias() -= matrix_parameters(q, w_M) * dP;
    dk_v = llt_S_.solve(rhs);
  }

  // ∂(M w_M + D̃ w_D + K̃ w_K)/∂(q, v) into dG_dq_, dG_dv_ (derivatives.py: MatrixDerivatives):
  // the body wrenches g = S_K (Jr w_K) + S_D (Jr w_D) on G and −X.dual g on T, their own variation
  // through Element::matrix_tangent and the twists' derivatives at w_K and w_D, and their motion
  // with the bodies with ∂(M w_M)/∂q from one RNEA derivative without gravity.
  void matrix_derivatives(const VectorXd & q, const VectorXd & v, const VectorXd & w_M, const VectorXd & w_D,
                          const VectorXd & w_K) {
    const Eigen::Index nv = model_.nv;
    if (!at_v_current_) relative_twists(q, v, at_v_);  // (once per step: the start's, for every stage solve)
    at_v_current_ = true;
    relative_twists(q, w_D, at_D_);
    relative_twists(q, w_K, at_K_);
    ForceList fext(model_.njoints, pinocchio::Force::Zero());
    dG_dq_.setZero(nv, nv);
    dG_dv_.setZero(nv, nv);
    Matrix6 G_d, G_x;
    auto add_wrench = [&](FrameIndex frame, const Vector6 & f) {
      const pinocchio::Frame & fr = model_.frames[frame];
      fext[fr.parentJoint] -= fr.placement.act(pinocchio::Force(f));  // (−: RNEA subtracts Jᵀ fext)
    };
    const auto & links = kernel_.links();
    for (std::size_t i = 0; i < links.size(); ++i) {
      const Link & lk = links[i];
      const Twist & tv = at_v_[i];
      const bool damped = lk.element->damped();
      const Vector6 xi_D = damped ? at_D_[i].xi : Vector6::Zero().eval();
      lk.element->evaluate(tv.X, tv.xi, true, ev_);
      const Vector6 g = ev_.SK * at_K_[i].xi + ev_.SD * xi_D;
      exact_ = lk.element->matrix_tangent(tv.X, tv.xi, at_K_[i].xi, xi_D, G_d, G_x) && exact_;
      Matrix6x dg_dq = G_d * tv.Jr + G_x * tv.dxi_dq + ev_.SK * at_K_[i].dxi_dq;
      if (damped) dg_dq.noalias() += ev_.SD * at_D_[i].dxi_dq;
      const Matrix6x dg_dv = G_x * tv.Jr;
      const Matrix6 dual = tv.X.toDualActionMatrix();
      dG_dq_.noalias() += tv.J_G.transpose() * dg_dq - tv.J_T.transpose() * (dual * (dg_dq + Kernel::force_cross_map(g) * tv.Jr));
      dG_dv_.noalias() += tv.J_G.transpose() * dg_dv - tv.J_T.transpose() * (dual * dg_dv);
      add_wrench(lk.grasp, g);
      add_wrench(lk.tip, -dual * g);
    }
    const VectorXd zero = VectorXd::Zero(nv);
    pinocchio::computeRNEADerivatives(*free_model_, *free_data_, q, zero, w_M, fext);
    dG_dq_ += free_data_->dtau_dq;
  }

  using Twist = Kernel::RelativeTwist;

  // Every link's relative kinematics at (q, w) (derivatives.py: relative_twist).
  void relative_twists(const VectorXd & q, const VectorXd & w, std::vector<Twist> & out) {
    const VectorXd zero = VectorXd::Zero(model_.nv);
    Data & data = *mdata_;
    pinocchio::computeForwardKinematicsDerivatives(model_, data, q, w, zero);  // (fills the joint Jacobians too)
    pinocchio::updateFramePlacements(model_, data);
    const auto & links = kernel_.links();
    out.resize(links.size());
    for (std::size_t i = 0; i < links.size(); ++i) Kernel::relative_twist(model_, data, links[i], out[i]);
  }

  // ∂G/∂p (nv, np) at the last matrix_derivatives (step_derivative.py: _matrix_parameters): a unit
  // law's Jrᵀ (S_K ξ_K + S_D ξ_D); the object's mass, ∂(M w_M)/∂m = J_jᵀ I₁ a_j with a_j the
  // object's body acceleration for q̈ = w_M at rest and I₁ its inertia per kg.
  MatrixXd matrix_parameters(const VectorXd & q, const VectorXd & w_M) {
    const Eigen::Index nv = model_.nv, np = static_cast<Eigen::Index>(params_.size());
    MatrixXd out = MatrixXd::Zero(nv, np);
    Matrix6x J(6, nv);
    const VectorXd zero = VectorXd::Zero(nv);
    for (Eigen::Index k = 0; k < np; ++k) {
      const Param & p = params_[static_cast<std::size_t>(k)];
      if (!p.law && !p.offset) {  // the object's mass
        pinocchio::forwardKinematics(model_, *data_, q, zero, w_M);
        pinocchio::computeJointJacobians(model_, *data_, q);
        J.setZero();
        pinocchio::getJointJacobian(model_, *data_, p.joint, pinocchio::LOCAL, J);
        out.col(k) = J.transpose() * (p.unit_inertia * data_->a[p.joint]).toVector();
        continue;
      }
      if (p.offset) {  // (step_derivative.py: _offset_matrices)
        const coopdyn::Element & element = *kernel_.links()[p.link].element;
        const Twist & tv = at_v_[p.link];
        const Vector6 xi_K = at_K_[p.link].xi, xi_D = element.damped() ? at_D_[p.link].xi : Vector6::Zero().eval();
        element.evaluate(tv.X, tv.xi, true, ev_);
        Matrix6 G_d, G_x;
        exact_ = element.matrix_tangent(tv.X, tv.xi, xi_K, xi_D, G_d, G_x) && exact_;
        const Matrix6 ad = Kernel::motion_cross(p.delta);
        const Vector6 g = ev_.SK * xi_K + ev_.SD * xi_D;
        const Vector6 dg = G_d * p.delta - G_x * (ad * tv.xi) - ev_.SK * (ad * xi_K) - ev_.SD * (ad * xi_D);
        out.col(k) = tv.Jr.transpose() * dg - (ad * tv.Jr).transpose() * g;
        continue;
      }
      const Twist & tK = at_K_[p.link];
      p.law->evaluate(tK.X, Vector6::Zero(), true, ev_);
      out.col(k) = tK.Jr.transpose() * (ev_.SK * tK.xi + ev_.SD * at_D_[p.link].xi);
    }
    return out;
  }

  // dq̈ = ∂q̈/∂q dq + ∂q̈/∂v dv + ∂q̈/∂τ dU + ∂q̈/∂p dP at the last stage() (a zero dU or dP skipped).
  void acceleration_derivative(const MatrixXd & dq, const MatrixXd & dv, const RefMat & dU, const RefMat & dP,
                               MatrixXd & out) const {
    out.noalias() = d_.da_dq * dq;
    out.noalias() += d_.da_dv * dv;
    if (!dU.isZero(0.0)) out.noalias() += d_.da_dtau * dU;
    if (dP.size() && !dP.isZero(0.0)) out.noalias() += da_dp_ * dP;
  }

  void keep_start() {
    start_wrench_ = d_.W;
    start_dW_dq_ = d_.dW_dq;
    start_dW_dv_ = d_.dW_dv;
    start_dW_dp_ = dW_dp_;
  }

  // Sample k: (q, v), the wrenches at the last keep_start() (the step's start, or the last stage()).
  void sample(Eigen::Index k, const VectorXd & q, const VectorXd & v, const MatrixXd & dq, const MatrixXd & dv,
              const RefMat & dP, MatrixXd & Q, MatrixXd & V, MatrixXd & W, MatrixXd & dX, MatrixXd & dW,
              bool wrench = true) {
    const Eigen::Index nv = model_.nv, L = static_cast<Eigen::Index>(kernel_.links().size());
    if (k == Q.rows() - 1) keep_start();  // (the end: stage() has just run there)
    Q.row(k) = q.transpose();
    V.row(k) = v.transpose();
    dX.middleRows(2 * nv * k, nv) = dq;
    dX.middleRows(2 * nv * k + nv, nv) = dv;
    if (!wrench) {
      W.row(k).setConstant(std::numeric_limits<double>::quiet_NaN());
      dW.middleRows(6 * L * k, 6 * L).setConstant(std::numeric_limits<double>::quiet_NaN());
      return;
    }
    for (Eigen::Index l = 0; l < L; ++l) W.block(k, 6 * l, 1, 6) = start_wrench_.row(l);
    dW.middleRows(6 * L * k, 6 * L) = start_dW_dq_ * dq + start_dW_dv_ * dv + start_dW_dp_ * dP;
  }

  // q ⊕ δ and its tangent derivative from q's (dq) and δ's (ddelta). dIntegrate is block
  // diagonal, joint by joint (the identity on a revolute or prismatic joint): applied block-wise.
  void integrate(const VectorXd & q, const VectorXd & delta, const MatrixXd & dq, const MatrixXd & ddelta, VectorXd & out,
                 MatrixXd & dout) {
    const Eigen::Index nv = model_.nv;
    out.resize(model_.nq);
    pinocchio::integrate(model_, q, delta, out);
    J0_.setZero(nv, nv);
    J1_.setZero(nv, nv);
    pinocchio::dIntegrate(model_, q, delta, J0_, pinocchio::ARG0);
    pinocchio::dIntegrate(model_, q, delta, J1_, pinocchio::ARG1);
    dout.resize(nv, dq.cols());
    for (pinocchio::JointIndex j = 1; j < model_.joints.size(); ++j) {
      const Eigen::Index i0 = model_.joints[j].idx_v(), n = model_.joints[j].nv();
      if (n == 1) {
        dout.row(i0) = J0_(i0, i0) * dq.row(i0) + J1_(i0, i0) * ddelta.row(i0);
        continue;
      }
      dout.middleRows(i0, n).noalias() = J0_.block(i0, i0, n, n) * dq.middleRows(i0, n);
      dout.middleRows(i0, n).noalias() += J1_.block(i0, i0, n, n) * ddelta.middleRows(i0, n);
    }
  }

  // The chart rate r = dexp⁻¹(δ) v and its derivative dr = ∂r/∂v dv + ∂r/∂δ dδ (the identity on
  // every joint but the free-flyer and spherical blocks; lie.py: dexp_inv_rate).
  void chart(const VectorXd & delta, const VectorXd & v, const MatrixXd & ddelta, const MatrixXd & dv, VectorXd & rate,
             MatrixXd & drate) const {
    using Complex = std::complex<double>;
    using Vector6c = Eigen::Matrix<Complex, 6, 1>;
    constexpr double step = 1e-30;
    rate = v;
    drate = dv;
    Eigen::Matrix<double, 6, 6> N;
    for (const auto & [i0, n] : charts_) {
      const int off = 6 - n;  // a spherical joint's δ is the rotation part of a logarithm
      Vector6 e = Vector6::Zero();
      e.tail(n) = delta.segment(i0, n);
      const Matrix6 J = coopdyn::jlog6_of_log<double>(e);
      rate.segment(i0, n) = J.bottomRightCorner(n, n) * v.segment(i0, n);
      const Eigen::Matrix<Complex, Eigen::Dynamic, 1> vc = v.segment(i0, n).cast<Complex>();
      for (int k = 0; k < n; ++k) {
        Vector6c ec = e.cast<Complex>();
        ec[off + k] += Complex(0.0, step);
        const Eigen::Matrix<Complex, 6, 6> Jc = coopdyn::jlog6_of_log<Complex>(ec);
        N.block(0, k, n, 1) = (Jc.bottomRightCorner(n, n) * vc).imag() / step;
      }
      drate.middleRows(i0, n).noalias() = J.bottomRightCorner(n, n) * dv.middleRows(i0, n);
      drate.middleRows(i0, n).noalias() += N.topLeftCorner(n, n) * ddelta.middleRows(i0, n);
    }
  }

  bp::object kernel_obj_;  // keeps the kernel alive
  Kernel & kernel_;
  const Model & model_;
  std::unique_ptr<Data> data_;  // scratch: the mass parameter's kinematics (only with one)
  bool symplectic_;
  std::vector<std::vector<double>> A_;
  std::vector<double> b_;
  std::vector<std::pair<Eigen::Index, int>> charts_;
  std::vector<Param> params_;
  bool exact_ = true;
  Kernel::Derivatives d_;
  MatrixXd da_dp_, dW_dp_, start_wrench_, start_dW_dq_, start_dW_dv_, start_dW_dp_;
  std::vector<VectorXd> kd_, ka_;
  std::vector<MatrixXd> dkd_, dka_;
  MatrixXd dka0_;
  MatrixXd J0_, J1_, G_;
  std::unique_ptr<Controller> ctrl_;
  ElementEval ev_;
  // a linearly implicit method: γ and its stages; generalized-α: (α_m, α_f, γ, β)
  double gamma_ = 0.0;
  int stages_ = 0;
  bool alpha_ = false;
  double am_ = 0.0, af_ = 0.0, ag_ = 0.0, ab_ = 0.0;
  std::unique_ptr<Model> free_model_;  // the model without gravity: RNEA(q, 0, a) = M a (implicit methods)
  std::unique_ptr<Data> free_data_;
  std::unique_ptr<Data> mdata_;  // scratch: the matrices' kinematics (implicit methods)
  VectorXd f_;
  MatrixXd M_, K_, D_, dG_dq_, dG_dv_;
  Eigen::LLT<MatrixXd> llt_S_;
  std::vector<Twist> at_v_, at_D_, at_K_;
  bool at_v_current_ = false;  // at_v_ is the current step's start's
  bool carried_ = false;  // generalized-α's acceleration, carried within a period
  VectorXd a_carry_;
  MatrixXd da_carry_;
};

}  // namespace coopdyn_native
