// The library of built-in mechanical systems on R^n, each a Lagrangian with fixed
// dimension, written for any scalar type, with closed-form gradient and inverse
// Legendre map (checked against automatic differentiation in the tests).
//
//   harmonic oscillator  L = v^2/2 - omega^2 q^2/2                       Q = R
//                        exact: q(t) = q0 cos(omega t) + p0/omega sin(omega t)
//   pendulum             L = m l^2 v^2/2 + m g l cos(q)                  Q = R (angle
//                        from the downward vertical; energy E = m l^2 v^2/2 - m g l cos q)
//   Kepler problem       L = |v|^2/2 + mu/|q|                            Q = R^2 \ {0}
//                        invariants: energy, angular momentum q x p, Runge-Lenz vector
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>

#include "core/scalar.h"

namespace dvm {

namespace detail {
inline void require_positive(const char* system, const char* name, double value) {
  if (!(value > 0.0) || !std::isfinite(value))
    throw std::invalid_argument(std::string(system) + ": parameter " + name +
                                " must be positive and finite, got " + std::to_string(value));
}
}  // namespace detail

struct HarmonicOscillator {
  static constexpr int dim = 1;
  double omega = 1.0;

  explicit HarmonicOscillator(double omega_ = 1.0) : omega(omega_) {
    detail::require_positive("harmonic", "omega", omega);
  }
  std::string name() const { return "harmonic"; }

  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& v) const {
    return 0.5 * v[0] * v[0] - (0.5 * omega * omega) * q[0] * q[0];
  }
  template <class T>
  void gradient(const Vec<T, 1>& q, const Vec<T, 1>& v, Vec<T, 1>& dLdq, Vec<T, 1>& dLdv) const {
    dLdq[0] = -(omega * omega) * q[0];
    dLdv[0] = v[0];
  }
  Vec<double, 1> velocity(const Vec<double, 1>&, const Vec<double, 1>& p) const { return p; }

  // The exact flow at time t from (q0, p0).
  void exact(double t, const Vec<double, 1>& q0, const Vec<double, 1>& p0, Vec<double, 1>& q,
             Vec<double, 1>& p) const {
    const double c = std::cos(omega * t), s = std::sin(omega * t);
    q[0] = c * q0[0] + s * p0[0] / omega;
    p[0] = -omega * s * q0[0] + c * p0[0];
  }
};

struct Pendulum {
  static constexpr int dim = 1;
  double m = 1.0, l = 1.0, g = 1.0;

  Pendulum(double m_ = 1.0, double l_ = 1.0, double g_ = 1.0) : m(m_), l(l_), g(g_) {
    detail::require_positive("pendulum", "m", m);
    detail::require_positive("pendulum", "l", l);
    if (!std::isfinite(g)) throw std::invalid_argument("pendulum: parameter g must be finite");
  }
  std::string name() const { return "pendulum"; }

  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& v) const {
    using std::cos;
    return (0.5 * m * l * l) * v[0] * v[0] + (m * g * l) * cos(q[0]);
  }
  template <class T>
  void gradient(const Vec<T, 1>& q, const Vec<T, 1>& v, Vec<T, 1>& dLdq, Vec<T, 1>& dLdv) const {
    using std::sin;
    dLdq[0] = -(m * g * l) * sin(q[0]);
    dLdv[0] = (m * l * l) * v[0];
  }
  Vec<double, 1> velocity(const Vec<double, 1>&, const Vec<double, 1>& p) const { return p / (m * l * l); }
};

struct Kepler {
  static constexpr int dim = 2;
  double mu = 1.0;

  explicit Kepler(double mu_ = 1.0) : mu(mu_) { detail::require_positive("kepler", "mu", mu); }
  std::string name() const { return "kepler"; }

  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    using std::sqrt;
    return 0.5 * (v[0] * v[0] + v[1] * v[1]) + mu / sqrt(q[0] * q[0] + q[1] * q[1]);
  }
  template <class T>
  void gradient(const Vec<T, 2>& q, const Vec<T, 2>& v, Vec<T, 2>& dLdq, Vec<T, 2>& dLdv) const {
    using std::sqrt;
    const T r2 = q[0] * q[0] + q[1] * q[1];
    const T k = -mu / (r2 * sqrt(r2));
    dLdq[0] = k * q[0];
    dLdq[1] = k * q[1];
    dLdv = v;
  }
  Vec<double, 2> velocity(const Vec<double, 2>&, const Vec<double, 2>& p) const { return p; }

  static double angular_momentum(const Vec<double, 2>& q, const Vec<double, 2>& p) {
    return q[0] * p[1] - q[1] * p[0];
  }
};

}  // namespace dvm
