// End-to-end tests of `[integrator] method = "galerkin"`: the shipped scenes
// against Kepler's exact solution and, on S^2 and SO(3), against an order-8 composition
// of a midpoint map at a small step (with the momentum maps conserved to round-off), built-in and written Lagrangians giving the same
// run, `dvm converge` measuring order 2s, `dvm methods` listing the methods, and bad
// values refused with exit status 2 and a message naming the key.
#define BOOST_TEST_MODULE cli_galerkin
#include <boost/test/unit_test.hpp>

#include "tests/cli/cli_harness.h"
#include "tests/address_sanitizer.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "mechanics/systems.h"

namespace {

using namespace cli_test;

// The numbers of a JSON array "key": [a, b, ...].

}  // namespace

BOOST_AUTO_TEST_CASE(kepler_galerkin_scene_matches_the_exact_solution) {
  // order 12 at h = 0.05 over 10 time units: the error is far below the 1e-9 checked
  const Output o = cli_test::dvm({"run", scene("kepler-galerkin.toml"), "--json", "--set", "integrator.t_end=10.0", "--csv",
                        temp_dir() + "/kg.csv"});
  BOOST_TEST_CONTEXT(o.out << o.err) {
    BOOST_TEST(o.status == 0);
    BOOST_TEST(json_string(o.out, "method") == "galerkin");
    BOOST_TEST(json_number(o.out, "stages") == 6.0);
    BOOST_TEST(json_number(o.out, "order") == 12.0);
    const std::vector<double> q = json_array(o.out, "q_final"), p = json_array(o.out, "p_final");
    BOOST_REQUIRE(q.size() == 2u);
    BOOST_REQUIRE(p.size() == 2u);
    dvm::Vec<double, 2> qe, pe;
    dvm::Kepler(1.0).exact(10.0, dvm::Vec<double, 2>(0.4, 0.0), dvm::Vec<double, 2>(0.0, 2.0), qe, pe);
    for (int i = 0; i < 2; ++i) {
      BOOST_TEST(std::fabs(q[i] - qe[i]) <= 1e-9);
      BOOST_TEST(std::fabs(p[i] - pe[i]) <= 1e-9);
    }
    BOOST_TEST(json_number(o.out, "max_abs_energy_error") <= 1e-10);
    BOOST_TEST(invariant_error(o.out, "angular momentum") <= 1e-12);
  }
}

BOOST_AUTO_TEST_CASE(written_lagrangian_runs_the_same_galerkin_method) {
  std::vector<double> finals[2];
  int k = 0;
  for (const char* s : {"pendulum.toml", "pendulum_written.toml"}) {
    const Output o = cli_test::dvm({"run", scene(s), "--json", "--set", "integrator.method=galerkin", "--set",
                          "integrator.stages=3", "--set", "integrator.quadrature=lobatto", "--set",
                          "integrator.t_end=5.0", "--set", "integrator.step=0.1", "--csv",
                          temp_dir() + "/pw.csv"});
    BOOST_TEST_CONTEXT(s << "\n" << o.out << o.err) {
      BOOST_TEST(o.status == 0);
      BOOST_TEST(json_string(o.out, "quadrature") == "lobatto");
    }
    finals[k] = json_array(o.out, "q_final");
    const std::vector<double> p = json_array(o.out, "p_final");
    finals[k].insert(finals[k].end(), p.begin(), p.end());
    ++k;
  }
  BOOST_REQUIRE(finals[0].size() == 2u);
  BOOST_REQUIRE(finals[1].size() == 2u);
  for (int i = 0; i < 2; ++i) BOOST_TEST(std::fabs(finals[0][i] - finals[1][i]) <= 1e-12);
}

BOOST_AUTO_TEST_CASE(converge_measures_order_2s) {
  for (int s : {1, 2, 3}) {
    const Output o = cli_test::dvm({"converge", scene("kepler-galerkin.toml"), "--json", "--t-end", "1", "--steps-list",
                          s == 1 ? "40,80,160,320" : (s == 2 ? "10,20,40,80" : "6,12,24,48"), "--set",
                          "integrator.stages=" + std::to_string(s)});
    BOOST_TEST_CONTEXT("s=" << s << "\n" << o.out << o.err) {
      BOOST_TEST(o.status == 0);
      BOOST_TEST(json_number(o.out, "map_order") == 2.0 * s);
      BOOST_TEST(std::fabs(json_number(o.out, "fitted_order") - 2.0 * s) <= 0.3);
    }
  }
}

BOOST_AUTO_TEST_CASE(methods_lists_the_galerkin_methods) {
  const Output t = cli_test::dvm({"methods"});
  BOOST_TEST(t.status == 0);
  BOOST_TEST(t.out.find("method = \"galerkin\"") != std::string::npos);
  BOOST_TEST(t.out.find("\ngauss      6      6      12") != std::string::npos, t.out);
  BOOST_TEST(t.out.find("\nlobatto    6      7      12") != std::string::npos, t.out);
  const Output j = cli_test::dvm({"methods", "--json"});
  BOOST_TEST(j.status == 0);
  // the first Galerkin entry of the array of methods (Gauss, s = 1): order 2
  const Json methods = parse_json(j.out);
  const auto g = std::find_if(methods.begin(), methods.end(),
                              [](const Json& e) { return e.value("name", "") == "galerkin"; });
  BOOST_REQUIRE(g != methods.end());
  BOOST_TEST(json_double(g->at("order")) == 2.0);
}

BOOST_AUTO_TEST_CASE(bad_galerkin_values_are_refused_with_status_2) {
  struct Case {
    std::vector<std::string> sets;
    std::string scene, needle;
  };
  const std::vector<Case> cases = {
      {{"integrator.stages=7"}, "kepler-galerkin.toml", "integrator.stages"},
      {{"integrator.stages=0"}, "kepler-galerkin.toml", "integrator.stages"},
      {{"integrator.stages=2.5"}, "kepler-galerkin.toml", "integrator.stages"},
      {{"integrator.quadrature=radau"}, "kepler-galerkin.toml", "integrator.quadrature"},
      {{"integrator.method=collocation"}, "kepler-galerkin.toml", "integrator.method"},
      {{"integrator.stages=3"}, "kepler.toml", "applies only to method = \"galerkin\""},
      {{"integrator.quadrature=gauss"}, "kepler.toml", "applies only to method = \"galerkin\""},
      {{"integrator.form=hamiltonian", "integrator.map=midpoint"}, "kepler-galerkin.toml", "lagrangian form only"},
      {{"integrator.composition=triple-jump", "integrator.map=midpoint"}, "kepler-galerkin.toml", "no composition"},
      // on curved spaces: the chain, other forms, compositions (S^2 and SO(3))
      {{"integrator.method=galerkin"}, "spherical-chain.toml", "spherical-chain takes no method = \"galerkin\""},
      {{"integrator.form=hamiltonian"}, "spherical-pendulum-galerkin.toml", "lagrangian form only"},
      {{"integrator.form=hamiltonian", "integrator.method=galerkin"}, "rigid-body.toml", "lagrangian form only"},
      {{"integrator.composition=kahan-li8", "integrator.map=sphere-exp"}, "spherical-pendulum-galerkin.toml",
       "no composition"},
      {{"integrator.stages=7"}, "spherical-pendulum-galerkin.toml", "integrator.stages"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args = {"run", scene(c.scene)};
    for (const auto& s : c.sets) args.insert(args.end(), {"--set", s});
    const Output o = cli_test::dvm(args);
    BOOST_TEST_CONTEXT(c.scene << " " << c.sets.front() << ": " << o.err) {
      BOOST_TEST(o.status == 2);
      BOOST_TEST(o.err.find(c.needle) != std::string::npos);
      BOOST_TEST(o.out.empty());
    }
  }
}

// (q_final, p_final) of a JSON report, one vector.
std::vector<double> final_state(const std::string& json) {
  std::vector<double> x = json_array(json, "q_final");
  const std::vector<double> p = json_array(json, "p_final");
  x.insert(x.end(), p.begin(), p.end());
  return x;
}

// A run of `scene` with the settings, JSON report; requires status 0.
std::string run_json(const std::string& name, const std::vector<std::string>& sets) {
  std::vector<std::string> args = {"run", scene(name), "--json", "--csv", temp_dir() + "/m.csv"};
  for (const auto& s : sets) args.insert(args.end(), {"--set", s});
  const Output o = cli_test::dvm(args);
  BOOST_TEST_REQUIRE(o.status == 0, name << ": " << o.out << o.err);
  return o.out;
}

BOOST_AUTO_TEST_CASE(galerkin_on_the_sphere_matches_an_order_8_composition) {
  // the shipped scene (s = 4, order 8, h = 0.05) to t = 5 against kahan-li8 of the
  // midpoint exp map at h = 0.005; J3 conserved to round-off, |x| = 1 to round-off
  const std::string g = run_json("spherical-pendulum-galerkin.toml", {"integrator.t_end=5.0"});
  BOOST_TEST(json_string(g, "method") == "galerkin");
  BOOST_TEST(json_string(g, "map") == "none");
  BOOST_TEST(json_number(g, "stages") == 4.0);
  BOOST_TEST(json_number(g, "order") == 8.0);
  BOOST_TEST(json_number(g, "max_point_defect") <= 1e-15);
  BOOST_TEST(invariant_error(g, "vertical angular momentum") <= 1e-13);
  BOOST_TEST(json_number(g, "max_abs_energy_error") <= 1e-6);
  const std::string r = run_json("spherical-pendulum.toml", {"integrator.t_end=5.0", "integrator.step=0.005",
                                                             "integrator.composition=kahan-li8"});
  const std::vector<double> a = final_state(g), b = final_state(r);
  BOOST_REQUIRE(a.size() == 6u);
  BOOST_REQUIRE(b.size() == 6u);
  double d = 0.0;
  for (int i = 0; i < 6; ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
  BOOST_TEST_MESSAGE("spherical pendulum, galerkin s = 4 h = 0.05 vs kahan-li8 h = 0.005 at t = 5: " << d);
  BOOST_TEST(d <= 1e-7);
  // the CSV has the columns of the other S^2 runs
  std::ifstream csv(temp_dir() + "/m.csv");
  std::string header;
  std::getline(csv, header);
  BOOST_TEST(header == "t,x,y,z,p_x,p_y,p_z,energy,J3");
}

// The heavy top, s = 3 Gauss and s = 2 Lobatto (order 6 and 4), against kahan-li8 of the
// midpoint exp map; the free rigid body's spatial angular momentum to round-off. The
// reference (1000 steps of 15 substeps on SO(3)) takes most of this suite's time under
// AddressSanitizer, where the steps on SO(3) run more than an order of magnitude slower;
// the sanitized suites run every Galerkin method on SO(3) in test_cli_combinations, so
// this accuracy study adds no path the sanitizers would check (tests/README.md).
BOOST_AUTO_TEST_CASE(galerkin_on_so3_matches_an_order_8_composition,
                     *boost::unit_test::enable_if<!dvm_tests::kAddressSanitizer>()) {
  const std::string r = run_json("heavy-top.toml", {"integrator.t_end=2.0", "integrator.step=0.002",
                                                    "integrator.composition=kahan-li8"});
  struct Case {
    std::string stages, quadrature;
    double tolerance;
  };
  for (const Case& c : {Case{"3", "gauss", 1e-8}, Case{"2", "lobatto", 1e-6}}) {
    const std::string g =
        run_json("heavy-top.toml", {"integrator.t_end=2.0", "integrator.step=0.01", "integrator.method=galerkin",
                                    "integrator.stages=" + c.stages, "integrator.quadrature=" + c.quadrature});
    BOOST_TEST_CONTEXT(c.quadrature << " s=" << c.stages) {
      BOOST_TEST(json_string(g, "quadrature") == c.quadrature);
      BOOST_TEST(json_number(g, "max_point_defect") <= 1e-14);
      BOOST_TEST(invariant_error(g, "vertical angular momentum") <= 1e-13);
      const std::vector<double> a = final_state(g), b = final_state(r);
      BOOST_REQUIRE(a.size() == 7u);
      BOOST_REQUIRE(b.size() == 7u);
      double d = 0.0;
      for (int i = 0; i < 7; ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
      BOOST_TEST_MESSAGE("heavy top, galerkin " << c.quadrature << " s = " << c.stages
                                                << " h = 0.01 vs kahan-li8 h = 0.002 at t = 2: " << d);
      BOOST_TEST(d <= c.tolerance);
    }
  }
  const std::string b = run_json("rigid-body.toml", {"integrator.t_end=20.0", "integrator.step=0.05",
                                                     "integrator.method=galerkin", "integrator.stages=2"});
  BOOST_TEST(invariant_error(b, "spatial angular momentum") <= 1e-13);
  BOOST_TEST(json_number(b, "max_abs_energy_error") <= 1e-6);
}
