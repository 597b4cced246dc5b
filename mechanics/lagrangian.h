// Lagrangians L : TQ -> R on Q = R^n, and what is derived from them.
//
//   Legendre map   FL(q, v) = (q, dL/dv(q, v)) = (q, p)
//   energy         E_L(q, v) = <dL/dv(q, v), v> - L(q, v)
//   regularity     L is regular at (q, v) when the velocity Hessian d2L/dv2 is
//                  invertible there; then FL is a local diffeomorphism and the
//                  discrete Legendre equations define a one-step map.
//
// A Lagrangian type S provides
//   static constexpr int dim;                    // n, fixed at compile time
//   std::string name() const;
//   template <class T> T operator()(const Vec<T, dim>& q, const Vec<T, dim>& v) const;
// written for any scalar T (double and nested ceres::Jet), and may provide
//   template <class T> void gradient(q, v, Vec<T, dim>& dLdq, Vec<T, dim>& dLdv) const;
//   Vec<double, dim> velocity(q, p) const;       // the inverse Legendre map
// as closed-form optimisations; tests check them against automatic differentiation.
#pragma once

#include <sstream>
#include <stdexcept>
#include <type_traits>
#include <utility>

#include "core/dense_solve.h"
#include "core/map_operations.h"
#include "core/scalar.h"

namespace dvm {

template <class S, class = void>
struct has_gradient : std::false_type {};
template <class S>
struct has_gradient<S, std::void_t<decltype(std::declval<const S&>().gradient(
                           std::declval<const Vec<double, S::dim>&>(), std::declval<const Vec<double, S::dim>&>(),
                           std::declval<Vec<double, S::dim>&>(), std::declval<Vec<double, S::dim>&>()))>>
    : std::true_type {};

template <class S, class = void>
struct has_velocity : std::false_type {};
template <class S>
struct has_velocity<S, std::void_t<decltype(std::declval<const S&>().velocity(
                           std::declval<const Vec<double, S::dim>&>(), std::declval<const Vec<double, S::dim>&>()))>>
    : std::true_type {};

// The same Lagrangian with its closed forms hidden: everything is then derived by
// automatic differentiation. Used to check closed forms against the generic path,
// and by anyone who wants to measure what the closed forms buy.
template <class S>
struct GenericOnly {
  static constexpr int dim = S::dim;
  S system;
  std::string name() const { return system.name(); }
  template <class T>
  T operator()(const Vec<T, dim>& q, const Vec<T, dim>& v) const {
    return system(q, v);
  }
};

// dL/dq and dL/dv at (q, v), for any scalar T: the system's closed form if it has
// one, automatic differentiation otherwise.
template <class S, class T>
void lagrangian_gradient(const S& L, const Vec<T, S::dim>& q, const Vec<T, S::dim>& v, Vec<T, S::dim>& dLdq,
                         Vec<T, S::dim>& dLdv) {
  constexpr int N = S::dim;
  if constexpr (has_gradient<S>::value) {
    L.gradient(q, v, dLdq, dLdv);
  } else {
    using D = ceres::Jet<T, 2 * N>;
    Vec<D, N> qd, vd;
    for (int i = 0; i < N; ++i) {
      qd[i] = seed<T, 2 * N>(q[i], i);
      vd[i] = seed<T, 2 * N>(v[i], N + i);
    }
    const D l = L(qd, vd);
    dLdq = l.v.template head<N>();
    dLdv = l.v.template tail<N>();
  }
}

// p = dL/dv(q, v).
template <class S>
Vec<double, S::dim> legendre(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& v) {
  Vec<double, S::dim> a, b;
  lagrangian_gradient(L, q, v, a, b);
  return b;
}

// E_L(q, v) = <dL/dv, v> - L.
template <class S>
double energy(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& v) {
  Vec<double, S::dim> a, b;
  lagrangian_gradient(L, q, v, a, b);
  return b.dot(v) - L(q, v);
}

// The velocity Hessian d2L/dv2 at (q, v).
template <class S>
Mat<double, S::dim, S::dim> velocity_hessian(const S& L, const Vec<double, S::dim>& q,
                                             const Vec<double, S::dim>& v) {
  constexpr int N = S::dim;
  using D = ceres::Jet<double, N>;
  Vec<D, N> qd = constants<D>(q), vd;
  for (int i = 0; i < N; ++i) vd[i] = seed<double, N>(v[i], i);
  Vec<D, N> a, b;
  lagrangian_gradient(L, qd, vd, a, b);
  Mat<double, N, N> H;
  for (int i = 0; i < N; ++i) H.row(i) = b[i].v.transpose();
  return H;
}

// Raised when the Legendre transform cannot be inverted (a degenerate Lagrangian).
struct DegenerateLagrangianError : std::domain_error {
  using std::domain_error::domain_error;
};

// v with dL/dv(q, v) = p: the system's closed form, or Newton's method from `guess`.
template <class S>
Vec<double, S::dim> legendre_inverse(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& p,
                                     Vec<double, S::dim> guess = Vec<double, S::dim>::Zero()) {
  if constexpr (has_velocity<S>::value) {
    (void)guess;
    return L.velocity(q, p);
  } else {
    constexpr int N = S::dim;
    Vec<double, N> v = guess;
    const double scale = std::fmax(1e-300, max_abs(p));
    for (int it = 0; it < 50; ++it) {
      const Vec<double, N> r = legendre(L, q, v) - p;
      if (max_abs(r) <= 1e-14 * scale) return v;
      const Mat<double, N, N> H = velocity_hessian(L, q, v);
      Vec<double, N> dv;
      try {
        dv = solve_dense<double, N, N>(H, r);
      } catch (const std::domain_error&) {
        throw DegenerateLagrangianError(L.name() + ": the velocity Hessian d2L/dv2 is singular; "
                                                   "the Legendre transform cannot be inverted");
      }
      v -= dv;
      if (max_abs(dv) <= 4e-16 * std::fmax(1.0, max_abs(v))) return v;
    }
    throw DegenerateLagrangianError(L.name() + ": Newton's method for the inverse Legendre map did not converge");
  }
}

}  // namespace dvm
