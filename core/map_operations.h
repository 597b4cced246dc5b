// What every discretization map on R^n gives, derived generically (paper Sec. 2-3).
//
//   inverse        R_d^{-1}(q0, q1) = (x, v): the map's closed form if it provides
//                  one, otherwise Newton's method on R_d(x, v) = (q0, q1) with a
//                  Jacobian by automatic differentiation. Derivatives of the inverse
//                  (needed by D1 L_d, D2 L_d and their Jacobians) come from the
//                  implicit function theorem: after the double solve, a few
//                  iterations z <- z - J^{-1} (R_d(z) - q) in the Jet scalar with the
//                  exact double Jacobian J make the k-th derivative parts exact after
//                  k + 1 iterations.
//   adjoint        R_d^*(x, v) = (R^2_x(-v), R^1_x(-v))                   (Prop. 2.4)
//   tangent lift   R_d^T = T R_d o kappa_Q : T(TQ) -> TQ x TQ              (Prop. 3.2)
//                  In coordinates, with kappa_Q((x, v), (xdot, vdot)) =
//                  ((x, xdot), (v, vdot)):
//                  R_d^T((x, v), (xdot, vdot)) = ((R^1(x, xdot), DR^1 . (v, vdot)),
//                                                 (R^2(x, xdot), DR^2 . (v, vdot))).
//                  It is a discretization map on TQ; its inverse is T(R_d^{-1}).
//   cotangent lift R_d^{T*} : T(T*Q) -> T*Q x T*Q                          (Prop. 3.4)
//                  the composition of Tulczyjew's alpha_Q : T T*Q -> T* TQ, the
//                  cotangent map of R_d^{-1}, and T*(Q x Q) = T*Q x T*Q with the sign
//                  of the first momentum flipped. In coordinates: (q0, q1) = R_d(q, qdot)
//                  and, with DR the Jacobian of R_d at (q, qdot) (rows R^1, R^2,
//                  columns x, v),  DR^T (pi0, pi1) = (pdot, p),  p0 = -pi0,  p1 = pi1.
//                  It is a symplectomorphism: it pulls Omega_12 = w_2 - w_1 back to
//                  the tangent lift d_T w_Q = dq ^ dpdot + dqdot ^ dp.
//   its inverse    (Eq. 3.6): (q, qdot) = R_d^{-1}(q0, q1) and (pdot, p) = DR^T (-p0, p1).
//
// Examples (Ex. 3.4, Eqs. 3.8-3.9, Sec. 5.1): the midpoint map's cotangent lift is
//   (q, p, qdot, pdot) -> (q - qdot/2, p - pdot/2; q + qdot/2, p + pdot/2),
// and that of R_d(q, v) = (q - v, q) is (q - qdot, p; q, p + pdot).
#pragma once

#include <Eigen/LU>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

#include "core/dense_solve.h"
#include "core/discretization_map.h"

namespace dvm {

constexpr int twice(int n) { return n == Eigen::Dynamic ? Eigen::Dynamic : 2 * n; }

// (a, b) stacked into one vector of twice the size.
template <class T, int N>
inline Vec<T, twice(N)> stack(const Vec<T, N>& a, const Vec<T, N>& b) {
  Vec<T, twice(N)> out(2 * a.rows());
  out.head(a.rows()) = a;
  out.tail(b.rows()) = b;
  return out;
}

// A Jet with value a and unit derivative in direction k (works at any nesting).
template <class T, int K>
inline ceres::Jet<T, K> seed(const T& a, int k) {
  ceres::Jet<T, K> j(a);
  j.v[k] = constant<T>(1.0);
  return j;
}

// Raised when a map is evaluated or inverted outside its domain.
struct MapDomainError : std::domain_error {
  using std::domain_error::domain_error;
};

// R_d(x, v) and its Jacobian J (2N x 2N; rows (R^1, R^2), columns (x, v)).
template <class M, class T, int N>
PointPair<T, N> map_with_jacobian(const M& map, const Vec<T, N>& x, const Vec<T, N>& v,
                                  Mat<T, twice(N), twice(N)>& J) {
  static_assert(N != Eigen::Dynamic, "map_with_jacobian needs a fixed dimension");
  using D = ceres::Jet<T, 2 * N>;
  Vec<D, N> xd, vd;
  for (int i = 0; i < N; ++i) {
    xd[i] = seed<T, 2 * N>(x[i], i);
    vd[i] = seed<T, 2 * N>(v[i], N + i);
  }
  const PointPair<D, N> r = map(xd, vd);
  PointPair<T, N> out;
  for (int i = 0; i < N; ++i) {
    out.q0[i] = r.q0[i].a;
    out.q1[i] = r.q1[i].a;
    J.row(i) = r.q0[i].v.transpose();
    J.row(N + i) = r.q1[i].v.transpose();
  }
  return out;
}

struct InverseOptions {
  int max_iterations = 50;
  double tolerance = 1e-14;  // on |R_d(x, v) - (q0, q1)|_inf, relative to |q|_inf
};

// Newton's method for R_d(x, v) = (q0, q1) in doubles; also returns the Jacobian
// of R_d at the solution. Throws MapDomainError if it does not converge.
template <class M, int N>
TangentPoint<double, N> newton_inverse(const M& map, const Vec<double, N>& q0, const Vec<double, N>& q1,
                                       Mat<double, 2 * N, 2 * N>* jacobian = nullptr,
                                       const InverseOptions& options = {}) {
  const Vec<double, 2 * N> target = stack(q0, q1);
  Vec<double, 2 * N> z = stack(Vec<double, N>(0.5 * (q0 + q1)), Vec<double, N>(q1 - q0)), F;
  Mat<double, 2 * N, 2 * N> J;
  const double scale = std::fmax(1.0, max_abs(target));
  double fnorm = 0.0;
  for (int it = 0; it < options.max_iterations; ++it) {
    const PointPair<double, N> r =
        map_with_jacobian(map, Vec<double, N>(z.template head<N>()), Vec<double, N>(z.template tail<N>()), J);
    F = stack(Vec<double, N>(r.q0 - q0), Vec<double, N>(r.q1 - q1));
    fnorm = max_abs(F);
    if (!std::isfinite(fnorm)) break;
    if (fnorm <= options.tolerance * scale) {
      if (jacobian) *jacobian = J;
      return {z.template head<N>(), z.template tail<N>()};
    }
    const Vec<double, 2 * N> dz = J.fullPivLu().solve(F);
    z -= dz;
    if (max_abs(dz) <= 1e-16 * std::fmax(1.0, max_abs(z)) && fnorm <= 1e3 * options.tolerance * scale) {
      if (jacobian) *jacobian = J;
      return {z.template head<N>(), z.template tail<N>()};
    }
  }
  throw MapDomainError(map.name() + ": Newton inverse did not converge (residual " + std::to_string(fnorm) +
                       "); the points may be outside the map's domain");
}

// R_d^{-1}(q0, q1) for any scalar T.
template <class M, class T, int N>
TangentPoint<T, N> inverse(const M& map, const Vec<T, N>& q0, const Vec<T, N>& q1) {
  if constexpr (M::provides_inverse) {
    return map.inverse(q0, q1);
  } else {
    Mat<double, 2 * N, 2 * N> J;
    const TangentPoint<double, N> base = newton_inverse(map, values(q0), values(q1), &J);
    if constexpr (!is_jet_v<T>) {
      return base;
    } else {
      // Implicit function theorem by fixed point: derivative parts of order k are
      // exact after k + 1 sweeps with the exact Jacobian at the solution.
      const Mat<double, 2 * N, 2 * N> Jinv = J.inverse();
      Vec<T, N> x = constants<T>(base.x), v = constants<T>(base.v);
      for (int sweep = 0; sweep <= jet_depth<T>::value; ++sweep) {
        const PointPair<T, N> r = map(x, v);
        const Vec<T, 2 * N> F = stack(Vec<T, N>(r.q0 - q0), Vec<T, N>(r.q1 - q1));
        for (int i = 0; i < 2 * N; ++i) {
          T corr = constant<T>(0.0);
          for (int j = 0; j < 2 * N; ++j) corr = corr + Jinv(i, j) * F[j];
          if (i < N)
            x[i] = x[i] - corr;
          else
            v[i - N] = v[i - N] - corr;
        }
      }
      return {x, v};
    }
  }
}

template <class M, class = void>
struct has_inverse_increment : std::false_type {};
template <class M>
struct has_inverse_increment<M, std::void_t<decltype(std::declval<const M&>().inverse_increment(
                                    std::declval<const Vec<double, 1>&>(), std::declval<const Vec<double, 1>&>()))>>
    : std::true_type {};

// R_d^{-1}(q0, q0 + dq), without forming q0 + dq when the map can avoid it.
template <class M, class T, int N>
TangentPoint<T, N> inverse_increment(const M& map, const Vec<T, N>& q0, const Vec<T, N>& dq) {
  if constexpr (has_inverse_increment<M>::value) {
    return map.inverse_increment(q0, dq);
  } else {
    return inverse(map, q0, Vec<T, N>(q0 + dq));
  }
}

template <class M, class = void>
struct has_displacement : std::false_type {};
template <class M>
struct has_displacement<M, std::void_t<decltype(std::declval<const M&>().displacement(
                               std::declval<const Vec<double, 1>&>(), std::declval<const Vec<double, 1>&>()))>>
    : std::true_type {};

// R_d(x, v) - (x, x), without forming R_d(x, v) when the map can avoid it (for points
// near x of size much larger than v, forming them rounds v away).
template <class M, class T, int N>
PointPair<T, N> displacement(const M& map, const Vec<T, N>& x, const Vec<T, N>& v) {
  if constexpr (has_displacement<M>::value) {
    return map.displacement(x, v);
  } else {
    const PointPair<T, N> r = map(x, v);
    return {Vec<T, N>(r.q0 - x), Vec<T, N>(r.q1 - x)};
  }
}

// The adjoint map R_d^*(x, v) = (R^2_x(-v), R^1_x(-v)) (Prop. 2.4).
template <class M>
class Adjoint {
 public:
  static constexpr bool provides_inverse = true;
  explicit Adjoint(M map) : map_(std::move(map)) {}
  std::string name() const { return "adjoint(" + map_.name() + ")"; }
  bool symmetric() const { return map_.symmetric(); }
  int order() const { return map_.order(); }
  const M& base() const { return map_; }

  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    const PointPair<T, N> r = map_(x, Vec<T, N>(-v));
    return {r.q1, r.q0};
  }
  template <class T, int N>
  PointPair<T, N> displacement(const Vec<T, N>& x, const Vec<T, N>& v) const {
    const PointPair<T, N> r = dvm::displacement(map_, x, Vec<T, N>(-v));
    return {r.q1, r.q0};
  }
  // R_d^*(x, v) = (q0, q1)  <=>  R_d(x, -v) = (q1, q0).
  template <class T, int N>
  TangentPoint<T, N> inverse(const Vec<T, N>& q0, const Vec<T, N>& q1) const {
    const TangentPoint<T, N> t = dvm::inverse(map_, q1, q0);
    return {t.x, -t.v};
  }
  // R_d^*(x, v) = (q0, q0 + dq)  <=>  R_d(x, -v) = (q0 + dq, (q0 + dq) - dq): the base
  // map's increment form, so that v = -(-dq) carries no cancellation.
  template <class T, int N>
  TangentPoint<T, N> inverse_increment(const Vec<T, N>& q0, const Vec<T, N>& dq) const {
    const TangentPoint<T, N> t = dvm::inverse_increment(map_, Vec<T, N>(q0 + dq), Vec<T, N>(-dq));
    return {t.x, -t.v};
  }

 private:
  M map_;
};

template <class M>
Adjoint<M> adjoint(const M& map) {
  return Adjoint<M>(map);
}

// The tangent lift R_d^T = T R_d o kappa_Q (Prop. 3.2), a discretization map on
// TQ = R^{2N}. A point of TQ is X = (x, v); a velocity at it is V = (xdot, vdot).
template <class M>
class TangentLift {
 public:
  static constexpr bool provides_inverse = true;
  explicit TangentLift(M map) : map_(std::move(map)) {}
  std::string name() const { return "tangent-lift(" + map_.name() + ")"; }
  bool symmetric() const { return map_.symmetric(); }
  int order() const { return map_.order(); }

  template <class T, int N2>
  PointPair<T, N2> operator()(const Vec<T, N2>& X, const Vec<T, N2>& V) const {
    return lifted(X, V, [this](const auto& x, const auto& xdot) { return map_(x, xdot); });
  }
  // R_d^T(X, V) - (X, X): the base map's displacement, differentiated along V (the
  // derivative of R^i(x + e v, ...) - (x + e v) is that of R^i minus v).
  template <class T, int N2>
  PointPair<T, N2> displacement(const Vec<T, N2>& X, const Vec<T, N2>& V) const {
    return lifted(X, V, [this](const auto& x, const auto& xdot) { return dvm::displacement(map_, x, xdot); });
  }

  // (R_d^T)^{-1} = kappa_Q^{-1} o T(R_d^{-1}).
  template <class T, int N2>
  TangentPoint<T, N2> inverse(const Vec<T, N2>& Q0, const Vec<T, N2>& Q1) const {
    constexpr int N = N2 / 2;
    using D = ceres::Jet<T, 1>;
    Vec<D, N> a, b;
    for (int i = 0; i < N; ++i) {
      a[i] = D(Q0[i], Vec<T, 1>::Constant(Q0[N + i]));
      b[i] = D(Q1[i], Vec<T, 1>::Constant(Q1[N + i]));
    }
    const TangentPoint<D, N> t = dvm::inverse(map_, a, b);
    TangentPoint<T, N2> out;
    for (int i = 0; i < N; ++i) {
      out.x[i] = t.x[i].a;
      out.x[N + i] = t.x[i].v[0];
      out.v[i] = t.v[i].a;
      out.v[N + i] = t.v[i].v[0];
    }
    return out;
  }

 private:
  // f (the map or its displacement) at (x + e v, xdot + e vdot), X = (x, v), V = (xdot,
  // vdot), with one Jet: values and derivatives unpacked into points of TQ.
  template <class T, int N2, class F>
  static PointPair<T, N2> lifted(const Vec<T, N2>& X, const Vec<T, N2>& V, const F& f) {
    static_assert(N2 != Eigen::Dynamic && N2 % 2 == 0, "a point of TQ has 2N coordinates");
    constexpr int N = N2 / 2;
    using D = ceres::Jet<T, 1>;
    Vec<D, N> x, xdot;
    for (int i = 0; i < N; ++i) {
      x[i] = D(X[i], Vec<T, 1>::Constant(X[N + i]));
      xdot[i] = D(V[i], Vec<T, 1>::Constant(V[N + i]));
    }
    const PointPair<D, N> r = f(x, xdot);
    PointPair<T, N2> out;
    for (int i = 0; i < N; ++i) {
      out.q0[i] = r.q0[i].a;
      out.q0[N + i] = r.q0[i].v[0];
      out.q1[i] = r.q1[i].a;
      out.q1[N + i] = r.q1[i].v[0];
    }
    return out;
  }

  M map_;
};

template <class M>
TangentLift<M> tangent_lift(const M& map) {
  return TangentLift<M>(map);
}

// A point (q, p) of T*Q with a tangent vector (qdot, pdot): an element of T(T*Q).
template <class T, int N>
struct CotangentVelocity {
  Vec<T, N> q, p, qdot, pdot;
};
// A pair of points of T*Q.
template <class T, int N>
struct CotangentPair {
  Vec<T, N> q0, p0, q1, p1;
};

// The cotangent lift R_d^{T*}(q, p, qdot, pdot) = (q0, p0, q1, p1) (Prop. 3.4).
template <class M, class T, int N>
CotangentPair<T, N> cotangent_lift(const M& map, const Vec<T, N>& q, const Vec<T, N>& p,
                                   const Vec<T, N>& qdot, const Vec<T, N>& pdot) {
  Mat<T, 2 * N, 2 * N> J;
  const PointPair<T, N> r = map_with_jacobian(map, q, qdot, J);
  const Vec<T, 2 * N> pi = solve_dense<T, 2 * N, 2 * N>(J.transpose(), stack(pdot, p));
  return {r.q0, Vec<T, N>(-pi.template head<N>()), r.q1, Vec<T, N>(pi.template tail<N>())};
}

// Its inverse (Eq. 3.6): (q, qdot) = R_d^{-1}(q0, q1), (pdot, p) = DR^T (-p0, p1).
template <class M, class T, int N>
CotangentVelocity<T, N> cotangent_lift_inverse(const M& map, const Vec<T, N>& q0, const Vec<T, N>& p0,
                                               const Vec<T, N>& q1, const Vec<T, N>& p1) {
  const TangentPoint<T, N> t = inverse(map, q0, q1);
  Mat<T, 2 * N, 2 * N> J;
  map_with_jacobian(map, t.x, t.v, J);
  const Vec<T, 2 * N> a = J.transpose() * stack(Vec<T, N>(-p0), p1);
  return {t.x, Vec<T, N>(a.template tail<N>()), t.v, Vec<T, N>(a.template head<N>())};
}

}  // namespace dvm
