// Lagrangian systems on S^2 and SO(3), their discrete Lagrangians, and the Legendre
// map in local coordinates.
//
// A system type S on a manifold M provides `using Manifold = M`, `dim = M::dim`,
// `name()` and a scalar-generic L(x, v) with x a stored point and v a stored tangent
// vector at x (an embedded 3-vector on S^2, the body angular velocity on SO(3)).
//
//   spherical pendulum  L = m l^2 |v|^2/2 - m g l x_3        on S^2 (x_3 upward)
//   free rigid body     L = (I1 w1^2 + I2 w2^2 + I3 w3^2)/2   on SO(3), w body velocity
//   heavy top           L = w.I w/2 - m g e3.(R chi)          on SO(3), chi the centre
//                                                              of mass in the body frame
// Symmetries: rotations about the vertical for the pendulum and the top (conserved:
// the vertical component of the angular momentum), all rotations for the free rigid
// body (conserved: the spatial angular momentum R I w).
//
// The discrete Lagrangian is L_d(q0, q1) = h L(R_d^{-1}(q0, q1)/h) as on R^n.
// Momenta are covectors; D1 L_d and D2 L_d are taken in the charts centred at q0 and
// q1 (their coordinates at the chart centre), and stored as the manifold stores
// covectors (Sphere: tangent 3-vector; SO(3): body angular momentum).
#pragma once

#include <stdexcept>
#include <string>
#include <utility>

#include "core/manifold_maps.h"
#include "mechanics/lagrangian.h"

namespace dvm {

struct SphericalPendulum {
  using Manifold = Sphere;
  static constexpr int dim = 2;
  double m = 1.0, l = 1.0, g = 1.0;
  SphericalPendulum(double m_ = 1.0, double l_ = 1.0, double g_ = 1.0) : m(m_), l(l_), g(g_) {
    if (!(m > 0 && l > 0 && std::isfinite(m) && std::isfinite(l) && std::isfinite(g)))
      throw std::invalid_argument("spherical-pendulum: m and l must be positive and finite, g finite");
  }
  std::string name() const { return "spherical-pendulum"; }
  template <class T>
  T operator()(const Vec<T, 3>& x, const Vec<T, 3>& v) const {
    return (0.5 * m * l * l) * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) - (m * g * l) * x[2];
  }
  // Vertical angular momentum (x cross p)_3: conserved.
  static double vertical_momentum(const Vec<double, 3>& x, const Vec<double, 3>& p) { return x.cross(p)[2]; }
};

struct RigidBody {
  using Manifold = SO3;
  static constexpr int dim = 3;
  Vec<double, 3> inertia;
  explicit RigidBody(const Vec<double, 3>& I = Vec<double, 3>(1.0, 2.0, 3.0)) : inertia(I) {
    for (int i = 0; i < 3; ++i)
      if (!(I[i] > 0) || !std::isfinite(I[i]))
        throw std::invalid_argument("rigid-body: principal moments of inertia must be positive and finite");
    if (I[0] + I[1] < I[2] || I[1] + I[2] < I[0] || I[0] + I[2] < I[1])
      throw std::invalid_argument("rigid-body: moments of inertia violate the triangle inequality");
  }
  std::string name() const { return "rigid-body"; }
  template <class T>
  T operator()(const Mat<T, 3, 3>&, const Vec<T, 3>& w) const {
    return 0.5 * (inertia[0] * w[0] * w[0] + inertia[1] * w[1] * w[1] + inertia[2] * w[2] * w[2]);
  }
  // Spatial angular momentum R Pi: conserved.
  static Vec<double, 3> spatial_momentum(const Mat<double, 3, 3>& R, const Vec<double, 3>& Pi) { return R * Pi; }
};

struct HeavyTop {
  using Manifold = SO3;
  static constexpr int dim = 3;
  Vec<double, 3> inertia, chi;
  double m = 1.0, g = 1.0;
  HeavyTop(const Vec<double, 3>& I = Vec<double, 3>(1.0, 1.0, 0.5), double m_ = 1.0, double g_ = 1.0,
           const Vec<double, 3>& chi_ = Vec<double, 3>(0.0, 0.0, 1.0))
      : inertia(I), chi(chi_), m(m_), g(g_) {
    for (int i = 0; i < 3; ++i)
      if (!(I[i] > 0) || !std::isfinite(I[i]) || !std::isfinite(chi[i]))
        throw std::invalid_argument("heavy-top: moments of inertia must be positive, chi finite");
    if (!(m > 0) || !std::isfinite(g)) throw std::invalid_argument("heavy-top: m must be positive, g finite");
  }
  std::string name() const { return "heavy-top"; }
  template <class T>
  T operator()(const Mat<T, 3, 3>& R, const Vec<T, 3>& w) const {
    // e3.(R chi) = third row of R times chi
    const T height = R(2, 0) * chi[0] + R(2, 1) * chi[1] + R(2, 2) * chi[2];
    return 0.5 * (inertia[0] * w[0] * w[0] + inertia[1] * w[1] * w[1] + inertia[2] * w[2] * w[2]) -
           (m * g) * height;
  }
  static double vertical_momentum(const Mat<double, 3, 3>& R, const Vec<double, 3>& Pi) { return (R * Pi)[2]; }
};

// Legendre map in local coordinates: p = d/dnu L(x, tangent(x, nu)), returned in the
// manifold's stored covector form.
template <class S>
typename S::Manifold::template Tangent<double> manifold_legendre(
    const S& L, const typename S::Manifold::template Point<double>& x,
    const typename S::Manifold::template Tangent<double>& v) {
  using M = typename S::Manifold;
  constexpr int n = M::dim;
  using D = ceres::Jet<double, n>;
  const Vec<double, n> nu0 = M::tangent_coordinates(x, v);
  Vec<D, n> nu;
  for (int i = 0; i < n; ++i) nu[i] = seed<double, n>(nu0[i], i);
  typename M::template Point<D> xd;
  for (int i = 0; i < x.size(); ++i) xd(i) = D(x(i));
  const D l = L(xd, M::tangent(x, nu));
  return M::covector_from_local(x, Vec<double, n>(l.v));
}

// Energy <p, v> - L at (x, v).
template <class S>
double manifold_energy(const S& L, const typename S::Manifold::template Point<double>& x,
                       const typename S::Manifold::template Tangent<double>& v) {
  using M = typename S::Manifold;
  const auto p = manifold_legendre(L, x, v);
  return M::covector_to_local(x, p).dot(M::tangent_coordinates(x, v)) - L(x, v);
}

// dL/dnu (the chart momentum) and d2L/dnu2 at x and the tangent coordinates nu, by
// nested Jets: the gradient by the outer Jet, the Hessian by the inner one.
template <class S>
void manifold_velocity_derivatives(const S& L, const typename S::Manifold::template Point<double>& x,
                                   const Vec<double, S::Manifold::dim>& nu, Vec<double, S::Manifold::dim>& grad,
                                   Mat<double, S::Manifold::dim, S::Manifold::dim>& H) {
  using M = typename S::Manifold;
  constexpr int n = M::dim;
  using D = ceres::Jet<double, n>;
  using DD = ceres::Jet<D, n>;
  Vec<DD, n> nud;
  for (int i = 0; i < n; ++i) nud[i] = seed<D, n>(seed<double, n>(nu[i], i), i);
  typename M::template Point<DD> xdd;
  for (int i = 0; i < x.size(); ++i) xdd(i) = DD(D(x(i)));
  const DD l = L(xdd, M::tangent(x, nud));
  for (int i = 0; i < n; ++i) {
    grad[i] = l.v[i].a;
    H.row(i) = l.v[i].v.transpose();
  }
}

// d2L/dnu2 at (x, v): the velocity Hessian in the coordinates of T_x M, whose
// regularity makes the Legendre transform invertible there.
template <class S>
Mat<double, S::Manifold::dim, S::Manifold::dim> manifold_velocity_hessian(
    const S& L, const typename S::Manifold::template Point<double>& x,
    const typename S::Manifold::template Tangent<double>& v) {
  constexpr int n = S::Manifold::dim;
  Vec<double, n> grad;
  Mat<double, n, n> H;
  manifold_velocity_derivatives(L, x, Vec<double, n>(S::Manifold::tangent_coordinates(x, v)), grad, H);
  return H;
}

// The velocity with momentum p at x (Newton's method in local coordinates).
template <class S>
typename S::Manifold::template Tangent<double> manifold_legendre_inverse(
    const S& L, const typename S::Manifold::template Point<double>& x,
    const typename S::Manifold::template Tangent<double>& p) {
  using M = typename S::Manifold;
  constexpr int n = M::dim;
  const Vec<double, n> target = M::covector_to_local(x, p);
  Vec<double, n> nu = Vec<double, n>::Zero();
  const double scale = std::fmax(1e-300, max_abs(target));
  for (int it = 0; it < 50; ++it) {
    Vec<double, n> r;
    Mat<double, n, n> H;
    manifold_velocity_derivatives(L, x, nu, r, H);
    r -= target;
    if (max_abs(r) <= 1e-14 * scale) break;
    Vec<double, n> dnu;
    try {
      dnu = solve_dense<double, n, n>(H, r);
    } catch (const std::domain_error&) {
      throw DegenerateLagrangianError(L.name() + ": the velocity Hessian is singular");
    }
    nu -= dnu;
    if (max_abs(dnu) <= 4e-16 * std::fmax(1.0, max_abs(nu))) break;
  }
  return M::tangent(x, nu);
}

template <class System, class Map>
class ManifoldDiscreteLagrangian {
 public:
  using M = typename Map::Manifold;
  static constexpr int n = M::dim;
  template <class T>
  using P = typename M::template Point<T>;
  static_assert(std::is_same_v<typename System::Manifold, M>, "system and map live on different manifolds");

  ManifoldDiscreteLagrangian(System L, Map R, double h) : L_(std::move(L)), R_(std::move(R)), h_(h) {
    // A negative h is allowed: compositions take substeps of negative size gamma_i h.
    if (!(h != 0.0) || !std::isfinite(h)) throw std::invalid_argument("the time step h must be nonzero and finite");
  }
  const System& lagrangian() const { return L_; }
  const Map& map() const { return R_; }
  double step() const { return h_; }

  template <class T>
  T operator()(const P<T>& q0, const P<T>& q1) const {
    const ManifoldTangent<M, T> t = R_.inverse(q0, q1);
    typename M::template Tangent<T> u = t.v;
    for (int i = 0; i < u.size(); ++i) u(i) = t.v(i) * (1.0 / h_);
    return h_ * L_(t.x, u);
  }

  // L_d from q0 and the relative position rel of q1 (see Sphere::relative, SO3::relative).
  template <class T, class Rel>
  T evaluate_relative(const P<T>& q0, const Rel& rel) const {
    return at_node(R_.inverse_relative(q0, rel));
  }

  // D1 L_d(q0, q1) in the chart centred at q0 (q0 a double point, q1 any scalar).
  // `rel` is the relative position of q1 from q0, known more accurately than the
  // stored points give it (the step has it from its unknown); it replaces the value
  // of the relative position, whose derivatives come from the points.
  template <class T, class Rel>
  Vec<T, n> D1_local(const P<double>& q0, const P<T>& q1, const Rel& rel) const {
    const auto m = moved_first(q0, q1, rel);
    return evaluate_relative(m.first, m.second).v;
  }
  // D2 L_d(q0, q1) in the chart centred at q1, with the relative position rel.
  template <class Rel>
  Vec<double, n> D2_local(const P<double>& q0, const P<double>& q1, const Rel& rel) const {
    const auto m = moved_second(q0, q1, rel);
    return evaluate_relative(m.first, m.second).v;
  }

  // With a force (discrete Lagrange-d'Alembert, Marsden and West 2001, Sec. 3.2): D1 L_d
  // + F_d^- in the chart of q0 and D2 L_d + F_d^+ in the chart of q1. The force F
  // (mechanics/written_manifold.h, ManifoldForce) is evaluated at the map's node (x, v) =
  // R_d^{-1}(q0, q1), v divided by h, at time t, and held there; the discrete forces are
  // the derivatives of the virtual work h <F, disp(x, x')>, x' the node of the moved
  // points. The moved points and their node are formed once for both terms, and the
  // held node is their value. `work` (where given) receives h <F, v>, the work over the
  // step.
  template <class T, class Rel, class Fo>
  Vec<T, n> D1_local(const P<double>& q0, const P<T>& q1, const Rel& rel, const Fo& force, double t,
                     T* work = nullptr) const {
    const auto m = moved_first(q0, q1, rel);
    return with_force(R_.inverse_relative(m.first, m.second), force, t, work).v;
  }
  template <class Rel, class Fo>
  Vec<double, n> D2_local(const P<double>& q0, const P<double>& q1, const Rel& rel, const Fo& force, double t,
                          double* work = nullptr) const {
    const auto m = moved_second(q0, q1, rel);
    return with_force(R_.inverse_relative(m.first, m.second), force, t, work).v;
  }

  // The function whose first derivatives are D1_local and D2_local, at a point a and the
  // relative position r of the other point, both Jets D over scalars T whose derivative
  // parts move the points: h L at their node, and with a force the virtual work
  // h <F, disp(x, x')> of F held at the node's value x (type T), at time t. A step's
  // derivative (ManifoldStep::derivatives) differentiates it once more, in T.
  template <class D, class Rel>
  D generating_value(const P<D>& a, const Rel& r) const {
    return at_node(R_.inverse_relative(a, r));
  }
  template <class D, class Rel, class Fo>
  D generating_value(const P<D>& a, const Rel& r, const Fo& force, double t) const {
    using T = std::decay_t<decltype(a(0).a)>;
    return with_force(R_.inverse_relative(a, r), force, t, static_cast<T*>(nullptr));
  }

 private:
  // (a, r) for the derivatives in the chart of q0: a = chart(q0, eta) with Jets seeded in
  // eta, r the relative position of q1 from a with its value replaced by rel.
  template <class T, class Rel>
  auto moved_first(const P<double>& q0, const P<T>& q1, const Rel& rel) const {
    using D = ceres::Jet<T, n>;
    Vec<D, n> eta;
    for (int i = 0; i < n; ++i) eta[i] = seed<T, n>(constant<T>(0.0), i);
    P<D> b;
    for (int i = 0; i < q1.size(); ++i) b(i) = D(q1(i));
    const P<D> a = M::chart(q0, eta);
    auto r = M::relative(a, b);
    for (int i = 0; i < r.size(); ++i) r(i).a = rel(i);
    return std::make_pair(a, r);
  }
  // (a, r) for the derivatives in the chart of q1: a = q0 (constant Jets), r the relative
  // position of chart(q1, eta) from it with its value replaced by rel.
  template <class Rel>
  auto moved_second(const P<double>& q0, const P<double>& q1, const Rel& rel) const {
    using D = ceres::Jet<double, n>;
    Vec<D, n> eta;
    for (int i = 0; i < n; ++i) eta[i] = seed<double, n>(0.0, i);
    P<D> a;
    for (int i = 0; i < q0.size(); ++i) a(i) = D(q0(i));
    auto r = M::relative(a, M::chart(q1, eta));
    for (int i = 0; i < r.size(); ++i) r(i).a = rel(i);
    return std::make_pair(a, r);
  }
  // h L(x, v / h) at a node (x, v) of the map's inverse
  template <class T>
  T at_node(const ManifoldTangent<M, T>& node) const {
    typename M::template Tangent<T> u = node.v;
    for (int i = 0; i < u.size(); ++i) u(i) = node.v(i) * (1.0 / h_);
    return h_ * L_(node.x, u);
  }
  // h L + h <F, disp(x, x')> at the node of the moved points (Jets D over scalars T), F
  // evaluated at the held node x (the value parts) and time t.
  template <class D, class Fo, class T>
  D with_force(const ManifoldTangent<M, D>& node, const Fo& force, double t, T* work) const {
    P<T> x;
    typename M::template Tangent<T> u;
    for (int i = 0; i < x.size(); ++i) x(i) = node.x(i).a;
    for (int i = 0; i < u.size(); ++i) u(i) = node.v(i).a * (1.0 / h_);
    Vec<T, Fo::size> F;
    force.value(t, x, u, F);
    if (work) {
      T w = constant<T>(0.0);
      for (int i = 0; i < Fo::size; ++i) w += F[i] * node.v(i).a;
      *work = w;
    }
    const Vec<D, Fo::size> d = Fo::template displacement<D>(x, node.x);
    D W = constant<D>(0.0);
    for (int i = 0; i < Fo::size; ++i) W += D(F[i]) * d[i];
    return at_node(node) + W * h_;
  }

  System L_;
  Map R_;
  double h_;
};

}  // namespace dvm

namespace dvm {

// A chain of K spherical pendulums (Q = (S^2)^K): link i has unit direction x_i, length
// l_i and a point mass m_i at its end; the first link hangs from a fixed pivot. With
// r_i = sum_{j <= i} l_j x_j (x_3 upward),
//   L = sum_i m_i |dr_i/dt|^2 / 2 - g sum_i m_i (r_i)_3.
// Rotations about the vertical are a symmetry: sum_i (r_i x m_i dr_i/dt)_3 is conserved.
template <int K>
struct SphericalChain {
  using Manifold = SpherePower<K>;
  static constexpr int dim = 2 * K;
  Vec<double, K> m, l;
  double g = 1.0;
  SphericalChain(const Vec<double, K>& m_, const Vec<double, K>& l_, double g_) : m(m_), l(l_), g(g_) {
    for (int i = 0; i < K; ++i)
      if (!(m[i] > 0) || !(l[i] > 0) || !std::isfinite(m[i]) || !std::isfinite(l[i]))
        throw std::invalid_argument("spherical-chain: masses and lengths must be positive and finite");
    if (!std::isfinite(g)) throw std::invalid_argument("spherical-chain: g must be finite");
  }
  std::string name() const { return "spherical-chain"; }
  template <class T>
  T operator()(const Vec<T, 3 * K>& x, const Vec<T, 3 * K>& v) const {
    T kinetic = constant<T>(0.0), height = constant<T>(0.0);
    Vec<T, 3> u = Vec<T, 3>::Constant(constant<T>(0.0));
    T z = constant<T>(0.0);
    for (int i = 0; i < K; ++i) {
      for (int j = 0; j < 3; ++j) u[j] = u[j] + l[i] * v[3 * i + j];
      z = z + l[i] * x[3 * i + 2];
      kinetic = kinetic + (0.5 * m[i]) * (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
      height = height + m[i] * z;
    }
    return kinetic - g * height;
  }
  // The vertical angular momentum sum_i (r_i x p_i)_3 in terms of the stored momenta:
  // rotations about e3 move every x_i by e3 x x_i, so J3 = sum_i (x_i x p_i)_3 with p_i
  // the momentum conjugate to x_i.
  static double vertical_momentum(const Vec<double, 3 * K>& x, const Vec<double, 3 * K>& p) {
    double J = 0.0;
    for (int i = 0; i < K; ++i) J += x[3 * i] * p[3 * i + 1] - x[3 * i + 1] * p[3 * i];
    return J;
  }
};

}  // namespace dvm
