// Work-precision sweep of the Kepler problem, eccentricity 0.6, initial data of
// Hairer-Lubich-Wanner (GNI Sec. I.2): q0 = (1 - e, 0), p0 = (0, sqrt((1 + e)/(1 - e))),
// error at T = 20 (a little over three periods of 2 pi) against the exact flow.
// Hand-written implicit midpoint is the cost floor of the midpoint equations.
#include "examples/bench/suite.h"

namespace dvm::bench {

std::vector<Method<Kepler>> kepler_methods() {
  using V = Vec<double, 2>;
  std::vector<Method<Kepler>> m = dvm_methods<Kepler>(false);
  for (auto& x : peer_methods<Kepler>()) m.push_back(std::move(x));
  m.push_back({"hand implicit midpoint (Newton)", "hand", 2, true, true,
               [](const Problem<Kepler>& Q, double h, std::int64_t steps,
                  const StateObserver<2>* track) {
                 V q = Q.q0, p = Q.p0;
                 ObserverCall<Kepler> E(Q.sys, q, p, track);
                 const std::int64_t it =
                     hand_midpoint_kepler(Q.sys, q, p, h, steps, [&E](const V& a, const V& b) { E(a, b); });
                 return Outcome<2>{q, p, it >= 0};
               }});
  return m;
}

Problem<Kepler> kepler_problem(double t_end, std::vector<std::int64_t> steps) {
  using V = Vec<double, 2>;
  const double e = 0.6;
  Problem<Kepler> P{"kepler", Kepler(1.0), V(1.0 - e, 0.0), V(0.0, std::sqrt((1.0 + e) / (1.0 - e))), t_end,
                    std::move(steps), {}, {}, {}, {}};
  const Kepler sys = P.sys;
  P.exact = [sys](double t, const V& q0, const V& p0, V& q, V& p) { sys.exact(t, q0, p0, q, p); };
  reference(P, 0, 0);
  return P;
}

ProblemResult run_kepler(const SuiteConfig& c) {
  std::vector<std::int64_t> n;
  for (int k = 0; k < (c.tiny ? 2 : 12); ++k) n.push_back((c.tiny ? 40 : 25) << k);
  Problem<Kepler> P = kepler_problem(c.tiny ? 2.0 : 20.0, n);
  ProblemResult out;
  out.rows = sweep(P, kepler_methods(), c.sweep);
  out.problem = P.name;
  out.reference_note = P.reference_note;
  return out;
}

}  // namespace dvm::bench
