// The position-momentum step of a theta map on a separable Lagrangian written in a
// scene, of any size, by Newton's method with a sparse Jacobian.
//
// It solves the equation of SeparableThetaStep (solvers/separable_theta_step.h): for
// L(q, v) = v^T M v / 2 + U(q) with M constant (mechanics/dynamic_system.h, WrittenParts),
// the theta map R_d(x, v) = (x - theta v, x + (1 - theta) v) (paper Ex. 2.6), D = q1 - q0
// and q_theta = q0 + theta D, the discrete Legendre equations of Sec. 5.3 are
//   p0 = M D / h - h (1 - theta) F(q_theta),   p1 - p0 = h F(q_theta),   F = grad U,
// and the first is solved for D by the simplified Newton across steps of
// solvers/separable_newton.h, with the Jacobian of the residual
// -(M / h - h theta (1 - theta) Hess U). Hess U comes from SparsePotentialHessian
// (mechanics/sparse_hessian.h): its pattern read off the tape and ceil(colours / 8)
// reverse gradients in Jets, so a chain or a lattice costs O(n) per Jacobian, where
// the generic run-time-sized step (DynamicThetaStep) forms the full 2n x 2n Hessian of L
// (ceil(2n / 8) passes, O(n^2)) and factors it densely (O(n^3)). The Jacobian is a
// sparse symmetric matrix of M's and Hess U's entries, factored by Eigen's
// SimplicialLDLT (fill-reducing ordering analysed once, at construction); a failed
// factorisation or a zero pivot is a failed step with a message. The equation is the
// generic step's, so the two agree to round-off (tests/solvers/test_sparse_separable.cc).
//
// It has the contract of `integrate` (N = Eigen::Dynamic, step_size(), step(q, p, dq,
// dp)). Workspace is allocated at construction; the steps of a composition share one
// SparsePotentialHessian (its pattern and colouring), and copies of a step share its
// factorisation, so steps must not run on two threads at once.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/sparse_hessian.h"
#include "solvers/separable_newton.h"

namespace dvm {

class SparseSeparableThetaStep : public SeparableThetaNewton<SparseSeparableThetaStep> {
 public:
  // The pattern and colouring of Hess U at the state q (mechanics/sparse_hessian.h), to
  // share between the steps of a composition.
  static std::shared_ptr<SparsePotentialHessian> hessian_of(const WrittenDynamic& L, const V& q) {
    return std::make_shared<SparsePotentialHessian>(L.parts().potential, L.dim(), q.data());
  }

  SparseSeparableThetaStep(const WrittenDynamic& L, std::shared_ptr<SparsePotentialHessian> hessian, double theta,
                           double h, StepOptions options = {})
      : SeparableThetaNewton(L.dim(), theta, h, options, constant_mass(L)), L_(L), separable_(L), hessian_(std::move(hessian)) {
    const int n = L_.dim();
    if (!hessian_ || hessian_->dim() != n) throw std::invalid_argument("the sparse Hessian is not the system's");
    const WrittenParts& w = L.parts();
    Lv_.resize(n);
    zero_ = V::Zero(n);
    hess_.resize(hessian_->entries());
    // J's pattern: Hess U's (the diagonal included) and M's nonzero entries
    std::vector<Eigen::Triplet<double>> t;
    t.reserve(hessian_->entries());
    const auto& cols = hessian_->columns();
    for (int j = 0; j < n; ++j)
      for (int i : cols[static_cast<std::size_t>(j)]) t.emplace_back(i, j, 0.0);
    if (!w.split.diagonal)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
          if (w.mass(i, j) != 0.0) t.emplace_back(i, j, 0.0);
    J_.resize(n, n);
    J_.setFromTriplets(t.begin(), t.end());  // duplicates summed: zeros
    J_.makeCompressed();
    // where each Hessian entry sits among J's values, and M / h at every value
    position_.resize(hessian_->entries());
    mass_over_h_.assign(static_cast<std::size_t>(J_.nonZeros()), 0.0);
    std::size_t k = 0;
    for (int j = 0; j < n; ++j) {
      Eigen::SparseMatrix<double>::InnerIterator it(J_, j);
      for (int i : cols[static_cast<std::size_t>(j)]) {
        while (it.row() < i) ++it;
        position_[k++] = static_cast<std::size_t>(&it.valueRef() - J_.valuePtr());
      }
      for (Eigen::SparseMatrix<double>::InnerIterator m(J_, j); m; ++m) {
        const double Mij = w.split.diagonal ? (m.row() == j ? w.mass_diagonal[j] : 0.0) : w.mass(m.row(), j);
        mass_over_h_[static_cast<std::size_t>(&m.valueRef() - J_.valuePtr())] = Mij / h_;
      }
    }
    factorisation_ = std::make_shared<Factorisation>();
    factorisation_->ldlt.analyzePattern(J_);
  }

  static const char* factorisation() { return "sparse LDL^T factorisation"; }

 private:
  friend class SeparableThetaNewton<SparseSeparableThetaStep>;
  // F = grad U(x): the reverse gradient of the potential's tape
  void force(const V& x, V& F) const { separable_.gradient(x, zero_, F, Lv_); }
  // J = M / h - h theta (1 - theta) Hess U(x); returns its largest entry in magnitude
  double jacobian(const V& x) const {
    hessian_->evaluate(x.data(), hess_.data());
    double* J = J_.valuePtr();
    for (std::size_t k = 0; k < mass_over_h_.size(); ++k) J[k] = mass_over_h_[k];
    const double c = h_ * theta_ * (1.0 - theta_);
    for (std::size_t k = 0; k < position_.size(); ++k) J[position_[k]] -= c * hess_[k];
    double m = 0.0;
    for (std::size_t k = 0; k < mass_over_h_.size(); ++k) m = std::fmax(m, std::fabs(J[k]));
    return std::isfinite(m) ? m : INFINITY;
  }
  void solve(const V& r, V& dx) const { dx = factorisation_->ldlt.solve(r); }
  KeptJacobian& kept() const { return *factorisation_; }
  bool factor() const {
    auto& ldlt = factorisation_->ldlt;
    ldlt.factorize(J_);
    if (ldlt.info() != Eigen::Success) return false;
    const auto& d = ldlt.vectorD();
    for (Eigen::Index i = 0; i < d.size(); ++i)
      if (!(d[i] != 0.0) || !std::isfinite(d[i])) return false;
    return true;
  }
  WrittenDynamic L_;
  WrittenSeparable separable_;  // its force
  std::shared_ptr<SparsePotentialHessian> hessian_;
  std::vector<std::size_t> position_;
  std::vector<double> mass_over_h_;
  mutable V Lv_, zero_;
  mutable std::vector<double> hess_;
  mutable Eigen::SparseMatrix<double> J_;
  // The factored Jacobian, kept from step to step (SimplicialLDLT is not copyable:
  // copies of a step share it, and with it the Jacobian they keep).
  struct Factorisation : KeptJacobian {
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
  };
  std::shared_ptr<Factorisation> factorisation_;
};

}  // namespace dvm
