// The FPU chain (mechanics/chain.h) as a run-time-sized system of the concept of
// mechanics/dynamic_system.h, so that the generic run-time-sized steps (and what they
// give: the derivative of the step, `dvm run --linearize`) run on it:
//
//   L = sum_i m v_i^2 / 2 - V(q),   L_q = -grad V,   L_v = m v,
//   L_qq = -Hess V (tridiagonal, the bonds' stiffnesses),   L_qv = 0,   L_vv = m I,
//   v = p / m.
//
// The chain's own step (solvers/chain_step.h) solves the same theta-map equations with
// its tridiagonal Newton iteration; here the Hessian is returned dense, as the concept
// asks.
#pragma once

#include <Eigen/Core>
#include <string>

#include "mechanics/chain.h"
#include "mechanics/dynamic_system.h"

namespace dvm {

struct ChainDynamic {
  static constexpr Structure structure = Structure::separable;
  FPUChain C;
  mutable Eigen::VectorXd g, diag, off;  // scratch of the bond loops

  explicit ChainDynamic(FPUChain chain) : C(std::move(chain)) {}
  int dim() const { return C.n; }
  std::string name() const { return C.name(); }
  double value(const DynIn& q, const DynIn& v) const { return 0.5 * C.m * v.squaredNorm() - C.potential(q); }
  void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const {
    C.gradient(q, g);
    Lq = -g;
    Lv = C.m * v;
  }
  void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv, DynMatOut Lqq, DynMatOut Lqv,
               DynMatOut Lvv) const {
    gradient(q, v, Lq, Lv);
    C.hessian(q, diag, off);
    Lqq.setZero();
    for (int i = 0; i < C.n; ++i) Lqq(i, i) = -diag[i];
    for (int i = 0; i + 1 < C.n; ++i) Lqq(i, i + 1) = Lqq(i + 1, i) = -off[i];
    Lqv.setZero();
    Lvv.setZero();
    Lvv.diagonal().setConstant(C.m);
  }
  void velocity(const DynIn&, const DynIn& p, DynOut v) const { v = p / C.m; }
};

}  // namespace dvm
