// The position-momentum step of a theta map on a separable Lagrangian, by Newton's
// method on the structured equation.
//
// For L(q, v) = v^T M v / 2 - V(q) with M constant (mechanics/structure.h) and the theta
// map R_d(x, v) = (x - theta v, x + (1 - theta) v) (paper Ex. 2.6), the discrete
// Lagrangian of Sec. 5.3 is, with D = q1 - q0 and q_theta = q0 + theta D,
//   L_d(q0, q1) = D^T M D / (2h) - h V(q_theta),
// and with F = -grad V = dL/dq the discrete Legendre equations are
//   p0 = -D1 L_d = M D / h - h (1 - theta) F(q_theta),
//   p1 =  D2 L_d = M D / h + h theta F(q_theta),   so  p1 - p0 = h F(q_theta).
// The step solves the first for D by simplified Newton on the residual
// p0 - M D / h + h (1 - theta) F(q0 + theta D), by the one Newton driver
// (solvers/newton_driver.h). Its Jacobian -(M / h + h theta (1 - theta) Hess V) comes
// from one level of Jets through the system's gradient (its closed form where it has
// one), where the generic PositionMomentumStep differentiates L_d twice through the
// inverse map for every iteration; the residual itself is one force in doubles. The
// equation is the same, so the two agree to round-off (tests/solvers/test_splitting.cc);
// at theta = 0 and 1 it is explicit and Newton ends after one correction. It has the contract of
// `integrate` (N, step_size(), step(q, p, dq, dp)); fixed size only.
#pragma once

#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include "mechanics/lagrangian.h"
#include "mechanics/separable.h"
#include "mechanics/structure.h"
#include "solvers/newton_driver.h"

namespace dvm {

template <class S>
class SeparableThetaStep {
  static_assert(is_separable_v<S>, "SeparableThetaStep needs a system that declares a separable structure");
  static_assert(state_size<S>::value != Eigen::Dynamic, "SeparableThetaStep is for fixed-size systems");

 public:
  static constexpr int N = S::dim;
  using V = Vec<double, N>;

  // q_ref: a point where L is defined (M is read off there; it is constant).
  SeparableThetaStep(S L, double theta, double h, StepOptions options, const V& q_ref)
      : L_(std::move(L)), theta_(theta), h_(h), options_(options), M_(mass_matrix(L_, q_ref)) {
    if (!(theta >= 0.0 && theta <= 1.0)) throw std::invalid_argument("theta must lie in [0, 1]");
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
  }

  double step_size() const { return h_; }

  // One step from (q0, p0): dq holds the starting guess on entry and q1 - q0 on return,
  // dp receives p1 - p0 = h F(q_theta). Simplified Newton by the driver
  // (solvers/newton_driver.h, Refresh::within_step): the Jacobian is formed and
  // factored at the starting guess and formed again only where an iteration fails to
  // shrink the residual fourfold.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    Equation eq{*this, q0, p0, max_abs(p0), max_abs(q0)};
    FixedLU<N> la;
    V r, dx, start;
    Mat<double, N, N> J;
    DriverState state;
    StepSummary s = newton_drive(eq, la, Refresh::within_step, options_, dq, r, dx, J, state, start);
    if (!s.converged) return s;
    V F;
    force(q0 + theta_ * dq, F);
    dp = h_ * F;
    if (!std::isfinite(max_abs(dp))) s.fail("non-finite momentum");
    return s;
  }

 private:
  // The equation in D = q1 - q0 for the driver: F(D) = -(p0 - M D / h + h (1 - theta)
  // F(q_theta)), whose Jacobian is J = M / h + h theta (1 - theta) Hess V (the sign turned
  // so that J is the matrix jacobian() forms).
  struct Equation {
    using Vector = V;
    using Matrix = Mat<double, N, N>;
    const SeparableThetaStep& st;
    const V& q0;
    const V& p0;
    double pscale, x0;
    void residual(const V& D, V& r) const {
      V F;
      st.force(q0 + st.theta_ * D, F);
      r = -(p0 - st.M_ * D / st.h_ + (st.h_ * (1.0 - st.theta_)) * F);
    }
    double jacobian(const V& D, V& r, Matrix& J) const {
      residual(D, r);
      st.jacobian(q0 + st.theta_ * D, J);
      return max_abs(J);
    }
    double scale(double Dn, double Jmax) const { return pscale + Jmax * Dn; }
    double offset() const { return x0; }
  };

  void force(const V& q, V& F) const {
    V dLdv;
    gradient_of(L_, q, V::Zero().eval(), F, dLdv);
  }
  // J = M / h + h theta (1 - theta) Hess V(q), Hess V = -dF/dq from one level of Jets
  // through the gradient.
  void jacobian(const V& q, Mat<double, N, N>& J) const {
    using D = ceres::Jet<double, N>;
    Vec<D, N> qd, zero, Fd, dLdv;
    for (int i = 0; i < N; ++i) {
      qd[i] = D(q[i], i);
      zero[i] = D(0.0);
    }
    gradient_of(L_, qd, zero, Fd, dLdv);
    const double c = h_ * theta_ * (1.0 - theta_);
    for (int i = 0; i < N; ++i) J.row(i) = M_.row(i) / h_ - c * Fd[i].v.transpose();
  }

  S L_;
  double theta_, h_;
  StepOptions options_;
  Mat<double, N, N> M_;
};

}  // namespace dvm
