// A chain of n particles on a line with nearest-neighbour nonlinear springs: the
// Fermi-Pasta-Ulam(-Tsingou) chain (Fermi, Pasta, Ulam 1955; Hairer, Lubich, Wanner,
// Geometric Numerical Integration, Sec. I.5 for the stiff variant).
//
//   L(q, v) = sum_i m v_i^2 / 2 - sum_bonds V(r),   V(r) = k r^2/2 + alpha r^3/3 + beta r^4/4
//
// q_i is the displacement of particle i from its rest position. Bonds join neighbours,
// r = q_i - q_{i-1}; with fixed ends (fixed = true) two more bonds tie the first and
// last particle to walls at rest, r = q_0 and r = -q_{n-1}. With free ends the
// potential depends on differences only, so it is invariant under the translations
// q_i -> q_i + c, and by Noether's theorem the total momentum sum_i p_i is conserved
// (exactly so by any theta-map integrator, see solvers/chain_step.h).
//
// The Hessian of the potential is tridiagonal (each bond couples two neighbours), which
// is what makes a step cost O(n). FPUChain is the dynamic-size form used by the chain
// step; FixedChain<N> is the same Lagrangian with a compile-time size, usable with every
// fixed-size tool (position-momentum step, Hamiltonian step), so that the two paths can
// be checked against each other.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/scalar.h"
#include "mechanics/structure.h"

namespace dvm {

struct FPUChain {
  int n = 8;
  double m = 1.0, k = 1.0, alpha = 0.0, beta = 0.0;
  bool fixed = true;

  FPUChain(int n_, double m_ = 1.0, double k_ = 1.0, double alpha_ = 0.0, double beta_ = 0.0, bool fixed_ = true)
      : n(n_), m(m_), k(k_), alpha(alpha_), beta(beta_), fixed(fixed_) {
    if (n < 1) throw std::invalid_argument("chain: parameter n must be a whole number >= 1, got " + std::to_string(n));
    if (!(m > 0.0) || !std::isfinite(m))
      throw std::invalid_argument("chain: parameter m must be positive and finite, got " + std::to_string(m));
    if (!std::isfinite(k) || !std::isfinite(alpha) || !std::isfinite(beta))
      throw std::invalid_argument("chain: parameters k, alpha, beta must be finite");
  }
  std::string name() const { return "chain"; }
  int dim() const { return n; }

  // V(r), V'(r), V''(r) of one spring.
  template <class T>
  T spring(const T& r) const {
    return r * r * (0.5 * k + r * (alpha / 3.0 + 0.25 * beta * r));
  }
  double spring_force(double r) const { return r * (k + r * (alpha + beta * r)); }
  double spring_stiffness(double r) const { return k + r * (2.0 * alpha + 3.0 * beta * r); }

  // Number of bonds and the displacement of bond b (b = 0 .. bonds()-1). With fixed
  // ends bond b joins particles b-1 and b (particle -1 and n being the walls).
  int bonds() const { return fixed ? n + 1 : n - 1; }
  template <class Vector>
  auto bond_length(const Vector& q, int b) const {
    using T = std::decay_t<decltype(q[0])>;
    if (fixed) {
      const T left = b >= 1 ? T(q[b - 1]) : constant<T>(0.0);
      const T right = b < n ? T(q[b]) : constant<T>(0.0);
      return T(right - left);
    }
    return T(q[b + 1] - q[b]);
  }
  // The particles at the two ends of bond b (-1 for a wall).
  int bond_left(int b) const { return fixed ? b - 1 : b; }
  int bond_right(int b) const { return fixed ? (b < n ? b : -1) : b + 1; }

  template <class Vector>
  auto potential(const Vector& q) const {
    using T = std::decay_t<decltype(q[0])>;
    T V = constant<T>(0.0);
    for (int b = 0; b < bonds(); ++b) V = V + spring(bond_length(q, b));
    return V;
  }

  // g = grad V(q), q any vector expression with q[i] (an Eigen::Ref of a run-time-sized
  // system's interface reads in place, not through a temporary VectorXd).
  template <class Vector>
  void gradient(const Vector& q, Eigen::VectorXd& g) const {
    g.setZero(n);
    for (int b = 0; b < bonds(); ++b) {
      const double f = spring_force(bond_length(q, b));
      const int l = bond_left(b), r = bond_right(b);
      if (r >= 0) g[r] += f;
      if (l >= 0) g[l] -= f;
    }
  }

  // The size of the terms that make up grad V(q): the largest spring force, plus the
  // round-off met in forming bond lengths from positions of size |q| (stiffness times
  // |q|). grad V itself can be far smaller (a second difference of smooth
  // displacements), so residual tolerances are judged against this.
  double gradient_scale(const Eigen::VectorXd& q) const {
    double f = 0.0, s = 0.0;
    for (int b = 0; b < bonds(); ++b) {
      const double r = bond_length(q, b);
      f = std::fmax(f, std::fabs(spring_force(r)));
      s = std::fmax(s, std::fabs(spring_stiffness(r)));
    }
    return f + s * max_abs(q);
  }

  // The tridiagonal Hessian of V: diag (n) and off (n-1, off[i] couples i and i+1).
  void hessian(const Eigen::VectorXd& q, Eigen::VectorXd& diag, Eigen::VectorXd& off) const {
    diag.setZero(n);
    off.setZero(std::max(n - 1, 0));
    for (int b = 0; b < bonds(); ++b) {
      const double s = spring_stiffness(bond_length(q, b));
      const int l = bond_left(b), r = bond_right(b);
      if (r >= 0) diag[r] += s;
      if (l >= 0) diag[l] += s;
      if (l >= 0 && r >= 0) off[l] -= s;
    }
  }

  // gradient(), hessian() and the two maxima of gradient_scale() in one pass over the
  // bonds (each bond length formed once): g = grad V(q), Hess V(q) into diag and off,
  // and on return the largest |spring force| and |spring stiffness|, so that
  // gradient_scale(q) = force_max + stiffness_max * max_abs(q). The same operations in
  // the same order as the three separate calls, so the same values.
  void derivatives(const Eigen::VectorXd& q, Eigen::VectorXd& g, Eigen::VectorXd& diag, Eigen::VectorXd& off,
                   double& force_max, double& stiffness_max) const {
    g.setZero(n);
    diag.setZero(n);
    off.setZero(std::max(n - 1, 0));
    double f_max = 0.0, s_max = 0.0;
    for (int b = 0; b < bonds(); ++b) {
      const double r = bond_length(q, b);
      const double f = spring_force(r), s = spring_stiffness(r);
      f_max = std::fmax(f_max, std::fabs(f));
      s_max = std::fmax(s_max, std::fabs(s));
      const int left = bond_left(b), right = bond_right(b);
      if (right >= 0) {
        g[right] += f;
        diag[right] += s;
      }
      if (left >= 0) {
        g[left] -= f;
        diag[left] += s;
      }
      if (left >= 0 && right >= 0) off[left] -= s;
    }
    force_max = f_max;
    stiffness_max = s_max;
  }

  double energy(const Eigen::VectorXd& q, const Eigen::VectorXd& p) const {
    return p.squaredNorm() / (2.0 * m) + potential(q);
  }
  static double total_momentum(const Eigen::VectorXd& p) {
    // compensated, so that the conservation test measures the integrator, not the sum
    double s = 0.0, c = 0.0;
    for (Eigen::Index i = 0; i < p.size(); ++i) {
      const double y = p[i] - c, t = s + y;
      c = (t - s) - y;
      s = t;
    }
    return s;
  }
};

// The same chain with a compile-time number of particles, as a Lagrangian.
template <int N>
struct FixedChain {
  static constexpr int dim = N;
  static constexpr Structure structure = Structure::separable;
  FPUChain chain;
  explicit FixedChain(FPUChain c) : chain(std::move(c)) {
    if (chain.n != N) throw std::invalid_argument("FixedChain: n does not match the compile-time size");
  }
  std::string name() const { return "chain"; }
  template <class T>
  T operator()(const Vec<T, N>& q, const Vec<T, N>& v) const {
    T kin = constant<T>(0.0);
    for (int i = 0; i < N; ++i) kin = kin + v[i] * v[i];
    return (0.5 * chain.m) * kin - chain.potential(q);
  }
  Vec<double, N> velocity(const Vec<double, N>&, const Vec<double, N>& p) const { return p / chain.m; }
};

}  // namespace dvm
