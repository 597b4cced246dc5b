// A Lagrangian of fixed size N with its type erased: any Lagrangian of mechanics/ with
// dim = N seen through one type, so that a step template is compiled once per size
// rather than once per system.
//
// The contract of a fixed-size Lagrangian (mechanics/lagrangian.h): dim, name(),
// operator()(q, v) and gradient(q, v, dLdq, dLdv) for every scalar type a step
// evaluates L in, and velocity(q, p), the inverse Legendre map. Here each of those is a
// virtual function, one per scalar type of ErasedScalars<N> (double and the Jets the
// steps nest: seeds of 1, N, 2N and 3N directions, and those nested once), implemented
// once per system by ModelOf<S> with the system's own code: its closed-form gradient
// where it has one, automatic differentiation otherwise (lagrangian_gradient), its
// closed-form velocity or Newton's method on the Legendre map (legendre_inverse). A step
// calls L a few times per Newton iteration, so the indirect call is paid a few times per
// iteration, not per arithmetic operation.
//
// A step instantiated with a scalar type outside the list does not compile (the
// overload is missing): add the type to ErasedScalars.
#pragma once

#include <memory>
#include <string>
#include <type_traits>
#include <utility>

#include "mechanics/lagrangian.h"

namespace dvm {

namespace erased_detail {

template <class... Ts>
struct TypeList {};

// The types of a list, each once, in their first order.
template <class Out, class... In>
struct Unique;
template <class... Out>
struct Unique<TypeList<Out...>> {
  using type = TypeList<Out...>;
};
template <class... Out, class T, class... Rest>
struct Unique<TypeList<Out...>, T, Rest...> {
  using type = typename Unique<std::conditional_t<std::disjunction_v<std::is_same<T, Out>...>, TypeList<Out...>,
                                                  TypeList<Out..., T>>,
                               Rest...>::type;
};

// The virtual functions of one scalar type.
template <int N, class T>
class Slot {
 public:
  virtual ~Slot() = default;
  virtual T value(const Vec<T, N>& q, const Vec<T, N>& v) const = 0;
  virtual void gradient(const Vec<T, N>& q, const Vec<T, N>& v, Vec<T, N>& dLdq, Vec<T, N>& dLdv) const = 0;
};

template <int N, class List>
class Slots;
template <int N, class... Ts>
class Slots<N, TypeList<Ts...>> : public Slot<N, Ts>... {
 public:
  using Slot<N, Ts>::value...;
  using Slot<N, Ts>::gradient...;
};

}  // namespace erased_detail

// The scalar types the steps of kernels_rn_sized.h evaluate L in, and no others: each
// is a value and a gradient compiled for every system, with nested Jets where the
// system's gradient is not in closed form. (Removing one and compiling the sized
// kernels names the steps that need it.)
template <int N>
struct ErasedScalars {
  using J1 = ceres::Jet<double, N>;
  using J2 = ceres::Jet<double, 2 * N>;
  using type = typename erased_detail::Unique<
      erased_detail::TypeList<>, double, J1, J2,
      ceres::Jet<J2, 2 * N>,                    // second derivatives in (q, v) (the Hamiltonian form)
      ceres::Jet<double, 3 * N>,                // the boundary-value problems' three nodes
      ceres::Jet<double, 1>, ceres::Jet<J2, 1>  // a derivative along one direction (the Legendre lift)
      >::type;
};

template <int N>
class ErasedLagrangian {
 public:
  static constexpr int dim = N;

  // What a system provides: value and gradient for every scalar type, its name and
  // the inverse Legendre map.
  class Model : public erased_detail::Slots<N, typename ErasedScalars<N>::type> {
   public:
    virtual std::string name() const = 0;
    virtual Vec<double, N> velocity(const Vec<double, N>& q, const Vec<double, N>& p) const = 0;
  };

 private:
  // The overrides of Model for the system S: one layer per scalar type.
  template <class S, class Base, class List>
  class Impl;
  template <class S, class Base>
  class Impl<S, Base, erased_detail::TypeList<>> : public Base {
   public:
    explicit Impl(S s) : s_(std::move(s)) {}

   protected:
    S s_;
  };
  template <class S, class Base, class T, class... Rest>
  class Impl<S, Base, erased_detail::TypeList<T, Rest...>> : public Impl<S, Base, erased_detail::TypeList<Rest...>> {
    using Next = Impl<S, Base, erased_detail::TypeList<Rest...>>;

   public:
    using Next::Next;
    using Next::value;  // the other scalar types' overrides stay visible
    using Next::gradient;
    T value(const Vec<T, N>& q, const Vec<T, N>& v) const override { return this->s_(q, v); }
    void gradient(const Vec<T, N>& q, const Vec<T, N>& v, Vec<T, N>& dLdq, Vec<T, N>& dLdv) const override {
      lagrangian_gradient(this->s_, q, v, dLdq, dLdv);
    }
  };

 public:
  template <class S>
  class ModelOf final : public Impl<S, Model, typename ErasedScalars<N>::type> {
    static_assert(S::dim == N, "ErasedLagrangian<N> holds a Lagrangian of N coordinates");
    using Base = Impl<S, Model, typename ErasedScalars<N>::type>;

   public:
    explicit ModelOf(S s) : Base(std::move(s)) {}
    std::string name() const override { return this->s_.name(); }
    Vec<double, N> velocity(const Vec<double, N>& q, const Vec<double, N>& p) const override {
      return legendre_inverse(this->s_, q, p);
    }
  };

  explicit ErasedLagrangian(std::shared_ptr<const Model> model) : model_(std::move(model)) {}

  std::string name() const { return model_->name(); }
  template <class T>
  T operator()(const Vec<T, N>& q, const Vec<T, N>& v) const {
    return model_->value(q, v);
  }
  template <class T>
  void gradient(const Vec<T, N>& q, const Vec<T, N>& v, Vec<T, N>& dLdq, Vec<T, N>& dLdv) const {
    model_->gradient(q, v, dLdq, dLdv);
  }
  // The inverse Legendre map: the system's closed form, or Newton's method.
  Vec<double, N> velocity(const Vec<double, N>& q, const Vec<double, N>& p) const { return model_->velocity(q, p); }

 private:
  std::shared_ptr<const Model> model_;
};

// The erased view of a fixed-size Lagrangian.
template <class S>
ErasedLagrangian<S::dim> erase_lagrangian(const S& L) {
  using E = ErasedLagrangian<S::dim>;
  return E(std::make_shared<const typename E::template ModelOf<S>>(L));
}

}  // namespace dvm
