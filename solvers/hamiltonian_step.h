// The Hamiltonian step of a discretization map (paper Sec. 5.1, Eq. 5.1):
//
//   (R_d^{T*})^{-1}(q0, p0; q1, p1) = h X_H( tau_{T*Q}( (R_d^{T*})^{-1}(q0, p0; q1, p1) ) )
//
// with (R_d^{T*})^{-1} the inverse of the cotangent lift (Eq. 3.6, built generically in
// core/map_operations.h from the map's inverse and its Jacobian): it sends the pair of
// points to a base point (q, p) of T*Q and a tangent vector (qdot, pdot) at it, and the
// step asks that tangent vector to be h times the Hamiltonian vector field at the base
// point. Because R_d^{T*} is a symplectomorphism between (T(T*Q), d_T w_Q) and
// (T*Q x T*Q, w_2 - w_1), the solution (q0, p0) -> (q1, p1) is a symplectic map for any
// discretization map and any H (the image of the Lagrangian submanifold dH under the
// lift is again Lagrangian).
//
// Examples (Sec. 5.1): the midpoint map gives the implicit midpoint rule
//   q1 - q0 = h dH/dp(m),  p1 - p0 = -h dH/dq(m),  m = ((q0 + q1)/2, (p0 + p1)/2);
// R_d(q, v) = (q - v, q) (the adjoint-Euler theta map, theta = 1), whose lift is
// (q - qdot, p; q, p + pdot), gives
//   q1 - q0 = h dH/dp(q1, p0),  p1 - p0 = -h dH/dq(q1, p0),
// explicit for separable H = T(p) + V(q): q1 first, then p1.
//
// VectorFieldSample::trapezoidal replaces h X_H(base point) by the average
// h (X_H(q0, p0) + X_H(q1, p1)) / 2 (the remark after Sec. 5.1: the vector field is
// sampled at the two end points instead of the base point). With the midpoint map that
// is the trapezoidal rule, which is NOT symplectic for a non-quadratic H; it is kept as
// the counter-example that shows the symplecticity check can fail.
//
// Eq. 5.1 is stated for any discretization map on T*Q, R^{TT*Q}; symplecticity
// (Prop. 5.1) needs it to be a cotangent lift. OnCotangentBundle<M> marks a map M on
// R^{2n} as such a map given directly on T*Q (points z = (q, p), velocities
// (qdot, pdot)): the step then inverts it, (z, zdot) = M^{-1}(z0, z1), instead of the
// cotangent lift of a map on Q. With the theta map of R^{2n} that is the theta method
// z1 - z0 = h X_H(z0 + theta (z1 - z0)), symplectic only at theta = 1/2 (where it is the
// cotangent lift of the midpoint map, the implicit midpoint rule).
//
// With a force (Force, not NoForce; Marsden and West 2001, Sec. 3.2, in the Hamiltonian
// form): a generalized force F(q, v) joins the vector field where it is sampled, as the
// vertical lift of F at the velocity v = dH/dp there, so that the step is Eq. 5.1 for the
// forced Hamilton equations q' = H_p, p' = -H_q + F:
//   qdot - h dH/dp(q, p) = 0,   pdot + h dH/dq(q, p) - h F(q, dH/dp(q, p)) = 0.
// Force is a callable F(q, v) for every scalar type the step evaluates (the time of
// the sample is the force object's own); the summary reports the work h <F, dH/dp> at the
// solution (the trapezoidal sample: the mean of the two ends'). The step on S^2 and SO(3)
// gives it the manifold's force in the chart (solvers/manifold_hamiltonian_step.h).
//
// Unknowns are the increments (dq, dp) = (q1 - q0, p1 - p0), of size O(h). The
// symplecticity of the computed map is measured by differentiating through the solve:
// with F(y, x) = 0 the step equation in the initial point y = (q0, p0) and the
// increment x, the implicit function theorem gives dx/dy = -F_x^{-1} F_y, so the
// one-step Jacobian is M = I + dx/dy, exact to round-off at the solution; the defect
// |M^T J M - J| (J the canonical symplectic matrix) is then a measurement.
#pragma once

#include <Eigen/LU>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "core/map_operations.h"
#include "mechanics/hamiltonian.h"
#include "solvers/newton_driver.h"

namespace dvm {

enum class VectorFieldSample { base_point, trapezoidal };

// A discretization map M on T*Q = R^{2n} used as R^{TT*Q} in Eq. 5.1 (not lifted).
template <class M>
struct OnCotangentBundle {
  M map;
  std::string name() const { return map.name() + " on T*Q"; }
  bool symmetric() const { return map.symmetric(); }
};
template <class M>
struct is_on_cotangent_bundle : std::false_type {};
template <class M>
struct is_on_cotangent_bundle<OnCotangentBundle<M>> : std::true_type {};

template <class Ham, class Map, class Force = NoForce>
class HamiltonianStep {
 public:
  static constexpr int N = Ham::dim;
  static constexpr bool kForced = is_force_v<Force>;
  using V = Vec<double, N>;
  using V2 = Vec<double, 2 * N>;
  using M2 = Mat<double, 2 * N, 2 * N>;

  HamiltonianStep(Ham H, Map R, double h, StepOptions options = {},
                  VectorFieldSample sample = VectorFieldSample::base_point, Force force = {})
      : H_(std::move(H)), R_(std::move(R)), h_(h), options_(options), sample_(sample), force_(std::move(force)) {
    // negative sizes are the backward substeps of compositions (solvers/composition.h)
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
  }

  double step_size() const { return h_; }
  const Ham& hamiltonian() const { return H_; }
  const Map& map() const { return R_; }
  VectorFieldSample sample() const { return sample_; }
  // Newton's method with the Jacobian of the step's first iterate kept for its later
  // iterations while they converge (solve_newton_kept), not formed at each: for a
  // residual whose Jacobian costs many residuals (the chart step on S^2 and SO(3)).
  void keep_jacobian_within_step(bool on) { kept_jacobian_ = on; }

  // The residual of Eq. 5.1 at (q0, p0; q0 + dq, p0 + dp), for any scalar:
  //   (qdot - h dH/dp(q, p),  pdot + h dH/dq(q, p))   (with a force: pdot + h dH/dq - h F)
  // with (q, p; qdot, pdot) = (R_d^{T*})^{-1}(q0, p0; q1, p1).
  template <class T>
  Vec<T, 2 * N> residual(const Vec<T, N>& q0, const Vec<T, N>& p0, const Vec<T, N>& dq, const Vec<T, N>& dp) const {
    Vec<T, N> q, qdot, p, pdot;
    inverse_lift(q0, p0, dq, dp, q, qdot, p, pdot);
    Vec<T, N> fq, fp;
    field(q0, p0, dq, dp, q, p, fq, fp);
    return stack(Vec<T, N>(qdot - h_ * fq), Vec<T, N>(pdot - h_ * fp));
  }

  // The force's work over the step from (q0, p0) by the solved increments: h <F, dH/dp>
  // where the field is sampled (0 without a force).
  double work(const V& q0, const V& p0, const V& dq, const V& dp) const {
    if constexpr (kForced) {
      V q, qdot, p, pdot, fq, fp;
      inverse_lift(q0, p0, dq, dp, q, qdot, p, pdot);
      double w = 0.0;
      field(q0, p0, dq, dp, q, p, fq, fp, &w);
      return w;
    }
    return 0.0;
  }
  struct Residual {
    const HamiltonianStep* step;
    V q0, p0;
    template <class T>
    bool operator()(const T* x, T* r) const {
      Vec<T, N> dq, dp;
      for (int i = 0; i < N; ++i) {
        dq[i] = x[i];
        dp[i] = x[N + i];
      }
      const Vec<T, 2 * N> F = step->residual(constants<T>(q0), constants<T>(p0), dq, dp);
      for (int i = 0; i < 2 * N; ++i) r[i] = F[i];
      return true;
    }
  };

  // One step from (q0, p0); (dq, dp) hold the starting guess on entry and the
  // increments on return. Map domain errors are reported in the summary.
  StepSummary step(double /*t*/, const V& q0, const V& p0, V& dq, V& dp) const {
    Residual f{this, q0, p0};
    V fq, fp;
    hamiltonian_vector_field(H_, q0, p0, fq, fp);
    if constexpr (kForced) fp += force_(q0, fq);  // (a start at rest driven by the force alone)
    const double s0 = std::fabs(h_) * std::fmax(max_abs(fq), max_abs(fp));
    V2 x = stack(dq, dp);
    const double x0 = std::fmax(max_abs(q0), max_abs(p0));
    StepSummary s;
    try {
      if (kept_jacobian_ && options_.solver == SolverKind::newton)
        s = solve_newton_kept<2 * N>(f, x, x0, options_, s0);
      else
        s = solve_step_system<2 * N>(f, x, x0, options_, s0);
    } catch (const std::domain_error& e) {
      s.fail(e.what());
    }
    dq = x.template head<N>();
    dp = x.template tail<N>();
    if constexpr (kForced)
      if (s.converged) s.work = work(q0, p0, dq, dp);
    return s;
  }

  // The Jacobian M = d(q1, p1)/d(q0, p0) of the one-step map at a solved step
  // (q0, p0) -> (q0 + dq, p0 + dp), by the implicit function theorem.
  M2 jacobian(const V& q0, const V& p0, const V& dq, const V& dp) const {
    constexpr int K = 4 * N;
    using D = ceres::Jet<double, K>;
    Vec<D, N> a, b, c, d;
    for (int i = 0; i < N; ++i) {
      a[i] = seed<double, K>(q0[i], i);
      b[i] = seed<double, K>(p0[i], N + i);
      c[i] = seed<double, K>(dq[i], 2 * N + i);
      d[i] = seed<double, K>(dp[i], 3 * N + i);
    }
    const Vec<D, 2 * N> F = residual(a, b, c, d);
    M2 Fy, Fx;
    for (int i = 0; i < 2 * N; ++i) {
      Fy.row(i) = F[i].v.template head<2 * N>().transpose();
      Fx.row(i) = F[i].v.template tail<2 * N>().transpose();
    }
    return M2::Identity() - Fx.partialPivLu().solve(Fy);
  }

 private:
  // (q, qdot, p, pdot) = (R_d^{T*})^{-1}(q0, p0; q0 + dq, p0 + dp).
  template <class T>
  void inverse_lift(const Vec<T, N>& q0, const Vec<T, N>& p0, const Vec<T, N>& dq, const Vec<T, N>& dp, Vec<T, N>& q,
                    Vec<T, N>& qdot, Vec<T, N>& p, Vec<T, N>& pdot) const {
    if constexpr (is_on_cotangent_bundle<Map>::value) {
      // (z, zdot) = R^{-1}(z0, z0 + dz) of the map given on T*Q
      const TangentPoint<T, 2 * N> z = inverse_increment(R_.map, stack(q0, p0), stack(dq, dp));
      q = z.x.template head<N>();
      p = z.x.template tail<N>();
      qdot = z.v.template head<N>();
      pdot = z.v.template tail<N>();
    } else {
      // (q, qdot) = R_d^{-1}(q0, q0 + dq) without forming q1 - q0.
      const TangentPoint<T, N> t = inverse_increment(R_, q0, dq);
      Mat<T, 2 * N, 2 * N> J;
      map_with_jacobian(R_, t.x, t.v, J);
      // (pdot, p) = DR^T (-p0, p1), split as DR^T (-p0, p0) + DR^T (0, dp) so that maps
      // whose x-columns of DR sum to zero (all theta maps) give pdot = dp exactly.
      const Vec<T, 2 * N> a = J.transpose() * stack(Vec<T, N>(-p0), p0) +
                              J.transpose() * stack(Vec<T, N>(Vec<T, N>::Constant(constant<T>(0.0))), dp);
      q = t.x;
      qdot = t.v;
      pdot = a.template head<N>();
      p = a.template tail<N>();
    }
  }
  // The vector field (fq, fp) = X_H (+ the force's vertical lift) sampled as chosen: at
  // the base point (q, p), or the mean of the two ends'. work (where given, doubles):
  // h <F, fq> there.
  template <class T>
  void field(const Vec<T, N>& q0, const Vec<T, N>& p0, const Vec<T, N>& dq, const Vec<T, N>& dp, const Vec<T, N>& q,
             const Vec<T, N>& p, Vec<T, N>& fq, Vec<T, N>& fp, double* work = nullptr) const {
    auto at = [&](const Vec<T, N>& x, const Vec<T, N>& y, Vec<T, N>& a, Vec<T, N>& b, double* w) {
      hamiltonian_vector_field(H_, x, y, a, b);
      if constexpr (kForced) {
        const Vec<T, N> F = force_(x, a);
        b += F;
        if constexpr (std::is_same_v<T, double>)
          if (w) *w = h_ * F.dot(a);
      }
      (void)w;
    };
    if (sample_ == VectorFieldSample::base_point) {
      at(q, p, fq, fp, work);
    } else {
      Vec<T, N> a0, b0, a1, b1;
      double w0 = 0.0, w1 = 0.0;
      at(q0, p0, a0, b0, &w0);
      at(Vec<T, N>(q0 + dq), Vec<T, N>(p0 + dp), a1, b1, &w1);
      fq = 0.5 * (a0 + a1);
      fp = 0.5 * (b0 + b1);
      if (work) *work = 0.5 * (w0 + w1);
    }
  }

  Ham H_;
  Map R_;
  double h_;
  StepOptions options_;
  VectorFieldSample sample_;
  Force force_;
  bool kept_jacobian_ = false;
};

// The canonical symplectic matrix J = [[0, I], [-I, 0]] on (q, p).
template <int N>
Mat<double, 2 * N, 2 * N> canonical_symplectic() {
  Mat<double, 2 * N, 2 * N> J = Mat<double, 2 * N, 2 * N>::Zero();
  J.template block<N, N>(0, N) = Mat<double, N, N>::Identity();
  J.template block<N, N>(N, 0) = -Mat<double, N, N>::Identity();
  return J;
}

// max |M^T J M - J|: zero to round-off exactly when M is symplectic.
template <int N>
double symplectic_defect(const Mat<double, 2 * N, 2 * N>& M) {
  const Mat<double, 2 * N, 2 * N> J = canonical_symplectic<N>();
  return max_abs(Mat<double, 2 * N, 2 * N>(M.transpose() * J * M - J));
}

}  // namespace dvm
