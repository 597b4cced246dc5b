// Discretization maps on S^2 and SO(3) (paper Ex. 2.7, 2.8, 3.5, 3.6, Sec. 5.1),
// and the local representation that makes every R^n tool apply to them.
//
// All maps here are of the Prop. 2.3 form built from a retraction R and theta:
//   R_d(x, v) = (R_x(-theta v), R_x((1 - theta) v)),
// theta = 1/2 giving the midpoint forms and theta = 0 the fixed-first-point forms
// (x, R_x(v)). The retractions are
//   S^2:    exp_x(v) = cos|v| x + sin|v| v/|v|   and   (x + v)/|x + v|  (projection)
//   SO(3):  R exp(hat w)   and   R cay(w)  (w the body angular velocity)
// Closed-form inverses (the rest use Newton's method in local coordinates):
//   S^2 exp, theta = 1/2:  x = (q0 + q1)/|q0 + q1|, v = angle(q0, q1) (q1 - q0)/|q1 - q0|
//   S^2 projection, 1/2:   x = (q0 + q1)/|q0 + q1|, v = 2 (q1 - q0)/|q0 + q1|
//   S^2 exp, theta = 0:    (q0, log_{q0} q1)
//   S^2 projection, 0:     (q0, q1/(q0.q1) - q0), defined for q0.q1 > 0 only
//   theta = 1 is theta = 0 with the roles of q0 and q1 exchanged and v negated;
//   SO(3) exp, any theta:  w = log(q0^T q1), x = q0 exp(theta w)
//   SO(3) Cayley, 0 and 1: w = cay^{-1}(q0^T q1), x = q0 or q1 (rotation < pi)
//   SO(3) Cayley, 1/2:     with W = q0^T q1 and its unit quaternion (s, u), s >= 0:
//                          w = 4 u/(1 + s), x = q0 cay(w/2)
// Points outside a map's domain (antipodal points on the sphere, q0.q1 <= 0 for the
// projection map, rotations by pi for Cayley) raise MapDomainError, never a NaN.
//
// LocalRepresentation<Map>: the map written in the chart centred at a point c,
//   (eta, nu) -> (chart^{-1}(q0), chart^{-1}(q1)),  (q0, q1) = R_d(chart(eta), D chart(eta) nu),
// is a discretization map on R^dim; the identities, lifts and checks of the R^n code
// apply to it unchanged, and are the identities of the manifold map in coordinates.
#pragma once

#include <memory>
#include <stdexcept>
#include <string>

#include "core/embedded_retraction.h"
#include "core/manifolds.h"
#include "core/map_operations.h"

namespace dvm {

template <class M, class T>
struct ManifoldPair {
  typename M::template Point<T> q0, q1;
};
template <class M, class T>
struct ManifoldTangent {
  typename M::template Point<T> x;
  typename M::template Tangent<T> v;
};

// written: a retraction given as a function into the embedding, normalised onto the
// manifold (core/embedded_retraction.h); its maps use Newton's inverse at every theta.
enum class RetractionKind { exp, projection, cayley, written };

inline std::string to_string(RetractionKind k) {
  switch (k) {
    case RetractionKind::exp: return "exp";
    case RetractionKind::projection: return "projection";
    case RetractionKind::written: return "written";
    default: return "cayley";
  }
}

namespace detail {
inline void check_theta(double theta) {
  if (!(theta >= 0.0 && theta <= 1.0))
    throw std::invalid_argument("theta must lie in [0, 1], got " + std::to_string(theta));
}

// f(x, v) for a written retraction, in the scalar type of the step: O numbers (3 on
// S^2, 9 on SO(3)).
template <int O, class T>
Eigen::Matrix<T, O, 1> evaluate_embedded(const EmbeddedRetraction& f, const T* x, const T* v) {
  Eigen::Matrix<T, O, 1> out;
  if constexpr (EmbeddedRetraction::supports<T>) {
    f.evaluate(x, v, out.data());
  } else {
    throw std::logic_error("a written retraction is evaluated for the scalar types of the steps on S^2, (S^2)^K "
                           "and SO(3) only (core/embedded_retraction.h)");
  }
  return out;
}
}  // namespace detail

template <class Map>
ManifoldTangent<typename Map::Manifold, double> newton_manifold_inverse_values(
    const Map& map, const typename Map::Manifold::template Point<double>& q0,
    const typename Map::Manifold::template Point<double>& q1);
template <class Map, class P>
ManifoldTangent<typename Map::Manifold, typename P::Scalar> newton_manifold_inverse(const Map& map, const P& q0,
                                                                                    const P& q1);

// What the maps of Prop. 2.3 on S^2 and SO(3) share: the retraction (built in, or
// written in the embedding), theta and the name; symmetric and of order 2 at theta = 1/2.
template <class Derived>
class RetractionThetaMap {
 public:
  RetractionKind kind() const { return kind_; }
  double theta() const { return theta_; }
  std::string name() const { return name_; }
  bool symmetric() const { return theta_ == 0.5; }
  int order() const { return symmetric() ? 2 : 1; }
  const std::shared_ptr<const EmbeddedRetraction>& written() const { return written_; }
  // The same retraction at another theta (the adjoint is 1 - theta: Prop. 2.4).
  Derived at_theta(double theta, std::string name) const {
    Derived m = static_cast<const Derived&>(*this);
    detail::check_theta(theta);
    m.theta_ = theta;
    m.name_ = std::move(name);
    return m;
  }

 protected:
  RetractionThetaMap(RetractionKind kind, double theta, std::string name, std::shared_ptr<const EmbeddedRetraction> f,
                     const char* space)
      : kind_(kind), theta_(theta), name_(std::move(name)), written_(std::move(f)) {
    detail::check_theta(theta);
    if ((kind == RetractionKind::written) != static_cast<bool>(written_))
      throw std::invalid_argument(std::string("a written ") + space + " map needs its function, and only it has one");
  }
  RetractionKind kind_;
  double theta_;
  std::string name_;
  std::shared_ptr<const EmbeddedRetraction> written_;
};

// Discretization maps on S^2 from the exponential or the projection retraction, or a
// retraction written in the embedding.
class SphereMap : public RetractionThetaMap<SphereMap> {
 public:
  using Manifold = Sphere;
  SphereMap(RetractionKind kind, double theta, std::string name)
      : RetractionThetaMap(kind, theta, std::move(name), nullptr, "S^2") {
    if (kind == RetractionKind::cayley) throw std::invalid_argument("S^2 maps use the exp or projection retraction");
  }
  // The map of Prop. 2.3 from the retraction R_x(v) = f(x, v)/|f(x, v)|.
  SphereMap(std::shared_ptr<const EmbeddedRetraction> f, double theta, std::string name)
      : RetractionThetaMap(RetractionKind::written, theta, std::move(name), std::move(f), "S^2") {}
  bool closed_form_inverse() const {
    return kind_ != RetractionKind::written && (theta_ == 0.0 || theta_ == 0.5 || theta_ == 1.0);
  }

  template <class T>
  Vec<T, 3> retract(const Vec<T, 3>& x, const Vec<T, 3>& v) const {
    if (kind_ == RetractionKind::written) {
      using std::sqrt;
      const Vec<T, 3> y = detail::evaluate_embedded<3>(*written_, x.data(), v.data());
      const T n = sqrt(detail::dot(y, y));
      return Vec<T, 3>(y[0] / n, y[1] / n, y[2] / n);
    }
    return kind_ == RetractionKind::exp ? Sphere::exp(x, v) : Sphere::projection(x, v);
  }

  template <class T>
  ManifoldPair<Sphere, T> operator()(const Vec<T, 3>& x, const Vec<T, 3>& v) const {
    return {retract(x, Vec<T, 3>(-theta_ * v)), retract(x, Vec<T, 3>((1.0 - theta_) * v))};
  }

  template <class T>
  ManifoldTangent<Sphere, T> inverse(const Vec<T, 3>& q0, const Vec<T, 3>& q1) const {
    if (closed_form_inverse()) return inverse_relative(q0, Sphere::relative(q0, q1));
    return newton_manifold_inverse(*this, q0, q1);
  }

  // R_d^{-1}(q0, q0 + d) from q0 and the difference d = q1 - q0, given accurately
  // (Sphere::relative_chart), so that nothing is computed from q1 - q0 rounded.
  // With |q0| = |q1| = 1: q0.q1 = 1 + q0.d and q1.d = -q0.d.
  template <class T>
  ManifoldTangent<Sphere, T> inverse_relative(const Vec<T, 3>& q0, const Vec<T, 3>& d) const {
    using std::sqrt;
    if (!closed_form_inverse())
      return newton_manifold_inverse(*this, q0, Vec<T, 3>(q0[0] + d[0], q0[1] + d[1], q0[2] + d[2]));
    const T a = detail::dot(q0, d);  // q0.q1 - 1
    const Vec<T, 3> q1(q0[0] + d[0], q0[1] + d[1], q0[2] + d[2]);
    if (theta_ == 0.0 || theta_ == 1.0) {
      // fixed first point: (x, v) = (q0, R_{q0}^{-1}(q1)); theta = 1 exchanges the
      // roles: (q1, -R_{q1}^{-1}(q0)), with q0 = q1 - d and q1.(-d) = a.
      const bool first = theta_ == 0.0;
      const Vec<T, 3>& base = first ? q0 : q1;
      const Vec<T, 3> e = first ? d : Vec<T, 3>(-d);
      const T be = a;  // base.e: q0.d = q1.(-d) = q0.q1 - 1
      // w = other - (base.other) base = e - (base.e) base; c = base.other = 1 + base.e
      const Vec<T, 3> w(e[0] - be * base[0], e[1] - be * base[1], e[2] - be * base[2]);
      const T c = 1.0 + be;
      T k;
      if (kind_ == RetractionKind::exp) {
        k = detail::angle_over_sin(detail::dot(w, w), c);
      } else {
        if (!(value(c) > 1e-12))
          throw MapDomainError(name_ + ": inverse needs q0.q1 > 0, got q0.q1 = " + std::to_string(value(c)));
        k = 1.0 / c;
      }
      const double sign = first ? 1.0 : -1.0;
      return {base, Vec<T, 3>(sign * k * w[0], sign * k * w[1], sign * k * w[2])};
    }
    // theta = 1/2: x = (q0 + q1)/|q0 + q1| = (2 q0 + d)/c, c^2 = 4 + 4 a + |d|^2 = 4 - |d|^2
    const Vec<T, 3> sum(2.0 * q0[0] + d[0], 2.0 * q0[1] + d[1], 2.0 * q0[2] + d[2]);
    const T d2 = detail::dot(d, d);
    const T c2 = 4.0 - d2;
    if (!(value(c2) > 1e-20)) throw MapDomainError(name_ + ": inverse undefined for antipodal points");
    const T c = sqrt(c2);
    const Vec<T, 3> x(sum[0] / c, sum[1] / c, sum[2] / c);
    T k;
    if (kind_ == RetractionKind::projection) {
      k = 2.0 / c;
    } else {
      // angle(q0, q1) / |d| = (2/c) atan(u)/u with u = |d|/c
      using std::atan;
      const T u2 = d2 / c2;
      T r;
      if (value(u2) < 1e-6)
        r = 1.0 - u2 / 3.0 + u2 * u2 / 5.0 - u2 * u2 * u2 / 7.0;
      else
        r = atan(sqrt(u2)) / sqrt(u2);
      k = (2.0 / c) * r;
    }
    return {x, Vec<T, 3>(k * d[0], k * d[1], k * d[2])};
  }
};

// Discretization maps on SO(3) from the group exponential or the Cayley map.
class SO3Map : public RetractionThetaMap<SO3Map> {
 public:
  using Manifold = SO3;
  SO3Map(RetractionKind kind, double theta, std::string name)
      : RetractionThetaMap(kind, theta, std::move(name), nullptr, "SO(3)") {
    if (kind == RetractionKind::projection) throw std::invalid_argument("SO(3) maps use the exp or Cayley retraction");
  }
  // The map of Prop. 2.3 from the retraction R_R(w) = the orthonormalised f(R, w).
  SO3Map(std::shared_ptr<const EmbeddedRetraction> f, double theta, std::string name)
      : RetractionThetaMap(RetractionKind::written, theta, std::move(name), std::move(f), "SO(3)") {}
  bool closed_form_inverse() const {
    return kind_ == RetractionKind::exp ||
           (kind_ == RetractionKind::cayley && (theta_ == 0.0 || theta_ == 0.5 || theta_ == 1.0));
  }

  template <class T>
  Mat<T, 3, 3> tau(const Vec<T, 3>& w) const {
    return kind_ == RetractionKind::exp ? SO3::exp(w) : SO3::cay(w);
  }
  template <class T>
  Mat<T, 3, 3> retract(const Mat<T, 3, 3>& R, const Vec<T, 3>& w) const {
    if (kind_ == RetractionKind::written)
      return orthonormalised(detail::evaluate_embedded<9>(*written_, R.data(), w.data()));
    return SO3::mul(R, tau(w));
  }
  // Gram-Schmidt on the columns of A (stored column-major in a): Q with Q^T Q = I,
  // equal to A where A is already a rotation.
  template <class T>
  static Mat<T, 3, 3> orthonormalised(const Vec<T, 9>& a) {
    using std::sqrt;
    Vec<T, 3> c[3];
    for (int j = 0; j < 3; ++j) {
      c[j] = Vec<T, 3>(a[3 * j], a[3 * j + 1], a[3 * j + 2]);
      for (int k = 0; k < j; ++k) {
        const T p = detail::dot(c[k], c[j]);
        for (int i = 0; i < 3; ++i) c[j][i] = c[j][i] - p * c[k][i];
      }
      const T n = sqrt(detail::dot(c[j], c[j]));
      for (int i = 0; i < 3; ++i) c[j][i] = c[j][i] / n;
    }
    Mat<T, 3, 3> Q;
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) Q(i, j) = c[j][i];
    return Q;
  }

  template <class T>
  ManifoldPair<SO3, T> operator()(const Mat<T, 3, 3>& R, const Vec<T, 3>& w) const {
    return {retract(R, Vec<T, 3>(-theta_ * w)), retract(R, Vec<T, 3>((1.0 - theta_) * w))};
  }

  template <class T>
  ManifoldTangent<SO3, T> inverse(const Mat<T, 3, 3>& q0, const Mat<T, 3, 3>& q1) const {
    if (closed_form_inverse()) return inverse_relative(q0, SO3::relative(q0, q1));
    return newton_manifold_inverse(*this, q0, q1);
  }

  // R_d^{-1}(q0, q0 W) from q0 and the relative rotation W = q0^T q1, given
  // accurately (SO3::relative_chart) rather than as a product of stored rotations.
  template <class T>
  ManifoldTangent<SO3, T> inverse_relative(const Mat<T, 3, 3>& q0, const Mat<T, 3, 3>& W) const {
    using std::sqrt;
    if (!closed_form_inverse()) return newton_manifold_inverse(*this, q0, Mat<T, 3, 3>(SO3::mul(q0, W)));
    if (kind_ == RetractionKind::exp) {
      const Vec<T, 3> w = SO3::log(W);
      return {SO3::mul(q0, SO3::exp(Vec<T, 3>(theta_ * w))), w};
    }
    if (theta_ == 0.0) return {q0, SO3::cay_inverse(W)};
    if (theta_ == 1.0) return {SO3::mul(q0, W), SO3::cay_inverse(W)};
    const T d = 1.0 + W(0, 0) + W(1, 1) + W(2, 2);
    if (!(value(d) > 1e-10)) throw MapDomainError(name_ + ": inverse undefined for a relative rotation by pi");
    const T s = 0.5 * sqrt(d);
    const T k = 1.0 / (s * (1.0 + s));
    const Vec<T, 3> w(k * (W(2, 1) - W(1, 2)), k * (W(0, 2) - W(2, 0)), k * (W(1, 0) - W(0, 1)));
    return {SO3::mul(q0, SO3::cay(Vec<T, 3>(0.5 * w))), w};
  }
};

// The adjoint of a Prop. 2.3 map is the map of the same retraction with theta
// replaced by 1 - theta (Prop. 2.4).
inline SphereMap adjoint_map(const SphereMap& m) { return m.at_theta(1.0 - m.theta(), m.name() + "*"); }
inline SO3Map adjoint_map(const SO3Map& m) { return m.at_theta(1.0 - m.theta(), m.name() + "*"); }

// The map in the chart centred at c: a discretization map on R^dim.
template <class Map>
class LocalRepresentation {
 public:
  using M = typename Map::Manifold;
  static constexpr bool provides_inverse = false;
  LocalRepresentation(Map map, typename M::template Point<double> centre) : map_(std::move(map)), c_(std::move(centre)) {}
  std::string name() const { return "local(" + map_.name() + ")"; }
  bool symmetric() const { return map_.symmetric(); }
  int order() const { return map_.order(); }

  // x = chart(c, eta) and v = D chart(c, eta) nu, as the manifold stores them.
  template <class T>
  ManifoldTangent<M, T> point_and_velocity(const Vec<T, M::dim>& eta, const Vec<T, M::dim>& nu) const {
    auto xv = M::chart_and_tangent(c_, eta, nu);
    return {xv.first, xv.second};
  }

  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& eta, const Vec<T, N>& nu) const {
    static_assert(N == M::dim, "a local representation lives in R^dim");
    const ManifoldTangent<M, T> t = point_and_velocity<T>(eta, nu);
    const ManifoldPair<M, T> r = map_(t.x, t.v);
    return {M::chart_inverse(c_, r.q0), M::chart_inverse(c_, r.q1)};
  }

 private:
  Map map_;
  typename M::template Point<double> c_;
};

// A non-owning view of a manifold map with the interface LocalRepresentation needs,
// so that a local representation can be re-centred every step without copying the
// map (whose name is a std::string). The viewed map must outlive the view.
template <class Map>
struct MapView {
  using Manifold = typename Map::Manifold;
  const Map* map;
  std::string name() const { return map->name(); }
  bool symmetric() const { return map->symmetric(); }
  int order() const { return map->order(); }
  template <class X, class V>
  auto operator()(const X& x, const V& v) const {
    return (*map)(x, v);
  }
};

// Newton's method in the chart centred at q0.
template <class Map>
ManifoldTangent<typename Map::Manifold, double> newton_manifold_inverse_values(
    const Map& map, const typename Map::Manifold::template Point<double>& q0,
    const typename Map::Manifold::template Point<double>& q1) {
  using M = typename Map::Manifold;
  const LocalRepresentation<Map> local(map, q0);
  const Vec<double, M::dim> a = Vec<double, M::dim>::Zero(), b = M::chart_inverse(q0, q1);
  const TangentPoint<double, M::dim> t = dvm::inverse(local, a, b);
  return local.point_and_velocity(t.x, t.v);
}

// R_d^{-1}(q0, q1) for any scalar T, by Newton's method in the chart centred at the
// value of q0; derivatives by the implicit function theorem on the map's local
// representation (dvm::inverse), so that discrete Lagrangians of maps without a
// closed-form inverse can be differentiated. The chart coordinates of q1 are formed
// from the stored point, so v carries an absolute error of order eps (relative
// eps/|v|), where the closed forms take the relative position without cancellation.
template <class Map, class P>
ManifoldTangent<typename Map::Manifold, typename P::Scalar> newton_manifold_inverse(const Map& map, const P& q0,
                                                                                    const P& q1) {
  using M = typename Map::Manifold;
  using T = typename P::Scalar;
  if constexpr (!is_jet_v<T>) {
    return newton_manifold_inverse_values(map, q0, q1);
  } else {
    typename M::template Point<double> c;
    for (Eigen::Index i = 0; i < c.size(); ++i) c(i) = value(q0(i));
    const LocalRepresentation<MapView<Map>> local(MapView<Map>{&map}, c);
    const Vec<T, M::dim> a = M::chart_inverse(c, q0), b = M::chart_inverse(c, q1);
    const TangentPoint<T, M::dim> t = dvm::inverse(local, a, b);
    return local.point_and_velocity(t.x, t.v);
  }
}

// A generic point of M for checks.
template <class M>
typename M::template Point<double> base_point() {
  return M::sample_point();
}

}  // namespace dvm

namespace dvm {

// A sphere map applied to each factor of (S^2)^K.
template <int K>
class SpherePowerMap {
 public:
  using Manifold = SpherePower<K>;
  explicit SpherePowerMap(SphereMap factor) : f_(std::move(factor)) {}
  std::string name() const { return f_.name(); }
  double theta() const { return f_.theta(); }
  bool symmetric() const { return f_.symmetric(); }
  int order() const { return f_.order(); }

  const SphereMap& factor() const { return f_; }

  template <class T>
  ManifoldPair<Manifold, T> operator()(const Vec<T, 3 * K>& x, const Vec<T, 3 * K>& v) const {
    ManifoldPair<Manifold, T> out;
    for (int i = 0; i < K; ++i) {
      const ManifoldPair<Sphere, T> r = f_(Manifold::block(x, i), Manifold::block(v, i));
      Manifold::template put<T, 3 * K>(out.q0, i, r.q0);
      Manifold::template put<T, 3 * K>(out.q1, i, r.q1);
    }
    return out;
  }
  template <class T>
  ManifoldTangent<Manifold, T> inverse(const Vec<T, 3 * K>& q0, const Vec<T, 3 * K>& q1) const {
    ManifoldTangent<Manifold, T> out;
    for (int i = 0; i < K; ++i) {
      const ManifoldTangent<Sphere, T> t = f_.inverse(Manifold::block(q0, i), Manifold::block(q1, i));
      Manifold::template put<T, 3 * K>(out.x, i, t.x);
      Manifold::template put<T, 3 * K>(out.v, i, t.v);
    }
    return out;
  }
  template <class T>
  ManifoldTangent<Manifold, T> inverse_relative(const Vec<T, 3 * K>& q0, const Vec<T, 3 * K>& d) const {
    ManifoldTangent<Manifold, T> out;
    for (int i = 0; i < K; ++i) {
      const ManifoldTangent<Sphere, T> t = f_.inverse_relative(Manifold::block(q0, i), Manifold::block(d, i));
      Manifold::template put<T, 3 * K>(out.x, i, t.x);
      Manifold::template put<T, 3 * K>(out.v, i, t.v);
    }
    return out;
  }

 private:
  SphereMap f_;
};

template <int K>
SpherePowerMap<K> adjoint_map(const SpherePowerMap<K>& m) {
  return SpherePowerMap<K>(adjoint_map(m.factor()));
}

}  // namespace dvm
