// Banded linear systems A x = b by Gaussian elimination with partial pivoting, in
// O(n kl (kl + ku)) operations: the step of a long chain couples each link with its
// neighbours only (mechanics/spherical_chain.h), so its linear algebra is banded.
//
// A has kl subdiagonals and ku superdiagonals: A(i, j) = 0 unless -kl <= j - i <= ku.
// Row interchanges widen the upper band of U to kl + ku, so each row is stored with
// room for it (LAPACK's dgbtrf keeps the same room, by columns).
#pragma once

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

namespace dvm {

class BandedLU {
 public:
  BandedLU(int n, int kl, int ku) : n_(n), kl_(kl), ku_(ku), width_(2 * kl + ku + 1) {
    if (n < 1 || kl < 0 || ku < 0) throw std::invalid_argument("BandedLU: needs n >= 1 and kl, ku >= 0");
    a_.assign(static_cast<std::size_t>(n) * static_cast<std::size_t>(width_), 0.0);
    pivot_.assign(static_cast<std::size_t>(n), 0);
    inverse_pivot_.assign(static_cast<std::size_t>(n), 0.0);
  }
  int size() const { return n_; }

  void set_zero() { std::fill(a_.begin(), a_.end(), 0.0); }
  // The entry (i, j) of A before factor(); j - i must lie in [-kl, ku].
  double& at(int i, int j) { return a_[index(i, j)]; }
  double at(int i, int j) const { return a_[index(i, j)]; }
  // The numbers stored (the band, with room for the pivots' fill): entry (i, j) is
  // storage()[offset(i, j)], the rest zero before factor().
  double* storage() { return a_.data(); }
  std::size_t storage_size() const { return a_.size(); }
  std::size_t offset(int i, int j) const { return index(i, j); }

  // L U = P A in place. False if a pivot is zero or not finite, or smaller than
  // 1e-14 times the largest entry of A (singular to working precision).
  bool factor() {
    double scale = 0.0;
    bool finite = true;
    for (double x : a_) {
      scale = std::max(scale, std::fabs(x));  // (not fmax: this loop vectorises)
      finite = finite && x - x == 0.0;
    }
    if (!finite) return false;
    for (int k = 0; k < n_; ++k) {
      const int last = std::min(n_ - 1, k + kl_);
      int p = k;
      double best = std::fabs(a_[index(k, k)]);
      for (int i = k + 1; i <= last; ++i) {
        const double x = std::fabs(a_[index(i, k)]);
        if (x > best) {
          best = x;
          p = i;
        }
      }
      pivot_[static_cast<std::size_t>(k)] = p;
      if (!(best > 1e-14 * scale)) return false;
      const int right = std::min(n_ - 1, k + kl_ + ku_);
      if (p != k)
        for (int j = k; j <= right; ++j) std::swap(a_[index(k, j)], a_[index(p, j)]);
      const double inv = 1.0 / a_[index(k, k)];
      inverse_pivot_[static_cast<std::size_t>(k)] = inv;
      for (int i = k + 1; i <= last; ++i) {
        double& l = a_[index(i, k)];
        if (l == 0.0) continue;
        l *= inv;
        const double f = l;
        const double* rk = &a_[index(k, k)];
        double* ri = &a_[index(i, k)];
        for (int j = 1; j <= right - k; ++j) ri[j] -= f * rk[j];
      }
    }
    return true;
  }
  // x = A^{-1} b, in place, after factor(). The bands of chains (1 and 1, 2 and 2) take
  // loops of fixed length, which the compiler unrolls.
  void solve(double* b) const {
    if (kl_ == 1 && ku_ == 1)
      solve_band<1, 1>(b);
    else if (kl_ == 2 && ku_ == 2)
      solve_band<2, 2>(b);
    else
      solve_band<0, 0>(b);
  }
  template <class Vector>
  void solve(Vector& b) const {
    solve(b.data());
  }

 private:
  // KL, KU: the band's size known at compile time (0: kl_ and ku_).
  template <int KL, int KU>
  void solve_band(double* b) const {
    const int kl = KL > 0 ? KL : kl_, ku = KU > 0 ? KU : ku_, w = width_, n = n_;
    const double* a = a_.data();
    if constexpr (KL == 1 && KU == 1) {
      // tridiagonal: the values each row passes to the next held in registers rather
      // than stored and read back (U's two superdiagonals past the last row are the
      // zeros the storage was made with: nothing writes there)
      double x = b[0];
      for (int k = 0; k + 1 < n; ++k) {
        double next = b[k + 1];
        if (pivot_[static_cast<std::size_t>(k)] != k) std::swap(x, next);
        b[k] = x;
        x = next - a[(k + 1) * w] * x;  // L(k + 1, k)
      }
      b[n - 1] = x;
      double x1 = 0.0, x2 = 0.0;  // x_{k+1}, x_{k+2}
      for (int k = n - 1; k >= 0; --k) {
        const double* u = a + k * w + 1;  // U(k, k), U(k, k + 1), U(k, k + 2)
        const double xk = (b[k] - u[2] * x2 - u[1] * x1) * inverse_pivot_[static_cast<std::size_t>(k)];
        b[k] = xk;
        x2 = x1;
        x1 = xk;
      }
      return;
    }
    // L: row i holds L(i, k) at i w + k - i + kl
    for (int k = 0; k < n; ++k) {
      const int p = pivot_[static_cast<std::size_t>(k)];
      if (p != k) std::swap(b[k], b[p]);
      const double bk = b[k];
      for (int j = 1; j <= kl && k + j < n; ++j) b[k + j] -= a[(k + j) * w - j + kl] * bk;
    }
    // U by columns, each x_k taken from the rows above as soon as it is known: by rows,
    // each row's dot product would load the x just stored (as a vector where the loop
    // is vectorised, which the store cannot forward), and a division by the pivot
    // would set the recurrence's pace
    for (int k = n - 1; k >= 0; --k) {
      const double x = b[k] * inverse_pivot_[static_cast<std::size_t>(k)];
      b[k] = x;
      for (int j = 1; j <= kl + ku && k - j >= 0; ++j) b[k - j] -= a[(k - j) * w + j + kl] * x;
    }
  }

  // row i holds columns i - kl ... i + kl + ku
  std::size_t index(int i, int j) const {
    return static_cast<std::size_t>(i) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(j - i + kl_);
  }
  int n_, kl_, ku_, width_;
  std::vector<double> a_;
  std::vector<int> pivot_;
  std::vector<double> inverse_pivot_;  // 1 / U(k, k)
};

}  // namespace dvm
