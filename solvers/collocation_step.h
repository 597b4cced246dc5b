// The Galerkin step with Gauss quadrature on a separable Lagrangian, as Gauss
// collocation iterated on the stage forces.
//
// For L(q, v) = v^T M v / 2 - V(q) with M constant (mechanics/structure.h), the Galerkin
// discrete Lagrangian of degree s with s Gauss points (solvers/galerkin_step.h) gives
// the s-stage Gauss collocation method for q' = v, M v' = F(q), F = -grad V (Marsden
// and West, Acta Numerica 2001, Thm 2.6.1 and Sec. 2.6.3; Hairer, Lubich, Wanner,
// Geometric Numerical Integration (GNI), VI.6.3). With the Gauss coefficients
// (c_i, b_i, a_ij = int_0^{c_i} l_j, l_j the Lagrange basis on the c's), eliminating the
// stage velocities gives the Nystrom form (GNI II.2.3): with a = M^{-1} F and
// v0 = M^{-1} p0, the stage increments Z_i = Q_i - q0 solve
//   Z_i = c_i h v0 + h^2 sum_j abar_ij a(q0 + Z_j),          abar = A^2,
// and then
//   q1 = q0 + h v0 + h^2 sum_i bbar_i a(Q_i),               bbar = b^T A,
//   p1 = p0 + h sum_i b_i F(Q_i),
// p1 being the Galerkin step's own momentum update (the quadrature of the force).
//
// The stage equations are solved by fixed-point iteration, as the collocation codes
// for second-order systems do (GNI VIII.6; Hairer's gni_irk2): each sweep costs s
// forces and s solves with M (a division for a diagonal M), no Jacobian. The
// iteration contracts like h^2 |abar| |M^{-1} d2V|; it stops when the change of Z is
// below StepOptions::residual_tolerance times |Z| + |q0|, or when it stops decreasing
// below stall_tolerance times that (the round-off plateau). A sweep that grows the
// change above that, a non-finite sweep or max_iterations sweeps hand the step to the
// simplified Newton iteration of the generic Galerkin step (GalerkinStep, or
// DynamicGalerkinStep for run-time-sized systems; the same equations), built on first
// use; newton_steps() counts such steps.
//
// Starting guess. The collocation polynomial u of degree s through (0, 0) and
// (c_i, Z_i) (in units of h, relative to q0) ends at u(1) = q1 - q0, so the next step's
// stages are guessed by extrapolation, Z_i' = u(1 + c_i) - u(1) = sum_k E_ik Z_k, and
// corrected as galerkin_step.h corrects its nodes: the errors d_n of that extrapolation
// at the last two steps are extrapolated in the step index, Z' = E Z + 2 d_n - d_{n-1}.
// A step that does not continue the previous one starts from Z_i = c_i h v0. Measured on
// Kepler (e = 0.6, s = 6, 8000 steps of h = 0.125): 3.74 sweeps a step, 5.5 from c h v0
// at every step, 3.75 without the correction (at h = 0.0625: 2.71 against 2.83).
//
// Sizes: fixed N for built-ins, or run-time (mechanics/dynamic_system.h); stage count S
// at compile time, or S = 0 for 1..kGalerkinMaxStages at run time in fixed-capacity
// storage. No allocation per step (the generic step's first use allocates it). The
// answer equals the generic Galerkin step's to round-off (tests/solvers/test_collocation.cc).
#pragma once

#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "mechanics/quadrature.h"
#include "mechanics/separable.h"
#include "solvers/dynamic_galerkin_step.h"
#include "solvers/galerkin_step.h"
#include "solvers/integrate.h"
#include "solvers/newton.h"

namespace dvm {

// The Nystrom coefficients of s-stage Gauss collocation (computed in long double):
// c_i, b_i, abar = A^2, bbar = b^T A, and the extrapolation E of the collocation
// polynomial to the next step's stages (see above).
struct GaussNystromTables {
  int s = 0;
  std::array<double, kGalerkinMaxStages> c{}, b{}, bbar{};
  std::array<std::array<double, kGalerkinMaxStages>, kGalerkinMaxStages> abar{}, E{};

  explicit GaussNystromTables(int stages) : s(stages) {
    const Quadrature quad(QuadratureKind::gauss, s);
    using LD = long double;
    // l_j(t), the Lagrange basis on the nodes c_1..c_s
    auto lagrange = [&](int j, LD t) {
      LD l = 1.0L;
      for (int k = 0; k < s; ++k)
        if (k != j) l *= (t - quad.c[k]) / (quad.c[j] - quad.c[k]);
      return l;
    };
    // L_k(t), the Lagrange basis on the nodes 0, c_1..c_s, for the node c_k
    auto with_zero = [&](int k, LD t) {
      LD l = t / quad.c[k];
      for (int m = 0; m < s; ++m)
        if (m != k) l *= (t - quad.c[m]) / (quad.c[k] - quad.c[m]);
      return l;
    };
    std::array<std::array<LD, kGalerkinMaxStages>, kGalerkinMaxStages> A{};
    for (int i = 0; i < s; ++i)
      for (int j = 0; j < s; ++j) {
        // int_0^{c_i} l_j = c_i sum_m b_m l_j(c_i c_m): Gauss with s points is exact for
        // degree 2s - 1 >= s - 1
        LD sum = 0.0L;
        for (int m = 0; m < s; ++m) sum += quad.b[m] * lagrange(j, quad.c[i] * quad.c[m]);
        A[i][j] = quad.c[i] * sum;
      }
    for (int i = 0; i < s; ++i) {
      c[i] = static_cast<double>(quad.c[i]);
      b[i] = static_cast<double>(quad.b[i]);
      LD bb = 0.0L;
      for (int k = 0; k < s; ++k) bb += quad.b[k] * A[k][i];
      bbar[i] = static_cast<double>(bb);
      for (int j = 0; j < s; ++j) {
        LD a2 = 0.0L;
        for (int k = 0; k < s; ++k) a2 += A[i][k] * A[k][j];
        abar[i][j] = static_cast<double>(a2);
        E[i][j] = static_cast<double>(with_zero(j, 1.0L + quad.c[i]) - with_zero(j, 1.0L));
      }
    }
  }
};

// Sys: the separable system (its force and M^{-1}); Full: the same Lagrangian as the
// generic step takes it (WrittenDynamic for a WrittenSeparable view of it), Sys itself
// by default.
template <class Sys, int S = 0, class Full = Sys>
class SeparableGaussStep {
  static_assert(S >= 0 && S <= kGalerkinMaxStages, "Gauss collocation stages 1..6 (0: chosen at run time)");

 public:
  static constexpr int N = state_size<Sys>::value;  // Sys::dim, or Eigen::Dynamic
  static constexpr int SMax = S > 0 ? S : kGalerkinMaxStages;
  static constexpr bool takes_guess = false;  // the step makes its own guess
  static constexpr int Cols = S > 0 ? S : Eigen::Dynamic;
  using V = Vec<double, N>;
  // the s stages as columns
  // (one row for a system of one coordinate: Eigen stores it row-major)
  using Stages = std::conditional_t<
      N == Eigen::Dynamic, Eigen::MatrixXd,
      Eigen::Matrix<double, N, Cols, N == 1 && SMax != 1 ? Eigen::RowMajor : Eigen::ColMajor, N, SMax>>;
  // the generic step it hands a step to when the fixed point does not converge (its
  // stage count at run time: one instantiation serves every S)
  using Generic = std::conditional_t<N == Eigen::Dynamic, DynamicGalerkinStep<Full>, GalerkinStep<Full>>;

  // q_ref: a point where L is defined (mechanics/separable.h reads M there when Sys has
  // no closed-form velocity). max_newton_dim: the largest n for which a step may be
  // handed to the generic step (its s n x s n dense Jacobian); beyond it such a step
  // fails with a message instead.
  template <class F = Full, std::enable_if_t<std::is_same_v<F, Sys>, int> = 0>
  SeparableGaussStep(Sys L, int stages, double h, StepOptions options, const V& q_ref,
                     Eigen::Index max_newton_dim = std::numeric_limits<Eigen::Index>::max())
      : SeparableGaussStep(L, L, stages, h, options, q_ref, max_newton_dim) {}

  SeparableGaussStep(Sys L, Full full, int stages, double h, StepOptions options, const V& q_ref,
                     Eigen::Index max_newton_dim = std::numeric_limits<Eigen::Index>::max())
      : parts_(std::move(L), q_ref),
        full_(std::move(full)),
        s_(check_stages(stages)),
        h_(h),
        options_(options),
        max_newton_dim_(max_newton_dim),
        t_(stages) {
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
    const Eigen::Index n = parts_.dim();
    for (int i = 0; i < s_; ++i) {
      hc_[i] = h * t_.c[i];
      hb_[i] = h * t_.b[i];
      h2bbar_[i] = h * h * t_.bbar[i];
      for (int j = 0; j < s_; ++j) h2abar_[i][j] = h * h * t_.abar[i][j];
    }
    v0_ = x_ = f_ = a_ = q_end_ = V::Zero(n);
    Z_ = Znew_ = Zprev_ = F_ = Acc_ = Stages::Zero(n, s_);
    Zext_ = Stages::Zero(n, s_);
    guess_.zero_like(Zext_);
  }

  double step_size() const { return h_; }
  int stages() const { return s_; }
  int order() const { return 2 * s_; }
  // Steps handed to the generic Newton iteration since construction.
  long newton_steps() const { return newton_steps_; }
  // Forces evaluated by the fixed-point sweeps since construction (s per sweep).
  long forces() const { return forces_; }

  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const {
    StepSummary sum;
    const int s = s_;
    parts_.velocity(q0, p0, v0_);
    const double qsize = max_abs(q0);
    const bool continues = have_prev_ && max_abs(q0 - q_end_) <= 1e-12 * (qsize + dq_size_) + 1e-300;
    have_prev_ = false;
    if (continues) {
      extrapolate();  // Zext_ = E Zprev_
      Z_ = Zext_ + guess_.correction();
    } else {
      for (int i = 0; i < s; ++i) Z_.col(i) = hc_[i] * v0_;
      guess_.forget();
    }
    double dn_prev = INFINITY;
    int it = 0;
    bool converged = false;
    while (it < options_.max_iterations) {
      ++it;
      sweep(q0);  // Znew_ = G(Z_); F_, Acc_ at Z_
      const double dn = max_abs(Znew_ - Z_), zn = max_abs(Znew_);  // NaN if any entry is
      Z_.swap(Znew_);
      const double scale = zn + qsize + options_.absolute_floor;
      sum.residual = last_change_ = dn;
      sum.scale = scale;
      if (!std::isfinite(dn)) break;
      // The forces of this sweep were taken at the Z before the change dn, so dq and dp
      // are as accurate as that Z: the step is accepted when the change itself is
      // below the tolerance (not when the changes still to come would be, as simplified
      // Newton judges: that leaves an error of |dF/dq| dn in every dp, measured 5e-8
      // after 8000 Kepler steps at s = 6 against 5e-11).
      if (dn <= options_.residual_tolerance * scale || (dn >= dn_prev && dn <= options_.stall_tolerance * scale)) {
        converged = true;  // (the second: at the round-off plateau)
        break;
      }
      if (dn >= dn_prev) break;  // not contracting
      dn_prev = dn;
    }
    if (!converged) return by_newton(t, q0, p0, dq, dp, it);
    // the end point and momentum from the forces of the last sweep
    dq = h_ * v0_;
    dp.setZero(parts_.dim());
    for (int i = 0; i < s; ++i) {
      dq += h2bbar_[i] * Acc_.col(i);
      dp += hb_[i] * F_.col(i);
    }
    sum.iterations = it;
    sum.converged = true;
    if (continues) {
      guess_.record(Z_, Zext_);
    }
    Zprev_ = Z_;
    q_end_ = q0 + dq;
    dq_size_ = max_abs(dq);
    have_prev_ = true;
    return sum;
  }

 private:
  static int check_stages(int s) { return check_galerkin_stages(s, S); }

  // One fixed-point sweep: the forces and accelerations at q0 + Z_, and
  // Znew_ = c h v0 + h^2 abar Acc.
  void sweep(const V& q0) const {
    const int s = s_;
    for (int j = 0; j < s; ++j) {
      x_ = q0 + Z_.col(j);
      parts_.force(x_, f_);
      parts_.velocity(x_, f_, a_);
      F_.col(j) = f_;
      Acc_.col(j) = a_;
    }
    forces_ += s;
    for (int i = 0; i < s; ++i) {
      Znew_.col(i) = hc_[i] * v0_;
      for (int j = 0; j < s; ++j) Znew_.col(i) += h2abar_[i][j] * Acc_.col(j);
    }
  }

  // Zext_ = the previous step's collocation polynomial at this step's stages.
  void extrapolate() const {
    const int s = s_;
    for (int i = 0; i < s; ++i) {
      Zext_.col(i) = t_.E[i][0] * Zprev_.col(0);
      for (int k = 1; k < s; ++k) Zext_.col(i) += t_.E[i][k] * Zprev_.col(k);
    }
  }

  // The step by the generic Galerkin step's simplified Newton iteration, from the
  // guess dq = h v0 + h^2 a(q0) / 2.
  StepSummary by_newton(double t, const V& q0, const V& p0, V& dq, V& dp, int sweeps) const {
    guess_.forget();
    if (parts_.dim() > max_newton_dim_) {
      StepSummary f = step_fault("the fixed-point iteration of the Gauss collocation stages does not converge (last "
                                 "change " + std::to_string(last_change_) + ") and a Newton iteration would need dense " +
                                 std::to_string(s_ * parts_.dim()) + " x " + std::to_string(s_ * parts_.dim()) +
                                 " matrices; a smaller step converges",
                                 last_change_, sweeps);
      return f;
    }
    if (!generic_) generic_.emplace(full_, QuadratureKind::gauss, s_, h_, options_);
    parts_.force(q0, f_);
    parts_.velocity(q0, f_, a_);
    dq = h_ * v0_ + (0.5 * h_ * h_) * a_;
    StepSummary g = generic_->step(t, q0, p0, dq, dp);
    g.iterations += sweeps;  // (the sweeps form no Jacobian)
    ++newton_steps_;
    return g;
  }

  SeparableParts<Sys> parts_;
  Full full_;
  int s_;
  double h_;
  StepOptions options_;
  Eigen::Index max_newton_dim_;
  GaussNystromTables t_;
  // h c_i, h b_i, h^2 bbar_i, h^2 abar_ij
  std::array<double, SMax> hc_{}, hb_{}, h2bbar_{};
  std::array<std::array<double, SMax>, SMax> h2abar_{};
  // workspace and the state carried from step to step
  mutable V v0_, x_, f_, a_, q_end_;
  mutable Stages Z_, Znew_, Zprev_, F_, Acc_, Zext_;
  mutable ExtrapolationErrors<Stages> guess_;
  mutable bool have_prev_ = false;
  mutable double dq_size_ = 0.0, last_change_ = NAN;
  mutable long newton_steps_ = 0, forces_ = 0;
  mutable std::optional<Generic> generic_;
};

}  // namespace dvm
