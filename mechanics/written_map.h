// A discretization map on R^n written as text (paper Def. 2.2), applied component by
// component: each coordinate q_i is mapped by the same expressions in the scalars
// x = q_i and v = v_i, in one of two forms,
//   points:      R_d(x, v) = (q0(x, v), q1(x, v)),
//   retraction:  R_d(x, v) = (R(x, -theta v), R(x, (1 - theta) v))   (Prop. 2.3),
// with the language of mechanics/expression.h (parameters and pi as constants).
//
// Everything else comes from the generic R^n path (core/map_operations.h): the inverse
// by Newton's method with derivatives by the implicit function theorem, the lifts, and
// with them the discrete Lagrangian and every form. The adjoint (Prop. 2.4)
//   R_d^*(x, v) = (R^2(x, -v), R^1(x, -v))
// is the same type with a flag, so compositions use one step type.
//
// Def. 2.2 is checked at construction, never assumed: at sample points x,
//   R_d(x, 0) = (x, x)   and   d/dv (R^2 - R^1)(x, 0) = 1
// (the component form of D_v R^2 - D_v R^1 = Id at the zero section), the derivative by
// a Jet. A map that breaks either is refused with the residual and the point. Whether
// the map is its own adjoint is measured the same way (|R_d - R_d^*| at sample points),
// which decides its claimed order: 2 if symmetric, else 1.
#pragma once

#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/discretization_map.h"
#include "mechanics/expression.h"

namespace dvm {

// x to six significant digits, for the messages about written texts.
inline std::string show_number(double x) {
  std::ostringstream out;
  out.precision(6);
  out << x;
  return out.str();
}

class WrittenMap {
 public:
  static constexpr bool provides_inverse = false;
  using Params = std::vector<std::pair<std::string, double>>;

  // R_d(x, v) = (q0(x, v), q1(x, v)). Throws std::invalid_argument naming "q0" or "q1"
  // for a parse error, or a violation of Def. 2.2.
  static WrittenMap points(std::string name, const std::string& q0, const std::string& q1, const Params& params = {}) {
    WrittenMap m(std::move(name));
    m.first_ = parse("q0", q0, params);
    m.second_ = parse("q1", q1, params);
    m.finish();
    return m;
  }
  // R_d(x, v) = (R(x, -theta v), R(x, (1 - theta) v)) for a retraction R(x, v).
  static WrittenMap retraction(std::string name, const std::string& r, double theta, const Params& params = {}) {
    if (!(theta >= 0.0 && theta <= 1.0))
      throw std::invalid_argument("theta must lie in [0, 1], got " + show_number(theta));
    WrittenMap m(std::move(name));
    m.first_ = parse("retraction", r, params);
    m.retraction_ = true;
    m.theta_ = theta;
    m.finish();
    return m;
  }

  // The flat retraction R(x, v) = x + v (retraction-theta): the same map, evaluated
  // without the tape, which is faster per step.
  static WrittenMap flat_retraction(std::string name, double theta) {
    WrittenMap m = retraction(std::move(name), "x + v", theta);
    m.flat_ = true;
    return m;
  }

  std::string name() const { return adjoint_ ? name_ + "*" : name_; }
  bool is_retraction() const { return retraction_; }
  double theta() const { return retraction_ ? (adjoint_ ? 1.0 - theta_ : theta_) : NAN; }
  bool symmetric() const { return symmetric_; }
  int order() const { return symmetric_ ? 2 : 1; }
  // |R_d - R_d^*| at the sample points (0 for a symmetric map, up to round-off).
  double asymmetry() const { return asymmetry_; }
  WrittenMap adjoint() const {
    WrittenMap a = *this;
    a.adjoint_ = !adjoint_;
    return a;
  }
  // The same retraction at another theta (Prop. 2.3; the stages of a composition with a
  // theta per stage), its symmetry measured again. Throws std::invalid_argument for a
  // map written as q0 and q1, which has no theta, or a theta outside [0, 1].
  WrittenMap at_theta(double theta) const {
    if (!retraction_) throw std::invalid_argument("a map written as q0 and q1 has no theta");
    if (!(theta >= 0.0 && theta <= 1.0))
      throw std::invalid_argument("theta must lie in [0, 1], got " + show_number(theta));
    WrittenMap m = *this;
    m.theta_ = theta;
    m.adjoint_ = false;
    m.finish();
    return m;
  }
  const std::string& text(int which) const { return (which == 0 ? first_ : second_)->text(); }

  template <class T, int N>
  PointPair<T, N> operator()(const Vec<T, N>& x, const Vec<T, N>& v) const {
    PointPair<T, N> out;
    out.q0.resize(x.size());
    out.q1.resize(x.size());
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      const std::pair<T, T> r = scalar(x[i], v[i]);
      out.q0[i] = r.first;
      out.q1[i] = r.second;
    }
    return out;
  }

  // (R^1, R^2)(x, v) for scalars.
  template <class T>
  std::pair<T, T> scalar(const T& x, const T& v) const {
    if (adjoint_) {
      const std::pair<T, T> r = plain(x, T(-v));
      return {r.second, r.first};
    }
    return plain(x, v);
  }

 private:
  explicit WrittenMap(std::string name) : name_(std::move(name)) {}

  template <class T>
  std::pair<T, T> plain(const T& x, const T& v) const {
    if (retraction_) {
      const T a = -theta_ * v, b = (1.0 - theta_) * v;
      if (flat_) return {x + a, x + b};
      return {(*first_)(&x, &a), (*first_)(&x, &b)};
    }
    return {(*first_)(&x, &v), (*second_)(&x, &v)};
  }

  static std::shared_ptr<const Expression> parse(const std::string& key, const std::string& text, const Params& params) {
    ExpressionSymbols s;
    s.variables.push_back({"x", 0, 0});
    s.variables.push_back({"v", 1, 0});
    s.constants = params;
    try {
      return std::make_shared<const Expression>(Expression::parse(text, s));
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(key + ": " + e.what());
    }
  }

  // Def. 2.2 and the symmetry measurement, at x in a few points over [-2, 2].
  void finish() {
    using J = ceres::Jet<double, 1>;
    const double xs[] = {-1.7, -0.4, 0.0, 0.3, 1.1, 2.0};
    const char* where = retraction_ ? "retraction" : "q1";
    for (double x : xs) {
      const std::pair<double, double> z = plain(x, 0.0);
      const double e0 = std::fabs(z.first - x), e1 = std::fabs(z.second - x);
      if (!(e0 <= 1e-13 * (1.0 + std::fabs(x))) || !(e1 <= 1e-13 * (1.0 + std::fabs(x))))
        throw std::invalid_argument(std::string(retraction_ ? "retraction" : e0 > e1 ? "q0" : "q1") +
                                    ": not a discretization map (Def. 2.2): R_d(x, 0) = (x, x) fails at x = " +
                                    show_number(x) + " by " + show_number(std::fmax(e0, e1)));
      const std::pair<J, J> d = plain(J(x), J(0.0, 0));
      const double slope = d.second.v[0] - d.first.v[0];
      if (!(std::fabs(slope - 1.0) <= 1e-12))
        throw std::invalid_argument(std::string(where) +
                                    ": not a discretization map (Def. 2.2): d/dv (R^2 - R^1) at v = 0 must be 1, is " +
                                    show_number(slope) + " at x = " + show_number(x));
    }
    asymmetry_ = 0.0;
    for (double x : xs)
      for (double v : {-0.6, -0.2, 0.25, 0.7}) {
        const std::pair<double, double> r = plain(x, v), s = plain(x, -v);
        asymmetry_ = std::fmax(asymmetry_, std::fmax(std::fabs(r.first - s.second), std::fabs(r.second - s.first)));
      }
    if (!std::isfinite(asymmetry_))
      throw std::invalid_argument(std::string(where) + ": not finite near the zero section (|v| <= 0.7, |x| <= 2)");
    symmetric_ = asymmetry_ <= 1e-14 * 4.0;
  }

  std::string name_;
  std::shared_ptr<const Expression> first_, second_;
  bool retraction_ = false;
  double theta_ = 0.5;
  bool adjoint_ = false;
  bool flat_ = false;
  bool symmetric_ = false;
  double asymmetry_ = 0.0;
};

}  // namespace dvm
