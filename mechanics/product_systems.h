// A rigid body moving in space: Q = R^3 x SO(3) (core/product_manifold.h), the point
// (r, R) with r the centre of mass and R the attitude, the velocity (rdot, w) with w
// the body angular velocity.
//
//   L = m |rdot|^2/2 + (I1 w1^2 + I2 w2^2 + I3 w3^2)/2 - m g r_3 - k |r + R b|^2/2
//
// Gravity (x_3 upward) acts at the centre of mass; optionally the body point b (body
// frame) is tied to the origin by a spring of stiffness k, which couples translation
// and rotation. Symmetries and their momentum maps (p the momentum conjugate to r,
// Pi the body angular momentum):
//   translations (k = 0): p; horizontal ones only when g != 0
//   rotations about the origin, (r, R) -> (Q r, Q R) (every k): the total angular
//     momentum J = r x p + R Pi; about the vertical only (J_3) when g != 0.
#pragma once

#include <stdexcept>
#include <string>

#include "core/product_manifold.h"
#include "mechanics/manifold_systems.h"

namespace dvm {

using SpaceBody = Product<Euclidean<3>, SO3>;  // R^3 x SO(3), points (r, vec R)

struct RigidBodyInSpace {
  using Manifold = SpaceBody;
  static constexpr int dim = 6;
  double m = 1.0, g = 0.0, k = 0.0;
  Vec<double, 3> inertia{1.0, 2.0, 3.0}, b{0.0, 0.0, 0.0};
  RigidBodyInSpace(double m_, const Vec<double, 3>& I, double g_ = 0.0, double k_ = 0.0,
                   const Vec<double, 3>& b_ = Vec<double, 3>::Zero())
      : m(m_), g(g_), k(k_), inertia(I), b(b_) {
    if (!(m > 0) || !std::isfinite(m) || !std::isfinite(g) || !(k >= 0) || !std::isfinite(k))
      throw std::invalid_argument("rigid-body-in-space: m must be positive, g finite, k >= 0");
    for (int i = 0; i < 3; ++i)
      if (!(I[i] > 0) || !std::isfinite(I[i]) || !std::isfinite(b[i]))
        throw std::invalid_argument("rigid-body-in-space: moments of inertia must be positive, b finite");
  }
  std::string name() const { return "rigid-body-in-space"; }

  template <class T>
  T operator()(const Vec<T, 12>& x, const Vec<T, 6>& v) const {
    // x = (r, R column-major): R(i, j) = x[3 + 3 j + i]
    T kinetic = (0.5 * m) * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) +
                0.5 * (inertia[0] * v[3] * v[3] + inertia[1] * v[4] * v[4] + inertia[2] * v[5] * v[5]);
    T spring = constant<T>(0.0);
    if (k != 0.0) {
      for (int i = 0; i < 3; ++i) {
        const T a = x[i] + x[3 + i] * b[0] + x[6 + i] * b[1] + x[9 + i] * b[2];
        spring = spring + a * a;
      }
    }
    return kinetic - (m * g) * x[2] - (0.5 * k) * spring;
  }

  static Vec<double, 3> position(const Vec<double, 12>& x) { return x.head<3>(); }
  static Mat<double, 3, 3> attitude(const Vec<double, 12>& x) {
    return Eigen::Map<const Mat<double, 3, 3>>(x.data() + 3);
  }
  static Vec<double, 12> point(const Vec<double, 3>& r, const Mat<double, 3, 3>& R) {
    return SpaceBody::make_point<double>(r, R);
  }
  // Linear momentum p and total angular momentum r x p + R Pi.
  static Vec<double, 3> linear_momentum(const Vec<double, 12>&, const Vec<double, 6>& p) { return p.head<3>(); }
  static Vec<double, 3> angular_momentum(const Vec<double, 12>& x, const Vec<double, 6>& p) {
    return position(x).cross(Vec<double, 3>(p.head<3>())) + attitude(x) * Vec<double, 3>(p.tail<3>());
  }
};

}  // namespace dvm
