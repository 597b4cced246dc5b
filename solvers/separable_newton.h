// The base of the steps of a theta map on a separable Lagrangian of run-time size that
// solve by simplified Newton across steps (Refresh::across_steps of
// solvers/newton_driver.h): the sparse one (solvers/sparse_separable_step.h) and the
// dense one (solvers/dense_separable_step.h).
//
// SeparableThetaNewton<Step>: for
// L(q, v) = v^T M v / 2 + U(q) with M constant and the theta map
// R_d(x, v) = (x - theta v, x + (1 - theta) v) (paper Ex. 2.6), with q_theta = q0 + theta D,
//   r = p0 - M D / h + h (1 - theta) F(q_theta),   dp = h F(q_theta),   F = grad U,
//   J = M / h - h theta (1 - theta) Hess U
// (solvers/separable_theta_step.h derives them). The base holds M (ConstantMass); Step
// (which derives from it) supplies
//   void force(const V& x, V& F) const           F = grad U(x)
//   double jacobian(const V& x) const            J formed at x; its largest entry (or INFINITY)
//   bool factor() const, void solve(const V& r, V& dx) const, const char* factorisation() const
//   DriverState& kept() const                    the kept factorisation's state, shared
//                                                by copies of a step
#pragma once

#include <Eigen/Core>
#include <stdexcept>
#include <utility>

#include "mechanics/dynamic_system.h"
#include "mechanics/nbody_dynamic.h"
#include "mechanics/written_dynamic.h"
#include "solvers/dynamic_step.h"
#include "solvers/newton_driver.h"

namespace dvm {

// M, constant: its diagonal when it is diagonal; otherwise the full matrix of a written
// text's parts (WrittenParts::mass, held alive by the step's copy of the system).
struct ConstantMass {
  Eigen::VectorXd diagonal;                 // (empty when M is full)
  const Eigen::MatrixXd* full = nullptr;
  bool is_diagonal() const { return full == nullptr; }
  void times(const Eigen::VectorXd& v, Eigen::VectorXd& out) const {
    if (full)
      out.noalias() = *full * v;
    else
      out = v.cwiseProduct(diagonal);
  }
};

inline ConstantMass constant_mass(const NBodyDynamic& L) {
  ConstantMass m;
  m.diagonal.resize(L.dim());
  for (int i = 0; i < L.bodies(); ++i) m.diagonal.segment<3>(3 * i).setConstant(L.m(i));
  return m;
}

inline ConstantMass constant_mass(const WrittenDynamic& L) {
  const WrittenParts& w = L.parts();
  ConstantMass m;
  if (w.split.diagonal)
    m.diagonal = w.mass_diagonal;
  else
    m.full = &w.mass;
  return m;
}

template <class Step>
class SeparableThetaNewton {
 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;

  double step_size() const { return h_; }
  double theta() const { return theta_; }
  int dim() const { return n_; }

  // Forgets the kept factorisation: the next step forms and factors a Jacobian.
  void reset() const { static_cast<const Step&>(*this).kept().valid = false; }

  // One step from (q0, p0): dq holds the starting guess on entry and q1 - q0 on return,
  // dp receives p1 - p0 = h F(q_theta) (the contract of `integrate`).
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    if (!dynamic_detail::sizes_match(n_, q0, p0, dq, s)) return s;
    if (dp.size() != n_) dp.resize(n_);
    const Step& self = static_cast<const Step&>(*this);
    Equation eq{self, *this, q0, p0, dynamic_detail::inf_norm(p0), dynamic_detail::inf_norm(q0)};
    Factor la{self};
    s = newton_drive(eq, la, Refresh::across_steps, options_, dq, r_, dx_, J_, self.kept(), start_);
    if (s.converged) {
      x_ = q0 + theta_ * dq;
      self.force(x_, F_);
      dp = h_ * F_;
      if (!std::isfinite(dynamic_detail::inf_norm(dp))) s.fail("non-finite momentum");
    }
    if (!s.converged && s.iterations == 0) s.iterations = 1;
    return s;
  }

 protected:
  SeparableThetaNewton(int n, double theta, double h, StepOptions options, ConstantMass mass)
      : theta_(theta), h_(h), options_(options), n_(n), mass_(std::move(mass)) {
    if (!(theta >= 0.0 && theta <= 1.0)) throw std::invalid_argument("theta must lie in [0, 1]");
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    x_.resize(n);
    F_.resize(n);
    r_.resize(n);
    dx_.resize(n);
    start_.resize(n);
  }

  double theta_, h_;
  StepOptions options_;
  int n_;
  ConstantMass mass_;

 private:
  // The separable equation for the driver, F(D) = r above, dF/dD = -J: the step forms J
  // (jacobian(x)) in its own storage and factors it, so the driver's matrix is unused and
  // the correction is J^{-1} r with the sign turned.
  struct Equation {
    using Vector = V;
    using Matrix = Eigen::MatrixXd;
    const Step& step;
    const SeparableThetaNewton& base;
    const V& q0;
    const V& p0;
    double pscale, x0;
    void residual(const V& D, V& r) const {
      base.x_ = q0 + base.theta_ * D;
      step.force(base.x_, base.F_);
      base.mass_.times(D, r);
      r = p0 - r / base.h_ + (base.h_ * (1.0 - base.theta_)) * base.F_;
    }
    double jacobian(const V& D, V& r, Matrix&) const {
      residual(D, r);
      return step.jacobian(base.x_);
    }
    double scale(double Dn, double Jmax) const { return pscale + Jmax * Dn; }
    double offset() const { return x0; }
  };
  struct Factor {
    const Step& step;
    bool factor(const Eigen::MatrixXd&, double) const { return step.factor(); }
    void solve(const V& r, V& dx) const {
      step.solve(r, dx);
      dx = -dx;
    }
    const char* name() const { return step.factorisation(); }
  };
  mutable V x_, F_, r_, dx_, start_;
  mutable Eigen::MatrixXd J_;  // (unused: the step holds its Jacobian)
};

}  // namespace dvm
