// The run-time-sized steps of the built-in systems of fixed size on R^n
// (make_run_time_sized_run, declared in kernels_rn.h): DynamicThetaStep and, in the
// hamiltonian form, DynamicHamiltonianThetaStep of H from L by the Legendre transform,
// alone or composed, and DynamicGalerkinStep (solvers/dynamic_step.h,
// solvers/dynamic_galerkin_step.h), the steps the Lagrangians written on R^n run too.
// They give their derivative by the implicit function theorem (--linearize), and the
// hamiltonian one is the faster step of the hamiltonian form from two coordinates on
// (kernels_rn.h). Here they run on the built-in system through ErasedDynamicLagrangian
// (its closed-form gradient, the Hessian by one Jet level through it: FixedAsDynamic),
// and the built-in's own view (columns, invariants, exact solution) through
// ErasedRnView<Eigen::Dynamic>: one instantiation serves every built-in system.
#include "mechanics/erased_dynamic.h"
#include "solvers/dynamic_galerkin_step.h"
#include "solvers/dynamic_step.h"
#include "solvers/runtime/kernels_rn.h"

namespace dvm::kernels {

std::unique_ptr<Run> make_run_time_sized_run(const ErasedDynamicLagrangian& L, const ErasedRnView<Eigen::Dynamic>& view,
                                         const Problem& pr, const Method& me, RunReport base,
                                         const Eigen::VectorXd& q, const Eigen::VectorXd& p,
                                         const Eigen::VectorXd& v0) {
  using Sys = ErasedDynamicLagrangian;
  const StepOptions opt = me.step_options();
  const double h = pr.step;
  base.step_path = StepPath::generic;
  if (me.galerkin)
    return stepper_run<true>(view, DynamicGalerkinStep<Sys>(L, me.quadrature, me.stages, h, opt), q, p, v0, base,
                             pr.steps);
  const ThetaMap R = dynamic_theta_map(me);
  if (me.form == Form::hamiltonian) {
    // H from L by the Legendre transform; lift = "none": the theta map on T*Q itself
    using Step = DynamicHamiltonianThetaStep<LegendreDynamicHamiltonian<Sys>>;
    const LegendreDynamicHamiltonian<Sys> H(L);
    const bool on_bundle = me.effective_lift() == Lift::none;
    auto make = [&](double hk, const ThetaMap& Rk) { return Step(H, Rk, hk, opt, on_bundle); };
    return composable_run<true>(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
  }
  auto make = [&](double hk, const ThetaMap& Rk) { return DynamicThetaStep<Sys>(L, Rk, hk, opt); };
  return composable_run<true>(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
}

}  // namespace dvm::kernels
