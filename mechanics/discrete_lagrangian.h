// The discrete Lagrangian of a discretization map (paper Sec. 5.3):
//
//   L_d(q0, q1) = h L(R_d^{-1}(q0, q1) / h),
//
// where (x, v) / h = (x, v / h): the point x and the velocity v / h. Its partial
// derivatives give the discrete Legendre maps
//   p0 = -D1 L_d(q0, q1),    p1 = D2 L_d(q0, q1),
// and the discrete Euler-Lagrange equations D1 L_d(q_k, q_{k+1}) + D2 L_d(q_{k-1}, q_k) = 0.
//
// Derivatives are by automatic differentiation through the map's inverse. When the
// Lagrangian has a closed-form gradient the chain rule is applied by hand:
//   d L_d = h <dL/dq, dx> + <dL/dv, dv>,
// which keeps the scalar one Jet level shallower. For the momentum update the
// combination D1 L_d + D2 L_d (the derivative along a common shift of q0 and q1) is
// computed directly, not as a sum of two large terms: for the theta maps the shift
// leaves v unchanged, so p_{k+1} - p_k = (D1 + D2) L_d carries no cancellation.
#pragma once

#include <stdexcept>

#include "core/map_operations.h"
#include "mechanics/lagrangian.h"

namespace dvm {

template <class System, class Map>
class DiscreteLagrangian {
 public:
  static constexpr int N = System::dim;
  template <class T>
  using V = Vec<T, N>;

  DiscreteLagrangian(System L, Map R, double h) : L_(std::move(L)), R_(std::move(R)), h_(h) {
    // A negative h is allowed: compositions take substeps of negative size gamma_i h.
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
  }

  const System& lagrangian() const { return L_; }
  const Map& map() const { return R_; }
  double step() const { return h_; }

  // L_d(q0, q1), for any scalar.
  template <class T>
  T operator()(const V<T>& q0, const V<T>& q1) const {
    const TangentPoint<T, N> t = inverse(R_, q0, q1);
    return h_ * L_(t.x, V<T>(t.v * (1.0 / h_)));
  }

  // Directional derivatives of L_d at (q0, q1 = q0 + dq): q0 and dq carry K
  // derivative directions each; returns the K derivatives of L_d (the value is not
  // computed). Working with the increment dq lets maps that can (the theta maps)
  // avoid the cancellation in q1 - q0, whose round-off, of size eps |q0| / h in
  // the momentum, would otherwise dominate the step residual at small h.
  template <class T, int K>
  Vec<T, K> slopes(const V<ceres::Jet<T, K>>& q0, const V<ceres::Jet<T, K>>& dq) const {
    using D = ceres::Jet<T, K>;
    const TangentPoint<D, N> t = inverse_increment(R_, q0, dq);
    if constexpr (has_gradient<System>::value) {
      V<T> x, u;
      for (int i = 0; i < N; ++i) {
        x[i] = t.x[i].a;
        u[i] = t.v[i].a * (1.0 / h_);
      }
      V<T> dLdq, dLdv;
      L_.gradient(x, u, dLdq, dLdv);
      Vec<T, K> out = Vec<T, K>::Constant(constant<T>(0.0));
      for (int i = 0; i < N; ++i) out += (h_ * dLdq[i]) * t.x[i].v + dLdv[i] * t.v[i].v;
      return out;
    } else {
      const D l = h_ * L_(t.x, V<D>(t.v * (1.0 / h_)));
      return l.v;
    }
  }

  // D1 L_d(q0, q0 + dq): moving q0 with q1 fixed moves dq the opposite way.
  template <class T>
  V<T> D1Ld_increment(const V<T>& q0, const V<T>& dq) const {
    using D = ceres::Jet<T, N>;
    V<D> a, b;
    for (int i = 0; i < N; ++i) {
      a[i] = seed<T, N>(q0[i], i);
      b[i] = D(dq[i]);
      b[i].v[i] = constant<T>(-1.0);
    }
    return slopes<T, N>(a, b);
  }

  // D1 L_d(q0, q1).
  template <class T>
  V<T> D1Ld(const V<T>& q0, const V<T>& q1) const {
    return D1Ld_increment(q0, V<T>(q1 - q0));
  }

  // D2 L_d(q0, q0 + dq): moving q1 with q0 fixed moves dq alike.
  template <class T>
  V<T> D2Ld_increment(const V<T>& q0, const V<T>& dq) const {
    using D = ceres::Jet<T, N>;
    V<D> a, b;
    for (int i = 0; i < N; ++i) {
      a[i] = D(q0[i]);
      b[i] = seed<T, N>(dq[i], i);
    }
    return slopes<T, N>(a, b);
  }

  // D2 L_d(q0, q1).
  template <class T>
  V<T> D2Ld(const V<T>& q0, const V<T>& q1) const {
    return D2Ld_increment(q0, V<T>(q1 - q0));
  }

  // D2 L_d(q0, q0 + dq) and (D1 + D2) L_d(q0, q0 + dq) in one evaluation: the
  // common shift of q0 and q1 moves q0 and leaves dq unchanged.
  void D2Ld_and_shift(const V<double>& q0, const V<double>& dq, V<double>& d2, V<double>& shift) const {
    using D = ceres::Jet<double, 2 * N>;
    V<D> a, b;
    for (int i = 0; i < N; ++i) {
      a[i] = seed<double, 2 * N>(q0[i], N + i);
      b[i] = seed<double, 2 * N>(dq[i], i);
    }
    const Vec<double, 2 * N> s = slopes<double, 2 * N>(a, b);
    d2 = s.template head<N>();
    shift = s.template tail<N>();
  }

 private:
  System L_;
  Map R_;
  double h_;
};

}  // namespace dvm
