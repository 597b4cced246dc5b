// Run kernels of Lagrangians written in a scene with holonomic constraints
// ([system] constraints): the constrained theta step of solvers/constrained_step.h,
// composed or not, with the force where the system has one. Separate from
// kernels_written.cc so that the two compile side by side.
#include "solvers/runtime/kernels_dynamic.h"

namespace dvm::kernels {

std::unique_ptr<Run> make_constrained_run(const WrittenDynamic& L, const Problem& pr, const Method& me,
                                          const DynamicView<WrittenDynamic>& view, const Eigen::VectorXd& q,
                                          const Eigen::VectorXd& p, const Eigen::VectorXd& v0, const RunReport& base_in,
                                          const std::shared_ptr<const ControlSignal>& signal) {
  if (me.form != Form::lagrangian || me.galerkin)  // (validate refuses it first)
    throw InputError(pr.constraints_where + ": constraints enter the lagrangian form of the theta-family maps only");
  const int n = L.dim();
  if (n > kMaxDenseDynamicDim)
    throw InputError("integrator.map: map = \"" + me.map->name + "\" with system.constraints needs dense " +
                     std::to_string(n) + " x " + std::to_string(n) + " matrices, beyond the " +
                     std::to_string(kMaxDenseDynamicDim) + " coordinates the run-time-sized dense steps take");
  RunReport base = base_in;
  base.step_path = StepPath::generic;
  const StepOptions opt = me.step_options();
  const double h = pr.step;
  const ThetaMap R = dynamic_theta_map(me);
  const auto con = std::make_shared<const WrittenConstraints>(pr.written);
  const MomentumMap momentum = L.separable()               ? MomentumMap::constant
                               : L.parts().split.quadratic ? MomentumMap::linear
                                                           : MomentumMap::general;
  auto run_with = [&](auto force, auto nc) {
    using Force = std::remove_const_t<typename decltype(force)::element_type>;
    constexpr int NC = decltype(nc)::value, MC = NC == Eigen::Dynamic ? Eigen::Dynamic : 1;
    auto make = [&](double hk, const ThetaMap& Rk) {
      return ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, Force, NC, MC>(L, Rk, hk, con, opt, momentum,
                                                                                    force);
    };
    return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
  };
  if (pr.forced()) {
    const auto force = std::make_shared<WrittenForce>(pr.written, signal);
    require_finite_force(*force, pr, q, v0);
    base.forced = true;
    return run_with(std::shared_ptr<const WrittenForce>(force), std::integral_constant<int, Eigen::Dynamic>());
  }
  // the step of fixed size for the few coordinates of a pendulum, a planar linkage or
  // a point on a surface in R^3 with one constraint: the saddle-point Jacobian and its LU
  // of fixed size (bench_constrained measures the constrained scenes)
  const std::shared_ptr<const NoForce> none;
  if (me.use_structure && con->count() == 1 && n == 2) return run_with(none, std::integral_constant<int, 2>());
  if (me.use_structure && con->count() == 1 && n == 3) return run_with(none, std::integral_constant<int, 3>());
  return run_with(none, std::integral_constant<int, Eigen::Dynamic>());
}

}  // namespace dvm::kernels
