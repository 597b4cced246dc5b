// `dvm run` with [problem] kind = "boundary-value" for the spherical pendulum on S^2:
// one Ceres problem over all interior nodes with ceres::SphereManifold
// (solvers/manifold_boundary_value.h). Output as for the initial-value run on S^2 (CSV
// t,x,y,z,p0,p1,p2,energy,J3), JSON as for boundary-value problems on R^n plus the
// largest distance from S^2.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <vector>

#include "examples/dvm/commands.h"
#include "examples/dvm/json.h"
#include "examples/dvm/report.h"
#include "solvers/manifold_boundary_value.h"

namespace dvm::cli {

int run_manifold_boundary_value(const Scene& s, const RunOptions& o);

int run_manifold_boundary_value(const Scene& s, const RunOptions& o) {
  using V3 = Vec<double, 3>;
  if (s.system != "spherical-pendulum")
    throw InputError(s.path + ": system \"" + s.system + "\" has no boundary-value runner");
  const auto& P = s.params;
  const SphericalPendulum L(P.at("m"), P.at("l"), P.at("g"));
  const bool exp = s.map.find("exp") != std::string::npos;
  const bool fixed = s.map.find("fixed") != std::string::npos;
  const SphereMap R(exp ? RetractionKind::exp : RetractionKind::projection, fixed ? 0.0 : 0.5, s.map);
  const SphereBoundaryValueProblem<SphericalPendulum, SphereMap> B(L, R, s.step);
  BoundaryValueOptions bo;
  bo.max_iterations = std::max(s.max_iterations, 100);
  const auto start = std::chrono::steady_clock::now();
  const auto res = B.solve(V3(s.q[0], s.q[1], s.q[2]), V3(s.q_final[0], s.q_final[1], s.q_final[2]),
                           static_cast<int>(s.steps), bo);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  const std::string csv_path = o.csv.empty() ? s.csv : o.csv;
  File csv;
  if (!csv_path.empty()) {
    csv.reset(std::fopen(csv_path.c_str(), "w"));
    if (!csv) throw InputError("cannot open the CSV file '" + csv_path + "' for writing");
    std::fprintf(csv.get(), "t,x,y,z,p0,p1,p2,energy,J3\n");
  }
  const auto K = static_cast<std::size_t>(s.steps);
  std::vector<double> E(K + 1);
  double emin = INFINITY, emax = -INFINITY, defect = 0.0, jmin = INFINITY, jmax = -INFINITY;
  for (std::size_t k = 0; k <= K; ++k) {
    const V3& q = res.q[k];
    const V3& p = res.p[k];
    E[k] = manifold_energy(L, q, manifold_legendre_inverse(L, q, p));
    const double J = SphericalPendulum::vertical_momentum(q, p);
    emin = std::fmin(emin, E[k]);
    emax = std::fmax(emax, E[k]);
    jmin = std::fmin(jmin, J);
    jmax = std::fmax(jmax, J);
    defect = std::fmax(defect, Sphere::point_defect(q));
    if (csv && (k % static_cast<std::size_t>(s.every) == 0 || k == K)) {
      std::fprintf(csv.get(), "%.17g", static_cast<double>(k) * s.step);
      for (int i = 0; i < 3; ++i) std::fprintf(csv.get(), ",%.17g", q[i]);
      for (int i = 0; i < 3; ++i) std::fprintf(csv.get(), ",%.17g", p[i]);
      std::fprintf(csv.get(), ",%.17g,%.17g\n", E[k], J);
    }
  }
  if (csv && std::fflush(csv.get()) != 0) {
    std::cerr << "dvm: error writing '" << csv_path << "'\n";
    return 3;
  }
  auto vec = [](const V3& x) { return std::vector<double>{x[0], x[1], x[2]}; };
  if (o.json) {
    Json::Object j;
    j.str("status", res.converged ? "ok" : "failed")
        .str("system", s.system)
        .str("manifold", Sphere::name)
        .str("map", R.name())
        .str("form", s.form)
        .str("problem", "boundary-value")
        .num("step", s.step)
        .num("steps", static_cast<double>(s.steps))
        .num("t_final", static_cast<double>(s.steps) * s.step)
        .arr("q_initial", vec(res.q.front()))
        .arr("p_initial", vec(res.p.front()))
        .arr("q_final", vec(res.q.back()))
        .arr("p_final", vec(res.p.back()))
        .num("energy_initial", E.front())
        .num("energy_final", E.back())
        .num("max_abs_energy_error", std::fmax(emax - E.front(), E.front() - emin))
        .num("max_point_defect", defect)
        .num("vertical_angular_momentum_spread", jmax - jmin)
        .num("max_del_residual", res.max_residual)
        .num("residual_scale", res.scale)
        .num("solver_iterations", res.iterations)
        .num("wall_seconds", wall);
    if (!res.converged) j.str("message", res.message);
    std::cout << j.dump() << "\n";
  } else if (!o.quiet) {
    std::printf("%s boundary-value problem on S^2 with %s (h = %g, %lld steps): %s in %.3f s\n", s.system.c_str(),
                R.name().c_str(), s.step, static_cast<long long>(s.steps), res.converged ? "solved" : "FAILED", wall);
    std::printf("  max DEL residual %.3e (scale %.3e), %d Ceres iterations, largest distance from S^2 %.1e\n",
                res.max_residual, res.scale, res.iterations, defect);
    std::printf("  p_initial [%.15g, %.15g, %.15g]; energy varies by %.3e, J3 by %.3e along the solution\n",
                res.p.front()[0], res.p.front()[1], res.p.front()[2], emax - emin, jmax - jmin);
    if (!csv_path.empty()) std::printf("  wrote %s\n", csv_path.c_str());
  }
  if (!res.converged) {
    std::fprintf(stderr, "dvm: the boundary-value problem did not converge: %s\n", res.message.c_str());
    return 3;
  }
  return 0;
}

}  // namespace dvm::cli
