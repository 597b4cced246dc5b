// The constrained position-momentum step of a theta map (solvers/constrained_step.h)
// on a separable Lagrangian written in a scene, of any size, with sparse matrices
// throughout: a chain of rigid links in Cartesian coordinates, a mesh of bars.
//
// For L(q, v) = v^T M v / 2 + U(q), M constant (mechanics/written_dynamic.h, WrittenParts),
// holonomic constraints g(t, q) = 0 (mechanics/written_constraints.h), the theta map
// R_d(x, v) = (x - theta v, x + (1 - theta) v) (paper Ex. 2.6), D = q1 - q0,
// q_theta = q0 + theta D, F = grad U and G = Dg, the equations of ConstrainedThetaStep
// (Marsden and West, Acta Numerica 2001, Sec. 3.5) read
//   1. M D / h - h (1 - theta) F(q_theta) - p0 + G0^T lambda = 0,   g(t1, q0 + D) = 0,
//   2. p1~ = p0 + h F(q_theta) - G0^T lambda,
//      M v1 + G1^T mu = p1~,   G1 v1 + g_t(t1, q1) = 0,   p1 = p1~ - G1^T mu,
// With a generalized force F_f(t, q, v) (mechanics/written_force.h) F is grad U + F_f at
// the node (t0 + theta h, q_theta, D / h), as in the dense step (the discrete
// Lagrange-d'Alembert principle, solvers/dynamic_step.h). The first equation is solved
// for (D, lambda) by newton_drive (solvers/newton_driver.h) with the saddle-point Jacobian
//   [ M / h - h theta (1 - theta) (Hess U + d F_f/dq) - (1 - theta) d F_f/dv    s G0^T ]
//   [ s G1(q0 + D)                                                             0      ]
// (the multiplier carried as lambda / s, s = max|J_DD| / max|G0| fixed at the object's
// first Jacobian and kept for its later steps, as the dense step scales it), the
// second by one linear solve with
//   [ M    G1^T ]
//   [ G1   0    ].
// Both matrices are sparse: Hess U's pattern and colouring come from
// SparsePotentialHessian (mechanics/sparse_hessian.h), Dg's pattern from the
// constraints' tapes (WrittenConstraints::pattern), the force's from its components'
// tapes (WrittenForce::pattern: a damping force on each coordinate adds the diagonal).
// Each is factored with partial pivoting (the zero block rules out a Cholesky
// factorisation), its ordering analysed once at construction (SparseOrBanded below): in
// a band where a Cuthill-McKee ordering makes one narrow (a chain of links), else by
// Eigen's SparseLU. A chain of k
// links costs O(k) a step where the dense ConstrainedThetaStep costs O(k^3)
// (bench_constrained measures both). The equations are the dense step's, so the two
// agree to round-off (tests/solvers/test_sparse_constrained.cc).
//
// derivative() gives the step's derivative by the implicit function theorem, as the
// dense step's does, with these matrices. The Jacobian is formed at each step's first
// iterate and serves its later ones while each shrinks the residual fourfold
// (Refresh::within_step). Workspace is allocated at construction; a step allocates
// nothing in the banded case, and in SparseLU's factorisations and solves otherwise.
// Copies of a step (the stages of a composition) share the potential's
// SparsePotentialHessian, whose evaluation writes its workspace: neither one step nor
// its copies may run on two threads at once.
#pragma once

#include <Eigen/Core>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/banded_solve.h"
#include "mechanics/sparse_hessian.h"
#include "mechanics/written_constraints.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/written_force.h"
#include "solvers/dynamic_step.h"
#include "solvers/newton_driver.h"
#include "solvers/separable_newton.h"

namespace dvm {

namespace constrained_detail {

// A square sparse matrix of fixed pattern (structurally symmetric), factored in a band
// where a Cuthill-McKee ordering of its graph makes the band narrow (a chain of links:
// each rod's multiplier couples the two joints it joins), else by Eigen's SparseLU
// (COLAMD ordering). The band is factored by BandedLU (core/banded_solve.h: partial
// pivoting, O(N b^2), a pivot below 1e-14 of the largest entry refused), with no
// indices to follow. analyse() once, then factor() and solve() allocate nothing in
// the banded case.
class SparseOrBanded {
 public:
  // The widest band factored as a band (the saddle-point matrix of a planar chain of
  // rods ordered by Cuthill-McKee has b = 3 to 5).
  static constexpr int kMaxBand = 8;

  void analyse(const Eigen::SparseMatrix<double>& A) {
    const int N = static_cast<int>(A.rows());
    // the graph's neighbours, from the column-major pattern (symmetric)
    std::vector<std::vector<int>> adj(static_cast<std::size_t>(N));
    for (int j = 0; j < N; ++j)
      for (Eigen::SparseMatrix<double>::InnerIterator it(A, j); it; ++it)
        if (it.row() != j) adj[static_cast<std::size_t>(j)].push_back(static_cast<int>(it.row()));
    auto degree = [&](int v) { return adj[static_cast<std::size_t>(v)].size(); };
    // Cuthill-McKee: breadth first from a node of least degree in each component,
    // neighbours in order of degree
    order_.assign(static_cast<std::size_t>(N), -1);
    std::vector<int> queue;
    queue.reserve(static_cast<std::size_t>(N));
    std::vector<int> by_degree(static_cast<std::size_t>(N));
    for (int v = 0; v < N; ++v) by_degree[static_cast<std::size_t>(v)] = v;
    std::stable_sort(by_degree.begin(), by_degree.end(), [&](int a, int b) { return degree(a) < degree(b); });
    int next = 0;
    for (int start : by_degree) {
      if (order_[static_cast<std::size_t>(start)] >= 0) continue;
      std::size_t head = queue.size();
      queue.push_back(start);
      order_[static_cast<std::size_t>(start)] = next++;
      while (head < queue.size()) {
        const int v = queue[head++];
        std::vector<int> nb;
        for (int u : adj[static_cast<std::size_t>(v)])
          if (order_[static_cast<std::size_t>(u)] < 0) nb.push_back(u);
        std::stable_sort(nb.begin(), nb.end(), [&](int a, int b) { return degree(a) < degree(b); });
        for (int u : nb) {
          order_[static_cast<std::size_t>(u)] = next++;
          queue.push_back(u);
        }
      }
    }
    int band = 0;
    for (int j = 0; j < N; ++j)
      for (int u : adj[static_cast<std::size_t>(j)])
        band = std::max(band, std::abs(order_[static_cast<std::size_t>(u)] - order_[static_cast<std::size_t>(j)]));
    band_.reset();
    if (band <= kMaxBand) {
      band_ = std::make_unique<BandedLU>(N, band, band);
      at_.clear();
      at_.reserve(static_cast<std::size_t>(A.nonZeros()));
      for (int j = 0; j < N; ++j)
        for (Eigen::SparseMatrix<double>::InnerIterator it(A, j); it; ++it)
          at_.push_back(band_->offset(order_[static_cast<std::size_t>(it.row())], order_[static_cast<std::size_t>(j)]));
      y_.resize(N);
    } else {
      lu_.analyzePattern(A);
    }
  }
  bool banded() const { return band_ != nullptr; }
  // A's values (in the pattern analysed) factored; false where A is singular
  bool factor(const Eigen::SparseMatrix<double>& A) {
    if (!band_) {
      // SparseLU fails only on an exactly zero pivot: a matrix singular to working
      // precision is caught by solving A x = A 1 and asking for x = 1 to 1e-8
      lu_.factorize(A);
      if (lu_.info() != Eigen::Success) return false;
      ones_.setOnes(A.cols());
      y_ = A * ones_;
      y_ = lu_.solve(y_).eval();
      return std::isfinite(y_.sum()) && (y_ - ones_).template lpNorm<Eigen::Infinity>() <= 1e-8;
    }
    band_->set_zero();
    double* b = band_->storage();
    const double* v = A.valuePtr();
    for (std::size_t k = 0; k < at_.size(); ++k) b[at_[k]] = v[k];
    return band_->factor();
  }
  // x = A^{-1} r
  void solve(const Eigen::VectorXd& r, Eigen::VectorXd& x) {
    if (!band_) {
      x = lu_.solve(r);
      return;
    }
    const Eigen::Index N = r.size();
    for (Eigen::Index i = 0; i < N; ++i) y_[order_[static_cast<std::size_t>(i)]] = r[i];
    band_->solve(y_.data());
    x.resize(N);
    for (Eigen::Index i = 0; i < N; ++i) x[i] = y_[order_[static_cast<std::size_t>(i)]];
  }

 private:
  std::vector<int> order_;        // the new index of each row and column
  std::unique_ptr<BandedLU> band_;
  std::vector<std::size_t> at_;   // where each stored value of A goes in the band
  Eigen::VectorXd y_, ones_;
  Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>> lu_;
};

}  // namespace constrained_detail

class SparseConstrainedThetaStep {
 public:
  static constexpr int N = Eigen::Dynamic;
  using V = Eigen::VectorXd;
  using Sparse = Eigen::SparseMatrix<double>;

  // hessian: the pattern of Hess U (SparseSeparableThetaStep::hessian_of), shared by the
  // steps of a composition. force: a generalized force F(t, q, v) (mechanics/written_force.h),
  // or none; each step keeps a copy of it (its workspace).
  SparseConstrainedThetaStep(const WrittenDynamic& L, std::shared_ptr<SparsePotentialHessian> hessian,
                             std::shared_ptr<const WrittenConstraints> constraints, double theta, double h,
                             StepOptions options = {}, std::shared_ptr<const WrittenForce> force = nullptr)
      : L_(L), hessian_(std::move(hessian)), con_(std::move(constraints)), theta_(theta), h_(h), options_(options),
        force_(std::move(force)) {
    if (!L_.separable()) throw std::invalid_argument("SparseConstrainedThetaStep: the Lagrangian is not separable");
    if (!(theta >= 0.0 && theta <= 1.0)) throw std::invalid_argument("theta must lie in [0, 1]");
    dynamic_detail::require_step(h);
    dynamic_detail::require_newton(options);
    const int n = L_.dim();
    if (!hessian_ || hessian_->dim() != n) throw std::invalid_argument("the sparse Hessian is not the system's");
    if (!con_ || con_->dim() != n)
      throw std::invalid_argument("SparseConstrainedThetaStep: constraints on the system's coordinates are needed");
    if (con_->count() >= n)
      throw std::invalid_argument("SparseConstrainedThetaStep: " + std::to_string(con_->count()) +
                                  " constraints on " + std::to_string(n) + " coordinates leave no motion");
    if (force_ && force_->dim() != n)
      throw std::invalid_argument("SparseConstrainedThetaStep: the force is not on the system's coordinates");
    work_ = std::make_shared<Work>(*this);
  }
  SparseConstrainedThetaStep(const SparseConstrainedThetaStep& o)
      : L_(o.L_), hessian_(o.hessian_), con_(o.con_), theta_(o.theta_), h_(o.h_), options_(o.options_),
        force_(o.force_) {
    work_ = std::make_shared<Work>(*this);
  }
  SparseConstrainedThetaStep& operator=(const SparseConstrainedThetaStep&) = delete;

  double step_size() const { return h_; }
  double theta() const { return theta_; }
  int dim() const { return L_.dim(); }
  int constraints() const { return con_->count(); }
  bool forced() const { return force_ != nullptr; }
  const WrittenDynamic& lagrangian() const { return L_; }
  // Whether Newton's saddle-point Jacobian is factored in a band (else by SparseLU).
  bool banded() const { return work_->lu.banded(); }

  // Puts p on the hidden constraint at (t, q) (equation 2 with p~ = p): p - G^T mu with
  // G v + g_t = 0, v = M^{-1} (p - G^T mu), which v receives. Returns an empty string,
  // or what failed.
  std::string project(double t, const V& q, V& p, V& v) const {
    Work& w = *work_;
    const char* failed = w.project(t, q, p, v);
    if (*failed) return failed;
    w.subtract_normals(w.G1, 1.0, w.mu.data(), p.data());
    return "";
  }

  // One step from (q0, p0) at time t (the contract of ConstrainedThetaStep::step).
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary s;
    const int n = dim();
    if (!dynamic_detail::sizes_match(n, q0, p0, dq, s)) return s;
    if (dp.size() != n) dp.resize(n);
    Work& w = *work_;
    try {
      w.begin(q0, p0, t);
      w.y.head(n) = dq;  // the multipliers' guess: the last step's, kept in w.y
      Equation eq{w};
      Factor la{w};
      s = newton_drive(eq, la, Refresh::within_step, options_, w.y, w.r, w.dx, w.unused, w.state, w.start);
      dq = w.y.head(n);
      if (s.converged) {
        // p1~ - p0 = h F(q_theta) - G0^T lambda, at the solution (the driver's last
        // correction moved it from the last residual's point), F with the force's
        // component and its work <F_f, D> there
        w.forces(dq);
        if (w.force) s.work = w.Ff.dot(dq);
        dp = h_ * w.F;
        w.subtract_normals(w.G0, w.s, w.y.data() + n, dp.data());
        w.q1 = q0 + dq;
        w.p1 = p0 + dp;
        const char* failed = w.project(w.t1, w.q1, w.p1, w.v1);
        if (*failed) {
          s.fail(failed);
        } else {
          w.subtract_normals(w.G1, 1.0, w.mu.data(), dp.data());  // p1 - p0 = (p1~ - p0) - G1^T mu
          if (!std::isfinite(dynamic_detail::inf_norm(dp))) s.fail("non-finite momentum");
        }
      }
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    if (!s.converged && s.iterations == 0) s.iterations = 1;
    return s;
  }

  // The force's control inputs (WrittenForce::controls()), 0 without a force.
  int controls() const { return force_ ? force_->controls() : 0; }

  // The derivative A = d(q1, p1)/d(q0, p0) (2n x 2n, coordinates before momenta) of the
  // step from (q0, p0) at t0 whose solved increment is dq, as
  // ConstrainedThetaStep::derivative gives it: the implicit function theorem on the two
  // equations of the header comment, with the step's sparse matrices. With
  // G = grad U + F_f at the node, G_q = Hess U + dF_f/dq, G_v = dF_f/dv and
  // H_lambda = sum lambda_i Hess g_i(t0, q0),
  //   [J_D    G0^T] [dD     ]     [ H_lambda - h (1 - theta) G_q ]        [ I ]
  //   [G1     0   ] [dlambda] = - [ G1                           ] dq0 +  [ 0 ] dp0,
  // J_D = M / h - h theta (1 - theta) G_q - (1 - theta) G_v (equation 1's Jacobian at the
  // solution, the multiplier column scaled as the step scales it); lambda itself is the
  // solution of the same system for the residual's terms without it (G0^T lambda is
  // that, exactly, at the solution). Then dp1~ = dp0 + h G_q (dq0 + theta dD) + G_v dD
  // - H_lambda dq0 - G0^T dlambda, and equation 2 with [M G1^T; G1 0] as
  // constrained_detail::right_transform_derivative differentiates it (L_vq = 0, L_vv = M).
  // The constraints' Hessians are those of each on the coordinates it reads
  // (WrittenConstraints::sparse_second_derivatives). The right-hand sides are 2n columns
  // (and one per control input): O(n) solves in the step's factorisations, which cost
  // O(n) each in a band, and A of 4 n^2 numbers. Allocates; false where a matrix is
  // singular or a value not finite. Not from two threads at once.
  bool derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A) const {
    return differentiate(t0, q0, p0, dq, A, nullptr);
  }
  // The derivative B = d(q1, p1)/du (2n x controls()) in the force's control inputs u,
  // held over the step: F_u enters as the force does, h (1 - theta) F_u in equation 1's
  // right-hand side and h F_u in dp1~.
  bool control_derivative(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& B) const {
    Eigen::MatrixXd A;
    return differentiate(t0, q0, p0, dq, A, &B);
  }
  // A and, where B is not null, B from one differentiation: what derivative() and
  // control_derivative() give (B 2n x 0 without control inputs).
  bool derivatives(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    return differentiate(t0, q0, p0, dq, A, B);
  }

  // The rank of Dg at (t, q) as the runtime checks it where a dense SVD of Dg would cost
  // O(m^2 n): the pivots of the sparse LDL^T factorisation (fill-reducing ordering) of
  // D D^T, D = Dg with each row scaled to unit length, above 1e-12 of the largest. A
  // heuristic, not a rank-revealing factorisation: it catches constraints that repeat
  // or combine others to round-off (a pivot at round-off), but a near dependence may
  // leave no small pivot. -1 where a pivot is exactly zero (the factorisation stops
  // there: a rank below count()).
  static int rank(const WrittenConstraints& con, double t, const V& q) {
    const int n = con.dim(), m = con.count();
    std::vector<double> G(con.entries());
    V gt(m);
    con.sparse_gradients(t, q, G.data(), gt.data());
    std::vector<Eigen::Triplet<double>> e;
    e.reserve(G.size());
    std::size_t k = 0;
    for (int i = 0; i < m; ++i) {
      const auto& row = con.pattern()[static_cast<std::size_t>(i)];
      double norm = 0.0;
      for (std::size_t a = 0; a < row.size(); ++a) norm += G[k + a] * G[k + a];
      norm = norm > 0.0 ? 1.0 / std::sqrt(norm) : 1.0;
      for (int j : row) e.emplace_back(i, j, norm * G[k++]);
    }
    Sparse D(m, n);
    D.setFromTriplets(e.begin(), e.end());
    const Sparse S = D * D.transpose();
    const Eigen::SimplicialLDLT<Sparse> ldlt(S);
    if (ldlt.info() != Eigen::Success) return -1;
    const V d = ldlt.vectorD();
    const double top = d.cwiseAbs().maxCoeff();
    int rank = 0;
    for (Eigen::Index i = 0; i < d.size(); ++i)
      if (d[i] > 1e-12 * top) ++rank;
    return rank;
  }


 private:
  struct Work;

  bool differentiate(double t0, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    const int n = dim(), m = constraints();
    if (q0.size() != n || p0.size() != n || dq.size() != n)
      throw std::invalid_argument("SparseConstrainedThetaStep::derivative: a state of " + std::to_string(q0.size()) +
                                  " coordinates; the system has " + std::to_string(n));
    const double th = theta_, h = h_;
    Work& w = *work_;
    const WrittenConstraints& con = w.con;
    const auto& pattern = con.pattern();
    // equation 1's Jacobian at the solution (G1 at q1 = q0 + dq with it), factored
    w.begin(q0, p0, t0);
    V y = V::Zero(n + m);
    y.head(n) = dq;
    w.at(y);
    if (!std::isfinite(w.jacobian()) || !w.factor()) return false;
    const Eigen::MatrixXd Fu = [&] {
      Eigen::MatrixXd f(n, 0);
      if (B && w.force) w.force->sparse_jacobian(w.tn, w.x, w.u, w.Fq.data(), w.Fv.data(), nullptr, &f);
      return f;
    }();
    const int c = static_cast<int>(Fu.cols()), in = 2 * n + c;
    // lambda: J (0, lambda / s) = (rho, 0), rho = p0 + h (1 - theta) G - M D / h
    V rhs = V::Zero(n + m), z(n + m);
    rhs.head(n) = p0 + (h * (1.0 - th)) * w.F - w.MD / h;
    w.lu.solve(rhs, z);
    const V lambda = w.s * z.tail(m);
    // G_q and G_v at the node
    std::vector<Eigen::Triplet<double>> tq, tv;
    const auto& cols = w.hessian->columns();
    std::size_t e = 0;
    for (int j = 0; j < n; ++j)
      for (int i : cols[static_cast<std::size_t>(j)]) tq.emplace_back(i, j, w.hess[e++]);
    if (w.force) {
      std::size_t eq = 0, ev = 0;
      for (const WrittenForce::Row& row : w.force->pattern()) {
        for (int j : row.q) tq.emplace_back(row.i, j, w.Fq[eq++]);
        for (int j : row.v) tv.emplace_back(row.i, j, w.Fv[ev++]);
      }
    }
    Sparse Gq(n, n), Gv(n, n);
    Gq.setFromTriplets(tq.begin(), tq.end());
    Gv.setFromTriplets(tv.begin(), tv.end());
    // Dg's rows as sparse matrices, and the constraints' Hessians on their patterns
    auto rows_of = [&](const std::vector<double>& G) {
      std::vector<Eigen::Triplet<double>> t;
      t.reserve(G.size());
      std::size_t k = 0;
      for (int i = 0; i < m; ++i)
        for (int j : pattern[static_cast<std::size_t>(i)]) t.emplace_back(i, j, G[k++]);
      Sparse S(m, n);
      S.setFromTriplets(t.begin(), t.end());
      return S;
    };
    const Sparse G0 = rows_of(w.G0), G1 = rows_of(w.G1);
    std::vector<double> H(con.hessian_entries()), Gqt(con.entries());
    // f(a, b, weight_i H_i(a, b)) for each nonzero entry of sum_i weight_i Hess g_i (the
    // Hessians in H, on each constraint's pattern)
    auto for_weighted = [&](const V& weight, auto&& f) {
      std::size_t eh = 0;
      for (int i = 0; i < m; ++i) {
        const auto& row = pattern[static_cast<std::size_t>(i)];
        const int k = static_cast<int>(row.size());
        for (int a = 0; a < k; ++a)
          for (int b = 0; b < k; ++b) {
            const double hab = weight[i] * H[eh + static_cast<std::size_t>(a * k + b)];
            if (hab != 0.0) f(row[static_cast<std::size_t>(a)], row[static_cast<std::size_t>(b)], hab);
          }
        eh += static_cast<std::size_t>(k) * static_cast<std::size_t>(k);
      }
    };
    auto solve_columns = [](constrained_detail::SparseOrBanded& lu, const Eigen::MatrixXd& R, Eigen::MatrixXd& X) {
      X.resize(R.rows(), R.cols());
      V r(R.rows()), x(R.rows());
      for (Eigen::Index j = 0; j < R.cols(); ++j) {
        r = R.col(j);
        lu.solve(r, x);
        X.col(j) = x;
      }
    };
    // equation 1: the inputs (dq0, dp0, du) as columns, the multiplier rows times s
    con.sparse_second_derivatives(t0, q0, H.data(), Gqt.data());
    Eigen::MatrixXd R1 = Eigen::MatrixXd::Zero(n + m, in), Z1;
    const Eigen::MatrixXd Gqd = Gq;                    // G_q, dense
    Eigen::MatrixXd Hl = Eigen::MatrixXd::Zero(n, n);  // H_lambda
    for_weighted(lambda, [&](int a, int b, double x) { Hl(a, b) += x; });
    R1.topLeftCorner(n, n) = (h * (1.0 - th)) * Gqd - Hl;
    R1.block(0, n, n, n).setIdentity();
    if (c > 0) R1.topRightCorner(n, c) = (h * (1.0 - th)) * Fu;
    R1.bottomLeftCorner(m, n) = -w.s * Eigen::MatrixXd(G1);
    solve_columns(w.lu, R1, Z1);
    const Eigen::MatrixXd dD = Z1.topRows(n);
    const Eigen::MatrixXd dlambda = w.s * Z1.bottomRows(m);
    Eigen::MatrixXd dq1 = dD;
    dq1.leftCols(n).diagonal().array() += 1.0;
    Eigen::MatrixXd dpt = (h * th) * (Gq * dD) + Gv * dD - G0.transpose() * dlambda;
    dpt.leftCols(n) += h * Gqd - Hl;
    dpt.block(0, n, n, n).diagonal().array() += 1.0;
    if (c > 0) dpt.rightCols(c) += h * Fu;
    // equation 2 at (t1, q1, p1~): v1, mu and [M G1^T; G1 0] factored by the projection
    w.q1 = q0 + dq;
    w.p1 = p0 + h * w.F;
    w.subtract_normals(w.G0, 1.0, lambda.data(), w.p1.data());
    if (*w.project(w.t1, w.q1, w.p1, w.v1)) return false;
    con.sparse_second_derivatives(w.t1, w.q1, H.data(), Gqt.data());
    Eigen::MatrixXd R2 = Eigen::MatrixXd::Zero(n + m, in), Y2;
    R2.topRows(n) = dpt;
    Eigen::MatrixXd Hmu = Eigen::MatrixXd::Zero(n, in);  // H_mu dq1
    for_weighted(w.mu, [&](int a, int b, double x) { Hmu.row(a) += x * dq1.row(b); });
    R2.topRows(n) -= Hmu;
    // rows v1^T Hess g_i + grad (g_t)_i, times dq1
    std::size_t eh = 0, eg = 0;
    for (int i = 0; i < m; ++i) {
      const auto& row = pattern[static_cast<std::size_t>(i)];
      const int k = static_cast<int>(row.size());
      for (int b = 0; b < k; ++b) {
        double hv = Gqt[eg + static_cast<std::size_t>(b)];
        for (int a = 0; a < k; ++a)
          hv += w.v1[row[static_cast<std::size_t>(a)]] * H[eh + static_cast<std::size_t>(a * k + b)];
        if (hv != 0.0) R2.row(n + i) -= hv * dq1.row(row[static_cast<std::size_t>(b)]);
      }
      eh += static_cast<std::size_t>(k) * static_cast<std::size_t>(k);
      eg += static_cast<std::size_t>(k);
    }
    solve_columns(w.plu, R2, Y2);
    const Eigen::MatrixXd dp1 = dpt - Hmu - G1.transpose() * Y2.bottomRows(m);
    return dynamic_detail::assemble_derivative(n, dq1, dp1, A, B);
  }

  // Equation 1 for the driver: the step forms its sparse Jacobian itself (the driver's
  // matrix is unused).
  struct Equation {
    using Vector = V;
    using Matrix = Eigen::MatrixXd;
    Work& w;
    void residual(const V& y, V& r) const {
      w.at(y);
      w.form(y, r);
    }
    double jacobian(const V& y, V& r, Matrix&) const {
      w.at(y);
      const double big = w.jacobian();
      w.form(y, r);
      return big;
    }
    double scale(double yn, double Jmax) const { return w.pscale + Jmax * yn; }
    double offset() const { return w.x0; }
  };
  struct Factor {
    Work& w;
    bool factor(const Eigen::MatrixXd&, double) const { return w.factor(); }
    void solve(const V& r, V& dx) const { w.lu.solve(r, dx); }
    const char* name() const { return w.lu.banded() ? "banded LU factorisation" : "sparse LU factorisation"; }
  };

  struct Work {
    explicit Work(const SparseConstrainedThetaStep& step)
        : L(step.L_), separable(L), mass(constant_mass(L)), hessian(step.hessian_), con(*step.con_),
          force(step.force_ ? std::make_unique<WrittenForce>(*step.force_) : nullptr), theta(step.theta_),
          h(step.h_) {
      n = L.dim();
      m = con.count();
      const int k = n + m;
      const WrittenParts& parts = L.parts();
      D.resize(n);
      x.resize(n);
      u.resize(n);
      F.resize(n);
      Ff.resize(n);
      MD.resize(n);
      q1.resize(n);
      p1.resize(n);
      v1.resize(n);
      g1.resize(m);
      gt.resize(m);
      mu.resize(m);
      y = V::Zero(k);
      r.resize(k);
      dx.resize(k);
      start.resize(k);
      b.resize(k);
      G0.resize(con.entries());
      G1.resize(con.entries());
      hess.resize(hessian->entries());
      // the patterns: M's entries, Hess U's, and Dg's in both off-diagonal blocks
      std::vector<Eigen::Triplet<double>> t, tp;
      auto mass_at = [&](int i, int j) { return parts.split.diagonal ? (i == j ? parts.mass_diagonal[j] : 0.0) : parts.mass(i, j); };
      const auto& cols = hessian->columns();
      for (int j = 0; j < n; ++j)
        for (int i : cols[static_cast<std::size_t>(j)]) t.emplace_back(i, j, 0.0);
      // M's entries (its diagonal alone where it is diagonal)
      std::vector<std::pair<int, int>> masses;
      for (int j = 0; j < n; ++j)
        for (int i = parts.split.diagonal ? j : 0; i < (parts.split.diagonal ? j + 1 : n); ++i)
          if (mass_at(i, j) != 0.0) masses.emplace_back(i, j);
      for (const auto& e : masses) {
        t.emplace_back(e.first, e.second, 0.0);
        tp.emplace_back(e.first, e.second, 0.0);
      }
      const auto& pattern = con.pattern();
      for (int c = 0; c < m; ++c)
        for (int j : pattern[static_cast<std::size_t>(c)]) {
          t.emplace_back(j, n + c, 0.0);
          t.emplace_back(n + c, j, 0.0);
          tp.emplace_back(j, n + c, 0.0);
          tp.emplace_back(n + c, j, 0.0);
        }
      // the force's F_q and F_v (a row per component), the pattern kept symmetric
      if (force) {
        for (const WrittenForce::Row& row : force->pattern())
          for (const auto* cols_of : {&row.q, &row.v})
            for (int j : *cols_of) {
              t.emplace_back(row.i, j, 0.0);
              t.emplace_back(j, row.i, 0.0);
            }
        Fq.resize(force->q_entries());
        Fv.resize(force->v_entries());
      }
      J.resize(k, k);
      J.setFromTriplets(t.begin(), t.end());  // duplicates summed: zeros
      J.makeCompressed();
      P.resize(k, k);
      P.setFromTriplets(tp.begin(), tp.end());
      P.makeCompressed();
      // where each value goes among the matrices' values
      auto at = [](Sparse& A, int i, int j) {  // (a column's rows are sorted: a binary search)
        const int* first = A.innerIndexPtr() + A.outerIndexPtr()[j];
        const int* last = A.innerIndexPtr() + A.outerIndexPtr()[j + 1];
        const int* it = std::lower_bound(first, last, i);
        if (it == last || *it != i) throw std::logic_error("SparseConstrainedThetaStep: an entry outside the pattern");
        return static_cast<std::size_t>(it - A.innerIndexPtr());
      };
      for (int j = 0; j < n; ++j)
        for (int i : cols[static_cast<std::size_t>(j)]) hess_at.push_back(at(J, i, j));
      for (const auto& e : masses) {
        mass_J.emplace_back(at(J, e.first, e.second), mass_at(e.first, e.second) / h);
        mass_P.emplace_back(at(P, e.first, e.second), mass_at(e.first, e.second));
      }
      if (force)
        for (const WrittenForce::Row& row : force->pattern()) {
          for (int j : row.q) Fq_at.push_back(at(J, row.i, j));
          for (int j : row.v) Fv_at.push_back(at(J, row.i, j));
        }
      for (int c = 0; c < m; ++c)
        for (int j : pattern[static_cast<std::size_t>(c)]) {
          G0_at.push_back(at(J, j, n + c));
          G1_at.push_back(at(J, n + c, j));
          GT_P.push_back(at(P, j, n + c));
          G_P.push_back(at(P, n + c, j));
        }
      lu.analyse(J);
      plu.analyse(P);
    }

    void begin(const V& q0_, const V& p0_, double t0) {
      q0 = &q0_;
      p0 = &p0_;
      t1 = t0 + h;
      tn = t0 + theta * h;
      pscale = dynamic_detail::inf_norm(p0_);
      x0 = dynamic_detail::inf_norm(q0_);
      con.sparse_gradients(t0, q0_, G0.data(), gt.data());
      g0max = 0.0;
      for (double a : G0) g0max = std::fmax(g0max, std::fabs(a));
    }
    // q_theta = q0 + theta D, v = D / h and the force at the node: F = grad U(q_theta), plus
    // with a force F_f(t_theta, q_theta, v), which Ff receives.
    void forces(const V& D_) {
      x = *q0 + theta * D_;
      separable.force(x, F);
      if (force) {
        u = D_ / h;
        force->value(tn, x, u, Ff);
        F += Ff;
      }
    }
    // The terms at y = (D, lambda / s): q_theta, F(q_theta), M D, q1 = q0 + D, g(t1, q1).
    void at(const V& y_) {
      D = y_.head(n);
      forces(D);
      mass.times(D, MD);
      q1 = *q0 + D;
      con.value(t1, q1, g1);
    }
    // r = (M D / h - h (1 - theta) F(q_theta) - p0 + s G0^T y_lambda, s g(t1, q0 + D)) from
    // the terms of the last at()
    void form(const V& y_, V& r_) const {
      r_.head(n) = MD / h - (h * (1.0 - theta)) * F - *p0;
      add_normals(G0, s, y_.data() + n, r_.data());
      r_.tail(m) = s * g1;
    }
    // J's values at the point of the last at() (s set at the first); its largest entry
    // (INFINITY where one is not finite)
    double jacobian() {
      hessian->evaluate(x.data(), hess.data());
      con.sparse_gradients(t1, q1, G1.data(), gt.data());
      double* v = J.valuePtr();
      const auto size = static_cast<std::size_t>(J.nonZeros());
      std::fill_n(v, size, 0.0);
      for (const auto& e : mass_J) v[e.first] = e.second;
      const double c = h * theta * (1.0 - theta);
      for (std::size_t e = 0; e < hess_at.size(); ++e) v[hess_at[e]] -= c * hess[e];
      if (force) {  // d/dD of -h (1 - theta) F_f(t, q0 + theta D, D / h) (F_f itself: at())
        force->sparse_jacobian(tn, x, u, Fq.data(), Fv.data());
        for (std::size_t e = 0; e < Fq_at.size(); ++e) v[Fq_at[e]] -= c * Fq[e];
        for (std::size_t e = 0; e < Fv_at.size(); ++e) v[Fv_at[e]] -= (1.0 - theta) * Fv[e];
      }
      if (s == 0.0) {
        double jd = 0.0;
        for (std::size_t e = 0; e < size; ++e) jd = std::fmax(jd, std::fabs(v[e]));
        s = std::isfinite(jd) && jd > 0.0 && g0max > 0.0 ? jd / g0max : 1.0;
      }
      for (std::size_t e = 0; e < G0.size(); ++e) {
        v[G0_at[e]] = s * G0[e];
        v[G1_at[e]] = s * G1[e];
      }
      double big = 0.0;
      for (std::size_t e = 0; e < size; ++e) big = std::fmax(big, std::fabs(v[e]));
      return std::isfinite(big) ? big : INFINITY;
    }
    bool factor() { return lu.factor(J); }
    // Equation 2 at (t, q) with p~ in p: v and mu (p itself is not changed here)
    const char* project(double t, const V& q, const V& p, V& v) {
      con.sparse_gradients(t, q, G1.data(), gt.data());
      double* a = P.valuePtr();
      for (const auto& e : mass_P) a[e.first] = e.second;
      for (std::size_t e = 0; e < G1.size(); ++e) a[GT_P[e]] = a[G_P[e]] = G1[e];
      if (!plu.factor(P))
        return "the constraint Jacobian is singular where the momentum is projected (redundant constraints)";
      b.head(n) = p;
      b.tail(m) = -gt;
      plu.solve(b, dx);
      if (!std::isfinite(dynamic_detail::inf_norm(dx))) return "non-finite momentum projection";
      v = dx.head(n);
      mu = dx.tail(m);
      return "";
    }
    // out += c G^T y and out -= c G^T y for G's pattern-ordered entries
    void add_normals(const std::vector<double>& G, double c, const double* y_, double* out) const {
      const auto& pattern = con.pattern();
      std::size_t e = 0;
      for (int k = 0; k < m; ++k) {
        const double a = c * y_[k];
        for (int j : pattern[static_cast<std::size_t>(k)]) out[j] += G[e++] * a;
      }
    }
    void subtract_normals(const std::vector<double>& G, double c, const double* y_, double* out) const {
      add_normals(G, -c, y_, out);
    }

    WrittenDynamic L;
    WrittenSeparable separable;  // F = grad U
    ConstantMass mass;
    std::shared_ptr<SparsePotentialHessian> hessian;
    WrittenConstraints con;  // this step's copy (its workspace)
    std::unique_ptr<WrittenForce> force;  // and of the force (none: null)
    double theta, h;
    int n = 0, m = 0;
    const V* q0 = nullptr;
    const V* p0 = nullptr;
    double t1 = 0.0, tn = 0.0, pscale = 0.0, x0 = 0.0, s = 0.0, g0max = 0.0;
    V D, x, u, F, Ff, MD, q1, p1, v1, g1, gt, mu, y, r, dx, start, b;
    std::vector<double> Fq, Fv;                // the force's Jacobian entries (pattern order)
    std::vector<std::size_t> Fq_at, Fv_at;     // where they go in J
    std::vector<double> G0, G1, hess;  // Dg at q0 and at q1 (pattern order), Hess U's entries
    Sparse J, P;                       // equation 1's Jacobian, equation 2's matrix
    std::vector<std::size_t> hess_at, G0_at, G1_at, GT_P, G_P;
    std::vector<std::pair<std::size_t, double>> mass_J, mass_P;  // where M / h (M) goes, and its value
    constrained_detail::SparseOrBanded lu, plu;  // their factorisations
    Eigen::MatrixXd unused;  // (the driver's matrix: J is the sparse one above)
    DriverState state;
  };

  WrittenDynamic L_;
  std::shared_ptr<SparsePotentialHessian> hessian_;
  std::shared_ptr<const WrittenConstraints> con_;
  double theta_, h_;
  StepOptions options_;
  std::shared_ptr<const WrittenForce> force_;
  std::shared_ptr<Work> work_;
};

}  // namespace dvm
