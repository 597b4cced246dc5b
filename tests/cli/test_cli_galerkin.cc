// End-to-end tests of `[integrator] method = "galerkin"` (issue 9): the shipped scene
// against Kepler's exact solution, built-in and written Lagrangians giving the same
// run, `dvm converge` measuring order 2s, `dvm methods` listing the methods, and bad
// values refused with exit status 2 and a message naming the key.
#define BOOST_TEST_MODULE cli_galerkin
#include <boost/test/unit_test.hpp>

#include "tests/cli/cli_harness.h"

#include <cmath>
#include <string>
#include <vector>

#include "mechanics/systems.h"

namespace {

using namespace cli_test;

// The numbers of a JSON array "key": [a, b, ...].
std::vector<double> json_array(const std::string& json, const std::string& key) {
  std::vector<double> out;
  auto pos = json.find("\"" + key + "\": [");
  if (pos == std::string::npos) return out;
  const char* c = json.c_str() + pos + key.size() + 5;
  while (*c && *c != ']') {
    char* end = nullptr;
    out.push_back(std::strtod(c, &end));
    c = end;
    while (*c == ',' || *c == ' ' || *c == '\n') ++c;
  }
  return out;
}

}  // namespace

BOOST_AUTO_TEST_CASE(kepler_galerkin_scene_matches_the_exact_solution) {
  // order 12 at h = 0.05 over 10 time units: the error is far below the 1e-9 checked
  const Output o = cli_test::dvm({"run", scene("kepler-galerkin.toml"), "--json", "--set", "integrator.t_end=10.0", "--csv",
                        temp_dir() + "/kg.csv"});
  BOOST_TEST_CONTEXT(o.out << o.err) {
    BOOST_TEST(o.status == 0);
    BOOST_TEST(o.out.find("\"method\": \"galerkin\"") != std::string::npos);
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
    BOOST_TEST(json_number(o.out, "max_abs_angular_momentum_error") <= 1e-12);
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
      BOOST_TEST(o.out.find("\"quadrature\": \"lobatto\"") != std::string::npos);
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
  const auto g = j.out.find("\"name\": \"galerkin\"");
  BOOST_REQUIRE(g != std::string::npos);
  BOOST_TEST(json_number(j.out, "order", g) == 2.0);
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
      {{"integrator.method=galerkin"}, "spherical-pendulum.toml", "R^n systems only"},
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
