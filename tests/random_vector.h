// A vector of n entries drawn uniformly from [-scale, scale], the same for the same seed:
// the pseudo-random states and directions of the suites that check derivatives and steps
// on systems of run-time size.
#pragma once

#include <Eigen/Core>
#include <random>

inline Eigen::VectorXd random_vector(int n, double scale, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  Eigen::VectorXd x(n);
  for (int i = 0; i < n; ++i) x[i] = scale * U(rng);
  return x;
}
