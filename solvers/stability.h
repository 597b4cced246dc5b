// Linear stability of one-step methods on the harmonic oscillator q'' = -omega^2 q.
//
// On L = v^2/2 - omega^2 q^2/2 every method of dvm is a linear map of (q, p),
// (q_1, p_1) = M(h omega) (q_0, p_0), with det M = 1 (the method is symplectic). Its
// eigenvalues are the roots of z^2 - tr(M) z + 1, so the method is stable (bounded
// powers of M) when |tr M| < 2, and unstable (an eigenvalue of modulus > 1) when
// |tr M| > 2. The stability threshold of a method is the largest x such that it is
// stable for every h omega in (0, x).
//
// Two ways to find it, which the tests compare:
//   - from the trace: M is the product of the closed-form matrices of the substeps
//     (below, for the theta maps), scanned in h omega and refined by bisection;
//   - from the growth of a run of the integrator itself (`grows`), bisected near the
//     first threshold.
//
// Closed form for a substep of size h with the theta map (omega = 1 after scaling
// h omega -> h): with x = q0 + theta dq, the position-momentum step
//   p0 = dq/h + h (1 - theta) x,   p1 = dq/h - h theta x
// gives dq = (p0 - h (1 - theta) q0) / (1/h + h theta (1 - theta)). The adjoint of the
// theta map is the (1 - theta) map. For theta = 1/2 each substep matrix is
// orthogonal (a Cayley transform), so every composition of midpoint steps is stable
// for every h omega; theta = 0 and 1 (explicit and adjoint Euler, Stormer-Verlet
// when composed) give finite thresholds.
#pragma once

#include <cmath>
#include <vector>

#include "core/scalar.h"
#include "solvers/composition_methods.h"

namespace dvm {

using Mat2 = Eigen::Matrix2d;

// The one-step matrix of the theta map's step of size h on q'' = -q (columns: images
// of (q, p) = (1, 0) and (0, 1)).
inline Mat2 theta_step_matrix(double theta, double h) {
  const double denom = 1.0 / h + h * theta * (1.0 - theta);
  Mat2 M;
  for (int c = 0; c < 2; ++c) {
    const double q0 = c == 0 ? 1.0 : 0.0, p0 = c == 0 ? 0.0 : 1.0;
    const double dq = (p0 - h * (1.0 - theta) * q0) / denom;
    const double x = q0 + theta * dq;
    M(0, c) = q0 + dq;
    M(1, c) = dq / h - h * theta * x;
  }
  return M;
}

// The one-step matrix of a composition of the theta map (and its adjoint, the
// (1 - theta) map) at h omega = x.
inline Mat2 composition_matrix(double theta, const std::vector<Substep>& substeps, double x) {
  Mat2 M = Mat2::Identity();
  for (const Substep& s : substeps) M = theta_step_matrix(s.adjoint ? 1.0 - theta : theta, s.weight * x) * M;
  return M;
}

// Stable in the sense of bounded powers: |tr| < 2, or M = +-I.
inline bool linearly_stable(const Mat2& M) {
  const double t = M.trace();
  if (std::fabs(t) < 2.0) return true;
  const double s = t > 0 ? 1.0 : -1.0;
  return (M - s * Mat2::Identity()).cwiseAbs().maxCoeff() <= 1e-12 * M.cwiseAbs().maxCoeff();
}

// The first h omega at which a matrix family loses stability, scanned on (0, x_max]
// with spacing dx and refined by bisection to `tol`; +infinity if it stays stable.
// Instability bands narrower than dx can be missed (the tests check the result).
template <class MatrixOf>
double stability_threshold(const MatrixOf& matrix_of, double x_max = 20.0, double dx = 1e-3, double tol = 1e-13) {
  double lo = 0.0;
  for (double x = dx; x <= x_max + 0.5 * dx; x += dx) {
    if (!linearly_stable(matrix_of(x))) {
      double hi = x;
      while (hi - lo > tol * hi) {
        const double mid = 0.5 * (lo + hi);
        (linearly_stable(matrix_of(mid)) ? lo : hi) = mid;
      }
      return 0.5 * (lo + hi);
    }
    lo = x;
  }
  return INFINITY;
}

// Threshold of a composition of the theta map by the trace test.
inline double composition_threshold(double theta, const std::vector<Substep>& substeps, double x_max = 20.0) {
  return stability_threshold([&](double x) { return composition_matrix(theta, substeps, x); }, x_max);
}

}  // namespace dvm
