// Cost per step of a Lagrangian written as text (mechanics/expression.h, evaluated
// from its tape) against the same system built in, all measured in this process:
//
//   built-in           the system's C++ struct with its closed-form gradient and
//                      inverse Legendre map (the path the engine takes by default);
//   built-in, autodiff the same struct with its closed forms hidden (GenericOnly):
//                      derivatives by nested Jets, exactly as for a written one;
//   written            the Lagrangian parsed from text, its size fixed at compile time
//                      (WrittenLagrangian<N>): its gradient by the derivative program
//                      (mechanics/derivative_program.h), one Jet level through it for
//                      the Jacobian, as the built-in's closed-form gradient;
//   written, run-time  the same text through the run-time-sized generic step
//                      (WrittenDynamic: gradient and Hessian by the derivative program;
//                      DynamicThetaStep);
//   dvm run            the built-in system and the text through the runtime API, exactly
//                      as `dvm run` runs a scene (make_run, execute; the energy monitored
//                      at the end only), whatever step each takes (its step_path shown):
//                      the figure a user sees; and the text again with
//                      system.compile (its derivative programs compiled to machine
//                      code, mechanics/native_code.h; needs the C compiler cc or $DVM_CC);
//   ..., E each        the built-in and the text as a scene runs them by default, the
//                      energy monitored at every step: for a text, its inverse Legendre
//                      map and energy each step (mechanics/written_dynamic.h).
//
// Each runs the midpoint map's position-momentum step with Newton's method, the same
// tolerances and start, and reports ns/step, the ratio to the built-in row, and the
// largest difference of the final state (round-off only: the equations are the same).
// Then separable texts against the built-in closed forms: Stormer-Verlet by kicks and
// drifts on Kepler and on the FPU chain, and the midpoint map on the chain (the sparse
// step of a written potential against the built-in tridiagonal Newton step).
//
// usage: bench_written_lagrangian [--steps N] [--repeats R]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "examples/bench/step_timing.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "mechanics/written_lagrangian.h"
#include "mechanics/chain.h"
#include "mechanics/chain_dynamic.h"
#include "mechanics/dynamic_system.h"
#include "mechanics/written_dynamic.h"
#include "solvers/chain_step.h"
#include "solvers/dynamic_step.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"
#include "solvers/runtime/recorder.h"
#include "solvers/runtime/registry.h"
#include "solvers/runtime/run.h"
#include "solvers/sparse_separable_step.h"
#include "solvers/splitting_step.h"

using namespace dvm;
using namespace dvm::bench;

namespace {

template <class System>
Result measure(const System& L, const Vec<double, System::dim>& q0, const Vec<double, System::dim>& p0, double h,
               std::int64_t steps, int repeats) {
  const PositionMomentumStep<System, ThetaMap> S(L, ThetaMap::midpoint(), h);
  const Vec<double, System::dim> v0 = legendre_inverse(L, q0, p0);
  return time_steps(S, q0, p0, v0, steps, repeats, L.name());
}

// The run-time-sized path of the same text.
Result measure_dynamic(const std::shared_ptr<WrittenSystem>& text, const Eigen::VectorXd& q0,
                       const Eigen::VectorXd& p0, double h, std::int64_t steps, int repeats) {
  const WrittenDynamic L(text);
  const DynamicThetaStep<WrittenDynamic> S(L, ThetaMap::midpoint(), h);
  const Eigen::VectorXd v0 = legendre_inverse(L, q0, p0);
  return time_steps(S, q0, p0, v0, steps, repeats, "written, run-time sized");
}

// A run through the runtime API as `dvm run` runs a scene: the built-in `system` with
// `params`, or the written text (its derivatives compiled with `compile`, system.compile);
// the midpoint map, or Stormer-Verlet by composition of the explicit Euler maps with
// `stormer_verlet`; the energy monitored at the last step only (what is timed is the
// steps), or every `monitor_every` steps (1: as a scene runs by default). The best of
// `repeats`, and the step path taken.
struct RunResult {
  Result timing;
  std::string step_path;
};
RunResult measure_run(const std::string& system, const std::map<std::string, double>& params,
                      const std::shared_ptr<WrittenSystem>& text, const Eigen::VectorXd& q0, const Eigen::VectorXd& p0,
                      double h, std::int64_t steps, int repeats, bool compile = false, bool stormer_verlet = false,
                      std::int64_t monitor_every = 0) {
  Problem pr;
  if (text) {
    pr.system = &written_system_entry();
    pr.written = text;
    pr.compile = compile;
  } else {
    pr.system = &find_system_entry(system, "bench_written_lagrangian");
    pr.params = params;
  }
  pr.dim = static_cast<int>(q0.size());
  pr.q.assign(q0.data(), q0.data() + q0.size());
  pr.p.assign(p0.data(), p0.data() + p0.size());
  pr.momentum_given = true;
  pr.step = h;
  pr.steps = steps;
  dvm::Method me;
  me.map = &find_map_entry(stormer_verlet ? "explicit-euler" : "midpoint", "bench_written_lagrangian");
  if (stormer_verlet) {
    me.theta = 0.0;
    me.composition = "stormer-verlet";
  }
  validate(pr, me);
  RunResult best;
  for (int r = 0; r < repeats; ++r) {
    OutputSpec out;
    out.monitor_every = monitor_every > 0 ? monitor_every : steps;
    Recorder rec(out);
    auto run = make_run(pr, me);
    const auto t0 = std::chrono::steady_clock::now();
    const RunReport rep = run->execute(&rec);
    const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                      static_cast<double>(steps);
    if (rep.failed) {
      std::fprintf(stderr, "dvm run of %s failed: %s\n", system.c_str(), rep.loop.failure.message.c_str());
      std::exit(3);
    }
    if (ns < best.timing.ns_per_step) {
      best.timing.ns_per_step = ns;
      best.timing.state = rep.q_final;
      best.timing.state.insert(best.timing.state.end(), rep.p_final.begin(), rep.p_final.end());
      best.step_path = rep.step_path == StepPath::none ? "generic" : to_string(rep.step_path);
    }
  }
  return best;
}

std::shared_ptr<WrittenSystem> written(std::vector<std::string> coords, std::vector<std::pair<std::string, double>> params,
                                       const std::string& L) {
  auto s = std::make_shared<WrittenSystem>();
  s->name = "written";
  s->coordinates = std::move(coords);
  s->params = std::move(params);
  s->check_names();
  s->lagrangian = Expression::parse(L, s->symbols(WrittenSystem::Kind::lagrangian));
  return s;
}

template <class S>
void compare(const char* title, const S& builtin, const std::string& registry_name,
             const std::map<std::string, double>& params, const std::shared_ptr<WrittenSystem>& text,
             const Vec<double, S::dim>& q0, const Vec<double, S::dim>& p0, double h, std::int64_t steps, int repeats) {
  constexpr int N = S::dim;
  const Result a = measure(builtin, q0, p0, h, steps, repeats);
  const Result b = measure(GenericOnly<S>{builtin}, q0, p0, h, steps, repeats);
  const Result c = measure(WrittenLagrangian<N>(text), q0, p0, h, steps, repeats);
  const Result d = measure_dynamic(text, q0, p0, h, steps, repeats);
  const RunResult e = measure_run(registry_name, params, nullptr, q0, p0, h, steps, repeats);
  const RunResult f = measure_run(registry_name, params, text, q0, p0, h, steps, repeats);
  const RunResult g = measure_run(registry_name, params, text, q0, p0, h, steps, repeats, true);
  // as shipped: the energy monitored at every step (its inverse Legendre map included)
  const RunResult e1 = measure_run(registry_name, params, nullptr, q0, p0, h, steps, repeats, false, false, 1);
  const RunResult f1 = measure_run(registry_name, params, text, q0, p0, h, steps, repeats, false, false, 1);
  auto diff = [&](const Result& r) {
    double m = 0;
    for (std::size_t i = 0; i < r.state.size(); ++i) m = std::fmax(m, std::fabs(r.state[i] - a.state[i]));
    return m;
  };
  std::printf("%s, h = %g, %lld steps, best of %d\n  L = %s\n", title, h, static_cast<long long>(steps), repeats,
              text->lagrangian.text().c_str());
  std::printf("  %-28s %10s %8s %14s\n", "Lagrangian", "ns/step", "ratio", "|state diff|");
  std::printf("  %-28s %10.1f %8.2f %14s\n", "built-in (closed forms)", a.ns_per_step, 1.0, "-");
  std::printf("  %-28s %10.1f %8.2f %14.3e\n", "built-in, autodiff only", b.ns_per_step, b.ns_per_step / a.ns_per_step,
              diff(b));
  std::printf("  %-28s %10.1f %8.2f %14.3e\n", "written in the scene", c.ns_per_step, c.ns_per_step / a.ns_per_step,
              diff(c));
  std::printf("  %-28s %10.1f %8.2f %14.3e\n", "written, run-time sized", d.ns_per_step, d.ns_per_step / a.ns_per_step,
              diff(d));
  std::printf("  %-28s %10.1f %8.2f %14.3e   step path %s\n", "dvm run, built-in", e.timing.ns_per_step,
              e.timing.ns_per_step / a.ns_per_step, diff(e.timing), e.step_path.c_str());
  std::printf("  %-28s %10.1f %8.2f %14.3e   step path %s\n", "dvm run, written", f.timing.ns_per_step,
              f.timing.ns_per_step / a.ns_per_step, diff(f.timing), f.step_path.c_str());
  std::printf("  %-28s %10.1f %8.2f %14.3e   step path %s, |against interpreted| %.3e\n", "dvm run, written, compiled",
              g.timing.ns_per_step, g.timing.ns_per_step / a.ns_per_step, diff(g.timing), g.step_path.c_str(),
              state_diff(f.timing, g.timing));
  std::printf("  %-28s %10.1f %8.2f %14.3e\n", "dvm run, built-in, E each", e1.timing.ns_per_step,
              e1.timing.ns_per_step / a.ns_per_step, diff(e1.timing));
  std::printf("  %-28s %10.1f %8.2f %14.3e\n", "dvm run, written, E each", f1.timing.ns_per_step,
              f1.timing.ns_per_step / a.ns_per_step, diff(f1.timing));
  std::printf("  written / built-in autodiff = %.2f; dvm run, written / built-in = %.2f, compiled %.2f; "
              "with E each step (as shipped) %.2f\n\n",
              c.ns_per_step / b.ns_per_step, f.timing.ns_per_step / e.timing.ns_per_step,
              g.timing.ns_per_step / e.timing.ns_per_step, f1.timing.ns_per_step / e1.timing.ns_per_step);
}

// ---- derivatives alone ------------------------------------------------------------------
// One gradient, and one Hessian with its gradient, of the same text through
// WrittenDynamic: by its derivative program (the default), by the tape (reverse mode,
// forward over reverse for the Hessian) and by the program compiled
// (mechanics/native_code.h), at one state, best of `repeats` runs of `calls`.
void derivative_costs(const std::vector<std::pair<std::string, std::shared_ptr<WrittenSystem>>>& texts,
                      std::int64_t calls, int repeats) {
  std::printf("Derivatives of the texts above, one call, best of %d runs of %lld\n", repeats,
              static_cast<long long>(calls));
  std::printf("  %-18s %14s %14s %8s %14s %14s %8s %14s %14s\n", "text", "grad program", "grad tape", "ratio",
              "Hess program", "Hess tape", "ratio", "grad compiled", "Hess compiled");
  for (const auto& t : texts) {
    const WrittenDynamic P(t.second), R(t.second, WrittenDerivatives::forward_over_reverse),
        C(t.second, WrittenDerivatives::compiled);
    const int n = P.dim();
    const Eigen::VectorXd q = Eigen::VectorXd::LinSpaced(n, 0.3, 0.7), v = Eigen::VectorXd::LinSpaced(n, -0.2, 0.4);
    Eigen::VectorXd gq(n), gv(n);
    Eigen::MatrixXd A(n, n), B(n, n), D(n, n);
    auto best = [&](auto&& f) {
      double b = INFINITY;
      for (int r = 0; r < repeats; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        for (std::int64_t k = 0; k < calls; ++k) f();
        b = std::fmin(b, std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count() /
                             static_cast<double>(calls));
      }
      return b;
    };
    const double gp = best([&] { P.gradient(q, v, gq, gv); }), gt = best([&] { R.gradient(q, v, gq, gv); });
    const double hp = best([&] { P.hessian(q, v, gq, gv, A, B, D); }), ht = best([&] { R.hessian(q, v, gq, gv, A, B, D); });
    const double gc = best([&] { C.gradient(q, v, gq, gv); }), hc = best([&] { C.hessian(q, v, gq, gv, A, B, D); });
    std::printf("  %-18s %11.1f ns %11.1f ns %8.2f %11.1f ns %11.1f ns %8.2f %11.1f ns %11.1f ns\n", t.first.c_str(), gp,
                gt, gt / gp, hp, ht, ht / hp, gc, hc);
  }
  std::printf("\n");
}

// ---- explicit steps on separable systems ------------------------------------------------
// Stormer-Verlet by composition of the explicit Euler maps (solvers/splitting_step.h):
// the built-in system's closed-form force against a written text's, whose structure is
// read off its terms (WrittenSeparable: the reverse gradient of the potential's tape).


template <class S, class V>
Result measure_explicit(const S& L, const V& q0, const V& p0, double h, std::int64_t steps, int repeats) {
  const ExplicitSplittingStep<S> step(L, 0.0, h, substeps(find_composition("stormer-verlet"), false), q0);
  return time_steps(step, q0, p0, V(V::Zero(q0.size())), steps, repeats, L.name() + ", Stormer-Verlet");
}

void explicit_kepler(std::int64_t steps, int repeats) {
  const auto text = written({"x", "y"}, {{"mu", 1.0}}, "(x_dot^2 + y_dot^2)/2 + mu/sqrt(x^2 + y^2)");
  const WrittenDynamic W(text);
  const Vec<double, 2> q0(0.4, 0.0), p0(0.0, 2.0);
  const Result a = measure_explicit(Kepler(1.0), q0, p0, 0.005, steps, repeats);
  const Result b = measure_explicit(WrittenSeparable(W), Eigen::VectorXd(q0), Eigen::VectorXd(p0), 0.005, steps, repeats);
  const RunResult e = measure_run("kepler", {{"mu", 1.0}}, nullptr, q0, p0, 0.005, steps, repeats, false, true);
  const RunResult f = measure_run("kepler", {{"mu", 1.0}}, text, q0, p0, 0.005, steps, repeats, false, true);
  const RunResult g = measure_run("kepler", {{"mu", 1.0}}, text, q0, p0, 0.005, steps, repeats, true, true);
  std::printf("Kepler, e = 0.6, Stormer-Verlet by composition (kicks and drifts), h = 0.005, %lld steps, best of %d\n",
              static_cast<long long>(steps), repeats);
  std::printf("  %-28s %10s %8s %14s\n", "Lagrangian", "ns/step", "ratio", "|state diff|");
  std::printf("  %-28s %10.1f %8.2f %14s\n", "built-in (closed forms)", a.ns_per_step, 1.0, "-");
  std::printf("  %-28s %10.1f %8.2f %14.3e\n", "written, run-time sized", b.ns_per_step, b.ns_per_step / a.ns_per_step,
              state_diff(a, b));
  std::printf("  %-28s %10.1f %8.2f %14.3e   step path %s\n", "dvm run, built-in", e.timing.ns_per_step,
              e.timing.ns_per_step / a.ns_per_step, state_diff(a, e.timing), e.step_path.c_str());
  std::printf("  %-28s %10.1f %8.2f %14.3e   step path %s\n", "dvm run, written", f.timing.ns_per_step,
              f.timing.ns_per_step / a.ns_per_step, state_diff(a, f.timing), f.step_path.c_str());
  std::printf("  %-28s %10.1f %8.2f %14.3e   |against interpreted| %.3e\n", "dvm run, written, compiled",
              g.timing.ns_per_step, g.timing.ns_per_step / a.ns_per_step, state_diff(a, g.timing),
              state_diff(f.timing, g.timing));
  std::printf("  dvm run, written / built-in = %.2f, compiled %.2f\n\n", f.timing.ns_per_step / e.timing.ns_per_step,
              g.timing.ns_per_step / e.timing.ns_per_step);
}

// The FPU chain between walls written with sums (k = 1, alpha = 1/4, beta = 1), and its
// first normal mode.
std::shared_ptr<WrittenSystem> written_chain(int n) {
  auto w = std::make_shared<WrittenSystem>();
  w->name = "written chain";
  w->add_array("q", n, ExpressionSymbols::Boundary::fixed);
  w->params = {{"n", n}};
  w->check_names();
  w->lagrangian = Expression::parse(
      "sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n + 1, (q[i] - q[i-1])^2/2 + (q[i] - q[i-1])^3/12 + "
      "(q[i] - q[i-1])^4/4)",
      w->symbols(WrittenSystem::Kind::lagrangian));
  return w;
}
Eigen::VectorXd first_mode(int n) {
  Eigen::VectorXd q(n);
  for (int i = 0; i < n; ++i) q[i] = std::sin(M_PI * (i + 1) / (n + 1));
  return q;
}

void explicit_chain(int repeats) {
  std::printf("FPU chain between walls (k = 1, alpha = 0.25, beta = 1), Stormer-Verlet by composition, h = 0.05, "
              "best of %d\n  L = sum(i, 1, n, q_dot[i]^2/2) - sum(i, 1, n + 1, (q[i] - q[i-1])^2/2 + "
              "(q[i] - q[i-1])^3/12 + (q[i] - q[i-1])^4/4)\n",
              repeats);
  std::printf("  %8s %8s %14s %14s %8s %14s %14s\n", "n", "steps", "built-in ns", "written ns", "ratio",
              "written ns/n", "|state diff|");
  double per_particle_1000 = 0.0;
  for (int n : {1000, 10000, 25000}) {
    const WrittenDynamic W(written_chain(n));
    const Eigen::VectorXd q0 = first_mode(n), p0 = Eigen::VectorXd::Zero(n);
    const std::int64_t steps = 2000000 / n;
    const Result a = measure_explicit(ChainDynamic(FPUChain(n, 1.0, 1.0, 0.25, 1.0, true)), q0, p0, 0.05, steps,
                                      repeats);
    const Result b = measure_explicit(WrittenSeparable(W), q0, p0, 0.05, steps, repeats);
    const double per = b.ns_per_step / n;
    if (n == 1000) per_particle_1000 = per;
    std::printf("  %8d %8lld %14.0f %14.0f %8.2f %14.2f %14.3e\n", n, static_cast<long long>(steps), a.ns_per_step,
                b.ns_per_step, b.ns_per_step / a.ns_per_step, per, state_diff(a, b));
    if (n == 25000)
      std::printf("  written ns per particle, n = 25000 against n = 1000: %.2f (1 is linear)\n\n", per / per_particle_1000);
  }
}

// The midpoint map on the same chain: the built-in ChainStep (tridiagonal Newton,
// solvers/chain_step.h) against the written text through SparseSeparableThetaStep (the
// sparse Hessian of its potential, solvers/sparse_separable_step.h), which is what
// `dvm run` takes for it; and, at n = 1000, the dense generic step (DynamicThetaStep,
// `use_structure = false`), the path of a written chain without the sparse step.
void implicit_chain(int repeats) {
  std::printf("FPU chain between walls (the same text), midpoint map with Newton's method, h = 0.05, best of %d\n",
              repeats);
  std::printf("  %8s %8s %14s %14s %8s %14s %8s %14s\n", "n", "steps", "built-in ns", "written ns", "ratio",
              "written ns/n", "colours", "|state diff|");
  double per_particle_1000 = 0.0, dense_1000 = 0.0, sparse_1000 = 0.0;
  for (int n : {1000, 10000, 25000}) {
    const WrittenDynamic W(written_chain(n));
    const Eigen::VectorXd q0 = first_mode(n), p0 = Eigen::VectorXd::Zero(n);
    const std::int64_t steps = 400000 / n;
    const ChainStep builtin(FPUChain(n, 1.0, 1.0, 0.25, 1.0, true), ThetaMap::midpoint(), 0.05);
    const auto H = SparseSeparableThetaStep::hessian_of(W, q0);
    const Eigen::VectorXd v0 = Eigen::VectorXd::Zero(n);
    const Result a = time_steps(builtin, q0, p0, v0, steps, repeats, "built-in chain, midpoint");
    // a new step for each repeat: each timed run pays the Jacobian of its first step,
    // which the step keeps for the later ones, as a `dvm run` does
    Result b;
    for (int r = 0; r < repeats; ++r) {
      const SparseSeparableThetaStep sparse(W, H, 0.5, 0.05);
      const Result t = time_steps(sparse, q0, p0, v0, steps, 1, "written chain, midpoint");
      if (t.ns_per_step < b.ns_per_step) b = t;
    }
    const double per = b.ns_per_step / n;
    if (n == 1000) {
      per_particle_1000 = per;
      sparse_1000 = b.ns_per_step;
      const Result c =
          time_steps(DynamicThetaStep<WrittenDynamic>(W, ThetaMap::midpoint(), 0.05), q0, p0, v0, 3, 1, "dense step");
      dense_1000 = c.ns_per_step;
    }
    std::printf("  %8d %8lld %14.0f %14.0f %8.2f %14.2f %8d %14.3e\n", n, static_cast<long long>(steps), a.ns_per_step,
                b.ns_per_step, b.ns_per_step / a.ns_per_step, per, H->colours(), state_diff(a, b));
    if (n == 25000)
      std::printf("  written ns per particle, n = 25000 against n = 1000: %.2f (1 is linear)\n", per / per_particle_1000);
  }
  std::printf("  n = 1000, the dense generic step (3 steps): %.0f ns/step, %.0f times the sparse step\n\n", dense_1000,
              dense_1000 / sparse_1000);
}

}  // namespace

int main(int argc, char** argv) {
  std::int64_t steps = 200000;
  int repeats = 5;
  parse_steps_and_repeats(argc, argv, "bench_written_lagrangian", steps, repeats);
  compare("pendulum (m = l = g = 1), q0 = 2, p0 = 0", Pendulum(1.0, 1.0, 1.0), "pendulum",
          {{"m", 1.0}, {"l", 1.0}, {"g", 1.0}},
          written({"theta"}, {{"m", 1.0}, {"l", 1.0}, {"g", 1.0}}, "0.5*m*l^2*theta_dot^2 + m*g*l*cos(theta)"),
          Vec<double, 1>(2.0), Vec<double, 1>(0.0), 0.01, steps, repeats);
  compare("Kepler, e = 0.6", Kepler(1.0), "kepler", {{"mu", 1.0}},
          written({"x", "y"}, {{"mu", 1.0}}, "(x_dot^2 + y_dot^2)/2 + mu/sqrt(x^2 + y^2)"), Vec<double, 2>(0.4, 0.0),
          Vec<double, 2>(0.0, 2.0), 0.005, steps, repeats);
  compare("double pendulum (all parameters 1), q0 = (0.5, 0.3), p0 = 0 (regular motion)", DoublePendulum(),
          "double-pendulum", {{"m1", 1.0}, {"m2", 1.0}, {"l1", 1.0}, {"l2", 1.0}, {"g", 1.0}},
          written({"a", "b"}, {{"m1", 1.0}, {"m2", 1.0}, {"l1", 1.0}, {"l2", 1.0}, {"g", 1.0}},
                  "(m1 + m2)/2*l1^2*a_dot^2 + m2/2*l2^2*b_dot^2 + m2*l1*l2*a_dot*b_dot*cos(a - b)"
                  " + (m1 + m2)*g*l1*cos(a) + m2*g*l2*cos(b)"),
          Vec<double, 2>(0.5, 0.3), Vec<double, 2>(0.0, 0.0), 0.01, steps, repeats);
  derivative_costs({{"pendulum", written({"theta"}, {{"m", 1.0}, {"l", 1.0}, {"g", 1.0}},
                                          "0.5*m*l^2*theta_dot^2 + m*g*l*cos(theta)")},
                    {"Kepler", written({"x", "y"}, {{"mu", 1.0}}, "(x_dot^2 + y_dot^2)/2 + mu/sqrt(x^2 + y^2)")},
                    {"double pendulum", written({"a", "b"}, {{"m1", 1.0}, {"m2", 1.0}, {"l1", 1.0}, {"l2", 1.0}, {"g", 1.0}},
                                                "(m1 + m2)/2*l1^2*a_dot^2 + m2/2*l2^2*b_dot^2 + m2*l1*l2*a_dot*b_dot*cos(a - b)"
                                                " + (m1 + m2)*g*l1*cos(a) + m2*g*l2*cos(b)")}},
                   steps, repeats);
  explicit_kepler(5 * steps, repeats);
  explicit_chain(repeats);
  implicit_chain(repeats);
  return 0;
}
