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

#include <exception>
#include <functional>
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
    if (K < 2) throw std::invalid_argument("boundary-value problem: need at least 2 steps (one interior node)");
    std::vector<double> x(static_cast<std::size_t>(K + 1) * N);
    auto node = [&](int k) { return x.data() + static_cast<std::size_t>(k) * N; };
    for (int k = 0; k <= K; ++k) {
      const V qk = (guess && static_cast<int>(guess->size()) == K + 1 && k > 0 && k < K)
                       ? (*guess)[static_cast<std::size_t>(k)]
                       : V(qa + (static_cast<double>(k) / K) * (qb - qa));
      for (int i = 0; i < N; ++i) node(k)[i] = qk[i];
    }
    ceres::Problem problem;
    for (int k = 1; k < K; ++k) {
      auto* cost = new ceres::AutoDiffCostFunction<DelResidual, N, N, N, N>(new DelResidual{&dl_});
      problem.AddResidualBlock(cost, nullptr, node(k - 1), node(k), node(k + 1));
    }
    problem.SetParameterBlockConstant(node(0));
    problem.SetParameterBlockConstant(node(K));

    ceres::Solver::Options so;
    so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    so.max_num_iterations = opt.max_iterations;
    so.function_tolerance = 1e-14;
    so.gradient_tolerance = 1e-30;
    so.parameter_tolerance = 1e-15;
    // The step equations are square and, near a solution, well posed: start with a
    // trust region so large that the first steps are (nearly) Gauss-Newton steps.
    so.initial_trust_region_radius = 1e12;
    so.minimizer_progress_to_stdout = opt.verbose;
    so.logging_type = opt.verbose ? ceres::PER_MINIMIZER_ITERATION : ceres::SILENT;
    BoundaryValuePoll poll(opt.poll);
    poll.attach(so);
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    poll.rethrow();

    BoundaryValueResult<N> res;
    res.iterations = static_cast<int>(summary.iterations.size());
    res.q.resize(static_cast<std::size_t>(K + 1));
    for (int k = 0; k <= K; ++k)
      for (int i = 0; i < N; ++i) res.q[static_cast<std::size_t>(k)][i] = node(k)[i];
    res.p.resize(static_cast<std::size_t>(K + 1));
    double rmax = 0.0, pmax = 0.0;
    for (int k = 0; k < K; ++k) {
      const V& a = res.q[static_cast<std::size_t>(k)];
      const V& b = res.q[static_cast<std::size_t>(k + 1)];
      res.p[static_cast<std::size_t>(k)] = -dl_.D1Ld(a, b);
      pmax = std::fmax(pmax, max_abs(res.p[static_cast<std::size_t>(k)]));
      if (k >= 1) rmax = std::fmax(rmax, max_abs(del(res.q[static_cast<std::size_t>(k - 1)], a, b)));
    }
    res.p[static_cast<std::size_t>(K)] =
        dl_.D2Ld(res.q[static_cast<std::size_t>(K - 1)], res.q[static_cast<std::size_t>(K)]);
    pmax = std::fmax(pmax, max_abs(res.p[static_cast<std::size_t>(K)]));
    double qmax = 0.0;
    for (const V& qk : res.q) qmax = std::fmax(qmax, max_abs(qk));
    const V v0 = (res.q[1] - res.q[0]) / dl_.step();
    const double W = max_abs(velocity_hessian(dl_.lagrangian(), res.q[0], v0));
    res.max_residual = rmax;
    res.scale = pmax + W * qmax / dl_.step();
    res.converged = std::isfinite(rmax) && rmax <= opt.residual_tolerance * std::fmax(res.scale, 1e-300);
    res.message = summary.BriefReport();
    if (!res.converged)
      res.message = "discrete Euler-Lagrange residual " + std::to_string(rmax) + " above tolerance (scale " +
                    std::to_string(res.scale) + "); Ceres: " + res.message;
    return res;
  }

 private:
  DL dl_;
};

}  // namespace dvm
