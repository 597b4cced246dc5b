// The Galerkin discrete Lagrangian step of solvers/galerkin_step.h for run-time-sized
// systems (mechanics/dynamic_system.h): the same method, equations, starting guess and
// solver, with n (and the stage count s = 1..6) chosen at run time and the Jacobian
// assembled from the Hessian blocks the system provides.
//
// The method (Marsden and West, "Discrete mechanics and variational integrators", Acta
// Numerica 2001, Sec. 2.2.6 and Thm 2.6.1; Hairer, Lubich, Wanner, Geometric Numerical
// Integration, VI.6.3): with the Lagrange basis l_j of degree s on d_j = j / s, a
// quadrature (c_i, b_i), i = 1..m (Gauss m = s, Lobatto m = s + 1), and the increments
// X_j = q_j - q0, j = 1..s, the nodes are
//   x_i = q0 + sum_j l_j(c_i) X_j,   v_i = (1/h) sum_j l_j'(c_i) X_j,
// and with g_i = L_q(x_i, v_i), p_i = L_v(x_i, v_i) the s n equations
//   R_j = sum_i b_i (h l_j(c_i) g_i + l_j'(c_i) p_i) (+ p0 for j = 0) = 0,  j = 0..s-1,
// determine X; then dq = X_s and dp = h sum_i b_i g_i (the force quadrature, added
// without cancellation). Order 2s for both quadratures.
//
// The Jacobian. Block (j, k) of dR/dX, from L_qq, L_qv, L_vv at the m nodes:
//   sum_i [ b_i l_j(c_i) h (l_k(c_i) L_qq + (l_k'(c_i)/h) L_qv)
//         + b_i l_j'(c_i)   (l_k(c_i) L_qv^T + (l_k'(c_i)/h) L_vv) ],
// what GalerkinStep obtains by differentiating L_q and L_v with Jets.
//
// The solve, as GalerkinStep: simplified Newton with the Jacobian inverted once and
// reused across iterations and steps while the corrections contract (ratio below
// `contraction`, default 0.25), refreshed when they do not or when the iteration stalls
// on an old Jacobian; stopping rule newton_verdict with scale |p0| + |J| |X| and stall
// size |X| + |q0|; the correction of the accepted residual applied. Starting guess of a
// step that continues the previous one: the previous polynomial extrapolated, E X_prev,
// plus the extrapolated errors of the last two extrapolations, 2 d_n - d_{n-1} (see
// galerkin_step.h); otherwise X_j = (j/s) dq from the caller's guess.
//
// The Jacobian is factored by DenseLU (core/dense_solve.h) and inverted; it is
// refused as singular when a pivot is not above 1e-14 max|J| or when its reciprocal
// condition in the 1-norm, computed from the inverse, is not above 1e-13 (GalerkinStep's
// threshold on Eigen's estimate of the same number). Only Newton's method is offered:
// StepOptions::solver = tiny is refused at construction.
//
// The coefficient tables are computed here as galerkin_step.h computes them (GalerkinStep
// keeps them private). Workspace is allocated at construction; a step, including a
// refresh of the Jacobian, allocates nothing (tests/solvers/test_dynamic.cc). The step
// keeps the previous polynomial and the inverted Jacobian in mutable members: one object
// must not be shared between threads.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "mechanics/dynamic_system.h"
#include "mechanics/quadrature.h"
#include "solvers/galerkin_step.h"
#include "solvers/newton.h"

namespace dvm {

template <class Sys>
class DynamicGalerkinStep {
  static_assert(is_dynamic_system_v<Sys>, "DynamicGalerkinStep needs a run-time-sized system (dynamic_system.h)");

 public:
  static constexpr int N = Eigen::Dynamic;
  static constexpr int SMax = kGalerkinMaxStages;
  static constexpr int MMax = SMax + 1;
  using V = Eigen::VectorXd;

  DynamicGalerkinStep(Sys L, QuadratureKind kind, int stages, double h, StepOptions options = {})
      : L_(std::move(L)), quad_(kind, check_stages(stages)), s_(stages), h_(h), options_(options), t_(quad_, s_) {
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
    if (options.solver != SolverKind::newton)
      throw std::invalid_argument("run-time-sized steps solve by Newton's method only (solver = \"newton\")");
    const int s = s_, m = quad_.points, n = L_.dim();
    for (int i = 0; i < m; ++i) {
      bh_[i] = h_ * t_.b[i];
      for (int j = 1; j <= s; ++j) {
        Af_[j - 1][i] = t_.A[i][j];
        Bf_[j - 1][i] = t_.B[i][j] / h_;
      }
      for (int j = 0; j < s; ++j) WAf_[i][j] = h_ * t_.WA[i][j];
    }
    const int K = s * n;
    for (V* x : {&X_, &Xprev_, &Xext_, &R_, &delta_}) x->setZero(K);
    guess_.zero_like(X_);
    q_end_.setZero(n);
    force_.setZero(n);
    xs_.setZero(n, m);
    vs_.setZero(n, m);
    G_.setZero(n, m);
    P_.setZero(n, m);
    Lq_.setZero(n);
    Lv_.setZero(n);
    x_.setZero(n);
    v_.setZero(n);
    Lqq_.setZero(n, n);
    Lqv_.setZero(n, n);
    Lvv_.setZero(n, n);
    dg_.setZero(n, n);
    dpk_.setZero(n, n);
    J_.setZero(K, K);
    Jinv_.setZero(K, K);
    lu_.resize(K);
  }

  double step_size() const { return h_; }
  int stages() const { return s_; }
  int order() const { return 2 * s_; }
  int dim() const { return L_.dim(); }
  const Quadrature& quadrature() const { return quad_; }
  const Sys& lagrangian() const { return L_; }
  long jacobian_updates() const { return jacobian_updates_; }
  void set_contraction(double c) { contraction_ = c; }
  double last_guess_error() const {
    return guess_measured_ ? (guess_.err1 - guess_.corr).template lpNorm<Eigen::Infinity>() : NAN;
  }
  double last_extrapolation_error() const {
    return guess_measured_ ? guess_.err1.template lpNorm<Eigen::Infinity>() : NAN;
  }
  void reset() const {
    have_prev_ = false;
    lu_valid_ = false;
    guess_.forget();
    guess_measured_ = false;
  }

  // One step from (q0, p0); dq carries a guess of q1 - q0 on entry (used unless the
  // step continues the previous one), q1 - q0 on return; dp receives p1 - p0.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    const int s = s_, n = L_.dim();
    StepSummary sum;
    if (q0.size() != n || p0.size() != n || dq.size() != n) {
      sum.message = "the state has " + std::to_string(q0.size()) + " coordinates; the system has " +
                    std::to_string(n);
      return sum;
    }
    if (dp.size() != n) dp.resize(n);
    guess_measured_ = false;
    double gap = 0.0;
    for (int a = 0; a < n; ++a) gap = std::fmax(gap, std::fabs(q0[a] - q_end_[a]));
    const bool continues = have_prev_ && gap <= 1e-12 * (max_abs(q0) + max_abs(dq)) + 1e-300;
    if (continues) {
      extrapolate();
      X_ = Xext_ + guess_.correction();
    } else {
      for (int j = 1; j <= s; ++j) X_.segment((j - 1) * n, n) = (static_cast<double>(j) / s) * dq;
      guess_.forget();
    }
    have_prev_ = false;
    bool fresh = false;
    try {
      if (!lu_valid_) {
        refresh(q0);
        ++sum.jacobians;
        fresh = true;
      }
      double dxn = INFINITY;
      const double pscale = dynamic_detail::inf_norm(p0), q0size = dynamic_detail::inf_norm(q0);
      for (int it = 0; it < options_.max_iterations; ++it) {
        residual(q0, p0);
        sum.iterations = it + 1;
        sum.residual = dynamic_detail::inf_norm(R_);
        const double xn = dynamic_detail::inf_norm(X_);
        sum.scale = pscale + Jmax_ * xn + options_.absolute_floor;
        if (!std::isfinite(sum.residual)) {
          sum.message = "non-finite residual";
          return sum;
        }
        const NewtonVerdict verdict = newton_verdict(sum, dxn, xn + q0size, options_);
        apply_inverse();  // delta_ = J^{-1} R
        if (verdict == NewtonVerdict::converged) {
          X_ -= delta_;
          dq = X_.segment((s - 1) * n, n);
          dp = force_;
          if (!std::isfinite(max_abs(dq)) || !std::isfinite(max_abs(dp))) {
            sum.converged = false;
            sum.message = "non-finite step";
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
        if (verdict == NewtonVerdict::failed) {
          if (fresh) return sum;
          sum.message.clear();  // stalled on an old Jacobian: refresh and go on
          refresh(q0);
          ++sum.jacobians;
          fresh = true;
          dxn = INFINITY;
          continue;
        }
        X_ -= delta_;
        const double nd = dynamic_detail::inf_norm(delta_);
        if (!std::isfinite(nd)) {
          sum.message = "singular Galerkin step Jacobian";
          lu_valid_ = false;
          return sum;
        }
        if (it >= 1 && nd > contraction_ * dxn && !fresh) {
          refresh(q0);
          ++sum.jacobians;
          fresh = true;
          dxn = INFINITY;
          continue;
        }
        dxn = nd;
      }
      sum.message = "no convergence within " + std::to_string(options_.max_iterations) + " iterations";
    } catch (const std::domain_error& e) {
      sum.message = e.what();
    }
    lu_valid_ = false;
    return sum;
  }

 private:
  static int check_stages(int s) { return check_galerkin_stages(s, 0); }

  // R_ and force_ at X_, as GalerkinStep::residual_fast:
  //   x = q0 + X A, v = X B / h (n x m), R = h G WA + P WB (n x s), force = h G b,
  // in plain loops (Eigen's expressions of run-time size cost more than the arithmetic
  // at the small sizes that matter most).
  void residual(const V& q0, const V& p0) const {
    const int s = s_, m = quad_.points, n = L_.dim();
    const double* X = X_.data();
    for (int i = 0; i < m; ++i) {
      double* x = xs_.col(i).data();
      double* v = vs_.col(i).data();
      for (int a = 0; a < n; ++a) {
        x[a] = Af_[0][i] * X[a];
        v[a] = Bf_[0][i] * X[a];
      }
      for (int j = 1; j < s; ++j) {
        const double* Xj = X + j * n;
        const double af = Af_[j][i], bf = Bf_[j][i];
        for (int a = 0; a < n; ++a) {
          x[a] += af * Xj[a];
          v[a] += bf * Xj[a];
        }
      }
      for (int a = 0; a < n; ++a) x[a] += q0[a];
      L_.gradient(xs_.col(i), vs_.col(i), G_.col(i), P_.col(i));
    }
    double* R = R_.data();
    for (int j = 0; j < s; ++j) {
      double* r = R + j * n;
      for (int a = 0; a < n; ++a) r[a] = WAf_[0][j] * G_(a, 0);
      for (int i = 1; i < m; ++i)
        for (int a = 0; a < n; ++a) r[a] += WAf_[i][j] * G_(a, i);
      for (int i = 0; i < m; ++i)
        for (int a = 0; a < n; ++a) r[a] += t_.WB[i][j] * P_(a, i);
    }
    for (int a = 0; a < n; ++a) {
      R[a] += p0[a];
      double f = bh_[0] * G_(a, 0);
      for (int i = 1; i < m; ++i) f += bh_[i] * G_(a, i);
      force_[a] = f;
    }
  }

  // delta_ = Jinv_ R_, as a sum of columns (GalerkinStep::apply_inverse).
  void apply_inverse() const {
    const Eigen::Index K = R_.size();
    double* d = delta_.data();
    for (Eigen::Index i = 0; i < K; ++i) d[i] = 0.0;
    for (Eigen::Index k = 0; k < K; ++k) {
      const double r = R_[k];
      const double* c = Jinv_.col(k).data();
      for (Eigen::Index i = 0; i < K; ++i) d[i] += c[i] * r;
    }
  }

  // Xext_ = E Xprev_: the previous polynomial at this step's control points.
  void extrapolate() const {
    const int s = s_, n = L_.dim();
    for (int j = 1; j <= s; ++j) {
      double* a = Xext_.data() + (j - 1) * n;
      for (int c = 0; c < n; ++c) a[c] = 0.0;
      for (int k = 1; k <= s; ++k) {
        const double e = t_.E[j][k];
        const double* x = Xprev_.data() + (k - 1) * n;
        for (int c = 0; c < n; ++c) a[c] += e * x[c];
      }
    }
  }

  // The Jacobian dR/dX at the current nodes X_, inverted.
  void refresh(const V& q0) const {
    const int s = s_, n = L_.dim();
    J_.setZero();
    const double inv_h = 1.0 / h_;
    for (int i = 0; i < quad_.points; ++i) {
      // the node as GalerkinStep::node: x = q0 + sum_j A_ij X_j, v = (sum_j B_ij X_j) / h
      x_ = q0;
      v_.setZero();
      for (int j = 1; j <= s; ++j) {
        x_ += t_.A[i][j] * X_.segment((j - 1) * n, n);
        v_ += t_.B[i][j] * X_.segment((j - 1) * n, n);
      }
      v_ *= inv_h;
      L_.hessian(x_, v_, Lq_, Lv_, Lqq_, Lqv_, Lvv_);
      for (int k = 1; k <= s; ++k) {
        // d(h g_i)/dX_k and d(p_i)/dX_k
        dg_ = h_ * (t_.A[i][k] * Lqq_ + (t_.B[i][k] / h_) * Lqv_);
        dpk_ = t_.A[i][k] * Lqv_.transpose() + (t_.B[i][k] / h_) * Lvv_;
        for (int j = 0; j < s; ++j) J_.block(j * n, (k - 1) * n, n, n) += t_.WA[i][j] * dg_ + t_.WB[i][j] * dpk_;
      }
    }
    if (!std::isfinite(J_.template lpNorm<Eigen::Infinity>())) throw std::domain_error("non-finite Galerkin Jacobian");
    Jmax_ = J_.cwiseAbs().maxCoeff();
    if (!lu_.factor(J_)) throw std::domain_error("singular Galerkin step Jacobian");
    lu_.inverse(Jinv_);
    // the reciprocal condition in the 1-norm, from the inverse (GalerkinStep asks
    // Eigen's LU for its estimate of the same number, which allocates for run-time sizes)
    double nJ = 0.0, nI = 0.0;
    for (Eigen::Index c = 0; c < J_.cols(); ++c) {
      nJ = std::fmax(nJ, J_.col(c).template lpNorm<1>());
      const double ci = Jinv_.col(c).template lpNorm<1>();
      nI = std::isnan(ci) ? ci : std::fmax(nI, ci);
    }
    const double rcond = 1.0 / (nJ * nI);
    if (!(rcond > 1e-13)) throw std::domain_error("singular Galerkin step Jacobian");
    lu_valid_ = true;
    ++jacobian_updates_;
  }

  Sys L_;
  Quadrature quad_;
  int s_;
  double h_;
  StepOptions options_;
  GalerkinTables<SMax> t_;
  std::array<double, MMax> bh_{};
  std::array<std::array<double, SMax + 1>, MMax> WAf_{};
  std::array<std::array<double, MMax>, SMax> Af_{}, Bf_{};
  // workspace and the state carried from step to step (as GalerkinStep)
  mutable V X_, Xprev_, R_, delta_, Xext_;
  mutable ExtrapolationErrors<V> guess_;
  mutable bool guess_measured_ = false;
  mutable V q_end_, force_, Lq_, Lv_, x_, v_;
  mutable Eigen::MatrixXd xs_, vs_, G_, P_, Lqq_, Lqv_, Lvv_, dg_, dpk_, J_, Jinv_;
  mutable DenseLU lu_;
  double contraction_ = 0.25;
  mutable double Jmax_ = 0.0;
  mutable bool lu_valid_ = false, have_prev_ = false;
  mutable long jacobian_updates_ = 0;
};

}  // namespace dvm
