// The implicit theta maps the structured Newton steps are checked with: theta 1/2
// (midpoint), 0.3 and 0.7, each alone, composed (triple-jump, kahan-li6), as a DIRK
// (weights 0.3, 0.4, 0.3) and as a DIRK with a theta per stage (0.2, theta, 0.8): 15
// methods (tests/solvers/test_splitting.cc, tests/solvers/test_sparse_separable.cc).
#pragma once

#include <string>
#include <vector>

#include "solvers/runtime/problem.h"
#include "solvers/runtime/registry.h"

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
