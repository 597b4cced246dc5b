// Higher order by composition (paper Sec. 6), two ways that give one map.
//
// 1. Composition of one-step maps. With substeps (w_k, a_k), k = 1..S, the step is
//      Psi_h = Phi^{(S)}_{w_S h} o ... o Phi^{(1)}_{w_1 h},
//    Phi^{(k)} the position-momentum step of the map R_d (a_k false) or of its adjoint
//    R_d^* (a_k true; Prop. 2.4: the discrete Lagrangian of R_d^* gives the adjoint
//    method). Substep sizes may be negative.
//
// 2. Composition of discrete Lagrangians (generating functions). With
//      L_d(q_0, q_S) = sum_k L_d^{(k)}(q_{k-1}, q_k),   L_d^{(k)} of size w_k h,
//    and the micro-nodes q_1..q_{S-1} eliminated by stationarity, the step
//      p_0 = -D1 L_d^{(1)}(q_0, q_1),
//      0   = D2 L_d^{(k)}(q_{k-1}, q_k) + D1 L_d^{(k+1)}(q_k, q_{k+1}),  k = 1..S-1,
//      p_S = D2 L_d^{(S)}(q_{S-1}, q_S)
//    is solved for q_1..q_S together (one Newton iteration on S N unknowns with a
//    block-tridiagonal Jacobian). The micro-node equations say that the momentum
//    leaving substep k equals the one entering substep k + 1, so the solution is the
//    map of route 1; tests check this to round-off.
//
// Route 1 is ComposedStep (any step type and its adjoint's, composed); the
// position-momentum steps of R_d and R_d^* composed are its instance that route 2
// equals. Both plug into `integrate` (they have N, step_size() and step(q, p, dq, dp)).
#pragma once

#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/map_operations.h"
#include "solvers/composition_methods.h"
#include "solvers/integrate.h"
#include "solvers/newton_driver.h"
#include "solvers/position_momentum_step.h"

namespace dvm {

namespace composition_detail {
// A step with control_derivative(t, q, p, dq, B) (the forced steps with control inputs).
template <class S, class = void>
struct has_control_derivative : std::false_type {};
template <class S>
struct has_control_derivative<S, std::void_t<decltype(std::declval<const S&>().control_derivative(
                                     0.0, std::declval<const Eigen::VectorXd&>(), std::declval<const Eigen::VectorXd&>(),
                                     std::declval<const Eigen::VectorXd&>(), std::declval<Eigen::MatrixXd&>()))>>
    : std::true_type {};
// A step with derivatives(t, q, p, dq, A, B*): A and B from one differentiation.
template <class S, class = void>
struct has_joint_derivatives : std::false_type {};
template <class S>
struct has_joint_derivatives<S, std::void_t<decltype(std::declval<const S&>().derivatives(
                                    0.0, std::declval<const Eigen::VectorXd&>(), std::declval<const Eigen::VectorXd&>(),
                                    std::declval<const Eigen::VectorXd&>(), std::declval<Eigen::MatrixXd&>(),
                                    std::declval<Eigen::MatrixXd*>()))>> : std::true_type {};
}  // namespace composition_detail

// The substeps of "no composition": the map's own step.
inline std::vector<Substep> single_substep() { return {{1.0, false}}; }

// Route 1 for any basic method: substeps of a step type `Plain` and of a step type
// `Dual` (its adjoint), each any type with N, step_size() and
// step(q, p, dq, dp) (the contract of `integrate`), built by the caller for each
// substep size w_k h. This is how a method of another form (a Hamiltonian step from a
// cotangent lift, say) composes.
template <class Plain, class Dual = Plain>
class ComposedStep {
 public:
  static constexpr int N = Plain::N;
  static_assert(Dual::N == N, "the stages of a composition act on one space");
  using V = Vec<double, N>;

  // make_plain(hk) and make_dual(hk) build the step of size hk (possibly negative).
  template <class MakePlain, class MakeDual>
  ComposedStep(double h, std::vector<Substep> substeps, const MakePlain& make_plain, const MakeDual& make_dual)
      : h_(h), substeps_(std::move(substeps)) {
    if (substeps_.empty()) throw std::invalid_argument("a composition needs at least one substep");
    for (const Substep& s : substeps_) {
      if (!(s.weight != 0.0) || !std::isfinite(s.weight))
        throw std::invalid_argument("composition substeps must have nonzero finite weights");
      if (s.adjoint) {
        index_.push_back(dual_.size());
        dual_.push_back(make_dual(s.weight * h));
      } else {
        index_.push_back(plain_.size());
        plain_.push_back(make_plain(s.weight * h));
      }
    }
  }

  double step_size() const { return h_; }
  const std::vector<Substep>& substeps() const { return substeps_; }

  // One step from (q0, p0): dq holds a guess of the increment over the whole step on
  // entry (about h v), the increment on return; dp receives p_S - p_0. The summary
  // adds up the iterations and keeps the worst relative residual; on failure its
  // message names the substep.
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary total;
    total.converged = true;
    total.iterations = 0;
    total.residual = 0.0;
    total.scale = 0.0;
    CompensatedVector<N> Q(V::Zero(q0.size())), P(V::Zero(q0.size()));  // increments since the start
    // Each substep starts from the previous substep's increment rescaled to its size
    // (the first from the caller's guess).
    // Steps that take a guess of the momentum increment too (Hamiltonian steps) get
    // the previous substep's, rescaled likewise (zero for the first).
    V prev = dq, d, e = V::Zero(dq.size());
    double prev_weight = 1.0, elapsed = 0.0;  // the weights of the substeps done
    for (std::size_t k = 0; k < substeps_.size(); ++k) {
      const double w = substeps_[k].weight;
      d = prev * (w / prev_weight);
      e *= w / prev_weight;
      const V q = q0 + Q.sum, p = p0 + P.sum;
      const double tk = t + elapsed * h_;  // substep k starts there (earlier, after a backward substep)
      const StepSummary s =
          substeps_[k].adjoint ? dual_[index_[k]].step(tk, q, p, d, e) : plain_[index_[k]].step(tk, q, p, d, e);
      total.iterations += s.iterations;
      total.jacobians += s.jacobians;
      total.work += s.work;
      if (!(s.residual / s.scale <= total.residual / std::fmax(total.scale, 1e-300))) {
        total.residual = s.residual;
        total.scale = s.scale;
      }
      if (!s.converged) {
        total.converged = false;
        total.residual = s.residual;
        total.scale = s.scale;
        total.message = "substep " + std::to_string(k + 1) + " of " + std::to_string(substeps_.size()) + ": " +
                        s.message;
        return total;
      }
      Q.add(d);
      P.add(e);
      prev = d;
      prev_weight = w;
      elapsed += w;
    }
    dq = Q.sum;
    dp = P.sum;
    return total;
  }

  // The derivative A = d(q_S, p_S)/d(q0, p0) of the whole step from (q0, p0) at time t,
  // as the chain rule gives it: the product A_S ... A_1 of the substeps' derivatives
  // at the substep states, which are found again by solving the substeps from (q0, p0)
  // with copies of the substep steps (so the run's own steps keep their warm starts).
  // Where the substeps give a derivative in controls too, B (2n x c; u held over the
  // whole step) is the sum of A_S ... A_{k+1} B_k. Exists where both substep types give
  // derivative(t, q, p, dq, A); dq is not read (the substeps are solved again). Returns
  // false where a substep fails or a derivative is singular. Allocates.
  template <class P = Plain, class D = Dual,
            class = decltype(std::declval<const P&>().derivative(0.0, std::declval<const Eigen::VectorXd&>(),
                                                                  std::declval<const Eigen::VectorXd&>(),
                                                                  std::declval<const Eigen::VectorXd&>(),
                                                                  std::declval<Eigen::MatrixXd&>())),
            class = decltype(std::declval<const D&>().derivative(0.0, std::declval<const Eigen::VectorXd&>(),
                                                                  std::declval<const Eigen::VectorXd&>(),
                                                                  std::declval<const Eigen::VectorXd&>(),
                                                                  std::declval<Eigen::MatrixXd&>()))>
  bool derivative(double t, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A) const {
    return chain(t, q0, p0, dq, A, nullptr);
  }
  template <class P = Plain, class D = Dual,
            std::enable_if_t<composition_detail::has_control_derivative<P>::value &&
                                 composition_detail::has_control_derivative<D>::value,
                             int> = 0>
  bool control_derivative(double t, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& B) const {
    Eigen::MatrixXd A;
    return chain(t, q0, p0, dq, A, &B);
  }
  // A and, where B is not null, B from one pass through the substeps.
  template <class P = Plain, class D = Dual,
            std::enable_if_t<composition_detail::has_control_derivative<P>::value &&
                                 composition_detail::has_control_derivative<D>::value,
                             int> = 0>
  bool derivatives(double t, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    return chain(t, q0, p0, dq, A, B);
  }
  // The controls the substeps' force reads (where the substep type says).
  template <class P = Plain, class = decltype(std::declval<const P&>().controls())>
  int controls() const {
    return plain_.empty() ? dual_.front().controls() : plain_.front().controls();
  }

 private:
  template <class S>
  static bool substep_derivative(const S& s, double t, const Eigen::VectorXd& q, const Eigen::VectorXd& p,
                                 const Eigen::VectorXd& d, Eigen::MatrixXd& A, Eigen::MatrixXd* B) {
    if constexpr (composition_detail::has_joint_derivatives<S>::value)
      if (B) return s.derivatives(t, q, p, d, A, B);
    if (!s.derivative(t, q, p, d, A)) return false;
    if (B) {
      if constexpr (composition_detail::has_control_derivative<S>::value)
        return s.control_derivative(t, q, p, d, *B);
      else
        return false;
    }
    return true;
  }
  bool chain(double t, const V& q0, const V& p0, const V& dq, Eigen::MatrixXd& A, Eigen::MatrixXd* B) const {
    std::vector<Plain> plain(plain_);
    std::vector<Dual> dual(dual_);
    const Eigen::Index n = q0.size();
    V q = q0, p = p0, prev = dq, d, e = V::Zero(n);
    double prev_weight = 1.0, elapsed = 0.0;
    A = Eigen::MatrixXd::Identity(2 * n, 2 * n);
    if (B) B->resize(2 * n, 0);
    Eigen::MatrixXd Ak, Bk;
    for (std::size_t k = 0; k < substeps_.size(); ++k) {
      const double w = substeps_[k].weight;
      d = prev * (w / prev_weight);
      e *= w / prev_weight;
      const double tk = t + elapsed * h_;
      const bool adj = substeps_[k].adjoint;
      const Eigen::VectorXd qk = q, pk = p;
      const StepSummary s = adj ? dual[index_[k]].step(tk, q, p, d, e) : plain[index_[k]].step(tk, q, p, d, e);
      if (!s.converged) return false;
      const Eigen::VectorXd dk = d;
      const bool ok = adj ? substep_derivative(dual[index_[k]], tk, qk, pk, dk, Ak, B ? &Bk : nullptr)
                          : substep_derivative(plain[index_[k]], tk, qk, pk, dk, Ak, B ? &Bk : nullptr);
      if (!ok) return false;
      if (B) {
        if (B->cols() == 0) B->setZero(2 * n, Bk.cols());
        *B = Ak * *B + Bk;
      }
      A = Ak * A;
      q += d;
      p += e;
      prev = d;
      prev_weight = w;
      elapsed += w;
    }
    return A.allFinite() && (!B || B->allFinite());
  }

  double h_;
  std::vector<Substep> substeps_;
  std::vector<std::size_t> index_;
  std::vector<Plain> plain_;
  std::vector<Dual> dual_;
};

// Route 2: the composed discrete Lagrangian sum_k L_d^{(k)}(q_{k-1}, q_k), solved for
// all nodes at once.
template <class System, class Map>
class ComposedLagrangianStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using PlainDL = DiscreteLagrangian<System, Map>;
  using DualDL = DiscreteLagrangian<System, Adjoint<Map>>;

  ComposedLagrangianStep(const System& L, const Map& R, double h, std::vector<Substep> substeps,
                         StepOptions options = {})
      : h_(h), substeps_(std::move(substeps)), options_(options) {
    if (substeps_.empty()) throw std::invalid_argument("a composition needs at least one substep");
    for (const Substep& s : substeps_) {
      if (s.adjoint) {
        index_.push_back(dual_.size());
        dual_.emplace_back(L, adjoint(R), s.weight * h);
      } else {
        index_.push_back(plain_.size());
        plain_.emplace_back(L, R, s.weight * h);
      }
    }
  }

  double step_size() const { return h_; }

  // The composed discrete Lagrangian at the nodes q_0..q_S (for checks).
  double value(const std::vector<V>& nodes) const {
    double sum = 0.0;
    for (std::size_t k = 0; k < substeps_.size(); ++k)
      sum += substeps_[k].adjoint ? dual_[index_[k]](nodes[k], nodes[k + 1]) : plain_[index_[k]](nodes[k], nodes[k + 1]);
    return sum;
  }

  // D1 and D2 of substep k's discrete Lagrangian at (a, a + d), and their Jacobians
  // with respect to (q_{k-1}, q_k) (N x 2N each).
  void pair(std::size_t k, const V& a, const V& d, V& D1, V& D2, Mat<double, N, 2 * N>& J1,
            Mat<double, N, 2 * N>& J2) const {
    if (substeps_[k].adjoint)
      pair_of(dual_[index_[k]], a, d, D1, D2, J1, J2);
    else
      pair_of(plain_[index_[k]], a, d, D1, D2, J1, J2);
  }

  // One step: the same contract as ComposedStep::step. The nodes start from the
  // guess split in proportion to the weights; Newton's method by the driver
  // (solvers/newton_driver.h), the Jacobian formed and factored at every iteration.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    const std::size_t S = substeps_.size();
    const int n = static_cast<int>(S) * N;
    Eigen::VectorXd x(n), r(n), dx(n), start(n);  // x: the increments q_k - q_{k-1}, k = 1..S
    for (std::size_t k = 0; k < S; ++k) x.segment<N>(static_cast<int>(k) * N) = dq * substeps_[k].weight;
    Eigen::MatrixXd J(n, n);
    Equation eq{*this, q0, p0};
    NodesLU la{DenseLU(n), Eigen::VectorXd(n)};
    DriverState state;
    StepSummary s = newton_drive(eq, la, Refresh::every_iteration, options_, x, r, dx, J, state, start);
    if (!s.converged) return s;
    CompensatedVector<N> Q(V::Zero());
    for (std::size_t k = 0; k + 1 < S; ++k) Q.add(V(x.segment<N>(static_cast<int>(k) * N)));
    const V last = x.segment<N>(static_cast<int>(S - 1) * N);
    V D1, D2;
    Mat<double, N, 2 * N> J1, J2;
    pair(S - 1, V(q0 + Q.sum), last, D1, D2, J1, J2);
    Q.add(last);
    dq = Q.sum;
    dp = D2 - p0;
    return s;
  }

 private:
  // The S N equations for the driver, in the increments x_k = q_k - q_{k-1}: equation k
  // is D1 L_d^{(k)}(q_{k-1}, q_k) plus D2 L_d^{(k-1)}(q_{k-2}, q_{k-1}) (p0 for k = 1);
  // the Jacobian formed is the one in the nodes q_1..q_S (block tridiagonal), which
  // NodesLU turns into the correction of the increments. The residual's scale is the
  // mean size of its terms, (|p0| + sum_k |D1_k|) / S.
  struct Equation {
    using Vector = Eigen::VectorXd;
    using Matrix = Eigen::MatrixXd;
    const ComposedLagrangianStep& st;
    const V& q0;
    const V& p0;
    mutable double terms = 0.0;
    void residual(const Vector& x, Vector& F) const {  // (the driver forms J at every iteration)
      Matrix J(x.size(), x.size());
      jacobian(x, F, J);
    }
    double jacobian(const Vector& x, Vector& F, Matrix& J) const {
      const std::size_t S = st.substeps_.size();
      F.setZero();
      J.setZero();
      V a = q0;  // q_{k-1}
      double scale = max_abs(p0);
      for (std::size_t k = 0; k < S; ++k) {
        const int r = static_cast<int>(k) * N;
        const V inc = x.segment<N>(r);
        V D1, D2;
        Mat<double, N, 2 * N> J1, J2;
        st.pair(k, a, inc, D1, D2, J1, J2);
        // equation k (rows r..r+N): D1 of substep k, plus D2 of substep k-1 (or p0)
        F.segment<N>(r) += D1;
        if (k == 0) F.segment<N>(r) += p0;
        // unknowns: node k (columns (k-1)N..) is q_{k-1} for k >= 1; node k+1 is q_k
        if (k > 0) J.block<N, N>(r, r - N) += J1.template leftCols<N>();
        J.block<N, N>(r, r) += J1.template rightCols<N>();
        if (k + 1 < S) {
          F.segment<N>(r + N) += D2;
          if (k > 0) J.block<N, N>(r + N, r - N) += J2.template leftCols<N>();
          J.block<N, N>(r + N, r) += J2.template rightCols<N>();
        }
        scale += max_abs(D1);
        a = a + inc;
      }
      terms = scale / static_cast<double>(S);
      return inf_norm(J);
    }
    double scale(double, double) const { return terms; }
    double offset() const { return max_abs(q0); }
  };
  // The nodes' Jacobian factored; solve() gives the change of the increments, the
  // differences of the nodes' changes J^{-1} r.
  struct NodesLU {
    DenseLU lu;
    Eigen::VectorXd delta;
    bool factor(const Eigen::MatrixXd& J, double Jmax) { return lu.factor(J, Jmax); }
    void solve(const Eigen::VectorXd& r, Eigen::VectorXd& dx) {
      lu.solve(r, delta);
      for (Eigen::Index i = dx.size() - 1; i >= N; --i) dx[i] = delta[i] - delta[i - N];
      dx.head<N>() = delta.head<N>();
    }
    const char* name() const { return "dense LU of the composed Jacobian"; }
  };

  template <class DL>
  static void pair_of(const DL& dl, const V& a, const V& d, V& D1, V& D2, Mat<double, N, 2 * N>& J1,
                      Mat<double, N, 2 * N>& J2) {
    // Jets in the 2N directions (q_{k-1}, q_k); the increment d = q_k - q_{k-1}.
    using T = ceres::Jet<double, 2 * N>;
    Vec<T, N> aj, dj;
    for (int i = 0; i < N; ++i) {
      aj[i] = T(a[i]);
      aj[i].v[i] = 1.0;
      dj[i] = T(d[i]);
      dj[i].v[i] = -1.0;
      dj[i].v[N + i] = 1.0;
    }
    const Vec<T, N> d1 = dl.D1Ld_increment(aj, dj);
    // D2 at (a, a + d): the inner derivative moves d alone.
    using U = ceres::Jet<T, N>;
    Vec<U, N> a2, d2;
    for (int i = 0; i < N; ++i) {
      a2[i] = U(aj[i]);
      d2[i] = seed<T, N>(dj[i], i);
    }
    const Vec<T, N> dd2 = dl.template slopes<T, N>(a2, d2);
    for (int i = 0; i < N; ++i) {
      D1[i] = d1[i].a;
      D2[i] = dd2[i].a;
      J1.row(i) = d1[i].v.transpose();
      J2.row(i) = dd2[i].v.transpose();
    }
  }

  double h_;
  std::vector<Substep> substeps_;
  StepOptions options_;
  std::vector<std::size_t> index_;
  std::vector<PlainDL> plain_;
  std::vector<DualDL> dual_;
};

}  // namespace dvm
