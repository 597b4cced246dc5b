// Work-precision sweeps of Henon-Heiles (chaotic regime, energy 1/8; GNI Sec. I.3)
// and of the Fermi-Pasta-Ulam chain (omega = 50; GNI Sec. I.5.1). No exact flow:
// the reference is computed twice (see suite.h).
#include "examples/bench/suite.h"

namespace dvm::bench {

namespace {
std::vector<std::int64_t> doubling(std::int64_t first, int count) {
  std::vector<std::int64_t> n;
  for (int k = 0; k < count; ++k) n.push_back(first << k);
  return n;
}
}  // namespace

ProblemResult run_henon_heiles(const SuiteConfig& c) {
  using V = Vec<double, 2>;
  // examples/scenes/henon_heiles.toml: H = 1/8, (x, y) = (0, 0.1), p_y = 0.2
  Problem<HenonHeiles> P{"henon-heiles", HenonHeiles(1.0), V(0.0, 0.1), V(0.4479583313955291, 0.2),
                         c.tiny ? 2.0 : 20.0, c.tiny ? doubling(20, 2) : doubling(50, 10), {}, {}, {}, {}};
  ProblemResult out;
  out.reference_agreement = reference(P, c.tiny ? 400 : 4000, c.tiny ? 2000 : 40000);
  std::vector<Method<HenonHeiles>> m = dvm_methods<HenonHeiles>(false);
  for (auto& x : peer_methods<HenonHeiles>()) m.push_back(std::move(x));
  out.rows = sweep(P, m, c.sweep);
  out.problem = P.name;
  out.reference_note = P.reference_note;
  return out;
}

ProblemResult run_fpu(const SuiteConfig& c) {
  using V = Vec<double, 6>;
  // examples/scenes/fpu.toml (GNI's initial values)
  V q0, p0;
  q0 << 0.6929646455628166, 0.7212489168102785, 0.0, 0.0, 0.0, 0.0;
  p0 << 0.0, 1.4142135623730951, 0.0, 0.0, 0.0, 0.0;
  Problem<FermiPastaUlam> P{"fpu", FermiPastaUlam(50.0), q0, p0, c.tiny ? 0.2 : 10.0,
                            c.tiny ? doubling(40, 2) : doubling(250, 9), {}, {}, {}, {}};
  ProblemResult out;
  out.reference_agreement = reference(P, c.tiny ? 200 : 20000, c.tiny ? 2000 : 100000);
  std::vector<Method<FermiPastaUlam>> m = dvm_methods<FermiPastaUlam>(true);
  for (auto& x : peer_methods<FermiPastaUlam>()) m.push_back(std::move(x));
  out.rows = sweep(P, m, c.sweep);
  out.problem = P.name;
  out.reference_note = P.reference_note;
  return out;
}

}  // namespace dvm::bench
