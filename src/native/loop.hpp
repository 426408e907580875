// The compiled step loop: coopdyn.simulate's loop (coopdyn/simulate.py) and energy monitor
// (coopdyn/monitor.py) in C++, for runs whose every piece is built in. It steps through a Method
// (methods/: the twins of coopdyn/integrators/, one header per family), calls a Controller
// (controllers/) and offers the methods its services: the closed loop's evaluations, the chart,
// the step matrix, the error norm. The same operations in the same order as the Python loop
// (but for the gravity note in controllers/gravity_pd.hpp), tested equal to round-off
// (tests/test_compiled_loop.py). It runs in chunks of steps with the GIL released; Python
// (coopdyn/compiled.py) turns what a chunk reports into samples, warnings and errors.
#pragma once

#include "controllers/controller.hpp"
#include "kernel.hpp"
#include "methods/method.hpp"

#include <pinocchio/algorithm/joint-configuration.hpp>

#include <Python.h>

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace coopdyn_native {

// What a chunk reports (coopdyn/compiled.py reads the names from _native.STATUSES).
enum Status { RUNNING = 0, DONE = 1, DIVERGED = 2, STEP_MATRIX = 3, ENERGY = 4, H_MIN = 5, CONTROLLER = 6, FAILED = 7, SCENE = 8 };
inline const char * const STATUS_NAMES[] = {"running", "done", "diverged", "step_matrix", "energy", "h_min", "controller", "failed", "scene"};

struct Event {  // a warning for Python to issue
  int kind;     // 0: rotation alarm (link, theta, t); 1: energy balance (t, dE, work, excess, scale)
  double a, b, c, d, e;
};

// The energy-balance monitor (coopdyn.monitor.EnergyMonitor), same arithmetic.
struct Monitor {
  bool on = false, raise = false;
  int every = 1;
  double rtol = 0.05, E0 = 0, peak = 0, scale = 0, work = 0, abs_work = 0, uncertainty = 0, max_excess = 0;
  bool has_pending = false, has_before = false, violated = false;
  double pending_h = 0, pending_p = 0, before_h = 0, before_p = 0;
  long steps = 0;
  // The step whose work the next step's start closes: h, Δq̇ on the actuated joints, τ at its
  // start and Δq̇ᵀ D̃ Δq̇ (EnergyMonitor._open).
  bool has_open = false;
  double open_h = 0, open_dissipation = 0;
  VectorXd open_dv, open_tau;

  // The open step's work taken at its mean velocity and torque: h/4 (Δq̇ᵀ D̃ Δq̇ − Δτ·Δq̇) added to
  // the point rule's, its torque ending at tau_end (EnergyMonitor._close_step).
  void close_step(const VectorXd & tau_end) {
    if (!has_open) return;
    const double input = (tau_end - open_tau).dot(open_dv);
    work += 0.25 * open_h * (open_dissipation - input);
    has_open = false;
  }

  // (p_next: the next interval's start power; fresh: after a jump of the held torques, no
  // three-point rule across it)
  void close_interval(double p_end, double h_next, bool has_next, double p_next, bool fresh) {
    if (has_pending) {
      const double h = pending_h, p = pending_p;
      double dw;
      if (has_before && std::abs(before_h - h) <= 1e-12 * h) {
        dw = h / 12.0 * (5.0 * p_end + 8.0 * p - before_p);
        uncertainty += h / 12.0 * std::abs(p_end - 2.0 * p + before_p);
      } else {
        dw = 0.5 * h * (p + p_end);
        uncertainty += 0.5 * h * std::abs(p_end - p);
      }
      work += dw;
      abs_work += std::abs(dw);
      has_before = true;
      before_h = pending_h;
      before_p = pending_p;
    }
    if (fresh) has_before = false;
    has_pending = has_next;
    pending_h = h_next;
    pending_p = p_next;
  }
};

class Loop {
  struct ControllerFailure : std::runtime_error {  // a built-in controller returned non-finite torques
    using std::runtime_error::runtime_error;
  };

public:
  Loop(Kernel & kernel, std::unique_ptr<Controller> controller, std::unique_ptr<Method> method, bool adaptive,
       int error_order, const VectorXd & kp, const VectorXd & kd, const VectorXd & q0, const VectorXd & v0, double dt,
       double t_final, long n_steps, long save_every, double max_speed, int energy_mode, long energy_every,
       double energy_rtol, double rtol, double atol, double h_min)
    : k_(kernel), model_(kernel.model()), ctrl_(std::move(controller)), method_(std::move(method)), adaptive_(adaptive),
      error_order_(error_order), kp_(kp), kd_(kd), dt_(dt), t_final_(t_final), n_steps_(n_steps), every_(save_every),
      max_speed_(max_speed), rtol_(rtol), atol_(atol), h_min_(h_min), q_(q0), v_(v0) {
    const auto nq = model_.nq, nv = model_.nv;
    na_ = kernel.actuated().size();
    act_ = kernel.actuated();
    tau_.setZero(na_);
    neutral_ = pinocchio::neutral(model_);
    for (pinocchio::JointIndex j = 1; j < model_.joints.size(); ++j)
      if (model_.joints[j].nv() > 1)
        chart_.push_back({model_.joints[j].idx_v(), model_.joints[j].nv(),
                          boost::get<pinocchio::JointModelFreeFlyer>(&model_.joints[j].toVariant()) != nullptr});
    other_charts_ = std::any_of(chart_.begin(), chart_.end(), [](const Chart & c) { return !c.free_flyer; });
    if (other_charts_) dI_.setZero(nv, nv);
    // the output grid
    if (adaptive_) {
      for (long k = every_; k < n_steps_; k += every_) outputs_.push_back(std::min(double(k) * dt_, t_final_));
      outputs_.push_back(std::min(double(n_steps_) * dt_, t_final_));
    }
    const long n_save = n_steps_ / every_ + 2;
    T_.reserve(n_save);
    Q_.reserve(n_save * nq);
    V_.reserve(n_save * nv);
    TAU_.reserve(n_save * na_);
    q_new_.setZero(nq);
    tmp2_.setZero(nv);
    v_new_.setZero(nv);
    monitor_.on = energy_mode > 0;
    monitor_.raise = energy_mode == 2;
    monitor_.every = static_cast<int>(std::max<long>(1, energy_every));
    monitor_.rtol = energy_rtol;
    start();
  }

  // Start again from (q0, v0) with the same settings, as a new Loop built from them would (the
  // method's carried state, the records, samples, events, counters and the energy monitor
  // forgotten; the buffers' memory kept): coopdyn.Simulator's runs after its first.
  void restart(const VectorXd & q0, const VectorXd & v0) {
    if (q0.size() != model_.nq || v0.size() != model_.nv)
      throw std::invalid_argument("Loop.restart: q0 must have nq entries and v0 nv entries");
    q_ = q0;
    v_ = v0;
    method_->new_run();
    k_.clear_rotation_alarm();  // (a step that diverged leaves it set: the next run starts clear)
    start();
  }

  // (the per-run state at (q_, v_), t = 0)
  void start() {
    j_out_ = 0;
    status_ = RUNNING;
    t_ = 0.0;
    h_ = first_h_;
    after_rejection_ = false;
    k_step_ = 0;
    n_rhs_ = n_jac_ = n_accepted_ = n_rejected_ = 0;
    n_factor_ = n_factor0_;
    have_first_ = pending_ = false;
    first_p_ = last_p_ = fsal_p_ = fsal_p_start_ = 0.0;
    T_.clear();
    Q_.clear();
    V_.clear();
    TAU_.clear();
    events_.clear();
    warned_.clear();
    message_.clear();
    fail_t_ = fail_h_ = 0.0;
    next_sample_ = 0;
    holding_ = false;
    sampled_at_ = std::numeric_limits<double>::quiet_NaN();
    const Monitor settings = monitor_;
    monitor_ = Monitor();
    monitor_.on = settings.on;
    monitor_.raise = settings.raise;
    monitor_.every = settings.every;
    monitor_.rtol = settings.rtol;
    if (monitor_.on) {
      double motion;
      monitor_.E0 = k_.total_energy(q_, v_, &motion);
      monitor_.peak = monitor_.scale = motion;
    }
    if (adaptive_) save(0.0, q_, v_, true);
  }

  // Run up to `budget` steps (attempts, for adaptive methods) with the GIL released — kept when
  // the controller is Python code, which takes it at every call (a hand-over each time would
  // cost more than the other threads gain) —; the status.
  int advance(long budget) {
    if (status_ != RUNNING) return status_;
    struct Released {  // the GIL, given back on every way out
      PyThreadState * state;
      explicit Released(bool release) : state(release ? PyEval_SaveThread() : nullptr) {}
      ~Released() {
        if (state) PyEval_RestoreThread(state);
      }
    } released(!ctrl_->calls_python());
    try {
      if (adaptive_)
        run_adaptive(budget);
      else
        run_fixed(budget);
    } catch (const ControllerFailure & e) {
      fail(CONTROLLER, e.what());
    } catch (const CallbackError & e) {
      fail(CONTROLLER, e.what());
    } catch (const StepMatrixError & e) {
      fail(STEP_MATRIX, e.what());
    } catch (const GraspGeometryError & e) {
      fail(SCENE, e.what());
    } catch (const std::exception & e) {
      fail(FAILED, e.what());
    } catch (...) {
      fail(FAILED, "unknown C++ exception");
    }
    return status_;
  }

  // The samples so far: t (n,), Q (n, nq), V (n, nv), TAU (n, n_actuated).
  bp::tuple samples() const {
    const Eigen::Index n = static_cast<Eigen::Index>(T_.size());
    using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    const VectorXd t = Eigen::Map<const VectorXd>(T_.data(), n);
    const MatrixXd Q = Eigen::Map<const RowMat>(Q_.data(), n, model_.nq);
    const MatrixXd V = Eigen::Map<const RowMat>(V_.data(), n, model_.nv);
    const MatrixXd TAU = Eigen::Map<const RowMat>(TAU_.data(), n, na_);
    return bp::make_tuple(t, Q, V, TAU, pending_);
  }

  // The samples so far except the last (which may still wait for its torque), removed from the
  // loop's buffers: a run streamed to disk keeps one sample in memory between chunks.
  bp::tuple take_samples() {
    const Eigen::Index n = static_cast<Eigen::Index>(T_.size()) - 1;
    const Eigen::Index m = n > 0 ? n : 0;
    using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    const VectorXd t = Eigen::Map<const VectorXd>(T_.data(), m);
    const MatrixXd Q = Eigen::Map<const RowMat>(Q_.data(), m, model_.nq);
    const MatrixXd V = Eigen::Map<const RowMat>(V_.data(), m, model_.nv);
    const MatrixXd TAU = Eigen::Map<const RowMat>(TAU_.data(), m, na_);
    if (m > 0) {
      T_.erase(T_.begin(), T_.begin() + m);
      Q_.erase(Q_.begin(), Q_.begin() + m * model_.nq);
      V_.erase(V_.begin(), V_.begin() + m * model_.nv);
      TAU_.erase(TAU_.begin(), TAU_.begin() + m * na_);
    }
    return bp::make_tuple(t, Q, V, TAU);
  }

  bp::list take_events() {
    bp::list out;
    for (const Event & e : events_) out.append(bp::make_tuple(e.kind, e.a, e.b, e.c, e.d, e.e));
    events_.clear();
    return out;
  }

  // (counters) n_rhs, n_jac, n_factor, n_accepted, n_rejected
  bp::tuple counters() const { return bp::make_tuple(n_rhs_, n_jac_, n_factor_, n_accepted_, n_rejected_); }
  // What stopped the run: (message, t, h, the failing state's q, v).
  bp::tuple failure() const { return bp::make_tuple(message_, fail_t_, fail_h_, q_fail_, v_fail_); }
  double time() const { return t_; }

  // ---------------------------------------------------------------- services for the methods
  // τ at (t, q, v) into tau(); `kinematics_done`: the kernel's kinematics are at (q, v) already.
  // Under a control_dt hold: the last sample's τ (System.torque).
  void torque(double t, const VectorXd & q, const VectorXd & v, bool kinematics_done = false) {
    if (holding_) {
      tau_ = tau_hold_;
      return;
    }
    if (!kinematics_done && ctrl_->reads_kernel()) k_.kinematics(q, v, false);
    ctrl_->torque(t, q, v, tau_);
    const double sq = tau_.dot(tau_);
    if (!std::isfinite(sq)) {
      std::string bad;
      for (Eigen::Index i = 0; i < tau_.size(); ++i)
        if (!std::isfinite(tau_[i])) bad += (bad.empty() ? "" : ", ") + std::to_string(i);
      // At a runaway state (an adaptive method's trial stage far past its stability limit) the
      // torques carry the state's overflow: the attempt is rejected, or the run reported diverged.
      if (!bad.empty() && sane(q, v)) {
        fail_t_ = t;
        throw ControllerFailure("[" + bad + "]");
      }
    }
  }
  const VectorXd & tau() const { return tau_; }
  // Whether (q, v) is finite and no faster than max_speed (System._sane).
  bool sane(const VectorXd & q, const VectorXd & v) const {
    return q.allFinite() && v.allFinite() && (v.size() == 0 || v.cwiseAbs().maxCoeff() <= max_speed_);
  }
  Eigen::Index n_actuated() const { return na_; }
  Kernel & kernel() { return k_; }
  // q̈ into `a`: one counted RHS evaluation, recorded.
  void acceleration(double t, const VectorXd & q, const VectorXd & v, VectorXd & a) {
    ++n_rhs_;
    kinematics_and_torque(t, q, v, false);
    a = k_.accel(q, v, tau_);
    record(v);
  }
  // f = M q̈, M, K̃, D̃ at (t, q, v), left in the kernel (f_terms(), mass(), stiffness(),
  // damping_matrix()): one counted RHS and Jacobian evaluation, recorded.
  void implicit_terms(double t, const VectorXd & q, const VectorXd & v) {
    ++n_rhs_;
    ++n_jac_;
    kinematics_and_torque(t, q, v, true);
    k_.terms(q, v, tau_);
    record(v);
    step_damping_ = true;
  }
  // Implicit Euler's v⁺ at (t, q, v) in one kernel call: RHS, Jacobian and factorisation, counted.
  void implicit_euler_velocity(double t, const VectorXd & q, const VectorXd & v, double h, VectorXd & v_new) {
    ++n_rhs_;
    ++n_jac_;
    ++n_factor_;
    kinematics_and_torque(t, q, v, true);
    k_.ie_velocity(q, v, tau_, h, kp_, kd_, v_new);
    record(v);
  }
  // One factorisation of the step matrix M + gh·D̃ + gh2·K̃ (with the controller's gains), counted.
  void factor(const MatrixXd & M, const MatrixXd & K, const MatrixXd & D, double gh, double gh2) {
    ++n_factor_;
    k_.factor(M, K, D, gh, kp_, kd_, gh2);
  }
  void count_rhs(long n) { n_rhs_ += n; }
  // The torque just computed is the step's start (a method that evaluates τ without q̈).
  void record_start_torque() {
    have_first_ = true;
    first_tau_ = tau_;
  }
  // The last evaluation's torque and power start the next attempt (first same as last).
  void keep_last_record() {
    fsal_p_ = last_p_;
    fsal_tau_ = last_tau_;
  }
  void integrate(const VectorXd & q, const VectorXd & dq, VectorXd & out) { pinocchio::integrate(model_, q, dq, out); }
  // δ̇ = dIntegrate(q₀, δ)⁻¹ v on the multi-DOF joints' blocks (a free flyer's block is Jexp6(δ),
  // which pinocchio::dIntegrate computes for it; the other joints' blocks come from dIntegrate).
  void chart_velocity(const VectorXd & q0, const VectorXd & delta, const VectorXd & v, VectorXd & out) {
    out = v;
    if (chart_.empty()) return;
    if (other_charts_) pinocchio::dIntegrate(model_, q0, delta, dI_, pinocchio::ARG1);
    for (const auto & [i0, n, free_flyer] : chart_) {
      if (free_flyer) {  // fixed size, no allocation
        Eigen::Matrix<double, 6, 6> J;
        pinocchio::Jexp6<pinocchio::SETTO>(pinocchio::Motion(Vector6(delta.segment<6>(i0))), J);
        out.segment<6>(i0) = J.partialPivLu().solve(v.segment<6>(i0));
      } else if (n == 6)
        out.segment<6>(i0) = Eigen::Matrix<double, 6, 6>(dI_.block<6, 6>(i0, i0)).partialPivLu().solve(v.segment<6>(i0));
      else if (n == 3)
        out.segment<3>(i0) = Eigen::Matrix3d(dI_.block<3, 3>(i0, i0)).partialPivLu().solve(v.segment<3>(i0));
      else
        out.segment(i0, n) = dI_.block(i0, i0, n, n).partialPivLu().solve(v.segment(i0, n));
    }
  }
  // RMS of the embedded error (e_d in the chart, e_v) scaled by atol + rtol·|y| (base.py: error_norm).
  double error_norm(const VectorXd & q0, const VectorXd & v0, const VectorXd & v1, const VectorXd & e_d,
                    const VectorXd & e_v) {
    pinocchio::difference(model_, neutral_, q0, tmp2_);
    double sum = 0.0;
    for (Eigen::Index i = 0; i < e_d.size(); ++i) {
      const double sc = atol_ + rtol_ * std::abs(tmp2_[i]);
      sum += (e_d[i] / sc) * (e_d[i] / sc);
    }
    double sum_v = 0.0;
    for (Eigen::Index i = 0; i < e_v.size(); ++i) {
      const double sc = atol_ + rtol_ * std::max(std::abs(v0[i]), std::abs(v1[i]));
      sum_v += (e_v[i] / sc) * (e_v[i] / sc);
    }
    return std::sqrt((sum + sum_v) / double(2 * e_v.size()));
  }

private:
  // The kernel's kinematics at (q, v) (with the joint Jacobians for the implicit terms), then τ
  // into tau_: what every evaluation starts with (Kernel's protocol).
  void kinematics_and_torque(double t, const VectorXd & q, const VectorXd & v, bool jacobians) {
    k_.kinematics(q, v, jacobians);
    torque(t, q, v, true);
  }
  double net_power(const VectorXd & v) const {
    double p = 0.0;
    for (Eigen::Index i = 0; i < na_; ++i) p += tau_[i] * v[act_[i]];
    return 0.0 + p - k_.last_dissipation();
  }
  void record(const VectorXd & v) {
    const double p = net_power(v);
    if (!have_first_) {
      have_first_ = true;
      first_p_ = p;
      first_tau_ = tau_;
    }
    last_p_ = p;
    last_tau_ = tau_;
  }
  // A step from (t, q, v) begins: the controller's sample is taken when one is due (System.begin_step).
  void begin_step(double t, const VectorXd & q, const VectorXd & v) {
    have_first_ = false;
    step_damping_ = false;
    if (sample(t, q, v)) method_->restart();
  }
  // With a control_dt: τ at (t, q, v), held, when t is on or past the next sample instant (to
  // 1e-9 of the period; System.sample); whether a sample was taken.
  bool sample(double t, const VectorXd & q, const VectorXd & v) {
    if (control_dt_ <= 0.0 || t < (double(next_sample_) - 1e-9) * control_dt_) return false;
    const bool held = holding_;
    holding_ = false;
    torque(t, q, v);
    if (held)
      jump_ = tau_ - tau_hold_;
    else
      jump_ = tau_;
    tau_hold_ = tau_;
    holding_ = true;
    sampled_at_ = t;
    next_sample_ = static_cast<long>(std::floor(t / control_dt_ + 1e-9)) + 1;
    return true;
  }
  double next_sample_time() const {
    return control_dt_ > 0.0 ? double(next_sample_) * control_dt_ : std::numeric_limits<double>::infinity();
  }
  // One step (fixed) or attempt (adaptive) from (t, q_, v_) into q_new_, v_new_; the error norm.
  double step(double t, double h) { return method_->step(*this, t, q_, v_, h, q_new_, v_new_); }

  double next_step(double h, double error) const {
    if (error == 0.0) return 5.0 * h;
    return h * std::min(5.0, std::max(0.2, 0.9 * std::pow(error, -1.0 / (error_order_ + 1))));
  }

  // ---------------------------------------------------------------- the loop's bookkeeping
  void save(double t, const VectorXd & q, const VectorXd & v, bool step_follows) {
    T_.push_back(t);
    Q_.insert(Q_.end(), q.data(), q.data() + q.size());
    V_.insert(V_.end(), v.data(), v.data() + v.size());
    if (step_follows) {
      TAU_.resize(TAU_.size() + na_, 0.0);
      pending_ = true;
    } else {
      torque(t, q, v);
      TAU_.insert(TAU_.end(), tau_.data(), tau_.data() + na_);
      pending_ = false;
    }
  }
  // The pending sample's torque: the step's own evaluation at its start.
  void settle(double t, bool reused_start) {
    if (!pending_) return;
    const VectorXd & tau = reused_start ? fsal_tau_start_ : first_tau_;
    if (!reused_start && !have_first_) {
      torque(t, Eigen::Map<const VectorXd>(&Q_[Q_.size() - model_.nq], model_.nq),
             Eigen::Map<const VectorXd>(&V_[V_.size() - model_.nv], model_.nv));
      std::copy(tau_.data(), tau_.data() + na_, TAU_.end() - na_);
    } else {
      std::copy(tau.data(), tau.data() + na_, TAU_.end() - na_);
    }
    pending_ = false;
  }
  double start_power(bool reused_start) const { return reused_start ? fsal_p_start_ : first_p_; }

  bool diverged(double t, const VectorXd & q, const VectorXd & v, double h) {
    if (v.squaredNorm() <= max_speed_ * max_speed_ && std::isfinite(q.squaredNorm())) return false;
    const bool finite = q.allFinite() && v.allFinite();
    if ((v.size() == 0 || v.cwiseAbs().maxCoeff() <= max_speed_) && finite) return false;
    message_ = finite ? "fast" : "non-finite";
    fail_t_ = t;
    fail_h_ = h;
    q_fail_ = q;
    v_fail_ = v;
    status_ = DIVERGED;
    return true;
  }

  void after_step(double t) {
    const int link = k_.rotation_alarm();
    if (link < 0) return;
    const double theta = k_.rotation_alarm_angle();
    k_.clear_rotation_alarm();
    if (std::find(warned_.begin(), warned_.end(), link) != warned_.end()) return;
    warned_.push_back(link);
    events_.push_back({0, double(link), theta, t, 0, 0});
  }

  void monitor_check(double t, const VectorXd & q, const VectorXd & v) {
    double motion;
    const double total = k_.total_energy(q, v, &motion);
    Monitor & m = monitor_;
    m.peak = std::max(m.peak, motion);
    m.scale = m.peak + m.abs_work;
    const double excess = (total - m.E0) - m.work;
    const double tol = m.rtol * m.scale + m.uncertainty + 1e-9 * (std::abs(m.E0) + 1.0);
    m.max_excess = std::max(m.max_excess, excess);
    if (excess > tol && !m.violated) {
      m.violated = true;
      events_.push_back({1, t, total - m.E0, m.work, excess, m.scale});
      if (m.raise) status_ = ENERGY;
    }
  }
  void monitor_after_step(double t0, const VectorXd & q0, const VectorXd & v0, const VectorXd & v1, double h,
                          bool reused_start) {
    const double p = start_power(reused_start);
    const VectorXd & tau = reused_start ? fsal_tau_start_ : first_tau_;  // (as settle())
    double jump = 0.0;  // a new control sample at t0: the last hold ends on the power before it
    const bool sampled = t0 == sampled_at_;
    if (sampled) {
      for (Eigen::Index i = 0; i < na_; ++i) jump += jump_[i] * v0[act_[i]];
      held_.noalias() = tau - jump_;  // (no allocation after the first)
      monitor_.close_step(held_);
    } else {
      monitor_.close_step(tau);
    }
    monitor_.close_interval(p - jump, h, true, p, sampled);
    Monitor & m = monitor_;
    if (step_damping_) {  // (a linearly implicit step's D̃; the other methods' work is the point rule's)
      dv_.noalias() = v1 - v0;
      m.open_h = h;
      m.open_dissipation = k_.damping_form(dv_, Ddv_);  // (Ddv_: scratch, no allocation after the first step)
      m.open_dv.resize(na_);
      for (Eigen::Index i = 0; i < na_; ++i) m.open_dv[i] = dv_[act_[i]];
      m.open_tau = tau;
      m.has_open = true;
    }
    ++m.steps;
    if (m.steps % m.every == 0) monitor_check(t0, q0, v0);
  }
  void monitor_finish(double t, const VectorXd & q, const VectorXd & v) {
    kinematics_and_torque(t, q, v, false);
    k_.accel(q, v, tau_);
    const double p = net_power(v);
    monitor_.close_step(tau_);
    monitor_.close_interval(p, 0.0, false, p, false);
    monitor_check(t, q, v);
  }

  void finish() {
    if (monitor_.on) monitor_finish(t_, q_, v_);
    if (status_ == RUNNING) status_ = DONE;
    settle_fresh();
  }

  void fail(int status, const std::string & message) {
    status_ = status;
    message_ = message;
    settle_fresh();
  }

  void settle_fresh() {
    if (pending_) {  // the last sample's torque, computed afresh
      const double t = fail_t_;
      try {
        torque(T_.back(), Eigen::Map<const VectorXd>(&Q_[Q_.size() - model_.nq], model_.nq),
               Eigen::Map<const VectorXd>(&V_[V_.size() - model_.nv], model_.nv));
        std::copy(tau_.data(), tau_.data() + na_, TAU_.end() - na_);
        pending_ = false;
      } catch (const std::exception &) {
        // left pending: Python evaluates it again, and a completed run (e.g. one of zero length,
        // whose only call is this one) raises the controller's error instead of keeping a zero
      }
      fail_t_ = t;
    }
  }

  // One accepted step's tail: checks, warnings, the monitor; false when the run must stop.
  bool accept(double t, double t_new, double h, bool reused_start) {
    if (diverged(t_new, q_new_, v_new_, h)) return false;
    after_step(t_new);
    if (monitor_.on) {
      monitor_after_step(t, q_, v_, v_new_, h, reused_start);
      if (status_ != RUNNING) return false;
    }
    t_ = t_new;
    q_.swap(q_new_);
    v_.swap(v_new_);
    ++n_accepted_;
    return true;
  }

  void run_fixed(long budget) {
    for (; budget > 0; --budget) {
      const long k = k_step_;
      if (k % every_ == 0 || k == n_steps_) save(t_, q_, v_, k < n_steps_);
      if (k == n_steps_) {
        finish();
        return;
      }
      const double h = std::min(dt_, t_final_ - double(k) * dt_);
      begin_step(t_, q_, v_);
      fail_t_ = t_;  // where a failing step started (a StepMatrixError reports it)
      fail_h_ = h;
      step(t_, h);
      settle(t_, false);
      const double t_new = (k + 1 == n_steps_) ? t_final_ : double(k + 1) * dt_;
      if (!accept(t_, t_new, h, false)) return;
      ++k_step_;
    }
  }

  void run_adaptive(long budget) {
    for (; budget > 0; --budget) {
      while (j_out_ < outputs_.size() && outputs_[j_out_] <= t_) ++j_out_;
      if (j_out_ == outputs_.size()) {
        finish();
        return;
      }
      begin_step(t_, q_, v_);  // (a controller's sample is due: taken here)
      // (a sample instant within 1e-9 of the period before an output time is that time: no ulp-long step)
      const double t_out = outputs_[j_out_], t_sample = next_sample_time();
      const double t_land = t_sample < t_out - 1e-9 * control_dt_ ? t_sample : t_out;
      double h_try = std::min(h_, t_land - t_);
      if (t_ + h_try * (1.0 + 1e-9) >= t_land) h_try = t_land - t_;  // land on the output time (or sample instant)
      fail_t_ = t_;
      fail_h_ = h_try;
      const bool reused = method_->reuses_start();
      if (reused) {
        fsal_p_start_ = fsal_p_;
        fsal_tau_start_ = fsal_tau_;
      }
      double err;
      try {
        err = step(t_, h_try);
        geometry_.clear();
      } catch (const GraspGeometryError & e) {  // a trial stage flung the grasps together (a step far too long
        err = std::numeric_limits<double>::infinity();  // for the stiffest mode): rejected, as a non-finite error
        geometry_ = e.what();  // (simulate.py: _adaptive_loop)
      }
      settle(t_, reused);
      h_ = next_step(h_try, err);
      if (!(err <= 1.0)) {
        method_->rejected();
        k_.clear_rotation_alarm();
        ++n_rejected_;
        after_rejection_ = true;
        if (h_ < h_min_) {  // a non-finite error shrinks the step (next_step: 0.2 h) like a large one
          if (!geometry_.empty()) {  // at every step down to h_min: the grasps' own geometry
            fail_t_ = t_;
            fail(SCENE, geometry_);
            return;
          }
          if (diverged(t_ + h_try, q_new_, v_new_, h_try)) return;
          fail_t_ = t_;
          status_ = H_MIN;
          return;
        }
        continue;
      }
      method_->accepted();
      if (after_rejection_) h_ = std::min(h_, h_try);  // no growth right after a rejection (simulate.py: _adaptive_loop)
      after_rejection_ = false;
      const double t_new = (h_try == t_land - t_) ? t_land : t_ + h_try;
      if (!accept(t_, t_new, h_try, reused)) return;
      if (t_ >= t_out) {
        save(t_, q_, v_, t_ < t_final_);
        ++j_out_;
      }
    }
  }

  Kernel & k_;
  const Model & model_;
  std::unique_ptr<Controller> ctrl_;
  std::unique_ptr<Method> method_;
  bool adaptive_;
  int error_order_;
  bool after_rejection_ = false;  // the step being attempted follows a rejected attempt
  std::string geometry_;  // why the last attempt failed, when the grasps' geometry did
  VectorXd kp_, kd_;
  double dt_, t_final_;
  long n_steps_, every_;
  double max_speed_, rtol_, atol_, h_min_;
  Eigen::Index na_ = 0;
  Eigen::VectorXi act_;
  VectorXd neutral_;
  struct Chart {
    Eigen::Index i0, n;  // the joint's velocity block
    bool free_flyer;
  };
  std::vector<Chart> chart_;  // the joints with more than one degree of freedom
  bool other_charts_ = false;  // one of them is not a free flyer: chart_velocity needs dIntegrate
  MatrixXd dI_;
  std::vector<double> outputs_;
  std::size_t j_out_ = 0;
  // state
  int status_ = RUNNING;
  double t_ = 0.0, h_ = 0.0, first_h_ = 0.0;
  long n_factor0_ = 0;  // (set_factorisations: the discretisations made before the run)
  long k_step_ = 0;
  VectorXd q_, v_, q_new_, v_new_;
  long n_rhs_ = 0, n_jac_ = 0, n_factor_ = 0, n_accepted_ = 0, n_rejected_ = 0;
  // the records of evaluations (System._first / _last)
  VectorXd tau_, first_tau_, last_tau_, fsal_tau_, fsal_tau_start_;
  double first_p_ = 0, last_p_ = 0, fsal_p_ = 0, fsal_p_start_ = 0;
  bool have_first_ = false, pending_ = false;
  VectorXd tmp2_;  // scratch of error_norm
  // outputs
  std::vector<double> T_, Q_, V_, TAU_;
  std::vector<Event> events_;
  std::vector<int> warned_;
  Monitor monitor_;
  bool step_damping_ = false;  // this step's implicit_terms() left its D̃ in the kernel
  VectorXd dv_, Ddv_, held_;   // (the monitor's scratch: a step's Δq̇, D̃ Δq̇, the held torque)
  std::string message_;
  double fail_t_ = 0.0, fail_h_ = 0.0;
  VectorXd q_fail_, v_fail_;

  // the controller's sample period (0: called at every evaluation), the next sample's index, the held τ
  double control_dt_ = 0.0;
  long next_sample_ = 0;
  bool holding_ = false;
  double sampled_at_ = std::numeric_limits<double>::quiet_NaN();  // the last sample's time
  VectorXd tau_hold_, jump_;  // the held τ, and how the last sample changed it

public:
  void set_first_step(double h) { h_ = first_h_ = h; }
  void set_control_period(double control_dt) { control_dt_ = control_dt; }
  void set_factorisations(long n) { n_factor_ = n_factor0_ = n; }
};

}  // namespace coopdyn_native
