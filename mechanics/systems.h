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
#include "mechanics/structure.h"

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
  static constexpr Structure structure = Structure::separable;
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
  static constexpr Structure structure = Structure::separable;
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
  static constexpr Structure structure = Structure::separable;
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

  // The exact flow at time t from (q0, p0) on a bound (elliptic) orbit: Kepler's
  // equation E - e sin E = M solved by Newton's method, then Lagrange's f and g
  // functions in the eccentric-anomaly difference dE:
  //   q = f q0 + g p0,  p = fdot q0 + gdot p0,
  //   f = 1 - a/r0 (1 - cos dE),  g = t - (dE - sin dE)/n,
  //   fdot = -sqrt(mu a) sin dE/(r r0),  gdot = 1 - a/r (1 - cos dE).
  // Throws for an orbit that is not bound.
  void exact(double t, const Vec<double, 2>& q0, const Vec<double, 2>& p0, Vec<double, 2>& q,
             Vec<double, 2>& p) const {
    const double r0 = q0.norm(), v2 = p0.squaredNorm(), rv = q0.dot(p0);
    const double inv_a = 2.0 / r0 - v2 / mu;
    if (!(inv_a > 0.0)) throw std::domain_error("kepler: exact solution needs a bound orbit (negative energy)");
    const double a = 1.0 / inv_a, n = std::sqrt(mu * inv_a * inv_a * inv_a);
    const double ecosE0 = 1.0 - r0 / a, esinE0 = rv / std::sqrt(mu * a);
    const double e = std::hypot(ecosE0, esinE0);
    const double E0 = std::atan2(esinE0, ecosE0);
    const double M = (E0 - esinE0) + n * t;
    double E = M + (e > 0.8 ? 0.0 : e * std::sin(M));
    for (int it = 0; it < 100; ++it) {
      const double dE = (E - e * std::sin(E) - M) / (1.0 - e * std::cos(E));
      E -= dE;
      if (std::fabs(dE) <= 1e-16 * std::fmax(1.0, std::fabs(E))) break;
    }
    const double d = E - E0;
    const double r = a * (1.0 - e * std::cos(E));
    const double f = 1.0 - a / r0 * (1.0 - std::cos(d));
    const double g = t - (d - std::sin(d)) / n;
    const double fdot = -std::sqrt(mu * a) * std::sin(d) / (r * r0);
    const double gdot = 1.0 - a / r * (1.0 - std::cos(d));
    q = f * q0 + g * p0;
    p = fdot * q0 + gdot * p0;
  }
};

}  // namespace dvm
