// Holonomic constraints end to end ([system] constraints, solvers/constrained_step.h):
// the Cartesian pendulum and double pendulum against their angle twins, orders measured
// by `dvm converge`, a constraint with forces, the projection of an initial velocity,
// the constrained steps' Jacobians; every bad input and every combination the
// constrained step does not take refused with exit 2, naming the keys, nothing written;
// Lagrangians that depend on time (Kapitza's pendulum, a damping Lagrangian against a
// damping force); forces on S^2 and SO(3); constraints on S^2 and SO(3) against the
// systems they reduce to, and their orders; Galerkin with forces on S^2 and SO(3). The
// long runs (10^6 steps) are in test_cli_constraints_long.cc.
#define BOOST_TEST_MODULE cli_constraints
#include <boost/test/unit_test.hpp>

#include <Eigen/Core>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "tests/address_sanitizer.h"
#include "tests/cli/constraint_runs.h"

using namespace cli_test;

// The pendulum in (x, y) with x^2 + y^2 = l^2 against the built-in pendulum in its angle
// q: at t = 10, composed to order 8 (kahan-li8) with h = 0.01, x = l sin q and
// y = -l cos q to 1e-10, and the momenta (p_x, p_y) = m l p_q / (m l^2) (cos q, sin q).
// The same for the double pendulum, two constraints, against the built-in one: the
// positions, and the momenta pulled back to the angles.
BOOST_AUTO_TEST_CASE(cartesian_pendulums_agree_with_their_angle_twins) {
  const std::vector<std::string> order8 = {"integrator.composition=\"kahan-li8\"", "integrator.t_end=10.0"};
  const Json c = run("pendulum_cartesian.toml", order8), a = run("pendulum.toml", order8);
  const double q = vec(a, "q_final")[0], pq = vec(a, "p_final")[0];
  const auto xy = vec(c, "q_final"), pxy = vec(c, "p_final");
  BOOST_TEST(std::fabs(xy[0] - std::sin(q)) <= 1e-10);
  BOOST_TEST(std::fabs(xy[1] + std::cos(q)) <= 1e-10);
  BOOST_TEST(std::fabs(pxy[0] - pq * std::cos(q)) <= 1e-10);
  BOOST_TEST(std::fabs(pxy[1] - pq * std::sin(q)) <= 1e-10);
  BOOST_TEST(c.at("constrained").get<bool>());
  BOOST_TEST(c.at("constraints").get<int>() == 1);
  BOOST_TEST(c.at("max_constraint_residual").get<double>() <= 1e-14);
  BOOST_TEST(c.at("max_hidden_constraint_residual").get<double>() <= 1e-13);
  // x is not cyclic: the constraint involves it, so p_x is not reported as conserved
  BOOST_TEST((!c.contains("invariants") || c.at("invariants").empty()));

  const Json d = run("double_pendulum_cartesian.toml", order8), b = run("double_pendulum.toml", order8);
  const auto ab = vec(b, "q_final"), xy2 = vec(d, "q_final");
  const double x1 = std::sin(ab[0]), y1 = -std::cos(ab[0]);
  BOOST_TEST_MESSAGE("double pendulum, Cartesian against angles at t = 10: " << std::fabs(xy2[0] - x1) << " "
                                                                             << std::fabs(xy2[3] - (y1 - std::cos(ab[1]))));
  BOOST_TEST(std::fabs(xy2[0] - x1) <= 1e-10);
  BOOST_TEST(std::fabs(xy2[1] - y1) <= 1e-10);
  BOOST_TEST(std::fabs(xy2[2] - (x1 + std::sin(ab[1]))) <= 1e-10);
  BOOST_TEST(std::fabs(xy2[3] - (y1 - std::cos(ab[1]))) <= 1e-10);
  // the momenta pulled back along (a, b) -> (x1, y1, x2, y2) (unit rods) are the angles'
  const auto p4 = vec(d, "p_final"), pab = vec(b, "p_final");
  const double pa = (p4[0] + p4[2]) * std::cos(ab[0]) + (p4[1] + p4[3]) * std::sin(ab[0]);
  const double pb = p4[2] * std::cos(ab[1]) + p4[3] * std::sin(ab[1]);
  BOOST_TEST_MESSAGE("double pendulum, pulled-back momenta against the angles': " << std::fabs(pa - pab[0]) << " "
                                                                                  << std::fabs(pb - pab[1]));
  BOOST_TEST(std::fabs(pa - pab[0]) <= 1e-10 * std::fmax(1.0, std::fabs(pab[0])));
  BOOST_TEST(std::fabs(pb - pab[1]) <= 1e-10 * std::fmax(1.0, std::fabs(pab[1])));
  BOOST_TEST(d.at("constraints").get<int>() == 2);
  BOOST_TEST(std::fabs(d.at("energy_initial").get<double>() - b.at("energy_initial").get<double>()) <= 1e-15);
}

// The scissor lift in nine coordinates and eight constraints against its one-coordinate
// twin (scissor_lift_one_coordinate.toml), kahan-li8 to t = 1: every left link at th,
// every right one at pi - th, the slider at L cos(th), to 1e-10; the momenta pulled back
// along that embedding give the twin's p_th = -L sin(th) p_s + sum p_a - sum p_b.
BOOST_AUTO_TEST_CASE(the_scissor_lift_agrees_with_its_one_coordinate_twin) {
  const std::vector<std::string> order8 = {"integrator.composition=\"kahan-li8\""};
  const Json c = run("scissor_lift.toml", order8), a = run("scissor_lift_one_coordinate.toml", order8);
  const double th = vec(a, "q_final")[0], pth = vec(a, "p_final")[0], L = 5.0;
  const auto q = vec(c, "q_final"), p = vec(c, "p_final");
  BOOST_TEST_REQUIRE(q.size() == 9u);
  BOOST_TEST(th > 0.5);  // the lift has opened from 0.05 pi
  BOOST_TEST(std::fabs(q[0] - L * std::cos(th)) <= 1e-10);
  double pulled = -L * std::sin(th) * p[0];
  for (int k = 1; k <= 4; ++k) {
    BOOST_TEST(std::fabs(q[k] - th) <= 1e-10, "a" << k - 1);
    BOOST_TEST(std::fabs(q[4 + k] - (M_PI - th)) <= 1e-10, "b" << k - 1);
    pulled += p[k] - p[4 + k];
  }
  BOOST_TEST_MESSAGE("scissor lift, nine coordinates against one at t = 1: slider "
                     << std::fabs(q[0] - L * std::cos(th)) << ", p_th " << std::fabs(pulled - pth));
  BOOST_TEST(std::fabs(pulled - pth) <= 1e-9 * std::fabs(pth));
  BOOST_TEST(c.at("constraints").get<int>() == 8);
  BOOST_TEST(c.at("max_constraint_residual").get<double>() <= 1e-13);
  BOOST_TEST(c.at("max_hidden_constraint_residual").get<double>() <= 1e-12);
  BOOST_TEST(std::fabs(c.at("energy_initial").get<double>() - a.at("energy_initial").get<double>()) <= 1e-12);
  // the text's velocities are definitions: its derivatives still come from a program
  BOOST_TEST(c.at("derivatives").get<std::string>() == "program");
}

// `dvm converge` measures the orders of the constrained steps (its reference: Lobatto
// Galerkin s = 6 under the constraints, order 12): 2 for the midpoint, 4 for the triple
// jump, 8 for kahan-li8; Lobatto Galerkin 2s for s = 1, 2, 3 (the constraints at its
// nodes); with forces (the slider-crank) 2 and 4, and Galerkin 4 and 6; the four-bar
// linkage and the scissor lift (eight constraints) 2 and Galerkin 4; a support that
// moves (a constraint in t), Galerkin 4 and 6.
BOOST_AUTO_TEST_CASE(converge_measures_the_orders_under_constraints_and_forces) {
  struct Case {
    const char* scene;
    std::string method, steps;  // a composition, or "lobatto:s"
    double order;
  };
  const std::vector<Case> cases = {
      {"pendulum_cartesian.toml", "none", "40,80,160,320", 2.0},
      {"pendulum_cartesian.toml", "triple-jump:4", "20,40,80,160", 4.0},
      {"pendulum_cartesian.toml", "kahan-li8", "5,10,20", 8.0},
      {"pendulum_cartesian.toml", "lobatto:1", "10,20,40,80", 2.0},
      {"pendulum_cartesian.toml", "lobatto:2", "10,20,40,80", 4.0},
      {"pendulum_cartesian.toml", "lobatto:3", "4,8,16,32", 6.0},
      {"four_bar.toml", "none", "40,80,160,320", 2.0},
      {"four_bar.toml", "lobatto:2", "20,40,80,160", 4.0},
      {"slider_crank.toml", "none", "40,80,160,320", 2.0},
      {"slider_crank.toml", "triple-jump:4", "20,40,80,160", 4.0},
      {"slider_crank.toml", "lobatto:2", "20,40,80,160", 4.0},
      {"slider_crank.toml", "lobatto:3", "10,20,40,80", 6.0},
      {"scissor_lift.toml", "lobatto:2", "10,20,40,80", 4.0},
      {"moving support", "lobatto:2", "10,20,40,80", 4.0},
      {"moving support", "lobatto:3", "10,20,40,80", 6.0},
  };
  // a pendulum whose support moves, y_s = A cos(w t): a constraint in t, held by Galerkin
  // at the nodes' times
  const std::string moving = write_scene(
      "moving_support.toml",
      "[system]\ncoordinates = [\"x\", \"y\"]\nparams = { m = 1.3, l = 0.9, g = 9.81, A = 0.2, w = 2.5 }\n"
      "lagrangian = \"m*(x_dot^2 + y_dot^2)/2 - m*g*y\"\nconstraints = [\"x^2 + (y - A*cos(w*t))^2 - l^2\"]\n"
      "[initial]\nq = [0.579795918513922, -0.4883579685560397]\nv = [0.0, 0.0]\n"
      "[integrator]\nmap = \"midpoint\"\nstep = 0.01\nt_end = 1.0\n");
  for (const Case& c : cases) {
    BOOST_TEST_CONTEXT(c.scene << ", " << c.method) {
      const std::string path = std::string(c.scene) == "moving support" ? moving : scene(c.scene);
      std::vector<std::string> args = {"converge", path, "--t-end", "1", "--steps-list", c.steps, "--json"};
      if (c.method.rfind("lobatto:", 0) == 0)
        args.insert(args.end(), {"--set", "integrator.method=\"galerkin\"", "--set", "integrator.quadrature=\"lobatto\"",
                                 "--set", "integrator.stages=" + c.method.substr(8)});
      else
        args.insert(args.end(), {"--set", "integrator.composition=\"" + c.method + "\""});
      const Output o = dvm(args);
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      const double order = parse_json(o.out).at("fitted_order").get<double>();
      BOOST_TEST_MESSAGE(c.scene << " " << c.method << ": " << order);
      BOOST_TEST(std::fabs(order - c.order) <= 0.1 * c.order, o.out);
    }
  }
}

// Constraints and forces together (the slider-crank): the constraint holds, the work
// and the energy balance are reported, and E - E_0 - W stays at the method's O(h^2)
// (a quarter at half the step), the constraint forces doing no work.
BOOST_AUTO_TEST_CASE(constraints_and_forces_together) {
  const Json a = run("slider_crank.toml", {"integrator.t_end=5.0"});
  const Json b = run("slider_crank.toml", {"integrator.t_end=5.0", "integrator.step=0.0005"});
  BOOST_TEST(a.at("forced").get<bool>());
  BOOST_TEST(a.at("constrained").get<bool>());
  BOOST_TEST(a.at("work").get<double>() > 0.0);  // the torque does more work than the friction takes
  BOOST_TEST(a.at("max_constraint_residual").get<double>() <= 1e-14);
  const double b1 = a.at("max_abs_energy_balance").get<double>(), b2 = b.at("max_abs_energy_balance").get<double>();
  BOOST_TEST_MESSAGE("slider-crank energy balance at h and h/2: " << b1 << ", " << b2);
  BOOST_TEST(std::fabs(b1 / b2 - 4.0) <= 0.4);
}

// initial.project_velocity: a velocity with a part across the rod is refused, or with
// the key the part is removed: the run then starts from the tangential velocity.
BOOST_AUTO_TEST_CASE(an_initial_velocity_off_the_constraint_is_refused_or_projected) {
  // at (x, y) = (0.6, -0.8) the tangent is (0.8, 0.6): v = 0.5 (0.8, 0.6) + 0.3 (0.6, -0.8)
  const std::vector<std::string> state = {"initial.q=[0.6, -0.8]", "integrator.t_end=1.0"};
  auto sets = state;
  sets.push_back("initial.v=[0.58, 0.06]");
  const Output r = dvm(with_sets({"run", scene("pendulum_cartesian.toml"), "--no-output"}, sets));
  BOOST_TEST(r.status == 2);
  BOOST_TEST(r.err.find("initial.v") != std::string::npos, r.err);
  BOOST_TEST(r.err.find("system.constraints[1]") != std::string::npos, r.err);
  BOOST_TEST(r.err.find("initial.project_velocity") != std::string::npos, r.err);
  sets.push_back("initial.project_velocity=true");
  const Json p = run("pendulum_cartesian.toml", sets);
  auto tangential = state;
  tangential.push_back("initial.v=[0.4, 0.3]");
  const Json t = run("pendulum_cartesian.toml", tangential);
  const auto a = vec(p, "p_initial"), b = vec(t, "p_initial");
  BOOST_TEST(std::fabs(a[0] - b[0]) <= 1e-15);
  BOOST_TEST(std::fabs(a[1] - b[1]) <= 1e-15);
  BOOST_TEST(std::fabs(vec(p, "q_final")[0] - vec(t, "q_final")[0]) <= 1e-14);
}

// A Lagrangian L(t, q, v) (t read in system.lagrangian). Kapitza's pendulum
// (kapitza_pendulum.toml): started 0.3 from upright on a pivot shaken fast enough, it
// stays within 0.3 of upright to t = 20; unshaken (a = 0) it falls. Its twin in
// Cartesian coordinates on the moving pivot (a constraint in t, L free of t) gives the
// same trajectory to 1e-10 at t = 10 with kahan-li8. The report says the energy is not
// conserved.
BOOST_AUTO_TEST_CASE(a_lagrangian_in_t_keeps_kapitzas_pendulum_upright) {
  auto digits17 = [](double x) {
    std::ostringstream s;
    s.precision(17);
    s << x;
    return s.str();
  };
  const std::string csv = temp_dir() + "/kapitza.csv";
  // the largest |th - pi| of the rows of a run to t = 20
  auto swing = [&](const std::vector<std::string>& sets) {
    std::vector<std::string> all = {"integrator.t_end=20.0"};
    all.insert(all.end(), sets.begin(), sets.end());
    const Output o = dvm(with_sets({"run", scene("kapitza_pendulum.toml"), "--csv", csv, "--quiet"}, all));
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    std::ifstream in(csv);
    std::string line;
    std::getline(in, line);
    BOOST_TEST_REQUIRE(line.rfind("t,th,p_th,energy", 0) == 0, line);
    double worst = 0.0;
    int rows = 0;
    while (std::getline(in, line)) {
      const double th = std::stod(line.substr(line.find(',') + 1));
      worst = std::fmax(worst, std::fabs(th - M_PI));
      ++rows;
    }
    BOOST_TEST(rows == 2001);  // t = 0, 0.01, ..., 20
    return worst;
  };
  const double shaken = swing({}), still = swing({"system.params.a=0.0"});
  BOOST_TEST_MESSAGE("Kapitza pendulum: largest |th - pi| to t = 20 shaken " << shaken << ", still " << still);
  BOOST_TEST(shaken <= 0.3 + 1e-9);
  BOOST_TEST(still > 2.0);

  const std::vector<std::string> order8 = {"integrator.composition=\"kahan-li8\"", "integrator.t_end=10.0"};
  const Json a = run("kapitza_pendulum.toml", order8);
  BOOST_TEST(a.at("time_dependent").get<bool>());
  BOOST_TEST(a.at("max_abs_energy_error").get<double>() > 0.1);  // not conserved
  const double th0 = M_PI - 0.3, A = 0.05, w = 40.0;
  auto cartesian = order8;
  for (const std::string& k :
       {std::string("system.params={ m = 1.0, l = 1.0, g = 1.0, a = 0.05, w = 40.0 }"),
        std::string("system.constraints=[\"x^2 + (y - a*cos(w*t))^2 - l^2\"]"),
        "initial.q=[" + digits17(std::sin(th0)) + ", " + digits17(A - std::cos(th0)) + "]",
        std::string("integrator.step=0.001")})
    cartesian.push_back(k);
  const Json c = run("pendulum_cartesian.toml", cartesian);
  BOOST_TEST(!c.contains("time_dependent"));  // (its L does not read t; its constraint does)
  const double th = vec(a, "q_final")[0], T = 10.0;
  const auto xy = vec(c, "q_final");
  BOOST_TEST_MESSAGE("Kapitza pendulum, Cartesian against angle at t = 10: " << std::fabs(xy[0] - std::sin(th)) << " "
                                                                            << std::fabs(xy[1] - (A * std::cos(w * T) - std::cos(th))));
  BOOST_TEST(std::fabs(xy[0] - std::sin(th)) <= 1e-10);
  BOOST_TEST(std::fabs(xy[1] - (A * std::cos(w * T) - std::cos(th))) <= 1e-10);

  const Output text = dvm({"run", scene("kapitza_pendulum.toml"), "--no-output", "--set", "integrator.t_end=0.1"});
  BOOST_TEST(text.status == 0);
  BOOST_TEST(text.out.find("the Lagrangian depends on t: the energy is not conserved") != std::string::npos, text.out);
}

// The damped oscillator as the Caldirola-Kanai Lagrangian exp(c t / m) (m x_dot^2 - k
// x^2) / 2, its L in t, against the same oscillator damped by a force
// (damped_oscillator.toml): at t = 10, composed to order 8, the same x to 1e-10 (the
// momenta differ by the factor exp(c t / m)); `dvm converge` measures 2 for the
// midpoint, 4 for the triple jump and for Galerkin with 2 stages, 6 with 3. And the
// Cartesian pendulum with exp(c t) L, constrained to its circle, is the angle pendulum
// damped by the force -c th_dot (the constrained step, and its projection, at the
// times of L).
BOOST_AUTO_TEST_CASE(a_lagrangian_in_t_damps_as_a_force_does) {
  const std::string ck = write_scene("caldirola_kanai.toml",
                                     "[system]\ncoordinates = [\"x\"]\nparams = { m = 1.0, k = 1.0, c = 0.1 }\n"
                                     "lagrangian = \"exp(c*t/m)*(0.5*m*x_dot^2 - 0.5*k*x^2)\"\n"
                                     "[initial]\nq = [1.0]\nv = [0.0]\n[integrator]\nmap = \"midpoint\"\n"
                                     "step = 0.05\nt_end = 10.0\n");
  const std::vector<std::string> order8 = {"integrator.composition=\"kahan-li8\"", "integrator.t_end=10.0"};
  const Output o = dvm(with_sets({"run", ck, "--json"}, order8));
  BOOST_TEST_REQUIRE(o.status == 0, o.err);
  const Json k = parse_json(o.out), f = run("damped_oscillator.toml", order8);
  BOOST_TEST(std::fabs(vec(k, "q_final")[0] - vec(f, "q_final")[0]) <= 1e-10);
  BOOST_TEST(std::fabs(vec(k, "p_final")[0] - std::exp(0.1 * 10.0) * vec(f, "p_final")[0]) <= 1e-10);
  struct Case {
    std::vector<std::string> sets;
    std::string steps;
    double order;
  };
  const std::vector<Case> cases = {
      {{"integrator.composition=\"none\""}, "40,80,160,320", 2.0},
      {{"integrator.composition=\"triple-jump:4\""}, "20,40,80,160", 4.0},
      {{"integrator.method=\"galerkin\"", "integrator.stages=2"}, "20,40,80,160", 4.0},
      {{"integrator.method=\"galerkin\"", "integrator.stages=3"}, "25,50,100,200", 6.0},
  };
  for (const Case& c : cases) {
    BOOST_TEST_CONTEXT(c.sets.back()) {
      const Output r = dvm(with_sets({"converge", ck, "--steps-list", c.steps, "--json"}, c.sets));
      BOOST_TEST_REQUIRE(r.status == 0, r.err);
      const double order = parse_json(r.out).at("fitted_order").get<double>();
      BOOST_TEST_MESSAGE("Caldirola-Kanai " << c.sets.back() << ": " << order);
      BOOST_TEST(std::fabs(order - c.order) <= 0.05 * c.order, r.out);
    }
  }
  // the damped pendulum from th = 2 at rest: exp(c t) ((x_dot^2 + y_dot^2) / 2 - y) on the
  // unit circle, and th_dot^2 / 2 + cos th with the force -c th_dot
  const Json x = run("pendulum_cartesian.toml", {"system.params={ c = 0.3 }",
                                                 "system.lagrangian=\"exp(c*t)*((x_dot^2 + y_dot^2)/2 - y)\"",
                                                 "system.constraints=[\"x^2 + y^2 - 1\"]", order8[0], order8[1]});
  const Json t = run("damped_oscillator.toml", {"system.coordinates=[\"th\"]", "system.params={ c = 0.3 }",
                                                "system.lagrangian=\"th_dot^2/2 + cos(th)\"",
                                                "system.forces={ th = \"-c*th_dot\" }", "initial.q=[2.0]", order8[0],
                                                order8[1]});
  const double th = vec(t, "q_final")[0];
  BOOST_TEST(std::fabs(vec(x, "q_final")[0] - std::sin(th)) <= 1e-10);
  BOOST_TEST(std::fabs(vec(x, "q_final")[1] + std::cos(th)) <= 1e-10);
  BOOST_TEST(x.at("max_constraint_residual").get<double>() <= 1e-14);
}

// A damped, driven heavy top written on SO(3): the scene of the order study below, and
// a short run of it composed by the triple jump (the forced composed step on SO(3)).
static std::string damped_top_scene() {
  const std::string top = "[system]\nspace = \"SO(3)\"\n"
                          "params = { I1 = 1.0, I2 = 1.0, I3 = 0.5, m = 1.0, g = 1.0, c = 0.2 }\n"
                          "lagrangian = \"0.5*(I1*w1^2 + I2*w2^2 + I3*w3^2) - m*g*R33\"\n"
                          "forces = { w1 = \"-c*w1 + 0.3*sin(2*t)\", w2 = \"-c*w2\", w3 = \"-c*w3*R33\" }\n"
                          "[initial]\nrotation = [0.9689124217106447, 0.24740395925452294, 0.0, 0.0]\n"
                          "omega = [0.0, 0.3, 5.0]\n[integrator]\nmap = \"so3-exp\"\nstep = 0.01\nt_end = 2.0\n";
  return write_scene("damped_top.toml", top);
}

// The damped, driven heavy top's orders by `dvm converge`: 2 for so3-exp and so3-cayley,
// 4 for the triple jump. Each study integrates its reference (kahan-li8, 800 steps), which
// under AddressSanitizer takes most of this suite's time; the sanitized suite runs the
// same forced steps, composed, in forces_on_the_sphere_and_the_rotation_group, and
// `dvm converge` on every combination in test_cli_combinations.
BOOST_AUTO_TEST_CASE(orders_of_a_damped_driven_top,
                     *boost::unit_test::enable_if<!dvm_tests::kAddressSanitizer>()) {
  const std::string top_path = damped_top_scene();
  struct Case {
    std::string set;
    double order;
  };
  for (const Case& c : {Case{"integrator.composition=\"none\"", 2.0}, Case{"integrator.map=\"so3-cayley\"", 2.0},
                        Case{"integrator.composition=\"triple-jump:4\"", 4.0}}) {
    const Output o = dvm({"converge", top_path, "--steps-list", "50,100,200,400", "--json", "--set", c.set});
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    const double order = parse_json(o.out).at("fitted_order").get<double>();
    BOOST_TEST_MESSAGE("damped heavy top, " << c.set << ": order " << order);
    BOOST_TEST(std::fabs(order - c.order) <= 0.05 * c.order, o.out);
  }
}

// Forces on S^2 and SO(3) (the discrete Lagrange-d'Alembert principle at the map's node,
// solvers/manifold_step.h). A constant body torque about the symmetry axis
// (satellite_torque.toml): the body angular momentum and the rotation angle exact to
// round-off, the work T3 times the angle, the energy balance at round-off. The damped,
// driven heavy top composed by the triple jump runs, its force doing work. A spherical
// body damped by -c w: w(t) = w(0) exp(-c t / I), the midpoint
// error of order 2. On S^2 a force in the embedding gives the trajectory and the work of
// the same force on the pendulum constrained in R^3, composed to order 8 (1e-12); the
// momentum maps of the symmetries are then not reported as invariants.
BOOST_AUTO_TEST_CASE(forces_on_the_sphere_and_the_rotation_group) {
  {
    const Json r = run("satellite_torque.toml", {});
    const double T = 10.0, I3 = 1.0, T3 = 0.5, w0 = 1.0, angle = w0 * T + T3 * T * T / (2.0 * I3);
    BOOST_TEST(r.at("forced").get<bool>());
    const auto q = vec(r, "q_final"), p = vec(r, "p_final");  // the quaternion [w, x, y, z], pi
    BOOST_TEST(std::fabs(p[2] - (I3 * w0 + T3 * T)) <= 1e-12);
    BOOST_TEST(std::fabs(p[0]) + std::fabs(p[1]) <= 1e-14);
    const double sign = q[0] * std::cos(angle / 2) >= 0.0 ? 1.0 : -1.0;  // (q and -q: one rotation)
    BOOST_TEST(std::fabs(sign * q[0] - std::cos(angle / 2)) <= 1e-12);
    BOOST_TEST(std::fabs(sign * q[3] - std::sin(angle / 2)) <= 1e-12);
    BOOST_TEST(std::fabs(r.at("work").get<double>() - T3 * (angle - 0.0)) <= 1e-11);
    BOOST_TEST(r.at("max_abs_energy_balance").get<double>() <= 1e-11);
    BOOST_TEST((!r.contains("invariants") || r.at("invariants").empty()));  // (no J reported as conserved)
  }
  {
    const Output o = dvm({"run", damped_top_scene(), "--json", "--no-output", "--set",
                          "integrator.composition=\"triple-jump:4\""});
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    const Json r = parse_json(o.out);
    BOOST_TEST(r.at("forced").get<bool>());
    BOOST_TEST(r.at("steps").get<int>() == 200);
    BOOST_TEST(r.at("work").get<double>() < 0.0);  // (the damping takes more than the drive gives)
  }
  {  // a spherical body, I = 2, damped by -c w: pi(t) = pi(0) exp(-c t / I)
    const std::string ball = "[system]\nspace = \"SO(3)\"\nparams = { I = 2.0, c = 0.5 }\n"
                             "lagrangian = \"0.5*I*(w1^2 + w2^2 + w3^2)\"\n"
                             "forces = { w1 = \"-c*w1\", w2 = \"-c*w2\", w3 = \"-c*w3\" }\n"
                             "[initial]\nrotation = [1.0, 0.0, 0.0, 0.0]\nomega = [0.3, -0.4, 1.2]\n"
                             "[integrator]\nmap = \"so3-exp\"\nstep = 0.02\nt_end = 4.0\n";
    const std::string path = write_scene("damped_ball.toml", ball);
    auto error = [&](const std::string& h) {
      const Output o = dvm({"run", path, "--json", "--no-output", "--set", "integrator.step=" + h});
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      const auto p = vec(parse_json(o.out), "p_final");
      const double e = std::exp(-0.5 * 4.0 / 2.0);
      return std::fmax(std::fabs(p[0] - 0.6 * e), std::fmax(std::fabs(p[1] + 0.8 * e), std::fabs(p[2] - 2.4 * e)));
    };
    const double e1 = error("0.02"), e2 = error("0.01");
    BOOST_TEST_MESSAGE("damped ball: error at h and h/2 " << e1 << ", " << e2);
    BOOST_TEST(e1 <= 1e-4);
    BOOST_TEST(std::fabs(e1 / e2 - 4.0) <= 0.1);
  }
  {  // S^2 against R^3 with a constraint, the same force
    const std::vector<std::string> sets = {
        "system.forces={ x = \"-0.3*x_dot + 0.5*sin(3*t)\", y = \"-0.3*y_dot\", z = \"-0.3*z_dot*x\" }",
        "integrator.composition=\"kahan-li8\"", "integrator.t_end=5.0", "integrator.step=0.01"};
    const Json s = run("spherical_pendulum_written.toml", sets);
    auto r3 = sets;
    r3.push_back("system.invariants={}");
    const Json r = run("spherical_pendulum_r3.toml", r3);
    const auto a = vec(s, "q_final"), b = vec(r, "q_final");
    double d = 0.0;
    for (int i = 0; i < 3; ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
    BOOST_TEST_MESSAGE("forced spherical pendulum, S^2 against R^3 at t = 5: " << d);
    BOOST_TEST(d <= 1e-12);
    BOOST_TEST(std::fabs(s.at("work").get<double>() - r.at("work").get<double>()) <= 1e-12);
    BOOST_TEST(std::fabs(s.at("work").get<double>()) > 1.0);
    BOOST_TEST(s.at("max_abs_energy_balance").get<double>() <= 1e-12);
    BOOST_TEST((!s.contains("invariants") || s.at("invariants").empty()));  // J3 is not conserved
  }
}

// The written spherical pendulum run with `sets` and with a force that is zero: the same
// states to the bit, forced, and no work.
static void zero_force_gives_the_unforced_run(const std::vector<std::string>& sets) {
  const Json a = run("spherical_pendulum_written.toml", sets);
  auto zero = sets;
  zero.push_back("system.forces={ x = \"0*x_dot\" }");
  const Json b = run("spherical_pendulum_written.toml", zero);
  BOOST_TEST(b.at("forced").get<bool>());
  BOOST_TEST(vec(a, "q_final") == vec(b, "q_final"));
  BOOST_TEST(vec(a, "p_final") == vec(b, "p_final"));
  BOOST_TEST(b.at("work").get<double>() == 0.0);
}

// Galerkin with forces on S^2 and SO(3) (ManifoldGalerkinStep with its force: the force
// held at each quadrature node, paired with the node's virtual displacement).
//   - The constant torque about the symmetry axis (satellite_torque.toml): the angular
//     momentum I3 w0 + T3 t exact (the quadrature of a constant torque is exact), the
//     angle exact too (its increment h w(t_k + h/2) for the quadratic angle of a constant
//     acceleration), the work T3 times the angle and the energy balance at round-off,
//     for Gauss s = 1, 2 and Lobatto s = 2.
//   - The rest-to-rest slew of satellite_control.toml, its torque read from a table.
//   - The spherical body damped by -c w: errors of order 2s against pi(0) exp(-c t / I)
//     (s = 1: 2, s = 2: 4).
//   - On S^2, a damped and driven spherical pendulum: order 2s against a fine run of the
//     map's forced step composed to order 8, and the energy balance of the same order.
//   - A force that is zero gives the unforced Galerkin run to the bit.
//   - Unforced, a start from rest (the first step's control points all 0, where the
//     Jacobian's differences are not relative to them): the trajectory of the maps.
BOOST_AUTO_TEST_CASE(galerkin_with_forces_on_the_sphere_and_the_rotation_group) {
  for (const std::string& quad : {"gauss", "lobatto"})
    for (int s = 1; s <= 2; ++s) {
      if (quad == "lobatto" && s == 1) continue;
      const Json r = run("satellite_torque.toml", {"integrator.method=\"galerkin\"", "integrator.quadrature=\"" + quad + "\"",
                                                   "integrator.stages=" + std::to_string(s)});
      const double T = 10.0, I3 = 1.0, T3 = 0.5, w0 = 1.0, angle = w0 * T + T3 * T * T / (2.0 * I3);
      BOOST_TEST(r.at("forced").get<bool>());
      BOOST_TEST(r.at("method").get<std::string>() == "galerkin");
      const auto q = vec(r, "q_final"), p = vec(r, "p_final");
      BOOST_TEST(std::fabs(p[2] - (I3 * w0 + T3 * T)) <= 1e-12, quad << " s = " << s);
      BOOST_TEST(std::fabs(p[0]) + std::fabs(p[1]) <= 1e-14);
      const double sign = q[0] * std::cos(angle / 2) >= 0.0 ? 1.0 : -1.0;
      BOOST_TEST(std::fabs(sign * q[0] - std::cos(angle / 2)) <= 1e-11, quad << " s = " << s);
      BOOST_TEST(std::fabs(sign * q[3] - std::sin(angle / 2)) <= 1e-11, quad << " s = " << s);
      BOOST_TEST(std::fabs(r.at("work").get<double>() - T3 * angle) <= 1e-10, quad << " s = " << s);
      BOOST_TEST(r.at("max_abs_energy_balance").get<double>() <= 1e-11, quad << " s = " << s);
    }
  {  // the rest-to-rest slew of satellite_control.toml (a torque from a table): turned by
     // pi/2 about e3 and at rest again, as with the map
    const Json r = run("satellite_control.toml", {"integrator.method=\"galerkin\"", "integrator.stages=2"});
    const auto q = vec(r, "q_final"), p = vec(r, "p_final");
    const double sign = q[0] >= 0.0 ? 1.0 : -1.0, c = std::sqrt(0.5);
    BOOST_TEST(std::fabs(sign * q[0] - c) + std::fabs(q[1]) + std::fabs(q[2]) + std::fabs(sign * q[3] - c) <= 1e-12);
    BOOST_TEST(std::fabs(p[0]) + std::fabs(p[1]) + std::fabs(p[2]) <= 1e-12);
  }
  {  // the damped spherical body: order 2s
    const std::string ball = "[system]\nspace = \"SO(3)\"\nparams = { I = 2.0, c = 0.5 }\n"
                             "lagrangian = \"0.5*I*(w1^2 + w2^2 + w3^2)\"\n"
                             "forces = { w1 = \"-c*w1\", w2 = \"-c*w2\", w3 = \"-c*w3\" }\n"
                             "[initial]\nrotation = [1.0, 0.0, 0.0, 0.0]\nomega = [0.3, -0.4, 1.2]\n"
                             "[integrator]\nmethod = \"galerkin\"\nstep = 0.2\nt_end = 4.0\n";
    const std::string path = write_scene("damped_ball_galerkin.toml", ball);
    auto error = [&](int s, const std::string& h) {
      const Output o = dvm({"run", path, "--json", "--no-output", "--set", "integrator.step=" + h, "--set",
                            "integrator.stages=" + std::to_string(s)});
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      const auto p = vec(parse_json(o.out), "p_final");
      const double e = std::exp(-0.5 * 4.0 / 2.0);
      return std::fmax(std::fabs(p[0] - 0.6 * e), std::fmax(std::fabs(p[1] + 0.8 * e), std::fabs(p[2] - 2.4 * e)));
    };
    for (int s = 1; s <= 2; ++s) {
      const double e1 = error(s, "0.2"), e2 = error(s, "0.1"), ratio = e1 / e2, expected = std::pow(2.0, 2 * s);
      BOOST_TEST_MESSAGE("damped ball, Galerkin s = " << s << ": errors " << e1 << ", " << e2 << ", ratio " << ratio);
      BOOST_TEST(std::fabs(ratio / expected - 1.0) <= 0.05, "s = " << s << ": ratio " << ratio);
    }
  }
  {  // S^2: a damped, driven spherical pendulum, order 2s against a fine reference
    const std::vector<std::string> forced = {
        "system.forces={ x = \"-0.3*x_dot + 0.5*sin(3*t)\", y = \"-0.3*y_dot\", z = \"-0.3*z_dot*x\" }",
        "integrator.t_end=2.0"};
    auto with = [&](std::vector<std::string> extra) {
      extra.insert(extra.begin(), forced.begin(), forced.end());
      return run("spherical_pendulum_written.toml", extra);
    };
    const Json ref = with({"integrator.composition=\"kahan-li8\"", "integrator.step=0.002"});
    const auto qr = vec(ref, "q_final");
    for (int s = 1; s <= 2; ++s) {
      double err[2], balance[2];
      for (int k = 0; k < 2; ++k) {
        const Json g = with({"integrator.method=\"galerkin\"", "integrator.stages=" + std::to_string(s),
                             std::string("integrator.step=") + (k == 0 ? "0.04" : "0.02")});
        const auto q = vec(g, "q_final");
        err[k] = 0.0;
        for (int i = 0; i < 3; ++i) err[k] = std::fmax(err[k], std::fabs(q[i] - qr[i]));
        balance[k] = std::fabs(g.at("energy_balance_final").get<double>());
        BOOST_TEST(std::fabs(g.at("work").get<double>() - ref.at("work").get<double>()) <= 1e-2);
      }
      const double expected = std::pow(2.0, 2 * s);
      BOOST_TEST_MESSAGE("forced spherical pendulum, Galerkin s = " << s << ": errors " << err[0] << ", " << err[1]
                                                                     << "; energy balance " << balance[0] << ", "
                                                                     << balance[1]);
      BOOST_TEST(std::fabs(err[0] / err[1] / expected - 1.0) <= 0.15, "s = " << s);
      BOOST_TEST(balance[0] / balance[1] >= 0.8 * expected, "s = " << s);
    }
  }
  {  // released from rest (X = 0 at the first step): the spherical pendulum and the heavy
     // top, unforced, against the maps composed to order 8 at a fine step
    struct Rest {
      std::string scene, set;
    };
    for (const Rest& c : {Rest{"spherical_pendulum_written.toml", "initial.v=[0.0, 0.0, 0.0]"},
                          Rest{"heavy_top_written.toml", "initial.omega=[0.0, 0.0, 0.0]"}}) {
      const Json g = run(c.scene, {c.set, "integrator.method=\"galerkin\"", "integrator.stages=3",
                                   "integrator.step=0.01", "integrator.t_end=1.0"});
      const Json r = run(c.scene, {c.set, "integrator.composition=\"kahan-li8\"", "integrator.step=0.002",
                                   "integrator.t_end=1.0"});
      BOOST_TEST(g.at("status").get<std::string>() == "ok");
      const auto a = vec(g, "q_final"), b = vec(r, "q_final");
      double d = 0.0;
      for (std::size_t i = 0; i < a.size(); ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
      BOOST_TEST_MESSAGE(c.scene << " from rest, Galerkin s = 3 against kahan-li8: " << d);
      BOOST_TEST(d <= 1e-9, c.scene);
    }
  }
  // a zero force: the unforced run
  zero_force_gives_the_unforced_run({"integrator.method=\"galerkin\"", "integrator.stages=2", "integrator.t_end=1.0"});
}

// The hamiltonian form with forces on S^2 and SO(3) (ManifoldHamiltonianStep with its
// force: the forced Hamilton equations p' = -H_q + F sampled at the base point of
// Eq. 5.1, the force pulled back by the chart, at time t0 + theta h):
//   - a constant torque about a symmetric body's axis: the angular momentum, the angle,
//     the work and the energy balance exact to round-off (the midpoint of a motion
//     whose momentum is linear in t), and the rest-to-rest slew from a control table;
//   - a damped spherical body against pi(0) exp(-c t / I): order 2, the balance at
//     round-off (a quadratic H about a fixed axis);
//   - the damped, driven heavy top against the lagrangian form composed to order 8 at a
//     fine step: order 2 alone and 4 in the triple jump (a force read at t0, or not
//     pulled back by the chart, gives order 1);
//   - on S^2 the damped, driven spherical pendulum composed to order 8 against the
//     lagrangian form composed alike: the trajectory and the work to 1e-11;
//   - a force that is zero gives the unforced hamiltonian run to the bit.
BOOST_AUTO_TEST_CASE(hamiltonian_form_with_forces_on_the_sphere_and_the_rotation_group) {
  const std::string Hsat = "system.hamiltonian=\"0.5*(pi1^2/I1 + pi2^2/I2 + pi3^2/I3)\"";
  const std::string ham = "integrator.form=\"hamiltonian\"";
  auto distance = [](const Json& a, const Json& b, const char* key) {
    const auto x = vec(a, key), y = vec(b, key);
    double d = 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) d = std::fmax(d, std::fabs(x[i] - y[i]));
    return d;
  };
  {
    const Json r = run("satellite_torque.toml", {Hsat, ham});
    const double T = 10.0, I3 = 1.0, T3 = 0.5, w0 = 1.0, angle = w0 * T + T3 * T * T / (2.0 * I3);
    BOOST_TEST(r.at("forced").get<bool>());
    BOOST_TEST(r.at("form").get<std::string>() == "hamiltonian");
    const auto q = vec(r, "q_final"), p = vec(r, "p_final");
    BOOST_TEST(std::fabs(p[2] - (I3 * w0 + T3 * T)) <= 1e-12);
    BOOST_TEST(std::fabs(p[0]) + std::fabs(p[1]) <= 1e-14);
    const double sign = q[0] * std::cos(angle / 2) >= 0.0 ? 1.0 : -1.0;
    BOOST_TEST(std::fabs(sign * q[0] - std::cos(angle / 2)) <= 1e-11);
    BOOST_TEST(std::fabs(sign * q[3] - std::sin(angle / 2)) <= 1e-11);
    BOOST_TEST(std::fabs(r.at("work").get<double>() - T3 * angle) <= 1e-10);
    BOOST_TEST(r.at("max_abs_energy_balance").get<double>() <= 1e-11);
  }
  {  // the slew of satellite_control.toml: turned by pi/2 about e3 and at rest again
    const Json r = run("satellite_control.toml", {Hsat, ham});
    const auto q = vec(r, "q_final"), p = vec(r, "p_final");
    const double sign = q[0] >= 0.0 ? 1.0 : -1.0, c = std::sqrt(0.5);
    BOOST_TEST(std::fabs(sign * q[0] - c) + std::fabs(q[1]) + std::fabs(q[2]) + std::fabs(sign * q[3] - c) <= 1e-12);
    BOOST_TEST(std::fabs(p[0]) + std::fabs(p[1]) + std::fabs(p[2]) <= 1e-12);
    BOOST_TEST(r.at("max_abs_energy_balance").get<double>() <= 1e-12);
  }
  {  // the damped spherical body: order 2, the balance at round-off
    const std::string ball = "[system]\nspace = \"SO(3)\"\nparams = { I = 2.0, c = 0.5 }\n"
                             "lagrangian = \"0.5*I*(w1^2 + w2^2 + w3^2)\"\n"
                             "hamiltonian = \"(pi1^2 + pi2^2 + pi3^2)/(2*I)\"\n"
                             "forces = { w1 = \"-c*w1\", w2 = \"-c*w2\", w3 = \"-c*w3\" }\n"
                             "[initial]\nrotation = [1.0, 0.0, 0.0, 0.0]\nomega = [0.3, -0.4, 1.2]\n"
                             "[integrator]\nform = \"hamiltonian\"\nmap = \"so3-exp\"\nt_end = 4.0\n";
    const std::string path = write_scene("damped_ball_hamiltonian.toml", ball);
    double err[2];
    for (int k = 0; k < 2; ++k) {
      const Output o = dvm({"run", path, "--json", "--no-output", "--set", k == 0 ? "integrator.step=0.02" : "integrator.step=0.01"});
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      const Json r = parse_json(o.out);
      const auto p = vec(r, "p_final");
      const double e = std::exp(-0.5 * 4.0 / 2.0);
      err[k] = std::fmax(std::fabs(p[0] - 0.6 * e), std::fmax(std::fabs(p[1] + 0.8 * e), std::fabs(p[2] - 2.4 * e)));
      BOOST_TEST(r.at("max_abs_energy_balance").get<double>() <= 1e-12);  // (400 steps of round-off)
      BOOST_TEST(r.at("work").get<double>() < -0.1);
    }
    BOOST_TEST_MESSAGE("damped ball, hamiltonian form: errors " << err[0] << ", " << err[1]);
    BOOST_TEST(std::fabs(err[0] / err[1] - 4.0) <= 0.1);
  }
  {  // the damped, driven heavy top: orders 2 and 4 against a fine reference
    const std::string top = damped_top_scene();
    const std::string Htop = "system.hamiltonian=\"0.5*(pi1^2/I1 + pi2^2/I2 + pi3^2/I3) + m*g*R33\"";
    auto at = [&](std::vector<std::string> sets) {
      const Output o = dvm(with_sets({"run", top, "--json", "--no-output"}, sets));
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      return parse_json(o.out);
    };
    const Json ref = at({"integrator.composition=\"kahan-li8\"", "integrator.step=0.0025"});
    struct Case {
      std::string composition;
      double order;
    };
    for (const Case& c : {Case{"none", 2.0}, Case{"triple-jump:4", 4.0}}) {
      double err[2];
      for (int k = 0; k < 2; ++k) {
        const Json r = at({Htop, ham, "integrator.composition=\"" + c.composition + "\"",
                           k == 0 ? "integrator.step=0.04" : "integrator.step=0.02"});
        BOOST_TEST(r.at("forced").get<bool>());
        // (the chart step keeps its first iterate's Jacobian for the later iterations)
        BOOST_TEST(2 * r.at("jacobians").get<long>() < r.at("solver_iterations").get<long>());
        err[k] = std::fmax(distance(r, ref, "q_final"), distance(r, ref, "p_final"));
      }
      const double ratio = err[0] / err[1], expected = std::pow(2.0, c.order);
      BOOST_TEST_MESSAGE("damped driven top, hamiltonian form, " << c.composition << ": errors " << err[0] << ", "
                                                                 << err[1] << ", ratio " << ratio);
      BOOST_TEST(std::fabs(ratio / expected - 1.0) <= 0.15, c.composition << ": ratio " << ratio);
    }
  }
  {  // S^2: the two forms composed to order 8 against each other
    const std::vector<std::string> sets = {
        "system.forces={ x = \"-0.3*x_dot + 0.5*sin(3*t)\", y = \"-0.3*y_dot\", z = \"-0.3*z_dot*x\" }",
        "integrator.composition=\"kahan-li8\"", "integrator.t_end=5.0", "integrator.step=0.01"};
    auto h = sets;
    h.push_back(ham);
    const Json a = run("spherical_pendulum_written.toml", h), b = run("spherical_pendulum_written.toml", sets);
    BOOST_TEST_MESSAGE("forced spherical pendulum, hamiltonian against lagrangian form, kahan-li8: "
                       << distance(a, b, "q_final") << ", work " << a.at("work").get<double>() - b.at("work").get<double>());
    BOOST_TEST(distance(a, b, "q_final") <= 1e-11);
    BOOST_TEST(std::fabs(a.at("work").get<double>() - b.at("work").get<double>()) <= 1e-11);
    BOOST_TEST(std::fabs(a.at("work").get<double>()) > 1.0);
    BOOST_TEST(a.at("max_abs_energy_balance").get<double>() <= 1e-11);
  }
  zero_force_gives_the_unforced_run({ham, "integrator.t_end=1.0"});  // a zero force: the unforced run
}

// Controls read by forces on S^2 and SO(3) (ManifoldForce with the run's ControlSignal):
//   - a rest-to-rest slew (satellite_control.toml): a torque of pi/2 then -pi/2 from a
//     table, held over each step, stops the body turned by pi/2 about e3, exact to
//     round-off for the midpoint-type map about a fixed axis;
//   - a table holding f(t_k + h/2) (the midpoint node of step k) gives the run of the
//     control written as f(t) to round-off, and the same table moved by one step does
//     not: step k reads u_k, on SO(3) with the state in the torque and under a
//     constraint;
//   - on S^2 a control written in t gives the run of the force written in t, composed
//     (each substep at its own node), and a constant table the run of the constant force
//     composed (every substep of step k reads u_k).
// A file of the wrong length, a control no torque reads and controls on (S^2)^K are
// refused (test below).
BOOST_AUTO_TEST_CASE(controls_on_the_sphere_and_the_rotation_group) {
  {
    const Json r = run("satellite_control.toml", {});
    BOOST_TEST(r.at("forced").get<bool>());
    BOOST_TEST(r.at("steps").get<int>() == 200);
    const auto q = vec(r, "q_final"), p = vec(r, "p_final");
    const double sign = q[0] >= 0.0 ? 1.0 : -1.0, c = std::cos(M_PI / 4);
    BOOST_TEST_MESSAGE("slew by a tabulated torque: quaternion error " << std::fabs(sign * q[0] - c) << " "
                                                                       << std::fabs(sign * q[3] - c) << ", |pi| "
                                                                       << std::fabs(p[2]));
    BOOST_TEST(std::fabs(sign * q[0] - c) <= 1e-13);
    BOOST_TEST(std::fabs(sign * q[3] - c) <= 1e-13);
    BOOST_TEST(std::fabs(q[1]) + std::fabs(q[2]) <= 1e-14);
    BOOST_TEST(std::fabs(p[0]) + std::fabs(p[1]) + std::fabs(p[2]) <= 1e-12);
    BOOST_TEST(std::fabs(r.at("work").get<double>()) <= 1e-12);  // (at rest again: all work given back)
    BOOST_TEST(r.at("max_abs_energy_balance").get<double>() <= 1e-12);
  }
  // f(t) = 0.3 sin 2t + 0.1 tabulated at the nodes t_k + h/2 (shift 0) or one step late
  const double h = 0.01;
  const int steps = 300;
  auto table = [&](const std::string& name, int shift) {
    std::ostringstream text;
    text.precision(17);
    text << "u\n";
    for (int k = 0; k < steps; ++k) text << 0.3 * std::sin(2.0 * ((k + shift) * h + h / 2)) + 0.1 << "\n";
    return write_scene(name, text.str());
  };
  const std::string on_time = table("u_on_time.csv", 0), late = table("u_late.csv", 1);
  auto distance = [](const Json& a, const Json& b) {
    double d = 0.0;
    for (const char* key : {"q_final", "p_final"}) {
      const auto x = vec(a, key), y = vec(b, key);
      for (std::size_t i = 0; i < x.size(); ++i) d = std::fmax(d, std::fabs(x[i] - y[i]));
    }
    return d;
  };
  const std::string expression = "system.controls={ u = \"0.3*sin(2*t) + 0.1\" }";
  auto from = [](const std::string& file) { return "system.controls={ u = { csv = \"" + file + "\" } }"; };
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
      // an asymmetric body, the torque mixing the control with the state
      {"satellite_torque.toml",
       {"system.params={ I1 = 2.0, I2 = 1.5, I3 = 1.0 }", "system.forces={ w1 = \"0.5*u\", w3 = \"u - 0.2*w3\" }",
        "initial.omega=[0.2, 0.1, 1.0]", "integrator.t_end=3.0"}},
      // the body on an axle, a control torque about the axle
      {"compound_pendulum_so3.toml", {"system.forces={ w1 = \"u\" }", "integrator.t_end=3.0"}}};
  for (const auto& one : cases) {
    const std::string& name = one.first;
    const std::vector<std::string>& sets = one.second;
    BOOST_TEST_CONTEXT(name) {
      auto with = [&](const std::string& controls) {
        auto all = sets;
        all.push_back(controls);
        return run(name, all);
      };
      const Json e = with(expression), t = with(from(on_time)), l = with(from(late));
      BOOST_TEST_MESSAGE(name << ": tabulated at the nodes against the expression " << distance(t, e)
                              << ", one step late " << distance(l, e));
      BOOST_TEST(distance(t, e) <= 1e-13);
      BOOST_TEST(distance(l, e) >= 1e-4);
      BOOST_TEST(std::fabs(t.at("work").get<double>()) > 1e-3);
    }
  }
  {  // S^2, composed by the triple jump: a control in t against the force in t, and a
     // constant table against the constant force
    const std::vector<std::string> base = {"integrator.composition=\"triple-jump:4\"", "integrator.t_end=3.0",
                                           "integrator.step=0.01"};
    auto with = [&](std::vector<std::string> more) {
      auto all = base;
      all.insert(all.end(), more.begin(), more.end());
      return run("spherical_pendulum_written.toml", all);
    };
    const Json a = with({"system.forces={ x = \"u*z - 0.2*x_dot\" }", "system.controls={ u = \"0.5*cos(3*t)\" }"});
    const Json b = with({"system.forces={ x = \"0.5*cos(3*t)*z - 0.2*x_dot\" }"});
    std::ostringstream constant;
    for (int k = 0; k < steps; ++k) constant << "0.7\n";
    const Json c = with({"system.forces={ y = \"u\" }", from(write_scene("u_constant.csv", constant.str()))});
    const Json d = with({"system.forces={ y = \"0.7\" }"});
    BOOST_TEST_MESSAGE("S^2, triple jump: control in t against the force in t " << distance(a, b)
                       << ", constant table against the constant force " << distance(c, d));
    BOOST_TEST(distance(a, b) <= 1e-14);
    BOOST_TEST(distance(c, d) <= 1e-14);
    BOOST_TEST(std::fabs(c.at("work").get<double>()) > 0.1);
  }
}

// Constraints on S^2 and SO(3) (solvers/manifold_constrained_step.h), each against the
// one-coordinate system it reduces to, composed to order 8 (kahan-li8, h = 0.01) to
// t = 10 and compared to 1e-10:
//   - the spherical pendulum held on the great circle y = 0 is the planar pendulum
//     (pendulum.toml's m = l = g = 1): x = sin q, z = -cos q, and p = p_q (cos q, 0, sin q);
//   - the bead on a rotating hoop (bead_on_rotating_hoop.toml, a constraint in t) is
//     the one-coordinate Lagrangian (theta_dot^2 + Om^2 sin^2 theta) / 2 + g cos theta,
//     its hoop at the angle Om t;
//   - the compound pendulum on SO(3) (compound_pendulum_so3.toml, two constraints) is
//     pendulum.toml: the rotation about e1 by q, pi = (p_q, 0, 0);
//   - the damped bead on a fixed hoop (a force in the embedding with the constraint) is
//     the damped pendulum, the work equal (the constraint force does none).
// Each run holds its constraints and their hidden constraint at round-off, and reports
// the momentum maps of L's symmetries only where the constraints share them.
BOOST_AUTO_TEST_CASE(constraints_on_the_sphere_and_the_rotation_group) {
  const std::vector<std::string> order8 = {"integrator.composition=\"kahan-li8\"", "integrator.t_end=10.0",
                                           "integrator.step=0.01"};
  const Json a = run("pendulum.toml", order8);
  const double q = vec(a, "q_final")[0], pq = vec(a, "p_final")[0];
  auto held = [](const Json& r, int m) {
    BOOST_TEST(r.at("constrained").get<bool>());
    BOOST_TEST(r.at("constraints").get<int>() == m);
    BOOST_TEST(r.at("max_constraint_residual").get<double>() <= 1e-14);
    BOOST_TEST(r.at("max_hidden_constraint_residual").get<double>() <= 1e-13);
  };
  {  // the great circle y = 0
    auto sets = order8;
    sets.insert(sets.end(), {"system.constraints=[\"y\"]", "system.params.g=1.0", "initial.q=[0.9092974268256817, 0.0, "
                             "0.4161468365471424]", "initial.v=[0.0, 0.0, 0.0]"});
    const Json s = run("spherical_pendulum_written.toml", sets);
    const auto x = vec(s, "q_final"), p = vec(s, "p_final");
    BOOST_TEST_MESSAGE("pendulum on a great circle of S^2 against the angle at t = 10: " << std::fabs(x[0] - std::sin(q))
                                                                                       << " " << std::fabs(x[2] + std::cos(q)));
    BOOST_TEST(std::fabs(x[0] - std::sin(q)) <= 1e-10);
    BOOST_TEST(std::fabs(x[1]) <= 1e-15);
    BOOST_TEST(std::fabs(x[2] + std::cos(q)) <= 1e-10);
    BOOST_TEST(std::fabs(p[0] - pq * std::cos(q)) <= 1e-10);
    BOOST_TEST(std::fabs(p[1]) <= 1e-14);
    BOOST_TEST(std::fabs(p[2] - pq * std::sin(q)) <= 1e-10);
    held(s, 1);
    BOOST_TEST(std::fabs(s.at("energy_initial").get<double>() - a.at("energy_initial").get<double>()) <= 1e-15);
    BOOST_TEST(s.at("max_abs_energy_error").get<double>() <= 1e-9);
    BOOST_TEST((!s.contains("invariants") || s.at("invariants").empty()));  // (y = 0 breaks the symmetry about e3)
  }
  {  // the bead on the rotating hoop against its one coordinate
    const std::string angle = write_scene(
        "hoop_angle.toml",
        "[system]\ncoordinates = [\"th\"]\nparams = { g = 9.81, Om = 4.0 }\n"
        "lagrangian = \"0.5*(th_dot^2 + Om^2*sin(th)^2) + g*cos(th)\"\n"
        "[initial]\nq = [0.2]\nv = [0.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.01\nt_end = 10.0\n");
    const Output o = dvm(with_sets({"run", angle, "--json", "--no-output"}, order8));
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    const double th = vec(parse_json(o.out), "q_final")[0], phi = 4.0 * 10.0;
    const Json b = run("bead_on_rotating_hoop.toml", order8);
    const auto x = vec(b, "q_final");
    const double d = std::fmax(std::fabs(x[0] - std::sin(th) * std::cos(phi)),
                               std::fmax(std::fabs(x[1] - std::sin(th) * std::sin(phi)), std::fabs(x[2] + std::cos(th))));
    BOOST_TEST_MESSAGE("bead on a rotating hoop against its angle at t = 10: " << d << " (theta " << th << ")");
    BOOST_TEST(d <= 1e-10);
    held(b, 1);
    BOOST_TEST(b.at("max_abs_energy_error").get<double>() > 1.0);  // (the hoop's drive does work)
  }
  {  // the compound pendulum on SO(3)
    const Json r = run("compound_pendulum_so3.toml", order8);
    const auto u = vec(r, "q_final"), pi = vec(r, "p_final");  // the quaternion [w, x, y, z], pi
    const double sign = u[0] * std::cos(q / 2) >= 0.0 ? 1.0 : -1.0;
    BOOST_TEST_MESSAGE("compound pendulum on SO(3) against the angle at t = 10: "
                       << std::fabs(sign * u[0] - std::cos(q / 2)) << " " << std::fabs(sign * u[1] - std::sin(q / 2)));
    BOOST_TEST(std::fabs(sign * u[0] - std::cos(q / 2)) <= 1e-10);
    BOOST_TEST(std::fabs(sign * u[1] - std::sin(q / 2)) <= 1e-10);
    BOOST_TEST(std::fabs(u[2]) + std::fabs(u[3]) <= 1e-14);
    BOOST_TEST(std::fabs(pi[0] - pq) <= 1e-10);
    BOOST_TEST(std::fabs(pi[1]) + std::fabs(pi[2]) <= 1e-13);
    held(r, 2);
    BOOST_TEST(std::fabs(r.at("energy_initial").get<double>() - a.at("energy_initial").get<double>()) <= 1e-15);
    // L (I1 != I2) has no symmetry about e1 in space, nor do the constraints about e2, e3:
    // no momentum map is reported as conserved
    BOOST_TEST((!r.contains("invariants") || r.at("invariants").empty()));
  }
  {  // damped on a fixed hoop: the force -c v in the embedding against -c th_dot
    auto sets = order8;
    sets.insert(sets.end(), {"system.constraints=[\"y\"]", "system.params.g=1.0",
                             "system.forces={ x = \"-0.3*x_dot\", y = \"-0.3*y_dot\", z = \"-0.3*z_dot\" }",
                             "initial.q=[0.9092974268256817, 0.0, 0.4161468365471424]", "initial.v=[0.0, 0.0, 0.0]"});
    const Json s = run("spherical_pendulum_written.toml", sets);
    const std::string damped = write_scene(
        "damped_angle.toml",
        "[system]\ncoordinates = [\"th\"]\nlagrangian = \"0.5*th_dot^2 + cos(th)\"\nforces = { th = \"-0.3*th_dot\" }\n"
        "[initial]\nq = [2.0]\nv = [0.0]\n[integrator]\nmap = \"midpoint\"\nstep = 0.01\nt_end = 10.0\n");
    const Output o = dvm(with_sets({"run", damped, "--json", "--no-output"}, order8));
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    const Json t = parse_json(o.out);
    const double th = vec(t, "q_final")[0];
    const auto x = vec(s, "q_final");
    BOOST_TEST_MESSAGE("damped pendulum on a great circle against the angle at t = 10: "
                       << std::fabs(x[0] - std::sin(th)) << " " << std::fabs(x[2] + std::cos(th)));
    BOOST_TEST(std::fabs(x[0] - std::sin(th)) <= 1e-10);
    BOOST_TEST(std::fabs(x[2] + std::cos(th)) <= 1e-10);
    BOOST_TEST(s.at("forced").get<bool>());
    held(s, 1);
    BOOST_TEST(std::fabs(s.at("work").get<double>() - t.at("work").get<double>()) <= 1e-10);
    BOOST_TEST(s.at("work").get<double>() < -0.5);
    BOOST_TEST(s.at("max_abs_energy_balance").get<double>() <= 1e-12);
  }
}

// Orders under constraints on S^2 and SO(3), measured by `dvm converge`: 2 for the
// midpoint-type maps, 4 for the triple jump (the constrained step of a scleronomic or a
// rheonomic constraint composed with its adjoint), and the same with a force.
BOOST_AUTO_TEST_CASE(orders_under_constraints_on_the_sphere_and_the_rotation_group) {
  struct Case {
    const char* scene;
    std::string composition, steps;
    double order;
    std::vector<std::string> sets;
  };
  const std::vector<std::string> damped = {
      "system.constraints=[\"x + y\"]", "initial.q=[0.5, -0.5, -0.7071067811865476]", "initial.v=[0.0, 0.0, 0.0]",
      "system.forces={ x = \"-0.3*x_dot\", y = \"-0.3*y_dot + 0.4*sin(2*t)\", z = \"-0.3*z_dot\" }"};
  const std::vector<Case> cases = {
      {"bead_on_rotating_hoop.toml", "none", "40,80,160,320", 2.0, {}},
      {"bead_on_rotating_hoop.toml", "triple-jump:4", "20,40,80,160", 4.0, {}},
      {"compound_pendulum_so3.toml", "none", "40,80,160,320", 2.0, {}},
      {"compound_pendulum_so3.toml", "triple-jump:4", "20,40,80,160", 4.0, {}},
      {"spherical_pendulum_written.toml", "none", "40,80,160,320", 2.0, damped},
      {"spherical_pendulum_written.toml", "triple-jump:4", "20,40,80,160", 4.0, damped},
  };
  for (const Case& c : cases) {
    BOOST_TEST_CONTEXT(c.scene << ", " << c.composition << (c.sets.empty() ? "" : ", damped")) {
      std::vector<std::string> args = {"converge", scene(c.scene), "--t-end", "1", "--steps-list", c.steps, "--json",
                                       "--set", "integrator.composition=\"" + c.composition + "\""};
      const Output o = dvm(with_sets(args, c.sets));
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      const double order = parse_json(o.out).at("fitted_order").get<double>();
      BOOST_TEST_MESSAGE(c.scene << " " << c.composition << ": " << order);
      BOOST_TEST(std::fabs(order - c.order) <= 0.1 * c.order, o.out);
    }
  }
}

// Bad input, and the combinations the constrained step does not take: exit 2, the keys
// named, nothing on stdout, no file written.
BOOST_AUTO_TEST_CASE(bad_constraints_and_combinations_are_refused_naming_the_keys) {
  const std::string csv = temp_dir() + "/refused.csv";
  auto refused = [&](const std::string& scene_name, std::vector<std::string> sets, std::vector<std::string> says) {
    std::filesystem::remove(csv);
    const Output r = dvm(with_sets({"run", scene(scene_name), "--csv", csv}, sets));
    BOOST_TEST_CONTEXT(sets.front()) {
      BOOST_TEST(r.status == 2);
      BOOST_TEST(r.out.empty());
      BOOST_TEST(!std::filesystem::exists(csv));
      for (const std::string& s : says) BOOST_TEST(r.err.find(s) != std::string::npos, r.err);
    }
  };
  const std::string P = "pendulum_cartesian.toml";
  const std::string S = "spherical_pendulum_r3.toml";
  // redundant (a multiple of the first): rank 1 of 2
  refused(S, {"system.constraints=[\"x^2 + y^2 + z^2 - l^2\", \"2*x^2 + 2*y^2 + 2*z^2 - 2*l^2\"]"},
          {"system.constraints", "rank 1", "expected 2", "redundant"});
  // a second constraint the initial state violates
  refused(S, {"system.constraints=[\"x^2 + y^2 + z^2 - l^2\", \"x - 2\"]"},
          {"initial.q", "system.constraints[2]", "(\"x - 2\")"});
  refused(P, {"initial.q=[0.6, -0.9]", "initial.v=[0.0, 0.0]"}, {"initial.q", "system.constraints[1]", "beyond 1e-10"});
  refused(P, {"system.constraints=[\"x^2 + y^2 - \"]"}, {"system.constraints[1]", "after '-'"});
  refused(P, {"system.constraints=[\"x_dot*x\"]"}, {"system.constraints[1]", "unknown name 'x_dot'"});
  refused(P, {"system.constraints=\"x^2 + y^2 - l^2\""}, {"system.constraints", "expected a list"});
  refused(P, {"system.constraints=[]"}, {"system.constraints", "empty"});
  refused(P, {"system.constraints=[1.0]"}, {"system.constraints[1]", "expected a string"});
  refused(P, {"system.constraints=[\"x\", \"y\"]"}, {"system.constraints", "leave no motion"});
  refused(P, {"system.constraints=[\"sqrt(x - 5)\"]"}, {"system.constraints", "not finite"});
  refused(P, {"initial.project_velocity=1"}, {"initial.project_velocity", "true or false"});
  refused("pendulum_written.toml", {"initial.project_velocity=true"}, {"initial.project_velocity", "writes none"});
  refused("pendulum.toml", {"system.constraints=[\"theta\"]"}, {"system.constraints", "belongs to a written system"});
  refused("spherical_double_pendulum_written.toml", {"system.constraints=[\"x1\"]"},
          {"system.constraints", "on (S^2)^2 a written system takes none"});
  // what the constrained step does not take
  refused(P, {"integrator.method=galerkin"}, {"integrator.quadrature", "system.constraints", "\"lobatto\""});
  refused(P, {"integrator.method=galerkin", "integrator.quadrature=\"lobatto\"", "integrator.stages=7"},
          {"integrator.stages"});
  refused(P, {"integrator.form=hamiltonian", "integrator.lift=none"}, {"integrator.lift", "system.constraints"});
  refused(P, {"integrator.form=sode2"}, {"integrator.form", "lagrangian with constraints"});
  refused(P, {"integrator.form=sode1"}, {"integrator.form"});
  refused(P, {"integrator.map=explicit-euler", "integrator.composition=blanes-moan4"},
          {"integrator.composition", "system.constraints"});
  refused(P, {"integrator.solver=tiny"}, {"integrator.solver"});
  // a Lagrangian in t: the SODE forms where M is constant only (Kapitza's L has a term
  // linear in th_dot), no written H, t in no energy, invariant or Lagrangian on S^2
  const std::string K = "kapitza_pendulum.toml";
  refused(K, {"integrator.form=sode1"}, {"integrator.form", "is not separable"});
  refused(K, {"integrator.solver=tiny"}, {"integrator.solver"});
  refused(K, {"problem.kind=\"boundary-value\"", "problem.q_final=[3.0]", "problem.steps=10"}, {"problem.kind"});
  refused(K, {"system.hamiltonian=\"p_th^2/2\""}, {"system.hamiltonian", "depends on t", "not its Legendre transform"});
  refused(K, {"system.energy=\"t*th\""}, {"system.energy", "unknown name 't'", "an energy"});
  refused(K, {"system.invariants={ I = \"t\" }"}, {"system.invariants.I", "unknown name 't'"});
  refused("spherical_pendulum_written.toml", {"system.lagrangian=\"t*(x_dot^2 + y_dot^2 + z_dot^2)/2 - z\""},
          {"system.lagrangian", "unknown name 't'", "a Lagrangian on S^2 or SO(3)"});
  // forces on S^2 and SO(3): the lagrangian and hamiltonian forms of the maps and
  // Galerkin (the hamiltonian form with the written H), keyed by a coordinate (S^2) or a
  // body axis (SO(3)); none on (S^2)^K, nor controls
  const std::string T = "satellite_torque.toml", W = "spherical_pendulum_written.toml";
  refused(T, {"integrator.form=hamiltonian"}, {"integrator.form", "system.hamiltonian", "this scene writes none"});
  refused(T, {"integrator.form=sode1"}, {"integrator.form", "lagrangian with forces on SO(3)"});
  refused(T, {"system.forces={ x = \"1\" }"}, {"system.forces.x", "not a body axis", "w1, w2, w3"});
  refused(T, {"system.forces={ w3 = \"pi3\" }"}, {"system.forces.w3", "unknown name 'pi3'"});
  refused(W, {"system.forces={ x = \"-x_dot\" }", "integrator.form=newmark"},
          {"integrator.form", "lagrangian with forces on S^2"});
  refused(W, {"system.forces={ x = \"-x_dot\" }", "problem.kind=\"boundary-value\"", "problem.q_final=[0.0, 0.0, 1.0]",
              "problem.steps=10"},
          {"problem.kind", "lagrangian with forces on S^2"});
  refused(W, {"system.forces={ q = \"1\" }"}, {"system.forces.q", "not a coordinate"});
  refused("spherical_double_pendulum_written.toml", {"system.forces={ x1 = \"u\" }", "system.controls={ u = \"t\" }"},
          {"system.controls", "on (S^2)^2 a written system is conservative"});
  // controls on SO(3): one value per step, read by the torque (u follows t after R's
  // nine entries: a torque reading R22, the entry after t on R^n, reads no control)
  refused("satellite_control.toml", {"integrator.t_end=3.0"}, {"system.controls.u", "holds 200 values", "300"});
  refused(T, {"system.forces={ w3 = \"R22\" }", "system.controls={ u = \"t\" }"},
          {"system.controls.u", "no force reads the control 'u'"});
  refused(T, {"system.forces={ w3 = \"v\" }", "system.controls={ u = \"t\" }"},
          {"system.forces.w3", "unknown name 'v'"});
  refused("spherical_double_pendulum_written.toml", {"system.forces={ x1 = \"1\" }"},
          {"system.forces", "on (S^2)^2 a written system is conservative"});
  // constraints on S^2 and SO(3): the lagrangian form of the maps only, Newton's method,
  // fewer constraints than the space's dimension, the initial state on them
  const std::string H = "bead_on_rotating_hoop.toml", C = "compound_pendulum_so3.toml";
  refused(H, {"integrator.method=galerkin"}, {"integrator.method", "lagrangian with constraints on S^2"});
  refused(H, {"integrator.form=hamiltonian", "system.hamiltonian=\"(p_x^2 + p_y^2 + p_z^2)/2 + 9.81*z\""},
          {"integrator.form", "lagrangian with constraints on S^2"});
  refused(H, {"integrator.solver=tiny"}, {"integrator.solver", "lagrangian with constraints on S^2"});
  refused(H, {"problem.kind=\"boundary-value\"", "problem.q_final=[0.0, 0.6, -0.8]", "problem.steps=10"},
          {"problem.kind"});
  refused(H, {"system.constraints=[\"x\", \"y\"]"}, {"system.constraints", "leave no motion", "S^2 (dimension 2)"});
  refused(H, {"system.constraints=[\"x_dot\"]"}, {"system.constraints[1]", "unknown name 'x_dot'"});
  refused(H, {"initial.v=[0.0, 0.0, 0.0]"}, {"initial.v", "off the hidden constraint", "system.constraints[1]"});
  refused(H, {"initial.q=[0.6, 0.0, -0.8]", "system.constraints=[\"x - 0.5\"]"},
          {"initial.q", "system.constraints[1]", "(\"x - 0.5\")"});
  refused(C, {"system.constraints=[\"R21\", \"R21 + R31 - R31\"]"},
          {"system.constraints", "rank 1", "expected 2", "redundant"});
  refused(C, {"system.constraints=[\"R21\", \"R31\", \"R32\"]"},
          {"system.constraints", "leave no motion", "SO(3) (dimension 3)"});
  refused(C, {"system.constraints=[\"w1\"]"}, {"system.constraints[1]", "unknown name 'w1'"});
  refused(C, {"integrator.method=galerkin"}, {"integrator.method", "lagrangian with constraints on SO(3)"});
  refused(C, {"initial.omega=[0.0, 0.5, 0.0]"}, {"initial.omega", "off the hidden constraint"});
  refused(C, {"initial.rotation=[0.5403023058681398, 0.0, 0.8414709848078965, 0.0]"},
          {"initial.rotation", "system.constraints[2]", "(\"R31\")"});
}

// A Lagrangian in t in the hamiltonian form: H(t, q, p), the Legendre transform of L at
// each step's node time. Kapitza's pendulum (a pivot shaken in t) converges to the
// lagrangian form's Galerkin reference (dvm converge) at the orders of the maps: the
// midpoint 2, theta = 0.3 with its adjoint 2, the triple jump 4 (H read at another time,
// or at t = 0, converges to another solution or at a lower order); the theta map on T*Q
// (lift = "none") and a force in t run too.
BOOST_AUTO_TEST_CASE(a_lagrangian_in_t_runs_in_the_hamiltonian_form) {
  struct Order {
    std::vector<std::string> sets;
    double order;
  };
  for (const Order& want :
       {Order{{}, 2.0}, Order{{"integrator.map=theta", "integrator.theta=0.3", "integrator.composition=stormer-verlet"}, 2.0},
        Order{{"integrator.composition=\"triple-jump\""}, 4.0}}) {
    const std::string name = want.sets.empty() ? "midpoint" : want.sets.back();
    const double fitted = fitted_order({"converge", scene("kapitza_pendulum.toml"), "--t-end", "0.5", "--steps-list",
                                        "50,100,200,400", "--set", "integrator.form=hamiltonian"},
                                       want.sets);
    BOOST_TEST_MESSAGE("Kapitza's pendulum, hamiltonian form " << name << ": order " << fitted);
    BOOST_TEST(std::fabs(fitted - want.order) <= 0.05 * want.order, name);
  }
  for (const std::vector<std::string>& sets :
       {std::vector<std::string>{"integrator.lift=none"},
        std::vector<std::string>{"system.forces={ th = \"-0.1*th_dot + 0.2*cos(3*t)\" }"}}) {
    std::vector<std::string> args = {"run", scene("kapitza_pendulum.toml"), "--json", "--no-output", "--set",
                                     "integrator.form=hamiltonian", "--set", "integrator.t_end=1"};
    for (const std::string& k : sets) {
      args.push_back("--set");
      args.push_back(k);
    }
    const Output o = dvm(args);
    BOOST_TEST_CONTEXT(sets.front()) {
      BOOST_TEST_REQUIRE(o.status == 0, o.err);
      BOOST_TEST(parse_json(o.out).at("time_dependent").get<bool>());
      BOOST_TEST(parse_json(o.out).at("form").get<std::string>() == "hamiltonian");
    }
  }
}

// The hamiltonian form under constraints (the cotangent lift with multipliers,
// solvers/constrained_hamiltonian_step.h). On the Cartesian pendulum and the
// slider-crank (separable, the second with forces) its unconstrained step is the
// lagrangian form's, so the two constrained runs give the same states to 1e-12: the
// midpoint, theta = 0.3 with its adjoint, the triple jump; the constraint and its hidden
// constraint hold to 1e-12 at every step. `dvm converge` (its reference: Lobatto
// Galerkin of the lagrangian form) measures the orders on the four-bar linkage, whose L
// is not separable: 2 for the midpoint, 4 for the triple jump.
BOOST_AUTO_TEST_CASE(constraints_in_the_hamiltonian_form,
                     *boost::unit_test::enable_if<!dvm_tests::kAddressSanitizer>()) {
  for (const char* name : {"pendulum_cartesian.toml", "slider_crank.toml"})
    for (const std::vector<std::string>& method :
         {std::vector<std::string>{}, std::vector<std::string>{"integrator.map=theta", "integrator.theta=0.3",
                                                               "integrator.composition=stormer-verlet"},
          std::vector<std::string>{"integrator.composition=triple-jump"}}) {
      const std::string what = std::string(name) + (method.empty() ? " midpoint" : " " + method.back());
      BOOST_TEST_CONTEXT(what) {
        std::vector<std::string> sets = method;
        sets.push_back("integrator.t_end=2.0");
        const Json lag = run(name, sets);
        sets.push_back("integrator.form=hamiltonian");
        const Json ham = run(name, sets);
        BOOST_TEST(ham.at("form").get<std::string>() == "hamiltonian");
        BOOST_TEST(ham.at("constrained").get<bool>());
        double d = 0.0, size = 0.0;
        for (const char* key : {"q_final", "p_final"})
          for (std::size_t i = 0; i < vec(lag, key).size(); ++i) {
            d = std::fmax(d, std::fabs(vec(lag, key)[i] - vec(ham, key)[i]));
            size = std::fmax(size, std::fabs(vec(lag, key)[i]));
          }
        BOOST_TEST_MESSAGE(what << ": hamiltonian against lagrangian form " << d);
        BOOST_TEST(d <= 1e-12 * size);
        BOOST_TEST(ham.at("max_constraint_residual").get<double>() <= 1e-12);
        BOOST_TEST(ham.at("max_hidden_constraint_residual").get<double>() <= 1e-12);
      }
    }
  for (const auto& [composition, steps, order] :
       {std::tuple<std::string, std::string, double>{"none", "40,80,160,320", 2.0},
        std::tuple<std::string, std::string, double>{"triple-jump:4", "20,40,80,160", 4.0}}) {
    const Output o = dvm({"converge", scene("four_bar.toml"), "--t-end", "1", "--steps-list", steps, "--json", "--set",
                          "integrator.form=hamiltonian", "--set", "integrator.composition=\"" + composition + "\""});
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    const double fitted = parse_json(o.out).at("fitted_order").get<double>();
    BOOST_TEST_MESSAGE("four-bar linkage, hamiltonian form, " << composition << ": order " << fitted);
    BOOST_TEST(std::fabs(fitted - order) <= 0.1 * order, o.out);
  }
}

// A Lagrangian in t with a constant mass matrix in the SODE and Newmark forms: the
// driven oscillator L = x_dot^2 / 2 - x^2 / 2 + A x cos(w t), whose solution is
// x = C cos t + D sin t + K cos(w t), K = A / (1 - w^2). Each form (sode1, sode2 at
// theta 1/2, Newmark (1/2, 1/4), sode2 through the Legendre lift at theta 0.3 with its
// adjoint) ends at the exact state to order 2 (halving the step divides the error by
// 4), and sode2 composed by the triple jump to order 4. Each run gives the states of its
// twin, the undriven L with the drive as the force A cos(w t) (the forced step), to
// round-off. (An order study: test_cli_combinations runs these forms on a Lagrangian in
// t under the sanitizers.)
static const char kDrivenHead[] = "[system]\ncoordinates = [\"x\"]\nparams = { A = 0.5, w = 2.0 }\n";
static const char kDrivenTail[] =
    "[initial]\nq = [1.0]\nv = [0.3]\n[integrator]\nmap = \"midpoint\"\nstep = 0.02\nt_end = 2.0\n";
static std::string driven_in_t_scene() {
  return write_scene("driven_in_t.toml", std::string(kDrivenHead) +
                                             "lagrangian = \"x_dot^2/2 - x^2/2 + A*x*cos(w*t)\"\n" + kDrivenTail);
}
BOOST_AUTO_TEST_CASE(a_lagrangian_in_t_runs_in_the_sode_and_newmark_forms,
                     *boost::unit_test::enable_if<!dvm_tests::kAddressSanitizer>()) {
  const double A = 0.5, w = 2.0, x0 = 1.0, v0 = 0.3, T = 2.0;
  const std::string driven = driven_in_t_scene();
  const std::string forced =
      write_scene("driven_by_force.toml", std::string(kDrivenHead) +
                                              "lagrangian = \"x_dot^2/2 - x^2/2\"\nforces = { x = \"A*cos(w*t)\" }\n" +
                                              kDrivenTail);
  const double K = A / (1.0 - w * w), C = x0 - K, D = v0;
  const double x_exact = C * std::cos(T) + D * std::sin(T) + K * std::cos(w * T);
  const double v_exact = -C * std::sin(T) + D * std::cos(T) - K * w * std::sin(w * T);
  auto error = [&](const Json& j) {
    return std::hypot(vec(j, "q_final")[0] - x_exact, vec(j, "p_final")[0] - v_exact);
  };
  auto run_at = [&](const std::string& path, std::vector<std::string> sets, double h) {
    sets.push_back("integrator.step=" + std::to_string(h));
    const Output o = dvm(with_sets({"run", path, "--json", "--no-output"}, sets));
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    return parse_json(o.out);
  };
  struct Case {
    std::vector<std::string> sets;
    double h, order;
  };
  const std::vector<Case> cases = {
      {{"integrator.form=sode1"}, 0.02, 2.0},
      {{"integrator.form=sode2"}, 0.02, 2.0},
      {{"integrator.form=newmark"}, 0.02, 2.0},
      {{"integrator.form=sode2", "integrator.lift=legendre", "integrator.map=theta", "integrator.theta=0.3",
        "integrator.composition=stormer-verlet"},
       0.02, 2.0},
      {{"integrator.form=sode2", "integrator.composition=triple-jump"}, 0.1, 4.0},
  };
  for (const Case& c : cases) {
    BOOST_TEST_CONTEXT(c.sets.back()) {
      const Json a = run_at(driven, c.sets, c.h), b = run_at(driven, c.sets, c.h / 2);
      BOOST_TEST(a.at("time_dependent").get<bool>());
      const std::string form = c.sets.front().substr(c.sets.front().find('=') + 1);
      BOOST_TEST(a.at("form").get<std::string>() == form);
      const double order = std::log2(error(a) / error(b));
      BOOST_TEST_MESSAGE("driven oscillator in t, " << c.sets.back() << ": errors " << error(a) << ", " << error(b)
                                                    << ", order " << order);
      BOOST_TEST(std::fabs(order - c.order) <= 0.05 * c.order);
      const Json f = run_at(forced, c.sets, c.h / 2);
      BOOST_TEST(std::fabs(vec(b, "q_final")[0] - vec(f, "q_final")[0]) <= 1e-13);
      BOOST_TEST(std::fabs(vec(b, "p_final")[0] - vec(f, "p_final")[0]) <= 1e-13);
    }
  }
}

// The SODE and Newmark forms refuse a Lagrangian in t without a constant, positive
// definite M, naming the form: M = exp(0.1 t), a term linear in x_dot (not separable),
// and M = -1.
BOOST_AUTO_TEST_CASE(the_sode_forms_refuse_a_lagrangian_in_t_without_a_constant_mass) {
  const std::string driven = driven_in_t_scene();
  for (const std::string& lagrangian :
       {std::string("exp(0.1*t)*(x_dot^2 - x^2)/2"), std::string("x_dot*cos(t)*x + x_dot^2/2 - x^2/2"),
        std::string("-x_dot^2/2 + x*cos(t)")}) {
    BOOST_TEST_CONTEXT(lagrangian) {
      const Output o = dvm({"run", driven, "--no-output", "--set", "integrator.form=sode2", "--set",
                            "system.lagrangian=\"" + lagrangian + "\""});
      BOOST_TEST(o.status == 2, o.err);
      BOOST_TEST(o.err.find("integrator.form") != std::string::npos, o.err);
    }
  }
}

// dvm run --linearize on a constrained scene: each step's Jacobian A_k of the
// constrained step (ConstrainedThetaStep::derivative; tests/solvers/test_constrained.cc
// checks it against central differences), 1 + (2n)^2 columns a row. A_k maps onto the
// constraint's cotangent bundle: with the first rows of A_k and the last of A_{k-1} it
// is symplectic there, (A_k A_{k-1})^T J (A_k A_{k-1}) = A_{k-1}^T J A_{k-1}; the same
// for the triple jump of the constrained midpoint, for Lobatto Galerkin s = 3 and for the
// hamiltonian form, whose A_k is the lagrangian form's here (a separable L).
BOOST_AUTO_TEST_CASE(linearize_gives_the_constrained_steps_jacobians) {
  const std::string npy = temp_dir() + "/constrained_A.npy";
  const Output o = dvm({"run", scene("pendulum_cartesian.toml"), "--no-output", "--quiet", "--linearize", npy, "--set",
                        "integrator.t_end=0.05"});
  BOOST_TEST_REQUIRE(o.status == 0, o.err);
  const std::string bytes = slurp(npy);
  const auto header_len = static_cast<std::size_t>(static_cast<unsigned char>(bytes[8]) |
                                                   (static_cast<unsigned char>(bytes[9]) << 8));
  const std::string header = bytes.substr(10, header_len);
  BOOST_TEST(header.find(" 5, 17)") != std::string::npos, header);  // (the row count padded for rewriting)
  std::vector<double> v((bytes.size() - 10 - header_len) / sizeof(double));
  std::memcpy(v.data(), bytes.data() + 10 + header_len, v.size() * sizeof(double));
  BOOST_TEST_REQUIRE(v.size() == 5u * 17u);
  auto A = [&](int k) {
    Eigen::Matrix4d a;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) a(i, j) = v[static_cast<std::size_t>(k * 17 + 1 + 4 * i + j)];
    return a;
  };
  Eigen::Matrix4d J = Eigen::Matrix4d::Zero();
  J.topRightCorner<2, 2>().setIdentity();
  J.bottomLeftCorner<2, 2>() = -Eigen::Matrix2d::Identity();
  for (int k = 1; k < 5; ++k) {
    const Eigen::Matrix4d P = A(k - 1), Q = A(k);
    const Eigen::Matrix4d before = P.transpose() * J * P, after = P.transpose() * Q.transpose() * J * Q * P;
    BOOST_TEST((after - before).cwiseAbs().maxCoeff() <= 1e-12 * before.cwiseAbs().maxCoeff());
  }
  BOOST_TEST(v[17] == 0.01);  // t_1
  // composed (the chain rule over the substeps): the same property
  const Output c = dvm({"run", scene("pendulum_cartesian.toml"), "--no-output", "--quiet", "--linearize", npy, "--set",
                        "integrator.t_end=0.05", "--set", "integrator.composition=\"triple-jump:4\""});
  BOOST_TEST_REQUIRE(c.status == 0, c.err);
  const std::string composed = slurp(npy);
  std::memcpy(v.data(), composed.data() + 10 + header_len, v.size() * sizeof(double));
  for (int k = 1; k < 5; ++k) {
    const Eigen::Matrix4d P = A(k - 1), Q = A(k);
    const Eigen::Matrix4d before = P.transpose() * J * P, after = P.transpose() * Q.transpose() * J * Q * P;
    BOOST_TEST((after - before).cwiseAbs().maxCoeff() <= 1e-12 * before.cwiseAbs().maxCoeff());
  }
  // Lobatto Galerkin under the constraint (ConstrainedGalerkinStep::derivative): the same
  const Output g = dvm({"run", scene("pendulum_cartesian.toml"), "--no-output", "--quiet", "--linearize", npy, "--set",
                        "integrator.t_end=0.05", "--set", "integrator.method=\"galerkin\"", "--set",
                        "integrator.quadrature=\"lobatto\"", "--set", "integrator.stages=3"});
  BOOST_TEST_REQUIRE(g.status == 0, g.err);
  const std::string galerkin = slurp(npy);
  BOOST_TEST_REQUIRE(galerkin.size() == composed.size());
  std::memcpy(v.data(), galerkin.data() + 10 + header_len, v.size() * sizeof(double));
  for (int k = 1; k < 5; ++k) {
    const Eigen::Matrix4d P = A(k - 1), Q = A(k);
    const Eigen::Matrix4d before = P.transpose() * J * P, after = P.transpose() * Q.transpose() * J * Q * P;
    BOOST_TEST((after - before).cwiseAbs().maxCoeff() <= 1e-12 * before.cwiseAbs().maxCoeff());
  }
  // the hamiltonian form (ConstrainedHamiltonianThetaStep::derivative): on this separable
  // Lagrangian the constrained Hamiltonian step is the position-momentum step's map, so
  // the same A_k to the solvers' tolerance, and the same property; plain and composed
  for (const std::string composition : {"none", "triple-jump:4"}) {
    auto values = [&](const std::string& form) {
      const Output r = dvm({"run", scene("pendulum_cartesian.toml"), "--no-output", "--quiet", "--linearize", npy,
                            "--set", "integrator.t_end=0.05", "--set", "integrator.form=\"" + form + "\"", "--set",
                            "integrator.composition=\"" + composition + "\""});
      BOOST_TEST_REQUIRE(r.status == 0, r.err);
      const std::string b = slurp(npy);
      BOOST_TEST_REQUIRE(b.size() == composed.size());
      std::vector<double> out(v.size());
      std::memcpy(out.data(), b.data() + 10 + header_len, out.size() * sizeof(double));
      return out;
    };
    const std::vector<double> lagrangian = values("lagrangian"), hamiltonian = values("hamiltonian");
    double scale = 0.0, diff = 0.0;
    for (std::size_t i = 0; i < v.size(); ++i) {
      scale = std::fmax(scale, std::fabs(lagrangian[i]));
      diff = std::fmax(diff, std::fabs(lagrangian[i] - hamiltonian[i]));
    }
    BOOST_TEST_MESSAGE("hamiltonian form, composition " << composition << ": A_k against the lagrangian form's "
                                                        << diff / scale);
    BOOST_TEST(diff <= 1e-10 * scale, composition);
    v = hamiltonian;
    for (int k = 1; k < 5; ++k) {
      const Eigen::Matrix4d P = A(k - 1), Q = A(k);
      const Eigen::Matrix4d before = P.transpose() * J * P, after = P.transpose() * Q.transpose() * J * Q * P;
      BOOST_TEST((after - before).cwiseAbs().maxCoeff() <= 1e-12 * before.cwiseAbs().maxCoeff(), composition);
    }
  }
}

// A chain of rods in Cartesian coordinates (chain_cartesian.toml: 32 coordinates, 16
// constraints) steps by the sparse constrained step: the dense step's trajectory
// (integrator.use_structure = false) to round-off, plain and composed to order 4, damped
// and driven or not, the same work of the forces, and with --linearize the same A_k;
// a redundant constraint is refused (by the SVD of Dg at 16 rods, by the sparse rank
// heuristic at 2100); and a chain beyond the dense steps' 4096 coordinates runs, damped
// or not.
BOOST_AUTO_TEST_CASE(a_chain_of_rods_steps_on_sparse_matrices) {
  const std::string C = "chain_cartesian.toml";
  auto agree = [&](const std::vector<std::string>& sets) {
    std::vector<std::string> dense_sets = sets;
    dense_sets.push_back("integrator.use_structure=false");
    const Json s = run(C, sets), d = run(C, dense_sets);
    BOOST_TEST(s.at("step_path").get<std::string>() == "constrained-sparse-newton");
    BOOST_TEST(d.at("step_path").get<std::string>() == "generic");
    for (const char* key : {"q_final", "p_final"}) {
      const Eigen::VectorXd a = Eigen::Map<const Eigen::VectorXd>(vec(s, key).data(), 32);
      const Eigen::VectorXd b = Eigen::Map<const Eigen::VectorXd>(vec(d, key).data(), 32);
      BOOST_TEST_MESSAGE(sets.front() << ": " << key << " sparse against dense "
                                      << (a - b).lpNorm<Eigen::Infinity>() / b.lpNorm<Eigen::Infinity>());
      BOOST_TEST((a - b).lpNorm<Eigen::Infinity>() <= 1e-11 * b.lpNorm<Eigen::Infinity>());
    }
    if (s.contains("work")) {
      const double ws = s.at("work").get<double>(), wd = d.at("work").get<double>();
      BOOST_TEST(std::fabs(ws - wd) <= 1e-11 * std::fabs(wd));
    }
    BOOST_TEST(s.at("max_constraint_residual").get<double>() <= 1e-14);
    BOOST_TEST(s.at("max_hidden_constraint_residual").get<double>() <= 1e-12);
    return s;
  };
  const Json plain = agree({"integrator.t_end=0.5"});
  // the chain has fallen and folded: not the state it started from
  BOOST_TEST(vec(plain, "q_final")[0] < 0.03);
  agree({"integrator.t_end=0.5", "integrator.composition=\"triple-jump:4\""});
  agree({"integrator.t_end=0.5", "integrator.map=\"theta\"", "integrator.theta=0.3"});
  // damped and driven: a damper on two joints, one between joints, a drive in t
  const std::string forces = "system.forces={ \"x[3]\" = \"-0.1*x_dot[3]\", \"y[5]\" = \"-0.2*y_dot[5] - "
                             "0.3*(y_dot[5] - y_dot[6])\", \"y[6]\" = \"0.3*(y_dot[5] - y_dot[6])\", "
                             "\"x[16]\" = \"0.05*sin(4*t)\" }";
  const Json forced = agree({"integrator.t_end=0.5", forces});
  BOOST_TEST(forced.at("work").get<double>() != 0.0);
  agree({"integrator.t_end=0.5", forces, "integrator.composition=\"triple-jump:4\""});
  // with --linearize, damped and driven: the sparse step's derivatives A_k, the dense
  // step's to round-off (tests/solvers/test_sparse_constrained.cc compares the two steps'
  // derivatives with a control input and against central differences)
  const std::string npy = temp_dir() + "/chain_A.npy", npy_dense = temp_dir() + "/chain_A_dense.npy";
  auto linearized = [&](const std::string& path, const std::vector<std::string>& sets) {
    const Output o = dvm(with_sets({"run", scene(C), "--no-output", "--json", "--linearize", path}, sets));
    BOOST_TEST_REQUIRE(o.status == 0, o.err);
    return parse_json(o.out).at("step_path").get<std::string>();
  };
  BOOST_TEST(linearized(npy, {"integrator.t_end=0.003", forces}) == "constrained-sparse-newton");
  BOOST_TEST(linearized(npy_dense, {"integrator.t_end=0.003", forces, "integrator.use_structure=false"}) == "generic");
  const std::string sparse_bytes = slurp(npy), dense_bytes = slurp(npy_dense);
  BOOST_TEST_REQUIRE(sparse_bytes.size() == dense_bytes.size());
  const std::size_t hlen =
      static_cast<unsigned char>(sparse_bytes[8]) + 256u * static_cast<unsigned char>(sparse_bytes[9]);
  const std::size_t count = (sparse_bytes.size() - 10 - hlen) / sizeof(double);
  BOOST_TEST_REQUIRE(count == 3u * (1u + 64u * 64u));  // 3 steps: t_k and A_k (64 x 64)
  std::vector<double> As(count), Ad(count);
  std::memcpy(As.data(), sparse_bytes.data() + 10 + hlen, count * sizeof(double));
  std::memcpy(Ad.data(), dense_bytes.data() + 10 + hlen, count * sizeof(double));
  double diff = 0.0, size = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    diff = std::fmax(diff, std::fabs(As[i] - Ad[i]));
    size = std::fmax(size, std::fabs(Ad[i]));
  }
  BOOST_TEST_MESSAGE("--linearize: sparse A_k against dense " << diff / size);
  BOOST_TEST(diff <= 1e-11 * size);
  // the first rod written twice: Dg rank-deficient
  std::string constraints = "system.constraints=[\"x[1]^2 + y[1]^2 - l^2\"";
  for (int i = 1; i <= 16; ++i)
    constraints += i == 1 ? ", \"x[1]^2 + y[1]^2 - l^2\""
                          : ", \"(x[" + std::to_string(i) + "] - x[" + std::to_string(i - 1) + "])^2 + (y[" +
                                std::to_string(i) + "] - y[" + std::to_string(i - 1) + "])^2 - l^2\"";
  const Output r = dvm(with_sets({"run", scene(C), "--no-output"}, {constraints + "]"}));
  BOOST_TEST(r.status == 2);
  BOOST_TEST(r.err.find("system.constraints") != std::string::npos, r.err);
  BOOST_TEST(r.err.find("rank 16") != std::string::npos, r.err);
  BOOST_TEST(r.err.find("expected 17") != std::string::npos, r.err);
  // 2100 rods, 4200 coordinates: beyond what the dense steps take, two steps
  const int k = 2100;
  std::string list = "\"x[1]^2 + y[1]^2 - l^2\"";
  for (int i = 2; i <= k; ++i)
    list += ", \"(x[" + std::to_string(i) + "] - x[" + std::to_string(i - 1) + "])^2 + (y[" + std::to_string(i) +
            "] - y[" + std::to_string(i - 1) + "])^2 - l^2\"";
  std::string q0 = "", x0 = "";
  auto num = [](double a) {
    std::ostringstream o;
    o.precision(17);
    o << a;
    return o.str();
  };
  for (int i = 1; i <= k; ++i) {  // x[1..k], then y[1..k]: every rod at 0.5 rad from the vertical
    q0 += (i > 1 ? ", " : "") + num(i * 0.1 * std::sin(0.5));
    x0 += ", " + num(-i * 0.1 * std::cos(0.5));
  }
  auto big_chain = [&](const std::string& name, const std::string& constraints) {
    return write_scene(name, "[system]\ncoordinates = [\"x[n]\", \"y[n]\"]\nparams = { n = " + std::to_string(k) +
                                 ", m = 0.1, l = 0.1, g = 9.81 }\nlagrangian = \"sum(i, 1, n, m/2*(x_dot[i]^2 + "
                                 "y_dot[i]^2) - m*g*y[i])\"\nconstraints = [" + constraints +
                                 "]\n[initial]\nq = [" + q0 + x0 + "]\nv = \"0\"\n"
                                 "[integrator]\nmap = \"midpoint\"\nstep = 1e-3\nt_end = 2e-3\n");
  };
  const std::string big = big_chain("chain_2100.toml", list);
  // its first rod twice (times 2): beyond the SVD's size, the sparse rank check
  const Output twice = dvm({"run", big_chain("chain_2100_twice.toml", list + ", \"2*(x[1]^2 + y[1]^2 - l^2)\""),
                            "--no-output"});
  BOOST_TEST(twice.status == 2);
  BOOST_TEST(twice.err.find("expected 2101") != std::string::npos, twice.err);
  BOOST_TEST(twice.err.find("sparse LDL^T") != std::string::npos, twice.err);
  // in less address space than one 4200 x 4200 matrix of doubles (134 MiB): the sparse
  // step and the run around it form no dense one
  const Output b = dvm_within(134, {"run", big, "--json", "--no-output"});
  BOOST_TEST_REQUIRE(b.status == 0, b.err);
  const Json bj = parse_json(b.out);
  BOOST_TEST(bj.at("step_path").get<std::string>() == "constrained-sparse-newton");
  BOOST_TEST(bj.at("max_constraint_residual").get<double>() <= 1e-14);
  // damped at its free end too (before, a force sent it to the dense step, which refused it)
  const Output bf = dvm({"run", big, "--json", "--no-output", "--set",
                         "system.forces={ \"x[2100]\" = \"-0.1*x_dot[2100]\", \"y[2100]\" = \"-0.1*y_dot[2100]\" }"});
  BOOST_TEST_REQUIRE(bf.status == 0, bf.err);
  const Json bfj = parse_json(bf.out);
  BOOST_TEST(bfj.at("step_path").get<std::string>() == "constrained-sparse-newton");
  BOOST_TEST(bfj.at("max_constraint_residual").get<double>() <= 1e-14);
  // and the dense step refuses it, naming the sparse one
  const Output bd = dvm({"run", big, "--no-output", "--set", "integrator.use_structure=false"});
  BOOST_TEST(bd.status == 2);
  BOOST_TEST(bd.err.find("sparse constrained step") != std::string::npos, bd.err);
}
