// Composition (paper Sec. 6): the method tables, the two routes to one map, the
// adjoint method, Stormer-Verlet from the Euler maps, symplectic DIRK as compositions
// of midpoint steps.
#define BOOST_TEST_MODULE composition
#include <boost/test/unit_test.hpp>

#include <quadmath.h>

#include <cmath>
#include <limits>

#include "mechanics/systems.h"
#include "solvers/composition.h"
#include "solvers/manifold_composition.h"
#include "tests/composed_steps.h"
#include "tests/displacement_check.h"
#include "tests/verification/common.h"

using namespace dvm;
using V1 = Vec<double, 1>;
using V2 = Vec<double, 2>;

namespace {

std::vector<CompositionScheme> every_scheme() {
  std::vector<CompositionScheme> all = composition_schemes();
  for (int p = 2; p <= RecursiveTripleJump::max_order; p += 2) all.push_back(find_composition("triple-jump:" + std::to_string(p)));
  return all;
}

// sum_i g_i^k over the step fractions of a scheme, counted as fractions of one
// symmetric order-2 method (a Phi^*_b Phi_a pair counts as b and a).
double power_sum(const CompositionScheme& s, int k) {
  long double sum = 0;
  for (double g : s.gamma) sum += std::pow((long double)g, k);
  for (double a : s.alpha) sum += std::pow((long double)a, k);
  for (double b : s.beta) sum += std::pow((long double)b, k);
  return (double)sum;
}

// The local-error check works in quadruple precision (GCC's __float128), so that
// errors of order-8 methods at small h stay far above round-off.
using quad = __float128;

// Pendulum: one Stormer-Verlet step (kick-drift-kick) of size h.
void verlet_q(quad h, quad& q, quad& p) {
  p -= 0.5 * h * sinq(q);
  q += h * p;
  p -= 0.5 * h * sinq(q);
}
// Pendulum: symplectic Euler steps. `a` (the map (q, q + v), explicit Euler):
// p1 = p0 - h sin q0, q1 = q0 + h p1; `b` its adjoint (the map (q - v, q)):
// q1 = q0 + h p0, p1 = p0 - h sin q1.
void euler_a_q(quad h, quad& q, quad& p) {
  p -= h * sinq(q);
  q += h * p;
}
void euler_b_q(quad h, quad& q, quad& p) {
  q += h * p;
  p -= h * sinq(q);
}
// One step of a scheme with Stormer-Verlet as the symmetric basic method
// (of_symmetric) or with the Euler pair (with_adjoint). The double coefficients
// satisfy sum gamma = 1 only to round-off, which would put an O(1e-17 h) floor under
// the local error; the middle fraction is recomputed in quadruple precision so that
// consistency holds exactly (the tables' own sums are checked separately), leaving
// every other digit as published.
void scheme_step_q(const CompositionScheme& s, quad h, quad& q, quad& p) {
  if (s.kind == CompositionKind::of_symmetric) {
    const std::size_t mid = s.gamma.size() / 2;
    quad rest = 0;
    for (std::size_t i = 0; i < s.gamma.size(); ++i)
      if (i != mid) rest += s.gamma[i];
    for (std::size_t i = 0; i < s.gamma.size(); ++i) verlet_q((i == mid ? 1 - rest : (quad)s.gamma[i]) * h, q, p);
  } else if (s.kind == CompositionKind::rkn_splitting) {
    // kick first, the middle kick(s) and drift(s) recomputed so that each flow sums to
    // one step exactly (the conversion to Euler substeps is checked separately)
    auto exact = [](const std::vector<double>& c) {
      std::vector<quad> x(c.begin(), c.end());
      const std::size_t n = x.size(), lo = (n - 1) / 2, hi = n / 2;
      quad rest = 0;
      for (std::size_t i = 0; i < n; ++i)
        if (i != lo && i != hi) rest += x[i];
      x[lo] = x[hi] = (1 - rest) / (lo == hi ? 1 : 2);
      return x;
    };
    const std::vector<quad> b = exact(s.kick), a = exact(s.drift);
    for (std::size_t i = 0; i < b.size(); ++i) {
      p -= b[i] * h * sinq(q);
      if (i < a.size()) q += a[i] * h * p;
    }
  } else {
    for (std::size_t i = 0; i < s.alpha.size(); ++i) {
      euler_b_q(s.beta[i] * h, q, p);
      euler_a_q(s.alpha[i] * h, q, p);
    }
  }
}
// The pendulum flow over h by classical RK4 with steps of at most 2e-5 (error about
// h (2e-5)^4 < 1e-19 for the h used here).
void pendulum_flow_q(quad h, quad& q, quad& p) {
  const int n = static_cast<int>(std::ceil((double)h / 2e-5));
  const quad k = h / n;
  for (int i = 0; i < n; ++i) {
    const quad k1q = p, k1p = -sinq(q);
    const quad k2q = p + k / 2 * k1p, k2p = -sinq(q + k / 2 * k1q);
    const quad k3q = p + k / 2 * k2p, k3p = -sinq(q + k / 2 * k2q);
    const quad k4q = p + k * k3p, k4p = -sinq(q + k * k3q);
    q += k / 6 * (k1q + 2 * k2q + 2 * k3q + k4q);
    p += k / 6 * (k1p + 2 * k2p + 2 * k3p + k4p);
  }
}

}  // namespace

BOOST_AUTO_TEST_CASE(tables_are_consistent) {
  for (const CompositionScheme& s : every_scheme()) {
    BOOST_TEST_CONTEXT(s.name) {
      if (s.kind == CompositionKind::of_symmetric) {
        BOOST_TEST(static_cast<int>(s.gamma.size()) == s.stages);
        // symmetry: gamma_i = gamma_{s+1-i} exactly as stored
        for (std::size_t i = 0; i < s.gamma.size(); ++i) BOOST_TEST(s.gamma[i] == s.gamma[s.gamma.size() - 1 - i]);
      } else if (s.kind == CompositionKind::rkn_splitting) {
        // stages kicks after the first (first same as last), one drift fewer than kicks
        BOOST_TEST(static_cast<int>(s.kick.size()) == s.stages + 1);
        BOOST_TEST(s.drift.size() + 1 == s.kick.size());
        for (std::size_t i = 0; i < s.kick.size(); ++i) BOOST_TEST(s.kick[i] == s.kick[s.kick.size() - 1 - i]);
        for (std::size_t i = 0; i < s.drift.size(); ++i) BOOST_TEST(s.drift[i] == s.drift[s.drift.size() - 1 - i]);
        double kicks = 0.0, drifts = 0.0, abs1 = 0.0;  // each flow over a whole step
        for (double b : s.kick) kicks += b, abs1 += std::fabs(b);
        for (double a : s.drift) drifts += a, abs1 += std::fabs(a);
        BOOST_TEST(std::fabs(kicks - 1.0) <= 4e-16 * abs1);
        BOOST_TEST(std::fabs(drifts - 1.0) <= 4e-16 * abs1);
      } else {
        BOOST_TEST(static_cast<int>(s.alpha.size()) == s.stages);
        BOOST_TEST(s.beta.size() == s.alpha.size());
        for (std::size_t i = 0; i < s.alpha.size(); ++i) BOOST_TEST(s.alpha[i] == s.beta[s.beta.size() - 1 - i]);
      }
      BOOST_TEST(s.symmetric);
      BOOST_TEST(!s.citation.empty());
      // consistency (order 1): the fractions add up to one step. Stored as doubles,
      // sums hold to a few units of round-off relative to sum |gamma_i|^k, and a
      // typo in a published digit would show far above that.
      double abs1 = 0.0;
      for (double g : s.gamma) abs1 += std::fabs(g);
      for (double g : s.alpha) abs1 += std::fabs(g);
      for (double g : s.beta) abs1 += std::fabs(g);
      if (s.kind != CompositionKind::rkn_splitting) BOOST_TEST(std::fabs(power_sum(s, 1) - 1.0) <= 4e-16 * abs1);
      // necessary conditions seen already on linear problems: sum g^k = 0 for odd
      // k = 3, 5, ..., p - 1 (of_symmetric); Yoshida's tables carry 15 digits, so
      // they hold to about 1e-15 relative
      if (s.kind == CompositionKind::of_symmetric)
        for (int k = 3; k < s.order; k += 2) {
          double absk = 0.0;
          for (double g : s.gamma) absk += std::pow(std::fabs(g), k);
          BOOST_TEST(std::fabs(power_sum(s, k)) <= 1e-13 * absk, "k = " << k << ": " << power_sum(s, k));
        }
    }
  }
}

// The local error of one step of size h of a scheme on the pendulum.
double local_error(const CompositionScheme& s, double h) {
  quad q = 1.2, p = 0.3, qe = q, pe = p;
  scheme_step_q(s, h, q, p);
  pendulum_flow_q(h, qe, pe);
  return std::fmax((double)fabsq(q - qe), (double)fabsq(p - pe));
}

BOOST_AUTO_TEST_CASE(local_error_order_in_quadruple_precision) {
  // The order conditions that only a nonlinear problem reveals: the local error of
  // one step on the pendulum, against RK4 with tiny steps, is O(h^{p+1}); computed
  // in quadruple precision, at h0, h0/2, h0/4 with h0 = 0.1 (order <= 4), 0.2
  // (orders 6, 8) or 0.3 (orders 10, 12). A symmetric method's local error is
  // C h^{p+1} + D h^{p+3} + ..., so the slopes s1 (h0, h0/2) and s2 (h0/2, h0/4)
  // differ by about 3/4 of the h^2 term, which (4 s2 - s1)/3 removes.
  for (const CompositionScheme& s : every_scheme()) {
    BOOST_TEST_CONTEXT(s.name) {
      // (the splittings' error constants are small by design: their steps start larger)
      const double h0 = (s.kind == CompositionKind::rkn_splitting ? 2.0 : 1.0) *
                        (s.order <= 4 ? 0.1 : s.order <= 8 ? 0.2 : 0.3);
      const double e0 = local_error(s, h0), e1 = local_error(s, h0 / 2), e2 = local_error(s, h0 / 4);
      const double s1 = std::log2(e0 / e1), s2 = std::log2(e1 / e2), slope = (4 * s2 - s1) / 3;
      BOOST_TEST_MESSAGE(s.name << ": h0 = " << h0 << ", local errors " << e0 << ", " << e1 << ", " << e2
                                << "; slopes " << s1 << ", " << s2 << ", extrapolated " << slope);
      BOOST_TEST(e2 > 1e-18);  // 100 times the reference error, far above round-off
      BOOST_TEST(std::fabs(slope - (s.order + 1)) <= 0.3);
    }
  }
}

BOOST_AUTO_TEST_CASE(recursive_triple_jump_matches_the_closed_forms) {
  const std::vector<double> a = find_composition("triple-jump:4").gamma, b = TripleJump4::gamma();
  BOOST_TEST(a.size() == b.size());
  // The recursion computes 2^(1/3) as pow(2, 1/3) with 1/3 rounded, the closed form as
  // cbrt(2): the two agree to round-off, not bit for bit (clang's libm calls differ from
  // GCC's folded constants by an ulp; found by the clang sanitizer build).
  for (std::size_t i = 0; i < a.size(); ++i)
    BOOST_TEST(std::fabs(a[i] - b[i]) <= 4 * std::numeric_limits<double>::epsilon() * std::fabs(b[i]));
  BOOST_TEST(find_composition("triple-jump:2").gamma == std::vector<double>{1.0});
  BOOST_TEST(find_composition("triple-jump:8").stages == 27);
  BOOST_CHECK_THROW(find_composition("triple-jump:5"), std::invalid_argument);
  BOOST_CHECK_THROW(find_composition("triple-jump:14"), std::invalid_argument);
  BOOST_CHECK_THROW(find_composition("triple-jump:x"), std::invalid_argument);
  BOOST_CHECK_THROW(find_composition("yoshida7"), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(substeps_of_a_non_symmetric_map_use_the_adjoint) {
  const CompositionScheme tj = find_composition("triple-jump");
  const std::vector<Substep> a = substeps(tj, true), b = substeps(tj, false);
  BOOST_TEST(a.size() == 3u);
  BOOST_TEST(b.size() == 6u);
  for (std::size_t i = 0; i < 3; ++i) {
    BOOST_TEST(!a[i].adjoint);
    BOOST_TEST(b[2 * i].adjoint);  // Phi^*_{gamma h/2} first
    BOOST_TEST(!b[2 * i + 1].adjoint);
    BOOST_TEST(b[2 * i].weight == 0.5 * tj.gamma[i]);
  }
}

BOOST_AUTO_TEST_CASE(splittings_become_euler_substeps_that_merge_back) {
  // A splitting's substeps (explicit Euler = kick then drift, its adjoint = drift then
  // kick), with neighbouring kicks and drifts merged, give back the published kicks
  // and drifts; from the adjoint Euler map the flipped substeps are the same sequence.
  for (const char* name : {"blanes-moan4", "blanes-moan6"}) {
    BOOST_TEST_CONTEXT(name) {
      const CompositionScheme s = find_composition(name);
      BOOST_TEST((s.kind == CompositionKind::rkn_splitting));
      for (bool from_adjoint : {false, true}) {
        const std::vector<Substep> sub = from_adjoint ? adjoint_substeps(substeps(s, false)) : substeps(s, false);
        std::vector<double> kicks, drifts;
        bool last_kick = false;
        for (const Substep& x : sub) {
          // the Euler map of that substep: kick first unless it is the adjoint (of the
          // map whose adjoint flag is false: explicit Euler, or its adjoint when flipped)
          const bool kick_first = x.adjoint == from_adjoint;
          for (bool kick : {kick_first, !kick_first}) {
            std::vector<double>& list = kick ? kicks : drifts;
            if (!list.empty() && last_kick == kick)
              list.back() += x.weight;
            else
              list.push_back(x.weight);
            last_kick = kick;
          }
        }
        BOOST_TEST_REQUIRE(kicks.size() == s.kick.size());
        BOOST_TEST_REQUIRE(drifts.size() == s.drift.size());
        for (std::size_t i = 0; i < kicks.size(); ++i) BOOST_TEST(std::fabs(kicks[i] - s.kick[i]) <= 1e-15);
        for (std::size_t i = 0; i < drifts.size(); ++i) BOOST_TEST(std::fabs(drifts[i] - s.drift[i]) <= 1e-15);
      }
      // a symmetric map has no kicks and drifts
      BOOST_CHECK_THROW(substeps(s, true), std::invalid_argument);
    }
  }
  // Table 3 of Blanes & Moan (2002): the closed entries from the listed ones
  const CompositionScheme b4 = find_composition("blanes-moan4");
  BOOST_TEST(b4.kick.size() == 7u);
  BOOST_TEST(std::fabs(b4.kick[3] - (1.0 - 2.0 * (0.0829844064174052 + 0.396309801498368 - 0.0390563049223486))) <= 1e-16);
  BOOST_TEST(std::fabs(b4.drift[2] - (0.5 - (0.245298957184271 + 0.604872665711080))) <= 1e-16);
  const CompositionScheme b6 = find_composition("blanes-moan6");
  BOOST_TEST(b6.kick.size() == 12u);
  BOOST_TEST(std::fabs(b6.kick[5] - 0.23666992478693111) <= 1e-16);  // 1/2 - (b_1 + ... + b_5)
  BOOST_TEST(std::fabs(b6.drift[5] - 0.20477705429147008) <= 1e-16);  // 1 - 2 (a_1 + ... + a_5)
}

BOOST_AUTO_TEST_CASE(adjoint_method_is_the_inverse_of_the_negative_step) {
  // Prop. 2.4 with Sec. 5: the method of the adjoint map is the adjoint method,
  // Phi^*_h = (Phi_{-h})^{-1}. Step forward with R_d^* and h, then with R_d and -h:
  // back to the start.
  const Kepler K;
  V2 q0, p0;
  verification::kepler_initial(0.5, q0, p0);
  auto check = [&](const auto& R, const char* what) {
    using M = std::decay_t<decltype(R)>;
    const double h = 0.05;
    const PositionMomentumStep<Kepler, Adjoint<M>> fwd(K, adjoint(R), h);
    const PositionMomentumStep<Kepler, M> back(K, R, -h);
    V2 dq = h * p0, dp, dq2, dp2;
    BOOST_TEST_REQUIRE(fwd.step(0.0, q0, p0, dq, dp).converged);
    const V2 q1 = q0 + dq, p1 = p0 + dp;
    dq2 = -dq;
    BOOST_TEST_REQUIRE(back.step(0.0, q1, p1, dq2, dp2).converged);
    const double err = std::fmax(max_abs(V2(q1 + dq2 - q0)), max_abs(V2(p1 + dp2 - p0)));
    BOOST_TEST_MESSAGE(what << ": |Phi_{-h}(Phi*_h(z)) - z| = " << err);
    BOOST_TEST(err <= 1e-14, what);
  };
  check(ThetaMap::explicit_euler(), "explicit-euler");
  check(ThetaMap(0.3), "theta 0.3");
  check(ThetaMap::midpoint(), "midpoint");
  check(RetractionMap<EuclideanRetraction>({}, 0.2), "retraction-theta 0.2 (generic inverse)");
}

BOOST_AUTO_TEST_CASE(euler_maps_compose_to_stormer_verlet) {
  // Paper Sec. 6: Phi_{h/2} o Phi^*_{h/2} with Phi from (q, q + v) and Phi^* from
  // (q - v, q) is Stormer-Verlet. For L = |v|^2/2 - V(q) the adjoint half step is
  // drift-kick (q += h/2 p, p -= h/2 V'(q)), the other kick-drift, so together:
  //   q_half = q + h/2 p,  p1 = p - h V'(q_half),  q1 = q_half + h/2 p1.
  const Kepler K;
  V2 q0, p0;
  verification::kepler_initial(0.6, q0, p0);
  const double h = 0.01;
  const std::int64_t steps = 500;
  const CompositionStep<Kepler, ThetaMap> S(K, ThetaMap::explicit_euler(), h, substeps(find_composition("stormer-verlet"), false));
  const ComposedLagrangianStep<Kepler, ThetaMap> C(K, ThetaMap::explicit_euler(), h, substeps(find_composition("stormer-verlet"), false));
  V2 q = q0, p = p0, qc = q0, pc = p0;
  BOOST_TEST_REQUIRE(!integrate(S, 0.0, q, p, p0, steps, [](auto&&...) {}).failed);
  BOOST_TEST_REQUIRE(!integrate(C, 0.0, qc, pc, p0, steps, [](auto&&...) {}).failed);
  V2 qv = q0, pv = p0;
  for (std::int64_t k = 0; k < steps; ++k) {
    const V2 qh = qv + 0.5 * h * pv;
    const V2 force = -qh / std::pow(qh.norm(), 3);
    pv = pv + h * force;
    qv = qh + 0.5 * h * pv;
  }
  const double err = std::fmax(max_abs(V2(q - qv)), max_abs(V2(p - pv)));
  const double err2 = std::fmax(max_abs(V2(qc - qv)), max_abs(V2(pc - pv)));
  BOOST_TEST_MESSAGE("composition of Euler maps vs closed-form Stormer-Verlet, Kepler e = 0.6, 500 steps: " << err
                     << " (route 1), " << err2 << " (route 2)");
  BOOST_TEST(err <= 1e-13);
  BOOST_TEST(err2 <= 1e-13);
  // and it is a different method from the plain symplectic Euler
  V2 qe = q0, pe = p0;
  const PositionMomentumStep<Kepler, ThetaMap> E(K, ThetaMap::explicit_euler(), h);
  integrate(E, 0.0, qe, pe, p0, steps, [](auto&&...) {});
  BOOST_TEST(max_abs(V2(qe - qv)) >= 1e-4);
}

template <class Map>
double two_route_difference(const Map& R, const CompositionScheme& s, bool map_symmetric, int steps,
                            StepOptions opt = {}) {
  const Pendulum L;
  const V1 q0(1.3), p0(0.4);
  const double h = 0.1;
  const std::vector<Substep> subs = s.name == "none" ? single_substep() : substeps(s, map_symmetric);
  const CompositionStep<Pendulum, Map> A(L, R, h, subs, opt);
  const ComposedLagrangianStep<Pendulum, Map> B(L, R, h, subs, opt);
  V1 qa = q0, pa = p0, qb = q0, pb = p0;
  const V1 v0 = legendre_inverse(L, q0, p0);
  const bool fa = integrate(A, 0.0, qa, pa, v0, steps, [](auto&&...) {}).failed;
  const bool fb = integrate(B, 0.0, qb, pb, v0, steps, [](auto&&...) {}).failed;
  if (fa || fb) return INFINITY;
  return std::fmax(std::fabs(qa[0] - qb[0]), std::fabs(pa[0] - pb[0]));
}

BOOST_AUTO_TEST_CASE(two_routes_give_one_map) {
  // Composition of one-step maps against the composed discrete Lagrangian
  // sum_k L_d^{(k)}(q_{k-1}, q_k) with the micro-nodes solved together with q_S.
  double worst = 0.0;
  for (const char* name : {"stormer-verlet", "triple-jump", "mclachlan4", "yoshida6a", "kahan-li8"}) {
    const CompositionScheme s = find_composition(name);
    BOOST_TEST_CONTEXT(name) {
      const double a = two_route_difference(ThetaMap::midpoint(), s, true, 20);
      const double b = two_route_difference(ThetaMap::explicit_euler(), s, false, 20);
      const double c = two_route_difference(ThetaMap(0.3), s, false, 20);
      const double d = two_route_difference(RetractionMap<EuclideanRetraction>({}, 0.2), s, false, 5);
      BOOST_TEST_MESSAGE(name << ": route 1 - route 2 after 20 steps: midpoint " << a << ", explicit-euler " << b
                              << ", theta 0.3 " << c << "; generic retraction map (5 steps) " << d);
      for (double x : {a, b, c, d}) {
        BOOST_TEST(x <= 1e-13);
        worst = std::fmax(worst, x);
      }
    }
  }
  BOOST_TEST_MESSAGE("largest route difference: " << worst);
}

BOOST_AUTO_TEST_CASE(two_routes_agree_with_a_loose_tolerance) {
  // Both routes apply the Newton correction of the residual they accept (as
  // solve_newton does), which takes it to round-off; so even with a residual
  // tolerance of 1e-6 they agree to round-off. (Before the composed-Lagrangian loop
  // did so, they differed by 2.5e-6, 2.2e-7 and 7.5e-7 here.)
  StepOptions loose;
  loose.residual_tolerance = 1e-6;
  loose.accept_tolerance = 1e-6;
  for (const char* name : {"stormer-verlet", "triple-jump", "kahan-li8"}) {
    const double d = two_route_difference(ThetaMap::explicit_euler(), find_composition(name), false, 20, loose);
    BOOST_TEST_MESSAGE(name << ", tolerance 1e-6: route 1 - route 2 after 20 steps " << d);
    BOOST_TEST(d <= 1e-13, name << ": " << d);
  }
}

// The displacement check of the cross-product suite (tests/displacement_check.h,
// tests/cli/test_cli_combinations.cc) on real steps, against Kepler's exact flow: the
// kahan-li8 composition of the midpoint map passes it; the same composition with any one
// of its stages left out fails it, and so does a step that returns its input.
BOOST_AUTO_TEST_CASE(the_displacement_check_fails_a_composition_that_drops_a_stage) {
  const Kepler L(1.0);
  const V2 q0(0.4, 0.0), p0(0.0, 2.0);
  const double h = 1e-3;
  const int K = 3;
  V2 qe, pe;
  L.exact(K * h, q0, p0, qe, pe);
  const std::vector<double> dq_ref{qe[0] - q0[0], qe[1] - q0[1]}, dp_ref{pe[0] - p0[0], pe[1] - p0[1]};
  auto judge = [&](const std::vector<Substep>& subs) {
    const CompositionStep<Kepler, ThetaMap> S(L, ThetaMap::midpoint(), h, subs);
    V2 q = q0, p = p0;
    const RunSummary run = integrate(S, 0.0, q, p, p0, K, [](auto&&...) {});
    BOOST_REQUIRE(!run.failed);
    return dvm_test::judge_displacement({q0[0], q0[1]}, {p0[0], p0[1]}, {q[0], q[1]}, {p[0], p[1]}, dq_ref, dp_ref, 8,
                                        h);
  };
  const std::vector<Substep> all = substeps(find_composition("kahan-li8"), true);
  const auto whole = judge(all);
  BOOST_TEST(whole.ok, whole.message);
  BOOST_TEST_MESSAGE("kahan-li8, midpoint, Kepler: displacement error " << whole.error_q << " (q), " << whole.error_p
                                                                         << " (p) against the tolerance " << whole.tol);
  for (std::size_t k = 0; k < all.size(); ++k) {
    std::vector<Substep> dropped = all;
    dropped.erase(dropped.begin() + static_cast<std::ptrdiff_t>(k));
    const auto v = judge(dropped);
    BOOST_TEST(!v.ok, "stage " << k + 1 << " left out");
    BOOST_TEST(std::fmax(v.error_q, v.error_p) >= 0.5 * std::fabs(all[k].weight), "stage " << k + 1);
  }
  const auto idle = dvm_test::judge_displacement({q0[0], q0[1]}, {p0[0], p0[1]}, {q0[0], q0[1]}, {p0[0], p0[1]},
                                                 dq_ref, dp_ref, 8, h);
  BOOST_TEST(!idle.ok);
}

BOOST_AUTO_TEST_CASE(composed_lagrangian_is_stationary_at_the_micro_nodes) {
  // The value of sum_k L_d^{(k)} at the solved nodes is stationary in each interior
  // node (checked by central differences), and not at perturbed nodes.
  const Pendulum L;
  const std::vector<Substep> subs = substeps(find_composition("triple-jump"), false);
  const double h = 0.2;
  const CompositionStep<Pendulum, ThetaMap> A(L, ThetaMap::explicit_euler(), h, subs);
  const ComposedLagrangianStep<Pendulum, ThetaMap> B(L, ThetaMap::explicit_euler(), h, subs);
  // nodes from route 1, substep by substep
  std::vector<V1> nodes = {V1(1.0)};
  V1 p(0.5);
  for (const Substep& s : subs) {
    const CompositionStep<Pendulum, ThetaMap> one(L, ThetaMap::explicit_euler(), h, {s});
    V1 dq = V1(s.weight * h * p[0]), dp;
    BOOST_TEST_REQUIRE(one.step(0.0, nodes.back(), p, dq, dp).converged);
    nodes.push_back(nodes.back() + dq);
    p += dp;
  }
  const double eps = 1e-5;
  for (std::size_t k = 1; k + 1 < nodes.size(); ++k) {
    auto plus = nodes, minus = nodes;
    plus[k][0] += eps;
    minus[k][0] -= eps;
    const double g = (B.value(plus) - B.value(minus)) / (2 * eps);
    BOOST_TEST(std::fabs(g) <= 1e-8, "node " << k << " gradient " << g);
  }
  auto moved = nodes;
  moved[2][0] += 1e-3;
  auto plus = moved, minus = moved;
  plus[2][0] += eps;
  minus[2][0] -= eps;
  BOOST_TEST(std::fabs((B.value(plus) - B.value(minus)) / (2 * eps)) >= 1e-5);
}

namespace {

// `steps` steps of the Runge-Kutta method a_ij = b_j (j < i), a_ii = b_i/2 with weights b
// on the pendulum q' = p, p' = -sin q, solved as a Runge-Kutta method: stage by stage,
// each implicit stage by fixed-point iteration to a repeated iterate.
std::pair<double, double> dirk_pendulum(const std::vector<double>& b, double h, int steps, double q, double p) {
  for (int n = 0; n < steps; ++n) {
    std::vector<double> kq(b.size()), kp(b.size());
    for (std::size_t i = 0; i < b.size(); ++i) {
      double Q = q, P = p;
      for (std::size_t j = 0; j < i; ++j) {
        Q += h * b[j] * kq[j];
        P += h * b[j] * kp[j];
      }
      double gq = P, gp = -std::sin(Q);
      for (int it = 0; it < 200; ++it) {
        const double nq = P + 0.5 * h * b[i] * gp, np = -std::sin(Q + 0.5 * h * b[i] * gq);
        const bool done = nq == gq && np == gp;
        gq = nq;
        gp = np;
        if (done) break;
      }
      kq[i] = gq;
      kp[i] = gp;
    }
    for (std::size_t i = 0; i < b.size(); ++i) {
      q += h * b[i] * kq[i];
      p += h * b[i] * kp[i];
    }
  }
  return {q, p};
}

}  // namespace

BOOST_AUTO_TEST_CASE(midpoint_compositions_are_symplectic_dirk_methods) {
  // Sec. 6.2: the Runge-Kutta method with a_ij = b_j (j < i), a_ii = b_i/2, weights b
  // is the composition of implicit midpoint steps of sizes b_1 h, ..., b_s h
  // (dirk_scheme). Solved as a Runge-Kutta method and compared with the composition of
  // midpoint-map steps over 30 steps of the pendulum, for the triple jump (the 3-stage
  // order-4 symplectic DIRK), a 2-stage and a 4-stage set of weights that are not
  // palindromes (so the order of the substeps matters and is checked).
  const double h = 0.1;
  const int steps = 30;
  const Pendulum L;
  for (const std::vector<double>& b : std::vector<std::vector<double>>{
           TripleJump4::gamma(), {0.3, 0.7}, {0.25, 0.5, -0.1, 0.35}}) {
    const auto [y0, y1] = dirk_pendulum(b, h, steps, 1.1, 0.2);
    const CompositionStep<Pendulum, ThetaMap> S(L, ThetaMap::midpoint(), h, substeps(dirk_scheme(b), true));
    V1 q(1.1), p(0.2);
    BOOST_TEST_REQUIRE(!integrate(S, 0.0, q, p, p, steps, [](auto&&...) {}).failed);
    const double err = std::fmax(std::fabs(q[0] - y0), std::fabs(p[0] - y1));
    BOOST_TEST_MESSAGE("symplectic DIRK (" << b.size() << " stages) vs composed midpoint steps, 30 steps: " << err);
    BOOST_TEST(err <= 1e-13);
  }
  // the reversed 2-stage weights are another method: the comparison above can fail
  const auto [r0, r1] = dirk_pendulum({0.7, 0.3}, h, steps, 1.1, 0.2);
  const auto [y0, y1] = dirk_pendulum({0.3, 0.7}, h, steps, 1.1, 0.2);
  BOOST_TEST(std::fmax(std::fabs(r0 - y0), std::fabs(r1 - y1)) > 1e-8);
  // the orders dirk_scheme states, and the weights it refuses
  BOOST_TEST(dirk_scheme(TripleJump4::gamma()).order == 4);
  BOOST_TEST(dirk_scheme({0.3, 0.7}).order == 2);
  BOOST_TEST(!dirk_scheme({0.3, 0.7}).symmetric);
  BOOST_CHECK_THROW(dirk_scheme({0.3, 0.6}), std::invalid_argument);
  BOOST_CHECK_THROW(dirk_scheme({1.0, 0.0}), std::invalid_argument);
  BOOST_CHECK_THROW(dirk_scheme({}), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(failures_name_the_substep) {
  // A step far too large for the pendulum's Newton solve fails in some substep and
  // says which; nothing is thrown.
  const Pendulum L;
  StepOptions opt;
  opt.max_iterations = 3;
  const CompositionStep<Pendulum, ThetaMap> S(L, ThetaMap::midpoint(), 40.0, substeps(find_composition("yoshida8a"), true), opt);
  V1 dq(40.0), dp;
  const StepSummary s = S.step(0.0, V1(3.0), V1(2.0), dq, dp);
  BOOST_TEST(!s.converged);
  BOOST_TEST(s.message.find("substep") != std::string::npos);
  BOOST_CHECK_THROW((CompositionStep<Pendulum, ThetaMap>(L, ThetaMap::midpoint(), 0.1, {})), std::invalid_argument);
}

namespace {
// A basic method of another kind: the symplectic Euler steps of the pendulum written
// by hand, kick-drift (that of the map (q, q + v)) or drift-kick (its adjoint).
struct HandEuler {
  static constexpr int N = 1;
  double h;
  bool drift_first;
  double step_size() const { return h; }
  StepSummary step(double /*t*/, const V1& q, const V1& p, V1& dq, V1& dp) const {
    double Q = q[0], P = p[0];
    if (drift_first) {
      Q += h * P;
      P -= h * std::sin(Q);
    } else {
      P -= h * std::sin(Q);
      Q += h * P;
    }
    dq[0] = Q - q[0];
    dp[0] = P - p[0];
    StepSummary s;
    s.converged = true;
    s.residual = 0.0;
    s.scale = 1.0;
    return s;
  }
};
}  // namespace

BOOST_AUTO_TEST_CASE(any_step_type_composes) {
  // ComposedStep takes any step type as the basic method: the hand-written Euler pair
  // composed by Kahan-Li's order 8 gives the map-derived composition to round-off.
  const std::vector<Substep> subs = substeps(find_composition("kahan-li8"), false);
  const double h = 0.2;
  const ComposedStep<HandEuler> hand(
      h, subs, [](double hk) { return HandEuler{hk, false}; }, [](double hk) { return HandEuler{hk, true}; });
  const CompositionStep<Pendulum, ThetaMap> derived(Pendulum(), ThetaMap::explicit_euler(), h, subs);
  V1 qa(2.0), pa(0.0), qb(2.0), pb(0.0);
  BOOST_TEST_REQUIRE(!integrate(hand, 0.0, qa, pa, pa, 50, [](auto&&...) {}).failed);
  BOOST_TEST_REQUIRE(!integrate(derived, 0.0, qb, pb, pb, 50, [](auto&&...) {}).failed);
  const double err = std::fmax(std::fabs(qa[0] - qb[0]), std::fabs(pa[0] - pb[0]));
  BOOST_TEST_MESSAGE("hand-written Euler pair vs explicit-euler map, kahan-li8, 50 steps: " << err);
  BOOST_TEST(err <= 1e-13);
}

namespace {
// A step that only records when it was told it starts (t) and how long it is; q moves
// by its length, so that q is the time the step reaches.
struct ClockStep {
  static constexpr int N = 1;
  using V = V1;
  double h;
  std::vector<std::pair<double, double>>* log;  // (t, h) of each call
  double step_size() const { return h; }
  StepSummary step(double t, const V&, const V&, V& dq, V& dp) const {
    log->emplace_back(t, h);
    dq = V1(h);
    dp = V1(0.0);
    StepSummary s;
    s.converged = true;
    s.iterations = 1;
    s.scale = 1.0;
    return s;
  }
};
// The same on a "manifold" (the contract of integrate's point steps): the line, whose
// points are their own chart.
struct Line {
  static V1 tangent_coordinates(const V1&, const V1& v) { return v; }
  static V1 next_guess(const V1& before, const V1& now) { return now - before; }
};
struct ClockPointStep {
  using M = Line;
  static constexpr int n = 1;
  using Point = V1;
  using Covector = V1;
  ClockStep clock;
  double step_size() const { return clock.h; }
  StepSummary step(double t, const Point& q0, const Covector& p0, V1& xi, Point& q1, Covector& p1) const {
    V1 dp;
    const StepSummary s = clock.step(t, q0, p0, xi, dp);
    q1 = q0 + xi;
    p1 = p0 + dp;
    return s;
  }
};
}  // namespace

// The step contract carries the time: the loop tells step k it starts at t0 + k h (a
// product, not a running sum), and a composition tells each substep where it starts,
// t plus the weights of the substeps before it times h (backward substeps included).
// A time-dependent Lagrangian, force or control reads this t.
BOOST_AUTO_TEST_CASE(every_step_and_substep_is_told_when_it_starts) {
  std::vector<std::pair<double, double>> log;
  const double t0 = 0.25, h = 0.1;
  {
    const ClockStep one{h, &log};
    V1 q(t0), p(0.0);
    BOOST_TEST_REQUIRE(!integrate(one, t0, q, p, p, 7, [](auto&&...) {}).failed);
    BOOST_TEST_REQUIRE(log.size() == 7u);
    for (int k = 0; k < 7; ++k) BOOST_TEST(log[k].first == t0 + k * h);  // exactly
  }
  for (const char* name : {"triple-jump", "suzuki5", "kahan-li8"}) {
    const std::vector<Substep> subs = substeps(find_composition(name), true);
    const ComposedStep<ClockStep> composed(h, subs, [&](double hk) { return ClockStep{hk, &log}; },
                                           [&](double hk) { return ClockStep{hk, &log}; });
    log.clear();
    V1 q(t0), p(0.0);
    BOOST_TEST_REQUIRE(!integrate(composed, t0, q, p, p, 3, [](auto&&...) {}).failed);
    BOOST_TEST_REQUIRE(log.size() == 3 * subs.size(), name);
    bool backward = false;
    for (std::size_t i = 0; i < log.size(); ++i) {
      const double t = log[i].first, hk = log[i].second;
      if (i % subs.size() == 0)
        BOOST_TEST(t == t0 + static_cast<double>(i / subs.size()) * h, name << " step " << i / subs.size());
      else  // a substep starts where the one before it ended
        BOOST_TEST(t == log[i - 1].first + log[i - 1].second, boost::test_tools::tolerance(1e-15));
      backward = backward || hk < 0.0;
    }
    if (std::string(name) == "triple-jump") BOOST_TEST(backward);  // its middle substep goes back in time
    // the last substep ends where the next step starts
    BOOST_TEST(log.back().first + log.back().second == t0 + 3 * h, boost::test_tools::tolerance(1e-15));
    BOOST_TEST(q[0] == t0 + 3 * h, boost::test_tools::tolerance(1e-15));
  }
  const std::vector<Substep> subs = substeps(find_composition("triple-jump"), true);
  const ComposedPointStep<ClockPointStep> on_points(h, subs, [&](double hk) { return ClockPointStep{{hk, &log}}; },
                                                    [&](double hk) { return ClockPointStep{{hk, &log}}; });
  log.clear();
  V1 q(t0), p(0.0);
  BOOST_TEST_REQUIRE(!integrate(on_points, t0, q, p, V1(1.0), 4, [](auto&&...) {}).failed);
  BOOST_TEST_REQUIRE(log.size() == 4 * subs.size());
  for (std::size_t i = 0; i < log.size(); ++i) {
    if (i % subs.size() == 0)
      BOOST_TEST(log[i].first == t0 + static_cast<double>(i / subs.size()) * h);
    else
      BOOST_TEST(log[i].first == log[i - 1].first + log[i - 1].second, boost::test_tools::tolerance(1e-15));
  }
}
