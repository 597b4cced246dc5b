// The position-momentum step of a theta map on a separable Lagrangian of run-time size
// whose potential couples most coordinates (n bodies; a written text whose Hessian of U
// is not sparse), by Newton's method with a dense Jacobian kept across steps.
//
// The equation and the iteration are those of solvers/separable_newton.h: with
// D = q1 - q0 and q_theta = q0 + theta D, p0 = M D / h - h (1 - theta) F(q_theta) is
// solved for D, with J = M / h - h theta (1 - theta) Hess U. The generic run-time-sized
// step (DynamicThetaStep) forms the 2n x 2n Hessian of L and factors a dense n x n
// Jacobian at every step; here the Jacobian is the system's n x n Hess U (n bodies: its
// closed form, O(n^2)) and M, factored by a dense LU with partial pivoting only where
// the iteration stops converging, so that a step costs its force evaluations and
// O(n^2) triangular solves. A pivot below 64 eps times the Jacobian's largest entry, or
// a non-finite one, is a failed step with a message.
// The equation is the generic step's, so the two agree within the Newton tolerance
// (tests/solvers/test_sparse_separable.cc: 1e-11 against the generic path through the
// runtime, 1e-13 against the sparse step over 50 steps).
//
// Sys: NBodyDynamic, or WrittenDynamic with a separable text (its force from the
// potential's tape alone, WrittenSeparable). The n x n matrices a Jacobian is formed in
// (Work) are shared by the steps of a composition, each of which keeps its own
// factorisation (one n x n LU); copies of a step share its factorisation. So steps must
// not run on two threads at once.
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <type_traits>
#include <utility>

#include "mechanics/dynamic_system.h"
#include "mechanics/nbody_dynamic.h"
#include "mechanics/written_dynamic.h"
#include "solvers/separable_newton.h"

namespace dvm {

template <class Sys>
class DenseSeparableThetaStep : public SeparableThetaNewton<DenseSeparableThetaStep<Sys>> {
  using Base = SeparableThetaNewton<DenseSeparableThetaStep<Sys>>;
  // the force: the potential's tape alone for a written text
  using ForceSys = std::conditional_t<std::is_same_v<Sys, WrittenDynamic>, WrittenSeparable, Sys>;

 public:
  using V = Eigen::VectorXd;

  // Where a Jacobian is formed, to share between the steps of a composition.
  struct Work {
    explicit Work(int n)
        : zero(V::Zero(n)), Lq(n), Lv(n), Lqq(n, n), Lqv(n, n), Lvv(n, n), J(n, n) {}
    V zero, Lq, Lv;
    Eigen::MatrixXd Lqq, Lqv, Lvv, J;
  };
  static std::shared_ptr<Work> workspace(const Sys& L) { return std::make_shared<Work>(L.dim()); }

  DenseSeparableThetaStep(const Sys& L, std::shared_ptr<Work> work, double theta, double h,
                          StepOptions options = {})
      : Base(L.dim(), theta, h, options, constant_mass(L)),
        L_(L),
        force_(L),
        work_(std::move(work)),
        factorisation_(std::make_shared<Factorisation>(L.dim())) {
    if (!work_ || work_->J.rows() != L.dim()) throw std::invalid_argument("the workspace is not the system's");
  }

  const char* factorisation() const { return "dense LU factorisation"; }

 private:
  friend Base;
  void force(const V& x, V& F) const { force_.gradient(x, work_->zero, F, work_->Lv); }
  // J = M / h - h theta (1 - theta) Hess U(x), Hess U = d2L/dq2 (the kinetic part does not
  // depend on q); returns its largest entry in magnitude
  double jacobian(const V& x) const {
    Work& w = *work_;
    L_.hessian(x, w.zero, w.Lq, w.Lv, w.Lqq, w.Lqv, w.Lvv);
    const double h = this->h_, c = h * this->theta_ * (1.0 - this->theta_);
    w.J = -c * w.Lqq;
    const ConstantMass& M = this->mass_;
    if (M.is_diagonal())
      w.J.diagonal() += M.diagonal / h;
    else
      w.J += *M.full / h;
    const double m = dynamic_detail::inf_norm(w.J);
    return std::isfinite(m) ? m : INFINITY;
  }
  // Singular where a pivot is zero at round-off: below 64 eps times J's largest entry.
  bool factor() const {
    auto& lu = factorisation_->lu;
    lu.compute(work_->J);
    const double floor = 64.0 * std::numeric_limits<double>::epsilon() * factorisation_->Jmax;
    const auto d = lu.matrixLU().diagonal();
    for (Eigen::Index i = 0; i < d.size(); ++i)
      if (!(std::fabs(d[i]) > floor) || !std::isfinite(d[i])) return false;
    return true;
  }
  void solve(const V& r, V& dx) const { dx = factorisation_->lu.solve(r); }
  DriverState& kept() const { return *factorisation_; }

  Sys L_;  // its Hessian
  ForceSys force_;
  std::shared_ptr<Work> work_;
  // The factored Jacobian, kept from step to step and shared by copies of the step.
  struct Factorisation : DriverState {
    explicit Factorisation(int n) : lu(n) {}  // (its storage sized here: a step allocates nothing)
    Eigen::PartialPivLU<Eigen::MatrixXd> lu;
  };
  std::shared_ptr<Factorisation> factorisation_;
};

}  // namespace dvm
