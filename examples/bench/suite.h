// The benchmark suite behind `make charts`: problems, method families and sweeps.
//
// A problem is a Lagrangian system on R^n with initial data (q0, p0), a final time T
// and its energy H(q, p) = <p, v> - L(q, v), v = M^{-1} p. Its global error at T is
//   err(h) = max_i |q_i(T) - q_i^ref(T)|       (positions, max norm)
// against the exact flow where one is known (harmonic oscillator, Kepler) and
// otherwise against a reference computed twice: dvm's order-8 composition
// (kahan-li8 of the midpoint map) at a small step and Boost.Odeint's
// Runge-Kutta-Fehlberg 7(8) (a non-symplectic order-8 method, nothing shared with dvm
// but the force) at a small fixed step; the two must agree, and their difference is
// written next to the data. The energy error of a run is max_k |H(q_k, p_k) - H_0| / |H_0|
// over every step.
//
// A method family is one entry of a table (`Method<System>`): a name, who wrote it
// (dvm, odeint, hand), a nominal order, whether each step solves an implicit equation,
// and a callable run(problem, h, steps, observer) -> Outcome (final state, converged),
// the observer (or nullptr) called with (q_k, p_k) after every step. Each point of a
// sweep is run once with an observer that records the energy error, then timed
// separately without one, so the energy evaluation never enters the CPU time (the
// timed run must reproduce the observed one bit for bit).
// A new family is one more `add(...)` in `dvm_methods` (or in a problem's own table)
// with a lambda that integrates the problem (the Galerkin methods are added so).
#pragma once

#include <boost/numeric/odeint.hpp>
#include <boost/numeric/odeint/stepper/symplectic_rkn_sb3a_m4_mclachlan.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "examples/bench/hand_written.h"
#include "mechanics/lagrangian.h"
#include "mechanics/systems_classic.h"
#include "solvers/composition.h"
#include "solvers/collocation_step.h"
#include "solvers/galerkin_step.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/integrate.h"
#include "solvers/position_momentum_step.h"
#include "solvers/separable_theta_step.h"
#include "solvers/sode_step.h"
#include "solvers/splitting_step.h"

namespace dvm::bench {

// ---------------------------------------------------------------------------------
// problems and outcomes

template <class System>
struct Problem {
  static constexpr int N = System::dim;
  using V = Vec<double, N>;
  std::string name;
  System sys;
  V q0, p0;
  double t_end = 1.0;
  std::vector<std::int64_t> steps;  // the sweep of step counts (h = t_end / n)
  // exact flow (q0, p0) -> (q, p) at t, when one is known
  std::function<void(double, const V&, const V&, V&, V&)> exact;
  // the reference final position (exact, or computed; see reference())
  V q_ref, p_ref;
  std::string reference_note;  // how q_ref was obtained and checked
};

template <class System>
double energy_of(const System& L, const Vec<double, System::dim>& q, const Vec<double, System::dim>& p) {
  const Vec<double, System::dim> v = L.velocity(q, p);
  return p.dot(v) - L(q, v);
}

template <int N>
struct Outcome {
  Vec<double, N> q, p;
  bool converged = false;
};

// Called with (q_k, p_k) after every step, when given.
template <int N>
using StateObserver = std::function<void(const Vec<double, N>&, const Vec<double, N>&)>;

// Forwards to the observer if there is one (one branch per step otherwise).
template <class System>
struct ObserverCall {
  const StateObserver<System::dim>* obs;
  ObserverCall(const System&, const Vec<double, System::dim>&, const Vec<double, System::dim>&,
                const StateObserver<System::dim>* o)
      : obs(o) {}
  void operator()(const Vec<double, System::dim>& q, const Vec<double, System::dim>& p) const {
    if (obs) (*obs)(q, p);
  }
};

// Running maximum of |H - H_0| / |H_0|.
template <class System>
struct MaxEnergyError {
  const System* sys;
  double H0, max_err = 0.0;
  MaxEnergyError(const System& s, const Vec<double, System::dim>& q, const Vec<double, System::dim>& p)
      : sys(&s), H0(energy_of(s, q, p)) {}
  void operator()(const Vec<double, System::dim>& q, const Vec<double, System::dim>& p) {
    const double e = std::fabs(energy_of(*sys, q, p) - H0) / std::fabs(H0);
    if (!(e <= max_err)) max_err = e;  // NaN propagates
  }
};

// run(problem, h, steps, observer or nullptr)
template <class System>
using RunFn = std::function<Outcome<System::dim>(const Problem<System>&, double h, std::int64_t steps,
                                                 const StateObserver<System::dim>* observe)>;

template <class System>
struct Method {
  std::string name;    // as in the charts and CSV
  std::string family;  // dvm | odeint | hand
  int order;           // nominal
  bool implicit;       // each step solves an implicit equation
  bool chart;          // drawn in the work-precision chart (all are in the CSV)
  RunFn<System> run;
};

// ---------------------------------------------------------------------------------
// dvm methods

// Any step type with the `integrate` contract.
template <class System, class Step>
Outcome<System::dim> run_step(const Step& S, const Problem<System>& P, std::int64_t steps,
                              const StateObserver<System::dim>* track) {
  using V = Vec<double, System::dim>;
  V q = P.q0, p = P.p0;
  const V v0 = P.sys.velocity(q, p);
  ObserverCall<System> E(P.sys, q, p, track);
  const RunSummary r =
      integrate(S, 0.0, q, p, v0, steps, [&E](std::int64_t, double, const V& qk, const V& pk, const StepSummary&) {
        E(qk, pk);
      });
  return {q, p, !r.failed};
}

// The explicit Euler maps (theta 0 or 1), alone or composed, on a separable system: the
// kicks and drifts `dvm run` steps them by (solvers/splitting_step.h); null otherwise.
template <class System>
RunFn<System> dvm_splitting(ThetaMap R, const std::vector<Substep>& sub) {
  if constexpr (is_separable_v<System>) {
    if (R.theta() == 0.0 || R.theta() == 1.0)
      return [R, sub](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
        const ExplicitSplittingStep<System> S(P.sys, R.theta(), h, sub, P.q0);
        return run_step(S, P, steps, track);
      };
  }
  return nullptr;
}

// Any other theta map, alone or composed, on a separable system of 3 coordinates or more:
// Newton on the structured equation as `dvm run` steps it (solvers/separable_theta_step.h);
// null otherwise.
template <class System>
RunFn<System> dvm_separable_newton(ThetaMap R, const std::vector<Substep>& sub) {
  if constexpr (is_separable_v<System> && System::dim >= 3) {
    return [R, sub](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
      auto make = [&](double theta) {
        return [&P, theta](double hk) { return SeparableThetaStep<System>(P.sys, theta, hk, StepOptions{}, P.q0); };
      };
      if (sub.size() == 1 && !sub.front().adjoint && sub.front().weight == 1.0)
        return run_step(SeparableThetaStep<System>(P.sys, R.theta(), h, StepOptions{}, P.q0), P, steps, track);
      const ComposedStep<SeparableThetaStep<System>> C(h, sub, make(R.theta()), make(1.0 - R.theta()));
      return run_step(C, P, steps, track);
    };
  }
  return nullptr;
}

// The position-momentum step of a theta map, alone (explicit or structured where dvm
// run's is, unless `generic`: Newton on the step equation of L_d, use_structure = false).
template <class System>
RunFn<System> dvm_map(ThetaMap R, bool generic = false) {
  if (!generic) {
    if (RunFn<System> f = dvm_splitting<System>(R, single_substep())) return f;
    if (RunFn<System> f = dvm_separable_newton<System>(R, single_substep())) return f;
  }
  return [R](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
    const PositionMomentumStep<System, ThetaMap> S(P.sys, R, h);
    return run_step(S, P, steps, track);
  };
}

// A composition of a theta map (route 1; explicit or structured where dvm run's is,
// unless `generic`: then by Newton's method on each substep's equation of L_d, as with
// use_structure = false).
template <class System>
RunFn<System> dvm_composition(ThetaMap R, const std::string& scheme, bool generic = false) {
  const std::vector<Substep> sub = substeps(find_composition(scheme), R.symmetric());
  if (!generic) {
    if (RunFn<System> f = dvm_splitting<System>(R, sub)) return f;
    if (RunFn<System> f = dvm_separable_newton<System>(R, sub)) return f;
  }
  return [R, sub](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
    // the position-momentum steps of R and of its adjoint map, composed
    using Plain = PositionMomentumStep<System, ThetaMap>;
    using Dual = PositionMomentumStep<System, Adjoint<ThetaMap>>;
    const ComposedStep<Plain, Dual> S(
        h, sub, [&](double hk) { return Plain(P.sys, R, hk); }, [&](double hk) { return Dual(P.sys, adjoint(R), hk); });
    return run_step(S, P, steps, track);
  };
}

// The Hamiltonian form (Eq. 5.1) of a theta map, with H the Legendre transform of L.
template <class System>
RunFn<System> dvm_hamiltonian(ThetaMap R) {
  return [R](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
    const HamiltonianStep<LegendreHamiltonian<System>, ThetaMap> S(LegendreHamiltonian<System>(P.sys), R, h);
    return run_step(S, P, steps, track);
  };
}

// The SODE forms (Sec. 4) with the tangent lift of a theta map.
template <class System>
RunFn<System> dvm_sode(ThetaMap R, SodeForm form) {
  return [R, form](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
    const auto lift = tangent_lift(R);
    using Step = SodeStep<System, std::decay_t<decltype(lift)>>;
    const VelocityFormStep<Step> S(Step(P.sys, lift, h, form));
    return run_step(S, P, steps, track);
  };
}

// Newmark's method (gamma, beta) in velocity form.
template <class System>
RunFn<System> dvm_newmark(double gamma, double beta) {
  return [gamma, beta](const Problem<System>& P, double h, std::int64_t steps,
                       const StateObserver<System::dim>* track) {
    const VelocityFormStep<NewmarkStep<System>> S(NewmarkStep<System>(P.sys, h, gamma, beta));
    return run_step(S, P, steps, track);
  };
}

// The Galerkin variational integrator of s stages (solvers/galerkin_step.h; with Gauss
// quadrature the one-step map is Gauss collocation, order 2s), fixed-size in s. Gauss on
// a separable system runs as dvm run runs it: collocation iterated on the stage forces
// (solvers/collocation_step.h).
// (Every system of the suite is separable and measured with Gauss quadrature: the
// generic step of S stages is not instantiated for them, which keeps the suite's compile
// time; their collocation hands a non-contracting step to GalerkinStep<System>.)
template <class System, int S>
RunFn<System> dvm_galerkin(QuadratureKind kind) {
  if constexpr (is_separable_v<System>) {
    if (kind != QuadratureKind::gauss)
      throw std::invalid_argument("the suite measures Galerkin with Gauss quadrature on separable systems");
    return [](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
      const SeparableGaussStep<System, S> C(P.sys, S, h, StepOptions{}, P.q0);
      return run_step(C, P, steps, track);
    };
  } else {
    return [kind](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
      const GalerkinStep<System, S> G(P.sys, kind, S, h);
      return run_step(G, P, steps, track);
    };
  }
}

// The compositions measured with each basic map: every table of
// solvers/composition_methods.h (orders 4 to 8) and the recursive triple jumps of
// orders 6 and 8 (the chart draws a few; the CSV has all).
inline std::vector<std::string> suite_compositions() {
  std::vector<std::string> names;
  for (const CompositionScheme& s : composition_schemes())
    if (s.name != "stormer-verlet") names.push_back(s.name);
  names.push_back("triple-jump:6");
  names.push_back("triple-jump:8");
  return names;
}

// The dvm table for a system: the theta maps alone (position-momentum form), on small
// systems also the Hamiltonian, SODE and Newmark forms, the compositions of
// explicit Euler (Stormer-Verlet basic method; the splittings into kicks and drifts
// directly of explicit Euler and its adjoint) and of the midpoint map. `heavy`
// problems (large dim: every Newton iteration forms an N x N Jacobian by nested
// Jets) get the compositions of explicit Euler and a few of the midpoint map. The
// Galerkin methods (Gauss, s = 2, 4, 6: orders 4, 8, 12) are measured on every system
// (all separable: collocation on the stage forces, no Jacobian).
template <class System>
std::vector<Method<System>> dvm_methods(bool heavy) {
  std::vector<Method<System>> m;
  auto add = [&m](std::string name, int order, bool implicit, bool chart, RunFn<System> run) {
    m.push_back({std::move(name), "dvm", order, implicit, chart, std::move(run)});
  };
  add("dvm explicit-euler", 1, false, true, dvm_map<System>(ThetaMap::explicit_euler()));
  add("dvm adjoint-euler", 1, false, false, dvm_map<System>(ThetaMap::adjoint_euler()));
  add("dvm midpoint", 2, true, true, dvm_map<System>(ThetaMap::midpoint()));
  add("dvm theta-0.3", 1, true, false, dvm_map<System>(ThetaMap(0.3)));
  add("dvm stormer-verlet (EE composed)", 2, false, true,
      dvm_composition<System>(ThetaMap::explicit_euler(), "stormer-verlet"));
  if constexpr (System::dim <= 2) {  // the other forms (paper Sec. 4 and 5.1), on the small systems
    add("dvm hamiltonian midpoint", 2, true, true, dvm_hamiltonian<System>(ThetaMap::midpoint()));
    add("dvm hamiltonian adjoint-euler", 1, false, false, dvm_hamiltonian<System>(ThetaMap::adjoint_euler()));
    add("dvm sode1 midpoint (trapezoidal)", 2, true, false, dvm_sode<System>(ThetaMap::midpoint(), SodeForm::sode1));
    add("dvm sode2 midpoint", 2, true, false, dvm_sode<System>(ThetaMap::midpoint(), SodeForm::sode2));
    add("dvm newmark gamma=1/2 beta=1/4", 2, true, false, dvm_newmark<System>(0.5, 0.25));
  }
  add("dvm galerkin gauss s=2", 4, true, true, dvm_galerkin<System, 2>(QuadratureKind::gauss));
  add("dvm galerkin gauss s=4", 8, true, true, dvm_galerkin<System, 4>(QuadratureKind::gauss));
  add("dvm galerkin gauss s=6", 12, true, true, dvm_galerkin<System, 6>(QuadratureKind::gauss));
  const std::vector<std::string> chart_ee = {"triple-jump", "mclachlan4", "kahan-li6", "kahan-li8", "blanes-moan4",
                                             "blanes-moan6"};
  const std::vector<std::string> chart_mp = {"triple-jump", "kahan-li8"};
  const std::vector<std::string> heavy_mp = {"triple-jump", "kahan-li6", "kahan-li8"};
  for (const std::string& c : suite_compositions()) {
    const int order = find_composition(c).order;
    const bool ce = std::find(chart_ee.begin(), chart_ee.end(), c) != chart_ee.end();
    // a splitting into kicks and drifts composes explicit Euler with its adjoint directly (EE)
    const bool splitting = find_composition(c).kind == CompositionKind::rkn_splitting;
    add("dvm " + c + (splitting ? " (EE)" : " (SV)"), order, false, ce,
        dvm_composition<System>(ThetaMap::explicit_euler(), c));
  }
  for (const std::string& c : suite_compositions()) {
    if (heavy && std::find(heavy_mp.begin(), heavy_mp.end(), c) == heavy_mp.end()) continue;
    if (find_composition(c).kind == CompositionKind::rkn_splitting) continue;  // no midpoint stages
    const int order = find_composition(c).order;
    const bool cm = std::find(chart_mp.begin(), chart_mp.end(), c) != chart_mp.end();
    add("dvm " + c + " (midpoint)", order, true, cm, dvm_composition<System>(ThetaMap::midpoint(), c));
  }
  return m;
}

// ---------------------------------------------------------------------------------
// peers: Boost.Odeint's symplectic steppers on std::array states, and hand-written
// Stormer-Verlet

template <int N>
using Arr = std::array<double, N>;

template <int N>
Vec<double, N> to_vec(const Arr<N>& a) {
  Vec<double, N> v;
  for (int i = 0; i < N; ++i) v[i] = a[static_cast<std::size_t>(i)];
  return v;
}
template <int N>
Arr<N> to_arr(const Vec<double, N>& v) {
  Arr<N> a;
  for (int i = 0; i < N; ++i) a[static_cast<std::size_t>(i)] = v[i];
  return a;
}

// The symplectic steppers in (q, p) form: dq/dt = M^{-1} p, dp/dt = F(q).
template <class Stepper, class System>
RunFn<System> odeint_qp() {
  return [](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
    constexpr int N = System::dim;
    using V = Vec<double, N>;
    const System& L = P.sys;
    Arr<N> q = to_arr<N>(P.q0), p = to_arr<N>(P.p0);
    auto coor = [&L](const Arr<N>& pp, Arr<N>& dqdt) {
      dqdt = to_arr<N>(L.velocity(V::Zero(), to_vec<N>(pp)));
    };
    auto mom = [&L](const Arr<N>& qq, Arr<N>& dpdt) { dpdt = to_arr<N>(force(L, to_vec<N>(qq))); };
    Stepper stepper;
    ObserverCall<System> E(L, P.q0, P.p0, track);
    double t = 0.0;
    for (std::int64_t n = 0; n < steps; ++n) {
      stepper.do_step(std::make_pair(coor, mom), std::make_pair(std::ref(q), std::ref(p)), t, h);
      t = static_cast<double>(n + 1) * h;
      E(to_vec<N>(q), to_vec<N>(p));
    }
    const V qf = to_vec<N>(q), pf = to_vec<N>(p);
    return Outcome<N>{qf, pf, std::isfinite(qf.sum() + pf.sum())};
  };
}

// velocity_verlet in (x, v) form with the acceleration M^{-1} F(x); p = M v.
template <class System>
RunFn<System> odeint_velocity_verlet() {
  return [](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
    constexpr int N = System::dim;
    using V = Vec<double, N>;
    const System& L = P.sys;
    Arr<N> x = to_arr<N>(P.q0), v = to_arr<N>(L.velocity(P.q0, P.p0));
    auto acc = [&L](const Arr<N>& xx, const Arr<N>&, Arr<N>& a, double) {
      a = to_arr<N>(L.velocity(V::Zero(), force(L, to_vec<N>(xx))));
    };
    auto momentum = [&L](const V& q, const V& vel) {
      V dq, dv;
      L.gradient(q, vel, dq, dv);
      return dv;
    };
    boost::numeric::odeint::velocity_verlet<Arr<N>> stepper;
    ObserverCall<System> E(L, P.q0, P.p0, track);
    double t = 0.0;
    for (std::int64_t n = 0; n < steps; ++n) {
      stepper.do_step(acc, std::make_pair(std::ref(x), std::ref(v)), t, h);
      t = static_cast<double>(n + 1) * h;
      E(to_vec<N>(x), momentum(to_vec<N>(x), to_vec<N>(v)));
    }
    const V qf = to_vec<N>(x), pf = momentum(qf, to_vec<N>(v));
    return Outcome<N>{qf, pf, std::isfinite(qf.sum() + pf.sum())};
  };
}

// Classical RK4 (Odeint, non-symplectic) on y = (q, p): the drift baseline.
template <class System>
RunFn<System> odeint_rk4() {
  return [](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
    constexpr int N = System::dim;
    using V = Vec<double, N>;
    using Y = Arr<2 * N>;
    const System& L = P.sys;
    auto f = [&L](const Y& y, Y& dy, double) {
      V q, p;
      for (int i = 0; i < N; ++i) {
        q[i] = y[static_cast<std::size_t>(i)];
        p[i] = y[static_cast<std::size_t>(N + i)];
      }
      const V v = L.velocity(q, p), F = force(L, q);
      for (int i = 0; i < N; ++i) {
        dy[static_cast<std::size_t>(i)] = v[i];
        dy[static_cast<std::size_t>(N + i)] = F[i];
      }
    };
    Y y;
    for (int i = 0; i < N; ++i) {
      y[static_cast<std::size_t>(i)] = P.q0[i];
      y[static_cast<std::size_t>(N + i)] = P.p0[i];
    }
    boost::numeric::odeint::runge_kutta4<Y> stepper;
    ObserverCall<System> E(L, P.q0, P.p0, track);
    V q, p;
    auto unpack = [&] {
      for (int i = 0; i < N; ++i) {
        q[i] = y[static_cast<std::size_t>(i)];
        p[i] = y[static_cast<std::size_t>(N + i)];
      }
    };
    for (std::int64_t n = 0; n < steps; ++n) {
      stepper.do_step(f, y, static_cast<double>(n) * h, h);
      if (track) {
        unpack();
        E(q, p);
      }
    }
    unpack();
    return Outcome<N>{q, p, std::isfinite(q.sum() + p.sum())};
  };
}

template <class System>
RunFn<System> hand_verlet_fn() {
  return [](const Problem<System>& P, double h, std::int64_t steps, const StateObserver<System::dim>* track) {
    using V = Vec<double, System::dim>;
    V q = P.q0, p = P.p0;
    ObserverCall<System> E(P.sys, q, p, track);
    hand_verlet(P.sys, q, p, h, steps, [&E](const V& qk, const V& pk) { E(qk, pk); });
    return Outcome<System::dim>{q, p, std::isfinite(q.sum() + p.sum())};
  };
}

template <class System>
std::vector<Method<System>> peer_methods() {
  namespace odeint = boost::numeric::odeint;
  constexpr int N = System::dim;
  std::vector<Method<System>> m;
  m.push_back({"odeint symplectic_euler", "odeint", 1, false, true,
               odeint_qp<odeint::symplectic_euler<Arr<N>>, System>()});
  m.push_back({"odeint velocity_verlet", "odeint", 2, false, true, odeint_velocity_verlet<System>()});
  m.push_back({"odeint rkn_sb3a_mclachlan", "odeint", 4, false, true,
               odeint_qp<odeint::symplectic_rkn_sb3a_mclachlan<Arr<N>>, System>()});
  m.push_back({"odeint rkn_sb3a_m4_mclachlan", "odeint", 4, false, true,
               odeint_qp<odeint::symplectic_rkn_sb3a_m4_mclachlan<Arr<N>>, System>()});
  m.push_back({"hand stormer-verlet", "hand", 2, false, true, hand_verlet_fn<System>()});
  return m;
}

// ---------------------------------------------------------------------------------
// the reference solution

// Runge-Kutta-Fehlberg 7(8) at a fixed step (Odeint), the independent cross-check.
template <class System>
void rkf78(const System& L, Vec<double, System::dim>& q, Vec<double, System::dim>& p, double t_end,
           std::int64_t steps) {
  constexpr int N = System::dim;
  using V = Vec<double, N>;
  using Y = Arr<2 * N>;
  auto f = [&L](const Y& y, Y& dy, double) {
    V qq, pp;
    for (int i = 0; i < N; ++i) {
      qq[i] = y[static_cast<std::size_t>(i)];
      pp[i] = y[static_cast<std::size_t>(N + i)];
    }
    const V v = L.velocity(qq, pp), F = force(L, qq);
    for (int i = 0; i < N; ++i) {
      dy[static_cast<std::size_t>(i)] = v[i];
      dy[static_cast<std::size_t>(N + i)] = F[i];
    }
  };
  Y y;
  for (int i = 0; i < N; ++i) {
    y[static_cast<std::size_t>(i)] = q[i];
    y[static_cast<std::size_t>(N + i)] = p[i];
  }
  boost::numeric::odeint::runge_kutta_fehlberg78<Y> stepper;
  const double h = t_end / static_cast<double>(steps);
  for (std::int64_t n = 0; n < steps; ++n) stepper.do_step(f, y, static_cast<double>(n) * h, h);
  for (int i = 0; i < N; ++i) {
    q[i] = y[static_cast<std::size_t>(i)];
    p[i] = y[static_cast<std::size_t>(N + i)];
  }
}

// Fills P.q_ref/p_ref: the exact flow if known, else kahan-li8 (midpoint) with
// `ref_steps` steps, cross-checked by RKF78 with `check_steps` steps. Returns the
// max-norm difference of the two positions (0 for an exact reference).
template <class System>
double reference(Problem<System>& P, std::int64_t ref_steps, std::int64_t check_steps) {
  using V = Vec<double, System::dim>;
  if (P.exact) {
    P.exact(P.t_end, P.q0, P.p0, P.q_ref, P.p_ref);
    P.reference_note = "exact solution";
    return 0.0;
  }
  const auto run = dvm_composition<System>(ThetaMap::midpoint(), "kahan-li8");
  const Outcome<System::dim> a = run(P, P.t_end / static_cast<double>(ref_steps), ref_steps, nullptr);
  V q = P.q0, p = P.p0;
  rkf78(P.sys, q, p, P.t_end, check_steps);
  P.q_ref = a.q;
  P.p_ref = a.p;
  const double diff = (a.q - q).cwiseAbs().maxCoeff();
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "dvm kahan-li8 (midpoint) with %lld steps; Odeint RKF78 with %lld steps agrees to %.1e (max |q|)",
                static_cast<long long>(ref_steps), static_cast<long long>(check_steps), diff);
  P.reference_note = buf;
  if (!a.converged) P.reference_note += " [reference run failed]";
  return diff;
}

// ---------------------------------------------------------------------------------
// timing and sweeps

inline double cpu_seconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// One row of the work-precision data.
struct Row {
  std::string problem, method, family;
  int order;
  bool implicit, chart;
  double h;
  std::int64_t steps;
  double error, max_energy_error, cpu_seconds;
  bool converged;
};

struct SweepOptions {
  double min_seconds = 0.02;     // repeat a timed run until this much CPU time has passed (best of)
  double max_run_seconds = 1.0;  // stop refining a method once one run takes longer
  double floor_error = 1e-13;    // stop refining once the error is below this (round-off)
};

template <class System>
std::vector<Row> sweep(const Problem<System>& P, const std::vector<Method<System>>& methods, const SweepOptions& o) {
  std::vector<Row> rows;
  for (const Method<System>& m : methods) {
    for (std::int64_t n : P.steps) {
      const double h = P.t_end / static_cast<double>(n);
      MaxEnergyError<System> E(P.sys, P.q0, P.p0);
      const StateObserver<System::dim> observe = [&E](const Vec<double, System::dim>& q,
                                                      const Vec<double, System::dim>& p) { E(q, p); };
      const Outcome<System::dim> tracked = m.run(P, h, n, &observe);
      Row r{P.name, m.name, m.family, m.order, m.implicit, m.chart, h, n, NAN, E.max_err, NAN, tracked.converged};
      if (tracked.converged) r.error = (tracked.q - P.q_ref).cwiseAbs().maxCoeff();
      if (!tracked.converged || !std::isfinite(r.error) || r.error > 1.0) {
        r.converged = tracked.converged && std::isfinite(r.error);
        rows.push_back(r);
        continue;  // diverged or useless: try a smaller step
      }
      double best = INFINITY, spent = 0.0;
      int repeats = 0;
      while (repeats < 1 || (spent < o.min_seconds && repeats < 50)) {
        const double t0 = cpu_seconds();
        const Outcome<System::dim> timed = m.run(P, h, n, nullptr);
        const double dt = cpu_seconds() - t0;
        if ((timed.q - tracked.q).cwiseAbs().maxCoeff() != 0.0) r.converged = false;  // must be reproducible
        best = std::fmin(best, dt);
        spent += dt;
        ++repeats;
      }
      r.cpu_seconds = best;
      rows.push_back(r);
      if (r.error < o.floor_error || best > o.max_run_seconds) break;
    }
  }
  return rows;
}

// Slope of log(error) against log(h) by least squares over the points with
// floor < error < 1e-2 (the asymptotic range, above round-off and above the accuracy
// of a computed reference); NaN with < 3 points.
inline double fitted_order(const std::vector<const Row*>& rows, double floor = 1e-13) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  int n = 0;
  for (const Row* r : rows) {
    if (!r->converged || !(r->error > floor && r->error < 1e-2)) continue;
    const double x = std::log(r->h), y = std::log(r->error);
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
    ++n;
  }
  if (n < 3) return NAN;
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// CPU time to reach `target` error, by log-log interpolation between the two sweep
// points that bracket it (NaN when the sweep does not bracket it).
inline double cpu_at(const std::vector<const Row*>& rows, double target) {
  for (std::size_t i = 0; i + 1 < rows.size(); ++i) {
    const Row* a = rows[i];
    const Row* b = rows[i + 1];
    if (!a->converged || !b->converged || !(a->cpu_seconds > 0) || !(b->cpu_seconds > 0)) continue;
    if (a->error >= target && b->error <= target && a->error > b->error) {
      const double s = std::log(target / a->error) / std::log(b->error / a->error);
      return std::exp(std::log(a->cpu_seconds) + s * std::log(b->cpu_seconds / a->cpu_seconds));
    }
  }
  return NAN;
}

// ---------------------------------------------------------------------------------
// the problem suites (one translation unit each)

struct SuiteConfig {
  bool tiny = false;  // a few small runs (tests)
  SweepOptions sweep;
};

struct ProblemResult {
  std::vector<Row> rows;
  std::string problem, reference_note;
  double reference_agreement = 0.0;
};

ProblemResult run_harmonic(const SuiteConfig&);
ProblemResult run_pendulum(const SuiteConfig&);
ProblemResult run_kepler(const SuiteConfig&);
ProblemResult run_henon_heiles(const SuiteConfig&);
ProblemResult run_fpu(const SuiteConfig&);
ProblemResult run_outer_solar_system(const SuiteConfig&);
ProblemResult run_rigid_body(const SuiteConfig&);  // on SO(3): dvm only (suite_rigid_body.cc)

// Kepler, e = 0.6 (also used by the ratio program): the method table and the problem
// with the exact reference filled in.
std::vector<Method<Kepler>> kepler_methods();
std::vector<Method<HarmonicOscillator>> harmonic_methods();
std::vector<Method<Pendulum>> pendulum_methods();
Problem<Kepler> kepler_problem(double t_end, std::vector<std::int64_t> steps);

}  // namespace dvm::bench
