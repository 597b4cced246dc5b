// Second-order differential equations (SODEs) discretized by a discretization map on
// TQ (paper Sec. 4), and the Newmark family (Sec. 4.1).
//
// The Euler-Lagrange equations of a regular Lagrangian are the SODE
//   Gamma(q, v) = (v, a(q, v)),   a = (d2L/dv2)^{-1} (dL/dq - (d2L/dv dq) v),
// a vector field on TQ = R^{2n}. A discretization map R on TQ (any map on R^{2n}, in
// particular the tangent lift R_d^T of a map on Q, Prop. 3.2) sends the pair
// (Y0, Y1) = ((q0, v0), (q1, v1)) to a base point X in TQ and a tangent vector W at it,
// (X, W) = R^{-1}(Y0, Y1), and the step asks W to be h times the vector field. Two
// ways of sampling the vector field give the two discretizations:
//   sode1 (Eq. 4.1, the "first option"):  W = h (Gamma(Y0) + Gamma(Y1)) / 2
//   sode2 (Eq. 4.2):                       W = h Gamma(X)
// With the midpoint map (or the tangent lift of the midpoint map on Q, which is the
// midpoint map of TQ) sode1 is the trapezoidal rule and sode2 the implicit midpoint
// rule: they agree for linear a and differ at O(h^3) per step otherwise (the paper's
// worked example; tests/solvers/test_sode.cc measures it). Note on provenance: the
// names follow the reading of the paper (Eq. 4.1 = end-point sampling, the
// form whose Hamiltonian analogue is the non-symplectic trapezoidal method of the
// remark after Sec. 5.1; Eq. 4.2 = base-point sampling, the analogue of Eq. 5.1).
//
// Newmark (Newmark 1959; Hughes, The Finite Element Method, Sec. 9.1): with a_k = a(q_k, v_k)
//   q1 = q0 + h v0 + h^2 ((1/2 - beta) a0 + beta a1)
//   v1 = v0 + h ((1 - gamma) a0 + gamma a1).
// It is the first-option discretization through the explicit-Euler map on TQ,
// R(Y, W) = (Y, Y + W) (so W = Y1 - Y0), with the vector field replaced by the Newmark
// quadrature of Gamma along the step,
//   W = h (v0 + h ((1/2 - beta) a0 + beta a1),  (1 - gamma) a0 + gamma a1);
// NewmarkStep writes the residual that way. Linear stability on q'' = -w^2 q: for
// gamma >= 1/2 the method is unconditionally stable when 2 beta >= gamma, and stable
// only for w h < 1/sqrt(gamma/2 - beta) otherwise; for gamma < 1/2 it is unstable.
//
// Unknowns are the increments (dq, dv). Steps work in (q, v); VelocityFormStep adapts
// them to the (q, p) interface of the integrate loop through the Legendre map.
#pragma once

#include <stdexcept>

#include "core/map_operations.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/lagrangian.h"
#include "solvers/newton.h"

namespace dvm {

// a(q, v) of the Euler-Lagrange equations of L, for any scalar.
template <class S, class T>
Vec<T, S::dim> lagrangian_acceleration(const S& L, const Vec<T, S::dim>& q, const Vec<T, S::dim>& v) {
  constexpr int N = S::dim;
  using D = ceres::Jet<T, 2 * N>;
  Vec<D, N> qd, vd, a, b;
  for (int i = 0; i < N; ++i) {
    qd[i] = seed<T, 2 * N>(q[i], i);
    vd[i] = seed<T, 2 * N>(v[i], N + i);
  }
  lagrangian_gradient(L, qd, vd, a, b);
  Mat<T, N, N> W;
  Vec<T, N> rhs;
  for (int i = 0; i < N; ++i) {
    rhs[i] = a[i].a;
    for (int j = 0; j < N; ++j) {
      W(i, j) = b[i].v[N + j];
      rhs[i] = rhs[i] - b[i].v[j] * v[j];
    }
  }
  return solve_dense<T, N, N>(W, rhs);
}

// The step equations of a (q, v) step as a functor of the increment dY, for the
// solvers: step.residual(Y0, dY) = 0.
template <class Step, int K>
struct IncrementResidual {
  const Step* step;
  Vec<double, K> Y0;
  template <class T>
  bool operator()(const T* x, T* r) const {
    Vec<T, K> dY;
    for (int i = 0; i < K; ++i) dY[i] = x[i];
    const Vec<T, K> F = step->residual(constants<T>(Y0), dY);
    for (int i = 0; i < K; ++i) r[i] = F[i];
    return true;
  }
};

// Solves step.residual(Y0, dY) = 0 for dY = (dq, dv), which carry the guess in and the
// increments out; the residual is judged against s0 + |J| |dY|.
template <int N, class Step>
StepSummary solve_increments(const Step& step, const Vec<double, 2 * N>& Y0, double s0, const StepOptions& options,
                             Vec<double, N>& dq, Vec<double, N>& dv) {
  IncrementResidual<Step, 2 * N> f{&step, Y0};
  auto scale_of = [s0](const Vec<double, 2 * N>& x, const Mat<double, 2 * N, 2 * N>& J) {
    return s0 + max_abs(J) * max_abs(x);
  };
  Vec<double, 2 * N> x = stack(dq, dv);
  StepSummary s;
  try {
    s = solve_step_system<2 * N>(f, x, max_abs(Y0), options, scale_of);
  } catch (const std::domain_error& e) {
    s.converged = false;
    s.message = e.what();
  }
  dq = x.template head<N>();
  dv = x.template tail<N>();
  return s;
}

enum class SodeForm { sode1, sode2 };
inline const char* to_string(SodeForm f) { return f == SodeForm::sode1 ? "sode1" : "sode2"; }

// Discretization of the SODE of L by a map MapTQ on TQ = R^{2n}.
template <class System, class MapTQ>
class SodeStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using V2 = Vec<double, 2 * N>;

  SodeStep(System L, MapTQ R, double h, SodeForm form, StepOptions options = {})
      : L_(std::move(L)), R_(std::move(R)), h_(h), form_(form), options_(options) {
    if (!(h > 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be positive and finite");
  }
  double step_size() const { return h_; }
  const System& lagrangian() const { return L_; }
  SodeForm form() const { return form_; }
  std::string name() const { return std::string(to_string(form_)) + "(" + R_.name() + ")"; }

  template <class T>
  Vec<T, 2 * N> gamma(const Vec<T, 2 * N>& Y) const {
    const Vec<T, N> q = Y.template head<N>(), v = Y.template tail<N>();
    return stack(v, lagrangian_acceleration(L_, q, v));
  }

  template <class T>
  Vec<T, 2 * N> residual(const Vec<T, 2 * N>& Y0, const Vec<T, 2 * N>& dY) const {
    const TangentPoint<T, 2 * N> t = inverse_increment(R_, Y0, dY);
    if (form_ == SodeForm::sode2) return t.v - h_ * gamma(t.x);
    const Vec<T, 2 * N> Y1 = Y0 + dY;
    return t.v - (0.5 * h_) * (gamma(Y0) + gamma(Y1));
  }

  // One step in (q, v); (dq, dv) carry the guess in and the increments out.
  StepSummary step_qv(const V& q0, const V& v0, V& dq, V& dv) const {
    const V2 Y0 = stack(q0, v0);
    return solve_increments<N>(*this, Y0, h_ * max_abs(gamma(Y0)), options_, dq, dv);
  }

 private:
  System L_;
  MapTQ R_;
  double h_;
  SodeForm form_;
  StepOptions options_;
};

// The Newmark family on the SODE of L.
template <class System>
class NewmarkStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using V2 = Vec<double, 2 * N>;

  NewmarkStep(System L, double h, double gamma, double beta, StepOptions options = {})
      : L_(std::move(L)), h_(h), gamma_(gamma), beta_(beta), options_(options) {
    if (!(h > 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be positive and finite");
    if (!(gamma >= 0.0 && gamma <= 1.0) || !(beta >= 0.0 && beta <= 0.5))
      throw std::invalid_argument("newmark: expected gamma in [0, 1] and beta in [0, 1/2]");
  }
  double step_size() const { return h_; }
  double gamma() const { return gamma_; }
  double beta() const { return beta_; }
  const System& lagrangian() const { return L_; }
  std::string name() const { return "newmark"; }

  // The explicit-Euler map on TQ gives W = Y1 - Y0 = dY; the residual is dY minus h
  // times the Newmark quadrature of Gamma.
  template <class T>
  Vec<T, 2 * N> residual(const Vec<T, 2 * N>& Y0, const Vec<T, 2 * N>& dY) const {
    const Vec<T, N> q0 = Y0.template head<N>(), v0 = Y0.template tail<N>();
    const Vec<T, N> q1 = q0 + dY.template head<N>(), v1 = v0 + dY.template tail<N>();
    const Vec<T, N> a0 = lagrangian_acceleration(L_, q0, v0), a1 = lagrangian_acceleration(L_, q1, v1);
    const Vec<T, N> Wq = h_ * (v0 + h_ * ((0.5 - beta_) * a0 + beta_ * a1));
    const Vec<T, N> Wv = h_ * ((1.0 - gamma_) * a0 + gamma_ * a1);
    return dY - stack(Wq, Wv);
  }

  StepSummary step_qv(const V& q0, const V& v0, V& dq, V& dv) const {
    const V2 Y0 = stack(q0, v0);
    const double s0 = h_ * std::fmax(max_abs(v0), max_abs(lagrangian_acceleration(L_, q0, v0)));
    return solve_increments<N>(*this, Y0, s0, options_, dq, dv);
  }

 private:
  System L_;
  double h_, gamma_, beta_;
  StepOptions options_;
};

// A (q, v) step seen through the Legendre map as a (q, p) step for integrate():
// v0 = FL^{-1}(q0, p0), step, p1 = FL(q1, v1), dp = p1 - p0.
template <class Step>
class VelocityFormStep {
 public:
  static constexpr int N = Step::N;
  using V = Vec<double, N>;
  explicit VelocityFormStep(Step s) : s_(std::move(s)) {}
  double step_size() const { return s_.step_size(); }
  const Step& inner() const { return s_; }
  StepSummary step(const V& q0, const V& p0, V& dq, V& dp) const {
    const auto& L = s_.lagrangian();
    const V v0 = legendre_inverse(L, q0, p0);
    V dv = V::Zero();
    if (last_valid_) dv = last_dv_;
    StepSummary s = s_.step_qv(q0, v0, dq, dv);
    if (s.converged) {
      dp = legendre(L, V(q0 + dq), V(v0 + dv)) - p0;
      last_dv_ = dv;
      last_valid_ = true;
    }
    return s;
  }

 private:
  Step s_;
  mutable V last_dv_ = V::Zero();
  mutable bool last_valid_ = false;
};

}  // namespace dvm
