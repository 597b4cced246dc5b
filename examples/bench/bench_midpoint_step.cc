// Cost per step of the generic midpoint step on the pendulum, against baselines
// measured in the same process:
//
//   hand-written Newton   the same implicit midpoint equations, written out by hand:
//                         with M = m l^2, k = m g l and the increment d = q1 - q0,
//                           f(d) = M d/h + (h/2) k sin(q0 + d/2) - p0 = 0,
//                           p1   = M d/h - (h/2) k sin(q0 + d/2),
//                         the same starting guess, tolerance and compensated sums;
//   odeint velocity_verlet  Boost.Odeint's explicit Stormer-Verlet (one force per step).
//
// The generic step derives everything from L(q, v) and the map: the map inverse,
// D1 L_d and its Jacobian by automatic differentiation (closed-form gradient of L,
// and, in the "autodiff only" row, not even that), solved by Newton or TinySolver.
//
// usage: bench_midpoint_step [--steps N] [--repeats R]
#include <boost/numeric/odeint.hpp>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "examples/bench/hand_written.h"
#include "examples/bench/step_timing.h"
#include "mechanics/systems.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"

using namespace dvm;
using V1 = Vec<double, 1>;

namespace {

struct Result {
  double ns_per_step;
  double q, p;
  double iterations_per_step;
};

template <class F>
Result best_of(int repeats, std::int64_t steps, F&& run_once) {
  Result best{INFINITY, 0, 0, 0};
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    Result res = run_once();
    const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                      static_cast<double>(steps);
    if (ns < best.ns_per_step) {
      best = res;
      best.ns_per_step = ns;
    }
  }
  return best;
}

template <class System>
Result generic(const System& L, double h, std::int64_t steps, SolverKind solver) {
  StepOptions opt;
  opt.solver = solver;
  const PositionMomentumStep<System, ThetaMap> S(L, ThetaMap::midpoint(), h, opt);
  V1 q(2.0), p(0.0);
  const RunSummary r = integrate(S, 0.0, q, p, V1::Zero(), steps, [](auto&&...) {});
  if (r.failed) {
    std::fprintf(stderr, "generic run failed at step %lld\n", static_cast<long long>(r.failed_step));
    std::exit(3);
  }
  return {0, q[0], p[0], static_cast<double>(r.solver_iterations) / static_cast<double>(steps)};
}

// The implicit midpoint equations of the pendulum, by hand (examples/bench/hand_written.h:
// the generic loop's starting guess, stopping rule and compensated sums).
Result hand_written(const Pendulum& P, double h, std::int64_t steps) {
  double q = 2.0, p = 0.0;
  const std::int64_t iters = bench::hand_midpoint_pendulum(P, q, p, h, steps, [](double, double) {});
  if (iters < 0) {
    std::fprintf(stderr, "hand-written run failed at step %lld\n", static_cast<long long>(-1 - iters));
    std::exit(3);
  }
  return {0, q, p, static_cast<double>(iters) / static_cast<double>(steps)};
}

Result odeint_verlet(const Pendulum& P, double h, std::int64_t steps) {
  using State = std::array<double, 1>;
  namespace odeint = boost::numeric::odeint;
  odeint::velocity_verlet<State> stepper;
  const double a = P.g / P.l;
  auto force = [a](const State& x, const State&, State& acc, double) { acc[0] = -a * std::sin(x[0]); };
  State x{2.0}, v{0.0};
  auto xv = std::make_pair(std::ref(x), std::ref(v));
  double t = 0.0;
  for (std::int64_t n = 0; n < steps; ++n) {
    stepper.do_step(force, xv, t, h);
    t += h;
  }
  return {0, x[0], v[0] * P.m * P.l * P.l, 0};
}

}  // namespace

int main(int argc, char** argv) {
  std::int64_t steps = 2000000;
  int repeats = 5;
  dvm::bench::parse_steps_and_repeats(argc, argv, "bench_midpoint_step", steps, repeats);
  const Pendulum P(1.0, 1.0, 1.0);
  const double h = 0.01;
  const Result hand = best_of(repeats, steps, [&] { return hand_written(P, h, steps); });
  const Result gen = best_of(repeats, steps, [&] { return generic(P, h, steps, SolverKind::newton); });
  const Result gen_ad =
      best_of(repeats, steps, [&] { return generic(GenericOnly<Pendulum>{P}, h, steps, SolverKind::newton); });
  const Result tiny = best_of(repeats, steps, [&] { return generic(P, h, steps, SolverKind::tiny); });
  const Result verlet = best_of(repeats, steps, [&] { return odeint_verlet(P, h, steps); });

  std::printf("pendulum (m = l = g = 1), q0 = 2, p0 = 0, h = %g, %lld steps, best of %d\n", h,
              static_cast<long long>(steps), repeats);
  std::printf("%-40s %12s %10s %12s %14s\n", "method", "ns/step", "ratio", "iters/step", "|q - q_hand|");
  auto row = [&](const char* name, const Result& r) {
    std::printf("%-40s %12.1f %10.2f %12.2f %14.3e\n", name, r.ns_per_step, r.ns_per_step / hand.ns_per_step,
                r.iterations_per_step, std::fabs(r.q - hand.q));
  };
  row("hand-written Newton (implicit midpoint)", hand);
  row("dvm generic midpoint, Newton", gen);
  row("dvm generic midpoint, autodiff only", gen_ad);
  row("dvm generic midpoint, TinySolver", tiny);
  row("odeint velocity_verlet (explicit)", verlet);
  std::printf("ratio = ns/step over the hand-written Newton loop; target for the generic Newton row: <= 3\n");
  std::printf("generic/hand-written = %.2f\n", gen.ns_per_step / hand.ns_per_step);
  return 0;
}
