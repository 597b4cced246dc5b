// Products of configuration spaces: R^n as a manifold, the product M1 x M2 of any two
// manifolds of core/manifolds.h (nest for more factors), and the product of two
// discretization maps.
//
// R^n: chart(c, eta) = c + eta, tangent vectors and covectors are plain n-vectors.
// On R^n the theta map of Prop. 2.3 with the identity retraction,
//   R_d(x, v) = (x - theta v, x + (1 - theta) v),   R_d^{-1}(q0, q1) = (q0 + theta d, d), d = q1 - q0.
//
// M1 x M2: a point is the pair (x1, x2), stored as one column holding the coefficients
// of x1 then those of x2 (column-major for matrices: on R^3 x SO(3), (r, vec(R))).
// Tangent vectors and covectors are stacked the same way, charts are products of
// charts (chart((c1, c2), (eta1, eta2)) = (chart1(c1, eta1), chart2(c2, eta2))), and
// every operation acts factor by factor. The product of maps
//   (R1 x R2)_d((x1, x2), (v1, v2)) = ((R1_d^0, R2_d^0), (R1_d^1, R2_d^1))
// is a discretization map on the product (both axioms of Def. 2.2 hold factor by
// factor), symmetric when both factors are.
#pragma once

#include <string>
#include <utility>

#include "core/manifold_maps.h"

namespace dvm {

template <int N>
struct Euclidean {
  static constexpr int dim = N;
  static constexpr const char* name = "R^n";
  template <class T>
  using Point = Vec<T, N>;
  template <class T>
  using Tangent = Vec<T, N>;

  template <class T, class U>
  static Vec<T, N> tangent(const Vec<U, N>&, const Vec<T, N>& nu) {
    return nu;
  }
  template <class T>
  static Vec<T, N> tangent_coordinates(const Vec<double, N>&, const Vec<T, N>& v) {
    return v;
  }
  template <class T>
  static Vec<T, N> chart(const Vec<double, N>& c, const Vec<T, N>& eta) {
    Vec<T, N> x;
    for (int i = 0; i < N; ++i) x[i] = eta[i] + c[i];
    return x;
  }
  template <class T>
  static Vec<T, N> chart_inverse(const Vec<double, N>& c, const Vec<T, N>& y) {
    Vec<T, N> eta;
    for (int i = 0; i < N; ++i) eta[i] = y[i] - c[i];
    return eta;
  }
  template <class T>
  static std::pair<Vec<T, N>, Vec<T, N>> chart_and_tangent(const Vec<double, N>& c, const Vec<T, N>& eta,
                                                           const Vec<T, N>& nu) {
    return {chart(c, eta), nu};
  }
  static Vec<double, N> covector_to_local(const Vec<double, N>&, const Vec<double, N>& p) { return p; }
  static Vec<double, N> covector_from_local(const Vec<double, N>&, const Vec<double, N>& p) { return p; }
  static double point_defect(const Vec<double, N>&) { return 0.0; }
  static double tangent_defect(const Vec<double, N>&, const Vec<double, N>&) { return 0.0; }
  static double distance(const Vec<double, N>& x, const Vec<double, N>& y) { return (x - y).cwiseAbs().maxCoeff(); }
  static Vec<double, N> clean(const Vec<double, N>& x) { return x; }
  static Vec<double, N> sample_point() {
    Vec<double, N> x;
    for (int i = 0; i < N; ++i) x[i] = 0.3 + 0.4 * i;
    return x;
  }
  template <class T, class U>
  static Vec<T, N> relative(const Vec<U, N>& q0, const Vec<T, N>& q1) {
    Vec<T, N> d;
    for (int i = 0; i < N; ++i) d[i] = q1[i] - q0[i];
    return d;
  }
  template <class T>
  static Vec<T, N> relative_chart(const Vec<double, N>&, const Vec<T, N>& xi) {
    return xi;
  }
  static Vec<double, N> next_guess(const Vec<double, N>& q_prev, const Vec<double, N>& q) { return q - q_prev; }
};

// The theta map on R^n (identity retraction).
template <int N>
class EuclideanThetaMap {
 public:
  using Manifold = Euclidean<N>;
  EuclideanThetaMap(double theta, std::string name) : theta_(theta), name_(std::move(name)) {
    detail::check_theta(theta);
  }
  double theta() const { return theta_; }
  std::string name() const { return name_; }
  bool symmetric() const { return theta_ == 0.5; }
  int order() const { return symmetric() ? 2 : 1; }
  bool closed_form_inverse() const { return true; }
  template <class T>
  ManifoldPair<Manifold, T> operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    return {Vec<T, N>(x - theta_ * v), Vec<T, N>(x + (1.0 - theta_) * v)};
  }
  template <class T>
  ManifoldTangent<Manifold, T> inverse(const Vec<T, N>& q0, const Vec<T, N>& q1) const {
    return inverse_relative(q0, Euclidean<N>::relative(q0, q1));
  }
  template <class T>
  ManifoldTangent<Manifold, T> inverse_relative(const Vec<T, N>& q0, const Vec<T, N>& d) const {
    return {Vec<T, N>(q0 + theta_ * d), d};
  }

 private:
  double theta_;
  std::string name_;
};

template <int N>
EuclideanThetaMap<N> adjoint_map(const EuclideanThetaMap<N>& m) {
  return EuclideanThetaMap<N>(1.0 - m.theta(), m.name() + "*");
}

namespace detail {
// Number of stored coefficients of an Eigen type.
template <class E>
constexpr int coefficients = E::RowsAtCompileTime * E::ColsAtCompileTime;

// The block of `size` coefficients of a stacked column starting at `offset`, as type E.
template <class E, class T, int K>
E unstack(const Vec<T, K>& x, int offset) {
  E out;
  for (int i = 0; i < coefficients<E>; ++i) out(i) = x[offset + i];
  return out;
}
template <class T, int K, class E>
void stack_into(Vec<T, K>& x, int offset, const E& e) {
  for (int i = 0; i < coefficients<E>; ++i) x[offset + i] = e(i);
}
}  // namespace detail

template <class M1, class M2>
struct Product {
  template <class T>
  using P1 = typename M1::template Point<T>;
  template <class T>
  using P2 = typename M2::template Point<T>;
  template <class T>
  using T1 = typename M1::template Tangent<T>;
  template <class T>
  using T2 = typename M2::template Tangent<T>;
  static constexpr int s1 = detail::coefficients<P1<double>>, s2 = detail::coefficients<P2<double>>;
  static constexpr int t1 = detail::coefficients<T1<double>>, t2 = detail::coefficients<T2<double>>;
  static constexpr int d1 = M1::dim, d2 = M2::dim;
  static constexpr int dim = d1 + d2;
  static constexpr const char* name = "product";
  template <class T>
  using Point = Vec<T, s1 + s2>;
  template <class T>
  using Tangent = Vec<T, t1 + t2>;

  template <class T>
  static P1<T> first(const Point<T>& x) {
    return detail::unstack<P1<T>>(x, 0);
  }
  template <class T>
  static P2<T> second(const Point<T>& x) {
    return detail::unstack<P2<T>>(x, s1);
  }
  template <class T>
  static Point<T> make_point(const P1<T>& a, const P2<T>& b) {
    Point<T> x;
    detail::stack_into(x, 0, a);
    detail::stack_into(x, s1, b);
    return x;
  }
  template <class T>
  static Tangent<T> make_tangent(const T1<T>& a, const T2<T>& b) {
    Tangent<T> v;
    detail::stack_into(v, 0, a);
    detail::stack_into(v, t1, b);
    return v;
  }
  template <class T>
  static T1<T> tangent_first(const Tangent<T>& v) {
    return detail::unstack<T1<T>>(v, 0);
  }
  template <class T>
  static T2<T> tangent_second(const Tangent<T>& v) {
    return detail::unstack<T2<T>>(v, t1);
  }
  template <class T>
  static Vec<T, d1> local_first(const Vec<T, dim>& eta) {
    return detail::unstack<Vec<T, d1>>(eta, 0);
  }
  template <class T>
  static Vec<T, d2> local_second(const Vec<T, dim>& eta) {
    return detail::unstack<Vec<T, d2>>(eta, d1);
  }
  template <class T>
  static Vec<T, dim> make_local(const Vec<T, d1>& a, const Vec<T, d2>& b) {
    Vec<T, dim> out;
    detail::stack_into(out, 0, a);
    detail::stack_into(out, d1, b);
    return out;
  }

  template <class T, class U>
  static Tangent<T> tangent(const Point<U>& x, const Vec<T, dim>& nu) {
    return make_tangent<T>(M1::tangent(first(x), local_first(nu)), M2::tangent(second(x), local_second(nu)));
  }
  template <class T>
  static Vec<T, dim> tangent_coordinates(const Point<double>& x, const Tangent<T>& v) {
    return make_local<T>(M1::tangent_coordinates(first(x), tangent_first(v)),
                         M2::tangent_coordinates(second(x), tangent_second(v)));
  }
  template <class T>
  static Point<T> chart(const Point<double>& c, const Vec<T, dim>& eta) {
    return make_point<T>(M1::chart(first(c), local_first(eta)), M2::chart(second(c), local_second(eta)));
  }
  template <class T>
  static Vec<T, dim> chart_inverse(const Point<double>& c, const Point<T>& y) {
    return make_local<T>(M1::chart_inverse(first(c), first(y)), M2::chart_inverse(second(c), second(y)));
  }
  template <class T>
  static std::pair<Point<T>, Tangent<T>> chart_and_tangent(const Point<double>& c, const Vec<T, dim>& eta,
                                                           const Vec<T, dim>& nu) {
    const auto a = M1::chart_and_tangent(first(c), local_first(eta), local_first(nu));
    const auto b = M2::chart_and_tangent(second(c), local_second(eta), local_second(nu));
    return {make_point<T>(a.first, b.first), make_tangent<T>(a.second, b.second)};
  }
  static Vec<double, dim> covector_to_local(const Point<double>& x, const Tangent<double>& p) {
    return make_local<double>(M1::covector_to_local(first(x), tangent_first(p)),
                              M2::covector_to_local(second(x), tangent_second(p)));
  }
  static Tangent<double> covector_from_local(const Point<double>& x, const Vec<double, dim>& p) {
    return make_tangent<double>(M1::covector_from_local(first(x), local_first(p)),
                                M2::covector_from_local(second(x), local_second(p)));
  }
  static double point_defect(const Point<double>& x) {
    return std::fmax(M1::point_defect(first(x)), M2::point_defect(second(x)));
  }
  static double tangent_defect(const Point<double>& x, const Tangent<double>& v) {
    return std::fmax(M1::tangent_defect(first(x), tangent_first(v)), M2::tangent_defect(second(x), tangent_second(v)));
  }
  static double distance(const Point<double>& x, const Point<double>& y) { return (x - y).cwiseAbs().maxCoeff(); }
  static Point<double> clean(const Point<double>& x) {
    return make_point<double>(M1::clean(first(x)), M2::clean(second(x)));
  }
  static Point<double> sample_point() { return make_point<double>(M1::sample_point(), M2::sample_point()); }

  // Relative positions of the factors, stacked.
  template <class T>
  using R1 = decltype(M1::relative(std::declval<P1<double>>(), std::declval<P1<T>>()));
  template <class T>
  using R2 = decltype(M2::relative(std::declval<P2<double>>(), std::declval<P2<T>>()));
  static constexpr int r1 = detail::coefficients<R1<double>>, r2 = detail::coefficients<R2<double>>;
  template <class T>
  using Relative = Vec<T, r1 + r2>;

  template <class T, class U>
  static Relative<T> relative(const Point<U>& q0, const Point<T>& q1) {
    Relative<T> r;
    detail::stack_into(r, 0, M1::relative(detail::unstack<P1<U>>(q0, 0), first(q1)));
    detail::stack_into(r, r1, M2::relative(detail::unstack<P2<U>>(q0, s1), second(q1)));
    return r;
  }
  template <class T>
  static Relative<T> relative_chart(const Point<double>& q0, const Vec<T, dim>& xi) {
    Relative<T> r;
    detail::stack_into(r, 0, M1::relative_chart(first(q0), local_first(xi)));
    detail::stack_into(r, r1, M2::relative_chart(second(q0), local_second(xi)));
    return r;
  }
  static Vec<double, dim> next_guess(const Point<double>& q_prev, const Point<double>& q) {
    return make_local<double>(M1::next_guess(first(q_prev), first(q)), M2::next_guess(second(q_prev), second(q)));
  }
};

template <class Map1, class Map2>
class ProductMap {
 public:
  using A = typename Map1::Manifold;
  using B = typename Map2::Manifold;
  using Manifold = Product<A, B>;
  ProductMap(Map1 a, Map2 b) : a_(std::move(a)), b_(std::move(b)) {}
  std::string name() const { return a_.name() + " x " + b_.name(); }
  double theta() const { return a_.theta(); }
  bool symmetric() const { return a_.symmetric() && b_.symmetric(); }
  int order() const { return std::min(a_.order(), b_.order()); }
  bool closed_form_inverse() const { return a_.closed_form_inverse() && b_.closed_form_inverse(); }
  const Map1& first() const { return a_; }
  const Map2& second() const { return b_; }

  template <class T>
  ManifoldPair<Manifold, T> operator()(const typename Manifold::template Point<T>& x,
                                       const typename Manifold::template Tangent<T>& v) const {
    const auto ra = a_(Manifold::first(x), Manifold::tangent_first(v));
    const auto rb = b_(Manifold::second(x), Manifold::tangent_second(v));
    return {Manifold::template make_point<T>(ra.q0, rb.q0), Manifold::template make_point<T>(ra.q1, rb.q1)};
  }
  template <class T>
  ManifoldTangent<Manifold, T> inverse(const typename Manifold::template Point<T>& q0,
                                       const typename Manifold::template Point<T>& q1) const {
    const auto ta = a_.inverse(Manifold::first(q0), Manifold::first(q1));
    const auto tb = b_.inverse(Manifold::second(q0), Manifold::second(q1));
    return {Manifold::template make_point<T>(ta.x, tb.x), Manifold::template make_tangent<T>(ta.v, tb.v)};
  }
  template <class T>
  ManifoldTangent<Manifold, T> inverse_relative(const typename Manifold::template Point<T>& q0,
                                                const typename Manifold::template Relative<T>& rel) const {
    using RA = typename Manifold::template R1<T>;
    using RB = typename Manifold::template R2<T>;
    const auto ta = a_.inverse_relative(Manifold::first(q0), detail::unstack<RA>(rel, 0));
    const auto tb = b_.inverse_relative(Manifold::second(q0), detail::unstack<RB>(rel, Manifold::r1));
    return {Manifold::template make_point<T>(ta.x, tb.x), Manifold::template make_tangent<T>(ta.v, tb.v)};
  }

 private:
  Map1 a_;
  Map2 b_;
};

template <class Map1, class Map2>
ProductMap<Map1, Map2> adjoint_map(const ProductMap<Map1, Map2>& m) {
  return ProductMap<Map1, Map2>(adjoint_map(m.first()), adjoint_map(m.second()));
}

}  // namespace dvm
