// The integrate loop stops at the first faulty step (solvers/integrate.h): a solve
// that did not converge, a step that would make the state non-finite, a step or an
// observer that throws std::domain_error. The run reports the step index, the time
// and why, and returns the last good state.
#define BOOST_TEST_MODULE integrate_faults
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <limits>
#include <stdexcept>

#include "solvers/integrate.h"

namespace {

using dvm::StepSummary;
using V = dvm::Vec<double, 2>;

// q_{k+1} = growth * q_k, p unchanged; at step `throw_at` it throws a domain error.
struct ScalingStep {
  static constexpr int N = 2;
  double growth = 10.0;
  std::int64_t throw_at = -1;
  mutable std::int64_t calls = 0;
  double step_size() const { return 0.5; }
  StepSummary step(double /*t*/, const V& q, const V& p, V& dq, V& dp) const {
    if (calls++ == throw_at) throw std::domain_error("outside the domain of the map");
    dq = (growth - 1.0) * q;
    dp = V::Zero();
    (void)p;
    StepSummary s;
    s.converged = true;
    s.iterations = 1;
    s.residual = 0.0;
    s.scale = 1.0;
    return s;
  }
};

}  // namespace

BOOST_AUTO_TEST_CASE(a_state_that_would_overflow_stops_the_run_at_that_step) {
  // 1 * 10^k overflows after 10^308: step k = 308 (from q = 1e308) is the first that
  // would give inf
  ScalingStep S;
  V q(1.0, -1.0), p(0.0, 0.0);
  const dvm::RunSummary run = dvm::integrate(S, 0.0, q, p, V::Zero(), 1000, [](auto&&...) {});
  BOOST_TEST(run.failed);
  BOOST_TEST(run.failed_step == 308);
  BOOST_TEST(run.steps_done == 308);
  BOOST_TEST(run.failed_time == 308 * 0.5);
  BOOST_TEST(run.failure.message.find("non-finite") != std::string::npos);
  BOOST_TEST(q.allFinite());
  BOOST_TEST(q[0] == 1e308, boost::test_tools::tolerance(1e-12));
}

BOOST_AUTO_TEST_CASE(a_domain_error_in_the_step_or_the_observer_stops_the_run) {
  ScalingStep S;
  S.growth = 1.0;
  S.throw_at = 7;
  V q(1.0, 2.0), p(3.0, 4.0);
  const dvm::RunSummary a = dvm::integrate(S, 1.0, q, p, V::Zero(), 100, [](auto&&...) {});
  BOOST_TEST(a.failed);
  BOOST_TEST(a.failed_step == 7);
  BOOST_TEST(a.failed_time == 1.0 + 7 * 0.5);
  BOOST_TEST(a.failure.message == "outside the domain of the map");
  BOOST_TEST(a.steps_done == 7);

  // the observer cannot evaluate the state reached by step 4 (k = 5 after it)
  ScalingStep T;
  T.growth = 1.0;
  int seen = 0;
  const dvm::RunSummary b = dvm::integrate(T, 0.0, q, p, V::Zero(), 100, [&](std::int64_t k, auto&&...) {
    ++seen;
    if (k == 5) throw std::domain_error("degenerate Legendre transform");
  });
  BOOST_TEST(b.failed);
  BOOST_TEST(b.failed_step == 4);
  BOOST_TEST(b.steps_done == 5);  // step 4 completed; the state it reached is returned
  BOOST_TEST(seen == 5);
  BOOST_TEST(b.failure.message.find("degenerate Legendre transform") != std::string::npos);
  // other exceptions are not numerical faults: they pass through
  ScalingStep U;
  U.growth = 1.0;
  BOOST_CHECK_THROW(dvm::integrate(U, 0.0, q, p, V::Zero(), 10, [](auto&&...) { throw std::logic_error("bug"); }),
                    std::logic_error);
}

BOOST_AUTO_TEST_CASE(a_non_finite_residual_is_named_in_the_failure) {
  dvm::RunSummary run;
  StepSummary s;
  s.iterations = 25;
  s.residual = std::numeric_limits<double>::quiet_NaN();
  s.message = "no convergence within 25 iterations";
  BOOST_TEST(!run.record(s, 3, 0.0, 0.1));
  BOOST_TEST(run.failed_step == 3);
  BOOST_TEST(run.failure.message.find("not finite") != std::string::npos);
  BOOST_TEST(run.failure.message.find("no convergence within 25 iterations") != std::string::npos);
}
