// The articulated-body algorithm after a forwardKinematics(q, v) pass (Featherstone's ABA in
// Pinocchio's local convention: abaLocalConvention with fext in pinocchio/src/algorithm/aba.hxx,
// as of Pinocchio 4.1.0; re-check these steps against it when the pin version moves).
//
// pinocchio::aba recomputes what forwardKinematics(q, v) has just left in the Data — each
// joint's data (calc), liMi and the body velocities — and, after the accelerations, the body
// accelerations in world gravity (data.a) and the joint forces (data.f), which q̈ does not need.
// ArticulatedBody runs only the rest, with the same operations in the same order, so q̈ is
// Pinocchio's to the last bit where this extension and the pin wheels are compiled alike (x86-64:
// tested against pinocchio.aba in tests/test_native.py):
//   pass 1: the articulated inertia started from the body's constant spatial inertia matrix,
//           the bias force v ×* I v − f_ext (these need no joint type: a plain loop);
//   pass 2 (leaves to root): the bias acceleration c + v × v_J, then Pinocchio's backward step;
//   pass 3 (root to leaves): the accelerations and q̈.
#pragma once

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/multibody/visitor.hpp>

#include <vector>

namespace coopdyn_native {

using Matrix6List = std::vector<pinocchio::Data::Matrix6, Eigen::aligned_allocator<pinocchio::Data::Matrix6>>;
// The type Pinocchio's compiled algorithms take (computeABADerivatives with fext): a vector with
// another allocator made the compiler instantiate them here, ~50 s of the kernel's build.
using ForceList = std::vector<pinocchio::Force>;

namespace aba_detail {

using pinocchio::Data;
using pinocchio::Model;

// Pass 1's bias acceleration c + v × v_J (moved here: it needs the joint's type, as this step
// does, and only this joint's backward step reads it before pass 3), then
// pinocchio::impl::AbaLocalConventionBackwardStep.
struct BackwardStep : pinocchio::fusion::JointUnaryVisitorBase<BackwardStep> {
  typedef boost::fusion::vector<const Model &, Data &> ArgsType;

  template <typename JointModel>
  static void algo(const pinocchio::JointModelBase<JointModel> & jmodel,
                   pinocchio::JointDataBase<typename JointModel::JointDataDerived> & jdata, const Model & model,
                   Data & data) {
    const auto i = jmodel.id();
    const auto parent = model.parents[i];
    data.a_gf[i] = jdata.c() + (data.v[i] ^ jdata.v());
    Data::Matrix6 & Ia = data.Yaba[i];
    jmodel.jointVelocitySelector(data.u) -= jdata.S().transpose() * data.f[i];
    jmodel.calc_aba(jdata.derived(), jmodel.jointVelocitySelector(model.armature), Ia, parent > 0);
    if (parent > 0) {
      pinocchio::Force & pa = data.f[i];
      pa.toVector().noalias() += Ia * data.a_gf[i].toVector() + jdata.UDinv() * jmodel.jointVelocitySelector(data.u);
      data.Yaba[parent] += pinocchio::impl::internal::SE3actOn<double>::run(data.liMi[i], Ia);
      data.f[parent] += data.liMi[i].act(pa);
    }
  }
};

// pinocchio::impl::AbaLocalConventionForwardStep2 up to q̈ (without data.a and data.f).
struct ForwardStep : pinocchio::fusion::JointUnaryVisitorBase<ForwardStep> {
  typedef boost::fusion::vector<const Model &, Data &> ArgsType;

  template <typename JointModel>
  static void algo(const pinocchio::JointModelBase<JointModel> & jmodel,
                   pinocchio::JointDataBase<typename JointModel::JointDataDerived> & jdata, const Model & model,
                   Data & data) {
    const auto i = jmodel.id();
    data.a_gf[i] += data.liMi[i].actInv(data.a_gf[model.parents[i]]);
    jmodel.jointVelocitySelector(data.ddq).noalias() =
      jdata.Dinv() * jmodel.jointVelocitySelector(data.u) - jdata.UDinv().transpose() * data.a_gf[i].toVector();
    data.a_gf[i] += jdata.S() * jmodel.jointVelocitySelector(data.ddq);
  }
};

}  // namespace aba_detail

class ArticulatedBody {
public:
  // The model's inertias are read here once (as in the rest of the Kernel, a scene's model does not
  // change after it is built; pass 1's momenta read the same inertias from the model).
  explicit ArticulatedBody(const pinocchio::Model & model) {
    for (const auto & inertia : model.inertias) inertia_matrices_.push_back(inertia.matrix());
  }

  // q̈ for the joint torques `tau` (nv) and the external forces `fext` (one per joint, in the
  // joint's frame), after forwardKinematics(model, data, q, v) at the same (q, v). A reference
  // to data.ddq.
  const Eigen::VectorXd & accelerations(const pinocchio::Model & model, pinocchio::Data & data,
                                        const Eigen::VectorXd & tau, const ForceList & fext) const {
    using namespace aba_detail;
    data.v[0].setZero();
    data.a_gf[0] = -model.gravity;
    data.u = tau;
    const auto n = static_cast<pinocchio::JointIndex>(model.njoints);
    for (pinocchio::JointIndex i = 1; i < n; ++i) {  // pass 1 but for the bias acceleration
      data.Yaba[i] = inertia_matrices_[i];
      data.h[i] = model.inertias[i] * data.v[i];
      data.f[i] = data.v[i].cross(data.h[i]);
      data.f[i] -= fext[i];
    }
    for (pinocchio::JointIndex i = n - 1; i > 0; --i)
      BackwardStep::run(model.joints[i], data.joints[i], BackwardStep::ArgsType(model, data));
    for (pinocchio::JointIndex i = 1; i < n; ++i)
      ForwardStep::run(model.joints[i], data.joints[i], ForwardStep::ArgsType(model, data));
    return data.ddq;
  }

private:
  Matrix6List inertia_matrices_;  // each body's spatial inertia as a 6 × 6 matrix, constant in its joint's frame
};

}  // namespace coopdyn_native
