// The scene dynamics' hot path: class Kernel (see kernel.cpp for the equations and the module).
#pragma once

#include <pinocchio/multibody.hpp>
#include <pinocchio/spatial.hpp>
#include <pinocchio/algorithm/center-of-mass.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/energy.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/aba-derivatives.hpp>
#include <pinocchio/algorithm/frames-derivatives.hpp>
#include <pinocchio/algorithm/kinematics-derivatives.hpp>

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <eigenpy/eigenpy.hpp>
#include <boost/python.hpp>

#include "aba.hpp"
#include "elements/element.hpp"
#include "elements/joint_springs.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <functional>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

namespace bp = boost::python;
using pinocchio::Data;
using pinocchio::FrameIndex;
using pinocchio::Model;
using pinocchio::SE3;
using coopdyn::ElementEval;
using coopdyn::Matrix6;
using coopdyn::Vector6;

using Matrix6x = Eigen::Matrix<double, 6, Eigen::Dynamic>;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using RefVec = Eigen::Ref<const VectorXd>;
using RefMat = Eigen::Ref<const MatrixXd>;
using SparseMatrix = Eigen::SparseMatrix<double>;

namespace coopdyn_native {

// The step matrix of a linearly implicit step is not positive definite (translated to
// coopdyn.errors.StepMatrixError).
struct StepMatrixError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The dynamics' derivatives are not finite at a state (a run that diverged).
struct NotFiniteError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Above this rotation of a deformation [rad] the SE(3) logarithm nears its jump at π.
constexpr double ROTATION_ALARM = 0.9 * M_PI;

struct Link {
  FrameIndex tip, grasp;
  std::unique_ptr<coopdyn::Element> element;
  // The v indices its Jr can reach (the joints that carry T or G), when they are few enough for
  // K̃ and D̃ to be assembled on them alone; empty: on every column (see Kernel::reach).
  std::vector<Eigen::Index> cols;
};

inline void check_size(const RefVec & x, Eigen::Index n, const char * name) {
  if (x.size() != n)
    throw std::invalid_argument(
      std::string(name) + " has " + std::to_string(x.size()) + " entries, expected " + std::to_string(n));
}

class Kernel {
public:
  // model: the scene's; link_model: the same without the elastic joints' motors, which come last
  // (Scene.link_model: its joints, frames and coordinates are the head of model's).
  Kernel(bp::object model_obj, bp::object data_obj, bp::list links, const RefVec & damping,
         const Eigen::Ref<const Eigen::VectorXi> & actuated, FrameIndex object_frame, const RefVec & joint_springs,
         bp::object link_model_obj)
    : model_obj_(model_obj), data_obj_(data_obj), link_model_obj_(link_model_obj),
      full_model_(bp::extract<const Model &>(model_obj)), full_data_(bp::extract<Data &>(data_obj)),
      model_(bp::extract<const Model &>(link_model_obj)),
      own_data_(model_.nv == full_model_.nv ? nullptr : std::make_unique<Data>(model_)),
      data_(own_data_ ? *own_data_ : full_data_), aba_(model_), nq_(full_model_.nq),
      nv_(full_model_.nv), nql_(model_.nq), nvl_(model_.nv), damping_(damping), actuated_(actuated),
      object_frame_(object_frame), springs_(joint_springs, full_model_.nq, full_model_.nv) {
    const auto nv = nv_;
    if (nql_ > nq_ || nvl_ > nv_ || model_.njoints > full_model_.njoints || model_.nframes > full_model_.nframes)
      throw std::invalid_argument("link_model must be the head of model");
    for (const auto & sp : springs_.springs)
      if (sp.motor_v < nvl_ || sp.link_v >= nvl_ || sp.motor_q < nql_ || sp.link_q >= nql_)
        throw std::invalid_argument("joint springs: the motors must come after link_model's coordinates");
    if (full_model_.nv - nvl_ != static_cast<Eigen::Index>(springs_.springs.size()))
      throw std::invalid_argument("every coordinate after link_model's must be a motor's");
    check_size(damping, nv, "damping");
    if (object_frame_ >= model_.frames.size()) throw std::invalid_argument("object_frame out of range");
    for (Eigen::Index i = 0; i < actuated_.size(); ++i)
      if (actuated_[i] < 0 || actuated_[i] >= nv) throw std::invalid_argument("actuated index out of range");
    for (bp::ssize_t i = 0; i < bp::len(links); ++i) {
      bp::tuple t = bp::extract<bp::tuple>(links[i]);
      Link lk;
      const std::string kind = bp::extract<std::string>(t[0]);
      lk.tip = bp::extract<FrameIndex>(t[1]);
      lk.grasp = bp::extract<FrameIndex>(t[2]);
      if (lk.tip >= model_.frames.size() || lk.grasp >= model_.frames.size())
        throw std::invalid_argument("link frame index out of range");
      lk.element = coopdyn::make_element(kind, bp::extract<bp::dict>(t[3]));
      lk.cols = reach(lk);
      links_.push_back(std::move(lk));
    }
    has_damping_ = !damping_.isZero(0.0);
    fext_.assign(model_.njoints, pinocchio::Force::Zero());
    gravity_axes(model_);
    J_G_.setZero(6, nvl_);
    J_T_.setZero(6, nvl_);
    SJ_.setZero(6, nvl_);
    Q_.setZero(nv);
    tau_full_.setZero(nv);
    K_t_.setZero(nv, nv);
    D_t_.setZero(nv, nv);
    // The elastic joints' motors: no element's Jacobian reaches them (they hang on the world, no
    // frame of an interconnection is theirs), their block of M is diagonal (B), and only their
    // springs couple them to the links — every Pinocchio pass runs on the links' model, each
    // motor is solved beside it, and the step matrix eliminates them in O(m) (factor()).
    eliminate_ = !springs_.empty();
    if (eliminate_) {  // each motor's B: its rotor's inertia about its axis (z), plus any armature
      B_.resize(nv_ - nvl_);
      for (pinocchio::JointIndex j = model_.njoints; j < full_model_.njoints; ++j) {
        const auto i = full_model_.joints[j].idx_v();
        B_[i - nvl_] = full_model_.inertias[j].inertia().matrix()(2, 2) + full_model_.armature[i];
      }
      M_.setZero(nv, nv);
      acc_.setZero(nv);
      tau_link_.setZero(nvl_);
    }
    sparse_pattern();
    blockwise_ = springs_.empty() &&
                 std::all_of(links_.begin(), links_.end(), [](const Link & lk) { return !lk.cols.empty(); });
  }

  VectorXd acceleration(const RefVec & q, const RefVec & v, const RefVec & tau, bp::object wrench) {
    const Vector6 w = object_wrench(wrench);
    kinematics(q, v, false);
    return forward_dynamics(v, tau, wrench.is_none() ? nullptr : &w);
  }

  // Q = Σ Jrᵀ G_f_G (nv), the interconnections' generalized force at (q, v), and the elastic
  // joints' springs'.
  VectorXd spring_force(const RefVec & q, const RefVec & v) {
    const VectorXd tau = VectorXd::Zero(actuated_.size());
    kinematics(q, v, true);
    generalized_force(v, tau, nullptr, false);
    VectorXd out = Q_;
    springs_.add_force(q, v, out);
    return out;
  }

  // g(q) on the actuated joints (n_actuated), as pinocchio::computeGeneralizedGravity.
  VectorXd gravity(const RefVec & q) {
    if (!kinematic_gravity())
      throw std::invalid_argument(
        "gravity: every actuated joint must be revolute, prismatic or helical (one degree of freedom, a constant "
        "axis) in a model without mimic joints");
    kinematics(q, VectorXd::Zero(nv_), false);
    return actuated_gravity(q);
  }

  // --- the C++ interface of the compiled step loop (loop.hpp): no Python objects, no wrench ---
  // Each evaluation is kinematics(q, v, ·), then what reads it (actuated_gravity, for a
  // controller), then accel, terms or ie_velocity at the same (q, v): one kinematics pass serves
  // the controller's gravity term and the elements.
  const Model & model() const { return full_model_; }
  Data & full_data() { return full_data_; }  // (the scene's Data: what compute_derivatives leaves)
  const std::vector<Link> & links() const { return links_; }
  // The scene's model without the elastic joints' motors (the same as model() without them): its
  // coordinates are the head of q and v, its joints and frames model()'s first — what a
  // controller that reads the links only needs, cheaper to run through.
  const Model & link_model() const { return model_; }

  // A pinocchio::Data of this kernel's model for a controller's own use, lent until the pointer
  // is destroyed and then kept for the next borrower: the loops that coopdyn.Simulator makes run
  // after run do not each build one (~25 µs on two Pandas). Every Pinocchio algorithm the
  // controllers call writes what it reads, so a lent Data computes what a fresh one would.
  using LentData = std::unique_ptr<Data, std::function<void(Data *)>>;
  // With `links`, a Data of link_model().
  LentData lend_data(bool links = false) {
    auto & spare = links ? spare_link_data_ : spare_data_;
    std::unique_ptr<Data> data;
    {
      const std::lock_guard<std::mutex> lock(spare_mutex_);
      if (!spare.empty()) {
        data = std::move(spare.back());
        spare.pop_back();
      }
    }
    if (!data) data = std::make_unique<Data>(links ? model_ : full_model_);
    return LentData(data.release(), [this, &spare](Data * returned) {
      const std::lock_guard<std::mutex> lock(spare_mutex_);
      spare.emplace_back(returned);
    });
  }
  const Eigen::VectorXi & actuated() const { return actuated_; }
  // Placements at q, and the joint velocities at v (for accel) or the joint Jacobians (for the
  // implicit terms).
  void kinematics(const RefVec & q, const RefVec & v, bool jacobians) {
    check_size(q, nq_, "q");
    check_size(v, nv_, "v");
    if (jacobians)
      pinocchio::computeJointJacobians(model_, data_, q.head(nql_));
    else
      pinocchio::forwardKinematics(model_, data_, q.head(nql_), v.head(nvl_));
    kinematics_ = jacobians ? JACOBIANS : VELOCITIES;
    kinematics_q_ = q;
  }
  // Whether actuated_gravity applies: every actuated joint has one degree of freedom and a
  // constant motion subspace (revolute, prismatic, helical), as URDF arms have, and no joint
  // mimics another.
  bool kinematic_gravity() const { return gravity_ok_; }
  // g(q) on the actuated joints from the placements of the last kinematics(), which must have
  // been at this q: the subtrees' masses and first moments, each joint's axis against their
  // weight. (A reference, valid until the next call.)
  const VectorXd & actuated_gravity(const VectorXd & q) {
    check_kinematics_at(q, "actuated_gravity");
    pinocchio::centerOfMass(model_, data_, pinocchio::POSITION, false);  // mass-weighted: no 0/0
    const Eigen::Vector3d & o_g = model_.gravity.linear();
    for (Eigen::Index i = 0; i < actuated_.size(); ++i) {
      const auto j = gravity_joint_[i];
      if (j == 0) {  // a motor: a rotor on the world, no weight
        g_act_[i] = 0.0;
        continue;
      }
      const Eigen::Vector3d j_g = data_.oMi[j].rotation().transpose() * o_g;
      const pinocchio::Motion & S = gravity_axis_[i];  // in joint j's frame, as data_.com[j]
      g_act_[i] = -(data_.mass[j] * S.linear().dot(j_g) + S.angular().dot(data_.com[j].cross(j_g)));
    }
    return g_act_;
  }
  // q̈ at (q, v, τ) after kinematics(q, v, false) (a reference into the Data, valid until the next call).
  const VectorXd & accel(const VectorXd & q, const VectorXd & v, const VectorXd & tau) {
    check_kinematics_at(q, "accel");
    return forward_dynamics(v, tau, nullptr);
  }
  // f = M q̈, M, K̃, D̃ at (q, v, τ) after kinematics(q, v, true), left in f_terms(), mass(),
  // stiffness(), damping().
  void terms(const VectorXd & q, const VectorXd & v, const VectorXd & tau) {
    check_kinematics_at(q, "terms");
    implicit_parts(q, v, tau, nullptr);
  }
  const VectorXd & f_terms() const { return tau_full_; }
  const MatrixXd & mass() const { return eliminate_ ? M_ : data_.M; }
  const MatrixXd & stiffness() const { return K_t_; }
  const MatrixXd & damping_matrix() const { return D_t_; }
  // M of the last terms() on the step matrix's sparse pattern (both triangles), when the scene has
  // one (a beam's: sparse_pattern()); mass() holds the same values.
  bool has_sparse_mass() const { return sparse_available_; }
  const SparseMatrix & sparse_mass() const { return M_sp_; }
  // Δq̇ᵀ D̃ Δq̇ [W] with the D̃ of the last terms(), for Δq̇ [m/s, rad/s]: on the pattern when
  // the scene has one (O(nnz), not O(nv²)); `scratch` for the dense product.
  double damping_form(const VectorXd & dv, VectorXd & scratch) const {
    if (!sparse_available_) {
      scratch.noalias() = D_t_ * dv;
      return dv.dot(scratch);
    }
    const auto * outer = M_sp_.outerIndexPtr();
    const auto * inner = M_sp_.innerIndexPtr();
    double sum = 0.0;
    for (Eigen::Index j = 0; j < nv_; ++j) {
      double col = 0.0;
      for (auto p = outer[j]; p < outer[j + 1]; ++p) col += D_t_(inner[p], j) * dv[inner[p]];
      sum += col * dv[j];
    }
    return sum;
  }
  // damping_form for Python: Δq̇ᵀ D̃ Δq̇ [W] with the D̃ of the last implicit_terms().
  double damping_form_given(const RefVec & dv) const {
    check_size(dv, nv_, "dv");
    VectorXd scratch;
    return damping_form(VectorXd(dv), scratch);
  }
  // k_v, k_q of the last factor() (see solve()).
  void solve_into(const VectorXd & f_q, const VectorXd & Mf_v, VectorXd & k_q, VectorXd & k_v) {
    step_rhs(Mf_v, gh_, f_q);
    step_solve(rhs_, k_v);
    k_q = f_q + gh_ * k_v;
  }
  // After kinematics(q, v, true).
  void ie_velocity(const VectorXd & q, const VectorXd & v, const VectorXd & tau, double h, const VectorXd & kp,
                   const VectorXd & kd, VectorXd & v_new) {
    check_kinematics_at(q, "ie_velocity");
    implicit_parts(q, v, tau, nullptr);
    factor(mass(), K_t_, D_t_, h, kp, kd, h * h);
    step_rhs(tau_full_, h, v);
    step_solve(rhs_, x_);
    v_new = v + h * x_;
  }
  // Kinetic + gravity + elastic energy at (q, v) [J], as Dynamics.energy.
  double total_energy(const VectorXd & q, const VectorXd & v, double * motion = nullptr) {
    kinematics_ = NONE;
    const double kinetic = pinocchio::computeKineticEnergy(model_, data_, q.head(nql_), v.head(nvl_)) + motor_energy(v);
    const double potential = pinocchio::computePotentialEnergy(model_, data_);
    const double u = elastic_energies().sum() + springs_.energy(q);
    if (motion) *motion = kinetic + u;
    return kinetic + potential + u;
  }

  // (f, M, K̃, D̃): f = Sτ + Q − Bq̇ − b(q, q̇) = M q̈ and the stiffness matrices (without gains).
  bp::tuple implicit_terms(const RefVec & q, const RefVec & v, const RefVec & tau, bp::object wrench) {
    const Vector6 w = object_wrench(wrench);
    kinematics(q, v, true);
    implicit_parts(q, v, tau, wrench.is_none() ? nullptr : &w);
    return bp::make_tuple(VectorXd(tau_full_), MatrixXd(mass()), MatrixXd(K_t_), MatrixXd(D_t_));
  }

  // factor() for matrices from Python, which need not have the motors' structure: checked, then
  // eliminated or not.
  void factor_given(const RefMat & M, const RefMat & K, const RefMat & D, double gh, const RefVec & kp, const RefVec & kd,
                    double gh2) {
    factor(M, K, D, gh, kp, kd, gh2, true);
  }

  // What factor() raises when the step matrix is not finite, or not positive definite.
  static StepMatrixError not_finite() { return StepMatrixError("the step matrix M + γh·D̃ + (γh)²·K̃ is not finite"); }
  static StepMatrixError not_positive_definite() {
    return StepMatrixError("the step matrix M + γh·D̃ + (γh)²·K̃ is not positive definite");
  }

  // Factorise S = M + gh (D̃ + Kd) + gh2 (K̃ + Kp) from the last implicit_terms (or given matrices);
  // gh2 = gh² but for generalized-α. The motors are eliminated: the kernel's own matrices have
  // their structure by construction (`check`: matrices from elsewhere are checked first).
  void factor(const RefMat & M, const RefMat & K, const RefMat & D, double gh, const RefVec & kp, const RefVec & kd,
              double gh2, bool check = false) {
    sparse_factored_ = factored_ = false;  // (until this factor succeeds: a failed one leaves nothing to solve with)
    check_size(kp, actuated_.size(), "kp");
    check_size(kd, actuated_.size(), "kd");
    const auto nv = nv_;
    if (M.rows() != nv || M.cols() != nv || K.rows() != nv || K.cols() != nv || D.rows() != nv || D.cols() != nv)
      throw std::invalid_argument("factor: M, K and D must be nv x nv");
    gh_ = gh;
    if (sparse_ && !check) {  // the kernel's own matrices: nonzero on the pattern sparse_pattern() found only
      if (!gather_step_matrix(M, K, D, gh, kp, kd, gh2)) throw not_finite();
      sllt_.factorize(S_sp_);
      if (sllt_.info() != Eigen::Success) throw not_positive_definite();
      eliminated_ = false;
      sparse_factored_ = factored_ = true;
      return;
    }
    Kg_ = K;
    S_ = M + gh * D;
    for (Eigen::Index i = 0; i < actuated_.size(); ++i) {
      Kg_(actuated_[i], actuated_[i]) += kp[i];
      S_(actuated_[i], actuated_[i]) += gh * kd[i];
    }
    S_.noalias() += gh2 * Kg_;
    if (!S_.allFinite()) throw not_finite();  // (LLT "succeeds" on NaN)
    eliminated_ = eliminate_ && (!check || motors_decoupled());
    if (eliminated_) {  // S = [S_ll S_lm; S_ml diag]: factor the links' Schur complement
      S_a_ = S_.topLeftCorner(nvl_, nvl_);
      for (const auto & sp : springs_.springs) {
        const double d = S_(sp.motor_v, sp.motor_v);
        if (!(d > 0.0)) throw not_positive_definite();
        S_a_(sp.link_v, sp.link_v) -= S_(sp.link_v, sp.motor_v) * S_(sp.motor_v, sp.link_v) / d;
      }
      llt_a_.compute(S_a_);
      if (llt_a_.info() != Eigen::Success) throw not_positive_definite();
      factored_ = true;
      return;
    }
    llt_.compute(S_);  // reads the lower triangle
    if (llt_.info() != Eigen::Success) throw not_positive_definite();
    factored_ = true;
  }

  // x = S⁻¹ b with the last factor(): the full Cholesky factor, or (motors eliminated) the
  // links' Schur complement then each motor from its own row.
  void step_solve(const VectorXd & b, VectorXd & x) {
    if (sparse_factored_) {
      x = sllt_.solve(b);
      return;
    }
    if (!eliminated_) {
      x = llt_.solve(b);
      return;
    }
    b_a_ = b.head(nvl_);
    for (const auto & sp : springs_.springs)
      b_a_[sp.link_v] -= S_(sp.link_v, sp.motor_v) * b[sp.motor_v] / S_(sp.motor_v, sp.motor_v);
    llt_a_.solveInPlace(b_a_);
    x.resize(b.size());
    x.head(nvl_) = b_a_;
    for (const auto & sp : springs_.springs)
      x[sp.motor_v] = (b[sp.motor_v] - S_(sp.motor_v, sp.link_v) * x[sp.link_v]) / S_(sp.motor_v, sp.motor_v);
  }

  // (k_q, k_v) of (I − γhJ) k = (f_q, f_v), given M f_v: S k_v = M f_v − γh K̃ f_q, k_q = f_q + γh k_v.
  bp::tuple solve(const RefVec & f_q, const RefVec & Mf_v) {
    if (!factored_) throw std::logic_error("solve before a successful factor");
    check_size(f_q, nv_, "f_q");
    check_size(Mf_v, nv_, "Mf_v");
    step_rhs(Mf_v, gh_, f_q);
    VectorXd k_v;
    step_solve(rhs_, k_v);
    return bp::make_tuple(VectorXd(f_q + gh_ * k_v), k_v);
  }

  // One linearly implicit Euler velocity update: v⁺ = v + h k_v with (f_q, f_v) = (v, M⁻¹f):
  // (M + h(D̃ + Kd) + h²(K̃ + Kp)) k_v = f − h (K̃ + Kp) v.
  VectorXd implicit_euler_velocity(const RefVec & q, const RefVec & v, const RefVec & tau, double h,
                                   const RefVec & kp, const RefVec & kd, bp::object wrench) {
    const Vector6 w = object_wrench(wrench);
    kinematics(q, v, true);
    implicit_parts(q, v, tau, wrench.is_none() ? nullptr : &w);
    factor(mass(), K_t_, D_t_, h, kp, kd, h * h);
    step_rhs(tau_full_, h, v);
    step_solve(rhs_, x_);
    return v + h * x_;
  }

  // ½ eᵀ K e of each link (n_links,) [J] at q (its own kinematics pass).
  VectorXd elastic_energies_at(const RefVec & q) {
    check_size(q, nq_, "q");
    kinematics_ = NONE;
    pinocchio::forwardKinematics(model_, data_, q.head(nql_));
    return elastic_energies();
  }
  // ½ eᵀ K e of each link (n_links,) [J] at the frame placements of the last kinematics pass.
  VectorXd elastic_energies() {
    VectorXd out(links_.size());
    const Vector6 zero = Vector6::Zero();
    for (std::size_t i = 0; i < links_.size(); ++i) {
      const Link & lk = links_[i];
      const SE3 & oMT = pinocchio::updateFramePlacement(model_, data_, lk.tip);
      const SE3 & oMG = pinocchio::updateFramePlacement(model_, data_, lk.grasp);
      lk.element->evaluate(oMT.actInv(oMG), zero, false, ev_);
      out[i] = ev_.energy;
    }
    return out;
  }

  // Every element's evaluation at (q, v): a list of (energy, deformation, G_f_G, power, S_K, S_D, θ).
  bp::list element_states(const RefVec & q, const RefVec & v) {
    check_size(q, nq_, "q");
    check_size(v, nv_, "v");
    kinematics_ = NONE;
    pinocchio::forwardKinematics(model_, data_, q.head(nql_), v.head(nvl_));
    bp::list out;
    for (const Link & lk : links_) {
      relative(lk, ev_, true);
      out.append(bp::make_tuple(ev_.energy, Vector6(ev_.deformation), Vector6(ev_.f), ev_.power, Matrix6(ev_.SK),
                                Matrix6(ev_.SD), ev_.theta));
    }
    return out;
  }

  // What derivatives() computes (see there); Minv is the whole M⁻¹ (symmetric).
  struct Derivatives {
    VectorXd a;
    MatrixXd da_dq, da_dv, da_dtau, Minv, W, dW_dq, dW_dv;
    bool exact = true;
  };

  // Exact ∂q̈/∂(q, v, τ) and every element's wrench G_f_G with its derivatives at (q, v, τ): the
  // twin of coopdyn/dynamics/derivatives.py, same equations (see there): the elements' wrenches as
  // body-fixed external forces of Pinocchio's ABA derivatives, plus M⁻¹ times their own variation
  // through Element::tangent. Returns (q̈ (nv), ∂q̈/∂q, ∂q̈/∂v (nv, nv), ∂q̈/∂τ (nv, na),
  // W (L, 6), ∂W/∂q, ∂W/∂v (6L, nv), exact).
  bp::tuple derivatives(const RefVec & q, const RefVec & v, const RefVec & tau, bp::object wrench) {
    check_size(q, full_model_.nq, "q");
    check_size(v, full_model_.nv, "v");
    check_size(tau, actuated_.size(), "tau");
    Vector6 w = Vector6::Zero();
    if (!wrench.is_none()) w = object_wrench(wrench);
    compute_derivatives(q, v, tau, wrench.is_none() ? nullptr : &w, derivatives_);
    const Derivatives & d = derivatives_;
    return bp::make_tuple(d.a, d.da_dq, d.da_dv, d.da_dtau, d.W, d.dW_dq, d.dW_dv, d.exact);
  }

  // A link's relative kinematics (derivatives.py: RelativeTwist): X = T_M_G, the frames' LOCAL
  // Jacobians, Ad(X⁻¹), Jr = J_G − Ad(X⁻¹) J_T, the twist ξ and ∂ξ/∂q at the velocity of the data's
  // last computeForwardKinematicsDerivatives (after updateFramePlacements too).
  struct RelativeTwist {
    SE3 X;
    Matrix6 Ad_inv;
    Matrix6x J_G, J_T, Jr, dxi_dq;
    Vector6 xi;
  };
  static void relative_twist(const Model & model, Data & data, const Link & lk, RelativeTwist & t) {
    const Eigen::Index nv = model.nv;
    Matrix6x dVG_dq = Matrix6x::Zero(6, nv), dVG_dv = Matrix6x::Zero(6, nv), dVT_dq = Matrix6x::Zero(6, nv),
             dVT_dv = Matrix6x::Zero(6, nv);
    t.X = data.oMf[lk.tip].actInv(data.oMf[lk.grasp]);
    t.J_G.setZero(6, nv);
    t.J_T.setZero(6, nv);
    pinocchio::getFrameJacobian(model, data, lk.grasp, pinocchio::LOCAL, t.J_G);
    pinocchio::getFrameJacobian(model, data, lk.tip, pinocchio::LOCAL, t.J_T);
    t.Ad_inv = t.X.toActionMatrixInverse();
    t.Jr = t.J_G - t.Ad_inv * t.J_T;
    pinocchio::getFrameVelocityDerivatives(model, data, lk.grasp, pinocchio::LOCAL, dVG_dq, dVG_dv);
    pinocchio::getFrameVelocityDerivatives(model, data, lk.tip, pinocchio::LOCAL, dVT_dq, dVT_dv);
    const Vector6 V_T = t.Ad_inv * pinocchio::getFrameVelocity(model, data, lk.tip, pinocchio::LOCAL).toVector();
    t.xi = pinocchio::getFrameVelocity(model, data, lk.grasp, pinocchio::LOCAL).toVector() - V_T;
    t.dxi_dq = dVG_dq - motion_cross(V_T) * t.Jr - t.Ad_inv * dVT_dq;
  }

  // derivatives() into `out`, for C++ callers (sensitivity.hpp); `wrench`: the object's external
  // wrench in world axes, or null. After it, full_data() holds the frames' placements and the
  // joint Jacobians at q.
  void compute_derivatives(const RefVec & q, const RefVec & v, const RefVec & tau, const Vector6 * wrench, Derivatives & out) {
    kinematics_ = NONE;
    const Eigen::Index nv = full_model_.nv, L = static_cast<Eigen::Index>(links_.size()), na = actuated_.size();
    pinocchio::computeForwardKinematicsDerivatives(full_model_, full_data_, q, v, VectorXd::Zero(nv));
    pinocchio::computeJointJacobians(full_model_, full_data_, q);
    pinocchio::updateFramePlacements(full_model_, full_data_);
    ForceList fext(full_model_.njoints, pinocchio::Force::Zero());
    MatrixXd dQ_dq = MatrixXd::Zero(nv, nv), dQ_dv = MatrixXd::Zero(nv, nv);
    dQ_dv.diagonal() = -damping_;
    MatrixXd & W = out.W;
    MatrixXd & dW_dq = out.dW_dq;
    MatrixXd & dW_dv = out.dW_dv;
    W.resize(L, 6);
    dW_dq.resize(6 * L, nv);
    dW_dv.resize(6 * L, nv);
    RelativeTwist rt;
    Matrix6 F_d, F_x;
    bool exact = true;
    auto add_wrench = [&](FrameIndex frame, const Vector6 & f) {
      const pinocchio::Frame & fr = full_model_.frames[frame];
      fext[fr.parentJoint] += fr.placement.act(pinocchio::Force(f));
    };
    for (Eigen::Index i = 0; i < L; ++i) {
      const Link & lk = links_[static_cast<std::size_t>(i)];
      relative_twist(full_model_, full_data_, lk, rt);
      const SE3 & X = rt.X;
      const Matrix6x &J_G = rt.J_G, &J_T = rt.J_T, &Jr = rt.Jr, &dxi_dq = rt.dxi_dq;
      const Vector6 & xi = rt.xi;
      lk.element->evaluate(X, xi, false, ev_);
      exact = lk.element->tangent(X, xi, F_d, F_x) && exact;
      const Matrix6x df_dq = F_d * Jr + F_x * dxi_dq, df_dv = F_x * Jr;
      const Matrix6 dual = X.toDualActionMatrix();
      const Vector6 f_G = ev_.f;
      dQ_dq.noalias() += J_G.transpose() * df_dq - J_T.transpose() * (dual * (df_dq + force_cross_map(f_G) * Jr));
      dQ_dv.noalias() += J_G.transpose() * df_dv - J_T.transpose() * (dual * df_dv);
      add_wrench(lk.grasp, f_G);
      add_wrench(lk.tip, -dual * f_G);
      W.row(i) = f_G.transpose();
      dW_dq.middleRows(6 * i, 6) = df_dq;
      dW_dv.middleRows(6 * i, 6) = df_dv;
    }
    if (wrench != nullptr) {  // constant in world axes: its body-axes value turns with the object
      const Vector6 & w = *wrench;
      const coopdyn::Matrix3 & R = full_data_.oMf[object_frame_].rotation();
      Vector6 f_o;
      f_o << R.transpose() * w.head<3>(), R.transpose() * w.tail<3>();
      Matrix6x J_o = Matrix6x::Zero(6, nv);
      pinocchio::getFrameJacobian(full_model_, full_data_, object_frame_, pinocchio::LOCAL, J_o);
      Matrix6 df = Matrix6::Zero();
      df.topRightCorner<3, 3>() = coopdyn::skew(f_o.head<3>());
      df.bottomRightCorner<3, 3>() = coopdyn::skew(f_o.tail<3>());
      dQ_dq.noalias() += J_o.transpose() * (df * J_o);
      add_wrench(object_frame_, f_o);
    }
    VectorXd tau_full = -damping_.cwiseProduct(v);
    for (Eigen::Index i = 0; i < na; ++i) tau_full[actuated_[i]] += tau[i];
    if (!springs_.empty()) {
      springs_.add_force(q, v, tau_full);
      MatrixXd K_s = MatrixXd::Zero(nv, nv), D_s = MatrixXd::Zero(nv, nv);
      springs_.add_matrices(K_s, D_s);
      dQ_dq -= K_s;
      dQ_dv -= D_s;
    }
    pinocchio::computeABADerivatives(full_model_, full_data_, q, v, tau_full, fext);
    MatrixXd & Minv = out.Minv;
    Minv = full_data_.Minv;
    Minv.triangularView<Eigen::StrictlyLower>() = Minv.transpose().triangularView<Eigen::StrictlyLower>();
    out.da_dq = full_data_.ddq_dq + Minv * dQ_dq;
    out.da_dv = full_data_.ddq_dv + Minv * dQ_dv;
    out.da_dtau.resize(nv, na);
    for (Eigen::Index i = 0; i < na; ++i) out.da_dtau.col(i) = Minv.col(actuated_[i]);
    if (!out.da_dq.allFinite() || !out.da_dv.allFinite() || !full_data_.ddq.allFinite())
      throw NotFiniteError("the dynamics' derivatives are not finite at this state");
    out.a = full_data_.ddq;
    out.exact = exact;
  }

  // ad(w) for a twist w = [v; ω] (derivatives.py: motion_cross).
  static Matrix6 motion_cross(const Vector6 & w) {
    Matrix6 out = Matrix6::Zero();
    out.topLeftCorner<3, 3>() = out.bottomRightCorner<3, 3>() = coopdyn::skew(w.tail<3>());
    out.topRightCorner<3, 3>() = coopdyn::skew(w.head<3>());
    return out;
  }
  // Λ(f) with Λ(f)·δ = δ ×* f for a wrench f = [force; torque] (derivatives.py: force_cross_map).
  static Matrix6 force_cross_map(const Vector6 & f) {
    Matrix6 out = Matrix6::Zero();
    out.topRightCorner<3, 3>() = out.bottomLeftCorner<3, 3>() = -coopdyn::skew(f.head<3>());
    out.bottomRightCorner<3, 3>() = -coopdyn::skew(f.tail<3>());
    return out;
  }

  // The readouts of a trajectory Q (n, nq), V (n, nv), one sample per row: deformations
  // (n, 6L, zero-padded), energies (n, L), dissipated powers (n, L), the wrench on the object at
  // G and on the arm at T, in world axes (n, 6L each), the positions of G and T (n, 3L each),
  // the object frame's position (n, 3), kinetic and gravity energy (n, 2).
  bp::tuple readouts(const RefMat & Q, const RefMat & V) {
    const Eigen::Index n = Q.rows(), L = static_cast<Eigen::Index>(links_.size());
    if (Q.cols() != nq_ || V.cols() != nv_ || V.rows() != n)
      throw std::invalid_argument("readouts: Q must be (n, nq) and V (n, nv)");
    kinematics_ = NONE;
    MatrixXd E(n, 6 * L), U(n, L), P(n, L), WG(n, 6 * L), WT(n, 6 * L), PG(n, 3 * L), PT(n, 3 * L), PO(n, 3), KP(n, 2);
    for (Eigen::Index k = 0; k < n; ++k) {
      const VectorXd q = Q.row(k).transpose(), v = V.row(k).transpose();
      pinocchio::forwardKinematics(model_, data_, q.head(nql_), v.head(nvl_));
      KP(k, 0) = pinocchio::computeKineticEnergy(model_, data_) + motor_energy(v);
      KP(k, 1) = pinocchio::computePotentialEnergy(model_, data_);
      PO.row(k) = pinocchio::updateFramePlacement(model_, data_, object_frame_).translation().transpose();
      for (Eigen::Index i = 0; i < L; ++i) {
        const Link & lk = links_[i];
        const SE3 T_M_G = relative(lk, ev_, false);
        const SE3 & oMT = data_.oMf[lk.tip];
        const SE3 & oMG = data_.oMf[lk.grasp];
        E.block<1, 6>(k, 6 * i) = ev_.deformation.transpose();
        U(k, i) = ev_.energy;
        P(k, i) = ev_.power;
        const pinocchio::Force f_G(ev_.f);
        const pinocchio::Force f_T = -T_M_G.act(f_G);  // action = reaction, in T
        WG.block<1, 3>(k, 6 * i) = (oMG.rotation() * f_G.linear()).transpose();
        WG.block<1, 3>(k, 6 * i + 3) = (oMG.rotation() * f_G.angular()).transpose();
        WT.block<1, 3>(k, 6 * i) = (oMT.rotation() * f_T.linear()).transpose();
        WT.block<1, 3>(k, 6 * i + 3) = (oMT.rotation() * f_T.angular()).transpose();
        PG.block<1, 3>(k, 3 * i) = oMG.translation().transpose();
        PT.block<1, 3>(k, 3 * i) = oMT.translation().transpose();
      }
    }
    return bp::make_tuple(E, U, P, WG, WT, PG, PT, PO, KP);
  }

  double last_dissipation() const { return last_dissipation_; }
  // Index of the first link whose rotation deformation passed 0.9π since the last clear, or −1.
  int rotation_alarm() const { return rotation_alarm_; }
  double rotation_alarm_angle() const { return rotation_alarm_angle_; }
  // Whether factor() takes the sparse Cholesky factor on the kernel's own matrices (sparse_pattern());
  // set False to take the dense one (benchmarks/beam_scale.py compares them), True to go back to
  // it — a scene without the pattern stays dense. The next factor() takes the change: a factor
  // and the solves that use it always agree, even when a run in another thread is under way.
  bool sparse_step_matrix() const { return sparse_; }
  void set_sparse_step_matrix(bool on) { sparse_ = on && sparse_available_; }
  void clear_rotation_alarm() { rotation_alarm_ = -1; rotation_alarm_angle_ = 0.0; }

  // Q = Σ Jrᵀ G_f_G at (q, v) after kinematics(q, v, false), without the Jacobians: the elements'
  // wrenches on the joints (as forward_dynamics applies them), summed over each joint's subtree
  // and projected on its motion subspace (one pass from the leaves). What a peer simulator adds
  // as passive force (coopdyn.mujoco); equal to spring_force to round-off (tests/test_mujoco.py).
  const VectorXd & passive_force() {
    if (kinematics_ != VELOCITIES) throw std::logic_error("passive_force needs kinematics(q, v, false) first");
    kinematics_ = NONE;
    link_wrenches();
    for (pinocchio::JointIndex j = model_.njoints - 1; j > 0; --j)
      ProjectForce::run(model_.joints[j], data_.joints[j], ProjectForce::ArgsType(model_, data_, fext_, Q_));
    Q_.tail(nv_ - nvl_).setZero();  // (the motors: no interconnection reaches them)
    return Q_;
  }

private:
  std::mutex spare_mutex_;
  std::vector<std::unique_ptr<Data>> spare_data_, spare_link_data_;  // lent out by lend_data(), back when returned

  static Vector6 object_wrench(bp::object wrench) {
    if (wrench.is_none()) return Vector6::Zero();
    const VectorXd w = bp::extract<VectorXd>(wrench)();
    if (w.size() != 6) throw std::invalid_argument("object wrench must have 6 entries");
    return w;
  }

  // Evaluate the element of link `lk` at the kinematics of the last forwardKinematics(q, v)
  // (updates the placements of T and G in data_.oMf), with ξ = V_G − Ad(T_M_G⁻¹) V_T = Jr q̇ from
  // the frame velocities; returns T_M_G. For the readouts and forward_dynamics (the implicit
  // terms, which need Jr itself, take ξ = Jr q̇ in generalized_force).
  SE3 relative(const Link & lk, ElementEval & ev, bool jacobians) {
    const SE3 & oMT = pinocchio::updateFramePlacement(model_, data_, lk.tip);
    const SE3 & oMG = pinocchio::updateFramePlacement(model_, data_, lk.grasp);
    const SE3 T_M_G = oMT.actInv(oMG);
    const pinocchio::Motion V_T = pinocchio::getFrameVelocity(model_, data_, lk.tip, pinocchio::LOCAL);
    const pinocchio::Motion V_G = pinocchio::getFrameVelocity(model_, data_, lk.grasp, pinocchio::LOCAL);
    lk.element->evaluate(T_M_G, (V_G - T_M_G.actInv(V_T)).toVector(), jacobians, ev);
    return T_M_G;
  }

  // q̈ at (q, v, τ) after kinematics(q, v, false): each element's wrench from the frames'
  // placements and velocities (as the readouts), applied to the joints carrying T and G as
  // external forces of the articulated-body algorithm; equal to Σ Jrᵀ G_f_G without the Jacobians.
  const VectorXd & forward_dynamics(const RefVec & v, const RefVec & tau, const Vector6 * wrench) {
    if (kinematics_ != VELOCITIES) throw std::logic_error("accel needs kinematics(q, v, false) first");
    kinematics_ = NONE;
    check_size(tau, actuated_.size(), "tau");
    const double p_diss = link_wrenches();
    if (wrench) {
      const pinocchio::Frame & object = model_.frames[object_frame_];
      fext_[object.parentJoint] += object.placement.act(pinocchio::Force(local_wrench(*wrench)));
    }
    tau_full_.setZero();
    joint_torques(v, tau, p_diss);
    if (!eliminate_) return aba_.accelerations(model_, data_, tau_full_, fext_);
    tau_link_ = tau_full_.head(nvl_);
    acc_.head(nvl_) = aba_.accelerations(model_, data_, tau_link_, fext_);
    for (Eigen::Index i = nvl_; i < nv_; ++i) acc_[i] = tau_full_[i] / B_[i - nvl_];  // B θ̈ = τ_m − τ_s − d_m θ̇
    return acc_;
  }

private:
  // f into Q through joint i's motion subspace, then onto its parent (leaves first).
  struct ProjectForce : pinocchio::fusion::JointUnaryVisitorBase<ProjectForce> {
    typedef boost::fusion::vector<const Model &, Data &, ForceList &, VectorXd &> ArgsType;
    template <typename JointModel>
    static void algo(const pinocchio::JointModelBase<JointModel> & jmodel,
                     pinocchio::JointDataBase<typename JointModel::JointDataDerived> & jdata, const Model & model,
                     Data & data, ForceList & f, VectorXd & Q) {
      const auto i = jmodel.id();
      jmodel.jointVelocitySelector(Q).noalias() = jdata.S().transpose() * f[i];
      if (model.parents[i] > 0) f[model.parents[i]] += data.liMi[i].act(f[i]);
    }
  };

  // Each element's wrench from the frames' placements and velocities (after kinematics(q, v,
  // false)) into fext_, on the joints carrying G and T; the elements' dissipated power [W].
  double link_wrenches() {
    for (pinocchio::Force & f : fext_) f.setZero();
    double p_diss = 0.0;
    for (std::size_t i = 0; i < links_.size(); ++i) {
      const Link & lk = links_[i];
      const SE3 T_M_G = relative(lk, ev_, false);
      const pinocchio::Force G_f_G(ev_.f);
      const pinocchio::Frame & grasp = model_.frames[lk.grasp];
      const pinocchio::Frame & tip = model_.frames[lk.tip];
      fext_[grasp.parentJoint] += grasp.placement.act(G_f_G);     // placement: jMG
      fext_[tip.parentJoint] -= tip.placement.act(T_M_G.act(G_f_G));  // action = reaction, in T
      p_diss += ev_.power;
      watch_rotation(i);
    }
    return p_diss;
  }

  // What the implicit methods need at (q, v), after kinematics(q, v, true): tau_full_ = f =
  // Sτ + Q − Bq̇ − b(q, q̇), K_t_, D_t_ and data_.M = M(q) with both triangles (crba fills the
  // upper one).
  void implicit_parts(const RefVec & q, const RefVec & v, const RefVec & tau, const Vector6 * wrench) {
    generalized_force(v, tau, wrench, true);
    tau_full_.head(nvl_) -= pinocchio::nonLinearEffects(model_, data_, q.head(nql_), v.head(nvl_));
    pinocchio::crba(model_, data_, RefVec(q.head(nql_)));  // (a Ref: the type Pinocchio's compiled crba takes)
    if (sparse_available_) {  // M is nonzero on the pattern only (crba writes each joint's row over its subtree)
      const auto * outer = M_sp_.outerIndexPtr();
      const auto * inner = M_sp_.innerIndexPtr();
      double * m = M_sp_.valuePtr();
      for (Eigen::Index j = 0; j < nv_; ++j)
        for (auto p = outer[j]; p < outer[j + 1]; ++p) {
          const Eigen::Index i = inner[p];
          m[p] = i > j ? (data_.M(i, j) = data_.M(j, i)) : data_.M(i, j);
        }
    } else {
      data_.M.triangularView<Eigen::StrictlyLower>() = data_.M.transpose().triangularView<Eigen::StrictlyLower>();
    }
    if (eliminate_) {  // M = diag(M_links, B)
      M_.topLeftCorner(nvl_, nvl_) = data_.M;
      M_.diagonal().tail(nv_ - nvl_) = B_;
    }
  }

  // After kinematics(q, v, true): tau_full_ = Sτ + Q − Bq̇ (+ the object wrench); with
  // `matrices`, also K_t_ = Σ Jrᵀ S_K Jr and D_t_ = Σ Jrᵀ S_D Jr + B.
  void generalized_force(const RefVec & v, const RefVec & tau, const Vector6 * wrench, bool matrices) {
    if (kinematics_ != JACOBIANS) throw std::logic_error("the implicit terms need kinematics(q, v, true) first");
    kinematics_ = NONE;
    check_size(tau, actuated_.size(), "tau");
    Q_.setZero();
    double p_diss = 0.0;
    if (matrices && blockwise_) {  // K̃ and D̃ are nonzero on the links' blocks and the diagonal only
      for (const Link & lk : links_)
        for (const auto b : lk.cols)
          for (const auto a : lk.cols) K_t_(a, b) = D_t_(a, b) = 0.0;
      D_t_.diagonal() = damping_;
    } else if (matrices) {
      K_t_.setZero();
      D_t_.setZero();
      D_t_.diagonal() = damping_;
    }
    for (std::size_t i = 0; i < links_.size(); ++i) {
      const Link & lk = links_[i];
      const SE3 & oMT = pinocchio::updateFramePlacement(model_, data_, lk.tip);
      const SE3 & oMG = pinocchio::updateFramePlacement(model_, data_, lk.grasp);
      const SE3 T_M_G = oMT.actInv(oMG);
      const Vector6 xi = relative_jacobian(lk, T_M_G, v);
      lk.element->evaluate(T_M_G, xi, matrices, ev_);
      if (lk.cols.empty())
        Q_.head(nvl_).noalias() += J_G_.transpose() * ev_.f;
      else
        for (const auto c : lk.cols) Q_[c] += J_G_.col(c).dot(ev_.f);
      p_diss += ev_.power;
      watch_rotation(i);
      if (matrices && !lk.cols.empty()) {  // on the columns Jr reaches: O(1) per element of a beam
        add_on_columns(lk.cols, ev_.SK, K_t_);
        if (lk.element->damped()) add_on_columns(lk.cols, ev_.SD, D_t_);
      } else if (matrices) {  // (over the links' columns: Jr is zero in the motors')
        SJ_ = ev_.SK.lazyProduct(J_G_);
        K_t_.topLeftCorner(nvl_, nvl_) += J_G_.transpose().lazyProduct(SJ_);
        if (lk.element->damped()) {
          SJ_ = ev_.SD.lazyProduct(J_G_);
          D_t_.topLeftCorner(nvl_, nvl_) += J_G_.transpose().lazyProduct(SJ_);
        }
      }
    }
    if (wrench) {
      const Vector6 local = local_wrench(*wrench);
      J_G_.setZero();
      pinocchio::getFrameJacobian(model_, data_, object_frame_, pinocchio::LOCAL, J_G_);
      Q_.head(nvl_).noalias() += J_G_.transpose() * local;
    }
    tau_full_ = Q_;
    joint_torques(v, tau, p_diss);
    if (matrices) springs_.add_matrices(K_t_, D_t_);
  }

  // Jr = J_G − Ad(T_M_G⁻¹) J_T of link `lk` into J_G_ (after kinematics(q, v, true)), and ξ = Jr q̇:
  // on its Link::cols when it has them (Pinocchio writes a frame's supporting columns only; the
  // other columns of J_G_ and J_T_ are left as they were and never read: O(1) per beam element),
  // on every column otherwise (lazy products: cheaper than GEMM at 6 × nv).
  Vector6 relative_jacobian(const Link & lk, const SE3 & T_M_G, const RefVec & v) {
    if (lk.cols.empty()) {
      J_G_.setZero();
      J_T_.setZero();
      pinocchio::getFrameJacobian(model_, data_, lk.grasp, pinocchio::LOCAL, J_G_);
      pinocchio::getFrameJacobian(model_, data_, lk.tip, pinocchio::LOCAL, J_T_);
      J_G_ -= T_M_G.toActionMatrixInverse().lazyProduct(J_T_);
      return J_G_ * v.head(nvl_);
    }
    for (const auto c : lk.cols) {
      J_G_.col(c).setZero();
      J_T_.col(c).setZero();
    }
    pinocchio::getFrameJacobian(model_, data_, lk.grasp, pinocchio::LOCAL, J_G_);
    pinocchio::getFrameJacobian(model_, data_, lk.tip, pinocchio::LOCAL, J_T_);
    const Matrix6 Ad = T_M_G.toActionMatrixInverse();
    Vector6 xi = Vector6::Zero();
    for (const auto c : lk.cols) {
      J_G_.col(c) -= Ad.lazyProduct(J_T_.col(c));
      xi += J_G_.col(c) * v[c];
    }
    return xi;
  }

  // Whether the step matrix S = M + γh (D̃ + Kd) + (γh)² (K̃ + Kp) is sparse enough for a sparse
  // Cholesky factor (sparse_, and its pattern in S_sp_, analysed once): M couples a joint's
  // coordinates with its ancestors' only (CRBA), each link's K̃ and D̃ its Link::cols, the gains
  // and the joints' damping the diagonal. A beam's nodes hang on the world and its elements join
  // neighbours: S is block-tridiagonal but for the arms and the grasps, and AMD ordering keeps its
  // factor O(n) where the dense one is O(n³). Dense when the pattern fills more than a third of
  // S, below 48 coordinates, with motors (they are eliminated instead) or a link that reaches
  // every column.
  void sparse_pattern() {
    sparse_ = sparse_available_ = false;
    const Eigen::Index nv = nv_;
    if (eliminate_ || nv < 48) return;
    for (const Link & lk : links_)
      if (lk.cols.empty()) return;
    using Pattern = Eigen::Matrix<bool, Eigen::Dynamic, Eigen::Dynamic>;
    Pattern on = Pattern::Zero(nv, nv);
    on.diagonal().setConstant(true);
    for (pinocchio::JointIndex jb = 1; jb < model_.joints.size(); ++jb)
      for (auto ja = jb; ja > 0; ja = model_.parents[ja])
        for (int a = 0; a < model_.joints[ja].nv(); ++a)
          for (int b = 0; b < model_.joints[jb].nv(); ++b) {
            const auto i = model_.joints[ja].idx_v() + a, j = model_.joints[jb].idx_v() + b;
            on(i, j) = on(j, i) = true;
          }
    for (const Link & lk : links_)
      for (const auto i : lk.cols)
        for (const auto j : lk.cols) on(i, j) = true;
    std::vector<Eigen::Triplet<double>> lower;
    for (Eigen::Index j = 0; j < nv; ++j)
      for (Eigen::Index i = j; i < nv; ++i)
        if (on(i, j)) lower.emplace_back(i, j, 1.0);
    if (3 * (2 * static_cast<Eigen::Index>(lower.size()) - nv) > nv * nv) return;
    S_sp_.resize(nv, nv);
    S_sp_.setFromTriplets(lower.begin(), lower.end());
    S_sp_.makeCompressed();
    sllt_.analyzePattern(S_sp_);
    if (sllt_.info() != Eigen::Success) return;
    std::vector<Eigen::Triplet<double>> full;
    for (Eigen::Index j = 0; j < nv; ++j)
      for (Eigen::Index i = 0; i < nv; ++i)
        if (on(i, j)) full.emplace_back(i, j, 0.0);
    Kg_sp_.resize(nv, nv);
    Kg_sp_.setFromTriplets(full.begin(), full.end());
    Kg_sp_.makeCompressed();
    M_sp_ = Kg_sp_;
    s_diag_.resize(actuated_.size());
    kg_diag_.resize(actuated_.size());
    for (Eigen::Index a = 0; a < actuated_.size(); ++a) {
      const auto c = actuated_[a];
      s_diag_[a] = S_sp_.outerIndexPtr()[c];  // (a column's lower triangle starts at its diagonal)
      kg_diag_[a] = Kg_sp_.outerIndexPtr()[c + 1] - (S_sp_.outerIndexPtr()[c + 1] - S_sp_.outerIndexPtr()[c]);
    }
    sparse_ = sparse_available_ = true;
  }

  // S_sp_ = the lower triangle of M + γh (D̃ + Kd) + (γh)² (K̃ + Kp) and Kg_sp_ = K̃ + Kp on the
  // pattern (the same operations, in the same order, as the dense S_ and Kg_); false if not finite.
  // Column j of the full pattern ends with the entries of its lower triangle, S_sp_'s column j.
  bool gather_step_matrix(const RefMat & M, const RefMat & K, const RefMat & D, double gh, const RefVec & kp,
                          const RefVec & kd, double gh2) {
    const auto * s_outer = S_sp_.outerIndexPtr();
    const auto * s_inner = S_sp_.innerIndexPtr();
    const auto * k_outer = Kg_sp_.outerIndexPtr();
    const auto * k_inner = Kg_sp_.innerIndexPtr();
    double * s = S_sp_.valuePtr();
    double * kg = Kg_sp_.valuePtr();
    for (Eigen::Index j = 0; j < nv_; ++j) {
      for (auto p = k_outer[j]; p < k_outer[j + 1]; ++p) kg[p] = K(k_inner[p], j);
      for (auto p = s_outer[j]; p < s_outer[j + 1]; ++p) s[p] = M(s_inner[p], j) + gh * D(s_inner[p], j);
    }
    for (Eigen::Index a = 0; a < actuated_.size(); ++a) {
      kg[kg_diag_[a]] += kp[a];
      s[s_diag_[a]] += gh * kd[a];
    }
    bool finite = true;
    for (Eigen::Index j = 0; j < nv_; ++j) {
      const auto shift = k_outer[j + 1] - s_outer[j + 1];  // S's entry p is K_g's p + shift
      for (auto p = s_outer[j]; p < s_outer[j + 1]; ++p) {
        s[p] += gh2 * kg[p + shift];
        finite = finite && std::isfinite(s[p]);
      }
    }
    for (Eigen::Index p = 0; p < Kg_sp_.nonZeros(); ++p) finite = finite && std::isfinite(kg[p]);
    return finite;
  }

  // rhs_ = a − c K_g x with the last factor()'s K_g (K̃ + Kp): sparse after a sparse factor.
  void step_rhs(const VectorXd & a, double c, const VectorXd & x) {
    if (sparse_factored_) {
      rhs_ = a;
      rhs_.noalias() -= c * (Kg_sp_ * x);
    } else {
      rhs_.noalias() = a - c * (Kg_ * x);
    }
  }

  // The v indices of the joints that carry a link's frames T and G and of their ancestors — the
  // only columns its Jr = J_G − Ad J_T can fill — when they are at most half of the links' model's
  // (a beam element reaches its two nodes' 12 of 6 per node; two arms and a box, 13 of 20: dense
  // products are cheaper there); empty otherwise, or with mimic joints (their columns are shared).
  std::vector<Eigen::Index> reach(const Link & lk) const {
    std::vector<Eigen::Index> cols;
    if (!model_.mimicking_joints.empty()) return cols;
    for (const FrameIndex f : {lk.tip, lk.grasp})
      for (auto j = model_.frames[f].parentJoint; j > 0; j = model_.parents[j])
        for (int k = 0; k < model_.joints[j].nv(); ++k) cols.push_back(model_.joints[j].idx_v() + k);
    std::sort(cols.begin(), cols.end());
    cols.erase(std::unique(cols.begin(), cols.end()), cols.end());
    if (2 * static_cast<Eigen::Index>(cols.size()) > nvl_) cols.clear();
    return cols;
  }

  // out(c, c) += Jr(:, c)ᵀ S Jr(:, c) for Jr in J_G_, on the columns c it reaches (Link::cols).
  void add_on_columns(const std::vector<Eigen::Index> & c, const Matrix6 & S, MatrixXd & out) {
    const auto m = static_cast<Eigen::Index>(c.size());
    for (Eigen::Index a = 0; a < m; ++a) J_T_.col(a) = J_G_.col(c[a]);  // (J_T_ is free after Jr)
    SJ_.leftCols(m).noalias() = S * J_T_.leftCols(m);
    for (Eigen::Index b = 0; b < m; ++b)
      for (Eigen::Index a = 0; a < m; ++a) out(c[a], c[b]) += J_T_.col(a).dot(SJ_.col(b));
  }

  // A world-axes wrench at the object frame, in the object frame's axes (updates its placement).
  Vector6 local_wrench(const Vector6 & w) {
    const auto & R = pinocchio::updateFramePlacement(model_, data_, object_frame_).rotation();
    Vector6 local;
    local.head<3>().noalias() = R.transpose() * w.head<3>();
    local.tail<3>().noalias() = R.transpose() * w.tail<3>();
    return local;
  }

  // tau_full_ += Sτ − Bq̇ + the elastic joints' springs at (q of the last kinematics, v);
  // last_dissipation_ = p_diss + q̇ᵀBq̇ + the springs' damping power.
  void joint_torques(const RefVec & v, const RefVec & tau, double p_diss) {
    for (Eigen::Index i = 0; i < actuated_.size(); ++i) tau_full_[actuated_[i]] += tau[i];
    if (has_damping_) {
      tau_full_.array() -= damping_.array() * v.array();
      p_diss += (damping_.array() * v.array().square()).sum();
    }
    if (!springs_.empty()) p_diss += springs_.add_force(kinematics_q_, v, tau_full_);
    last_dissipation_ = p_diss;
  }

  // The loop's protocol (kinematics at q, then what reads it at the same q): a C++ caller that
  // breaks it is a bug, not a user error. Compared bit for bit, so a NaN q still matches its own pass.
  void check_kinematics_at(const VectorXd & q, const char * reader) const {
    if (kinematics_ == NONE) throw std::logic_error(std::string(reader) + " before kinematics");
    if (q.size() != kinematics_q_.size() ||
        std::memcmp(q.data(), kinematics_q_.data(), sizeof(double) * static_cast<std::size_t>(q.size())) != 0)
      throw std::logic_error(std::string(reader) + " at another q than the last kinematics pass");
  }

  void watch_rotation(std::size_t link) {
    if (ev_.theta > ROTATION_ALARM && rotation_alarm_ < 0) {
      rotation_alarm_ = static_cast<int>(link);
      rotation_alarm_angle_ = ev_.theta;
    }
  }

  // For actuated_gravity: each actuated joint and its (constant) motion subspace; gravity_ok_
  // when every actuated joint qualifies and no joint mimics another (a mimic joint's weight
  // would act through joints this formula does not see).
  void gravity_axes(const Model & model) {
    static const char * const constant_axis[] = {
      "JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned", "JointModelRUBX",
      "JointModelRUBY", "JointModelRUBZ", "JointModelRevoluteUnboundedUnaligned", "JointModelPX", "JointModelPY",
      "JointModelPZ", "JointModelPrismaticUnaligned", "JointModelHX", "JointModelHY", "JointModelHZ",
      "JointModelHelicalUnaligned"};
    Data tmp(model);
    pinocchio::forwardKinematics(model, tmp, pinocchio::neutral(model));
    g_act_.setZero(actuated_.size());
    gravity_ok_ = model.mimicking_joints.empty();
    if (!gravity_ok_) return;
    for (Eigen::Index i = 0; i < actuated_.size(); ++i) {
      if (actuated_[i] >= nvl_) {  // a motor (after the links' model): no weight (actuated_gravity)
        gravity_joint_.push_back(0);
        gravity_axis_.emplace_back(Vector6::Zero());
        continue;
      }
      pinocchio::JointIndex joint = 0;
      for (pinocchio::JointIndex j = 1; j < model.joints.size(); ++j)
        if (model.joints[j].idx_v() <= actuated_[i] && actuated_[i] < model.joints[j].idx_v() + model.joints[j].nv())
          joint = j;
      const std::string kind = joint ? model.joints[joint].shortname() : "";
      if (!joint || model.joints[joint].nv() != 1 ||
          std::find(std::begin(constant_axis), std::end(constant_axis), kind) == std::end(constant_axis)) {
        gravity_ok_ = false;
        gravity_joint_.clear();
        gravity_axis_.clear();
        return;
      }
      gravity_joint_.push_back(joint);
      gravity_axis_.emplace_back(Vector6(tmp.joints[joint].S().matrix().col(0)));
    }
  }

  bp::object model_obj_, data_obj_, link_model_obj_;  // keep the Python objects alive
  const Model & full_model_;  // the scene's (derivatives; the controllers' model())
  Data & full_data_;
  const Model & model_;  // the links' (every pass of the hot path: the head of q and v)
  // Its Data: the scene's own (Dynamics.data: its readers see the state of the last evaluation)
  // when there are no motors, else one of the kernel's (readers do their own kinematics pass)
  std::unique_ptr<Data> own_data_;
  Data & data_;
  ArticulatedBody aba_;
  Eigen::Index nq_, nv_, nql_, nvl_;  // the scene's sizes, the links' model's
  std::vector<Link> links_;
  VectorXd damping_;
  Eigen::VectorXi actuated_;
  FrameIndex object_frame_;
  coopdyn::JointSprings springs_;
  bool has_damping_ = false;
  double last_dissipation_ = 0.0;
  int rotation_alarm_ = -1;
  double rotation_alarm_angle_ = 0.0;
  enum Kinematics { NONE, VELOCITIES, JACOBIANS } kinematics_ = NONE;  // what data_ holds for the next step
  VectorXd kinematics_q_;  // the q of the last kinematics()
  ForceList fext_;
  bool gravity_ok_ = false;
  std::vector<pinocchio::JointIndex> gravity_joint_;
  std::vector<pinocchio::Motion> gravity_axis_;
  VectorXd g_act_;
  ElementEval ev_;
  Derivatives derivatives_;
  Matrix6x J_G_, J_T_, SJ_;
  VectorXd Q_, tau_full_, rhs_;
  MatrixXd K_t_, D_t_, S_, Kg_;
  double gh_ = 0.0;
  bool factored_ = false;
  Eigen::LLT<MatrixXd> llt_;
  // the step matrix's sparse Cholesky factor (sparse_pattern()): its pattern, S's lower triangle
  // gathered into it at each factor(), and whether the last factor() took it
  std::atomic<bool> sparse_{false};  // (set from Python while a loop may run in another thread)
  bool sparse_available_ = false, sparse_factored_ = false;
  SparseMatrix S_sp_;
  // With the pattern: K_g of the last sparse factor() and M of the last implicit terms on the full
  // pattern (both triangles), the actuated coordinates' diagonal entries in S_sp_ and Kg_sp_, and
  // whether K̃ and D̃ are zeroed on the links' blocks alone (every link's columns known, no motors)
  SparseMatrix Kg_sp_, M_sp_;
  std::vector<Eigen::Index> s_diag_, kg_diag_;
  bool blockwise_ = false;
  Eigen::SimplicialLLT<SparseMatrix, Eigen::Lower, Eigen::AMDOrdering<SparseMatrix::StorageIndex>> sllt_;
  // the motors (the coordinates after the links' model's): whether the scene has any and whether
  // the last factor() eliminated them; their inertias B; M = diag(M_links, B); q̈ and the links' τ
  bool eliminate_ = false, eliminated_ = false;
  VectorXd B_;
  MatrixXd M_, S_a_;
  VectorXd acc_, tau_link_;
  Eigen::LLT<MatrixXd> llt_a_;
  VectorXd b_a_, x_;

  // Whether every motor's row of S_ holds only its diagonal and its link (what the elimination
  // takes; true of the kernel's own matrices by construction).
  bool motors_decoupled() const {
    for (const auto & sp : springs_.springs)
      for (Eigen::Index j = 0; j < S_.cols(); ++j)
        if (j != sp.motor_v && j != sp.link_v && (S_(sp.motor_v, j) != 0.0 || S_(j, sp.motor_v) != 0.0)) return false;
    return true;
  }
  // ½ Σ B θ̇², the motors' kinetic energy [J] (the links' model leaves them out).
  double motor_energy(const VectorXd & v) const {
    return eliminate_ ? 0.5 * (B_.array() * v.tail(nv_ - nvl_).array().square()).sum() : 0.0;
  }
};

}  // namespace coopdyn_native
