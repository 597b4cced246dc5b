// The states of a run, step by step, and how far two such runs are apart: the
// comparisons of one step type against another (the same method by two classes).
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <boost/test/unit_test.hpp>

#include "solvers/integrate.h"

namespace dvm_test {

// (q, p) after every step of `integrate`, one vector per step; the run's summary in
// *summary where given. A failed run fails the test.
template <class Step, class V>
std::vector<Eigen::VectorXd> trajectory(const Step& S, V q, V p, const V& v0, int steps,
                                        dvm::RunSummary* summary = nullptr) {
  std::vector<Eigen::VectorXd> out;
  const dvm::RunSummary run = dvm::integrate(
      S, 0.0, q, p, v0, steps, [&](std::int64_t, double, const auto& qk, const auto& pk, const dvm::StepSummary&) {
        Eigen::VectorXd y(2 * qk.size());
        y << qk, pk;
        out.push_back(y);
      });
  if (summary) *summary = run;
  BOOST_TEST(!run.failed, run.failure.message);
  return out;
}

// The largest difference between two trajectories, relative to the largest state of b
// (logged: the measured values behind the tolerances of the comparisons).
inline double trajectory_difference(const std::vector<Eigen::VectorXd>& a, const std::vector<Eigen::VectorXd>& b) {
  BOOST_REQUIRE(a.size() == b.size());
  double d = 0.0, s = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    d = std::fmax(d, (a[k] - b[k]).cwiseAbs().maxCoeff());
    s = std::fmax(s, b[k].cwiseAbs().maxCoeff());
  }
  BOOST_TEST_MESSAGE("  trajectory difference " << d / s);
  return d / s;
}

}  // namespace dvm_test
