// The constrained theta step on sparse matrices (SparseConstrainedThetaStep,
// solvers/sparse_constrained_step.h) as make_constrained_run (kernels_constrained.cc)
// takes it: a separable text of many coordinates, with a force or not, composed or not.
// A translation unit of its own, compiled beside kernels_constrained.cc: with it there,
// GCC's inliner (its budget per translation unit, solvers/CMakeLists.txt) left more of
// the small fixed-size constrained steps out of line (time `dvm run
// examples/scenes/pendulum_cartesian.toml --no-output` built each way).
#include "solvers/runtime/kernels_dynamic.h"
#include "solvers/sparse_constrained_step.h"

namespace dvm::kernels {

std::unique_ptr<Run> make_sparse_constrained_run(const WrittenDynamic& L, const Problem& pr, const Method& me,
                                                 const DynamicView<WrittenDynamic>& view, const Eigen::VectorXd& q,
                                                 const Eigen::VectorXd& p, const Eigen::VectorXd& v0, RunReport base,
                                                 const std::shared_ptr<const WrittenConstraints>& con,
                                                 const std::shared_ptr<const WrittenForce>& force) {
  std::shared_ptr<SparsePotentialHessian> H;
  try {
    H = SparseSeparableThetaStep::hessian_of(L, q);
  } catch (const SparsePotentialHessian::TooDense&) {
    return nullptr;  // terms coupling most coordinates: the caller's dense step, within its limit
  }
  con->check_pattern(0.0, q);
  const StepOptions opt = me.step_options();
  auto make = [&](double hk, const ThetaMap& Rk) {
    return SparseConstrainedThetaStep(L, H, con, Rk.theta(), hk, opt, force);
  };
  base.step_path = StepPath::constrained_sparse_newton;
  base.hessian_colours = H->colours();
  return composable_run(view, me, pr.step, rn_stages(me, dynamic_theta_map(me)), make, q, p, v0, base, pr.steps);
}

}  // namespace dvm::kernels
