// Holonomic constraints over long runs: the four-bar linkage held on its constraint over
// 10^6 steps and against its one-coordinate form, the spherical pendulum in R^3 against
// the S^2 maps with both energies bounded over 10^6 steps, constraints on SO(3) and S^2
// held over 10^6 steps. Not in the sanitized set:
// these runs take seconds in a release build and minutes under the sanitizers, and the
// code they drive is the sanitized test_cli_constraints's.
#define BOOST_TEST_MODULE cli_constraints_long
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "tests/cli/constraint_runs.h"

using namespace cli_test;

// The four-bar linkage: over 10^6 steps (t = 1000 at h = 0.001) the constraint and its
// hidden constraint hold to 1e-12 relative at every step, and the energy error stays bounded (no larger than over the first 10^5 steps);
// composed to order 8 it follows its one-coordinate form (the crank angle at t = 2).
BOOST_AUTO_TEST_CASE(the_four_bar_linkage_stays_closed_and_matches_its_one_coordinate_form) {
  const Json shortrun = run("four_bar.toml", {"integrator.t_end=100.0"});
  const Json longrun = run("four_bar.toml", {"integrator.t_end=1000.0"});
  BOOST_TEST(longrun.at("steps").get<double>() == 1e6);
  BOOST_TEST(longrun.at("max_constraint_residual").get<double>() <= 1e-12);
  BOOST_TEST(longrun.at("max_hidden_constraint_residual").get<double>() <= 1e-12);
  const double e1 = shortrun.at("max_abs_energy_error").get<double>(), e2 = longrun.at("max_abs_energy_error").get<double>();
  BOOST_TEST_MESSAGE("four-bar energy error over 1e5 and 1e6 steps: " << e1 << ", " << e2);
  BOOST_TEST(e2 <= 1.05 * e1);

  const std::vector<std::string> order8 = {"integrator.composition=\"kahan-li8\"", "integrator.step=0.01",
                                           "integrator.t_end=2.0"};
  const Json two = run("four_bar.toml", order8), one = run("four_bar_one_coordinate.toml", order8);
  BOOST_TEST(std::fabs(vec(two, "q_final")[0] - vec(one, "q_final")[0]) <= 1e-9);
  BOOST_TEST(std::fabs(two.at("energy_initial").get<double>() - one.at("energy_initial").get<double>()) <= 1e-12);
}

// The spherical pendulum in R^3 (x^2 + y^2 + z^2 = l^2) and on S^2 (the sphere's
// exponential map) are two discretisations of one motion: their difference at t = 2
// shrinks fourfold as h halves (both of order 2), and each one's energy error is bounded
// over 10^6 steps (no larger than over the first 10^5); J3 is conserved in both, and the
// R^3 twin holds its constraint and hidden constraint to 1e-12 relative at every step.
BOOST_AUTO_TEST_CASE(the_spherical_pendulum_in_r3_follows_the_sphere_maps) {
  std::vector<double> d;
  for (double h : {0.004, 0.002}) {
    const std::vector<std::string> sets = {"integrator.step=" + std::to_string(h), "integrator.t_end=2.0"};
    const Json r3 = run("spherical_pendulum_r3.toml", sets), s2 = run("spherical-pendulum.toml", sets);
    const auto a = vec(r3, "q_final"), b = vec(s2, "q_final");
    double m = 0.0;
    for (int i = 0; i < 3; ++i) m = std::fmax(m, std::fabs(a[static_cast<std::size_t>(i)] - b[static_cast<std::size_t>(i)]));
    d.push_back(m);
  }
  BOOST_TEST_MESSAGE("R^3 against S^2 at t = 2: " << d[0] << ", " << d[1]);
  BOOST_TEST(d[0] <= 1e-3);
  BOOST_TEST(std::fabs(d[0] / d[1] - 4.0) <= 0.4);
  for (const char* s : {"spherical_pendulum_r3.toml", "spherical-pendulum.toml"}) {
    BOOST_TEST_CONTEXT(s) {
      const Json a = run(s, {"integrator.t_end=500.0"}), b = run(s, {"integrator.t_end=5000.0"});
      BOOST_TEST(b.at("steps").get<double>() == 1e6);
      BOOST_TEST(b.at("max_abs_energy_error").get<double>() <= 1.05 * a.at("max_abs_energy_error").get<double>());
      BOOST_TEST(b.at("max_abs_energy_error").get<double>() <= 1e-3);
      for (const auto& inv : b.at("invariants")) BOOST_TEST(inv.at("max_abs_error").get<double>() <= 1e-12);
      if (b.contains("constrained")) {  // the R^3 twin: on its constraint at every step
        BOOST_TEST(b.at("max_constraint_residual").get<double>() <= 1e-12);
        BOOST_TEST(b.at("max_hidden_constraint_residual").get<double>() <= 1e-12);
      }
    }
  }
  const Json r = run("spherical_pendulum_r3.toml", {"integrator.t_end=5.0"});
  BOOST_TEST(r.at("invariants").size() == 1u);
}


// Constraints on SO(3) and S^2 over 10^6 steps: the body on an axle
// (compound_pendulum_so3.toml, two constraints) holds them and their hidden constraint to
// 1e-12 relative at every step, its energy error bounded (no larger than over the first
// 10^5 steps); the bead on the rotating hoop (a constraint in t, energy not conserved)
// holds its constraint likewise over 10^6 steps to t = 500. (A constraint in t is held to
// the round-off of the time it is evaluated at, about |g_t| eps t: Om eps t = 4.4e-13 at
// t = 500, ten times that at t = 5000.)
BOOST_AUTO_TEST_CASE(constraints_on_the_rotation_group_and_the_sphere_hold_over_long_runs) {
  const Json a = run("compound_pendulum_so3.toml", {"integrator.t_end=1000.0"});
  const Json b = run("compound_pendulum_so3.toml", {"integrator.t_end=10000.0"});
  BOOST_TEST(b.at("steps").get<double>() == 1e6);
  BOOST_TEST(b.at("max_constraint_residual").get<double>() <= 1e-12);
  BOOST_TEST(b.at("max_hidden_constraint_residual").get<double>() <= 1e-12);
  const double e1 = a.at("max_abs_energy_error").get<double>(), e2 = b.at("max_abs_energy_error").get<double>();
  BOOST_TEST_MESSAGE("compound pendulum on SO(3), energy error over 1e5 and 1e6 steps: " << e1 << ", " << e2);
  BOOST_TEST(e2 <= 1.05 * e1);
  BOOST_TEST(e2 <= 1e-3);
  const Json h = run("bead_on_rotating_hoop.toml", {"integrator.step=0.0005", "integrator.t_end=500.0"});
  BOOST_TEST(h.at("steps").get<double>() == 1e6);
  BOOST_TEST(h.at("max_constraint_residual").get<double>() <= 1e-12);
  BOOST_TEST(h.at("max_hidden_constraint_residual").get<double>() <= 1e-12);
}
