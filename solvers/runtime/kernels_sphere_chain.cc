// Run kernels on (S^2)^n: the chain of spherical pendulums with any number of links
// (SphereChainStep, O(n) a step, solvers/sphere_chain_step.h), and at n = 1..4 the chain
// and Lagrangians written on (S^2)^K, K = 2..4, through one set of compiled steps per n
// (BuiltinOrWritten<SphericalChain<K>>, solvers/runtime/kernels_manifold.h).
#include "solvers/runtime/factories.h"
#include "solvers/runtime/flat_state_view.h"
#include "solvers/runtime/kernels_manifold.h"
#include "solvers/sphere_chain_step.h"

namespace dvm::factories {

namespace {

// What a run of the chain at any number of links monitors and writes: the columns of
// the compiled chain (t, x1, y1, z1, ..., p_x1, p_y1, p_z1, ..., energy, J3).
struct SphereChainView : kernels::FlatStateView {
  DynamicSphericalChain L;
  // the banded solver of the Legendre inverse: the steps' own (the energy is evaluated
  // between steps, and each step factors before it solves)
  std::shared_ptr<ChainCouplingSolve> legendre;
  std::vector<std::string> columns() const {
    std::vector<std::string> c{"t"};
    for (const char* prefix : {"", "p_"})
      for (int i = 1; i <= L.links(); ++i)
        for (const char* x : {"x", "y", "z"}) c.push_back(prefix + (x + std::to_string(i)));
    c.push_back("energy");
    c.push_back("J3");
    return c;
  }
  int row_size() const { return 6 * L.links() + 3; }
  void fill_row(double* row, double t, const Point& q, const Covector& p, double E) const {
    int k = 0;
    row[k++] = t;
    for (Eigen::Index i = 0; i < q.size(); ++i) row[k++] = q[i];
    for (Eigen::Index i = 0; i < p.size(); ++i) row[k++] = p[i];
    row[k++] = E;
    row[k++] = DynamicSphericalChain::vertical_momentum(q, p);
  }
  Eigen::VectorXd velocity(const Point& q, const Covector& p) const {
    return chain_legendre_inverse(L, q, p, *legendre);
  }
  double energy(const Point& q, const Covector& p) const { return L.energy(q, velocity(q, p)); }
  int invariant_count() const { return 1; }
  void invariants(const Point& q, const Covector& p, double* out) const {
    out[0] = DynamicSphericalChain::vertical_momentum(q, p);
  }
  std::vector<InvariantReport> invariant_reports(const double* I0) const {
    InvariantReport r;
    r.name = "vertical angular momentum";
    r.initial = {I0[0]};
    r.array = true;
    return {r};
  }
  double point_defect(const Point& q) const { return DynamicSpherePower::point_defect(q); }
};

// The chain at any number of links by SphereChainStep: the lagrangian form, any sphere
// map, alone or composed (a theta per stage included).
std::unique_ptr<Run> sphere_chain_run(const Problem& pr, const Method& me, const SphereMap& f, int links) {
  const auto& P = pr.params;
  const DynamicSphericalChain L(Eigen::VectorXd::Constant(links, P.at("m")), Eigen::VectorXd::Constant(links, P.at("l")),
                                P.at("g"));
  const std::shared_ptr<SphereChainStep::Work> work = SphereChainStep::workspace(L);
  const SphereChainView view{{}, L, work->solver};
  RunReport base = kernels::base_report(pr, me, L.name());
  base.manifold = DynamicSpherePower::name;
  base.step_path = StepPath::sphere_chain_banded_newton;
  const Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(pr.q.data(), 3 * links);
  Eigen::VectorXd p, v0;
  try {
    if (pr.momentum_given) {
      p = Eigen::Map<const Eigen::VectorXd>(pr.p.data(), 3 * links);
      v0 = view.velocity(q, p);
    } else {
      v0 = Eigen::Map<const Eigen::VectorXd>(pr.v.data(), 3 * links);
      p = chain_legendre(L, q, v0);
    }
    if (!std::isfinite(view.energy(q, p))) kernels::refuse_nonfinite_energy(pr);
  } catch (const std::domain_error& e) {
    throw InputError(pr.origin + ": system: the Lagrangian is degenerate at the initial state: " + e.what());
  }
  const StepOptions opt = me.step_options();
  const std::vector<kernels::Stage<SphereMap>> stages = kernels::composition_stages(
      me, f, f.symmetric(), [](const SphereMap& m) { return adjoint_map(m); },
      [&](double th) { return kernels::at_theta(f, th); });
  auto make = [&](double hk, const SphereMap& Rk) { return SphereChainStep(L, Rk, hk, opt, work); };
  if (me.composition == "none") return kernels::stepper_run(view, make(pr.step, f), q, p, v0, base, pr.steps);
  return kernels::stepper_run(view, kernels::compose_stages<ComposedPointStep<SphereChainStep>>(pr.step, stages, make),
                              q, p, v0, base, pr.steps);
}

// Calls run(std::integral_constant<int, n>) for n in K..4, instantiating run for
// those sizes only; throws InputError(what) for any other n.
template <int K, class F>
std::unique_ptr<Run> for_factors(int n, F&& run, const char* what) {
  if (n == K) return run(std::integral_constant<int, K>{});
  if constexpr (K < 4)
    return for_factors<K + 1>(n, run, what);
  else
    throw InputError(what);
}

}  // namespace

std::unique_ptr<Run> spherical_chain(const Problem& pr, const Method& me) {
  const auto& P = pr.params;
  const SphereMap f = kernels::sphere_map(me);
  const int links = static_cast<int>(P.at("n"));
  if (me.use_structure && me.solver == SolverKind::newton) return sphere_chain_run(pr, me, f, links);
  if (links > 4) {
    const std::string n = "system.params.n = " + std::to_string(links);
    if (!me.use_structure)
      throw InputError("integrator.use_structure = false: the compiled steps of the spherical chain take 1 to 4 links, "
                       "got " + n + "; expected use_structure = true (the chain's own step, any number of links)");
    throw InputError("integrator.solver = \"tiny\": the chain's own step of any number of links solves by Newton, "
                     "and the compiled steps take 1 to 4 links, got " + n + "; expected solver = \"newton\"");
  }
  auto run = [&](auto k) {
    constexpr int K = decltype(k)::value;
    const SphericalChain<K> L(Vec<double, K>::Constant(P.at("m")), Vec<double, K>::Constant(P.at("l")), P.at("g"));
    if constexpr (K == 1) {  // (S^2)^1 is written as S^2 (kernels_sphere.cc): no written branch
      return kernels::make_manifold_run<kSpherePowerParts, SphericalChain<1>, SpherePowerMap<1>>(
          L, SpherePowerMap<1>(f), pr, me);
    } else {
      using Sys = kernels::BuiltinOrWritten<SphericalChain<K>>;
      return kernels::make_manifold_run<kSpherePowerParts, Sys, SpherePowerMap<K>, SphericalChain<K>>(
          kernels::as_builtin(L), SpherePowerMap<K>(f), pr, me, L);
    }
  };
  return for_factors<1>(links, run, "system.params.n: the compiled steps of the spherical chain take 1 to 4 links");
}

std::unique_ptr<Run> written_sphere_power(const Problem& pr, const Method& me) {
  const SphereMap f = kernels::sphere_map(me);
  auto run = [&](auto k) {
    constexpr int K = decltype(k)::value;
    using Sys = kernels::BuiltinOrWritten<SphericalChain<K>>;
    const WrittenManifoldLagrangian<SpherePower<K>> L(pr.written);
    return kernels::make_manifold_run<kSpherePowerParts, Sys, SpherePowerMap<K>,
                                      WrittenManifoldLagrangian<SpherePower<K>>>(
        kernels::as_written<SphericalChain<K>>(L), SpherePowerMap<K>(f), pr, me, L);
  };
  return for_factors<2>(pr.written->factors, run, "system.space: Lagrangians are written on (S^2)^K for K = 2 to 4");
}

}  // namespace dvm::factories
