// CPU time to reach a global error of 1e-8 and 1e-10 on Kepler: Galerkin variational
// integrators against Boost.Odeint's four symplectic steppers and a hand-written Gauss
// collocation of order 12, all measured in this run.
//
// Problem: L = |v|^2/2 + 1/|q|, q0 = (0.4, 0), p0 = (0, 2): eccentricity 0.6,
// semi-major axis 1, period 2 pi; integrated to t = 1000 (about 159 revolutions) with
// fixed steps. Error: max over the components of q and p of |x - x_exact| at t = 1000,
// the exact solution from Kepler's equation (Kepler::exact).
//
// Rows:
//   - odeint: the four symplectic steppers;
//   - hand gauss6: Gauss collocation of 6 stages by fixed-point iteration on the stage
//     forces, written out for Kepler (hand_written.h), the baseline the Galerkin Gauss
//     step of a separable system is measured against;
//   - galerkin gauss s=2..6: what dvm runs for Kepler (separable): Gauss collocation on
//     the stage forces (solvers/collocation_step.h), compile-time stage count; s=6 also
//     with the stage count at run time, as `dvm run` instantiates it;
//   - galerkin gauss s=6 (newton): the generic Galerkin step (simplified Newton on the
//     nodes, solvers/galerkin_step.h) that non-separable systems take;
//   - galerkin lobatto s=3, 6: the generic step (Lobatto has no collocation path);
//   - dvm run gauss s=6: the same method through the runtime API exactly as `dvm run`
//     runs a scene (make_run, then execute with a Recorder writing a CSV with one row at
//     the end, the energy and invariants monitored every step).
// For every method a sweep of step counts (factor sqrt 2 apart) runs until the error
// is below the sweep's floor or one run exceeds the time budget; each row prints the
// steps, the error, the process CPU time of the run (best of repeats) and, for
// Galerkin, solver iterations (sweeps for collocation) and Jacobian factorisations per
// step. Each method's order is measured by a log-log fit of error against h over the
// rows with errors in [1e-11, 1e-3] (Odeint's own order() is not trusted). The CPU time
// at errors 1e-8 and 1e-10 is interpolated log-log between the two rows that bracket it
// (extrapolated with the measured order from the last two rows when a sweep stops
// above, and marked so).
// The summary prints the ratios (best Odeint time) / (best Galerkin time) at 1e-8,
// (Galerkin Gauss s = 6) / (hand gauss6) at 1e-10, and (dvm run) / (Galerkin Gauss s = 6)
// at equal steps (the median over the sweep's rows).
//
// usage: bench_galerkin_kepler [--smoke] [--t-end T] [--budget SECONDS]
//   --smoke  a tiny run (t = 10, three step counts per method) that checks the program
//            and its output, for the test suite; no timing is meaningful there.
#include <boost/numeric/odeint.hpp>
#include <boost/numeric/odeint/stepper/symplectic_rkn_sb3a_m4_mclachlan.hpp>
#include <time.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <algorithm>
#include <filesystem>

#include "examples/bench/hand_written.h"
#include "mechanics/systems.h"
#include "solvers/collocation_step.h"
#include "solvers/galerkin_step.h"
#include "solvers/runtime/recorder.h"
#include "solvers/runtime/run.h"

using namespace dvm;
using V2 = Vec<double, 2>;
using State = std::array<double, 2>;

namespace {

double cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

struct Row {
  std::int64_t steps;
  double error, seconds, iterations_per_step, jacobians_per_step;
};

// Which kind of row a method is (the summary compares them).
enum class Kind { odeint, hand, galerkin, dvm_run };

struct Entry {
  std::string name;
  Kind kind;
  // runs n steps to T, writes the final state; returns (iterations, jacobians) per step
  std::function<std::pair<double, double>(std::int64_t n, V2& q, V2& p)> run;
  std::vector<Row> rows;
  double order = NAN;
  std::array<double, 2> time_at{NAN, NAN};  // at the two targets
  std::array<bool, 2> extrapolated{false, false};
  bool galerkin() const { return kind != Kind::odeint; }
};

const std::array<double, 2> kTargets = {1e-8, 1e-10};

// Odeint: coordinate part dq/dt = p and momentum part dp/dt = -q/|q|^3 of the
// separable Hamiltonian |p|^2/2 - 1/|q|.
struct Coordinate {
  void operator()(const State& p, State& dqdt) const { dqdt = p; }
};
struct Momentum {
  void operator()(const State& q, State& dpdt) const {
    const double r2 = q[0] * q[0] + q[1] * q[1];
    const double k = -1.0 / (r2 * std::sqrt(r2));
    dpdt[0] = k * q[0];
    dpdt[1] = k * q[1];
  }
};

// velocity_verlet takes the acceleration a(q, v, t) instead.
struct Acceleration {
  void operator()(const State& q, const State&, State& a, double) const { Momentum()(q, a); }
};

template <class Stepper>
Entry odeint_method(const std::string& name, double T) {
  Entry m;
  m.name = "odeint " + name;
  m.kind = Kind::odeint;
  m.run = [T](std::int64_t n, V2& q, V2& p) {
    Stepper stepper;
    State x{q[0], q[1]}, y{p[0], p[1]};
    const double h = T / static_cast<double>(n);
    for (std::int64_t k = 0; k < n; ++k) {
      if constexpr (std::is_same_v<Stepper, boost::numeric::odeint::velocity_verlet<State>>)
        stepper.do_step(Acceleration(), std::make_pair(std::ref(x), std::ref(y)), static_cast<double>(k) * h, h);
      else
        stepper.do_step(std::make_pair(Coordinate(), Momentum()), std::make_pair(std::ref(x), std::ref(y)),
                        static_cast<double>(k) * h, h);
    }
    q = V2(x[0], x[1]);
    p = V2(y[0], y[1]);
    return std::pair<double, double>(0.0, 0.0);
  };
  return m;
}

// A galerkin_run (the generic step) or a run of any step type, as a method's row.
std::pair<double, double> per_step(const RunSummary& run, long jacobians, std::int64_t n, V2& q) {
  if (run.failed) {
    q.setConstant(NAN);
    return {NAN, NAN};
  }
  const double dn = static_cast<double>(n);
  return {static_cast<double>(run.solver_iterations) / dn, static_cast<double>(jacobians) / dn};
}

// The generic Galerkin step (simplified Newton on the nodes).
Entry galerkin_newton(int s, QuadratureKind kind, double T) {
  Entry m;
  m.name = std::string("galerkin ") + to_string(kind) + " s=" + std::to_string(s) +
           (kind == QuadratureKind::gauss ? " (newton)" : "");
  m.kind = Kind::galerkin;
  m.run = [s, kind, T](std::int64_t n, V2& q, V2& p) {
    const GalerkinRunStats r = galerkin_run(Kepler(1.0), s, kind, T / static_cast<double>(n), n, q, p);
    return per_step(r.run, r.jacobian_updates, n, q);
  };
  return m;
}

// Gauss collocation on the stage forces, what dvm runs for a separable system, with the
// stage count s at compile time (S = s) or at run time (S = 0, as `dvm run` has it).
template <int S>
Entry galerkin_collocation(double T, int s = S) {
  Entry m;
  m.name = "galerkin gauss s=" + std::to_string(s) + (S == 0 ? " (run-time s)" : "");
  m.kind = Kind::galerkin;
  m.run = [T, s](std::int64_t n, V2& q, V2& p) {
    const SeparableGaussStep<Kepler, S> step(Kepler(1.0), s, T / static_cast<double>(n), StepOptions{}, q);
    const V2 v0 = p;
    const RunSummary r = integrate(step, 0.0, q, p, v0, n, [](auto&&...) {});
    return per_step(r, step.newton_steps(), n, q);
  };
  return m;
}

Entry hand_gauss6(double T) {
  Entry m;
  m.name = "hand gauss6 (fixed point)";
  m.kind = Kind::hand;
  m.run = [T](std::int64_t n, V2& q, V2& p) {
    const std::int64_t forces = bench::hand_gauss6_kepler(Kepler(1.0), q, p, T / static_cast<double>(n), n, [](auto&&...) {});
    if (forces < 0) {
      q.setConstant(NAN);
      return std::pair<double, double>(NAN, NAN);
    }
    return std::pair<double, double>(static_cast<double>(forces) / (6.0 * static_cast<double>(n)), 0.0);
  };
  return m;
}

// Galerkin Gauss s = 6 through the runtime API, as `dvm run` runs a scene: one CSV row at
// the end (and the initial one), energy and invariants monitored every step.
Entry dvm_run(double T) {
  Entry m;
  m.name = "dvm run gauss s=6";
  m.kind = Kind::dvm_run;
  m.run = [T](std::int64_t n, V2& q, V2& p) {
    Problem pr;
    pr.system = &find_system_entry("kepler", "bench_galerkin_kepler");
    pr.params = {{"mu", 1.0}};
    pr.dim = 2;
    pr.q = {q[0], q[1]};
    pr.p = {p[0], p[1]};
    pr.momentum_given = true;
    pr.step = T / static_cast<double>(n);
    pr.steps = n;
    dvm::Method me;
    me.map = &find_map_entry("midpoint", "bench_galerkin_kepler");
    me.galerkin = true;
    me.stages = 6;
    me.quadrature = QuadratureKind::gauss;
    OutputSpec out;
    out.csv = (std::filesystem::temp_directory_path() / "bench_galerkin_kepler.csv").string();
    out.every = n;
    Recorder rec(out);
    const RunReport r = make_run(pr, me)->execute(&rec);
    std::filesystem::remove(out.csv);
    if (r.failed || r.step_path != StepPath::gauss_collocation) {
      q.setConstant(NAN);
      return std::pair<double, double>(NAN, NAN);
    }
    q = V2(r.q_final[0], r.q_final[1]);
    p = V2(r.p_final[0], r.p_final[1]);
    return std::pair<double, double>(static_cast<double>(r.solver_iterations) / static_cast<double>(n),
                                     static_cast<double>(r.newton_steps) / static_cast<double>(n));
  };
  return m;
}

// Least-squares slope of log(error) against log(h) over errors in [lo, hi].
double fit_order(const std::vector<Row>& rows, double T, double lo, double hi) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (const Row& r : rows) {
    if (!(r.error >= lo && r.error <= hi)) continue;
    const double x = std::log(T / static_cast<double>(r.steps)), y = std::log(r.error);
    sx += x, sy += y, sxx += x * x, sxy += x * y;
    ++n;
  }
  return n >= 2 ? (n * sxy - sx * sy) / (n * sxx - sx * sx) : NAN;
}

// log-log interpolation of the time at target k between the rows bracketing it (the
// first crossing), or extrapolation along the measured order.
void time_at(Entry& m, int k) {
  const double target = kTargets[k];
  double& t = m.time_at[k];
  const auto& R = m.rows;
  for (std::size_t i = 1; i < R.size(); ++i)
    if (R[i - 1].error > target && R[i].error <= target) {
      const double u = std::log(target / R[i - 1].error) / std::log(R[i].error / R[i - 1].error);
      t = std::exp(std::log(R[i - 1].seconds) + u * std::log(R[i].seconds / R[i - 1].seconds));
      return;
    }
  if (!R.empty() && R.front().error <= target) {
    t = R.front().seconds;  // already below at the coarsest step: an upper bound
    m.extrapolated[k] = true;
    return;
  }
  if (R.size() >= 2 && m.order > 0) {
    // error ~ C n^-order and time ~ n: time(target) = time_last (e_last/target)^(1/order)
    const Row& r = R.back();
    t = r.seconds * std::pow(r.error / target, 1.0 / m.order);
    m.extrapolated[k] = true;
  }
}

const Entry* find(const std::vector<Entry>& methods, const std::string& name) {
  for (const Entry& m : methods)
    if (m.name == name) return &m;
  return nullptr;
}

}  // namespace

int main(int argc, char** argv) {
  bool smoke = false;
  double T = 1000.0, budget = 1.5;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--smoke")) {
      smoke = true;
    } else if (!std::strcmp(argv[i], "--t-end") && i + 1 < argc) {
      T = std::atof(argv[++i]);
    } else if (!std::strcmp(argv[i], "--budget") && i + 1 < argc) {
      budget = std::atof(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: bench_galerkin_kepler [--smoke] [--t-end T] [--budget SECONDS]\n");
      return 2;
    }
  }
  if (smoke) T = 10.0;
  const V2 q0(0.4, 0.0), p0(0.0, 2.0);
  V2 qr, pr;
  Kepler(1.0).exact(T, q0, p0, qr, pr);

  namespace ode = boost::numeric::odeint;
  std::vector<Entry> methods;
  methods.push_back(odeint_method<ode::symplectic_euler<State>>("symplectic_euler", T));
  methods.push_back(odeint_method<ode::velocity_verlet<State>>("velocity_verlet", T));
  methods.push_back(odeint_method<ode::symplectic_rkn_sb3a_mclachlan<State>>("rkn_sb3a_mclachlan", T));
  methods.push_back(odeint_method<ode::symplectic_rkn_sb3a_m4_mclachlan<State>>("rkn_sb3a_m4_mclachlan", T));
  methods.push_back(hand_gauss6(T));
  methods.push_back(galerkin_collocation<2>(T));
  methods.push_back(galerkin_collocation<3>(T));
  methods.push_back(galerkin_collocation<4>(T));
  methods.push_back(galerkin_collocation<5>(T));
  methods.push_back(galerkin_collocation<6>(T));
  methods.push_back(galerkin_collocation<0>(T, 6));
  methods.push_back(galerkin_newton(6, QuadratureKind::gauss, T));
  for (int s = 3; s <= kGalerkinMaxStages; s += 3) methods.push_back(galerkin_newton(s, QuadratureKind::lobatto, T));
  methods.push_back(dvm_run(T));

  std::printf("Kepler e = 0.6, q0 = (0.4, 0), p0 = (0, 2), t = %g; error = max |x - exact| over q and p\n", T);
  std::printf("%-30s %12s %12s %12s %8s %8s\n", "method", "steps", "error", "cpu_s", "iter/st", "jac/st");
  for (Entry& m : methods) {
    // start near 16 steps per unit time for the low orders and fewer for Galerkin
    double n = smoke ? 200.0 : (m.galerkin() ? 2.0 * T : 16.0 * T);
    const int max_rows = smoke ? 3 : 40;
    const double floor = m.galerkin() ? 3e-11 : 3e-9;
    for (int k = 0; k < max_rows; ++k, n *= std::sqrt(2.0)) {
      const std::int64_t steps = static_cast<std::int64_t>(std::llround(n));
      Row row{steps, NAN, INFINITY, 0, 0};
      // best of repeats: runs are repeated until 0.3 s have been spent on the row
      double spent = 0.0;
      for (int rep = 0; rep < 50 && (rep < 1 || spent < 0.3) && !smoke; ++rep) {
        V2 q = q0, p = p0;
        const double c0 = cpu_seconds();
        const auto it = m.run(steps, q, p);
        const double dt = cpu_seconds() - c0;
        spent += dt;
        row.seconds = std::fmin(row.seconds, dt);
        row.error = std::fmax(max_abs(V2(q - qr)), max_abs(V2(p - pr)));
        row.iterations_per_step = it.first;
        row.jacobians_per_step = it.second;
        if (dt > budget) break;
      }
      if (smoke) {
        V2 q = q0, p = p0;
        const double c0 = cpu_seconds();
        const auto it = m.run(steps, q, p);
        row.seconds = cpu_seconds() - c0;
        row.error = std::fmax(max_abs(V2(q - qr)), max_abs(V2(p - pr)));
        row.iterations_per_step = it.first;
        row.jacobians_per_step = it.second;
      }
      m.rows.push_back(row);
      std::printf("%-30s %12lld %12.3e %12.4e %8.3f %8.4f\n", m.name.c_str(), static_cast<long long>(steps), row.error,
                  row.seconds, row.iterations_per_step, row.jacobians_per_step);
      std::fflush(stdout);
      if (!(row.error > floor) || row.seconds > budget) break;
    }
    m.order = fit_order(m.rows, T, 1e-11, 1e-3);
    time_at(m, 0);
    time_at(m, 1);
  }

  std::printf("\n%-30s %8s %14s %14s %14s\n", "method", "order", "cpu_s@1e-8", "cpu_s@1e-10", "min_error");
  const Entry *best_odeint = nullptr, *best_galerkin = nullptr;
  for (const Entry& m : methods) {
    double emin = INFINITY;
    for (const Row& r : m.rows) emin = std::fmin(emin, r.error);
    std::printf("%-30s %8.2f %14.4e%s %13.4e%s %13.3e\n", m.name.c_str(), m.order, m.time_at[0],
                m.extrapolated[0] ? "*" : " ", m.time_at[1], m.extrapolated[1] ? "*" : " ", emin);
    if (!std::isfinite(m.time_at[0]) || m.kind == Kind::hand || m.kind == Kind::dvm_run) continue;
    const Entry*& best = m.kind == Kind::galerkin ? best_galerkin : best_odeint;
    if (!best || m.time_at[0] < best->time_at[0]) best = &m;
  }
  std::printf("(* extrapolated along the measured order, or an upper bound: the sweep did not bracket the error)\n");
  const char* note = smoke ? " (smoke run: not a measurement)" : "";
  if (best_odeint && best_galerkin) {
    std::printf("\nbest odeint:   %s, %.4e s at error 1e-8%s\n", best_odeint->name.c_str(), best_odeint->time_at[0],
                best_odeint->extrapolated[0] ? " (extrapolated)" : "");
    std::printf("best galerkin: %s, %.4e s at error 1e-8%s\n", best_galerkin->name.c_str(), best_galerkin->time_at[0],
                best_galerkin->extrapolated[0] ? " (extrapolated)" : "");
    std::printf("ratio best-odeint / best-galerkin = %.2f%s\n", best_odeint->time_at[0] / best_galerkin->time_at[0],
                note);
  } else {
    std::printf("\nratio best-odeint / best-galerkin = nan (a method family has no time at 1e-8)\n");
  }
  // the Galerkin Gauss step of a separable system against the hand-written collocation
  const Entry *g6 = find(methods, "galerkin gauss s=6"), *hand = find(methods, "hand gauss6 (fixed point)"),
              *run = find(methods, "dvm run gauss s=6");
  for (int k = 0; k < 2; ++k)
    std::printf("ratio galerkin gauss s=6 / hand gauss6 at %.0e = %.2f%s%s\n", kTargets[k],
                g6->time_at[k] / hand->time_at[k], g6->extrapolated[k] || hand->extrapolated[k] ? " (extrapolated)" : "",
                note);
  // dvm run against the step in this program, row by row (the same step counts)
  std::vector<double> ratios;
  for (const Row& a : run->rows)
    for (const Row& b : g6->rows)
      if (a.steps == b.steps && b.seconds > 0) ratios.push_back(a.seconds / b.seconds);
  std::sort(ratios.begin(), ratios.end());
  std::printf("ratio dvm run / galerkin gauss s=6 at equal steps = %.2f (median of %zu rows, %.2f .. %.2f)%s\n",
              ratios.empty() ? NAN : ratios[ratios.size() / 2], ratios.size(), ratios.empty() ? NAN : ratios.front(),
              ratios.empty() ? NAN : ratios.back(), note);
  return 0;
}
