// The constrained theta step on sparse matrices (SparseConstrainedThetaStep,
// solvers/sparse_constrained_step.h) as make_constrained_run (kernels_constrained.cc)
// takes it: a separable text of many coordinates, with a force or not, composed or not;
// and the check of a constrained run's initial state, which projects a velocity with
// the sparse step's projection on such a text. A translation unit of its own, compiled
// beside kernels_constrained.cc, which is then shorter to compile; with the sparse step
// in that file, its small fixed-size constrained steps also ran slower (GCC inlines up
// to a budget per translation unit, solvers/CMakeLists.txt; time `dvm run
// examples/scenes/pendulum_cartesian.toml --no-output` built each way).
#include <Eigen/SVD>

#include "solvers/constrained_step.h"
#include "solvers/runtime/kernels_dynamic.h"
#include "solvers/sparse_constrained_step.h"

namespace dvm::kernels {

namespace {
std::string constraint_text(const Problem& pr, int i) {
  return "system.constraints[" + std::to_string(i + 1) + "] (\"" +
         pr.written->constraints[static_cast<std::size_t>(i)].text() + "\")";
}
}  // namespace

void require_constraint_rank(const Problem& pr, const Eigen::MatrixXd& D, const std::string& along) {
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(D);
  const Eigen::VectorXd s = svd.singularValues();
  int rank = 0;
  for (Eigen::Index i = 0; i < s.size(); ++i)
    if (s[i] > 1e-10 * s[0]) ++rank;
  if (rank == D.rows()) return;
  std::ostringstream msg;
  msg.precision(6);
  msg << pr.constraints_where << ": the constraint Jacobian Dg" << along << " has rank " << rank
      << " at the initial state, expected " << D.rows() << " (one per constraint; singular values [";
  for (Eigen::Index i = 0; i < s.size(); ++i) msg << (i ? ", " : "") << s[i];
  msg << "]): the constraints are redundant there, or contradict each other";
  throw InputError(msg.str());
}

int check_constraint_start_terms(const Problem& pr, const Eigen::VectorXd& g, const Eigen::VectorXd& norms,
                                 const Eigen::VectorXd& across, double qn, double vn, const std::string& position_key) {
  std::ostringstream msg;
  msg.precision(6);
  const int m = static_cast<int>(g.size());
  if (!g.allFinite() || !norms.allFinite() || !across.allFinite()) {
    msg << pr.constraints_where << ": a constraint or its derivative is not finite at the initial state (t = 0)";
    throw InputError(msg.str());
  }
  for (int i = 0; i < m; ++i) {
    const double gn = norms[i], r = std::fabs(g[i]) / (gn * qn > 0.0 ? gn * qn : 1.0);
    if (!(r <= kConstraintStartTolerance)) {
      msg << position_key << ": the initial position is off " << constraint_text(pr, i) << ": g = " << g[i]
          << " at t = 0, relative " << r << " (|g| / (|grad g| |q|)), beyond " << kConstraintStartTolerance
          << "; give a position on the constraints";
      throw InputError(msg.str());
    }
  }
  for (int i = 0; i < m; ++i) {
    const double gn = norms[i], r = std::fabs(across[i]) / (gn * vn > 0.0 ? gn * vn : 1.0);
    if (!(r <= kConstraintStartTolerance)) return i;
  }
  return -1;
}

[[noreturn]] void refuse_velocity_off_constraint(const Problem& pr, int i, double across, double vn, double norm,
                                                 const std::string& velocity_key) {
  std::ostringstream msg;
  msg.precision(6);
  msg << velocity_key << ": the initial velocity is off the hidden constraint of " << constraint_text(pr, i)
      << ": grad g . v + dg/dt = " << across << ", relative "
      << std::fabs(across) / (norm * vn > 0.0 ? norm * vn : 1.0) << ", beyond " << kConstraintStartTolerance
      << "; give a velocity along the constraints, or set initial.project_velocity = true to project it";
  throw InputError(msg.str());
}

void check_constrained_start(const WrittenDynamic& L, const Problem& pr, const Eigen::VectorXd& q,
                             Eigen::VectorXd& p, Eigen::VectorXd& v0) {
  const WrittenSystem& w = *pr.written;
  const int n = L.dim(), m = static_cast<int>(w.constraints.size());
  const auto con = std::make_shared<const WrittenConstraints>(pr.written);
  // each constraint's g, |grad g| and grad g . v + dg/dt (the terms of
  // WrittenConstraints::relative_residuals; no m x n matrix: a long chain has m ~ n / 2)
  Eigen::VectorXd g, norms, across;
  con->row_terms(0.0, q, v0, g, norms, across);
  if (!g.allFinite() || !norms.allFinite() || !across.allFinite())
    check_constraint_start_terms(pr, g, norms, across, 1.0, 1.0, "initial.q");  // (refuses)
  // rank of Dg: by its singular values against the largest where the SVD is cheap (m^2 n
  // at most 1e8), else as the sparse step finds it (a heuristic: a repeated constraint
  // is caught, SparseConstrainedThetaStep::rank)
  if (static_cast<double>(m) * m * n <= 1e8) {
    std::vector<double> G(con->entries());
    Eigen::VectorXd gt(m);
    con->sparse_gradients(0.0, q, G.data(), gt.data());
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(m, n);
    std::size_t e = 0;
    for (int i = 0; i < m; ++i)
      for (int j : con->pattern()[static_cast<std::size_t>(i)]) D(i, j) = G[e++];
    require_constraint_rank(pr, D, "");
  } else {
    const int rank = SparseConstrainedThetaStep::rank(*con, 0.0, q);
    if (rank < m) {
      std::ostringstream msg;
      msg << pr.constraints_where << ": the constraint Jacobian Dg has "
          << (rank < 0 ? std::string("rank below ") + std::to_string(m) : "rank " + std::to_string(rank))
          << " at the initial state, expected " << m << " (one per constraint; by the pivots of the sparse LDL^T "
          << "factorisation of Dg Dg^T, those below 1e-12 of the largest taken as zero): the constraints are "
          << "redundant there, or contradict each other";
      throw InputError(msg.str());
    }
  }
  // each constraint's relative residuals (WrittenConstraints::relative_residuals)
  const double vn = v0.norm();
  const int i = check_constraint_start_terms(pr, g, norms, across, q.norm(), vn, "initial.q");
  if (i < 0) return;
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
  refuse_velocity_off_constraint(pr, i, across[i], vn, norms[i], pr.momentum_given ? "initial.p" : "initial.v");
}

std::unique_ptr<Run> make_sparse_constrained_run(const WrittenDynamic& L, const Problem& pr, const Method& me,
                                                 const DynamicView<WrittenDynamic>& view, const Eigen::VectorXd& q,
                                                 const Eigen::VectorXd& p, const Eigen::VectorXd& v0, RunReport base,
                                                 const std::shared_ptr<const WrittenConstraints>& con,
                                                 const std::shared_ptr<const WrittenForce>& force) {
  std::shared_ptr<SparsePotentialHessian> H;
  try {
    H = SparseSeparableThetaStep::hessian_of(L, q);
  } catch (const SparsePotentialHessian::TooDense&) {
    return nullptr;  // terms coupling most coordinates: the caller's dense step, within its limit
  }
  con->check_pattern(0.0, q);
  const StepOptions opt = me.step_options();
  auto make = [&](double hk, const ThetaMap& Rk) {
    return SparseConstrainedThetaStep(L, H, con, Rk.theta(), hk, opt, force);
  };
  base.step_path = StepPath::constrained_sparse_newton;
  base.hessian_colours = H->colours();
  return composable_run<true>(view, me, pr.step, rn_stages(me, dynamic_theta_map(me)), make, q, p, v0, base, pr.steps);
}

}  // namespace dvm::kernels
