// Steps of the theta discretization maps for run-time-sized systems
// (mechanics/dynamic_system.h): the step equations assembled from the derivative
// blocks the system provides, solved by Newton's method in storage sized once.
//
// The theta map R_d(x, v) = (x - theta v, x + (1 - theta) v), theta in [0, 1]
// (explicit Euler 0, midpoint 1/2, adjoint Euler 1; core/discretization_map.h).
//
// 1. Position-momentum step (discrete Legendre form; solvers/position_momentum_step.h).
//    The discrete Lagrangian L_d(q0, q1) = h L(x, v) at R_d^{-1}(q0, q1) / h, i.e.
//    x = q0 + theta dq, v = dq / h with dq = q1 - q0 (paper Sec. 5.3), has
//      D1 L_d = h (1 - theta) L_q(x, v) - L_v(x, v),   (D1 + D2) L_d = h L_q(x, v).
//    Given (q0, p0), the increment dq solves
//      F(dq) = p0 + h (1 - theta) L_q(x, v) - L_v(x, v) = 0,
//    then dp = p1 - p0 = h L_q(x, v) (the common shift of q0 and q1 leaves v unchanged:
//    no cancellation). With dx/ddq = theta I and dv/ddq = I / h, the Jacobian is
//      dF/ddq = h theta (1 - theta) L_qq + (1 - theta) L_qv - theta L_qv^T - L_vv / h,
//    built from one call of the system's hessian() per Newton iteration. A generalized
//    force F(t, q, v) enters by the discrete Lagrange-d'Alembert principle as
//    L_q + F in both equations (ThetaEquation below). A Lagrangian L(t, q, v) is
//    evaluated at the node's time t0 + theta h, as the force is (the quadrature of
//    L_d), so L_d(t0; q0, q1) = h L(t0 + theta h, x, v).
//
// 2. Hamiltonian step (paper Sec. 5.1, Eq. 5.1; solvers/hamiltonian_step.h). The
//    inverse of the cotangent lift of the theta map sends (q0, p0; q1, p1) to the base
//    point x = (1 - theta) q0 + theta q1 = q0 + theta dq,
//          p = theta p0 + (1 - theta) p1 = p0 + (1 - theta) dp,
//    and the tangent vector (dq, dp); Eq. 5.1 asks it to be h X_H(x, p):
//      F(dq, dp) = (dq - h H_p(x, p),  dp + h H_q(x, p)) = 0,
//    with the Jacobian (H_pq = H_qp^T)
//      [ I - h theta H_pq      -h (1 - theta) H_pp   ]
//      [ h theta H_qq           I + h (1 - theta) H_qp ].
//    The map is symplectic for any H (the lift is a symplectomorphism, Prop. 5.1 of the
//    paper); with theta = 1/2 it is the implicit midpoint rule.
//
// Adjoints. The theta map's adjoint is the (1 - theta) map (Prop. 2.4), and the method
// of the adjoint map is the adjoint method, so adjoint() of either step is the same
// type with 1 - theta: ComposedStep<DynamicThetaStep<Sys>> composes one type.
//
// Solving: each equation is written once (ThetaEquation, HamiltonianThetaEquation below:
// residual, Jacobian blocks, scale) and solved by newton_drive (solvers/newton_driver.h),
// which holds the stopping rule, the correction of the accepted residual and the refresh
// of the Jacobian; the linear solves use DenseLU (a pivot not above 1e-14 max|J| is
// singular). The scales are |p0| + |J| |dq| for the position-momentum step (stall
// measured against |dq| + |q0|), |h| max(|H_p|, |H_q|)(q0, p0) + |J| |(dq, dp)| for the
// Hamiltonian step (against |(dq, dp)| + max(|q0|, |p0|)). The position-momentum step
// may keep its Jacobian across steps (keep_jacobian, Refresh::across_steps): a step then
// costs gradients of L and triangular solves, and L's Hessian only where the iteration
// stops converging fourfold; compiled for a number of coordinates K known in advance
// (DynamicThetaStep<Sys, K>) it keeps the first iteration's Jacobian within each step by
// the same rule (Refresh::within_step) and forms dp from the last gradient.
// Non-convergence, singular Jacobians, non-finite values and std::domain_error from the
// system (e.g. a degenerate Legendre transform) are reported in the StepSummary, never
// thrown. Only Newton's method is offered: StepOptions::solver = tiny is refused at
// construction.
//
// Workspace is allocated at construction for the system's dimension; a step allocates
// nothing (checked with Eigen's EIGEN_RUNTIME_NO_MALLOC and a count of operator new in
// tests/solvers/test_dynamic.cc). One object must not be used from two threads at once,
// nor copies of a step that keeps its Jacobian (they share its factorisation).
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/discretization_map.h"
#include "mechanics/dynamic_system.h"
#include "solvers/newton.h"
#include "solvers/newton_driver.h"

namespace dvm {

namespace dynamic_detail {

// A = d(q1, p1)/d(q0, p0) and, where B is given, B = d(q1, p1)/du from the derivatives
// dq1 and dp1 (n x (2n + c): the columns of q0, p0, then the c inputs), as the constrained
// steps' derivatives give them; false where a value is not finite.
template <class M1, class M2>
bool assemble_derivative(Eigen::Index n, const M1& dq1, const M2& dp1, Eigen::MatrixXd& A, Eigen::MatrixXd* B) {
  A.resize(2 * n, 2 * n);
  A.topRows(n) = dq1.leftCols(2 * n);
  A.bottomRows(n) = dp1.leftCols(2 * n);
  if (!B) return A.allFinite();
  const Eigen::Index c = dq1.cols() - 2 * n;
  B->resize(2 * n, c);
  B->topRows(n) = dq1.rightCols(c);
  B->bottomRows(n) = dp1.rightCols(c);
  return A.allFinite() && B->allFinite();
}

inline void require_newton(const StepOptions& options) {
  if (options.solver != SolverKind::newton)
    throw std::invalid_argument("run-time-sized steps solve by Newton's method only (solver = \"newton\")");
}
inline void require_step(double h) {
  // negative sizes are the backward substeps of compositions (solvers/composition.h)
  if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
}
// A summary for a state whose size is not the system's.
inline bool sizes_match(int n, const Eigen::VectorXd& q0, const Eigen::VectorXd& p0, const Eigen::VectorXd& dq,
                        StepSummary& s) {
  if (q0.size() == n && p0.size() == n && dq.size() == n) return true;
  s.message = "the state has " + std::to_string(q0.size()) + " coordinates (p " + std::to_string(p0.size()) +
              ", dq " + std::to_string(dq.size()) + "); the system has " + std::to_string(n);
  return false;
}

}  // namespace dynamic_detail

// The position-momentum equation of the theta map (paper Sec. 5.3) for a run-time-sized
// Lagrangian Sys, over its derivative blocks: for the increment D = q1 - q0,
//   F(D) = p0 + h (1 - theta) G(x, v) - L_v(x, v),   x = q0 + theta D,  v = D / h,
//   dF/dD = h theta (1 - theta) G_q + (1 - theta) G_v - theta L_qv^T - L_vv / h,
// and p1 - p0 = h G(x, v) at the solution, with G = L_q (G_q = L_qq, G_v = L_qv), or
// G = L_q + F with a generalized force F(t, q, v) (mechanics/written_force.h). The force
// enters by the discrete Lagrange-d'Alembert principle (Marsden and West, Acta Numerica
// 2001, Sec. 3.2) with the discrete forces of the map and quadrature of L_d: the virtual
// work h <F, delta x> at the node x = q0 + theta D, t = t0 + theta h, whose variation
// delta x = (1 - theta) delta q0 + theta delta q1 gives
//   F_d^- = h (1 - theta) F,   F_d^+ = h theta F,
// and the forced discrete Legendre transforms p0 = -D1 L_d - F_d^-, p1 = D2 L_d + F_d^+
// are the equation above. It is the unforced step with L_q replaced by L_q + F at the
// same point, so the adjoint of the forced theta step is the forced (1 - theta) step and
// its compositions keep their order. The work of the force over the step, h <F, v> =
// <F(t, x, v), D> at the solution, is the same quadrature (work()). The equation of
// solvers/newton_driver.h; K: the number of coordinates where it is known when compiled
// (else Dynamic); Force: the type of the force (NoForce, solvers/newton.h: none, and no
// trace of one in the compiled equation; WrittenForce).
template <class Sys, int K = Eigen::Dynamic, class Force = NoForce>
class ThetaEquation {
 public:
  using Vector = Eigen::Matrix<double, K, 1>;
  using Matrix = Eigen::Matrix<double, K, K>;
  static constexpr bool kForced = is_force_v<Force>;

  // force: the generalized force (an object of the caller's, used from one thread at a
  // time); required where Force is not NoForce
  ThetaEquation(const Sys& L, double theta, double h, const Force* force = nullptr)
      : L_(&L), force_(force), th_(theta), h_(h) {
    if (kForced && !force_) throw std::invalid_argument("ThetaEquation: a forced equation needs its force");
    const int n = L.dim();
    x_.resize(n);
    v_.resize(n);
    Lq_.resize(n);
    Lv_.resize(n);
    Lqq_.resize(n, n);
    Lqv_.resize(n, n);
    Lvv_.resize(n, n);
    if constexpr (kForced) {
      F_.resize(n);
      Fq_.resize(n, n);
      Fv_.resize(n, n);
    }
  }
  // The start of the step, at time t0 (read by a force and by L(t, q, v), both at the
  // node's time t0 + theta h).
  void begin(const Vector& q0, const Vector& p0, double t0 = 0.0) {
    q0_ = &q0;
    p0_ = &p0;
    t_ = t0 + th_ * h_;
    if constexpr (has_time<Sys>::value) L_->set_time(t_);
    pscale_ = dynamic_detail::inf_norm(p0);
    q0size_ = dynamic_detail::inf_norm(q0);
  }
  void residual(const Vector& D, Vector& r) {
    at(D);
    L_->gradient(x_, v_, Lq_, Lv_);
    if constexpr (kForced) add_force();
    form(r);
  }
  double jacobian(const Vector& D, Vector& r, Matrix& J) {
    at(D);
    L_->hessian(x_, v_, Lq_, Lv_, Lqq_, Lqv_, Lvv_);
    if constexpr (kForced) add_force_and_jacobian();
    form(r);
    const double a = h_ * th_ * (1.0 - th_), b = 1.0 - th_, inv_h = 1.0 / h_;
    const Eigen::Index n = J.rows();
    for (Eigen::Index j = 0; j < n; ++j)
      for (Eigen::Index i = 0; i < n; ++i)
        J(i, j) = a * Lqq_(i, j) + b * Lqv_(i, j) - th_ * Lqv_(j, i) - inv_h * Lvv_(i, j);
    if constexpr (kForced) J += a * Fq_ + b * Fv_;
    const double m = dynamic_detail::inf_norm(J);
    return std::isfinite(m) ? m : INFINITY;
  }
  double scale(double Dn, double Jmax) const { return pscale_ + Jmax * Dn; }
  double offset() const { return q0size_; }
  // L_qq and L_qv at the point of the last jacobian() (the step's derivative reads them),
  // and with a force its F_q and F_v there.
  const Matrix& Lqq() const { return Lqq_; }
  const Matrix& Lqv() const { return Lqv_; }
  const Matrix& Fq() const { return Fq_; }
  const Matrix& Fv() const { return Fv_; }

  // p1 - p0 = h G at the solution D.
  void momentum(const Vector& D, Vector& dp) {
    at(D);
    L_->gradient(x_, v_, Lq_, Lv_);
    if constexpr (kForced) add_force();
    for (Eigen::Index i = 0; i < dp.size(); ++i) dp[i] = h_ * Lq_[i];
  }
  // The work of the force over the step, <F(t, x, v), D>, after momentum(D) (0 without
  // a force).
  double work(const Vector& D) const {
    if constexpr (kForced) return F_.dot(D);
    return (void)D, 0.0;
  }
  // The same from L_q of the last evaluation and the correction c applied after it (x
  // moved by -theta c, v by -c / h), to first order with the blocks of the last Jacobian:
  // for a correction at the residual's tolerance what this leaves out (c times the change
  // of the Hessian since, and c^2) lies below the round-off of dp, for one gradient less.
  // Without a force only (with one the step calls momentum(), which also gives the work).
  void momentum_after(const Vector& c, Vector& dp) const {
    const Eigen::Index n = dp.size();
    const double inv_h = 1.0 / h_;
    for (Eigen::Index i = 0; i < n; ++i) {
      double d = Lq_[i];
      for (Eigen::Index j = 0; j < n; ++j) d -= (th_ * Lqq_(i, j) + inv_h * Lqv_(i, j)) * c[j];
      dp[i] = h_ * d;
    }
  }

 private:
  void add_force() {
    force_->value(t_, x_, v_, F_);
    Lq_ += F_;
  }
  void add_force_and_jacobian() {
    force_->jacobian(t_, x_, v_, F_, Fq_, Fv_);
    Lq_ += F_;
  }
  // x = q0 + theta D, v = D / h (as ThetaMap::inverse_increment and DiscreteLagrangian)
  void at(const Vector& D) {
    const double inv_h = 1.0 / h_;
    const Vector& q0 = *q0_;
    for (Eigen::Index i = 0; i < x_.size(); ++i) {
      x_[i] = q0[i] + th_ * D[i];
      v_[i] = D[i] * inv_h;
    }
  }
  // F, written as PositionMomentumStep evaluates it
  void form(Vector& r) const {
    const double b = 1.0 - th_;
    const Vector& p0 = *p0_;
    for (Eigen::Index i = 0; i < r.size(); ++i) r[i] = p0[i] + ((h_ * Lq_[i]) * b - Lv_[i]);
  }

  const Sys* L_;
  const Force* force_;
  double th_, h_, t_ = 0.0;
  const Vector* q0_ = nullptr;
  const Vector* p0_ = nullptr;
  double pscale_ = 0.0, q0size_ = 0.0;
  Vector x_, v_, Lq_, Lv_, F_;  // Lq_: G = L_q (+ F), what the equation reads
  Matrix Lqq_, Lqv_, Lvv_, Fq_, Fv_;
};

// The position-momentum step of the theta map for a run-time-sized Lagrangian Sys: the
// ThetaEquation solved by newton_drive (solvers/newton_driver.h) with a dense LU.
// K: the number of coordinates where it is known when the step is compiled (the runtime
// makes K = 1 and 2 for a written Lagrangian of so few): the same step, its workspace and
// its loops of fixed size; the state stays run-time sized. Sys::dim() must equal K.
// Refresh of the Jacobian: kept across steps (keep_jacobian), else kept within each step
// where K is known (a step that converges in two iterations then costs one Hessian of L
// and two gradients instead of two Hessians and a gradient, and forms dp from the last
// gradient), else formed at every iteration. Force: the type of a generalized force
// (ThetaEquation), NoForce for none.
template <class Sys, int K = Eigen::Dynamic, class Force = NoForce>
class DynamicThetaStep {
  static_assert(is_dynamic_system_v<Sys>, "DynamicThetaStep needs a run-time-sized system (dynamic_system.h)");

 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;

  static constexpr bool kForced = is_force_v<Force>;

  // keep_jacobian: the factorisation of an earlier step kept while it serves
  // (Refresh::across_steps); otherwise as the comment above says. force: the generalized
  // force F(t, q, v) (ThetaEquation), required where Force is not NoForce; each copy of
  // the step evaluates its own copy of it.
  DynamicThetaStep(Sys L, ThetaMap R, double h, StepOptions options = {}, bool keep_jacobian = false,
                   std::shared_ptr<const Force> force = nullptr)
      : L_(std::move(L)), R_(std::move(R)), h_(h), options_(options), force_(std::move(force)) {
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    const int n = L_.dim();
    if (K != Eigen::Dynamic && n != K)
      throw std::invalid_argument("DynamicThetaStep<" + std::to_string(K) + ">: a system of " + std::to_string(n) +
                                  " coordinates");
    if constexpr (kForced)
      if (!force_ || force_->dim() != n)
        throw std::invalid_argument("DynamicThetaStep: a forced step needs a force of the system's dimension");
    work_ = std::make_shared<Work>(L_, R_.theta(), h_, n, force_.get());
    refresh_ = keep_jacobian ? Refresh::across_steps : K != Eigen::Dynamic ? Refresh::within_step
                                                                           : Refresh::every_iteration;
    kept_ = std::make_shared<Kept>(n);
  }
  // A copy has its own equation and workspace (reading its own L); a factorisation kept
  // across steps is shared with it.
  DynamicThetaStep(const DynamicThetaStep& o)
      : L_(o.L_), R_(o.R_), h_(o.h_), options_(o.options_), force_(o.force_), refresh_(o.refresh_) {
    work_ = std::make_shared<Work>(L_, R_.theta(), h_, L_.dim(), force_.get());
    kept_ = refresh_ == Refresh::across_steps ? o.kept_ : std::make_shared<Kept>(L_.dim());
  }
  DynamicThetaStep& operator=(const DynamicThetaStep&) = delete;

  double step_size() const { return h_; }
  bool keeps_jacobian() const { return refresh_ == Refresh::across_steps; }
  // Forgets the kept factorisation (keep_jacobian): the next step forms one.
  void reset() const { kept_->state.valid = false; }
  const Sys& lagrangian() const { return L_; }
  const ThetaMap& map() const { return R_; }
  const StepOptions& options() const { return options_; }
  int dim() const { return L_.dim(); }
  // The force's control inputs (WrittenForce::controls()), 0 without a force.
  int controls() const {
    if constexpr (kForced) return force_->controls();
    return 0;
  }

  // The step of the adjoint map (1 - theta), of the same size (with a force: the forced
  // step of the adjoint map, ThetaEquation).
  DynamicThetaStep adjoint() const {
    return DynamicThetaStep(L_, R_.adjoint(), h_, options_, keeps_jacobian(), force_);
  }

  // The derivative of the step (q0, p0) -> (q1, p1) = (q0 + dq, p0 + dp) at the dq that
  // step() solved for, by the implicit function theorem on its equation (no finite
  // differences). F(dq; q0, p0) = p0 + h (1 - theta) L_q(x, v) - L_v(x, v) = 0 with
  // x = q0 + theta dq, v = dq / h, and F_D its Jacobian in dq (what the driver factors):
  //   d dq = -F_D^{-1} (F_q0 dq0 + dp0),   F_q0 = h (1 - theta) L_qq - L_vq,
  //   dp1  = dp0 + h L_qq (dq0 + theta d dq) + L_qv d dq     (p1 - p0 = h L_q(x, v)).
  // A (2n x 2n, the coordinates then the momenta, for rows and columns) receives
  // [dq1/dq0  dq1/dp0; dp1/dq0  dp1/dp0]. The step is the discrete flow of a discrete
  // Lagrangian, which is symplectic (Marsden and West, Acta Numerica 2001), so
  // A^T J A = J up to round-off and the tolerance dq was solved to. A does not depend on
  // p0. Returns false where F_D is singular (or not finite) at dq. F_D and L's blocks
  // come from the step's own ThetaEquation, in its workspace (so, as step(), not from
  // two threads at once). Allocates.
  // With a force F(t, q, v) the equation reads G = L_q + F for L_q (ThetaEquation), so
  // L_qq and L_qv above become G_q = L_qq + F_q and G_v = L_qv + F_v, except in F_q0's
  // L_vq (from L_v alone); t0 is the time the step starts at. A is then not symplectic.
  bool derivative(const V& q0, const V& dq, Eigen::MatrixXd& A) const { return derivative(0.0, q0, dq, A); }
  // (the signature of the steps whose derivative depends on p0 too, solvers/constrained_step.h)
  bool derivative(double t0, const V& q0, const V&, const V& dq, Eigen::MatrixXd& A) const {
    return derivative(t0, q0, dq, A);
  }
  bool derivative(double t0, const V& q0, const V& dq, Eigen::MatrixXd& A) const {
    return differentiate(t0, q0, dq, &A, nullptr);
  }

  // The derivative B = d(q1, p1)/du (2n x c) of the step in the force's control inputs
  // u (WrittenForce::controls(), held constant over the step), at the dq that step()
  // solved for: u enters only through F at the node, so with F_u = dF/du there
  //   d dq = -F_D^{-1} h (1 - theta) F_u du,   dp1 = h theta G_q d dq + G_v d dq + h F_u du.
  // Returns false where F_D is singular. Allocates.
  template <class Fo = Force, std::enable_if_t<is_force_v<Fo>, int> = 0>
  bool control_derivative(double t0, const V& q0, const V&, const V& dq, Eigen::MatrixXd& B) const {
    return differentiate(t0, q0, dq, nullptr, &B);
  }
  // A and, where B is not null, B (2n x controls(); 2n x 0 without a force) from one
  // Jacobian and one factorisation: what derivative() and control_derivative() give.
  bool derivatives(double t0, const V& q0, const V&, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    return differentiate(t0, q0, dq, &A, B);
  }

  // One step from (q0, p0); dq holds the starting guess on entry and q1 - q0 on return,
  // dp receives p1 - p0.
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    const int n = K == Eigen::Dynamic ? L_.dim() : K;
    if (!dynamic_detail::sizes_match(n, q0, p0, dq, s)) return s;
    if (dp.size() != n) dp.resize(n);
    Work& w = *work_;
    Kept& k = *kept_;
    try {
      w.q0 = q0;
      w.p0 = p0;
      w.D = dq;
      w.eq.begin(w.q0, w.p0, t);
      s = newton_drive(w.eq, k.lu, refresh_, options_, w.D, w.r, w.dx, w.J, k.state, w.start);
      dq = w.D;
      if (s.converged) {
        if (K != Eigen::Dynamic && refresh_ == Refresh::within_step && !kForced &&
            s.residual <= options_.residual_tolerance * s.scale)
          w.eq.momentum_after(w.dx, w.dp);  // (w.dx: the correction applied last)
        else
          w.eq.momentum(w.D, w.dp);
        dp = w.dp;
        if constexpr (kForced) s.work = w.eq.work(w.D);
        if (!std::isfinite(dynamic_detail::inf_norm(w.dp))) s.fail("non-finite momentum");
      }
    } catch (const std::domain_error& e) {
      s.fail(e.what());
      k.state.valid = false;
    }
    if (!s.converged && s.iterations == 0) s.iterations = 1;
    return s;
  }

 private:
  bool differentiate(double t0, const V& q0, const V& dq, Eigen::MatrixXd* A, Eigen::MatrixXd* B) const {
    const int n = L_.dim();
    if (q0.size() != n || dq.size() != n)
      throw std::invalid_argument("DynamicThetaStep::derivative: a state of " + std::to_string(q0.size()) +
                                  " coordinates (dq " + std::to_string(dq.size()) + "); the system has " +
                                  std::to_string(n));
    using M = Eigen::MatrixXd;
    const double th = R_.theta(), h = h_;
    Work& w = *work_;
    w.q0 = q0;
    w.p0.setZero();  // (F_D does not depend on p0)
    w.D = dq;
    w.eq.begin(w.q0, w.p0, t0);
    if (!std::isfinite(w.eq.jacobian(w.D, w.r, w.J))) return false;
    M Fu;
    if constexpr (kForced) {
      if (B) {
        const V x = q0 + th * dq, v = dq / h;
        V F(n);
        M Fq(n, n), Fv(n, n);
        w.force->jacobian(t0 + th * h, x, v, F, Fq, Fv, &Fu);
      }
    }
    const M FD = w.J;
    M Gq = w.eq.Lqq(), Gv = w.eq.Lqv();
    if constexpr (kForced) {
      Gq += w.eq.Fq();
      Gv += w.eq.Fv();
    }
    const Eigen::FullPivLU<M> lu(FD);
    if (!lu.isInvertible()) return false;
    if (A) {
      const M Lvq = w.eq.Lqv().transpose();
      const M Dq = -lu.solve(M(h * (1.0 - th) * Gq - Lvq));  // d dq / d q0
      const M Dp = -lu.inverse();                             // d dq / d p0
      const M I = M::Identity(n, n);
      A->resize(2 * n, 2 * n);
      A->topLeftCorner(n, n) = I + Dq;
      A->topRightCorner(n, n) = Dp;
      A->bottomLeftCorner(n, n) = h * Gq * (I + th * Dq) + Gv * Dq;
      A->bottomRightCorner(n, n) = I + (h * th) * Gq * Dp + Gv * Dp;
      if (!A->allFinite()) return false;
    }
    if (B) {
      if constexpr (kForced) {
        const M dD = -lu.solve(M(h * (1.0 - th) * Fu));
        B->resize(2 * n, Fu.cols());
        B->topRows(n) = dD;
        B->bottomRows(n) = h * th * Gq * dD + Gv * dD + h * Fu;
        return B->allFinite();
      } else {
        B->resize(2 * n, 0);
      }
    }
    return true;
  }

  using SV = Eigen::Matrix<double, K, 1>;
  using SM = Eigen::Matrix<double, K, K>;
  // The equation and the driver's workspace, sized once.
  struct Work {
    Work(const Sys& L, double theta, double h, int n, const Force* f)
        : force(f ? std::make_unique<Force>(*f) : nullptr), eq(L, theta, h, force.get()) {
      q0.resize(n);
      p0.resize(n);
      D.resize(n);
      r.resize(n);
      dx.resize(n);
      dp.resize(n);
      start.resize(n);
      J.resize(n, n);
    }
    std::unique_ptr<Force> force;  // this step's copy of the force (its workspace)
    ThetaEquation<Sys, K, Force> eq;
    SV q0, p0, D, r, dx, dp, start;
    SM J;
  };
  // The factorisation and what the driver keeps of it (shared by copies where it is kept
  // across steps: they then use one factorisation, from one thread at a time).
  struct Kept {
    explicit Kept(int n) : lu(n) {}
    DenseLUOf<K> lu;
    DriverState state;
  };

  Sys L_;
  ThetaMap R_;
  double h_;
  StepOptions options_;
  std::shared_ptr<const Force> force_;
  Refresh refresh_ = Refresh::every_iteration;
  std::shared_ptr<Work> work_;
  std::shared_ptr<Kept> kept_;
};

// The Hamiltonian equation (Eq. 5.1) of the theta map for a run-time-sized Hamiltonian
// Ham (WrittenDynamicHamiltonian, LegendreDynamicHamiltonian<Sys>, or any type of the
// concept with (q, p) as its blocks), for the increments y = (dq, dp):
//   F(y) = (dq - h H_p(Q, P),  dp + h H_q(Q, P)),   Q = q0 + theta dq,
// with P = p0 + (1 - theta) dp for the cotangent lift of the theta map on Q, and
// P = p0 + theta dp for the theta map given directly on T*Q (`on_bundle`, the map of
// OnCotangentBundle<ThetaMap> in solvers/hamiltonian_step.h: the theta method, not
// symplectic unless theta = 1/2). The Jacobian (H_pq = H_qp^T, b the weight of dp in P):
//   [ I - h theta H_pq      -h b H_pp   ]
//   [ h theta H_qq           I + h b H_qp ].
// A Hamiltonian in t (has_time: the Legendre transform of L(t, q, v)) is evaluated at the
// node's time t0 + theta h, as the lagrangian form's ThetaEquation evaluates L.
// A generalized force F(t, q, v) (Force; NoForce: none) joins the momentum equation at
// the node, with the velocity there, V = H_p(Q, P), and t = t0 + theta h:
//   dp + h H_q(Q, P) - h F(t, Q, V) = 0,
// the Hamilton equations of the forced system (p' = -H_q + F) by the same lift; its
// Jacobian rows gain -h theta (F_q + F_v H_pq) and -h b F_v H_pp. The work of the force
// over the step is <F, dq> at the last evaluation.
// The equation of solvers/newton_driver.h.
template <class Ham, class Force = NoForce>
class HamiltonianThetaEquation {
 public:
  using Vector = Eigen::VectorXd;
  using Matrix = Eigen::MatrixXd;
  static constexpr bool kForced = is_force_v<Force>;

  HamiltonianThetaEquation(const Ham& H, double theta, double h, bool on_bundle, const Force* force = nullptr)
      : H_(&H), force_(force), th_(theta), b_(on_bundle ? theta : 1.0 - theta), h_(h) {
    if (kForced && !force_) throw std::invalid_argument("HamiltonianThetaEquation: a forced equation needs its force");
    const int n = H.dim();
    x_.resize(n);
    p_.resize(n);
    Hq_.resize(n);
    Hp_.resize(n);
    Hqq_.resize(n, n);
    Hqp_.resize(n, n);
    Hpp_.resize(n, n);
    if constexpr (kForced) {
      F_.resize(n);
      Fq_.resize(n, n);
      Fv_.resize(n, n);
    }
  }
  // The start of the step, at time t0 (read by a force and by H(t, q, p), both at the
  // node's time t0 + theta h): the scale of the terms, |h| max(|H_p|, |H_q|) at (q0, p0).
  void begin(const Vector& q0, const Vector& p0, double t0 = 0.0) {
    q0_ = &q0;
    p0_ = &p0;
    t_ = t0 + th_ * h_;
    if constexpr (has_time<Ham>::value) H_->set_time(t_);
    H_->gradient(q0, p0, Hq_, Hp_);
    s0_ = std::fabs(h_) * std::fmax(dynamic_detail::inf_norm(Hp_), dynamic_detail::inf_norm(Hq_));
    x0_ = std::fmax(dynamic_detail::inf_norm(q0), dynamic_detail::inf_norm(p0));
  }
  void residual(const Vector& y, Vector& r) {
    at(y);
    H_->gradient(x_, p_, Hq_, Hp_);
    if constexpr (kForced) {
      force_->value(t_, x_, Hp_, F_);
      Hq_ -= F_;
    }
    form(y, r);
  }
  double jacobian(const Vector& y, Vector& r, Matrix& J) {
    at(y);
    H_->hessian(x_, p_, Hq_, Hp_, Hqq_, Hqp_, Hpp_);
    if constexpr (kForced) {
      force_->jacobian(t_, x_, Hp_, F_, Fq_, Fv_);
      Hq_ -= F_;
    }
    form(y, r);
    const Eigen::Index n = x_.size();
    const double ht = h_ * th_, hb = h_ * b_;
    for (Eigen::Index j = 0; j < n; ++j)
      for (Eigen::Index i = 0; i < n; ++i) {
        J(i, j) = (i == j ? 1.0 : 0.0) - ht * Hqp_(j, i);
        J(i, n + j) = -hb * Hpp_(i, j);
        J(n + i, j) = ht * Hqq_(i, j);
        J(n + i, n + j) = (i == j ? 1.0 : 0.0) + hb * Hqp_(i, j);
      }
    if constexpr (kForced) {  // dV/dQ = H_pq = H_qp^T, dV/dP = H_pp
      J.bottomLeftCorner(n, n) -= ht * (Fq_ + Fv_ * Hqp_.transpose());
      J.bottomRightCorner(n, n) -= hb * (Fv_ * Hpp_);
    }
    const double m = dynamic_detail::inf_norm(J);
    return std::isfinite(m) ? m : INFINITY;
  }
  double scale(double yn, double Jmax) const { return s0_ + Jmax * yn; }
  double offset() const { return x0_; }
  // The force's work over the step, <F, dq>, F from the last evaluation (0 without one).
  double work(const Vector& y) const {
    if constexpr (kForced) return F_.dot(y.head(F_.size()));
    return (void)y, 0.0;
  }
  // dF/dP (2n x n) at the point of the last jacobian(): the columns of the momentum P at
  // which H is evaluated, [-h H_pp; h H_qp - h F_v H_pp] (the constrained step moves the
  // start momentum p0, and so P, by its multipliers: solvers/constrained_hamiltonian_step.h).
  void momentum_columns(Matrix& out) const {
    const Eigen::Index n = x_.size();
    out.resize(2 * n, n);
    out.topRows(n) = -h_ * Hpp_;
    out.bottomRows(n) = h_ * Hqp_;
    if constexpr (kForced) out.bottomRows(n).noalias() -= h_ * (Fv_ * Hpp_);
  }
  // dF/dQ (2n x n) at the point of the last jacobian(): [-h H_pq; h H_qq - h (F_q + F_v H_pq)]
  // (J's first n columns are I + theta dF/dQ). With momentum_columns, the columns of q0
  // and p0, which move Q and P by the identity (the step's derivative).
  void position_columns(Matrix& out) const {
    const Eigen::Index n = x_.size();
    out.resize(2 * n, n);
    out.topRows(n) = -h_ * Hqp_.transpose();
    out.bottomRows(n) = h_ * Hqq_;
    if constexpr (kForced) out.bottomRows(n).noalias() -= h_ * (Fq_ + Fv_ * Hqp_.transpose());
  }
  // dF/du (2n x c) at the point of the last jacobian(), the force's control inputs u held
  // over the step: [0; -h F_u(t, Q, V)]. Evaluates the force's Jacobian again.
  void control_columns(Matrix& out) const {
    const Eigen::Index n = x_.size();
    if constexpr (kForced) {
      Vector F(n);
      Matrix Fq(n, n), Fv(n, n), Fu;
      force_->jacobian(t_, x_, Hp_, F, Fq, Fv, &Fu);
      out.setZero(2 * n, Fu.cols());
      out.bottomRows(n) = -h_ * Fu;
    } else {
      out.resize(2 * n, 0);
    }
  }

 private:
  void at(const Vector& y) {
    const Eigen::Index n = x_.size();
    for (Eigen::Index i = 0; i < n; ++i) {
      x_[i] = (*q0_)[i] + th_ * y[i];
      p_[i] = (*p0_)[i] + b_ * y[n + i];
    }
  }
  void form(const Vector& y, Vector& r) const {
    const Eigen::Index n = x_.size();
    for (Eigen::Index i = 0; i < n; ++i) {
      r[i] = y[i] - h_ * Hp_[i];
      r[n + i] = y[n + i] + h_ * Hq_[i];
    }
  }

  const Ham* H_;
  const Force* force_;
  double th_, b_, h_, t_ = 0.0;
  const Vector* q0_ = nullptr;
  const Vector* p0_ = nullptr;
  double s0_ = 0.0, x0_ = 0.0;
  Vector x_, p_, Hq_, Hp_, F_;  // Hq_: H_q (- F), what the equation reads
  Matrix Hqq_, Hqp_, Hpp_, Fq_, Fv_;
};

// The Hamiltonian step of the theta map for a run-time-sized Hamiltonian: the
// HamiltonianThetaEquation solved by newton_drive with a dense LU, a Jacobian at every
// iteration. Force: the type of a generalized force (HamiltonianThetaEquation), NoForce
// for none.
template <class Ham, class Force = NoForce>
class DynamicHamiltonianThetaStep {
  static_assert(is_dynamic_system_v<Ham>,
                "DynamicHamiltonianThetaStep needs a run-time-sized Hamiltonian (dynamic_system.h)");

 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;

  static constexpr bool kForced = is_force_v<Force>;

  // force: required where Force is not NoForce; each copy of the step evaluates its own
  // copy of it
  DynamicHamiltonianThetaStep(Ham H, ThetaMap R, double h, StepOptions options = {}, bool on_bundle = false,
                              std::shared_ptr<const Force> force = nullptr)
      : H_(std::move(H)), R_(std::move(R)), h_(h), options_(options), on_bundle_(on_bundle), force_(std::move(force)) {
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    if constexpr (kForced)
      if (!force_ || force_->dim() != H_.dim())
        throw std::invalid_argument("DynamicHamiltonianThetaStep: a forced step needs a force of the system's dimension");
    work_ = std::make_shared<Work>(H_, R_.theta(), h_, on_bundle_, force_.get());
  }
  // A copy has its own equation and workspace, reading its own H.
  DynamicHamiltonianThetaStep(const DynamicHamiltonianThetaStep& o)
      : H_(o.H_), R_(o.R_), h_(o.h_), options_(o.options_), on_bundle_(o.on_bundle_), force_(o.force_) {
    work_ = std::make_shared<Work>(H_, R_.theta(), h_, on_bundle_, force_.get());
  }
  DynamicHamiltonianThetaStep& operator=(const DynamicHamiltonianThetaStep&) = delete;

  double step_size() const { return h_; }
  const Ham& hamiltonian() const { return H_; }
  const ThetaMap& map() const { return R_; }
  const StepOptions& options() const { return options_; }
  int dim() const { return H_.dim(); }

  // The step of the adjoint map (1 - theta), of the same size.
  DynamicHamiltonianThetaStep adjoint() const {
    return DynamicHamiltonianThetaStep(H_, R_.adjoint(), h_, options_, on_bundle_, force_);
  }

  // The force's control inputs (WrittenForce::controls()), 0 without a force.
  int controls() const {
    if constexpr (kForced) return force_->controls();
    return 0;
  }

  // The derivative A = d(q1, p1)/d(q0, p0) (2n x 2n, the coordinates then the momenta)
  // of the step at its solution, by the implicit function theorem on its equation
  // F(y; q0, p0) = 0, y = (dq, dp) (no finite differences). Q = q0 + theta dq and
  // P = p0 + b dp move with q0 and p0 by the identity, so with G = [dF/dQ  dF/dP]
  // (HamiltonianThetaEquation::position_columns, momentum_columns) the driver's Jacobian
  // is F_y = I + [theta dF/dQ  b dF/dP], and
  //   dy/d(q0, p0) = -F_y^{-1} G,   A = I + dy/d(q0, p0).
  // The interface passes dq alone (as to the lagrangian form's steps): (dq, dp) are this
  // step's last solve's where that solve was from the same (t0, q0, p0) to dq up to
  // round-off (a run differentiates the step it has just taken, dq = q1 - q0), else
  // found again by solving the step from (q0, p0) with dq as the guess; in the step's
  // own workspace (so, as step(), not from two threads at once). The cotangent lift of the
  // theta map is symplectic (paper Sec. 5.1), so A^T J A = J up to round-off for an
  // unforced H; on T*Q itself (on_bundle) only at theta = 1/2. Returns false where the
  // solve fails or F_y is singular. Allocates.
  bool derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A) const {
    return differentiate(t0, q0, p0, dq, &A, nullptr);
  }
  // B = d(q1, p1)/du (2n x c) in the force's control inputs, held over the step:
  // -F_y^{-1} [0; -h F_u].
  template <class Fo = Force, std::enable_if_t<is_force_v<Fo>, int> = 0>
  bool control_derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& B) const {
    return differentiate(t0, q0, p0, dq, nullptr, &B);
  }
  // A and, where B is not null, B from one solve and one factorisation.
  bool derivatives(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    return differentiate(t0, q0, p0, dq, &A, B);
  }

  // One step from (q0, p0); (dq, dp) hold the starting guess on entry and the
  // increments on return.
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    const int n = H_.dim();
    if (!dynamic_detail::sizes_match(n, q0, p0, dq, s)) return s;
    if (dp.size() != n) dp.setZero(n);
    Work& w = *work_;
    w.y.head(n) = dq;
    w.y.tail(n) = dp;
    w.last.solved = false;
    try {
      w.eq.begin(q0, p0, t);
      s = newton_drive(w.eq, w.lu, Refresh::every_iteration, options_, w.y, w.r, w.dx, w.J, w.state, w.start);
      if constexpr (kForced) s.work = w.eq.work(w.y);
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    dq = w.y.head(n);
    dp = w.y.tail(n);
    if (s.converged) w.last.remember(t, q0, p0, w.y);
    return s;
  }

 private:
  bool differentiate(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd* A, Eigen::MatrixXd* B) const {
    const int n = H_.dim();
    if (q0.size() != n || p0.size() != n || dq.size() != n)
      throw std::invalid_argument("DynamicHamiltonianThetaStep::derivative: a state of " + std::to_string(q0.size()) +
                                  " coordinates (p0 " + std::to_string(p0.size()) + ", dq " +
                                  std::to_string(dq.size()) + "); the system has " + std::to_string(n));
    using M = Eigen::MatrixXd;
    Work& w = *work_;
    V d = dq, e = V::Zero(n);
    if (w.last.is(t0, q0, p0, dq))
      d = w.last.y.head(n), e = w.last.y.tail(n);
    else if (!step(t0, q0, p0, d, e).converged)
      return false;
    w.y.head(n) = d;
    w.y.tail(n) = e;
    w.eq.begin(q0, p0, t0);
    if (!std::isfinite(w.eq.jacobian(w.y, w.r, w.J))) return false;
    const Eigen::FullPivLU<M> lu(w.J);
    if (!lu.isInvertible()) return false;
    M cols;
    if (A) {
      M G(2 * n, 2 * n);
      w.eq.position_columns(cols);
      G.leftCols(n) = cols;
      w.eq.momentum_columns(cols);
      G.rightCols(n) = cols;
      *A = M::Identity(2 * n, 2 * n) - lu.solve(G);
      if (!A->allFinite()) return false;
    }
    if (B) {
      w.eq.control_columns(cols);
      *B = cols.cols() > 0 ? M(-lu.solve(cols)) : M(2 * n, 0);
      if (!B->allFinite()) return false;
    }
    return true;
  }

  struct Work {
    Work(const Ham& H, double theta, double h, bool on_bundle, const Force* f)
        : force(f ? std::make_unique<Force>(*f) : nullptr), eq(H, theta, h, on_bundle, force.get()) {
      const int m = 2 * H.dim();
      y.resize(m);
      r.resize(m);
      dx.resize(m);
      start.resize(m);
      J.resize(m, m);
      lu.resize(m);
    }
    std::unique_ptr<Force> force;  // this step's copy of the force (its workspace)
    HamiltonianThetaEquation<Ham, Force> eq;
    Eigen::VectorXd y, r, dx, start;
    Eigen::MatrixXd J;
    DenseLU lu;
    DriverState state;
    // the last converged solve: from (t, q0, p0) to y = (dq, dp)
    struct LastSolve {
      bool solved = false;
      double t = 0.0;
      Eigen::VectorXd q0, p0, y;
      void remember(double t_, const V& q, const V& p, const Eigen::VectorXd& y_) {
        t = t_, q0 = q, p0 = p, y = y_;
        solved = true;
      }
      // whether it was from (t_, q, p) to dq, which a run passes as q1 - q0: the solve's
      // dq to the round-off of forming q1 (a compensated sum) and subtracting q0
      bool is(double t_, const V& q, const V& p, const V& dq) const {
        if (!solved || t != t_ || q0 != q || p0 != p) return false;
        const double eps = std::numeric_limits<double>::epsilon();
        for (Eigen::Index i = 0; i < dq.size(); ++i)
          if (!(std::fabs(dq[i] - y[i]) <= 8 * eps * (std::fabs(q[i]) + std::fabs(y[i])))) return false;
        return true;
      }
    } last;
  };

  Ham H_;
  ThetaMap R_;
  double h_;
  StepOptions options_;
  bool on_bundle_;
  std::shared_ptr<const Force> force_;
  std::shared_ptr<Work> work_;
};

}  // namespace dvm
