// Run-time-sized systems and steps (mechanics/dynamic_system.h, solvers/dynamic_step.h,
// solvers/dynamic_galerkin_step.h, solvers/dynamic_sode_step.h): derivatives of every
// dynamic system against the fixed-size systems and nested Jets; each step against its
// fixed-size counterpart; adjoints and composition; written chains of 10 and 50
// coordinates and 10 bodies (momentum conserved to round-off, bounded energy error);
// measured orders; forces (orders against the driven damped oscillator, work and impulse
// balances); a degenerate Lagrangian reported as a failure; steps that allocate nothing
// (those that keep their Jacobian across steps included).
//
// The allocation check: Eigen's EIGEN_RUNTIME_NO_MALLOC makes every Eigen heap
// allocation call eigen_assert, which is redefined here so that it is active in release
// builds too and counts the "heap allocation is forbidden" failures (any other failed
// Eigen assertion aborts, as in a debug build); the replaceable operator new counts the
// other heap allocations (std::vector, std::string).
#define EIGEN_RUNTIME_NO_MALLOC
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>

namespace dvm_test {
inline std::atomic<long> eigen_mallocs{0};
inline std::atomic<long> operator_news{0};
inline void eigen_assert_failed(const char* what, const char* file, int line) {
  if (std::strstr(what, "heap allocation is forbidden")) {
    ++eigen_mallocs;
    return;
  }
  std::fprintf(stderr, "Eigen assertion failed: %s (%s:%d)\n", what, file, line);
  std::abort();
}
}  // namespace dvm_test
#define eigen_assert(x) ((x) ? static_cast<void>(0) : ::dvm_test::eigen_assert_failed(#x, __FILE__, __LINE__))

// (GCC flags free() of memory from operator new, not knowing that operator new is
// the malloc below)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void* operator new(std::size_t n) {
  ++dvm_test::operator_news;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, std::align_val_t a) {
  ++dvm_test::operator_news;
  const std::size_t al = static_cast<std::size_t>(a);
  if (void* p = std::aligned_alloc(al, (n + al - 1) / al * al + (n ? 0 : al))) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

#define BOOST_TEST_MODULE dynamic
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <random>
#include <vector>

#include "mechanics/dynamic_system.h"
#include "mechanics/nbody_dynamic.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "mechanics/written_force.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/composition.h"
#include "solvers/dense_separable_step.h"
#include "solvers/dynamic_galerkin_step.h"
#include "solvers/dynamic_sode_step.h"
#include "solvers/dynamic_step.h"
#include "solvers/galerkin_step.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"
#include "solvers/sode_step.h"
#include "tests/composed_steps.h"
#include "tests/verification/common.h"
#include "tests/random_vector.h"
#include "tests/solvers/trajectories.h"

using namespace dvm;
using Eigen::MatrixXd;
using Eigen::VectorXd;
using dvm_test::trajectory;
using dvm_test::trajectory_difference;

static_assert(is_dynamic_system_v<NBodyDynamic> && is_dynamic_system_v<WrittenDynamic> &&
              is_dynamic_system_v<WrittenDynamicHamiltonian> && is_dynamic_system_v<FixedAsDynamic<Kepler>> &&
              is_dynamic_system_v<LegendreDynamicHamiltonian<WrittenDynamic>>);
static_assert(!is_dynamic_system_v<Kepler> && !is_dynamic_system_v<NBody<3>>);
static_assert(has_dynamic_velocity<NBodyDynamic>::value && has_dynamic_velocity<FixedAsDynamic<Kepler>>::value);
static_assert(!has_dynamic_velocity<WrittenDynamic>::value &&
              !has_dynamic_velocity<FixedAsDynamic<GenericOnly<Kepler>>>::value);
static_assert(DynamicThetaStep<NBodyDynamic>::N == Eigen::Dynamic &&
              DynamicGalerkinStep<WrittenDynamic>::N == Eigen::Dynamic);

namespace {

// blocks = false: every term on the tape (Expression::Block)
std::shared_ptr<WrittenSystem> written(std::vector<std::string> coords, std::vector<std::pair<std::string, double>> params,
                                       const std::string& L, const std::string& H = "", bool blocks = true) {
  auto s = std::make_shared<WrittenSystem>();
  s->name = "written";
  s->coordinates = std::move(coords);
  s->params = std::move(params);
  s->check_names();
  s->lagrangian = Expression::parse(L, s->symbols(WrittenSystem::Kind::lagrangian), blocks);
  if (!H.empty()) s->hamiltonian = Expression::parse(H, s->symbols(WrittenSystem::Kind::hamiltonian));
  return s;
}

// The system with generalized forces {coordinate index, F_i(t, q, v) as text}.
std::shared_ptr<WrittenSystem> with_forces(std::shared_ptr<WrittenSystem> s,
                                           const std::vector<std::pair<int, std::string>>& forces) {
  for (const auto& [i, text] : forces)
    s->forces.emplace_back(i, Expression::parse(text, s->symbols(WrittenSystem::Kind::force)));
  return s;
}

// DoublePendulum(1.3, 0.7, 1.1, 0.9, 9.81) as text.
const DoublePendulum kPendulum2(1.3, 0.7, 1.1, 0.9, 9.81);
std::shared_ptr<WrittenSystem> written_double_pendulum() {
  return written({"a", "b"}, {{"m1", 1.3}, {"m2", 0.7}, {"l1", 1.1}, {"l2", 0.9}, {"g", 9.81}},
                 "(m1 + m2)/2*l1^2*a_dot^2 + m2/2*l2^2*b_dot^2 + m2*l1*l2*a_dot*b_dot*cos(a - b)"
                 " + (m1 + m2)*g*l1*cos(a) + m2*g*l2*cos(b)");
}
// Kepler(1.5) as text, with its Hamiltonian.
const Kepler kKepler(1.5);
std::shared_ptr<WrittenSystem> written_kepler() {
  return written({"x", "y"}, {{"mu", 1.5}}, "(x_dot^2 + y_dot^2)/2 + mu/sqrt(x^2 + y^2)",
                 "(p_x^2 + p_y^2)/2 - mu/sqrt(x^2 + y^2)");
}
// FermiPastaUlam(7) as text: 6 coordinates, 12 derivative directions (two chunks of 8).
std::shared_ptr<WrittenSystem> written_fpu() {
  return written({"a", "b", "c", "d", "e", "f"}, {{"w", 7.0}},
                 "(a_dot^2 + b_dot^2 + c_dot^2 + d_dot^2 + e_dot^2 + f_dot^2)/2"
                 " - 0.25*w^2*((b - a)^2 + (d - c)^2 + (f - e)^2) - (a^4 + (c - b)^4 + (e - d)^4 + f^4)");
}

// A chain of n unit masses with free ends, L = sum v_i^2/2 - sum_i V(x_{i+1} - x_i),
// V(r) = k r^2/2 + beta r^4/4: translation invariant, so sum p_i is conserved.
std::shared_ptr<WrittenSystem> written_chain(int n, bool blocks = true) {
  std::vector<std::string> c;
  for (int i = 0; i < n; ++i) c.push_back("x" + std::to_string(i));
  std::string kin, pot;
  for (int i = 0; i < n; ++i) kin += (i ? " + " : "") + c[i] + "_dot^2";
  for (int i = 0; i + 1 < n; ++i) {
    const std::string r = "(" + c[i + 1] + " - " + c[i] + ")";
    pot += (i ? " + " : "") + std::string("k/2*") + r + "^2 + beta/4*" + r + "^4";
  }
  return written(c, {{"k", 1.0}, {"beta", 0.5}}, "(" + kin + ")/2 - (" + pot + ")", "", blocks);
}

double rel_diff(const MatrixXd& a, const MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / std::fmax(1e-300, b.cwiseAbs().maxCoeff());
}

struct Derivatives {
  double value = 0;
  VectorXd Lq, Lv;
  MatrixXd Lqq, Lqv, Lvv;
};
template <class Sys>
Derivatives derivatives(const Sys& L, const VectorXd& q, const VectorXd& v) {
  const int n = L.dim();
  Derivatives d;
  d.value = L.value(q, v);
  d.Lq.resize(n);
  d.Lv.resize(n);
  d.Lqq.resize(n, n);
  d.Lqv.resize(n, n);
  d.Lvv.resize(n, n);
  L.hessian(q, v, d.Lq, d.Lv, d.Lqq, d.Lqv, d.Lvv);
  VectorXd gq(n), gv(n);
  L.gradient(q, v, gq, gv);  // the gradient alone equals the Hessian call's
  BOOST_TEST(rel_diff(gq, d.Lq) <= 1e-15);
  BOOST_TEST(rel_diff(gv, d.Lv) <= 1e-15);
  return d;
}

// Relative agreement of all derivative blocks.
void check_same(const Derivatives& a, const Derivatives& b, double tol) {
  BOOST_TEST(std::fabs(a.value - b.value) <= tol * std::fabs(b.value));
  BOOST_TEST(rel_diff(a.Lq, b.Lq) <= tol);
  BOOST_TEST(rel_diff(a.Lv, b.Lv) <= tol);
  const double scale = std::fmax(b.Lqq.cwiseAbs().maxCoeff(), std::fmax(b.Lqv.cwiseAbs().maxCoeff(), b.Lvv.cwiseAbs().maxCoeff()));
  BOOST_TEST((a.Lqq - b.Lqq).cwiseAbs().maxCoeff() <= tol * scale);
  BOOST_TEST((a.Lqv - b.Lqv).cwiseAbs().maxCoeff() <= tol * scale);
  BOOST_TEST((a.Lvv - b.Lvv).cwiseAbs().maxCoeff() <= tol * scale);
}

// The value, gradient and Hessian of a fixed-size function f(q, v) (a Lagrangian or a
// Hamiltonian) by nested Jets: the reference the dynamic derivatives are checked against.
template <class F>
Derivatives nested_jets(const F& f, const VectorXd& q, const VectorXd& v) {
  constexpr int N = F::dim;
  using D = ceres::Jet<double, 2 * N>;
  using DD = ceres::Jet<D, 2 * N>;
  Vec<DD, N> qd, vd;
  for (int i = 0; i < N; ++i) {
    qd[i] = DD(D(q[i], i));
    qd[i].v[i] = D(1.0);
    vd[i] = DD(D(v[i], N + i));
    vd[i].v[N + i] = D(1.0);
  }
  const DD y = f(qd, vd);
  Derivatives d;
  d.value = y.a.a;
  d.Lq = y.a.v.template head<N>();
  d.Lv = y.a.v.template tail<N>();
  d.Lqq.resize(N, N);
  d.Lqv.resize(N, N);
  d.Lvv.resize(N, N);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      d.Lqq(i, j) = y.v[j].v[i];
      d.Lqv(i, j) = y.v[N + j].v[i];
      d.Lvv(i, j) = y.v[N + j].v[N + i];
    }
  return d;
}

template <int N>
Vec<double, N> fixed(const VectorXd& x) {
  return Vec<double, N>(x);
}

// Three bodies, well separated, G != 1.
NBody<3> nbody3() { return NBody<3>(1.2, {1.0, 0.3, 0.01}); }
void nbody3_state(VectorXd& q, VectorXd& p) {
  q.resize(9);
  p.resize(9);
  q << 0.0, 0.0, 0.1, 1.0, 0.1, 0.0, -0.3, 1.5, 0.2;
  p << 0.0, -0.05, 0.01, 0.0, 0.35, 0.02, -0.008, 0.0, 0.001;
}

}  // namespace

// ---------------------------------------------------------------------------------
// Derivatives.

BOOST_AUTO_TEST_CASE(nbody_dynamic_equals_nbody_with_three_bodies) {
  const NBody<3> F = nbody3();
  const NBodyDynamic D(1.2, {1.0, 0.3, 0.01});
  BOOST_TEST(D.dim() == 9);
  VectorXd q, p;
  nbody3_state(q, p);
  const VectorXd v = random_vector(9, 0.7, 5);
  // the same formulas as NBody<3>: equal to round-off
  const Derivatives d = derivatives(D, q, v);
  check_same(d, derivatives(FixedAsDynamic<NBody<3>>(F), q, v), 1e-14);
  // the Hessian against nested Jets through L itself (no closed form used)
  check_same(d, nested_jets(GenericOnly<NBody<3>>{F}, q, v), 1e-13);
  VectorXd vel(9);
  D.velocity(q, p, vel);
  BOOST_TEST(rel_diff(vel, VectorXd(F.velocity(fixed<9>(q), fixed<9>(p)))) <= 1e-16);
  const auto a = NBodyDynamic::momenta(q, p);
  const auto b = NBody<3>::momenta(fixed<9>(q), fixed<9>(p));
  for (int i = 0; i < 6; ++i) BOOST_TEST(a[static_cast<std::size_t>(i)] == b[static_cast<std::size_t>(i)]);
  BOOST_CHECK_THROW(NBodyDynamic(1.0, {}), std::invalid_argument);
  BOOST_CHECK_THROW(NBodyDynamic(1.0, {1.0, -1.0}), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(written_dynamic_equals_the_builtin_systems_both_ways) {
  // forward over reverse (the default) and forward over forward, each against the
  // built-in system's closed-form gradient with one Jet level and against nested Jets
  auto check = [](const auto& builtin, const std::shared_ptr<WrittenSystem>& text, unsigned seed) {
    using S = std::decay_t<decltype(builtin)>;
    const WrittenDynamic R(text), F(text, WrittenDerivatives::forward_over_forward);
    BOOST_TEST(R.reverse_mode());
    BOOST_TEST(!F.reverse_mode());
    for (int k = 0; k < 3; ++k) {
      const VectorXd q = random_vector(S::dim, 0.8, seed + k), v = random_vector(S::dim, 1.2, seed + 10 + k);
      BOOST_TEST_CONTEXT(builtin.name() << " point " << k) {
        const Derivatives ref = nested_jets(GenericOnly<S>{builtin}, q, v);
        const Derivatives r = derivatives(R, q, v), f = derivatives(F, q, v);
        check_same(r, ref, 1e-13);
        check_same(f, ref, 1e-13);
        check_same(r, derivatives(FixedAsDynamic<S>(builtin), q, v), 1e-13);
      }
    }
  };
  check(kPendulum2, written_double_pendulum(), 11);  // 4 directions: one pass of K = 4
  check(kKepler, written_kepler(), 21);
  check(FermiPastaUlam(7.0), written_fpu(), 31);  // 12 directions: two passes of K = 8
  // a tape longer than the stack storage of reverse mode: still reverse by default
  const auto chain = written_chain(50, false);
  BOOST_TEST(chain->lagrangian.tape().size() > static_cast<std::size_t>(Expression::kStackTape));
  BOOST_TEST(WrittenDynamic(chain).reverse_mode());
  BOOST_TEST(!WrittenDynamic(chain, WrittenDerivatives::forward_over_forward).reverse_mode());
}

BOOST_AUTO_TEST_CASE(long_tapes_are_differentiated_correctly_both_ways) {
  // the 50-coordinate chain (its tape longer than Expression::kStackTape: reverse mode
  // keeps its values in the per-thread buffer) forced forward over forward (13 chunks of
  // 8 directions) against its 12-coordinate sibling differentiated in reverse mode
  // from the stack, at a state where the coordinates from 10 on are equal and at rest
  // (the springs past the 12th carry no load, so the first 12 rows agree); and the
  // long chain in reverse mode against forward
  const WrittenDynamic L50(written_chain(50, false), WrittenDerivatives::forward_over_forward),
      L12(written_chain(12, false)), R50(written_chain(50, false)), B50(written_chain(50));
  BOOST_TEST(!L50.reverse_mode());
  BOOST_TEST(L12.reverse_mode());
  BOOST_TEST(R50.reverse_mode());
  BOOST_TEST(written_chain(12, false)->lagrangian.tape().size() <= static_cast<std::size_t>(Expression::kStackTape));
  BOOST_TEST(!written_chain(50)->lagrangian.blocks().empty());
  VectorXd q = VectorXd::Zero(50), v = VectorXd::Zero(50);
  q.head(10) = random_vector(10, 0.5, 3);
  v.head(10) = random_vector(10, 0.5, 4);
  q.tail(40).setConstant(0.25);
  const Derivatives a = derivatives(L50, q, v);
  const VectorXd q2 = random_vector(50, 0.5, 5), v2 = random_vector(50, 0.5, 6);
  check_same(derivatives(R50, q2, v2), derivatives(L50, q2, v2), 1e-14);
  check_same(derivatives(B50, q2, v2), derivatives(L50, q2, v2), 1e-13);  // blocks: another order of the sum
  const Derivatives b = derivatives(L12, VectorXd(q.head(12)), VectorXd(v.head(12)));
  BOOST_TEST(std::fabs(a.value - b.value) <= 1e-14 * std::fabs(b.value));
  BOOST_TEST(rel_diff(a.Lq.head(12), b.Lq) <= 1e-14);
  // rows 0..10 (row 11 of the long chain also holds the unloaded spring's stiffness)
  BOOST_TEST(rel_diff(a.Lqq.topLeftCorner(11, 12), b.Lqq.topRows(11)) <= 1e-14);
  BOOST_TEST(a.Lq.tail(38).cwiseAbs().maxCoeff() == 0.0);
  BOOST_TEST(rel_diff(a.Lvv, MatrixXd::Identity(50, 50)) == 0.0);
  BOOST_TEST(a.Lqv.cwiseAbs().maxCoeff() == 0.0);
  // a tridiagonal Lqq: the chain couples neighbours only
  for (int i = 0; i < 50; ++i)
    for (int j = 0; j < 50; ++j)
      if (std::abs(i - j) > 1) BOOST_TEST(a.Lqq(i, j) == 0.0);
}

BOOST_AUTO_TEST_CASE(legendre_maps_of_dynamic_systems) {
  const WrittenDynamic L(written_double_pendulum());
  const FixedAsDynamic<DoublePendulum> B(kPendulum2);
  const VectorXd q = random_vector(2, 0.9, 1), v = random_vector(2, 1.5, 2);
  const VectorXd p = legendre(L, q, v);
  BOOST_TEST(rel_diff(p, VectorXd(dvm::legendre(kPendulum2, fixed<2>(q), fixed<2>(v)))) <= 1e-15);
  BOOST_TEST(std::fabs(energy(L, q, v) - energy(kPendulum2, fixed<2>(q), fixed<2>(v))) <= 1e-14);
  // Newton (written) and the closed form (built-in) invert it
  BOOST_TEST(rel_diff(legendre_inverse(L, q, p), v) <= 1e-14);
  BOOST_TEST(rel_diff(legendre_inverse(B, q, p), v) <= 1e-14);
  BOOST_TEST(rel_diff(legendre_inverse_checked(L, q, p), v) <= 1e-14);
  BOOST_TEST(std::fabs(L.energy_at(q, v, p) - energy(kPendulum2, fixed<2>(q), fixed<2>(v))) <= 1e-14);
  // separable texts: E = <p, v>/2 - U(q) from the potential's terms, against the closed
  // forms; a constant M that is not diagonal, and a term of degree 0 that names a
  // velocity (x_dot^0), which U is evaluated with
  const WrittenDynamic K(written_kepler());
  BOOST_TEST(K.parts().separable);
  const VectorXd qk = random_vector(2, 1.0, 7), vk = random_vector(2, 1.0, 8);
  const double Ek = energy(kKepler, fixed<2>(qk), fixed<2>(vk));
  const double terms = vk.squaredNorm() / 2 + 1.5 / qk.norm();  // (E is their difference)
  BOOST_TEST(std::fabs(K.energy_at(qk, vk, legendre(K, qk, vk)) - Ek) <= 4e-15 * terms);  // (a few roundings of the terms)
  const WrittenDynamic C(written({"x", "y"}, {{"k", 3.0}},
                                 "x_dot^2 + x_dot*y_dot + y_dot^2 + k*x_dot^0*cos(x) - y^2/2"));
  BOOST_TEST(C.parts().separable);
  BOOST_TEST(!C.parts().split.diagonal);
  const VectorXd pc = legendre(C, qk, vk);
  const double Ec = vk[0] * vk[0] + vk[0] * vk[1] + vk[1] * vk[1] - 3.0 * std::cos(qk[0]) + qk[1] * qk[1] / 2;
  BOOST_TEST(std::fabs(C.energy_at(qk, vk, pc) - Ec) <= 4e-15 * (vk.squaredNorm() * 1.5 + 3.0 + qk[1] * qk[1]));
  const NBodyDynamic Nb(1.0, {1.0, 2.0});
  const VectorXd qn = random_vector(6, 1.0, 3), pn = random_vector(6, 1.0, 4);
  BOOST_TEST(rel_diff(legendre(Nb, qn, legendre_inverse(Nb, qn, pn)), pn) <= 1e-16);
}

BOOST_AUTO_TEST_CASE(hamiltonians_equal_the_fixed_size_hamiltonians) {
  auto hd = [](const auto& H, const VectorXd& q, const VectorXd& p) { return derivatives(H, q, p); };
  // H of a Lagrangian by the Legendre transform (implicit differentiation, no third
  // derivatives) against LegendreHamiltonian differentiated by nested Jets: built-in
  // (closed-form velocity) and written (Newton) double pendulum
  const LegendreHamiltonian<DoublePendulum> Hf(kPendulum2);
  const LegendreDynamicHamiltonian<FixedAsDynamic<DoublePendulum>> Hb{FixedAsDynamic<DoublePendulum>(kPendulum2)};
  const LegendreDynamicHamiltonian<WrittenDynamic> Hw{WrittenDynamic(written_double_pendulum())};
  for (int k = 0; k < 3; ++k) {
    const VectorXd q = random_vector(2, 1.0, 40 + k), p = random_vector(2, 2.0, 50 + k);
    BOOST_TEST_CONTEXT("double pendulum point " << k) {
      const Derivatives ref = nested_jets(Hf, q, p);
      check_same(hd(Hb, q, p), ref, 1e-13);
      check_same(hd(Hw, q, p), ref, 1e-13);
    }
  }
  // the written H(q, p) against WrittenHamiltonian<2> by nested Jets and against the
  // Legendre transform of the written L
  const auto text = written_kepler();
  const WrittenHamiltonian<2> Kf{text};
  const WrittenDynamicHamiltonian Kw(text), Kff(text, WrittenDerivatives::forward_over_forward);
  const LegendreDynamicHamiltonian<WrittenDynamic> Kl{WrittenDynamic(text)};
  for (int k = 0; k < 3; ++k) {
    const VectorXd q = random_vector(2, 1.0, 60 + k), p = random_vector(2, 1.0, 70 + k);
    BOOST_TEST_CONTEXT("Kepler point " << k) {
      const Derivatives ref = nested_jets(Kf, q, p);
      check_same(hd(Kw, q, p), ref, 1e-13);
      check_same(hd(Kff, q, p), ref, 1e-13);
      check_same(hd(Kl, q, p), ref, 1e-13);
    }
  }
  BOOST_CHECK_THROW(WrittenDynamicHamiltonian{written_double_pendulum()}, std::invalid_argument);
}

// ---------------------------------------------------------------------------------
// Steps against their fixed-size counterparts.
//
// Tolerance. Both paths solve the same equations with the same stopping rule and apply
// the correction of the accepted residual, so each step differs only by the round-off of
// evaluating residual and Jacobian in another order: a few units of 1e-16 relative, added
// up over 100 steps and carried along by the flow. Measured (logged below): at most
// 6e-16 relative to the largest state for the theta steps (position-momentum and
// Hamiltonian), 1.4e-14 for the Galerkin steps, whose simplified Newton stops one
// contraction (ratio up to 0.25) after the tolerance 2e-15, so the result keeps a part of
// the old Jacobian's last bits. Tolerances 1e-14 and 1e-13 leave a margin of 10, while a
// wrong sign or factor anywhere gives differences of 1e-4 or more.

BOOST_AUTO_TEST_CASE(theta_step_equals_the_position_momentum_step) {
  const double tol = 1e-14;
  for (double theta : {0.0, 0.3, 0.5, 1.0}) {
    const ThetaMap R(theta);
    BOOST_TEST_CONTEXT("theta = " << theta) {
      {  // Kepler, e = 0.6: the fixed system wrapped
        Vec<double, 2> q0, p0;
        verification::kepler_initial(0.6, q0, p0);
        const Vec<double, 2> v0 = legendre_inverse(kKepler, q0, p0);
        const double h = 0.01;
        const auto a = trajectory(PositionMomentumStep<Kepler, ThetaMap>(kKepler, R, h), q0, p0, v0, 100);
        const auto b = trajectory(DynamicThetaStep<FixedAsDynamic<Kepler>>(FixedAsDynamic<Kepler>(kKepler), R, h),
                                  VectorXd(q0), VectorXd(p0), VectorXd(v0), 100);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
      }
      {  // NBody<3> against NBodyDynamic with three bodies
        VectorXd q, p;
        nbody3_state(q, p);
        const NBody<3> F = nbody3();
        const Vec<double, 9> v0 = F.velocity(fixed<9>(q), fixed<9>(p));
        const double h = 0.02;
        const auto a = trajectory(PositionMomentumStep<NBody<3>, ThetaMap>(F, R, h), fixed<9>(q), fixed<9>(p), v0, 100);
        const auto b = trajectory(DynamicThetaStep<NBodyDynamic>(NBodyDynamic(1.2, {1.0, 0.3, 0.01}), R, h), q, p,
                                  VectorXd(v0), 100);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
      }
      {  // the written double pendulum: WrittenLagrangian<2> and the built-in system
        const auto text = written_double_pendulum();
        const Vec<double, 2> q0(0.5, 0.3), p0(0.2, -0.1);
        const Vec<double, 2> v0 = legendre_inverse(kPendulum2, q0, p0);
        const double h = 0.01;
        const auto a = trajectory(PositionMomentumStep<WrittenLagrangian<2>, ThetaMap>(WrittenLagrangian<2>(text), R, h),
                                  q0, p0, v0, 100);
        const auto c = trajectory(PositionMomentumStep<DoublePendulum, ThetaMap>(kPendulum2, R, h), q0, p0, v0, 100);
        const auto b = trajectory(DynamicThetaStep<WrittenDynamic>(WrittenDynamic(text), R, h), VectorXd(q0),
                                  VectorXd(p0), VectorXd(v0), 100);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
        BOOST_TEST(trajectory_difference(b, c) <= tol);
      }
    }
  }
}

BOOST_AUTO_TEST_CASE(steps_of_fixed_size_equal_the_fixed_size_steps) {
  // DynamicThetaStep<Sys, K> (K = 1, 2: the runtime's step for written Lagrangians of so
  // few coordinates) keeps the first iteration's Jacobian while the residual shrinks
  // fourfold and forms dp from the last gradient and the Hessian's blocks: the same
  // equation and stopping rule, so the same trajectory to round-off (measured: below
  // 4e-16 relative over 100 steps), for one Jacobian a step where Newton's method forms two
  const double tol = 1e-14;
  for (double theta : {0.0, 0.3, 0.5, 1.0}) {
    const ThetaMap R(theta);
    BOOST_TEST_CONTEXT("theta = " << theta) {
      {  // the written pendulum and the built-in one (K = 1)
        const auto text = written({"a"}, {{"m", 1.3}, {"l", 0.8}, {"g", 9.81}},
                                  "m/2*l^2*a_dot^2 + m*g*l*cos(a)");
        const Pendulum P(1.3, 0.8, 9.81);
        const Vec<double, 1> q0(2.0), p0(0.3);
        const Vec<double, 1> v0 = legendre_inverse(P, q0, p0);
        const double h = 0.02;
        RunSummary fixed_run, newton_run;
        const auto a = trajectory(PositionMomentumStep<Pendulum, ThetaMap>(P, R, h), q0, p0, v0, 100, &newton_run);
        const auto b = trajectory(DynamicThetaStep<WrittenDynamic, 1>(WrittenDynamic(text), R, h), VectorXd(q0),
                                  VectorXd(p0), VectorXd(v0), 100, &fixed_run);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
        if (theta > 0.0 && theta < 1.0) BOOST_TEST(fixed_run.jacobians < newton_run.jacobians);
      }
      {  // Kepler, e = 0.6, written and built-in (K = 2)
        Vec<double, 2> q0, p0;
        verification::kepler_initial(0.6, q0, p0);
        const Vec<double, 2> v0 = legendre_inverse(kKepler, q0, p0);
        const double h = 0.01;
        const auto a = trajectory(PositionMomentumStep<Kepler, ThetaMap>(kKepler, R, h), q0, p0, v0, 100);
        const auto b = trajectory(DynamicThetaStep<WrittenDynamic, 2>(WrittenDynamic(written_kepler()), R, h),
                                  VectorXd(q0), VectorXd(p0), VectorXd(v0), 100);
        const auto c = trajectory(DynamicThetaStep<FixedAsDynamic<Kepler>, 2>(FixedAsDynamic<Kepler>(kKepler), R, h),
                                  VectorXd(q0), VectorXd(p0), VectorXd(v0), 100);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
        BOOST_TEST(trajectory_difference(c, a) <= tol);
      }
      {  // the written double pendulum (a mass matrix that depends on q)
        const Vec<double, 2> q0(0.5, 0.3), p0(0.2, -0.1);
        const Vec<double, 2> v0 = legendre_inverse(kPendulum2, q0, p0);
        const double h = 0.01;
        const auto a = trajectory(PositionMomentumStep<DoublePendulum, ThetaMap>(kPendulum2, R, h), q0, p0, v0, 100);
        const auto b = trajectory(DynamicThetaStep<WrittenDynamic, 2>(WrittenDynamic(written_double_pendulum()), R, h),
                                  VectorXd(q0), VectorXd(p0), VectorXd(v0), 100);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
      }
    }
  }
  {  // long steps (h = 0.3, a pendulum turning over): from the starting guess 0 the first
     // Jacobian is too far from the solution to serve and a second one is formed; each
     // step equals Newton's with a Jacobian every iteration to round-off (measured: 1e-16
     // relative), from either guess
    const auto text = written({"a"}, {{"m", 1.0}, {"l", 1.0}, {"g", 9.81}}, "m/2*l^2*a_dot^2 + m*g*l*cos(a)");
    const WrittenDynamic L(text);
    const DynamicThetaStep<WrittenDynamic> newton(L, ThetaMap::midpoint(), 0.3);
    const DynamicThetaStep<WrittenDynamic, 1> fixed(L, ThetaMap::midpoint(), 0.3);
    int refreshed = 0;
    for (double q0 : {0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0})
      for (double guess : {0.0, 1.95}) {
        const VectorXd q = VectorXd::Constant(1, q0), p = VectorXd::Constant(1, 6.5);
        VectorXd da = VectorXd::Constant(1, guess), db = da, ea(1), eb(1);
        const StepSummary sa = newton.step(0.0, q, p, da, ea), sb = fixed.step(0.0, q, p, db, eb);
        BOOST_TEST_REQUIRE((sa.converged && sb.converged));
        BOOST_TEST(std::fabs(da[0] - db[0]) <= 1e-14 * 6.5);
        BOOST_TEST(std::fabs(ea[0] - eb[0]) <= 1e-14 * 6.5);
        refreshed += sb.iterations >= 2;
      }
    BOOST_TEST(refreshed >= 1);
  }
  // a system of another size is refused
  using OneCoordinate = DynamicThetaStep<WrittenDynamic, 1>;
  BOOST_CHECK_THROW(OneCoordinate(WrittenDynamic(written_kepler()), ThetaMap::midpoint(), 0.1), std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(hamiltonian_theta_step_equals_the_hamiltonian_step) {
  const double tol = 1e-14;
  for (double theta : {0.0, 0.3, 0.5, 1.0}) {
    const ThetaMap R(theta);
    BOOST_TEST_CONTEXT("theta = " << theta) {
      Vec<double, 2> q0, p0;
      verification::kepler_initial(0.6, q0, p0);
      const Vec<double, 2> v0 = legendre_inverse(kKepler, q0, p0);
      const double h = 0.01;
      {  // H of Kepler's L by the Legendre transform
        using HF = LegendreHamiltonian<Kepler>;
        using HD = LegendreDynamicHamiltonian<FixedAsDynamic<Kepler>>;
        const auto a = trajectory(HamiltonianStep<HF, ThetaMap>(HF(kKepler), R, h), q0, p0, v0, 100);
        const auto b = trajectory(DynamicHamiltonianThetaStep<HD>(HD(FixedAsDynamic<Kepler>(kKepler)), R, h),
                                  VectorXd(q0), VectorXd(p0), VectorXd(v0), 100);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
      }
      {  // the written H(q, p) of Kepler, and the Legendre transform of the written L
        const auto text = written_kepler();
        const auto a =
            trajectory(HamiltonianStep<WrittenHamiltonian<2>, ThetaMap>(WrittenHamiltonian<2>{text}, R, h), q0, p0, v0, 100);
        const auto b = trajectory(DynamicHamiltonianThetaStep<WrittenDynamicHamiltonian>(WrittenDynamicHamiltonian(text), R, h),
                                  VectorXd(q0), VectorXd(p0), VectorXd(v0), 100);
        const auto c = trajectory(DynamicHamiltonianThetaStep<LegendreDynamicHamiltonian<WrittenDynamic>>(
                                      LegendreDynamicHamiltonian<WrittenDynamic>(WrittenDynamic(text)), R, h),
                                  VectorXd(q0), VectorXd(p0), VectorXd(v0), 100);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
        BOOST_TEST(trajectory_difference(c, a) <= tol);
      }
      {  // the written double pendulum's H by the Legendre transform (Newton inverse;
         // the fixed-size path cannot differentiate it: it would need a third Jet level)
        using HF = LegendreHamiltonian<DoublePendulum>;
        const Vec<double, 2> qa(0.5, 0.3), pa(0.2, -0.1);
        const Vec<double, 2> va = legendre_inverse(kPendulum2, qa, pa);
        const auto a = trajectory(HamiltonianStep<HF, ThetaMap>(HF(kPendulum2), R, h), qa, pa, va, 100);
        const auto b = trajectory(DynamicHamiltonianThetaStep<LegendreDynamicHamiltonian<WrittenDynamic>>(
                                      LegendreDynamicHamiltonian<WrittenDynamic>(WrittenDynamic(written_double_pendulum())), R, h),
                                  VectorXd(qa), VectorXd(pa), VectorXd(va), 100);
        BOOST_TEST(trajectory_difference(b, a) <= tol);
      }
    }
  }
}

// (Kepler at every stage count, Gauss and Lobatto, is test_galerkin's: the fixed-size
// steps it instantiates anyway are the reference there.)
BOOST_AUTO_TEST_CASE(galerkin_step_equals_the_fixed_size_galerkin_step) {
  // written double pendulum (forward over reverse Hessians) and three bodies
  const double tol = 1e-13;
  {
    const auto text = written_double_pendulum();
    const Vec<double, 2> q0(0.5, 0.3), p0(0.2, -0.1);
    const Vec<double, 2> v0 = legendre_inverse(kPendulum2, q0, p0);
    const GalerkinStep<WrittenLagrangian<2>, 3> F(WrittenLagrangian<2>(text), QuadratureKind::gauss, 3, 0.02);
    const DynamicGalerkinStep<WrittenDynamic> D(WrittenDynamic(text), QuadratureKind::gauss, 3, 0.02);
    BOOST_TEST(trajectory_difference(trajectory(D, VectorXd(q0), VectorXd(p0), VectorXd(v0), 100),
                                     trajectory(F, q0, p0, v0, 100)) <= tol);
  }
  {
    VectorXd q, p;
    nbody3_state(q, p);
    const NBody<3> B = nbody3();
    const Vec<double, 9> v0 = B.velocity(fixed<9>(q), fixed<9>(p));
    const GalerkinStep<NBody<3>, 2> F(B, QuadratureKind::lobatto, 2, 0.05);
    const DynamicGalerkinStep<NBodyDynamic> D(NBodyDynamic(1.2, {1.0, 0.3, 0.01}), QuadratureKind::lobatto, 2, 0.05);
    BOOST_TEST(trajectory_difference(trajectory(D, q, p, VectorXd(v0), 100),
                                     trajectory(F, fixed<9>(q), fixed<9>(p), v0, 100)) <= tol);
  }
  BOOST_CHECK_THROW(DynamicGalerkinStep<NBodyDynamic>(NBodyDynamic(1.0, {1.0}), QuadratureKind::gauss, 7, 0.1),
                    std::invalid_argument);
}

// ---------------------------------------------------------------------------------
// Adjoints and composition.

namespace {
// A step of S from (q0, p0) from the guess dq, then a step of `back` from where it ended
// from the guess -dq (and -dp for the momentum where guess_dp): `back` must return to
// (q0, p0) to 1e-15. Returns the increment dq of S.
template <class Step, class Back>
VectorXd undone_by(const Step& S, const Back& back, const VectorXd& q0, const VectorXd& p0, VectorXd dq,
                   bool guess_dp = false) {
  VectorXd dp = VectorXd::Zero(q0.size());
  BOOST_TEST(S.step(0.0, q0, p0, dq, dp).converged);
  const VectorXd q1 = q0 + dq, p1 = p0 + dp;
  VectorXd eq = -dq, ep = guess_dp ? VectorXd(-dp) : VectorXd::Zero(q0.size());
  BOOST_TEST(back.step(0.0, q1, p1, eq, ep).converged);
  BOOST_TEST((q1 + eq - q0).cwiseAbs().maxCoeff() <= 1e-15);
  BOOST_TEST((p1 + ep - p0).cwiseAbs().maxCoeff() <= 1e-15);
  return dq;
}
}  // namespace

BOOST_AUTO_TEST_CASE(the_adjoint_step_undoes_the_step_backwards) {
  // Phi^*_h = (Phi_{-h})^{-1}: the (1 - theta) step of size -h takes Phi_h(y) back to y
  const FixedAsDynamic<Kepler> L(kKepler);
  Vec<double, 2> qf, pf;
  verification::kepler_initial(0.5, qf, pf);
  const VectorXd q0 = qf, p0 = pf;
  const double h = 0.05;
  for (double theta : {0.0, 0.3, 0.5}) {
    BOOST_TEST_CONTEXT("theta = " << theta) {
      const DynamicThetaStep<FixedAsDynamic<Kepler>> S(L, ThetaMap(theta), h);
      const auto back = DynamicThetaStep<FixedAsDynamic<Kepler>>(L, ThetaMap(theta), -h).adjoint();
      BOOST_TEST(back.map().theta() == 1.0 - theta);
      undone_by(S, back, q0, p0, h * p0);

      using HD = LegendreDynamicHamiltonian<FixedAsDynamic<Kepler>>;
      const DynamicHamiltonianThetaStep<HD> T(HD(L), ThetaMap(theta), h);
      const auto tback = DynamicHamiltonianThetaStep<HD>(HD(L), ThetaMap(theta), -h).adjoint();
      undone_by(T, tback, q0, p0, h * p0, true);
    }
  }
}

// The step's derivative by the implicit function theorem against central differences
// of the step itself, and symplectic: the written pendulum (n = 1), the written double
// pendulum and Kepler (n = 2), for the midpoint and an asymmetric theta map.
namespace {
// The Jacobian of flow(q, p) -> (q1, p1) at (q0, p0) by central differences, column by
// column (error ~ eps^2 from truncation, ~1e-16/eps from the solves, each converged to
// round-off).
template <class Flow>
MatrixXd central_differences(const Flow& flow, const VectorXd& q0, const VectorXd& p0, double eps = 1e-5) {
  const Eigen::Index n = q0.size();
  MatrixXd C(2 * n, 2 * n);
  for (Eigen::Index j = 0; j < 2 * n; ++j) {
    VectorXd qa = q0, pa = p0, qb = q0, pb = p0;
    if (j < n) {
      qa[j] += eps;
      qb[j] -= eps;
    } else {
      pa[j - n] += eps;
      pb[j - n] -= eps;
    }
    C.col(j) = (flow(qa, pa) - flow(qb, pb)) / (2.0 * eps);
  }
  return C;
}
// max |A^T J A - J|
double symplectic_defect_of(const MatrixXd& A) {
  const Eigen::Index n = A.rows() / 2;
  MatrixXd J = MatrixXd::Zero(2 * n, 2 * n);
  J.topRightCorner(n, n) = MatrixXd::Identity(n, n);
  J.bottomLeftCorner(n, n) = -MatrixXd::Identity(n, n);
  return (A.transpose() * J * A - J).cwiseAbs().maxCoeff();
}
// With a force (and a step starting at t0 != 0, which a time-dependent force reads) the
// step is not symplectic: A^T J A = J is then asserted to fail, by more than the
// tolerance it holds to without one.
template <class Sys, class Force = NoForce>
void check_step_derivative(const Sys& L, const VectorXd& q0, const VectorXd& p0, double h,
                           std::shared_ptr<const Force> force = nullptr, double t0 = 0.0) {
  const int n = L.dim();
  for (double theta : {0.5, 0.3}) {
    BOOST_TEST_CONTEXT(L.name() << ", theta = " << theta << (force ? ", forced" : "")) {
      const DynamicThetaStep<Sys, Eigen::Dynamic, Force> S(L, ThetaMap(theta), h, {}, false, force);
      // the state (q1, p1) one step from (q, p)
      auto flow = [&](const VectorXd& q, const VectorXd& p) {
        VectorXd dq = h * legendre_inverse(L, q, p), dp = VectorXd::Zero(n);
        BOOST_TEST_REQUIRE(S.step(t0, q, p, dq, dp).converged);
        VectorXd y(2 * n);
        y << q + dq, p + dp;
        return y;
      };
      VectorXd dq = h * legendre_inverse(L, q0, p0), dp = VectorXd::Zero(n);
      BOOST_TEST_REQUIRE(S.step(t0, q0, p0, dq, dp).converged);
      MatrixXd A;
      BOOST_TEST_REQUIRE(S.derivative(t0, q0, dq, A));
      BOOST_TEST(A.rows() == 2 * n);
      BOOST_TEST(A.cols() == 2 * n);
      const MatrixXd C = central_differences(flow, q0, p0);
      const double size = std::max(1.0, A.cwiseAbs().maxCoeff());
      BOOST_TEST((A - C).cwiseAbs().maxCoeff() <= 1e-7 * size);
      const double defect = symplectic_defect_of(A);
      if (force)
        BOOST_TEST(defect > 1e-6 * size * size);
      else
        BOOST_TEST(defect <= 1e-12 * size * size);
      // not the identity, nor the derivative of the step without its theta terms: the
      // momenta move with the coordinates
      BOOST_TEST(A.bottomLeftCorner(n, n).cwiseAbs().maxCoeff() > 1e-3);
    }
  }
}
}  // namespace

// The Hamiltonian theta step's derivative (DynamicHamiltonianThetaStep::derivative) against
// central differences of the step (relative 1e-7): H from L by the Legendre transform, for
// the cotangent lift of the theta map (symplectic: A^T J A = J to 1e-12) and the theta map
// on T*Q itself (lift none: symplectic at theta = 1/2 only, so asserted to fail elsewhere),
// and with a force (not symplectic). The double pendulum's H_qp is not zero, so a
// transposed block in dF/dQ would show.
namespace {
template <class Ham, class Force = NoForce>
void check_hamiltonian_step_derivative(const Ham& H, const VectorXd& q0, const VectorXd& p0, double h,
                                       std::shared_ptr<const Force> force = nullptr, double t0 = 0.0) {
  const int n = H.dim();
  for (const auto& [theta, on_bundle] : {std::pair(0.5, false), std::pair(0.3, false), std::pair(0.5, true),
                                         std::pair(0.3, true)}) {
    BOOST_TEST_CONTEXT(H.name() << ", theta = " << theta << (on_bundle ? ", on T*Q" : ", cotangent lift")
                                << (force ? ", forced" : "")) {
      const DynamicHamiltonianThetaStep<Ham, Force> S(H, ThetaMap(theta), h, {}, on_bundle, force);
      auto flow = [&](const VectorXd& q, const VectorXd& p) {
        VectorXd dq = VectorXd::Zero(n), dp = VectorXd::Zero(n);
        BOOST_TEST_REQUIRE(S.step(t0, q, p, dq, dp).converged);
        VectorXd y(2 * n);
        y << q + dq, p + dp;
        return y;
      };
      const VectorXd y1 = flow(q0, p0);
      const VectorXd dq = y1.head(n) - q0;
      // A at the step just taken (dp from its solve), A2 below after other solves (dp
      // found again by solving the step)
      MatrixXd A;
      BOOST_TEST_REQUIRE(S.derivative(t0, q0, p0, dq, A));
      BOOST_TEST(A.rows() == 2 * n);
      BOOST_TEST(A.cols() == 2 * n);
      const MatrixXd C = central_differences(flow, q0, p0);
      const double size = std::max(1.0, A.cwiseAbs().maxCoeff());
      BOOST_TEST((A - C).cwiseAbs().maxCoeff() <= 1e-7 * size);
      const double defect = symplectic_defect_of(A);
      BOOST_TEST_MESSAGE("symplectic defect " << defect);
      if (force || (on_bundle && theta != 0.5))
        BOOST_TEST(defect > 1e-6 * size * size);
      else
        BOOST_TEST(defect <= 1e-12 * size * size);
      BOOST_TEST(A.bottomLeftCorner(n, n).cwiseAbs().maxCoeff() > 1e-3);
      // A and B (none without a force) from one differentiation, after the central
      // differences' solves
      MatrixXd A2, B;
      BOOST_TEST_REQUIRE(S.derivatives(t0, q0, p0, dq, A2, &B));
      BOOST_TEST((A2 - A).cwiseAbs().maxCoeff() <= 1e-13 * size);
      BOOST_TEST(B.rows() == 2 * n);
      BOOST_TEST(B.cols() == S.controls());
    }
  }
}
}  // namespace

BOOST_AUTO_TEST_CASE(the_hamiltonian_step_derivative_by_the_implicit_function_theorem) {
  VectorXd q2(2), p2(2);
  q2 << 0.5, 0.3;
  p2 << 0.2, -0.1;
  using Dp = FixedAsDynamic<DoublePendulum>;
  check_hamiltonian_step_derivative(LegendreDynamicHamiltonian<Dp>(Dp(kPendulum2)), q2, p2, 0.02);
  Vec<double, 2> qk, pk;
  verification::kepler_initial(0.6, qk, pk);
  using Kp = FixedAsDynamic<Kepler>;
  check_hamiltonian_step_derivative(LegendreDynamicHamiltonian<Kp>(Kp(kKepler)), VectorXd(qk), VectorXd(pk), 0.01);
  // a double pendulum damped at its second joint and driven at its first, from t0 = 1.3
  const auto damped2 = with_forces(written_double_pendulum(), {{0, "sin(2*t)*cos(b)"}, {1, "-0.5*(b_dot - a_dot)"}});
  check_hamiltonian_step_derivative(LegendreDynamicHamiltonian<WrittenDynamic>(WrittenDynamic(damped2)), q2, p2, 0.02,
                                    std::make_shared<const WrittenForce>(damped2), 1.3);
}

// The SODE and Newmark steps of a separable system of run-time size (DynamicSodeStep)
// against the fixed-size steps of the same forms (SodeStep through the tangent lift of
// the theta map, NewmarkStep, each seen in (q, p) by VelocityFormStep) on Kepler: the same
// equations and stopping rule, so the states to round-off over 100 steps (measured at
// most 2.8e-15 relative: the fixed-size step inverts its Jacobian in closed form, this
// one factors it; 1e-13 leaves a margin of 35) and the same Newton iterations (a wrong
// Jacobian block still converges, to the same states, but takes more: Newmark's J_qq
// without its factor h took 17 iterations a step where 4 do). Then the adjoint
// (1 - theta, or Newmark's (1 - gamma, 1/2 - gamma + beta)) of size -h undoes a step,
// as Phi^*_h = (Phi_{-h})^{-1} says.
BOOST_AUTO_TEST_CASE(sode_steps_equal_the_fixed_size_sode_steps) {
  using D = FixedAsDynamic<Kepler>;
  const D L(kKepler);
  Vec<double, 2> qf, pf;
  verification::kepler_initial(0.6, qf, pf);
  const Vec<double, 2> vf = legendre_inverse(kKepler, qf, pf);
  const VectorXd q0 = qf, p0 = pf, v0 = vf;
  const auto Minv = DynamicSodeStep<D>::mass_inverse(L, q0, v0);
  const double h = 0.01;
  for (double theta : {0.0, 0.3, 0.5})
    for (SodeForm form : {SodeForm::sode1, SodeForm::sode2}) {
      BOOST_TEST_CONTEXT(to_string(form) << ", theta = " << theta) {
        const auto lift = tangent_lift(ThetaMap(theta));
        using Fixed = SodeStep<Kepler, std::decay_t<decltype(lift)>>;
        RunSummary ra, rb;
        const auto a = trajectory(VelocityFormStep<Fixed>(Fixed(kKepler, lift, h, form)), qf, pf, vf, 100, &ra);
        const auto b = trajectory(DynamicSodeStep<D>(L, Minv, SodeScheme::sode(form == SodeForm::sode1, theta), h),
                                  q0, p0, v0, 100, &rb);
        BOOST_TEST(trajectory_difference(b, a) <= 1e-13);
        BOOST_TEST(std::abs(rb.solver_iterations - ra.solver_iterations) <= 5);
      }
    }
  for (auto [gamma, beta] : {std::pair{0.5, 0.25}, std::pair{0.6, 0.3}, std::pair{0.5, 0.0}, std::pair{0.7, 0.1}}) {
    BOOST_TEST_CONTEXT("newmark, gamma = " << gamma << ", beta = " << beta) {
      RunSummary ra, rb;
      using Fixed = VelocityFormStep<NewmarkStep<Kepler>>;
      const auto a = trajectory(Fixed(NewmarkStep<Kepler>(kKepler, h, gamma, beta)), qf, pf, vf, 100, &ra);
      const auto b = trajectory(DynamicSodeStep<D>(L, Minv, SodeScheme::newmark(gamma, beta), h), q0, p0, v0, 100, &rb);
      BOOST_TEST(trajectory_difference(b, a) <= 1e-13);
      BOOST_TEST(std::abs(rb.solver_iterations - ra.solver_iterations) <= 5);
    }
  }
  // the adjoint of size -h from Phi_h(y) back to y
  const double H = 0.05;
  for (const SodeScheme& sc : {SodeScheme::sode(true, 0.3), SodeScheme::sode(false, 0.3),
                               SodeScheme::newmark(0.6, 0.3), SodeScheme::newmark(0.7, 0.1)}) {
    BOOST_TEST_CONTEXT("kind " << static_cast<int>(sc.kind) << ", theta " << sc.theta << ", gamma " << sc.gamma) {
      const DynamicSodeStep<D> S(L, Minv, sc, H);
      const VectorXd dq = undone_by(S, S.adjoint().with_step(-H), q0, p0, H * v0);
      // and the step did move (a step that returns its input is undone by another)
      BOOST_TEST(dq.cwiseAbs().maxCoeff() >= 0.01);
    }
  }
}

BOOST_AUTO_TEST_CASE(the_step_derivative_by_the_implicit_function_theorem) {
  const auto pendulum = written({"theta"}, {{"m", 1.3}, {"l", 0.8}, {"g", 9.81}},
                                "m*l^2*theta_dot^2/2 + m*g*l*cos(theta)");
  VectorXd q1(1), p1(1);
  q1 << 2.0;
  p1 << 0.4;
  check_step_derivative(WrittenDynamic(pendulum), q1, p1, 0.05);
  VectorXd q2(2), p2(2);
  q2 << 0.5, 0.3;
  p2 << 0.2, -0.1;
  check_step_derivative(WrittenDynamic(written_double_pendulum()), q2, p2, 0.02);
  Vec<double, 2> qk, pk;
  verification::kepler_initial(0.6, qk, pk);
  check_step_derivative(FixedAsDynamic<Kepler>(kKepler), VectorXd(qk), VectorXd(pk), 0.01);
  // with forces in t, q and v: a damped, driven pendulum; a double pendulum damped at its
  // second joint and driven at its first (F_q and F_v both enter)
  const auto driven = with_forces(written({"theta"}, {{"m", 1.3}, {"l", 0.8}, {"g", 9.81}, {"c", 0.7}},
                                          "m*l^2*theta_dot^2/2 + m*g*l*cos(theta)"),
                                  {{0, "-c*theta_dot*(1 + theta^2) + 2*cos(3*t)"}});
  check_step_derivative(WrittenDynamic(driven), q1, p1, 0.05, std::make_shared<const WrittenForce>(driven), 0.7);
  const auto damped2 = with_forces(written_double_pendulum(), {{0, "sin(2*t)*cos(b)"}, {1, "-0.5*(b_dot - a_dot)"}});
  check_step_derivative(WrittenDynamic(damped2), q2, p2, 0.02, std::make_shared<const WrittenForce>(damped2), 1.3);
}

BOOST_AUTO_TEST_CASE(composed_dynamic_steps_equal_the_fixed_size_compositions) {
  // ComposedStep (solvers/composition.h) with N = Eigen::Dynamic: the dynamic theta step
  // and its adjoint (the same type) against CompositionStep<Kepler, ThetaMap>, and the
  // dynamic Hamiltonian step against ComposedStep of HamiltonianStep; a non-symmetric map
  // (theta = 0.3: adjoint halves) and the symmetric midpoint, with the 4th-order triple
  // jump. (The substeps solve to the same tolerance as single steps, so the tolerance is
  // that of the Galerkin comparison: measured up to 1.1e-14.)
  const double h = 0.05;
  Vec<double, 2> q0, p0;
  verification::kepler_initial(0.5, q0, p0);
  const FixedAsDynamic<Kepler> L(kKepler);
  for (double theta : {0.3, 0.5}) {
    BOOST_TEST_CONTEXT("theta = " << theta) {
      const ThetaMap R(theta);
      const std::vector<Substep> sub = substeps(find_composition("triple-jump:4"), R.symmetric());
      using Step = DynamicThetaStep<FixedAsDynamic<Kepler>>;
      const ComposedStep<Step> D(
          h, sub, [&](double hk) { return Step(L, R, hk); }, [&](double hk) { return Step(L, R, hk).adjoint(); });
      static_assert(ComposedStep<Step>::N == Eigen::Dynamic);
      const auto a = trajectory(CompositionStep<Kepler, ThetaMap>(kKepler, R, h, sub), q0, p0, p0, 100);
      const auto b = trajectory(D, VectorXd(q0), VectorXd(p0), VectorXd(p0), 100);
      BOOST_TEST(trajectory_difference(b, a) <= 1e-13);

      using HD = LegendreDynamicHamiltonian<FixedAsDynamic<Kepler>>;
      using HS = DynamicHamiltonianThetaStep<HD>;
      using HF = HamiltonianStep<LegendreHamiltonian<Kepler>, ThetaMap>;
      const ComposedStep<HS> DH(
          h, sub, [&](double hk) { return HS(HD(L), R, hk); }, [&](double hk) { return HS(HD(L), R, hk).adjoint(); });
      const ComposedStep<HF> FH(
          h, sub, [&](double hk) { return HF(LegendreHamiltonian<Kepler>(kKepler), R, hk); },
          [&](double hk) { return HF(LegendreHamiltonian<Kepler>(kKepler), R.adjoint(), hk); });
      BOOST_TEST(trajectory_difference(trajectory(DH, VectorXd(q0), VectorXd(p0), VectorXd(p0), 100),
                                       trajectory(FH, q0, p0, p0, 100)) <= 1e-13);
    }
  }
}

// ---------------------------------------------------------------------------------
// Large systems: written chains and ten bodies.

namespace {

double compensated_sum(const VectorXd& x) {
  double s = 0.0, c = 0.0;
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    const double y = x[i] - c, t = s + y;
    c = (t - s) - y;
    s = t;
  }
  return s;
}

// A free written chain of n unit masses: sum p conserved to round-off, the energy error
// below energy_tol E0 and, with `no_drift`, no worse over the second half of the run than
// over the first (within a factor 2: the error oscillates).
template <class Step>
void check_chain(const Step& S, const WrittenDynamic& L, int n, int steps, double energy_tol, bool no_drift) {
  const VectorXd q0 = random_vector(n, 0.3, 100 + n);
  const VectorXd p0 = random_vector(n, 0.4, 200 + n).array() + 0.1;  // moving as a whole
  auto E = [&](const VectorXd& q, const VectorXd& p) { return energy(L, q, p); };  // v = p
  const double E0 = E(q0, p0), P0 = compensated_sum(p0);
  double dP = 0.0, dE1 = 0.0, dE2 = 0.0;
  VectorXd q = q0, p = p0;
  const RunSummary run = integrate(S, 0.0, q, p, p0, steps, [&](std::int64_t k, double, const VectorXd& qk, const VectorXd& pk, const StepSummary&) {
    dP = std::fmax(dP, std::fabs(compensated_sum(pk) - P0));
    const double e = std::fabs(E(qk, pk) - E0);
    (2 * k <= steps ? dE1 : dE2) = std::fmax(2 * k <= steps ? dE1 : dE2, e);
  });
  BOOST_TEST(!run.failed, run.failure.message);
  BOOST_TEST_MESSAGE("chain n = " << n << ": |dP| = " << dP << ", |dE| = " << dE1 << " then " << dE2 << " (E0 = " << E0
                                  << ")");
  BOOST_TEST(dP <= 1e-13 * p0.cwiseAbs().sum());
  BOOST_TEST(std::fmax(dE1, dE2) <= energy_tol * E0);
  if (no_drift) BOOST_TEST(dE2 <= 2.0 * dE1);
}

}  // namespace

// (a tenth of the steps under AddressSanitizer: long_horizon, tests/verification/common.h)
BOOST_AUTO_TEST_CASE(written_chains_of_10_and_50_coordinates) {
  const double h = 0.05;
  {
    const WrittenDynamic L(written_chain(10));
    BOOST_TEST(L.reverse_mode());
    check_chain(DynamicThetaStep<WrittenDynamic>(L, ThetaMap::midpoint(), h), L, 10,
                verification::long_horizon(2000), 1e-3, true);
    check_chain(DynamicGalerkinStep<WrittenDynamic>(L, QuadratureKind::gauss, 2, h), L, 10,
                verification::long_horizon(1000), 1e-6, false);
  }
  {
    const WrittenDynamic L(written_chain(50));
    BOOST_TEST(L.reverse_mode());  // its tape is longer than the stack storage: the per-thread buffer
    check_chain(DynamicThetaStep<WrittenDynamic>(L, ThetaMap::midpoint(), h), L, 50,
                verification::long_horizon(200), 1e-3, true);
  }
}

BOOST_AUTO_TEST_CASE(ten_bodies_conserve_momentum_and_angular_momentum) {
  // a central mass and nine light bodies (masses 1e-4 i) on slightly eccentric orbits of
  // radii 1.5^(i-1), inclined by 0.05 i: a planetary system without close encounters
  std::vector<double> m = {1.0};
  VectorXd q = VectorXd::Zero(30), p = VectorXd::Zero(30);
  for (int i = 1; i < 10; ++i) {
    m.push_back(1e-4 * i);
    const double r = std::pow(1.5, i - 1), a = 0.7 * i, inc = 0.05 * i;
    const double v = 1.02 * std::sqrt(1.0 / r);
    q.segment<3>(3 * i) << r * std::cos(a), r * std::sin(a) * std::cos(inc), r * std::sin(a) * std::sin(inc);
    p.segment<3>(3 * i) << -v * std::sin(a), v * std::cos(a) * std::cos(inc), v * std::cos(a) * std::sin(inc);
    p.segment<3>(3 * i) *= m.back();
  }
  const NBodyDynamic B(1.0, m);
  const auto J0 = NBodyDynamic::momenta(q, p);
  auto E = [&](const VectorXd& x, const VectorXd& y) { return energy(B, x, legendre_inverse(B, x, y)); };
  const double E0 = E(q, p);
  double dJ = 0.0, dE = 0.0, scale = 0.0;
  for (double j : J0) scale = std::fmax(scale, std::fabs(j));
  const DynamicThetaStep<NBodyDynamic> S(B, ThetaMap::midpoint(), 0.01);
  VectorXd v0(30);
  B.velocity(q, p, v0);
  const RunSummary run = integrate(S, 0.0, q, p, v0, 3000, [&](std::int64_t, double, const VectorXd& x, const VectorXd& y, const StepSummary&) {
    const auto J = NBodyDynamic::momenta(x, y);
    for (int i = 0; i < 6; ++i) dJ = std::fmax(dJ, std::fabs(J[static_cast<std::size_t>(i)] - J0[static_cast<std::size_t>(i)]));
    dE = std::fmax(dE, std::fabs(E(x, y) - E0));
  });
  BOOST_TEST(!run.failed, run.failure.message);
  BOOST_TEST_MESSAGE("ten bodies: |dJ| = " << dJ << " (scale " << scale << "), |dE| = " << dE << " (E0 = " << E0 << ")");
  BOOST_TEST(dJ <= 1e-13 * scale);
  BOOST_TEST(dE <= 1e-5 * std::fabs(E0));
}

// ---------------------------------------------------------------------------------
// Orders, by a log-log fit at t = 1 against Kepler's exact solution (written Kepler).

BOOST_AUTO_TEST_CASE(measured_orders_of_the_dynamic_steps) {
  const auto text = written_kepler();
  Vec<double, 2> qf, pf;
  verification::kepler_initial(0.5, qf, pf);
  Vec<double, 2> qe, pe;
  kKepler.exact(1.0, qf, pf, qe, pe);
  auto error_of = [&](const auto& S, double h) {
    VectorXd q = qf, p = pf;
    const int steps = static_cast<int>(std::lround(1.0 / h));
    const RunSummary run = integrate(S, 0.0, q, p, VectorXd(pf), steps, [](auto&&...) {});
    BOOST_TEST(!run.failed, run.failure.message);
    return std::fmax((q - VectorXd(qe)).cwiseAbs().maxCoeff(), (p - VectorXd(pe)).cwiseAbs().maxCoeff());
  };
  std::vector<double> hs, e_mid, e_ham, e_gauss, e_lobatto;
  for (int k = 0; k < 5; ++k) {
    const double h = 0.1 / std::pow(2.0, k);
    hs.push_back(h);
    e_mid.push_back(error_of(DynamicThetaStep<WrittenDynamic>(WrittenDynamic(text), ThetaMap::midpoint(), h), h));
    e_ham.push_back(error_of(
        DynamicHamiltonianThetaStep<WrittenDynamicHamiltonian>(WrittenDynamicHamiltonian(text), ThetaMap::midpoint(), h), h));
    e_gauss.push_back(error_of(DynamicGalerkinStep<WrittenDynamic>(WrittenDynamic(text), QuadratureKind::gauss, 2, h), h));
    e_lobatto.push_back(
        error_of(DynamicGalerkinStep<WrittenDynamic>(WrittenDynamic(text), QuadratureKind::lobatto, 2, h), h));
  }
  const double o_mid = verification::fit_order(hs, e_mid), o_ham = verification::fit_order(hs, e_ham);
  const double o_gauss = verification::fit_order(hs, e_gauss), o_lob = verification::fit_order(hs, e_lobatto);
  BOOST_TEST_MESSAGE("orders: theta = 1/2 " << o_mid << ", Hamiltonian midpoint " << o_ham << ", Gauss s = 2 " << o_gauss
                                            << ", Lobatto s = 2 " << o_lob);
  BOOST_TEST(std::fabs(o_mid - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_ham - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_gauss - 4.0) <= 0.2);
  BOOST_TEST(std::fabs(o_lob - 4.0) <= 0.2);
}

// ---------------------------------------------------------------------------------
// Forces (discrete Lagrange-d'Alembert, solvers/dynamic_step.h).

namespace {
// m x'' + c x' + k x = A cos(w t): L = m x_dot^2/2 - k x^2/2, F = -c x_dot + A cos(w t),
// and its exact solution from (x0, v0) at t = 0: the steady oscillation a cos wt + b sin wt
// plus the damped free oscillation that matches the initial state.
struct DrivenOscillator {
  double m = 1.3, k = 2.0, c = 0.4, A = 0.8, w = 1.7;
  std::shared_ptr<WrittenSystem> text() const {
    return with_forces(written({"x"}, {{"m", m}, {"k", k}, {"c", c}, {"A", A}, {"w", w}}, "m*x_dot^2/2 - k*x^2/2"),
                       {{0, "-c*x_dot + A*cos(w*t)"}});
  }
  // (x, p) at t from (x0, v0)
  void exact(double t, double x0, double v0, double& x, double& p) const {
    const double d = k - m * w * w, det = d * d + c * c * w * w;
    const double a = A * d / det, b = A * c * w / det;  // d a + c w b = A, d b - c w a = 0
    const double g = c / (2.0 * m), wd = std::sqrt(k / m - g * g);
    const double X = x0 - a, Y = (v0 - b * w + g * X) / wd;  // the free part's cos and sin amplitudes
    const double e = std::exp(-g * t), C = std::cos(wd * t), S = std::sin(wd * t);
    x = a * std::cos(w * t) + b * std::sin(w * t) + e * (X * C + Y * S);
    const double v = -a * w * std::sin(w * t) + b * w * std::cos(w * t) + e * (-g * (X * C + Y * S) + wd * (Y * C - X * S));
    p = m * v;
  }
  // max(|x - xe|, |p - pe|) at T after steps of S of size h from x0 with p = m v0 (v0 the
  // first guess's velocity)
  template <class S>
  double final_error(const S& step, double h, double T, double x0, double v0, double xe, double pe) const {
    VectorXd q(1), p(1), v(1);
    q << x0;
    p << m * v0;
    v << v0;
    const RunSummary run = integrate(step, 0.0, q, p, v, std::lround(T / h), [](auto&&...) {});
    BOOST_TEST(!run.failed, run.failure.message);
    return std::fmax(std::fabs(q[0] - xe), std::fabs(p[0] - pe));
  }
  // |E_N - E_0 - W_N| after 2000 steps of S of size h from (x0, p0) (from the guess
  // h p0 / m), the works W_k summed from each step's, relative to max(E_0, max |W_k|);
  // `largest` receives max |W_k|
  template <class S>
  double energy_balance(const S& step, double h, double x0, double p0, double& largest) const {
    VectorXd q(1), p(1), dq(1), dp(1);
    q << x0;
    p << p0;
    dq = h * p / m;
    auto energy = [&] { return p[0] * p[0] / (2 * m) + k * q[0] * q[0] / 2; };
    const double E0 = energy();
    double W = 0.0;
    largest = 0.0;
    for (int i = 0; i < 2000; ++i) {
      const StepSummary s = step.step(i * h, q, p, dq, dp);
      BOOST_TEST_REQUIRE(s.converged);
      q += dq;
      p += dp;
      W += s.work;
      largest = std::fmax(largest, std::fabs(W));
    }
    return std::fabs(energy() - E0 - W) / std::fmax(E0, largest);
  }
};
}  // namespace

// The forced steps converge to the exact solution of the damped, driven oscillator at
// their orders: the midpoint 2, the explicit Euler map 1, the Stormer-Verlet composition
// of the theta = 0.3 step with its adjoint 2 (which needs the adjoint of the forced step
// to be the forced (1 - theta) step), the triple jump of the midpoint 4, Galerkin with
// Gauss and Lobatto quadrature and s = 2 stages 4 (forces at the quadrature nodes, the
// nodes' times t0 + c_i h), the Hamiltonian form's theta = 0.3 lift composed with its
// adjoint 2; Galerkin Gauss s = 1 and the Hamiltonian midpoint (H from L and H written)
// give the forced midpoint step's states to round-off. A force read at
// the start of the step instead of at the map's node t0 + theta h leaves the midpoint
// first order.
BOOST_AUTO_TEST_CASE(forced_steps_converge_to_the_driven_damped_oscillator_at_their_orders) {
  const DrivenOscillator osc;
  const auto text = osc.text();
  const auto force = std::make_shared<WrittenForce>(text);
  const WrittenDynamic L(text);
  const double T = 2.0, x0 = 1.0, v0 = 0.3;
  double xe, pe;
  osc.exact(T, x0, v0, xe, pe);
  using Step = DynamicThetaStep<WrittenDynamic, Eigen::Dynamic, WrittenForce>;
  auto error_of = [&](const auto& S, double h) { return osc.final_error(S, h, T, x0, v0, xe, pe); };
  auto composed = [&](double theta, const char* scheme, double h) {
    const ThetaMap R(theta);
    return ComposedStep<Step>(
        h, substeps(find_composition(scheme), R.symmetric()),
        [&](double hk) { return Step(L, R, hk, {}, false, force); },
        [&](double hk) { return Step(L, R, hk, {}, false, force).adjoint(); });
  };
  using Galerkin = DynamicGalerkinStep<WrittenDynamic, WrittenForce>;
  std::vector<double> hs, mid, euler, verlet, jump, gauss, lobatto, lifted;
  using HL = LegendreDynamicHamiltonian<WrittenDynamic>;
  using Lifted = DynamicHamiltonianThetaStep<HL, WrittenForce>;
  for (int k = 0; k < 5; ++k) {
    const double h = 0.1 / std::pow(2.0, k);
    hs.push_back(h);
    mid.push_back(error_of(Step(L, ThetaMap::midpoint(), h, {}, false, force), h));
    euler.push_back(error_of(Step(L, ThetaMap(0.0), h, {}, false, force), h));
    verlet.push_back(error_of(composed(0.3, "stormer-verlet", h), h));
    jump.push_back(error_of(composed(0.5, "triple-jump:4", h), h));
    gauss.push_back(error_of(Galerkin(L, QuadratureKind::gauss, 2, h, {}, force), h));
    lobatto.push_back(error_of(Galerkin(L, QuadratureKind::lobatto, 2, h, {}, force), h));
    // the cotangent lift of the theta = 0.3 map composed with its adjoint
    const ThetaMap R(0.3);
    lifted.push_back(error_of(ComposedStep<Lifted>(
                                  h, substeps(find_composition("stormer-verlet"), false),
                                  [&](double hk) { return Lifted(HL(L), R, hk, {}, false, force); },
                                  [&](double hk) { return Lifted(HL(L), R, hk, {}, false, force).adjoint(); }),
                              h));
  }
  const double o_mid = verification::fit_order(hs, mid), o_euler = verification::fit_order(hs, euler);
  const double o_verlet = verification::fit_order(hs, verlet), o_jump = verification::fit_order(hs, jump);
  const double o_gauss = verification::fit_order(hs, gauss), o_lobatto = verification::fit_order(hs, lobatto);
  const double o_lifted = verification::fit_order(hs, lifted);
  BOOST_TEST(std::fabs(o_lifted - 2.0) <= 0.1);
  BOOST_TEST_MESSAGE("forced orders: midpoint " << o_mid << ", explicit Euler " << o_euler << ", theta 0.3 with its adjoint "
                                                << o_verlet << ", triple jump " << o_jump << ", Galerkin Gauss s = 2 "
                                                << o_gauss << ", Lobatto s = 2 " << o_lobatto
                                                << ", Hamiltonian theta 0.3 with its adjoint " << o_lifted);
  BOOST_TEST(std::fabs(o_gauss - 4.0) <= 0.2);
  BOOST_TEST(std::fabs(o_lobatto - 4.0) <= 0.2);
  BOOST_TEST(std::fabs(o_mid - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_euler - 1.0) <= 0.1);
  BOOST_TEST(std::fabs(o_verlet - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_jump - 4.0) <= 0.2);
  BOOST_TEST(mid.back() <= 1e-4);  // close to the solution, not only converging
  BOOST_TEST(gauss.back() <= 1e-9);
  // 200 steps of h = 0.05 from (1, 0.4): the final state and the summed work
  struct End {
    double q, p, W;
  };
  auto run200 = [](const auto& S) {
    const double h = 0.05;
    VectorXd q(1), p(1), dq(1), dp(1);
    q << 1.0;
    p << 0.4;
    dq << 0.02;
    dp.setZero();
    double W = 0.0;
    for (int k = 0; k < 200; ++k) {
      const StepSummary s = S.step(k * h, q, p, dq, dp);
      BOOST_TEST_REQUIRE(s.converged);
      q += dq;
      p += dp;
      W += s.work;
    }
    return End{q[0], p[0], W};
  };
  const End midpoint = run200(Step(L, ThetaMap::midpoint(), 0.05, {}, false, force));
  BOOST_TEST(std::fabs(midpoint.W) > 0.1);
  auto same_as_midpoint = [&](const End& e) {
    BOOST_TEST(std::fabs(e.q - midpoint.q) <= 1e-13);
    BOOST_TEST(std::fabs(e.p - midpoint.p) <= 1e-13);
    BOOST_TEST(std::fabs(e.W - midpoint.W) <= 1e-13);
  };
  // The Hamiltonian form: the cotangent lift of the midpoint map with the force at its
  // node, for a quadratic L the implicit midpoint rule of the forced equations as the
  // forced midpoint step is: the same states and work, from H by the Legendre transform
  // and from H written
  {
    const auto written_h = osc.text();
    written_h->hamiltonian =
        Expression::parse("p_x^2/(2*m) + k*x^2/2", written_h->symbols(WrittenSystem::Kind::hamiltonian));
    same_as_midpoint(
        run200(DynamicHamiltonianThetaStep<HL, WrittenForce>(HL(L), ThetaMap::midpoint(), 0.05, {}, false, force)));
    same_as_midpoint(run200(DynamicHamiltonianThetaStep<WrittenDynamicHamiltonian, WrittenForce>(
        WrittenDynamicHamiltonian(written_h), ThetaMap::midpoint(), 0.05, {}, false, force)));
  }
  // Gauss s = 1 is the midpoint rule: the same states, step after step
  same_as_midpoint(run200(Galerkin(L, QuadratureKind::gauss, 1, 0.05, {}, force)));
}

namespace {
// A midpoint step S handed t0 - h / 2 for t0: L evaluated at the step's start t0 instead
// of its node's time t0 + h / 2.
template <class S>
struct AtStart {
  static constexpr int N = Eigen::Dynamic;
  S step_of;
  double step_size() const { return step_of.step_size(); }
  StepSummary step(double t, const VectorXd& q0, const VectorXd& p0, VectorXd& dq, VectorXd& dp) const {
    return step_of.step(t - 0.5 * step_of.step_size(), q0, p0, dq, dp);
  }
};
}  // namespace

// A Lagrangian that depends on time: the Caldirola-Kanai Lagrangian
//   L(t, x, v) = exp(c t / m) (m v^2 / 2 - k x^2 / 2)
// has the Euler-Lagrange equation m x'' + c x' + k x = 0, the damped oscillator, with
// the momentum p = exp(c t / m) m v. The steps that evaluate L at their nodes' times
// converge to its exact solution at their orders: the midpoint 2, the theta = 0.3 step
// with its adjoint 2, the triple jump 4, Galerkin Gauss and Lobatto with s = 2 stages
// 4. L evaluated at the start of each step (t0 for every node, as a step that ignored
// the time would) leaves the midpoint first order. The step of a time-dependent L is
// still symplectic (L_d(t_k; q0, q1) generates it), and its derivative is checked
// against central differences at t0 = 0.7.
BOOST_AUTO_TEST_CASE(a_lagrangian_in_t_converges_to_the_damped_oscillator_at_its_orders) {
  DrivenOscillator osc;
  osc.A = 0.0;  // the free damped oscillation
  const auto text = written({"x"}, {{"m", osc.m}, {"k", osc.k}, {"c", osc.c}}, "exp(c*t/m)*(m*x_dot^2/2 - k*x^2/2)");
  BOOST_TEST(text->time_dependent());
  const WrittenDynamic L(text);
  BOOST_TEST(L.time_dependent());
  BOOST_TEST(!L.separable());  // (no structure is read off a text in t)
  // the time is read: L and its derivatives at t = 1 are exp(c / m) times those at t = 0
  {
    VectorXd q(1), v(1), Lq0(1), Lv0(1), Lq1(1), Lv1(1);
    q << 0.4;
    v << -0.3;
    MatrixXd A(1, 1), B(1, 1), C(1, 1), A1(1, 1), B1(1, 1), C1(1, 1);
    L.set_time(0.0);
    const double L0 = L.value(q, v);
    L.hessian(q, v, Lq0, Lv0, A, B, C);
    L.set_time(1.0);
    const double e = std::exp(osc.c / osc.m);
    BOOST_TEST(L.value(q, v) == e * L0, boost::test_tools::tolerance(1e-14));
    L.hessian(q, v, Lq1, Lv1, A1, B1, C1);
    BOOST_TEST(Lq1[0] == e * Lq0[0], boost::test_tools::tolerance(1e-14));
    BOOST_TEST(Lv1[0] == e * Lv0[0], boost::test_tools::tolerance(1e-14));
    BOOST_TEST(C1(0, 0) == e * C(0, 0), boost::test_tools::tolerance(1e-14));
    L.gradient(q, v, Lq1, Lv1);
    BOOST_TEST(Lv1[0] == e * Lv0[0], boost::test_tools::tolerance(1e-14));
    L.set_time(0.0);
  }
  const double T = 2.0, x0 = 1.0, v0 = 0.3;
  double xe, pe;
  osc.exact(T, x0, v0, xe, pe);
  pe *= std::exp(osc.c * T / osc.m);  // the canonical momentum
  using Step = DynamicThetaStep<WrittenDynamic>;
  auto error_of = [&](const auto& S, double h) { return osc.final_error(S, h, T, x0, v0, xe, pe); };
  auto composed = [&](double theta, const char* scheme, double h) {
    const ThetaMap R(theta);
    return ComposedStep<Step>(
        h, substeps(find_composition(scheme), R.symmetric()), [&](double hk) { return Step(L, R, hk); },
        [&](double hk) { return Step(L, R, hk).adjoint(); });
  };
  using Galerkin = DynamicGalerkinStep<WrittenDynamic>;
  std::vector<double> hs, mid, verlet, jump, gauss, lobatto, start;
  for (int k = 0; k < 5; ++k) {
    const double h = 0.1 / std::pow(2.0, k);
    hs.push_back(h);
    mid.push_back(error_of(Step(L, ThetaMap::midpoint(), h), h));
    verlet.push_back(error_of(composed(0.3, "stormer-verlet", h), h));
    jump.push_back(error_of(composed(0.5, "triple-jump:4", h), h));
    gauss.push_back(error_of(Galerkin(L, QuadratureKind::gauss, 2, h, {}), h));
    lobatto.push_back(error_of(Galerkin(L, QuadratureKind::lobatto, 2, h, {}), h));
    start.push_back(error_of(AtStart<Step>{Step(L, ThetaMap::midpoint(), h)}, h));
  }
  const double o_mid = verification::fit_order(hs, mid), o_verlet = verification::fit_order(hs, verlet);
  const double o_jump = verification::fit_order(hs, jump), o_gauss = verification::fit_order(hs, gauss);
  const double o_lobatto = verification::fit_order(hs, lobatto), o_start = verification::fit_order(hs, start);
  BOOST_TEST_MESSAGE("L(t, q, v) orders: midpoint " << o_mid << ", theta 0.3 with its adjoint " << o_verlet
                                                    << ", triple jump " << o_jump << ", Galerkin Gauss s = 2 " << o_gauss
                                                    << ", Lobatto s = 2 " << o_lobatto << ", L at the step's start "
                                                    << o_start);
  BOOST_TEST(std::fabs(o_mid - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_verlet - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_jump - 4.0) <= 0.2);
  BOOST_TEST(std::fabs(o_gauss - 4.0) <= 0.2);
  BOOST_TEST(std::fabs(o_lobatto - 4.0) <= 0.2);
  BOOST_TEST(std::fabs(o_start - 1.0) <= 0.15);
  BOOST_TEST(mid.back() <= 1e-4);
  BOOST_TEST(gauss.back() <= 1e-9);
  // the hamiltonian form, H(t, q, p) from L at the node's time: its midpoint is the
  // lagrangian midpoint for this L, quadratic with its coefficients frozen at the node;
  // the theta = 0.3 lift with its adjoint order 2; H read at the step's start order 1
  using HL = LegendreDynamicHamiltonian<WrittenDynamic>;
  using HStep = DynamicHamiltonianThetaStep<HL>;
  {
    VectorXd q(1), p(1), v(1);
    q << x0;
    v << v0;
    p = osc.m * v;
    BOOST_TEST(trajectory_difference(trajectory(HStep(HL(L), ThetaMap::midpoint(), 0.05), q, p, v, 200),
                                     trajectory(Step(L, ThetaMap::midpoint(), 0.05), q, p, v, 200)) <= 1e-13);
  }
  std::vector<double> hverlet, hstart;
  for (double h : hs) {
    const ThetaMap R(0.3);
    hverlet.push_back(error_of(ComposedStep<HStep>(
                                   h, substeps(find_composition("stormer-verlet"), false),
                                   [&](double hk) { return HStep(HL(L), R, hk); },
                                   [&](double hk) { return HStep(HL(L), R, hk).adjoint(); }),
                               h));
    hstart.push_back(error_of(AtStart<HStep>{HStep(HL(L), ThetaMap::midpoint(), h)}, h));
  }
  const double o_hverlet = verification::fit_order(hs, hverlet), o_hstart = verification::fit_order(hs, hstart);
  BOOST_TEST_MESSAGE("H(t, q, p) orders: theta 0.3 lift with its adjoint " << o_hverlet << ", H at the step's start "
                                                                           << o_hstart);
  BOOST_TEST(std::fabs(o_hverlet - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_hstart - 1.0) <= 0.15);
  // symplectic, and its derivative the linearisation, at a step that starts at t0 = 0.7
  VectorXd q1(1), p1(1);
  q1 << 0.8;
  p1 << -0.5;
  check_step_derivative<WrittenDynamic, NoForce>(L, q1, p1, 0.05, nullptr, 0.7);
}

// One forced step of the oscillator, whose equation is linear in D = q1 - q0, against
// the equation solved by hand: with x = q0 + theta D, v = D / h and the discrete forces
// F_d^- = h (1 - theta) F, F_d^+ = h theta F at (t0 + theta h, x, v),
//   p0 + h (1 - theta) (-k x - c v + f) - m v = 0,   f = A cos(w (t0 + theta h)),
//   D = (p0 + h (1 - theta) (f - k q0)) / (m / h + (1 - theta) c + h theta (1 - theta) k),
//   p1 - p0 = h (-k x - c v + f),
// which pins the split of the force between the two ends (theta and 1 - theta swapped is
// also consistent, and of the same order once composed with its adjoint).
BOOST_AUTO_TEST_CASE(one_forced_step_solves_the_discrete_lagrange_dalembert_equation) {
  const DrivenOscillator o;
  const auto text = o.text();
  const double h = 0.1, t0 = 0.9, q0 = 0.6, p0 = -0.3;
  for (double theta : {0.0, 0.3, 0.5, 1.0}) {
    BOOST_TEST_CONTEXT("theta = " << theta) {
      const DynamicThetaStep<WrittenDynamic, Eigen::Dynamic, WrittenForce> S(WrittenDynamic(text), ThetaMap(theta), h, {},
                                                                              false, std::make_shared<WrittenForce>(text));
      VectorXd q(1), p(1), dq(1), dp(1);
      q << q0;
      p << p0;
      dq << h * p0 / o.m;
      const StepSummary s = S.step(t0, q, p, dq, dp);
      BOOST_TEST_REQUIRE(s.converged);
      const double b = 1.0 - theta, f = o.A * std::cos(o.w * (t0 + theta * h));
      const double D = (p0 + h * b * (f - o.k * q0)) / (o.m / h + b * o.c + h * theta * b * o.k);
      const double x = q0 + theta * D, v = D / h, F = -o.c * v + f;
      BOOST_TEST(std::fabs(dq[0] - D) <= 1e-15);
      BOOST_TEST(std::fabs(dp[0] - h * (-o.k * x + F)) <= 1e-15);
      BOOST_TEST(std::fabs(s.work - F * D) <= 1e-16);
    }
  }
}

// The balances the discrete Lagrange-d'Alembert principle gives exactly:
// - energy: for the midpoint map and a quadratic L the step is the implicit midpoint rule
//   of the forced equations, so E_{k+1} - E_k = <F(t, x, v), dq>, the step's work
//   (StepSummary::work): E_N - E_0 = W_N to round-off;
// - momentum (forced Noether): along a coordinate L does not depend on, p_{k+1} - p_k =
//   h F at the map's node (t_k + theta h, q_k + theta dq, dq / h), recomputed here from
//   the trajectory, at theta = 0.3 with a force in t, q and v.
BOOST_AUTO_TEST_CASE(the_forced_step_balances_energy_and_momentum_by_the_work_and_impulse) {
  const DrivenOscillator osc;
  const auto text = osc.text();
  const WrittenDynamic L(text);
  const double h = 0.05;
  {
    const DynamicThetaStep<WrittenDynamic, Eigen::Dynamic, WrittenForce> S(L, ThetaMap::midpoint(), h, {}, false,
                                                                            std::make_shared<WrittenForce>(text));
    double largest = 0.0;
    const double defect = osc.energy_balance(S, h, 1.0, 0.2, largest);
    BOOST_TEST(largest > 0.1);  // the force does work
    BOOST_TEST(defect <= 1e-13);
  }
  // x cyclic, y an oscillator; forces in both, the one along x in t, x, y and x_dot
  const auto planar = with_forces(written({"x", "y"}, {{"c", 0.3}}, "(x_dot^2 + y_dot^2)/2 - y^2/2 + x_dot*y_dot/4"),
                                  {{0, "-c*x_dot + cos(2*t)*y*cos(x)"}, {1, "-c*y_dot"}});
  const WrittenDynamic P(planar);
  const double theta = 0.3;
  const DynamicThetaStep<WrittenDynamic, Eigen::Dynamic, WrittenForce> S(P, ThetaMap(theta), h, {}, false,
                                                                          std::make_shared<WrittenForce>(planar));
  VectorXd q(2), p(2), dq(2), dp(2);
  q << 0.4, 1.0;
  p << 0.5, -0.2;
  dq = h * legendre_inverse(P, q, p);
  const double c = 0.3;
  double impulse = 0.0, compensation = 0.0, largest = 0.0;
  const double px0 = p[0];
  for (int k = 0; k < 400; ++k) {
    const double t = k * h;
    const StepSummary s = S.step(t, q, p, dq, dp);
    BOOST_TEST_REQUIRE(s.converged, "step " << k << ": " << s.message);
    // h F_x at the node, from the states alone
    const double x = q[0] + theta * dq[0], y = q[1] + theta * dq[1], xdot = dq[0] / h;
    const double term = h * (-c * xdot + std::cos(2 * (t + theta * h)) * y * std::cos(x)) - compensation;
    const double sum = impulse + term;
    compensation = (sum - impulse) - term;
    impulse = sum;
    largest = std::fmax(largest, std::fabs(impulse));
    q += dq;
    p += dp;
  }
  BOOST_TEST(largest > 0.1);
  BOOST_TEST(std::fabs((p[0] - px0) - impulse) <= 1e-13 * std::fmax(1.0, largest));
}

// The SODE and Newmark steps with a force (solvers/dynamic_sode_step.h), a = M^{-1}(L_q + F):
// - sode2 at theta = 1/2 is the forced midpoint position-momentum step on a separable L:
//   the same states and work of each step (to 1e-13, the round-off two codes accumulate
//   over 200 steps apart) on a coupled mass matrix with a force
//   in t, q and x_dot, which a force read at another time or point would not give;
// - the step's equation is linear on the driven damped oscillator, so Newton with the
//   exact Jacobian (F_v in its velocity columns) ends in at most two iterations: a
//   Jacobian without the force's terms takes more;
// - orders against the oscillator's exact solution: Newmark (1/2, 1/4) and (1/2, 0) 2,
//   sode1 at theta 0.3 1, sode2 at theta 0.3 composed with its adjoint 2, the triple
//   jump of Newmark 4 (each stage's force at its own time);
// - Newmark (1/2, 1/4) and sode2 at 1/2 keep E_N - E_0 = W_N to round-off (a quadratic
//   potential), and the adjoint of size -h from t0 + h undoes a step from t0.
BOOST_AUTO_TEST_CASE(forced_sode_and_newmark_steps) {
  using Sode = DynamicSodeStep<WrittenDynamic, WrittenForce>;
  const double h = 0.05;
  {
    const auto planar = with_forces(written({"x", "y"}, {{"c", 0.3}}, "(x_dot^2 + y_dot^2)/2 - y^2/2 + x_dot*y_dot/4"),
                                    {{0, "-c*x_dot + cos(2*t)*y*cos(x)"}, {1, "-c*y_dot + sin(t)*x"}});
    const WrittenDynamic P(planar);
    const auto force = std::make_shared<const WrittenForce>(planar);
    VectorXd q(2), p(2);
    q << 0.4, 1.0;
    p << 0.5, -0.2;
    const VectorXd v = legendre_inverse(P, q, p);
    const Sode S(P, Sode::mass_inverse(P, q, v), SodeScheme::sode(false, 0.5), h, {}, force);
    const DynamicThetaStep<WrittenDynamic, Eigen::Dynamic, WrittenForce> T(P, ThetaMap::midpoint(), h, {}, false,
                                                                            force);
    VectorXd qa = q, pa = p, qb = q, pb = p, da = h * v, db = h * v, ea(2), eb(2);
    double d = 0.0, dw = 0.0, work = 0.0;
    for (int k = 0; k < 200; ++k) {
      const StepSummary a = S.step(k * h, qa, pa, da, ea), b = T.step(k * h, qb, pb, db, eb);
      BOOST_TEST_REQUIRE((a.converged && b.converged));
      dw = std::fmax(dw, std::fabs(a.work - b.work));
      work += b.work;
      qa += da, pa += ea, qb += db, pb += eb;
      d = std::fmax(d, std::fmax((qa - qb).cwiseAbs().maxCoeff(), (pa - pb).cwiseAbs().maxCoeff()));
    }
    BOOST_TEST_MESSAGE("forced sode2 midpoint against the forced midpoint step: states " << d << ", work of a step "
                                                                                      << dw << " (of " << work << ")");
    BOOST_TEST(std::fabs(work) > 0.05);
    BOOST_TEST(d <= 1e-13);
    BOOST_TEST(dw <= 1e-13);
  }
  const DrivenOscillator osc;
  const auto text = osc.text();
  const WrittenDynamic L(text);
  const auto force = std::make_shared<const WrittenForce>(text);
  VectorXd q0(1), p0(1), v0(1);
  q0 << 1.0;
  v0 << 0.3;
  p0 = osc.m * v0;
  const auto Minv = Sode::mass_inverse(L, q0, v0);
  auto step = [&](const SodeScheme& sc, double hk) { return Sode(L, Minv, sc, hk, {}, force); };
  const std::vector<SodeScheme> schemes = {SodeScheme::newmark(0.5, 0.25), SodeScheme::newmark(0.6, 0.3),
                                           SodeScheme::sode(true, 0.3), SodeScheme::sode(false, 0.3, true)};
  for (const SodeScheme& sc : schemes) {
    BOOST_TEST_CONTEXT("kind " << static_cast<int>(sc.kind) << ", theta " << sc.theta << ", gamma " << sc.gamma) {
      RunSummary run;
      trajectory(step(sc, h), q0, p0, v0, 200, &run);
      BOOST_TEST(run.max_step_iterations <= 2);
      // the adjoint of size -h, from t0 + h, back to the start of a step from t0
      const double t0 = 0.7;
      const Sode S = step(sc, h), back = S.adjoint().with_step(-h);
      VectorXd dq = h * v0, dp = VectorXd::Zero(1);
      BOOST_TEST_REQUIRE(S.step(t0, q0, p0, dq, dp).converged);
      const VectorXd q1 = q0 + dq, p1 = p0 + dp;
      VectorXd eq = -dq, ep = VectorXd::Zero(1);
      BOOST_TEST_REQUIRE(back.step(t0 + h, q1, p1, eq, ep).converged);
      BOOST_TEST(std::fabs(q1[0] + eq[0] - q0[0]) <= 1e-15);
      BOOST_TEST(std::fabs(p1[0] + ep[0] - p0[0]) <= 1e-15);
      BOOST_TEST(std::fabs(dq[0]) >= 0.01);
    }
  }
  // orders against the exact solution
  const double T = 2.0;
  double xe, pe;
  osc.exact(T, q0[0], v0[0], xe, pe);
  auto composed = [&](const SodeScheme& sc, const char* scheme, double hk) {
    return ComposedStep<Sode>(
        hk, substeps(find_composition(scheme), sc.kind == SodeScheme::Kind::newmark ? sc.gamma == 0.5 : false),
        [&](double hj) { return step(sc, hj); }, [&](double hj) { return step(sc, hj).adjoint(); });
  };
  std::vector<double> hs, trapezoid, explicit_newmark, sode1, verlet, jump;
  for (int k = 0; k < 5; ++k) {
    const double hk = 0.1 / std::pow(2.0, k);
    hs.push_back(hk);
    auto error_of = [&](const auto& S) { return osc.final_error(S, hk, T, q0[0], v0[0], xe, pe); };
    trapezoid.push_back(error_of(step(SodeScheme::newmark(0.5, 0.25), hk)));
    explicit_newmark.push_back(error_of(step(SodeScheme::newmark(0.5, 0.0), hk)));
    sode1.push_back(error_of(step(SodeScheme::sode(true, 0.3), hk)));
    verlet.push_back(error_of(composed(SodeScheme::sode(false, 0.3), "stormer-verlet", hk)));
    jump.push_back(error_of(composed(SodeScheme::newmark(0.5, 0.25), "triple-jump:4", hk)));
  }
  const double o_trap = verification::fit_order(hs, trapezoid), o_expl = verification::fit_order(hs, explicit_newmark);
  const double o_sode1 = verification::fit_order(hs, sode1), o_verlet = verification::fit_order(hs, verlet);
  const double o_jump = verification::fit_order(hs, jump);
  BOOST_TEST_MESSAGE("forced sode orders: newmark (1/2, 1/4) " << o_trap << ", (1/2, 0) " << o_expl << ", sode1 theta 0.3 "
                                                               << o_sode1 << ", sode2 theta 0.3 with its adjoint "
                                                               << o_verlet << ", newmark triple jump " << o_jump);
  BOOST_TEST(std::fabs(o_trap - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_expl - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_sode1 - 1.0) <= 0.1);
  BOOST_TEST(std::fabs(o_verlet - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(o_jump - 4.0) <= 0.2);
  BOOST_TEST(trapezoid.back() <= 1e-4);  // close to the solution, not only converging
  // the energy balance
  for (const SodeScheme& sc : {SodeScheme::newmark(0.5, 0.25), SodeScheme::sode(false, 0.5)}) {
    double largest = 0.0;
    const double defect = osc.energy_balance(step(sc, h), h, q0[0], p0[0], largest);
    BOOST_TEST(largest > 0.1);
    BOOST_TEST(defect <= 1e-13);
  }
}

// ---------------------------------------------------------------------------------
// Failures.

BOOST_AUTO_TEST_CASE(a_degenerate_written_lagrangian_is_reported_not_crashed) {
  // L does not depend on v: L_vv = 0, the Legendre map has no inverse
  const WrittenDynamic L(written({"x", "y"}, {}, "-(x^2 + y^2)/2 + cos(x)*y"));
  const VectorXd q = random_vector(2, 0.5, 1), p = random_vector(2, 0.5, 2), v = VectorXd::Zero(2);
  BOOST_CHECK_THROW(legendre_inverse(L, q, p), DegenerateLagrangianError);
  BOOST_CHECK_THROW(legendre_inverse_checked(L, q, p), DegenerateLagrangianError);
  BOOST_CHECK_THROW(require_regular(L, q, v), DegenerateLagrangianError);
  // the Hamiltonian form: the Legendre transform fails inside the step, reported
  {
    const DynamicHamiltonianThetaStep<LegendreDynamicHamiltonian<WrittenDynamic>> S(
        LegendreDynamicHamiltonian<WrittenDynamic>(L), ThetaMap::midpoint(), 0.1);
    VectorXd dq = VectorXd::Zero(2), dp = VectorXd::Zero(2);
    StepSummary s;
    BOOST_CHECK_NO_THROW(s = S.step(0.0, q, p, dq, dp));
    BOOST_TEST(!s.converged);
    BOOST_TEST(s.message.find("not regular") != std::string::npos, s.message);
    VectorXd qq = q, pp = p;
    RunSummary run;
    BOOST_CHECK_NO_THROW(run = integrate(S, 0.0, qq, pp, v, 10, [](auto&&...) {}));
    BOOST_TEST(run.failed);
    BOOST_TEST(run.failed_step == 0);
  }
  // the Lagrangian form with theta = 0 or 1: the step Jacobian (1 - theta) L_qv -
  // theta L_qv^T - L_vv / h + h theta (1 - theta) L_qq vanishes
  auto singular = [&](const auto& S) {
    VectorXd dq = VectorXd::Zero(2), dp = VectorXd::Zero(2);
    StepSummary s;
    BOOST_CHECK_NO_THROW(s = S.step(0.0, q, p, dq, dp));
    BOOST_TEST(!s.converged);
    BOOST_TEST(s.message == "singular step Jacobian");
    VectorXd qq = q, pp = p;
    RunSummary run;
    BOOST_CHECK_NO_THROW(run = integrate(S, 0.0, qq, pp, v, 10, [](auto&&...) {}));
    BOOST_TEST(run.failed);
  };
  for (double theta : {0.0, 1.0}) {
    singular(DynamicThetaStep<WrittenDynamic>(L, ThetaMap(theta), 0.1));
    singular(DynamicThetaStep<WrittenDynamic, 2>(L, ThetaMap(theta), 0.1));
  }
  // (For 0 < theta < 1 the step equation p0 + h (1 - theta) L_q(x) = 0 of such an L is
  // solvable where L_qq is invertible: only the Legendre map, checked at the initial
  // state, detects the degeneracy there.)
}

BOOST_AUTO_TEST_CASE(bad_input_is_refused_at_construction_and_bad_states_reported) {
  StepOptions tiny;
  tiny.solver = SolverKind::tiny;
  const NBodyDynamic B(1.0, {1.0, 1.0});
  BOOST_CHECK_THROW(DynamicThetaStep<NBodyDynamic>(B, ThetaMap::midpoint(), 0.1, tiny), std::invalid_argument);
  BOOST_CHECK_THROW(DynamicThetaStep<NBodyDynamic>(B, ThetaMap::midpoint(), 0.0), std::invalid_argument);
  BOOST_CHECK_THROW(DynamicGalerkinStep<NBodyDynamic>(B, QuadratureKind::gauss, 2, 0.1, tiny), std::invalid_argument);
  const DynamicThetaStep<NBodyDynamic> S(B, ThetaMap::midpoint(), 0.1);
  VectorXd q = VectorXd::Zero(5), p = VectorXd::Zero(5), dq = q, dp = q;
  const StepSummary s = S.step(0.0, q, p, dq, dp);
  BOOST_TEST(!s.converged);
  BOOST_TEST(s.message.find("the system has 6") != std::string::npos, s.message);
  // two bodies at the same point: a non-finite residual, reported
  q = VectorXd::Zero(6);
  p = VectorXd::Zero(6);
  dq = q;
  dp = q;
  const StepSummary t = S.step(0.0, q, p, dq, dp);
  BOOST_TEST(!t.converged);
  BOOST_TEST(!t.message.empty());
}

// ---------------------------------------------------------------------------------
// No allocation in a step.

namespace {

// Heap allocations (Eigen's and operator new's) in `steps` steps, after one warm-up step.
template <class S, class = void>
struct has_reset : std::false_type {};
template <class S>
struct has_reset<S, std::void_t<decltype(std::declval<const S&>().reset())>> : std::true_type {};

template <class Step>
long allocations_in_steps(const Step& S, const VectorXd& q0, const VectorXd& p0, const VectorXd& guess, int steps,
                          bool reset_each = false) {
  VectorXd q = q0, p = p0, dq = guess, dp = VectorXd::Zero(q0.size());
  BOOST_TEST(S.step(0.0, q, p, dq, dp).converged);
  q += dq;
  p += dp;
  const long e0 = dvm_test::eigen_mallocs, n0 = dvm_test::operator_news;
  Eigen::internal::set_is_malloc_allowed(false);
  bool ok = true;
  for (int k = 0; k < steps; ++k) {
    if constexpr (has_reset<Step>::value)
      if (reset_each) S.reset();  // a refresh of the Jacobian in every step
    ok = ok && S.step(0.0, q, p, dq, dp).converged;
    q += dq;
    p += dp;
  }
  Eigen::internal::set_is_malloc_allowed(true);
  BOOST_TEST(ok);
  return (dvm_test::eigen_mallocs - e0) + (dvm_test::operator_news - n0);
}

}  // namespace

BOOST_AUTO_TEST_CASE(steps_allocate_nothing) {
  // the check itself works
  {
    const long e0 = dvm_test::eigen_mallocs;
    Eigen::internal::set_is_malloc_allowed(false);
    VectorXd x(1000);
    Eigen::internal::set_is_malloc_allowed(true);
    BOOST_TEST(dvm_test::eigen_mallocs - e0 == 1);
    BOOST_TEST(x.size() == 1000);
  }
  const double h = 0.01;
  VectorXd q, p;
  nbody3_state(q, p);
  const NBodyDynamic B(1.2, {1.0, 0.3, 0.01});
  const VectorXd g3 = h * legendre_inverse(B, q, p);
  BOOST_TEST(allocations_in_steps(DynamicThetaStep<NBodyDynamic>(B, ThetaMap::midpoint(), h), q, p, g3, 5) == 0);
  BOOST_TEST(allocations_in_steps(DynamicGalerkinStep<NBodyDynamic>(B, QuadratureKind::gauss, 3, h), q, p, g3, 5, true) == 0);
  {  // the SODE and Newmark steps: their Newton iteration and M's factorisation
    const auto Minv = DynamicSodeStep<NBodyDynamic>::mass_inverse(B, q, g3 / h);
    using Sode = DynamicSodeStep<NBodyDynamic>;
    BOOST_TEST(allocations_in_steps(Sode(B, Minv, SodeScheme::sode(false, 0.5), h), q, p, g3, 5) == 0);
    BOOST_TEST(allocations_in_steps(Sode(B, Minv, SodeScheme::newmark(0.6, 0.3), h), q, p, g3, 5) == 0);
  }

  const auto text = written_kepler();
  Vec<double, 2> qf, pf;
  verification::kepler_initial(0.5, qf, pf);
  const VectorXd qk = qf, pk = pf, gk = h * pk;
  BOOST_TEST(allocations_in_steps(DynamicThetaStep<WrittenDynamic>(WrittenDynamic(text), ThetaMap(0.3), h), qk, pk, gk, 5) == 0);
  BOOST_TEST(allocations_in_steps(DynamicThetaStep<WrittenDynamic, 2>(WrittenDynamic(text), ThetaMap(0.3), h), qk, pk, gk, 5) == 0);
  {  // with a force: its value and Jacobian too
    const auto driven = DrivenOscillator().text();
    const auto force = std::make_shared<WrittenForce>(driven);
    const VectorXd q1 = VectorXd::Constant(1, 0.7), p1 = VectorXd::Constant(1, 0.2), g1 = h * p1;
    using Dyn = DynamicThetaStep<WrittenDynamic, Eigen::Dynamic, WrittenForce>;
    using One = DynamicThetaStep<WrittenDynamic, 1, WrittenForce>;
    BOOST_TEST(allocations_in_steps(Dyn(WrittenDynamic(driven), ThetaMap(0.3), h, {}, false, force), q1, p1, g1, 5) == 0);
    BOOST_TEST(allocations_in_steps(One(WrittenDynamic(driven), ThetaMap(0.3), h, {}, false, force), q1, p1, g1, 5) == 0);
  }
  BOOST_TEST(allocations_in_steps(DynamicHamiltonianThetaStep<WrittenDynamicHamiltonian>(WrittenDynamicHamiltonian(text),
                                                                                        ThetaMap::midpoint(), h),
                                  qk, pk, gk, 5) == 0);
  // Newton's inverse of the Legendre map inside every evaluation of H
  BOOST_TEST(allocations_in_steps(DynamicHamiltonianThetaStep<LegendreDynamicHamiltonian<WrittenDynamic>>(
                                      LegendreDynamicHamiltonian<WrittenDynamic>(WrittenDynamic(text)), ThetaMap::midpoint(), h),
                                  qk, pk, gk, 5) == 0);
  BOOST_TEST(allocations_in_steps(DynamicGalerkinStep<WrittenDynamic>(WrittenDynamic(text), QuadratureKind::lobatto, 4, h),
                                  qk, pk, gk, 5, true) == 0);
  // large: the 50-coordinate chain (forward over forward), a 100 x 100 Galerkin Jacobian
  const WrittenDynamic C(written_chain(50));
  const VectorXd qc = random_vector(50, 0.3, 1), pc = random_vector(50, 0.3, 2);
  BOOST_TEST(allocations_in_steps(DynamicThetaStep<WrittenDynamic>(C, ThetaMap::midpoint(), 0.05), qc, pc, VectorXd(0.05 * pc), 2) == 0);
  BOOST_TEST(allocations_in_steps(DynamicGalerkinStep<WrittenDynamic>(C, QuadratureKind::gauss, 2, 0.05), qc, pc,
                                  VectorXd(0.05 * pc), 2, true) == 0);
  // Jacobians kept across steps (Refresh::across_steps of solvers/newton_driver.h), formed again in every step here
  BOOST_TEST(allocations_in_steps(DynamicThetaStep<WrittenDynamic>(C, ThetaMap::midpoint(), 0.05, {}, true), qc, pc,
                                  VectorXd(0.05 * pc), 3, true) == 0);
  BOOST_TEST(allocations_in_steps(
                 DenseSeparableThetaStep<NBodyDynamic>(B, DenseSeparableThetaStep<NBodyDynamic>::workspace(B), 0.5, h), q,
                 p, g3, 5, true) == 0);
}

namespace {
// A scalar equation for newton_drive: F(x) = a (x^2 - c) (domain: all x), or, with
// logarithm = true, F(x) = log(x / c) (domain x > 0; NaN outside; Newton's method from x
// stays in it while x < e c).
struct ScalarEquation {
  using Vector = Eigen::Matrix<double, 1, 1>;
  using Matrix = Eigen::Matrix<double, 1, 1>;
  double a = 1.0, c = 4.0;
  bool logarithm = false;
  int outside = 0;  // residuals asked for outside the domain
  double f(double x) const { return logarithm ? std::log(x / c) : a * (x * x - c); }
  double df(double x) const { return logarithm ? 1.0 / x : 2.0 * a * x; }
  void residual(const Vector& x, Vector& r) {
    outside += logarithm && !(x[0] > 0.0);
    r[0] = f(x[0]);
  }
  double jacobian(const Vector& x, Vector& r, Matrix& J) {
    r[0] = f(x[0]);
    J(0, 0) = df(x[0]);
    return std::isfinite(J(0, 0)) ? std::fabs(J(0, 0)) : INFINITY;
  }
  double scale(double xn, double Jmax) const { return std::fabs(c) + Jmax * xn; }
  double offset() const { return 0.0; }
};
}  // namespace

// The driver's refresh of a kept Jacobian and its failure messages: a Jacobian kept from
// another equation that throws the iterate out of the domain (a NaN residual) makes the
// driver start again from the guess with a fresh Jacobian, and it converges; an
// equation with no root ends with the iteration count and the Jacobians formed in its
// message; a zero Jacobian is reported as singular.
BOOST_AUTO_TEST_CASE(the_driver_restarts_from_the_guess_and_names_its_failures) {
  using V = ScalarEquation::Vector;
  using M = ScalarEquation::Matrix;
  DenseLUOf<1> lu(1);
  DriverState state;
  V x, r, dx, start;
  M J;
  StepOptions opt;
  // 0.05 (x^2 - 4) = 0 from 3: the factorisation of J = 0.1 x near x = 2 is kept
  ScalarEquation first{0.05, 4.0, false, 0};
  x[0] = 3.0;
  StepSummary s = newton_drive(first, lu, Refresh::across_steps, opt, x, r, dx, J, state, start);
  BOOST_TEST_REQUIRE(s.converged);
  BOOST_TEST(x[0] == 2.0, boost::test_tools::tolerance(1e-15));
  BOOST_TEST_REQUIRE(state.valid);
  // log(x / 0.5) = 0 from 1 with that Jacobian: the first update, log(2) / 0.2 or so,
  // lands at x < 0; Newton's method from 1 itself stays in the domain
  ScalarEquation second{1.0, 0.5, true, 0};
  x[0] = 1.0;
  s = newton_drive(second, lu, Refresh::across_steps, opt, x, r, dx, J, state, start);
  BOOST_TEST(s.converged, s.message);
  BOOST_TEST(x[0] == 0.5, boost::test_tools::tolerance(1e-14));
  BOOST_TEST(second.outside == 1);  // the kept Jacobian's iterate, once
  BOOST_TEST(s.jacobians >= 1);
  BOOST_TEST(s.iterations >= 2);  // the kept Jacobian's iterate, then Newton from the guess
  // x^2 + 1 = 0 has no real root
  ScalarEquation none{1.0, -1.0, false, 0};
  x[0] = 0.7;
  opt.max_iterations = 12;
  s = newton_drive(none, lu, Refresh::every_iteration, opt, x, r, dx, J, state, start);
  BOOST_TEST(!s.converged);
  BOOST_TEST(s.message.find("no convergence within 12 iterations") != std::string::npos, s.message);
  BOOST_TEST(s.message.find("Jacobians formed") != std::string::npos, s.message);
  // at x = 0 the Jacobian of x^2 - 4 is zero (and the residual is not)
  ScalarEquation flat{1.0, 4.0, false, 0};
  x[0] = 0.0;
  s = newton_drive(flat, lu, Refresh::every_iteration, opt, x, r, dx, J, state, start);
  BOOST_TEST(!s.converged);
  BOOST_TEST(s.message.find("singular step Jacobian") != std::string::npos, s.message);
}
