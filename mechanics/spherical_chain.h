// The chain of spherical pendulums with any number of links, and the linear algebra
// of its mass matrix in O(K) operations.
//
// SphericalChain<K> (mechanics/manifold_systems.h) is the chain at a compiled number of
// links. In the embedding (x_i unit vectors, u_i = dx_i/dt, r_i = sum_{j <= i} l_j x_j)
// its Lagrangian is
//   L = u^T M u / 2 - sum_j c_j (x_j)_3,
//   M = (l_i l_j mu_max(i, j))_{ij} (x) I_3,   mu_j = sum_{k >= j} m_k,   c_j = g l_j mu_j,
// since sum_i m_i |dr_i/dt|^2 = sum_{j,k} l_j l_k mu_max(j,k) u_j.u_k and
// sum_i m_i (r_i)_3 = sum_j l_j mu_j (x_j)_3. M is dense, but with
//   s_k = sum_{j <= k} l_j u_j   (the velocity of mass k)   and   w_i = sum_{k >= i} m_k s_k
// it is (M u)_i = l_i w_i: a product costs O(K).
//
// ChainCouplingSolve solves the systems (D + c B^T M C) delta = r that Newton's method
// on the chain's step equation and its Legendre map meet, D block diagonal (2 x 2 per
// link), B and C block diagonal (3 x 2 per link: tangent vectors of the factors), by
// keeping s and w as unknowns: per link
//   D_i delta_i + c l_i B_i^T w_i = r_i,   s_i - s_{i-1} - l_i C_i delta_i = 0,
//   w_i - w_{i+1} - m_i s_i = 0,
// a banded system of 8 K unknowns (core/banded_solve.h), O(K) to factor and solve,
// made dimensionless link by link (below).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/banded_solve.h"
#include "core/dynamic_sphere_power.h"

namespace dvm {

class DynamicSphericalChain {
 public:
  using Manifold = DynamicSpherePower;
  using V = Eigen::VectorXd;

  DynamicSphericalChain(V m, V l, double g) : m_(std::move(m)), l_(std::move(l)), g_(g) {
    if (m_.size() < 1 || m_.size() != l_.size())
      throw std::invalid_argument("spherical-chain: needs one mass and one length per link, at least one link");
    for (Eigen::Index i = 0; i < m_.size(); ++i)
      if (!(m_[i] > 0) || !(l_[i] > 0) || !std::isfinite(m_[i]) || !std::isfinite(l_[i]))
        throw std::invalid_argument("spherical-chain: masses and lengths must be positive and finite");
    if (!std::isfinite(g)) throw std::invalid_argument("spherical-chain: g must be finite");
    const int K = links();
    mu_.resize(K);
    double tail = 0.0;
    for (int i = K - 1; i >= 0; --i) mu_[i] = tail += m_[i];
  }
  std::string name() const { return "spherical-chain"; }
  int links() const { return static_cast<int>(m_.size()); }
  int dim() const { return 2 * links(); }
  const V& masses() const { return m_; }
  const V& lengths() const { return l_; }
  double g() const { return g_; }
  // d/d(x_i)_3 of the potential sum_j c_j (x_j)_3
  double height_coefficient(int i) const { return g_ * l_[i] * mu_[i]; }
  // mu_i, the mass at and below link i
  double mass_below(int i) const { return mu_[i]; }
  // M_ii = l_i^2 mu_i, the diagonal 3 x 3 block of M over I_3 (|M_ij| <= sqrt(M_ii M_jj))
  double mass_diagonal(int i) const { return l_[i] * l_[i] * mu_[i]; }

  // out = M u, O(K). The two running sums are compensated (Neumaier), so that their
  // round-off does not grow with the number of links: the step's residual is formed
  // from them and must reach a relative 2e-15 at any K.
  void mass_times(const V& u, V& out) const {
    const int K = links();
    out.resize(3 * K);
    double s[3] = {0, 0, 0}, cs[3] = {0, 0, 0};
    for (int k = 0; k < K; ++k)
      for (int c = 0; c < 3; ++c) {
        add_compensated(s[c], cs[c], l_[k] * u[3 * k + c]);
        out[3 * k + c] = m_[k] * (s[c] + cs[c]);  // m_k s_k, summed from the end below
      }
    double w[3] = {0, 0, 0}, cw[3] = {0, 0, 0};
    for (int i = K - 1; i >= 0; --i)
      for (int c = 0; c < 3; ++c) {
        add_compensated(w[c], cw[c], out[3 * i + c]);
        out[3 * i + c] = l_[i] * (w[c] + cw[c]);
      }
  }
  double potential(const V& x) const {
    double U = 0.0;
    for (int j = 0; j < links(); ++j) U += height_coefficient(j) * x[3 * j + 2];
    return U;
  }
  // E = u^T M u / 2 + U(x)
  double energy(const V& x, const V& u) const {
    V Mu;
    mass_times(u, Mu);
    return 0.5 * u.dot(Mu) + potential(x);
  }
  // The vertical angular momentum sum_i (x_i x p_i)_3 (as SphericalChain<K>'s).
  static double vertical_momentum(const V& x, const V& p) {
    double J = 0.0;
    for (Eigen::Index i = 0; i < x.size() / 3; ++i) J += x[3 * i] * p[3 * i + 1] - x[3 * i + 1] * p[3 * i];
    return J;
  }

 private:
  // sum + c carries the running total to about twice working precision
  static void add_compensated(double& sum, double& c, double x) {
    const double t = sum + x;
    c += std::fabs(sum) >= std::fabs(x) ? (sum - t) + x : (x - t) + sum;
    sum = t;
  }
  V m_, l_, mu_;
  double g_;
};

class ChainCouplingSolve {
 public:
  using V = Eigen::VectorXd;
  using M2 = Mat<double, 2, 2>;
  using M32 = Mat<double, 3, 2>;

  // Unknowns and equations of link i at 8 i ... 8 i + 7: delta_i (2), s_i (3), w_i (3),
  // each made dimensionless so that the pivots do not depend on the chain's units:
  // with J_i = c l_i^2 mu_i (the size of the coupling's diagonal block), the unknowns
  // s_i / l_i and w_i / (l_i mu_i) and the equations
  //   (D_i delta_i) / J_i + B_i^T w~_i = r_i / J_i,
  //   s~_i - (l_{i-1} / l_i) s~_{i-1} - C_i delta_i = 0,
  //   w~_i - (l_{i+1} mu_{i+1} / (l_i mu_i)) w~_{i+1} - (m_i / mu_i) s~_i = 0.
  // The farthest couplings: s_{i-1} in the rows of s_i (8 below the diagonal), w_{i+1}
  // in the rows of w_i (8 above) and w_i in those of delta_i (up to 7 above).
  explicit ChainCouplingSolve(const DynamicSphericalChain& chain)
      : chain_(chain), lu_(8 * chain.links(), 8, 8), row_scale_(chain.links()) {}

  int links() const { return chain_.links(); }

  // Factors D + c B^T M C; false if it is singular to working precision.
  bool factor(const std::vector<M2>& D, const std::vector<M32>& B, const std::vector<M32>& C, double c) {
    const int K = links();
    const V& m = chain_.masses();
    const V& l = chain_.lengths();
    lu_.set_zero();
    for (int i = 0; i < K; ++i) {
      const int o = 8 * i;
      const std::size_t u = static_cast<std::size_t>(i);
      const double mu = chain_.mass_below(i);
      row_scale_[i] = 1.0 / (c * l[i] * l[i] * mu);
      for (int a = 0; a < 2; ++a) {
        for (int b = 0; b < 2; ++b) lu_.at(o + a, o + b) = D[u](a, b) * row_scale_[i];
        for (int k = 0; k < 3; ++k) lu_.at(o + a, o + 5 + k) = B[u](k, a);
      }
      for (int k = 0; k < 3; ++k) {
        lu_.at(o + 2 + k, o + 2 + k) = 1.0;
        if (i > 0) lu_.at(o + 2 + k, o - 6 + k) = -l[i - 1] / l[i];
        for (int b = 0; b < 2; ++b) lu_.at(o + 2 + k, o + b) = -C[u](k, b);
        lu_.at(o + 5 + k, o + 5 + k) = 1.0;
        if (i + 1 < K) lu_.at(o + 5 + k, o + 13 + k) = -(l[i + 1] * chain_.mass_below(i + 1)) / (l[i] * mu);
        lu_.at(o + 5 + k, o + 2 + k) = -m[i] / mu;
      }
    }
    return lu_.factor();
  }
  // delta with (D + c B^T M C) delta = r (2 K entries), after factor().
  void solve(const V& r, V& delta) const {
    const int K = links();
    work_.setZero(8 * K);
    for (int i = 0; i < K; ++i) work_.segment<2>(8 * i) = r.segment<2>(2 * i) * row_scale_[i];
    lu_.solve(work_);
    delta.resize(2 * K);
    for (int i = 0; i < K; ++i) delta.segment<2>(2 * i) = work_.segment<2>(8 * i);
  }

 private:
  DynamicSphericalChain chain_;
  BandedLU lu_;
  V row_scale_;
  mutable V work_;
};

// The Legendre map of the chain at x and its inverse, in the stored form of
// SpherePower: p_i = P_i (M u)_i with P_i the projection onto T_{x_i} S^2, and the
// tangent u with that momentum, from B^T M B nu = B^T p (B the factors' tangent bases).
inline Eigen::VectorXd chain_legendre(const DynamicSphericalChain& L, const Eigen::VectorXd& x,
                                      const Eigen::VectorXd& u) {
  Eigen::VectorXd Mu;
  L.mass_times(u, Mu);
  return DynamicSpherePower::tangent(x, DynamicSpherePower::tangent_coordinates(x, Mu));
}
inline Eigen::VectorXd chain_legendre_inverse(const DynamicSphericalChain& L, const Eigen::VectorXd& x,
                                              const Eigen::VectorXd& p, ChainCouplingSolve& solver) {
  const int K = L.links();
  std::vector<Mat<double, 2, 2>> D(static_cast<std::size_t>(K), Mat<double, 2, 2>::Zero());
  std::vector<Mat<double, 3, 2>> B(static_cast<std::size_t>(K));
  for (int i = 0; i < K; ++i) B[static_cast<std::size_t>(i)] = Sphere::basis(x.segment<3>(3 * i));
  if (!solver.factor(D, B, B, 1.0)) throw std::domain_error("spherical-chain: the mass matrix is singular at x");
  Eigen::VectorXd nu;
  solver.solve(DynamicSpherePower::tangent_coordinates(x, p), nu);
  return DynamicSpherePower::tangent(x, nu);
}

}  // namespace dvm
