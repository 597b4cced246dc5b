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
#pragma once

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

}  // namespace dvm::bench
