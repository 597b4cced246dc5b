// Kernels for systems on S^2, (S^2)^n and SO(3): the system view (stored coordinates,
// momentum maps, columns) and make_manifold_run, which picks the step type of the
// method once. The steps are solved in the chart centred at the current point
// (solvers/manifold_step.h); their output on each space (one rule for the built-ins and
// the Lagrangians written there: the momentum of position column c is p_c):
//   S^2     CSV  t, x, y, z, p_x, p_y, p_z, energy, J3          (J3 = (x cross p)_3)
//   (S^2)^n CSV  t, x1, y1, z1, ..., p_x1, p_y1, p_z1, ..., energy, J3
//   SO(3)   CSV  t, qw, qx, qy, qz, pi1, pi2, pi3, energy, m0, m1, m2 (rigid body: the
//                spatial angular momentum R pi) or J3 (heavy top: its vertical part)
// Included only by the kernels_*.cc translation units.
#pragma once

#include <algorithm>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "mechanics/manifold_hamiltonian.h"
#include "mechanics/manifold_systems.h"
#include "mechanics/written_manifold.h"
#include "solvers/runtime/factories.h"
#include "solvers/manifold_boundary_value.h"
#include "solvers/manifold_composition.h"
#include "solvers/manifold_galerkin_step.h"
#include "solvers/manifold_constrained_step.h"
#include "solvers/manifold_hamiltonian_step.h"
#include "solvers/manifold_step.h"
#include "solvers/runtime/kernels.h"
#include "solvers/runtime/manifold_map_of.h"

namespace dvm::kernels {

using V3 = Vec<double, 3>;
using M3 = Mat<double, 3, 3>;

// ---- maps from registry entries ------------------------------------------------------
// (Galerkin takes no map: the default map's type is only a template argument there.)
inline SphereMap sphere_map(const Method& m) {
  if (!m.map) return SphereMap(RetractionKind::exp, 0.5, "sphere-exp");
  return sphere_map_of(*m.map, m.theta, m.written_retraction);
}
inline SO3Map so3_map(const Method& m) {
  if (!m.map) return SO3Map(RetractionKind::exp, 0.5, "so3-exp");
  return so3_map_of(*m.map, m.theta, m.written_retraction);
}

// The map of a composition's stage at theta (integrator.thetas): the same retraction.
inline SphereMap at_theta(const SphereMap& R, double th) { return R.at_theta(th, R.name()); }
inline SO3Map at_theta(const SO3Map& R, double th) { return R.at_theta(th, R.name()); }
template <int K>
SpherePowerMap<K> at_theta(const SpherePowerMap<K>& R, double th) {
  return SpherePowerMap<K>(at_theta(R.factor(), th));
}

// ---- built-in or written: one set of steps per space ---------------------------------
// A Lagrangian (or Hamiltonian) on S^2 or SO(3) that is either a built-in B or one
// written in the scene, W. The kernels are instantiated once for both (the steps,
// maps, compositions, Galerkin step and Hamiltonian steps of a space are most
// of the build); the price is one predictable branch per evaluation of L or H, and GCC
// inlining the Jet arithmetic differently, faster for some systems and slower for
// others than a build per system.
template <class B, class W>
struct BuiltinOr {
  using Manifold = typename B::Manifold;
  static constexpr int dim = Manifold::dim;
  std::optional<B> builtin;
  std::optional<W> written;

  std::string name() const { return written ? written->name() : builtin->name(); }
  // The built-in branch is the expected one and stays inlined; the written one is a
  // call (its tape interpreter is large).
  template <class T, int N>
  [[gnu::always_inline]] T operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    if (__builtin_expect(written.has_value(), 0)) return call_written(*written, x, v);
    return (*builtin)(x, v);
  }
  template <class T>
  [[gnu::always_inline]] T operator()(const Mat<T, 3, 3>& R, const Vec<T, 3>& w) const {
    if (__builtin_expect(written.has_value(), 0)) return call_written(*written, R, w);
    return (*builtin)(R, w);
  }

 private:
  template <class X, class V>
  [[gnu::noinline]] static typename V::Scalar call_written(const W& f, const X& x, const V& v) {
    return f(x, v);
  }
};

template <class Builtin>
using BuiltinOrWritten = BuiltinOr<Builtin, WrittenManifoldLagrangian<typename Builtin::Manifold>>;
template <class Builtin>
using BuiltinOrWrittenHamiltonian = BuiltinOr<decltype(hamiltonian_of(std::declval<const Builtin&>())),
                                              WrittenManifoldHamiltonian<typename Builtin::Manifold>>;

template <class Builtin>
BuiltinOrWrittenHamiltonian<Builtin> hamiltonian_of(const BuiltinOrWritten<Builtin>& L) {
  BuiltinOrWrittenHamiltonian<Builtin> H;
  if (L.written)
    H.written = hamiltonian_of(*L.written);
  else
    H.builtin = hamiltonian_of(*L.builtin);
  return H;
}

template <class Builtin>
BuiltinOrWritten<Builtin> as_builtin(const Builtin& b) {
  BuiltinOrWritten<Builtin> L;
  L.builtin = b;
  return L;
}
template <class Builtin>
BuiltinOrWritten<Builtin> as_written(const WrittenManifoldLagrangian<typename Builtin::Manifold>& w) {
  BuiltinOrWritten<Builtin> L;
  L.written = w;
  return L;
}

// ---- per system: stored coordinates, momentum maps, columns ----------------------------
template <int N>
std::vector<double> stored(const Vec<double, N>& x) {
  return std::vector<double>(x.data(), x.data() + N);
}
inline std::vector<double> stored(const M3& R) {
  const Vec<double, 4> q = SO3::to_quaternion(R);
  return {q[0], q[1], q[2], q[3]};
}
template <int N>
std::vector<double> embedded(const Vec<double, N>& x) {
  return stored(x);
}
inline std::vector<double> embedded(const M3& R) { return std::vector<double>(R.data(), R.data() + 9); }

inline std::vector<double> momentum_map(const SphericalPendulum&, const V3& x, const V3& p) {
  return {SphericalPendulum::vertical_momentum(x, p)};
}
inline std::vector<double> momentum_map(const RigidBody&, const M3& R, const V3& p) {
  const V3 m = RigidBody::spatial_momentum(R, p);
  return {m[0], m[1], m[2]};
}
inline std::vector<double> momentum_map(const HeavyTop&, const M3& R, const V3& p) {
  return {HeavyTop::vertical_momentum(R, p)};
}
template <int K>
std::vector<double> momentum_map(const SphericalChain<K>&, const Vec<double, 3 * K>& x, const Vec<double, 3 * K>& p) {
  return {SphericalChain<K>::vertical_momentum(x, p)};
}

inline std::vector<std::string> point_columns(const SphericalPendulum&) { return {"x", "y", "z"}; }
inline std::vector<std::string> point_columns(const RigidBody&) { return {"qw", "qx", "qy", "qz"}; }
inline std::vector<std::string> point_columns(const HeavyTop&) { return {"qw", "qx", "qy", "qz"}; }
template <int K>
std::vector<std::string> point_columns(const SphericalChain<K>&) {
  std::vector<std::string> out;
  for (int i = 1; i <= K; ++i)
    for (const char* c : {"x", "y", "z"}) out.push_back(c + std::to_string(i));
  return out;
}
// The stored covector's columns: p_c for each position column c (S^2, (S^2)^K); the
// body angular momentum pi1, pi2, pi3 on SO(3).
template <class S>
std::vector<std::string> covector_columns(const S& L) {
  if constexpr (std::is_same_v<typename S::Manifold, SO3>) {
    return {"pi1", "pi2", "pi3"};
  } else {
    std::vector<std::string> out;
    for (const std::string& c : point_columns(L)) out.push_back("p_" + c);
    return out;
  }
}
inline std::vector<std::string> momentum_columns(const SphericalPendulum&) { return {"J3"}; }
inline std::vector<std::string> momentum_columns(const RigidBody&) { return {"m0", "m1", "m2"}; }
inline std::vector<std::string> momentum_columns(const HeavyTop&) { return {"J3"}; }
template <int K>
std::vector<std::string> momentum_columns(const SphericalChain<K>&) {
  return {"J3"};
}
// The name of the conserved momentum in the report (and its historical JSON keys).
template <class S>
std::string momentum_name(const S&) {
  return std::is_same_v<S, RigidBody> ? "spatial angular momentum" : "vertical angular momentum";
}
template <class S>
std::vector<InvariantReport> momentum_reports(const S& L, const double* I0) {
  InvariantReport r;
  r.name = momentum_name(L);
  for (int i = 0; i < static_cast<int>(momentum_columns(L).size()); ++i) r.initial.push_back(I0[i]);
  r.array = true;
  return {r};
}

// Written systems (mechanics/written_manifold.h): columns named after the text's
// names, and J_k for each axis whose rotations leave L unchanged.
template <class M>
std::vector<std::string> point_columns(const WrittenManifoldLagrangian<M>& L) {
  if constexpr (std::is_same_v<M, SO3>)
    return {"qw", "qx", "qy", "qz"};
  else
    return L.system->coordinates;
}
template <class M>
std::vector<std::string> covector_columns(const WrittenManifoldLagrangian<M>& L) {
  std::vector<std::string> out;
  for (int i = 0; i < M::template Tangent<double>::RowsAtCompileTime; ++i)
    out.push_back(std::is_same_v<M, SO3> ? "pi" + std::to_string(i + 1)
                                         : "p_" + L.system->coordinates[static_cast<std::size_t>(i)]);
  return out;
}
template <class M>
std::vector<double> momentum_map(const WrittenManifoldLagrangian<M>& L, const typename M::template Point<double>& x,
                                 const typename M::template Tangent<double>& p) {
  return L.momenta(x, p);
}
template <class M>
std::vector<std::string> momentum_columns(const WrittenManifoldLagrangian<M>& L) {
  std::vector<std::string> out;
  for (int k = 0; k < 3; ++k)
    if (L.symmetric_axes[static_cast<std::size_t>(k)]) out.push_back("J" + std::to_string(k + 1));
  return out;
}
template <class M>
std::vector<InvariantReport> momentum_reports(const WrittenManifoldLagrangian<M>& L, const double* I0) {
  std::vector<InvariantReport> out;
  int i = 0;
  for (int k = 0; k < 3; ++k)
    if (L.symmetric_axes[static_cast<std::size_t>(k)]) {
      InvariantReport r;
      r.name = std::string(std::is_same_v<M, SO3> ? "spatial " : "") + "angular momentum about e" +
               std::to_string(k + 1);
      r.initial = {I0[i++]};
      out.push_back(r);
    }
  return out;
}
template <class M>
double monitored_energy(const WrittenManifoldLagrangian<M>& L, const typename M::template Point<double>& x,
                        const typename M::template Tangent<double>& p) {
  return L.energy_at(x, manifold_legendre_inverse(L, x, p), p);
}
template <class S>
double monitored_energy(const S& L, const typename S::Manifold::template Point<double>& x,
                        const typename S::Manifold::template Tangent<double>& p) {
  return manifold_energy(L, x, manifold_legendre_inverse(L, x, p));
}

// ---- the view -------------------------------------------------------------------------
template <class S, class Map>
struct ManifoldView {
  using Mf = typename Map::Manifold;
  using Point = typename Mf::template Point<double>;
  using Covector = typename Mf::template Tangent<double>;
  static constexpr int C = Covector::RowsAtCompileTime;
  static constexpr bool erase_steps = true;  // (AnyPointStep: their steps solve an equation each step)
  S L;
  // With forces (system.forces) the momentum maps of L's symmetries are not conserved:
  // their columns are written, but they are not reported as invariants.
  bool forced = false;
  // With constraints (system.constraints on S^2 or SO(3)), or null.
  static constexpr bool kConstrainable = std::is_same_v<Mf, Sphere> || std::is_same_v<Mf, SO3>;
  std::shared_ptr<const ManifoldConstraints<Mf>> constraints = nullptr;
  // The run's control inputs (system.controls, read by the force), or null: after step
  // k - 1 -> k the force reads u_k (ControlSignal::set_step).
  std::shared_ptr<const ControlSignal> controls = nullptr;
  void after_step(std::int64_t k, double) const {
    if (controls) controls->set_step(k);
  }

  std::vector<std::string> columns() const {
    std::vector<std::string> c{"t"};
    for (const auto& n : point_columns(L)) c.push_back(n);
    for (const auto& n : covector_columns(L)) c.push_back(n);
    c.push_back("energy");
    for (const auto& n : momentum_columns(L)) c.push_back(n);
    return c;
  }
  int row_size() const { return static_cast<int>(columns().size()); }
  void fill_row(double* row, double t, const Point& q, const Covector& p, double E) const {
    int k = 0;
    row[k++] = t;
    for (double x : stored(q)) row[k++] = x;
    for (int i = 0; i < C; ++i) row[k++] = p[i];
    row[k++] = E;
    for (double x : momentum_map(L, q, p)) row[k++] = x;
  }
  double energy(const Point& q, const Covector& p) const { return monitored_energy(L, q, p); }
  int invariant_count() const { return forced ? 0 : static_cast<int>(momentum_columns(L).size()); }
  void invariants(const Point& q, const Covector& p, double* out) const {
    if (forced) return;
    int k = 0;
    for (double x : momentum_map(L, q, p)) out[k++] = x;
  }
  std::vector<InvariantReport> invariant_reports(const double* I0) const {
    return forced ? std::vector<InvariantReport>() : momentum_reports(L, I0);
  }
  double point_defect(const Point& q) const { return Mf::point_defect(q); }
  // The relative residuals of the constraints and of their hidden constraint at (t, q, p)
  // (ManifoldConstraints::relative_residuals, v = FL^{-1}(q, p)); false without.
  // (compiled for the spaces that take constraints only)
  template <bool C = kConstrainable, std::enable_if_t<C, int> = 0>
  bool constraint_residuals(double t, const Point& q, const Covector& p, double& g, double& hidden) const {
    if (!constraints) return false;
    constraints->relative_residuals(t, q, manifold_legendre_inverse(L, q, p), g, hidden);
    return true;
  }
  void finish_report(RunReport& r, const Point& q, const Covector& p) const {
    r.q_final = stored(q);
    r.p_final = std::vector<double>(p.data(), p.data() + C);
    r.q_embedded = embedded(q);
  }
  void diagnose(std::string&, const Point&, const Covector&) const {}
  bool exact(double, const Point&, const Covector&, std::vector<double>&, std::vector<double>&) const { return false; }
};

// Whether J3 is among the conserved momenta (the spread a boundary-value run reports).
template <class S>
bool vertical_symmetry(const S&) {
  return true;
}
template <class M>
bool vertical_symmetry(const WrittenManifoldLagrangian<M>& L) {
  return L.symmetric_axes[2];
}

template <class S>
struct is_written : std::false_type {};
template <class M>
struct is_written<WrittenManifoldLagrangian<M>> : std::true_type {};

// The initial state (q, p, v0); refuses a Lagrangian that is degenerate there and a
// written Hamiltonian that disagrees with the Legendre transform of L.
template <class S, class Map>
void manifold_initial_state(const Problem& pr, const S& L, typename Map::Manifold::template Point<double>& q,
                            typename Map::Manifold::template Tangent<double>& p,
                            typename Map::Manifold::template Tangent<double>& v0) {
  using Mf = typename Map::Manifold;
  using Point = typename Mf::template Point<double>;
  using Covector = typename Mf::template Tangent<double>;
  if constexpr (std::is_same_v<Mf, SO3>)
    q = SO3::from_quaternion(Vec<double, 4>(pr.q[0], pr.q[1], pr.q[2], pr.q[3]));
  else
    q = Eigen::Map<const Point>(pr.q.data());
  const std::string where = pr.written ? pr.written_where : pr.origin + ": system";
  if (pr.momentum_given) {
    p = Eigen::Map<const Covector>(pr.p.data());
    try {
      v0 = manifold_legendre_inverse(L, q, p);
    } catch (const DegenerateLagrangianError& e) {
      throw InputError(where + ": the Lagrangian is degenerate at the initial state: " + e.what());
    }
  } else {
    v0 = Eigen::Map<const Covector>(pr.v.data());
    p = manifold_legendre(L, q, v0);
  }
  if constexpr (is_written<S>::value) {
    // a Lagrangian written in the scene: its velocity Hessian where the run starts, and
    // the written Hamiltonian against the Legendre transform of L there
    require_regular_hessian(manifold_velocity_hessian(L, q, v0), where);
    if (L.has_hamiltonian()) {
      const double H = hamiltonian_of(L)(q, p), E = manifold_energy(L, q, v0);
      if (!(std::fabs(H - E) <= 1e-9 * std::fmax(1.0, std::fabs(E)))) {
        std::ostringstream m;
        m.precision(17);
        m << pr.hamiltonian_where << ": system.hamiltonian does not match the Legendre transform of the Lagrangian "
          << "at the initial state: H(x, p) = " << H << " but E_L(x, v) = <p, v> - L = " << E;
        throw InputError(m.str());
      }
    }
  }
}

// The initial state of a constrained run on S^2 or SO(3) (system.constraints): the rows
// of Dg(0, q) independent, q on the constraints and v on their hidden constraint, each to
// kConstraintStartTolerance relative (ManifoldConstraints::relative_residuals' measures);
// a velocity off the hidden constraint is refused, or projected where the scene sets
// initial.project_velocity (the step's right transform: p moved along the normals).
template <class Step, class S>
void check_manifold_constrained_start(const Problem& pr, const S& shown, const Step& step,
                                      const ManifoldConstraints<typename Step::M>& con,
                                      const typename Step::Point& q, typename Step::Covector& p,
                                      typename Step::Covector& v0) {
  using Mf = typename Step::M;
  constexpr int n = Mf::dim;
  const int m = con.count();
  Eigen::VectorXd g(m), gt(m), norms(m), across(m);
  Eigen::MatrixXd G(m, n);
  con.chart_gradient(0.0, q, g, G, gt);
  const Vec<double, n> nu = Mf::tangent_coordinates(q, v0);
  for (int i = 0; i < m; ++i) {
    norms[i] = G.row(i).norm();
    across[i] = G.row(i).dot(nu) + gt[i];
  }
  constexpr bool rotation = std::is_same_v<Mf, SO3>;  // (the keys of the initial state there)
  if (!G.allFinite() || !g.allFinite() || !gt.allFinite())
    check_constraint_start_terms(pr, g, norms, across, 1.0, 1.0, "");  // (refuses: not finite)
  require_constraint_rank(pr, G, std::string(" along ") + Mf::name);
  const int i = check_constraint_start_terms(pr, g, norms, across, q.norm(), nu.norm(),
                                             rotation ? "initial.rotation (or initial.R)" : "initial.q");
  if (i < 0) return;
  if (pr.project_velocity) {
    Vec<double, n> pi = Mf::covector_to_local(q, p);
    StepSummary s;
    if (!step.project(0.0, q, pi, s)) throw InputError(pr.project_velocity_where + ": " + s.message);
    p = Mf::covector_from_local(q, pi);
    v0 = manifold_legendre_inverse(shown, q, p);
    return;
  }
  refuse_velocity_off_constraint(pr, i, across[i], nu.norm(), norms[i],
                                 pr.momentum_given ? (rotation ? "initial.pi" : "initial.p")
                                                   : (rotation ? "initial.omega" : "initial.v"));
}

// The force a scene writes on S^2 or SO(3) (system.forces), refused where it is not
// finite at the initial state (q, v0) and t = 0; with the run's control signal where
// the system declares controls (system.controls), which the view advances.
template <class Mf, class View>
std::shared_ptr<const ManifoldForce<Mf>> checked_force(const Problem& pr, const typename Mf::template Point<double>& q,
                                                       const typename Mf::template Tangent<double>& v0, View& view) {
  if (!pr.written->controls.empty()) view.controls = std::make_shared<const ControlSignal>(pr.written->controls);
  auto force = std::make_shared<const ManifoldForce<Mf>>(pr.written, view.controls);
  Vec<double, ManifoldForce<Mf>::size> F0;
  force->value(0.0, q, v0, F0);
  if (!F0.allFinite()) throw InputError(pr.forces_where + ": the force is not finite at the initial state (t = 0)");
  return force;
}

// ---- the factory ---------------------------------------------------------------------
// Which parts of the method are built for this system (Parts, factories.h: the rest was
// refused by validate(), which reads the same constant, and is not instantiated): the
// Hamiltonian form, Galerkin, boundary values.
// The steps integrate L; the run reports as `Shown` (its name, columns, energy and
// momentum maps): a system that is a special case of another one (the free rigid body
// is the heavy top with m g = 0, to the bit) runs the other's steps, instantiated once.
template <const factories::KernelParts& Parts, class S, class Map, class Shown = S>
std::unique_ptr<Run> make_manifold_run(const S& L, const Map& R, const Problem& pr, const Method& me,
                                       const Shown& shown) {
  constexpr bool Hamiltonian = Parts.hamiltonian, Galerkin = Parts.galerkin, BoundaryValue = Parts.boundary_value;
  static_assert(std::is_same_v<typename Shown::Manifold, typename S::Manifold>, "shown on another manifold");
  using View = ManifoldView<Shown, Map>;
  using Mf = typename Map::Manifold;
  using Point = typename View::Point;
  using Covector = typename View::Covector;
  View view{shown, pr.forced()};
  RunReport base = base_report(pr, me, shown.name());
  base.manifold = Mf::name;
  const StepOptions opt = me.step_options();
  const double h = pr.step;

  // (validate refuses these first: the steps below but the constrained one hold no constraint)
  if (pr.constrained() && (pr.boundary_value || me.galerkin || me.form != Form::lagrangian))
    throw InputError(pr.constraints_where + ": constraints on S^2 and SO(3) enter the lagrangian form of the maps");
  if (pr.boundary_value) {
    if constexpr (BoundaryValue)
      return std::make_unique<BoundaryValueRun<View, SphereBoundaryValueProblem<S, Map>>>(
          view, SphereBoundaryValueProblem<S, Map>(L, R, h), Point(pr.q[0], pr.q[1], pr.q[2]),
          Point(pr.q_final[0], pr.q_final[1], pr.q_final[2]), pr.steps, h, me.max_iterations, base,
          vertical_symmetry(L));
    else
      throw InputError("problem.kind: unsupported");  // refused by validate()
  }
  Point q;
  Covector p, v0;
  manifold_initial_state<Shown, Map>(pr, shown, q, p, v0);
  if (!std::isfinite(view.energy(q, p))) refuse_nonfinite_energy(pr);

  const bool forced = pr.forced();  // (a written Lagrangian on S^2 or SO(3) with system.forces)
  if (me.galerkin) {
    if constexpr (Galerkin) {
      // system.forces: the forced Galerkin step (the discrete Lagrange-d'Alembert
      // principle at its quadrature nodes)
      if constexpr (std::is_same_v<Mf, Sphere> || std::is_same_v<Mf, SO3>)
        if (forced) {
          const auto force = checked_force<Mf>(pr, q, v0, view);
          base.forced = true;
          return stepper_run(view,
                             ManifoldGalerkinStep<S, ManifoldForce<Mf>>(L, me.quadrature, me.stages, h, opt, force), q,
                             p, v0, base, pr.steps);
        }
      return stepper_run(view, ManifoldGalerkinStep<S>(L, me.quadrature, me.stages, h, opt), q, p, v0, base,
                         pr.steps);
    } else {
      throw InputError("integrator.method: unsupported");  // refused by validate()
    }
  }
  const std::vector<Stage<Map>> stages = composition_stages(
      me, R, R.symmetric(), [](const Map& m) { return adjoint_map(m); },
      [&](double th) { return at_theta(R, th); });
  // runs of the lagrangian form on S^2 and SO(3) may write their steps' derivatives
  // (--linearize: ManifoldStep::derivatives), and those of the unforced hamiltonian form
  // (ManifoldHamiltonianStep::derivatives), not on (S^2)^K (validate refuses it)
  constexpr bool Linearizable = std::is_same_v<Mf, Sphere> || std::is_same_v<Mf, SO3>;
  auto composed = [&](auto make, auto linearizable) -> std::unique_ptr<Run> {
    using Step = decltype(make(h, R));
    constexpr bool Lin = decltype(linearizable)::value;
    if (me.composition == "none") return stepper_run<Lin>(view, make(h, R), q, p, v0, base, pr.steps);
    return stepper_run<Lin>(view, compose_stages<ComposedPointStep<Step>>(h, stages, make), q, p, v0, base, pr.steps);
  };
  if (me.form == Form::hamiltonian) {
    if constexpr (Hamiltonian) {
      using H = decltype(hamiltonian_of(L));
      // system.forces: the forced Hamilton equations sampled where Eq. 5.1 samples X_H
      if constexpr (std::is_same_v<Mf, Sphere> || std::is_same_v<Mf, SO3>)
        if (forced) {
          const auto force = checked_force<Mf>(pr, q, v0, view);
          base.forced = true;
          return composed(
              [&](double hk, const Map& Rk) {
                return ManifoldHamiltonianStep<H, Map, ManifoldForce<Mf>>(hamiltonian_of(L), Rk, hk, opt,
                                                                         VectorFieldSample::base_point, force);
              },
              std::false_type{});
        }
      if (forced) throw InputError(pr.forces_where + ": forces are written on R^n, S^2 and SO(3)");
      return composed(
          [&](double hk, const Map& Rk) { return ManifoldHamiltonianStep<H, Map>(hamiltonian_of(L), Rk, hk, opt); },
          std::integral_constant<bool, Linearizable>{});
    } else {
      throw InputError("integrator.form: unsupported");  // refused by validate()
    }
  }
  if (me.form != Form::lagrangian) throw InputError("integrator.form: unsupported");  // refused by validate()
  // system.constraints (S^2, SO(3)): the constrained step, with the force where the system
  // has one, composed or not
  if constexpr (View::kConstrainable)
    if (pr.constrained()) {
      const auto con = std::make_shared<const ManifoldConstraints<Mf>>(pr.written);
      check_manifold_constrained_start(pr, shown, ConstrainedManifoldStep<S, Map>(L, R, h, opt, con), *con, q, p, v0);
      view.constraints = con;
      base.constrained = true;
      base.constraints = con->count();
      if (!std::isfinite(view.energy(q, p))) refuse_nonfinite_energy(pr);
      // (one step type with a force or none)
      const std::shared_ptr<const ManifoldForce<Mf>> force = forced ? checked_force<Mf>(pr, q, v0, view) : nullptr;
      base.forced = forced;
      // (composed also for composition = "none", one stage: one run type)
      auto make = [&](double hk, const Map& Rk) { return ConstrainedManifoldStep<S, Map>(L, Rk, hk, opt, con, force); };
      return stepper_run(view, compose_stages<ComposedPointStep<decltype(make(h, R))>>(h, stages, make), q, p, v0, base,
                         pr.steps);
    }
  if (pr.constrained()) throw InputError(pr.constraints_where + ": constraints are written on R^n, S^2 and SO(3)");
  // system.forces: the forced step (the discrete Lagrange-d'Alembert principle at the
  // map's node), composed or not
  if constexpr (std::is_same_v<Mf, Sphere> || std::is_same_v<Mf, SO3>)
    if (forced) {
      const auto force = checked_force<Mf>(pr, q, v0, view);
      base.forced = true;
      return composed(
          [&](double hk, const Map& Rk) { return ManifoldStep<S, Map, ManifoldForce<Mf>>(L, Rk, hk, opt, force); },
          std::true_type{});
    }
  if (forced) throw InputError(pr.forces_where + ": forces are written on R^n, S^2 and SO(3)");
  return composed([&](double hk, const Map& Rk) { return ManifoldStep<S, Map>(L, Rk, hk, opt); },
                  std::integral_constant<bool, Linearizable>{});
}

template <const factories::KernelParts& Parts, class S, class Map>
std::unique_ptr<Run> make_manifold_run(const S& L, const Map& R, const Problem& pr, const Method& me) {
  return make_manifold_run<Parts, S, Map, S>(L, R, pr, me, L);
}

}  // namespace dvm::kernels
