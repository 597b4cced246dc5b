// Scalars for scalar-generic code: plain doubles and Ceres Jets, nested.
//
// Everything in dvm that is differentiated is written once as a template on the
// scalar type T and evaluated with T = double, T = ceres::Jet<double, N> (first
// derivatives) and T = ceres::Jet<ceres::Jet<double, N>, M> (second derivatives,
// e.g. the Jacobian of the discrete Euler-Lagrange residual, which already holds a
// first derivative of L_d).
//
// Ceres only defines arithmetic between a Jet<T, N> and its own scalar T, so with
// nested Jets an expression such as `0.5 * v * v` does not compile: 0.5 is a
// double, not a Jet<double, N>. This header closes that gap, so that a Lagrangian
// can be written with ordinary numeric literals and double parameters:
//   - arithmetic (+ - * /) between any Jet and any arithmetic type;
//   - Eigen ScalarBinaryOpTraits so that Eigen expressions may mix a matrix of
//     (nested) Jets with a double scalar;
//   - dvm::constant<T>(c) builds the constant c as a scalar of type T;
//   - dvm::value(x) reads the double at the bottom of a nested Jet.
#pragma once

#include <ceres/jet.h>

#include <Eigen/Core>
#include <cmath>
#include <type_traits>

namespace dvm {

template <class T>
struct is_jet : std::false_type {};
template <class T, int N>
struct is_jet<ceres::Jet<T, N>> : std::true_type {};
template <class T>
inline constexpr bool is_jet_v = is_jet<T>::value;

// Nesting depth: 0 for double, 1 for Jet<double, N>, 2 for Jet<Jet<double,N>,M>.
template <class T>
struct jet_depth : std::integral_constant<int, 0> {};
template <class T, int N>
struct jet_depth<ceres::Jet<T, N>>
    : std::integral_constant<int, 1 + jet_depth<T>::value> {};

// The constant c as a scalar of type T (all derivative parts zero).
template <class T>
inline T constant(double c) {
  if constexpr (is_jet_v<T>) {
    return T(constant<typename T::Scalar>(c));
  } else {
    return static_cast<T>(c);
  }
}

// The double value at the bottom of a (possibly nested) Jet.
template <class T>
inline double value(const T& x) {
  if constexpr (is_jet_v<T>) {
    return value(x.a);
  } else {
    return static_cast<double>(x);
  }
}

template <class T, int N>
using Vec = Eigen::Matrix<T, N, 1>;
template <class T, int R, int C>
using Mat = Eigen::Matrix<T, R, C>;

// Element-wise double values of a vector of scalars.
template <class T, int N>
inline Vec<double, N> values(const Vec<T, N>& x) {
  Vec<double, N> out(x.rows());
  for (int i = 0; i < x.rows(); ++i) out[i] = value(x[i]);
  return out;
}

// Cast a double vector to scalars of type T (constants).
template <class T, int N>
inline Vec<T, N> constants(const Vec<double, N>& x) {
  Vec<T, N> out(x.rows());
  for (int i = 0; i < x.rows(); ++i) out[i] = constant<T>(x[i]);
  return out;
}

// Infinity norm of the double values (used for convergence tests on any T). A NaN
// anywhere gives NaN (std::fmax would drop it and hide a failure).
template <class Derived>
inline double max_abs(const Eigen::MatrixBase<Derived>& x) {
  double m = 0.0;
  for (Eigen::Index j = 0; j < x.cols(); ++j)
    for (Eigen::Index i = 0; i < x.rows(); ++i) {
      const double a = std::fabs(value(x(i, j)));
      if (std::isnan(a)) return a;
      if (a > m) m = a;
    }
  return m;
}

// max |x_i| over a vector or matrix of doubles, NaN if any entry is NaN (as max_abs above,
// in plain loops over the storage: four running maxima, which do not
// wait on each other, where one would make each comparison wait on the last).
// (fixed sizes: one pass over a few entries, inlined)
template <class Derived>
[[gnu::always_inline]] inline double inf_norm_fixed(const Eigen::PlainObjectBase<Derived>& x) {
  const double* d = x.data();
  double m = 0.0;
  bool nan = false;
  for (Eigen::Index i = 0; i < Derived::SizeAtCompileTime; ++i) {
    const double a = std::fabs(d[i]);
    nan |= a != a;
    m = a > m ? a : m;
  }
  return nan ? NAN : m;
}
template <class Derived>
double inf_norm(const Eigen::PlainObjectBase<Derived>& x) {
  if constexpr (Derived::SizeAtCompileTime != Eigen::Dynamic && Derived::SizeAtCompileTime <= 16)
    return inf_norm_fixed(x);
  const double* d = x.data();
  const Eigen::Index n = x.size();
  double m[4] = {0.0, 0.0, 0.0, 0.0};
  bool nan = false;
  const Eigen::Index n4 = n - n % 4;  // (the bounds named once: g++ misreads a shared index
                                      // at a fixed size and warns of an overflow)
  for (Eigen::Index i = 0; i < n4; i += 4)
    for (int k = 0; k < 4; ++k) {
      const double a = std::fabs(d[i + k]);
      nan |= a != a;
      m[k] = a > m[k] ? a : m[k];
    }
  for (Eigen::Index i = n4; i < n; ++i) {
    const double a = std::fabs(d[i]);
    nan |= a != a;
    m[0] = a > m[0] ? a : m[0];
  }
  const double m01 = m[1] > m[0] ? m[1] : m[0], m23 = m[3] > m[2] ? m[3] : m[2];
  return nan ? NAN : m23 > m01 ? m23 : m01;
}

}  // namespace dvm

// Mixed Jet / arithmetic operators, found by argument-dependent lookup on Jet.
// Ceres already provides Jet<T,N> op T; these cover every other arithmetic type
// (in particular double against a nested Jet) by converting it to T first.
namespace ceres {

#define DVM_JET_SCALAR_OPERATOR(op)                                            \
  template <class T, int N, class S,                                           \
            std::enable_if_t<std::is_arithmetic_v<S> && !std::is_same_v<S, T>, \
                             int> = 0>                                         \
  inline Jet<T, N> operator op(const Jet<T, N>& f, S s) {                      \
    return f op dvm::constant<T>(static_cast<double>(s));                      \
  }                                                                            \
  template <class T, int N, class S,                                           \
            std::enable_if_t<std::is_arithmetic_v<S> && !std::is_same_v<S, T>, \
                             int> = 0>                                         \
  inline Jet<T, N> operator op(S s, const Jet<T, N>& f) {                      \
    return dvm::constant<T>(static_cast<double>(s)) op f;                      \
  }
DVM_JET_SCALAR_OPERATOR(+)
DVM_JET_SCALAR_OPERATOR(-)
DVM_JET_SCALAR_OPERATOR(*)
#undef DVM_JET_SCALAR_OPERATOR

// Jet / number as a product with the reciprocal: Ceres' own Jet<T, N> / T builds
// T(1.0), which does not compile once T is itself a nested Jet (depth 3 and more, as
// met by a Hamiltonian of a Lagrangian differentiated twice).
template <class T, int N, class S, std::enable_if_t<std::is_arithmetic_v<S>, int> = 0>
inline Jet<T, N> operator/(const Jet<T, N>& f, S s) {
  return f * dvm::constant<T>(1.0 / static_cast<double>(s));
}
template <class T, int N, class S,
          std::enable_if_t<std::is_arithmetic_v<S> && !std::is_same_v<S, T>, int> = 0>
inline Jet<T, N> operator/(S s, const Jet<T, N>& f) {
  return dvm::constant<T>(static_cast<double>(s)) / f;
}

}  // namespace ceres

// Let Eigen expressions combine matrices of nested Jets with double scalars.
namespace Eigen {
template <class T, int N, int M, class BinaryOp>
struct ScalarBinaryOpTraits<ceres::Jet<ceres::Jet<T, N>, M>, double, BinaryOp> {
  using ReturnType = ceres::Jet<ceres::Jet<T, N>, M>;
};
template <class T, int N, int M, class BinaryOp>
struct ScalarBinaryOpTraits<double, ceres::Jet<ceres::Jet<T, N>, M>, BinaryOp> {
  using ReturnType = ceres::Jet<ceres::Jet<T, N>, M>;
};
}  // namespace Eigen
