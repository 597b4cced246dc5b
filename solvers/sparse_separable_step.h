// The position-momentum step of a theta map on a separable Lagrangian written in a
// scene, of any size, by Newton's method with a sparse Jacobian.
//
// It solves the equation of SeparableThetaStep (solvers/separable_theta_step.h): for
// L(q, v) = v^T M v / 2 + U(q) with M constant (mechanics/written_dynamic.h, WrittenParts),
// the theta map R_d(x, v) = (x - theta v, x + (1 - theta) v) (paper Ex. 2.6), D = q1 - q0
// and q_theta = q0 + theta D, the discrete Legendre equations of Sec. 5.3 are
//   p0 = M D / h - h (1 - theta) F(q_theta),   p1 - p0 = h F(q_theta),   F = grad U,
// and the first is solved for D by the simplified Newton across steps of
// solvers/separable_newton.h, with the Jacobian of the residual
// -(M / h - h theta (1 - theta) Hess U). Hess U comes from SparsePotentialHessian
// (mechanics/sparse_hessian.h): its pattern read off the tape and ceil(colours / 8)
// reverse gradients in Jets, so a chain or a lattice costs O(n) per Jacobian, where
// the generic run-time-sized step (DynamicThetaStep) forms the full 2n x 2n Hessian of L
// (ceil(2n / 8) passes, O(n^2)) and factors it densely (O(n^3)). The Jacobian, of M's
// and Hess U's entries, is factored in its band where that band is narrow (kMaxBand:
// a chain's is tridiagonal; BandedLU of core/banded_solve.h, partial pivoting), else as
// a sparse symmetric matrix by Eigen's SimplicialLDLT (fill-reducing ordering analysed
// once, at construction); a failed factorisation or a zero pivot is a failed step with
// a message. The equation is the generic step's, so the two agree to round-off
// (tests/solvers/test_sparse_separable.cc).
//
// It has the contract of `integrate` (N = Eigen::Dynamic, step_size(), step(q, p, dq,
// dp)). Workspace is allocated at construction; the steps of a composition share one
// SparsePotentialHessian (its pattern and colouring), and copies of a step share its
// factorisation, so steps must not run on two threads at once.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/banded_solve.h"
#include "mechanics/sparse_hessian.h"
#include "mechanics/written_dynamic.h"
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
    // J's pattern: Hess U's (the diagonal included) and M's nonzero entries; its
    // half-bandwidth in the coordinates' own order picks the factorisation
    const auto& cols = hessian_->columns();
    int band = 0;
    for (int j = 0; j < n; ++j)
      for (int i : cols[static_cast<std::size_t>(j)]) band = std::max(band, std::abs(i - j));
    if (!w.split.diagonal)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
          if (w.mass(i, j) != 0.0) band = std::max(band, std::abs(i - j));
    factorisation_ = std::make_shared<Factorisation>();
    if (band <= kMaxBand) {
      // banded: J's entries as offsets into the band's storage, refilled at each Jacobian
      auto& B = factorisation_->band;
      B = std::make_unique<BandedLU>(n, band, band);
      position_.resize(hessian_->entries());
      std::size_t k = 0;
      for (int j = 0; j < n; ++j)
        for (int i : cols[static_cast<std::size_t>(j)]) position_[k++] = B->offset(i, j);
      for (int j = 0; j < n; ++j)
        for (int i = std::max(0, j - band); i <= std::min(n - 1, j + band); ++i) {
          const double Mij = w.split.diagonal ? (i == j ? w.mass_diagonal[j] : 0.0) : w.mass(i, j);
          if (Mij != 0.0) mass_entries_.emplace_back(B->offset(i, j), Mij / h_);
        }
      return;
    }
    std::vector<Eigen::Triplet<double>> t;
    t.reserve(hessian_->entries());
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
    std::size_t k = 0;
    for (int j = 0; j < n; ++j) {
      Eigen::SparseMatrix<double>::InnerIterator it(J_, j);
      for (int i : cols[static_cast<std::size_t>(j)]) {
        while (it.row() < i) ++it;
        position_[k++] = static_cast<std::size_t>(&it.valueRef() - J_.valuePtr());
      }
      for (Eigen::SparseMatrix<double>::InnerIterator m(J_, j); m; ++m) {
        const double Mij = w.split.diagonal ? (m.row() == j ? w.mass_diagonal[j] : 0.0) : w.mass(m.row(), j);
        if (Mij != 0.0) mass_entries_.emplace_back(static_cast<std::size_t>(&m.valueRef() - J_.valuePtr()), Mij / h_);
      }
    }
    factorisation_->ldlt.analyzePattern(J_);
  }

  // Whether J is factored in its band (else by the sparse LDL^T).
  bool banded() const { return factorisation_->band != nullptr; }

  const char* factorisation() const {
    return banded() ? "banded LU factorisation" : "sparse LDL^T factorisation";
  }

  // The widest band factored as a band (b entries on each side of the diagonal, in the
  // coordinates' own order): a chain's Jacobian is tridiagonal (b = 1), a lattice of
  // rows of w particles has b = w. Beyond, the fill-reducing sparse LDL^T. A band costs
  // about 3 b^2 n to factor and 4 b n to solve with no ordering to follow and no
  // indices to read: on a tridiagonal matrix it is faster than the sparse LDL^T both
  // to factor and to solve.
  static constexpr int kMaxBand = 8;

 private:
  friend class SeparableThetaNewton<SparseSeparableThetaStep>;
  // F = grad U(x): the reverse gradient of the potential's tape
  void force(const V& x, V& F) const { separable_.gradient(x, zero_, F, Lv_); }
  // J = M / h - h theta (1 - theta) Hess U(x), in the band or among the sparse matrix's
  // values; returns its largest entry in magnitude
  double jacobian(const V& x) const {
    hessian_->evaluate(x.data(), hess_.data());
    double* J;
    std::size_t size;
    if (banded()) {
      BandedLU& B = *factorisation_->band;
      B.set_zero();
      J = B.storage();
      size = B.storage_size();
    } else {
      J = J_.valuePtr();
      size = static_cast<std::size_t>(J_.nonZeros());
      std::fill_n(J, size, 0.0);
    }
    for (const auto& m : mass_entries_) J[m.first] = m.second;
    const double c = h_ * theta_ * (1.0 - theta_);
    for (std::size_t k = 0; k < position_.size(); ++k) J[position_[k]] -= c * hess_[k];
    double m = 0.0;
    for (std::size_t k = 0; k < size; ++k) m = std::fmax(m, std::fabs(J[k]));
    return std::isfinite(m) ? m : INFINITY;
  }
  void solve(const V& r, V& dx) const {
    if (banded()) {
      dx = r;
      factorisation_->band->solve(dx);
    } else {
      dx = factorisation_->ldlt.solve(r);
    }
  }
  DriverState& kept() const { return *factorisation_; }
  bool factor() const {
    if (banded()) return factorisation_->band->factor();
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
  std::vector<std::size_t> position_;                       // of Hess U's entries in J's storage
  std::vector<std::pair<std::size_t, double>> mass_entries_;  // M / h: where, and the value
  mutable V Lv_, zero_;
  mutable std::vector<double> hess_;
  mutable Eigen::SparseMatrix<double> J_;
  // The factored Jacobian, kept from step to step (SimplicialLDLT is not copyable:
  // copies of a step share it, and with it the Jacobian they keep).
  struct Factorisation : DriverState {
    std::unique_ptr<BandedLU> band;  // J and its factors, where J is banded
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
  };
  std::shared_ptr<Factorisation> factorisation_;
};

}  // namespace dvm
