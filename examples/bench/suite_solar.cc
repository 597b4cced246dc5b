// Work-precision sweep of the outer solar system (GNI Sec. I.2.4, Table 2.1; data of
// examples/scenes/outer_solar_system.toml): six bodies in R^3, units of solar masses,
// AU and days. Error in the positions after T = 20000 days (about 55 years), against a
// reference computed twice (see suite.h).
#include "examples/bench/suite.h"

namespace dvm::bench {

ProblemResult run_outer_solar_system(const SuiteConfig& c) {
  using Sys = NBody<6>;
  using V = Vec<double, Sys::dim>;
  const Sys sys(2.95912208286e-4, {1.00000597682, 0.000954786104043, 0.000285583733151, 0.0000437273164546,
                                   0.0000517759138449, 1.0 / 1.3e8});
  V q0, v0;
  q0 << 0.0, 0.0, 0.0, -3.5023653, -3.8169847, -1.5507963, 9.0755314, -3.0458353, -1.6483708, 8.3101420,
      -16.2901086, -7.2521278, 11.4707666, -25.7294829, -10.8169456, -15.5387357, -25.2225594, -3.1902382;
  v0 << 0.0, 0.0, 0.0, 0.00565429, -0.00412490, -0.00190589, 0.00168318, 0.00483525, 0.00192462, 0.00354178,
      0.00137102, 0.00055029, 0.00288930, 0.00114527, 0.00039677, 0.00276725, -0.00170702, -0.00136504;
  V p0;
  for (int i = 0; i < 6; ++i)
    for (int a = 0; a < 3; ++a) p0[3 * i + a] = sys.m(i) * v0[3 * i + a];
  std::vector<std::int64_t> n;
  for (int k = 0; k < (c.tiny ? 2 : 7); ++k) n.push_back((c.tiny ? 10 : 100) << k);
  Problem<Sys> P{"outer-solar-system", sys, q0, p0, c.tiny ? 1000.0 : 20000.0, n, {}, {}, {}, {}};
  ProblemResult out;
  out.reference_agreement = reference(P, c.tiny ? 40 : 4000, c.tiny ? 400 : 40000);
  std::vector<Method<Sys>> m = dvm_methods<Sys>(true);
  for (auto& x : peer_methods<Sys>()) m.push_back(std::move(x));
  out.rows = sweep(P, m, c.sweep);
  out.problem = P.name;
  out.reference_note = P.reference_note;
  return out;
}

}  // namespace dvm::bench
