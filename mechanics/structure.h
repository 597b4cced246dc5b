// The structure of a Lagrangian on R^n, which decides how cheap a step can be.
//
//   separable    L(q, v) = v^T M v / 2 - V(q),     M constant, symmetric, positive definite
//   mechanical   L(q, v) = v^T M(q) v / 2 - V(q)   (the mass matrix depends on q)
//   general      anything else (a term linear in v, a kinetic energy that is not
//                quadratic in v, ...)
//
// Each class contains the one before it. What a separable structure buys: for the theta
// maps R_d(x, v) = (x - theta v, x + (1 - theta) v) (paper Ex. 2.6) the discrete
// Lagrangian is
//   L_d(q0, q1) = (q1 - q0)^T M (q1 - q0) / (2h) - h V((1 - theta) q0 + theta q1),
// so at theta = 0 and theta = 1 the discrete Legendre equations p0 = -D1 L_d,
// p1 = D2 L_d are explicit: one force F = -grad V and one solve with M per step, no
// Newton iteration (solvers/splitting_step.h).
//
// A built-in system declares its structure with `static constexpr Structure structure`.
// A declaration is a promise the fast steps rely on, so it is checked before a run:
// check_structure evaluates the gradient of L at sample points (q, v, w) around the
// initial state and tests the identities that define the class,
//   dL/dv(q, 0) = 0,  dL/dv(q, v + w) = dL/dv(q, v) + dL/dv(q, w)       (p = M(q) v)
//   <w, dL/dv(q, v)> = <v, dL/dv(q, w)>,  <v, dL/dv(q, v)> > 0          (M symmetric, positive)
//   mechanical: dL/dq(q, 2v) - dL/dq(q, 0) = 4 (dL/dq(q, v) - dL/dq(q, 0))  (T quadratic in v)
//   separable:  dL/dv(q, v) = dL/dv(q0, v),  dL/dq(q, v) = dL/dq(q, 0)   (M constant, no coupling)
// by gradients only, a few per sample whatever the size, so it costs little for systems
// of any size (fixed: S::dim; run-time-sized: mechanics/dynamic_system.h). A system that
// fails the test of its declared class is refused (StructureError, naming the identity
// and its residual). Systems that declare nothing (Lagrangians written in a scene) are
// classified by the same test: the most specific class whose identities hold at every
// sample. A sample is evidence, not a proof; only declared structure selects a fast step.
#pragma once

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <type_traits>

#include "mechanics/lagrangian.h"

namespace dvm {

enum class Structure { general, mechanical, separable };

inline const char* structure_name(Structure s) {
  switch (s) {
    case Structure::separable:
      return "separable";
    case Structure::mechanical:
      return "mechanical";
    case Structure::general:
      break;
  }
  return "general";
}

// The structure a system type declares (general when it declares none).
template <class S, class = void>
struct declared_structure : std::integral_constant<Structure, Structure::general> {};
template <class S>
struct declared_structure<S, std::void_t<decltype(S::structure)>> : std::integral_constant<Structure, S::structure> {};

template <class S, class = void>
struct has_declared_structure : std::false_type {};
template <class S>
struct has_declared_structure<S, std::void_t<decltype(S::structure)>> : std::true_type {};

template <class S>
inline constexpr bool is_separable_v = declared_structure<S>::value == Structure::separable;

// A system whose declared structure its Lagrangian does not have.
struct StructureError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

// The outcome of testing one class: whether its identities held at every sample, and
// otherwise which one failed, with its residual against its scale.
struct StructureTest {
  bool holds = true;
  std::string failed;  // e.g. "dL/dv(q, 0) = 0"
  double residual = 0.0, scale = 0.0;
  void check(const char* identity, double r, double s) {
    if (!holds) return;
    if (!(r <= kTolerance * s)) {
      holds = false;
      failed = identity;
      residual = r;
      scale = s;
    }
  }
  // relative: the identities hold exactly in exact arithmetic, to a few ulps in floating point
  static constexpr double kTolerance = 1e-10;
};

// The size of a system's state: S::dim for a fixed-size Lagrangian, Eigen::Dynamic for a
// run-time-sized one (int dim() const).
template <class S, class = void>
struct state_size : std::integral_constant<int, Eigen::Dynamic> {};
template <class S>
struct state_size<S, std::enable_if_t<std::is_integral_v<std::remove_cv_t<decltype(S::dim)>>>>
    : std::integral_constant<int, S::dim> {};

template <class S>
using StateVec = Vec<double, state_size<S>::value>;

template <class S>
int system_dim(const S& L) {
  if constexpr (state_size<S>::value == Eigen::Dynamic)
    return L.dim();
  else
    return (void)L, S::dim;
}

// dL/dq and dL/dv at (q, v) in doubles, for either kind of system (outputs sized).
template <class S, class V>
void gradient_of(const S& L, const V& q, const V& v, V& Lq, V& Lv) {
  if constexpr (state_size<S>::value == Eigen::Dynamic)
    L.gradient(q, v, Lq, Lv);
  else
    lagrangian_gradient(L, q, v, Lq, Lv);
}

namespace detail {

// Deterministic sample points around (q0, v0): each coordinate moved by up to 10% of
// the state's size (so that a singularity away from the initial state, Kepler's at
// the origin say, is not met), velocities v and w mixed from v0 and unit-scale directions.
template <class V>
void structure_sample(const V& q0, const V& v0, int k, V& q, V& v, V& w) {
  const double sq = 0.1 * std::fmax(max_abs(q0), 1e-3), sv = std::fmax(max_abs(v0), 1.0);
  q = q0;
  v = v0;
  w = v0;
  for (int i = 0; i < q0.size(); ++i) {
    // a fixed, irregular pattern in [-1, 1] (no two samples or coordinates alike)
    const double a = std::sin(1.7 * (k + 1) + 2.3 * (i + 1) + 0.3 * (k + 1) * (i + 1));
    const double b = std::cos(2.9 * (k + 1) - 1.1 * (i + 1) + 0.7 * (k + 1) * (i + 1));
    const double c = std::sin(0.9 * (k + 1) - 3.1 * (i + 1) + 0.5 * (k + 2) * (i + 1));
    q[i] += sq * a;
    v[i] = (k % 2 == 0 ? 0.5 * v0[i] : 0.0) + sv * b;
    w[i] = sv * c;
  }
}

constexpr int kStructureSamples = 4;

}  // namespace detail

// Tests the identities of class `c` (separable or mechanical) at the sample points
// around (q0, v0). `general` always holds.
template <class S>
StructureTest test_structure(const S& L, Structure c, const StateVec<S>& q0, const StateVec<S>& v0) {
  using V = StateVec<S>;
  StructureTest t;
  if (c == Structure::general) return t;
  const Eigen::Index n = q0.size();
  const V zero = V::Zero(n);
  V q = zero, v = zero, w = zero, vw = zero;
  V Lq0 = zero, Lv0 = zero, Lq = zero, Lv = zero, Lqw = zero, Lw = zero, Lqs = zero, Lvw = zero, Lq2 = zero,
    Lv2 = zero, Lref = zero, Lqr = zero;
  for (int k = 0; k < detail::kStructureSamples && t.holds; ++k) {
    detail::structure_sample(q0, v0, k, q, v, w);
    gradient_of(L, q, zero, Lq0, Lv0);
    gradient_of(L, q, v, Lq, Lv);
    gradient_of(L, q, w, Lqw, Lw);
    vw = v + w;
    gradient_of(L, q, vw, Lqs, Lvw);
    const double ps = max_abs(Lv) + max_abs(Lw) + 1e-300;
    t.check("dL/dv(q, 0) = 0", max_abs(Lv0), ps);
    t.check("dL/dv(q, v + w) = dL/dv(q, v) + dL/dv(q, w) (p linear in v)", max_abs(V(Lvw - Lv - Lw)), ps);
    const double vLw = v.dot(Lw), wLv = w.dot(Lv);
    t.check("<w, dL/dv(q, v)> = <v, dL/dv(q, w)> (M symmetric)", std::fabs(vLw - wLv),
            max_abs(v) * max_abs(Lw) * static_cast<double>(n) + max_abs(w) * max_abs(Lv) * static_cast<double>(n));
    if (t.holds && !(v.dot(Lv) > 0.0)) {
      t.holds = false;
      t.failed = "<v, dL/dv(q, v)> > 0 (M positive definite)";
      t.residual = v.dot(Lv);
      t.scale = max_abs(v) * max_abs(Lv);
    }
    if (c == Structure::separable) {
      gradient_of(L, q0, v, Lqr, Lref);
      t.check("dL/dv(q, v) = dL/dv(q0, v) (M the same at every q)", max_abs(V(Lv - Lref)), max_abs(Lref) + 1e-300);
      t.check("dL/dq(q, v) = dL/dq(q, 0) (no term couples q and v)", max_abs(V(Lq - Lq0)),
              max_abs(Lq0) + max_abs(v) * max_abs(Lv) + 1e-300);
    } else {
      const V v2 = 2.0 * v;
      gradient_of(L, q, v2, Lq2, Lv2);
      t.check("dL/dq(q, 2v) - dL/dq(q, 0) = 4 (dL/dq(q, v) - dL/dq(q, 0)) (kinetic energy quadratic in v)",
              max_abs(V((Lq2 - Lq0) - 4.0 * (Lq - Lq0))), max_abs(V(Lq2 - Lq0)) + max_abs(Lq0) + 1e-300);
    }
  }
  return t;
}

// The most specific class whose identities hold at the samples.
template <class S>
Structure sampled_structure(const S& L, const StateVec<S>& q0, const StateVec<S>& v0) {
  if (test_structure(L, Structure::separable, q0, v0).holds) return Structure::separable;
  if (test_structure(L, Structure::mechanical, q0, v0).holds) return Structure::mechanical;
  return Structure::general;
}

// Throws StructureError when the system's declared class fails its test at the
// samples around (q0, v0); returns the declared class otherwise.
template <class S>
Structure check_structure(const S& L, const StateVec<S>& q0, const StateVec<S>& v0) {
  constexpr Structure d = declared_structure<S>::value;
  const StructureTest t = test_structure(L, d, q0, v0);
  if (!t.holds) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "residual %.3e against scale %.3e", t.residual, t.scale);
    throw StructureError(L.name() + ": declared " + structure_name(d) + " but its Lagrangian is not: the identity " +
                         t.failed + " fails near the initial state (" + buf + ")");
  }
  return d;
}

}  // namespace dvm
