// Small dense linear solves for any scalar type (double or nested Jets).
//
// Eigen's decompositions need more of a scalar type than Ceres' Jets guarantee
// when they are nested, so the geometric code that must run on every scalar
// (cotangent lifts, Newton refinement of inverses) uses this Gaussian elimination
// with partial pivoting chosen on the double values. Sizes here are a few dozen at
// most; cost is O(n^3).
#pragma once

#include <stdexcept>

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

}  // namespace dvm
