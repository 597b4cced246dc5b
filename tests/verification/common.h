// Helpers for the verification suite: running a method to a fixed time, reference
// solutions independent of the engine, and log-log order fits.
#pragma once

#include <array>
#include <cmath>
#include <vector>

#include "mechanics/systems.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"
#include "tests/address_sanitizer.h"

namespace dvm::verification {

// Step count of a long-horizon loop (bounded energy, drift of momentum maps, staying on
// the manifold over 10^5 to 10^6 steps): n, or n / 10 under AddressSanitizer.
// ASan checks every load and store of the nested Jets in a manifold step, which makes
// these loops far more than ten times slower than in Release (time the test cases of
// test_verification_manifolds in both builds). A tenth of the loop runs the same code path for
// the sanitizers to check; `make test` asserts the long-time properties at full length.
// Tolerances that depend on n are computed from the returned count.
constexpr std::int64_t long_horizon(std::int64_t n) { return dvm_tests::kAddressSanitizer ? n / 10 : n; }

// (q, p) at time t_end = steps * h from (q0, p0), by the position-momentum method of
// the map. Fails the calling test (returns NaN) if any step fails.
template <class System, class Map>
std::pair<Vec<double, System::dim>, Vec<double, System::dim>> run(const System& L, const Map& R, double h,
                                                                   std::int64_t steps,
                                                                   const Vec<double, System::dim>& q0,
                                                                   const Vec<double, System::dim>& p0,
                                                                   StepOptions opt = {}) {
  const PositionMomentumStep<System, Map> S(L, R, h, opt);
  Vec<double, System::dim> q = q0, p = p0;
  const Vec<double, System::dim> v0 = legendre_inverse(L, q0, p0);
  const RunSummary r = integrate(S, 0.0, q, p, v0, steps, [](auto&&...) {});
  if (r.failed) q.setConstant(NAN);
  return {q, p};
}

// Least-squares slope of log(err) against log(h), over the points whose error is
// above `plateau` (round-off would flatten the fit).
inline double fit_order(const std::vector<double>& hs, const std::vector<double>& errs, double plateau = 1e-11) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (std::size_t i = 0; i < hs.size(); ++i) {
    if (!(errs[i] > plateau)) continue;
    const double x = std::log(hs[i]), y = std::log(errs[i]);
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
    ++n;
  }
  if (n < 3) return NAN;
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// Classical fourth-order Runge-Kutta in long double: n steps of y' = f(y) to t_end,
// for reference solutions independent of the engine.
template <std::size_t K, class F>
void rk4(const F& f, std::array<long double, K>& y, double t_end, int n) {
  using LD = long double;
  const LD h = (LD)t_end / n;
  auto add = [](const std::array<LD, K>& a, const std::array<LD, K>& b, LD c) {
    std::array<LD, K> r;
    for (std::size_t i = 0; i < K; ++i) r[i] = a[i] + c * b[i];
    return r;
  };
  for (int k = 0; k < n; ++k) {
    const auto k1 = f(y), k2 = f(add(y, k1, h / 2)), k3 = f(add(y, k2, h / 2)), k4 = f(add(y, k3, h));
    for (std::size_t i = 0; i < K; ++i) y[i] += h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
  }
}

// Classical fourth-order Runge-Kutta for the pendulum q' = p/(m l^2), p' = -m g l sin q,
// in long double: an independent reference at a step far smaller than any tested.
inline void pendulum_reference(const Pendulum& P, double t_end, double q0, double p0, double& q, double& p) {
  const long double a = 1.0L / (P.m * P.l * P.l), b = (long double)P.m * P.g * P.l;
  const int n = 20000;
  const long double h = (long double)t_end / n;
  long double Q = q0, Pm = p0;
  auto f = [&](long double x, long double y, long double& dx, long double& dy) {
    dx = a * y;
    dy = -b * std::sin(x);
  };
  for (int i = 0; i < n; ++i) {
    long double k1q, k1p, k2q, k2p, k3q, k3p, k4q, k4p;
    f(Q, Pm, k1q, k1p);
    f(Q + h / 2 * k1q, Pm + h / 2 * k1p, k2q, k2p);
    f(Q + h / 2 * k2q, Pm + h / 2 * k2p, k3q, k3p);
    f(Q + h * k3q, Pm + h * k3p, k4q, k4p);
    Q += h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q);
    Pm += h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p);
  }
  q = (double)Q;
  p = (double)Pm;
}

// Hairer-Lubich-Wanner's Kepler initial data with eccentricity e (Sec. I.2).
inline void kepler_initial(double e, Vec<double, 2>& q0, Vec<double, 2>& p0) {
  q0 = Vec<double, 2>(1.0 - e, 0.0);
  p0 = Vec<double, 2>(0.0, std::sqrt((1.0 + e) / (1.0 - e)));
}

}  // namespace dvm::verification
