// The kernels of the fixed-size systems on R^n compiled once per size
// (make_sized_run<N>, declared in kernels_rn.h): every choice of the method that
// make_rn_run<S> does not compile for each system S, run with the system and its view
// erased (ErasedLagrangian<N>, ErasedRnView<N>):
//
//   form / method     step
//   lagrangian        PositionMomentumStep<L, Map> for the maps inverted by Newton's
//                     method (retraction-theta, written) and for TinySolver
//   hamiltonian       HamiltonianStep<LegendreHamiltonian<L>, Map>, or on the cotangent
//                     bundle itself (lift none, the theta maps): of one coordinate, by
//                     TinySolver, of retraction-theta and written maps (the theta maps
//                     by Newton's method from two coordinates are make_rn_run's)
//   sode1 / sode2     SodeStep<L, tangent lift of Map>, or of the Legendre lift
//   newmark           NewmarkStep<L>
//   galerkin          GalerkinStep<L> (Gauss collocation of a separable system is
//                     make_rn_run's)
//   composition       ComposedStep of any of these
//   boundary value    BoundaryValueProblem<L, Map>
//
// Included only by kernels_rn_size*.cc, each instantiating one size.
#pragma once

#include <memory>
#include <type_traits>
#include <variant>

#include "solvers/runtime/kernels_rn.h"

namespace dvm::kernels {

template <int N>
std::unique_ptr<Run> make_sized_run(const ErasedLagrangian<N>& L, const ErasedRnView<N>& view, const Problem& pr,
                                    const Method& me, RunReport base, const SizedStart<N>* start) {
  using S = ErasedLagrangian<N>;
  using View = ErasedRnView<N>;
  const StepOptions opt = me.step_options();
  const double h = pr.step;

  if (!start) {
    return std::visit(
        [&](const auto& R) -> std::unique_ptr<Run> {
          using Map = std::decay_t<decltype(R)>;
          return std::make_unique<BoundaryValueRun<View, BoundaryValueProblem<S, Map>>>(
              view, BoundaryValueProblem<S, Map>(L, R, h), to_vec<N>(pr.q), to_vec<N>(pr.q_final), pr.steps, h,
              me.max_iterations, base, false);
        },
        rn_map(me));
  }
  const Vec<double, N>&q = start->q, &p = start->p, &v0 = start->v0;

  if (me.galerkin) return stepper_run(view, GalerkinStep<S>(L, me.quadrature, me.stages, h, opt), q, p, v0, base, pr.steps);

  if (me.form == Form::newmark) {
    const NewmarkStep<S> basic(L, h, me.newmark_gamma, me.newmark_beta, opt);
    auto make = [&](double hk, const NewmarkStep<S>& b) { return VelocityFormStep<NewmarkStep<S>>(b.with_step(hk)); };
    const auto stages = composition_stages(
        me, basic, me.newmark_gamma == 0.5, [](const NewmarkStep<S>& b) { return b.adjoint(); },
        [&](double) -> NewmarkStep<S> { throw InputError("integrator.thetas: unsupported"); });  // refused by validate()
    return composable_run(view, me, h, stages, make, q, p, v0, base, pr.steps);
  }

  return std::visit(
      [&](const auto& R) -> std::unique_ptr<Run> {
        using Map = std::decay_t<decltype(R)>;
        switch (me.form) {
          case Form::lagrangian: {
            auto make = [&](double hk, const Map& Rk) { return PositionMomentumStep<S, Map>(L, Rk, hk, opt); };
            return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
          }
          case Form::hamiltonian: {
            using H = LegendreHamiltonian<S>;
            const H ham(L);
            if (me.effective_lift() == Lift::none) {
              // the map itself on T*Q = R^{2n} (the theta family: validate refuses written maps)
              if constexpr (std::is_same_v<Map, ThetaMap>) {
                auto make = [&](double hk, const Map& Rk) {
                  return HamiltonianStep<H, OnCotangentBundle<Map>>(ham, OnCotangentBundle<Map>{Rk}, hk, opt);
                };
                return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
              }
              throw InputError("integrator.lift: unsupported");
            }
            auto make = [&](double hk, const Map& Rk) { return HamiltonianStep<H, Map>(ham, Rk, hk, opt); };
            return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
          }
          case Form::sode1:
          case Form::sode2: {
            // the lift of the adjoint map gives the adjoint SODE step (Prop. 3.3 for the
            // tangent lift; R_d^L is the cotangent lift of R_d conjugated by FL, Prop. 3.7)
            const SodeForm f = me.form == Form::sode1 ? SodeForm::sode1 : SodeForm::sode2;
            if (me.effective_lift() == Lift::legendre) {
              // (the theta family: validate refuses written maps)
              if constexpr (std::is_same_v<Map, ThetaMap>) {
                using RL = LegendreLiftedMap<S, Map>;
                auto make = [&, f](double hk, const Map& Rk) {
                  return VelocityFormStep<SodeStep<S, RL>>(SodeStep<S, RL>(L, RL(L, Rk), hk, f, opt));
                };
                return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
              }
              throw InputError("integrator.lift: unsupported");
            }
            auto make = [&, f](double hk, const Map& Rk) {
              const auto lift = tangent_lift(Rk);
              using Step = SodeStep<S, std::decay_t<decltype(lift)>>;
              return VelocityFormStep<Step>(Step(L, lift, hk, f, opt));
            };
            return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
          }
          case Form::newmark:
            break;
        }
        throw InputError("integrator.form: unsupported");
      },
      rn_map(me));
}

}  // namespace dvm::kernels
