// Lagrangians and Hamiltonians written in a scene on S^2 and SO(3): a WrittenSystem
// (mechanics/written_lagrangian.h) whose space is the sphere or the rotation group,
// evaluated as a system of mechanics/manifold_systems.h, so every step, map,
// composition and Galerkin method built for the spherical pendulum, the rigid body
// and the heavy top runs it unchanged.
//
//   S^2    L(x, v): x the embedded unit vector, v = dx/dt tangent at x (v.x = 0); the
//          text names their components after the coordinates (default x, y, z and
//          x_dot, y_dot, z_dot). H(x, p) takes the stored covector p (a tangent
//          3-vector acting by v -> p.v) as p_x, p_y, p_z.
//   (S^2)^K  K unit vectors x_1 ... x_K stacked in one 3K-vector (SpherePower<K>), the
//          coordinates named three per factor (default x1, y1, z1, x2, ...); it runs
//          the spherical chain's steps.
//   SO(3)  L(R, w): R11 ... R33 the entries of the rotation matrix, w1 w2 w3 the body
//          angular velocity (dR/dt = R hat(w)); H(R, pi) with pi1 pi2 pi3 the body
//          angular momentum.
//
// The text is evaluated for every scalar type the steps use (nested Jets included):
// each evaluation reads the stored point and vector in place.
//
// Symmetries. A rotation Q about a coordinate axis e_k acts on S^2 by (x, v) ->
// (Q x, Q v), on (S^2)^K by the same Q on every factor, and on SO(3) by left
// multiplication (R, w) -> (Q R, w). Where L is invariant, Noether's theorem conserves
// J_k = (x cross p)_k on S^2 (sum_i (x_i cross p_i)_k on (S^2)^K) and the spatial
// angular momentum component J_k = (R pi)_k on SO(3). rotation_symmetries() finds the
// axes numerically: L at a few fixed sample states against L at their rotated images,
// equal to 1e-10 relative (and the constraints, where the scene writes some, likewise).
// Those J_k are reported as invariants; the built-in systems
// report the same quantities (vertical for the pendulum and the top, all three for the
// free body).
#pragma once

#include <array>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "mechanics/manifold_systems.h"
#include "mechanics/written_force.h"
#include "mechanics/written_lagrangian.h"

namespace dvm {

namespace written_manifold_detail {

// The number of S^2 factors of M: 1 for S^2, K for (S^2)^K, 0 for SO(3).
template <class M>
struct sphere_factors : std::integral_constant<int, 0> {};
template <>
struct sphere_factors<Sphere> : std::integral_constant<int, 1> {};
template <int K>
struct sphere_factors<SpherePower<K>> : std::integral_constant<int, K> {};

template <class M>
constexpr WrittenSystem::Space space_of() {
  static_assert(sphere_factors<M>::value > 0 || std::is_same_v<M, SO3>,
                "written systems live on R^n, S^2, (S^2)^K or SO(3)");
  return sphere_factors<M>::value > 0 ? WrittenSystem::Space::sphere : WrittenSystem::Space::rotation;
}

template <class M>
const std::shared_ptr<const WrittenSystem>& checked(const std::shared_ptr<const WrittenSystem>& s) {
  if (!s || s->lagrangian.empty()) throw std::invalid_argument("a written system needs a Lagrangian");
  if (s->space != space_of<M>() || (sphere_factors<M>::value > 0 && s->factors != sphere_factors<M>::value))
    throw std::invalid_argument(s->name + ": the written system does not live on " + std::string(M::name) +
                                (sphere_factors<M>::value > 1 ? " with " + std::to_string(sphere_factors<M>::value) +
                                                                    " factors"
                                                              : std::string()));
  return s;
}

// J = sum_i x_i cross p_i over the S^2 factors of a stacked point.
template <int N>
Vec<double, 3> total_cross(const Vec<double, N>& x, const Vec<double, N>& p) {
  Vec<double, 3> J = Vec<double, 3>::Zero();
  for (int i = 0; i < N / 3; ++i)
    J += Vec<double, 3>(x.template segment<3>(3 * i)).cross(Vec<double, 3>(p.template segment<3>(3 * i)));
  return J;
}

// The rotation by angle a about the coordinate axis k.
inline Mat<double, 3, 3> axis_rotation(int k, double a) {
  Vec<double, 3> w = Vec<double, 3>::Zero();
  w[k] = a;
  return SO3::exp(w);
}

}  // namespace written_manifold_detail

template <class M>
struct WrittenManifoldLagrangian {
  using Manifold = M;
  static constexpr int dim = M::dim;
  template <class T>
  using P = typename M::template Point<T>;
  template <class T>
  using V = typename M::template Tangent<T>;

  std::shared_ptr<const WrittenSystem> system;
  std::array<bool, 3> symmetric_axes{};  // L is invariant under rotations about e_k

  explicit WrittenManifoldLagrangian(std::shared_ptr<const WrittenSystem> s)
      : system(written_manifold_detail::checked<M>(s)) {
    symmetric_axes = rotation_symmetries();
  }
  std::string name() const { return system->name; }

  // (one overload per space: the scalar is deduced from the argument types)
  template <class T, int N>
  T operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    static_assert(N == 3 * written_manifold_detail::sphere_factors<M>::value, "a point of (S^2)^K is a 3K-vector");
    return system->lagrangian(x.data(), v.data());
  }
  template <class T>
  T operator()(const Mat<T, 3, 3>& R, const Vec<T, 3>& w) const {
    static_assert(std::is_same_v<M, SO3>, "a point of SO(3) is a 3x3 matrix");
    return system->lagrangian(R.data(), w.data());
  }

  // The monitored energy: the written one if given, else E_L = <dL/dv, v> - L.
  double energy_at(const P<double>& x, const V<double>& v, const V<double>& p) const {
    if (!system->energy.empty()) return system->energy(x.data(), v.data(), p.data());
    return manifold_energy(*this, x, v);
  }
  bool has_hamiltonian() const { return !system->hamiltonian.empty(); }

  // J_k for each symmetric axis k, in order.
  std::vector<double> momenta(const P<double>& x, const V<double>& p) const {
    Vec<double, 3> J;
    if constexpr (std::is_same_v<M, SO3>)
      J = x * p;
    else
      J = written_manifold_detail::total_cross(x, p);
    std::vector<double> out;
    for (int k = 0; k < 3; ++k)
      if (symmetric_axes[static_cast<std::size_t>(k)]) out.push_back(J[k]);
    return out;
  }

  // Which rotations about e1, e2, e3 leave L unchanged (see the header comment).
  std::array<bool, 3> rotation_symmetries() const {
    using written_manifold_detail::axis_rotation;
    // fixed sample states, not aligned with any axis
    const Vec<double, 3> dirs[3] = {{0.48, -0.6, 0.64}, {-0.36, 0.8, 0.48}, {0.8, 0.36, -0.48}};
    const Vec<double, 3> vels[3] = {{0.7, -0.2, 0.5}, {-0.3, 0.9, 0.4}, {0.2, 0.6, -1.1}};
    std::array<bool, 3> out{};
    for (int k = 0; k < 3; ++k) {
      bool invariant = true;
      int compared = 0;
      for (int s = 0; s < 3 && invariant; ++s)
        for (double a : {0.7, 2.3}) {
          const Mat<double, 3, 3> Q = axis_rotation(k, a);
          double L0, L1;
          if constexpr (!std::is_same_v<M, SO3>) {
            // factor i starts from the sample directions in turn
            P<double> x, v, Qx, Qv;
            for (int i = 0; i < x.size() / 3; ++i) {
              const Vec<double, 3> xi = dirs[(s + i) % 3].normalized();
              const Vec<double, 3> vi = vels[(s + 2 * i) % 3] - vels[(s + 2 * i) % 3].dot(xi) * xi;
              x.template segment<3>(3 * i) = xi;
              v.template segment<3>(3 * i) = vi;
              Qx.template segment<3>(3 * i) = Q * xi;
              Qv.template segment<3>(3 * i) = Q * vi;
            }
            L0 = (*this)(x, v);
            L1 = (*this)(Qx, Qv);
            if (!constraints_invariant(x, Qx)) invariant = false;
          } else {
            const Mat<double, 3, 3> R = SO3::exp(Vec<double, 3>(1.3 * dirs[s]));
            L0 = (*this)(R, vels[s]);
            L1 = (*this)(Mat<double, 3, 3>(Q * R), vels[s]);
            if (!constraints_invariant(R, Mat<double, 3, 3>(Q * R))) invariant = false;
          }
          if (!invariant) break;
          if (!std::isfinite(L0) && !std::isfinite(L1)) continue;  // outside L's domain here
          ++compared;
          if (!(std::fabs(L1 - L0) <= 1e-10 * std::fmax(1.0, std::fabs(L0)))) {
            invariant = false;
            break;
          }
        }
      out[static_cast<std::size_t>(k)] = invariant && compared > 0;
    }
    return out;
  }

 private:
  // Whether the constraints (system.constraints, if any) take the same values at x and
  // at its rotated image y, at two times, to 1e-10 relative: a symmetry of L conserves
  // its momentum map only where the constraints share it.
  template <class X>
  bool constraints_invariant(const X& x, const X& y) const {
    constexpr int entries = static_cast<int>(X::SizeAtCompileTime);
    for (const Expression& g : system->constraints)
      for (double t : {0.0, 0.37}) {
        std::array<double, entries + 1> a, b;
        for (int i = 0; i < entries; ++i) {
          a[static_cast<std::size_t>(i)] = x.data()[i];
          b[static_cast<std::size_t>(i)] = y.data()[i];
        }
        a[entries] = b[entries] = t;
        const double g0 = g(a.data(), a.data()), g1 = g(b.data(), b.data());
        if (!std::isfinite(g0) && !std::isfinite(g1)) continue;
        if (!(std::fabs(g1 - g0) <= 1e-10 * std::fmax(1.0, std::fabs(g0)))) return false;
      }
    return true;
  }
};

template <class M>
struct WrittenManifoldHamiltonian {
  using Manifold = M;
  std::shared_ptr<const WrittenSystem> system;
  std::string name() const { return system->name; }
  template <class T, int N>
  T operator()(const Vec<T, N>& x, const Vec<T, N>& p) const {
    static_assert(N == 3 * written_manifold_detail::sphere_factors<M>::value, "a point of (S^2)^K is a 3K-vector");
    return system->hamiltonian(x.data(), static_cast<const T*>(nullptr), p.data());
  }
  template <class T>
  T operator()(const Mat<T, 3, 3>& R, const Vec<T, 3>& pi) const {
    static_assert(std::is_same_v<M, SO3>, "a point of SO(3) is a 3x3 matrix");
    return system->hamiltonian(R.data(), static_cast<const T*>(nullptr), pi.data());
  }
};

// The written Hamiltonian (the Hamiltonian form takes only written-out Hamiltonians on
// curved spaces: mechanics/manifold_hamiltonian.h). Throws when the scene gives none.
template <class M>
WrittenManifoldHamiltonian<M> hamiltonian_of(const WrittenManifoldLagrangian<M>& L) {
  if (!L.has_hamiltonian())
    throw std::invalid_argument(L.name() + ": the Hamiltonian form on " + std::string(M::name) +
                                " needs the Hamiltonian written in the scene (system.hamiltonian)");
  return {L.system};
}

// A force written on S^2 or SO(3) ([system] forces; Kind::force): on S^2 a force in the
// embedding, one component per coordinate (x, y, z), whose part normal to the sphere does
// no virtual work; on SO(3) a body torque, one component per body axis (keyed w1, w2,
// w3). Each component reads the point, the velocity, the time t (block 0, after the
// point's entries) and the run's control inputs (after t; ControlSignal,
// mechanics/written_force.h: a tabulated control holds u_k over step k, whatever
// substep evaluates the force), in any scalar type (the steps differentiate it in Jets).
//
// It enters the step by the discrete Lagrange-d'Alembert principle (ManifoldStep,
// solvers/manifold_step.h) through the virtual work h <F, disp(x, y)> at the map's node
// x: disp(x, y) = y on S^2, vee(skew(x^T y)) on SO(3), whose derivative in y at y = x
// is the virtual displacement (delta x itself; the body rotation vee(x^T delta x)).
template <class M>
class ManifoldForce {
 public:
  static_assert(std::is_same_v<M, Sphere> || std::is_same_v<M, SO3>, "forces are written on S^2 and SO(3)");
  static constexpr int size = 3;  // components: the embedding's on S^2, the body axes on SO(3)
  template <class T>
  using P = typename M::template Point<T>;
  template <class T>
  using V = typename M::template Tangent<T>;

  // controls: the run's control signal, required where the system declares controls.
  explicit ManifoldForce(std::shared_ptr<const WrittenSystem> s, std::shared_ptr<const ControlSignal> controls = nullptr)
      : system_(written_manifold_detail::checked<M>(s)), controls_(std::move(controls)) {
    if (system_->forces.empty()) throw std::invalid_argument("ManifoldForce: the system writes no forces");
    const int c = static_cast<int>(system_->controls.size());
    if (c > 0 && (!controls_ || controls_->count() != c))
      throw std::invalid_argument("ManifoldForce: the system declares " + std::to_string(c) +
                                  " controls; their signal is needed");
  }
  int controls() const { return static_cast<int>(system_->controls.size()); }

  // F(t, x, v) into F, the controls at t (or at the run's step where tabulated). The
  // expressions' first block is held on the stack for up to kInlineControls controls.
  template <class T>
  void value(double t, const P<T>& x, const V<T>& v, Vec<T, size>& F) const {
    const int c = controls();
    if (c == 0) {
      std::array<T, entries + 1> a;
      evaluate(t, x, v, a.data(), nullptr, 0, F);
    } else if (c <= kInlineControls) {
      std::array<T, entries + 1 + kInlineControls> a;
      std::array<double, kInlineControls> u;
      evaluate(t, x, v, a.data(), u.data(), c, F);
    } else {
      std::vector<T> a(static_cast<std::size_t>(entries + 1 + c));
      std::vector<double> u(static_cast<std::size_t>(c));
      evaluate(t, x, v, a.data(), u.data(), c, F);
    }
  }

  // dF/du (size x controls()) at (t, x, v), the controls at their current values (one
  // forward pass per control); a step's derivative in its controls (ManifoldStep::
  // derivatives) pairs it with the virtual displacement.
  Eigen::MatrixXd control_jacobian(double t, const P<double>& x, const V<double>& v) const {
    using J = ceres::Jet<double, 1>;
    const int c = controls();
    std::vector<double> u(static_cast<std::size_t>(c));
    if (c > 0) controls_->values(t, u.data());
    std::vector<J> a(static_cast<std::size_t>(entries + 1 + c));
    V<J> vj;
    for (int i = 0; i < vj.size(); ++i) vj(i) = J(v(i));
    Eigen::MatrixXd dF = Eigen::MatrixXd::Zero(size, c);
    for (int j = 0; j < c; ++j) {
      for (int i = 0; i < entries; ++i) a[static_cast<std::size_t>(i)] = J(x(i));
      a[entries] = J(t);
      for (int k = 0; k < c; ++k) a[static_cast<std::size_t>(entries + 1 + k)] = J(u[static_cast<std::size_t>(k)]);
      a[static_cast<std::size_t>(entries + 1 + j)].v[0] = 1.0;
      for (const auto& [i, e] : system_->forces) dF(i, j) = e(a.data(), vj.data()).v[0];
    }
    return dF;
  }

  // The virtual displacement's functional disp(x, y) (above), x the node as it is (its
  // derivatives dropped), y the node moved.
  template <class D, class T>
  static Vec<D, size> displacement(const P<T>& x, const P<D>& y) {
    Vec<D, size> d;
    if constexpr (std::is_same_v<M, SO3>) {
      Mat<D, 3, 3> W;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          D w = constant<D>(0.0);
          for (int k = 0; k < 3; ++k) w += D(x(k, i)) * y(k, j);
          W(i, j) = w;
        }
      d[0] = 0.5 * (W(2, 1) - W(1, 2));
      d[1] = 0.5 * (W(0, 2) - W(2, 0));
      d[2] = 0.5 * (W(1, 0) - W(0, 1));
    } else {
      (void)x;
      for (int i = 0; i < size; ++i) d[i] = y[i];
    }
    return d;
  }

  const WrittenSystem& system() const { return *system_; }

 private:
  static constexpr int entries = std::is_same_v<M, SO3> ? 9 : 3;  // the point's stored numbers
  static constexpr int kInlineControls = 4;

  // a: the first block (entries + 1 + c), u: room for the c = controls() values (passed,
  // so that the compiler sees the block's size in each branch of value())
  template <class T>
  void evaluate(double t, const P<T>& x, const V<T>& v, T* a, double* u, int c, Vec<T, size>& F) const {
    for (int i = 0; i < entries; ++i) a[i] = x(i);
    a[entries] = constant<T>(t);
    if (c > 0) {
      controls_->values(t, u);
      for (int j = 0; j < c; ++j) a[entries + 1 + j] = constant<T>(u[j]);
    }
    for (int i = 0; i < size; ++i) F[i] = constant<T>(0.0);
    for (const auto& [i, e] : system_->forces) F[i] = e(a, v.data());
  }

  std::shared_ptr<const WrittenSystem> system_;
  std::shared_ptr<const ControlSignal> controls_;
};

// Holonomic constraints written on S^2 or SO(3) ([system] constraints; Kind::constraint):
// m expressions g_i(t, x) in the point's stored entries (x, y, z on S^2, R11 ... R33 on
// SO(3)) and the time t (block 0, after the entries), each constrained to 0. They
// restrict the motion to a submanifold of the space (on S^2 a curve, on SO(3) rotations
// about a fixed axis, say); the constrained step (solvers/manifold_constrained_step.h)
// differentiates them in the chart centred at a point, in any scalar type.
//
// `chart_gradient` gives, at (t, c), G(i, j) = d/deta_j g_i(t, chart(c, eta)) at eta = 0
// (the rows of Dg in the chart's coordinates, which pair with the chart's tangent
// coordinates: Dg(c) tangent(c, nu) = G nu) and g_t(i) = dg_i/dt, by one Jet level.
// The relative residuals the runtime reports are R^n's (mechanics/written_constraints.h)
// taken in the embedding: |g_i| / (|grad g_i| |x|) and |grad g_i . v + dg_i/dt| / (|grad
// g_i| |v|), grad g_i the gradient along the space (G's rows in the chart's orthonormal
// coordinates on S^2, the body axes on SO(3)) and |x| the point's Euclidean norm (1 on
// S^2, sqrt 3 for a rotation matrix).
template <class M>
class ManifoldConstraints {
 public:
  static constexpr int n = M::dim;
  // the point's stored numbers
  static constexpr int entries = std::is_same_v<M, SO3> ? 9 : 3 * written_manifold_detail::sphere_factors<M>::value;
  template <class T>
  using P = typename M::template Point<T>;

  explicit ManifoldConstraints(std::shared_ptr<const WrittenSystem> s) : system_(written_manifold_detail::checked<M>(s)) {
    if (system_->constraints.empty() || count() >= n)
      throw std::invalid_argument("ManifoldConstraints: from 1 to " + std::to_string(n - 1) + " constraints on " +
                                  std::string(M::name) + ", got " + std::to_string(count()));
  }
  int count() const { return static_cast<int>(system_->constraints.size()); }
  const WrittenSystem& system() const { return *system_; }

  // g(t, x) into g[0 .. count()), any scalar (t and x of the same).
  template <class T>
  void value(const T& t, const P<T>& x, T* g) const {
    std::array<T, entries + 1> a;
    for (int i = 0; i < entries; ++i) a[static_cast<std::size_t>(i)] = x.data()[i];
    a[entries] = t;
    for (int i = 0; i < count(); ++i) g[i] = system_->constraints[static_cast<std::size_t>(i)](a.data(), a.data());
  }

  // g, G and g_t at (t, c) (header comment); g, gt of count() entries, G count() x n.
  template <class Gv, class Gm, class Gt>
  void chart_gradient(double t, const P<double>& c, Gv& g, Gm& Gc, Gt& gt) const {
    using D = ceres::Jet<double, n + 1>;
    Vec<D, n> eta;
    for (int i = 0; i < n; ++i) eta[i] = D(0.0, i);
    std::array<D, n> out;  // (fewer constraints than the space's dimension: the scene checks it)
    value(D(t, n), P<D>(M::chart(c, eta)), out.data());
    for (int i = 0; i < count(); ++i) {
      const D& e = out[static_cast<std::size_t>(i)];
      g[i] = e.a;
      for (int j = 0; j < n; ++j) Gc(i, j) = e.v[j];
      gt[i] = e.v[n];
    }
  }

  // The largest relative residuals at (t, x) with velocity v (header comment) into
  // position and velocity.
  void relative_residuals(double t, const P<double>& x, const typename M::template Tangent<double>& v,
                          double& position, double& velocity) const {
    std::array<double, n> g, gt;
    Mat<double, n, n> G;
    chart_gradient(t, x, g, G, gt);
    const Vec<double, n> nu = M::tangent_coordinates(x, v);
    const double xn = x.norm(), vn = nu.norm();
    position = velocity = 0.0;
    for (int i = 0; i < count(); ++i) {
      const double gn = G.row(i).norm(), a = std::fabs(g[static_cast<std::size_t>(i)]);
      const double b = std::fabs(G.row(i).dot(nu) + gt[static_cast<std::size_t>(i)]);
      position = std::fmax(position, gn * xn > 0.0 ? a / (gn * xn) : a);
      velocity = std::fmax(velocity, gn * vn > 0.0 ? b / (gn * vn) : b);
    }
    if (!std::isfinite(position)) position = INFINITY;
    if (!std::isfinite(velocity)) velocity = INFINITY;
  }


 private:
  std::shared_ptr<const WrittenSystem> system_;
};

}  // namespace dvm
