// (S^2)^K with K known only at run time: the configuration space of the spherical
// chain of any number of links (mechanics/spherical_chain.h, solvers/sphere_chain_step.h).
#pragma once

#include <Eigen/Core>
#include <cmath>

#include "core/manifolds.h"

namespace dvm {

// The storage of SpherePower<K> (core/manifolds.h) in Eigen's dynamic vectors,
// K = x.size() / 3; the operations a run-time-sized step and the integrate loop need,
// at double only.
struct DynamicSpherePower {
  static constexpr int dim = Eigen::Dynamic;
  static constexpr const char* name = "(S^2)^n";
  template <class T>
  using Point = Eigen::Matrix<T, Eigen::Dynamic, 1>;
  template <class T>
  using Tangent = Eigen::Matrix<T, Eigen::Dynamic, 1>;
  using V = Eigen::VectorXd;

  static int factors(const V& x) { return static_cast<int>(x.size() / 3); }
  static Vec<double, 3> block(const V& x, int i) { return x.segment<3>(3 * i); }

  static V tangent(const V& x, const V& nu) {
    V v(x.size());
    for (int i = 0; i < factors(x); ++i)
      v.segment<3>(3 * i) = Sphere::tangent(block(x, i), Vec<double, 2>(nu.segment<2>(2 * i)));
    return v;
  }
  static V tangent_coordinates(const V& x, const V& v) {
    V nu(2 * factors(x));
    for (int i = 0; i < factors(x); ++i) nu.segment<2>(2 * i) = Sphere::tangent_coordinates(block(x, i), block(v, i));
    return nu;
  }
  static V covector_to_local(const V& x, const V& p) { return tangent_coordinates(x, p); }
  static V covector_from_local(const V& x, const V& p) { return tangent(x, p); }
  static double point_defect(const V& x) {
    double d = 0.0;
    for (int i = 0; i < factors(x); ++i) d = std::fmax(d, Sphere::point_defect(block(x, i)));
    return d;
  }
  static double tangent_defect(const V& x, const V& v) {
    double d = 0.0;
    for (int i = 0; i < factors(x); ++i) d = std::fmax(d, Sphere::tangent_defect(block(x, i), block(v, i)));
    return d;
  }
  static V next_guess(const V& q_prev, const V& q) {
    V g(2 * factors(q));
    for (int i = 0; i < factors(q); ++i) g.segment<2>(2 * i) = Sphere::next_guess(block(q_prev, i), block(q, i));
    return g;
  }
};

}  // namespace dvm
