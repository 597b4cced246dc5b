// Cost per step of the hamiltonian form (the cotangent lift of a theta map, Eq. 5.1 of
// the paper, H from L by the Legendre transform) on the built-in systems of R^n, by the
// two steps `dvm run` can take for it, measured in this process:
//
//   fixed size   HamiltonianStep<LegendreHamiltonian<ErasedLagrangian<N>>, ThetaMap>:
//                the residual in Jets of size 2N, H's gradient through a Newton
//                inverse of the Legendre map in nested Jets (make_sized_run<N>);
//   run-time     DynamicHamiltonianThetaStep<LegendreDynamicHamiltonian<
//                ErasedDynamicLagrangian>>: the residual's Jacobian from H's closed
//                Hessian blocks (L's gradient and one Jet level of it, its inverse
//                Legendre map in closed form where the system has one)
//                (make_run_time_sized_run).
//
// Both erase the system behind one indirect call per evaluation, as `dvm run` does.
// Each runs the midpoint map with the lift "cotangent" and "none" (the map on T*Q
// itself) from the system's example scene, Newton's method and the same tolerances,
// and reports ns/step, the ratio run-time / fixed, and the largest difference of their
// states after 100 steps (both solve the same equations: round-off and the solver's
// tolerance; over the timed runs a chaotic system such as the double pendulum
// amplifies it to O(1)).
// kernels_rn.h routes the hamiltonian form by the ratio: to the run-time-sized step
// where it is below 1.
//
// usage: bench_hamiltonian_form [--steps N] [--repeats R]
#include <cstdio>

#include "examples/bench/step_timing.h"
#include "mechanics/erased_dynamic.h"
#include "mechanics/erased_lagrangian.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "solvers/dynamic_step.h"
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
  const LegendreDynamicHamiltonian<ErasedDynamicLagrangian> dyn_H{ErasedDynamicLagrangian(FixedAsDynamic<S>(system))};
  const Eigen::VectorXd q0d = q0, p0d = p0, v0d = v0;
  const ThetaMap R = ThetaMap::midpoint();
  std::printf("%s (%d coordinate%s), h = %g, %lld steps, best of %d\n", title, N, N == 1 ? "" : "s", h,
              static_cast<long long>(steps), repeats);
  std::printf("  %-10s %12s %12s %8s %14s\n", "lift", "fixed ns", "run-time ns", "ratio", "|diff| at 100");
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
    std::printf("  %-10s %12.1f %12.1f %8.2f %14.3e\n", none ? "none" : "cotangent", a.ns_per_step, b.ns_per_step,
                b.ns_per_step / a.ns_per_step, diff);
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::int64_t steps = 20000;
  int repeats = 3;
  parse_steps_and_repeats(argc, argv, "bench_hamiltonian_form", steps, repeats);
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
