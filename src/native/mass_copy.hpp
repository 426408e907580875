// MassCopy: a method's copy of the mass matrix, sparse on a beam scene's pattern.
#pragma once

#include "kernel.hpp"

namespace coopdyn_native {

// A method's copy of M(q) from the kernel's last terms(), for its products M x between the
// kernel's evaluations (implicit Euler keeps one over several steps): sparse on the step matrix's
// pattern when the scene has one (a beam's: O(nnz) per product, not O(nv²)), dense otherwise.
class MassCopy {
public:
  void take(const Kernel & k) {
    sparse_ = k.has_sparse_mass();
    if (sparse_)
      sparse_M_ = k.sparse_mass();
    else
      dense_M_ = k.mass();
  }
  // out = M x
  void times(const VectorXd & x, VectorXd & out) const {
    if (sparse_)
      out.noalias() = sparse_M_ * x;
    else
      out.noalias() = dense_M_ * x;
  }
  // M⁻¹ b (a fresh factor each call: a method's first step only)
  VectorXd solve(const VectorXd & b) const {
    if (!sparse_) return dense_M_.llt().solve(b);
    Eigen::SimplicialLLT<SparseMatrix, Eigen::Lower, Eigen::AMDOrdering<SparseMatrix::StorageIndex>> llt(sparse_M_);
    return llt.solve(b);
  }

private:
  bool sparse_ = false;
  MatrixXd dense_M_;
  SparseMatrix sparse_M_;
};

}  // namespace coopdyn_native
