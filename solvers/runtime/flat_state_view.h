// What the views of the run-time-sized chains (kernels_chain.cc, kernels_sphere_chain.cc)
// share: a state stored flat in two Eigen vectors, reported as it is stored (the
// embedded coordinates are the stored ones), with no failure diagnosis and no exact
// solution. Included only by those kernels_*.cc translation units.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "solvers/runtime/run.h"

namespace dvm::kernels {

struct FlatStateView {
  using Point = Eigen::VectorXd;
  using Covector = Eigen::VectorXd;
  void finish_report(RunReport& r, const Point& q, const Covector& p) const {
    r.q_final.assign(q.data(), q.data() + q.size());
    r.p_final.assign(p.data(), p.data() + p.size());
    r.q_embedded = r.q_final;
  }
  void diagnose(std::string&, const Point&, const Covector&) const {}
  bool exact(double, const Point&, const Covector&, std::vector<double>&, std::vector<double>&) const { return false; }
};

}  // namespace dvm::kernels
