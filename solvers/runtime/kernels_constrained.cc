// Run kernels of Lagrangians written in a scene with holonomic constraints
// ([system] constraints): the constrained theta step of solvers/constrained_step.h,
// composed or not, and Lobatto Galerkin (solvers/constrained_galerkin_step.h), with the
// force where the system has one, and the check of a constrained run's initial state.
// Separate from kernels_written.cc so that the two compile side by side.
#include <Eigen/SVD>

#include "solvers/constrained_galerkin_step.h"
#include "solvers/runtime/kernels_dynamic.h"

namespace dvm::kernels {

void check_constrained_start(const WrittenDynamic& L, const Problem& pr, const Eigen::VectorXd& q,
                                    Eigen::VectorXd& p, Eigen::VectorXd& v0) {
  const WrittenSystem& w = *pr.written;
  const int n = L.dim(), m = static_cast<int>(w.constraints.size());
  WrittenConstraints con(pr.written);
  Eigen::VectorXd g(m), gt(m);
  Eigen::MatrixXd G(m, n);
  con.jacobian(0.0, q, g, G, gt);
  auto text = [&](int i) {
    return "system.constraints[" + std::to_string(i + 1) + "] (\"" + w.constraints[static_cast<std::size_t>(i)].text() + "\")";
  };
  std::ostringstream msg;
  msg.precision(6);
  if (!G.allFinite() || !g.allFinite() || !gt.allFinite()) {
    msg << pr.constraints_where << ": a constraint or its derivative is not finite at the initial state (t = 0)";
    throw InputError(msg.str());
  }
  // rank of Dg: its singular values against the largest
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(G);
  const Eigen::VectorXd s = svd.singularValues();
  int rank = 0;
  for (Eigen::Index i = 0; i < s.size(); ++i)
    if (s[i] > 1e-10 * s[0]) ++rank;
  if (rank < m) {
    msg << pr.constraints_where << ": the constraint Jacobian Dg has rank " << rank << " at the initial state, "
        << "expected " << m << " (one per constraint; singular values [";
    for (Eigen::Index i = 0; i < s.size(); ++i) msg << (i ? ", " : "") << s[i];
    msg << "]): the constraints are redundant there, or contradict each other";
    throw InputError(msg.str());
  }
  const double qn = q.norm();
  for (int i = 0; i < m; ++i) {
    const double gn = G.row(i).norm(), r = std::fabs(g[i]) / (gn * qn > 0.0 ? gn * qn : 1.0);
    if (!(r <= kConstraintStartTolerance)) {
      msg << "initial.q: the initial position is off " << text(i) << ": g = " << g[i] << " at t = 0, relative "
          << r << " (|g| / (|grad g| |q|)), beyond " << kConstraintStartTolerance
          << "; give a position on the constraints";
      throw InputError(msg.str());
    }
  }
  const double vn = v0.norm();
  for (int i = 0; i < m; ++i) {
    const double gn = G.row(i).norm(), b = std::fabs(G.row(i).dot(v0) + gt[i]);
    const double r = b / (gn * vn > 0.0 ? gn * vn : 1.0);
    if (r <= kConstraintStartTolerance) continue;
    if (pr.project_velocity) {
      constrained_detail::Projection<WrittenDynamic, WrittenConstraints> project(n, m);
      const char* failed = project(L, con, 0.0, q, p, v0, MomentumMap::general);
      if (*failed) throw InputError(pr.project_velocity_where + ": " + failed);
      return;
    }
    msg << (pr.momentum_given ? "initial.p" : "initial.v") << ": the initial velocity is off the hidden constraint of "
        << text(i) << ": grad g . v + dg/dt = " << G.row(i).dot(v0) + gt[i] << ", relative " << r << ", beyond "
        << kConstraintStartTolerance << "; give a velocity along the constraints, or set "
        << "initial.project_velocity = true to project it";
    throw InputError(msg.str());
  }
}

std::unique_ptr<Run> make_constrained_run(const WrittenDynamic& L, const Problem& pr, const Method& me,
                                          const DynamicView<WrittenDynamic>& view, const Eigen::VectorXd& q,
                                          const Eigen::VectorXd& p, const Eigen::VectorXd& v0, const RunReport& base_in,
                                          const std::shared_ptr<const ControlSignal>& signal) {
  // (validate refuses these first)
  if (me.form != Form::lagrangian || (me.galerkin && me.quadrature != QuadratureKind::lobatto))
    throw InputError(pr.constraints_where + ": constraints enter the lagrangian form of the theta-family maps and "
                     "Lobatto Galerkin only");
  const int n = L.dim();
  if (n > kMaxDenseDynamicDim)
    throw InputError((me.galerkin ? std::string("integrator.method: method = \"galerkin\"")
                                  : "integrator.map: map = \"" + me.map->name + "\"") +
                     " with system.constraints needs dense " + std::to_string(n) + " x " + std::to_string(n) +
                     " matrices, beyond the " + std::to_string(kMaxDenseDynamicDim) +
                     " coordinates the run-time-sized dense steps take");
  RunReport base = base_in;
  base.step_path = StepPath::generic;
  const StepOptions opt = me.step_options();
  const double h = pr.step;
  const auto con = std::make_shared<const WrittenConstraints>(pr.written);
  const MomentumMap momentum = L.separable()               ? MomentumMap::constant
                               : L.parts().split.quadratic ? MomentumMap::linear
                                                           : MomentumMap::general;
  std::shared_ptr<const WrittenForce> force;
  if (pr.forced()) {
    auto f = std::make_shared<WrittenForce>(pr.written, signal);
    require_finite_force(*f, pr, q, v0);
    base.forced = true;
    force = std::move(f);
  }
  if (me.galerkin) {  // the constraints at the Lobatto nodes (validate refused Gauss)
    auto galerkin = [&](auto fo) {
      using Force = std::remove_const_t<typename decltype(fo)::element_type>;
      return stepper_run(view,
                         ConstrainedGalerkinStep<WrittenDynamic, WrittenConstraints, Force>(L, me.stages, h, con, opt,
                                                                                           momentum, fo),
                         q, p, v0, base, pr.steps);
    };
    return force ? galerkin(force) : galerkin(std::shared_ptr<const NoForce>());
  }
  const ThetaMap R = dynamic_theta_map(me);
  auto run_with = [&](auto fo, auto nc) {
    using Force = std::remove_const_t<typename decltype(fo)::element_type>;
    constexpr int NC = decltype(nc)::value, MC = NC == Eigen::Dynamic ? Eigen::Dynamic : 1;
    auto make = [&](double hk, const ThetaMap& Rk) {
      return ConstrainedThetaStep<WrittenDynamic, WrittenConstraints, Force, NC, MC>(L, Rk, hk, con, opt, momentum, fo);
    };
    return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
  };
  if (force) return run_with(force, std::integral_constant<int, Eigen::Dynamic>());
  // the step of fixed size for the few coordinates of a pendulum, a planar linkage or
  // a point on a surface in R^3 with one constraint: the saddle-point Jacobian and its LU
  // of fixed size (bench_constrained measures the constrained scenes)
  const std::shared_ptr<const NoForce> none;
  if (me.use_structure && con->count() == 1 && n == 2) return run_with(none, std::integral_constant<int, 2>());
  if (me.use_structure && con->count() == 1 && n == 3) return run_with(none, std::integral_constant<int, 3>());
  return run_with(none, std::integral_constant<int, Eigen::Dynamic>());
}

}  // namespace dvm::kernels
