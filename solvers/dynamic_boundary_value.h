// Boundary values of a system of run-time size (mechanics/dynamic_system.h) with a map
// of the theta family: the problem of solvers/boundary_value.h (q_0 and q_K fixed, the
// discrete Euler-Lagrange equation at every interior node, one sparse Ceres problem),
// its residual and Jacobian written out from the system's gradient and Hessian instead
// of Jets of the three nodes, so that it is compiled once per system type, not per size.
//
// The theta map R_d(x, v) = (x - theta v, x + (1 - theta) v) has the inverse
// x = (1 - theta) q0 + theta q1, v = q1 - q0, so (paper Sec. 3, L_d = h L(R_d^{-1}/h))
//   L_d(q0, q1) = h L(x, (q1 - q0) / h),
//   D1 L_d = h (1 - theta) L_q - L_v,     D2 L_d = h theta L_q + L_v,
// L's derivatives taken at (x, (q1 - q0) / h). With the nodes (a, b, c) of interior node
// b, the residual is DEL = D2 L_d(a, b) + D1 L_d(b, c); with the Hessian blocks L_qq,
// L_qv (d2L / dq_i dv_j) and L_vv at the left interval's point (index 1) and the right
// one's (index 2), its Jacobian blocks are
//   d/da = h theta (1 - theta) L_qq1 - theta L_qv1 + (1 - theta) L_qv1^T - L_vv1 / h
//   d/db = h theta^2 L_qq1 + theta (L_qv1 + L_qv1^T) + L_vv1 / h
//        + h (1 - theta)^2 L_qq2 - (1 - theta) (L_qv2 + L_qv2^T) + L_vv2 / h
//   d/dc = h theta (1 - theta) L_qq2 + (1 - theta) L_qv2 - theta L_qv2^T - L_vv2 / h.
// The fixed-size problem differentiates the same residual by Jets: the two agree to
// round-off (test_boundary_value). A Lagrangian in t, forces and constraints are not
// part of this problem (the runtime refuses them).
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <utility>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "solvers/boundary_value.h"

namespace dvm {

template <class Sys>
class DynamicBoundaryValueProblem {
 public:
  using V = Eigen::VectorXd;
  using M = Eigen::MatrixXd;

  DynamicBoundaryValueProblem(Sys L, double theta, double h)
      : L_(std::move(L)), theta_(theta), h_(h), n_(L_.dim()), work_(n_) {}

  V D1Ld(const V& a, const V& b) const {
    at(a, b, false);
    return h_ * (1.0 - theta_) * work_.Lq - work_.Lv;
  }
  V D2Ld(const V& a, const V& b) const {
    at(a, b, false);
    return h_ * theta_ * work_.Lq + work_.Lv;
  }
  V del(const V& a, const V& b, const V& c) const { return D2Ld(a, b) + D1Ld(b, c); }

  // DEL at the nodes (a, b, c) into r, and where J[i] is not null its derivative in
  // node i as n x n row-major blocks (Ceres' layout).
  void evaluate(const double* a, const double* b, const double* c, double* r, double* const* J) const {
    using Row = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    const bool jac = J && (J[0] || J[1] || J[2]);
    const double th = theta_, ph = 1.0 - theta_, h = h_;
    Work& w = work_;
    const Eigen::Map<const V> qa(a, n_), qb(b, n_), qc(c, n_);
    at(qa, qb, jac);  // the left interval
    Eigen::Map<V>(r, n_) = h * th * w.Lq + w.Lv;
    if (jac) {
      if (J[0]) Eigen::Map<Row>(J[0], n_, n_) = h * th * ph * w.Lqq - th * w.Lqv + ph * w.Lqv.transpose() - w.Lvv / h;
      if (J[1]) Eigen::Map<Row>(J[1], n_, n_) = h * th * th * w.Lqq + th * (w.Lqv + w.Lqv.transpose()) + w.Lvv / h;
    }
    at(qb, qc, jac);  // the right interval
    Eigen::Map<V>(r, n_) += h * ph * w.Lq - w.Lv;
    if (jac) {
      if (J[1])
        Eigen::Map<Row>(J[1], n_, n_) += h * ph * ph * w.Lqq - ph * (w.Lqv + w.Lqv.transpose()) + w.Lvv / h;
      if (J[2]) Eigen::Map<Row>(J[2], n_, n_) = h * th * ph * w.Lqq + ph * w.Lqv - th * w.Lqv.transpose() - w.Lvv / h;
    }
  }

  // Solves for q_1 .. q_{K-1} between q_0 = qa and q_K = qb (solve_boundary_value:
  // the same Ceres problem, stopping rule and result as the fixed-size problem's).
  BoundaryValueResult<Eigen::Dynamic> solve(const V& qa, const V& qb, int K, const BoundaryValueOptions& opt = {},
                                            const std::vector<V>* guess = nullptr) const {
    return solve_boundary_value<Eigen::Dynamic>(
        qa, qb, K, h_, opt, guess, [&] { return new Cost(*this); },
        [&](const V& a, const V& b) { return D1Ld(a, b); }, [&](const V& a, const V& b) { return D2Ld(a, b); },
        [&](const V& q0, const V& v0) {
          L_.hessian(q0, v0, work_.Lq, work_.Lv, work_.Lqq, work_.Lqv, work_.Lvv);
          return max_abs(work_.Lvv);
        });
  }

 private:
  // DEL_k as Ceres' cost function of the three nodes; Ceres evaluates the blocks one at
  // a time (solve_boundary_value's one thread), so they share the problem's workspace.
  class Cost final : public ceres::CostFunction {
   public:
    explicit Cost(const DynamicBoundaryValueProblem& P) : P_(P) {
      set_num_residuals(P.n_);
      mutable_parameter_block_sizes()->assign(3, P.n_);
    }
    bool Evaluate(double const* const* x, double* r, double** J) const override {
      P_.evaluate(x[0], x[1], x[2], r, J);
      return true;
    }

   private:
    const DynamicBoundaryValueProblem& P_;
  };

  // L's gradient (and Hessian) at the interval (a, b)'s point, x = a + theta (b - a),
  // v = (b - a) / h.
  template <class A, class B>
  void at(const A& a, const B& b, bool hessian) const {
    Work& w = work_;
    w.v = (b - a) / h_;
    w.x = a + theta_ * (b - a);
    if (hessian)
      L_.hessian(w.x, w.v, w.Lq, w.Lv, w.Lqq, w.Lqv, w.Lvv);
    else
      L_.gradient(w.x, w.v, w.Lq, w.Lv);
  }

  struct Work {
    explicit Work(int n) : x(n), v(n), Lq(n), Lv(n), Lqq(n, n), Lqv(n, n), Lvv(n, n) {}
    V x, v, Lq, Lv;
    M Lqq, Lqv, Lvv;
  };

  Sys L_;
  double theta_, h_;
  int n_;
  mutable Work work_;
};

}  // namespace dvm
