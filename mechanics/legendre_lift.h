// The discretization map on TQ induced by a map R_d on Q and a regular Lagrangian L
// (paper Prop. 5.3):
//
//   R_d^L = (FL^{-1}, FL^{-1}) o R_d^{T*} o TFL : TTQ -> TQ x TQ,
//
// with FL(q, v) = (q, dL/dv) the Legendre map, TFL its tangent map
// TFL(q, v; qdot, vdot) = (q, p; qdot, pdot), pdot = d2L/dvdq qdot + d2L/dv2 vdot, and
// R_d^{T*} the cotangent lift of R_d (core/map_operations.h). Prop. 5.3 (b): R_d^L is a
// discretization map on TQ; (a): the method it defines on the Euler-Lagrange vector
// field Gamma_L (Eq. 5.2, the sode2 form of solvers/sode_step.h, W = h Gamma_L(X) with
// (X, W) = (R_d^L)^{-1}(Y0, Y1)) is the Hamiltonian method of Eq. 5.1 for R_d^{T*}
// carried to TQ by FL, hence symplectic. Cor. 5.4: for L = v^T M v / 2 - V(q) with M
// constant and the midpoint map, R_d^L is the tangent lift R_d^T; for other maps or a
// mass matrix that depends on q it is not.
//
// Points X = (q, v) and velocities W = (qdot, vdot) of TQ = R^{2n} are stacked vectors.
// Every part is scalar-generic: FL^{-1} by the fixed-point sweeps of
// mechanics/hamiltonian.h, the inverse of R_d^{T*} by Eq. 3.6.
//   (R_d^L)^{-1}(Y0, Y1): p_i = dL/dv(q_i, v_i); (q, p, qdot, pdot) = (R_d^{T*})^{-1}(q0, p0;
//   q1, p1); v = FL^{-1}(q, p); vdot = (d2L/dv2)^{-1} (pdot - d2L/dvdq qdot) at (q, v).
#pragma once

#include <string>

#include "core/dense_solve.h"
#include "core/map_operations.h"
#include "mechanics/hamiltonian.h"

namespace dvm {

template <class S, class Map>
class LegendreLiftedMap {
 public:
  static constexpr bool provides_inverse = true;
  static constexpr int n = S::dim;

  LegendreLiftedMap(S L, Map R) : L_(std::move(L)), R_(std::move(R)) {}
  std::string name() const { return "legendre-lift(" + R_.name() + ")"; }
  bool symmetric() const { return R_.symmetric(); }
  int order() const { return R_.order(); }
  const S& lagrangian() const { return L_; }

  template <class T, int N2>
  PointPair<T, N2> operator()(const Vec<T, N2>& X, const Vec<T, N2>& W) const {
    static_assert(N2 == 2 * n, "a point of TQ has 2 dim coordinates");
    const Vec<T, n> q = X.template head<n>(), v = X.template tail<n>();
    const Vec<T, n> qd = W.template head<n>(), vd = W.template tail<n>();
    // TFL: p = dL/dv(q, v) and pdot, its derivative along (qdot, vdot), by one Jet
    using D = ceres::Jet<T, 1>;
    Vec<D, n> qj, vj, a, b;
    for (int i = 0; i < n; ++i) {
      qj[i] = D(q[i], Vec<T, 1>::Constant(qd[i]));
      vj[i] = D(v[i], Vec<T, 1>::Constant(vd[i]));
    }
    lagrangian_gradient(L_, qj, vj, a, b);
    Vec<T, n> p, pd;
    for (int i = 0; i < n; ++i) {
      p[i] = b[i].a;
      pd[i] = b[i].v[0];
    }
    const CotangentPair<T, n> c = cotangent_lift(R_, q, p, qd, pd);
    return {stack(c.q0, velocity(c.q0, c.p0)), stack(c.q1, velocity(c.q1, c.p1))};
  }

  template <class T, int N2>
  TangentPoint<T, N2> inverse(const Vec<T, N2>& Y0, const Vec<T, N2>& Y1) const {
    static_assert(N2 == 2 * n, "a point of TQ has 2 dim coordinates");
    const Vec<T, n> q0 = Y0.template head<n>(), q1 = Y1.template head<n>();
    const Vec<T, n> p0 = momentum(q0, Vec<T, n>(Y0.template tail<n>()));
    const Vec<T, n> p1 = momentum(q1, Vec<T, n>(Y1.template tail<n>()));
    const CotangentVelocity<T, n> z = cotangent_lift_inverse(R_, q0, p0, q1, p1);
    const Vec<T, n> v = velocity(z.q, z.p);
    // d2L/dvdq and d2L/dv2 at (q, v): the derivatives of dL/dv
    using D = ceres::Jet<T, 2 * n>;
    Vec<D, n> qj, vj, a, b;
    for (int i = 0; i < n; ++i) {
      qj[i] = seed<T, 2 * n>(z.q[i], i);
      vj[i] = seed<T, 2 * n>(v[i], n + i);
    }
    lagrangian_gradient(L_, qj, vj, a, b);
    Mat<T, n, n> Lvv;
    Vec<T, n> rhs = z.pdot;
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        rhs[i] = rhs[i] - b[i].v[j] * z.qdot[j];
        Lvv(i, j) = b[i].v[n + j];
      }
    const Vec<T, n> vd = solve_dense<T, n, n>(Lvv, rhs);
    return {stack(z.q, v), stack(z.qdot, vd)};
  }

 private:
  // p = dL/dv(q, v)
  template <class T>
  Vec<T, n> momentum(const Vec<T, n>& q, const Vec<T, n>& v) const {
    Vec<T, n> a, b;
    lagrangian_gradient(L_, q, v, a, b);
    return b;
  }
  // v = FL^{-1}(q, p), with the regularity check at the solution
  template <class T>
  Vec<T, n> velocity(const Vec<T, n>& q, const Vec<T, n>& p) const {
    return legendre_inverse_regular(L_, q, p);
  }

  S L_;
  Map R_;
};

}  // namespace dvm
