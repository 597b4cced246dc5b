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
// Forces. A generalized force F(t, q, v) (Force, e.g. WrittenForce; NoForce of
// solvers/newton.h: none) enters by the discrete Lagrange-d'Alembert principle with
// the same quadrature: the virtual work h sum_i b_i <F_i, delta x_i> at the nodes,
// F_i = F(t0 + c_i h, x_i, v_i), delta x_i = sum_j l_j(c_i) delta q_j, is g_i = L_q + F_i
// in the equations above (and in dp); in the Jacobian L_qq and L_qv become L_qq + F_q and
// L_qv + F_v where they differentiate g_i (not in the p_i terms). The step reports the
// force's work h sum_i b_i <F_i, v_i> (StepSummary::work), like dp at the last evaluation.
// A Lagrangian L(t, q, v) (mechanics/dynamic_system.h, has_time) is evaluated at the
// same node times t0 + c_i h.
//
// The solve, as GalerkinStep: the one driver (solvers/newton_driver.h) with
// Refresh::contracting, the Jacobian inverted once and reused across iterations and
// steps while the corrections contract fourfold, refreshed when they do not or when the
// iteration stalls on an old Jacobian; the residual's scale |p0| + |J| |X|, the
// increments those of a point of size |q0|. Starting guess of a
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
#include <Eigen/LU>
#include <array>
#include <cmath>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/quadrature.h"
#include "solvers/galerkin_step.h"
#include "solvers/newton.h"
#include "solvers/newton_driver.h"

namespace dvm {

template <class Sys, class Con, class Force>
class ConstrainedGalerkinStep;

template <class Sys, class Force = NoForce>
class DynamicGalerkinStep {
  static_assert(is_dynamic_system_v<Sys>, "DynamicGalerkinStep needs a run-time-sized system (dynamic_system.h)");

 public:
  static constexpr int N = Eigen::Dynamic;
  static constexpr int SMax = kGalerkinMaxStages;
  static constexpr int MMax = SMax + 1;
  using V = Eigen::VectorXd;
  static constexpr bool kForced = is_force_v<Force>;

  // force: the generalized force, required where Force is not NoForce (the step keeps
  // its own copy)
  DynamicGalerkinStep(Sys L, QuadratureKind kind, int stages, double h, StepOptions options = {},
                      std::shared_ptr<const Force> force = nullptr)
      : L_(std::move(L)), quad_(kind, check_stages(stages)), s_(stages), h_(h), options_(options), t_(quad_, s_) {
    if constexpr (kForced) {
      if (!force || force->dim() != L_.dim())
        throw std::invalid_argument("DynamicGalerkinStep: a forced step needs a force of the system's dimension");
      force_fn_.emplace(*force);
    }
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
    for (V* x : {&X_, &Xprev_, &Xext_, &R_, &delta_, &start_}) x->setZero(K);
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
    lu_.inv.setZero(K, K);
    lu_.lu.resize(K);
    if constexpr (kForced) {
      F_.setZero(n, m);
      Fcol_.setZero(n);
      Fq_.setZero(n, n);
      Fv_.setZero(n, n);
    }
  }

  double step_size() const { return h_; }
  int stages() const { return s_; }
  int order() const { return 2 * s_; }
  int dim() const { return L_.dim(); }
  const Quadrature& quadrature() const { return quad_; }
  const Sys& lagrangian() const { return L_; }
  long jacobian_updates() const { return jacobian_updates_; }
  double last_guess_error() const {
    return guess_measured_ ? (guess_.err1 - guess_.corr).template lpNorm<Eigen::Infinity>() : NAN;
  }
  double last_extrapolation_error() const {
    return guess_measured_ ? guess_.err1.template lpNorm<Eigen::Infinity>() : NAN;
  }
  void reset() const {
    have_prev_ = false;
    kept_.valid = false;
    guess_.forget();
    guess_measured_ = false;
  }
  // The force's control inputs (WrittenForce::controls()), 0 without a force.
  int controls() const {
    if constexpr (kForced) return force_fn_->controls();
    return 0;
  }

  // The derivative A = d(q1, p1)/d(q0, p0) (2n x 2n) of the step from (q0, p0) at time t0
  // whose increment was dq, by the implicit function theorem on the stage equations
  // R(X; q0, p0) = 0: with J = dR/dX (the Newton Jacobian) and, at the nodes,
  // G_q = dg_i/dx, G_v = dg_i/dv (g_i = L_q + F_i), L_vq = dp_i/dx,
  //   dR_j/dq0 = sum_i (h WA_ij G_q + WB_ij L_vq),   dR_j/dp0 = I for j = 0 (else 0),
  //   dX = -J^{-1} (dR/dq0 dq0 + dR/dp0 dp0),   dq1 = dq0 + dX_s,
  //   dp1 = dp0 + h sum_i b_i (G_q (dq0 + sum_k A_ik dX_k) + G_v sum_k (B_ik / h) dX_k).
  // The stage increments X are found again by a copy of the step (one step's solve, the
  // carried state of this one untouched). Without a force A is symplectic (the method
  // is variational). Returns false where the solve fails or J is singular. Allocates.
  bool derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A) const {
    return linearise(t0, q0, p0, dq, &A, nullptr);
  }
  // The derivative B = d(q1, p1)/du (2n x c) in the force's control inputs u (held over
  // the step): u enters through F_i, dR_j/du = sum_i h WA_ij F_u,i and
  // dp1 = h sum_i b_i (F_u,i du + G_q sum_k A_ik dX_k + G_v sum_k (B_ik / h) dX_k).
  template <class Fo = Force, std::enable_if_t<is_force_v<Fo>, int> = 0>
  bool control_derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& B) const {
    return linearise(t0, q0, p0, dq, nullptr, &B);
  }
  // A and, where B is not null, B from one differentiation: what derivative() and
  // control_derivative() give (B 2n x 0 without control inputs).
  bool derivatives(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    return linearise(t0, q0, p0, dq, &A, B);
  }

  // One step from (q0, p0); dq carries a guess of q1 - q0 on entry (used unless the
  // step continues the previous one), q1 - q0 on return; dp receives p1 - p0.
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    const int s = s_, n = L_.dim();
    t0_ = t;
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
    Equation eq{*this, q0, p0, dynamic_detail::inf_norm(p0), dynamic_detail::inf_norm(q0)};
    try {
      sum = newton_drive(eq, lu_, Refresh::contracting, options_, X_, R_, delta_, J_, kept_, start_);
    } catch (const std::domain_error& e) {  // L undefined at a node
      sum.fail(e.what());
      kept_.valid = false;
    }
    jacobian_updates_ += sum.jacobians;
    if (!sum.converged) return sum;
    dq = X_.segment((s - 1) * n, n);
    dp = force_;  // the force quadrature at the last evaluation (before the final correction)
    if constexpr (kForced) {
      double w = 0.0;
      for (int i = 0; i < quad_.points; ++i) w += bh_[i] * F_.col(i).dot(vs_.col(i));
      sum.work = w;
    }
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

 private:
  // the constrained step (solvers/constrained_galerkin_step.h) adds its terms to this
  // step's equations, at its nodes
  template <class, class, class>
  friend class ConstrainedGalerkinStep;

  static int check_stages(int s) { return check_galerkin_stages(s, 0); }
  // the time of quadrature node i in the step that started at t0_
  double node_time(int i) const { return node_time_at(t0_, i); }

  // R_ and force_ at X_, as GalerkinStep::residual_fast:
  //   x = q0 + X A, v = X B / h (n x m), R = h G WA + P WB (n x s), force = h G b,
  // in plain loops (Eigen's expressions of run-time size cost more than the arithmetic
  // at the small sizes that matter most).
  void residual(const V& q0, const V& p0, const V& x_in, V& r_out) const {
    const int s = s_, m = quad_.points, n = L_.dim();
    const double* X = x_in.data();
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
      if constexpr (has_time<Sys>::value) L_.set_time(node_time(i));
      L_.gradient(xs_.col(i), vs_.col(i), G_.col(i), P_.col(i));
      if constexpr (kForced) {
        force_fn_->value(node_time(i), xs_.col(i), vs_.col(i), Fcol_);
        F_.col(i) = Fcol_;
        G_.col(i) += Fcol_;
      }
    }
    double* R = r_out.data();
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

  // The step equation for the driver, as GalerkinStep's.
  struct Equation {
    using Vector = V;
    using Matrix = Eigen::MatrixXd;
    const DynamicGalerkinStep& step;
    const V& q0;
    const V& p0;
    double pscale, q0size;
    void residual(const Vector& x, Vector& r) const { step.residual(q0, p0, x, r); }
    double jacobian(const Vector& x, Vector& r, Matrix& J) const {
      const double Jmax = step.form_jacobian(q0, x, J);
      step.residual(q0, p0, x, r);
      return Jmax;
    }
    double scale(double xn, double Jmax) const { return pscale + Jmax * xn; }
    double offset() const { return q0size; }
  };

  // The Jacobian factored by DenseLU and kept as its inverse (applied as a sum of
  // columns at every iteration); singular where DenseLU finds it so or where its
  // reciprocal condition in the 1-norm, computed from the inverse, is not above 1e-13
  // (GalerkinStep's threshold on Eigen's estimate of the same number, which allocates
  // for run-time sizes).
  struct InverseLU {
    DenseLU lu;
    Eigen::MatrixXd inv;
    bool factor(const Eigen::MatrixXd& J, double Jmax) {
      if (!lu.factor(J, Jmax)) return false;
      lu.inverse(inv);
      double nJ = 0.0, nI = 0.0;
      for (Eigen::Index c = 0; c < J.cols(); ++c) {
        nJ = std::fmax(nJ, J.col(c).template lpNorm<1>());
        const double ci = inv.col(c).template lpNorm<1>();
        nI = std::isnan(ci) ? ci : std::fmax(nI, ci);
      }
      return 1.0 / (nJ * nI) > 1e-13;
    }
    void solve(const V& r, V& dx) const {
      const Eigen::Index K = r.size();
      double* d = dx.data();
      for (Eigen::Index i = 0; i < K; ++i) d[i] = 0.0;
      for (Eigen::Index k = 0; k < K; ++k) {
        const double rk = r[k];
        const double* c = inv.col(k).data();
        for (Eigen::Index i = 0; i < K; ++i) d[i] += c[i] * rk;
      }
    }
    const char* name() const { return "LU with reciprocal condition above 1e-13"; }
  };

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

  // The Jacobian dR/dX at the nodes of the increments X into J; returns max|J_ij|
  // (not finite where an entry is not).
  double form_jacobian(const V& q0, const V& X, Eigen::MatrixXd& J) const {
    const int s = s_, n = L_.dim();
    J.setZero();
    const double inv_h = 1.0 / h_;
    for (int i = 0; i < quad_.points; ++i) {
      // the node as GalerkinStep::node: x = q0 + sum_j A_ij X_j, v = (sum_j B_ij X_j) / h
      x_ = q0;
      v_.setZero();
      for (int j = 1; j <= s; ++j) {
        x_ += t_.A[i][j] * X.segment((j - 1) * n, n);
        v_ += t_.B[i][j] * X.segment((j - 1) * n, n);
      }
      v_ *= inv_h;
      if constexpr (has_time<Sys>::value) L_.set_time(node_time(i));
      L_.hessian(x_, v_, Lq_, Lv_, Lqq_, Lqv_, Lvv_);
      if constexpr (kForced) {  // g_i = L_q + F_i: F_q, F_v join the derivatives of g_i only
        force_fn_->jacobian(node_time(i), x_, v_, Fcol_, Fq_, Fv_);
        Fq_ += Lqq_;
        Fv_ += Lqv_;
      }
      const Eigen::MatrixXd& Gq = kForced ? Fq_ : Lqq_;  // dg_i/dx, dg_i/dv
      const Eigen::MatrixXd& Gv = kForced ? Fv_ : Lqv_;
      for (int k = 1; k <= s; ++k) {
        // d(h g_i)/dX_k and d(p_i)/dX_k
        dg_ = h_ * (t_.A[i][k] * Gq + (t_.B[i][k] / h_) * Gv);
        dpk_ = t_.A[i][k] * Lqv_.transpose() + (t_.B[i][k] / h_) * Lvv_;
        for (int j = 0; j < s; ++j) J.block(j * n, (k - 1) * n, n, n) += t_.WA[i][j] * dg_ + t_.WB[i][j] * dpk_;
      }
    }
    return max_abs(J);
  }

  // derivative() and control_derivative(): A and/or B at the step from (q0, p0).
  bool linearise(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd* A, Eigen::MatrixXd* B) const {
    using Mat = Eigen::MatrixXd;
    const int s = s_, m = quad_.points, n = L_.dim(), K = s * n;
    if (q0.size() != n || p0.size() != n || dq.size() != n)
      throw std::invalid_argument("DynamicGalerkinStep::derivative: a state of " + std::to_string(q0.size()) +
                                  " coordinates; the system has " + std::to_string(n));
    DynamicGalerkinStep solve = *this;  // the stage increments X of this step, found again
    solve.reset();
    V d = dq, e(n);
    if (!solve.step(t0, q0, p0, d, e).converged) return false;
    const V X = solve.X_;
    const int c = controls();
    Mat J(K, K), Rq = Mat::Zero(K, n), Rp = Mat::Zero(K, n), Ru = Mat::Zero(K, c);
    solve.form_jacobian(q0, X, J);
    Rp.topRows(n).setIdentity();
    // per node: G_q, G_v, and with a force F_u
    std::vector<Mat> Gq(static_cast<std::size_t>(m)), Gv(static_cast<std::size_t>(m)), Fu(static_cast<std::size_t>(m));
    V x(n), v(n), Lq(n), Lv(n), F(n);
    Mat Lqq(n, n), Lqv(n, n), Lvv(n, n), Fq(n, n), Fv(n, n);
    for (int i = 0; i < m; ++i) {
      const auto k = static_cast<std::size_t>(i);
      x = q0;
      v.setZero();
      for (int j = 1; j <= s; ++j) {
        x += t_.A[i][j] * X.segment((j - 1) * n, n);
        v += (t_.B[i][j] / h_) * X.segment((j - 1) * n, n);
      }
      if constexpr (has_time<Sys>::value) solve.L_.set_time(node_time_at(t0, i));
      solve.L_.hessian(x, v, Lq, Lv, Lqq, Lqv, Lvv);
      Gq[k] = Lqq;
      Gv[k] = Lqv;
      if constexpr (kForced) {
        solve.force_fn_->jacobian(node_time_at(t0, i), x, v, F, Fq, Fv, c > 0 ? &Fu[k] : nullptr);
        Gq[k] += Fq;
        Gv[k] += Fv;
      }
      for (int j = 0; j < s; ++j) {
        Rq.middleRows(j * n, n) += (h_ * t_.WA[i][j]) * Gq[k] + t_.WB[i][j] * Lqv.transpose();
        if (c > 0) Ru.middleRows(j * n, n) += (h_ * t_.WA[i][j]) * Fu[k];
      }
    }
    const Eigen::FullPivLU<Mat> lu(J);
    if (!lu.isInvertible()) return false;
    // dp1 from the stage derivatives dX (K x cols) and the direct terms
    auto momentum = [&](const Mat& dX, Mat direct) {
      for (int i = 0; i < m; ++i) {
        const auto k = static_cast<std::size_t>(i);
        Mat dx = Mat::Zero(n, dX.cols()), dv = Mat::Zero(n, dX.cols());
        for (int j = 1; j <= s; ++j) {
          dx += t_.A[i][j] * dX.middleRows((j - 1) * n, n);
          dv += (t_.B[i][j] / h_) * dX.middleRows((j - 1) * n, n);
        }
        direct += bh_[i] * (Gq[k] * dx + Gv[k] * dv);
      }
      return direct;
    };
    if (A) {
      const Mat dXq = -lu.solve(Rq), dXp = -lu.solve(Rp);
      Mat direct_q = Mat::Zero(n, n);
      for (int i = 0; i < m; ++i) direct_q += bh_[i] * Gq[static_cast<std::size_t>(i)];
      A->resize(2 * n, 2 * n);
      A->topLeftCorner(n, n) = Mat::Identity(n, n) + dXq.bottomRows(n);
      A->topRightCorner(n, n) = dXp.bottomRows(n);
      A->bottomLeftCorner(n, n) = momentum(dXq, direct_q);
      A->bottomRightCorner(n, n) = momentum(dXp, Mat::Identity(n, n));
      if (!A->allFinite()) return false;
    }
    if (B) {
      const Mat dXu = -lu.solve(Ru);
      Mat direct_u = Mat::Zero(n, c);
      for (int i = 0; i < m && c > 0; ++i) direct_u += bh_[i] * Fu[static_cast<std::size_t>(i)];
      B->resize(2 * n, c);
      B->topRows(n) = dXu.bottomRows(n);
      B->bottomRows(n) = momentum(dXu, direct_u);
      if (!B->allFinite()) return false;
    }
    return true;
  }
  double node_time_at(double t0, int i) const { return t0 + static_cast<double>(quad_.c[static_cast<std::size_t>(i)]) * h_; }

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
  mutable V X_, Xprev_, R_, delta_, Xext_, start_;
  mutable ExtrapolationErrors<V> guess_;
  mutable bool guess_measured_ = false;
  mutable V q_end_, force_, Lq_, Lv_, x_, v_;
  mutable Eigen::MatrixXd xs_, vs_, G_, P_, Lqq_, Lqv_, Lvv_, dg_, dpk_, J_;
  mutable InverseLU lu_;
  mutable DriverState kept_;  // whether lu_ holds a Jacobian kept across steps
  mutable bool have_prev_ = false;
  mutable long jacobian_updates_ = 0;
  // the force (a copy of the caller's: its workspace), its values at the nodes (n x m),
  // and the start of the current step
  mutable std::optional<Force> force_fn_;
  mutable Eigen::MatrixXd F_, Fq_, Fv_;
  mutable V Fcol_;
  mutable double t0_ = 0.0;
};

}  // namespace dvm
