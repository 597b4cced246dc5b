// Galerkin discrete Lagrangians and their position-momentum step.
//
// The exact discrete Lagrangian L_d(q0, q1) = int_0^h L(q, qdot) dt along the true
// motion is approximated by extremising a quadrature of the action over curves of
// degree s with the right end points:
//
//   L_d(q0, q1) = ext_{q_1..q_{s-1}}  h sum_i b_i L(q(c_i h), qdot(c_i h)),
//   q(tau h) = sum_{j=0}^{s} q_j l_j(tau),   q_0 = q0, q_s = q1,
//
// l_j the Lagrange basis of degree s on the control points d_j = j / s of [0, 1], and
// (c_i, b_i) a quadrature rule (mechanics/quadrature.h). (Marsden and West, "Discrete
// mechanics and variational integrators", Acta Numerica 2001, Sec. 2.2.6; the same idea
// as the paper's composition with micro-nodes, Sec. 6, with the micro-nodes inside the
// step.) With Gauss-Legendre quadrature of s points the one-step map is Gauss
// collocation of order 2s (symplectic, symmetric); with Gauss-Lobatto of s + 1 points
// it is the Lobatto IIIA-IIIB pair, also of order 2s (Marsden and West, Thm 2.6.1 and
// Sec. 2.6.3; Hairer, Lubich, Wanner, Geometric Numerical Integration, VI.6.3).
// For s = 1 with Gauss (midpoint) quadrature, L_d = h L((q0 + q1)/2, (q1 - q0)/h): the
// midpoint discrete Lagrangian.
//
// The step. With the unknowns X_j = q_j - q0, j = 1..s (increments: no cancellation
// in q1 - q0), the nodes at the quadrature points are
//   x_i = q0 + sum_j l_j(c_i) X_j,   v_i = (1/h) sum_j l_j'(c_i) X_j
// (sum_j l_j = 1 and sum_j l_j' = 0 remove q_0), and with g_i = dL/dq(x_i, v_i),
// p_i = dL/dv(x_i, v_i),
//   dL_d/dq_j = sum_i b_i (h l_j(c_i) g_i + l_j'(c_i) p_i).
// Given (q0, p0), the s N equations
//   R_0 = p0 + dL_d/dq_0 = 0,   R_j = dL_d/dq_j = 0 (j = 1..s-1)
// determine X; then q1 = q0 + X_s and, because the dL_d/dq_j sum to h sum_i b_i g_i,
//   p1 = dL_d/dq_s = p0 + h sum_i b_i g_i
// at the solution: the momentum increment is the quadrature of the force, added
// without cancellation.
//
// The solve is a simplified Newton iteration, the one driver (solvers/newton_driver.h)
// with Refresh::contracting: the Jacobian (from the Hessian of L at the quadrature
// points, by automatic differentiation through dL/dq, dL/dv) is inverted once and
// reused across iterations and steps while the corrections contract fourfold; it is
// refreshed when they do not or the iteration stalls. The starting guess for a step that
// continues the previous one is the previous step's polynomial extrapolated to the
// new control points, E X_prev (error O(h^{s+1}), stage order s), corrected by the
// errors of that same extrapolation at the two previous steps: along a trajectory
// the error d_n = X_n - E X_{n-1} is a smooth function of the state, of size
// O(h^{s+1}), so d_{n+1} = 2 d_n - d_{n-1} + O(h^2 d'') and the guess
//   X_{n+1}^0 = E X_n + 2 d_n - d_{n-1}
// has error O(h^{s+3}) (measured in tests/solvers/test_galerkin.cc). It costs two
// vector operations and no evaluation of the Lagrangian. (Hairer, Lubich, Wanner,
// Geometric Numerical Integration, Sect. VIII.6.1, discuss starting approximations
// for implicit Runge-Kutta methods: the extrapolated collocation polynomial, and
// improvements that spend extra evaluations of the vector field; this correction
// spends none.) Stopping rule: the driver's, as every Newton iteration of dvm;
// iterations are bounded by StepOptions::max_iterations and a step that does not
// converge is reported in its StepSummary.
//
// The step type fits `integrate` (N, step_size(), step(q, p, dq, dp)); it keeps the
// previous step's polynomial and the factored Jacobian in mutable members, so one
// object must not be shared between threads. Stage count S > 0 fixes all sizes at
// compile time; S = 0 takes the stage count at run time (1..kGalerkinMaxStages) in
// fixed-capacity storage (still no allocation per step).
#pragma once

#include <Eigen/LU>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "mechanics/lagrangian.h"
#include "mechanics/quadrature.h"
#include "solvers/integrate.h"
#include "solvers/newton.h"
#include "solvers/newton_driver.h"

namespace dvm {

constexpr int kGalerkinMaxStages = 6;

// s, checked: 1..kGalerkinMaxStages, and equal to `compiled` when that is nonzero (a
// compile-time stage count). Throws std::invalid_argument otherwise.
inline int check_galerkin_stages(int s, int compiled) {
  if (s < 1 || s > kGalerkinMaxStages || (compiled > 0 && s != compiled))
    throw std::invalid_argument("galerkin stages must be 1.." + std::to_string(kGalerkinMaxStages) +
                                (compiled > 0 ? " and equal to the compiled " + std::to_string(compiled) : std::string()) +
                                ", got " + std::to_string(s));
  return s;
}

// The correction of a starting guess by the errors of the last two extrapolations (see
// the top of this file): a step that continues its predecessor starts from
// E X_prev + correction(), and once it has converged record(X, E X_prev) books the
// error d_n = X - E X_prev. T is the unknowns' Eigen type (vector or matrix).
template <class T>
struct ExtrapolationErrors {
  T err1, err2, corr;  // d_n (the latest), d_{n-1}, and the last correction
  int known = 0;       // how many of d_n, d_{n-1} are known

  void zero_like(const T& x) {
    err1 = err2 = corr = x;
    err1.setZero();
    err2.setZero();
    corr.setZero();
    known = 0;
  }
  // 2 d_n - d_{n-1}, or d_n, or 0 with fewer errors known
  const T& correction() {
    if (known >= 2)
      corr = 2.0 * err1 - err2;
    else if (known == 1)
      corr = err1;
    else
      corr.setZero();
    return corr;
  }
  void record(const T& solution, const T& extrapolated) {
    err2.swap(err1);
    err1 = solution - extrapolated;
    if (known < 2) ++known;
  }
  void forget() { known = 0; }
};

// The coefficient tables of a Galerkin step with s stages (s <= SMax) and a quadrature
// (c_i, b_i) of m points: b_i, A_ij = l_j(c_i), B_ij = l_j'(c_i), WA_ij = b_i l_j(c_i),
// WB_ij = b_i l_j'(c_i) (l_j the Lagrange basis on the control points j / s), and E, the
// extrapolation of the previous step's polynomial to tau = 1 + d_j relative to its end
// (see the top of this file). Computed in long double, stored in double; shared by the
// fixed-size step below and the run-time-sized one (solvers/dynamic_galerkin_step.h).
template <int SMax>
struct GalerkinTables {
  static constexpr int MMax = SMax + 1;  // quadrature points (Lobatto: s + 1)
  std::array<double, MMax> b{};
  std::array<std::array<double, SMax + 1>, MMax> A{}, B{}, WA{}, WB{};
  std::array<std::array<double, SMax + 1>, SMax + 1> E{};

  GalerkinTables(const Quadrature& quad, int s) {
    const int m = quad.points;
    std::array<long double, SMax + 1> d{};
    for (int j = 0; j <= s; ++j) d[j] = static_cast<long double>(j) / s;
    auto basis = [&](int j, long double t, long double& l, long double& dl) {
      l = 1.0L;
      dl = 0.0L;
      for (int k = 0; k <= s; ++k) {
        if (k == j) continue;
        const long double f = (t - d[k]) / (d[j] - d[k]);
        dl = dl * f + l / (d[j] - d[k]);
        l *= f;
      }
    };
    for (int i = 0; i < m; ++i) {
      b[i] = static_cast<double>(quad.b[i]);
      for (int j = 0; j <= s; ++j) {
        long double l, dl;
        basis(j, quad.c[i], l, dl);
        A[i][j] = static_cast<double>(l);
        B[i][j] = static_cast<double>(dl);
        WA[i][j] = static_cast<double>(quad.b[i] * l);
        WB[i][j] = static_cast<double>(quad.b[i] * dl);
      }
    }
    for (int j = 1; j <= s; ++j)
      for (int k = 1; k <= s; ++k) {
        long double l, dl;
        basis(k, 1.0L + d[j], l, dl);
        E[j][k] = static_cast<double>(l - (k == s ? 1.0L : 0.0L));
      }
  }
};

template <class System, int S = 0>
class GalerkinStep {
  static_assert(S >= 0 && S <= kGalerkinMaxStages, "Galerkin stages 1..6 (0: chosen at run time)");

 public:
  static constexpr int N = System::dim;
  static constexpr int SMax = S > 0 ? S : kGalerkinMaxStages;
  static constexpr int K = S > 0 ? S * N : Eigen::Dynamic;
  static constexpr int KMax = SMax * N;
  static constexpr int MMax = SMax + 1;  // quadrature points (Lobatto: s + 1)
  using V = Vec<double, N>;
  template <class T>
  using XV = Eigen::Matrix<T, K, 1, 0, KMax, 1>;
  using XM = Eigen::Matrix<double, K, K, 0, KMax, KMax>;

  GalerkinStep(System L, QuadratureKind kind, int stages, double h, StepOptions options = {})
      : L_(std::move(L)), quad_(kind, check_stages(stages)), s_(stages), h_(h), options_(options), t_(quad_, s_) {
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
    const int s = s_, m = quad_.points;
    for (int i = 0; i < m; ++i) {
      bh_[i] = h_ * t_.b[i];
      for (int j = 1; j <= s; ++j) {
        Af_(j - 1, i) = t_.A[i][j];
        Bf_(j - 1, i) = t_.B[i][j] / h_;
      }
      for (int j = 0; j < s; ++j) {
        WAf_(i, j) = h_ * t_.WA[i][j];
        WBf_(i, j) = t_.WB[i][j];
      }
    }
    X_.setZero(s * N);
    Xprev_.setZero(s * N);
    Xext_.setZero(s * N);
    guess_.zero_like(X_);
    R_.setZero(s * N);
    delta_.setZero(s * N);
    J_.setZero(s * N, s * N);
    lu_.inv.setZero(s * N, s * N);
    start_.setZero(s * N);
  }

  double step_size() const { return h_; }
  int stages() const { return s_; }
  int order() const { return 2 * s_; }
  const Quadrature& quadrature() const { return quad_; }
  const System& lagrangian() const { return L_; }
  // Jacobian evaluations and factorisations since construction.
  long jacobian_updates() const { return jacobian_updates_; }
  // Diagnostics of the starting guess of the last step, if it converged and continued
  // its predecessor (NaN otherwise), in the max norm over the s N unknowns: the
  // distance of the guess used, and of the plain extrapolation E X_prev, from the
  // solution. Computed on request from the predictor's state (not in the step).
  double last_guess_error() const {
    return guess_measured_ ? (guess_.err1 - guess_.corr).template lpNorm<Eigen::Infinity>() : NAN;
  }
  double last_extrapolation_error() const {
    return guess_measured_ ? guess_.err1.template lpNorm<Eigen::Infinity>() : NAN;
  }
  // Forget the previous step (its polynomial and the Jacobian).
  void reset() const {
    have_prev_ = false;
    kept_.valid = false;
    guess_.forget();
    guess_measured_ = false;
  }

  // h sum_i b_i L(x_i, v_i) at the nodes q0 + X_j: the action whose stationary value
  // is L_d.
  template <class T>
  T action(const Vec<T, N>& q0, const XV<T>& X) const {
    T sum = constant<T>(0.0);
    for (int i = 0; i < quad_.points; ++i) {
      Vec<T, N> x, v;
      node(i, q0, X, x, v);
      sum += (h_ * t_.b[i]) * L_(x, v);
    }
    return sum;
  }

  // The step residual R(X) (s N values) and the force quadrature h sum_i b_i g_i,
  // for any scalar.
  template <class T>
  void residual(const Vec<T, N>& q0, const Vec<T, N>& p0, const XV<T>& X, XV<T>& R, Vec<T, N>& force) const {
    const int s = s_;
    R.setConstant(s * N, constant<T>(0.0));
    force.setConstant(constant<T>(0.0));
    Vec<T, N> x, v, g, p;
    for (int i = 0; i < quad_.points; ++i) {
      node(i, q0, X, x, v);
      lagrangian_gradient(L_, x, v, g, p);
      for (int a = 0; a < N; ++a) g[a] = g[a] * h_;
      for (int j = 0; j < s; ++j) R.template segment<N>(j * N) += t_.WA[i][j] * g + t_.WB[i][j] * p;
      force += t_.b[i] * g;
    }
    R.template segment<N>(0) += p0;
  }

  // One step from (q0, p0); dq carries a guess of q1 - q0 on entry (used unless the
  // step continues the previous one), q1 - q0 on return; dp receives p1 - p0.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    const int s = s_;
    guess_measured_ = false;
    const bool continues = have_prev_ && max_abs(V(q0 - q_end_)) <= 1e-12 * (max_abs(q0) + max_abs(dq)) + 1e-300;
    if (continues) {
      extrapolate();  // Xext_ = E Xprev_
      // the extrapolation errors of the last steps, extrapolated in the step index
      X_ = Xext_ + guess_.correction();
    } else {
      for (int j = 1; j <= s; ++j) X_.template segment<N>((j - 1) * N) = (static_cast<double>(j) / s) * dq;
      guess_.forget();
    }
    have_prev_ = false;
    Equation eq{*this, q0, p0, max_abs(p0), max_abs(q0)};
    StepSummary sum;
    try {
      sum = newton_drive_inlined(eq, lu_, Refresh::contracting, options_, X_, R_, delta_, J_, kept_, start_);
    } catch (const std::domain_error& e) {  // L undefined at a node
      sum.fail(e.what());
      kept_.valid = false;
    }
    jacobian_updates_ += sum.jacobians;
    if (!sum.converged) return sum;
    dq = X_.template segment<N>((s - 1) * N);
    dp = force_;  // the force quadrature at the last evaluation (before the final correction)
    if (!std::isfinite(max_abs(dq)) || !std::isfinite(max_abs(dp))) {
      sum.fail("non-finite step");
      kept_.valid = false;
      return sum;
    }
    if (continues) {
      guess_.record(X_, Xext_);
      guess_measured_ = true;
    }
    Xprev_ = X_;
    q_end_ = q0 + dq;
    have_prev_ = true;
    return sum;
  }

  // The Jacobian d(q1, p1)/d(q0, p0) of the one-step map at a converged step with
  // nodes X (from the implicit function theorem, by automatic differentiation): for
  // the symplecticity check.
  Mat<double, 2 * N, 2 * N> map_jacobian(const V& q0, const V& p0) const {
    static_assert(S > 0, "map_jacobian needs a compile-time stage count");
    constexpr int KK = S * N;
    using D = ceres::Jet<double, KK + 2 * N>;
    const XV<double> X = Xprev_;
    Vec<D, N> q0d, p0d, force;
    for (int a = 0; a < N; ++a) {
      q0d[a] = seed<double, KK + 2 * N>(q0[a], KK + a);
      p0d[a] = seed<double, KK + 2 * N>(p0[a], KK + N + a);
    }
    XV<D> Xd, Rd;
    for (int k = 0; k < KK; ++k) Xd[k] = seed<double, KK + 2 * N>(X[k], k);
    residual<D>(q0d, p0d, Xd, Rd, force);
    Mat<double, KK, KK> RX;
    Mat<double, KK, 2 * N> Ry;
    for (int k = 0; k < KK; ++k) {
      RX.row(k) = Rd[k].v.template head<KK>().transpose();
      Ry.row(k) = Rd[k].v.template tail<2 * N>().transpose();
    }
    const Mat<double, KK, 2 * N> dX = -RX.partialPivLu().solve(Ry);  // dX/d(q0, p0)
    Mat<double, 2 * N, 2 * N> M = Mat<double, 2 * N, 2 * N>::Zero();
    for (int a = 0; a < N; ++a) {
      M(a, a) = 1.0;  // q1 = q0 + X_s
      M.row(a) += dX.row((S - 1) * N + a);
      M(N + a, N + a) = 1.0;  // p1 = p0 + force(q0, X)
      const Eigen::Matrix<double, 1, KK> fX = force[a].v.template head<KK>().transpose();
      M.row(N + a) += fX * dX;
      M.row(N + a) += force[a].v.template tail<2 * N>().transpose();
    }
    return M;
  }

 private:
  static int check_stages(int s) { return check_galerkin_stages(s, S); }

  template <class T>
  void node(int i, const Vec<T, N>& q0, const XV<T>& X, Vec<T, N>& x, Vec<T, N>& v) const {
    x = q0;
    v.setConstant(constant<T>(0.0));
    for (int j = 1; j <= s_; ++j) {
      const auto Xj = X.template segment<N>((j - 1) * N);
      x += t_.A[i][j] * Xj;
      v += t_.B[i][j] * Xj;
    }
    const double inv_h = 1.0 / h_;
    for (int a = 0; a < N; ++a) v[a] = v[a] * inv_h;
  }

  // residual<double> for a compile-time stage count and M = m quadrature points (s
  // for Gauss, s + 1 for Lobatto), as small fixed-size matrix products:
  //   x = q0 + X A, v = X B / h (N x m), R = h G WA + P WB (N x s), force = h G b.
  // (With m fixed at compile time the products and the loop over the points are
  // unrolled, which costs less per evaluation than m read at run time;
  // bench_galerkin_kepler times the Galerkin steps against Odeint's Gauss-6.)
  template <int M>
  void residual_fast(const V& q0, const V& p0, const XV<double>& x, XV<double>& r, V& force) const {
    using NM = Eigen::Matrix<double, N, M>;
    const Eigen::Map<const Eigen::Matrix<double, N, SMax>> X(x.data());
    NM xs, vs, G, P;
    xs.noalias() = X * Af_.template leftCols<M>();
    xs.colwise() += q0;
    vs.noalias() = X * Bf_.template leftCols<M>();
    for (int i = 0; i < M; ++i) {
      V g, p;
      lagrangian_gradient(L_, V(xs.col(i)), V(vs.col(i)), g, p);
      G.col(i) = g;
      P.col(i) = p;
    }
    Eigen::Map<Eigen::Matrix<double, N, SMax>> R(r.data());
    R.noalias() = G * WAf_.template topRows<M>();
    R.noalias() += P * WBf_.template topRows<M>();
    R.col(0) += p0;
    force.noalias() = G * bh_.template head<M>();
  }

  // The residual R(x) at the increments x, and the force quadrature into force_.
  void evaluate(const V& q0, const V& p0, const XV<double>& x, XV<double>& r) const {
    if constexpr (S > 0) {
      if (quad_.points == S)
        residual_fast<S>(q0, p0, x, r, force_);
      else
        residual_fast<S + 1>(q0, p0, x, r, force_);
    } else
      residual<double>(q0, p0, x, r, force_);
  }

  // The step equation for the driver: R(X) = 0 in the increments X, its scale
  // |p0| + max|J| max|X|, the increments those of a point of size |q0|.
  struct Equation {
    using Vector = XV<double>;
    using Matrix = XM;
    const GalerkinStep& step;
    const V& q0;
    const V& p0;
    double pscale, q0size;
    void residual(const Vector& x, Vector& r) const { step.evaluate(q0, p0, x, r); }
    double jacobian(const Vector& x, Vector& r, Matrix& J) const {
      const double Jmax = step.form_jacobian(q0, x, J);
      step.evaluate(q0, p0, x, r);
      return Jmax;
    }
    double scale(double xn, double Jmax) const { return pscale + Jmax * xn; }
    double offset() const { return q0size; }
    // Eigen's packet maximum, which need not carry a NaN through: a non-finite step is
    // refused after the solve, where dq and dp are checked (the NaN-carrying maximum is the
    // slower at these sizes; bench_galerkin_kepler measures the step)
    double norm(const Vector& v) const { return v.template lpNorm<Eigen::Infinity>(); }
  };

  // The Jacobian's factorisation, kept as its inverse (applied as a matrix-vector
  // product at every iteration); singular where Eigen's estimate of its reciprocal
  // condition is not above 1e-13.
  struct InverseLU {
    XM inv;
    bool factor(const XM& J, double /*Jmax*/) {
      const Eigen::PartialPivLU<XM> lu(J);
      if (!(lu.rcond() > 1e-13)) return false;
      inv = lu.inverse();
      return true;
    }
    void solve(const XV<double>& r, XV<double>& dx) const {
      if constexpr (S > 0) {
        // as a sum of columns: packet operations down each column of the fixed size, into
        // a local, which stays in registers where dx, a reference the compiler cannot
        // tell apart from r, would be stored at every column
        XV<double> sum = inv.col(0) * r[0];
        for (int k = 1; k < K; ++k) sum += inv.col(k) * r[k];
        dx = sum;
      } else
        dx.noalias() = inv * r;
    }
    const char* name() const { return "LU with reciprocal condition above 1e-13"; }
  };

  // Xext_ = the previous step's polynomial extrapolated to this step's control
  // points, relative to this step's start: Xext_j = sum_k E_jk Xprev_k.
  void extrapolate() const {
    for (int j = 1; j <= s_; ++j) {
      V a = V::Zero();
      for (int k = 1; k <= s_; ++k) a += t_.E[j][k] * Xprev_.template segment<N>((k - 1) * N);
      Xext_.template segment<N>((j - 1) * N) = a;
    }
  }

  // The Jacobian dR/dX at the nodes of the increments X into J; returns max|J_ij|
  // (not finite where an entry is not).
  double form_jacobian(const V& q0, const XV<double>& X, XM& J) const {
    const int s = s_;
    using D = ceres::Jet<double, 2 * N>;
    J.setZero(s * N, s * N);
    V x, v;
    Vec<D, N> xd, vd, g, p;
    Mat<double, N, N> Gq, Gv, Pq, Pv;
    for (int i = 0; i < quad_.points; ++i) {
      node(i, q0, X, x, v);
      for (int a = 0; a < N; ++a) {
        xd[a] = seed<double, 2 * N>(x[a], a);
        vd[a] = seed<double, 2 * N>(v[a], N + a);
      }
      lagrangian_gradient(L_, xd, vd, g, p);
      for (int a = 0; a < N; ++a) {
        Gq.row(a) = g[a].v.template head<N>().transpose();
        Gv.row(a) = g[a].v.template tail<N>().transpose();
        Pq.row(a) = p[a].v.template head<N>().transpose();
        Pv.row(a) = p[a].v.template tail<N>().transpose();
      }
      for (int k = 1; k <= s; ++k) {
        // d(h g_i)/dX_k and d(p_i)/dX_k
        const Mat<double, N, N> dg = h_ * (t_.A[i][k] * Gq + (t_.B[i][k] / h_) * Gv);
        const Mat<double, N, N> dp = t_.A[i][k] * Pq + (t_.B[i][k] / h_) * Pv;
        for (int j = 0; j < s; ++j)
          J.template block<N, N>(j * N, (k - 1) * N) += t_.WA[i][j] * dg + t_.WB[i][j] * dp;
      }
    }
    return max_abs(J);
  }

  System L_;
  Quadrature quad_;
  int s_;
  double h_;
  StepOptions options_;
  GalerkinTables<SMax> t_;
  // the same tables as matrices for the fixed-size hot path (columns past the
  // quadrature's points are zero)
  Eigen::Matrix<double, SMax, MMax> Af_ = Eigen::Matrix<double, SMax, MMax>::Zero(),
                                    Bf_ = Eigen::Matrix<double, SMax, MMax>::Zero();
  Eigen::Matrix<double, MMax, SMax> WAf_ = Eigen::Matrix<double, MMax, SMax>::Zero(),
                                    WBf_ = Eigen::Matrix<double, MMax, SMax>::Zero();
  Eigen::Matrix<double, MMax, 1> bh_ = Eigen::Matrix<double, MMax, 1>::Zero();
  // workspace and the state carried from step to step
  mutable XV<double> X_, Xprev_, R_, start_;
  mutable XV<double> delta_;
  mutable V force_ = V::Zero();  // the force quadrature at the last residual
  // the predictor: the plain extrapolation of this step and the errors of the plain
  // extrapolations of the last two steps; guess_measured_: the last step converged
  // continuing its predecessor, so guess_.err1 and guess_.corr are its extrapolation
  // error and its correction
  mutable XV<double> Xext_;
  mutable ExtrapolationErrors<XV<double>> guess_;
  mutable bool guess_measured_ = false;
  // the Jacobian, its inverse and whether it is kept (Refresh::contracting)
  mutable XM J_;
  mutable InverseLU lu_;
  mutable DriverState kept_;
  mutable bool have_prev_ = false;
  mutable V q_end_ = V::Zero();
  mutable long jacobian_updates_ = 0;
};

// What a Galerkin run reports: the run summary and the solver's work.
struct GalerkinRunStats {
  RunSummary run;
  long jacobian_updates = 0;
};

// Integrate `steps` steps of size h from (q, p) (updated in place) with the Galerkin
// method of `stages` stages and the given quadrature: the entry point for benchmark
// suites. Stage counts 1..6 dispatch to the fixed-size instantiations.
template <class System, int S>
GalerkinRunStats galerkin_run_fixed(const System& L, QuadratureKind kind, double h, std::int64_t steps,
                                    Vec<double, System::dim>& q, Vec<double, System::dim>& p,
                                    const StepOptions& opt) {
  const GalerkinStep<System, S> step(L, kind, S, h, opt);
  const Vec<double, System::dim> v0 = legendre_inverse(L, q, p);
  GalerkinRunStats out;
  out.run = integrate(step, 0.0, q, p, v0, steps, [](auto&&...) {});
  out.jacobian_updates = step.jacobian_updates();
  return out;
}

template <class System>
GalerkinRunStats galerkin_run(const System& L, int stages, QuadratureKind kind, double h, std::int64_t steps,
                              Vec<double, System::dim>& q, Vec<double, System::dim>& p, const StepOptions& opt = {}) {
  switch (stages) {
    case 1: return galerkin_run_fixed<System, 1>(L, kind, h, steps, q, p, opt);
    case 2: return galerkin_run_fixed<System, 2>(L, kind, h, steps, q, p, opt);
    case 3: return galerkin_run_fixed<System, 3>(L, kind, h, steps, q, p, opt);
    case 4: return galerkin_run_fixed<System, 4>(L, kind, h, steps, q, p, opt);
    case 5: return galerkin_run_fixed<System, 5>(L, kind, h, steps, q, p, opt);
    case 6: return galerkin_run_fixed<System, 6>(L, kind, h, steps, q, p, opt);
    default: throw std::invalid_argument("galerkin stages must be 1..6, got " + std::to_string(stages));
  }
}

}  // namespace dvm
