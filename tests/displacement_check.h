// Whether a run moved the state as far as an accurate reference did.
//
// A step that does nothing, or a composition that drops a stage, still ends close to
// any reference after a few short steps: the state barely moves. What such a step gets
// wrong is the displacement. So the check compares displacements,
//
//   |dq - dq_ref|_inf <= tol |dq_ref|_inf,   |dp - dp_ref|_inf <= tol |dp_ref|_inf,
//
// dq = q_K - q_0 and dp = p_K - p_0 of the run, dq_ref and dp_ref those of a reference
// of much higher order on the same grid. A method of order r has a global error of
// O(h^r) relative to the displacement (K steps of local error O(h^(r+1)) against a
// displacement of O(K h)), so the tolerance is
//
//   tol = max((c h)^r, floor),
//
// c = 100 covering the error constants of the shipped systems (the fastest, FPU at
// omega = 50, has h omega = 0.05 at h = 1e-3) and `floor` the round-off of forming a
// displacement of size h from states of size 1 with step equations solved to about
// 1e-15. At h = 1e-3 that is 0.1 for order 1, 1e-2 for order 2, 1e-8 for order 8: a step
// that returns its input misses by 1 (all of dq_ref), a dropped stage of weight w by
// about |w|.
//
// The state must move: both reference displacements must be well above round-off, or
// the check says so instead of passing.
#pragma once

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

namespace dvm_test {

constexpr double kDisplacementScale = 100.0;
constexpr double kDisplacementFloor = 1e-9;

inline double displacement_tolerance(int order, double h) {
  return std::max(std::pow(kDisplacementScale * std::fabs(h), order), kDisplacementFloor);
}

struct DisplacementVerdict {
  bool ok = false;
  double error_q = NAN, error_p = NAN;  // |d - d_ref|_inf / |d_ref|_inf
  double tol = NAN;
  std::string message;  // why it failed, with the numbers
};

// The displacement of a state from `start` to `end` (as stored: a vector of numbers).
inline std::vector<double> displacement(const std::vector<double>& start, const std::vector<double>& end) {
  std::vector<double> d(end.size(), NAN);
  if (start.size() != end.size()) return d;
  for (std::size_t i = 0; i < end.size(); ++i) d[i] = end[i] - start[i];
  return d;
}

inline double inf_norm(const std::vector<double>& x) {
  double m = 0.0;
  for (double v : x) m = std::isnan(v) ? NAN : std::max(m, std::fabs(v));
  return m;
}

// |d - ref|_inf / |ref|_inf (NaN when the sizes differ or any value is NaN).
inline double relative_difference(const std::vector<double>& d, const std::vector<double>& ref) {
  if (d.size() != ref.size() || d.empty()) return NAN;
  double m = 0.0;
  for (std::size_t i = 0; i < d.size(); ++i) {
    const double e = std::fabs(d[i] - ref[i]);
    if (std::isnan(e)) return NAN;
    m = std::max(m, e);
  }
  return m / inf_norm(ref);
}

// The run (q0, p0) -> (q, p) against the reference displacements (dq_ref, dp_ref),
// for a method of order `order` with step h.
inline DisplacementVerdict judge_displacement(const std::vector<double>& q0, const std::vector<double>& p0,
                                              const std::vector<double>& q, const std::vector<double>& p,
                                              const std::vector<double>& dq_ref, const std::vector<double>& dp_ref,
                                              int order, double h) {
  DisplacementVerdict v;
  v.tol = displacement_tolerance(order, h);
  std::ostringstream m;
  m.precision(3);
  // the reference must move well beyond round-off, or nothing is being checked
  const double moved_q = inf_norm(dq_ref), moved_p = inf_norm(dp_ref);
  if (!(moved_q > 1e3 * kDisplacementFloor * std::max(1.0, inf_norm(q0))) ||
      !(moved_p > 1e3 * kDisplacementFloor * std::max(1.0, inf_norm(p0)))) {
    m << "the reference barely moves (|dq_ref| " << moved_q << ", |dp_ref| " << moved_p
      << "): the check would pass a step that does nothing; start from a state that moves";
    v.message = m.str();
    return v;
  }
  v.error_q = relative_difference(displacement(q0, q), dq_ref);
  v.error_p = relative_difference(displacement(p0, p), dp_ref);
  v.ok = v.error_q <= v.tol && v.error_p <= v.tol;
  if (!v.ok) {
    m << "displacement off the reference: |dq - dq_ref|/|dq_ref| = " << v.error_q
      << ", |dp - dp_ref|/|dp_ref| = " << v.error_p << " against the tolerance " << v.tol << " of order " << order
      << " at h = " << h;
    v.message = m.str();
  }
  return v;
}

}  // namespace dvm_test
