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
//   v1 = v0 + h ((1 - gamma) a0 + gamma a1).
// As an instance of the SODE machinery (a reconstruction: the paper's construction of
// Sec. 4.1 was not available when this was written). The map is R^{TTQ}, the tangent
// lift of the explicit-Euler map of Q, a map on TTQ:
//   R^{TTQ}(q, v; dq, dv) = ((q, v), (q + dq, v + dv)),
// which is the explicit-Euler map of TQ (tests/solvers/test_sode.cc checks the two
// agree), so (X, W) = (R^{TTQ})^{-1}(Y0, Y1) = (Y0, Y1 - Y0). The vector of T_{Y0}TQ
// that W is asked to equal is h times the Newmark quadrature of Gamma along the step,
//   N^{gamma,beta}(Y0, Y1) = (v0 + h ((1/2 - beta) a0 + beta a1),  (1 - gamma) a0 + gamma a1),
// an end-point sampling with the weights (gamma, beta): W = h N^{gamma,beta}(Y0, Y1).
// W = h N is the classical update above, term by term. For gamma = 1/2, beta = 1/4
// the velocity row gives h (a0 + a1)/2 = v1 - v0, so the position row is
// h (v0 + (v1 - v0)/2) = h (v0 + v1)/2: N = (Gamma(Y0) + Gamma(Y1))/2, the trapezoidal
// rule, which is sode1 through the midpoint map of TQ (tested to round-off on the
// pendulum).
// Why the weights have to sit in the sampling and cannot sit in the map alone: every
// map on TQ that does not depend on h and satisfies Def. 2.2 with a linear inverse
// (the theta maps of TQ and their tangent-lift forms) has W = Y1 - Y0, and its
// sampled vector is h times a combination of Gamma(Y0) = (v0, a0), Gamma(Y1) =
// (v1, a1) or Gamma(X). A single sample Gamma(X) cannot give the two accelerations a0
// and a1 of a nonlinear a, and end-point samples give the position row
// h (c0 v0 + c1 v1) = h v0 + c1 h^2 ((1 - gamma) a0 + gamma a1), i.e. only beta = gamma/2
// (c1 = 1/2); the h^2 weights (1/2 - beta, beta) of the general member need the
// quadrature above.
// The adjoint method Phi*_h = (Phi_{-h})^{-1} is Newmark again, with
// gamma* = 1 - gamma, beta* = 1/2 - gamma + beta (symmetric exactly for gamma = 1/2).
// Linear stability on q'' = -w^2 q: for gamma >= 1/2 the method is unconditionally
// stable when 2 beta >= gamma, and stable only for w h < 1/sqrt(gamma/2 - beta)
// otherwise; for gamma < 1/2 it is unstable.
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

enum class SodeForm { sode1, sode2, newmark };
inline const char* to_string(SodeForm f) {
  return f == SodeForm::sode1 ? "sode1" : f == SodeForm::sode2 ? "sode2" : "newmark";
}

// How a SODE step samples the vector field: the form, and Newmark's weights (used by
// SodeForm::newmark only).
struct SodeSampling {
  SodeForm form = SodeForm::sode2;
  double gamma = 0.5, beta = 0.25;
  SodeSampling(SodeForm f) : form(f) {}  // implicit: a form is a sampling
  static SodeSampling newmark(double gamma, double beta) {
    SodeSampling s(SodeForm::newmark);
    s.gamma = gamma;
    s.beta = beta;
    return s;
  }
};

// Discretization of the SODE of L by a map MapTQ on TQ = R^{2n}.
template <class System, class MapTQ>
class SodeStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using V2 = Vec<double, 2 * N>;

  SodeStep(System L, MapTQ R, double h, SodeSampling sampling, StepOptions options = {})
      : L_(std::move(L)), R_(std::move(R)), h_(h), sampling_(sampling), options_(options) {
    // negative sizes are the backward substeps of compositions (solvers/composition.h)
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
  }
  double step_size() const { return h_; }
  const System& lagrangian() const { return L_; }
  SodeForm form() const { return sampling_.form; }
  const SodeSampling& sampling() const { return sampling_; }
  void set_step_size(double h) {
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
    h_ = h;
  }
  void set_sampling(const SodeSampling& s) { sampling_ = s; }
  std::string name() const { return std::string(to_string(sampling_.form)) + "(" + R_.name() + ")"; }

  template <class T>
  Vec<T, 2 * N> gamma(const Vec<T, 2 * N>& Y) const {
    const Vec<T, N> q = Y.template head<N>(), v = Y.template tail<N>();
    return stack(v, lagrangian_acceleration(L_, q, v));
  }

  template <class T>
  Vec<T, 2 * N> residual(const Vec<T, 2 * N>& Y0, const Vec<T, 2 * N>& dY) const {
    const TangentPoint<T, 2 * N> t = inverse_increment(R_, Y0, dY);
    if (sampling_.form == SodeForm::sode2) return t.v - h_ * gamma(t.x);
    const Vec<T, 2 * N> Y1 = Y0 + dY;
    if (sampling_.form == SodeForm::sode1) {
      // the first option: R^2(Y0, h Gamma(Y0)) = R^1(Y1, h Gamma(Y1)), written as
      // R^1(Y1, .) - R^2(Y0, .) so that for the midpoint map it reads
      // dY - h (Gamma(Y0) + Gamma(Y1))/2
      const Vec<T, 2 * N> g0 = h_ * gamma(Y0), g1 = h_ * gamma(Y1);
      return Vec<T, 2 * N>(R_(Y1, g1).q0 - R_(Y0, g0).q1);
    }
    // Newmark's quadrature N^{gamma,beta}(Y0, Y1) of Gamma
    const double g = sampling_.gamma, b = sampling_.beta;
    const Vec<T, N> v0 = Y0.template tail<N>();
    const Vec<T, N> a0 = lagrangian_acceleration(L_, Vec<T, N>(Y0.template head<N>()), v0);
    const Vec<T, N> a1 = lagrangian_acceleration(L_, Vec<T, N>(Y1.template head<N>()), Vec<T, N>(Y1.template tail<N>()));
    const Vec<T, N> Nq = v0 + h_ * ((0.5 - b) * a0 + b * a1), Nv = (1.0 - g) * a0 + g * a1;
    return t.v - h_ * stack(Nq, Nv);
  }

  // One step in (q, v); (dq, dv) carry the guess in and the increments out.
  StepSummary step_qv(const V& q0, const V& v0, V& dq, V& dv) const {
    const V2 Y0 = stack(q0, v0);
    return solve_increments<N>(*this, Y0, std::fabs(h_) * max_abs(gamma(Y0)), options_, dq, dv);
  }

 private:
  System L_;
  MapTQ R_;
  double h_;
  SodeSampling sampling_;
  StepOptions options_;
};

// The Newmark family on the SODE of L: the SODE step of the map R^{TTQ} (the
// explicit-Euler map of TQ) with Newmark's sampling (see the top of this file).
template <class System>
class NewmarkStep {
 public:
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  using V2 = Vec<double, 2 * N>;
  using Sode = SodeStep<System, ThetaMap>;

  NewmarkStep(System L, double h, double gamma, double beta, StepOptions options = {})
      : sode_(std::move(L), ThetaMap::explicit_euler(), h, SodeSampling::newmark(gamma, beta), options) {
    if (!(h > 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be positive and finite");
    if (!(gamma >= 0.0 && gamma <= 1.0) || !(beta >= 0.0 && beta <= 0.5))
      throw std::invalid_argument("newmark: expected gamma in [0, 1] and beta in [0, 1/2]");
  }
  double step_size() const { return sode_.step_size(); }
  double gamma() const { return sode_.sampling().gamma; }
  double beta() const { return sode_.sampling().beta; }
  const System& lagrangian() const { return sode_.lagrangian(); }
  const Sode& sode() const { return sode_; }
  std::string name() const { return "newmark"; }

  // The adjoint method (gamma, beta) -> (1 - gamma, 1/2 - gamma + beta). beta* may
  // leave [0, 1/2]; it is the adjoint stage of a composition, not a user choice, and
  // is not checked.
  NewmarkStep adjoint() const {
    NewmarkStep a = *this;
    a.sode_.set_sampling(SodeSampling::newmark(1.0 - gamma(), 0.5 - gamma() + beta()));
    return a;
  }
  // The same method with step h (negative for the backward substeps of compositions).
  NewmarkStep with_step(double h) const {
    NewmarkStep a = *this;
    a.sode_.set_step_size(h);
    return a;
  }

  template <class T>
  Vec<T, 2 * N> residual(const Vec<T, 2 * N>& Y0, const Vec<T, 2 * N>& dY) const {
    return sode_.residual(Y0, dY);
  }
  StepSummary step_qv(const V& q0, const V& v0, V& dq, V& dv) const { return sode_.step_qv(q0, v0, dq, dv); }

 private:
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
