// A run-time-sized Lagrangian with its type erased: any system of the concept of
// mechanics/dynamic_system.h (typically FixedAsDynamic<S> of a built-in system) seen
// through one type, so that a run-time-sized step is compiled once for all of them
// rather than once per system. The runtime steps the built-in systems of R^n this way
// where a run needs a step that only the run-time-sized family has (the derivative of
// the step, `dvm run --linearize`: solvers/runtime/kernels_rn_run_time.cc).
//
// Each evaluation (value, gradient, Hessian, the inverse Legendre map) is one indirect
// call; a step evaluates L a few times per Newton iteration, so the call is paid that
// often, not per arithmetic operation. The closed-form inverse Legendre map is kept
// where the system has one (closed_velocity returns true), else the generic Newton
// iteration of dynamic_system.h runs on the erased system.
#pragma once

#include <memory>
#include <string>
#include <type_traits>
#include <utility>

#include "mechanics/dynamic_system.h"

namespace dvm {

class ErasedDynamicLagrangian {
 public:
  template <class Sys>
  explicit ErasedDynamicLagrangian(Sys system) : model_(std::make_shared<const ModelOf<Sys>>(std::move(system))) {
    static_assert(is_dynamic_system_v<Sys>, "ErasedDynamicLagrangian takes a run-time-sized system");
    static_assert(!has_time<Sys>::value, "ErasedDynamicLagrangian takes no Lagrangian in t");
  }

  int dim() const { return model_->dim(); }
  std::string name() const { return model_->name(); }
  double value(const DynIn& q, const DynIn& v) const { return model_->value(q, v); }
  void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const { model_->gradient(q, v, Lq, Lv); }
  void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv, DynMatOut Lqq, DynMatOut Lqv,
               DynMatOut Lvv) const {
    model_->hessian(q, v, Lq, Lv, Lqq, Lqv, Lvv);
  }
  // v = FL^{-1}(q, p) where the system has it in closed form (then true), else false
  // (dynamic_system.h's Newton iteration then; has_runtime_velocity)
  bool closed_velocity(const DynIn& q, const DynIn& p, DynOut v) const { return model_->closed_velocity(q, p, v); }

 private:
  class Model {
   public:
    virtual ~Model() = default;
    virtual int dim() const = 0;
    virtual std::string name() const = 0;
    virtual double value(const DynIn& q, const DynIn& v) const = 0;
    virtual void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const = 0;
    virtual void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv, DynMatOut Lqq, DynMatOut Lqv,
                         DynMatOut Lvv) const = 0;
    virtual bool closed_velocity(const DynIn& q, const DynIn& p, DynOut v) const = 0;
  };
  template <class Sys>
  class ModelOf final : public Model {
   public:
    explicit ModelOf(Sys s) : s_(std::move(s)) {}
    int dim() const override { return s_.dim(); }
    std::string name() const override { return s_.name(); }
    double value(const DynIn& q, const DynIn& v) const override { return s_.value(q, v); }
    void gradient(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv) const override { s_.gradient(q, v, Lq, Lv); }
    void hessian(const DynIn& q, const DynIn& v, DynOut Lq, DynOut Lv, DynMatOut Lqq, DynMatOut Lqv,
                 DynMatOut Lvv) const override {
      s_.hessian(q, v, Lq, Lv, Lqq, Lqv, Lvv);
    }
    bool closed_velocity(const DynIn& q, const DynIn& p, DynOut v) const override {
      if constexpr (has_dynamic_velocity<Sys>::value) {
        s_.velocity(q, p, v);
        return true;
      } else if constexpr (has_runtime_velocity<Sys>::value) {
        return s_.closed_velocity(q, p, v);
      } else {
        (void)q, (void)p, (void)v;
        return false;
      }
    }

   private:
    Sys s_;
  };

  std::shared_ptr<const Model> model_;
};

}  // namespace dvm
