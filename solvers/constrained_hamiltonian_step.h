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

  // The constrained step of the adjoint map (1 - theta).
  ConstrainedHamiltonianThetaStep adjoint() const {
    return ConstrainedHamiltonianThetaStep(H_, L_, R_.adjoint(), h_, con_, options_, momentum_, force_);
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
