// The classic test systems of geometric integration, each a Lagrangian on R^n with
// closed-form gradient and inverse Legendre map (checked against automatic
// differentiation in tests/mechanics), its energy, its momenta where a symmetry gives
// them, and its exact solution where one is known.
//
//   double pendulum   two point masses on massless rods, angles from the downward
//                     vertical: L = (m1+m2) l1^2 w1^2/2 + m2 l2^2 w2^2/2
//                     + m2 l1 l2 w1 w2 cos(t1 - t2) + (m1+m2) g l1 cos t1 + m2 g l2 cos t2.
//                     Chaotic; no exact solution; energy conserved.
//   Henon-Heiles      L = |v|^2/2 - (x^2 + y^2)/2 - lambda (x^2 y - y^3/3) (Henon and
//                     Heiles 1964; Hairer-Lubich-Wanner, GNI Sec. I.3).
//   Fermi-Pasta-Ulam  the stiff/soft spring chain of GNI Sec. I.5.1: 2m unit masses,
//                     L = |v|^2/2 - omega^2/4 sum_i (q_{2i} - q_{2i-1})^2
//                         - sum_{i=0}^{m} (q_{2i+1} - q_{2i})^4,  q_0 = q_{2m+1} = 0,
//                     here m = 3 (6 degrees of freedom). Besides the energy, the total
//                     oscillatory energy I = sum_j I_j, I_j = (y_j^2 + omega^2 x_j^2)/2 with
//                     x_j = (q_{2j} - q_{2j-1})/sqrt 2, y_j = (p_{2j} - p_{2j-1})/sqrt 2,
//                     is an adiabatic invariant: I(t) = I(0) + O(1/omega) for long times.
//   Duffing           the undamped, unforced Duffing oscillator
//                     L = v^2/2 - alpha q^2/2 - beta q^4/4; for alpha > 0, beta >= 0 the
//                     exact solution is q = A cn(w t + u0, k) with w^2 = alpha + beta A^2,
//                     k^2 = beta A^2/(2 w^2) (Jacobi elliptic functions, computed here by
//                     the arithmetic-geometric mean, Abramowitz-Stegun 16.4).
//   charged particle  a charge c of mass m in the plane, in a uniform magnetic field B
//                     normal to the plane (symmetric gauge A = B/2 (-y, x)) and an
//                     isotropic electric potential k |q|^2/2:
//                     L = m |v|^2/2 + (c B/2)(x v_y - y v_x) - k |q|^2/2.
//                     L is linear in v in the magnetic term, so p = m v + c A(q) is not
//                     m v: the Legendre transform is beyond a quadratic kinetic energy.
//                     Rotations are a symmetry: the canonical angular momentum
//                     x p_y - y p_x is conserved. The equations are linear, with exact
//                     solution z = x + i y = a e^{i w+ t} + b e^{i w- t},
//                     w± = (-c B ± sqrt(c^2 B^2 + 4 m k))/(2 m).
//   N-body            B bodies in R^3, L = sum_i m_i |v_i|^2/2 + G sum_{i<j} m_i m_j/|q_i - q_j|;
//                     invariants: energy, total momentum, total angular momentum. The outer
//                     solar system of GNI Sec. I.2.4 is the case B = 6 (examples/scenes).
#pragma once

#include <array>
#include <cmath>
#include <complex>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/scalar.h"
#include "mechanics/nbody_momenta.h"
#include "mechanics/systems.h"

namespace dvm {

struct DoublePendulum {
  static constexpr int dim = 2;
  static constexpr Structure structure = Structure::mechanical;
  double m1 = 1.0, m2 = 1.0, l1 = 1.0, l2 = 1.0, g = 1.0;

  DoublePendulum(double m1_ = 1, double m2_ = 1, double l1_ = 1, double l2_ = 1, double g_ = 1)
      : m1(m1_), m2(m2_), l1(l1_), l2(l2_), g(g_) {
    detail::require_positive("double-pendulum", "m1", m1);
    detail::require_positive("double-pendulum", "m2", m2);
    detail::require_positive("double-pendulum", "l1", l1);
    detail::require_positive("double-pendulum", "l2", l2);
    if (!std::isfinite(g)) throw std::invalid_argument("double-pendulum: parameter g must be finite");
  }
  std::string name() const { return "double-pendulum"; }

  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    using std::cos;
    const double M = m1 + m2;
    return (0.5 * M * l1 * l1) * v[0] * v[0] + (0.5 * m2 * l2 * l2) * v[1] * v[1] +
           (m2 * l1 * l2) * v[0] * v[1] * cos(q[0] - q[1]) + (M * g * l1) * cos(q[0]) + (m2 * g * l2) * cos(q[1]);
  }
  template <class T>
  void gradient(const Vec<T, 2>& q, const Vec<T, 2>& v, Vec<T, 2>& dLdq, Vec<T, 2>& dLdv) const {
    using std::cos;
    using std::sin;
    const double M = m1 + m2, k = m2 * l1 * l2;
    const T d = q[0] - q[1];
    const T c = cos(d), s = sin(d);
    const T w = k * (v[0] * v[1] * s);
    dLdq[0] = -w - (M * g * l1) * sin(q[0]);
    dLdq[1] = w - (m2 * g * l2) * sin(q[1]);
    dLdv[0] = (M * l1 * l1) * v[0] + k * (v[1] * c);
    dLdv[1] = (m2 * l2 * l2) * v[1] + k * (v[0] * c);
  }
  Vec<double, 2> velocity(const Vec<double, 2>& q, const Vec<double, 2>& p) const {
    const double M = m1 + m2, k = m2 * l1 * l2 * std::cos(q[0] - q[1]);
    const double a = M * l1 * l1, b = m2 * l2 * l2, det = a * b - k * k;
    return Vec<double, 2>((b * p[0] - k * p[1]) / det, (a * p[1] - k * p[0]) / det);
  }
};

struct HenonHeiles {
  static constexpr int dim = 2;
  static constexpr Structure structure = Structure::separable;
  double lambda = 1.0;
  explicit HenonHeiles(double lambda_ = 1.0) : lambda(lambda_) {
    if (!std::isfinite(lambda)) throw std::invalid_argument("henon-heiles: parameter lambda must be finite");
  }
  std::string name() const { return "henon-heiles"; }
  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    const T& x = q[0];
    const T& y = q[1];
    return 0.5 * (v[0] * v[0] + v[1] * v[1]) - 0.5 * (x * x + y * y) - lambda * (x * x * y - (1.0 / 3.0) * y * y * y);
  }
  template <class T>
  void gradient(const Vec<T, 2>& q, const Vec<T, 2>& v, Vec<T, 2>& dLdq, Vec<T, 2>& dLdv) const {
    const T& x = q[0];
    const T& y = q[1];
    dLdq[0] = -x - (2.0 * lambda) * (x * y);
    dLdq[1] = -y - lambda * (x * x - y * y);
    dLdv = v;
  }
  Vec<double, 2> velocity(const Vec<double, 2>&, const Vec<double, 2>& p) const { return p; }
};

// GNI Sec. I.5.1 with m = 3 stiff springs: 6 unit masses.
struct FermiPastaUlam {
  static constexpr int m = 3;
  static constexpr int dim = 2 * m;
  static constexpr Structure structure = Structure::separable;
  double omega = 50.0;
  explicit FermiPastaUlam(double omega_ = 50.0) : omega(omega_) {
    detail::require_positive("fpu", "omega", omega);
  }
  std::string name() const { return "fpu"; }
  template <class T>
  T operator()(const Vec<T, dim>& q, const Vec<T, dim>& v) const {
    T kin = constant<T>(0.0), stiff = constant<T>(0.0), soft = constant<T>(0.0);
    for (int i = 0; i < dim; ++i) kin += v[i] * v[i];
    // stiff springs: q_{2i} - q_{2i-1}, i = 1..m (1-based) = q[2i-1] - q[2i-2] (0-based)
    for (int i = 1; i <= m; ++i) {
      const T d = q[2 * i - 1] - q[2 * i - 2];
      stiff += d * d;
    }
    // soft springs: q_{2i+1} - q_{2i}, i = 0..m, with q_0 = q_{2m+1} = 0
    const T first = q[0], last = q[dim - 1];
    soft += first * first * first * first + last * last * last * last;
    for (int i = 1; i < m; ++i) {
      const T d = q[2 * i] - q[2 * i - 1];
      const T d2 = d * d;
      soft += d2 * d2;
    }
    return 0.5 * kin - (0.25 * omega * omega) * stiff - soft;
  }
  template <class T>
  void gradient(const Vec<T, dim>& q, const Vec<T, dim>& v, Vec<T, dim>& dLdq, Vec<T, dim>& dLdv) const {
    dLdv = v;
    for (int i = 0; i < dim; ++i) dLdq[i] = constant<T>(0.0);
    const double w2 = 0.5 * omega * omega;
    for (int i = 1; i <= m; ++i) {
      const T f = w2 * (q[2 * i - 1] - q[2 * i - 2]);  // d/dd of w^2/4 d^2
      dLdq[2 * i - 1] -= f;
      dLdq[2 * i - 2] += f;
    }
    dLdq[0] -= 4.0 * (q[0] * q[0] * q[0]);
    dLdq[dim - 1] -= 4.0 * (q[dim - 1] * q[dim - 1] * q[dim - 1]);
    for (int i = 1; i < m; ++i) {
      const T d = q[2 * i] - q[2 * i - 1];
      const T f = 4.0 * (d * d * d);
      dLdq[2 * i] -= f;
      dLdq[2 * i - 1] += f;
    }
  }
  Vec<double, dim> velocity(const Vec<double, dim>&, const Vec<double, dim>& p) const { return p; }

  // The oscillatory energy I = I_1 + ... + I_m of the stiff springs.
  double oscillatory_energy(const Vec<double, dim>& q, const Vec<double, dim>& p) const {
    double I = 0.0;
    for (int j = 1; j <= m; ++j) {
      const double x = (q[2 * j - 1] - q[2 * j - 2]) / std::sqrt(2.0);
      const double y = (p[2 * j - 1] - p[2 * j - 2]) / std::sqrt(2.0);
      I += 0.5 * (y * y + omega * omega * x * x);
    }
    return I;
  }
};

namespace detail {

// Jacobi elliptic functions sn, cn, dn of (u, k), 0 <= k < 1, by the descending
// arithmetic-geometric mean (Abramowitz and Stegun 16.4).
inline void jacobi_elliptic(double u, double k, double& sn, double& cn, double& dn) {
  if (k < 1e-300) {
    sn = std::sin(u);
    cn = std::cos(u);
    dn = 1.0;
    return;
  }
  double a[16], c[16];
  a[0] = 1.0;
  double b = std::sqrt(1.0 - k * k);
  c[0] = k;
  int n = 0;
  while (n < 15 && std::fabs(c[n]) > 1e-16 * a[n]) {
    a[n + 1] = 0.5 * (a[n] + b);
    c[n + 1] = 0.5 * (a[n] - b);
    b = std::sqrt(a[n] * b);
    ++n;
  }
  double phi = std::ldexp(a[n] * u, n);
  for (int j = n; j > 0; --j) phi = 0.5 * (phi + std::asin(c[j] / a[j] * std::sin(phi)));
  sn = std::sin(phi);
  cn = std::cos(phi);
  dn = std::sqrt(1.0 - k * k * sn * sn);
}

// Carlson's symmetric integral R_F(x, y, z) (duplication theorem).
inline double carlson_rf(double x, double y, double z) {
  for (int it = 0; it < 100; ++it) {
    const double sx = std::sqrt(x), sy = std::sqrt(y), sz = std::sqrt(z);
    const double l = sx * sy + sy * sz + sz * sx;
    x = 0.25 * (x + l);
    y = 0.25 * (y + l);
    z = 0.25 * (z + l);
    const double mu = (x + y + z) / 3.0;
    const double dx = 1 - x / mu, dy = 1 - y / mu, dz = 1 - z / mu;
    const double e = std::fmax(std::fabs(dx), std::fmax(std::fabs(dy), std::fabs(dz)));
    if (e < 1e-4) {
      const double e2 = dx * dy - dz * dz, e3 = dx * dy * dz;
      return (1.0 - e2 / 10.0 + e3 / 14.0 + e2 * e2 / 24.0 - 3.0 * e2 * e3 / 44.0) / std::sqrt(mu);
    }
  }
  return NAN;
}

// The incomplete elliptic integral of the first kind F(phi, k), any real phi.
inline double elliptic_f(double phi, double k) {
  const double K = carlson_rf(0.0, 1.0 - k * k, 1.0);
  const double n = std::round(phi / M_PI);
  const double r = phi - n * M_PI;  // in [-pi/2, pi/2]
  const double s = std::sin(r), c = std::cos(r);
  return 2.0 * n * K + s * carlson_rf(c * c, 1.0 - k * k * s * s, 1.0);
}

}  // namespace detail

struct Duffing {
  static constexpr int dim = 1;
  static constexpr Structure structure = Structure::separable;
  double alpha = 1.0, beta = 1.0;
  Duffing(double alpha_ = 1.0, double beta_ = 1.0) : alpha(alpha_), beta(beta_) {
    if (!std::isfinite(alpha) || !std::isfinite(beta))
      throw std::invalid_argument("duffing: parameters alpha and beta must be finite");
  }
  std::string name() const { return "duffing"; }
  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& v) const {
    const T q2 = q[0] * q[0];
    return 0.5 * v[0] * v[0] - (0.5 * alpha) * q2 - (0.25 * beta) * (q2 * q2);
  }
  template <class T>
  void gradient(const Vec<T, 1>& q, const Vec<T, 1>& v, Vec<T, 1>& dLdq, Vec<T, 1>& dLdv) const {
    dLdq[0] = -alpha * q[0] - beta * (q[0] * q[0] * q[0]);
    dLdv[0] = v[0];
  }
  Vec<double, 1> velocity(const Vec<double, 1>&, const Vec<double, 1>& p) const { return p; }

  bool has_exact() const { return alpha > 0.0 && beta >= 0.0; }
  // The exact flow (alpha > 0, beta >= 0): q = A cn(w t + u0, k), p = -A w sn dn.
  void exact(double t, const Vec<double, 1>& q0, const Vec<double, 1>& p0, Vec<double, 1>& q,
             Vec<double, 1>& p) const {
    if (!has_exact()) throw std::domain_error("duffing: exact solution needs alpha > 0 and beta >= 0");
    const double E = 0.5 * p0[0] * p0[0] + 0.5 * alpha * q0[0] * q0[0] + 0.25 * beta * std::pow(q0[0], 4);
    if (E == 0.0) {
      q = q0;
      p = p0;
      return;
    }
    const double A2 = beta > 0.0 ? 2.0 * E / (0.5 * alpha + std::sqrt(0.25 * alpha * alpha + beta * E)) : 2.0 * E / alpha;
    const double A = std::sqrt(A2);
    const double w = std::sqrt(alpha + beta * A2);
    const double k = std::sqrt(beta * A2 / (2.0 * w * w));
    // amplitude phi0: cos(phi0) = q0/A, sin(phi0) has the sign of -p0
    const double c0 = std::fmax(-1.0, std::fmin(1.0, q0[0] / A));
    const double s0 = std::copysign(std::sqrt(std::fmax(0.0, 1.0 - c0 * c0)), -p0[0]);
    const double u0 = detail::elliptic_f(std::atan2(s0, c0), k);
    double sn, cn, dn;
    detail::jacobi_elliptic(w * t + u0, k, sn, cn, dn);
    q[0] = A * cn;
    p[0] = -A * w * sn * dn;
  }
};

struct ChargedParticle {
  static constexpr int dim = 2;
  static constexpr Structure structure = Structure::general;
  double m = 1.0, c = 1.0, B = 1.0, k = 0.0;
  ChargedParticle(double m_ = 1, double c_ = 1, double B_ = 1, double k_ = 0) : m(m_), c(c_), B(B_), k(k_) {
    detail::require_positive("charged-particle", "m", m);
    if (!std::isfinite(c) || !std::isfinite(B) || !std::isfinite(k) || k < 0)
      throw std::invalid_argument("charged-particle: parameters c, B must be finite and k finite and >= 0");
  }
  std::string name() const { return "charged-particle"; }
  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    return (0.5 * m) * (v[0] * v[0] + v[1] * v[1]) + (0.5 * c * B) * (q[0] * v[1] - q[1] * v[0]) -
           (0.5 * k) * (q[0] * q[0] + q[1] * q[1]);
  }
  template <class T>
  void gradient(const Vec<T, 2>& q, const Vec<T, 2>& v, Vec<T, 2>& dLdq, Vec<T, 2>& dLdv) const {
    const double b = 0.5 * c * B;
    dLdq[0] = b * v[1] - k * q[0];
    dLdq[1] = -b * v[0] - k * q[1];
    dLdv[0] = m * v[0] - b * q[1];
    dLdv[1] = m * v[1] + b * q[0];
  }
  Vec<double, 2> velocity(const Vec<double, 2>& q, const Vec<double, 2>& p) const {
    const double b = 0.5 * c * B;
    return Vec<double, 2>((p[0] + b * q[1]) / m, (p[1] - b * q[0]) / m);
  }
  // The canonical angular momentum x p_y - y p_x (conserved: L is rotation invariant).
  static double angular_momentum(const Vec<double, 2>& q, const Vec<double, 2>& p) {
    return q[0] * p[1] - q[1] * p[0];
  }
  bool has_exact() const { return c * B != 0.0 || k > 0.0; }
  void exact(double t, const Vec<double, 2>& q0, const Vec<double, 2>& p0, Vec<double, 2>& q,
             Vec<double, 2>& p) const {
    using C = std::complex<double>;
    const Vec<double, 2> v0 = velocity(q0, p0);
    const double s = std::sqrt(c * c * B * B + 4.0 * m * k);
    if (!(s > 0.0)) throw std::domain_error("charged-particle: exact solution needs c B != 0 or k > 0");
    const double wp = (-c * B + s) / (2.0 * m), wm = (-c * B - s) / (2.0 * m);
    const C I(0.0, 1.0);
    const C z0(q0[0], q0[1]), dz0(v0[0], v0[1]);
    const C a = (dz0 - I * wm * z0) / (I * (wp - wm));
    const C b = z0 - a;
    const C z = a * std::exp(I * (wp * t)) + b * std::exp(I * (wm * t));
    const C dz = I * wp * a * std::exp(I * (wp * t)) + I * wm * b * std::exp(I * (wm * t));
    q = Vec<double, 2>(z.real(), z.imag());
    const double bb = 0.5 * c * B;
    p = Vec<double, 2>(m * dz.real() - bb * q[1], m * dz.imag() + bb * q[0]);
  }
};

// B bodies in R^3; q = (q_1, ..., q_B), q_i in R^3.
template <int B>
struct NBody {
  static constexpr int bodies = B;
  static constexpr int dim = 3 * B;
  static constexpr Structure structure = Structure::separable;
  double G = 1.0;
  std::array<double, B> mass{};

  NBody(double G_, const std::vector<double>& masses) : G(G_) {
    if (static_cast<int>(masses.size()) != B)
      throw std::invalid_argument("nbody: expected " + std::to_string(B) + " masses");
    if (!std::isfinite(G) || G < 0) throw std::invalid_argument("nbody: parameter G must be finite and >= 0");
    for (int i = 0; i < B; ++i) {
      mass[static_cast<std::size_t>(i)] = masses[static_cast<std::size_t>(i)];
      detail::require_positive("nbody", "mass", masses[static_cast<std::size_t>(i)]);
    }
  }
  std::string name() const { return "nbody"; }
  double m(int i) const { return mass[static_cast<std::size_t>(i)]; }

  template <class T>
  T operator()(const Vec<T, dim>& q, const Vec<T, dim>& v) const {
    using std::sqrt;
    T kin = constant<T>(0.0), pot = constant<T>(0.0);
    for (int i = 0; i < B; ++i) {
      const T v2 = v[3 * i] * v[3 * i] + v[3 * i + 1] * v[3 * i + 1] + v[3 * i + 2] * v[3 * i + 2];
      kin += m(i) * v2;
    }
    for (int i = 0; i < B; ++i)
      for (int j = i + 1; j < B; ++j) {
        const T dx = q[3 * i] - q[3 * j], dy = q[3 * i + 1] - q[3 * j + 1], dz = q[3 * i + 2] - q[3 * j + 2];
        pot += (G * m(i) * m(j)) / sqrt(dx * dx + dy * dy + dz * dz);
      }
    return 0.5 * kin + pot;
  }
  template <class T>
  void gradient(const Vec<T, dim>& q, const Vec<T, dim>& v, Vec<T, dim>& dLdq, Vec<T, dim>& dLdv) const {
    using std::sqrt;
    for (int i = 0; i < dim; ++i) dLdq[i] = constant<T>(0.0);
    for (int i = 0; i < B; ++i)
      for (int a = 0; a < 3; ++a) dLdv[3 * i + a] = m(i) * v[3 * i + a];
    for (int i = 0; i < B; ++i)
      for (int j = i + 1; j < B; ++j) {
        T d[3];
        for (int a = 0; a < 3; ++a) d[a] = q[3 * i + a] - q[3 * j + a];
        const T r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        const T f = (G * m(i) * m(j)) / (r2 * sqrt(r2));  // dL/dq_i = -f d
        for (int a = 0; a < 3; ++a) {
          const T fa = f * d[a];
          dLdq[3 * i + a] -= fa;
          dLdq[3 * j + a] += fa;
        }
      }
  }
  Vec<double, dim> velocity(const Vec<double, dim>&, const Vec<double, dim>& p) const {
    Vec<double, dim> v;
    for (int i = 0; i < B; ++i)
      for (int a = 0; a < 3; ++a) v[3 * i + a] = p[3 * i + a] / m(i);
    return v;
  }
  // Total momentum (3) and total angular momentum (3).
  static std::array<double, 6> momenta(const Vec<double, dim>& q, const Vec<double, dim>& p) {
    return nbody_momenta(q.data(), p.data(), B);
  }
};

}  // namespace dvm
