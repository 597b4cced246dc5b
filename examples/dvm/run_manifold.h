// The output side of `dvm run` on S^2 and SO(3), shared by run_manifold.cc and the
// translation units of the Galerkin methods (run_manifold_galerkin_*.cc): stored
// coordinates, momentum maps and CSV columns of each system, and run_stepper, which
// integrates with any manifold stepper and writes the CSV and the JSON or text report.
#pragma once

#include <chrono>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "examples/dvm/commands.h"
#include "examples/dvm/json.h"
#include "examples/dvm/output.h"
#include "examples/dvm/report.h"
#include "solvers/manifold_step.h"

namespace dvm::cli::manifold_run {

using V3 = Vec<double, 3>;
using M3 = Mat<double, 3, 3>;

// Stored coordinates written to the CSV and JSON: the point itself on S^2, the
// quaternion on SO(3).
template <int N>
std::vector<double> coordinates(const Vec<double, N>& x) {
  return std::vector<double>(x.data(), x.data() + N);
}
inline std::vector<double> coordinates(const M3& R) {
  const Vec<double, 4> q = SO3::to_quaternion(R);
  return {q[0], q[1], q[2], q[3]};
}

// The conserved momentum of each system (vertical or spatial angular momentum).
inline std::vector<double> momentum_map(const SphericalPendulum&, const V3& x, const V3& p) {
  return {SphericalPendulum::vertical_momentum(x, p)};
}
inline std::vector<double> momentum_map(const RigidBody&, const M3& R, const V3& p) {
  const V3 m = RigidBody::spatial_momentum(R, p);
  return {m[0], m[1], m[2]};
}
inline std::vector<double> momentum_map(const HeavyTop&, const M3& R, const V3& p) {
  return {HeavyTop::vertical_momentum(R, p)};
}
template <int K>
std::vector<double> momentum_map(const SphericalChain<K>&, const Vec<double, 3 * K>& x, const Vec<double, 3 * K>& p) {
  return {SphericalChain<K>::vertical_momentum(x, p)};
}
template <int K>
const char* momentum_columns(const SphericalChain<K>&) {
  return ",J3";
}
template <int K>
std::string point_columns(const SphericalChain<K>&) {
  std::string out = "t";
  for (int i = 1; i <= K; ++i)
    for (const char* c : {"x", "y", "z"}) out += "," + std::string(c) + std::to_string(i);
  for (int i = 0; i < 3 * K; ++i) out += ",p" + std::to_string(i);
  return out + ",energy";
}
inline const char* momentum_columns(const SphericalPendulum&) { return ",J3"; }
inline const char* momentum_columns(const RigidBody&) { return ",m0,m1,m2"; }
inline const char* momentum_columns(const HeavyTop&) { return ",J3"; }
inline std::string point_columns(const SphericalPendulum&) { return "t,x,y,z,p0,p1,p2,energy"; }
inline std::string point_columns(const RigidBody&) { return "t,qw,qx,qy,qz,pi0,pi1,pi2,energy"; }
inline std::string point_columns(const HeavyTop&) { return "t,qw,qx,qy,qz,pi0,pi1,pi2,energy"; }

template <class System, class Map, class Stepper>
int run_stepper(const Scene& s, const System& L, const Map& R, const RunOptions& o, const Stepper& stepper,
                typename Stepper::Point q, typename Stepper::Covector p, const typename Stepper::Covector& v0,
                double E0, const std::vector<double>& J0) {
  using M = typename Map::Manifold;
  using Point = typename M::template Point<double>;
  using Covector = typename M::template Tangent<double>;
  constexpr int C = Covector::RowsAtCompileTime;
  auto energy_at = [&](const Point& qk, const Covector& pk) {
    return manifold_energy(L, qk, manifold_legendre_inverse(L, qk, pk));
  };
  const bool galerkin = s.method == "galerkin";
  const std::string csv_path = o.csv.empty() ? s.csv : o.csv;
  OutputFile csv;
  if (!csv_path.empty()) {
    const int columns = 2 + static_cast<int>(coordinates(q).size()) + C + static_cast<int>(J0.size());
    csv.open(csv_path, output_source(s.path, o.csv, "--csv", "output.csv"),
             csv_bytes(output_rows(s.steps, s.every), columns));
    std::fprintf(csv.get(), "%s%s\n", point_columns(L).c_str(), momentum_columns(L));
  }
  auto write_row = [&](double t, const Point& qk, const Covector& pk, double e) {
    std::fprintf(csv.get(), "%.17g", t);
    for (double c : coordinates(qk)) std::fprintf(csv.get(), ",%.17g", c);
    for (int i = 0; i < C; ++i) std::fprintf(csv.get(), ",%.17g", pk[i]);
    std::fprintf(csv.get(), ",%.17g", e);
    for (double c : momentum_map(L, qk, pk)) std::fprintf(csv.get(), ",%.17g", c);
    std::fputc('\n', csv.get());
  };
  if (csv) write_row(0.0, q, p, E0);

  double max_energy_error = 0.0, E = E0, max_defect = M::point_defect(q), max_momentum_error = 0.0;
  const auto start = std::chrono::steady_clock::now();
  auto observer = [&](std::int64_t k, double t, const Point& qk, const Covector& pk, const StepSummary&) {
    E = energy_at(qk, pk);
    max_energy_error = std::fmax(max_energy_error, std::fabs(E - E0));
    max_defect = std::fmax(max_defect, M::point_defect(qk));
    const std::vector<double> J = momentum_map(L, qk, pk);
    for (std::size_t i = 0; i < J.size(); ++i) max_momentum_error = std::fmax(max_momentum_error, std::fabs(J[i] - J0[i]));
    if (csv && (k % s.every == 0 || k == s.steps)) write_row(t, qk, pk, E);
  };
  const RunSummary run = integrate_manifold(stepper, 0.0, q, p, v0, s.steps, observer);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::string kept;
  if (!finish_outputs(!run.failed, {&csv}, kept)) return 3;
  const double t_final = static_cast<double>(run.steps_done) * s.step;
  const char* momentum_name =
      std::is_same_v<System, RigidBody> ? "spatial_angular_momentum" : "vertical_angular_momentum";
  if (o.json) {
    Json::Object j;
    j.str("status", run.failed ? "failed" : "ok")
        .str("system", s.system)
        .str("manifold", M::name)
        .str("map", galerkin ? std::string("none") : R.name())
        .str("form", s.form)
        .str("composition", s.composition)
        .str("solver", s.solver)
        .num("step", s.step)
        .num("steps", static_cast<double>(run.steps_done))
        .num("steps_requested", static_cast<double>(s.steps))
        .num("t_final", t_final)
        .arr("q_final", coordinates(q))
        .arr("p_final", std::vector<double>(p.data(), p.data() + C))
        .num("energy_initial", E0)
        .num("energy_final", E)
        .num("max_abs_energy_error", max_energy_error)
        .num("max_point_defect", max_defect)
        .arr(std::string(momentum_name) + "_initial", J0)
        .num(std::string("max_abs_") + momentum_name + "_error", max_momentum_error)
        .num("wall_seconds", wall)
        .num("solver_iterations", static_cast<double>(run.solver_iterations))
        .num("max_step_iterations", run.max_step_iterations);
    if (galerkin)
      j.str("method", "galerkin").num("stages", s.stages).str("quadrature", s.quadrature).num("order", 2 * s.stages);
    if (run.failed) j.raw("failure", failure_json(run));
    std::cout << j.dump() << "\n";
  } else if (!o.quiet) {
    const std::string method =
        galerkin ? "galerkin " + s.quadrature + " s=" + std::to_string(s.stages) + " (order " +
                       std::to_string(2 * s.stages) + ", charts centred at each point)"
                 : R.name();
    std::printf("%s on %s with %s%s (h = %g): %lld steps to t = %.6g in %.3f s\n", s.system.c_str(), M::name,
                method.c_str(), s.composition == "none" ? "" : (", composition " + s.composition).c_str(), s.step,
                static_cast<long long>(run.steps_done), t_final, wall);
    std::printf("  energy %.15g -> %.15g, max |E - E0| = %.3e\n", E0, E, max_energy_error);
    std::printf("  %s: max error %.3e;  largest distance from %s %.1e\n", momentum_name, max_momentum_error, M::name,
                max_defect);
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

// method = "galerkin" (solvers/manifold_galerkin_step.h, the generating-function
// step, stages 1..6 dispatched to fixed sizes), one translation unit per system
// (run_manifold_galerkin_*.cc): the run with the same output as run_stepper.
int run_manifold_galerkin(const Scene& s, const SphericalPendulum& L, const SphereMap& R, const RunOptions& o,
                          const StepOptions& opt, const V3& q, const V3& p, const V3& v0, double E0,
                          const std::vector<double>& J0);
int run_manifold_galerkin(const Scene& s, const RigidBody& L, const SO3Map& R, const RunOptions& o,
                          const StepOptions& opt, const M3& q, const V3& p, const V3& v0, double E0,
                          const std::vector<double>& J0);
int run_manifold_galerkin(const Scene& s, const HeavyTop& L, const SO3Map& R, const RunOptions& o,
                          const StepOptions& opt, const M3& q, const V3& p, const V3& v0, double E0,
                          const std::vector<double>& J0);

}  // namespace dvm::cli::manifold_run
