#include "solvers/runtime/converge.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <set>
#include <sstream>

#include <unistd.h>

#include "solvers/runtime/json.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/runtime/run.h"

namespace dvm {

namespace {

Problem with_grid(const Problem& pr, double T, std::int64_t n) {
  Problem out = pr;
  out.step = T / static_cast<double>(n);
  out.steps = n;
  return out;
}

// Runs the problem with n steps to T; false (with the message) if the run failed.
bool final_state(const Problem& pr, const Method& me, double T, std::int64_t n, FinalState& out, std::int64_t& iterations,
                 std::string& failure, double* wall_seconds = nullptr) {
  const auto run = make_run(with_grid(pr, T, n), me);
  const RunReport r = run->execute(nullptr);
  iterations = r.solver_iterations;
  if (wall_seconds) *wall_seconds = r.wall_seconds;
  if (r.failed) {
    std::ostringstream m;
    m.precision(17);
    m << "the run with " << n << " steps (h = " << T / static_cast<double>(n) << ") failed at step "
      << r.loop.failed_step << " (t = " << r.loop.failed_time << "): " << r.loop.failure.message << " (residual "
      << r.loop.failure.residual << ")";
    failure = m.str();
    return false;
  }
  out.q = r.q_embedded;
  out.p = r.p_final;
  return true;
}

// The reference method of a problem: Galerkin s = 6 where the system runs it (Gauss;
// Lobatto under constraints, which Galerkin holds at its nodes), else kahan-li8 of the
// space's midpoint map.
Method reference_method(const Problem& pr, const Method& me, int& order, std::string& name) {
  Method ref;
  ref.solver = SolverKind::newton;
  ref.max_iterations = std::max(me.max_iterations, 25);
  ref.tolerance = 2e-15;
  if (pr.system->caps.galerkin) {
    ref.galerkin = true;
    ref.stages = 6;
    ref.quadrature = pr.constrained() ? QuadratureKind::lobatto : QuadratureKind::gauss;
    order = 12;
    name = std::string("galerkin ") + to_string(ref.quadrature) + " s=6 (order 12)";
    return ref;
  }
  const char* map = pr.system->space == Space::sphere ? "sphere-exp" : pr.system->space == Space::rotation ? "so3-exp" : "midpoint";
  ref.map = &find_map_entry(map, "converge");
  ref.theta = ref.map->theta;
  ref.composition = "kahan-li8";
  ref.weights.clear();
  order = 8;
  name = std::string(map) + ", composition kahan-li8 (order 8)";
  return ref;
}

}  // namespace

double state_distance(const FinalState& a, const FinalState& b) {
  double d = 0.0;
  for (std::size_t i = 0; i < a.q.size() && i < b.q.size(); ++i) d = std::fmax(d, std::fabs(a.q[i] - b.q[i]));
  for (std::size_t i = 0; i < a.p.size() && i < b.p.size(); ++i) d = std::fmax(d, std::fabs(a.p[i] - b.p[i]));
  return d;
}

double final_state_size(const FinalState& a) {
  double s = 0.0;
  for (double x : a.q) s = std::fmax(s, std::fabs(x));
  for (double x : a.p) s = std::fmax(s, std::fabs(x));
  return s;
}

Reference reference_solution(const Problem& pr, const Method& me, double T, std::int64_t n_start,
                             const std::vector<FinalState>& measured, bool show) {
  Reference out;
  std::vector<double> exact_q, exact_p;
  const auto run0 = make_run(with_grid(pr, T, n_start), me);
  if (run0->exact(T, exact_q, exact_p)) {
    out.state.q = exact_q;
    out.state.p = exact_p;
    out.exact = true;
    out.description = "exact solution";
    out.accuracy = exact_accuracy(out.state);
    return out;
  }
  int order = 0;
  std::string name;
  const Method rm = reference_method(pr, me, order, name);
  std::int64_t n = n_start;
  FinalState r1, r2;
  std::int64_t it = 0;
  std::string failure;
  if (!final_state(pr, rm, T, n, r1, it, failure))
    throw InputError("the reference run (" + name + ") failed: " + failure);
  double d = INFINITY;
  for (int level = 0; level < 5; ++level) {
    n *= 2;
    if (show) {
      std::fprintf(stderr, "\r  converge: reference run (%lld steps)          ", static_cast<long long>(n));
      std::fflush(stderr);
    }
    if (!final_state(pr, rm, T, n, r2, it, failure))
      throw InputError("the reference run (" + name + ") failed: " + failure);
    d = state_distance(r1, r2);
    double smallest = INFINITY;
    for (const FinalState& f : measured) smallest = std::fmin(smallest, state_distance(f, r2));
    // round-off of a run of n steps: about eps sqrt(n) times the solution's size
    const double floor = 64.0 * std::numeric_limits<double>::epsilon() * std::sqrt(static_cast<double>(n)) *
                         std::fmax(1.0, final_state_size(r2));
    if (d <= std::fmax(1e-2 * smallest, floor)) break;
    r1 = r2;
  }
  out.state = r2;
  out.description = name + " with " + std::to_string(n) + " steps";
  out.accuracy = d;
  return out;
}

double exact_accuracy(const FinalState& exact) { return 1e-15 * std::fmax(1.0, final_state_size(exact)); }

ConvergeReport converge(const Problem& pr, const Method& me, const ConvergeOptions& o) {
  if (pr.boundary_value)
    throw InputError("problem.kind: dvm converge measures initial-value runs; a boundary-value problem has no step "
                     "size to refine");
  validate(pr, me);
  const double T = o.t_end > 0.0 ? o.t_end : static_cast<double>(pr.steps) * pr.step;
  std::vector<std::int64_t> list = o.steps_list;
  if (list.empty()) {
    const std::int64_t n0 = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::llround(T / pr.step)));
    list = {n0, 2 * n0, 4 * n0, 8 * n0};
  }
  if (list.size() < 2) throw InputError("--steps-list: a convergence study needs at least two step counts");
  std::set<std::int64_t> seen;
  double total = 0.0;
  std::string shown;
  for (std::int64_t n : list) {
    if (n < 1) throw InputError("--steps-list: step counts must be at least 1");
    if (!seen.insert(n).second)
      throw InputError("--steps-list: the step count " + std::to_string(n) +
                       " appears twice; an order needs different step sizes");
    total += static_cast<double>(n);
    shown += (shown.empty() ? "" : ",") + std::to_string(n);
  }
  if (total > o.max_total_steps) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "the study's runs (%s) would take %.4g steps in all, more than the limit of %.4g",
                  echo(shown).c_str(), total, o.max_total_steps);
    throw InputError(std::string(o.steps_list.empty() ? "integrator.steps" : "--steps-list") + ": " + buf +
                     "; expected fewer or smaller step counts (or raise the limit with --max-steps)");
  }

  ConvergeReport rep;
  rep.system = pr.written ? pr.written->name : pr.system->name;
  rep.map = me.map_label();
  rep.method_label = me.label();
  rep.form = to_string(me.form);
  rep.composition = me.composition;
  rep.galerkin = me.galerkin;
  rep.stages = me.galerkin ? me.stages : 0;
  rep.quadrature = me.galerkin ? to_string(me.quadrature) : "";
  rep.weights = me.weights;
  rep.thetas = me.thetas;
  if (!me.galerkin && default_lift(me.form) != Lift::automatic) rep.lift = to_string(me.effective_lift());
  rep.map_order = me.galerkin ? 2 * me.stages : (me.form == Form::newmark ? (me.newmark_gamma == 0.5 ? 2 : 1)
                                                                           : (me.map ? me.map->order(me.theta) : 0));
  for (double th : me.thetas)  // a theta per stage: the least order of the stages' maps
    rep.map_order = std::min(rep.map_order, me.map->order(th));
  rep.method_order = me.order();
  rep.t_end = T;

  // the runs of the study
  std::vector<FinalState> finals(list.size());
  std::vector<bool> ok(list.size(), false);
  const bool show = isatty(fileno(stderr));
  for (std::size_t i = 0; i < list.size(); ++i) {
    if (show) {
      std::fprintf(stderr, "\r  converge: run %zu of %zu (%lld steps)   ", i + 1, list.size(),
                   static_cast<long long>(list[i]));
      std::fflush(stderr);
    }
    ConvergeRow row;
    row.steps = list[i];
    row.h = T / static_cast<double>(list[i]);
    std::string failure;
    ok[i] = final_state(pr, me, T, list[i], finals[i], row.iterations, failure, &row.wall_seconds);
    if (!ok[i] && rep.failure.empty()) rep.failure = failure;
    rep.rows.push_back(row);
  }

  // the reference
  std::vector<FinalState> measured;
  for (std::size_t i = 0; i < finals.size(); ++i)
    if (ok[i]) measured.push_back(finals[i]);
  const Reference reference =
      reference_solution(pr, me, T, *std::max_element(list.begin(), list.end()), measured, show);
  const FinalState& ref = reference.state;
  rep.reference = reference.description;
  rep.reference_accuracy = reference.accuracy;
  if (show) std::fprintf(stderr, "\r%*s\r", 60, "");
  rep.scale = final_state_size(ref);

  // errors, orders, the fit
  for (std::size_t i = 0; i < rep.rows.size(); ++i) {
    ConvergeRow& row = rep.rows[i];
    row.error = ok[i] ? state_distance(finals[i], ref) : NAN;
    if (!ok[i])
      row.excluded = "failed";
    else if (!(row.error > 10.0 * rep.reference_accuracy))
      row.excluded = "reference";
    else if (!(row.error < 0.1 * std::fmax(1e-300, rep.scale)))
      row.excluded = "pre-asymptotic";
    row.order = i == 0 ? NAN : std::log(rep.rows[i - 1].error / row.error) / std::log(rep.rows[i - 1].h / row.h);
  }
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int used = 0;
  for (const ConvergeRow& row : rep.rows) {
    if (!row.excluded.empty()) continue;
    const double x = std::log(row.h), y = std::log(row.error);
    sx += x, sy += y, sxx += x * x, sxy += x * y;
    ++used;
  }
  rep.fitted_points = used;
  rep.fitted_order = used >= 2 ? (used * sxy - sx * sy) / (used * sxx - sx * sx) : NAN;
  int at_reference = 0, pre = 0;
  for (const ConvergeRow& row : rep.rows) {
    at_reference += row.excluded == "reference";
    pre += row.excluded == "pre-asymptotic";
  }
  std::ostringstream note;
  note.precision(3);
  if (used < 2) {
    note << "not determined: " << used << " of " << rep.rows.size() << " runs have an error above 10 times the "
         << "reference's accuracy (" << rep.reference_accuracy << ") and below a tenth of the solution's size ("
         << rep.scale << ")";
    if (pre > 0) note << "; errors of the size of the solution mean the runs are not in the asymptotic range (a "
                         "chaotic horizon or steps too large: shorten --t-end or refine --steps-list)";
    if (at_reference > 0) note << "; errors at the reference's accuracy cannot show an order (coarser steps, or a "
                                  "shorter horizon where the reference is better)";
  } else if (at_reference + pre > 0) {
    note << "left out of the fit: " << at_reference << " run(s) within 10 times the reference's accuracy, " << pre
         << " run(s) with an error above a tenth of the solution's size";
  }
  rep.fit_note = note.str();
  // the fit against the orders it averages: neighbouring fitted runs whose observed
  // order is far from the fitted one mean a fit over runs in and out of the asymptotic
  // range (e.g. steps too coarse for a high order), and the fitted order is not the method's
  if (used >= 2) {
    std::ostringstream far;
    far.precision(3);
    int count = 0;
    const double allowed = std::fmax(0.5, 0.1 * std::fabs(rep.fitted_order));
    for (std::size_t i = 1; i < rep.rows.size(); ++i) {
      const ConvergeRow& a = rep.rows[i - 1];
      const ConvergeRow& b = rep.rows[i];
      if (!a.excluded.empty() || !b.excluded.empty() || !std::isfinite(b.order)) continue;
      if (std::fabs(b.order - rep.fitted_order) <= allowed) continue;
      far << (count++ ? ", " : "") << b.order << " (" << a.steps << " to " << b.steps << " steps)";
    }
    if (count > 0) {
      std::ostringstream w;
      w.precision(3);
      w << "the observed order" << (count > 1 ? "s " : " ") << far.str() << (count > 1 ? " differ" : " differs")
        << " from the fitted order " << rep.fitted_order << " by more than " << allowed
        << ": the fitted runs are not all in the asymptotic range, where the error falls as a power of h (steps "
           "too coarse for the order, or errors at round-off), so the fitted order is not the method's (change "
           "--steps-list or --t-end)";
      rep.warnings.push_back(w.str());
    }
  }
  return rep;
}

std::string converge_json(const ConvergeReport& r) {
  Json::Object j;
  j.str("system", r.system).str("map", r.map).str("form", r.form);
  if (!r.lift.empty()) j.str("lift", r.lift);
  j.str("composition", r.composition);
  if (!r.weights.empty()) j.arr("weights", r.weights);
  if (!r.thetas.empty()) j.arr("thetas", r.thetas);
  if (r.galerkin) j.str("method", "galerkin").num("stages", r.stages).str("quadrature", r.quadrature);
  j.num("t_end", r.t_end).str("reference", r.reference).num("reference_accuracy", r.reference_accuracy);
  std::string rows = "[\n";
  for (std::size_t i = 0; i < r.rows.size(); ++i) {
    const ConvergeRow& c = r.rows[i];
    Json::Object o;
    o.num("steps", static_cast<double>(c.steps)).num("h", c.h).num("error", c.error).num("order", c.order);
    o.num("iterations", static_cast<double>(c.iterations)).num("wall_seconds", c.wall_seconds);
    o.boolean("fitted", c.excluded.empty());
    if (!c.excluded.empty()) o.str("excluded", c.excluded);
    rows += "    " + o.dump(6) + (i + 1 < r.rows.size() ? ",\n" : "\n");
  }
  j.raw("runs", rows + "  ]").num("fitted_order", r.fitted_order).num("map_order", r.map_order);
  j.num("method_order", r.method_order);
  if (!r.fit_note.empty()) j.str("fit_note", r.fit_note);
  std::string warnings = "[";
  for (std::size_t i = 0; i < r.warnings.size(); ++i) warnings += (i ? ", " : "") + Json::string(r.warnings[i]);
  j.raw("warnings", warnings + "]");
  if (!r.failure.empty()) j.str("failure", r.failure);
  return j.dump();
}

int print_converge(const ConvergeReport& r, bool json) {
  if (json) {
    std::cout << converge_json(r) << "\n";
  } else {
    std::printf("%s with %s to t = %g; reference: %s (accuracy %.1e)\n", r.system.c_str(), r.method_label.c_str(),
                r.t_end, r.reference.c_str(), r.reference_accuracy);
    std::printf("  %12s %14s %14s %8s %12s %10s\n", "steps", "h", "error", "order", "iterations", "wall s");
    for (const ConvergeRow& c : r.rows) {
      // no number where there is none: the first row has no run before it, a failed run no error
      char error[32] = "-", order[32] = "-";
      if (std::isfinite(c.error)) std::snprintf(error, sizeof error, "%.6e", c.error);
      if (std::isfinite(c.order)) std::snprintf(order, sizeof order, "%.3f", c.order);
      std::printf("  %12lld %14.6e %14s %8s %12lld %10.3e%s%s\n", static_cast<long long>(c.steps), c.h, error, order,
                  static_cast<long long>(c.iterations), c.wall_seconds, c.excluded.empty() ? "" : "   not fitted: ",
                  c.excluded.c_str());
    }
    if (std::isnan(r.fitted_order))
      std::printf("  fitted order %s\n", r.fit_note.c_str());
    else
      std::printf("  fitted order %.3f over %d runs (the method's order is %d)%s%s\n", r.fitted_order,
                  r.fitted_points, r.method_order, r.fit_note.empty() ? "" : "; ", r.fit_note.c_str());
    std::fflush(stdout);
    for (const std::string& w : r.warnings) std::fprintf(stderr, "dvm: warning: %s\n", w.c_str());
  }
  if (!r.failure.empty()) {
    std::fprintf(stderr, "dvm: a run of the convergence study did not converge: %s\n", r.failure.c_str());
    return 3;
  }
  return 0;
}

}  // namespace dvm
