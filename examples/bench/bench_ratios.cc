// The speed targets of the benchmark suite, as ratios of CPU times measured in one
// process (best of R repeats; the method callables are those of the charts, suite.h):
//
//   1. dvm's generic implicit midpoint step (position-momentum step of the midpoint
//      map, Newton) over the hand-written Newton loop for the same equations
//      (examples/bench/hand_written.h), on the pendulum (q0 = 2) and on Kepler
//      (e = 0.6), h = 0.01.                                          target <= 3
//   2. Stormer-Verlet obtained by composition (explicit Euler and its adjoint,
//      Phi_{h/2} o Phi*_{h/2}), stepped as `dvm run` steps it on a separable system
//      (kicks and drifts, solvers/splitting_step.h), over Boost.Odeint's
//      velocity_verlet and over the hand-written Verlet, on Kepler, h = 0.01.
//                                                                   target <= 1.5
//      Not a target: the same composition by the generic path (Newton on each
//      substep, use_structure = false) over the explicit one, and how far apart
//      their final states are.
//   3. At equal error on Kepler (T = 20, the work-precision sweep): CPU time of the
//      best dvm method over that of the best Odeint symplectic stepper, at errors 1e-9
//      and 1e-10 (log-log interpolation along each sweep).          target <= 1
//
// usage: bench_ratios [--steps N] [--repeats R] [--out DIR] (DIR/ratios.md for the README)
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "examples/bench/suite.h"

using namespace dvm;
using namespace dvm::bench;

namespace {

template <class System>
const Method<System>& find(const std::vector<Method<System>>& table, const std::string& name) {
  for (const auto& m : table)
    if (m.name == name) return m;
  std::fprintf(stderr, "bench_ratios: no method \"%s\"\n", name.c_str());
  std::exit(2);
}

// Best-of-R CPU seconds per step of one method on a problem.
template <class System>
double ns_per_step(const Method<System>& m, const Problem<System>& P, double h, std::int64_t steps, int repeats) {
  double best = INFINITY;
  for (int r = 0; r < repeats; ++r) {
    const double t0 = cpu_seconds();
    const Outcome<System::dim> o = m.run(P, h, steps, nullptr);
    const double dt = cpu_seconds() - t0;
    if (!o.converged) {
      std::fprintf(stderr, "bench_ratios: %s failed\n", m.name.c_str());
      std::exit(3);
    }
    best = std::fmin(best, dt);
  }
  return 1e9 * best / static_cast<double>(steps);
}

std::string fmt2(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f", x);
  return b;
}

}  // namespace

int main(int argc, char** argv) {
  std::int64_t steps = 1000000;
  int repeats = 5;
  std::string dir;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--steps" && i + 1 < argc)
      steps = std::atoll(argv[++i]);
    else if (a == "--repeats" && i + 1 < argc)
      repeats = std::atoi(argv[++i]);
    else if (a == "--out" && i + 1 < argc)
      dir = argv[++i];
    else {
      std::fprintf(stderr, "usage: bench_ratios [--steps N] [--repeats R] [--out DIR]\n");
      return 2;
    }
  }
  if (steps < 10 || repeats < 1) {
    std::fprintf(stderr, "bench_ratios: steps >= 10 and repeats >= 1 required\n");
    return 2;
  }
  const bool tiny = steps < 10000;
  const double h = 0.01;
  std::ostringstream md;
  char line[512];
  auto out = [&](const char* s) {
    std::fputs(s, stdout);
    md << s;
  };

  // 1. generic midpoint against the hand-written Newton loop
  using V1 = Vec<double, 1>;
  const Problem<Pendulum> pend{"pendulum", Pendulum(1.0, 1.0, 1.0), V1(2.0), V1(0.0), h * steps, {}, {}, {}, {}, {}};
  const auto ptab = pendulum_methods();
  const Problem<Kepler> kep = kepler_problem(h * static_cast<double>(steps), {steps});
  const auto ktab = kepler_methods();
  // (the generic step: Newton on the step equation of L_d, as with use_structure = false)
  const Method<Pendulum> p_generic{"dvm midpoint (generic)", "dvm", 2, true, false,
                                   dvm_map<Pendulum>(ThetaMap::midpoint(), true)};
  const Method<Kepler> k_generic{"dvm midpoint (generic)", "dvm", 2, true, false,
                                 dvm_map<Kepler>(ThetaMap::midpoint(), true)};
  const double p_gen = ns_per_step(p_generic, pend, h, steps, repeats);
  const double p_hand = ns_per_step(find(ptab, "hand implicit midpoint (Newton)"), pend, h, steps, repeats);
  const double k_gen = ns_per_step(k_generic, kep, h, steps, repeats);
  const double k_hand = ns_per_step(find(ktab, "hand implicit midpoint (Newton)"), kep, h, steps, repeats);
  // 2. Stormer-Verlet by composition against Odeint and by hand
  const double sv_dvm = ns_per_step(find(ktab, "dvm stormer-verlet (EE composed)"), kep, h, steps, repeats);
  const double sv_ode = ns_per_step(find(ktab, "odeint velocity_verlet"), kep, h, steps, repeats);
  const double sv_hand = ns_per_step(find(ktab, "hand stormer-verlet"), kep, h, steps, repeats);
  // the same composition by the generic path, and how far apart the two end
  const Method<Kepler> sv_generic_method{"dvm stormer-verlet (EE composed, generic)", "dvm", 2, false, false,
                                         dvm_composition<Kepler>(ThetaMap::explicit_euler(), "stormer-verlet", true)};
  const double sv_generic = ns_per_step(sv_generic_method, kep, h, steps, repeats);
  const double sv_agree = (sv_generic_method.run(kep, h, steps, nullptr).q -
                           find(ktab, "dvm stormer-verlet (EE composed)").run(kep, h, steps, nullptr).q)
                              .cwiseAbs()
                              .maxCoeff();

  std::snprintf(line, sizeof line, "h = %g, %lld steps, best of %d; ns per step\n\n", h,
                static_cast<long long>(steps), repeats);
  out(line);
  out("| ratio | numerator (ns/step) | denominator (ns/step) | ratio | target |\n|---|---|---|---|---|\n");
  std::snprintf(line, sizeof line, "| generic midpoint / hand-written Newton, pendulum | %.1f | %.1f | %.2f | <= 3 |\n",
                p_gen, p_hand, p_gen / p_hand);
  out(line);
  std::snprintf(line, sizeof line, "| generic midpoint / hand-written Newton, Kepler | %.1f | %.1f | %.2f | <= 3 |\n",
                k_gen, k_hand, k_gen / k_hand);
  out(line);
  std::snprintf(line, sizeof line,
                "| Stormer-Verlet by composition / odeint velocity_verlet, Kepler | %.1f | %.1f | %.2f | <= 1.5 |\n",
                sv_dvm, sv_ode, sv_dvm / sv_ode);
  out(line);
  std::snprintf(line, sizeof line,
                "| Stormer-Verlet by composition / hand-written Verlet, Kepler | %.1f | %.1f | %.2f | <= 1.5 |\n",
                sv_dvm, sv_hand, sv_dvm / sv_hand);
  out(line);
  std::snprintf(line, sizeof line,
                "| (not a target) the same composition by the generic path (Newton) / by kicks and drifts, Kepler "
                "| %.1f | %.1f | %.2f | (final positions %.1e apart) |\n",
                sv_generic, sv_dvm, sv_generic / sv_dvm, sv_agree);
  out(line);

  // 3. equal error on Kepler
  std::vector<std::int64_t> n;
  for (int k = 0; k < (tiny ? 5 : 12); ++k) n.push_back((tiny ? 40 : 25) << k);
  const Problem<Kepler> sweep_problem = kepler_problem(tiny ? 2.0 : 20.0, n);
  SweepOptions so;
  if (tiny) so.min_seconds = 0.0;
  std::vector<Method<Kepler>> contenders;
  for (const auto& m : ktab)
    if (m.family == "dvm" || m.family == "odeint") contenders.push_back(m);
  const std::vector<Row> rows = sweep(sweep_problem, contenders, so);
  std::map<std::string, std::vector<const Row*>> by;
  std::map<std::string, std::string> family;
  for (const Row& r : rows) {
    by[r.method].push_back(&r);
    family[r.method] = r.family;
  }
  for (double target : {1e-9, 1e-10}) {
    std::string best_d, best_o;
    double cd = INFINITY, co = INFINITY;
    for (const auto& [name, rs] : by) {
      const double c = cpu_at(rs, target);
      if (std::isnan(c)) continue;
      if (family[name] == "dvm" && c < cd) {
        cd = c;
        best_d = name;
      }
      if (family[name] == "odeint" && c < co) {
        co = c;
        best_o = name;
      }
    }
    // n/a when a sweep does not reach the error
    std::snprintf(line, sizeof line,
                  "| best dvm (%s) / best odeint (%s), Kepler T = %g, error %.0e | %.3e s | %.3e s | %s | <= 1 |\n",
                  best_d.empty() ? "none" : best_d.c_str(), best_o.empty() ? "none" : best_o.c_str(),
                  sweep_problem.t_end, target, cd, co,
                  std::isfinite(cd) && std::isfinite(co) ? fmt2(cd / co).c_str() : "n/a");
    out(line);
  }
  if (!dir.empty()) {
    std::ofstream f(dir + "/ratios.md");
    if (!f) {
      std::fprintf(stderr, "bench_ratios: cannot write %s/ratios.md\n", dir.c_str());
      return 2;
    }
    f << md.str();
  }
  return 0;
}
