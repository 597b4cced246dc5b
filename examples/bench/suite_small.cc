// Work-precision sweeps of the one-degree-of-freedom problems: the harmonic oscillator
// (exact flow) and the pendulum (reference computed; hand-written implicit midpoint
// as the cost floor of the same equations).
#include "examples/bench/suite.h"

namespace dvm::bench {

namespace {
std::vector<std::int64_t> doubling(std::int64_t first, int count) {
  std::vector<std::int64_t> n;
  for (int k = 0; k < count; ++k) n.push_back(first << k);
  return n;
}
}  // namespace

std::vector<Method<HarmonicOscillator>> harmonic_methods() {
  std::vector<Method<HarmonicOscillator>> m = dvm_methods<HarmonicOscillator>(false);
  for (auto& x : peer_methods<HarmonicOscillator>()) m.push_back(std::move(x));
  return m;
}

std::vector<Method<Pendulum>> pendulum_methods() {
  using V = Vec<double, 1>;
  std::vector<Method<Pendulum>> m = dvm_methods<Pendulum>(false);
  for (auto& x : peer_methods<Pendulum>()) m.push_back(std::move(x));
  m.push_back({"hand implicit midpoint (Newton)", "hand", 2, true, true,
               [](const Problem<Pendulum>& Q, double h, std::int64_t steps, const StateObserver<1>* track) {
                 double q = Q.q0[0], p = Q.p0[0];
                 ObserverCall<Pendulum> E(Q.sys, Q.q0, Q.p0, track);
                 const std::int64_t it = hand_midpoint_pendulum(Q.sys, q, p, h, steps, [&E](double a, double b) {
                   E(V(a), V(b));
                 });
                 return Outcome<1>{V(q), V(p), it >= 0};
               }});
  return m;
}

ProblemResult run_harmonic(const SuiteConfig& c) {
  using V = Vec<double, 1>;
  Problem<HarmonicOscillator> P{"harmonic", HarmonicOscillator(1.0), V(1.0), V(0.0), c.tiny ? 2.0 : 20.0,
                                c.tiny ? doubling(20, 2) : doubling(50, 11), {}, {}, {}, {}};
  const HarmonicOscillator sys = P.sys;
  P.exact = [sys](double t, const V& q0, const V& p0, V& q, V& p) { sys.exact(t, q0, p0, q, p); };
  ProblemResult out;
  out.reference_agreement = reference(P, 0, 0);
  out.rows = sweep(P, harmonic_methods(), c.sweep);
  out.problem = P.name;
  out.reference_note = P.reference_note;
  return out;
}

ProblemResult run_pendulum(const SuiteConfig& c) {
  using V = Vec<double, 1>;
  Problem<Pendulum> P{"pendulum", Pendulum(1.0, 1.0, 1.0), V(2.0), V(0.0), c.tiny ? 2.0 : 20.0,
                      c.tiny ? doubling(20, 2) : doubling(50, 11), {}, {}, {}, {}};
  ProblemResult out;
  out.reference_agreement = reference(P, c.tiny ? 400 : 4000, c.tiny ? 2000 : 40000);
  out.rows = sweep(P, pendulum_methods(), c.sweep);
  out.problem = P.name;
  out.reference_note = P.reference_note;
  return out;
}

}  // namespace dvm::bench
