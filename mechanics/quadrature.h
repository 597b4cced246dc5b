// Quadrature rules on [0, 1] for Galerkin discrete Lagrangians:
//
//   int_0^1 f(t) dt  ~  sum_{i=1}^{m} b_i f(c_i).
//
//   Gauss-Legendre, m = s points: c_i = (1 + x_i)/2 with x_i the roots of the
//     Legendre polynomial P_s on [-1, 1]; b_i = 1 / ((1 - x_i^2) P_s'(x_i)^2).
//     Exact for polynomials of degree <= 2s - 1.
//   Gauss-Lobatto, m = s + 1 points: x = -1, 1 and the roots of P_s'; the weights
//     b_i = 1 / (s (s + 1) P_s(x_i)^2). Exact for degree <= 2s - 1.
//   (Abramowitz and Stegun, Handbook of Mathematical Functions, 25.4.29 and 25.4.32;
//   the weights above are theirs halved for the interval [0, 1].)
//
// The roots are found by Newton's method on the three-term recurrence
//   (k + 1) P_{k+1}(x) = (2k + 1) x P_k(x) - k P_{k-1}(x),
//   (1 - x^2) P_k'(x) = k (P_{k-1}(x) - x P_k(x)),
//   (1 - x^2) P_k''(x) = 2 x P_k'(x) - k (k + 1) P_k(x)   (Legendre's equation),
// in long double, started from the Chebyshev-like guesses cos(pi (i - 1/4)/(s + 1/2))
// (Gauss) and cos(pi i / s) (Lobatto), then rounded to double. Identities a rule must
// satisfy (tested): sum b_i = 1, exactness on t^k for k <= 2s - 1, symmetry
// c_i + c_{m+1-i} = 1 with equal weights.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

namespace dvm {

enum class QuadratureKind { gauss, lobatto };

inline const char* to_string(QuadratureKind k) { return k == QuadratureKind::gauss ? "gauss" : "lobatto"; }

struct Quadrature {
  static constexpr int max_stages = 8;
  QuadratureKind kind = QuadratureKind::gauss;
  int stages = 1;  // s: the degree of the exactness bound 2s - 1
  int points = 1;  // m: s (Gauss) or s + 1 (Lobatto)
  std::array<long double, max_stages + 1> c{}, b{};

  // P_k(x) and P_k'(x).
  static void legendre(int k, long double x, long double& P, long double& dP) {
    long double p0 = 1.0L, p1 = x;
    if (k == 0) {
      P = 1.0L;
      dP = 0.0L;
      return;
    }
    for (int j = 1; j < k; ++j) {
      const long double p2 = ((2 * j + 1) * x * p1 - j * p0) / (j + 1);
      p0 = p1;
      p1 = p2;
    }
    P = p1;
    dP = k * (p0 - x * p1) / (1.0L - x * x);
  }

  Quadrature(QuadratureKind k, int s) : kind(k), stages(s) {
    if (s < 1 || s > max_stages)
      throw std::invalid_argument("quadrature stages must be 1.." + std::to_string(max_stages) + ", got " +
                                  std::to_string(s));
    const long double pi = 3.141592653589793238462643383279502884L;
    std::array<long double, max_stages + 1> x{}, w{};
    if (k == QuadratureKind::gauss) {
      points = s;
      for (int i = 0; i < s; ++i) {
        long double r = std::cos(pi * (i + 0.75L) / (s + 0.5L)), P = 0, dP = 0;
        for (int it = 0; it < 100; ++it) {
          legendre(s, r, P, dP);
          const long double d = P / dP;
          r -= d;
          if (std::fabs(d) <= 1e-19L) break;
        }
        legendre(s, r, P, dP);
        x[i] = r;
        w[i] = 2.0L / ((1.0L - r * r) * dP * dP);
      }
    } else {
      points = s + 1;
      x[0] = 1.0L;
      x[s] = -1.0L;
      for (int i = 1; i < s; ++i) {
        long double r = std::cos(pi * i / s), P = 0, dP = 0;
        for (int it = 0; it < 100; ++it) {
          legendre(s, r, P, dP);
          const long double ddP = (2.0L * r * dP - s * (s + 1.0L) * P) / (1.0L - r * r);
          const long double d = dP / ddP;
          r -= d;
          if (std::fabs(d) <= 1e-19L) break;
        }
        x[i] = r;
      }
      for (int i = 0; i <= s; ++i) {
        long double P = 0, dP = 0;
        if (i == 0 || i == s)
          P = (x[i] > 0 || s % 2 == 0) ? 1.0L : -1.0L;  // P_s(1) = 1, P_s(-1) = (-1)^s
        else
          legendre(s, x[i], P, dP);
        w[i] = 2.0L / (s * (s + 1.0L) * P * P);
      }
    }
    // nodes ascending on [0, 1]
    for (int i = 0; i < points; ++i) {
      c[i] = 0.5L * (1.0L + x[i]);
      b[i] = 0.5L * w[i];
    }
    for (int i = 0; i < points; ++i)
      for (int j = i + 1; j < points; ++j)
        if (c[j] < c[i]) std::swap(c[i], c[j]), std::swap(b[i], b[j]);
  }
};

}  // namespace dvm
