// What the single path from a scene to a step guarantees, end to end:
//   - `dvm converge` measures the method the scene names (composition, Galerkin, any
//     form, S^2 and SO(3)), against a reference that reports its own accuracy, and
//     does not print an order it cannot support;
//   - every run writes its rows through the same atomic recorder (CSV and .npy, on
//     every space, initial- and boundary-value problems alike);
//   - written systems name their CSV columns after their coordinates.
#define BOOST_TEST_MODULE cli_one_path
#include <boost/test/unit_test.hpp>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "tests/address_sanitizer.h"
#include "tests/cli/cli_harness.h"

namespace {

using namespace cli_test;

double fitted(const Output& o) { return json_number(o.out, "fitted_order"); }

// Whether a run's JSON reports the invariant `name` (a member of its "invariants").
bool has_invariant(const std::string& json, const std::string& name) {
  const Json j = parse_json(json);
  return j.contains("invariants") && j.at("invariants").contains(name);
}

std::string first_line(const std::string& path) {
  std::ifstream f(path);
  std::string line;
  std::getline(f, line);
  return line;
}

}  // namespace

// The composition the scene names is the method measured: kahan-li8 on the Stormer-
// Verlet of the Euler maps is of order 8 on Kepler (against the exact solution); the
// map alone, explicit Euler, is of order 1.
BOOST_AUTO_TEST_CASE(converge_measures_the_composition_the_scene_names) {
  const Output o = dvm({"converge", scene("kepler-composition.toml"), "--t-end", "1", "--steps-list",
                        "10,14,20,28,40", "--json"});
  BOOST_TEST_MESSAGE("kepler-composition, kahan-li8: fitted order " << fitted(o) << "\n" << o.out);
  BOOST_TEST(o.status == 0, o.err);
  BOOST_TEST(json_string(o.out, "composition") == "kahan-li8");
  BOOST_TEST(json_string(o.out, "reference") == "exact solution");
  BOOST_TEST(std::fabs(fitted(o) - 8.0) <= 0.3);
  const Output e = dvm({"converge", scene("kepler-composition.toml"), "--t-end", "1", "--steps-list",
                        "1000,2000,4000", "--set", "integrator.composition=none", "--json"});
  BOOST_TEST(e.status == 0, e.err);
  BOOST_TEST(std::fabs(fitted(e) - 1.0) <= 0.1, e.out);

  // a written double pendulum composed with kahan-li8 (reference: Galerkin s = 6,
  // refined until it reports an accuracy below the errors measured)
  const Output w = dvm({"converge", scene("double_pendulum_written.toml"), "--t-end", "1", "--steps-list",
                        "4,6,8,12", "--set", "integrator.composition=kahan-li8", "--json"});
  BOOST_TEST_MESSAGE("written double pendulum, kahan-li8: fitted order " << fitted(w) << "\n" << w.out);
  BOOST_TEST(w.status == 0, w.err);
  BOOST_TEST(std::fabs(fitted(w) - 8.0) <= 0.3);
  BOOST_TEST(json_number(w.out, "reference_accuracy") <= 1e-13);
}

// composition = "dirk" with weights: the composition of substeps b_i h, with the
// midpoint map the symplectic DIRK of weights b (Sec. 6.2). The triple jump's weights
// reproduce composition = "triple-jump" to round-off; weights whose cubes do not sum to zero
// give order 2, the triple jump's 4 (measured by dvm converge); bad weights, weights
// without dirk and dirk without weights are refused naming the key.
BOOST_AUTO_TEST_CASE(dirk_composition_from_weights_in_the_scene) {
  const std::string tj = "[1.3512071919596578, -1.7024143839193153, 1.3512071919596578]";
  auto run = [&](const std::vector<std::string>& sets) {
    std::vector<std::string> args = {"run", scene("pendulum.toml"), "--set", "integrator.t_end=2.0", "--json",
                                     "--quiet", "--csv", "/dev/null"};
    for (const std::string& k : sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    return dvm(args);
  };
  const Output a = run({"integrator.composition=\"triple-jump\""});
  const Output b = run({"integrator.composition=\"dirk\"", "integrator.weights=" + tj});
  BOOST_TEST(a.status == 0, a.err);
  BOOST_TEST(b.status == 0, b.err);
  // (the weights typed in decimal round the triple jump's exact ones: last bits only)
  const auto qa = json_array(a.out, "q_final"), qb = json_array(b.out, "q_final");
  BOOST_REQUIRE_EQUAL(qa.size(), qb.size());
  for (std::size_t i = 0; i < qa.size(); ++i) BOOST_TEST(std::fabs(qa[i] - qb[i]) <= 1e-14);
  BOOST_TEST(json_array(b.out, "weights").size() == 3u);
  BOOST_TEST(json_string(b.out, "composition") == "dirk");
  for (const auto& [weights, order] : {std::make_pair(std::string("[0.3, 0.7]"), 2.0), std::make_pair(tj, 4.0)}) {
    const Output c = dvm({"converge", scene("pendulum.toml"), "--t-end", "1", "--steps-list", "10,20,40", "--set",
                          "integrator.composition=\"dirk\"", "--set", "integrator.weights=" + weights, "--json"});
    BOOST_TEST_MESSAGE("dirk " << weights << ": fitted order " << fitted(c));
    BOOST_TEST(c.status == 0, c.err);
    BOOST_TEST(std::fabs(fitted(c) - order) <= 0.2, weights << ": " << c.out);
  }
  const std::vector<std::pair<std::vector<std::string>, std::string>> refused = {
      {{"integrator.composition=\"dirk\""}, "integrator.weights"},
      {{"integrator.composition=\"dirk\"", "integrator.weights=[0.3, 0.6]"}, "integrator.weights"},
      {{"integrator.composition=\"dirk\"", "integrator.weights=[1.0, 0.0]"}, "integrator.weights"},
      {{"integrator.composition=\"triple-jump\"", "integrator.weights=[0.3, 0.7]"}, "integrator.weights"},
      {{"integrator.weights=[0.3, 0.7]"}, "integrator.weights"},
  };
  for (const auto& [sets, key] : refused) {
    const Output r = run(sets);
    BOOST_TEST(r.status == 2, sets.back());
    BOOST_TEST(r.err.find(key) != std::string::npos, r.err);
  }
}

// composition = "dirk" with integrator.thetas: stage i takes the map at theta_i. With
// the hamiltonian form and the theta map that is the symplectic partitioned pair of
// Sec. 6.2 (a_ii = theta_i b_i, a^_ii = (1 - theta_i) b_i). Every theta 1/2 is the DIRK
// itself, to the bit; a theta per stage runs on S^2 with a theta retraction too; every
// rule between the keys is refused naming its key. The orders are the next case's.
BOOST_AUTO_TEST_CASE(partitioned_pairs_from_thetas_in_the_scene) {
  auto run = [&](const std::string& file, const std::vector<std::string>& sets) {
    std::vector<std::string> args = {"run", scene(file), "--set", "integrator.t_end=2.0", "--json", "--quiet",
                                     "--csv", "/dev/null"};
    for (const std::string& k : sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    return dvm(args);
  };
  const std::string dirk = "integrator.composition=\"dirk\"", tj = "[1.3512071919596578, -1.7024143839193153, 1.3512071919596578]";
  // every theta 1/2: the DIRK of the weights with the midpoint map, bit for bit, in both forms
  for (const char* form : {"lagrangian", "hamiltonian"}) {
    const Output a = run("pendulum.toml", {dirk, "integrator.weights=" + tj, std::string("integrator.form=") + form});
    const Output b = run("pendulum.toml", {dirk, "integrator.weights=" + tj, "integrator.map=\"theta\"",
                                           "integrator.thetas=[0.5, 0.5, 0.5]", std::string("integrator.form=") + form});
    BOOST_TEST(a.status == 0, a.err);
    BOOST_TEST(b.status == 0, b.err);
    BOOST_TEST(json_array(a.out, "q_final") == json_array(b.out, "q_final"));
    BOOST_TEST(json_array(a.out, "p_final") == json_array(b.out, "p_final"));
    BOOST_TEST(json_array(b.out, "thetas").size() == 3u);
  }
  // a theta per stage on S^2, with a theta retraction
  {
    const Output o = run("spherical-pendulum.toml", {dirk, "integrator.map=\"sphere-exp-theta\"",
                                                     "integrator.weights=" + tj, "integrator.thetas=[0.3, 0.5, 0.7]"});
    BOOST_TEST(o.status == 0, o.err);
    BOOST_TEST(json_array(o.out, "thetas").size() == 3u);
  }
  // dvm converge names the weights and the thetas of the stages it measured
  {
    const Output o = dvm({"converge", scene("kepler.toml"), "--t-end", "0.1", "--steps-list", "10,20", "--set", dirk,
                          "--set", "integrator.map=\"theta\"", "--set", "integrator.weights=[0.5, 0.5]", "--set",
                          "integrator.thetas=[0.0, 1.0]", "--set", "integrator.form=\"hamiltonian\"", "--json"});
    BOOST_TEST(o.status == 0, o.err);
    BOOST_TEST(json_array(o.out, "thetas").size() == 2u);
    BOOST_TEST(json_array(o.out, "weights").size() == 2u);
  }
  const std::vector<std::pair<std::vector<std::string>, std::string>> refused = {
      {{"integrator.map=\"theta\"", "integrator.thetas=[0.5]"}, "integrator.thetas"},  // not dirk
      {{dirk, "integrator.map=\"theta\"", "integrator.weights=[0.3, 0.7]", "integrator.thetas=[0.5]"},
       "integrator.thetas"},
      {{dirk, "integrator.map=\"theta\"", "integrator.weights=[0.3, 0.7]", "integrator.thetas=[0.5, 1.5]"},
       "integrator.thetas"},
      {{dirk, "integrator.weights=[0.3, 0.7]", "integrator.thetas=[0.5, 0.5]"}, "integrator.thetas"},  // midpoint
      {{dirk, "integrator.map=\"theta\"", "integrator.theta=0.3", "integrator.weights=[0.3, 0.7]",
        "integrator.thetas=[0.5, 0.5]"},
       "integrator.theta"},
      // weights that do not sum to 1 are the weights' error, thetas or not
      {{dirk, "integrator.map=\"theta\"", "integrator.weights=[0.3, 0.6]", "integrator.thetas=[0.5, 0.5]"},
       "integrator.weights"},
      // newmark runs its own map on TQ: no theta per stage (refused before any run)
      {{dirk, "integrator.form=\"newmark\"", "integrator.map=\"theta\"", "integrator.weights=[0.3, 0.7]",
        "integrator.thetas=[0.5, 0.5]"},
       "integrator.thetas"},
  };
  for (const auto& [sets, key] : refused) {
    const Output r = run("pendulum.toml", sets);
    BOOST_TEST(r.status == 2, sets.back());
    BOOST_TEST(r.err.find(key) != std::string::npos, r.err);
  }
}

// The orders dvm converge measures for a theta per stage are those the pair conditions
// predict (2 when sum (theta_i - 1/2) b_i^2 = 0, else 1), on R^n and on S^2 with a theta
// retraction. Six studies of three step counts (up to 4000 steps) beside their
// references: in `make test`, not under AddressSanitizer, where the case above runs the
// same steps and a study of two short runs.
BOOST_AUTO_TEST_CASE(partitioned_pairs_have_the_orders_the_conditions_predict,
                     *boost::unit_test::enable_if<!dvm_tests::kAddressSanitizer>()) {
  const std::string dirk = "integrator.composition=\"dirk\"", tj = "[1.3512071919596578, -1.7024143839193153, 1.3512071919596578]";
  // measured orders: Kepler against its exact solution, the spherical pendulum against Galerkin
  struct Case {
    std::string file, map, weights, thetas, form;
    double order;
  };
  const std::vector<Case> cases = {
      {"kepler.toml", "theta", "[0.5, 0.5]", "[0.0, 1.0]", "hamiltonian", 2.0},   // symplectic Euler and its adjoint
      {"kepler.toml", "theta", "[0.3, 0.7]", "[0.3, 0.7]", "hamiltonian", 1.0},   // sum (theta - 1/2) b^2 = 0.08
      {"kepler.toml", "theta", tj, "[0.3, 0.5, 0.7]", "hamiltonian", 2.0},      // symmetric pair, not the DIRK's 4
      {"kepler.toml", "theta", tj, "[0.5, 0.5, 0.5]", "hamiltonian", 4.0},      // the DIRK
      {"spherical-pendulum.toml", "sphere-exp-theta", tj, "[0.3, 0.5, 0.7]", "lagrangian", 2.0},
      {"spherical-pendulum.toml", "sphere-exp-theta", "[0.3, 0.7]", "[0.3, 0.7]", "lagrangian", 1.0},
  };
  for (const Case& c : cases) {
    const Output o = dvm({"converge", scene(c.file), "--t-end", "1", "--steps-list",
                          c.order == 1.0 ? "1000,2000,4000" : "100,200,400", "--set", dirk, "--set",
                          "integrator.map=\"" + c.map + "\"", "--set", "integrator.weights=" + c.weights, "--set",
                          "integrator.thetas=" + c.thetas, "--set", "integrator.form=" + c.form, "--json"});
    BOOST_TEST_MESSAGE(c.file << " " << c.map << " weights " << c.weights << " thetas " << c.thetas << ": order "
                              << fitted(o));
    BOOST_TEST(o.status == 0, o.err);
    BOOST_TEST(std::fabs(fitted(o) - c.order) <= 0.15, c.file << " thetas " << c.thetas << ": " << o.out);
    // the study names what it measured: the weights and the thetas of the stages
    BOOST_TEST(json_array(o.out, "thetas").size() == json_array(o.out, "weights").size());
    BOOST_TEST(json_array(o.out, "thetas").size() >= 2u);
  }
}

// integrator.lift: how the map reaches the form's bundle.
//   - lift = "none" in the hamiltonian form takes the theta map on T*Q itself: on the
//     harmonic oscillator z_{k+1} = (I - theta h A)^{-1} (I + (1 - theta) h A) z_k, A the
//     matrix of X_H, where the cotangent lift (the default) gives the partitioned theta
//     method; both are checked against these closed forms, on the fixed-size system and
//     on a written one (the run-time-sized steps), and at theta = 1/2 the two coincide;
//   - lift = "legendre" in the sode forms is R_d^L (Prop. 5.3): with sode2 (Eq. 5.2) the
//     hamiltonian form's trajectory on the double pendulum (q and p = dL/dv), and for a
//     constant mass matrix with the midpoint map the tangent lift's (Cor. 5.4), not at
//     theta = 0.3;
//   - the combinations that do not apply are refused naming integrator.lift.
BOOST_AUTO_TEST_CASE(lifts_of_the_map_from_the_scene) {
  auto run = [&](const std::string& file, const std::vector<std::string>& sets) {
    std::vector<std::string> args = {"run", file, "--json", "--quiet", "--csv", "/dev/null"};
    for (const std::string& k : sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    return dvm(args);
  };
  // the harmonic oscillator, omega = 1.3, 200 steps of h = 0.05 from (q, p) = (1, 0.2)
  const double w = 1.3, h = 0.05;
  const int steps = 200;
  auto closed_form = [&](double th, bool on_bundle) {
    // one step: [1 -th_q h; th_p h w^2 1] (dq, dp) = h (p0, -w^2 q0), th_q = theta for q,
    // th_p = theta (on T*Q) or 1 - theta (cotangent lift) for p
    const double tq = th, tp = on_bundle ? th : 1.0 - th;
    double q = 1.0, p = 0.2;
    for (int k = 0; k < steps; ++k) {
      const double a = 1.0, b = -tp * h, c = tq * h * w * w, d = 1.0, r1 = h * p, r2 = -h * w * w * q;
      const double det = a * d - b * c, dq = (r1 * d - b * r2) / det, dp = (a * r2 - c * r1) / det;
      q += dq;
      p += dp;
    }
    return std::make_pair(q, p);
  };
  const std::string harmonic = write_scene("harmonic_lift.toml", R"([system]
builtin = "harmonic"
params = { omega = 1.3 }
[initial]
q = [1.0]
p = [0.2]
[integrator]
map = "theta"
form = "hamiltonian"
step = 0.05
steps = 200
)");
  const std::string written = write_scene("harmonic_written_lift.toml", R"([system]
coordinates = ["x"]
params = { w = 1.3 }
lagrangian = "0.5*x_dot^2 - 0.5*w^2*x^2"
hamiltonian = "0.5*p_x^2 + 0.5*w^2*x^2"
[initial]
q = [1.0]
p = [0.2]
[integrator]
map = "theta"
form = "hamiltonian"
step = 0.05
steps = 200
)");
  for (const std::string& file : {harmonic, written})
    for (double th : {0.3, 0.5, 1.0})
      for (bool on_bundle : {false, true}) {
        const Output o = run(file, {"integrator.theta=" + std::to_string(th),
                                    std::string("integrator.lift=") + (on_bundle ? "\"none\"" : "\"cotangent\"")});
        BOOST_TEST_CONTEXT(file << ", theta " << th << (on_bundle ? ", on T*Q" : ", cotangent lift")) {
          BOOST_TEST_REQUIRE(o.status == 0, o.err);
          BOOST_TEST(json_string(o.out, "lift") == (on_bundle ? "none" : "cotangent"));
          const auto [q, p] = closed_form(th, on_bundle);
          BOOST_TEST(std::fabs(json_array(o.out, "q_final").at(0) - q) <= 1e-13);
          BOOST_TEST(std::fabs(json_array(o.out, "p_final").at(0) - p) <= 1e-13);
        }
      }
  // the two lifts differ away from theta = 1/2 (the closed forms above differ by 1e-2)
  BOOST_TEST(std::fabs(closed_form(0.3, true).first - closed_form(0.3, false).first) > 1e-3);

  // R_d^L with sode2 is the hamiltonian form's method (Prop. 5.3 (a)), on a mass matrix
  // that depends on q
  for (const char* th : {"0.3", "0.5"}) {
    const std::vector<std::string> base = {"integrator.map=\"theta\"", std::string("integrator.theta=") + th,
                                           "integrator.t_end=1.0"};
    auto with = [&](std::vector<std::string> extra) {
      std::vector<std::string> s = base;
      s.insert(s.end(), extra.begin(), extra.end());
      return run(scene("double_pendulum.toml"), s);
    };
    const Output lag = with({"integrator.form=\"sode2\"", "integrator.lift=\"legendre\""});
    const Output ham = with({"integrator.form=\"hamiltonian\""});
    BOOST_TEST_CONTEXT("double pendulum, theta " << th) {
      BOOST_TEST_REQUIRE(lag.status == 0, lag.err);
      BOOST_TEST_REQUIRE(ham.status == 0, ham.err);
      BOOST_TEST(json_string(lag.out, "lift") == "legendre");
      const auto qa = json_array(lag.out, "q_final"), qb = json_array(ham.out, "q_final");
      const auto pa = json_array(lag.out, "p_final"), pb = json_array(ham.out, "p_final");
      BOOST_TEST_REQUIRE(qa.size() == 2u);
      for (std::size_t i = 0; i < 2; ++i) {
        BOOST_TEST(std::fabs(qa[i] - qb[i]) <= 1e-12);
        BOOST_TEST(std::fabs(pa[i] - pb[i]) <= 1e-12);
      }
    }
  }
  // Cor. 5.4: constant mass (the pendulum) and the midpoint map: R_d^L is the tangent lift
  for (const char* th : {"0.5", "0.3"}) {
    const std::vector<std::string> base = {"integrator.map=\"theta\"", std::string("integrator.theta=") + th,
                                           "integrator.t_end=2.0", "integrator.form=\"sode2\""};
    auto a = base, b = base;
    a.push_back("integrator.lift=\"legendre\"");
    b.push_back("integrator.lift=\"tangent\"");
    const Output la = run(scene("pendulum.toml"), a), ta = run(scene("pendulum.toml"), b);
    BOOST_TEST_REQUIRE(la.status == 0, la.err);
    BOOST_TEST_REQUIRE(ta.status == 0, ta.err);
    const double d = std::fabs(json_array(la.out, "q_final").at(0) - json_array(ta.out, "q_final").at(0));
    BOOST_TEST_MESSAGE("pendulum, theta " << th << ": |legendre - tangent| = " << d);
    if (std::string(th) == "0.5")
      BOOST_TEST(d <= 1e-13);
    else
      BOOST_TEST(d > 1e-6);
  }
  // measured orders: sode1 and sode2 with R_d^L of the midpoint map, and a composition
  for (const auto& [sets, order] :
       {std::make_pair(std::vector<std::string>{"integrator.form=\"sode1\"", "integrator.lift=\"legendre\""}, 2.0),
        std::make_pair(std::vector<std::string>{"integrator.form=\"sode2\"", "integrator.lift=\"legendre\"",
                                                "integrator.composition=\"triple-jump\""},
                       4.0),
        std::make_pair(std::vector<std::string>{"integrator.form=\"hamiltonian\"", "integrator.lift=\"none\"",
                                                "integrator.map=\"theta\"", "integrator.theta=0.3"},
                       1.0)}) {
    std::vector<std::string> args = {"converge", scene("double_pendulum.toml"), "--t-end", "1", "--steps-list",
                                     order == 1.0 ? "400,800,1600" : "20,40,80", "--json"};
    for (const std::string& k : sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    const Output o = dvm(args);
    BOOST_TEST_MESSAGE(sets.front() << " " << sets[1] << ": order " << fitted(o));
    BOOST_TEST(o.status == 0, o.err);
    BOOST_TEST(std::fabs(fitted(o) - order) <= 0.15, o.out);
  }
  const std::vector<std::pair<std::string, std::vector<std::string>>> refused = {
      {scene("pendulum.toml"), {"integrator.lift=\"tangent\""}},                                    // lagrangian form
      {scene("pendulum.toml"), {"integrator.form=\"sode2\"", "integrator.lift=\"none\""}},          // on TQ
      {scene("pendulum.toml"), {"integrator.form=\"hamiltonian\"", "integrator.lift=\"legendre\""}},
      {scene("pendulum.toml"), {"integrator.form=\"hamiltonian\"", "integrator.lift=\"cotangnet\""}},
      {scene("pendulum.toml"),
       {"integrator.form=\"sode2\"", "integrator.lift=\"legendre\"", "integrator.map=\"retraction-theta\""}},
      {scene("pendulum.toml"), {"integrator.form=\"newmark\"", "integrator.lift=\"tangent\""}},
      {scene("kepler-galerkin.toml"), {"integrator.lift=\"cotangent\""}},
      {scene("spherical-pendulum.toml"), {"integrator.form=\"hamiltonian\"", "integrator.lift=\"none\""}},
  };
  for (const auto& [file, sets] : refused) {
    const Output r = run(file, sets);
    BOOST_TEST(r.status == 2, file << " " << sets.back());
    BOOST_TEST(r.err.find("integrator.lift") != std::string::npos, r.err);
  }
}

// map = "written": a discretization map written in the scene's [map] section.
//   - the midpoint map written as q0 = x - v/2, q1 = x + v/2 reproduces the built-in
//     midpoint step to round-off (the written one goes through Newton's inverse), in
//     the lagrangian and hamiltonian forms, and the flat retraction x + v with theta
//     reproduces the theta map;
//   - a cubic-corrected midpoint map that is not built in is its own adjoint, so of
//     order 2, and with theta = 0.3 in place of 1/2 of order 1 (dvm converge);
//   - maps that break Def. 2.2 are refused naming the key, with the residual;
//     check-map --scene passes on the cubic map and refuses a broken one.
BOOST_AUTO_TEST_CASE(written_maps_run_every_form_and_are_checked) {
  const std::string dp = "[system]\nbuiltin = \"double-pendulum\"\n[initial]\nq = [0.5, 0.3]\nv = [0.0, 0.0]\n"
                         "[integrator]\nstep = 0.01\nt_end = 2.0\n";
  auto final_q = [&](const std::string& text, const std::vector<std::string>& sets) {
    std::vector<std::string> args = {"run", write_scene("written_map.toml", text), "--json", "--quiet"};
    for (const std::string& k : sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    const Output o = dvm(args);
    BOOST_TEST(o.status == 0, text << o.err);
    return json_array(o.out, "q_final");
  };
  auto distance = [](const std::vector<double>& a, const std::vector<double>& b) {
    double d = a.size() == b.size() && !a.empty() ? 0.0 : INFINITY;
    for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
    return d;
  };
  const std::string written_mid = dp + "map = \"written\"\n[map]\nq0 = \"x - v/2\"\nq1 = \"x + v/2\"\n";
  for (const char* form : {"lagrangian", "hamiltonian"}) {
    const std::string f = std::string("integrator.form=\"") + form + "\"";
    const double d = distance(final_q(written_mid, {f}), final_q(dp + "map = \"midpoint\"\n", {f}));
    BOOST_TEST_MESSAGE("written midpoint vs midpoint, " << form << ", 200 steps: " << d);
    BOOST_TEST(d <= 1e-13, form);
  }
  const double dr = distance(
      final_q(dp + "map = \"written\"\ntheta = 0.3\n[map]\nretraction = \"x + v\"\n", {}),
      final_q(dp + "map = \"theta\"\ntheta = 0.3\n", {}));
  BOOST_TEST(dr <= 1e-13);

  const std::string cubic = "[system]\nbuiltin = \"pendulum\"\n[initial]\nq = [2.0]\np = [0.0]\n[integrator]\n"
                            "map = \"written\"\nstep = 0.01\nt_end = 1.0\n[map]\nq0 = \"x - v/2 - c*v^3\"\n"
                            "q1 = \"x + v/2 + c*v^3\"\nparams = { c = 0.125 }\n";
  const std::string path = write_scene("cubic.toml", cubic);
  struct Case {
    std::vector<std::string> sets;
    double order;
  };
  for (const Case& c : {Case{{}, 2.0}, Case{{"map.q0=\"x - 0.3*v + v^3/10\"", "map.q1=\"x + 0.7*v + v^3/10\""}, 1.0}}) {
    std::vector<std::string> args = {"converge", path, "--t-end", "1", "--steps-list", "10,20,40,80", "--json"};
    for (const std::string& k : c.sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    const Output o = dvm(args);
    BOOST_TEST_MESSAGE("written cubic map, expected order " << c.order << ": fitted " << fitted(o));
    BOOST_TEST(o.status == 0, o.err);
    BOOST_TEST(std::fabs(fitted(o) - c.order) <= 0.1, o.out);
  }
  const Output ok = dvm({"check-map", "--scene", path});
  BOOST_TEST(ok.status == 0, ok.out << ok.err);
  const Json checked = parse_json(ok.out);
  BOOST_TEST(checked.value("claims_symmetric", false), ok.out);
  BOOST_TEST(checked.value("passed", false), ok.out);

  const std::vector<std::pair<std::string, std::vector<std::string>>> broken = {
      {"map.q1", {"map.q1=\"x + 2*v\""}},         // d/dv (R^2 - R^1) = 2.5 at v = 0
      {"map.q0", {"map.q0=\"x + 0.1 - v/2\""}},  // R_d(x, 0) != (x, x)
      {"map.q1", {"map.q1=\"x + v/2 + y\""}},    // an unknown name
      {"map.retraction", {"map.retraction=\"x + v\""}},  // both forms at once
      {"integrator.theta", {"integrator.theta=0.3"}},    // theta of a q0/q1 map
      {"integrator.theta", {"integrator.theta=0.5"}},    // even the default: it would do nothing
  };
  for (const auto& [key, sets] : broken) {
    std::vector<std::string> args = {"run", path, "--quiet"};
    for (const std::string& k : sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    const Output o = dvm(args);
    BOOST_TEST(o.status == 2, sets[0]);
    BOOST_TEST(o.err.find("'" + key + "'") != std::string::npos, o.err);
  }
  const Output bad = dvm({"check-map", "--scene", path, "--set", "map.q1=\"x + 2*v\""});
  BOOST_TEST(bad.status == 2);
  BOOST_TEST(bad.err.find("Def. 2.2") != std::string::npos, bad.err);
  // a written map on a system of the run-time-sized steps, and [map] without map = "written"
  const Output nb = dvm({"run", scene("figure_eight.toml"), "--set", "integrator.map=\"written\"", "--set",
                         "map.q0=\"x - v/2\"", "--set", "map.q1=\"x + v/2\"", "--quiet"});
  BOOST_TEST(nb.status == 2);
  BOOST_TEST(nb.err.find("integrator.map") != std::string::npos, nb.err);
  const Output stray = dvm({"run", scene("pendulum.toml"), "--set", "map.q0=\"x\"", "--quiet"});
  BOOST_TEST(stray.status == 2);
  BOOST_TEST(stray.err.find("[map]") != std::string::npos, stray.err);
}

// Galerkin s = 4 on the double pendulum: order 8, with a reference good enough to say so.
BOOST_AUTO_TEST_CASE(converge_measures_galerkin_against_a_reference_that_reports_its_accuracy) {
  const Output o = dvm({"converge", scene("double_pendulum.toml"), "--t-end", "1", "--steps-list", "5,7,10,14",
                        "--set", "integrator.method=galerkin", "--set", "integrator.stages=4", "--json"});
  BOOST_TEST_MESSAGE("double pendulum, galerkin s = 4: fitted order " << fitted(o) << "\n" << o.out);
  BOOST_TEST(o.status == 0, o.err);
  BOOST_TEST(json_string(o.out, "method") == "galerkin");
  BOOST_TEST(std::fabs(fitted(o) - 8.0) <= 0.3);
  const double acc = json_number(o.out, "reference_accuracy");
  BOOST_TEST(acc > 0.0);
  // every fitted run's error is well above the reference's accuracy
  const Json study = parse_json(o.out);
  for (const Json& run : study.at("runs"))
    if (run.value("fitted", false)) BOOST_TEST(json_double(run.at("error")) > 10.0 * acc, run.dump());
}

// On S^2 and SO(3), and in the Hamiltonian form, converge makes a table (and leaves
// the scene's CSV unwritten; an [output] key given with --set is refused): the triple
// jump of the sphere's midpoint map is of order 4 on the spherical pendulum, the error
// measured on the manifold.
BOOST_AUTO_TEST_CASE(converge_works_on_curved_spaces_and_in_every_form) {
  const std::string csv = temp_dir() + "/not_written.csv";
  std::string text = slurp(scene("spherical-pendulum.toml"));
  const auto out = text.find("[output]");
  BOOST_REQUIRE(out != std::string::npos);
  text = text.substr(0, out) + "[output]\ncsv = \"" + csv + "\"\n";
  const std::string with_csv = write_scene("spherical_with_csv.toml", text);
  const Output s = dvm({"converge", with_csv, "--t-end", "1", "--steps-list", "10,20,40,80", "--set",
                        "integrator.composition=triple-jump", "--json"});
  BOOST_TEST_MESSAGE("spherical pendulum, triple jump: fitted order " << fitted(s) << "\n" << s.out);
  BOOST_TEST(s.status == 0, s.err);
  BOOST_TEST(std::fabs(fitted(s) - 4.0) <= 0.3);
  BOOST_TEST(!file_exists(csv));

  const Output r = dvm({"converge", scene("rigid-body.toml"), "--t-end", "1", "--steps-list", "10,20,40", "--json"});
  BOOST_TEST(r.status == 0, r.err);
  BOOST_TEST(std::fabs(fitted(r) - 2.0) <= 0.2, r.out);

  const Output h = dvm({"converge", scene("pendulum.toml"), "--t-end", "1", "--steps-list", "10,20,40", "--set",
                        "integrator.form=hamiltonian", "--set", "integrator.map=adjoint-euler", "--json"});
  BOOST_TEST(h.status == 0, h.err);
  BOOST_TEST(json_string(h.out, "form") == "hamiltonian");
  BOOST_TEST(std::fabs(fitted(h) - 1.0) <= 0.15, h.out);
}

// What a convergence study cannot measure is refused, or flagged instead of printed.
BOOST_AUTO_TEST_CASE(converge_refuses_or_flags_what_it_cannot_measure) {
  const Output same = dvm({"converge", scene("pendulum.toml"), "--steps-list", "100,100"});
  BOOST_TEST(same.status == 2);
  BOOST_TEST(same.err.find("appears twice") != std::string::npos, same.err);
  const Output bvp = dvm({"converge", scene("pendulum_bvp.toml")});
  BOOST_TEST(bvp.status == 2);
  BOOST_TEST(bvp.err.find("problem.kind") != std::string::npos, bvp.err);
  // the double pendulum far beyond its predictable horizon: errors of the size of the
  // solution, no order printed, the reason given
  const Output chaos = dvm({"converge", scene("double_pendulum.toml"), "--t-end", "100", "--steps-list",
                            "2000,4000", "--json"});
  BOOST_TEST(chaos.status == 0, chaos.err);
  const Json study = parse_json(chaos.out);
  BOOST_TEST((study.contains("fitted_order") && study.at("fitted_order").is_null()), chaos.out);
  BOOST_TEST(study.value("fit_note", "").find("not determined") != std::string::npos, chaos.out);
}

// Every space writes .npy (never nothing with exit 0), with the CSV's columns, and its
// last row is the run's final state: t_final, q_final (the stored position), p_final.
BOOST_AUTO_TEST_CASE(npy_is_written_on_every_space) {
  for (const char* name : {"spherical-pendulum.toml", "rigid-body.toml", "spherical-chain.toml", "chain.toml"}) {
    const std::string npy = temp_dir() + "/" + name + ".npy", csv = temp_dir() + "/" + name + ".csv";
    const Output o = dvm({"run", scene(name), "--json", "--npy", npy, "--csv", csv, "--set", "integrator.t_end=1.0"});
    BOOST_TEST_CONTEXT(name << "\n" << o.err) {
      BOOST_TEST(o.status == 0);
      const std::string data = slurp(npy);
      BOOST_REQUIRE(data.size() > 128);
      BOOST_TEST(data.compare(1, 5, "NUMPY") == 0);
      // rows x columns in the header, and the CSV's column count
      const std::string header = first_line(csv);
      const int columns = 1 + static_cast<int>(std::count(header.begin(), header.end(), ','));
      const auto shape = data.find("'shape': (");
      BOOST_REQUIRE(shape != std::string::npos);
      const long rows = std::strtol(data.c_str() + shape + 10, nullptr, 10);
      const long cols = std::strtol(data.c_str() + data.find(',', shape) + 1, nullptr, 10);
      BOOST_TEST(cols == columns);
      BOOST_REQUIRE(static_cast<std::size_t>(rows * cols * 8 + 128) == data.size());
      // the last row, little-endian float64 (the header says '<f8'), against the report
      BOOST_TEST(data.find("'descr': '<f8'") != std::string::npos);
      std::vector<double> last(cols);
      std::memcpy(last.data(), data.data() + data.size() - 8 * cols, 8 * cols);
      std::vector<double> expect = {json_number(o.out, "t_final")};
      for (const char* key : {"q_final", "p_final"})
        for (double x : json_array(o.out, key)) expect.push_back(x);
      BOOST_REQUIRE(expect.size() <= last.size());
      for (std::size_t i = 0; i < expect.size(); ++i) BOOST_TEST(last[i] == expect[i], "column " << i);
    }
  }
}

// The boundary-value run on S^2 writes through the same atomic recorder: a symlink at
// the output path is replaced, never followed; a run that fails leaves the final path
// as it was and its nodes in PATH.partial.
BOOST_AUTO_TEST_CASE(boundary_values_on_the_sphere_write_atomically) {
  const std::string dir = temp_dir();
  const std::string bvp = write_scene(
      "s2bvp.toml",
      "[system]\nbuiltin = \"spherical-pendulum\"\nparams = { m = 1.0, l = 1.0, g = 9.81 }\n[initial]\n"
      "q = [0.6, 0.0, -0.8]\n[problem]\nkind = \"boundary-value\"\nq_final = [0.0, 0.6, -0.8]\nsteps = 50\n"
      "[integrator]\nmap = \"sphere-exp\"\nstep = 0.01\n");
  const std::string target = dir + "/target.txt", link = dir + "/link.csv";
  std::ofstream(target) << "keep\n";
  BOOST_REQUIRE(symlink(target.c_str(), link.c_str()) == 0);
  const Output o = dvm({"run", bvp, "--quiet", "--csv", link});
  BOOST_TEST(o.status == 0, o.err);
  BOOST_TEST(slurp(target) == "keep\n");
  struct stat st {};
  BOOST_TEST(lstat(link.c_str(), &st) == 0);
  BOOST_TEST(S_ISREG(st.st_mode));
  BOOST_TEST(first_line(link) == "t,x,y,z,p_x,p_y,p_z,energy,J3");

  // a failed solve (one Ceres iteration allowed) keeps an existing file and writes .partial
  const std::string csv = dir + "/s2old.csv";
  std::ofstream(csv) << "old\n";
  const Output f = dvm({"run", bvp, "--quiet", "--csv", csv, "--set", "integrator.max_iterations=1", "--set",
                        "problem.steps=2000", "--set", "integrator.step=0.0005"});
  BOOST_TEST_MESSAGE("S^2 boundary value, 1 iteration: exit " << f.status << ": " << f.err);
  BOOST_TEST(f.status == 3);
  BOOST_TEST(slurp(csv) == "old\n");
  BOOST_TEST(file_exists(csv + ".partial"));
  // bad input leaves it as it was too
  const Output bad = dvm({"run", bvp, "--quiet", "--csv", csv, "--set", "problem.q_final=[0.0, 0.6, -0.9]"});
  BOOST_TEST(bad.status == 2);
  BOOST_TEST(slurp(csv) == "old\n");
}

// A written system's CSV names its columns after its coordinates; built-in systems
// keep q0.., p0...
BOOST_AUTO_TEST_CASE(written_systems_name_their_columns) {
  const std::string csv = temp_dir() + "/dpw.csv", csv2 = temp_dir() + "/dp.csv";
  BOOST_TEST(dvm({"run", scene("double_pendulum_written.toml"), "--quiet", "--csv", csv, "--set",
                  "integrator.t_end=0.1"})
                 .status == 0);
  BOOST_TEST(first_line(csv) == "t,a,b,p_a,p_b,energy");
  BOOST_TEST(dvm({"run", scene("double_pendulum.toml"), "--quiet", "--csv", csv2, "--set", "integrator.t_end=0.1"})
                 .status == 0);
  BOOST_TEST(first_line(csv2) == "t,q0,q1,p0,p1,energy");
}

// Lagrangians written on S^2 and SO(3) run the built-ins' steps from the scene: the
// shipped scenes reproduce the built-in pendulum and top (every method is compared in
// tests/solvers/test_written_manifold.cc), name their columns as their built-in twins
// do, report J3, and every
// key that does not fit the space is refused with exit 2, naming it.
BOOST_AUTO_TEST_CASE(lagrangians_written_on_curved_spaces) {
  struct Twin {
    const char* written;
    const char* builtin;
    const char* header;
  };
  for (const Twin& t : {Twin{"spherical_pendulum_written.toml", "spherical-pendulum.toml", "t,x,y,z,p_x,p_y,p_z,energy,J3"},
                        Twin{"heavy_top_written.toml", "heavy-top.toml", "t,qw,qx,qy,qz,pi1,pi2,pi3,energy,J3"}}) {
    BOOST_TEST_CONTEXT(t.written) {
      const std::string csv = temp_dir() + "/written_manifold.csv";
      for (const char* form : {"lagrangian", "hamiltonian"}) {
        const std::vector<std::string> sets = {"--set", "integrator.t_end=0.5", "--set",
                                               std::string("integrator.form=\"") + form + "\""};
        std::vector<std::string> a = {"run", scene(t.written), "--json", "--quiet", "--csv", csv};
        std::vector<std::string> b = {"run", scene(t.builtin), "--json", "--quiet", "--csv", csv};
        a.insert(a.end(), sets.begin(), sets.end());
        b.insert(b.end(), sets.begin(), sets.end());
        const Output w = dvm(a);
        BOOST_TEST(w.status == 0, w.err);
        BOOST_TEST(first_line(csv) == t.header);
        const Output o = dvm(b);
        BOOST_TEST(o.status == 0, o.err);
        BOOST_TEST(first_line(csv) == t.header);  // twins name their columns alike
        const auto qw = json_array(w.out, "q_final"), qb = json_array(o.out, "q_final");
        BOOST_TEST_REQUIRE(qw.size() == qb.size());
        for (std::size_t i = 0; i < qw.size(); ++i) BOOST_TEST(std::fabs(qw[i] - qb[i]) <= 1e-13, form);
        const bool reports_j3 = has_invariant(w.out, "angular momentum about e3") ||
                                has_invariant(w.out, "spatial angular momentum about e3");
        BOOST_TEST(reports_j3, w.out);
      }
    }
  }
  // the coordinates of S^2 named in the scene name the columns
  const Output named = dvm({"run", scene("spherical_pendulum_written.toml"), "--quiet", "--csv",
                            temp_dir() + "/abc.csv", "--set", "integrator.t_end=0.1", "--set",
                            "system.coordinates=[\"a\", \"b\", \"c\"]", "--set",
                            "system.lagrangian=\"0.5*(a_dot^2 + b_dot^2 + c_dot^2) - g*c\"", "--set",
                            "system.hamiltonian=\"0.5*(p_a^2 + p_b^2 + p_c^2) + g*c\""});
  BOOST_TEST(named.status == 0, named.err);
  BOOST_TEST(first_line(temp_dir() + "/abc.csv") == "t,a,b,c,p_a,p_b,p_c,energy,J3");

  // on (S^2)^2 with equal masses and rods: the built-in spherical chain of two links
  {
    const std::string csv = temp_dir() + "/written_power.csv";
    std::vector<std::string> sets = {"--set", "integrator.t_end=0.5", "--set", "initial.q=[0.6, 0.0, -0.8, 0.0, 0.6, -0.8]",
                                     "--set", "initial.v=[0.0, 0.5, 0.0, 0.4, 0.4, 0.3]", "--set",
                                     "integrator.composition=\"kahan-li6\""};
    std::vector<std::string> a = {"run", scene("spherical_double_pendulum_written.toml"), "--json", "--quiet", "--csv",
                                  csv, "--set", "system.params.m2=1.0", "--set", "system.params.l2=1.0"};
    std::vector<std::string> b = {"run", scene("spherical-chain.toml"), "--json", "--quiet", "--csv", csv, "--set",
                                  "system.params.n=2", "--set", "system.params.g=9.81"};
    a.insert(a.end(), sets.begin(), sets.end());
    b.insert(b.end(), sets.begin(), sets.end());
    const Output w = dvm(a);
    BOOST_TEST(w.status == 0, w.err);
    BOOST_TEST(first_line(csv) == "t,x1,y1,z1,x2,y2,z2,p_x1,p_y1,p_z1,p_x2,p_y2,p_z2,energy,J3");
    const Output o = dvm(b);
    BOOST_TEST(o.status == 0, o.err);
    BOOST_TEST(first_line(csv) == "t,x1,y1,z1,x2,y2,z2,p_x1,p_y1,p_z1,p_x2,p_y2,p_z2,energy,J3");
    const auto qw = json_array(w.out, "q_final"), qb = json_array(o.out, "q_final");
    BOOST_TEST_REQUIRE(qw.size() == 6u);
    BOOST_TEST_REQUIRE(qb.size() == 6u);
    for (std::size_t i = 0; i < qw.size(); ++i) BOOST_TEST(std::fabs(qw[i] - qb[i]) <= 1e-13);
    BOOST_TEST(has_invariant(w.out, "angular momentum about e3"), w.out);
  }

  struct Refused {
    const char* scene;
    std::vector<std::string> sets;
    const char* key;
    const char* says;
  };
  const char* sp = "spherical_pendulum_written.toml";
  const char* top = "heavy_top_written.toml";
  for (const Refused& r : std::vector<Refused>{
           {sp, {"system.space=\"S3\""}, "system.space", "expected \"R^n\", \"S^2\", \"(S^2)^K\" with K from 1 to 4, or \"SO(3)\""},
           {sp, {"system.coordinates=[\"x\", \"y\"]"}, "system.coordinates", "3 components"},
           {"spherical_double_pendulum_written.toml", {"system.space=\"(S^2)^3\""}, "initial.q",
            "expected 9"},
           {"spherical_double_pendulum_written.toml", {"system.coordinates=[\"a\", \"b\", \"c\"]"},
            "system.coordinates", "the 3 components of each of the 2 embedded unit vectors"},
           {"spherical_double_pendulum_written.toml", {"system.space=\"(S^2)^5\""}, "system.space", "K from 1 to 4"},
           {"spherical_double_pendulum_written.toml", {"integrator.form=\"hamiltonian\""}, "integrator.form",
            "spherical chain's steps"},
           {"spherical_double_pendulum_written.toml", {"integrator.method=\"galerkin\""}, "integrator.method",
            "spherical chain's steps"},
           {top, {"system.coordinates=[\"a\"]"}, "system.coordinates", "names are fixed"},
           {top, {"system.params.w1=2.0"}, "system.params", "used twice"},
           {sp, {"system.lagrangian=\"0.5*(x_dot^2 + y_dot^2 + w_dot^2)\""}, "system.lagrangian", "unknown name 'w_dot'"},
           {top, {"system.lagrangian=\"0.5*(w1^2 + w2^2 + w3^2) - z\""}, "system.lagrangian", "unknown name 'z'"},
           {sp, {"system.hamiltonian=\"(p_x^2 + p_y^2 + p_z^2) + m*g*l*z\""}, "system.hamiltonian",
            "does not match the Legendre transform"},
           // z_dot^2 alone: the velocity Hessian has rank 1 on the tangent plane
           {sp, {"system.lagrangian=\"z_dot^2 - z\""}, "system.lagrangian", "degenerate"},
           {sp, {"integrator.form=\"sode1\""}, "integrator.form", "lagrangian and hamiltonian"},
           {top, {"integrator.form=\"newmark\""}, "integrator.form", "lagrangian and hamiltonian"},
           {sp, {"integrator.map=\"midpoint\""}, "integrator.map", "lives on R^n"},
           {top, {"integrator.map=\"sphere-exp\""}, "integrator.map", "lives on S^2"},
           {sp, {"integrator.map=\"written\"", "map.q0=\"x - v/2\"", "map.q1=\"x + v/2\""}, "integrator.map",
            "lives on R^n"},
           {top, {"problem.kind=\"boundary-value\"", "problem.q_final=[1.0, 0.0, 0.0, 0.0]"}, "problem.kind",
            "boundary-value"},
           {top, {"integrator.form=\"hamiltonian\"", "system.hamiltonian=\"\""}, "system.hamiltonian", ""},
       }) {
    std::vector<std::string> args = {"run", scene(r.scene), "--quiet", "--csv", temp_dir() + "/refused.csv"};
    for (const std::string& k : r.sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    const Output o = dvm(args);
    BOOST_TEST_CONTEXT(r.scene << " " << r.sets[0]) {
      BOOST_TEST(o.status == 2, o.err);
      BOOST_TEST(o.err.find(r.key) != std::string::npos, o.err);
      BOOST_TEST(o.err.find(r.says) != std::string::npos, o.err);
    }
  }
  // without a written H, the hamiltonian form is refused naming integrator.form
  const std::string no_h = write_scene(
      "top_no_h.toml", "[system]\nspace = \"SO(3)\"\nlagrangian = \"(w1^2 + 2*w2^2 + 3*w3^2)/2\"\n[initial]\n"
                       "rotation = [1.0, 0.0, 0.0, 0.0]\nomega = [0.1, 1.0, 0.2]\n[integrator]\nmap = \"so3-cayley\"\n"
                       "step = 0.01\nsteps = 10\nform = \"hamiltonian\"\n");
  const Output nh = dvm({"run", no_h, "--quiet"});
  BOOST_TEST(nh.status == 2, nh.err);
  BOOST_TEST(nh.err.find("key 'integrator.form': on SO(3) the hamiltonian form runs the Hamiltonian written") !=
                 std::string::npos,
             nh.err);
  // the free body written without H: the lagrangian form conserves all three J_k
  const Output fb = dvm({"run", no_h, "--json", "--quiet", "--set", "integrator.form=\"lagrangian\""});
  BOOST_TEST(fb.status == 0, fb.err);
  for (const char* k : {"spatial angular momentum about e1", "spatial angular momentum about e2",
                        "spatial angular momentum about e3"})
    BOOST_TEST(has_invariant(fb.out, k), k << "\n" << fb.out);
}

// Sizes known only at run time run through the run-time-sized kernels: a written chain
// of 12 coordinates (its total momentum conserved to round-off: the potential depends
// on differences only) and an N-body scene of 8 bodies.
BOOST_AUTO_TEST_CASE(sizes_known_only_at_run_time) {
  const int n = 12;
  std::string coords, kinetic, potential, q, v;
  for (int i = 0; i < n; ++i) {
    const std::string c = "x" + std::to_string(i);
    coords += (i ? ", \"" : "\"") + c + "\"";
    kinetic += (i ? " + " : "") + c + "_dot^2/2";
    if (i > 0) potential += (i > 1 ? " + " : "") + ("(" + c + " - x" + std::to_string(i - 1) + ")^4/4");
    q += (i ? ", " : "") + std::to_string(0.1 * std::sin(i));
    v += (i ? ", " : "") + std::to_string(i == 0 ? 0.3 : 0.0);
  }
  const std::string chain = write_scene(
      "chain12.toml", "[system]\ncoordinates = [" + coords + "]\nlagrangian = \"" + kinetic + " - (" + potential +
                          ")\"\n[initial]\nq = [" + q + "]\nv = [" + v + "]\n[integrator]\nmap = \"midpoint\"\n"
                          "step = 0.01\nsteps = 200\n");
  const Output c = dvm({"run", chain, "--json"});
  BOOST_TEST(c.status == 0, c.err);
  BOOST_TEST(json_array(c.out, "q_final").size() == static_cast<std::size_t>(n));
  BOOST_TEST(json_number(c.out, "max_abs_energy_error") <= 1e-4, c.out);
  const std::vector<double> p = json_array(c.out, "p_final");
  double total = 0.0;
  for (double x : p) total += x;
  BOOST_TEST(std::fabs(total - 0.3) <= 1e-14, c.out);

  std::string masses, qb, vb;
  for (int i = 0; i < 8; ++i) {
    const double a = 2.0 * M_PI * i / 8.0;
    masses += (i ? ", " : "") + std::string("1.0");
    char buf[128];
    std::snprintf(buf, sizeof buf, "%s%.17g, %.17g, 0.0", i ? ", " : "", std::cos(a), std::sin(a));
    qb += buf;
    std::snprintf(buf, sizeof buf, "%s%.17g, %.17g, 0.0", i ? ", " : "", -std::sin(a), std::cos(a));
    vb += buf;
  }
  const std::string bodies = write_scene(
      "nbody8.toml", "[system]\nbuiltin = \"nbody\"\nmasses = [" + masses + "]\nparams = { G = 0.1 }\n[initial]\nq = [" +
                         qb + "]\nv = [" + vb + "]\n[integrator]\nmap = \"midpoint\"\nstep = 0.001\nsteps = 200\n");
  const Output b = dvm({"run", bodies, "--json"});
  BOOST_TEST(b.status == 0, b.err);
  BOOST_TEST(json_array(b.out, "q_final").size() == 24u);
  const Json jb = parse_json(b.out);
  for (const char* inv : {"momentum x", "angular momentum z"}) {
    BOOST_REQUIRE_MESSAGE(jb.contains("invariants") && jb.at("invariants").contains(inv), inv);
    BOOST_TEST(json_double(jb.at("invariants").at(inv).at("max_abs_error")) <= 1e-13, inv);
  }
}

namespace {

// The objects of the JSON array printed by `dvm maps|methods|systems --json`.
std::vector<Json> json_objects(const std::string& json) {
  const Json j = parse_json(json);
  BOOST_REQUIRE_MESSAGE(j.is_array(), "not a JSON array:\n" << json);
  return std::vector<Json>(j.begin(), j.end());
}

// The parameters of a README cell "m = 1, l = 1", in order, each name with its number
// (NaN where the value is not a number, so that it equals none); "" is none.
std::vector<std::pair<std::string, double>> readme_params(const std::string& cell) {
  std::vector<std::pair<std::string, double>> out;
  std::istringstream in(cell);
  for (std::string part; std::getline(in, part, ',');) {
    const std::size_t eq = part.find('=');
    std::string name = part.substr(0, eq), value = eq == std::string::npos ? "" : part.substr(eq + 1);
    for (std::string* x : {&name, &value}) {
      while (!x->empty() && x->front() == ' ') x->erase(0, 1);
      while (!x->empty() && x->back() == ' ') x->pop_back();
    }
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    out.emplace_back(name, !value.empty() && *end == '\0' ? v : NAN);
  }
  return out;
}

// The cells of the README's table row for `name` ("| name | a | b |" -> {name, a, b});
// empty when the README has no such row.
std::vector<std::string> readme_row(const std::string& readme, const std::string& name) {
  const std::size_t at = readme.find("\n| " + name + " |");
  if (at == std::string::npos) return {};
  const std::string line = readme.substr(at + 1, readme.find('\n', at + 1) - at - 1);
  std::vector<std::string> cells;
  std::size_t from = 1;
  for (std::size_t bar; (bar = line.find(" |", from)) != std::string::npos; from = bar + 2) {
    std::string cell = line.substr(from, bar - from);
    while (!cell.empty() && cell.front() == ' ') cell.erase(0, 1);
    cells.push_back(cell);
  }
  return cells;
}

}  // namespace

// The READMEs' tables of systems, maps and composition methods
// agree with the registries the program dispatches from: every entry has its row, with
// the order (and for the maps on R^n, the symmetry) the registry states.
// The structure of the system is reported, and integrator.use_structure switches the
// explicit kicks and drifts of a separable system off (the same states, to round-off).
BOOST_AUTO_TEST_CASE(structure_is_reported_and_use_structure_switches_it) {
  const std::vector<std::string> sv = {"--set", "integrator.map=\"explicit-euler\"", "--set",
                                       "integrator.composition=\"stormer-verlet\"", "--set", "integrator.t_end=10",
                                       "--csv", "/dev/null", "--json"};
  std::vector<std::string> a = {"run", scene("kepler.toml")};
  a.insert(a.end(), sv.begin(), sv.end());
  const Output fast = dvm(a);
  BOOST_TEST(fast.status == 0, fast.err);
  BOOST_TEST(json_string(fast.out, "structure") == "separable", fast.out);
  BOOST_TEST(json_string(fast.out, "structure_source") == "declared", fast.out);
  BOOST_TEST(json_string(fast.out, "step_path") == "explicit-splitting", fast.out);
  BOOST_TEST(json_number(fast.out, "solver_iterations") == 0.0, fast.out);
  a.insert(a.end(), {"--set", "integrator.use_structure=false"});
  const Output slow = dvm(a);
  BOOST_TEST(slow.status == 0, slow.err);
  BOOST_TEST(json_string(slow.out, "step_path") == "generic", slow.out);
  BOOST_TEST(json_number(slow.out, "solver_iterations") > 0.0, slow.out);
  const std::vector<double> qa = json_array(fast.out, "q_final"), qb = json_array(slow.out, "q_final");
  BOOST_REQUIRE(qa.size() == 2u);
  BOOST_REQUIRE(qb.size() == 2u);
  BOOST_TEST(std::fabs(qa[0] - qb[0]) + std::fabs(qa[1] - qb[1]) <= 1e-12);
  // the text summary says it too
  const Output table = dvm({"run", scene("kepler.toml"), "--set", "integrator.map=\"adjoint-euler\"", "--set",
                            "integrator.t_end=1", "--csv", "/dev/null"});
  BOOST_TEST(table.out.find("structure separable (declared); steps explicit") != std::string::npos, table.out);
  // a value that is not a boolean is refused, naming the key
  const Output bad = dvm({"run", scene("kepler.toml"), "--set", "integrator.use_structure=1", "--csv", "/dev/null"});
  BOOST_TEST(bad.status == 2);
  BOOST_TEST(bad.err.find("integrator.use_structure") != std::string::npos, bad.err);
  BOOST_TEST(bad.err.find("expected true or false") != std::string::npos, bad.err);
  // a mechanical system; n bodies (run-time size) take the explicit steps too
  const Output dp = dvm({"run", scene("double_pendulum.toml"), "--set", "integrator.t_end=1", "--csv", "/dev/null",
                         "--json"});
  BOOST_TEST(dp.status == 0, dp.err);
  BOOST_TEST(json_string(dp.out, "structure") == "mechanical", dp.out);
  const Output nb = dvm({"run", scene("figure_eight.toml"), "--set", "integrator.map=\"explicit-euler\"", "--set",
                         "integrator.composition=\"kahan-li8\"", "--set", "integrator.t_end=1", "--csv", "/dev/null",
                         "--json"});
  BOOST_TEST(nb.status == 0, nb.err);
  BOOST_TEST(json_string(nb.out, "structure") == "separable", nb.out);
  BOOST_TEST(json_string(nb.out, "step_path") == "explicit-splitting", nb.out);
}

// [output] monitor_every: the energy and invariants are evaluated every N steps, at
// every row and at the last step; the maxima are over those steps, the final values exact.
BOOST_AUTO_TEST_CASE(monitor_every_evaluates_the_summary_less_often) {
  // a scene without output files: only the monitored steps are evaluated
  const std::string plain = write_scene("kepler_plain.toml", "[system]\nbuiltin = \"kepler\"\n[initial]\nq = [0.4, 0.0]\n"
                                        "p = [0.0, 2.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.005\nt_end = 10.0\n");
  const Output every = dvm({"run", plain, "--json"});
  const Output sparse = dvm({"run", plain, "--set", "output.monitor_every=7", "--json"});
  BOOST_TEST(every.status == 0, every.err);
  BOOST_TEST(sparse.status == 0, sparse.err);
  BOOST_TEST(json_number(every.out, "monitor_every") == 1.0);
  BOOST_TEST(json_number(sparse.out, "monitor_every") == 7.0);
  // the same run: the last step is monitored in both, the maximum is over fewer steps
  BOOST_TEST(json_number(sparse.out, "energy_final") == json_number(every.out, "energy_final"));
  BOOST_TEST(json_number(sparse.out, "max_abs_energy_error") <= json_number(every.out, "max_abs_energy_error"));
  BOOST_TEST(json_number(sparse.out, "max_abs_energy_error") > 0.0);
  // rows are still written with their energy
  const std::string csv = "kepler_monitor.csv";
  const Output rows = dvm({"run", plain, "--set", "output.monitor_every=1000", "--csv", csv});
  BOOST_TEST(rows.status == 0, rows.err);
  std::ifstream f(csv);
  std::string line;
  int n = 0;
  while (std::getline(f, line)) ++n;
  BOOST_TEST(n == 2002);  // header, t = 0 and 2000 steps
  std::remove(csv.c_str());
  const Output bad = dvm({"run", plain, "--set", "output.monitor_every=0"});
  BOOST_TEST(bad.status == 2);
  BOOST_TEST(bad.err.find("output.monitor_every") != std::string::npos, bad.err);
}

BOOST_AUTO_TEST_CASE(readme_tables_agree_with_the_registries) {
  // the systems in README.md, the maps in core/README.md, the compositions in
  // solvers/README.md
  std::string readme;
  for (const char* f : {"README.md", "core/README.md", "solvers/README.md"})
    readme += slurp(std::string(DVM_SCENES) + "/../../" + f);
  BOOST_REQUIRE(readme.size() > 10000);

  const Output maps = dvm({"maps", "--json"});
  BOOST_REQUIRE_EQUAL(maps.status, 0);
  const auto map_entries = json_objects(maps.out);
  BOOST_REQUIRE_GE(map_entries.size(), 13u);
  for (const Json& m : map_entries) {
    const std::string name = m.value("name", "");
    BOOST_TEST_CONTEXT("map " << name) {
      const auto row = readme_row(readme, name);
      BOOST_REQUIRE(!row.empty());
      const std::string order = std::to_string(static_cast<int>(json_double(m.at("order"))));
      if (m.value("space", "") == "R^n") {
        // | name | R_d(x, v) | symmetric | order | inverse |
        BOOST_REQUIRE_EQUAL(row.size(), 5u);
        const bool symmetric = m.value("symmetric", false);
        const bool takes_theta = m.value("takes_theta", false);
        BOOST_TEST((row[2] == (symmetric ? "yes" : "no") || (takes_theta && row[2] == "at θ = 1/2") ||
                    (name == "written" && row[2] == "measured")));
        BOOST_TEST(row[3].rfind(order, 0) == 0);
      } else {
        // | name | R_d(x, v) | order | domain of the inverse |
        BOOST_REQUIRE_EQUAL(row.size(), 4u);
        // the maps that take a theta: "1 (2 at theta = 1/2)", as on R^n
        const bool takes_theta = m.value("takes_theta", false);
        BOOST_TEST((takes_theta ? row[2].rfind(order + " (", 0) == 0 : row[2] == order));
      }
    }
  }

  const Output methods = dvm({"methods", "--json"});
  BOOST_REQUIRE_EQUAL(methods.status, 0);
  int compositions = 0;
  for (const Json& m : json_objects(methods.out)) {
    const std::string name = m.value("name", "");
    // the basic method alone, the Galerkin methods (their own table) and the lifts are
    // not compositions; of the recursive triple jumps (triple-jump:<order>), a family,
    // the README lists some
    if (name == "none" || m.contains("quadrature") || m.contains("lift")) continue;
    const auto row = readme_row(readme, name);
    if (name.find(':') != std::string::npos && row.empty()) continue;
    ++compositions;
    BOOST_TEST_CONTEXT("composition " << name) {
      // | method | order | stages | global | local | threshold |
      BOOST_REQUIRE_EQUAL(row.size(), 6u);
      BOOST_TEST(row[1] == std::to_string(static_cast<int>(json_double(m.at("order")))));
      BOOST_TEST(row[2] == std::to_string(static_cast<int>(json_double(m.at("stages")))));
    }
  }
  BOOST_TEST(compositions >= 17);

  // | name | space | coordinates | parameters (defaults) | forms | also |
  const Output systems = dvm({"systems", "--json"});
  BOOST_REQUIRE_EQUAL(systems.status, 0);
  const auto system_entries = json_objects(systems.out);
  BOOST_REQUIRE_GE(system_entries.size(), 14u);
  for (const Json& s : system_entries) {
    const std::string name = s.value("name", "");
    BOOST_TEST_CONTEXT("system " << name) {
      const auto row = readme_row(readme, name);
      BOOST_REQUIRE_EQUAL(row.size(), 6u);
      BOOST_TEST(row[1] == s.value("space", ""));
      // "params": {"m": 1, "l": 1} against "m = 1, l = 1": the same names in the same
      // order, with equal numbers
      const auto params = readme_params(row[3]);
      const Json& defaults = s.at("params");
      BOOST_TEST(params.size() == defaults.size(), row[3]);
      std::size_t k = 0;
      for (const auto& p : defaults.items()) {
        if (k < params.size()) {
          BOOST_TEST(params[k].first == p.key(), row[3]);
          BOOST_TEST(params[k].second == json_double(p.value()), row[3] << ": " << p.key());
        }
        ++k;
      }
      // "forms": ["a", "b"] -> "a, b"
      std::string forms;
      for (const Json& f : s.at("forms")) forms += (forms.empty() ? "" : ", ") + f.get<std::string>();
      BOOST_TEST(row[4] == forms);
      std::string also;
      for (const auto& [key, label] : {std::pair<std::string, std::string>{"retraction_maps", "retraction maps"},
                                       {"composition", "composition"},
                                       {"galerkin", "galerkin"},
                                       {"boundary_value", "boundary values"}})
        if (s.value(key, false)) also += (also.empty() ? "" : ", ") + label;
      BOOST_TEST(row[5] == also);
    }
  }
}

// ---------------------------------------------------------------------------------
// The documentation agrees with the program: the commands README.md shows run, every
// command `dvm help` lists has a --help that names the options the README uses, the
// shipped scenes are each listed once in examples/scenes/README.md, and no
// documentation file narrates history.

namespace {

std::string repo_file(const std::string& rel) { return std::string(DVM_SCENES) + "/../../" + rel; }

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

// The files of the checkout under `root`, leaving out build folders and hidden ones.
std::vector<std::filesystem::path> checkout_files(const std::string& root) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  for (auto it = fs::recursive_directory_iterator(root); it != fs::recursive_directory_iterator(); ++it) {
    const std::string name = it->path().filename().string();
    if (it->is_directory()) {
      if (name.rfind("build", 0) == 0 || name[0] == '.') it.disable_recursion_pending();
    } else {
      files.push_back(it->path());
    }
  }
  return files;
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t"), e = s.find_last_not_of(" \t");
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

std::vector<std::string> words(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

// A fenced block of a Markdown text: its info string ("sh", "toml", ...), the line
// number (1-based) of its first line of content, and its lines.
struct Fence {
  std::string info;
  int line = 0;
  std::vector<std::string> lines;
};

std::vector<Fence> fences(const std::string& md) {
  std::vector<Fence> out;
  const auto ls = lines_of(md);
  for (std::size_t i = 0; i < ls.size(); ++i) {
    if (ls[i].rfind("```", 0) != 0) continue;
    Fence f;
    f.info = trim(ls[i].substr(3));
    f.line = static_cast<int>(i) + 2;
    for (++i; i < ls.size() && ls[i].rfind("```", 0) != 0; ++i) f.lines.push_back(ls[i]);
    out.push_back(f);
  }
  return out;
}

// A command line of a fenced shell block that starts with `dvm ` or `make run` (a
// line "a && b" is two commands), with the README line it is on.
struct Shown {
  std::string text;
  int line;
};

std::vector<Shown> shown_commands(const std::string& md) {
  std::vector<Shown> out;
  for (const Fence& f : fences(md)) {
    if (f.info != "sh" && f.info != "bash" && f.info != "shell" && f.info != "console") continue;
    for (std::size_t i = 0; i < f.lines.size(); ++i) {
      std::string rest = f.lines[i];
      for (;;) {
        const auto amp = rest.find("&&");
        const std::string part = trim(rest.substr(0, amp));
        if (part.rfind("dvm ", 0) == 0 || part == "dvm" || part.rfind("make run", 0) == 0)
          out.push_back({part, f.line + static_cast<int>(i)});
        if (amp == std::string::npos) break;
        rest = rest.substr(amp + 2);
      }
    }
  }
  return out;
}

// The text of a command line before its comment (" # ..."; quotes respected).
std::string without_comment(const std::string& line) {
  char quote = 0;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quote) {
      if (c == quote) quote = 0;
    } else if (c == '\'' || c == '"') {
      quote = c;
    } else if (c == '#' && (i == 0 || line[i - 1] == ' ')) {
      return trim(line.substr(0, i));
    }
  }
  return trim(line);
}

// A word of a synopsis rather than of a command one can type: SCENE.toml, NAME, PATH,
// [--json], <command>, N1,N2,...
bool is_placeholder(const std::string& w) {
  if (w.find_first_of("[<") != std::string::npos || w.find("...") != std::string::npos) return true;
  const std::string stem = w.size() > 5 && w.compare(w.size() - 5, 5, ".toml") == 0 ? w.substr(0, w.size() - 5) : w;
  if (stem.empty() || !std::isupper(static_cast<unsigned char>(stem[0]))) return false;
  return std::all_of(stem.begin(), stem.end(), [](char c) {
    return std::isupper(static_cast<unsigned char>(c)) || std::isdigit(static_cast<unsigned char>(c)) || c == '_';
  });
}

bool is_synopsis(const std::string& command) {
  const auto ws = words(without_comment(command));
  return std::any_of(ws.begin(), ws.end(), is_placeholder);
}

// Runs a shell command line in `dir` (stdout and stderr captured).
Output sh_in(const std::string& dir, const std::string& line) {
  const std::string err = temp_dir() + "/sh_stderr.txt";
  const std::string cmd = "cd '" + dir + "' && {\n" + line + "\n} 2>'" + err + "'";
  FILE* pipe = popen(cmd.c_str(), "r");
  BOOST_REQUIRE(pipe);
  std::string out;
  char buf[4096];
  for (std::size_t n; (n = fread(buf, 1, sizeof buf, pipe)) > 0;) out.append(buf, n);
  const int st = pclose(pipe);
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, out, slurp(err)};
}

// The commands `dvm help` lists: the first word of each line of its "commands:" list.
std::vector<std::string> listed_commands() {
  const Output h = dvm({"help"});
  BOOST_REQUIRE_EQUAL(h.status, 0);
  std::vector<std::string> out;
  bool in_list = false;
  for (const std::string& l : lines_of(h.out)) {
    if (l == "commands:") {
      in_list = true;
    } else if (in_list && trim(l).empty()) {
      break;
    } else if (in_list) {
      out.push_back(words(l).at(0));
    }
  }
  return out;
}

// The options (--name) of a command line or synopsis, without brackets or values.
std::vector<std::string> options_of(const std::string& text) {
  std::vector<std::string> out;
  for (std::string w : words(without_comment(text))) {
    while (!w.empty() && (w.front() == '[' || w.front() == '`')) w.erase(0, 1);
    if (w.rfind("--", 0) != 0 || w.size() < 3) continue;
    const auto end = w.find_first_of("=]`.");
    out.push_back(w.substr(0, end));
  }
  return out;
}

}  // namespace

// `dvm --version` and `dvm version` print the CMake project version and the git
// revision captured when the build was configured (or "unknown"), and exit 0;
// `dvm help COMMAND` is `dvm COMMAND --help`.
BOOST_AUTO_TEST_CASE(version_and_help) {
  const Output v = dvm({"--version"}), w = dvm({"version"});
  BOOST_TEST(v.status == 0, v.err);
  BOOST_TEST(w.status == 0, w.err);
  BOOST_TEST(v.out == w.out);
  const std::string prefix = std::string("dvm ") + DVM_PROJECT_VERSION + " (git ";
  BOOST_TEST(v.out.rfind(prefix, 0) == 0, v.out);
  const std::string rev = v.out.substr(std::min(prefix.size(), v.out.size()));
  BOOST_TEST((rev == "unknown)\n" || (rev.size() == 14 && rev.find_first_not_of("0123456789abcdef") == 12 &&
                                      rev.compare(12, 2, ")\n") == 0)),
             v.out);
  BOOST_TEST(dvm({"version", "--bogus"}).status == 2);

  const Output h = dvm({"help"}), hh = dvm({"--help"});
  BOOST_TEST(h.status == 0);
  BOOST_TEST(h.out == hh.out);
  const auto commands = listed_commands();
  for (const char* c : {"run", "converge", "maps", "methods", "systems", "check-map", "version", "help"})
    BOOST_TEST((std::find(commands.begin(), commands.end(), c) != commands.end()), "dvm help lists " << c);
  const Output hr = dvm({"help", "run"}), rh = dvm({"run", "--help"});
  BOOST_TEST(hr.status == 0);
  BOOST_TEST(hr.out == rh.out);
  BOOST_TEST(dvm({"help", "no-such-command"}).status == 2);
}

// Every command `dvm help` lists has a --help that exits 0; every dvm command README.md
// shows (in its fenced shell lines and its inline code) is one of them, and each option
// it names is in that command's --help; an option named alone (`--set`) is in some
// command's --help.
BOOST_AUTO_TEST_CASE(readme_commands_and_options_are_in_the_help) {
  std::map<std::string, std::string> help;
  std::string all_help = dvm({"help"}).out;
  for (const std::string& c : listed_commands()) {
    const Output o = dvm({c, "--help"});
    BOOST_TEST_CONTEXT("dvm " << c << " --help") {
      BOOST_TEST(o.status == 0, o.err);
      BOOST_TEST(o.out.size() > 40u, o.out);
    }
    help[c] = o.out;
    all_help += o.out;
  }
  const std::string readme = slurp(repo_file("README.md"));
  std::vector<Shown> uses = shown_commands(readme);
  // inline code: `dvm ...` and `--option ...`
  const auto ls = lines_of(readme);
  std::vector<Shown> alone;
  for (std::size_t i = 0; i < ls.size(); ++i)
    for (std::size_t at = ls[i].find('`'); at != std::string::npos;) {
      const auto end = ls[i].find('`', at + 1);
      if (end == std::string::npos) break;
      const std::string code = ls[i].substr(at + 1, end - at - 1);
      if (code.rfind("dvm ", 0) == 0) uses.push_back({code, static_cast<int>(i) + 1});
      if (code.rfind("--", 0) == 0) alone.push_back({code, static_cast<int>(i) + 1});
      at = ls[i].find('`', end + 1);
    }
  int checked = 0;
  for (const Shown& s : uses) {
    if (s.text.rfind("dvm", 0) != 0) continue;
    const auto ws = words(without_comment(s.text));
    if (ws.size() < 2 || ws[1].front() == '<') continue;  // dvm <command> --help
    BOOST_TEST_CONTEXT("README.md:" << s.line << ": " << s.text) {
      if (ws[1].rfind("--", 0) == 0) {  // dvm --version, dvm --help
        BOOST_TEST(all_help.find(ws[1]) != std::string::npos);
        continue;
      }
      BOOST_REQUIRE(help.count(ws[1]));
      for (const std::string& opt : options_of(s.text)) {
        BOOST_TEST(help[ws[1]].find(opt) != std::string::npos, opt << " is not in dvm " << ws[1] << " --help");
        ++checked;
      }
    }
  }
  for (const Shown& s : alone)
    for (const std::string& opt : options_of(s.text))
      BOOST_TEST(all_help.find(opt) != std::string::npos, "README.md:" << s.line << ": " << opt << " in no --help");
  BOOST_TEST(checked >= 10);  // the synopsis alone names more options than that
}

// A smoke test: every command README.md shows in a fenced shell block runs (exit 0; what
// the commands print is checked by the suites of their features): each `dvm ...` line
// (a synopsis with placeholders such as SCENE.toml excepted) exits 0 with dvm the
// built binary, in a scratch folder holding a copy of the shipped scenes as
// examples/scenes and the README's own scenes (a toml block whose first line is
// "# NAME.toml"), where the files they write land; `make run` is the Makefile's run
// target, whose dvm command is run the same way (without make), and whose scene is
// the one the README's comment names.
BOOST_AUTO_TEST_CASE(readme_commands_run_smoke_test) {
  namespace fs = std::filesystem;
  const std::string readme = slurp(repo_file("README.md"));
  const std::string dir = temp_dir() + "/readme";
  // a copy of the shipped scenes, so that nothing a command writes reaches the sources
  fs::create_directories(dir + "/examples");
  fs::copy(DVM_SCENES, dir + "/examples/scenes", fs::copy_options::recursive);
  int written = 0;
  for (const Fence& f : fences(readme)) {
    if (f.info != "toml" || f.lines.empty() || f.lines[0].rfind("# ", 0) != 0) continue;
    const std::string name = trim(f.lines[0].substr(2));
    if (name.find('/') != std::string::npos || name.size() < 6 || name.compare(name.size() - 5, 5, ".toml") != 0)
      continue;
    std::ofstream out(dir + "/" + name);
    for (const auto& l : f.lines) out << l << "\n";
    ++written;
  }
  BOOST_TEST_MESSAGE("README scenes written: " << written);

  int ran = 0, make_runs = 0;
  for (const Shown& s : shown_commands(readme)) {
    BOOST_TEST_CONTEXT("README.md:" << s.line << ": " << s.text) {
      std::string line = without_comment(s.text);
      if (line.rfind("make run", 0) == 0) {
        ++make_runs;
        // the recipe of the run target: its line that runs the built dvm
        const auto mk = lines_of(slurp(repo_file("Makefile")));
        const auto target = std::find_if(mk.begin(), mk.end(), [](const std::string& l) { return l.rfind("run:", 0) == 0; });
        BOOST_REQUIRE(target != mk.end());
        std::string recipe;
        for (auto it = target + 1; it != mk.end() && !it->empty() && (*it)[0] == '\t'; ++it)
          if (it->find("/examples/dvm ") != std::string::npos) recipe = *it;
        BOOST_REQUIRE(!recipe.empty());
        const std::string args = recipe.substr(recipe.find("/examples/dvm ") + 13);
        // the scene the README's comment names is the one the target runs
        const auto toml = s.text.find(".toml");
        if (s.text.find('#') != std::string::npos && toml != std::string::npos) {
          const auto from = s.text.rfind(' ', toml) + 1;
          BOOST_TEST(args.find(s.text.substr(from, toml + 5 - from)) != std::string::npos, recipe);
        }
        line = "dvm" + args;
      } else if (is_synopsis(line)) {
        continue;
      }
      const Output o = sh_in(dir, "'" + std::string(DVM_BINARY) + "'" + line.substr(3));
      BOOST_TEST(o.status == 0, o.err);
      ++ran;
    }
  }
  BOOST_TEST(make_runs >= 1);
  BOOST_TEST(ran >= 4);
}

// No documentation file narrates history: what was measured before a change, what a
// figure predates, what the code used to do. Documentation states what is, with the
// figure and the command that produces it; history is in git.
BOOST_AUTO_TEST_CASE(documentation_states_what_is) {
  namespace fs = std::filesystem;
  const std::string root = fs::canonical(repo_file("")).string();
  const std::vector<std::string> phrases = {
      "before this work", "earlier still", "predate",        "the issue's target", "was measured at",
      "no longer",        "previously",    "formerly",       "until recently",     "so far",
      "not regenerated",  "used to",       "issue #",        "after the fix",      "before the fix"};
  // "used to" after these words is the passive ("is used to build"), not history
  const std::vector<std::string> passive = {"is ", "are ", "be ", "been ", "was ", "were "};
  int files = 0;
  std::vector<std::string> found;
  for (const fs::path& file : checkout_files(root)) {
    if (file.extension() != ".md") continue;
    ++files;
    const std::string rel = file.string().substr(root.size() + 1);
    const auto ls = lines_of(slurp(file.string()));
    for (std::size_t i = 0; i < ls.size(); ++i) {
      std::string low = ls[i];
      std::transform(low.begin(), low.end(), low.begin(), [](unsigned char c) { return std::tolower(c); });
      // a whole word or phrase: no letter or digit just before it, nor just after it
      // when it ends in one ("issue #" is followed by a number; "predate" may go on)
      auto alnum = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0; };
      auto starts_word = [&](std::size_t at) { return at == 0 || !alnum(low[at - 1]); };
      auto ends_word = [&](std::size_t end) { return !alnum(low[end - 1]) || end == low.size() || !alnum(low[end]); };
      std::vector<std::string> hits;
      for (const std::string& p : phrases)
        for (std::size_t at = low.find(p); at != std::string::npos; at = low.find(p, at + 1)) {
          if (!starts_word(at) || (p != "predate" && !ends_word(at + p.size()))) continue;
          if (p == "used to" && std::any_of(passive.begin(), passive.end(), [&](const std::string& w) {
                return at >= w.size() && low.compare(at - w.size(), w.size(), w) == 0;
              }))
            continue;
          hits.push_back(p);
          break;
        }
      for (std::size_t at = low.find("now"); at != std::string::npos; at = low.find("now", at + 1))
        if (starts_word(at) && ends_word(at + 3)) {
          hits.push_back("now");
          break;
        }
      for (const std::string& h : hits) found.push_back(rel + ":" + std::to_string(i + 1) + ": \"" + h + "\": " + ls[i]);
    }
  }
  BOOST_TEST(files >= 8);
  std::string report;
  for (const auto& f : found) report += "\n  " + f;
  BOOST_TEST(found.empty(), "history in the documentation:" << report);

  // no issue numbers in code either (the word followed by a number, with or without #)
  std::vector<std::string> numbered;
  int sources = 0;
  for (const fs::path& file : checkout_files(root)) {
    const std::string name = file.filename().string(), ext = file.extension().string();
    if (ext != ".h" && ext != ".cc" && ext != ".txt" && ext != ".cmake" && ext != ".sh" && ext != ".gp" &&
        ext != ".toml" && name != "Makefile")
      continue;
    ++sources;
    const auto ls = lines_of(slurp(file.string()));
    for (std::size_t i = 0; i < ls.size(); ++i) {
      std::string low = ls[i];
      std::transform(low.begin(), low.end(), low.begin(), [](unsigned char c) { return std::tolower(c); });
      for (std::size_t at = low.find("issue"); at != std::string::npos; at = low.find("issue", at + 1)) {
        std::size_t k = at + 5;
        while (k < low.size() && (low[k] == ' ' || low[k] == '#')) ++k;
        if (k > at + 5 && k < low.size() && std::isdigit(static_cast<unsigned char>(low[k])))
          numbered.push_back(file.string().substr(root.size() + 1) + ":" + std::to_string(i + 1) + ": " + ls[i]);
      }
    }
  }
  BOOST_TEST(sources >= 100);
  report.clear();
  for (const auto& f : numbered) report += "\n  " + f;
  BOOST_TEST(numbered.empty(), "issue numbers in the sources:" << report);
}

// What a scene cannot state is said where a new user reads: in the tutorial section,
// beside the first scene of one's own, and first among the known limitations (not
// inside a paragraph on performance).
BOOST_AUTO_TEST_CASE(readme_says_what_a_scene_cannot_state_beside_the_tutorial) {
  const std::string readme = slurp(repo_file("README.md"));
  auto section = [&](const std::string& heading) {
    const auto at = readme.find("\n## " + heading);
    BOOST_REQUIRE_MESSAGE(at != std::string::npos, heading);
    return readme.substr(at, readme.find("\n## ", at + 1) - at);
  };
  const std::string tutorial = section("Five minutes");
  for (const char* w : {"forces", "constraints", "depends on time"})
    BOOST_TEST(tutorial.find(w) != std::string::npos, "the tutorial section does not say: " << w);
  const std::string limits = section("Known limitations");
  const auto first = limits.find("\n- ");
  BOOST_REQUIRE(first != std::string::npos);
  const std::string bullet = limits.substr(first, limits.find("\n- ", first + 1) - first);
  for (const char* w : {"forces", "constraints", "time-dependent"})
    BOOST_TEST(bullet.find(w) != std::string::npos, "the first known limitation does not say: " << w);
}

// Documentation quotes no measured time: a duration (a number and a unit of time) in a
// .md file is a measurement that goes stale with the next change of code or machine.
// Measurements live in generated benchmark output (examples/charts: ratios.md, the
// table_*.md files and the section of its README between the charts markers); a bound
// the code enforces or a target, written "at least N <unit>" or "at most N <unit>", is a
// rule.
BOOST_AUTO_TEST_CASE(documentation_quotes_no_measured_time) {
  namespace fs = std::filesystem;
  const std::string root = fs::canonical(repo_file("")).string();
  // a number, then a unit of time: "N s", "N.M ns", "N minutes" (not the order "2s",
  // nor "s = 4")
  const std::regex duration(R"((^|[^\w.])[0-9]+(\.[0-9]+)?( ?(ns|us|ms)| (s|seconds|min|minutes|hours))([^\w^=]|$))");
  std::vector<std::string> found;
  int files = 0;
  for (const fs::path& file : checkout_files(root)) {
    if (file.extension() != ".md") continue;
    const std::string rel = file.string().substr(root.size() + 1), name = file.filename().string();
    if (rel.rfind("examples/charts/", 0) == 0 && (name == "ratios.md" || name.rfind("table_", 0) == 0)) continue;
    ++files;
    bool generated = false;
    const auto ls = lines_of(slurp(file.string()));
    for (std::size_t i = 0; i < ls.size(); ++i) {
      if (ls[i].find("<!-- charts:begin -->") != std::string::npos) generated = true;
      if (ls[i].find("<!-- charts:end -->") != std::string::npos) generated = false;
      if (generated) continue;
      for (std::sregex_iterator m(ls[i].begin(), ls[i].end(), duration), end; m != end; ++m) {
        const std::string before = ls[i].substr(0, static_cast<std::size_t>(m->position(0) + m->length(1)));
        auto ends_with = [&](const std::string& w) {
          return before.size() >= w.size() && before.compare(before.size() - w.size(), w.size(), w) == 0;
        };
        if (ends_with("at least ") || ends_with("at most ")) continue;
        found.push_back(rel + ":" + std::to_string(i + 1) + ": " + ls[i]);
        break;
      }
    }
  }
  BOOST_TEST(files >= 8);
  std::string report;
  for (const auto& f : found) report += "\n  " + f;
  BOOST_TEST(found.empty(), "measured times in the documentation:" << report);
}

namespace {

// The string value of `key = "value"` in a scene's text ("" if absent).
std::string scene_value(const std::string& text, const std::string& key) {
  for (const std::string& l : lines_of(text)) {
    const std::string t = trim(l);
    if (t.rfind(key, 0) != 0) continue;
    const std::string rest = trim(t.substr(key.size()));
    if (rest.empty() || rest[0] != '=') continue;
    const auto open = rest.find('"');
    if (open == std::string::npos) continue;
    return rest.substr(open + 1, rest.find('"', open + 1) - open - 1);
  }
  return "";
}

}  // namespace

// examples/scenes/README.md has one line per shipped scene and none for a scene that
// does not exist; each line names the scene's system (or "written") and its method:
// the map, the composition, galerkin, the boundary-value problem, as the scene says.
BOOST_AUTO_TEST_CASE(scenes_readme_lists_every_scene) {
  namespace fs = std::filesystem;
  std::map<std::string, std::vector<std::string>> rows;  // file -> cells
  const auto ls = lines_of(slurp(std::string(DVM_SCENES) + "/README.md"));
  for (std::size_t i = 0; i < ls.size(); ++i) {
    if (ls[i].rfind("| `", 0) != 0) continue;
    const std::string file = ls[i].substr(3, ls[i].find('`', 3) - 3);
    BOOST_TEST(rows.count(file) == 0u, "examples/scenes/README.md:" << i + 1 << ": " << file << " listed twice");
    std::vector<std::string> cells;
    std::size_t from = 1;
    for (std::size_t bar; (bar = ls[i].find(" |", from)) != std::string::npos; from = bar + 2)
      cells.push_back(trim(ls[i].substr(from, bar - from)));
    rows[file] = cells;
    BOOST_TEST(fs::exists(std::string(DVM_SCENES) + "/" + file),
               "examples/scenes/README.md:" << i + 1 << ": " << file << " is not a shipped scene");
  }
  int scenes = 0;
  for (const auto& e : fs::directory_iterator(DVM_SCENES)) {
    if (e.path().extension() != ".toml") continue;
    ++scenes;
    const std::string file = e.path().filename().string();
    BOOST_TEST_CONTEXT("examples/scenes/" << file) {
      if (!rows.count(file)) {
        BOOST_TEST(false, "no line in examples/scenes/README.md");
        continue;
      }
      const auto& cells = rows[file];
      BOOST_REQUIRE_EQUAL(cells.size(), 4u);
      const std::string text = slurp(e.path().string());
      const std::string builtin = scene_value(text, "builtin");
      const std::string system = builtin.empty() ? "written" : builtin;
      BOOST_TEST(cells[1].rfind(system, 0) == 0, cells[1] << " does not name " << system);
      for (const char* key : {"map", "composition", "method", "kind"}) {
        std::string v = scene_value(text, key);
        if (v.empty() || v == "none" || v == "initial-value" || (std::string(key) == "method" && v == "map")) continue;
        BOOST_TEST(cells[2].find(v) != std::string::npos, cells[2] << " does not name " << key << " " << v);
      }
      BOOST_TEST(cells[3].size() > 20u);
    }
  }
  BOOST_TEST(scenes >= 20);
  BOOST_TEST(rows.size() == static_cast<std::size_t>(scenes));
}

// The numbers `make charts` generates have one home: the file the Makefile's charts
// target passes to update_readme.sh holds the markers it writes between, and no other
// Markdown file holds them.
BOOST_AUTO_TEST_CASE(chart_numbers_have_one_home) {
  namespace fs = std::filesystem;
  std::string target;
  for (const std::string& l : lines_of(slurp(repo_file("Makefile")))) {
    const auto at = l.find("update_readme.sh ");
    if (at == std::string::npos) continue;
    target = words(l.substr(at))[1];
    const auto var = target.find("$(CHARTS)");
    if (var != std::string::npos) target.replace(var, 9, "examples/charts");
  }
  BOOST_REQUIRE_MESSAGE(!target.empty(), "the Makefile does not run update_readme.sh");
  const std::string text = slurp(repo_file(target));
  BOOST_TEST(text.find("\n<!-- charts:begin -->\n") != std::string::npos, target);
  BOOST_TEST(text.find("\n<!-- charts:end -->\n") != std::string::npos, target);
  const std::string root = fs::canonical(repo_file("")).string();
  for (const fs::path& file : checkout_files(root)) {
    if (file.extension() != ".md" || fs::equivalent(file, repo_file(target))) continue;
    BOOST_TEST(slurp(file.string()).find("<!-- charts:begin -->") == std::string::npos,
               file.string() << " holds the charts markers too");
  }
}

// Every relative link of every Markdown file (`[text](path)`, `![img](path)`) names a
// file or folder that exists.
BOOST_AUTO_TEST_CASE(documentation_links_resolve) {
  namespace fs = std::filesystem;
  const std::string root = fs::canonical(repo_file("")).string();
  int links = 0;
  for (const fs::path& file : checkout_files(root)) {
    if (file.extension() != ".md") continue;
    const auto ls = lines_of(slurp(file.string()));
    for (std::size_t i = 0; i < ls.size(); ++i)
      for (std::size_t at = ls[i].find("]("); at != std::string::npos; at = ls[i].find("](", at + 2)) {
        const auto end = ls[i].find(')', at + 2);
        if (end == std::string::npos) break;
        std::string target = ls[i].substr(at + 2, end - at - 2);
        if (target.find("://") != std::string::npos || target.empty() || target[0] == '#') continue;
        target = target.substr(0, target.find('#'));
        ++links;
        BOOST_TEST(fs::exists(file.parent_path() / target),
                   file.string().substr(root.size() + 1) << ":" << i + 1 << ": " << target << " does not exist");
      }
  }
  BOOST_TEST(links >= 20);
}

// `dvm run --help` documents every scene key the scene reader accepts: for each
// section the reader names (the message for an unknown section), and each key it takes
// there (the message for an unknown key; [initial] on R^n and on SO(3)), the help's
// block for that section has a line "key = ...".
BOOST_AUTO_TEST_CASE(run_help_lists_every_scene_key) {
  const std::string help = dvm({"run", "--help"}).out;
  auto after = [](const std::string& text, const std::string& marker) {
    const auto at = text.find(marker);
    return at == std::string::npos ? std::string() : text.substr(at + marker.size(), text.find('\n', at) - at - marker.size());
  };
  auto split = [](const std::string& list) {
    std::vector<std::string> out;
    std::istringstream in(list);
    for (std::string w; std::getline(in, w, ',');) out.push_back(trim(w));
    return out;
  };
  const Output bad = dvm({"run", scene("pendulum.toml"), "--set", "no_such_section.key=1"});
  BOOST_REQUIRE_EQUAL(bad.status, 2);
  const auto sections = split(after(bad.err, "unknown section; expected "));
  BOOST_REQUIRE_GE(sections.size(), 5u);
  int keys = 0;
  for (const std::string& sec : sections) {
    // the help's block of the section: from "  [sec]" to the next "  [" or blank line
    const auto ls = lines_of(help);
    std::string block;
    for (std::size_t i = 0; i < ls.size(); ++i) {
      if (ls[i].rfind("  [" + sec + "]", 0) != 0) continue;
      block = ls[i] + "\n";
      for (++i; i < ls.size() && ls[i].rfind("  [", 0) != 0 && !trim(ls[i]).empty(); ++i) block += ls[i] + "\n";
      break;
    }
    BOOST_TEST_CONTEXT("[" << sec << "]") {
      BOOST_REQUIRE_MESSAGE(!block.empty(), "no block for the section in dvm run --help");
      for (const char* s : {"pendulum.toml", "rigid-body.toml"}) {
        const Output o = dvm({"run", scene(s), "--set", sec + ".no_such_key=1"});
        BOOST_REQUIRE_EQUAL(o.status, 2);
        const auto taken = split(after(o.err, "[" + sec + "] takes: "));
        BOOST_REQUIRE_MESSAGE(!taken.empty(), o.err);
        for (const std::string& key : taken) {
          ++keys;
          bool found = false;
          for (std::size_t at = block.find(key + " = "); at != std::string::npos && !found;
               at = block.find(key + " = ", at + 1))
            found = at > 0 && (block[at - 1] == ' ' || block[at - 1] == '{');
          BOOST_TEST(found, key << " is not in the [" << sec << "] block of dvm run --help");
        }
      }
    }
  }
  BOOST_TEST(keys >= 33);
}

// The table of what each system runs, at the end of `dvm run --help`: every row's
// fields start under the header's column names, and the written Lagrangian has its
// rows with forces and with constraints on each space that takes them.
BOOST_AUTO_TEST_CASE(run_help_system_table_is_aligned) {
  const auto ls = lines_of(dvm({"run", "--help"}).out);
  std::size_t i = 0;
  while (i < ls.size() && ls[i].rfind("What each system runs", 0) != 0) ++i;
  BOOST_REQUIRE_LT(i + 1, ls.size());
  const std::string header = ls[++i];
  std::vector<std::size_t> at;
  for (const char* c : {"system", "space", "forms", "comp.", "galerkin", "boundary-value"}) {
    at.push_back(header.find(c));
    BOOST_REQUIRE_NE(at.back(), std::string::npos);
  }
  int rows = 0;
  std::set<std::string> written;
  for (++i; i < ls.size() && !trim(ls[i]).empty(); ++i, ++rows) {
    const std::string& r = ls[i];
    BOOST_TEST_CONTEXT(r) {
      for (std::size_t c = 0; c < at.size(); ++c) {
        BOOST_REQUIRE_LT(at[c], r.size());
        BOOST_TEST(r[at[c]] != ' ');                  // a field starts under its name
        BOOST_TEST((at[c] == 0 || r[at[c] - 1] == ' '));  // and not inside another
      }
      for (std::size_t c = 3; c < at.size(); ++c) {
        const std::string v = r.substr(at[c], r.find(' ', at[c]) - at[c]);
        BOOST_TEST((v == "yes" || v == "no"));
      }
    }
    if (r.rfind("  lagrangian, ", 0) == 0) written.insert(trim(r.substr(0, at[2])));
  }
  BOOST_TEST(rows >= 20);
  for (const char* what : {"forces", "constraints"})
    for (const char* space : {"R^n", "S^2", "SO(3)"}) {
      std::string key = std::string("lagrangian, ") + what;
      key += std::string(at[1] - 2 - key.size(), ' ') + space;
      BOOST_TEST(written.count(key) == 1u, key);
    }
}

// Retractions written in the embedding (map = "sphere-written", "so3-written"):
//   - the projection x + v written on S^2 and Cayley's R cay(w) written on SO(3) give
//     the built-in maps' trajectories at theta 0.3, in the lagrangian and hamiltonian forms;
//   - the shipped truncated exponential is of order 2 at theta = 1/2 and 1 at 0.3, and
//     check-map --scene passes on it;
//   - on the spherical chain the written projection acts on each link as
//     sphere-projection-theta does;
//   - texts that break an axiom, have the wrong count or the wrong form, or a missing
//     [map], are refused with exit 2 naming the key.
BOOST_AUTO_TEST_CASE(retractions_written_on_curved_spaces) {
  const std::string S = scene("spherical_pendulum_written_map.toml");
  auto run_q = [](std::vector<std::string> args) {
    args.insert(args.end(), {"--json", "--quiet", "--csv", temp_dir() + "/written_retraction.csv", "--set",
                             "integrator.t_end=0.5"});
    const Output o = dvm(args);
    BOOST_TEST(o.status == 0, o.err);
    return json_array(o.out, "q_final");
  };
  auto close = [](const std::vector<double>& a, const std::vector<double>& b) {
    bool ok = a.size() == b.size() && !a.empty();
    for (std::size_t i = 0; ok && i < a.size(); ++i) ok = std::fabs(a[i] - b[i]) <= 1e-12;
    return ok;
  };
  const std::string proj = "map.retraction=[\"x1 + v1\", \"x2 + v2\", \"x3 + v3\"]";
  for (const char* form : {"integrator.form=\"lagrangian\"", "integrator.form=\"hamiltonian\""}) {
    const auto a = run_q({"run", S, "--set", proj, "--set", "integrator.theta=0.3", "--set", form});
    const auto b = run_q({"run", scene("spherical-pendulum.toml"), "--set", "integrator.map=\"sphere-projection-theta\"",
                          "--set", "integrator.theta=0.3", "--set", "integrator.step=0.005", "--set", form});
    BOOST_TEST(close(a, b), form);
  }
  // SO(3): Cayley's retraction written entry by entry
  std::string cay = "map.retraction=[";
  {
    const std::string W = "(w1^2 + w2^2 + w3^2)", s = "4/(4 + " + W + ")";
    const char* hat[3][3] = {{"0", "-w3", "w2"}, {"w3", "0", "-w1"}, {"-w2", "w1", "0"}};
    const char* w[3] = {"w1", "w2", "w3"};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        cay += (i || j ? ", \"" : "\"");
        for (int k = 0; k < 3; ++k)
          cay += (k ? " + R" : "R") + std::to_string(i + 1) + std::to_string(k + 1) + "*(" + (k == j ? "1" : "0") +
                 " + " + s + "*(" + hat[k][j] + " + (" + w[k] + "*" + w[j] + (k == j ? " - " + W : "") + ")/2))";
        cay += "\"";
      }
    cay += "]";
  }
  const std::string top = scene("heavy-top.toml");
  for (const char* form : {"integrator.form=\"lagrangian\"", "integrator.form=\"hamiltonian\""}) {
    const auto a = run_q({"run", top, "--set", "integrator.map=\"so3-written\"", "--set", cay, "--set",
                          "integrator.theta=0.3", "--set", form});
    const auto b =
        run_q({"run", top, "--set", "integrator.map=\"so3-cayley-theta\"", "--set", "integrator.theta=0.3", "--set", form});
    BOOST_TEST(close(a, b), form);
  }
  for (const char* theta : {"0.5", "0.3"}) {
    const Output o = dvm({"converge", S, "--t-end", "1", "--steps-list", "40,80,160,320", "--json", "--set",
                          std::string("integrator.theta=") + theta});
    BOOST_TEST(o.status == 0, o.err);
    BOOST_TEST(std::fabs(fitted(o) - (std::string(theta) == "0.5" ? 2.0 : 1.0)) <= 0.02, o.out);
  }
  const Output ok = dvm({"check-map", "--scene", S});
  BOOST_TEST(ok.status == 0, ok.out << ok.err);
  BOOST_TEST(parse_json(ok.out).value("passed", false), ok.out);
  // on the spherical chain: the written projection on each link, as sphere-projection-theta
  {
    const std::string chain = scene("spherical-chain.toml");
    const auto a = run_q({"run", chain, "--set", "integrator.map=\"sphere-written\"", "--set", proj, "--set",
                          "integrator.theta=0.3"});
    const auto b = run_q({"run", chain, "--set", "integrator.map=\"sphere-projection-theta\"", "--set",
                          "integrator.theta=0.3"});
    BOOST_TEST(close(a, b));
  }

  struct Refused {
    std::string scene;
    std::vector<std::string> sets;
    const char* key;
    const char* says;
  };
  for (const Refused& r : std::vector<Refused>{
           {S, {"map.retraction=[\"x1 + 2*v1\", \"x2 + 2*v2\", \"x3 + 2*v3\"]"}, "map.retraction", "fails by"},
           {S, {"map.retraction=[\"x1 + v1 + 0.1\", \"x2 + v2\", \"x3 + v3\"]"}, "map.retraction", "R_x(0) = x"},
           {S, {"map.retraction=[\"x1 + v1\", \"x2 + v2\"]"}, "map.retraction", "array of 3 strings"},
           {S, {"map.retraction=[\"x1 + v1\", \"x2 + v2\", \"x3 + u3\"]"}, "map.retraction", "unknown name 'u3'"},
           {S, {"map.q0=\"x - v/2\""}, "map.q0", "written as a retraction"},
           {scene("spherical-pendulum.toml"), {"integrator.map=\"sphere-written\""}, "integrator.map",
            "needs the section [map]"},
           {top, {"integrator.map=\"so3-written\"", proj}, "map.retraction", "array of 9 strings"},
       }) {
    std::vector<std::string> args = {"run", r.scene, "--quiet"};
    for (const std::string& k : r.sets) args.insert(args.end(), {"--set", k});
    const Output o = dvm(args);
    BOOST_TEST_CONTEXT(r.sets[0]) {
      BOOST_TEST(o.status == 2);
      BOOST_TEST(o.err.find("'" + std::string(r.key) + "'") != std::string::npos, o.err);
      BOOST_TEST(o.err.find(r.says) != std::string::npos, o.err);
    }
  }
}

// The help describes the program that runs. converge: the reference its JSON reports
// (Galerkin Gauss s = 6, or kahan-li8 of the midpoint map) and the exclusion it applies
// (10 times the reference's accuracy), not another method or a fixed threshold; run:
// the column count it states for each space is the one the .npy files have.
BOOST_AUTO_TEST_CASE(help_describes_what_the_program_does) {
  const Output c = dvm({"converge", "--help"});
  BOOST_TEST(c.status == 0);
  BOOST_TEST(c.out.find("Runge-Kutta") == std::string::npos, c.out);
  BOOST_TEST(c.out.find("1e-12") == std::string::npos, c.out);
  for (const char* said : {"Galerkin Gauss s = 6", "kahan-li8", "10 times the reference's accuracy", "warnings"})
    BOOST_TEST(c.out.find(said) != std::string::npos, "converge --help does not say '" << said << "'");
  // the references it names are the ones the studies use
  const Output g = dvm({"converge", scene("double_pendulum.toml"), "--t-end", "1", "--steps-list", "20,40", "--json"});
  BOOST_TEST(g.status == 0, g.err);
  BOOST_TEST(json_string(g.out, "reference").rfind("galerkin gauss s=6", 0) == 0, g.out);
  const Output k = dvm({"converge", scene("spherical-chain.toml"), "--t-end", "0.1", "--steps-list", "4,8", "--json"});
  BOOST_TEST(k.status == 0, k.err);
  BOOST_TEST(json_string(k.out, "reference").find("kahan-li8") != std::string::npos, k.out);

  const Output r = dvm({"run", "--help"});
  BOOST_TEST(r.status == 0);
  // the help's words with its line breaks and indentation as single spaces
  std::string words;
  for (char ch : r.out)
    if (!std::isspace(static_cast<unsigned char>(ch)))
      words += ch;
    else if (!words.empty() && words.back() != ' ')
      words += ' ';
  BOOST_TEST(r.out.find("(2n+2)") == std::string::npos);
  BOOST_TEST(r.out.find("[--npy PATH]") != std::string::npos);
  struct Stated {
    const char* scene;
    const char* words;  // what the help says of that system's columns
    long columns;
  };
  for (const Stated& s : {Stated{"spherical-pendulum.toml", "9 for the spherical pendulum", 9},
                          Stated{"heavy-top.toml", "10 for the heavy top", 10},
                          Stated{"rigid-body.toml", "12 for rigid-body", 12},
                          Stated{"kepler.toml", "2n + 2 columns on R^n", 6},
                          Stated{"heavy_top_written.toml", "written ones too: the vertical one, J3", 10}}) {
    BOOST_TEST_CONTEXT(s.scene) {
      BOOST_TEST(words.find(s.words) != std::string::npos);
      const std::string npy = temp_dir() + "/columns.npy";
      const Output o = dvm({"run", scene(s.scene), "--quiet", "--npy", npy, "--csv", temp_dir() + "/columns.csv",
                            "--set", "integrator.t_end=1.0"});
      BOOST_TEST(o.status == 0, o.err);
      const std::string data = slurp(npy);
      const auto shape = data.find("'shape': (");
      BOOST_REQUIRE(shape != std::string::npos);
      BOOST_TEST(std::strtol(data.c_str() + data.find(',', shape) + 1, nullptr, 10) == s.columns);
    }
  }
}

// A study whose runs are not all in the asymptotic range says so: kahan-li8 (order 8)
// on the pendulum to t = 10 with 10, 20 and 40 steps observes orders 12.6 and 8.9 and
// fits 10.8; the warning goes to stderr (text) or "warnings" (JSON). A study in the
// asymptotic range (Kepler to t = 1, orders 8.09 and 8.02) has none. The first row
// has no order: "-" in the table, null in the JSON.
BOOST_AUTO_TEST_CASE(converge_warns_when_the_orders_disagree_with_the_fit) {
  const std::vector<std::string> far = {"converge", scene("pendulum.toml"), "--set", "integrator.composition=kahan-li8",
                                        "--t-end", "10", "--steps-list", "10,20,40"};
  const Output t = dvm(far);
  BOOST_TEST(t.status == 0, t.err);
  BOOST_TEST(t.err.find("warning") != std::string::npos, t.err);
  BOOST_TEST(t.err.find("asymptotic range") != std::string::npos, t.err);
  BOOST_TEST(t.out.find("nan") == std::string::npos, t.out);
  // the first row of the table: steps, h, error, then "-" for the order
  std::istringstream table(t.out);
  std::string line;
  std::getline(table, line);  // the title
  std::getline(table, line);  // the column names
  std::getline(table, line);
  std::istringstream first(line);
  std::string steps, h, error, order;
  first >> steps >> h >> error >> order;
  BOOST_TEST(steps == "10");
  BOOST_TEST(order == "-", line);

  std::vector<std::string> far_json = far;
  far_json.push_back("--json");
  const Output j = dvm(far_json);
  BOOST_TEST(j.status == 0, j.err);
  const Json study = parse_json(j.out);
  BOOST_REQUIRE(study.contains("warnings"));
  BOOST_TEST(study.at("warnings").size() == 1u, j.out);
  BOOST_TEST(study.at("runs").at(0).at("order").is_null());
  BOOST_TEST(j.err.find("warning") == std::string::npos, j.err);

  const Output ok = dvm({"converge", scene("kepler-composition.toml"), "--t-end", "1", "--steps-list", "10,20,40",
                         "--json"});
  BOOST_TEST(ok.status == 0, ok.err);
  const Json good = parse_json(ok.out);
  BOOST_TEST((good.contains("warnings") && good.at("warnings").empty()), ok.out);
  const Output okt = dvm({"converge", scene("kepler-composition.toml"), "--t-end", "1", "--steps-list", "10,20,40"});
  BOOST_TEST(okt.err.find("warning") == std::string::npos, okt.err);
}

BOOST_AUTO_TEST_CASE(solver_iterations_mean_newton_iterations_on_every_path) {
  // The written double pendulum's midpoint step by Newton's method, its Jacobian formed
  // once a step (use_structure, the default) or every iteration: the same equation to the
  // same tolerance, so the same count of iterations to within a few percent, and the
  // Jacobians formed a separate count, equal to the iterations only in the second.
  // (Iterations that meant "Jacobians formed" on one path gave 1 a step against 3.)
  double iterations[2], jacobians[2], steps[2];
  int k = 0;
  for (const char* structure : {"true", "false"}) {
    const Output o = dvm({"run", scene("double_pendulum_written.toml"), "--json", "--quiet", "--set",
                          std::string("integrator.use_structure=") + structure, "--set", "integrator.t_end=10"});
    BOOST_REQUIRE_MESSAGE(o.status == 0, o.err);
    iterations[k] = json_number(o.out, "solver_iterations");
    jacobians[k] = json_number(o.out, "jacobians");
    steps[k] = json_number(o.out, "steps");
    ++k;
  }
  BOOST_TEST(steps[0] == steps[1]);
  BOOST_TEST(iterations[0] >= 2.0 * steps[0]);  // Newton from the extrapolated guess: about 3 a step
  BOOST_TEST(std::fabs(iterations[0] - iterations[1]) <= 0.1 * iterations[1]);
  BOOST_TEST(jacobians[0] <= iterations[0]);
  BOOST_TEST(jacobians[0] < 0.5 * iterations[0]);  // kept within the step
  BOOST_TEST(jacobians[1] == iterations[1]);       // formed every iteration
}

BOOST_AUTO_TEST_CASE(readme_shows_a_work_precision_chart_on_its_first_screens) {
  // Speed against accuracy is what users judge an integrator by: README.md shows one
  // work-precision chart (an image the charts write) within its first 60 lines, with a
  // link to the charts' page.
  const auto ls = lines_of(slurp(repo_file("README.md")));
  std::string image, link;
  for (std::size_t i = 0; i < ls.size() && i < 60; ++i) {
    const auto at = ls[i].find("](examples/charts/wp_");
    if (at != std::string::npos && ls[i].rfind("![", at) != std::string::npos)
      image = ls[i].substr(at + 2, ls[i].find(')', at) - at - 2);
    if (ls[i].find("](examples/charts/README.md)") != std::string::npos) link = ls[i];
  }
  BOOST_REQUIRE_MESSAGE(!image.empty(), "no work-precision image in the first 60 lines of README.md");
  BOOST_TEST(image.size() > 4);
  BOOST_TEST(image.substr(image.size() - 4) == ".png");
  BOOST_TEST(std::filesystem::exists(repo_file(image)), image);
  BOOST_TEST(!link.empty(), "no link to examples/charts/README.md beside it");
}
