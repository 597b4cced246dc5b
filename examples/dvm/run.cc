// `dvm run`: integrate a scene. The system and map named in the scene are resolved
// once, here, into one instantiation of a templated run; the loop itself has no
// runtime dispatch.
#include "examples/dvm/commands.h"

#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>

#include "examples/dvm/json.h"
#include "examples/dvm/report.h"
#include "examples/dvm/run_forms.h"
#include "mechanics/systems.h"
#include "solvers/composition.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"

namespace dvm::cli {

namespace {


template <int N>
Vec<double, N> to_vec(const std::vector<double>& x) {
  Vec<double, N> v;
  for (int i = 0; i < N; ++i) v[i] = x[static_cast<std::size_t>(i)];
  return v;
}
template <int N>
std::vector<double> to_std(const Vec<double, N>& x) {
  return std::vector<double>(x.data(), x.data() + N);
}

template <class System>
constexpr bool has_angular_momentum = std::is_same_v<System, Kepler>;

template <class System, class Map>
int run_with(const Scene& s, const System& L, const Map& R, const RunOptions& o) {
  constexpr int N = System::dim;
  using V = Vec<double, N>;
  V q = to_vec<N>(s.q), p, v0;
  if (s.momentum_given) {
    p = to_vec<N>(s.p);
    v0 = legendre_inverse(L, q, p);
  } else {
    v0 = to_vec<N>(s.v);
    p = legendre(L, q, v0);
  }
  auto energy_at = [&](const V& qk, const V& pk) { return energy(L, qk, legendre_inverse(L, qk, pk)); };
  const double E0 = energy(L, q, v0);
  if (!std::isfinite(E0)) throw InputError(s.path + ": the energy at the initial state is not finite");

  StepOptions opt;
  opt.solver = s.solver == "tiny" ? SolverKind::tiny : SolverKind::newton;
  opt.max_iterations = s.max_iterations;
  opt.residual_tolerance = s.tolerance;
  opt.accept_tolerance = std::fmax(opt.accept_tolerance, s.tolerance);

  const std::string csv_path = o.csv.empty() ? s.csv : o.csv;
  File csv;
  if (!csv_path.empty()) {
    csv.reset(std::fopen(csv_path.c_str(), "w"));
    if (!csv) throw InputError("cannot open the CSV file '" + csv_path + "' for writing");
    std::fputs("t", csv.get());
    for (int i = 0; i < N; ++i) std::fprintf(csv.get(), ",q%d", i);
    for (int i = 0; i < N; ++i) std::fprintf(csv.get(), ",p%d", i);
    std::fputs(",energy\n", csv.get());
  }
  auto write_row = [&](double t, const V& qk, const V& pk, double e) {
    std::fprintf(csv.get(), "%.17g", t);
    for (int i = 0; i < N; ++i) std::fprintf(csv.get(), ",%.17g", qk[i]);
    for (int i = 0; i < N; ++i) std::fprintf(csv.get(), ",%.17g", pk[i]);
    std::fprintf(csv.get(), ",%.17g\n", e);
  };
  if (csv) write_row(0.0, q, p, E0);

  double max_energy_error = 0.0, E = E0;
  double J0 = 0.0, max_J_error = 0.0;
  if constexpr (has_angular_momentum<System>) J0 = System::angular_momentum(q, p);
  const auto start = std::chrono::steady_clock::now();
  auto observer = [&](std::int64_t k, double t, const V& qk, const V& pk, const StepSummary&) {
    E = energy_at(qk, pk);
    max_energy_error = std::fmax(max_energy_error, std::fabs(E - E0));
    if constexpr (has_angular_momentum<System>)
      max_J_error = std::fmax(max_J_error, std::fabs(System::angular_momentum(qk, pk) - J0));
    if (csv && (k % s.every == 0 || k == s.steps)) write_row(t, qk, pk, E);
  };
  // The map's own step, or its steps composed (resolved once, here).
  const RunSummary run =
      s.composition == "none"
          ? integrate(PositionMomentumStep<System, Map>(L, R, s.step, opt), 0.0, q, p, v0, s.steps, observer)
          : integrate(CompositionStep<System, Map>(L, R, s.step,
                                                   substeps(find_composition(s.composition), R.symmetric()), opt),
                      0.0, q, p, v0, s.steps, observer);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (csv && std::fflush(csv.get()) != 0) {
    std::cerr << "dvm: error writing '" << csv_path << "'\n";
    return 3;
  }
  const double t_final = static_cast<double>(run.steps_done) * s.step;

  if (o.json) {
    Json::Object j;
    j.str("status", run.failed ? "failed" : "ok")
        .str("system", s.system)
        .str("map", R.name())
        .str("composition", s.composition)
        .str("solver", s.solver)
        .num("step", s.step)
        .num("steps", static_cast<double>(run.steps_done))
        .num("steps_requested", static_cast<double>(s.steps))
        .num("t_final", t_final)
        .arr("q_final", to_std<N>(q))
        .arr("p_final", to_std<N>(p))
        .num("energy_initial", E0)
        .num("energy_final", E)
        .num("max_abs_energy_error", max_energy_error)
        .num("wall_seconds", wall)
        .num("solver_iterations", static_cast<double>(run.solver_iterations))
        .num("max_step_iterations", run.max_step_iterations)
        .str("form", s.form);
    if constexpr (has_angular_momentum<System>)
      j.num("angular_momentum_initial", J0).num("max_abs_angular_momentum_error", max_J_error);
    if (run.failed) j.raw("failure", failure_json(run));
    std::cout << j.dump() << "\n";
  } else if (!o.quiet) {
    std::printf("%s with %s%s (h = %g): %lld steps to t = %.6g in %.3f s\n", s.system.c_str(), R.name().c_str(),
                s.composition == "none" ? "" : (", composition " + s.composition).c_str(), s.step,
                static_cast<long long>(run.steps_done), t_final, wall);
    std::printf("  energy %.15g -> %.15g, max |E - E0| = %.3e\n", E0, E, max_energy_error);
    if constexpr (has_angular_momentum<System>)
      std::printf("  angular momentum %.15g, max |J - J0| = %.3e\n", J0, max_J_error);
    std::printf("  solver iterations %lld (at most %d in a step)\n", static_cast<long long>(run.solver_iterations),
                run.max_step_iterations);
    if (!csv_path.empty()) std::printf("  wrote %s\n", csv_path.c_str());
  }
  if (run.failed) {
    print_failure(run, s.step);
    return 3;
  }
  return 0;
}

template <class System>
int run_system(const Scene& s, const System& L, const RunOptions& o) {
  if (s.map == "retraction-theta") return run_with(s, L, RetractionMap<EuclideanRetraction>({}, s.theta), o);
  if (s.map == "explicit-euler") return run_with(s, L, ThetaMap::explicit_euler(), o);
  if (s.map == "adjoint-euler") return run_with(s, L, ThetaMap::adjoint_euler(), o);
  if (s.map == "midpoint") return run_with(s, L, ThetaMap::midpoint(), o);
  return run_with(s, L, ThetaMap(s.theta), o);
}

}  // namespace

int run_scene(const Scene& s, const RunOptions& o) {
  try {
    if (s.space != "R^n") return run_manifold_scene(s, o);
    const auto& P = s.params;
    // issue 3: boundary-value problems, the dynamic-size chain, the other forms
    if (s.problem == "boundary-value") return run_boundary_value(s, o);
    if (s.system == "chain") return run_chain(s, o);
    if (s.form != "lagrangian") return run_form(s, o);
    if (s.system == "harmonic") return run_system(s, HarmonicOscillator(P.at("omega")), o);
    if (s.system == "pendulum") return run_system(s, Pendulum(P.at("m"), P.at("l"), P.at("g")), o);
    if (s.system == "kepler") return run_system(s, Kepler(P.at("mu")), o);
  } catch (const std::invalid_argument& e) {
    throw InputError(s.path + ": " + e.what());
  } catch (const DegenerateLagrangianError& e) {
    throw InputError(s.path + ": " + e.what());
  }
  throw InputError(s.path + ": system \"" + s.system + "\" has no runner");
}

}  // namespace dvm::cli
