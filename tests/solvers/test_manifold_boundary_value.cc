// Whole-trajectory problems on S^2 and (S^2)^2 with Ceres' SphereManifold
// (solvers/manifold_boundary_value.h): the boundary-value solution between the two
// ends of a shot trajectory is that trajectory, with its momenta.
#define BOOST_TEST_MODULE manifold_boundary_value
#include <boost/test/unit_test.hpp>

#include "solvers/manifold_boundary_value.h"
#include "solvers/manifold_step.h"

using namespace dvm;

namespace {

template <class System, class Map>
std::vector<typename Map::Manifold::template Point<double>> shoot(
    const System& L, const Map& R, double h, int K, typename Map::Manifold::template Point<double> q,
    typename Map::Manifold::template Tangent<double> p) {
  using P = typename Map::Manifold::template Point<double>;
  const ManifoldStep<System, Map> S(L, R, h);
  std::vector<P> traj{q};
  const auto v0 = manifold_legendre_inverse(L, q, p);
  const RunSummary run = integrate(S, 0.0, q, p, v0, K, [&](std::int64_t, double, const P& qk, const auto&,
                                                                     const StepSummary&) { traj.push_back(qk); });
  BOOST_REQUIRE(!run.failed);
  return traj;
}

}  // namespace

BOOST_AUTO_TEST_CASE(spherical_pendulum_boundary_value_reproduces_the_shot_trajectory) {
  using V3 = Vec<double, 3>;
  const SphericalPendulum P(1.0, 1.0, 9.81);
  const double h = 0.01;
  const int K = 100;  // t = 1, well short of a conjugate point
  const V3 q0 = V3(0.6, 0.0, -0.8);
  const V3 p0(0.0, 1.5, 0.0);
  for (const SphereMap& R : {SphereMap(RetractionKind::exp, 0.5, "sphere-exp"),
                             SphereMap(RetractionKind::projection, 0.5, "sphere-projection"),
                             SphereMap(RetractionKind::projection, 0.0, "sphere-projection-fixed")}) {
    const auto traj = shoot(P, R, h, K, q0, p0);
    const SphereBoundaryValueProblem<SphericalPendulum, SphereMap> B(P, R, h);
    const auto res = B.solve(traj.front(), traj.back(), K);
    BOOST_TEST_CONTEXT(R.name()) {
      BOOST_TEST(res.converged, res.message);
      double dev = 0.0, defect = 0.0;
      for (int k = 0; k <= K; ++k) {
        dev = std::fmax(dev, max_abs(V3(res.q[k] - traj[k])));
        defect = std::fmax(defect, Sphere::point_defect(res.q[k]));
      }
      BOOST_TEST_MESSAGE(R.name() << ": max |q_bvp - q_shot| " << dev << ", |p_0 - p0| "
                                  << max_abs(V3(res.p[0] - p0)) << ", DEL residual " << res.max_residual
                                  << " (scale " << res.scale << "), iterations " << res.iterations
                                  << ", max ||q| - 1| " << defect);
      BOOST_TEST(dev <= 1e-11);
      BOOST_TEST(max_abs(V3(res.p[0] - p0)) <= 1e-9);
      BOOST_TEST(defect <= 1e-15);
    }
  }
}

BOOST_AUTO_TEST_CASE(double_spherical_pendulum_boundary_value) {
  // (S^2)^2 with ceres::ProductManifold of two SphereManifolds.
  using V6 = Vec<double, 6>;
  const SphericalChain<2> L(Vec<double, 2>(1.0, 1.0), Vec<double, 2>(1.0, 1.0), 9.81);
  const SpherePowerMap<2> R(SphereMap(RetractionKind::exp, 0.5, "sphere-exp"));
  const double h = 0.01;
  const int K = 60;
  V6 q0;
  q0 << 0.6, 0.0, -0.8, 0.0, 0.6, -0.8;
  const V6 v0 = (V6() << 0.0, 1.0, 0.0, -1.0, 0.0, 0.0).finished();
  const V6 p0 = manifold_legendre(L, q0, v0);
  const auto traj = shoot(L, R, h, K, q0, p0);
  const SphereBoundaryValueProblem<SphericalChain<2>, SpherePowerMap<2>> B(L, R, h);
  const auto res = B.solve(traj.front(), traj.back(), K);
  BOOST_TEST(res.converged, res.message);
  double dev = 0.0;
  for (int k = 0; k <= K; ++k) dev = std::fmax(dev, max_abs(V6(res.q[k] - traj[k])));
  BOOST_TEST_MESSAGE("(S^2)^2: max |q_bvp - q_shot| " << dev << ", |p_0 - p0| " << max_abs(V6(res.p[0] - p0))
                                                      << ", iterations " << res.iterations);
  BOOST_TEST(dev <= 1e-11);
  BOOST_TEST(max_abs(V6(res.p[0] - p0)) <= 1e-9);
}
