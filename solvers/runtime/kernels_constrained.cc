// Run kernels of Lagrangians written in a scene with holonomic constraints
// ([system] constraints): the constrained theta step of solvers/constrained_step.h,
// composed or not, and Lobatto Galerkin (solvers/constrained_galerkin_step.h), with the
// force where the system has one, and the check of a constrained run's initial state.
// Separate from kernels_written.cc so that the two compile side by side.
#include <Eigen/SVD>

#include "solvers/constrained_galerkin_step.h"
#include "solvers/runtime/kernels_dynamic.h"
#include "solvers/sparse_constrained_step.h"

namespace dvm::kernels {

// From this many coordinates a constrained theta step on a separable Lagrangian, with a
// force or not, is the sparse one (solvers/sparse_constrained_step.h); below, the dense
// one costs less (bench_constrained's table of chains compares them).
constexpr int kSparseConstrainedMinDim = 12;

void check_constrained_start(const WrittenDynamic& L, const Problem& pr, const Eigen::VectorXd& q,
                                    Eigen::VectorXd& p, Eigen::VectorXd& v0) {
  const WrittenSystem& w = *pr.written;
  const int n = L.dim(), m = static_cast<int>(w.constraints.size());
  const auto con = std::make_shared<const WrittenConstraints>(pr.written);
  // each constraint's g, |grad g| and grad g . v + dg/dt (the terms of
  // WrittenConstraints::relative_residuals; no m x n matrix: a long chain has m ~ n / 2)
  Eigen::VectorXd g, norms, across;
  con->row_terms(0.0, q, v0, g, norms, across);
  auto text = [&](int i) {
    return "system.constraints[" + std::to_string(i + 1) + "] (\"" + w.constraints[static_cast<std::size_t>(i)].text() + "\")";
  };
  std::ostringstream msg;
  msg.precision(6);
  if (!g.allFinite() || !norms.allFinite() || !across.allFinite()) {
    msg << pr.constraints_where << ": a constraint or its derivative is not finite at the initial state (t = 0)";
    throw InputError(msg.str());
  }
  // rank of Dg: by its singular values against the largest where the SVD is cheap (m^2 n
  // at most 1e8), else as the sparse step finds it (a heuristic: a repeated constraint
  // is caught, SparseConstrainedThetaStep::rank)
  const bool by_svd = static_cast<double>(m) * m * n <= 1e8;
  if (by_svd) {
    std::vector<double> G(con->entries());
    Eigen::VectorXd gt(m);
    con->sparse_gradients(0.0, q, G.data(), gt.data());
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(m, n);
    std::size_t e = 0;
    for (int i = 0; i < m; ++i)
      for (int j : con->pattern()[static_cast<std::size_t>(i)]) D(i, j) = G[e++];
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(D);
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
  } else {
    const int rank = SparseConstrainedThetaStep::rank(*con, 0.0, q);
    if (rank < m) {
      msg << pr.constraints_where << ": the constraint Jacobian Dg has "
          << (rank < 0 ? std::string("rank below ") + std::to_string(m) : "rank " + std::to_string(rank))
          << " at the initial state, expected " << m << " (one per constraint; by the pivots of the sparse LDL^T "
          << "factorisation of Dg Dg^T, those below 1e-12 of the largest taken as zero): the constraints are "
          << "redundant there, or contradict each other";
      throw InputError(msg.str());
    }
  }
  // each constraint's relative residuals (WrittenConstraints::relative_residuals)
  const double qn = q.norm(), vn = v0.norm();
  for (int i = 0; i < m; ++i) {
    const double gn = norms[i], r = std::fabs(g[i]) / (gn * qn > 0.0 ? gn * qn : 1.0);
    if (!(r <= kConstraintStartTolerance)) {
      msg << "initial.q: the initial position is off " << text(i) << ": g = " << g[i] << " at t = 0, relative "
          << r << " (|g| / (|grad g| |q|)), beyond " << kConstraintStartTolerance
          << "; give a position on the constraints";
      throw InputError(msg.str());
    }
  }
  for (int i = 0; i < m; ++i) {
    const double gn = norms[i], b = std::fabs(across[i]);
    const double r = b / (gn * vn > 0.0 ? gn * vn : 1.0);
    if (r <= kConstraintStartTolerance) continue;
    if (pr.project_velocity) {
      std::string failed;
      std::shared_ptr<SparsePotentialHessian> H;
      if (L.separable() && n >= kSparseConstrainedMinDim) try {
          H = SparseSeparableThetaStep::hessian_of(L, q);
        } catch (const SparsePotentialHessian::TooDense&) {
        }
      if (H) {  // (the sparse step's projection; its theta and step do not enter it)
        failed = SparseConstrainedThetaStep(L, H, con, 0.5, 1.0).project(0.0, q, p, v0);
      } else {
        constrained_detail::Projection<WrittenDynamic, WrittenConstraints> project(n, m);
        failed = project(L, *con, 0.0, q, p, v0, MomentumMap::general);
      }
      if (!failed.empty()) throw InputError(pr.project_velocity_where + ": " + failed);
      return;
    }
    msg << (pr.momentum_given ? "initial.p" : "initial.v") << ": the initial velocity is off the hidden constraint of "
        << text(i) << ": grad g . v + dg/dt = " << across[i] << ", relative " << r
        << ", beyond " << kConstraintStartTolerance << "; give a velocity along the constraints, or set "
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
  RunReport base = base_in;
  const StepOptions opt = me.step_options();
  const double h = pr.step;
  const auto con = std::make_shared<const WrittenConstraints>(pr.written);
  std::shared_ptr<const WrittenForce> force;
  if (pr.forced()) {
    auto f = std::make_shared<WrittenForce>(pr.written, signal);
    require_finite_force(*f, pr, q, v0);
    base.forced = true;
    force = std::move(f);
  }
  // a separable Lagrangian of many coordinates, with a force or not: the sparse step (no
  // derivative: --linearize takes the dense one below)
  // (kernels_sparse_constrained.cc; none where the potential's terms couple most
  // coordinates: the dense step below, within its limit)
  if (!me.galerkin && !me.linearize && me.use_structure && L.separable() && n >= kSparseConstrainedMinDim)
    if (auto run = make_sparse_constrained_run(L, pr, me, view, q, p, v0, base, con, force)) return run;
  if (n > kMaxDenseDynamicDim)
    throw InputError((me.galerkin ? std::string("integrator.method: method = \"galerkin\"")
                                  : "integrator.map: map = \"" + me.map->name + "\"") +
                     " with system.constraints needs dense " + std::to_string(n) + " x " + std::to_string(n) +
                     " matrices, beyond the " + std::to_string(kMaxDenseDynamicDim) +
                     " coordinates the run-time-sized dense steps take (the sparse constrained step takes a "
                     "separable Lagrangian of any size whose potential's Hessian is sparse: a theta map, without "
                     "--linearize)");
  base.step_path = StepPath::generic;
  const MomentumMap momentum = L.separable()               ? MomentumMap::constant
                               : L.parts().split.quadratic ? MomentumMap::linear
                                                           : MomentumMap::general;
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
