// Kernels for systems on R^n of fixed size (a Lagrangian type S with S::dim): the
// system view (energy, invariants, columns, exact solution, diagnosis of a failed
// step) and make_rn_run, which picks the step type of the method once. Included only
// by the kernels_*.cc translation units.
#pragma once

#include <array>
#include <cmath>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "mechanics/hamiltonian.h"
#include "mechanics/legendre_lift.h"
#include "mechanics/systems.h"
#include "mechanics/systems_classic.h"
#include "mechanics/written_lagrangian.h"
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

inline InvariantReport scalar_invariant(const std::string& name, const std::string& legacy = "") {
  InvariantReport r;
  r.name = name;
  r.initial.assign(1, 0.0);
  r.legacy_key = legacy;
  return r;
}

inline std::vector<InvariantReport> invariant_names(const Kepler&) {
  return {scalar_invariant("angular momentum", "angular_momentum")};
}
inline void invariant_values(const Kepler&, const Vec<double, 2>& q, const Vec<double, 2>& p, double* out) {
  out[0] = Kepler::angular_momentum(q, p);
}
inline std::vector<InvariantReport> invariant_names(const ChargedParticle&) {
  return {scalar_invariant("angular momentum", "angular_momentum")};
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
template <int N>
std::vector<InvariantReport> invariant_names(const WrittenLagrangian<N>& L) {
  std::vector<InvariantReport> out;
  for (int i = 0; i < N && static_cast<int>(out.size()) < kMaxInvariantValues; ++i)
    if (L.cyclic(i)) out.push_back(scalar_invariant("p_" + L.system->coordinates[static_cast<std::size_t>(i)] + " (cyclic)"));
  return out;
}
template <int N>
void invariant_values(const WrittenLagrangian<N>& L, const Vec<double, N>&, const Vec<double, N>& p, double* out) {
  int k = 0;
  for (int i = 0; i < N && k < kMaxInvariantValues; ++i)
    if (L.cyclic(i)) out[k++] = p[i];
}

// ---- the monitored energy: a written energy where the scene gives one, else E_L -------
// (A separable system's v = M^{-1} p is in closed form or from a factored M, so
// dL/dv(q, v) = M v is p to round-off: E_L = <p, v> - L(q, v) without the gradient,
// a third of a Kepler Galerkin step's monitoring cost.)
template <class S, int N>
double monitored_energy(const S& L, const Vec<double, N>& q, const Vec<double, N>& v, const Vec<double, N>& p) {
  if constexpr (is_separable_v<S>)
    return p.dot(v) - L(q, v);
  else
    return energy(L, q, v);
}
template <int N>
double monitored_energy(const WrittenLagrangian<N>& L, const Vec<double, N>& q, const Vec<double, N>& v,
                        const Vec<double, N>& p) {
  return L.energy_at(q, v, p);
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

template <class S>
struct is_written : std::false_type {};
template <int N>
struct is_written<WrittenLagrangian<N>> : std::true_type {};

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
    auto check = [&](const Vec<double, N>& v) { require_regular_hessian<N>(velocity_hessian(L, q, v), where); };
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
  if constexpr (is_written<S>::value) {
    if (L.has_hamiltonian()) {
      const double H = L.hamiltonian(q, p), E = energy(L, q, v0);
      if (!(std::fabs(H - E) <= 1e-9 * std::fmax(1.0, std::fabs(E)))) {
        std::ostringstream m;
        m.precision(17);
        m << pr.hamiltonian_where << ": system.hamiltonian does not match the Legendre transform of the Lagrangian at "
          << "the initial state: H(q, p) = " << H << " but E_L(q, v) = <p, v> - L = " << E;
        throw InputError(m.str());
      }
    }
  }
}

// ---- the factory ---------------------------------------------------------------------
// Which parts of the method table are built for a system type (what validate() refuses
// for the system is not instantiated): the forms other than lagrangian and
// boundary-value problems.
struct AllKernels {
  static constexpr bool hamiltonian = true, sode = true, newmark = true, boundary_value = true;
};
struct LagrangianKernels {
  static constexpr bool hamiltonian = false, sode = false, newmark = false, boundary_value = false;
};
struct LagrangianHamiltonianKernels {
  static constexpr bool hamiltonian = true, sode = false, newmark = false, boundary_value = false;
};

// `names`: the coordinate names for the columns (empty: q0.., p0..).
template <class S, class Set = AllKernels>
std::unique_ptr<Run> make_rn_run(const S& L, const Problem& pr, const Method& me,
                                 const std::vector<std::string>& names = {}) {
  constexpr int N = S::dim;
  using V = Vec<double, N>;
  RnView<S> view{L, names, !names.empty()};
  RunReport base = base_report(pr, me, L.name());
  const StepOptions opt = me.step_options();
  const double h = pr.step;

  if (pr.boundary_value) {
    if constexpr (Set::boundary_value) {
      return std::visit(
          [&](const auto& R) -> std::unique_ptr<Run> {
            using Map = std::decay_t<decltype(R)>;
            return std::make_unique<BoundaryValueRun<RnView<S>, BoundaryValueProblem<S, Map>>>(
                view, BoundaryValueProblem<S, Map>(L, R, h), to_vec<N>(pr.q), to_vec<N>(pr.q_final), pr.steps, h,
                me.max_iterations, base, false);
          },
          rn_map(me));
    } else {
      throw InputError("problem.kind: unsupported");  // refused by validate()
    }
  }

  V q, p, v0;
  initial_state(pr, L, q, p, v0);
  view.v0 = v0;
  view.sigma0 = velocity_hessian_scale(L, q, v0);
  if (!std::isfinite(view.energy(q, p))) refuse_nonfinite_energy(pr);
  report_structure(base, L, q, v0, pr);
  require_splitting_structure(base, me, pr);

  if (me.galerkin) {
    if constexpr (is_separable_v<S>)
      if (collocation_applies(me))
        return collocation_run(view, SeparableGaussStep<S>(L, me.stages, h, opt, q), q, p, v0, base, pr.steps);
    return stepper_run(view, GalerkinStep<S>(L, me.quadrature, me.stages, h, opt), q, p, v0, base, pr.steps);
  }

  if (me.form == Form::newmark) {
    if constexpr (!Set::newmark) {
      throw InputError("integrator.form: unsupported");  // refused by validate()
    } else {
      const NewmarkStep<S> basic(L, h, me.newmark_gamma, me.newmark_beta, opt);
      auto make = [&](double hk, const NewmarkStep<S>& b) { return VelocityFormStep<NewmarkStep<S>>(b.with_step(hk)); };
      const auto stages = composition_stages(
          me, basic, me.newmark_gamma == 0.5, [](const NewmarkStep<S>& b) { return b.adjoint(); },
          [&](double) -> NewmarkStep<S> { throw InputError("integrator.thetas: unsupported"); });  // refused by validate()
      return composable_run(view, me, h, stages, make, q, p, v0, base, pr.steps);
    }
  }

  return std::visit(
      [&](const auto& R) -> std::unique_ptr<Run> {
        using Map = std::decay_t<decltype(R)>;
        switch (me.form) {
          case Form::lagrangian: {
            if constexpr (is_separable_v<S> && std::is_same_v<Map, ThetaMap>) {
              if (splitting_applies(me, R))
                return splitting_run<RnView<S>, S, Map>(view, L, R, me, h, q, p, v0, base, pr.steps);
              if (S::dim >= 3 && separable_newton_applies(me)) {
                // any theta (a theta per stage included): Newton on the structured equation
                auto make = [&](double hk, const Map& Rk) { return SeparableThetaStep<S>(L, Rk.theta(), hk, opt, q); };
                base.step_path = "separable-newton";
                return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
              }
            }
            auto make = [&](double hk, const Map& Rk) { return PositionMomentumStep<S, Map>(L, Rk, hk, opt); };
            return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
          }
          case Form::hamiltonian: {
            if constexpr (!Set::hamiltonian) {
              throw InputError("integrator.form: unsupported");  // refused by validate()
            } else {
              // the scene's own H for a written L (H from it would need a third level of Jets)
              using H = std::conditional_t<is_written<S>::value, WrittenHamiltonian<N>, LegendreHamiltonian<S>>;
              const H ham = [&] {
                if constexpr (is_written<S>::value)
                  return H{L.system};
                else
                  return H(L);
              }();
              if (me.effective_lift() == Lift::none) {
                // the map itself on T*Q = R^{2n} (the theta family: validate refuses written maps)
                if constexpr (std::is_same_v<Map, ThetaMap>) {
                  auto make = [&](double hk, const Map& Rk) {
                    return HamiltonianStep<H, OnCotangentBundle<Map>>(ham, OnCotangentBundle<Map>{Rk}, hk, opt);
                  };
                  return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
                }
                throw InputError("integrator.lift: unsupported");
              }
              auto make = [&](double hk, const Map& Rk) { return HamiltonianStep<H, Map>(ham, Rk, hk, opt); };
              return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
            }
          }
          case Form::sode1:
          case Form::sode2: {
            if constexpr (!Set::sode) {
              throw InputError("integrator.form: unsupported");  // refused by validate()
            } else {
              // the lift of the adjoint map gives the adjoint SODE step (Prop. 3.3 for the
              // tangent lift; R_d^L is the cotangent lift of R_d conjugated by FL, Prop. 3.7)
              const SodeForm f = me.form == Form::sode1 ? SodeForm::sode1 : SodeForm::sode2;
              if (me.effective_lift() == Lift::legendre) {
                // (the theta family: validate refuses written maps)
                if constexpr (std::is_same_v<Map, ThetaMap>) {
                  using RL = LegendreLiftedMap<S, Map>;
                  auto make = [&, f](double hk, const Map& Rk) {
                    return VelocityFormStep<SodeStep<S, RL>>(SodeStep<S, RL>(L, RL(L, Rk), hk, f, opt));
                  };
                  return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
                }
                throw InputError("integrator.lift: unsupported");
              }
              auto make = [&, f](double hk, const Map& Rk) {
                const auto lift = tangent_lift(Rk);
                using Step = SodeStep<S, std::decay_t<decltype(lift)>>;
                return VelocityFormStep<Step>(Step(L, lift, hk, f, opt));
              };
              return composable_run(view, me, h, rn_stages(me, R), make, q, p, v0, base, pr.steps);
            }
          }
          case Form::newmark:
            break;
        }
        throw InputError("integrator.form: unsupported");
      },
      rn_map(me));
}

}  // namespace dvm::kernels
