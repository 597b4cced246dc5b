// A retraction on S^2 or SO(3) written as text in the embedding (paper Def. 2.2 with
// Prop. 2.3): the expressions of mechanics/expression.h give f(x, v) component by
// component, and the manifold's map normalises it onto the manifold
// (core/embedded_retraction.h, core/manifold_maps.h):
//
//   S^2    3 expressions in x1 x2 x3 (the unit vector) and v1 v2 v3 (a tangent vector):
//          R_x(v) = f(x, v)/|f(x, v)|, e.g. f = x + v (the projection retraction);
//   SO(3)  9 expressions, row by row (f11, f12, ..., f33), in R11 ... R33 and the body
//          angular velocity w1 w2 w3: R_R(w) = the columns of f(R, w) orthonormalised,
//          e.g. f = R (I + hat(w)) (which normalises to a retraction of order 1).
//
// With integrator.theta this is the map R_d(x, v) = (R_x(-theta v), R_x((1 - theta) v)),
// symmetric (order 2) at theta = 1/2; every theta is inverted by Newton's method in a
// chart, and the lifts, discrete Lagrangian and forms follow as for the built-in maps.
//
// The axioms are checked when the text is read, never assumed: at sample points x
// and each tangent direction u,
//   R_x(0) = x   and   d/dt R_x(t u) at t = 0 = u      (S^2: u tangent at x; SO(3):
//                                                      R hat(u), u = e1, e2, e3),
// the derivative by a Jet; a text that breaks either (or is not finite near the zero
// section) is refused with the residual and the point. Together they are Def. 2.2
// for every theta (Prop. 2.3).
#pragma once

#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/embedded_retraction.h"
#include "core/manifold_maps.h"
#include "mechanics/expression.h"

namespace dvm {

namespace written_retraction_detail {

// One override of EmbeddedEvaluator<T>::evaluate per scalar type, each calling
// Derived::eval<T>.
template <class Derived, class Base, class... Ts>
struct Overrides;
template <class Derived, class Base>
struct Overrides<Derived, Base> : Base {};
template <class Derived, class Base, class T, class... Rest>
struct Overrides<Derived, Base, T, Rest...> : Overrides<Derived, Base, Rest...> {
  using Overrides<Derived, Base, Rest...>::evaluate;
  void evaluate(const T* x, const T* v, T* out) const override {
    static_cast<const Derived*>(this)->eval(x, v, out);
  }
};
template <class Derived, class F>
struct Implement;
template <class Derived, class... Ts>
struct Implement<Derived, EmbeddedFunction<Ts...>> {
  using type = Overrides<Derived, EmbeddedFunction<Ts...>, Ts...>;
};

}  // namespace written_retraction_detail

class WrittenRetraction final
    : public written_retraction_detail::Implement<WrittenRetraction, EmbeddedRetraction>::type {
 public:
  enum class Space { sphere, rotation };
  using Params = std::vector<std::pair<std::string, double>>;

  // Throws std::invalid_argument starting "retraction[i]: " for a parse error in
  // component i, or "retraction: " for a wrong count or a broken axiom.
  WrittenRetraction(Space space, const std::vector<std::string>& texts, const Params& params = {},
                    std::string name = "written")
      : space_(space), name_(std::move(name)) {
    const std::size_t n = space == Space::sphere ? 3 : 9;
    if (texts.size() != n)
      throw std::invalid_argument("retraction: expected " + std::to_string(n) + " expressions (" +
                                  (space == Space::sphere ? "the components of f(x, v) in R^3"
                                                          : "the entries of f(R, w), row by row") +
                                  "), got " + std::to_string(texts.size()));
    ExpressionSymbols s;
    if (space == Space::sphere) {
      for (int i = 0; i < 3; ++i) {
        s.variables.push_back({"x" + std::to_string(i + 1), 0, i});
        s.variables.push_back({"v" + std::to_string(i + 1), 1, i});
      }
    } else {
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i)
          s.variables.push_back({"R" + std::to_string(i + 1) + std::to_string(j + 1), 0, 3 * j + i});
      for (int i = 0; i < 3; ++i) s.variables.push_back({"w" + std::to_string(i + 1), 1, i});
    }
    s.constants = params;
    components_.resize(n);
    texts_ = texts;
    for (std::size_t k = 0; k < n; ++k) {
      // the text is row by row, the storage column-major (as Eigen's matrices)
      const std::size_t at = space == Space::sphere ? k : 3 * (k % 3) + k / 3;
      try {
        components_[at] = Expression::parse(texts[k], s);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("retraction[" + std::to_string(k) + "]: " + e.what());
      }
    }
    check_axioms();
  }

  Space space() const { return space_; }
  const std::string& name() const { return name_; }
  std::string text() const override {
    std::string out = "f = (";
    for (std::size_t k = 0; k < texts_.size(); ++k) out += (k ? ", " : "") + texts_[k];
    return out + ")";
  }
  // The largest residual of the two axioms over the samples (for reports).
  double axiom_residual() const { return residual_; }

  template <class T>
  void eval(const T* x, const T* v, T* out) const {
    for (std::size_t k = 0; k < components_.size(); ++k) out[k] = components_[k](x, v);
  }

 private:
  static std::string show(double x) {
    std::ostringstream o;
    o.precision(6);
    o << x;
    return o.str();
  }

  void check_axioms() {
    using J = ceres::Jet<double, 1>;
    auto self = std::shared_ptr<const EmbeddedRetraction>(std::shared_ptr<const EmbeddedRetraction>{}, this);
    const Vec<double, 3> dirs[4] = {{0.48, -0.6, 0.64}, {-0.36, 0.8, 0.48}, {0.8, 0.36, -0.48}, {0.0, 0.0, 1.0}};
    residual_ = 0.0;
    for (const Vec<double, 3>& d : dirs) {
      if (space_ == Space::sphere) {
        const SphereMap R(self, 0.0, "written");
        const Vec<double, 3> x = d.normalized();
        const Vec<double, 3> r0 = R.retract(x, Vec<double, 3>(Vec<double, 3>::Zero()));
        refuse_if((r0 - x).norm(), "R_x(0) = x", x);
        // two tangent directions at x
        const Vec<double, 3> a = (std::fabs(x[0]) < 0.9 ? Vec<double, 3>::UnitX() : Vec<double, 3>::UnitY()).cross(x).normalized();
        for (const Vec<double, 3>& u : {a, Vec<double, 3>(x.cross(a))}) {
          Vec<J, 3> xj, vj;
          for (int i = 0; i < 3; ++i) {
            xj[i] = J(x[i]);
            vj[i] = J(0.0);
            vj[i].v[0] = u[i];
          }
          const Vec<J, 3> r = R.retract(xj, vj);
          Vec<double, 3> slope;
          for (int i = 0; i < 3; ++i) slope[i] = r[i].v[0];
          refuse_if((slope - u).norm(), "d/dt R_x(t u) = u at t = 0", x);
        }
      } else {
        const SO3Map R(self, 0.0, "written");
        const Mat<double, 3, 3> X = SO3::exp(Vec<double, 3>(1.3 * d));
        const Mat<double, 3, 3> r0 = R.retract(X, Vec<double, 3>(Vec<double, 3>::Zero()));
        refuse_if((r0 - X).norm(), "R_R(0) = R", d);
        for (int k = 0; k < 3; ++k) {
          Mat<J, 3, 3> Xj;
          Vec<J, 3> wj;
          for (int i = 0; i < 3; ++i) {
            wj[i] = J(0.0);
            wj[i].v[0] = i == k ? 1.0 : 0.0;
            for (int j = 0; j < 3; ++j) Xj(i, j) = J(X(i, j));
          }
          const Mat<J, 3, 3> r = R.retract(Xj, wj);
          Mat<double, 3, 3> slope;
          for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) slope(i, j) = r(i, j).v[0];
          refuse_if((slope - X * SO3::hat(Vec<double, 3>(Vec<double, 3>::Unit(k)))).norm(),
                    "d/dt R_R(t e_k) = R hat(e_k) at t = 0", d);
        }
      }
    }
  }
  void refuse_if(double residual, const char* axiom, const Vec<double, 3>& at) {
    if (!std::isfinite(residual) || !(residual <= 1e-12))
      throw std::invalid_argument("retraction: not a retraction (Def. 2.2 through Prop. 2.3): " + std::string(axiom) +
                                  " fails by " + show(residual) + " at " +
                                  (space_ == Space::sphere ? "x = (" : "R = exp(1.3 (") + show(at[0]) + ", " +
                                  show(at[1]) + ", " + show(at[2]) + (space_ == Space::sphere ? ")" : "))"));
    residual_ = std::fmax(residual_, residual);
  }

  Space space_;
  std::string name_;
  std::vector<Expression> components_;
  std::vector<std::string> texts_;
  double residual_ = 0.0;
};

}  // namespace dvm
