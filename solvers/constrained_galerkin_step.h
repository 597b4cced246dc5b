// The Galerkin discrete Lagrangian (solvers/dynamic_galerkin_step.h) under holonomic
// constraints g(t, q) = 0 (m of them, mechanics/written_constraints.h), with Lobatto
// quadrature: the constraints hold at every quadrature node.
//
// The discrete Lagrangian is extremised over the polynomials of degree s that keep the
// constraints at the m + 1 = s + 1 Lobatto nodes c_0 = 0 < c_1 < ... < c_s = 1 (Marsden
// and West, Acta Numerica 2001, Sec. 3.5: the augmented Lagrangian L - lambda . g,
// discretised by the same quadrature as L). With the notation of
// dynamic_galerkin_step.h (x_i, v_i the nodes, g_i = L_q + F_i, p_i = L_v, WA_ij =
// b_i l_j(c_i), WB_ij = b_i l_j'(c_i)), and G_i = Dg(t0 + c_i h, x_i), the unknowns are
// the increments X_1..X_s and the multipliers lambda_0..lambda_{s-1}, and the
// s (n + m) equations
//   R_j = sum_i [h WA_ij (g_i - G_i^T lambda_i) + WB_ij p_i] (+ p0 for j = 0) = 0,  j = 0..s-1,
//   g(t0 + c_i h, x_i) = 0,                                                   i = 1..s,
// (lambda_s = 0 in R_j; l_j(c_0) = 0 for j > 0, so lambda_0 enters R_0 only: it is the
// left constrained Legendre transform's multiplier, p0 - h b_0 G_0^T lambda_0 =
// -D1 L_d). Then q1 = x_s and
//   p1~ = p0 + h sum_{i=0..s} b_i g_i - h sum_{i=0..s-1} b_i G_i^T lambda_i,
// and the right transform puts p1 = p1~ - G_s^T mu on the hidden constraint, as
// ConstrainedThetaStep's equation 2 (constrained_detail::Projection; the multiplier
// of the last node is mu). This is the variational form of the Lobatto IIIA-IIIB pair
// for constrained systems (Jay, SIAM J. Numer. Anal. 33, 1996), which keeps the
// method's order 2s (s + 1 Lobatto nodes) on the positions and the momenta; the step is
// symplectic on the constraint's cotangent bundle. Gauss quadrature has no nodes at the
// ends of the step, where the step's state must lie on the constraint: the runtime
// refuses it with constraints.
//
// The solve: the one driver (solvers/newton_driver.h), a Jacobian formed at each step's
// first iterate and kept while each iteration shrinks the residual fourfold
// (Refresh::within_step; kept across steps, as the unconstrained Galerkin steps keep
// theirs, its constraint rows and the multipliers' curvature age with the state and the
// iteration slows to the fourfold limit), on the saddle-point Jacobian
//   [ dR/dX           -sc h WA_ij G_i^T ]
//   [ sr G_i A_ik      0                ]
// where dR/dX is the unconstrained stage Jacobian plus the multipliers' curvature
// -h WA_ij A_ik lambda_i . Hess g(x_i) at the interior nodes (without it the iteration
// contracts only by a factor of order h^2 lambda / m per iteration). The constraint
// rows are scaled by sr = max|dR/dX| / max|G_0| and the multipliers carried as
// lambda / sc, sc = sr / max|h WA_ij|, so that the rows and the columns of the
// constraints are of the size of the others (the driver's one stopping rule judges
// all the unknowns and residuals alike); both are set at the first Jacobian and kept
// (so that the last step's multipliers are the next one's guess). The increments' guess
// is the previous polynomial extrapolated, as unconstrained.
//
// derivative() and control_derivative() give the step's Jacobians by the implicit
// function theorem (dvm run --linearize). Workspace is allocated
// at construction; forming a Jacobian allocates (the constraints' Hessians,
// WrittenConstraints::second_derivatives), the iterations and steps that keep one do
// not. One object must not be used from two threads at once.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "solvers/constrained_step.h"
#include "solvers/dynamic_galerkin_step.h"

namespace dvm {

namespace constrained_detail {
// A value on the heap that each copy of its owner copies (the constraints' and the
// projection's workspaces: one per step object).
template <class T>
struct Owned {
  std::unique_ptr<T> p;
  Owned() = default;
  explicit Owned(std::unique_ptr<T> q) : p(std::move(q)) {}
  Owned(const Owned& o) : p(o.p ? std::make_unique<T>(*o.p) : nullptr) {}
  Owned(Owned&&) noexcept = default;
  Owned& operator=(const Owned&) = delete;
  Owned& operator=(Owned&&) noexcept = default;
  T& operator*() const { return *p; }
  T* operator->() const { return p.get(); }
};
}  // namespace constrained_detail

template <class Sys, class Con, class Force>
class ConstrainedGalerkinStep {
 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;
  using Inner = DynamicGalerkinStep<Sys, Force>;
  static constexpr bool kForced = is_force_v<Force>;

  // stages: the polynomial degree s (order 2s); momentum: how L_v depends on v, as for
  // ConstrainedThetaStep. The step keeps its own copies of the constraints and the force.
  ConstrainedGalerkinStep(Sys L, int stages, double h, std::shared_ptr<const Con> constraints,
                          StepOptions options = {}, MomentumMap momentum = MomentumMap::general,
                          std::shared_ptr<const Force> force = nullptr)
      : g_(std::move(L), QuadratureKind::lobatto, stages, h, options, force), momentum_(momentum) {
    const int n = g_.dim();
    if (!constraints || constraints->dim() != n)
      throw std::invalid_argument("ConstrainedGalerkinStep: constraints on the system's coordinates are needed");
    if (constraints->count() >= n)
      throw std::invalid_argument("ConstrainedGalerkinStep: " + std::to_string(constraints->count()) +
                                  " constraints on " + std::to_string(n) + " coordinates leave no motion");
    con_ = constrained_detail::Owned<Con>(std::make_unique<Con>(*constraints));
    const int s = g_.s_, m = con_->count(), K = s * (n + m);
    if (g_.quad_.points != s + 1 || g_.quad_.c[0] != 0.0L || g_.quad_.c[static_cast<std::size_t>(s)] != 1.0L)
      throw std::invalid_argument("ConstrainedGalerkinStep: Lobatto nodes from 0 to 1 expected");
    for (V* x : {&y_, &r_, &dx_, &start_, &yprev_}) x->setZero(K);
    X_.setZero(s * n);
    RX_.setZero(s * n);
    JX_.setZero(s * n, s * n);
    J_.setZero(K, K);
    lu_.inv.setZero(K, K);
    lu_.lu.resize(K);
    Gs_.assign(static_cast<std::size_t>(s + 1), Eigen::MatrixXd::Zero(m, n));
    gval_.setZero(m);
    gt_.setZero(m);
    q_end_.setZero(n);
    xi_.setZero(n);
    Hl_.setZero(n, n);
    p1_.setZero(n);
    v1_.setZero(n);
    proj_ = constrained_detail::Owned<constrained_detail::Projection<Sys, Con>>(
        std::make_unique<constrained_detail::Projection<Sys, Con>>(n, m));
  }
  ConstrainedGalerkinStep(const ConstrainedGalerkinStep&) = default;
  ConstrainedGalerkinStep(ConstrainedGalerkinStep&&) noexcept = default;
  ConstrainedGalerkinStep& operator=(const ConstrainedGalerkinStep&) = delete;

  double step_size() const { return g_.h_; }
  int stages() const { return g_.s_; }
  int order() const { return 2 * g_.s_; }
  int dim() const { return g_.dim(); }
  const Sys& lagrangian() const { return g_.lagrangian(); }
  void reset() const {
    have_prev_ = false;
    kept_.valid = false;
    g_.reset();
  }

  // The force's control inputs (WrittenForce::controls()), 0 without a force.
  int controls() const { return g_.controls(); }

  // The derivative A = d(q1, p1)/d(q0, p0) (2n x 2n) of the step from (q0, p0) at time t0
  // whose increment was dq, by the implicit function theorem (no finite differences):
  // on the stage equations with their multipliers and constraint rows, F(Y; q0, p0) = 0
  // for Y = (X, lambda / sc), dY = -J^{-1} dF/d(q0, p0) with J the saddle-point Jacobian
  // above (exact: the multipliers' curvature included), where at fixed Y
  //   dR_j/dq0 = sum_i [h WA_ij (G_q,i - lambda_i . Hess g(x_i)) + WB_ij L_vq,i],
  //   dR_0/dp0 = I,   d(sr g(x_i))/dq0 = sr G_i,
  // (the curvature at node 0 too, whose G_0 = Dg(q0) moves with q0); then
  //   dq1 = dq0 + dX_s,
  //   dp1~ = dp0 + sum_i h b_i [(G_q,i - lambda_i . Hess g(x_i)) dx_i + G_v,i dv_i]
  //          - sum_{i<s} h b_i G_i^T dlambda_i,
  // dx_i = dq0 + sum_k A_ik dX_k, dv_i = sum_k (B_ik / h) dX_k, and the right transform's
  // derivative as ConstrainedThetaStep's (constrained_detail::right_transform_derivative).
  // The stage increments and multipliers are found again by a copy of the step (this
  // step's carried state untouched). Without forces A is symplectic on the constraint's
  // cotangent bundle. False where a solve fails or a matrix is singular. Allocates.
  bool derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A) const {
    return linearise(t0, q0, p0, dq, &A, nullptr);
  }
  // The derivative B = d(q1, p1)/du (2n x c) in the force's control inputs u (held over
  // the step): u enters through F_i, dR_j/du = sum_i h WA_ij F_u,i, and dp1~ gains
  // h sum_i b_i F_u,i du.
  template <class Fo = Force, std::enable_if_t<is_force_v<Fo>, int> = 0>
  bool control_derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& B) const {
    return linearise(t0, q0, p0, dq, nullptr, &B);
  }
  // A and, where B is not null, B from one differentiation: what derivative() and
  // control_derivative() give (B 2n x 0 without control inputs).
  bool derivatives(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    return linearise(t0, q0, p0, dq, &A, B);
  }

  // One step from (q0, p0) at time t; dq carries a guess of q1 - q0 on entry (used
  // unless the step continues the previous one), q1 - q0 on return; dp receives p1 - p0.
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    const int s = g_.s_, n = g_.dim(), m = con_->count();
    StepSummary sum;
    if (!dynamic_detail::sizes_match(n, q0, p0, dq, sum)) return sum;
    if (dp.size() != n) dp.resize(n);
    g_.t0_ = t;
    double gap = 0.0;
    for (int a = 0; a < n; ++a) gap = std::fmax(gap, std::fabs(q0[a] - q_end_[a]));
    const bool continues = have_prev_ && gap <= 1e-12 * (max_abs(q0) + max_abs(dq)) + 1e-300;
    if (continues) {
      g_.Xprev_ = yprev_.head(s * n);
      g_.extrapolate();
      y_.head(s * n) = g_.Xext_;
      y_.tail(s * m) = yprev_.tail(s * m);
    } else {
      for (int j = 1; j <= s; ++j) y_.segment((j - 1) * n, n) = (static_cast<double>(j) / s) * dq;
      y_.tail(s * m).setZero();
    }
    have_prev_ = false;
    try {
      con_->gradients(t, q0, Gs_[0], gt_);  // G_0 at the step's start (it depends on no unknown)
      Equation eq{*this, q0, p0, dynamic_detail::inf_norm(p0), dynamic_detail::inf_norm(q0)};
      sum = newton_drive(eq, lu_, Refresh::within_step, g_.options_, y_, r_, dx_, J_, kept_, start_);
    } catch (const std::domain_error& e) {  // L or g undefined at a node
      sum.fail(e.what());
      kept_.valid = false;
    }
    if (!sum.converged) return sum;
    // q1 and p1~ (the node sums of the last evaluation, the multipliers of the solution)
    for (int a = 0; a < n; ++a) dq[a] = y_[(s - 1) * n + a];
    momentum_before_projection(p0, y_, p1_);
    if constexpr (kForced) {
      double w = 0.0;
      for (int i = 0; i < g_.quad_.points; ++i) w += g_.bh_[i] * g_.F_.col(i).dot(g_.vs_.col(i));
      sum.work = w;
    }
    // the right transform at q1: p1 on the hidden constraint (v1's guess: the last node's velocity)
    q_end_ = q0 + dq;
    v1_ = g_.vs_.col(s);
    const char* failed = "";
    try {
      failed = (*proj_)(g_.L_, *con_, t + g_.h_, q_end_, p1_, v1_, momentum_);
    } catch (const std::domain_error& e) {
      sum.fail(e.what());
      return sum;
    }
    if (*failed) {
      sum.fail(failed);
      return sum;
    }
    dp = p1_ - p0;
    if (!std::isfinite(max_abs(dq)) || !std::isfinite(max_abs(dp))) {
      sum.fail("non-finite step");
      kept_.valid = false;
      return sum;
    }
    yprev_ = y_;
    have_prev_ = true;
    return sum;
  }

 private:
  // p1~ = p0 + h sum_i b_i g_i - h sum_{i<s} b_i G_i^T lambda_i (header comment): the node
  // sums and G_i of the last evaluation, the multipliers of y.
  void momentum_before_projection(const V& p0, const V& y, V& p1) const {
    const int s = g_.s_, n = g_.dim(), m = con_->count();
    p1 = p0 + g_.force_;
    for (int i = 0; i < s; ++i)
      constrained_detail::subtract_normals(Gs_[static_cast<std::size_t>(i)], sc_ * g_.bh_[i], y.data() + s * n + i * m,
                                           p1.data());
  }

  bool linearise(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd* A, Eigen::MatrixXd* B) const {
    using Mat = Eigen::MatrixXd;
    const int s = g_.s_, n = g_.dim(), m = con_->count(), sn = s * n, K = s * (n + m), nodes = s + 1;
    const int c = controls(), cols = 2 * n + c;
    if (q0.size() != n || p0.size() != n || dq.size() != n)
      throw std::invalid_argument("ConstrainedGalerkinStep::derivative: a state of " + std::to_string(q0.size()) +
                                  " coordinates; the system has " + std::to_string(n));
    ConstrainedGalerkinStep S = *this;  // the solution Y of this step, found again
    S.reset();
    V d = dq, e(n);
    if (!S.step(t0, q0, p0, d, e).converged) return false;
    const V Y = S.y_;
    V r(K);
    Mat J(K, K);
    // (the step set the start time and G_0 at q0; this places the nodes at Y)
    if (!std::isfinite(S.form_jacobian(q0, p0, Y, r, J))) return false;
    const Eigen::PartialPivLU<Mat> lu(J);
    if (!constrained_detail::lu_invertible(lu)) return false;
    // dF/d(q0, p0, u) at fixed Y, and the nodes' blocks for dp1~
    Mat Fd = Mat::Zero(K, cols);
    Fd.block(0, n, n, n).setIdentity();
    std::vector<Mat> Gc(static_cast<std::size_t>(nodes)), Gv(static_cast<std::size_t>(nodes)),
        Fu(static_cast<std::size_t>(nodes));
    std::vector<Mat> H;
    V x(n), v(n), Lq(n), Lv(n), F(n);
    Mat Lqq(n, n), Lqv(n, n), Lvv(n, n), Fq(n, n), Fv(n, n), Gqt;
    for (int i = 0; i < nodes; ++i) {
      const auto k = static_cast<std::size_t>(i);
      x = S.g_.xs_.col(i);
      v = S.g_.vs_.col(i);
      const double ti = S.g_.node_time(i);
      if constexpr (has_time<Sys>::value) S.g_.L_.set_time(ti);
      S.g_.L_.hessian(x, v, Lq, Lv, Lqq, Lqv, Lvv);
      Gc[k] = Lqq;  // G_q,i - lambda_i . Hess g(x_i)
      Gv[k] = Lqv;
      if constexpr (kForced) {
        S.g_.force_fn_->jacobian(ti, x, v, F, Fq, Fv, c > 0 ? &Fu[k] : nullptr);
        Gc[k] += Fq;
        Gv[k] += Fv;
      }
      if (i < s) {  // the multiplier's curvature at the node
        S.con_->second_derivatives(ti, x, H, Gqt);
        for (int l = 0; l < m; ++l) Gc[k] -= (S.sc_ * Y[sn + i * m + l]) * H[static_cast<std::size_t>(l)];
      }
      for (int j = 0; j < s; ++j) {
        Fd.block(j * n, 0, n, n) += S.g_.WAf_[i][j] * Gc[k] + S.g_.t_.WB[i][j] * Lqv.transpose();
        if (c > 0) Fd.block(j * n, 2 * n, n, c) += S.g_.WAf_[i][j] * Fu[k];
      }
      if (i >= 1) Fd.block(sn + (i - 1) * m, 0, m, n) = S.sr_ * S.Gs_[k];
    }
    const Mat dY = -lu.solve(Fd);
    Mat dq1 = dY.middleRows((s - 1) * n, n);
    dq1.leftCols(n) += Mat::Identity(n, n);
    Mat dpt = Mat::Zero(n, cols), dx(n, cols), dv(n, cols);
    dpt.block(0, n, n, n).setIdentity();
    for (int i = 0; i < nodes; ++i) {
      const auto k = static_cast<std::size_t>(i);
      dx.setZero();
      dx.leftCols(n).setIdentity();
      dv.setZero();
      for (int j = 1; j <= s; ++j) {
        dx += S.g_.t_.A[i][j] * dY.middleRows((j - 1) * n, n);
        dv += S.g_.Bf_[j - 1][i] * dY.middleRows((j - 1) * n, n);
      }
      dpt += S.g_.bh_[i] * (Gc[k] * dx + Gv[k] * dv);
      if (c > 0) dpt.rightCols(c) += S.g_.bh_[i] * Fu[k];
      if (i < s) dpt -= (S.sc_ * S.g_.bh_[i]) * S.Gs_[k].transpose() * dY.middleRows(sn + i * m, m);
    }
    // the right transform at the solution: p1~, and its projection (mu, v1, G1)
    V p1(n), q1 = q0 + Y.segment((s - 1) * n, n), v1 = S.g_.vs_.col(s);
    S.momentum_before_projection(p0, Y, p1);
    const double t1 = t0 + g_.h_;
    try {
      if (*(*S.proj_)(S.g_.L_, *S.con_, t1, q1, p1, v1, momentum_)) return false;
    } catch (const std::domain_error&) {
      return false;
    }
    Mat dp1;
    if (!constrained_detail::right_transform_derivative<Eigen::Dynamic, Eigen::Dynamic, Eigen::Dynamic>(
            S.g_.L_, *S.con_, t1, q1, v1, S.proj_->mu, S.proj_->G, dq1, dpt, dp1))
      return false;
    if (A) {
      A->resize(2 * n, 2 * n);
      A->topRows(n) = dq1.leftCols(2 * n);
      A->bottomRows(n) = dp1.leftCols(2 * n);
      if (!A->allFinite()) return false;
    }
    if (B) {
      B->resize(2 * n, c);
      B->topRows(n) = dq1.rightCols(c);
      B->bottomRows(n) = dp1.rightCols(c);
      if (!B->allFinite()) return false;
    }
    return true;
  }

  // R (the first s n rows) and the constraint rows at y, into r. G_1..G_{s-1}, which R
  // reads, are evaluated at the nodes it places (G_0 by the step); G_s, which only the
  // Jacobian's last constraint rows read, where `jacobian`.
  void evaluate(const V& q0, const V& p0, const V& y, V& r, bool jacobian) const {
    const int s = g_.s_, n = g_.dim(), m = con_->count(), sn = s * n;
    X_ = y.head(sn);
    g_.residual(q0, p0, X_, RX_);
    for (int i = 1; i <= s; ++i) {  // the constraint rows (and the gradients there)
      const auto k = static_cast<std::size_t>(i);
      if (i < s || jacobian)
        con_->jacobian(g_.node_time(i), g_.xs_.col(i), gval_, Gs_[k], gt_);
      else
        con_->value(g_.node_time(i), g_.xs_.col(i), gval_);
      for (int l = 0; l < m; ++l) r[sn + (i - 1) * m + l] = sr_ * gval_[l];
    }
    const double* lam = y.data() + sn;
    for (int i = 0; i < s; ++i) {  // - h WA_ij G_i^T lambda_i in R_j (node 0: R_0 only)
      for (int j = 0; j < s; ++j) {
        const double w = sc_ * g_.WAf_[i][j];
        if (w != 0.0)
          constrained_detail::subtract_normals(Gs_[static_cast<std::size_t>(i)], w, lam + i * m, RX_.data() + j * n);
      }
    }
    r.head(sn) = RX_;
  }

  // r and the saddle-point Jacobian at y (the header comment); returns max|J_ij|.
  double form_jacobian(const V& q0, const V& p0, const V& y, V& r, Eigen::MatrixXd& J) const {
    const int s = g_.s_, n = g_.dim(), m = con_->count(), sn = s * n;
    X_ = y.head(sn);
    const double jx = g_.form_jacobian(q0, X_, JX_);
    if (sc_ == 0.0) {  // the scales of the constraint rows and of the multipliers (header comment)
      const double g0 = dynamic_detail::inf_norm(Gs_[0]);
      double w = 0.0;
      for (int i = 0; i < s; ++i)
        for (int j = 0; j < s; ++j) w = std::fmax(w, std::fabs(g_.WAf_[i][j]));
      const bool ok = std::isfinite(jx) && jx > 0.0 && g0 > 0.0;
      sr_ = ok ? jx / g0 : 1.0;
      sc_ = ok ? jx / (g0 * w) : 1.0;
    }
    evaluate(q0, p0, y, r, true);  // (places the nodes and evaluates G_1..G_s there)
    J.setZero();
    J.topLeftCorner(sn, sn) = JX_;
    // the multipliers' curvature at the interior nodes: d(-h WA_ij G_i^T lambda_i)/dX_k =
    // -h WA_ij A_ik sum_l lambda_il Hess g_l(x_i)
    for (int i = 1; i < s; ++i) {
      xi_ = g_.xs_.col(i);
      con_->second_derivatives(g_.node_time(i), xi_, H_, Gqt_);
      Hl_.setZero();
      for (int l = 0; l < m; ++l) Hl_ += (sc_ * y[sn + i * m + l]) * H_[static_cast<std::size_t>(l)];
      for (int j = 0; j < s; ++j)
        for (int k = 1; k <= s; ++k) {
          const double w = -g_.WAf_[i][j] * g_.t_.A[i][k];
          if (w != 0.0) J.block(j * n, (k - 1) * n, n, n) += w * Hl_;
        }
    }
    for (int i = 0; i < s; ++i) {
      const Eigen::MatrixXd& G = Gs_[static_cast<std::size_t>(i)];
      for (int j = 0; j < s; ++j) {
        const double w = -sc_ * g_.WAf_[i][j];
        if (w != 0.0) J.block(j * n, sn + i * m, n, m) += w * G.transpose();
      }
    }
    for (int i = 1; i <= s; ++i) {
      const Eigen::MatrixXd& G = Gs_[static_cast<std::size_t>(i)];
      for (int k = 1; k <= s; ++k) {
        const double a = g_.t_.A[i][k];
        if (a != 0.0) J.block(sn + (i - 1) * m, (k - 1) * n, m, n) = (sr_ * a) * G;
      }
    }
    const double Jmax = max_abs(J);
    return std::isfinite(Jmax) ? Jmax : INFINITY;
  }

  struct Equation {
    using Vector = V;
    using Matrix = Eigen::MatrixXd;
    const ConstrainedGalerkinStep& step;
    const V& q0;
    const V& p0;
    double pscale, q0size;
    void residual(const Vector& y, Vector& r) const { step.evaluate(q0, p0, y, r, false); }
    double jacobian(const Vector& y, Vector& r, Matrix& J) const { return step.form_jacobian(q0, p0, y, r, J); }
    double scale(double yn, double Jmax) const { return pscale + Jmax * yn; }
    double offset() const { return q0size; }
  };

  mutable Inner g_;  // the unconstrained stage equations, their tables and workspace
  constrained_detail::Owned<Con> con_;
  MomentumMap momentum_;
  mutable double sr_ = 0.0, sc_ = 0.0;  // the constraint rows' scale, the multipliers'
  mutable V y_, r_, dx_, start_, yprev_, X_, RX_, gval_, gt_, q_end_, p1_, v1_;
  mutable Eigen::MatrixXd JX_, J_, Hl_, Gqt_;
  mutable V xi_;
  mutable std::vector<Eigen::MatrixXd> H_;  // the constraints' Hessians at a node
  mutable std::vector<Eigen::MatrixXd> Gs_;  // G_0 .. G_s (m x n each)
  mutable typename Inner::InverseLU lu_;
  mutable DriverState kept_;
  mutable bool have_prev_ = false;
  constrained_detail::Owned<constrained_detail::Projection<Sys, Con>> proj_;
};

}  // namespace dvm
