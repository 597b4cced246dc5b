// The Hamiltonian form of the theta maps (the cotangent lift, paper Sec. 5.1, Eq. 5.1)
// under holonomic constraints g(t, q) = 0, for a run-time-sized Hamiltonian H, the
// Legendre transform of a Lagrangian L (LegendreDynamicHamiltonian, or a written H that
// the runtime has checked against it).
//
// The constrained position-momentum step (solvers/constrained_step.h) is the
// unconstrained step of the theta map from (q0, p0 - G0^T lambda), lambda chosen so
// that it ends on g(t1, q1) = 0, followed by the right constrained Legendre transform,
// which puts the momentum on the hidden constraint. Here the unconstrained step is the
// Hamiltonian one (HamiltonianThetaEquation, solvers/dynamic_step.h), with G0 = Dg(t0,
// q0) and t1 = t0 + h:
//   1. dq - h H_p(Q, P) = 0,   dp + h H_q(Q, P) - h F = 0,   g(t1, q0 + dq) = 0,
//      Q = q0 + theta dq, P = p0 - G0^T lambda + (1 - theta) dp, for (dq, dp, lambda);
//      p1~ = p0 - G0^T lambda + dp;
//   2. p1 = p1~ - G1^T mu with G1 H_p(q1, p1) + g_t(t1, q1) = 0 (H_p = FL^{-1}: the
//      projection of constrained_step.h, constrained_detail::Projection, on L).
// For a separable L the unconstrained Hamiltonian theta step is the position-momentum
// step of the same map (both give dq = h M^{-1} (p0 - h (1 - theta) grad U(Q)), dp =
// -h grad U(Q)), so the two constrained steps are one map; otherwise they are two
// discretizations of the same order. For a scleronomic g the step of the adjoint map
// (1 - theta) is the adjoint step, as for the constrained position-momentum step, so
// symmetric compositions raise its order.
//
// Equation 1 is solved by newton_drive with a dense LU of its Jacobian
//   [ J_H          dF/dP (-s G0^T) ]
//   [ s_g G1(dq)  0   0            ]
// J_H the unconstrained equation's Jacobian, dF/dP its columns in P
// (HamiltonianThetaEquation::momentum_columns), the multiplier carried as lambda / s
// and the constraint rows multiplied by s_g, with s = max|J_H| / max|dF/dP G0^T| and s_g
// = max|J_H| / max|G0| from the first Jacobian on, so that the multiplier's columns and
// the constraint's rows are of the size of J_H's (J_H is near the identity, dF/dP of the
// size of h: with one scale for both, as the constrained position-momentum step has, the
// multiplier's updates would stay above the stopping rule's at round-off). The theta
// map on T*Q itself (lift = "none") is not constrained here (the runtime refuses it).
//
// Workspace is allocated at construction; a step allocates nothing. One object must not
// be used from two threads at once (copies are independent).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

#include "solvers/constrained_step.h"
#include "solvers/dynamic_step.h"

namespace dvm {

// Equation 1 of the header comment, for solvers/newton_driver.h: unknowns y = (dq, dp,
// lambda / s).
template <class Ham, class Con, class Force = NoForce>
class ConstrainedHamiltonianThetaEquation {
 public:
  using Vector = Eigen::VectorXd;
  using Matrix = Eigen::MatrixXd;
  using Inner = HamiltonianThetaEquation<Ham, Force>;

  ConstrainedHamiltonianThetaEquation(const Ham& H, const Con& g, double theta, double h, const Force* force = nullptr)
      : eq_(H, theta, h, false, force), g_(&g), h_(h), n_(H.dim()), m_(g.count()) {
    p0s_.resize(n_);
    q1_.resize(n_);
    yin_.resize(2 * n_);
    rin_.resize(2 * n_);
    Jin_.resize(2 * n_, 2 * n_);
    Pc_.resize(2 * n_, n_);
    PG_.resize(2 * n_, m_);
    g1_.resize(m_);
    gt_.resize(m_);
    G0_.resize(m_, n_);
    G1_.resize(m_, n_);
  }

  // The start of the step at time t0; G0 = Dg(t0, q0). q0 and p0 must outlive the solve.
  void begin(const Vector& q0, const Vector& p0, double t0) {
    q0_ = &q0;
    p0_ = &p0;
    t1_ = t0 + h_;
    p0s_ = p0;
    eq_.begin(q0, p0s_, t0);  // (reads p0s_, which shift() moves by the multipliers)
    g_->gradients(t0, q0, G0_, gt_);
    g0max_ = dynamic_detail::inf_norm(G0_);
  }
  void residual(const Vector& y, Vector& r) {
    split(y);
    eq_.residual(yin_, rin_);
    g_->value(t1_, q1_, g1_);
    form(r);
  }
  double jacobian(const Vector& y, Vector& r, Matrix& J) {
    split(y);
    const double Jh = eq_.jacobian(yin_, rin_, Jin_);
    g_->jacobian(t1_, q1_, g1_, G1_, gt_);
    eq_.momentum_columns(Pc_);
    PG_.noalias() = Pc_ * G0_.transpose();
    if (s_ == 0.0) {  // (x = 0 until now, so the shift did not read the scales)
      const bool ok = std::isfinite(Jh) && Jh > 0.0;
      const double pg = dynamic_detail::inf_norm(PG_);
      s_ = ok && pg > 0.0 ? Jh / pg : 1.0;
      sr_ = ok && g0max_ > 0.0 ? Jh / g0max_ : 1.0;
    }
    form(r);
    const Eigen::Index n = n_, m = m_;
    J.setZero();
    J.topLeftCorner(2 * n, 2 * n) = Jin_;
    J.topRightCorner(2 * n, m) = -s_ * PG_;
    J.bottomLeftCorner(m, n) = sr_ * G1_;
    const double a = dynamic_detail::inf_norm(J);
    return std::isfinite(a) ? a : INFINITY;
  }
  double scale(double yn, double Jmax) const { return eq_.scale(yn, Jmax); }
  double offset() const { return eq_.offset(); }

  // At the solution y: p1~ - p0 = dp - s G0^T (lambda / s) into dp1, and the force's work
  // over the step.
  double momentum(const Vector& y, Vector& dp1) {
    split(y);
    dp1 = y.segment(n_, n_);
    constrained_detail::subtract_normals(G0_, s_, y.data() + 2 * n_, dp1.data());
    return eq_.work(yin_);
  }
  double end_time() const { return t1_; }

  // For the step's derivative, at the solution y after jacobian(y, ...): s (lambda =
  // s x, the multipliers), G0 = Dg(t0, q0), and the residual's columns in q0, p0 and the
  // force's control inputs ((2n + m) x (2n + c)). Q = q0 + theta dq moves with q0 by the
  // identity; P = p0 - G0^T lambda + (1 - theta) dp with p0 by the identity and with q0
  // by -H_lambda (the constraints' Hessians at (t0, q0) contracted with lambda); the
  // constraint rows s_g g(t1, q0 + dq) with q0 as with dq.
  double multiplier_scale() const { return s_; }
  const Matrix& start_gradients() const { return G0_; }
  void start_columns(const Matrix& H_lambda, Matrix& C) {
    const Eigen::Index n = n_, m = m_;
    Matrix Qc, Uc;
    eq_.position_columns(Qc);
    eq_.control_columns(Uc);
    C.setZero(2 * n + m, 2 * n + Uc.cols());
    C.topLeftCorner(2 * n, n) = Qc;
    C.topLeftCorner(2 * n, n).noalias() -= Pc_ * H_lambda;
    C.block(0, n, 2 * n, n) = Pc_;
    C.bottomLeftCorner(m, n) = sr_ * G1_;
    if (Uc.cols() > 0) C.topRightCorner(2 * n, Uc.cols()) = Uc;
  }

 private:
  // (dq, dp) for the unconstrained equation, q1, and its start momentum p0 - s G0^T x
  void split(const Vector& y) {
    for (int i = 0; i < n_; ++i) {
      yin_[i] = y[i];
      yin_[n_ + i] = y[n_ + i];
      q1_[i] = (*q0_)[i] + y[i];
      p0s_[i] = (*p0_)[i];
    }
    constrained_detail::subtract_normals(G0_, s_, y.data() + 2 * n_, p0s_.data());
  }
  void form(Vector& r) const {
    for (int i = 0; i < 2 * n_; ++i) r[i] = rin_[i];
    for (int k = 0; k < m_; ++k) r[2 * n_ + k] = sr_ * g1_[k];
  }

  Inner eq_;
  const Con* g_;
  double h_, t1_ = 0.0, s_ = 0.0, sr_ = 0.0, g0max_ = 0.0;
  int n_, m_;
  const Vector* q0_ = nullptr;
  const Vector* p0_ = nullptr;
  Vector p0s_, q1_, yin_, rin_, g1_, gt_;
  Matrix Jin_, Pc_, PG_, G0_, G1_;
};

// The constrained Hamiltonian theta step: equation 1 by the driver, then the projection.
// Ham: a run-time-sized Hamiltonian (the Legendre transform of L); Sys: that Lagrangian
// (the projection's FL^{-1}); Con: the constraints (as ConstrainedThetaStep's); Force: a
// generalized force F(t, q, v) at the node with v = H_p (NoForce: none).
template <class Ham, class Sys, class Con, class Force = NoForce>
class ConstrainedHamiltonianThetaStep {
  static_assert(is_dynamic_system_v<Sys>, "ConstrainedHamiltonianThetaStep needs a run-time-sized Lagrangian");

 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;
  static constexpr bool kForced = is_force_v<Force>;

  // momentum: how L_v depends on v (MomentumMap of constrained_step.h). Each copy of the
  // step evaluates its own copies of the constraints and the force.
  ConstrainedHamiltonianThetaStep(Ham H, Sys L, ThetaMap R, double h, std::shared_ptr<const Con> constraints,
                                  StepOptions options = {}, MomentumMap momentum = MomentumMap::general,
                                  std::shared_ptr<const Force> force = nullptr)
      : H_(std::move(H)),
        L_(std::move(L)),
        R_(std::move(R)),
        h_(h),
        options_(options),
        momentum_(momentum),
        con_(std::move(constraints)),
        force_(std::move(force)) {
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    if (H_.dim() != L_.dim())
      throw std::invalid_argument("ConstrainedHamiltonianThetaStep: H and L of different dimensions");
    if (!con_ || con_->dim() != L_.dim())
      throw std::invalid_argument("ConstrainedHamiltonianThetaStep: constraints on the system's coordinates are needed");
    if (con_->count() >= L_.dim())
      throw std::invalid_argument("ConstrainedHamiltonianThetaStep: " + std::to_string(con_->count()) +
                                  " constraints on " + std::to_string(L_.dim()) + " coordinates leave no motion");
    if constexpr (kForced)
      if (!force_ || force_->dim() != L_.dim())
        throw std::invalid_argument("ConstrainedHamiltonianThetaStep: a forced step needs a force of the system's "
                                    "dimension");
    work_ = std::make_shared<Work>(H_, *con_, R_.theta(), h_, force_.get(), L_.dim());
  }
  ConstrainedHamiltonianThetaStep(const ConstrainedHamiltonianThetaStep& o)
      : H_(o.H_),
        L_(o.L_),
        R_(o.R_),
        h_(o.h_),
        options_(o.options_),
        momentum_(o.momentum_),
        con_(o.con_),
        force_(o.force_) {
    work_ = std::make_shared<Work>(H_, *con_, R_.theta(), h_, force_.get(), L_.dim());
  }
  ConstrainedHamiltonianThetaStep& operator=(const ConstrainedHamiltonianThetaStep&) = delete;

  double step_size() const { return h_; }
  const Ham& hamiltonian() const { return H_; }
  const Sys& lagrangian() const { return L_; }
  const ThetaMap& map() const { return R_; }
  const StepOptions& options() const { return options_; }
  int dim() const { return L_.dim(); }
  int constraints() const { return con_->count(); }
  // The force's control inputs (WrittenForce::controls()), 0 without a force.
  int controls() const {
    if constexpr (kForced) return force_->controls();
    return 0;
  }

  // The constrained step of the adjoint map (1 - theta).
  ConstrainedHamiltonianThetaStep adjoint() const {
    return ConstrainedHamiltonianThetaStep(H_, L_, R_.adjoint(), h_, con_, options_, momentum_, force_);
  }

  // The derivative of the step (q0, p0) -> (q1, p1) at the increment dq that step()
  // solved for from (q0, p0) at time t0, by the implicit function theorem on its two
  // equations (no finite differences); A (2n x 2n) as DynamicThetaStep::derivative gives
  // it, coordinates before momenta. The step is solved again from (q0, p0) with dq as
  // the guess, for dp, the multipliers and the projection's mu and v1. Equation 1,
  // F(y; q0, p0) = 0 in y = (dq, dp, lambda / s), gives dy/d(q0, p0) = -F_y^{-1} C, F_y
  // the driver's Jacobian and C the columns of ConstrainedHamiltonianThetaEquation::
  // start_columns; then q1 = q0 + dq, p1~ = p0 - G0^T lambda + dp (whose derivative in
  // q0 has -H_lambda too), and equation 2 at (q1, p1~) as
  // constrained_detail::right_transform_derivative differentiates it. Without forces
  // the step is symplectic on the constraint's cotangent bundle, as the constrained
  // position-momentum step (A^T J A = J on the vectors tangent to it). Returns false
  // where the solve fails, a matrix is singular or a value is not finite. Allocates;
  // not from two threads at once (it uses the step's workspace).
  bool derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A) const {
    return differentiate(t0, q0, p0, dq, A, nullptr);
  }
  // B = d(q1, p1)/du (2n x c) in the force's control inputs u (held over the step): the
  // columns of the same solves for u, which enters through F at the node.
  template <class Fo = Force, std::enable_if_t<is_force_v<Fo>, int> = 0>
  bool control_derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& B) const {
    Eigen::MatrixXd A;
    return differentiate(t0, q0, p0, dq, A, &B);
  }
  // A and, where B is not null, B from one differentiation.
  bool derivatives(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    return differentiate(t0, q0, p0, dq, A, B);
  }

  // One step from (q0, p0) at time t; dq holds the starting guess on entry and q1 - q0
  // on return, dp receives p1 - p0 (the guesses of the momentum increment and of the
  // multiplier are the last step's, kept in the workspace).
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    const int n = L_.dim();
    if (!dynamic_detail::sizes_match(n, q0, p0, dq, s)) return s;
    if (dp.size() != n) dp.resize(n);
    Work& w = *work_;
    try {
      w.q0 = q0;
      w.p0 = p0;
      for (int i = 0; i < n; ++i) w.y[i] = dq[i];
      w.eq.begin(w.q0, w.p0, t);
      s = newton_drive(w.eq, w.lu, Refresh::within_step, options_, w.y, w.r, w.dx, w.J, w.state, w.start);
      for (int i = 0; i < n; ++i) dq[i] = w.y[i];
      if (s.converged) {
        const double work = w.eq.momentum(w.y, w.dp);
        if constexpr (kForced) s.work = work;
        constrained_detail::project_end(s, w.projection, L_, *w.con, momentum_, w.eq.end_time(), h_, q0, p0, dq, w.dp,
                                        w.q1, w.p1, w.v1, dp);
      }
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    if (!s.converged && s.iterations == 0) s.iterations = 1;
    return s;
  }

 private:
  bool differentiate(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    const int n = L_.dim(), m = con_->count();
    if (q0.size() != n || p0.size() != n || dq.size() != n)
      throw std::invalid_argument("ConstrainedHamiltonianThetaStep::derivative: a state of " +
                                  std::to_string(q0.size()) + " coordinates; the system has " + std::to_string(n));
    using M = Eigen::MatrixXd;
    V d = dq, e(n);
    if (!step(t0, q0, p0, d, e).converged) return false;
    // step() left (q0, p0) in w.q0, w.p0, the solution in w.y, and the projection's
    // q1, v1, mu and G1 = Dg(t1, q1)
    Work& w = *work_;
    w.eq.begin(w.q0, w.p0, t0);
    if (!std::isfinite(w.eq.jacobian(w.y, w.r, w.J))) return false;
    const double s = w.eq.multiplier_scale();
    const V lambda = s * w.y.tail(m);
    std::vector<M> H0;
    M Gqt0;
    w.con->second_derivatives(t0, w.q0, H0, Gqt0);
    M Hl = M::Zero(n, n);
    for (int i = 0; i < m; ++i) Hl += lambda[i] * H0[static_cast<std::size_t>(i)];
    M C;
    w.eq.start_columns(Hl, C);
    const Eigen::PartialPivLU<M> lu(w.J);
    if (!constrained_detail::lu_invertible(lu)) return false;
    const M Y = -lu.solve(C);  // d(dq, dp, lambda / s) / d(q0, p0, u)
    M dq1 = Y.topRows(n);
    dq1.leftCols(n) += M::Identity(n, n);
    // p1~ = p0 - G0^T lambda + dp, lambda = s x
    M dpt = Y.middleRows(n, n);
    dpt.noalias() -= s * (w.eq.start_gradients().transpose() * Y.bottomRows(m));
    dpt.leftCols(n) -= Hl;
    dpt.block(0, n, n, n) += M::Identity(n, n);
    M dp1;
    if (!constrained_detail::right_transform_derivative<Eigen::Dynamic, Eigen::Dynamic, Eigen::Dynamic>(
            L_, *w.con, w.eq.end_time(), w.q1, w.v1, w.projection.mu, w.projection.G, dq1, dpt, dp1))
      return false;
    return dynamic_detail::assemble_derivative(n, dq1, dp1, A, B);
  }

  using Eq = ConstrainedHamiltonianThetaEquation<Ham, Con, Force>;
  struct Work {
    Work(const Ham& H, const Con& c, double theta, double h, const Force* f, int n)
        : con(std::make_unique<Con>(c)),
          force(f ? std::make_unique<Force>(*f) : nullptr),
          eq(H, *con, theta, h, force.get()),
          projection(n, c.count()) {
      const int k = 2 * n + c.count();
      q0.resize(n);
      p0.resize(n);
      q1.resize(n);
      p1.resize(n);
      v1.resize(n);
      dp.resize(n);
      y = V::Zero(k);
      r.resize(k);
      dx.resize(k);
      start.resize(k);
      J.resize(k, k);
      lu.resize(k);
    }
    std::unique_ptr<Con> con;      // this step's copy of the constraints (their workspace)
    std::unique_ptr<Force> force;  // and of the force
    Eq eq;
    constrained_detail::Projection<Sys, Con> projection;
    V q0, p0, q1, p1, v1, dp, y, r, dx, start;
    Eigen::MatrixXd J;
    DenseLU lu;
    DriverState state;
  };

  Ham H_;
  Sys L_;
  ThetaMap R_;
  double h_;
  StepOptions options_;
  MomentumMap momentum_;
  std::shared_ptr<const Con> con_;
  std::shared_ptr<const Force> force_;
  std::shared_ptr<Work> work_;
};

}  // namespace dvm
