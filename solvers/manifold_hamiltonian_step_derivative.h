// The derivative of the Hamiltonian step on S^2 and SO(3) (ManifoldHamiltonianStep::
// derivatives, declared in solvers/manifold_hamiltonian_step.h): included by the files
// that differentiate steps (the tests; solvers/runtime/kernels_sphere.cc and
// kernels_rotation.cc, which instantiate it for the runtime's steps beside the steps
// themselves), not by those that only take them.
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>

#include "solvers/manifold_hamiltonian_step.h"

namespace dvm {

// The chart step (solvers/manifold_hamiltonian_step.h) works in the canonical coordinates
// (eta, pi) around q0 at both of its ends: the Hamiltonian and the map are written in the
// chart centred at q0 and its cotangent lift, and the step is the same in any chart
// (naturality, that header's comment), so its Jacobian Mc = d(eta1, pi1)/d(eta0, pi0)
// (the implicit function theorem on Eq. 5.1 in the chart, as HamiltonianStep::jacobian)
// is the step's derivative in those coordinates around q0. The coordinates around q1 of
// the end point follow by the cotangent lift of the change of charts
// phi(eta) = chart^{-1}(q1, chart(q0, eta)):
//   zeta = phi(eta),   pi' = Dphi(eta)^{-T} pi,
// whose Jacobian at (eta1, pi1), with S = sum_j pi'_j d2 phi_j/d eta2 (nested Jets), is
//   T = [ Dphi            0        ]
//       [ -Dphi^{-T} S    Dphi^{-T} ],
// so A = T Mc. Both are symplectic (a cotangent lift; the chart step of the cotangent
// lift of a map), so A^T J A = J without a force.
template <class Ham, class Map, class Force>
bool ManifoldHamiltonianStep<Ham, Map, Force>::derivatives(double t, const Point& q0, const Covector& p0,
                                                           const Point& q1, Eigen::MatrixXd& A,
                                                           Eigen::MatrixXd* B) const {
  static_assert(!kForced, "the derivative of a forced Hamiltonian step on a manifold is not written");
  using T = ceres::Jet<double, n>;
  using D = ceres::Jet<T, n>;
  try {
    // the step solved again from (q0, p0) in the chart centred at q0, q1 as the guess
    const Local local = local_step(q0, t);
    const V pi0 = M::covector_to_local(q0, p0);
    V xi = M::chart_inverse(q0, q1), dp = V::Zero();
    if (!local.step(t, V::Zero(), pi0, xi, dp).converged) return false;
    // Mc = I - F_y^{-1} F_x, F_y and F_x the derivatives of the chart step's residual in
    // the increments y = (dq, dp) and in the start x = (eta0, pi0), each by one pass in
    // the Jets of 2 dim directions that Newton's method evaluates the residual in (no
    // scalar type of more directions is compiled for the chart Hamiltonian and map)
    using J2 = ceres::Jet<double, 2 * n>;
    auto pass = [&](bool start) {
      Vec<J2, n> e0, p, dq, dpi;
      for (int i = 0; i < n; ++i) {
        e0[i] = start ? seed<double, 2 * n>(0.0, i) : J2(0.0);
        p[i] = start ? seed<double, 2 * n>(pi0[i], n + i) : J2(pi0[i]);
        dq[i] = start ? J2(xi[i]) : seed<double, 2 * n>(xi[i], i);
        dpi[i] = start ? J2(dp[i]) : seed<double, 2 * n>(dp[i], n + i);
      }
      const Vec<J2, 2 * n> F = local.residual(e0, p, dq, dpi);
      Mat<double, 2 * n, 2 * n> jac;
      for (int i = 0; i < 2 * n; ++i) jac.row(i) = F[i].v.transpose();
      return jac;
    };
    const Eigen::FullPivLU<Mat<double, 2 * n, 2 * n>> Fy(pass(false));
    if (!Fy.isInvertible()) return false;
    const Mat<double, 2 * n, 2 * n> Mc = Mat<double, 2 * n, 2 * n>::Identity() - Fy.solve(pass(true));
    // the change of charts at eta = xi, in nested Jets: Dphi (inner) and its second
    // derivatives (inner and outer)
    Vec<D, n> eta;
    for (int i = 0; i < n; ++i) {
      eta[i] = D(seed<double, n>(xi[i], i));
      eta[i].v[i] = T(1.0);
    }
    const Vec<D, n> phi = M::chart_inverse(q1, M::chart(q0, eta));
    Mat<double, n, n> Dphi;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) Dphi(j, i) = phi[j].v[i].a;
    const Eigen::FullPivLU<Mat<double, n, n>> lu(Dphi);
    if (!lu.isInvertible()) return false;
    const Mat<double, n, n> DphiInvT = lu.inverse().transpose();
    const V pi1 = DphiInvT * V(pi0 + dp);
    Mat<double, n, n> S = Mat<double, n, n>::Zero();
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (int k = 0; k < n; ++k) S(i, k) += pi1[j] * phi[j].v[i].v[k];
    Mat<double, 2 * n, 2 * n> Tc = Mat<double, 2 * n, 2 * n>::Zero();
    Tc.template topLeftCorner<n, n>() = Dphi;
    Tc.template bottomLeftCorner<n, n>() = -DphiInvT * S;
    Tc.template bottomRightCorner<n, n>() = DphiInvT;
    A = Tc * Mc;
    if (B) B->resize(2 * n, 0);
  } catch (const std::domain_error&) {
    return false;
  }
  return A.allFinite();
}

}  // namespace dvm
