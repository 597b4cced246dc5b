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
//   sode1 (Eq. 4.1, the "first option"):  R^2(Y0, h Gamma(Y0)) = R^1(Y1, h Gamma(Y1))
//   sode2 (Eq. 4.2):                       W = h Gamma(X)
// For a theta map of TQ sode1 is Y1 - Y0 = h ((1 - theta) Gamma(Y0) + theta Gamma(Y1))
// (explicit Euler at theta = 0, the trapezoidal rule at 1/2).
// With the midpoint map (or the tangent lift of the midpoint map on Q, which is the
// midpoint map of TQ) sode1 is the trapezoidal rule and sode2 the implicit midpoint
// rule: they agree for linear a and differ at O(h^3) per step otherwise (the paper's
// worked example after the two options in Sec. 4; tests/solvers/test_sode.cc measures
// it).
//
// Newmark (Newmark 1959; Hughes, The Finite Element Method, Sec. 9.1): with a_k = a(q_k, v_k)
//   q1 = q0 + h v0 + h^2 ((1/2 - beta) a0 + beta a1)
//   v1 = v0 + h ((1 - gamma) a0 + gamma a1),
// built as in the paper's Sec. 4.1: sode1 (Eq. 4.1) with the h-dependent map on TQ
//   R^1(q, v; qd, vd) = (q - qd/2 + (h/2)(gamma - 2 beta) vd,  v - gamma vd)
//   R^2(q, v; qd, vd) = (q + qd/2 + (h/2)(gamma - 2 beta) vd,  v + (1 - gamma) vd)
// (NewmarkMap below). Eq. 4.1, R^2(Y0, h Gamma(Y0)) = R^1(Y1, h Gamma(Y1)), reads
//   q0 + h v0/2 + (h^2/2)(gamma - 2 beta) a0 = q1 - h v1/2 + (h^2/2)(gamma - 2 beta) a1
//   v0 + h (1 - gamma) a0 = v1 - h gamma a1,
// and substituting the second row into the first gives the update above. (The paper's
// display of these two rows has -(h^2/2)(gamma - 2 beta) a1 on the right; with the map as
// the paper defines it the sign is +, which is what yields Newmark.) For gamma = 1/2,
// beta = 1/4 the map is the tangent lift of the midpoint map of Q, and Newmark is sode1
// through it, the trapezoidal rule.
// The adjoint method Phi*_h = (Phi_{-h})^{-1} is Newmark again, with
// gamma* = 1 - gamma, beta* = 1/2 - gamma + beta (symmetric exactly for gamma = 1/2).
// Linear stability on q'' = -w^2 q: for gamma >= 1/2 the method is unconditionally
// stable when 2 beta >= gamma, and stable only for w h < 1/sqrt(gamma/2 - beta)
// otherwise; for gamma < 1/2 it is unstable.
//
// Unknowns are the increments (dq, dv). Steps work in (q, v); VelocityFormStep adapts
// them to the (q, p) interface of the integrate loop through the Legendre map.
#pragma once

#include <array>
#include <stdexcept>
#include <utility>

#include "core/map_operations.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/lagrangian.h"
#include "solvers/newton_driver.h"

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
  Vec<double, 2 * N> x = stack(dq, dv);
  StepSummary s;
  try {
    s = solve_step_system<2 * N>(f, x, max_abs(Y0), options, s0);
  } catch (const std::domain_error& e) {
    s.fail(e.what());
  }
  dq = x.template head<N>();
  dv = x.template tail<N>();
  return s;
}

enum class SodeForm { sode1, sode2 };
inline const char* to_string(SodeForm f) { return f == SodeForm::sode1 ? "sode1" : "sode2"; }

// The paper's discretization map on TQ = R^{2n} of the Newmark family (Sec. 4.1), for the
// step h and the parameters (gamma, beta); a point X = (q, v), a velocity W = (qd, vd):
//   R^1(X, W) = (q - qd/2 + c vd, v - gamma vd),  R^2(X, W) = (q + qd/2 + c vd, v + (1 - gamma) vd),
// c = (h/2)(gamma - 2 beta). R(X, 0) = (X, X) and d/dW (R^2 - R^1) = Id (Def. 2.2). Its
// inverse is linear: W = Y1 - Y0, X = ((q0 + q1)/2 - c (v1 - v0), v0 + gamma (v1 - v0)).
// It is symmetric (its own adjoint) only for gamma = 1/2, beta = 1/4, where it is the
// tangent lift of the midpoint map (c = 0).
class NewmarkMap {
 public:
  static constexpr bool provides_inverse = true;
  NewmarkMap(double h, double gamma, double beta) : h_(h), gamma_(gamma), beta_(beta) {
    if (!std::isfinite(h) || !std::isfinite(gamma) || !std::isfinite(beta))
      throw std::invalid_argument("newmark map: h, gamma and beta must be finite");
  }
  std::string name() const { return "newmark-map"; }
  bool symmetric() const { return gamma_ == 0.5 && beta_ == 0.25; }
  int order() const { return symmetric() ? 2 : 1; }
  double step_size() const { return h_; }
  double gamma() const { return gamma_; }
  double beta() const { return beta_; }

  template <class T, int N2>
  PointPair<T, N2> operator()(const Vec<T, N2>& X, const Vec<T, N2>& W) const {
    const PointPair<T, N2> d = displacement(X, W);
    return {Vec<T, N2>(X + d.q0), Vec<T, N2>(X + d.q1)};
  }
  // R(X, W) - (X, X)
  template <class T, int N2>
  PointPair<T, N2> displacement(const Vec<T, N2>&, const Vec<T, N2>& W) const {
    static_assert(N2 != Eigen::Dynamic && N2 % 2 == 0, "a point of TQ has 2N coordinates");
    constexpr int N = N2 / 2;
    const double c = shift();
    PointPair<T, N2> r;
    for (int i = 0; i < N; ++i) {
      r.q0[i] = -0.5 * W[i] + c * W[N + i];
      r.q1[i] = 0.5 * W[i] + c * W[N + i];
      r.q0[N + i] = -gamma_ * W[N + i];
      r.q1[N + i] = (1.0 - gamma_) * W[N + i];
    }
    return r;
  }
  template <class T, int N2>
  TangentPoint<T, N2> inverse(const Vec<T, N2>& Y0, const Vec<T, N2>& Y1) const {
    return inverse_increment(Y0, Vec<T, N2>(Y1 - Y0));
  }
  template <class T, int N2>
  TangentPoint<T, N2> inverse_increment(const Vec<T, N2>& Y0, const Vec<T, N2>& dY) const {
    constexpr int N = N2 / 2;
    const double c = shift();
    TangentPoint<T, N2> t;
    t.v = dY;
    for (int i = 0; i < N; ++i) {
      t.x[i] = Y0[i] + 0.5 * dY[i] - c * dY[N + i];
      t.x[N + i] = Y0[N + i] + gamma_ * dY[N + i];
    }
    return t;
  }

 private:
  double shift() const { return 0.5 * h_ * (gamma_ - 2.0 * beta_); }
  double h_, gamma_, beta_;
};

// Discretization of the SODE of L by a map MapTQ on TQ = R^{2n}.
template <class System, class MapTQ>
class SodeStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using V2 = Vec<double, 2 * N>;

  SodeStep(System L, MapTQ R, double h, SodeForm form, StepOptions options = {})
      : L_(std::move(L)), R_(std::move(R)), h_(h), form_(form), options_(options) {
    // negative sizes are the backward substeps of compositions (solvers/composition.h)
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
  }
  double step_size() const { return h_; }
  const System& lagrangian() const { return L_; }
  SodeForm form() const { return form_; }
  const MapTQ& map() const { return R_; }
  const StepOptions& options() const { return options_; }
  std::string name() const { return std::string(to_string(form_)) + "(" + R_.name() + ")"; }

  template <class T>
  Vec<T, 2 * N> gamma(const Vec<T, 2 * N>& Y) const {
    const Vec<T, N> q = Y.template head<N>(), v = Y.template tail<N>();
    return stack(v, lagrangian_acceleration(L_, q, v));
  }

  template <class T>
  Vec<T, 2 * N> residual(const Vec<T, 2 * N>& Y0, const Vec<T, 2 * N>& dY) const {
    if (form_ == SodeForm::sode2) {
      const TangentPoint<T, 2 * N> t = inverse_increment(R_, Y0, dY);
      return t.v - h_ * gamma(t.x);
    }
    // the first option: R^2(Y0, h Gamma(Y0)) = R^1(Y1, h Gamma(Y1)), written as
    // R^1(Y1, .) - R^2(Y0, .) = dY + (R^1(Y1, .) - Y1) - (R^2(Y0, .) - Y0) through the
    // map's displacements, so that no point of size |Y| is formed and subtracted (for
    // the midpoint map it reads dY - h (Gamma(Y0) + Gamma(Y1))/2)
    const Vec<T, 2 * N> Y1 = Y0 + dY;
    const Vec<T, 2 * N> g0 = h_ * gamma(Y0), g1 = h_ * gamma(Y1);
    return Vec<T, 2 * N>(dY + displacement(R_, Y1, g1).q0 - displacement(R_, Y0, g0).q1);
  }

  // One step in (q, v); (dq, dv) carry the guess in and the increments out.
  StepSummary step_qv(double /*t*/, const V& q0, const V& v0, V& dq, V& dv) const {
    const V2 Y0 = stack(q0, v0);
    return solve_increments<N>(*this, Y0, std::fabs(h_) * max_abs(gamma(Y0)), options_, dq, dv);
  }

 private:
  System L_;
  MapTQ R_;
  double h_;
  SodeForm form_;
  StepOptions options_;
};

// Sec. 4.2, Eq. 4.3: the four points (R_d, R_d)(R_d^T(Gamma(q, v))) of Q for a map R_d on
// Q and a second-order vector field Gamma(q, v) = (v, a) at (q, v): with
// Y_i = (R^i(q, v), T R^i (v, a)) the two points of TQ given by the tangent lift,
// (R^1(Y_1), R^2(Y_1), R^1(Y_2), R^2(Y_2)). The map defines a second-order discrete
// equation through Gamma when the middle two coincide, R^2(Y_1) = R^1(Y_2) (Eq. 4.3):
// true for every theta map and for every map whose first point is the base point
// (R^1 = tau_Q, a retraction map), not in general.
template <class M, int N>
std::array<Vec<double, N>, 4> sode_diagram_points(const M& map, const Vec<double, N>& q, const Vec<double, N>& v,
                                                  const Vec<double, N>& a) {
  // R_d^T at the point (q, v) of TQ with velocity (v, a): TangentLift takes X = (q, v)
  // and V = (v, a) and differentiates R_d at (X.head, V.head) along (X.tail, V.tail)
  const PointPair<double, 2 * N> Y = tangent_lift(map)(stack(q, v), stack(v, a));
  auto point = [](const Vec<double, 2 * N>& y) { return std::make_pair(Vec<double, N>(y.template head<N>()), Vec<double, N>(y.template tail<N>())); };
  const auto [x1, u1] = point(Y.q0);
  const auto [x2, u2] = point(Y.q1);
  const PointPair<double, N> a1 = map(x1, u1), a2 = map(x2, u2);
  return {a1.q0, a1.q1, a2.q0, a2.q1};
}

// The Newmark family on the SODE of L: sode1 with the paper's NewmarkMap (see the top of
// this file).
template <class System>
class NewmarkStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using V2 = Vec<double, 2 * N>;
  using Sode = SodeStep<System, NewmarkMap>;

  NewmarkStep(System L, double h, double gamma, double beta, StepOptions options = {})
      : sode_(std::move(L), NewmarkMap(h, gamma, beta), h, SodeForm::sode1, options) {
    if (!(h > 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be positive and finite");
    if (!(gamma >= 0.0 && gamma <= 1.0) || !(beta >= 0.0 && beta <= 0.5))
      throw std::invalid_argument("newmark: expected gamma in [0, 1] and beta in [0, 1/2]");
  }
  double step_size() const { return sode_.step_size(); }
  double gamma() const { return sode_.map().gamma(); }
  double beta() const { return sode_.map().beta(); }
  const System& lagrangian() const { return sode_.lagrangian(); }
  const Sode& sode() const { return sode_; }
  std::string name() const { return "newmark"; }

  // The adjoint method (gamma, beta) -> (1 - gamma, 1/2 - gamma + beta). beta* may
  // leave [0, 1/2]; it is the adjoint stage of a composition, not a user choice, and
  // is not checked.
  NewmarkStep adjoint() const { return with(step_size(), 1.0 - gamma(), 0.5 - gamma() + beta()); }
  // The same method with step h (negative for the backward substeps of compositions);
  // the map depends on h and changes with it.
  NewmarkStep with_step(double h) const { return with(h, gamma(), beta()); }

  template <class T>
  Vec<T, 2 * N> residual(const Vec<T, 2 * N>& Y0, const Vec<T, 2 * N>& dY) const {
    return sode_.residual(Y0, dY);
  }
  StepSummary step_qv(double t, const V& q0, const V& v0, V& dq, V& dv) const {
    return sode_.step_qv(t, q0, v0, dq, dv);
  }

 private:
  explicit NewmarkStep(Sode s) : sode_(std::move(s)) {}
  NewmarkStep with(double h, double gamma, double beta) const {
    return NewmarkStep(Sode(lagrangian(), NewmarkMap(h, gamma, beta), h, SodeForm::sode1, sode_.options()));
  }
  Sode sode_;
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
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    const auto& L = s_.lagrangian();
    const V v0 = legendre_inverse(L, q0, p0);
    V dv = V::Zero();
    if (last_valid_) dv = last_dv_;
    StepSummary s = s_.step_qv(t, q0, v0, dq, dv);
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
