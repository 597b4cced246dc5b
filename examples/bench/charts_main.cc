// dvm_charts: the data behind `make charts`.
//
// 1. Work precision. For every problem and method family of the suite (suite.h), a
//    sweep of the step size: global position error at the final time, maximum
//    relative energy error over the run, CPU time (best of repeated runs, energy not
//    evaluated in the timed runs).
// 2. Long-time energy. Kepler e = 0.6, h = 0.01, 10^6 steps (t = 10^4, about 1600
//    periods): the relative energy error, maximum over each block of 1000 steps, for
//    symplectic methods and for classical RK4 (non-symplectic, its error drifts).
// 3. Stability. (a) On q'' = -q, the largest h omega below which a run stays bounded
//    (scan then bisection; runs of 1000 steps from (1, 0), unbounded meaning
//    max |(q, p)| > 1e4: near the threshold a stable orbit is a long thin ellipse, so a
//    small bound would flag stable runs); for dvm's theta-map methods also the
//    closed-form threshold
//    |trace M(h omega)| < 2 of solvers/stability.h. (b) On the pendulum from q = 2,
//    p = 0, the smallest step at which an implicit method's solver stops converging
//    within max(20, 20/h) steps.
//
// Output (in --out DIR): work_precision.csv, references.csv, energy_long.csv,
// stability.csv, the gnuplot data files wp_<problem>.dat, energy_long.dat,
// stability_threshold.dat, stability_pendulum.dat, and table_sweeps.md, table_long.md,
// table_stability.md (the numbers for the README). --part regenerates one of the three
// parts and its files only. usage: dvm_charts [--out DIR] [--tiny] [--part sweeps|long|stability]
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "examples/bench/suite.h"
#include "solvers/stability.h"

using namespace dvm;
using namespace dvm::bench;

namespace {

std::string fmt(double x, const char* f = "%.3e") {
  if (std::isinf(x)) return x > 0 ? "inf" : "-inf";
  if (std::isnan(x)) return "nan";
  char b[64];
  std::snprintf(b, sizeof b, f, x);
  return b;
}

std::ofstream open_out(const std::string& path) {
  std::ofstream f(path);
  if (!f) {
    std::fprintf(stderr, "dvm_charts: cannot write %s\n", path.c_str());
    std::exit(2);
  }
  return f;
}

std::string md_num(double x) { return std::isnan(x) ? "—" : fmt(x, "%.2e"); }

void write_problem(const std::string& dir, const ProblemResult& r, std::ofstream& csv, std::ostringstream& md) {
  std::map<std::string, std::vector<const Row*>> by_method;
  std::vector<std::string> order;
  for (const Row& row : r.rows) {
    csv << row.problem << ',' << row.method << ',' << row.family << ',' << row.order << ',' << row.implicit << ','
        << row.chart << ',' << fmt(row.h, "%.10g") << ',' << row.steps << ',' << fmt(row.error) << ','
        << fmt(row.max_energy_error) << ',' << fmt(row.cpu_seconds) << ',' << row.converged << '\n';
    if (!by_method.count(row.method)) order.push_back(row.method);
    by_method[row.method].push_back(&row);
  }
  // dvm's methods in wp_<problem>.dat, the peers in wp_<problem>_peers.dat
  for (const bool peers : {false, true}) {
    std::ofstream dat = open_out(dir + "/wp_" + r.problem + (peers ? "_peers" : "") + ".dat");
    dat << "# " << r.problem << ": CPU seconds, global position error; one block per method\n";
    bool first = true;
    for (const std::string& name : order) {
      const auto& rows = by_method[name];
      if (!rows.front()->chart || (rows.front()->family != "dvm") != peers) continue;
      std::ostringstream block;
      int n = 0;
      for (const Row* row : rows)
        if (row->converged && row->error > 0 && row->cpu_seconds > 0) {
          block << fmt(row->cpu_seconds) << ' ' << fmt(row->error) << '\n';
          ++n;
        }
      if (n == 0) continue;
      if (!first) dat << "\n\n";
      first = false;
      dat << '"' << name << "\" \"error\"\n" << block.str();
    }
  }
  md << "\n**" << r.problem << "** (reference: " << r.reference_note << ")\n\n";
  // errors below ten times the two references' disagreement are not fitted
  const double fit_floor = std::fmax(1e-13, 10.0 * r.reference_agreement);
  md << "| method | fitted order | CPU s at error 1e-6 | CPU s at error 1e-10 | max energy error at the finest step |\n";
  md << "|---|---|---|---|---|\n";
  for (const std::string& name : order) {
    const auto& rows = by_method[name];
    if (!rows.front()->chart) continue;
    double efinest = NAN;
    for (const Row* row : rows)
      if (row->converged) efinest = row->max_energy_error;
    md << "| " << name << " | " << (std::isnan(fitted_order(rows, fit_floor)) ? "—" : fmt(fitted_order(rows, fit_floor), "%.2f")) << " | "
       << md_num(cpu_at(rows, 1e-6)) << " | " << md_num(cpu_at(rows, 1e-10)) << " | " << md_num(efinest) << " |\n";
  }
}

// ---------------------------------------------------------------------------------
// long run

void long_run(const std::string& dir, bool tiny, std::ostringstream& md) {
  const std::int64_t steps = tiny ? 2000 : 1000000, block = tiny ? 20 : 1000;
  const double h = 0.01;
  const Problem<Kepler> P = kepler_problem(h * static_cast<double>(steps), {steps});
  std::vector<Method<Kepler>> all = kepler_methods();
  all.push_back({"odeint runge_kutta4 (not symplectic)", "odeint", 4, false, true, odeint_rk4<Kepler>()});
  const std::vector<std::string> chosen = {"dvm midpoint",
                                           "dvm stormer-verlet (EE composed)",
                                           "dvm triple-jump (SV)",
                                           "dvm triple-jump (midpoint)",
                                           "odeint velocity_verlet",
                                           "odeint rkn_sb3a_m4_mclachlan",
                                           "odeint runge_kutta4 (not symplectic)"};
  std::ofstream csv = open_out(dir + "/energy_long.csv");
  std::ofstream dat = open_out(dir + "/energy_long.dat");
  csv << "method,t,max_energy_error_in_block\n";
  dat << "# Kepler e = 0.6, h = " << h << ": t, max relative energy error over each block of " << block
      << " steps\n";
  md << "\nLong run: Kepler e = 0.6, h = " << h << ", " << steps << " steps (t = " << fmt(h * steps, "%g")
     << "); relative energy error, maximum over the first and the last block of " << block << " steps.\n\n";
  md << "| method | first block | last block | max over the run | CPU s |\n|---|---|---|---|---|\n";
  bool first = true;
  for (const std::string& name : chosen) {
    const Method<Kepler>* m = nullptr;
    for (const auto& x : all)
      if (x.name == name) m = &x;
    if (!m) continue;
    const double H0 = energy_of(P.sys, P.q0, P.p0);
    std::vector<double> t, e;
    double cur = 0.0, worst = 0.0;
    std::int64_t k = 0;
    const StateObserver<2> obs = [&](const Vec<double, 2>& q, const Vec<double, 2>& p) {
      const double err = std::fabs(energy_of(P.sys, q, p) - H0) / std::fabs(H0);
      if (!(err <= cur)) cur = err;
      ++k;
      if (k % block == 0) {
        t.push_back(h * static_cast<double>(k));
        e.push_back(cur);
        if (!(cur <= worst)) worst = cur;
        cur = 0.0;
      }
    };
    const double t0 = cpu_seconds();
    const Outcome<2> out = m->run(P, h, steps, &obs);
    const double cpu = cpu_seconds() - t0;
    if (!first) dat << "\n\n";
    first = false;
    dat << '"' << name << "\" \"error\"\n";
    for (std::size_t i = 0; i < t.size(); ++i) {
      csv << name << ',' << fmt(t[i], "%.6g") << ',' << fmt(e[i]) << '\n';
      dat << fmt(t[i], "%.6g") << ' ' << fmt(std::fmax(e[i], 1e-17)) << '\n';
    }
    md << "| " << name << (out.converged ? "" : " (failed)") << " | " << md_num(e.empty() ? NAN : e.front()) << " | "
       << md_num(e.empty() ? NAN : e.back()) << " | " << md_num(worst) << " | " << fmt(cpu, "%.2f") << " |\n";
    std::fprintf(stderr, "  long run %-40s max %.2e  (%.1f s)\n", name.c_str(), worst, cpu);
  }
}

// ---------------------------------------------------------------------------------
// stability

// Closed-form threshold for dvm's theta-map methods, from the method name.
double trace_threshold(const std::string& name) {
  auto ends = [&](const std::string& s) {
    return name.size() > s.size() && name.compare(name.size() - s.size(), s.size(), s) == 0;
  };
  if (name.rfind("dvm ", 0) != 0) return NAN;
  std::string body = name.substr(4);
  if (body == "explicit-euler") return composition_threshold(0.0, single_substep());
  if (body == "adjoint-euler") return composition_threshold(1.0, single_substep());
  if (body == "midpoint") return composition_threshold(0.5, single_substep());
  if (body == "theta-0.3") return composition_threshold(0.3, single_substep());
  if (body == "stormer-verlet (EE composed)")
    return composition_threshold(0.0, substeps(find_composition("stormer-verlet"), false));
  if (ends(" (SV)") || ends(" (EE)"))
    return composition_threshold(0.0, substeps(find_composition(body.substr(0, body.size() - 5)), false));
  if (ends(" (midpoint)"))
    return composition_threshold(0.5, substeps(find_composition(body.substr(0, body.size() - 11)), true));
  return NAN;
}

// First x = h omega in (0, x_max] at which `unstable(x)`, by a scan of spacing dx and
// bisection to 1e-4 relative; +inf if none.
template <class F>
double first_failure(F&& unstable, double x0, double x_max, double factor_or_dx, bool geometric) {
  double lo = 0.0;
  for (double x = x0; x <= x_max * (1 + 1e-12); x = geometric ? x * factor_or_dx : x + factor_or_dx) {
    if (unstable(x)) {
      double hi = x;
      while (hi - lo > 1e-4 * hi) {
        const double mid = 0.5 * (lo + hi);
        (unstable(mid) ? hi : lo) = mid;
      }
      return 0.5 * (lo + hi);
    }
    lo = x;
  }
  return INFINITY;
}

void stability(const std::string& dir, bool tiny, std::ostringstream& md) {
  const double x_max = tiny ? 3.0 : 8.0;
  const std::int64_t runs = tiny ? 100 : 1000;
  using V = Vec<double, 1>;
  Problem<HarmonicOscillator> H{"harmonic", HarmonicOscillator(1.0), V(1.0), V(0.0), 1.0, {}, {}, {}, {}, {}};
  std::ofstream csv = open_out(dir + "/stability.csv");
  csv << "method,family,kind,value\n";
  std::ofstream dat = open_out(dir + "/stability_threshold.dat");
  dat << "# method, largest stable h omega by runs (capped at x_max), trace threshold, x_max\n";
  md << "\nStability on q'' = -omega^2 q: largest stable h omega (runs of " << runs
     << " steps from (1, 0) staying below 1e4, bisection; \"> " << x_max << "\" = stable on the whole scan), and the closed-form threshold "
     << "(|trace| < 2) for dvm's theta-map methods.\n\n| method | by runs | closed form |\n|---|---|---|\n";
  for (const Method<HarmonicOscillator>& m : harmonic_methods()) {
    auto unstable = [&](double x) {
      double worst = 0.0;
      const StateObserver<1> obs = [&worst](const V& q, const V& p) {
        const double s = std::fmax(std::fabs(q[0]), std::fabs(p[0]));
        if (!(s <= worst)) worst = s;
      };
      const Outcome<1> o = m.run(H, x, runs, &obs);
      return !o.converged || !(worst <= 1e4);
    };
    const double by_runs = first_failure(unstable, 0.05, x_max, 0.05, false);
    const double trace = trace_threshold(m.name);
    csv << m.name << ',' << m.family << ",threshold_runs," << fmt(by_runs, "%.6g") << '\n';
    if (!std::isnan(trace)) csv << m.name << ',' << m.family << ",threshold_trace," << fmt(trace, "%.6g") << '\n';
    dat << '"' << m.name << "\" " << fmt(std::fmin(by_runs, x_max), "%.6g") << ' '
        << fmt(std::isnan(trace) ? -1.0 : std::fmin(trace, x_max), "%.6g") << ' ' << x_max << '\n';
    md << "| " << m.name << " | " << (std::isinf(by_runs) ? "> " + fmt(x_max, "%g") : fmt(by_runs, "%.4f")) << " | "
       << (std::isnan(trace) ? "—" : std::isinf(trace) ? "inf" : fmt(trace, "%.4f")) << " |\n";
  }

  // (b) pendulum: where the implicit solvers stop converging
  Problem<Pendulum> P{"pendulum", Pendulum(1.0, 1.0, 1.0), V(2.0), V(0.0), 1.0, {}, {}, {}, {}, {}};
  std::ofstream pdat = open_out(dir + "/stability_pendulum.dat");
  const double h_max = tiny ? 5.0 : 100.0;
  pdat << "# method, smallest step at which the solver fails on the pendulum (q0 = 2), capped at " << h_max << "\n";
  md << "\nPendulum (q0 = 2, p0 = 0; small-oscillation omega = 1): the smallest step at which each implicit "
        "method's solver stops converging within max(20, 20/h) steps (scan by factors 1.1 from 0.1, "
        "bisection; \"> "
     << h_max << "\" = converged on the whole scan).\n\n| method | failing step h |\n|---|---|\n";
  for (const Method<Pendulum>& m : pendulum_methods()) {
    if (!m.implicit) continue;
    auto fails = [&](double h) {
      const auto n = static_cast<std::int64_t>(std::fmax(20.0, std::ceil(20.0 / h)));
      return !m.run(P, h, n, nullptr).converged;
    };
    const double hf = first_failure(fails, 0.1, h_max, 1.1, true);
    csv << m.name << ',' << m.family << ",pendulum_solver_failure_h," << fmt(hf, "%.6g") << '\n';
    pdat << '"' << m.name << "\" " << fmt(std::fmin(hf, h_max), "%.6g") << ' ' << h_max << '\n';
    md << "| " << m.name << " | " << (std::isinf(hf) ? "> " + fmt(h_max, "%g") : fmt(hf, "%.4f")) << " |\n";
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string dir = "examples/charts", part;
  SuiteConfig cfg;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc)
      dir = argv[++i];
    else if (a == "--tiny")
      cfg.tiny = true;
    else if (a == "--part" && i + 1 < argc && (std::string(argv[i + 1]) == "sweeps" ||
                                                std::string(argv[i + 1]) == "long" ||
                                                std::string(argv[i + 1]) == "stability"))
      part = argv[++i];
    else {
      std::fprintf(stderr, "usage: dvm_charts [--out DIR] [--tiny] [--part sweeps|long|stability]\n");
      return 2;
    }
  }
  if (cfg.tiny) {
    cfg.sweep.min_seconds = 0.0;
    cfg.sweep.max_run_seconds = 0.5;
  }
  if (part.empty() || part == "sweeps") {
    using Runner = ProblemResult (*)(const SuiteConfig&);
    const std::vector<std::pair<std::string, Runner>> problems = {
        {"harmonic", run_harmonic},         {"pendulum", run_pendulum}, {"kepler", run_kepler},
        {"henon-heiles", run_henon_heiles}, {"fpu", run_fpu},           {"outer-solar-system", run_outer_solar_system},
        {"rigid-body", run_rigid_body}};
    std::ostringstream md;
    std::ofstream csv = open_out(dir + "/work_precision.csv");
    std::ofstream refs = open_out(dir + "/references.csv");
    csv << "problem,method,family,order,implicit,chart,h,steps,error,max_energy_error,cpu_seconds,converged\n";
    refs << "problem,reference,agreement\n";
    md << "Work precision: global position error (max norm) at the final time against CPU time; fitted order "
          "from the errors between max(1e-13, 10 x the references' agreement) and 1e-2; CPU time at an error by log-log interpolation along the "
          "sweep.\n";
    for (const auto& [name, run] : problems) {
      const double t0 = cpu_seconds();
      const ProblemResult r = run(cfg);
      refs << r.problem << ",\"" << r.reference_note << "\"," << fmt(r.reference_agreement) << '\n';
      write_problem(dir, r, csv, md);
      std::fprintf(stderr, "%s: %zu runs, %.1f s\n", name.c_str(), r.rows.size(), cpu_seconds() - t0);
    }
    open_out(dir + "/table_sweeps.md") << md.str();
  }
  if (part.empty() || part == "long") {
    const double t0 = cpu_seconds();
    std::ostringstream md;
    long_run(dir, cfg.tiny, md);
    open_out(dir + "/table_long.md") << md.str();
    std::fprintf(stderr, "long run: %.1f s\n", cpu_seconds() - t0);
  }
  if (part.empty() || part == "stability") {
    const double t0 = cpu_seconds();
    std::ostringstream md;
    stability(dir, cfg.tiny, md);
    open_out(dir + "/table_stability.md") << md.str();
    std::fprintf(stderr, "stability: %.1f s\n", cpu_seconds() - t0);
  }
  return 0;
}
