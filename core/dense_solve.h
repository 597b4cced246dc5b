// Small dense linear solves for any scalar type (double or nested Jets).
//
// Eigen's decompositions need more of a scalar type than Ceres' Jets guarantee
// when they are nested, so the geometric code that must run on every scalar
// (cotangent lifts, Newton refinement of inverses) uses this Gaussian elimination
// with partial pivoting chosen on the double values. Sizes here are a few dozen at
// most; cost is O(n^3). DenseLUOf below factors a matrix of doubles once, with the
// same pivoting and singularity rule, and solves with it many times (the steps' Newton
// iterations).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "core/scalar.h"

namespace dvm {

// Solves A x = b. Throws std::domain_error if A is singular to working precision.
template <class T, int R, int C>
Vec<T, R> solve_dense(Mat<T, R, C> A, Vec<T, R> b) {
  static_assert(R == C, "solve_dense needs a square matrix");
  const int n = static_cast<int>(A.rows());
  const double scale = max_abs(A);
  for (int k = 0; k < n; ++k) {
    int piv = k;
    double best = std::fabs(value(A(k, k)));
    for (int i = k + 1; i < n; ++i) {
      const double a = std::fabs(value(A(i, k)));
      if (a > best) {
        best = a;
        piv = i;
      }
    }
    if (!(best > 1e-14 * scale) || !std::isfinite(best))
      throw std::domain_error("dense solve: matrix is singular to working precision");
    if (piv != k) {
      A.row(k).swap(A.row(piv));
      std::swap(b[k], b[piv]);
    }
    for (int i = k + 1; i < n; ++i) {
      const T f = A(i, k) / A(k, k);
      for (int j = k + 1; j < n; ++j) A(i, j) = A(i, j) - f * A(k, j);
      b[i] = b[i] - f * b[k];
    }
  }
  Vec<T, R> x(n);
  for (int i = n - 1; i >= 0; --i) {
    T s = b[i];
    for (int j = i + 1; j < n; ++j) s = s - A(i, j) * x[j];
    x[i] = s / A(i, i);
  }
  return x;
}

// Views of a vector or matrix of doubles of run-time size (a vector, a segment of one, a
// fixed-size vector with the same storage), as arguments.
using DynIn = Eigen::Ref<const Eigen::VectorXd>;
using DynOut = Eigen::Ref<Eigen::VectorXd>;
using DynMatOut = Eigen::Ref<Eigen::MatrixXd>;

// LU factorisation with partial pivoting, P A = L U, of a square matrix of run-time
// size, in storage sized once: factor() and solve() allocate nothing. Singular to
// working precision means a pivot not above 1e-14 max|A| (the rule of solve_dense
// above) or not finite. Unblocked, column oriented: meant for the dense
// step matrices of a few to a few hundred unknowns. K: the size where it is known at
// compile time (the loops then have fixed lengths; DenseLU is the run-time-sized one).
template <int K = Eigen::Dynamic>
class DenseLUOf {
 public:
  DenseLUOf() {
    if constexpr (K != Eigen::Dynamic) {  // fixed storage starts defined (a copy of an unused factor reads it)
      lu_.setZero();
      piv_.setZero();
      inverse_pivot_.setZero();
    }
  }
  explicit DenseLUOf(int n) : DenseLUOf() { resize(n); }
  void resize(int n) {
    if (K != Eigen::Dynamic && n != K)
      throw std::invalid_argument("DenseLUOf<" + std::to_string(K) + ">: a matrix of size " + std::to_string(n));
    lu_.resize(n, n);
    piv_.resize(n);
    inverse_pivot_.resize(n);
  }
  int size() const { return static_cast<int>(lu_.rows()); }

  // Factors A (size() x size()); false if A is singular to working precision. amax:
  // max |A_ij| (NaN if A holds a NaN) where the caller has it already.
  bool factor(const Eigen::Ref<const Eigen::MatrixXd>& A, double amax = -1.0) {
    if (A.rows() != size()) resize(static_cast<int>(A.rows()));  // allocates only here
    const int n = size();
    if (A.outerStride() == A.rows())
      std::copy(A.data(), A.data() + A.size(), lu_.data());
    else
      lu_ = A;
    const double tiny = 1e-14 * (amax >= 0.0 || amax != amax ? amax : inf_norm(lu_));
    if (!std::isfinite(tiny)) return false;
    for (int k = 0; k < n; ++k) {
      int p = k;
      double best = std::fabs(lu_(k, k));
      for (int i = k + 1; i < n; ++i) {
        const double a = std::fabs(lu_(i, k));
        if (a > best) {
          best = a;
          p = i;
        }
      }
      piv_[k] = p;
      if (!(best > tiny) || !std::isfinite(best)) return false;
      if (p != k) lu_.row(k).swap(lu_.row(p));
      const double inv = 1.0 / lu_(k, k);
      inverse_pivot_[k] = inv;  // (the solves multiply: no division on their path)
      for (int i = k + 1; i < n; ++i) lu_(i, k) *= inv;
      for (int j = k + 1; j < n; ++j) {
        const double u = lu_(k, j);
        if (u == 0.0) continue;
        double* col = lu_.col(j).data();
        const double* l = lu_.col(k).data();
        for (int i = k + 1; i < n; ++i) col[i] -= l[i] * u;
      }
    }
    return true;
  }

  // x = A^{-1} b after a successful factor(); x may be b itself.
  void solve(const DynIn& b, DynOut x) const {
    const int n = size();
    if (x.data() != b.data()) x = b;
    for (int k = 0; k < n; ++k) {
      const int p = piv_[k];
      if (p != k) std::swap(x[k], x[p]);
    }
    for (int k = 0; k < n; ++k) {
      const double xk = x[k];
      if (xk == 0.0) continue;
      const double* l = lu_.col(k).data();
      for (int i = k + 1; i < n; ++i) x[i] -= l[i] * xk;
    }
    for (int k = n - 1; k >= 0; --k) {
      x[k] *= inverse_pivot_[k];
      const double xk = x[k];
      const double* u = lu_.col(k).data();
      for (int i = 0; i < k; ++i) x[i] -= u[i] * xk;
    }
  }

  // A^{-1} into `out` (size() x size()).
  void inverse(DynMatOut out) const {
    out.setIdentity();
    for (int j = 0; j < size(); ++j) solve(out.col(j), out.col(j));
  }

 private:
  Eigen::Matrix<double, K, K> lu_;
  Eigen::Matrix<int, K, 1> piv_;
  Eigen::Matrix<double, K, 1> inverse_pivot_;
};
using DenseLU = DenseLUOf<>;

}  // namespace dvm
