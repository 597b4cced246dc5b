// The position-momentum step of the theta maps under holonomic constraints g(t, q) = 0
// (m of them, mechanics/written_constraints.h), for a run-time-sized Lagrangian: the
// constrained discrete Euler-Lagrange equations with discrete multipliers and the
// constrained discrete Legendre transforms (Marsden and West, Acta Numerica 2001,
// Sec. 3.5), of which RATTLE is the Stormer-Verlet instance.
//
// With L_d(q0, q1) = h L(q0 + theta D, D / h), D = q1 - q0 (paper Sec. 5.3; the
// unconstrained equation ThetaEquation of solvers/dynamic_step.h, a force included),
// G0 = Dg(t0, q0), and t1 = t0 + h, one step from (q0, p0) solves
//   1. p0 - G0^T lambda = -D1 L_d(q0, q1) - F_d^-,   g(t1, q1) = 0
//      for (D, lambda) (n + m unknowns): the left constrained Legendre transform;
//   2. p1 = D2 L_d(q0, q1) + F_d^+ - G1^T mu,   G1 v1 + g_t(t1, q1) = 0,
//      v1 = FL^{-1}(q1, p1), G1 = Dg(t1, q1), for (v1, mu): the right one, which puts
//      p1 on the hidden constraint (for L = v^T M(q) v / 2 - U(q): G1 M^{-1} p1 = -g_t).
// Eliminating p0 between step k's second and step k + 1's first transform gives the
// constrained discrete Euler-Lagrange equation D2 L_d(q_{k-1}, q_k) + D1 L_d(q_k,
// q_{k+1}) + forces = G_k^T (lambda + mu). The positions q_k do not depend on how p_k
// was chosen along the constraint normals (lambda absorbs any G0^T shift of p0), so
// step 2 only chooses the representative of p1 that the energy and the next step's
// guess are evaluated at. Without forces the map (q0, p0) -> (q1, p1) is symplectic on
// the constraint's cotangent bundle, and for a scleronomic g the adjoint of the theta
// step is the constrained (1 - theta) step (Prop. 2.4 of the paper for the map, the
// construction symmetric in its two ends), so symmetric compositions raise its order as
// they raise the unconstrained one's (Hairer, Lubich and Wanner, Geometric Numerical
// Integration, VII.1.4 for RATTLE).
//
// Equation 1 is solved by newton_drive (solvers/newton_driver.h) with a dense LU of the
// saddle-point Jacobian
//   [ F_D               -s G0^T ]
//   [ s G1(D)            0      ]
// where F_D is ThetaEquation's Jacobian and the multiplier is carried as lambda / s:
// s = max|F_D| / max|G0| (at the first Jacobian the equation forms, then kept, so that
// one step's multiplier is the next one's starting guess) makes the constraint rows and
// the multiplier column of the size of the others, so that the driver's one stopping
// rule judges them alike; the Jacobian formed at the first iterate serves the step's
// later ones while each shrinks the residual fourfold (Refresh::within_step). Equation 2
// is linear in mu and, for a Lagrangian quadratic in the velocities, in v1: one solve
// (MomentumMap below; Newton's method on it otherwise, from v1 = D / h).
//
// Workspace is allocated at construction; a step allocates nothing. One object must
// not be used from two threads at once (copies are independent).
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <cmath>
#include <vector>
#include <memory>
#include <stdexcept>
#include <string>

#include "solvers/dynamic_step.h"

namespace dvm {

namespace constrained_detail {

// out -= c G^T mu (G: m x n), in loops: at the few coordinates and constraints of a
// linkage a matrix-vector product's call costs more than its arithmetic.
template <class Mat>
inline void subtract_normals(const Mat& G, double c, const double* mu, double* out) {
  const Eigen::Index m = G.rows(), n = G.cols();
  for (Eigen::Index k = 0; k < m; ++k) {
    const double a = c * mu[k];
    for (Eigen::Index i = 0; i < n; ++i) out[i] -= G(k, i) * a;
  }
}

// The size of the unknowns (D, lambda) where the numbers of coordinates N and of
// constraints M are known when compiled, else Dynamic.
constexpr int augmented(int N, int M) { return N == Eigen::Dynamic || M == Eigen::Dynamic ? Eigen::Dynamic : N + M; }

}  // namespace constrained_detail

// Equation 1 of the header comment, for solvers/newton_driver.h: the unknowns
// y = (D, lambda / s). N, M: the numbers of coordinates and of constraints where they are
// known when compiled (the runtime makes them so for the few of a pendulum or a
// linkage: bench_constrained), else Dynamic.
template <class Sys, class Con, class Force = NoForce, int N = Eigen::Dynamic, int M = Eigen::Dynamic>
class ConstrainedThetaEquation {
 public:
  static constexpr int K = constrained_detail::augmented(N, M);
  using Vector = Eigen::Matrix<double, K, 1>;
  using Matrix = Eigen::Matrix<double, K, K>;
  using Theta = ThetaEquation<Sys, N, Force>;

  ConstrainedThetaEquation(const Sys& L, const Con& g, double theta, double h, const Force* force = nullptr)
      : eq_(L, theta, h, force), g_(&g), h_(h), n_(L.dim()), m_(g.count()) {
    if ((N != Eigen::Dynamic && n_ != N) || (M != Eigen::Dynamic && m_ != M))
      throw std::invalid_argument("ConstrainedThetaEquation<" + std::to_string(N) + ", " + std::to_string(M) +
                                  ">: a system of " + std::to_string(n_) + " coordinates and " + std::to_string(m_) +
                                  " constraints");
    D_.resize(n_);
    rD_.resize(n_);
    q1_.resize(n_);
    g1_.resize(m_);
    gt_.resize(m_);
    JD_.resize(n_, n_);
    G0_.resize(m_, n_);
    G1_.resize(m_, n_);
  }

  // The start of the step at time t0; G0 = Dg(t0, q0).
  void begin(const typename Theta::Vector& q0, const typename Theta::Vector& p0, double t0) {
    q0_ = &q0;
    t1_ = t0 + h_;
    eq_.begin(q0, p0, t0);
    g_->gradients(t0, q0, G0_, gt_);
    g0max_ = dynamic_detail::inf_norm(G0_);
  }
  void residual(const Vector& y, Vector& r) {
    split(y);
    eq_.residual(D_, rD_);
    g_->value(t1_, q1_, g1_);
    form(y, r);
  }
  double jacobian(const Vector& y, Vector& r, Matrix& J) {
    split(y);
    const double Jd = eq_.jacobian(D_, rD_, JD_);
    g_->jacobian(t1_, q1_, g1_, G1_, gt_);
    if (s_ == 0.0) s_ = std::isfinite(Jd) && Jd > 0.0 && g0max_ > 0.0 ? Jd / g0max_ : 1.0;
    form(y, r);
    J.topLeftCorner(n_, n_) = JD_;
    J.topRightCorner(n_, m_) = -s_ * G0_.transpose();
    J.bottomLeftCorner(m_, n_) = s_ * G1_;
    J.bottomRightCorner(m_, m_).setZero();
    const double m = dynamic_detail::inf_norm(J);
    return std::isfinite(m) ? m : INFINITY;
  }
  double scale(double yn, double Jmax) const { return eq_.scale(yn, Jmax); }
  double offset() const { return eq_.offset(); }

  // At the solution y: p1~ - p0 = h G - G0^T lambda (the momentum before the right
  // transform's projection) into dp, and the force's work over the step.
  double momentum(const Vector& y, typename Theta::Vector& dp) {
    split(y);
    eq_.momentum(D_, dp);
    constrained_detail::subtract_normals(G0_, s_, y.data() + n_, dp.data());
    return eq_.work(D_);
  }
  double end_time() const { return t1_; }
  // The unconstrained part (the step's derivative reads its blocks).
  Theta& theta_equation() { return eq_; }

 private:
  void split(const Vector& y) {
    for (int i = 0; i < n_; ++i) {
      D_[i] = y[i];
      q1_[i] = (*q0_)[i] + y[i];
    }
  }
  void form(const Vector& y, Vector& r) const {
    for (int i = 0; i < n_; ++i) r[i] = rD_[i];
    constrained_detail::subtract_normals(G0_, s_, y.data() + n_, r.data());
    for (int k = 0; k < m_; ++k) r[n_ + k] = s_ * g1_[k];
  }

  Theta eq_;
  const Con* g_;
  double h_, t1_ = 0.0, s_ = 0.0, g0max_ = 0.0;
  int n_, m_;
  const typename Theta::Vector* q0_ = nullptr;
  typename Theta::Vector D_, rD_, q1_;
  Eigen::Matrix<double, M, 1> g1_, gt_;
  typename Theta::Matrix JD_;
  Eigen::Matrix<double, M, N> G0_, G1_;
};

// How the momentum depends on the velocity, which decides how the right transform
// (equation 2) is solved: `general`, Newton's method on L_v(q, v) + G^T mu = p~;
// `linear`, L = v^T M(q) v / 2 + U(q) (L_v = M(q) v): one solve with M(q) = L_vv;
// `constant`, M constant too (a separable L): M^{-1} kept from the first step, and mu
// from the m x m system G M^{-1} G^T mu = G M^{-1} p~ + g_t.
enum class MomentumMap { general, linear, constant };

namespace constrained_detail {

// The right constrained Legendre transform at (t, q) (equation 2 of the header
// comment): from p~ (the momentum before projection) finds v and mu with
//   L_v(q, v) + G^T mu = p~,   G v + g_t = 0,
// and writes p = p~ - G^T mu. v holds the starting guess on entry.
template <class Sys, class Con>
struct Projection {
  Eigen::VectorXd Lq, Lv, g, gt, r, x, mu;
  Eigen::MatrixXd Lqq, Lqv, Lvv, G, K, Minv, MG, S;
  DenseLU lu, small, mass;
  bool have_minv = false;
  Projection(int n, int m) {
    Lq.resize(n);
    Lv.resize(n);
    g.resize(m);
    gt.resize(m);
    r.resize(n + m);
    x.resize(n + m);
    mu.resize(m);
    Lqq.resize(n, n);
    Lqv.resize(n, n);
    Lvv.resize(n, n);
    G.resize(m, n);
    K.resize(n + m, n + m);
    Minv.resize(n, n);
    MG.resize(n, m);
    S.resize(m, m);
    lu.resize(n + m);
    small.resize(m);
    mass.resize(n);
  }
  // p~ in `p` on entry, p on return (G = Dg(t, q) left in G, mu in mu).
  const char* operator()(const Sys& L, const Con& con, double t, const Eigen::VectorXd& q, Eigen::VectorXd& p,
                         Eigen::VectorXd& v, MomentumMap kind) {
    const Eigen::Index n = q.size(), m = g.size();
    con.gradients(t, q, G, gt);
    if constexpr (has_time<Sys>::value) L.set_time(t);  // L(t, q, v): FL^{-1} at t (not kind constant)
    if (kind == MomentumMap::constant) {
      if (!have_minv) {
        L.hessian(q, v, Lq, Lv, Lqq, Lqv, Lvv);
        if (!mass.factor(Lvv)) return "the mass matrix d2L/dv2 is singular";
        mass.inverse(Minv);
        have_minv = true;
      }
      // (loops: at these sizes a product's call costs more than its arithmetic)
      for (Eigen::Index i = 0; i < n; ++i) {
        double a = 0.0;
        for (Eigen::Index j = 0; j < n; ++j) a += Minv(i, j) * p[j];
        v[i] = a;
        for (Eigen::Index k = 0; k < m; ++k) {
          double b = 0.0;
          for (Eigen::Index j = 0; j < n; ++j) b += Minv(i, j) * G(k, j);
          MG(i, k) = b;
        }
      }
      for (Eigen::Index k = 0; k < m; ++k) {
        double c = gt[k];
        for (Eigen::Index i = 0; i < n; ++i) c += G(k, i) * v[i];
        mu[k] = c;
        for (Eigen::Index l = 0; l < m; ++l) {
          double d = 0.0;
          for (Eigen::Index i = 0; i < n; ++i) d += G(k, i) * MG(i, l);
          S(k, l) = d;
        }
      }
      if (m == 1) {
        if (!(std::fabs(S(0, 0)) > 0.0))
          return "the constraint Jacobian is singular where the momentum is projected (redundant constraints)";
        mu[0] /= S(0, 0);
      } else {
        if (!small.factor(S))
          return "the constraint Jacobian is singular where the momentum is projected (redundant constraints)";
        small.solve(mu, mu);
      }
      for (Eigen::Index k = 0; k < m; ++k)
        for (Eigen::Index i = 0; i < n; ++i) v[i] -= MG(i, k) * mu[k];
      subtract_normals(G, 1.0, mu.data(), p.data());
      return std::isfinite(dynamic_detail::inf_norm(p)) ? "" : "non-finite momentum projection";
    }
    x.tail(m).setZero();  // mu
    const double scale = std::fmax(1e-300, dynamic_detail::inf_norm(p));
    for (int it = 0; it < 30; ++it) {
      L.hessian(q, v, Lq, Lv, Lqq, Lqv, Lvv);
      r.head(n) = Lv - p;
      r.head(n).noalias() += G.transpose() * x.tail(m);
      r.tail(m) = gt;
      r.tail(m).noalias() += G * v;
      if (it > 0 && r.head(n).template lpNorm<Eigen::Infinity>() <= 1e-14 * scale &&
          r.tail(m).template lpNorm<Eigen::Infinity>() <=
              1e-14 * (dynamic_detail::inf_norm(G) * dynamic_detail::inf_norm(v) + dynamic_detail::inf_norm(gt) + 1e-300))
        break;
      K.topLeftCorner(n, n) = Lvv;
      K.topRightCorner(n, m) = G.transpose();
      K.bottomLeftCorner(m, n) = G;
      K.bottomRightCorner(m, m).setZero();
      if (!lu.factor(K))
        return "the constraint Jacobian is singular where the momentum is projected (redundant constraints, or "
               "d2L/dv2 singular on them)";
      lu.solve(r, r);
      v -= r.head(n);
      x.tail(m) -= r.tail(m);
      if (!std::isfinite(dynamic_detail::inf_norm(r))) return "non-finite momentum projection";
      if (kind == MomentumMap::linear) break;
      if (it == 29) return "the momentum projection did not converge";
    }
    mu = x.tail(m);
    subtract_normals(G, 1.0, mu.data(), p.data());
    return "";
  }
};

// Whether a partially pivoted LU's pivots are all above 1e-13 of the largest (the
// saddle-point matrices of the steps' derivatives are singular exactly where the steps'
// own are).
template <class Mat>
bool lu_invertible(const Eigen::PartialPivLU<Mat>& lu) {
  const auto d = lu.matrixLU().diagonal().cwiseAbs();
  const double top = d.maxCoeff();
  return std::isfinite(top) && top > 0.0 && d.minCoeff() > 1e-13 * top;
}

// Matrices of run-time size within fixed maximum sizes R x C (on the stack where both are
// known when compiled: the derivatives of a pendulum's or a linkage's step allocate
// nothing; MatrixXd where either is Dynamic).
template <int R, int C>
using Bounded = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, R == 1 && C != 1 ? Eigen::RowMajor : Eigen::ColMajor,
                              R, C>;  // (Eigen's rule: at most one row is row-major)
template <int R>
using BoundedVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, R, 1>;

// The derivative of the right transform (equation 2 of the header comment) at its
// solution (t1, q1; v1, mu, G1 = Dg(t1, q1)): given the derivatives dq1 and dp1~ of q1
// and of the momentum before projection in some parameters (n x k each), dp1 of
// p1 = p1~ - G1^T mu. Differentiating L_v(q1, v1) + G1^T mu = p1~, G1 v1 + g_t = 0,
//   [L_vv  G1^T] [dv1]     [ L_vq + H_mu                   ]        [ -I ]
//   [G1     0  ] [dmu] = - [ v1^T Hess g_i + grad (g_t)_i  ] dq1 -  [  0 ] dp1~,
// H_mu = sum mu_i Hess g_i, and dp1 = dp1~ - H_mu dq1 - G1^T dmu. False where the
// matrix is singular. NX, MX, KX: the largest n, m and k (Dynamic: any; it then allocates).
template <int NX, int MX, int KX, class Sys, class Con, class Q, class VM, class GM>
bool right_transform_derivative(const Sys& L, const Con& con, double t1, const Q& q1, const Q& v1, const VM& mu,
                                const GM& G1, const Bounded<NX, KX>& dq1, const Bounded<NX, KX>& dpt,
                                Bounded<NX, KX>& dp1) {
  constexpr int SX = augmented(NX, MX);
  using MN = Bounded<NX, NX>;
  const Eigen::Index n = q1.size(), m = mu.size();
  // (the constraints' Hessians, sized once per thread and kept: m n^2 doubles, on the
  // heap at run-time sizes)
  thread_local std::vector<MN> H1;
  Bounded<MX, NX> Gqt1, Hv(m, n);
  con.second_derivatives(t1, q1, H1, Gqt1);
  MN Hm = MN::Zero(n, n);
  for (Eigen::Index i = 0; i < m; ++i) {
    Hm += mu[i] * H1[static_cast<std::size_t>(i)];
    Hv.row(i).noalias() = v1.transpose() * H1[static_cast<std::size_t>(i)];
    Hv.row(i) += Gqt1.row(i);
  }
  if constexpr (has_time<Sys>::value) L.set_time(t1);
  BoundedVector<NX> Lq1(n), Lv1(n);
  MN Lqq1(n, n), Lqv1(n, n), Lvv1(n, n);
  L.hessian(q1, v1, Lq1, Lv1, Lqq1, Lqv1, Lvv1);
  Bounded<SX, SX> K2 = Bounded<SX, SX>::Zero(n + m, n + m);
  Bounded<SX, KX> R2(n + m, dq1.cols());
  K2.topLeftCorner(n, n) = Lvv1;
  K2.topRightCorner(n, m) = G1.transpose();
  K2.bottomLeftCorner(m, n) = G1;
  const MN Hq = Lqv1.transpose() + Hm;
  R2.topRows(n).noalias() = Hq * dq1;
  R2.topRows(n) -= dpt;
  R2.bottomRows(m).noalias() = Hv * dq1;
  const Eigen::PartialPivLU<Bounded<SX, SX>> lu2(K2);
  if (!lu_invertible(lu2)) return false;
  const Bounded<SX, KX> Y2 = lu2.solve(R2);  // minus (dv1, dmu)
  dp1 = dpt;
  dp1.noalias() -= Hm * dq1;
  dp1.noalias() += G1.transpose() * Y2.bottomRows(m);
  return dp1.allFinite();
}

// After equation 1 of a constrained step has converged (the position-momentum step here,
// the Hamiltonian one in solvers/constrained_hamiltonian_step.h): from q1 = q0 + dq and
// the momentum increment before projection dpt = p1~ - p0, equation 2 at t1 (v1 = dq / h
// its starting guess), and dp = p1 - p0 = dpt - G1^T mu (without the round-off of
// forming p1 first); s fails where the projection does. q1, p1, v1: workspace.
template <class Sys, class Con, class Q, class D>
void project_end(StepSummary& s, Projection<Sys, Con>& projection, const Sys& L, const Con& con, MomentumMap kind,
                 double t1, double h, const Q& q0, const Q& p0, const Q& dq, const D& dpt, Eigen::VectorXd& q1,
                 Eigen::VectorXd& p1, Eigen::VectorXd& v1, Eigen::VectorXd& dp) {
  const Eigen::Index n = q0.size();
  const double inv_h = 1.0 / h;
  for (Eigen::Index i = 0; i < n; ++i) {
    q1[i] = q0[i] + dq[i];
    p1[i] = p0[i] + dpt[i];
    v1[i] = dq[i] * inv_h;
  }
  const char* failed = projection(L, con, t1, q1, p1, v1, kind);
  if (*failed) {
    s.fail(failed);
    return;
  }
  for (Eigen::Index i = 0; i < n; ++i) dp[i] = dpt[i];
  subtract_normals(projection.G, 1.0, projection.mu.data(), dp.data());
  if (!std::isfinite(dynamic_detail::inf_norm(dp))) s.fail("non-finite momentum");
}

}  // namespace constrained_detail

// The constrained step: equation 1 by the driver, then the projection. Sys: a
// run-time-sized Lagrangian (mechanics/dynamic_system.h); Con: the constraints
// (WrittenConstraints: count(), dim(), value(t, q, g), jacobian(t, q, g, G, g_t));
// Force: a generalized force (solvers/dynamic_step.h), NoForce for none; NC, MC: the
// numbers of coordinates and constraints where known when compiled (the equation's
// workspace, its Jacobian and LU then of fixed size; the state stays run-time sized).
template <class Sys, class Con, class Force = NoForce, int NC = Eigen::Dynamic, int MC = Eigen::Dynamic>
class ConstrainedThetaStep {
  static_assert(is_dynamic_system_v<Sys>, "ConstrainedThetaStep needs a run-time-sized system (dynamic_system.h)");

 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;
  static constexpr bool kForced = is_force_v<Force>;

  // momentum: how L_v depends on v (MomentumMap; `general` is right for every L, the
  // others save work where they hold). Each copy of the step evaluates its own copies
  // of the constraints and the force.
  ConstrainedThetaStep(Sys L, ThetaMap R, double h, std::shared_ptr<const Con> constraints, StepOptions options = {},
                       MomentumMap momentum = MomentumMap::general, std::shared_ptr<const Force> force = nullptr)
      : L_(std::move(L)),
        R_(std::move(R)),
        h_(h),
        options_(options),
        momentum_(momentum),
        con_(std::move(constraints)),
        force_(std::move(force)) {
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    if (!con_ || con_->dim() != L_.dim())
      throw std::invalid_argument("ConstrainedThetaStep: constraints on the system's coordinates are needed");
    if (con_->count() >= L_.dim())
      throw std::invalid_argument("ConstrainedThetaStep: " + std::to_string(con_->count()) + " constraints on " +
                                  std::to_string(L_.dim()) + " coordinates leave no motion");
    if ((NC != Eigen::Dynamic && L_.dim() != NC) || (MC != Eigen::Dynamic && con_->count() != MC))
      throw std::invalid_argument("ConstrainedThetaStep<" + std::to_string(NC) + ", " + std::to_string(MC) +
                                  ">: a system of " + std::to_string(L_.dim()) + " coordinates and " +
                                  std::to_string(con_->count()) + " constraints");
    if constexpr (kForced)
      if (!force_ || force_->dim() != L_.dim())
        throw std::invalid_argument("ConstrainedThetaStep: a forced step needs a force of the system's dimension");
    work_ = std::make_shared<Work>(L_, *con_, R_.theta(), h_, force_.get());
  }
  ConstrainedThetaStep(const ConstrainedThetaStep& o)
      : L_(o.L_), R_(o.R_), h_(o.h_), options_(o.options_), momentum_(o.momentum_), con_(o.con_), force_(o.force_) {
    work_ = std::make_shared<Work>(L_, *con_, R_.theta(), h_, force_.get());
  }
  ConstrainedThetaStep& operator=(const ConstrainedThetaStep&) = delete;

  double step_size() const { return h_; }
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
  ConstrainedThetaStep adjoint() const {
    return ConstrainedThetaStep(L_, R_.adjoint(), h_, con_, options_, momentum_, force_);
  }

  // Puts p on the hidden constraint at (t, q): p - G^T mu with G v + g_t = 0 for
  // v = FL^{-1}(q, p - G^T mu) (the projection of step 2; an initial momentum off it).
  // v: the starting guess on entry, that velocity on return. Returns an empty string,
  // or what failed.
  std::string project(double t, const V& q, V& p, V& v) const {
    Work& w = *work_;
    try {
      return w.projection(L_, *w.con, t, q, p, v, momentum_);
    } catch (const std::domain_error& e) {
      return e.what();
    }
  }

  // The derivative of the step (q0, p0) -> (q1, p1) at the increment dq that step()
  // solved for from (q0, p0) at time t0, by the implicit function theorem on its two
  // equations (no finite differences); A (2n x 2n) as DynamicThetaStep::derivative
  // gives it, coordinates before momenta. The multipliers at the solution are found
  // again from it: lambda from equation 1 by least squares (G0^T lambda = the
  // unconstrained residual, consistent at the solution), mu and v1 by equation 2.
  // With F1(D, lambda; q0, p0) the first equation's rows and g(t1, q0 + D) its last,
  //   [F_D  -G0^T] [dD     ]     [ -H_lambda + h (1 - theta) G_q - L_vq ]        [ I ]
  //   [G1    0   ] [dlambda] = - [  G1                                  ] dq0 -  [ 0 ] dp0,
  // H_lambda = sum lambda_i Hess g_i(q0), p1~ = p0 + h G - G0^T lambda, then equation 2
  // at (q1, p1~) as constrained_detail::right_transform_derivative differentiates it.
  // Without forces the step is symplectic on the constraint's cotangent bundle: A^T J A
  // = J on the vectors tangent to it (not on R^{2n}: A maps every direction onto that
  // bundle). Returns false where a matrix is singular or a value not finite. Its
  // matrices are of fixed maximum size where NC and MC are given and there is no force:
  // after its first call (which sizes A and its workspace) it allocates nothing there;
  // otherwise it allocates. Not from two threads at once (it uses the step's workspace).
  bool derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A) const {
    return differentiate(t0, q0, p0, dq, A, nullptr);
  }
  // The derivative B = d(q1, p1)/du (2n x c) in the force's control inputs u
  // (WrittenForce::controls(), held constant over the step): the columns of the same
  // two solves for the input u, which enters only through F at the node,
  // dF1/du = h (1 - theta) F_u and dp1~/du = h F_u + (the terms in d(D, lambda)/du).
  template <class Fo = Force, std::enable_if_t<is_force_v<Fo>, int> = 0>
  bool control_derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& B) const {
    Eigen::MatrixXd A;
    return differentiate(t0, q0, p0, dq, A, &B);
  }
  // A and, where B is not null, B from one differentiation: what derivative() and
  // control_derivative() give (B 2n x 0 without control inputs).
  bool derivatives(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    return differentiate(t0, q0, p0, dq, A, B);
  }

 private:
  bool differentiate(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    const int n = L_.dim(), m = con_->count();
    if (q0.size() != n || p0.size() != n || dq.size() != n)
      throw std::invalid_argument("ConstrainedThetaStep::derivative: a state of " + std::to_string(q0.size()) +
                                  " coordinates; the system has " + std::to_string(n));
    // the largest sizes: the coordinates, the constraints, both, and the inputs (q0, p0
    // and the controls), where known when compiled
    constexpr int NX = NC, MX = MC, SX = Eq::K, IX = NC == Eigen::Dynamic || kForced ? Eigen::Dynamic : 2 * NC;
    using MN = constrained_detail::Bounded<NX, NX>;
    using MI = constrained_detail::Bounded<NX, IX>;
    using VM = constrained_detail::BoundedVector<MX>;
    using TV = typename Eq::Theta::Vector;
    const double th = R_.theta(), h = h_;
    Work& w = *work_;
    auto& eq = w.eq.theta_equation();
    w.q0 = q0;
    w.p0 = p0;
    TV D = dq, r(n), hG(n);
    typename Eq::Theta::Matrix FD(n, n);
    eq.begin(w.q0, w.p0, t0);
    if (!std::isfinite(eq.jacobian(D, r, FD))) return false;
    MN Gq = eq.Lqq(), Gv = eq.Lqv();
    Eigen::MatrixXd Fu(n, 0);  // dF/du at the node (the columns of B)
    if constexpr (kForced) {
      Gq += eq.Fq();
      Gv += eq.Fv();
      if (B) {
        V F(n);
        Eigen::MatrixXd Fq(n, n), Fv(n, n);
        w.force->jacobian(t0 + th * h, V(q0 + th * dq), V(dq / h), F, Fq, Fv, &Fu);
      }
    }
    const int c = static_cast<int>(Fu.cols()), in = 2 * n + c;
    eq.momentum(D, hG);  // h G at the node
    // the multipliers at the solution
    const Con& con = *w.con;
    VM g0(m), gt0(m);
    constrained_detail::Bounded<MX, NX> G0(m, n), G1(m, n);
    con.jacobian(t0, q0, g0, G0, gt0);
    const constrained_detail::Bounded<MX, MX> GG = G0 * G0.transpose();
    const VM lambda = GG.ldlt().solve(G0 * r);
    V& q1 = w.q1;
    V& p1 = w.p1;
    V& v1 = w.v1;
    q1 = q0 + D;
    p1 = p0 + hG;
    p1.noalias() -= G0.transpose() * lambda;
    v1 = D / h;
    const double t1 = t0 + h;
    // (the step's own projection, with its momentum map: M^{-1} kept where M is constant)
    try {
      if (*w.projection(L_, con, t1, q1, p1, v1, momentum_)) return false;
    } catch (const std::domain_error&) {
      return false;
    }
    G1 = w.projection.G;
    const VM mu = w.projection.mu;
    thread_local std::vector<MN> H0;  // (as H1 of right_transform_derivative)
    constrained_detail::Bounded<MX, NX> Gqt0;
    con.second_derivatives(t0, q0, H0, Gqt0);
    MN Hl = MN::Zero(n, n);
    for (int i = 0; i < m; ++i) Hl += lambda[i] * H0[static_cast<std::size_t>(i)];
    // equation 1
    constrained_detail::Bounded<SX, SX> J1 = constrained_detail::Bounded<SX, SX>::Zero(n + m, n + m);
    constrained_detail::Bounded<SX, IX> R1 = constrained_detail::Bounded<SX, IX>::Zero(n + m, in);
    J1.topLeftCorner(n, n) = FD;
    J1.topRightCorner(n, m) = -G0.transpose();
    J1.bottomLeftCorner(m, n) = G1;
    R1.topLeftCorner(n, n) = h * (1.0 - th) * Gq - Hl;
    R1.topLeftCorner(n, n) -= eq.Lqv().transpose();
    R1.block(0, n, n, n).setIdentity();
    R1.bottomLeftCorner(m, n) = G1;
    if (c > 0) R1.topRightCorner(n, c) = h * (1.0 - th) * Fu;
    const Eigen::PartialPivLU<constrained_detail::Bounded<SX, SX>> lu1(J1);
    if (!constrained_detail::lu_invertible(lu1)) return false;
    const constrained_detail::Bounded<SX, IX> Y1 = lu1.solve(R1);  // minus d(D, lambda) / d(q0, p0)
    MI dq1 = -Y1.topRows(n);  // dD, then dq1 = dq0 + dD
    MI dpt = G0.transpose() * Y1.bottomRows(m);
    const MN Gt = h * th * Gq + Gv;
    dpt.noalias() += Gt * dq1;  // (h theta G_q + G_v) dD
    dq1.leftCols(n) += MN::Identity(n, n);
    dpt.leftCols(n) += h * Gq - Hl;
    dpt.block(0, n, n, n) += MN::Identity(n, n);
    if (c > 0) dpt.rightCols(c) += h * Fu;
    // equation 2
    MI dp1;
    if (!constrained_detail::right_transform_derivative<NX, MX, IX>(L_, con, t1, q1, v1, mu, G1, dq1, dpt, dp1))
      return false;
    return dynamic_detail::assemble_derivative(n, dq1, dp1, A, B);
  }

 public:

  // One step from (q0, p0) at time t; dq holds the starting guess on entry and q1 - q0
  // on return, dp receives p1 - p0.
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
      // (the multiplier's guess: the last step's, kept in w.y; the Newton iterates after the
      // first do not depend on it, but a good one lets the first residual meet the tolerance)
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
  using Eq = ConstrainedThetaEquation<Sys, Con, Force, NC, MC>;
  struct Work {
    Work(const Sys& L, const Con& c, double theta, double h, const Force* f)
        : con(std::make_unique<Con>(c)),
          force(f ? std::make_unique<Force>(*f) : nullptr),
          eq(L, *con, theta, h, force.get()),
          projection(L.dim(), c.count()) {
      const int n = L.dim(), k = n + c.count();
      q0.resize(n);
      p0.resize(n);
      q1.resize(n);
      p1.resize(n);
      v1.resize(n);
      dp.resize(n);
      y.resize(k);
      r.resize(k);
      dx.resize(k);
      start.resize(k);
      J.resize(k, k);
      lu.resize(k);
      y.setZero();
    }
    std::unique_ptr<Con> con;      // this step's copy of the constraints (their workspace)
    std::unique_ptr<Force> force;  // and of the force
    Eq eq;
    constrained_detail::Projection<Sys, Con> projection;
    typename Eq::Theta::Vector q0, p0, dp;
    V q1, p1, v1;
    typename Eq::Vector y, r, dx, start;
    typename Eq::Matrix J;
    DenseLUOf<Eq::K> lu;
    DriverState state;
  };

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
