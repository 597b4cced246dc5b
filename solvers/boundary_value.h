// Whole trajectories as one problem (discrete variational calculus; Marsden and West,
// "Discrete mechanics and variational integrators", Acta Numerica 2001, Sec. 1.3):
// with q_0 and q_K fixed, the discrete action S = sum_k L_d(q_k, q_{k+1}) is stationary
// in the interior nodes q_1 .. q_{K-1} exactly when every interior node satisfies the
// discrete Euler-Lagrange equation
//   DEL_k = D2 L_d(q_{k-1}, q_k) + D1 L_d(q_k, q_{k+1}) = 0,     k = 1 .. K-1.
// These K-1 residual blocks form one ceres::Problem: block k depends on three nodes
// only, so the Jacobian is block-tridiagonal and Ceres' sparse normal Cholesky
// (SuiteSparse in Debian's build) solves each iteration in O(K). The problem is built
// once; the nodes are its parameter blocks, q_0 and q_K held constant.
//
// Ceres minimises |DEL|^2, and its stopping rules are relative to the cost's
// decrease, so the result is checked here: converged means every DEL residual is
// below `residual_tolerance` times the size of the terms that make it up,
//   scale = max_k |p_k| + |d2L/dv2| max_k |q_k| / h,
// the second term being the momentum carried by a change of a node of the size of the
// nodes themselves: the nodes are absolute positions, and forming q_{k+1} - q_k from
// them costs eps |q| of absolute accuracy, that is eps |d2L/dv2| |q| / h in each
// momentum (a floor no solver can go under; it dominates for small h).
// The momenta along the solution follow from the discrete Legendre maps,
// p_k = -D1 L_d(q_k, q_{k+1}) (k < K) and p_K = D2 L_d(q_{K-1}, q_K); started from
// (q_0, p_0), the one-step integrator retraces the same nodes.
#pragma once

#include <ceres/ceres.h>

#include <cmath>
#include <exception>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/discrete_lagrangian.h"

namespace dvm {

struct BoundaryValueOptions {
  int max_iterations = 100;
  double residual_tolerance = 1e-14;  // on max |DEL_k| relative to the scale above
  bool verbose = false;
  // Called with the iteration's number after every iteration of Ceres (0: the starting
  // point), the hook of a caller that must act during a long solve (an interrupt, a
  // progress display). An exception it throws stops the solve: Ceres is told to abort
  // (nothing may be thrown through its minimizer), and solve() rethrows it once
  // ceres::Solve has returned.
  std::function<void(int iteration)> poll;
};

// BoundaryValueOptions::poll as a Ceres iteration callback; rethrow() after the solve.
class BoundaryValuePoll final : public ceres::IterationCallback {
 public:
  explicit BoundaryValuePoll(const std::function<void(int)>& poll) : poll_(poll) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    try {
      poll_(summary.iteration);
    } catch (...) {
      error_ = std::current_exception();
      return ceres::SOLVER_ABORT;
    }
    return ceres::SOLVER_CONTINUE;
  }
  // Adds itself to a solve's options when there is a hook to call.
  void attach(ceres::Solver::Options& so) {
    if (poll_) so.callbacks.push_back(this);
  }
  void rethrow() const {
    if (error_) std::rethrow_exception(error_);
  }

 private:
  const std::function<void(int)>& poll_;
  std::exception_ptr error_;
};

// Solves the least-squares problem of the DEL residual blocks (every boundary-value
// problem: this file's two, solvers/manifold_boundary_value.h) with Ceres' sparse
// normal Cholesky, within opt.max_iterations, calling opt.poll after each iteration;
// the tolerances on the cost's decrease and on the step are the caller's. One thread:
// the run-time-sized problem's cost functions share their problem's workspace.
inline ceres::Solver::Summary solve_del_problem(ceres::Problem& problem, const BoundaryValueOptions& opt,
                                                double function_tolerance, double parameter_tolerance) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  so.max_num_iterations = opt.max_iterations;
  so.function_tolerance = function_tolerance;
  so.gradient_tolerance = 1e-30;
  so.parameter_tolerance = parameter_tolerance;
  // The step equations are square and, near a solution, well posed: start with a
  // trust region so large that the first steps are (nearly) Gauss-Newton steps.
  so.initial_trust_region_radius = 1e12;
  so.num_threads = 1;
  so.minimizer_progress_to_stdout = opt.verbose;
  so.logging_type = opt.verbose ? ceres::PER_MINIMIZER_ITERATION : ceres::SILENT;
  BoundaryValuePoll poll(opt.poll);
  poll.attach(so);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  poll.rethrow();
  return summary;
}

template <int N>
struct BoundaryValueResult {
  bool converged = false;
  std::vector<Vec<double, N>> q;  // q_0 .. q_K
  std::vector<Vec<double, N>> p;  // discrete momenta p_0 .. p_K
  double max_residual = NAN;      // max_k |DEL_k|_inf
  double scale = NAN;             // the scale the residual is judged against
  int iterations = 0;
  std::string message;            // Ceres' brief report, or why the check failed
};

// The solve both boundary-value problems share (this one, of fixed size, and
// DynamicBoundaryValueProblem of run-time size, solvers/dynamic_boundary_value.h): the
// nodes q_0 .. q_K of n coordinates each (N: n, or Eigen::Dynamic) as Ceres' parameter
// blocks, the ends held constant, one residual block DEL_k per interior node from
// make_cost() (a new ceres::CostFunction of the three nodes k - 1, k, k + 1, owned by the
// problem); then the momenta and the check of the residual stated at the top, from
// d1(a, b) = D1 L_d(a, b), d2(a, b) = D2 L_d(a, b) and w(q0, v0) = max |d2L/dv2| at
// the first node.
template <int N, class MakeCost, class D1, class D2, class VelocityHessianMax>
BoundaryValueResult<N> solve_boundary_value(const Vec<double, N>& qa, const Vec<double, N>& qb, int K, double h,
                                            const BoundaryValueOptions& opt, const std::vector<Vec<double, N>>* guess,
                                            const MakeCost& make_cost, const D1& d1, const D2& d2,
                                            const VelocityHessianMax& w) {
  using V = Vec<double, N>;
  if (K < 2) throw std::invalid_argument("boundary-value problem: need at least 2 steps (one interior node)");
  const Eigen::Index n = qa.size();
  std::vector<double> x(static_cast<std::size_t>(K + 1) * static_cast<std::size_t>(n));
  auto node = [&](int k) { return x.data() + static_cast<std::size_t>(k) * static_cast<std::size_t>(n); };
  for (int k = 0; k <= K; ++k) {
    // the ends as given (qa + (qb - qa) may differ from qb in the last bit)
    const V qk = k == 0 ? qa
                 : k == K ? qb
                 : (guess && static_cast<int>(guess->size()) == K + 1) ? (*guess)[static_cast<std::size_t>(k)]
                                                                       : V(qa + (static_cast<double>(k) / K) * (qb - qa));
    for (Eigen::Index i = 0; i < n; ++i) node(k)[i] = qk[i];
  }
  ceres::Problem problem;
  for (int k = 1; k < K; ++k) problem.AddResidualBlock(make_cost(), nullptr, node(k - 1), node(k), node(k + 1));
  problem.SetParameterBlockConstant(node(0));
  problem.SetParameterBlockConstant(node(K));

  const ceres::Solver::Summary summary = solve_del_problem(problem, opt, 1e-14, 1e-15);

  BoundaryValueResult<N> res;
  res.iterations = static_cast<int>(summary.iterations.size());
  res.q.resize(static_cast<std::size_t>(K + 1));
  for (int k = 0; k <= K; ++k) res.q[static_cast<std::size_t>(k)] = Eigen::Map<const V>(node(k), n);
  res.p.resize(static_cast<std::size_t>(K + 1));
  res.p[0] = -d1(res.q[0], res.q[1]);
  double rmax = 0.0, pmax = max_abs(res.p[0]);
  V left = d2(res.q[0], res.q[1]);  // D2 L_d(q_{k-1}, q_k)
  for (int k = 1; k < K; ++k) {
    const V& a = res.q[static_cast<std::size_t>(k)];
    const V& b = res.q[static_cast<std::size_t>(k + 1)];
    const V right = d1(a, b);  // D1 L_d(q_k, q_{k+1})
    res.p[static_cast<std::size_t>(k)] = -right;
    pmax = std::fmax(pmax, max_abs(res.p[static_cast<std::size_t>(k)]));
    rmax = std::fmax(rmax, max_abs(V(left + right)));  // DEL_k
    left = d2(a, b);
  }
  res.p[static_cast<std::size_t>(K)] = left;
  pmax = std::fmax(pmax, max_abs(res.p[static_cast<std::size_t>(K)]));
  double qmax = 0.0;
  for (const V& qk : res.q) qmax = std::fmax(qmax, max_abs(qk));
  const V v0 = (res.q[1] - res.q[0]) / h;
  const double W = w(res.q[0], v0);
  res.max_residual = rmax;
  res.scale = pmax + W * qmax / h;
  res.converged = std::isfinite(rmax) && rmax <= opt.residual_tolerance * std::fmax(res.scale, 1e-300);
  res.message = summary.BriefReport();
  if (!res.converged)
    res.message = "discrete Euler-Lagrange residual " + std::to_string(rmax) + " above tolerance (scale " +
                  std::to_string(res.scale) + "); Ceres: " + res.message;
  return res;
}

template <class System, class Map>
class BoundaryValueProblem {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using DL = DiscreteLagrangian<System, Map>;

  BoundaryValueProblem(System L, Map R, double h) : dl_(std::move(L), std::move(R), h) {}
  const DL& discrete_lagrangian() const { return dl_; }

  struct DelResidual {
    const DL* dl;
    template <class T>
    bool operator()(const T* a, const T* b, const T* c, T* r) const {
      Vec<T, N> qa, qb, qc;
      for (int i = 0; i < N; ++i) {
        qa[i] = a[i];
        qb[i] = b[i];
        qc[i] = c[i];
      }
      const Vec<T, N> del = dl->D2Ld(qa, qb) + dl->D1Ld(qb, qc);
      for (int i = 0; i < N; ++i) r[i] = del[i];
      return true;
    }
  };

  // DEL_k at nodes (a, b, c).
  V del(const V& a, const V& b, const V& c) const { return dl_.D2Ld(a, b) + dl_.D1Ld(b, c); }

  // Solves for q_1 .. q_{K-1} between q_0 = qa and q_K = qb. `guess` (K + 1 nodes,
  // ends ignored) defaults to linear interpolation.
  BoundaryValueResult<N> solve(const V& qa, const V& qb, int K, const BoundaryValueOptions& opt = {},
                               const std::vector<V>* guess = nullptr) const {
    return solve_boundary_value<N>(
        qa, qb, K, dl_.step(), opt, guess,
        [&] { return new ceres::AutoDiffCostFunction<DelResidual, N, N, N, N>(new DelResidual{&dl_}); },
        [&](const V& a, const V& b) { return V(dl_.D1Ld(a, b)); }, [&](const V& a, const V& b) { return V(dl_.D2Ld(a, b)); },
        [&](const V& q0, const V& v0) { return max_abs(velocity_hessian(dl_.lagrangian(), q0, v0)); });
  }

 private:
  DL dl_;
};

}  // namespace dvm
