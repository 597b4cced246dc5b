#include "solvers/runtime/run.h"

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <sstream>

#include <Eigen/SVD>

#include "solvers/runtime/json.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/runtime/kernels.h"

namespace dvm {

const char* to_string(StepPath p) {
  switch (p) {
    case StepPath::none: return "";
    case StepPath::generic: return "generic";
    case StepPath::explicit_splitting: return "explicit-splitting";
    case StepPath::gauss_collocation: return "gauss-collocation";
    case StepPath::separable_newton: return "separable-newton";
    case StepPath::separable_sparse_newton: return "separable-sparse-newton";
    case StepPath::separable_dense_newton: return "separable-dense-newton";
    case StepPath::constrained_sparse_newton: return "constrained-sparse-newton";
    case StepPath::kept_jacobian_newton: return "kept-jacobian-newton";
    case StepPath::sphere_chain_banded_newton: return "sphere-chain-banded-newton";
  }
  return "";
}

std::ostream& operator<<(std::ostream& o, StepPath p) { return o << (p == StepPath::none ? "none" : to_string(p)); }

std::unique_ptr<Run> make_run(const Problem& problem, const Method& method) {
  validate(problem, method);
  try {
    std::unique_ptr<Run> run = problem.system->factory(problem, method);
    return run;
  } catch (const std::invalid_argument& e) {
    // a parameter a system's constructor refuses (a negative mass, ...)
    throw InputError(problem.origin + ": " + e.what());
  } catch (const DegenerateLagrangianError& e) {
    throw InputError(problem.origin + ": " + e.what());
  }
}

namespace kernels {

std::vector<std::string> velocity_names(const Problem& pr) {
  std::vector<std::string> out;
  if (!pr.written || pr.written->space != WrittenSystem::Space::euclidean) return out;
  for (const std::string& c : pr.written->coordinates) {
    const auto open = c.find('[');  // an array's entry q[3]: its velocity q_dot[3]
    out.push_back(open == std::string::npos ? c + "_dot" : c.substr(0, open) + "_dot" + c.substr(open));
  }
  return out;
}

RunReport base_report(const Problem& pr, const Method& me, const std::string& system_name) {
  RunReport r;
  r.system = system_name;
  r.map = me.map_label();
  r.method = me.galerkin ? "galerkin" : "map";
  r.composition = me.composition;
  r.weights = me.weights;
  r.thetas = me.thetas;
  if (!me.galerkin && default_lift(me.form) != Lift::automatic) r.lift = to_string(me.effective_lift());
  r.solver = to_string(me.solver);
  r.form = to_string(me.form);
  r.method_label = me.label();
  r.boundary_value = pr.boundary_value;
  r.step = pr.step;
  r.steps_requested = pr.steps;
  r.order = me.order();
  if (me.galerkin) {
    r.stages = me.stages;
    r.quadrature = to_string(me.quadrature);
  }
  if (me.form == Form::newmark) {
    r.newmark = true;
    r.gamma = me.newmark_gamma;
    r.beta = me.newmark_beta;
  }
  return r;
}

}  // namespace kernels

std::string shortest(double x) {
  char buf[32];
  for (int digits = 15; digits <= 17; ++digits) {
    std::snprintf(buf, sizeof buf, "%.*g", digits, x);
    if (std::strtod(buf, nullptr) == x) break;
  }
  return buf;
}

namespace {

std::string sci(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3e", x);
  return buf;
}

std::string failure_json(const RunSummary& run) {
  Json::Object f;
  f.num("step", static_cast<double>(run.failed_step))
      .num("time", run.failed_time)
      .num("residual", run.failure.residual)
      .num("scale", run.failure.scale)
      .num("iterations", run.failure.iterations)
      .str("message", run.failure.message);
  return f.dump(4);
}

// printf into a string, of any length
std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string format(const char* fmt, ...) {
  va_list args, again;
  va_start(args, fmt);
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, fmt, args);
  va_end(args);
  std::string out(static_cast<std::size_t>(n > 0 ? n : 0) + 1, '\0');
  std::vsnprintf(out.data(), out.size(), fmt, again);
  va_end(again);
  out.resize(out.size() - 1);
  return out;
}

}  // namespace

std::string run_failure_message(const RunReport& r) {
  if (!r.failed) return "";
  if (r.boundary_value)
    return format("the boundary-value problem did not converge after %lld Ceres iterations: largest discrete "
                  "Euler-Lagrange residual %.3e against scale %.3e (%s)%s%s",
                  static_cast<long long>(r.solver_iterations), r.max_del_residual, r.residual_scale, r.message.c_str(),
                  r.kept.empty() ? "" : "; the nodes are in ", r.kept.c_str());
  // a step that failed: a solve that did not converge (with its residual), a non-finite
  // state, or a map or Legendre transform outside its domain
  const RunSummary& run = r.loop;
  const auto& f = run.failure;
  const bool solve = f.iterations > 0 && std::isfinite(f.residual) && std::isfinite(f.scale);
  std::string out;
  if (solve)
    out = format("step %lld (t = %s -> %s) did not converge: residual %.3e against scale %.3e after %d iterations (%s)",
                 static_cast<long long>(run.failed_step), shortest(run.failed_time).c_str(),
                 shortest(run.failed_time + r.step).c_str(), f.residual, f.scale, f.iterations, f.message.c_str());
  else  // (a non-finite residual is named in the message already)
    out = format("step %lld (t = %s -> %s) failed: %s%s", static_cast<long long>(run.failed_step),
                 shortest(run.failed_time).c_str(), shortest(run.failed_time + r.step).c_str(), f.message.c_str(),
                 std::isfinite(f.residual) ? (" (residual " + sci(f.residual) + ")").c_str() : "");
  return out + format("; stopped after %lld completed steps%s%s", static_cast<long long>(run.steps_done),
                      r.kept.empty() ? "" : "; their rows are in ", r.kept.c_str());
}

std::string report_json(const RunReport& r) {
  Json::Object j;
  // The version of this report's keys: raised when a key changes meaning or goes.
  // 2: the conserved quantities besides the energy only under "invariants".
  j.num("json_version", 2).str("status", r.failed ? "failed" : "ok").str("system", r.system);
  if (!r.manifold.empty()) j.str("manifold", r.manifold);
  j.str("map", r.map).str("method", r.method).str("composition", r.composition).str("solver", r.solver);
  if (!r.weights.empty()) j.arr("weights", r.weights);
  if (!r.thetas.empty()) j.arr("thetas", r.thetas);
  j.str("form", r.form);
  if (!r.lift.empty()) j.str("lift", r.lift);
  j.str("problem", r.boundary_value ? "boundary-value" : "initial-value");
  if (!r.structure.empty()) j.str("structure", r.structure).str("structure_source", r.structure_source);
  if (r.step_path != StepPath::none) j.str("step_path", to_string(r.step_path));
  if (!r.derivatives.empty()) j.str("derivatives", r.derivatives);
  if (!r.derivatives.empty()) j.boolean("compiled", r.compiled);
  if (r.compiled) j.num("compile_seconds", r.compile_seconds).str("interpreted", r.interpreted);
  if (r.newton_steps >= 0) j.num("newton_steps", static_cast<double>(r.newton_steps));
  if (r.hessian_colours >= 0) j.num("hessian_colours", r.hessian_colours);
  j.num("step", r.step).num("steps", static_cast<double>(r.steps));
  if (!r.boundary_value) j.num("steps_requested", static_cast<double>(r.steps_requested));
  j.num("t_final", r.t_final);
  j.arr("q_initial", r.q_initial).arr("p_initial", r.p_initial);
  j.arr("q_final", r.q_final).arr("p_final", r.p_final);
  j.num("energy_initial", r.energy_initial).num("energy_final", r.energy_final);
  j.num("max_abs_energy_error", r.max_abs_energy_error);
  if (r.constrained)
    j.boolean("constrained", true)
        .num("constraints", r.constraints)
        .num("max_constraint_residual", r.max_constraint_residual)
        .num("max_hidden_constraint_residual", r.max_hidden_constraint_residual);
  if (r.time_dependent) j.boolean("time_dependent", true);
  if (r.forced)
    j.boolean("forced", true)
        .num("work", r.work)
        .num("energy_balance_final", r.energy_final - r.energy_initial - r.work)
        .num("max_abs_energy_balance", r.max_abs_energy_balance);
  if (r.max_point_defect >= 0.0) j.num("max_point_defect", r.max_point_defect);
  if (r.momentum_spread >= 0.0) j.num("vertical_angular_momentum_spread", r.momentum_spread);
  if (r.boundary_value) j.num("max_del_residual", r.max_del_residual).num("residual_scale", r.residual_scale);
  j.num("wall_seconds", r.wall_seconds).num("solver_iterations", static_cast<double>(r.solver_iterations));
  j.num("jacobians", static_cast<double>(r.jacobians));
  if (!r.boundary_value) j.num("max_step_iterations", r.max_step_iterations).num("monitor_every", static_cast<double>(r.monitor_every));
  if (r.order > 0) j.num("order", r.order);
  if (r.stages > 0) j.num("stages", r.stages).str("quadrature", r.quadrature);
  if (r.newmark) j.num("gamma", r.gamma).num("beta", r.beta);
  if (!r.invariants.empty()) {
    Json::Object inv;
    for (const InvariantReport& i : r.invariants) {
      Json::Object e;
      if (i.array)
        e.arr("initial", i.initial);
      else
        e.num("initial", i.initial.empty() ? NAN : i.initial[0]);
      e.num("max_abs_error", i.max_abs_error);
      inv.raw(i.name, e.dump(6));
    }
    j.raw("invariants", inv.dump(4));
  }
  if (r.boundary_value && r.failed) j.str("message", r.message);
  if (!r.boundary_value && r.failed) j.raw("failure", failure_json(r.loop));
  return j.dump();
}

void print_report(const RunReport& r, bool json, bool quiet, std::FILE* to) {
  if (json) {
    std::fprintf(to, "%s\n", report_json(r).c_str());
  } else if (!quiet) {
    const std::string space = r.manifold.empty() ? "" : " on " + r.manifold;
    if (r.boundary_value) {
      std::fprintf(to, "%s%s boundary-value problem with %s (h = %g, %lld steps): %s in %.3f s\n", r.system.c_str(),
                  space.c_str(), r.method_label.c_str(), r.step, static_cast<long long>(r.steps),
                  r.failed ? "FAILED" : "solved", r.wall_seconds);
      std::fprintf(to, "  max DEL residual %.3e (scale %.3e), %lld Ceres iterations\n", r.max_del_residual,
                  r.residual_scale, static_cast<long long>(r.solver_iterations));
      std::fprintf(to, "  p_initial [");
      for (std::size_t i = 0; i < r.p_initial.size(); ++i) std::fprintf(to, "%s%.15g", i ? ", " : "", r.p_initial[i]);
      std::fprintf(to, "]; energy varies by %.3e along the solution\n", r.max_abs_energy_error);
    } else {
      std::fprintf(to, "%s%s with %s (h = %g): %lld steps to t = %.6g\n", r.system.c_str(), space.c_str(),
                  r.method_label.c_str(), r.step, static_cast<long long>(r.steps), r.t_final);
      std::fprintf(to, "  %-44s %22s %12s\n", "quantity", "initial", "max |change|");
      std::fprintf(to, "  %-44s %22.15g %12.3e\n", "energy", r.energy_initial, r.max_abs_energy_error);
      if (r.constrained)
        std::fprintf(to, "  constraints: %d; relative residual at most %.3e, of the hidden constraint %.3e\n",
                     r.constraints, r.max_constraint_residual, r.max_hidden_constraint_residual);
      if (r.time_dependent)
        std::fprintf(to, "  the Lagrangian depends on t: the energy is not conserved (its change above)\n");
      if (r.forced)
        std::fprintf(to, "  forces: work W = %.15g to t = %.6g; energy balance |E - E_0 - W| at most %.3e\n", r.work,
                     r.t_final, r.max_abs_energy_balance);
      for (const InvariantReport& inv : r.invariants)
        for (std::size_t c = 0; c < inv.initial.size(); ++c) {
          const std::string n = inv.initial.size() > 1 ? inv.name + " [" + std::to_string(c) + "]" : inv.name;
          std::fprintf(to, "  %-44s %22.15g %12.3e\n", n.c_str(), inv.initial[c], inv.max_abs_error);
        }
      if (r.max_point_defect >= 0.0)
        std::fprintf(to, "  largest distance from %s: %.1e\n", r.manifold.c_str(), r.max_point_defect);
      if (!r.structure.empty()) {
        std::string how = "by the generic path";
        switch (r.step_path) {
          case StepPath::explicit_splitting: how = "explicit (kicks and drifts, no solve)"; break;
          case StepPath::separable_newton: how = "by Newton on the structured equation (Jacobian M/h + Hess V)"; break;
          case StepPath::separable_sparse_newton:
            how = "by Newton on the structured equation, sparse Jacobian (Hess V in " +
                  std::to_string(r.hessian_colours) + " colours)";
            break;
          case StepPath::separable_dense_newton:
            how = "by Newton on the structured equation, dense Jacobian kept across steps";
            break;
          case StepPath::constrained_sparse_newton:
            how = "by Newton on the constrained equation, sparse saddle-point Jacobian (Hess V in " +
                  std::to_string(r.hessian_colours) + " colours)";
            break;
          case StepPath::kept_jacobian_newton: how = "by Newton, the Jacobian (L's Hessian) kept across steps"; break;
          case StepPath::gauss_collocation:
            how = "by Gauss collocation on the stage forces (" + std::to_string(r.newton_steps) + " by Newton)";
            break;
          default: break;
        }
        if (r.derivatives == "program") how += "; derivatives by a program differentiated once";
        if (r.derivatives == "gradient-program") how += "; gradient by a program differentiated once";
        if (r.derivatives == "tape") how += "; derivatives by reverse mode on the tape";
        if (r.compiled) {
          char c[64];
          std::snprintf(c, sizeof c, ", compiled to machine code in %.3f s", r.compile_seconds);
          how += c;
          if (!r.interpreted.empty()) how += " (interpreted: " + r.interpreted + ")";
        }
        std::fprintf(to, "  structure %s (%s); steps %s\n", r.structure.c_str(), r.structure_source.c_str(), how.c_str());
      } else if (r.step_path == StepPath::sphere_chain_banded_newton) {
        std::fprintf(to, "  steps by Newton on the chain's equation, banded Jacobian (O(n) a step)\n");
      }
      std::fprintf(to,
                   "  solver iterations %lld (%.2f per step, at most %d in a step), Jacobians formed %lld; wall time "
                   "%.3f s (%.3g us/step)\n",
                  static_cast<long long>(r.solver_iterations),
                  static_cast<double>(r.solver_iterations) / std::fmax(1.0, static_cast<double>(r.steps)),
                  r.max_step_iterations, static_cast<long long>(r.jacobians), r.wall_seconds,
                  1e6 * r.wall_seconds / std::fmax(1.0, static_cast<double>(r.steps)));
    }
    for (const std::string& f : r.written) std::fprintf(to, "  wrote %s\n", f.c_str());
  }
  if (r.failed) std::fprintf(stderr, "dvm: %s\n", run_failure_message(r).c_str());
}

}  // namespace dvm

namespace dvm::kernels {

void require_regular_hessian(const Eigen::MatrixXd& Hd, const std::string& where,
                             const std::vector<std::string>& velocities) {
  if (!Hd.allFinite())
    throw InputError(where + ": the velocity Hessian d2L/dv2 is not finite at the initial state (an overflow or a "
                     "division by zero there); expected a Lagrangian that is finite at initial.q and initial.p/v");
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Hd, Eigen::ComputeFullV);
  const auto sv = svd.singularValues();
  const double smax = sv.maxCoeff(), smin = sv.minCoeff();
  if (!(smin > 1e-12 * smax) || !std::isfinite(smax)) {
    std::ostringstream m;
    m << where << ": the Lagrangian is degenerate at the initial state: the velocity Hessian d2L/dv2 is "
      << "singular there (singular values from " << smax << " down to " << smin << ")";
    if (static_cast<Eigen::Index>(velocities.size()) == Hd.rows() && Hd.rows() > 0) {
      // the null direction: the right singular vector of the smallest singular value
      Eigen::Index k = 0;
      sv.minCoeff(&k);
      const Eigen::VectorXd z = svd.matrixV().col(k);
      const double top = z.cwiseAbs().maxCoeff();
      std::vector<std::string> along;
      for (Eigen::Index i = 0; i < z.size(); ++i)
        if (std::fabs(z[i]) >= 0.3 * top) along.push_back(velocities[static_cast<std::size_t>(i)]);
      if (along.size() == 1) {
        m << ": L has no term of second order in " << along[0] << " there (d2L/dv2 vanishes along it)";
      } else if (along.size() <= 6) {
        m << ": d2L/dv2 vanishes along a combination of ";
        for (std::size_t i = 0; i < along.size(); ++i)
          m << (i == 0 ? "" : i + 1 == along.size() ? " and " : ", ") << along[i];
      }
    }
    m << "; the Legendre transform cannot be inverted and the discrete equations do not define a step";
    throw InputError(m.str());
  }
}

}  // namespace dvm::kernels
