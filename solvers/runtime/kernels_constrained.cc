// Run kernels of Lagrangians written in a scene with holonomic constraints
// ([system] constraints): the constrained theta step of solvers/constrained_step.h,
// composed or not, its Hamiltonian form (solvers/constrained_hamiltonian_step.h), and
// Lobatto Galerkin (solvers/constrained_galerkin_step.h), with the force where the
// system has one; the sparse step and the check of the initial state are
// kernels_sparse_constrained.cc's. Separate from kernels_written.cc so that the two
// compile side by side.
#include "solvers/constrained_galerkin_step.h"
#include "solvers/constrained_hamiltonian_step.h"
#include "solvers/runtime/kernels_dynamic.h"

namespace dvm::kernels {

std::unique_ptr<Run> make_constrained_run(const WrittenDynamic& L, const Problem& pr, const Method& me,
                                          const DynamicView<WrittenDynamic>& view, const Eigen::VectorXd& q,
                                          const Eigen::VectorXd& p, const Eigen::VectorXd& v0, const RunReport& base_in,
                                          const std::shared_ptr<const ControlSignal>& signal) {
  // (validate refuses these first)
  const bool hamiltonian = me.form == Form::hamiltonian;
  if ((me.form != Form::lagrangian && !hamiltonian) ||
      (hamiltonian && (me.galerkin || me.effective_lift() != Lift::cotangent)) ||
      (me.galerkin && me.quadrature != QuadratureKind::lobatto))
    throw InputError(pr.constraints_where + ": constraints enter the lagrangian form of the theta-family maps, "
                     "their hamiltonian form (the cotangent lift) and Lobatto Galerkin only");
  const int n = L.dim();
  RunReport base = base_in;
  const StepOptions opt = me.step_options();
  const double h = pr.step;
  const auto con = std::make_shared<const WrittenConstraints>(pr.written);
  std::shared_ptr<const WrittenForce> force;
  if (pr.forced()) {
    auto f = std::make_shared<WrittenForce>(pr.written, signal);
    require_finite_force(*f, pr, q, v0);
    base.forced = true;
    force = std::move(f);
  }
  // a separable Lagrangian of many coordinates, with a force or not, --linearize or not:
  // the sparse step (kernels_sparse_constrained.cc; none where the potential's terms
  // couple most coordinates: the dense step below, within its limit)
  if (!me.galerkin && !hamiltonian && me.use_structure && L.separable() && n >= kSparseConstrainedMinDim)
    if (auto run = make_sparse_constrained_run(L, pr, me, view, q, p, v0, base, con, force)) return run;
  require_dense_size(n,
                     (me.galerkin    ? std::string("integrator.method: method = \"galerkin\"")
                      : hamiltonian ? std::string("integrator.form: form = \"hamiltonian\"")
                                    : "integrator.map: map = \"" + me.map->name + "\"") +
                         " with system.constraints",
                     " (the sparse constrained step takes a separable Lagrangian of any size whose potential's "
                     "Hessian is sparse: a theta map)");
  base.step_path = StepPath::generic;
  const MomentumMap momentum = L.separable()               ? MomentumMap::constant
                               : L.parts().split.quadratic ? MomentumMap::linear
                                                           : MomentumMap::general;
  if (me.galerkin) {  // the constraints at the Lobatto nodes (validate refused Gauss)
    auto galerkin = [&](auto fo) {
      using Force = std::remove_const_t<typename decltype(fo)::element_type>;
      return stepper_run<true>(view,
                               ConstrainedGalerkinStep<WrittenDynamic, WrittenConstraints, Force>(L, me.stages, h, con,
                                                                                                 opt, momentum, fo),
                               q, p, v0, base, pr.steps);
    };
    return force ? galerkin(force) : galerkin(std::shared_ptr<const NoForce>());
  }
  const ThetaMap R = dynamic_theta_map(me);
  if (hamiltonian) {  // H: the scene's written H (checked against L's transform), or L's transform
    auto run_hamiltonian = [&](const auto& H) {
      auto with_force = [&](auto fo) {
        using Force = std::remove_const_t<typename decltype(fo)::element_type>;
        using Step = ConstrainedHamiltonianThetaStep<std::decay_t<decltype(H)>, WrittenDynamic, WrittenConstraints, Force>;
        auto make = [&](double hk, const ThetaMap& Rk) { return Step(H, L, Rk, hk, con, opt, momentum, fo); };
        return composable_run<true>(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
      };
      return force ? with_force(force) : with_force(std::shared_ptr<const NoForce>());
    };
    if (L.has_hamiltonian()) {
      const auto H = compiled_or_not([&](WrittenDerivatives m) { return WrittenDynamicHamiltonian(pr.written, m); }, pr);
      base.compile_seconds += H.compile_seconds();
      return run_hamiltonian(H);
    }
    return run_hamiltonian(LegendreDynamicHamiltonian<WrittenDynamic>(L));
  }
  auto run_with = [&](auto fo, auto nc) {
    using Force = std::remove_const_t<typename decltype(fo)::element_type>;
    constexpr int NC = decltype(nc)::value, MC = NC == Eigen::Dynamic ? Eigen::Dynamic : 1;
    auto make = [&](double hk, const ThetaMap& Rk) {
      return ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, Force, NC, MC>(L, Rk, hk, con, opt, momentum, fo);
    };
    return composable_run<NC == Eigen::Dynamic>(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
  };
  if (force) return run_with(force, std::integral_constant<int, Eigen::Dynamic>());
  // the step of fixed size for the few coordinates of a pendulum, a planar linkage or
  // a point on a surface in R^3 with one constraint: the saddle-point Jacobian and its LU
  // of fixed size (bench_constrained measures the constrained scenes)
  const std::shared_ptr<const NoForce> none;
  // (--linearize: the step of run-time size, whose derivative alone is compiled)
  const bool fixed = me.use_structure && !me.linearize && con->count() == 1;
  if (fixed && n == 2) return run_with(none, std::integral_constant<int, 2>());
  if (fixed && n == 3) return run_with(none, std::integral_constant<int, 3>());
  return run_with(none, std::integral_constant<int, Eigen::Dynamic>());
}

}  // namespace dvm::kernels
