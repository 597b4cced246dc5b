// Structure (mechanics/structure.h) and the explicit steps it allows
// (solvers/splitting_step.h):
//   - every built-in system on R^n (n bodies of any number included) declares the class its Lagrangian has, and the
//     sampled test finds exactly that class (double pendulum mechanical, charged
//     particle general); mislabelled systems are refused, each by the identity it breaks;
//   - the explicit steps of the Euler maps, alone and in every composition, give the
//     states the generic Newton path gives, through the runtime (use_structure true and
//     false), on every separable built-in;
//   - Galerkin Gauss on a separable system runs as Gauss collocation on the stage forces,
//     with the generic Galerkin step's states;
//   - first same as last: velocity Verlet costs one force per step;
//   - a full (non-diagonal) mass matrix is solved with, not inverted entry by entry.
#define BOOST_TEST_MODULE splitting
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "mechanics/systems_classic.h"
#include "mechanics/written_dynamic.h"
#include "mechanics/written_lagrangian.h"
#include "solvers/composition.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"
#include "solvers/runtime/problem.h"
#include "solvers/separable_theta_step.h"
#include "solvers/runtime/run.h"
#include "solvers/splitting_step.h"
#include "tests/solvers/structured_runs.h"

using namespace dvm;

namespace {

using V1 = Vec<double, 1>;
using V2 = Vec<double, 2>;

// ---- mislabelled systems -------------------------------------------------------------
// declares separable, but its mass depends on q (it is mechanical)
struct MassOnQ {
  static constexpr int dim = 1;
  static constexpr Structure structure = Structure::separable;
  std::string name() const { return "mass-on-q"; }
  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& v) const {
    return 0.5 * (1.0 + q[0] * q[0]) * v[0] * v[0] - 0.5 * q[0] * q[0];
  }
};
// declares separable, but has a term linear in v (a magnetic-type coupling q v)
struct LinearInV {
  static constexpr int dim = 1;
  static constexpr Structure structure = Structure::separable;
  std::string name() const { return "linear-in-v"; }
  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& v) const {
    return 0.5 * v[0] * v[0] + 0.3 * q[0] * v[0] - 0.5 * q[0] * q[0];
  }
};
// the same, declared mechanical: still wrong (dL/dv(q, 0) = 0.3 q)
struct LinearInVMechanical : LinearInV {
  static constexpr Structure structure = Structure::mechanical;
};
// declares separable, quadratic in v with a constant but indefinite "mass"
struct Indefinite {
  static constexpr int dim = 2;
  static constexpr Structure structure = Structure::separable;
  std::string name() const { return "indefinite"; }
  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    return 0.5 * (v[0] * v[0] - v[1] * v[1]) - 0.5 * (q[0] * q[0] + q[1] * q[1]);
  }
};
// declares mechanical, kinetic energy quartic in v
struct Quartic {
  static constexpr int dim = 1;
  static constexpr Structure structure = Structure::mechanical;
  std::string name() const { return "quartic"; }
  template <class T>
  T operator()(const Vec<T, 1>& q, const Vec<T, 1>& v) const {
    return 0.5 * v[0] * v[0] + 0.1 * v[0] * v[0] * v[0] * v[0] - 0.5 * q[0] * q[0];
  }
};

template <class S>
std::string refusal(const S& L, const Vec<double, S::dim>& q, const Vec<double, S::dim>& v) {
  try {
    check_structure(L, q, v);
  } catch (const StructureError& e) {
    return e.what();
  }
  return "";
}

// ---- a separable system with a full mass matrix, and one that counts its forces --------
// L = v^T M v / 2 - (|q|^2/2 + q0^4/4), M = [[2, 0.5], [0.5, 1]]
struct FullMass {
  static constexpr int dim = 2;
  static constexpr Structure structure = Structure::separable;
  std::shared_ptr<int> forces = std::make_shared<int>(0);
  std::string name() const { return "full-mass"; }
  template <class T>
  T operator()(const Vec<T, 2>& q, const Vec<T, 2>& v) const {
    return 0.5 * (2.0 * v[0] * v[0] + v[0] * v[1] + v[1] * v[1]) -
           (0.5 * (q[0] * q[0] + q[1] * q[1]) + 0.25 * q[0] * q[0] * q[0] * q[0]);
  }
  template <class T>
  void gradient(const Vec<T, 2>& q, const Vec<T, 2>& v, Vec<T, 2>& dLdq, Vec<T, 2>& dLdv) const {
    ++*forces;
    dLdq[0] = -q[0] - q[0] * q[0] * q[0];
    dLdq[1] = -q[1];
    dLdv[0] = 2.0 * v[0] + 0.5 * v[1];
    dLdv[1] = 0.5 * v[0] + v[1];
  }
};

// ---- the runtime: built-in problems with use_structure on and off ------------------------
Problem builtin(const std::string& name, std::vector<double> q, std::vector<double> v) {
  Problem pr;
  pr.system = &find_system_entry(name, "test");
  for (const ParamEntry& e : pr.system->params) pr.params[e.name] = e.default_value;
  pr.dim = static_cast<int>(q.size());
  pr.q = std::move(q);
  pr.v = std::move(v);
  pr.step = 0.01;
  pr.steps = 300;
  return pr;
}

std::vector<Problem> separable_problems() {
  std::vector<Problem> out;
  out.push_back(builtin("harmonic", {1.0}, {0.5}));
  out.push_back(builtin("pendulum", {2.0}, {0.0}));
  out.push_back(builtin("kepler", {0.4, 0.0}, {0.0, 2.0}));
  out.push_back(builtin("henon-heiles", {0.1, -0.2}, {0.3, 0.2}));
  out.push_back(builtin("duffing", {1.0}, {0.0}));
  Problem fpu = builtin("fpu", {0.2, 0.2 + 1.0 / 50, 0.0, 0.0, 0.0, 0.0}, {0, 0, 0, 0, 0, 0});
  fpu.step = 0.002;  // omega = 50
  out.push_back(fpu);
  Problem nb = builtin("nbody", {1, 0, 0, -1, 0, 0, 0, 0.5, 0.1}, {0, 0.5, 0, 0, -0.5, 0.1, 0.2, 0, 0});
  nb.masses = {1.0, 1.0, 0.1};
  out.push_back(nb);
  return out;
}

std::shared_ptr<WrittenSystem> written(std::vector<std::string> coordinates, const std::string& L,
                                       std::vector<std::pair<std::string, double>> params = {}) {
  auto w = std::make_shared<WrittenSystem>();
  w->coordinates = std::move(coordinates);
  w->params = std::move(params);
  w->check_names();
  w->lagrangian = Expression::parse(L, w->symbols(WrittenSystem::Kind::lagrangian));
  return w;
}

Problem written_problem(const std::shared_ptr<WrittenSystem>& w, std::vector<double> q, std::vector<double> v) {
  Problem pr;
  pr.system = &written_system_entry();
  pr.written = w;
  pr.dim = static_cast<int>(q.size());
  pr.q = std::move(q);
  pr.v = std::move(v);
  pr.step = 0.01;
  pr.steps = 10;
  return pr;
}

// Both explicit Euler maps with no composition, dirk (weights 0.3, 0.4, 0.3), every
// registered composition and the `extra` ones.
std::vector<Method> explicit_methods(std::vector<std::string> compositions) {
  compositions.insert(compositions.begin(), {"none", "dirk"});
  for (const CompositionScheme& c : composition_schemes()) compositions.push_back(c.name);
  std::vector<Method> out;
  for (const char* map : {"explicit-euler", "adjoint-euler"})
    for (const std::string& c : compositions) {
      Method me;
      me.map = &find_map_entry(map, "test");
      me.theta = me.map->theta;
      me.composition = c;
      if (c == "dirk") me.weights = {0.3, 0.4, 0.3};
      out.push_back(me);
    }
  return out;
}

}  // namespace

BOOST_AUTO_TEST_CASE(builtin_declarations_match_their_lagrangians) {
  // the sampled class of each built-in equals its declaration, and the check passes
  auto expect = [](const auto& L, const auto& q, const auto& v, Structure s) {
    using S = std::decay_t<decltype(L)>;
    BOOST_TEST_CONTEXT(L.name()) {
      BOOST_TEST((declared_structure<S>::value == s));
      BOOST_TEST((sampled_structure(L, q, v) == s));
      BOOST_TEST(refusal(L, q, v).empty());
    }
  };
  expect(HarmonicOscillator(2.0), V1(1.0), V1(0.5), Structure::separable);
  expect(Pendulum(1.3, 0.7, 9.81), V1(2.0), V1(0.0), Structure::separable);
  expect(Kepler(), V2(0.4, 0.0), V2(0.0, 2.0), Structure::separable);
  expect(HenonHeiles(), V2(0.1, -0.2), V2(0.3, 0.2), Structure::separable);
  expect(Duffing(1.0, 2.0), V1(1.0), V1(0.0), Structure::separable);
  expect(FermiPastaUlam(), Vec<double, 6>::Constant(0.1), Vec<double, 6>::Zero(), Structure::separable);
  expect(NBody<2>(1.0, {1.0, 0.5}), (Vec<double, 6>() << 1, 0, 0, -1, 0, 0).finished(),
         (Vec<double, 6>() << 0, 0.5, 0, 0, -0.5, 0).finished(), Structure::separable);
  expect(DoublePendulum(), V2(0.5, 1.0), V2(0.1, -0.3), Structure::mechanical);
  expect(ChargedParticle(), V2(1.0, 0.2), V2(0.0, 1.0), Structure::general);
}

BOOST_AUTO_TEST_CASE(mislabelled_systems_are_refused) {
  // each refusal names the system, its declaration and the identity that fails
  const std::string a = refusal(MassOnQ{}, V1(0.7), V1(0.2));
  BOOST_TEST(a.find("mass-on-q: declared separable") != std::string::npos, a);
  BOOST_TEST(a.find("M the same at every q") != std::string::npos, a);
  const std::string b = refusal(LinearInV{}, V1(0.7), V1(0.2));
  BOOST_TEST(b.find("declared separable") != std::string::npos, b);
  BOOST_TEST(b.find("dL/dv(q, 0) = 0") != std::string::npos, b);
  const std::string c = refusal(LinearInVMechanical{}, V1(0.7), V1(0.2));
  BOOST_TEST(c.find("declared mechanical") != std::string::npos, c);
  BOOST_TEST(c.find("dL/dv(q, 0) = 0") != std::string::npos, c);
  const std::string d = refusal(Indefinite{}, V2(0.7, 0.1), V2(0.2, 0.0));
  BOOST_TEST(d.find("M positive definite") != std::string::npos, d);
  const std::string e = refusal(Quartic{}, V1(0.7), V1(0.2));
  BOOST_TEST(e.find("declared mechanical") != std::string::npos, e);
  BOOST_TEST(e.find("p linear in v") != std::string::npos, e);
  // and what the samples find instead
  BOOST_TEST((sampled_structure(MassOnQ{}, V1(0.7), V1(0.2)) == Structure::mechanical));
  BOOST_TEST((sampled_structure(LinearInV{}, V1(0.7), V1(0.2)) == Structure::general));
  BOOST_TEST((sampled_structure(Quartic{}, V1(0.7), V1(0.2)) == Structure::general));
  // the explicit step will not take an indefinite mass matrix either
  BOOST_CHECK_THROW(ExplicitSplittingStep<Indefinite>(Indefinite{}, 0.0, 0.1, single_substep(), V2(0.7, 0.1)),
                    std::invalid_argument);
  BOOST_CHECK_THROW(ExplicitSplittingStep<FullMass>(FullMass{}, 0.5, 0.1, single_substep(), V2(0.7, 0.1)),
                    std::invalid_argument);
}

BOOST_AUTO_TEST_CASE(explicit_steps_equal_the_generic_path_on_every_separable_builtin) {
  for (const Problem& pr : separable_problems())
    for (const Method& me : explicit_methods({"triple-jump:6"})) {
      Method generic = me;
      generic.use_structure = false;
      const RunReport a = run(pr, me), b = run(pr, generic);
      BOOST_TEST_CONTEXT(pr.system->name << ", " << me.map->name << ", " << me.composition) {
        BOOST_TEST(!a.failed);
        BOOST_TEST(!b.failed);
        BOOST_TEST(a.step_path == StepPath::explicit_splitting);
        BOOST_TEST(b.step_path == StepPath::generic);
        BOOST_TEST(a.solver_iterations == 0);
        BOOST_TEST(b.solver_iterations > 0);
        BOOST_TEST(a.structure == "separable");
        BOOST_TEST(a.structure_source == "declared");
        // Newton stops at a relative residual of 2e-15 per substep: the two paths
        // agree to that over the run
        BOOST_TEST(max_diff(a.q_final, b.q_final) <= 1e-11 * std::fmax(1.0, max_abs(b.q_final)));
        BOOST_TEST(max_diff(a.p_final, b.p_final) <= 1e-11 * std::fmax(1.0, max_abs(b.p_final)));
        BOOST_TEST(std::fabs(a.max_abs_energy_error - b.max_abs_energy_error) <=
                   1e-9 * std::fmax(1.0, std::fabs(a.energy_initial)));
      }
    }
}

// The theta maps that are not explicit (midpoint, theta 0.3 and 0.7), alone, composed,
// as a DIRK and with a theta per stage: Newton on the structured equation
// (solvers/separable_theta_step.h) gives the generic path's states (use_structure =
// false) to the Newton tolerance over the run, with no more Jacobians, through the
// runtime on FPU (the separable built-in of fixed size >= 3) and as step types on every
// separable built-in of 1 and 2 coordinates.
BOOST_AUTO_TEST_CASE(implicit_theta_maps_on_separable_systems_equal_the_generic_path) {
  const std::vector<Method> methods = implicit_theta_methods();
  int compared = 0;
  for (const Problem& pr : separable_problems()) {
    if (pr.dim < 3 || pr.system->name == "nbody") continue;  // small or run-time sized: the generic path
    for (const Method& me : methods) {
      Method generic = me;
      generic.use_structure = false;
      validate(pr, me);
      const RunReport a = run(pr, me), b = run(pr, generic);
      BOOST_TEST_CONTEXT(pr.system->name << ", " << me.label()) {
        BOOST_TEST(!a.failed);
        BOOST_TEST(!b.failed);
        BOOST_TEST(a.step_path == StepPath::separable_newton);
        BOOST_TEST(b.step_path == StepPath::generic);
        BOOST_TEST(a.jacobians <= b.jacobians);
        BOOST_TEST(max_diff(a.q_final, b.q_final) <= 1e-11 * std::fmax(1.0, max_abs(b.q_final)));
        BOOST_TEST(max_diff(a.p_final, b.p_final) <= 1e-11 * std::fmax(1.0, max_abs(b.p_final)));
        ++compared;
      }
    }
  }
  BOOST_TEST(compared == 15);
  // the step types themselves on the small systems, 300 steps of a midpoint and a theta
  // 0.3 map, against PositionMomentumStep
  auto compare = [](const auto& L, const auto& q0, const auto& p0, double h, const char* what) {
    using Sys = std::decay_t<decltype(L)>;
    using Vn = Vec<double, Sys::dim>;
    for (double th : {0.5, 0.3}) {
      const SeparableThetaStep<Sys> A(L, th, h, StepOptions{}, q0);
      const PositionMomentumStep<Sys, ThetaMap> B(L, ThetaMap(th), h);
      Vn qa = q0, pa = p0, qb = q0, pb = p0;
      const bool fa = integrate(A, 0.0, qa, pa, p0, 300, [](auto&&...) {}).failed;
      const bool fb = integrate(B, 0.0, qb, pb, p0, 300, [](auto&&...) {}).failed;
      BOOST_TEST_CONTEXT(what << ", theta " << th) {
        BOOST_TEST(!fa);
        BOOST_TEST(!fb);
        BOOST_TEST((qa - qb).cwiseAbs().maxCoeff() <= 1e-12 * std::fmax(1.0, qb.cwiseAbs().maxCoeff()));
        BOOST_TEST((pa - pb).cwiseAbs().maxCoeff() <= 1e-12 * std::fmax(1.0, pb.cwiseAbs().maxCoeff()));
      }
    }
  };
  compare(Kepler(), V2(0.4, 0.0), V2(0.0, 2.0), 0.01, "kepler");
  compare(Pendulum(1.0, 1.0, 1.0), V1(2.0), V1(0.0), 0.01, "pendulum");
  compare(HenonHeiles(), V2(0.1, -0.2), V2(0.3, 0.2), 0.01, "henon-heiles");
}

// The splittings into kicks and drifts (blanes-moan4, blanes-moan6) are the same method
// from either Euler map and from either form (the cotangent lift of an Euler map is a
// symplectic Euler method), and are refused where their order does not hold: another
// map, form or lift, a manifold, a system that is not separable (declared or read off
// a written text).
BOOST_AUTO_TEST_CASE(splittings_are_one_method_and_refused_where_their_order_fails) {
  auto method = [](const char* map, const char* composition, Form form = Form::lagrangian) {
    Method me;
    me.map = &find_map_entry(map, "test");
    me.theta = me.map->theta;
    me.composition = composition;
    me.form = form;
    return me;
  };
  auto refused = [](const Problem& pr, const Method& me, const std::string& key, const std::string& word) {
    try {
      validate(pr, me);
      run(pr, me);
    } catch (const InputError& e) {
      const std::string m = e.what();
      BOOST_TEST(m.find(key) != std::string::npos, m);
      BOOST_TEST(m.find(word) != std::string::npos, m);
      return true;
    }
    return false;
  };
  const Problem kepler = builtin("kepler", {0.4, 0.0}, {0.0, 2.0});
  for (const char* c : {"blanes-moan4", "blanes-moan6"}) {
    BOOST_TEST_CONTEXT(c) {
      const RunReport a = run(kepler, method("explicit-euler", c));
      const RunReport b = run(kepler, method("adjoint-euler", c));
      const RunReport h = run(kepler, method("explicit-euler", c, Form::hamiltonian));
      const RunReport t = run(kepler, [&] {
        Method me = method("theta", c);
        me.theta = 1.0;
        return me;
      }());
      BOOST_TEST(a.step_path == StepPath::explicit_splitting);
      BOOST_TEST(h.step_path == StepPath::generic);
      // the same kicks and drifts: equal to the last bit from either Euler map
      BOOST_TEST(max_diff(a.q_final, b.q_final) == 0.0);
      BOOST_TEST(max_diff(a.p_final, b.p_final) == 0.0);
      BOOST_TEST(max_diff(b.q_final, t.q_final) == 0.0);
      // the Hamiltonian form's Newton solves: to their tolerance
      BOOST_TEST(max_diff(a.q_final, h.q_final) <= 1e-12);
      BOOST_TEST(max_diff(a.p_final, h.p_final) <= 1e-12);
      // refused: another map, form or lift, a manifold, a non-separable system
      BOOST_TEST(refused(kepler, method("midpoint", c), "integrator.composition", "\"midpoint\""));
      BOOST_TEST(refused(kepler, [&] {
        Method me = method("theta", c);
        me.theta = 0.3;
        return me;
      }(), "integrator.composition", "theta 0.3"));
      BOOST_TEST(refused(kepler, method("explicit-euler", c, Form::sode1), "integrator.composition", "sode1"));
      BOOST_TEST(refused(kepler, [&] {
        Method me = method("explicit-euler", c, Form::hamiltonian);
        me.lift = Lift::none;
        return me;
      }(), "integrator.composition", "lift"));
      Problem sphere;
      sphere.system = &find_system_entry("spherical-pendulum", "test");
      for (const ParamEntry& e : sphere.system->params) sphere.params[e.name] = e.default_value;
      sphere.dim = 3;
      sphere.q = {0.6, 0.0, -0.8};
      sphere.v = {0.0, 0.9, 0.0};
      sphere.step = 0.01;
      sphere.steps = 10;
      BOOST_TEST(refused(sphere, method("sphere-exp", c), "integrator.composition", "R^n"));
      BOOST_TEST(refused(builtin("double-pendulum", {0.5, 1.0}, {0.1, -0.3}), method("explicit-euler", c),
                         "integrator.composition", "\"mechanical\" (declared)"));
      BOOST_TEST(refused(written_problem(written({"a", "b"}, "a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + 2*cos(a) + cos(b)"),
                                         {0.5, 1.0}, {0.1, -0.3}),
                         method("explicit-euler", c), "integrator.composition", "\"mechanical\" (expression)"));
      BOOST_TEST(refused(builtin("charged-particle", {1.0, 0.2}, {0.0, 1.0}), method("adjoint-euler", c),
                         "integrator.composition", "\"general\""));
    }
  }
}

// Galerkin with Gauss quadrature on a separable system is Gauss collocation iterated on
// the stage forces (solvers/collocation_step.h): the same final states as the generic
// Galerkin step (use_structure = false) for every separable built-in and s = 1, 3, 6,
// and for written separable texts (run-time sized); Lobatto and non-separable systems
// keep the generic step.
BOOST_AUTO_TEST_CASE(galerkin_gauss_on_separable_systems_is_collocation_on_the_stage_forces) {
  auto galerkin = [](int s, QuadratureKind k) {
    Method me;
    me.map = &find_map_entry("midpoint", "test");
    me.galerkin = true;
    me.stages = s;
    me.quadrature = k;
    return me;
  };
  std::vector<Problem> problems = separable_problems();
  problems.push_back(written_problem(written({"x", "y"}, "(x_dot^2 + y_dot^2)/2 - x^2*y + (x^2 + y^2)/2"),
                                     {0.3, 0.1}, {0.0, 0.2}));
  problems.back().steps = 300;
  for (const Problem& pr : problems)
    for (int s : {1, 3, 6}) {
      const Method me = galerkin(s, QuadratureKind::gauss);
      Method generic = me;
      generic.use_structure = false;
      const RunReport a = run(pr, me), b = run(pr, generic);
      BOOST_TEST_CONTEXT(pr.system->name << ", s = " << s) {
        BOOST_TEST(!a.failed, a.loop.failure.message);
        BOOST_TEST(!b.failed);
        BOOST_TEST(a.step_path == StepPath::gauss_collocation);
        BOOST_TEST(b.step_path == StepPath::generic);
        BOOST_TEST(a.newton_steps == 0);
        BOOST_TEST(b.newton_steps == -1);
        BOOST_TEST(max_diff(a.q_final, b.q_final) <= 1e-11 * std::fmax(1.0, max_abs(b.q_final)));
        BOOST_TEST(max_diff(a.p_final, b.p_final) <= 1e-11 * std::fmax(1.0, max_abs(b.p_final)));
      }
    }
  const Problem kepler = builtin("kepler", {0.4, 0.0}, {0.0, 2.0});
  BOOST_TEST(run(kepler, galerkin(3, QuadratureKind::lobatto)).step_path == StepPath::generic);
  BOOST_TEST(run(builtin("double-pendulum", {0.5, 1.0}, {0.1, -0.3}), galerkin(3, QuadratureKind::gauss)).step_path ==
             StepPath::generic);
  const std::string j = report_json(run(kepler, galerkin(6, QuadratureKind::gauss)));
  BOOST_TEST(j.find("\"step_path\": \"gauss-collocation\"") != std::string::npos, j);
  BOOST_TEST(j.find("\"newton_steps\": 0") != std::string::npos, j);
}

BOOST_AUTO_TEST_CASE(implicit_maps_take_the_structured_newton_step_and_tiny_the_generic_path) {
  const Problem pr = builtin("kepler", {0.4, 0.0}, {0.0, 2.0});
  Method mid;
  mid.map = &find_map_entry("midpoint", "test");
  BOOST_TEST(run(pr, mid).step_path == StepPath::generic);  // 2 coordinates: the generic step
  const Problem fpu = builtin("fpu", {0.2, 0.2 + 1.0 / 50, 0.0, 0.0, 0.0, 0.0}, {0, 0, 0, 0, 0, 0});
  BOOST_TEST(run(fpu, mid).step_path == StepPath::separable_newton);
  Method mid_tiny = mid;
  mid_tiny.solver = SolverKind::tiny;
  BOOST_TEST(run(fpu, mid_tiny).step_path == StepPath::generic);
  Method tiny;
  tiny.map = &find_map_entry("explicit-euler", "test");
  tiny.theta = 0.0;
  tiny.solver = SolverKind::tiny;
  BOOST_TEST(run(pr, tiny).step_path == StepPath::generic);
  Method ham = tiny;
  ham.solver = SolverKind::newton;
  ham.form = Form::hamiltonian;
  BOOST_TEST(run(pr, ham).step_path == StepPath::generic);
}

BOOST_AUTO_TEST_CASE(structure_is_reported_for_every_system_on_rn) {
  Method me;
  me.map = &find_map_entry("midpoint", "test");
  const RunReport dp = run(builtin("double-pendulum", {0.5, 1.0}, {0.1, -0.3}), me);
  BOOST_TEST(dp.structure == "mechanical");
  BOOST_TEST(dp.structure_source == "declared");
  const RunReport cp = run(builtin("charged-particle", {1.0, 0.2}, {0.0, 1.0}), me);
  BOOST_TEST(cp.structure == "general");
  BOOST_TEST(cp.structure_source == "declared");
  // written Lagrangians: read off their text (Expression::split_velocity)
  const RunReport ws = run(written_problem(written({"x", "y"}, "(x_dot^2 + y_dot^2)/2 - x^2*y"), {0.3, 0.1}, {0.0, 0.2}), me);
  BOOST_TEST(ws.structure == "separable");
  BOOST_TEST(ws.structure_source == "expression");
  BOOST_TEST(ws.step_path == StepPath::generic);  // midpoint on 2 coordinates: L's Hessian each iteration
  BOOST_TEST(ws.derivatives == "program");
  // from 3 coordinates: Newton on the structured equation with the sparse Hess V
  const RunReport w3 =
      run(written_problem(written({"x", "y", "z"}, "(x_dot^2 + y_dot^2 + z_dot^2)/2 - x^2*y - z^4"), {0.3, 0.1, 0.2},
                          {0.0, 0.2, 0.1}),
          me);
  BOOST_TEST(w3.step_path == StepPath::separable_sparse_newton);
  const RunReport wm = run(
      written_problem(written({"a", "b"}, "a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + 2*cos(a) + cos(b)"),
                      {0.5, 1.0}, {0.1, -0.3}),
      me);
  BOOST_TEST(wm.structure == "mechanical");
  const RunReport wg = run(written_problem(written({"x", "y"}, "(x_dot^2 + y_dot^2)/2 + (x*y_dot - y*x_dot)/2"),
                                           {1.0, 0.2}, {0.0, 1.0}),
                           me);
  BOOST_TEST(wg.structure == "general");
  // the JSON carries the three fields
  const std::string j = report_json(dp);
  BOOST_TEST(j.find("\"structure\": \"mechanical\"") != std::string::npos, j);
  BOOST_TEST(j.find("\"structure_source\": \"declared\"") != std::string::npos, j);
  BOOST_TEST(j.find("\"step_path\": \"generic\"") != std::string::npos, j);
}

BOOST_AUTO_TEST_CASE(velocity_verlet_takes_one_force_per_step) {
  // adjoint Euler composed (Phi_{h/2} o Phi*_{h/2}): kick, drift, kick; the last kick's
  // force is the next step's first
  FullMass L;
  const V2 q0(0.7, -0.2), p0(0.1, 0.3);
  for (double theta : {1.0, 0.0}) {
    const ExplicitSplittingStep<FullMass> S(L, theta, 0.01, substeps(find_composition("stormer-verlet"), false), q0);
    BOOST_TEST(S.forces_per_step() == (theta == 1.0 ? 2 : 1));
    BOOST_TEST(S.first_same_as_last() == (theta == 1.0));
    *L.forces = 0;
    V2 q = q0, p = p0;
    const V2 v0 = V2::Zero();
    const RunSummary r = integrate(S, 0.0, q, p, v0, 100, [](auto&&...) {});
    BOOST_TEST(!r.failed);
    // one force per step, plus the first step's first kick (kick-drift-kick), plus the
    // mass matrix read off at construction (dL/dv at e_1, e_2: before the reset)
    BOOST_TEST(*L.forces == (theta == 1.0 ? 101 : 100));
  }
}

// The forces a step costs, as `dvm methods` reports them (splitting_forces_per_step of
// the step's own sequence), counted in a run: every composition with the explicit Euler
// map, and its adjoint, takes that many gradients a step after the first. A symmetric
// composition of S Stormer-Verlet stages costs S forces (merged kicks, the last force
// reused), and the splittings list their forces as their stages.
BOOST_AUTO_TEST_CASE(forces_per_step_are_the_forces_a_run_evaluates) {
  FullMass L;
  const V2 q0(0.7, -0.2), p0(0.1, 0.3);
  std::vector<CompositionScheme> schemes = composition_schemes();
  for (int order : {6, 8}) schemes.push_back(find_composition("triple-jump:" + std::to_string(order)));
  for (const CompositionScheme& c : schemes)
    for (double theta : {0.0, 1.0}) {
      const std::vector<Substep> sub = substeps(c, false);
      const int per_step = splitting_forces_per_step(splitting_sequence(theta, sub, 0.01));
      BOOST_TEST(per_step == c.stages, c.name);
      const ExplicitSplittingStep<FullMass> S(L, theta, 0.01, sub, q0);
      *L.forces = 0;
      V2 q = q0, p = p0;
      const V2 v0 = V2::Zero();
      BOOST_TEST_REQUIRE(!integrate(S, 0.0, q, p, v0, 40, [](auto&&...) {}).failed);
      // the first step also takes the force its last kick hands on
      BOOST_TEST(*L.forces == 40 * per_step + (S.first_same_as_last() ? 1 : 0), c.name << " theta " << theta);
    }
  // Euler alone: one force a step
  BOOST_TEST(splitting_forces_per_step(splitting_sequence(0.0, single_substep(), 0.01)) == 1);
  BOOST_TEST(splitting_forces_per_step(splitting_sequence(1.0, single_substep(), 0.01)) == 1);
}

BOOST_AUTO_TEST_CASE(a_full_mass_matrix_gives_the_generic_steps) {
  // the solve with M = [[2, 0.5], [0.5, 1]] against Newton on the same discrete Lagrangian
  const FullMass L;
  const V2 q0(0.7, -0.2), p0(0.1, 0.3);
  for (double theta : {0.0, 1.0})
    for (const char* c : {"none", "stormer-verlet", "kahan-li8"}) {
      const std::vector<Substep> sub = std::string(c) == "none" ? single_substep()
                                                                : substeps(find_composition(c), false);
      const ThetaMap R(theta);
      const ExplicitSplittingStep<FullMass> fast(L, theta, 0.05, sub, q0);
      const ComposedStep<PositionMomentumStep<FullMass, ThetaMap>> slow(
          0.05, sub, [&](double hk) { return PositionMomentumStep<FullMass, ThetaMap>(L, R, hk); },
          [&](double hk) { return PositionMomentumStep<FullMass, ThetaMap>(L, R.adjoint(), hk); });
      V2 qa = q0, pa = p0, qb = q0, pb = p0;
      const V2 v0 = V2(0.0, 0.3);
      integrate(fast, 0.0, qa, pa, v0, 200, [](auto&&...) {});
      const RunSummary r = integrate(slow, 0.0, qb, pb, v0, 200, [](auto&&...) {});
      BOOST_TEST_CONTEXT("theta " << theta << ", " << c) {
        BOOST_TEST(!r.failed);
        BOOST_TEST((qa - qb).cwiseAbs().maxCoeff() <= 1e-12);
        BOOST_TEST((pa - pb).cwiseAbs().maxCoeff() <= 1e-12);
      }
    }
}

// Written Lagrangians whose text is separable (Expression::split_velocity) take the same
// explicit steps as declared built-ins: the same states as the generic path of the
// same text, and as the built-in twin with the same method.
BOOST_AUTO_TEST_CASE(written_separable_lagrangians_take_the_explicit_steps) {
  struct Twin {
    std::string name;
    Problem written, builtin;
    bool has_builtin;
  };
  std::vector<Twin> twins;
  {
    Problem b = builtin("pendulum", {2.0}, {0.0});
    const auto& P = b.params;
    twins.push_back({"pendulum",
                     written_problem(written({"th"}, "m*l^2/2*th_dot^2 + m*g*l*cos(th)",
                                             {{"m", P.at("m")}, {"l", P.at("l")}, {"g", P.at("g")}}),
                                     b.q, b.v),
                     b, true});
  }
  {
    Problem b = builtin("kepler", {0.4, 0.0}, {0.0, 2.0});
    twins.push_back({"kepler", written_problem(written({"x", "y"}, "(x_dot^2 + y_dot^2)/2 + mu/sqrt(x^2 + y^2)",
                                                       {{"mu", b.params.at("mu")}}),
                                               b.q, b.v),
                     b, true});
  }
  {
    Problem b = builtin("fpu", {0.2, 0.2 + 1.0 / 50, 0.0, 0.0, 0.0, 0.0}, {0, 0, 0, 0, 0, 0});
    b.step = 0.002;
    Problem w = written_problem(
        written({"a", "b", "c", "d", "e", "f"},
                "(a_dot^2 + b_dot^2 + c_dot^2 + d_dot^2 + e_dot^2 + f_dot^2)/2"
                " - 0.25*w^2*((b - a)^2 + (d - c)^2 + (f - e)^2) - (a^4 + (c - b)^4 + (e - d)^4 + f^4)",
                {{"w", b.params.at("omega")}}),
        b.q, b.v);
    w.step = 0.002;
    twins.push_back({"fpu", w, b, true});
  }
  {
    // the FPU chain of 8 particles between walls, written with an array and sums
    Problem b = builtin("chain", {0.5, 0, 0, 0, 0, 0, 0, 0.1}, {0, 0, 0.3, 0, 0, 0, 0, 0});
    b.params["alpha"] = 0.25;
    b.params["beta"] = 1.0;
    auto w = std::make_shared<WrittenSystem>();
    w->add_array("q", 8, ExpressionSymbols::Boundary::fixed);
    w->params = {{"n", 8}, {"m", 1.0}, {"k", 1.0}, {"alpha", 0.25}, {"beta", 1.0}};
    w->check_names();
    w->lagrangian = Expression::parse(
        "sum(i, 1, n, m/2*q_dot[i]^2) - sum(i, 1, n + 1, k/2*(q[i] - q[i-1])^2 + alpha/3*(q[i] - q[i-1])^3 + "
        "beta/4*(q[i] - q[i-1])^4)",
        w->symbols(WrittenSystem::Kind::lagrangian));
    twins.push_back({"chain", written_problem(w, b.q, b.v), b, true});
  }
  // a full constant mass matrix (a cross term in v): the Cholesky path
  twins.push_back({"full mass",
                   written_problem(written({"x", "y"}, "x_dot^2 + x_dot*y_dot/2 + y_dot^2/2 - x^2/2 - x^4/4 - y^2/2"),
                                   {0.7, -0.2}, {0.1, 0.3}),
                   Problem(), false});
  for (Twin& t : twins)
    if (t.has_builtin) {  // the same steps
      t.written.step = t.builtin.step;
      t.written.steps = t.builtin.steps;
    }
  for (const Twin& t : twins)
    for (const Method& me : explicit_methods({})) {
      Method generic = me;
      generic.use_structure = false;
      const RunReport a = run(t.written, me), b = run(t.written, generic);
      BOOST_TEST_CONTEXT(t.name << ", " << me.map->name << ", " << me.composition) {
        BOOST_TEST(!a.failed);
        BOOST_TEST(a.step_path == StepPath::explicit_splitting);
        BOOST_TEST(b.step_path == StepPath::generic);
        BOOST_TEST(a.structure == "separable");
        BOOST_TEST(a.structure_source == "expression");
        BOOST_TEST(max_diff(a.q_final, b.q_final) <= 1e-11 * std::fmax(1.0, max_abs(b.q_final)));
        BOOST_TEST(max_diff(a.p_final, b.p_final) <= 1e-11 * std::fmax(1.0, max_abs(b.p_final)));
        if (t.has_builtin) {
          const RunReport d = run(t.builtin, me);
          BOOST_TEST(!d.failed);
          BOOST_TEST(max_diff(a.q_final, d.q_final) <= 1e-11 * std::fmax(1.0, max_abs(d.q_final)));
          BOOST_TEST(max_diff(a.p_final, d.p_final) <= 1e-11 * std::fmax(1.0, max_abs(d.p_final)));
          BOOST_TEST(std::fabs(a.energy_initial - d.energy_initial) <= 1e-14 * std::fmax(1.0, std::fabs(d.energy_initial)));
        }
      }
    }
  // mechanical and general texts keep the generic path, and say what they are
  Method ee;
  ee.map = &find_map_entry("explicit-euler", "test");
  ee.theta = ee.map->theta;
  const RunReport m = run(
      written_problem(written({"a", "b"}, "a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + 2*cos(a) + cos(b)"),
                      {0.5, 1.0}, {0.1, -0.3}),
      ee);
  BOOST_TEST(m.structure == "mechanical");
  BOOST_TEST(m.structure_source == "expression");
  BOOST_TEST(m.step_path == StepPath::generic);
  const RunReport g = run(written_problem(written({"x", "y"}, "(x_dot^2 + y_dot^2)/2 + (x*y_dot - y*x_dot)/2"),
                                          {1.0, 0.2}, {0.0, 1.0}),
                          ee);
  BOOST_TEST(g.structure == "general");
  BOOST_TEST(g.step_path == StepPath::generic);
  // a quadratic form in v that is not positive definite is not separable (nor mechanical)
  const RunReport ind = run(written_problem(written({"x", "y"}, "(x_dot^2 - y_dot^2)/2 - x^2 - y^4"), {0.3, 0.1},
                                            {0.1, 0.2}),
                            ee);
  BOOST_TEST(ind.structure == "general");
  BOOST_TEST(ind.step_path == StepPath::generic);

  // The pendulum has 1 coordinate, Kepler and the full mass matrix 2: their explicit steps
  // and runs are compiled for that size (WrittenSeparableOf<K>). Stormer-Verlet by them
  // equals the run-time-sized step (WrittenSeparable) to the bit over 1000 steps; with
  // system.compile (the force compiled to machine code) every explicit method's run
  // equals the interpreted run to the bit.
  int fixed_sizes_seen[3] = {0, 0, 0};
  for (const Twin& t : twins) {
    if (t.written.dim > 2) continue;
    ++fixed_sizes_seen[t.written.dim];
    const WrittenDynamic L(t.written.written);
    const auto sv = substeps(find_composition("stormer-verlet"), false);
    auto compare = [&](auto k) {
      constexpr int K = decltype(k)::value;
      const Eigen::VectorXd q0 = Eigen::Map<const Eigen::VectorXd>(t.written.q.data(), K);
      const Eigen::VectorXd p0 = legendre(L, q0, Eigen::Map<const Eigen::VectorXd>(t.written.v.data(), K));
      const ExplicitSplittingStep<WrittenSeparableOf<K>> fixed(WrittenSeparableOf<K>(L), 0.0, 0.01, sv,
                                                               Vec<double, K>(q0));
      const ExplicitSplittingStep<WrittenSeparable> dynamic(WrittenSeparable(L), 0.0, 0.01, sv, q0);
      Vec<double, K> qa = q0, pa = p0;
      Eigen::VectorXd qb = q0, pb = p0;
      BOOST_TEST(!integrate(fixed, 0.0, qa, pa, Vec<double, K>::Zero(), 1000, [](auto&&...) {}).failed);
      BOOST_TEST(!integrate(dynamic, 0.0, qb, pb, Eigen::VectorXd::Zero(K), 1000, [](auto&&...) {}).failed);
      BOOST_TEST_CONTEXT(t.name) {
        BOOST_TEST((qa - qb).cwiseAbs().maxCoeff() == 0.0);
        BOOST_TEST((pa - pb).cwiseAbs().maxCoeff() == 0.0);
        BOOST_TEST(qa.cwiseAbs().maxCoeff() > 0.1);
      }
    };
    if (t.written.dim == 1)
      compare(std::integral_constant<int, 1>());
    else
      compare(std::integral_constant<int, 2>());
    for (const Method& me : explicit_methods({})) {
      Problem c = t.written;
      c.compile = true;
      const RunReport a = run(t.written, me), b = run(c, me);
      BOOST_TEST_CONTEXT(t.name << ", " << me.map->name << ", " << me.composition) {
        BOOST_TEST(!a.compiled);
        BOOST_TEST(b.compiled);
        BOOST_TEST(b.step_path == StepPath::explicit_splitting);
        BOOST_TEST(max_diff(a.q_final, b.q_final) == 0.0);
        BOOST_TEST(max_diff(a.p_final, b.p_final) == 0.0);
      }
    }
  }
  BOOST_TEST(fixed_sizes_seen[1] >= 1);  // both compiled sizes were compared
  BOOST_TEST(fixed_sizes_seen[2] >= 1);
}

// A written ring (an array with periodic ends) of 10, 100 and 1000 coordinates runs with
// every map of R^n, both forms, the compositions and every Galerkin method, or is
// refused by validate() naming a key. At 1000 coordinates the dense steps (implicit
// maps, Galerkin, the Hamiltonian form by the Legendre transform) form 1000 x 1000
// matrices and cost a second or more per step at -O1, so they take one step, with no
// composition and the smallest Galerkin method; the explicit steps take everything.
BOOST_AUTO_TEST_CASE(written_systems_of_10_100_and_1000_coordinates_run_every_method) {
  for (int n : {10, 100, 1000}) {
    auto w = std::make_shared<WrittenSystem>();
    w->name = "ring";
    w->add_array("q", n, ExpressionSymbols::Boundary::periodic);
    w->params = {{"n", n}, {"k", 1.0}, {"beta", 0.5}};
    w->check_names();
    w->lagrangian = Expression::parse(
        "sum(i, 1, n, q_dot[i]^2/2 - k/2*(q[i+1] - q[i])^2 - beta/4*(q[i+1] - q[i])^4)",
        w->symbols(WrittenSystem::Kind::lagrangian));
    std::vector<double> q(static_cast<std::size_t>(n)), v(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
      q[static_cast<std::size_t>(i)] = 0.3 * std::sin(2 * M_PI * i / n) + 0.05 * std::cos(7.0 * i);
      v[static_cast<std::size_t>(i)] = 0.1 * std::cos(3.0 * i);
    }
    Problem pr = written_problem(w, q, v);
    pr.steps = n == 1000 ? 1 : 3;
    const bool big = n == 1000;
    std::vector<Method> methods;
    for (const MapEntry& m : map_registry()) {
      if (m.space != Space::euclidean || m.family == MapFamily::written) continue;
      const bool explicit_map = m.name == "explicit-euler" || m.name == "adjoint-euler";
      for (Form f : {Form::lagrangian, Form::hamiltonian})
        for (const char* c : {"none", "stormer-verlet", "suzuki5", "kahan-li8"}) {
          if (big && !(explicit_map && f == Form::lagrangian) && std::string(c) != "none") continue;
          Method me;
          me.map = &m;
          me.theta = m.takes_theta ? 0.3 : m.theta;
          me.form = f;
          me.composition = c;
          methods.push_back(me);
        }
    }
    for (QuadratureKind qk : {QuadratureKind::gauss, QuadratureKind::lobatto})
      for (int s = 1; s <= kGalerkinStagesMax; ++s) {
        if (big && (s > 1 || qk != QuadratureKind::gauss)) continue;
        Method me;
        me.galerkin = true;
        me.quadrature = qk;
        me.stages = s;
        methods.push_back(me);
      }
    int ran = 0, refused = 0, explicit_steps = 0;
    for (const Method& me : methods) {
      BOOST_TEST_CONTEXT("n = " << n << ": " << me.label()) {
        try {
          validate(pr, me);
        } catch (const InputError& e) {
          ++refused;
          BOOST_TEST(std::string(e.what()).find("integrator.") != std::string::npos, e.what());
          continue;
        }
        const RunReport r = run(pr, me);
        ++ran;
        explicit_steps += r.step_path == StepPath::explicit_splitting;
        BOOST_TEST(!r.failed);
        if (r.step_path == StepPath::explicit_splitting && (!big || me.composition == "none")) {
          // the kicks and drifts give the generic path's solution (Newton on each
          // substep's discrete Legendre equations), to round-off
          Method generic = me;
          generic.use_structure = false;
          const RunReport g = run(pr, generic);
          BOOST_TEST(g.step_path != StepPath::explicit_splitting);
          double d = 0.0, size = 0.0;
          for (std::size_t i = 0; i < r.q_final.size() && i < g.q_final.size(); ++i) {
            d = std::fmax(d, std::fabs(r.q_final[i] - g.q_final[i]) + std::fabs(r.p_final[i] - g.p_final[i]));
            size = std::fmax(size, std::fabs(r.q_final[i] - q[i]));
          }
          BOOST_TEST(g.q_final.size() == r.q_final.size());
          BOOST_TEST(size >= 1e-3);  // the runs moved
          BOOST_TEST(d <= 1e-12, "explicit against generic: " << d);
        }
        BOOST_TEST(r.structure == "separable");
        BOOST_TEST(r.q_final.size() == static_cast<std::size_t>(n));
        BOOST_TEST(std::isfinite(r.energy_final));
        BOOST_TEST(std::fabs(r.energy_final - r.energy_initial) <= 1e-2 * std::fabs(r.energy_initial));
      }
    }
    BOOST_TEST_MESSAGE("n = " << n << ": " << ran << " ran, " << refused << " refused, " << explicit_steps
                              << " by kicks and drifts");
    BOOST_TEST(ran > 0);
    BOOST_TEST(explicit_steps == 8);  // two explicit maps x four compositions, lagrangian form
  }
}

// The first-same-as-last reuse is guarded: a step started from a state that is not where
// the last step ended evaluates its first force afresh, so that it gives what a new step
// object gives, to the bit; and the constructor refuses what has no explicit step.
BOOST_AUTO_TEST_CASE(a_step_from_an_unrelated_state_does_not_reuse_the_last_force) {
  FullMass L;
  const V2 q0(0.7, -0.2), p0(0.1, 0.3), q1(-0.4, 0.5), p1(0.2, -0.1);
  const std::vector<Substep> sv = substeps(find_composition("stormer-verlet"), false);
  const ExplicitSplittingStep<FullMass> S(L, 1.0, 0.01, sv, q0), fresh(L, 1.0, 0.01, sv, q0);
  BOOST_TEST_REQUIRE(S.first_same_as_last());
  V2 dq = V2::Zero(), dp = V2::Zero(), eq = V2::Zero(), ep = V2::Zero();
  BOOST_TEST_REQUIRE(S.step(0.0, q0, p0, dq, dp).converged);
  *L.forces = 0;
  BOOST_TEST_REQUIRE(S.step(0.01, q1, p1, dq, dp).converged);  // not q0 + dq
  BOOST_TEST(*L.forces == 2);  // the first kick's force taken at q1, then the last kick's
  BOOST_TEST_REQUIRE(fresh.step(0.01, q1, p1, eq, ep).converged);
  BOOST_TEST(dq == eq, boost::test_tools::per_element());
  BOOST_TEST(dp == ep, boost::test_tools::per_element());
  // and from where it ended, the force is reused: one gradient
  const V2 q2 = q1 + dq, p2 = p1 + dp;
  *L.forces = 0;
  BOOST_TEST_REQUIRE(S.step(0.02, q2, p2, dq, dp).converged);
  BOOST_TEST(*L.forces == 1);

  const auto refused = [&](auto make, const char* what) {
    try {
      make();
      BOOST_ERROR(what << ": not refused");
    } catch (const std::invalid_argument& e) {
      BOOST_TEST_MESSAGE(what << ": " << e.what());
    }
  };
  refused([&] { ExplicitSplittingStep<FullMass>(L, 0.5, 0.01, sv, q0); }, "theta 1/2");
  refused([&] { ExplicitSplittingStep<FullMass>(L, 0.0, 0.0, sv, q0); }, "h = 0");
  refused([&] { ExplicitSplittingStep<FullMass>(L, 0.0, NAN, sv, q0); }, "h = NaN");
  refused([&] { ExplicitSplittingStep<FullMass>(L, 0.0, 0.01, {}, q0); }, "no substeps");
  refused([&] { ExplicitSplittingStep<FullMass>(L, 0.0, 0.01, {{0.0, false}}, q0); }, "a zero weight");
  refused([&] { ExplicitSplittingStep<FullMass>(L, 0.0, 0.01, {{INFINITY, false}}, q0); }, "an infinite weight");
}
