// SODE discretizations (Eq. 4.1 and 4.2) from maps on TQ, and the Newmark family from
// the paper's map on TQ (Sec. 4.1): the two SODE forms differ, the Newmark map is a
// discretization map with the paper's Jacobian, Newmark equals the classical update,
// and its orders and stability thresholds on q'' = -w^2 q are where the theory puts them.
#define BOOST_TEST_MODULE sode
#include <boost/test/unit_test.hpp>

#include <Eigen/Eigenvalues>
#include <tuple>
#include <vector>

#include "core/map_checks.h"
#include "mechanics/systems.h"
#include "solvers/integrate.h"
#include "solvers/sode_step.h"

using namespace dvm;
using V1 = Vec<double, 1>;
using V2 = Vec<double, 2>;

namespace {

// A retraction of R that is not affine, R_x(v) = x + v + v^2/2: its discretization map
// (Prop. 2.3) and that map's tangent lift are nonlinear and inverted by Newton.
struct CurvedRetraction {
  std::string name() const { return "curved"; }
  template <class T, int N>
  Vec<T, N> retract(const Vec<T, N>& x, const Vec<T, N>& v) const {
    Vec<T, N> out(x.rows());
    for (int i = 0; i < x.rows(); ++i) out[i] = x[i] + v[i] + 0.5 * v[i] * v[i];
    return out;
  }
};

template <class Step>
std::pair<V1, V1> one_step(const Step& S, const V1& q0, const V1& v0) {
  V1 dq = S.step_size() * v0, dv = V1::Zero();
  const StepSummary s = S.step_qv(0.0, q0, v0, dq, dv);
  BOOST_REQUIRE(s.converged);
  return {V1(q0 + dq), V1(v0 + dv)};
}

// n steps of S from (q, v), guess h v for the position increment.
template <class Step>
std::pair<V1, V1> n_steps(const Step& S, V1 q, V1 v, int n) {
  for (int i = 0; i < n; ++i) std::tie(q, v) = one_step(S, q, v);
  return {q, v};
}

}  // namespace

BOOST_AUTO_TEST_CASE(acceleration_of_the_euler_lagrange_equations) {
  const Pendulum P(2.0, 0.5, 9.81);
  const V1 a = lagrangian_acceleration(P, V1(0.7), V1(1.1));
  BOOST_TEST(std::fabs(a[0] + 9.81 / 0.5 * std::sin(0.7)) <= 1e-13);
  const V2 k = lagrangian_acceleration(Kepler(1.5), V2(0.6, -0.8), V2(0.3, 0.2));
  BOOST_TEST(std::fabs(k[0] + 1.5 * 0.6) <= 1e-14);
  BOOST_TEST(std::fabs(k[1] - 1.5 * 0.8) <= 1e-14);
}

BOOST_AUTO_TEST_CASE(midpoint_forms_are_trapezoidal_and_implicit_midpoint_and_differ) {
  // The tangent lift of the midpoint map on Q is the midpoint map on TQ; sode1 is then
  // the trapezoidal rule and sode2 the implicit midpoint rule.
  const Pendulum P;
  const auto lift = tangent_lift(ThetaMap::midpoint());
  const double h = 0.1;
  const V1 q0(1.2), v0(0.3);
  const auto [q1, v1] = one_step(SodeStep<Pendulum, decltype(lift)>(P, lift, h, SodeForm::sode1), q0, v0);
  const auto [q2, v2] = one_step(SodeStep<Pendulum, decltype(lift)>(P, lift, h, SodeForm::sode2), q0, v0);
  // each satisfies its own equations
  BOOST_TEST(std::fabs(q1[0] - q0[0] - 0.5 * h * (v0[0] + v1[0])) <= 1e-15);
  BOOST_TEST(std::fabs(v1[0] - v0[0] + 0.5 * h * (std::sin(q0[0]) + std::sin(q1[0]))) <= 1e-15);
  BOOST_TEST(std::fabs(q2[0] - q0[0] - 0.5 * h * (v0[0] + v2[0])) <= 1e-15);
  BOOST_TEST(std::fabs(v2[0] - v0[0] + h * std::sin(0.5 * (q0[0] + q2[0]))) <= 1e-15);
  // and they differ (7.5e-6 at h = 0.1, ten orders above round-off), by O(h^3):
  // in the asymptotic range halving h divides the difference by about 8
  const double d = std::fabs(v1[0] - v2[0]);
  BOOST_TEST_MESSAGE("|v(sode1) - v(sode2)| at h = 0.1: " << d);
  BOOST_TEST(d >= 1e-6);
  auto diff = [&](double hh) {
    const auto a1 = one_step(SodeStep<Pendulum, decltype(lift)>(P, lift, hh, SodeForm::sode1), q0, v0);
    const auto a2 = one_step(SodeStep<Pendulum, decltype(lift)>(P, lift, hh, SodeForm::sode2), q0, v0);
    return std::fabs(a1.second[0] - a2.second[0]);
  };
  const double ratio = diff(h / 4) / diff(h / 8);
  BOOST_TEST(std::log2(ratio) >= 2.8);
  BOOST_TEST(std::log2(ratio) <= 3.2);
  // For a linear SODE (harmonic oscillator) both are the Cayley transform: equal.
  const HarmonicOscillator H(2.0);
  const auto l1 = one_step(SodeStep<HarmonicOscillator, decltype(lift)>(H, lift, h, SodeForm::sode1), q0, v0);
  const auto l2 = one_step(SodeStep<HarmonicOscillator, decltype(lift)>(H, lift, h, SodeForm::sode2), q0, v0);
  BOOST_TEST(std::fabs(l1.first[0] - l2.first[0]) <= 1e-15);
  BOOST_TEST(std::fabs(l1.second[0] - l2.second[0]) <= 1e-15);
}

BOOST_AUTO_TEST_CASE(tangent_lift_of_theta_map_equals_theta_map_on_TQ) {
  const Pendulum P;
  const double h = 0.05;
  for (double th : {0.0, 0.3, 1.0})
    for (SodeForm f : {SodeForm::sode1, SodeForm::sode2}) {
      const auto lift = tangent_lift(ThetaMap(th));
      const auto a = one_step(SodeStep<Pendulum, decltype(lift)>(P, lift, h, f), V1(0.4), V1(-0.9));
      const auto b = one_step(SodeStep<Pendulum, ThetaMap>(P, ThetaMap(th), h, f), V1(0.4), V1(-0.9));
      BOOST_TEST(std::fabs(a.first[0] - b.first[0]) <= 1e-15);
      BOOST_TEST(std::fabs(a.second[0] - b.second[0]) <= 1e-15);
    }
}

BOOST_AUTO_TEST_CASE(sode_orders_for_linear_and_nonlinear_maps) {
  // Error at t = 1 on the harmonic oscillator against the exact flow, for the tangent
  // lift of the theta maps and of a curved (non-affine) retraction map, inverted by
  // Newton: order 2 for symmetric maps, 1 otherwise, in both forms.
  const HarmonicOscillator H(1.0);
  auto order_of = [&](const auto& map, SodeForm f) {
    std::vector<double> err;
    for (int k = 0; k < 3; ++k) {
      const int n = 20 << k;
      const SodeStep<HarmonicOscillator, std::decay_t<decltype(map)>> S(H, map, 1.0 / n, f);
      const auto [q, v] = n_steps(S, V1(1.0), V1(0.5), n);
      V1 qe, pe;
      H.exact(1.0, V1(1.0), V1(0.5), qe, pe);
      err.push_back(std::fmax(std::fabs(q[0] - qe[0]), std::fabs(v[0] - pe[0])));
    }
    return std::log2(err[1] / err[2]);
  };
  const RetractionMap<CurvedRetraction> curved({}, 0.3);
  for (SodeForm f : {SodeForm::sode1, SodeForm::sode2}) {
    BOOST_TEST(std::fabs(order_of(tangent_lift(ThetaMap::midpoint()), f) - 2.0) <= 0.05);
    BOOST_TEST(std::fabs(order_of(tangent_lift(curved), f) - 1.0) <= 0.1);
  }
  // sode2 samples Gamma at the base point, which the theta map places off-centre:
  // order 1.
  BOOST_TEST(std::fabs(order_of(tangent_lift(ThetaMap(0.3)), SodeForm::sode2) - 1.0) <= 0.1);
  // sode1 through the theta map weighs the end points (1 - theta, theta): order 1 for
  // theta in {0, 0.3, 1} (explicit Euler of TQ at 0), order 2 at 1/2 (above).
  for (double th : {0.0, 0.3, 1.0})
    BOOST_TEST(std::fabs(order_of(tangent_lift(ThetaMap(th)), SodeForm::sode1) - 1.0) <= 0.1, "theta " << th);
}

BOOST_AUTO_TEST_CASE(sode1_is_the_first_option_of_the_paper) {
  // Sec. 4: R^2(Y0, h Gamma(Y0)) = R^1(Y1, h Gamma(Y1)). For the theta map of TQ (the
  // tangent lift of the theta map of Q) that is
  // Y1 - Y0 = h ((1 - theta) Gamma(Y0) + theta Gamma(Y1)): explicit Euler at theta = 0,
  // written out here on the pendulum (a = -(g/l) sin q), and the implicit equations
  // checked to round-off at theta = 0.3 and 1.
  const Pendulum P(1.0, 2.0, 9.81);
  const double h = 0.05, w = 9.81 / 2.0;
  const V1 q0(1.1), v0(-0.4);
  const auto lift0 = tangent_lift(ThetaMap(0.0));
  const auto [qe, ve] = one_step(SodeStep<Pendulum, decltype(lift0)>(P, lift0, h, SodeForm::sode1), q0, v0);
  BOOST_TEST(std::fabs(qe[0] - (q0[0] + h * v0[0])) <= 1e-15);
  BOOST_TEST(std::fabs(ve[0] - (v0[0] - h * w * std::sin(q0[0]))) <= 1e-15);
  for (double th : {0.3, 1.0}) {
    const auto lift = tangent_lift(ThetaMap(th));
    const auto [q1, v1] = one_step(SodeStep<Pendulum, decltype(lift)>(P, lift, h, SodeForm::sode1), q0, v0);
    BOOST_TEST_CONTEXT("theta " << th) {
      BOOST_TEST(std::fabs(q1[0] - q0[0] - h * ((1 - th) * v0[0] + th * v1[0])) <= 1e-15);
      BOOST_TEST(std::fabs(v1[0] - v0[0] + h * w * ((1 - th) * std::sin(q0[0]) + th * std::sin(q1[0]))) <= 1e-15);
    }
  }
}

namespace {

// The classical Newmark update in acceleration form, written independently: solve
// a1 = a(q~ + beta h^2 a1, v~ + gamma h a1) for a1 (scalar Newton on the pendulum),
// with predictors q~ = q0 + h v0 + (1/2 - beta) h^2 a0, v~ = v0 + (1 - gamma) h a0.
void classical_newmark_pendulum(double g_over_l, double h, double gamma, double beta, double& q, double& v) {
  const double a0 = -g_over_l * std::sin(q);
  const double qt = q + h * v + (0.5 - beta) * h * h * a0, vt = v + (1.0 - gamma) * h * a0;
  double a1 = a0;
  for (int it = 0; it < 50; ++it) {
    const double F = a1 + g_over_l * std::sin(qt + beta * h * h * a1);
    const double dF = 1.0 + g_over_l * std::cos(qt + beta * h * h * a1) * beta * h * h;
    a1 -= F / dF;
    if (std::fabs(F) < 1e-17) break;
  }
  q = qt + beta * h * h * a1;
  v = vt + gamma * h * a1;
}

// The 2x2 amplification matrix of a Newmark step on q'' = -w^2 q, and its spectral radius.
double newmark_spectral_radius(double wh, double gamma, double beta) {
  const double w = 1.0, h = wh / w;
  const NewmarkStep<HarmonicOscillator> S(HarmonicOscillator(w), h, gamma, beta);
  Mat<double, 2, 2> A;
  for (int c = 0; c < 2; ++c) {
    const V1 q0(c == 0 ? 1.0 : 0.0), v0(c == 1 ? 1.0 : 0.0);
    V1 dq = V1::Zero(), dv = V1::Zero();
    BOOST_REQUIRE(S.step_qv(0.0, q0, v0, dq, dv).converged);
    A(0, c) = q0[0] + dq[0];
    A(1, c) = v0[0] + dv[0];
  }
  return Eigen::EigenSolver<Mat<double, 2, 2>>(A).eigenvalues().cwiseAbs().maxCoeff();
}

// Largest |q| over 2000 steps from (1, 0): bounded for a stable method.
double newmark_amplitude(double wh, double gamma, double beta) {
  const NewmarkStep<HarmonicOscillator> S(HarmonicOscillator(1.0), wh, gamma, beta);
  V1 q(1.0), v(0.0);
  double amp = 1.0;
  for (int k = 0; k < 2000; ++k) {
    V1 dq = V1::Zero(), dv = V1::Zero();
    if (!S.step_qv(0.0, q, v, dq, dv).converged) return INFINITY;
    q += dq;
    v += dv;
    amp = std::fmax(amp, std::fabs(q[0]));
    if (amp > 1e6) break;
  }
  return amp;
}

}  // namespace

BOOST_AUTO_TEST_CASE(sode_diagram_commutes_for_theta_maps_and_retractions) {
  // Sec. 4.2, Eq. 4.3: R^2(T R^1(Gamma)) = R^1(T R^2(Gamma)). For the theta map the four
  // points are (q - 2 theta v + theta^2 a, q + (1 - 2 theta) v - theta (1 - theta) a (twice),
  // q + 2 (1 - theta) v + (1 - theta)^2 a), written out here; for a map whose first point
  // is the base point (theta = 0 of a curved retraction) the diagram commutes too; the
  // midpoint map of the curved retraction R_x(v) = x + v + v^2/2 breaks it.
  const V1 q(0.7), v(-1.3), a(2.1);
  double worst = 0.0;
  for (double th : {0.0, 0.3, 0.5, 1.0}) {
    const auto P = sode_diagram_points(ThetaMap(th), q, v, a);
    const double e[4] = {q[0] - 2 * th * v[0] + th * th * a[0], q[0] + (1 - 2 * th) * v[0] - th * (1 - th) * a[0],
                         q[0] + (1 - 2 * th) * v[0] - th * (1 - th) * a[0],
                         q[0] + 2 * (1 - th) * v[0] + (1 - th) * (1 - th) * a[0]};
    for (int i = 0; i < 4; ++i) worst = std::fmax(worst, std::fabs(P[static_cast<std::size_t>(i)][0] - e[i]));
  }
  BOOST_TEST(worst <= 1e-15);
  const auto R0 = sode_diagram_points(RetractionMap<CurvedRetraction>({}, 0.0), q, v, a);
  BOOST_TEST(std::fabs(R0[1][0] - R0[2][0]) <= 1e-15);
  const auto Rh = sode_diagram_points(RetractionMap<CurvedRetraction>({}, 0.5), q, v, a);
  BOOST_TEST(std::fabs(Rh[1][0] - Rh[2][0]) > 1e-2);
}

BOOST_AUTO_TEST_CASE(newmark_map_is_a_discretization_map_with_the_papers_jacobian) {
  // Sec. 4.1: R^{TTQ} satisfies Def. 2.2 (every identity of core/map_checks.h, on TQ of R
  // and of R^2), is symmetric only for (gamma, beta) = (1/2, 1/4), and its Jacobian in
  // the columns (q, v, qdot, vdot) is the paper's
  //   [Id 0 -Id/2 (h/2)(gamma - 2 beta) Id; 0 Id 0 -gamma Id;
  //    Id 0  Id/2 (h/2)(gamma - 2 beta) Id; 0 Id 0 (1 - gamma) Id].
  for (const auto& [gamma, beta] : std::vector<std::pair<double, double>>{
           {0.5, 0.25}, {0.5, 0.0}, {0.6, 0.3025}, {0.5, 1.0 / 6.0}, {0.7, 0.1}, {1.0, 0.5}}) {
    const double h = 0.3;
    const NewmarkMap R(h, gamma, beta);
    BOOST_TEST_CONTEXT("gamma " << gamma << " beta " << beta) {
      for (const MapCheckReport& r : {check_map<2>(R), check_map<4>(R)}) {
        for (const auto& name : identity_names()) BOOST_TEST(r.residual(name) <= 1e-13, name << " = " << r.residual(name));
        if (gamma == 0.5 && beta == 0.25)
          BOOST_TEST(r.residual("adjoint_difference") <= 1e-15);
        else
          BOOST_TEST(r.residual("adjoint_difference") > 1e-3);
      }
      const double c = 0.5 * h * (gamma - 2.0 * beta);
      Mat<double, 4, 4> paper;
      paper << 1, 0, -0.5, c, 0, 1, 0, -gamma, 1, 0, 0.5, c, 0, 1, 0, 1.0 - gamma;
      Mat<double, 4, 4> J;
      map_with_jacobian(R, V2(0.4, -1.3), V2(0.2, 0.7), J);
      BOOST_TEST(max_abs(Mat<double, 4, 4>(J - paper)) == 0.0);
    }
  }
}

BOOST_AUTO_TEST_CASE(newmark_orders) {
  // Error at t = 1 on the pendulum against a fine trapezoidal reference (Newmark (1/2, 1/4)
  // with 2^14 steps, error about 1e-10): order 2 exactly for gamma = 1/2, whatever beta,
  // order 1 otherwise.
  const Pendulum P(1.0, 2.0, 9.81);
  auto final_state = [&](double gamma, double beta, int n) {
    const auto [q, v] = n_steps(NewmarkStep<Pendulum>(P, 1.0 / n, gamma, beta), V1(1.0), V1(0.5), n);
    return std::make_pair(q[0], v[0]);
  };
  const auto [qr, vr] = final_state(0.5, 0.25, 1 << 14);
  for (const auto& [gamma, beta, order] : std::vector<std::tuple<double, double, double>>{
           {0.5, 0.25, 2.0}, {0.5, 0.0, 2.0}, {0.5, 1.0 / 6.0, 2.0}, {0.6, 0.3025, 1.0}, {0.7, 0.1, 1.0}}) {
    std::vector<double> err;
    for (int n : {100, 200}) {
      const auto [q, v] = final_state(gamma, beta, n);
      err.push_back(std::fmax(std::fabs(q - qr), std::fabs(v - vr)));
    }
    const double p = std::log2(err[0] / err[1]);
    BOOST_TEST_MESSAGE("newmark gamma " << gamma << " beta " << beta << ": errors " << err[0] << ", " << err[1]
                                        << ", order " << p);
    BOOST_TEST(std::fabs(p - order) <= 0.05, "gamma " << gamma << " beta " << beta << " order " << p);
  }
}

BOOST_AUTO_TEST_CASE(newmark_equals_the_classical_update) {
  for (const auto& [gamma, beta] : std::vector<std::pair<double, double>>{
           {0.5, 0.25}, {0.5, 0.0}, {0.6, 0.3025}, {0.5, 1.0 / 6.0}, {0.7, 0.1}}) {
    const NewmarkStep<Pendulum> S(Pendulum(1.0, 2.0, 9.81), 0.05, gamma, beta);
    V1 q(1.0), v(0.5);
    double qc = 1.0, vc = 0.5;
    for (int k = 0; k < 50; ++k) {
      V1 dq = 0.05 * v, dv = V1::Zero();
      BOOST_REQUIRE(S.step_qv(0.0, q, v, dq, dv).converged);
      q += dq;
      v += dv;
      classical_newmark_pendulum(9.81 / 2.0, 0.05, gamma, beta, qc, vc);
    }
    BOOST_TEST_CONTEXT("gamma " << gamma << " beta " << beta) {
      BOOST_TEST(std::fabs(q[0] - qc) <= 1e-13);
      BOOST_TEST(std::fabs(v[0] - vc) <= 1e-13);
    }
  }
}

BOOST_AUTO_TEST_CASE(newmark_stability_thresholds) {
  const double tol = 1e-12;
  // Unconditionally stable region 2 beta >= gamma >= 1/2: any w h.
  for (const auto& [gamma, beta] : std::vector<std::pair<double, double>>{{0.5, 0.25}, {0.6, 0.3}, {0.5, 0.3}})
    for (double wh : {0.5, 3.0, 50.0, 1e4}) {
      BOOST_TEST_CONTEXT("gamma " << gamma << " beta " << beta << " wh " << wh) {
        BOOST_TEST(newmark_spectral_radius(wh, gamma, beta) <= 1.0 + tol);
        BOOST_TEST(newmark_amplitude(wh, gamma, beta) <= 10.0);
      }
    }
  // Conditionally stable (gamma >= 1/2 > ... 2 beta < gamma): threshold 1/sqrt(gamma/2 - beta).
  // (0.6, 0.29) sits just below the line 2 beta = gamma that bounds the unconditional
  // region: its threshold is w h = 10.
  for (const auto& [gamma, beta] :
       std::vector<std::pair<double, double>>{{0.5, 0.0}, {0.5, 1.0 / 6.0}, {0.6, 0.1}, {0.6, 0.29}}) {
    const double crit = 1.0 / std::sqrt(gamma / 2.0 - beta);
    BOOST_TEST_CONTEXT("gamma " << gamma << " beta " << beta << " critical wh " << crit) {
      BOOST_TEST(newmark_spectral_radius(0.95 * crit, gamma, beta) <= 1.0 + tol);
      BOOST_TEST(newmark_amplitude(0.95 * crit, gamma, beta) <= 100.0);
      // unstable just above: rho > 1 by far more than round-off (1.035 at (0.6, 0.29))
      BOOST_TEST(newmark_spectral_radius(1.05 * crit, gamma, beta) >= 1.0 + 1e-3);
      BOOST_TEST(newmark_amplitude(1.05 * crit, gamma, beta) >= 1e6);
    }
  }
  // gamma < 1/2: unstable at every step size (slowly for small w h).
  for (double wh : {0.1, 1.0, 10.0}) {
    BOOST_TEST_CONTEXT("gamma 0.4 beta 0.25 wh " << wh) {
      BOOST_TEST(newmark_spectral_radius(wh, 0.4, 0.25) >= 1.0 + 1e-5);
    }
  }
  // gamma > 1/2 damps: spectral radius strictly below 1 in the stable region.
  BOOST_TEST(newmark_spectral_radius(1.0, 0.7, 0.4) <= 0.99);
}

BOOST_AUTO_TEST_CASE(velocity_form_adapter_runs_in_the_integrate_loop) {
  // sode2 with the midpoint lift on the harmonic oscillator conserves energy (Cayley)
  const HarmonicOscillator H(2.0);
  const auto lift = tangent_lift(ThetaMap::midpoint());
  using Step = SodeStep<HarmonicOscillator, decltype(lift)>;
  const VelocityFormStep<Step> S(Step(H, lift, 0.1, SodeForm::sode2));
  V1 q(1.0), p(0.0);
  double worst = 0.0;
  const RunSummary run = integrate(S, 0.0, q, p, p, 2000, [&](std::int64_t, double, const V1& qk, const V1& pk,
                                                               const StepSummary&) {
    worst = std::fmax(worst, std::fabs(0.5 * pk[0] * pk[0] + 2.0 * qk[0] * qk[0] - 2.0));
  });
  BOOST_TEST(!run.failed);
  BOOST_TEST(worst <= 1e-13);
}

BOOST_AUTO_TEST_CASE(newmark_one_half_one_quarter_is_sode1_through_the_midpoint_map) {
  // With gamma = 1/2, beta = 1/4 Newmark's quadrature of Gamma is the trapezoidal rule,
  // which is sode1 (the first option of Sec. 4) through the midpoint map of TQ, the
  // tangent lift of the midpoint map: equal to round-off on the pendulum, through both
  // forms of the map. Another member differs at O(h^3).
  const Pendulum P(1.0, 2.0, 9.81);
  const double h = 0.05;
  const auto lift = tangent_lift(ThetaMap::midpoint());
  const SodeStep<Pendulum, decltype(lift)> A(P, lift, h, SodeForm::sode1);
  const SodeStep<Pendulum, ThetaMap> B(P, ThetaMap::midpoint(), h, SodeForm::sode1);
  const NewmarkStep<Pendulum> C(P, h, 0.5, 0.25), D(P, h, 0.5, 0.3);
  V1 qa(1.0), va(0.5), qb = qa, vb = va, qc = qa, vc = va, qd = qa, vd = va;
  auto advance = [](const auto& S, V1& q, V1& v) {
    V1 dq = S.step_size() * v, dv = V1::Zero();
    BOOST_REQUIRE(S.step_qv(0.0, q, v, dq, dv).converged);
    q += dq;
    v += dv;
  };
  for (int k = 0; k < 50; ++k) {
    advance(A, qa, va);
    advance(B, qb, vb);
    advance(C, qc, vc);
    advance(D, qd, vd);
  }
  BOOST_TEST(std::fabs(qa[0] - qc[0]) <= 1e-13);
  BOOST_TEST(std::fabs(va[0] - vc[0]) <= 1e-13);
  BOOST_TEST(std::fabs(qb[0] - qc[0]) <= 1e-13);
  BOOST_TEST(std::fabs(vb[0] - vc[0]) <= 1e-13);
  BOOST_TEST(std::fabs(qd[0] - qc[0]) >= 1e-5);
}

BOOST_AUTO_TEST_CASE(newmark_adjoint_is_the_inverse_of_the_backward_step) {
  // Phi*_h = (Phi_{-h})^{-1} with (gamma*, beta*) = (1 - gamma, 1/2 - gamma + beta):
  // a step of the adjoint followed by a step of -h of the method returns to the start
  // (Kepler, nonlinear, two degrees of freedom); gamma = 1/2 is its own adjoint.
  const Kepler K(1.0);
  for (const auto& [gamma, beta] :
       std::vector<std::pair<double, double>>{{0.5, 0.25}, {0.6, 0.3025}, {0.7, 0.1}, {0.5, 0.0}, {1.0, 0.5}}) {
    const NewmarkStep<Kepler> S(K, 0.05, gamma, beta);
    const NewmarkStep<Kepler> A = S.adjoint(), B = S.with_step(-0.05);
    const V2 q0(0.7, 0.1), v0(-0.2, 1.1);
    V2 dq = 0.05 * v0, dv = V2::Zero();
    BOOST_REQUIRE(A.step_qv(0.0, q0, v0, dq, dv).converged);
    const V2 q1 = q0 + dq, v1 = v0 + dv;
    V2 eq = -dq, ev = -dv;
    BOOST_REQUIRE(B.step_qv(0.0, q1, v1, eq, ev).converged);
    BOOST_TEST_CONTEXT("gamma " << gamma << " beta " << beta) {
      BOOST_TEST(max_abs(V2(q1 + eq - q0)) <= 1e-15);
      BOOST_TEST(max_abs(V2(v1 + ev - v0)) <= 1e-15);
      BOOST_TEST(A.gamma() == 1.0 - gamma);
      BOOST_TEST(std::fabs(A.beta() - (0.5 - gamma + beta)) <= 1e-16);
    }
  }
}
