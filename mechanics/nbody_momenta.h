// Total momentum and total angular momentum of point masses in R^3, shared by the
// fixed-size NBody<B> (systems_classic.h) and the run-time-sized NBodyDynamic
// (nbody_dynamic.h).
#pragma once

#include <array>

namespace dvm {

// q and p stack the bodies' positions and momenta (3 entries a body); returns the
// total momentum (3) and the total angular momentum sum q_i x p_i (3).
inline std::array<double, 6> nbody_momenta(const double* q, const double* p, int bodies) {
  std::array<double, 6> out{};
  for (int i = 0; i < bodies; ++i) {
    const double* x = q + 3 * i;
    const double* y = p + 3 * i;
    out[0] += y[0];
    out[1] += y[1];
    out[2] += y[2];
    out[3] += x[1] * y[2] - x[2] * y[1];
    out[4] += x[2] * y[0] - x[0] * y[2];
    out[5] += x[0] * y[1] - x[1] * y[0];
  }
  return out;
}

}  // namespace dvm
