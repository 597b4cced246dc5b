// Kernels for systems on R^n of fixed size (a Lagrangian type S with S::dim): the
// system view (energy, invariants, columns, exact solution, diagnosis of a failed
// step) and make_rn_run, which picks the step type of the method once. Included only
// by the kernels_*.cc translation units.
//
// What is compiled for each system and what once for each size: make_rn_run<S> builds,
// with S itself, the steps a benchmark shows to pay for it (the position-momentum step
// of the theta maps by Newton's method, alone and composed; on a separable S the kicks
// and drifts of the Euler maps, Newton on the structured equation from 3 coordinates,
// and Gauss collocation). The hamiltonian form of the theta maps by Newton's method
// runs, from two coordinates on, the run-time-sized step on the system erased at
// run-time size (make_run_time_sized_run, compiled once: kernels_rn_run_time.cc): H's
// Hessian blocks from L's in closed form cost less than the fixed-size step's nested
// Jets from two coordinates on, and about the same on one (bench_run_time_size
// measures both, and Galerkin both ways, where the fixed-size step is the faster).
// Every other choice of the method (the hamiltonian form on one coordinate, by
// TinySolver or of retraction-theta and written maps; the sode and newmark forms, maps
// inverted by Newton's method, TinySolver, Galerkin methods that are not Gauss
// collocation, boundary values) runs the same step templates with ErasedLagrangian<N>
// (mechanics/erased_lagrangian.h) and the view erased likewise (ErasedRnView<N>):
// make_sized_run<N>, compiled once for each size the built-in systems have
// (kernels_rn_sized.h). --linearize runs the run-time-sized steps that give their
// derivative, through make_run_time_sized_run.
#pragma once

#include <array>
#include <cmath>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "mechanics/erased_dynamic.h"
#include "mechanics/erased_lagrangian.h"
#include "mechanics/hamiltonian.h"
#include "mechanics/legendre_lift.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "solvers/composition.h"
#include "solvers/galerkin_step.h"
#include "solvers/hamiltonian_step.h"
#include "solvers/position_momentum_step.h"
#include "solvers/runtime/kernels.h"
#include "solvers/sode_step.h"

namespace dvm::kernels {

template <int N>
Vec<double, N> to_vec(const std::vector<double>& x) {
  Vec<double, N> v(static_cast<Eigen::Index>(x.size()));
  for (std::size_t i = 0; i < x.size(); ++i) v[static_cast<Eigen::Index>(i)] = x[i];
  return v;
}
template <class V>
std::vector<double> to_std(const V& x) {
  return std::vector<double>(x.data(), x.data() + x.size());
}

// ---- what each system conserves besides the energy ------------------------------------
template <class S>
std::vector<InvariantReport> invariant_names(const S&) {
  return {};
}
template <class S, int N>
void invariant_values(const S&, const Vec<double, N>&, const Vec<double, N>&, double*) {}

inline InvariantReport scalar_invariant(const std::string& name) {
  InvariantReport r;
  r.name = name;
  r.initial.assign(1, 0.0);
  return r;
}

inline std::vector<InvariantReport> invariant_names(const Kepler&) {
  return {scalar_invariant("angular momentum")};
}
inline void invariant_values(const Kepler&, const Vec<double, 2>& q, const Vec<double, 2>& p, double* out) {
  out[0] = Kepler::angular_momentum(q, p);
}
inline std::vector<InvariantReport> invariant_names(const ChargedParticle&) {
  return {scalar_invariant("angular momentum")};
}
inline void invariant_values(const ChargedParticle&, const Vec<double, 2>& q, const Vec<double, 2>& p, double* out) {
  out[0] = ChargedParticle::angular_momentum(q, p);
}
inline std::vector<InvariantReport> invariant_names(const FermiPastaUlam&) {
  return {scalar_invariant("oscillatory energy (adiabatic, O(1/omega))")};
}
inline void invariant_values(const FermiPastaUlam& F, const Vec<double, 6>& q, const Vec<double, 6>& p, double* out) {
  out[0] = F.oscillatory_energy(q, p);
}
template <int B>
std::vector<InvariantReport> invariant_names(const NBody<B>&) {
  std::vector<InvariantReport> out;
  for (const char* n : {"momentum x", "momentum y", "momentum z", "angular momentum x", "angular momentum y",
                        "angular momentum z"})
    out.push_back(scalar_invariant(n));
  return out;
}
template <int B>
void invariant_values(const NBody<B>&, const Vec<double, 3 * B>& q, const Vec<double, 3 * B>& p, double* out) {
  const auto m = NBody<B>::momenta(q, p);
  for (int i = 0; i < 6; ++i) out[i] = m[static_cast<std::size_t>(i)];
}
// ---- the monitored energy: E_L ----------------------------------------------------------
// (A separable system's v = M^{-1} p is in closed form or from a factored M, so
// dL/dv(q, v) = M v is p to round-off: E_L = <p, v> - L(q, v) without evaluating the
// gradient; bench_galerkin_kepler times the Kepler scene, monitored at every step.)
template <class S, int N>
double monitored_energy(const S& L, const Vec<double, N>& q, const Vec<double, N>& v, const Vec<double, N>& p) {
  if constexpr (is_separable_v<S>)
    return p.dot(v) - L(q, v);
  else
    return energy(L, q, v);
}
// ---- exact solutions, where a system has one ------------------------------------------
template <class S, class = void>
struct has_exact_member : std::false_type {};
template <class S>
struct has_exact_member<S, std::void_t<decltype(std::declval<const S&>().exact(
                               0.0, std::declval<const Vec<double, S::dim>&>(),
                               std::declval<const Vec<double, S::dim>&>(), std::declval<Vec<double, S::dim>&>(),
                               std::declval<Vec<double, S::dim>&>()))>> : std::true_type {};
template <class S, class = void>
struct has_exact_condition : std::false_type {};
template <class S>
struct has_exact_condition<S, std::void_t<decltype(std::declval<const S&>().has_exact())>> : std::true_type {};

// ---- the view of a fixed-size system on R^n --------------------------------------------
template <class S>
struct RnView {
  static constexpr int N = S::dim;
  using Point = Vec<double, N>;
  using Covector = Point;
  S L;
  std::vector<std::string> names;  // coordinate names of the columns
  bool named = false;              // columns "t, name.., p_name.., energy" (written systems)
  Point v0 = Point::Zero();        // initial velocity, the guess of the failure diagnosis
  Vec<double, 2> sigma0 = Vec<double, 2>::Zero();

  std::vector<std::string> columns() const {
    std::vector<std::string> c{"t"};
    for (int i = 0; i < N; ++i) c.push_back(named ? names[static_cast<std::size_t>(i)] : "q" + std::to_string(i));
    for (int i = 0; i < N; ++i) c.push_back(named ? "p_" + names[static_cast<std::size_t>(i)] : "p" + std::to_string(i));
    c.push_back("energy");
    return c;
  }
  int row_size() const { return 2 * N + 2; }
  void fill_row(double* row, double t, const Point& q, const Covector& p, double E) const {
    row[0] = t;
    for (int i = 0; i < N; ++i) row[1 + i] = q[i], row[1 + N + i] = p[i];
    row[2 * N + 1] = E;
  }
  double energy(const Point& q, const Covector& p) const {
    return monitored_energy(L, q, legendre_inverse(L, q, p), p);
  }
  int invariant_count() const { return static_cast<int>(invariant_names(L).size()); }
  void invariants(const Point& q, const Covector& p, double* out) const { invariant_values(L, q, p, out); }
  std::vector<InvariantReport> invariant_reports(const double* I0) const {
    std::vector<InvariantReport> r = invariant_names(L);
    for (std::size_t i = 0; i < r.size(); ++i) r[i].initial[0] = I0[i];
    return r;
  }
  double point_defect(const Point&) const { return -1.0; }
  void finish_report(RunReport& r, const Point& q, const Covector& p) const {
    r.q_final = to_std(q);
    r.p_final = to_std(p);
    r.q_embedded = r.q_final;
  }
  void diagnose(std::string& message, const Point& q, const Covector& p) const {
    message += "; " + legendre_diagnosis(L, q, p, v0, sigma0);
  }
  bool exact(double t, const Point& q0, const Covector& p0, std::vector<double>& q, std::vector<double>& p) const {
    if constexpr (!has_exact_member<S>::value) {
      (void)t, (void)q0, (void)p0, (void)q, (void)p;
      return false;
    } else {
      if constexpr (has_exact_condition<S>::value)
        if (!L.has_exact()) return false;
      Point qe, pe;
      try {
        L.exact(t, q0, p0, qe, pe);
      } catch (const std::domain_error&) {
        return false;  // e.g. Kepler on an orbit that is not bound
      }
      q = to_std(qe);
      p = to_std(pe);
      return true;
    }
  }
};

// The initial state (q, p, v0) of a problem; refuses a Lagrangian that is degenerate
// there (singular velocity Hessian) and a written Hamiltonian that disagrees with the
// Legendre transform of L.
template <class S>
void initial_state(const Problem& pr, const S& L, Vec<double, S::dim>& q, Vec<double, S::dim>& p,
                   Vec<double, S::dim>& v0) {
  constexpr int N = S::dim;
  q = to_vec<N>(pr.q);
  const std::string where = pr.written ? pr.written_where : pr.origin;
  if constexpr (!has_velocity<S>::value) {
    // no closed-form inverse Legendre map: the velocity Hessian must be invertible
    const std::vector<std::string> velocities = velocity_names(pr);
    auto check = [&](const Vec<double, N>& v) {
      require_regular_hessian(velocity_hessian(L, q, v), where, velocities);
    };
    if (pr.momentum_given) {
      check(Vec<double, N>::Zero());
      try {
        v0 = legendre_inverse(L, q, to_vec<N>(pr.p));
      } catch (const DegenerateLagrangianError& e) {
        throw InputError(where + ": the Lagrangian is degenerate at the initial state: " + e.what());
      }
    } else {
      v0 = to_vec<N>(pr.v);
    }
    check(v0);
  } else {
    if (pr.momentum_given) v0 = legendre_inverse(L, q, to_vec<N>(pr.p));
  }
  if (pr.momentum_given) {
    p = to_vec<N>(pr.p);
  } else {
    v0 = to_vec<N>(pr.v);
    p = legendre(L, q, v0);
  }
}

// ---- the view with the system's type erased ------------------------------------------
// The view of a fixed-size system for the kernels compiled once per size (make_sized_run):
// RnView<S>'s functions behind one indirect call each (they run at most once a step).
// ErasedRnView<Eigen::Dynamic> is the same view with run-time-sized points, for the
// run-time-sized steps (make_run_time_sized_run): each call converts them to S's size. It
// also holds a view of run-time-sized points of its own (the chain's), given with its
// number of coordinates.
template <int N>
class ErasedRnView {
 public:
  using Point = Vec<double, N>;
  using Covector = Point;
  static constexpr bool erase_steps = true;  // (AnyRnStep: their steps solve an equation each step)

  class Model {
   public:
    virtual ~Model() = default;
    virtual std::vector<std::string> columns() const = 0;
    virtual void fill_row(double* row, double t, const Point& q, const Covector& p, double E) const = 0;
    virtual double energy(const Point& q, const Covector& p) const = 0;
    virtual int invariant_count() const = 0;
    virtual void invariants(const Point& q, const Covector& p, double* out) const = 0;
    virtual std::vector<InvariantReport> invariant_reports(const double* I0) const = 0;
    virtual void finish_report(RunReport& r, const Point& q, const Covector& p) const = 0;
    virtual void diagnose(std::string& message, const Point& q, const Covector& p) const = 0;
    virtual bool exact(double t, const Point& q0, const Covector& p0, std::vector<double>& q,
                       std::vector<double>& p) const = 0;
  };
  template <class V>
  class ModelOf final : public Model {
   public:
    explicit ModelOf(V v) : v_(std::move(v)) {}
    std::vector<std::string> columns() const override { return v_.columns(); }
    void fill_row(double* row, double t, const Point& q, const Covector& p, double E) const override {
      v_.fill_row(row, t, q, p, E);
    }
    double energy(const Point& q, const Covector& p) const override { return v_.energy(q, p); }
    int invariant_count() const override { return v_.invariant_count(); }
    void invariants(const Point& q, const Covector& p, double* out) const override { v_.invariants(q, p, out); }
    std::vector<InvariantReport> invariant_reports(const double* I0) const override {
      return v_.invariant_reports(I0);
    }
    void finish_report(RunReport& r, const Point& q, const Covector& p) const override { v_.finish_report(r, q, p); }
    void diagnose(std::string& message, const Point& q, const Covector& p) const override {
      v_.diagnose(message, q, p);
    }
    bool exact(double t, const Point& q0, const Covector& p0, std::vector<double>& q,
               std::vector<double>& p) const override {
      return v_.exact(t, q0, p0, q, p);
    }

   private:
    V v_;
  };

  template <class S>
  explicit ErasedRnView(RnView<S> v) : n_(S::dim), model_(std::make_shared<const ModelOf<RnView<S>>>(std::move(v))) {}
  // a view of n coordinates whose points are run-time sized (N = Eigen::Dynamic only)
  template <class V>
  ErasedRnView(V v, int n) : n_(n), model_(std::make_shared<const ModelOf<V>>(std::move(v))) {
    static_assert(N == Eigen::Dynamic && std::is_same_v<typename V::Point, Eigen::VectorXd>,
                  "ErasedRnView(view, n) takes a view of run-time-sized points");
  }

  std::vector<std::string> columns() const { return model_->columns(); }
  int row_size() const { return 2 * n_ + 2; }
  void fill_row(double* row, double t, const Point& q, const Covector& p, double E) const {
    model_->fill_row(row, t, q, p, E);
  }
  double energy(const Point& q, const Covector& p) const { return model_->energy(q, p); }
  int invariant_count() const { return model_->invariant_count(); }
  void invariants(const Point& q, const Covector& p, double* out) const { model_->invariants(q, p, out); }
  std::vector<InvariantReport> invariant_reports(const double* I0) const { return model_->invariant_reports(I0); }
  double point_defect(const Point&) const { return -1.0; }
  void finish_report(RunReport& r, const Point& q, const Covector& p) const { model_->finish_report(r, q, p); }
  void diagnose(std::string& message, const Point& q, const Covector& p) const { model_->diagnose(message, q, p); }
  bool exact(double t, const Point& q0, const Covector& p0, std::vector<double>& q, std::vector<double>& p) const {
    return model_->exact(t, q0, p0, q, p);
  }

 private:
  int n_;  // the system's coordinates
  std::shared_ptr<const Model> model_;
};

// The start of a run of the kernels compiled per size: the initial state (q, p, v0), or
// none for a boundary-value problem (its ends are the problem's).
template <int N>
struct SizedStart {
  Vec<double, N> q, p, v0;
};

// Every choice of the method that make_rn_run<S> does not compile for S itself, for the
// erased system L of N coordinates and its view (kernels_rn_sized.cc; N = 1, 2 and 6,
// the sizes of the built-in systems). start: null for a boundary-value problem.
template <int N>
std::unique_ptr<Run> make_sized_run(const ErasedLagrangian<N>& L, const ErasedRnView<N>& view, const Problem& pr,
                                    const Method& me, RunReport base, const SizedStart<N>* start);

// The run-time-sized steps on the system L and its view, each erased
// (kernels_rn_run_time.cc, compiled once for every built-in system): the
// position-momentum step of the theta-family maps and their hamiltonian form, composed
// or not, and the Galerkin step. They give their derivative (--linearize: no fixed-size
// step compiles one), and run the hamiltonian form of the theta maps by Newton's
// method (hamiltonian_theta_path).
std::unique_ptr<Run> make_run_time_sized_run(const ErasedDynamicLagrangian& L, const ErasedRnView<Eigen::Dynamic>& view,
                                         const Problem& pr, const Method& me, RunReport base,
                                         const Eigen::VectorXd& q, const Eigen::VectorXd& p,
                                         const Eigen::VectorXd& v0);

// ---- the factory ---------------------------------------------------------------------
// Whether the method is the position-momentum step of a theta map solved by Newton's
// method (composed or not): the path make_rn_run compiles for each system.
inline bool theta_newton_path(const Method& me) {
  return !me.galerkin && me.form == Form::lagrangian && me.map && me.map->family == MapFamily::theta &&
         me.solver == SolverKind::newton;
}

// Whether the method is the hamiltonian form of a theta map (composed or not, lift
// cotangent or none) solved by Newton's method on a system of N coordinates: the path
// make_rn_run gives to the run-time-sized step from two coordinates on (the rule of the
// header comment).
inline bool hamiltonian_theta_path(const Method& me, int N) {
  return N >= 2 && !me.galerkin && me.form == Form::hamiltonian && me.map && me.map->family == MapFamily::theta &&
         me.solver == SolverKind::newton;
}

// `names`: the coordinate names for the columns (empty: q0.., p0..).
template <class S>
std::unique_ptr<Run> make_rn_run(const S& L, const Problem& pr, const Method& me,
                                 const std::vector<std::string>& names = {}) {
  constexpr int N = S::dim;
  using V = Vec<double, N>;
  RnView<S> view{L, names, !names.empty()};
  RunReport base = base_report(pr, me, L.name());
  const StepOptions opt = me.step_options();
  const double h = pr.step;

  if (pr.boundary_value) return make_sized_run<N>(erase_lagrangian(L), ErasedRnView<N>(view), pr, me, base, nullptr);

  V q, p, v0;
  initial_state(pr, L, q, p, v0);
  view.v0 = v0;
  view.sigma0 = velocity_hessian_scale(L, q, v0);
  if (!std::isfinite(view.energy(q, p))) refuse_nonfinite_energy(pr);
  report_structure(base, L, q, v0, pr);
  require_splitting_structure(base, me, pr);

  if (me.linearize || hamiltonian_theta_path(me, N))
    return make_run_time_sized_run(ErasedDynamicLagrangian(FixedAsDynamic<S>(L)), ErasedRnView<Eigen::Dynamic>(view), pr,
                               me, base, q, p, v0);

  if constexpr (is_separable_v<S>)
    if (collocation_applies(me))
      return collocation_run(view, SeparableGaussStep<S>(L, me.stages, h, opt, q), q, p, v0, base, pr.steps);

  if (theta_newton_path(me)) {
    const ThetaMap R(me.theta, me.map->name);
    if constexpr (is_separable_v<S>) {
      if (splitting_applies(me, R)) return splitting_run<RnView<S>, S, ThetaMap>(view, L, R, me, h, q, p, v0, base, pr.steps);
      if constexpr (S::dim >= 3) {
        if (separable_newton_applies(me)) {
          // any theta (a theta per stage included): Newton on the structured equation
          auto make = [&](double hk, const ThetaMap& Rk) { return SeparableThetaStep<S>(L, Rk.theta(), hk, opt, q); };
          base.step_path = StepPath::separable_newton;
          return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
        }
      }
    }
    auto make = [&](double hk, const ThetaMap& Rk) { return PositionMomentumStep<S, ThetaMap, false>(L, Rk, hk, opt); };
    return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
  }

  const SizedStart<N> start{q, p, v0};
  return make_sized_run<N>(erase_lagrangian(L), ErasedRnView<N>(view), pr, me, base, &start);
}

}  // namespace dvm::kernels
