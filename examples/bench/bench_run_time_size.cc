// Cost per step of the forms that `dvm run` may take at fixed or at run-time size on
// the built-in systems of R^n, by both steps, measured in this process:
//
//   hamiltonian  the cotangent lift of the midpoint map (Eq. 5.1 of the paper, H from L
//                by the Legendre transform), and the map on T*Q itself (lift none):
//                fixed size   HamiltonianStep<LegendreHamiltonian<ErasedLagrangian<N>>,
//                             ThetaMap>: the residual in Jets of size 2N, H's gradient
//                             through a Newton inverse of the Legendre map in nested
//                             Jets (make_sized_run<N>);
//                run-time     DynamicHamiltonianThetaStep<LegendreDynamicHamiltonian<
//                             ErasedDynamicLagrangian>>: the Jacobian from H's Hessian
//                             blocks, from L's gradient and one Jet level of it, the
//                             inverse Legendre map in closed form where the system has
//                             one (make_run_time_sized_run);
//   galerkin     the Galerkin step with Gauss (s = 2) and Lobatto (s = 3) quadrature:
//                GalerkinStep<ErasedLagrangian<N>> (make_sized_run<N>) against
//                DynamicGalerkinStep<ErasedDynamicLagrangian> (--linearize). (Gauss
//                on a separable system runs by collocation, SeparableGaussStep,
//                neither of these.)
//
// Both erase the system behind one indirect call per evaluation, as `dvm run` does.
// Each runs from the system's example scene, Newton's method and the same tolerances,
// and reports ns/step, the ratio run-time / fixed, and the largest difference of their
// states after 100 steps (both solve the same equations: round-off and the solver's
// tolerance; over the timed runs a chaotic system such as the double pendulum
// amplifies it to O(1)). kernels_rn.h takes the run-time-sized step where the ratio is
// below 1 (the hamiltonian form from two coordinates on; Galerkin stays at fixed size).
//
// usage: bench_run_time_size [--steps N] [--repeats R]
#include <cstdio>
#include <tuple>

#include "examples/bench/step_timing.h"
#include "mechanics/erased_dynamic.h"
#include "mechanics/erased_lagrangian.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "solvers/dynamic_galerkin_step.h"
#include "solvers/dynamic_step.h"
#include "solvers/galerkin_step.h"
#include "solvers/hamiltonian_step.h"

using namespace dvm;
using namespace dvm::bench;

namespace {

// q0 and either p0 or, with `velocity`, v0 (as the example scene gives it).
template <class S>
void compare(const char* title, const S& system, const Vec<double, S::dim>& q0, const Vec<double, S::dim>& x0,
             bool velocity, double h, std::int64_t steps, int repeats) {
  constexpr int N = S::dim;
  using V = Vec<double, N>;
  const V p0 = velocity ? V(legendre(system, q0, x0)) : x0;
  const V v0 = legendre_inverse(system, q0, p0);
  const ErasedLagrangian<N> fixed_L = erase_lagrangian(system);
  const LegendreHamiltonian<ErasedLagrangian<N>> fixed_H(fixed_L);
  const ErasedDynamicLagrangian dyn_L{FixedAsDynamic<S>(system)};
  const LegendreDynamicHamiltonian<ErasedDynamicLagrangian> dyn_H(dyn_L);
  const Eigen::VectorXd q0d = q0, p0d = p0, v0d = v0;
  const ThetaMap R = ThetaMap::midpoint();
  std::printf("%s (%d coordinate%s), h = %g, %lld steps, best of %d\n", title, N, N == 1 ? "" : "s", h,
              static_cast<long long>(steps), repeats);
  std::printf("  %-24s %12s %12s %8s %14s\n", "form", "fixed ns", "run-time ns", "ratio", "|diff| at 100");
  auto row = [](const char* form, const Result& a, const Result& b, double diff) {
    std::printf("  %-24s %12.1f %12.1f %8.2f %14.3e\n", form, a.ns_per_step, b.ns_per_step,
                b.ns_per_step / a.ns_per_step, diff);
  };
  for (const bool none : {false, true}) {
    // runs of n steps of each: the best of r, and the states after 100 steps
    auto fixed = [&](std::int64_t n, int r) {
      if (none) {
        using Step = HamiltonianStep<LegendreHamiltonian<ErasedLagrangian<N>>, OnCotangentBundle<ThetaMap>>;
        return time_steps(Step(fixed_H, OnCotangentBundle<ThetaMap>{R}, h), q0, p0, v0, n, r, title);
      }
      using Step = HamiltonianStep<LegendreHamiltonian<ErasedLagrangian<N>>, ThetaMap>;
      return time_steps(Step(fixed_H, R, h), q0, p0, v0, n, r, title);
    };
    auto run_time = [&](std::int64_t n, int r) {
      using Step = DynamicHamiltonianThetaStep<LegendreDynamicHamiltonian<ErasedDynamicLagrangian>>;
      return time_steps(Step(dyn_H, R, h, {}, none), q0d, p0d, v0d, n, r, title);
    };
    const Result a = fixed(steps, repeats), b = run_time(steps, repeats);
    const double diff = state_diff(fixed(100, 1), run_time(100, 1));
    row(none ? "hamiltonian, lift none" : "hamiltonian, cotangent", a, b, diff);
  }
  for (const auto& [kind, stages, name] : {std::tuple{QuadratureKind::gauss, 2, "galerkin, Gauss s = 2"},
                                           std::tuple{QuadratureKind::lobatto, 3, "galerkin, Lobatto s = 3"}}) {
    auto fixed = [&, kind = kind, stages = stages](std::int64_t n, int r) {
      return time_steps(GalerkinStep<ErasedLagrangian<N>>(fixed_L, kind, stages, h), q0, p0, v0, n, r, title);
    };
    auto run_time = [&, kind = kind, stages = stages](std::int64_t n, int r) {
      return time_steps(DynamicGalerkinStep<ErasedDynamicLagrangian>(dyn_L, kind, stages, h), q0d, p0d, v0d, n, r,
                        title);
    };
    const Result a = fixed(steps, repeats), b = run_time(steps, repeats);
    row(name, a, b, state_diff(fixed(100, 1), run_time(100, 1)));
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::int64_t steps = 20000;
  int repeats = 3;
  parse_steps_and_repeats(argc, argv, "bench_run_time_size", steps, repeats);
  using V1 = Vec<double, 1>;
  using V2 = Vec<double, 2>;
  using V6 = Vec<double, 6>;
  compare("pendulum", Pendulum(), V1(2.0), V1(0.0), false, 0.01, steps, repeats);
  compare("duffing", Duffing(), V1(1.5), V1(0.0), false, 0.01, steps, repeats);
  compare("kepler", Kepler(), V2(0.4, 0.0), V2(0.0, 2.0), false, 0.005, steps, repeats);
  compare("double pendulum", DoublePendulum(), V2(1.5, 2.0), V2(0.0, 0.0), true, 0.01, steps, repeats);
  compare("henon-heiles", HenonHeiles(), V2(0.0, 0.1), V2(0.4479583313955291, 0.2), false, 0.05, steps, repeats);
  compare("charged particle", ChargedParticle(1.0, 1.0, 4.0, 0.5), V2(1.0, 0.0), V2(0.0, 0.5), true, 0.01, steps,
          repeats);
  V6 q0, p0;
  q0 << 0.6929646455628166, 0.7212489168102785, 0, 0, 0, 0;
  p0 << 0, 1.4142135623730951, 0, 0, 0, 0;
  compare("fpu", FermiPastaUlam(50.0), q0, p0, false, 0.002, steps / 10, repeats);
  return 0;
}
