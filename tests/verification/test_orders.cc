// Measured orders of convergence: log-log fit of the global error at the fixed time
// t = 1 against h (not a full period, where closed orbits flatter some methods).
// Expected: 2 for symmetric maps (midpoint), 1 for all others (Euler maps, theta != 1/2).
#include <boost/test/unit_test.hpp>

#include "tests/verification/common.h"

using namespace dvm;
using namespace dvm::verification;

namespace {

const std::vector<double> kSteps = {0.1, 0.05, 0.025, 0.0125, 0.00625};
const double kEnd = 1.0;

template <class Map>
double harmonic_order(const Map& R) {
  const HarmonicOscillator L(1.5);
  const Vec<double, 1> q0(0.8), p0(0.3);
  Vec<double, 1> qe, pe;
  L.exact(kEnd, q0, p0, qe, pe);
  std::vector<double> errs;
  for (double h : kSteps) {
    const auto [q, p] = run(L, R, h, std::llround(kEnd / h), q0, p0);
    errs.push_back(std::fmax(max_abs(q - qe), max_abs(p - pe)));
  }
  return fit_order(kSteps, errs);
}

template <class Map>
double pendulum_order(const Map& R, StepOptions opt = {}) {
  const Pendulum L(1.0, 1.0, 1.0);
  const Vec<double, 1> q0(2.0), p0(0.0);  // a large, strongly nonlinear swing
  double qr, pr;
  pendulum_reference(L, kEnd, q0[0], p0[0], qr, pr);
  std::vector<double> errs;
  for (double h : kSteps) {
    const auto [q, p] = run(L, R, h, std::llround(kEnd / h), q0, p0, opt);
    errs.push_back(std::fmax(std::fabs(q[0] - qr), std::fabs(p[0] - pr)));
  }
  return fit_order(kSteps, errs);
}

template <class System, class Map>
double kepler_order(const System& L, const Map& R) {
  Vec<double, 2> q0, p0, qe, pe;
  kepler_initial(0.6, q0, p0);
  Kepler().exact(kEnd, q0, p0, qe, pe);
  std::vector<double> errs;
  for (double h : kSteps) {
    const auto [q, p] = run(L, R, h / 4, std::llround(kEnd / (h / 4)), q0, p0);
    errs.push_back(std::fmax(max_abs(q - qe), max_abs(p - pe)));
  }
  return fit_order(kSteps, errs);
}

}  // namespace

BOOST_AUTO_TEST_CASE(orders_of_the_theta_maps) {
  struct Case {
    ThetaMap map;
    double order;
  };
  const std::vector<Case> cases = {{ThetaMap::midpoint(), 2.0},      {ThetaMap::explicit_euler(), 1.0},
                                   {ThetaMap::adjoint_euler(), 1.0}, {ThetaMap(0.3), 1.0},
                                   {ThetaMap(0.7), 1.0}};
  for (const auto& c : cases) {
    BOOST_TEST_CONTEXT(c.map.name() << " theta=" << c.map.theta()) {
      const double a = harmonic_order(c.map), b = pendulum_order(c.map), k = kepler_order(Kepler(), c.map);
      BOOST_TEST_MESSAGE(c.map.name() << " theta=" << c.map.theta() << ": harmonic " << a << ", pendulum " << b
                                      << ", kepler " << k);
      BOOST_TEST(std::fabs(a - c.order) <= 0.1);
      BOOST_TEST(std::fabs(b - c.order) <= 0.1);
      BOOST_TEST(std::fabs(k - c.order) <= 0.1);
    }
  }
}

BOOST_AUTO_TEST_CASE(orders_through_the_generic_path) {
  // The Prop. 2.3 map of the flat retraction, inverted by Newton, with the
  // Lagrangian differentiated by automatic differentiation only.
  const GenericOnly<Kepler> K{Kepler()};
  BOOST_TEST(std::fabs(kepler_order(K, RetractionMap<EuclideanRetraction>({}, 0.5)) - 2.0) <= 0.1);
  BOOST_TEST(std::fabs(kepler_order(K, RetractionMap<EuclideanRetraction>({}, 0.2)) - 1.0) <= 0.1);
  // and the adjoint of explicit Euler built generically is adjoint Euler: order 1
  BOOST_TEST(std::fabs(pendulum_order(adjoint(ThetaMap::explicit_euler())) - 1.0) <= 0.1);
  StepOptions tiny;
  tiny.solver = SolverKind::tiny;
  BOOST_TEST(std::fabs(pendulum_order(ThetaMap::midpoint(), tiny) - 2.0) <= 0.1);
}
