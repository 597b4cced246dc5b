// Run kernels of the FPU chain of any length (solvers/chain_step.h: the theta-family
// maps, one tridiagonal Newton solve per step; compositions of that step). With
// --linearize the chain runs the run-time-sized steps that give their derivative
// (make_run_time_sized_run, kernels_rn.h) on ChainDynamic (mechanics/chain_dynamic.h), its
// Hessian dense: the same equations, solved by the dense Newton iteration.
#include "mechanics/chain.h"
#include "mechanics/chain_dynamic.h"
#include "solvers/chain_step.h"
#include "solvers/runtime/factories.h"
#include "solvers/runtime/flat_state_view.h"
#include "solvers/runtime/kernels.h"
#include "solvers/runtime/kernels_dynamic.h"
#include "solvers/runtime/kernels_rn.h"

namespace dvm::factories {

namespace {

struct ChainView : kernels::FlatStateView {
  FPUChain C;
  std::vector<std::string> columns() const {
    std::vector<std::string> c{"t"};
    for (int i = 0; i < C.n; ++i) c.push_back("q" + std::to_string(i));
    for (int i = 0; i < C.n; ++i) c.push_back("p" + std::to_string(i));
    c.push_back("energy");
    return c;
  }
  int row_size() const { return 2 * C.n + 2; }
  void fill_row(double* row, double t, const Point& q, const Covector& p, double E) const {
    row[0] = t;
    for (int i = 0; i < C.n; ++i) row[1 + i] = q[i], row[1 + C.n + i] = p[i];
    row[2 * C.n + 1] = E;
  }
  double energy(const Point& q, const Covector& p) const { return C.energy(q, p); }
  int invariant_count() const { return C.fixed ? 0 : 1; }
  void invariants(const Point&, const Covector& p, double* out) const {
    if (!C.fixed) out[0] = FPUChain::total_momentum(p);
  }
  std::vector<InvariantReport> invariant_reports(const double* I0) const {
    if (C.fixed) return {};
    InvariantReport r;
    r.name = "total momentum";
    r.initial = {I0[0]};
    return {r};
  }
  double point_defect(const Point&) const { return -1.0; }
};

}  // namespace

std::unique_ptr<Run> chain(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  const FPUChain C(static_cast<int>(P.at("n")), P.at("m"), P.at("k"), P.at("alpha"), P.at("beta"), P.at("fixed") != 0.0);
  const ChainView view{{}, C};
  Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(pr.q.data(), C.n), p, v0;
  if (pr.momentum_given) {
    p = Eigen::Map<const Eigen::VectorXd>(pr.p.data(), C.n);
    v0 = p / C.m;
  } else {
    v0 = Eigen::Map<const Eigen::VectorXd>(pr.v.data(), C.n);
    p = C.m * v0;
  }
  if (!std::isfinite(view.energy(q, p))) kernels::refuse_nonfinite_energy(pr);
  const RunReport base = kernels::base_report(pr, me, "chain");
  if (me.linearize) {
    kernels::require_dense_size(C.n, pr.origin + ": key 'system.params.n': got " + std::to_string(C.n) +
                                         "; with --linearize the chain's step");
    return kernels::make_run_time_sized_run(ErasedDynamicLagrangian(ChainDynamic(C)),
                                        kernels::ErasedRnView<Eigen::Dynamic>(view, C.n), pr, me, base, q, p, v0);
  }
  const ThetaMap R = std::get<ThetaMap>(kernels::rn_map(me));
  const StepOptions opt = me.step_options();
  auto make = [&](double hk, const ThetaMap& Rk) { return ChainStep(C, Rk, hk, opt); };
  return kernels::composable_run(view, me, pr.step, kernels::rn_stages(me, R), make, q, p, v0, base, pr.steps);
}

}  // namespace dvm::factories
