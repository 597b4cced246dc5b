// The SODE forms (paper Sec. 4) and the Newmark family (Sec. 4.1) for run-time-sized
// separable systems (mechanics/dynamic_system.h): L(q, v) = v^T M v / 2 - U(q) with M
// constant and positive definite (n bodies, a written Lagrangian whose text is
// separable, U(q) or U(t, q)). solvers/sode_step.h states the forms; here they are written once over the
// system's gradient and Hessian blocks and solved by newton_drive.
//
// The Euler-Lagrange equations of a separable L are the SODE Gamma(q, v) = (v, a(q)),
// a = M^{-1} L_q(q), whose Jacobian in (q, v) is [[0, I], [A, 0]] with A = M^{-1} L_qq:
// second derivatives of L, which the run-time-sized systems give. (For an L that is not
// separable a = L_vv^{-1} (L_q - L_vq v), and its Jacobian needs L's third derivatives,
// which they do not give; the runtime refuses those systems for these forms.)
//
// The maps on TQ: the tangent lift of the theta map is the theta map of TQ; for a
// separable L (FL(q, v) = (q, M v), linear) the Legendre lift R_d^L of the theta map
// (Prop. 5.3; mechanics/legendre_lift.h) takes the base point's velocity at 1 - theta,
// as the cotangent lift takes its momentum (theta p0 + (1 - theta) p1). So both are
//   R^1(X, W) = X - (theta W_q, theta_v W_v),  R^2(X, W) = X + ((1 - theta) W_q, (1 - theta_v) W_v),
// with theta_v = theta (tangent lift) or 1 - theta (Legendre lift; the two agree at
// theta = 1/2, Cor. 5.4). With Y = (q, v), the increment dY = Y1 - Y0 = (dq, dv) and
// g(Y) = h Gamma(Y):
//   sode1 (Eq. 4.1), R^2(Y0, g(Y0)) = R^1(Y1, g(Y1)):
//       F_q = dq - theta g_q(Y1) - (1 - theta) g_q(Y0),
//       F_v = dv - theta_v g_v(Y1) - (1 - theta_v) g_v(Y0),
//       dF/ddY = [[I, -theta h I], [-theta_v h A(q1), I]];
//   sode2 (Eq. 4.2), the field sampled at the base point X = (q0 + theta dq, v0 + theta_v dv):
//       F(dY) = dY - g(X),
//       dF/ddY = [[I, -theta_v h I], [-theta h A(q0 + theta dq), I]];
//   newmark (gamma, beta), sode1 through the paper's map on TQ (NewmarkMap, with
//     c = (h/2)(gamma - 2 beta)):
//       F_q = dq - (g_q(Y0) + g_q(Y1))/2 + c (g_v(Y1) - g_v(Y0)),
//       F_v = dv - gamma g_v(Y1) - (1 - gamma) g_v(Y0),
//       dF/ddY = [[I + c h A(q1), -(h/2) I], [-gamma h A(q1), I]].
// Each residual is formed in the order SodeStep forms it (through the maps'
// displacements), and judged, as there, against |h| max|Gamma(Y0)| + max|J| max|dY|.
// A generalized force F(t, q, v) (Force; NoForce: none, and no trace of one in the
// compiled equation) joins the acceleration, a = M^{-1} (L_q + F) (the forced
// Euler-Lagrange equations, Marsden and West, Acta Numerica 2001, Sec. 3.2), sampled
// where the field is: Y0 at t0, Y1 at t0 + h, the base point at t0 + theta h (sode2).
// Its Jacobian adds B = M^{-1} F_v to the velocity columns and M^{-1} F_q to A: with
// (wq, wv) the weights of dq and dv in the sample point Z ((1, 1), or (theta, theta_v)
// for sode2), kappa the weight of g_v(Z) in F_v (theta_v, 1 or gamma) and c Newmark's
// shift (0 for the sode forms),
//       dF/ddY = [[I + c wq h A, -b h I + c wv h B], [-kappa wq h A, I - kappa wv h B]],
// b the weight of v(Z) in F_q as above. The work of the force over the step is
// <F_bar, dq>, F_bar the force with the weights of the velocity update (theta_v F(Y1) +
// (1 - theta_v) F(Y0), F(Z), gamma F(Y1) + (1 - gamma) F(Y0)), so that M dv = h (the
// same weighting of L_q) + h F_bar: for a quadratic potential sode2 at theta = 1/2 and
// Newmark (1/2, 1/4) then keep E_1 - E_0 = <F_bar, dq> exactly, and sode2 at 1/2 is the
// midpoint position-momentum step with its force (solvers/dynamic_step.h) on a
// separable L.
// A Lagrangian in t (has_time: v^T M v / 2 - U(t, q), M constant in q and t) is
// evaluated where the force is, at the sample point's time, and p1 = L_v at t0 + h; its
// L_q(t, q) then enters the field as a force that depends on q alone would.
// Adjoints: the sode step of the theta map's adjoint (1 - theta) is the adjoint step
// (the lift of the adjoint map, Prop. 3.3): theta and theta_v go to 1 - theta and
// 1 - theta_v; Newmark's adjoint is (1 - gamma, 1/2 - gamma + beta). All are the same
// type, so ComposedStep composes one type.
//
// The step takes (q0, p0) as integrate() does: v0 = M^{-1} p0, the increments solved by
// Newton's method (a Jacobian at every iteration, dense LU of 2n unknowns, as
// solve_newton does for the fixed-size SodeStep), then p1 = L_v(q1, v1) (VelocityFormStep).
// The guess of dv is the last step's. Workspace is allocated at construction; a step
// allocates nothing. One object must not be used from two threads at once.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

#include "mechanics/dynamic_system.h"
#include "solvers/dynamic_step.h"
#include "solvers/newton_driver.h"

namespace dvm {

// M^{-1} of a separable system, formed once (from M's Cholesky factorisation) and shared
// by a step, its copies and its stages: the field applies it as a product, which for
// the small systems these steps serve costs less than the triangular solves of the
// factorisation at every evaluation.
using MassInverse = std::shared_ptr<const Eigen::MatrixXd>;

// Which discretization of the SODE a DynamicSodeStep takes.
struct SodeScheme {
  enum class Kind { sode1, sode2, newmark };
  Kind kind = Kind::sode2;
  double theta = 0.5;    // sode1, sode2: the theta map lifted
  double theta_v = 0.5;  // the velocities' theta: theta (tangent lift) or 1 - theta (Legendre lift)
  double gamma = 0.5, beta = 0.25;  // newmark

  // sode1 (first) or sode2 through the tangent lift of the theta map, or its Legendre lift
  static SodeScheme sode(bool first, double theta, bool legendre = false) {
    return {first ? Kind::sode1 : Kind::sode2, theta, legendre ? 1.0 - theta : theta, 0.5, 0.25};
  }
  static SodeScheme newmark(double gamma, double beta) { return {Kind::newmark, 0.5, 0.5, gamma, beta}; }
  // The adjoint method (beta* of Newmark may leave [0, 1/2]: the adjoint stage of a
  // composition, not a user's choice).
  SodeScheme adjoint() const {
    if (kind == Kind::newmark) return newmark(1.0 - gamma, 0.5 - gamma + beta);
    return {kind, 1.0 - theta, 1.0 - theta_v, gamma, beta};
  }
};

// The equation of solvers/newton_driver.h in the increment dY = (dq, dv) of a
// separable run-time-sized system (the top of this file), with the force F(t, q, v) of
// type Force (NoForce: none).
template <class Sys, class Force = NoForce>
class SeparableSodeEquation {
 public:
  using Vector = Eigen::VectorXd;
  using Matrix = Eigen::MatrixXd;
  static constexpr bool kForced = is_force_v<Force>;

  // Minv: M^{-1} (shared by the copies of a step and its stages); force: required where
  // Force is not NoForce.
  SeparableSodeEquation(const Sys& L, MassInverse Minv, SodeScheme scheme, double h, const Force* force = nullptr)
      : L_(&L), force_(force), Minv_(std::move(Minv)), sc_(scheme), h_(h) {
    if (kForced && !force_) throw std::invalid_argument("SeparableSodeEquation: a forced equation needs its force");
    const int n = L.dim();
    q0_.resize(n);
    v0_.resize(n);
    g0q_.resize(n);
    g0v_.resize(n);
    zq_.resize(n);
    zv_.resize(n);
    gq_.resize(n);
    gv_.resize(n);
    Lq_.resize(n);
    Lv_.resize(n);
    Lqq_.resize(n, n);
    Lqv_.resize(n, n);
    Lvv_.resize(n, n);
    A_.resize(n, n);
    if constexpr (kForced) {
      F0_.resize(n);
      Fz_.resize(n);
      Fq_.resize(n, n);
      Fv_.resize(n, n);
      B_.resize(n, n);
    }
  }
  // The step starts at (q0, v0) at time t0: g(Y0) and the scales.
  void begin(double t0, const Vector& q0, const Vector& v0) {
    t0_ = t0;
    q0_ = q0;
    v0_ = v0;
    field(t0_, q0_, v0_, g0q_, g0v_);
    if constexpr (kForced) F0_ = Fz_;
    s0_ = std::fmax(dynamic_detail::inf_norm(g0q_), dynamic_detail::inf_norm(g0v_));
    x0_ = std::fmax(dynamic_detail::inf_norm(q0_), dynamic_detail::inf_norm(v0_));
  }
  void residual(const Vector& dY, Vector& r) {
    at(dY);
    field(sample_time(), zq_, zv_, gq_, gv_);
    form(dY, r);
  }
  double jacobian(const Vector& dY, Vector& r, Matrix& J) {
    at(dY);
    if constexpr (has_time<Sys>::value) L_->set_time(sample_time());
    L_->hessian(zq_, zv_, Lq_, Lv_, Lqq_, Lqv_, Lvv_);
    if constexpr (kForced) {
      force_->jacobian(sample_time(), zq_, zv_, Fz_, Fq_, Fv_);
      Lq_ += Fz_;
      Lqq_ += Fq_;
      B_.noalias() = Minv_->lazyProduct(Fv_);  // B = M^{-1} F_v
    }
    from_gradient(zv_, gq_, gv_);
    form(dY, r);
    A_.noalias() = Minv_->lazyProduct(Lqq_);  // A = M^{-1} (L_qq + F_q)
    const Eigen::Index n = zq_.size();
    const double h = h_;
    // the blocks of dF/ddY (the top of this file)
    double aq, bq, av;  // J_qq = I + aq h A, J_qv = bq h I, J_vq = av h A
    double cv = 0.0, kv = 0.0;  // with a force: J_qv += cv h B, J_vv = I + kv h B
    if (sc_.kind == SodeScheme::Kind::newmark) {
      aq = shift();
      bq = -0.5;
      av = -sc_.gamma;
      cv = aq;
      kv = av;
    } else if (sc_.kind == SodeScheme::Kind::sode1) {
      aq = 0.0;
      bq = -sc_.theta;
      av = -sc_.theta_v;
      kv = av;
    } else {
      aq = 0.0;
      bq = -sc_.theta_v;
      av = -sc_.theta;
      kv = -sc_.theta_v;
    }
    J.setZero();
    for (Eigen::Index j = 0; j < n; ++j) {
      for (Eigen::Index i = 0; i < n; ++i) {
        J(i, j) = aq * h * A_(i, j);
        J(n + i, j) = av * h * A_(i, j);
        if constexpr (kForced) {
          J(i, n + j) = cv * h * B_(i, j);
          J(n + i, n + j) = kv * h * B_(i, j);
        }
      }
      J(j, j) += 1.0;
      J(j, n + j) += bq * h;
      J(n + j, n + j) += 1.0;
    }
    const double m = dynamic_detail::inf_norm(J);
    return std::isfinite(m) ? m : INFINITY;
  }
  double scale(double xn, double Jmax) const { return s0_ + Jmax * xn; }
  double offset() const { return x0_; }

  // The work of the force over the step, <F_bar, dq> (the top of this file), at the
  // increment dY: the force at the sample point evaluated there again (0 without one).
  double work(const Vector& dY) {
    if constexpr (kForced) {
      at(dY);
      force_->value(sample_time(), zq_, zv_, Fz_);
      const Eigen::Index n = zq_.size();
      const double w1 = sc_.kind == SodeScheme::Kind::sode2    ? 1.0
                        : sc_.kind == SodeScheme::Kind::sode1 ? sc_.theta_v
                                                               : sc_.gamma;
      double W = 0.0;
      for (Eigen::Index i = 0; i < n; ++i) W += (w1 * Fz_[i] + (1.0 - w1) * F0_[i]) * dY[i];
      return W;
    }
    return (void)dY, 0.0;
  }

 private:
  double shift() const { return 0.5 * h_ * (sc_.gamma - 2.0 * sc_.beta); }
  // The time of the sample point Z (at()): t0 + h, or t0 + theta h for sode2's base point.
  double sample_time() const { return t0_ + (sc_.kind == SodeScheme::Kind::sode2 ? sc_.theta : 1.0) * h_; }
  // The point Z where the field is sampled: Y1 = Y0 + dY, or the base point
  // (q0 + theta dq, v0 + theta_v dv) (sode2).
  void at(const Vector& dY) {
    const Eigen::Index n = zq_.size();
    if (sc_.kind != SodeScheme::Kind::sode2) {
      for (Eigen::Index i = 0; i < n; ++i) {
        zq_[i] = q0_[i] + dY[i];
        zv_[i] = v0_[i] + dY[n + i];
      }
      return;
    }
    const double wq = sc_.theta, wv = sc_.theta_v;
    for (Eigen::Index i = 0; i < n; ++i) {
      zq_[i] = q0_[i] + wq * dY[i];
      zv_[i] = v0_[i] + wv * dY[n + i];
    }
  }
  // g(Y) = h Gamma(t, q, v) = h (v, M^{-1} (L_q(q, v) + F(t, q, v))) into (gq, gv); the
  // force in Fz_
  void field(double t, const Vector& q, const Vector& v, Vector& gq, Vector& gv) {
    if constexpr (has_time<Sys>::value) L_->set_time(t);
    L_->gradient(q, v, Lq_, Lv_);
    if constexpr (kForced) {
      force_->value(t, q, v, Fz_);
      Lq_ += Fz_;
    } else {
      (void)t;
    }
    from_gradient(v, gq, gv);
  }
  // the same from L_q (plus F) of the last evaluation, at the point of velocity v
  void from_gradient(const Vector& v, Vector& gq, Vector& gv) {
    gv.noalias() = Minv_->lazyProduct(Lq_);
    gq = h_ * v;
    gv *= h_;
  }
  // F(dY) from g(Y0) and g(Z)
  void form(const Vector& dY, Vector& r) const {
    const Eigen::Index n = zq_.size();
    if (sc_.kind == SodeScheme::Kind::sode2) {
      for (Eigen::Index i = 0; i < n; ++i) {
        r[i] = dY[i] - gq_[i];
        r[n + i] = dY[n + i] - gv_[i];
      }
    } else if (sc_.kind == SodeScheme::Kind::sode1) {
      const double th = sc_.theta, b = 1.0 - th, tv = sc_.theta_v, bv = 1.0 - tv;
      for (Eigen::Index i = 0; i < n; ++i) {
        r[i] = (dY[i] + -th * gq_[i]) - b * g0q_[i];
        r[n + i] = (dY[n + i] + -tv * gv_[i]) - bv * g0v_[i];
      }
    } else {
      const double c = shift(), gm = sc_.gamma, b = 1.0 - gm;
      for (Eigen::Index i = 0; i < n; ++i) {
        r[i] = (dY[i] + (-0.5 * gq_[i] + c * gv_[i])) - (0.5 * g0q_[i] + c * g0v_[i]);
        r[n + i] = (dY[n + i] + -gm * gv_[i]) - b * g0v_[i];
      }
    }
  }

  const Sys* L_;
  const Force* force_;
  MassInverse Minv_;
  SodeScheme sc_;
  double h_;
  double t0_ = 0.0, s0_ = 0.0, x0_ = 0.0;
  Vector q0_, v0_, g0q_, g0v_, zq_, zv_, gq_, gv_, Lq_, Lv_;
  Matrix Lqq_, Lqv_, Lvv_, A_;
  Vector F0_, Fz_;     // the force at Y0 and at the last sample point (forced only)
  Matrix Fq_, Fv_, B_;  // its Jacobians there, B = M^{-1} F_v
};

// The sode1, sode2 and Newmark steps of a separable run-time-sized system Sys in the
// (q, p) contract of integrate() (the top of this file), with the force F(t, q, v) of
// type Force (NoForce: none; with one, each step reports the force's work).
template <class Sys, class Force = NoForce>
class DynamicSodeStep {
 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;
  static constexpr bool kForced = is_force_v<Force>;

  // M^{-1} for the steps of L: L_vv at (q, v), which a separable L has the same
  // everywhere, inverted through its Cholesky factorisation. Throws
  // std::invalid_argument where it is not positive definite.
  static MassInverse mass_inverse(const Sys& L, const V& q, const V& v) {
    const int n = L.dim();
    V Lq(n), Lv(n);
    Eigen::MatrixXd Lqq(n, n), Lqv(n, n), Lvv(n, n);
    L.hessian(q, v, Lq, Lv, Lqq, Lqv, Lvv);
    const Eigen::LLT<Eigen::MatrixXd> f(Lvv);
    if (f.info() != Eigen::Success || !Lvv.allFinite())
      throw std::invalid_argument("DynamicSodeStep: the velocity Hessian d2L/dv2 is not positive definite");
    return std::make_shared<const Eigen::MatrixXd>(f.solve(Eigen::MatrixXd::Identity(n, n)));
  }

  // force: required where Force is not NoForce; each copy of the step evaluates its own
  // copy of it (the force's workspace).
  DynamicSodeStep(Sys L, MassInverse Minv, SodeScheme scheme, double h, StepOptions options = {},
                  std::shared_ptr<const Force> force = nullptr)
      : L_(std::move(L)), Minv_(std::move(Minv)), sc_(scheme), h_(h), options_(options), force_(std::move(force)) {
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    if (!Minv_ || Minv_->rows() != L_.dim())
      throw std::invalid_argument("DynamicSodeStep: M^{-1} must be of the system's size");
    if constexpr (kForced)
      if (!force_ || force_->dim() != L_.dim())
        throw std::invalid_argument("DynamicSodeStep: a forced step needs a force of the system's size");
    work_ = std::make_shared<Work>(L_, Minv_, sc_, h_, force_.get());
  }
  // A copy has its own workspace and equation (reading its own L).
  DynamicSodeStep(const DynamicSodeStep& o)
      : L_(o.L_), Minv_(o.Minv_), sc_(o.sc_), h_(o.h_), options_(o.options_), force_(o.force_) {
    work_ = std::make_shared<Work>(L_, Minv_, sc_, h_, force_.get());
  }
  DynamicSodeStep& operator=(const DynamicSodeStep&) = delete;

  double step_size() const { return h_; }
  const Sys& lagrangian() const { return L_; }
  const SodeScheme& scheme() const { return sc_; }
  const StepOptions& options() const { return options_; }
  // The adjoint method and the same method with another step (the stages of compositions).
  DynamicSodeStep adjoint() const { return DynamicSodeStep(L_, Minv_, sc_.adjoint(), h_, options_, force_); }
  DynamicSodeStep with_step(double h) const { return DynamicSodeStep(L_, Minv_, sc_, h, options_, force_); }

  // One step from (q0, p0) at time t; dq holds the guess on entry and q1 - q0 on return,
  // dp receives p1 - p0.
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    const int n = L_.dim();
    if (!dynamic_detail::sizes_match(n, q0, p0, dq, s)) return s;
    if (dp.size() != n) dp.resize(n);
    Work& w = *work_;
    try {
      w.v0.noalias() = Minv_->lazyProduct(p0);
      w.x.head(n) = dq;
      w.x.tail(n) = w.last_dv;  // (zero before the first converged step)
      w.eq.begin(t, q0, w.v0);
      s = newton_drive(w.eq, w.lu, Refresh::every_iteration, options_, w.x, w.r, w.dx, w.J, w.state, w.start);
      dq = w.x.head(n);
      if (s.converged) {
        w.q1 = q0 + dq;
        w.v1 = w.v0 + w.x.tail(n);
        if constexpr (has_time<Sys>::value) L_.set_time(t + h_);
        L_.gradient(w.q1, w.v1, w.Lq, w.Lv);  // p1 = L_v(t + h, q1, v1)
        dp = w.Lv - p0;
        if constexpr (kForced) s.work = w.eq.work(w.x);
        w.last_dv = w.x.tail(n);
        if (!std::isfinite(dynamic_detail::inf_norm(dp))) s.fail("non-finite momentum");
      }
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    if (!s.converged && s.iterations == 0) s.iterations = 1;
    return s;
  }

 private:
  struct Work {
    Work(const Sys& L, const MassInverse& Minv, const SodeScheme& sc, double h, const Force* f)
        : force(f ? std::make_unique<Force>(*f) : nullptr), eq(L, Minv, sc, h, force.get()), lu(2 * L.dim()) {
      const int n = L.dim();
      x.resize(2 * n);
      r.resize(2 * n);
      dx.resize(2 * n);
      start.resize(2 * n);
      J.resize(2 * n, 2 * n);
      v0.resize(n);
      q1.resize(n);
      v1.resize(n);
      Lq.resize(n);
      Lv.resize(n);
      last_dv = V::Zero(n);
    }
    std::unique_ptr<Force> force;  // this step's copy of the force (its workspace)
    SeparableSodeEquation<Sys, Force> eq;
    DenseLU lu;
    DriverState state;
    V x, r, dx, start, v0, q1, v1, Lq, Lv, last_dv;
    Eigen::MatrixXd J;
  };

  Sys L_;
  MassInverse Minv_;
  SodeScheme sc_;
  double h_;
  StepOptions options_;
  std::shared_ptr<const Force> force_;
  std::shared_ptr<Work> work_;
};

}  // namespace dvm
