// `dvm run` for the integrator forms other than the Lagrangian position-momentum step,
// for the dynamic-size chain, and for boundary-value problems (issue 3). As in run.cc
// the scene's names are resolved once into one instantiation of a templated run.
//
//   form = "hamiltonian"   HamiltonianStep (Eq. 5.1) of the scene's map, with the
//                          Hamiltonian of the system's Lagrangian (Legendre transform)
//   form = "sode1"/"sode2" SodeStep of the tangent lift of the scene's map (Eq. 4.1/4.2)
//   form = "newmark"       NewmarkStep(gamma, beta)
//   composition = "..."    any of these composed (ComposedStep), the adjoint stages
//                          from the adjoint map (theta -> 1 - theta) or, for Newmark,
//                          the adjoint (gamma, beta) -> (1 - gamma, 1/2 - gamma + beta)
//   system = "chain"       ChainStep (tridiagonal Newton), theta-family maps
//   kind = "boundary-value" BoundaryValueProblem (one sparse Ceres problem)
//
// Every initial-value run writes the CSV (t, q.., p.., energy) and JSON summary of a
// Lagrangian-form run, with the same keys.
#include "examples/dvm/run_forms.h"

#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>

#include "examples/dvm/json.h"
#include "examples/dvm/output.h"
#include "examples/dvm/report.h"
#include "mechanics/chain.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/written_lagrangian.h"
#include "mechanics/systems.h"
#include "solvers/boundary_value.h"
#include "solvers/chain_step.h"
#include "solvers/composition.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/integrate.h"
#include "solvers/sode_step.h"

namespace dvm::cli {

namespace {


template <int N>
Vec<double, N> to_vec(const std::vector<double>& x) {
  Vec<double, N> v(static_cast<Eigen::Index>(x.size()));
  for (std::size_t i = 0; i < x.size(); ++i) v[static_cast<Eigen::Index>(i)] = x[i];
  return v;
}
template <int N>
std::vector<double> to_std(const Vec<double, N>& x) {
  return std::vector<double>(x.data(), x.data() + x.size());
}

StepOptions step_options(const Scene& s) {
  StepOptions opt;
  opt.solver = s.solver == "tiny" ? SolverKind::tiny : SolverKind::newton;
  opt.max_iterations = s.max_iterations;
  opt.residual_tolerance = s.tolerance;
  opt.accept_tolerance = std::fmax(opt.accept_tolerance, s.tolerance);
  return opt;
}

// Opens the run's CSV (output.h: a temporary renamed at the end) and writes its header.
void open_csv(OutputFile& csv, const Scene& s, const RunOptions& o, int n) {
  const std::string path = o.csv.empty() ? s.csv : o.csv;
  if (path.empty()) return;
  csv.open(path, output_source(s.path, o.csv, "--csv", "output.csv"), csv_bytes(output_rows(s.steps, s.every), 2 * n + 2));
  std::fputs("t", csv.get());
  for (int i = 0; i < n; ++i) std::fprintf(csv.get(), ",q%d", i);
  for (int i = 0; i < n; ++i) std::fprintf(csv.get(), ",p%d", i);
  std::fputs(",energy\n", csv.get());
}

template <class V>
void write_row(std::FILE* f, double t, const V& q, const V& p, double e) {
  std::fprintf(f, "%.17g", t);
  for (Eigen::Index i = 0; i < q.size(); ++i) std::fprintf(f, ",%.17g", q[i]);
  for (Eigen::Index i = 0; i < p.size(); ++i) std::fprintf(f, ",%.17g", p[i]);
  std::fprintf(f, ",%.17g\n", e);
}

// The run of any (q, p) stepper: the same output as run.cc's Lagrangian-form run.
// `energy_at(q, p)` gives the energy; `invariant(q, p)` an optional conserved
// quantity reported under `invariant_name` (empty: none).
template <int N, class Stepper, class Energy, class Invariant>
int run_stepper(const Scene& s, const Stepper& stepper, const std::string& method, Vec<double, N> q,
                Vec<double, N> p, const Vec<double, N>& v0, const Energy& energy_at, const std::string& invariant_name,
                const Invariant& invariant, const RunOptions& o) {
  using V = Vec<double, N>;
  const double E0 = energy_at(q, p);
  if (!std::isfinite(E0)) throw InputError(s.path + ": the energy at the initial state is not finite");
  const std::string csv_path = o.csv.empty() ? s.csv : o.csv;
  OutputFile csv;
  open_csv(csv, s, o, static_cast<int>(q.size()));
  if (csv) write_row(csv.get(), 0.0, q, p, E0);
  double max_energy_error = 0.0, E = E0;
  const double J0 = invariant(q, p);
  double max_J_error = 0.0;
  const auto start = std::chrono::steady_clock::now();
  const RunSummary run = integrate(stepper, 0.0, q, p, v0, s.steps,
                                   [&](std::int64_t k, double t, const V& qk, const V& pk, const StepSummary&) {
                                     E = energy_at(qk, pk);
                                     max_energy_error = std::fmax(max_energy_error, std::fabs(E - E0));
                                     if (!invariant_name.empty())
                                       max_J_error = std::fmax(max_J_error, std::fabs(invariant(qk, pk) - J0));
                                     if (csv && (k % s.every == 0 || k == s.steps)) write_row(csv.get(), t, qk, pk, E);
                                   });
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::string kept;
  if (!finish_outputs(!run.failed, {&csv}, kept)) return 3;
  const double t_final = static_cast<double>(run.steps_done) * s.step;
  if (o.json) {
    Json::Object j;
    j.str("status", run.failed ? "failed" : "ok")
        .str("system", s.system)
        .str("map", method)
        .str("method", s.method)
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
        .num("max_step_iterations", run.max_step_iterations);
    if (!invariant_name.empty())
      j.num(invariant_name + "_initial", J0).num("max_abs_" + invariant_name + "_error", max_J_error);
    j.str("form", s.form);
    if (s.form == "newmark") j.num("gamma", s.newmark_gamma).num("beta", s.newmark_beta);
    if (run.failed) j.raw("failure", failure_json(run));
    std::cout << j.dump() << "\n";
  } else if (!o.quiet) {
    std::printf("%s with %s, %s form%s (h = %g): %lld steps to t = %.6g in %.3f s\n", s.system.c_str(),
                method.c_str(), s.form.c_str(),
                s.composition == "none" ? "" : (", composition " + s.composition).c_str(), s.step, static_cast<long long>(run.steps_done), t_final, wall);
    std::printf("  energy %.15g -> %.15g, max |E - E0| = %.3e\n", E0, E, max_energy_error);
    if (!invariant_name.empty())
      std::printf("  %s %.15g, max error %.3e\n", invariant_name.c_str(), J0, max_J_error);
    std::printf("  solver iterations %lld (at most %d in a step)\n", static_cast<long long>(run.solver_iterations),
                run.max_step_iterations);
    if (!run.failed && !csv_path.empty()) std::printf("  wrote %s\n", csv_path.c_str());
  }
  if (run.failed) {
    print_failure(run, s.step, kept);
    return 3;
  }
  return 0;
}

// The adjoint of a theta-family map is the same family at 1 - theta (Prop. 2.4:
// R*(x, v) = (R^2_x(-v), R^1_x(-v))), so the adjoint stages of a composition reuse the
// basic method's step type.
ThetaMap same_type_adjoint(const ThetaMap& R) { return ThetaMap(1.0 - R.theta(), R.name() + "*"); }
RetractionMap<EuclideanRetraction> same_type_adjoint(const RetractionMap<EuclideanRetraction>& R) {
  return RetractionMap<EuclideanRetraction>({}, 1.0 - R.theta());
}

template <class S>
struct is_written : std::false_type {};
template <int N>
struct is_written<WrittenLagrangian<N>> : std::true_type {};

template <class System>
int run_form_with_system(const Scene& s, const System& L, const RunOptions& o) {
  constexpr int N = System::dim;
  using V = Vec<double, N>;
  V q = to_vec<N>(s.q), p, v0;
  if (s.momentum_given) {
    p = to_vec<N>(s.p);
    v0 = legendre_inverse_checked(L, q, p);
  } else {
    v0 = to_vec<N>(s.v);
    p = legendre_checked(L, q, v0);
  }
  auto energy_at = [&](const V& qk, const V& pk) { return energy(L, qk, legendre_inverse(L, qk, pk)); };
  std::string inv_name;
  auto invariant = [](const V& qk, const V& pk) {
    if constexpr (std::is_same_v<System, Kepler>) return Kepler::angular_momentum(qk, pk);
    (void)qk;
    (void)pk;
    return 0.0;
  };
  if constexpr (std::is_same_v<System, Kepler>) inv_name = "angular_momentum";
  const StepOptions opt = step_options(s);

  // The basic method's run, or its composition's (solvers/composition.h) when the
  // scene names one: make(hk, adjoint) builds the step of size hk of the basic method
  // or of its adjoint; `symmetric` says the basic method is its own adjoint.
  auto run_method = [&](const auto& make, bool symmetric, const std::string& name) -> int {
    if (s.composition == "none")
      return run_stepper<N>(s, make(s.step, false), name, q, p, v0, energy_at, inv_name, invariant, o);
    using Step = decltype(make(s.step, false));
    const ComposedStep<Step> step(
        s.step, substeps(find_composition(s.composition), symmetric), [&](double hk) { return make(hk, false); },
        [&](double hk) { return make(hk, true); });
    return run_stepper<N>(s, step, name, q, p, v0, energy_at, inv_name, invariant, o);
  };

  auto with_map = [&](const auto& R) -> int {
    using Map = std::decay_t<decltype(R)>;
    if (s.form == "hamiltonian") {
      if constexpr (is_written<System>::value) {
        // The scene's own H. (H from a written L by the Legendre transform would need
        // a third level of nested Jets, which Ceres' functions do not support.)
        if (!L.has_hamiltonian())
          throw InputError(s.path + ": key 'integrator.form': form = \"hamiltonian\" with a written Lagrangian "
                                    "needs system.hamiltonian = \"...\" (H in the coordinates and p_<name>)");
        using H = WrittenHamiltonian<N>;
        auto make = [&](double hk, bool adj) {
          return HamiltonianStep<H, Map>(H{s.written}, adj ? same_type_adjoint(R) : R, hk, opt);
        };
        return run_method(make, R.symmetric(), R.name());
      } else {
        using H = LegendreHamiltonian<System>;
        auto make = [&](double hk, bool adj) {
          return HamiltonianStep<H, Map>(H(L), adj ? same_type_adjoint(R) : R, hk, opt);
        };
        return run_method(make, R.symmetric(), R.name());
      }
    }
    if constexpr (is_written<System>::value) {
      throw InputError(s.path + ": key 'integrator.form': a written Lagrangian runs the lagrangian and hamiltonian "
                                "forms, got \"" + s.form + "\"");
    } else {
      // the tangent lift of the adjoint map gives the adjoint SODE step (both
      // samplings treat the two end points alike)
      auto make = [&](double hk, bool adj) {
        const auto lift = tangent_lift(adj ? same_type_adjoint(R) : R);
        using Step = SodeStep<System, std::decay_t<decltype(lift)>>;
        return VelocityFormStep<Step>(Step(L, lift, hk, s.form == "sode1" ? SodeForm::sode1 : SodeForm::sode2, opt));
      };
      return run_method(make, R.symmetric(), R.name());
    }
  };
  if (s.form == "newmark") {
    if constexpr (is_written<System>::value) {
      throw InputError(s.path + ": key 'integrator.form': a written Lagrangian runs the lagrangian and hamiltonian "
                                "forms, got \"newmark\"");
    } else {
      const NewmarkStep<System> basic(L, s.step, s.newmark_gamma, s.newmark_beta, opt);
      auto make = [&](double hk, bool adj) {
        return VelocityFormStep<NewmarkStep<System>>((adj ? basic.adjoint() : basic).with_step(hk));
      };
      return run_method(make, s.newmark_gamma == 0.5, "newmark");
    }
  }
  if (s.map == "retraction-theta") return with_map(RetractionMap<EuclideanRetraction>({}, s.theta));
  if (s.map == "explicit-euler") return with_map(ThetaMap::explicit_euler());
  if (s.map == "adjoint-euler") return with_map(ThetaMap::adjoint_euler());
  if (s.map == "midpoint") return with_map(ThetaMap::midpoint());
  return with_map(ThetaMap(s.theta));
}

ThetaMap theta_map_of(const Scene& s) {
  if (s.map == "explicit-euler") return ThetaMap::explicit_euler();
  if (s.map == "adjoint-euler") return ThetaMap::adjoint_euler();
  if (s.map == "midpoint") return ThetaMap::midpoint();
  return ThetaMap(s.theta);
}

FPUChain chain_of(const Scene& s) {
  const auto& P = s.params;
  return FPUChain(static_cast<int>(P.at("n")), P.at("m"), P.at("k"), P.at("alpha"), P.at("beta"),
                  P.at("fixed") != 0.0);
}

template <class System>
int run_boundary_value_with(const Scene& s, const System& L, const RunOptions& o) {
  constexpr int N = System::dim;
  const ThetaMap R = theta_map_of(s);
  auto solve_and_report = [&](const auto& map) -> int {
    using Map = std::decay_t<decltype(map)>;
    const BoundaryValueProblem<System, Map> B(L, map, s.step);
    const std::string csv_path = o.csv.empty() ? s.csv : o.csv;
    OutputFile csv;  // opened (and its room checked) before the solve
    open_csv(csv, s, o, N);
    const auto start = std::chrono::steady_clock::now();
    BoundaryValueOptions bo;
    bo.max_iterations = std::max(s.max_iterations, 100);
    const auto res = B.solve(to_vec<N>(s.q), to_vec<N>(s.q_final), static_cast<int>(s.steps), bo);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const auto K = static_cast<std::size_t>(s.steps);
    std::vector<double> E(K + 1);
    double emin = INFINITY, emax = -INFINITY;
    for (std::size_t k = 0; k <= K; ++k) {
      E[k] = energy(L, res.q[k], legendre_inverse(L, res.q[k], res.p[k]));
      emin = std::fmin(emin, E[k]);
      emax = std::fmax(emax, E[k]);
      if (csv && (k % static_cast<std::size_t>(s.every) == 0 || k == K))
        write_row(csv.get(), static_cast<double>(k) * s.step, res.q[k], res.p[k], E[k]);
    }
    std::string kept;
    if (!finish_outputs(res.converged, {&csv}, kept)) return 3;
    if (o.json) {
      Json::Object j;
      j.str("status", res.converged ? "ok" : "failed")
          .str("system", s.system)
          .str("map", map.name())
          .str("form", s.form)
          .str("problem", "boundary-value")
          .num("step", s.step)
          .num("steps", static_cast<double>(s.steps))
          .num("t_final", static_cast<double>(s.steps) * s.step)
          .arr("q_initial", to_std<N>(res.q.front()))
          .arr("p_initial", to_std<N>(res.p.front()))
          .arr("q_final", to_std<N>(res.q.back()))
          .arr("p_final", to_std<N>(res.p.back()))
          .num("energy_initial", E.front())
          .num("energy_final", E.back())
          .num("max_abs_energy_error", std::fmax(emax - E.front(), E.front() - emin))
          .num("max_del_residual", res.max_residual)
          .num("residual_scale", res.scale)
          .num("solver_iterations", res.iterations)
          .num("wall_seconds", wall);
      if (!res.converged) j.str("message", res.message);
      std::cout << j.dump() << "\n";
    } else if (!o.quiet) {
      std::printf("%s boundary-value problem with %s (h = %g, %lld steps): %s in %.3f s\n", s.system.c_str(),
                  map.name().c_str(), s.step, static_cast<long long>(s.steps), res.converged ? "solved" : "FAILED",
                  wall);
      std::printf("  max DEL residual %.3e (scale %.3e), %d Ceres iterations\n", res.max_residual, res.scale,
                  res.iterations);
      std::printf("  p_initial %.15g, energy varies by %.3e along the solution\n", res.p.front()[0], emax - emin);
      if (res.converged && !csv_path.empty()) std::printf("  wrote %s\n", csv_path.c_str());
    }
    if (!res.converged) {
      std::fprintf(stderr,
                   "dvm: the boundary-value problem did not converge after %d Ceres iterations: largest discrete "
                   "Euler-Lagrange residual %.3e against scale %.3e (%s)%s%s\n",
                   res.iterations, res.max_residual, res.scale, res.message.c_str(),
                   kept.empty() ? "" : "; the nodes are in ", kept.c_str());
      return 3;
    }
    return 0;
  };
  if (s.map == "retraction-theta") return solve_and_report(RetractionMap<EuclideanRetraction>({}, s.theta));
  return solve_and_report(R);
}

}  // namespace

int run_form(const Scene& s, const RunOptions& o) {
  const auto& P = s.params;
  if (s.system == "harmonic") return run_form_with_system(s, HarmonicOscillator(P.at("omega")), o);
  if (s.system == "pendulum") return run_form_with_system(s, Pendulum(P.at("m"), P.at("l"), P.at("g")), o);
  if (s.system == "kepler") return run_form_with_system(s, Kepler(P.at("mu")), o);
  if (s.system == "lagrangian") {
    switch (s.dim) {
      case 1: return run_form_with_system(s, WrittenLagrangian<1>(s.written), o);
      case 2: return run_form_with_system(s, WrittenLagrangian<2>(s.written), o);
      case 3: return run_form_with_system(s, WrittenLagrangian<3>(s.written), o);
      case 4: return run_form_with_system(s, WrittenLagrangian<4>(s.written), o);
      case 5: return run_form_with_system(s, WrittenLagrangian<5>(s.written), o);
      default: return run_form_with_system(s, WrittenLagrangian<6>(s.written), o);
    }
  }
  throw InputError(s.path + ": system \"" + s.system + "\" has no runner for form \"" + s.form + "\"");
}

int run_chain(const Scene& s, const RunOptions& o) {
  using V = Eigen::VectorXd;
  const FPUChain C = chain_of(s);
  V q = to_vec<Eigen::Dynamic>(s.q), p, v0;
  if (s.momentum_given) {
    p = to_vec<Eigen::Dynamic>(s.p);
    v0 = p / C.m;
  } else {
    v0 = to_vec<Eigen::Dynamic>(s.v);
    p = C.m * v0;
  }
  const ChainStep step(C, theta_map_of(s), s.step, step_options(s));
  auto energy_at = [&](const V& qk, const V& pk) { return C.energy(qk, pk); };
  auto invariant = [](const V&, const V& pk) { return FPUChain::total_momentum(pk); };
  return run_stepper<Eigen::Dynamic>(s, step, theta_map_of(s).name(), q, p, v0, energy_at,
                                     C.fixed ? std::string() : std::string("total_momentum"), invariant, o);
}

int run_boundary_value(const Scene& s, const RunOptions& o) {
  const auto& P = s.params;
  if (s.system == "harmonic") return run_boundary_value_with(s, HarmonicOscillator(P.at("omega")), o);
  if (s.system == "pendulum") return run_boundary_value_with(s, Pendulum(P.at("m"), P.at("l"), P.at("g")), o);
  if (s.system == "kepler") return run_boundary_value_with(s, Kepler(P.at("mu")), o);
  throw InputError(s.path + ": system \"" + s.system + "\" has no boundary-value runner");
}

}  // namespace dvm::cli
