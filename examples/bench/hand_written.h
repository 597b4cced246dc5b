// Hand-written integrators: the cost floors the generic engine is measured against.
//
//   Stormer-Verlet (kick-drift-kick), for L = v^T M v / 2 - V(q) with constant
//   diagonal M, written with the system's closed-form force F(q) = dL/dq:
//     p_{1/2} = p_0 + (h/2) F(q_0),  q_1 = q_0 + h M^{-1} p_{1/2},  p_1 = p_{1/2} + (h/2) F(q_1),
//   the force at q_1 reused by the next step (one force evaluation per step).
//
//   Implicit midpoint by Newton's method, for the pendulum and for Kepler: with the
//   increment d = q_1 - q_0 and x = q_0 + d/2 the midpoint discrete Lagrangian
//   L_d = h L(x, d/h) gives
//     f(d) = M d/h + (h/2) grad V(x) - p_0 = 0,   p_1 = M d/h - (h/2) grad V(x),
//   with Jacobian M/h + (h/4) Hess V(x). The same starting guess (linear
//   extrapolation of the previous increments), stopping rule and compensated sums as
//   the generic loop (solvers/integrate.h, solvers/newton.h).
//
//   Gauss collocation of 6 stages (order 12) on Kepler, by hand, in the Nystrom form of
//   Hairer, Lubich, Wanner, Geometric Numerical Integration (GNI), II.2.3 and VIII.6,
//   as their gni_irk2 code solves it: with a = -grad V (M = I) and stage increments
//   Z_i = Q_i - q0,
//     Z_i = c_i h v0 + h^2 sum_j abar_ij a(q0 + Z_j),   abar = A^2,
//     q1 = q0 + h v0 + h^2 sum_i bbar_i a(Q_i),        bbar = b^T A,
//     v1 = v0 + h sum_i b_i a(Q_i),
//   iterated to a fixed point (6 forces a sweep, no Jacobian) from the previous step's
//   stage polynomial extrapolated to the new stages; stopped, as dvm's steps are, when
//   a sweep changes Z by at most 2e-15 (|Z| + |q0|) or stops decreasing below 1e-14
//   times that. The coefficients are computed here on their own (Gauss nodes by Newton
//   on the Legendre polynomial, A by integrating the Lagrange basis in monomials), not
//   taken from dvm.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

#include "mechanics/systems.h"

namespace dvm::bench {

// The force F(q) = dL/dq (v = 0; the systems here are separable).
template <class System>
Vec<double, System::dim> force(const System& L, const Vec<double, System::dim>& q) {
  using V = Vec<double, System::dim>;
  V dq, dv;
  L.gradient(q, V::Zero().eval(), dq, dv);
  return dq;
}

// Stormer-Verlet by hand; `observe(q, p)` after every step.
template <class System, class Observer>
void hand_verlet(const System& L, Vec<double, System::dim>& q, Vec<double, System::dim>& p, double h,
                 std::int64_t steps, Observer&& observe) {
  using V = Vec<double, System::dim>;
  V F = force(L, q);
  const V zero = V::Zero();
  for (std::int64_t n = 0; n < steps; ++n) {
    p += (0.5 * h) * F;
    q += h * L.velocity(zero, p);
    F = force(L, q);
    p += (0.5 * h) * F;
    observe(q, p);
  }
}

// Kahan-Babuska compensated update x += y.
inline void kahan_add(double& x, double& c, double y) {
  const double z = y - c, t = x + z;
  c = (t - x) - z;
  x = t;
}

// Implicit midpoint on the pendulum, by hand. Returns the Newton iterations.
template <class Observer>
std::int64_t hand_midpoint_pendulum(const Pendulum& P, double& q, double& p, double h, std::int64_t steps,
                                    Observer&& observe) {
  const double M = P.m * P.l * P.l, k = P.m * P.g * P.l;
  double cq = 0.0, cp = 0.0, d = 0.0, d1 = 0.0, d2 = 0.0;
  std::int64_t iters = 0;
  for (std::int64_t n = 0; n < steps; ++n) {
    if (n >= 2)
      d = 2 * d1 - d2;
    else if (n == 1)
      d = d1;
    else
      d = h * p / M;
    double dx = INFINITY;
    bool ok = false;
    for (int it = 0; it < 25; ++it) {
      const double s = std::sin(q + 0.5 * d), c = std::cos(q + 0.5 * d);
      const double f = M * d / h + 0.5 * h * k * s - p;
      const double J = M / h + 0.25 * h * k * c;
      ++iters;
      const double scale = std::fabs(p) + std::fabs(J) * std::fabs(d);
      if (std::fabs(f) <= 2e-15 * scale) {  // converged: apply the last correction, as dvm does
        d -= f / J;
        ok = true;
        break;
      }
      if (std::fabs(dx) <= 1e-14 * (std::fabs(d) + std::fabs(q))) {  // stalled
        ok = std::fabs(f) <= 1e-10 * scale;
        break;
      }
      dx = f / J;
      d -= dx;
    }
    if (!ok || !std::isfinite(d)) return -1 - n;  // a failed solve: -(1 + step index)
    const double dp = -h * k * std::sin(q + 0.5 * d);
    kahan_add(q, cq, d);
    kahan_add(p, cp, dp);
    d2 = d1;
    d1 = d;
    observe(q, p);
  }
  return iters;
}

// Implicit midpoint on Kepler, by hand (2x2 Newton with the closed-form Hessian of
// V = -mu/|x|: Hess V = mu (I/r^3 - 3 x x^T/r^5)). Returns the Newton iterations, or
// -(1 + step index) for a failed solve.
template <class Observer>
std::int64_t hand_midpoint_kepler(const Kepler& K, Vec<double, 2>& q, Vec<double, 2>& p, double h,
                                  std::int64_t steps, Observer&& observe) {
  const double mu = K.mu;
  double cq[2] = {0, 0}, cp[2] = {0, 0};
  double d[2] = {h * p[0], h * p[1]}, d1[2] = {d[0], d[1]}, d2[2] = {d[0], d[1]};
  std::int64_t iters = 0;
  for (std::int64_t n = 0; n < steps; ++n) {
    for (int i = 0; i < 2; ++i) d[i] = n >= 2 ? 2 * d1[i] - d2[i] : d1[i];
    double dxn = INFINITY, g[2] = {0, 0};
    bool ok = false;
    for (int it = 0; it < 25; ++it) {
      const double x0 = q[0] + 0.5 * d[0], x1 = q[1] + 0.5 * d[1];
      const double r2 = x0 * x0 + x1 * x1, r = std::sqrt(r2), ir3 = mu / (r2 * r), ir5 = 3.0 * ir3 / r2;
      g[0] = ir3 * x0;
      g[1] = ir3 * x1;
      const double f0 = d[0] / h + 0.5 * h * g[0] - p[0], f1 = d[1] / h + 0.5 * h * g[1] - p[1];
      const double a = 1.0 / h + 0.25 * h * (ir3 - ir5 * x0 * x0), b = -0.25 * h * ir5 * x0 * x1,
                   c = 1.0 / h + 0.25 * h * (ir3 - ir5 * x1 * x1);
      ++iters;
      const double det = a * c - b * b;
      const double s0 = (c * f0 - b * f1) / det, s1 = (a * f1 - b * f0) / det;
      const double scale = std::fmax(std::fabs(p[0]), std::fabs(p[1])) +
                           (std::fabs(a) + std::fabs(b) + std::fabs(c)) * std::fmax(std::fabs(d[0]), std::fabs(d[1]));
      const double fn = std::fmax(std::fabs(f0), std::fabs(f1));
      if (fn <= 2e-15 * scale) {  // converged: apply the last correction
        d[0] -= s0;
        d[1] -= s1;
        ok = true;
        break;
      }
      if (dxn <= 1e-14 * (std::fmax(std::fabs(d[0]), std::fabs(d[1])) + std::fmax(std::fabs(q[0]), std::fabs(q[1])))) {
        ok = fn <= 1e-10 * scale;
        break;
      }
      d[0] -= s0;
      d[1] -= s1;
      dxn = std::fmax(std::fabs(s0), std::fabs(s1));
    }
    if (!ok || !std::isfinite(d[0] + d[1])) return -1 - n;
    // p1 - p0 = -h grad V(x) at the final x
    const double x0 = q[0] + 0.5 * d[0], x1 = q[1] + 0.5 * d[1];
    const double r2 = x0 * x0 + x1 * x1, ir3 = mu / (r2 * std::sqrt(r2));
    for (int i = 0; i < 2; ++i) kahan_add(q[i], cq[i], d[i]);
    kahan_add(p[0], cp[0], -h * ir3 * x0);
    kahan_add(p[1], cp[1], -h * ir3 * x1);
    for (int i = 0; i < 2; ++i) {
      d2[i] = d1[i];
      d1[i] = d[i];
    }
    observe(q, p);
  }
  return iters;
}

// The s-stage Gauss method's Nystrom coefficients on [0, 1], in long double: nodes c,
// weights b, abar = A^2, bbar = b^T A, and the extrapolation matrix E of the stage
// polynomial (through 0 and the Z_i) to the next step: Z_i' = u(1 + c_i) - u(1).
template <int S>
struct HandGaussTables {
  std::array<double, S> c{}, b{}, bbar{};
  std::array<std::array<double, S>, S> abar{}, E{};
  HandGaussTables() {
    using LD = long double;
    std::array<LD, S> x{}, w{};
    const LD pi = 3.141592653589793238462643383279502884L;
    for (int i = 0; i < S; ++i) {  // roots of P_S on [-1, 1] by Newton
      LD r = std::cos(pi * (i + 0.75L) / (S + 0.5L)), dP = 0;
      for (int it = 0; it < 100; ++it) {
        LD p0 = 1, p1 = r;
        for (int k = 1; k < S; ++k) {
          const LD p2 = ((2 * k + 1) * r * p1 - k * p0) / (k + 1);
          p0 = p1;
          p1 = p2;
        }
        dP = S * (r * p1 - p0) / (r * r - 1);
        const LD d = p1 / dP;
        r -= d;
        if (std::fabs(d) < 1e-19L) break;
      }
      x[i] = 0.5L * (1 - r);  // ascending on [0, 1]
      w[i] = 1 / ((1 - r * r) * dP * dP);
    }
    // A_ij = int_0^{c_i} l_j: l_j's monomial coefficients, integrated term by term
    std::array<std::array<LD, S>, S> A{};
    for (int j = 0; j < S; ++j) {
      std::array<LD, S + 1> poly{};
      poly[0] = 1;
      int deg = 0;
      for (int k = 0; k < S; ++k) {
        if (k == j) continue;
        const LD den = x[j] - x[k];
        for (int d = deg + 1; d >= 0; --d) poly[d] = ((d > 0 ? poly[d - 1] : 0) - x[k] * poly[d]) / den;
        ++deg;
      }
      for (int i = 0; i < S; ++i) {
        LD sum = 0, t = x[i];
        for (int d = 0; d <= deg; ++d, t *= x[i]) sum += poly[d] * t / (d + 1);
        A[i][j] = sum;
      }
    }
    auto basis0 = [&](int k, LD t) {  // Lagrange basis on 0, c_1..c_S, for c_k
      LD l = t / x[k];
      for (int m = 0; m < S; ++m)
        if (m != k) l *= (t - x[m]) / (x[k] - x[m]);
      return l;
    };
    for (int i = 0; i < S; ++i) {
      c[i] = static_cast<double>(x[i]);
      b[i] = static_cast<double>(w[i]);
      LD bb = 0;
      for (int k = 0; k < S; ++k) bb += w[k] * A[k][i];
      bbar[i] = static_cast<double>(bb);
      for (int j = 0; j < S; ++j) {
        LD a2 = 0;
        for (int k = 0; k < S; ++k) a2 += A[i][k] * A[k][j];
        abar[i][j] = static_cast<double>(a2);
        E[i][j] = static_cast<double>(basis0(j, 1 + x[i]) - basis0(j, 1));
      }
    }
  }
};

// Gauss-6 collocation on Kepler by hand (see the top of this file). Returns the force
// evaluations, or -(1 + step index) for a step whose iteration did not converge.
template <class Observer>
std::int64_t hand_gauss6_kepler(const Kepler& K, Vec<double, 2>& q, Vec<double, 2>& p, double h,
                                std::int64_t steps, Observer&& observe) {
  constexpr int S = 6;
  static const HandGaussTables<S> t;
  const double mu = K.mu;
  double hc[S], hb[S], h2bbar[S], h2abar[S][S];
  for (int i = 0; i < S; ++i) {
    hc[i] = h * t.c[i];
    hb[i] = h * t.b[i];
    h2bbar[i] = h * h * t.bbar[i];
    for (int j = 0; j < S; ++j) h2abar[i][j] = h * h * t.abar[i][j];
  }
  double Z[S][2], Zn[S][2], F[S][2], cq[2] = {0, 0}, cp[2] = {0, 0};
  std::int64_t forces = 0;
  for (std::int64_t n = 0; n < steps; ++n) {
    if (n == 0) {
      for (int i = 0; i < S; ++i)
        for (int a = 0; a < 2; ++a) Z[i][a] = hc[i] * p[a];
    } else {  // the previous stage polynomial, extrapolated
      for (int i = 0; i < S; ++i)
        for (int a = 0; a < 2; ++a) {
          double z = 0;
          for (int k = 0; k < S; ++k) z += t.E[i][k] * Zn[k][a];
          Z[i][a] = z;
        }
    }
    double dn_prev = INFINITY;
    bool ok = false;
    for (int it = 0; it < 25; ++it) {
      for (int j = 0; j < S; ++j) {
        const double x0 = q[0] + Z[j][0], x1 = q[1] + Z[j][1];
        const double r2 = x0 * x0 + x1 * x1, k = -mu / (r2 * std::sqrt(r2));
        F[j][0] = k * x0;
        F[j][1] = k * x1;
      }
      forces += S;
      double dn = 0, zn = 0;
      for (int i = 0; i < S; ++i)
        for (int a = 0; a < 2; ++a) {
          double z = hc[i] * p[a];
          for (int j = 0; j < S; ++j) z += h2abar[i][j] * F[j][a];
          dn = std::fmax(dn, std::fabs(z - Z[i][a]));
          zn = std::fmax(zn, std::fabs(z));
          Zn[i][a] = z;
        }
      for (int i = 0; i < S; ++i)
        for (int a = 0; a < 2; ++a) Z[i][a] = Zn[i][a];
      const double scale = zn + std::fmax(std::fabs(q[0]), std::fabs(q[1]));
      if (dn <= 2e-15 * scale || (dn >= dn_prev && dn <= 1e-14 * scale)) {
        ok = true;
        break;
      }
      if (!(dn < dn_prev)) break;
      dn_prev = dn;
    }
    if (!ok) return -1 - n;
    for (int a = 0; a < 2; ++a) {
      double dq = h * p[a], dp = 0;
      for (int i = 0; i < S; ++i) {
        dq += h2bbar[i] * F[i][a];
        dp += hb[i] * F[i][a];
      }
      kahan_add(q[a], cq[a], dq);
      kahan_add(p[a], cp[a], dp);
    }
    observe(q, p);
  }
  return forces;
}

}  // namespace dvm::bench
