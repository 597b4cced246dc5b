// Hamiltonians on the cotangent bundle of a curved space, and their expression in a
// chart (paper Sec. 5.1 applied on S^2, SO(3) and (S^2)^K).
//
// A covector p at x in M is stored as the manifold stores covectors (a tangent
// 3-vector on S^2 acting by v -> p.v; the body angular momentum on SO(3), acting on
// the body angular velocity by w -> p.w). A manifold Hamiltonian is a scalar-generic
// H(x, p) on such stored pairs, with `using Manifold`:
//
//   spherical pendulum  H = |p|^2/(2 m l^2) + m g l x_3
//   free rigid body     H = sum_i Pi_i^2/(2 I_i)
//   heavy top           H = sum_i Pi_i^2/(2 I_i) + m g e3.(R chi)
//
// Chart coordinates. Let phi(eta) = chart(c, eta) and D(eta) = D phi(eta), the linear
// map from chart velocities nu to stored tangent vectors (3 x dim). A stored covector
// p at phi(eta) has chart components pi = D^T p. Conversely, because the columns of
// D span the stored tangent space at phi(eta),
//   p = D (D^T D)^{-1} pi
// is the unique stored covector with those components (on SO(3), D = J_r(eta) is
// square and this is D^{-T} pi). The Hamiltonian in the chart is then
//   H_c(eta, pi) = H(phi(eta), D (D^T D)^{-1} pi),
// an ordinary Hamiltonian on T*R^dim: the canonical coordinates (eta, pi) of the
// chart make T*M's symplectic form dpi ^ deta, so the R^n Hamiltonian step applies
// unchanged in the chart and its symplecticity is the R^n matrix identity
// M^T J M = J there.
//
// Only written-out Hamiltonians are supported: the Legendre transform of the chart
// Lagrangian L(phi(eta), D(eta) nu) (LegendreHamiltonian) would need Jets three levels
// deep inside the step, and Ceres' sqrt and division do not compile at that depth
// (the central-projection chart of S^2 uses both).
#pragma once

#include <string>
#include <utility>

#include "core/dense_solve.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/manifold_systems.h"

namespace dvm {

// phi(eta) and D(eta) = D chart(c, eta) column by column, for any scalar.
template <class M, class T>
typename M::template Point<T> chart_with_differential(
    const typename M::template Point<double>& c, const Vec<T, M::dim>& eta,
    Mat<T, M::template Tangent<double>::RowsAtCompileTime, M::dim>& D) {
  constexpr int n = M::dim;
  typename M::template Point<T> x;
  for (int j = 0; j < n; ++j) {
    Vec<T, n> e;
    for (int i = 0; i < n; ++i) e[i] = constant<T>(i == j ? 1.0 : 0.0);
    const auto xv = M::chart_and_tangent(c, eta, e);
    if (j == 0) x = xv.first;
    D.col(j) = xv.second;
  }
  return x;
}

// The stored covector D (D^T D)^{-1} pi with chart components pi at phi(eta).
template <class M, class T>
typename M::template Tangent<T> covector_from_chart(
    const Mat<T, M::template Tangent<double>::RowsAtCompileTime, M::dim>& D, const Vec<T, M::dim>& pi) {
  constexpr int n = M::dim;
  constexpr int S = M::template Tangent<double>::RowsAtCompileTime;
  Mat<T, n, n> G;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      T g = constant<T>(0.0);
      for (int k = 0; k < S; ++k) g = g + D(k, i) * D(k, j);
      G(i, j) = g;
    }
  const Vec<T, n> a = solve_dense<T, n, n>(G, pi);
  typename M::template Tangent<T> p;
  for (int k = 0; k < S; ++k) {
    T s = constant<T>(0.0);
    for (int j = 0; j < n; ++j) s = s + D(k, j) * a[j];
    p[k] = s;
  }
  return p;
}

// The stored covector at chart(c, eta) whose chart components are pi (doubles).
template <class M>
typename M::template Tangent<double> covector_from_chart_at(const typename M::template Point<double>& c,
                                                             const Vec<double, M::dim>& eta,
                                                             const Vec<double, M::dim>& pi) {
  Mat<double, M::template Tangent<double>::RowsAtCompileTime, M::dim> D;
  chart_with_differential<M, double>(c, eta, D);
  return covector_from_chart<M, double>(D, pi);
}

// H_c(eta, pi) = H(phi(eta), D (D^T D)^{-1} pi): a manifold Hamiltonian in the chart.
template <class H>
struct ChartHamiltonian {
  using M = typename H::Manifold;
  static constexpr int dim = M::dim;
  H ham;
  typename M::template Point<double> centre;
  std::string name() const { return ham.name(); }
  template <class T>
  T operator()(const Vec<T, dim>& eta, const Vec<T, dim>& pi) const {
    Mat<T, M::template Tangent<double>::RowsAtCompileTime, dim> D;
    const auto x = chart_with_differential<M, T>(centre, eta, D);
    return ham(x, covector_from_chart<M, T>(D, pi));
  }
};

struct SphericalPendulumHamiltonian {
  using Manifold = Sphere;
  SphericalPendulum system;
  std::string name() const { return system.name(); }
  template <class T>
  T operator()(const Vec<T, 3>& x, const Vec<T, 3>& p) const {
    const double m = system.m, l = system.l, g = system.g;
    return (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) * (0.5 / (m * l * l)) + (m * g * l) * x[2];
  }
};

struct RigidBodyHamiltonian {
  using Manifold = SO3;
  RigidBody system;
  std::string name() const { return system.name(); }
  template <class T>
  T operator()(const Mat<T, 3, 3>&, const Vec<T, 3>& Pi) const {
    const Vec<double, 3>& I = system.inertia;
    return Pi[0] * Pi[0] * (0.5 / I[0]) + Pi[1] * Pi[1] * (0.5 / I[1]) + Pi[2] * Pi[2] * (0.5 / I[2]);
  }
};

struct HeavyTopHamiltonian {
  using Manifold = SO3;
  HeavyTop system;
  std::string name() const { return system.name(); }
  template <class T>
  T operator()(const Mat<T, 3, 3>& R, const Vec<T, 3>& Pi) const {
    const Vec<double, 3>& I = system.inertia;
    const Vec<double, 3>& chi = system.chi;
    const T height = R(2, 0) * chi[0] + R(2, 1) * chi[1] + R(2, 2) * chi[2];
    return Pi[0] * Pi[0] * (0.5 / I[0]) + Pi[1] * Pi[1] * (0.5 / I[1]) + Pi[2] * Pi[2] * (0.5 / I[2]) +
           (system.m * system.g) * height;
  }
};

// The Hamiltonian of a system, written out where it is known in closed form.
inline SphericalPendulumHamiltonian hamiltonian_of(const SphericalPendulum& s) { return {s}; }
inline RigidBodyHamiltonian hamiltonian_of(const RigidBody& s) { return {s}; }
inline HeavyTopHamiltonian hamiltonian_of(const HeavyTop& s) { return {s}; }

// The Hamiltonian in the chart centred at c.
template <class H>
ChartHamiltonian<H> chart_hamiltonian(const H& h, const typename H::Manifold::template Point<double>& c) {
  return {h, c};
}

}  // namespace dvm
