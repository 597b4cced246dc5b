// The derivative of the manifold position-momentum step (ManifoldStep::derivatives,
// declared in solvers/manifold_step.h): included by the files that differentiate steps
// (the tests; solvers/runtime/kernels_manifold_derivatives.cc, which instantiates it for
// the runtime's steps on S^2 and SO(3)), not by those that only take them, whose
// compile time and inlining it would otherwise change.
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <stdexcept>

#include "solvers/manifold_step.h"

namespace dvm {

// ManifoldStep::derivatives (what it gives: its declaration in solvers/manifold_step.h).
//
// With Phi(eta, zeta) the function of generating_value at a = chart(q0, eta) and
// b = chart(q1, zeta) (the discrete Lagrangian, plus the virtual work of the force held
// at the node), g = d Phi/d eta' and f = d Phi/d zeta' (its derivatives in the moved
// points, the force held), the step is pi0 + g(eta, zeta) = 0 and pi1 = f(eta, zeta), so
//   d zeta = -g_zeta^{-1} (g_eta d eta + d pi0),   d pi1 = f_eta d eta + f_zeta d zeta,
// and in the controls g_u, f_u = h Ddisp^T dF/du. Without a force Phi is L_d and
// g_eta, g_zeta, f_eta, f_zeta are blocks of its symmetric Hessian: A is symplectic.
// Each block is one evaluation of Phi in the nested Jets the step's own equation uses
// (the inner Jet over the point g or f differentiates in, the outer over the point the
// block differentiates in), so no other scalar type is compiled for L and the map.
template <class System, class Map, class Force>
bool ManifoldStep<System, Map, Force>::derivatives(double t, const Point& q0, const Covector& p0, const Point& q1,
                                                   Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
  (void)p0;  // (the step's equation is linear in p0: A does not depend on it)
  using T = ceres::Jet<double, n>;
  using D = ceres::Jet<T, n>;
  const double h = dl_.step(), t_node = t + dl_.map().theta() * h;
  try {
    const Vec<double, n> xi = M::chart_inverse(q0, q1);
    const auto rel = M::relative_chart(q0, xi);
    // d/d(outer point) of d Phi/d(inner point), the points moved in the charts centred
    // at q0 (first) and q1 (second)
    auto block = [&](bool inner_first, bool outer_first) {
      Vec<D, n> e0, e1;
      for (int i = 0; i < n; ++i) {
        const T outer = seed<double, n>(0.0, i);
        e0[i] = D(outer_first ? outer : T(0.0));
        e1[i] = D(outer_first ? T(0.0) : outer);
        (inner_first ? e0 : e1)[i].v[i] = T(1.0);
      }
      const typename M::template Point<D> a = M::chart(q0, e0);
      auto r = M::relative(a, M::chart(q1, e1));
      for (int i = 0; i < r.size(); ++i) r(i).a.a = rel(i);  // (the accurate value; derivatives from the points)
      D phi;
      if constexpr (kForced)
        phi = dl_.generating_value(a, r, *force_, t_node);
      else
        phi = dl_.generating_value(a, r);
      Mat<double, n, n> H;
      for (int i = 0; i < n; ++i)
        for (int k = 0; k < n; ++k) H(i, k) = phi.v[i].v[k];
      return H;
    };
    const Mat<double, n, n> g_eta = block(true, true), g_zeta = block(true, false), f_eta = block(false, true),
                            f_zeta = block(false, false);
    const Eigen::FullPivLU<Mat<double, n, n>> lu(g_zeta);
    if (!lu.isInvertible()) return false;
    const Mat<double, n, n> dz_eta = -lu.solve(g_eta), dz_pi = -lu.inverse();
    A.resize(2 * n, 2 * n);
    A.topLeftCorner(n, n) = dz_eta;
    A.topRightCorner(n, n) = dz_pi;
    A.bottomLeftCorner(n, n) = f_eta + f_zeta * dz_eta;
    A.bottomRightCorner(n, n) = f_zeta * dz_pi;
    if (B) {
      const int c = controls();
      B->setZero(2 * n, c);
      if constexpr (kForced)
        if (c > 0) {
          // the virtual displacement's derivatives in the moved first and second points
          // at the node, (size x n each), and the node
          Eigen::Matrix<double, Force::size, 2 * n> Dd;
          Point x;
          Covector v;
          for (int side = 0; side < 2; ++side) {
            Vec<T, n> e0, e1;
            for (int i = 0; i < n; ++i) {
              e0[i] = side == 0 ? seed<double, n>(0.0, i) : T(0.0);
              e1[i] = side == 0 ? T(0.0) : seed<double, n>(0.0, i);
            }
            const typename M::template Point<T> a = M::chart(q0, e0);
            auto r = M::relative(a, M::chart(q1, e1));
            for (int i = 0; i < r.size(); ++i) r(i).a = rel(i);
            const ManifoldTangent<M, T> node = dl_.map().inverse_relative(a, r);
            for (int i = 0; i < x.size(); ++i) x(i) = node.x(i).a;
            for (int i = 0; i < v.size(); ++i) v(i) = node.v(i).a / h;
            const Vec<T, Force::size> d = Force::template displacement<T>(x, node.x);
            for (int i = 0; i < Force::size; ++i) Dd.block(i, side * n, 1, n) = d[i].v.transpose();
          }
          const Eigen::MatrixXd Gu = h * Dd.transpose() * force_->control_jacobian(t_node, x, v);
          const Eigen::MatrixXd dz_u = -lu.solve(Gu.topRows(n));
          B->topRows(n) = dz_u;
          B->bottomRows(n) = Gu.bottomRows(n) + f_zeta * dz_u;
        }
    }
  } catch (const std::domain_error&) {
    return false;
  }
  return A.allFinite() && (!B || B->allFinite());
}

}  // namespace dvm
