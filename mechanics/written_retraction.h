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
// the derivative by a Jet; a text that breaks either (or is not finite there) is
// refused with the residual and the point. Together they are Def. 2.2
// for every theta (Prop. 2.3).
//
// The constructor, the destructor and the check are compiled once
// (mechanics/written_retraction.cc, library dvm_written_retraction): with them the
// vtable and the tape evaluations for every scalar type of EmbeddedRetraction are
// instantiated in that one translation unit, not in each file that makes a retraction.
// On (S^2)^K the sphere's map acts on each factor (SpherePowerMap).
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/embedded_retraction.h"
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
                    std::string name = "written");
  ~WrittenRetraction() override;

  Space space() const { return space_; }
  const std::string& name() const { return name_; }
  std::string text() const override;
  // The largest residual of the two axioms over the samples (for reports).
  double axiom_residual() const { return residual_; }

  template <class T>
  void eval(const T* x, const T* v, T* out) const {
    for (std::size_t k = 0; k < components_.size(); ++k) out[k] = components_[k](x, v);
  }

 private:
  void check_axioms();
  void refuse_if(double residual, const char* axiom, const double* at);

  Space space_;
  std::string name_;
  std::vector<Expression> components_;
  std::vector<std::string> texts_;
  double residual_ = 0.0;
};

}  // namespace dvm
