// What the suites of the structured steps (tests/solvers/test_splitting.cc,
// tests/solvers/test_sparse_separable.cc) share: a run through the runtime, the
// distances they compare final states by, and the implicit theta maps the structured
// Newton steps are checked with.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "solvers/runtime/problem.h"
#include "solvers/runtime/registry.h"
#include "solvers/runtime/run.h"

inline dvm::RunReport run(const dvm::Problem& pr, const dvm::Method& me) {
  return dvm::make_run(pr, me)->execute(nullptr);
}

// The largest |a_i - b_i| (infinite for vectors of other or no size), and the largest |a_i|.
inline double max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.empty()) return INFINITY;
  double d = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
  return d;
}
inline double max_abs(const std::vector<double>& a) {
  double d = 0.0;
  for (double x : a) d = std::fmax(d, std::fabs(x));
  return d;
}

// The implicit theta maps: theta 1/2 (midpoint), 0.3 and 0.7, each alone, composed
// (triple-jump, kahan-li6), as a DIRK (weights 0.3, 0.4, 0.3) and as a DIRK with a theta
// per stage (0.2, theta, 0.8): 15 methods.

inline std::vector<dvm::Method> implicit_theta_methods() {
  std::vector<dvm::Method> methods;
  for (double th : {0.5, 0.3, 0.7})
    for (const char* c : {"none", "triple-jump", "kahan-li6", "dirk", "dirk-thetas"}) {
      dvm::Method me;
      const std::string comp = c;
      me.map = &dvm::find_map_entry(th == 0.5 && comp != "dirk-thetas" ? "midpoint" : "theta", "test");
      me.theta = th;
      me.composition = comp == "dirk-thetas" ? "dirk" : comp;
      if (me.composition == "dirk") me.weights = {0.3, 0.4, 0.3};
      if (comp == "dirk-thetas") {
        me.thetas = {0.2, th, 0.8};
        me.theta = me.map->theta;
      }
      methods.push_back(me);
    }
  return methods;
}
