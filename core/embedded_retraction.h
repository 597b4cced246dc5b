// A retraction written as a function into the embedding space: a point x of S^2
// (3 numbers) or SO(3) (the 9 entries of R, column-major) and a tangent vector v (3
// numbers: the embedded tangent vector on S^2, the body angular velocity on SO(3))
// go to `out` in the same embedding, which the manifold's map then normalises onto the
// manifold (core/manifold_maps.h):
//   S^2:    R_x(v) = y / |y|,  y = f(x, v)
//   SO(3):  R_R(w) = the Gram-Schmidt orthonormalisation of the columns of f(R, w)
// Both normalisations leave a point of the manifold unchanged, so a function that
// already lands on it (exp, Cayley, the projection) is that retraction to round-off.
// Whether the result is a retraction (R_x(0) = x, D_v R_x(0) = Id, the axioms behind
// Def. 2.2 for the maps of Prop. 2.3) is checked where the function is made, not here.
//
// The steps evaluate a retraction for their scalar types: double and the Jets of
// their chart dimensions, nested for second derivatives. Core cannot see what computes
// f (an expression written in a scene lives in mechanics/), so the function is an
// interface with one virtual evaluate per scalar type of EmbeddedRetraction: the steps on
// S^2, (S^2)^K and SO(3) use exactly these. `supports<T>` says whether a type is in
// the list; a map asked for another type throws std::logic_error (no step of the
// runtime asks for one).
#pragma once

#include <string>
#include <type_traits>

#include <ceres/jet.h>

namespace dvm {

template <class T>
struct EmbeddedEvaluator {
  virtual ~EmbeddedEvaluator() = default;
  virtual void evaluate(const T* x, const T* v, T* out) const = 0;
};

template <class... Ts>
struct EmbeddedFunction : EmbeddedEvaluator<Ts>... {
  using EmbeddedEvaluator<Ts>::evaluate...;
  template <class T>
  static constexpr bool supports = (std::is_same_v<T, Ts> || ...);
  virtual std::string text() const = 0;  // what the function is, for reports
};

namespace embedded_detail {
template <int N>
using J = ceres::Jet<double, N>;
}  // namespace embedded_detail

// The scalar types of the steps on S^2 (chart dimension 2), (S^2)^K (2K, K <= 4) and
// SO(3) (3), with the Jets of two points (4, 6), nested Jets for the Jacobians of the
// step equations, and Jet<Jet<double, 9>, 3> of the boundary-value problem on S^2 (the list is what the
// kernels of solvers/runtime and the map checks instantiate, found by compiling them
// with a static_assert in detail::evaluate_embedded).
using EmbeddedRetraction =
    EmbeddedFunction<double, embedded_detail::J<1>, embedded_detail::J<2>, embedded_detail::J<3>,
                     embedded_detail::J<4>, embedded_detail::J<6>, ceres::Jet<embedded_detail::J<2>, 2>,
                     ceres::Jet<embedded_detail::J<3>, 3>, ceres::Jet<embedded_detail::J<4>, 4>,
                     ceres::Jet<embedded_detail::J<6>, 6>, ceres::Jet<embedded_detail::J<9>, 3>,
                     // the spherical chain of 4 links, (S^2)^4 (2, 3 links: the sizes above)
                     embedded_detail::J<8>, ceres::Jet<embedded_detail::J<8>, 8>,
                     // the identity checks of core/map_checks.h (dvm check-map)
                     ceres::Jet<embedded_detail::J<8>, 1>, ceres::Jet<embedded_detail::J<8>, 4>,
                     ceres::Jet<embedded_detail::J<12>, 1>, ceres::Jet<embedded_detail::J<12>, 6>>;

}  // namespace dvm
