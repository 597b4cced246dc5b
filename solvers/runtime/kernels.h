// The kernels behind make_run: templates instantiated in the kernels_*.cc translation
// units, never in a caller.
//
// A kernel is StepperRun<View, Stepper>: a system view (what is monitored, written
// and reported for a system: energy, invariants, columns, stored coordinates) and a
// step type of solvers/ (any form, any space). execute() is one call of integrate()
// (solvers/integrate.h: one loop for R^n and manifolds) with an observer that is a
// template parameter, so the loop has no runtime dispatch. Views whose steps each solve
// an equation (run-time-sized systems, manifolds, the forms compiled once per size)
// hold the step behind one virtual call (AnyRnStep, AnyPointStep), so that the loop is
// compiled once per view, not once per step type. The factory functions
// (make_rn_run, make_manifold_run, ...) read the method once and pick the step type:
//
//   form / method     R^n (fixed size)                    S^2, (S^2)^n, SO(3)
//   lagrangian        PositionMomentumStep<S, Map>        ManifoldStep<S, Map>
//     explicit Euler maps on a separable S (Method::use_structure):
//                     ExplicitSplittingStep<S>, composition included (kicks and drifts)
//     other theta maps on a separable S of fixed size >= 3 (Method::use_structure):
//                     SeparableThetaStep<S> (Newton, Jacobian from the gradient)
//   hamiltonian       HamiltonianStep<LegendreH<S>, Map>  ManifoldHamiltonianStep<H, Map>
//   sode1 / sode2     SodeStep<S, tangent lift of Map>    (refused)
//   newmark           NewmarkStep<S>                      (refused)
//   galerkin          GalerkinStep<S>                     ManifoldGalerkinStep<S> (s at run time)
//     Gauss quadrature on a separable S (Method::use_structure):
//                     SeparableGaussStep<S> (collocation, fixed point on the stage forces)
//   composition       ComposedStep<Step> of any of these, adjoint stages from the
//                     adjoint map (theta -> 1 - theta, Prop. 2.4) or Newmark's adjoint
//   boundary value    BoundaryValueProblem<S, Map>        SphereBoundaryValueProblem
// (Systems of run-time size on R^n: kernels_dynamic.h.)
//
// On R^n, S is the system's own type only for the theta maps solved by Newton's method,
// the splitting and Gauss collocation; every other row runs with S = ErasedLagrangian<N>,
// compiled once per size (kernels_rn.h, kernels_rn_sized.h).
//
// Maps are resolved from their registry entry into a value of the space's map type(s):
// on R^n std::variant<ThetaMap, WrittenMap>, visited once (retraction-theta is the
// written retraction x + v: the generic path, one type with the scene's written maps).
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include "mechanics/hamiltonian.h"
#include "mechanics/lagrangian.h"
#include "solvers/boundary_value.h"
#include "solvers/collocation_step.h"
#include "solvers/composition.h"
#include "solvers/integrate.h"
#include "solvers/runtime/run.h"
#include "solvers/separable_theta_step.h"
#include "solvers/splitting_step.h"

namespace dvm::kernels {

// ---- maps from registry entries ------------------------------------------------------
using RnMap = std::variant<ThetaMap, WrittenMap>;

inline RnMap rn_map(const Method& m) {
  const MapEntry& e = *m.map;
  switch (e.family) {
    case MapFamily::theta:
      return ThetaMap(m.theta, e.name);
    case MapFamily::retraction_theta:  // Prop. 2.3 from R_x(v) = x + v, by the generic path
      return WrittenMap::flat_retraction("retraction-theta(euclidean)", m.theta);
    case MapFamily::written:
      if (!m.written_map) break;
      return *m.written_map;
    case MapFamily::sphere:
    case MapFamily::rotation:
      break;
  }
  throw InputError("integrator.map: map \"" + e.name + "\" does not live on R^n");
}

// The theta of the method's map as a ThetaMap for the run-time-sized steps (kernels_dynamic.h,
// make_run_time_sized_run): retraction-theta with the flat retraction x + v is the same map,
// inverted in closed form there.
inline ThetaMap dynamic_theta_map(const Method& me) {
  const MapEntry& e = *me.map;
  switch (e.family) {
    case MapFamily::theta:
    case MapFamily::retraction_theta:
      return ThetaMap(me.theta, e.name);
    case MapFamily::written:
      // (validate refuses it first: SystemCapabilities::written_maps, and --linearize)
      throw InputError("integrator.map: the run-time-sized steps take the theta-family maps; map = \"written\" runs "
                       "on the built-in systems of fixed size");
    case MapFamily::sphere:
    case MapFamily::rotation:
      break;
  }
  throw InputError("integrator.map: map \"" + e.name + "\" does not live on R^n");
}

// The adjoint of a theta-family map is the same family at 1 - theta (Prop. 2.4), so the
// adjoint stages of a composition reuse the basic method's step type.
inline ThetaMap same_type_adjoint(const ThetaMap& R) { return R.adjoint(); }
inline WrittenMap same_type_adjoint(const WrittenMap& R) { return R.adjoint(); }

// ---- the loop around any stepper -----------------------------------------------------
// A system view V provides
//   using Point, Covector;                    the stepper's state types
//   std::vector<std::string> columns() const; the CSV columns
//   int row_size() const;
//   void fill_row(double* row, double t, const Point&, const Covector&, double E) const;
//   double energy(const Point&, const Covector&) const;
//   int invariant_count() const; void invariants(const Point&, const Covector&, double*) const;
//   std::vector<InvariantReport> invariant_reports(const double* initial) const;
//   void finish_report(RunReport&, const Point&, const Covector&) const;  stored forms
//   double point_defect(const Point&) const;  (< 0: not a manifold)
constexpr int kMaxInvariantValues = 8;

// A step that may hand some steps to a Newton iteration reports how many
// (SeparableGaussStep::newton_steps).
template <class S, class = void>
struct has_newton_steps : std::false_type {};
template <class S>
struct has_newton_steps<S, std::void_t<decltype(std::declval<const S&>().newton_steps())>> : std::true_type {};

// A step that gives its derivative at a solved increment,
// derivative(t0, q0, p0, dq, A) (DynamicThetaStep, ConstrainedThetaStep).
template <class S, class = void>
struct has_step_derivative : std::false_type {};
template <class S>
struct has_step_derivative<S, std::void_t<decltype(std::declval<const S&>().derivative(
                                  0.0, std::declval<const Eigen::VectorXd&>(), std::declval<const Eigen::VectorXd&>(),
                                  std::declval<const Eigen::VectorXd&>(), std::declval<Eigen::MatrixXd&>()))>>
    : std::true_type {};

// A manifold step that gives its derivative in canonical coordinates at its solution,
// derivatives(t0, q0, p0, q1, A, B*) (ManifoldStep, ComposedPointStep of it;
// solvers/manifold_step.h), and the controls it reads, controls().
template <class S, class = void>
struct has_manifold_derivative : std::false_type {};
template <class S>
struct has_manifold_derivative<
    S, std::void_t<decltype(std::declval<const S&>().derivatives(
                       0.0, std::declval<const typename S::Point&>(), std::declval<const typename S::Covector&>(),
                       std::declval<const typename S::Point&>(), std::declval<Eigen::MatrixXd&>(), nullptr)),
                   decltype(std::declval<const S&>().controls())>> : std::true_type {};
template <class S>
constexpr bool gives_step_derivative_v = has_step_derivative<S>::value || has_manifold_derivative<S>::value;

// A step whose derivative is known at run time only (AnyRnStep: bool gives_derivative()).
template <class S, class = void>
struct has_derivative_flag : std::false_type {};
template <class S>
struct has_derivative_flag<S, std::void_t<decltype(bool(std::declval<const S&>().gives_derivative()))>>
    : std::true_type {};

// The rows of OutputSpec::linearize: after step k -> k + 1, t_k and the step's Jacobian
// A_k, row by row: on R^n from the step's derivative at (q_k, p_k, q_{k+1} - q_k), on S^2
// and SO(3) from its derivative in the canonical coordinates around q_k and q_{k+1}
// (2 dim columns each). Steps without a derivative refuse the file (validate refuses the
// run first: Method::linearize).
template <class Stepper, bool = gives_step_derivative_v<Stepper>>
class StepDerivatives {
 public:
  template <class Point, class Covector>
  StepDerivatives(const Recorder* rec, const Stepper&, const Point&, const Covector&, std::int64_t) {
    if (rec && !rec->spec().linearize.empty())
      throw InputError(rec->spec().linearize_source + ": this run's step gives no derivative");
  }
  template <class Point, class Covector>
  void record(std::int64_t, double, const Point&, const Covector&) {}
  bool finish(bool, std::string&, std::vector<std::string>&) { return true; }
};
// A step that gives its derivative in the force's control inputs too,
// control_derivative(t0, q0, p0, dq, B), and how many there are, controls().
template <class S, class = void>
struct has_control_derivative : std::false_type {};
template <class S>
struct has_control_derivative<S, std::void_t<decltype(std::declval<const S&>().control_derivative(
                                     0.0, std::declval<const Eigen::VectorXd&>(), std::declval<const Eigen::VectorXd&>(),
                                     std::declval<const Eigen::VectorXd&>(), std::declval<Eigen::MatrixXd&>())),
                                 decltype(std::declval<const S&>().controls())>> : std::true_type {};

// The state the derivatives are taken at: run-time-sized vectors on R^n, the step's own
// point and covector types on a manifold.
template <class Stepper, bool = has_manifold_derivative<Stepper>::value>
struct DerivativeState {
  using Point = Eigen::VectorXd;
  using Covector = Eigen::VectorXd;
  static int dim(const Point& q) { return static_cast<int>(q.size()); }
};
template <class Stepper>
struct DerivativeState<Stepper, true> {
  using Point = typename Stepper::Point;
  using Covector = typename Stepper::Covector;
  static int dim(const Point&) { return Stepper::n; }
};

template <class Stepper>
class StepDerivatives<Stepper, true> {
  static constexpr bool kManifold = has_manifold_derivative<Stepper>::value;
  using Point = typename DerivativeState<Stepper>::Point;
  using Covector = typename DerivativeState<Stepper>::Covector;

 public:
  StepDerivatives(const Recorder* rec, const Stepper& stepper, const Point& q0, const Covector& p0, std::int64_t steps)
      : stepper_(&stepper), q_(q0), p_(p0) {
    if (!rec || rec->spec().linearize.empty()) return;
    if constexpr (has_derivative_flag<Stepper>::value)
      if (!stepper.gives_derivative())
        throw InputError(rec->spec().linearize_source + ": this run's step gives no derivative");
    OutputSpec spec;
    spec.npy = rec->spec().linearize;
    spec.npy_source = rec->spec().linearize_source;
    spec.inputs = rec->spec().inputs;
    out_ = std::make_unique<Recorder>(spec);
    m_ = 2 * DerivativeState<Stepper>::dim(q0);
    std::vector<std::string> columns{"t"};
    for (int i = 0; i < m_; ++i)
      for (int j = 0; j < m_; ++j) columns.push_back("A[" + std::to_string(i) + "," + std::to_string(j) + "]");
    // with control inputs, B_k = d(q_{k+1}, p_{k+1})/du_k after A_k, row by row
    if constexpr (kManifold || has_control_derivative<Stepper>::value) controls_ = stepper.controls();
    for (int i = 0; i < m_; ++i)
      for (int j = 0; j < controls_; ++j) columns.push_back("B[" + std::to_string(i) + "," + std::to_string(j) + "]");
    out_->open(columns, static_cast<double>(steps));
    row_.resize(columns.size());
  }
  // After step k - 1 -> k, which started at t: its derivative, at the state before it.
  void record(std::int64_t, double t, const Point& qk, const Covector& pk) {
    if (!out_) return;
    row_[0] = t;
    // with control inputs, A and B from one differentiation where the step gives them
    // so; where that fails, each alone (A may exist where B does not)
    int got = 0;  // 1: A, 2: A and B
    if constexpr (kManifold) {
      if (controls_ > 0 && stepper_->derivatives(t, q_, p_, qk, A_, &B_)) got = 2;
      if (got == 0 && stepper_->derivatives(t, q_, p_, qk, A_, nullptr)) got = 1;
    } else {
      const Eigen::VectorXd dq = Eigen::VectorXd(qk) - q_;
      if constexpr (composition_detail::has_joint_derivatives<Stepper>::value)
        if (controls_ > 0 && stepper_->derivatives(t, q_, p_, dq, A_, &B_)) got = 2;
      if (got == 0 && stepper_->derivative(t, q_, p_, dq, A_)) {
        got = 1;
        if constexpr (has_control_derivative<Stepper>::value)
          if (controls_ > 0 && stepper_->control_derivative(t, q_, p_, dq, B_)) got = 2;
      }
    }
    const Eigen::Index m = m_;
    const std::size_t at = static_cast<std::size_t>(1 + m * m);
    if (got == 0) std::fill(row_.begin() + 1, row_.end(), NAN);  // singular at the solution
    if (got >= 1)
      for (Eigen::Index i = 0; i < m; ++i)
        for (Eigen::Index j = 0; j < m; ++j) row_[static_cast<std::size_t>(1 + i * m + j)] = A_(i, j);
    if (got == 1) std::fill(row_.begin() + static_cast<std::ptrdiff_t>(at), row_.end(), NAN);
    if (got == 2)
      for (Eigen::Index i = 0; i < m; ++i)
        for (int j = 0; j < controls_; ++j) row_[at + static_cast<std::size_t>(i * controls_ + j)] = B_(i, j);
    out_->row(row_.data());
    q_ = qk;
    p_ = pk;
  }
  bool finish(bool complete, std::string& kept, std::vector<std::string>& written) {
    if (!out_) return true;
    std::string k;
    const bool ok = out_->finish(complete, k);
    if (!k.empty()) kept += (kept.empty() ? "" : ", ") + k;
    if (ok && complete) written.push_back(out_->spec().npy);
    return ok;
  }

 private:
  const Stepper* stepper_;
  Point q_;  // the state the next step starts from
  Covector p_;
  Eigen::MatrixXd A_, B_;
  int m_ = 0, controls_ = 0;
  std::vector<double> row_;
  std::unique_ptr<Recorder> out_;
};

// ---- steps behind one virtual call ----------------------------------------------------
// A step on R^n of Size coordinates (Eigen::Dynamic: run-time size) with its type
// erased. The views that declare `static constexpr bool erase_steps = true` (those of the
// systems of run-time size and of the kernels compiled once per size, whose steps solve
// an implicit equation each step) run every such step through one StepperRun, so that
// the run loop, the recorder's calls and the monitors are compiled once per view rather
// than once per step type (stepper_run below). The indirect call is paid once a step.
// Steps that take no starting guess (the explicit splitting) or count Newton steps of
// their own are run as they are. The derivative of the step, and in its controls, are
// forwarded where the step gives them and the run is linearizable (Lin); elsewhere
// gives_derivative() is false and StepDerivatives refuses --linearize. Move-only: a step
// may keep state across steps (its last increment, a kept Jacobian).
template <class S>
constexpr bool erasable_step_v =
    (is_point_stepper<S>::value || takes_guess<S>::value) && !has_newton_steps<S>::value;

template <int Size>
class AnyRnStep {
 public:
  static constexpr int N = Size;
  using V = Vec<double, N>;
  using M = Eigen::MatrixXd;

  template <bool Lin, class Step>
  static AnyRnStep of(Step s) {
    return AnyRnStep(std::make_unique<Model<Step, Lin>>(std::move(s)));
  }
  double step_size() const { return h_; }
  StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const { return impl_->step(t, q0, p0, dq, dp); }
  bool gives_derivative() const { return impl_->gives_derivative(); }
  int controls() const { return impl_->controls(); }
  bool derivative(double t, const V& q0, const V& p0, const V& dq, M& A) const {
    return impl_->derivatives(t, q0, p0, dq, A, nullptr);
  }
  bool control_derivative(double t, const V& q0, const V& p0, const V& dq, M& B) const {
    return impl_->control_derivative(t, q0, p0, dq, B);
  }
  bool derivatives(double t, const V& q0, const V& p0, const V& dq, M& A, M* B) const {
    return impl_->derivatives(t, q0, p0, dq, A, B);
  }

 private:
  struct Base {
    virtual ~Base() = default;
    virtual double step_size() const = 0;
    virtual StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const = 0;
    virtual bool gives_derivative() const = 0;
    virtual int controls() const = 0;
    // A, and B where B is not null (false: not given, or singular at the solution)
    virtual bool derivatives(double t, const V& q0, const V& p0, const V& dq, M& A, M* B) const = 0;
    virtual bool control_derivative(double t, const V& q0, const V& p0, const V& dq, M& B) const = 0;
  };
  template <class Step, bool Lin>
  struct Model final : Base {
    static_assert(!is_point_stepper<Step>::value && Step::N == Size && erasable_step_v<Step>,
                  "AnyRnStep<N> holds a step on R^n of N coordinates");
    static constexpr bool kDerivative = Lin && has_step_derivative<Step>::value;
    static constexpr bool kControls = Lin && has_control_derivative<Step>::value;
    explicit Model(Step step) : s(std::move(step)) {}
    double step_size() const override { return s.step_size(); }
    StepSummary step(double t, const V& q0, const V& p0, V& dq, V& dp) const override {
      return s.step(t, q0, p0, dq, dp);
    }
    bool gives_derivative() const override { return kDerivative; }
    int controls() const override {
      if constexpr (kControls)
        return s.controls();
      else
        return 0;
    }
    bool derivatives(double t, const V& q0, const V& p0, const V& dq, M& A, M* B) const override {
      if constexpr (kDerivative) {
        if constexpr (Lin && composition_detail::has_joint_derivatives<Step>::value)
          if (B) return s.derivatives(t, q0, p0, dq, A, B);
        if (!s.derivative(t, q0, p0, dq, A)) return false;
        return !B || control_derivative(t, q0, p0, dq, *B);
      } else {
        return false;
      }
    }
    bool control_derivative(double t, const V& q0, const V& p0, const V& dq, M& B) const override {
      if constexpr (kControls)
        return s.control_derivative(t, q0, p0, dq, B);
      else
        return false;
    }
    Step s;
  };
  explicit AnyRnStep(std::unique_ptr<Base> impl) : impl_(std::move(impl)), h_(impl_->step_size()) {}
  std::unique_ptr<Base> impl_;
  double h_;
};

// A step on a manifold (M, n, Point, Covector: solvers/integrate.h) with its type erased,
// as AnyRnStep is on R^n: the derivative in canonical coordinates, and in the controls,
// forwarded where the step gives it and the run is linearizable.
template <class Mf, int Dim, class P, class C>
class AnyPointStep {
 public:
  using M = Mf;
  static constexpr int n = Dim;
  using Point = P;
  using Covector = C;
  using Xi = Vec<double, n>;

  template <bool Lin, class Step>
  static AnyPointStep of(Step s) {
    return AnyPointStep(std::make_unique<Model<Step, Lin>>(std::move(s)));
  }
  double step_size() const { return h_; }
  StepSummary step(double t, const Point& q0, const Covector& p0, Xi& xi, Point& q1, Covector& p1) const {
    return impl_->step(t, q0, p0, xi, q1, p1);
  }
  bool gives_derivative() const { return impl_->gives_derivative(); }
  int controls() const { return impl_->controls(); }
  bool derivatives(double t, const Point& q0, const Covector& p0, const Point& q1, Eigen::MatrixXd& A,
                   Eigen::MatrixXd* B) const {
    return impl_->derivatives(t, q0, p0, q1, A, B);
  }

 private:
  struct Base {
    virtual ~Base() = default;
    virtual double step_size() const = 0;
    virtual StepSummary step(double t, const Point& q0, const Covector& p0, Xi& xi, Point& q1, Covector& p1) const = 0;
    virtual bool gives_derivative() const = 0;
    virtual int controls() const = 0;
    virtual bool derivatives(double t, const Point& q0, const Covector& p0, const Point& q1, Eigen::MatrixXd& A,
                             Eigen::MatrixXd* B) const = 0;
  };
  template <class Step, bool Lin>
  struct Model final : Base {
    static_assert(std::is_same_v<typename Step::M, M> && Step::n == n && std::is_same_v<typename Step::Point, Point> &&
                      std::is_same_v<typename Step::Covector, Covector> && erasable_step_v<Step>,
                  "AnyPointStep holds a step on its manifold");
    static constexpr bool kDerivative = Lin && has_manifold_derivative<Step>::value;
    explicit Model(Step step) : s(std::move(step)) {}
    double step_size() const override { return s.step_size(); }
    StepSummary step(double t, const Point& q0, const Covector& p0, Xi& xi, Point& q1, Covector& p1) const override {
      return s.step(t, q0, p0, xi, q1, p1);
    }
    bool gives_derivative() const override { return kDerivative; }
    int controls() const override {
      if constexpr (kDerivative)
        return s.controls();
      else
        return 0;
    }
    bool derivatives(double t, const Point& q0, const Covector& p0, const Point& q1, Eigen::MatrixXd& A,
                     Eigen::MatrixXd* B) const override {
      if constexpr (kDerivative)
        return s.derivatives(t, q0, p0, q1, A, B);
      else
        return false;
    }
    Step s;
  };
  explicit AnyPointStep(std::unique_ptr<Base> impl) : impl_(std::move(impl)), h_(impl_->step_size()) {}
  std::unique_ptr<Base> impl_;
  double h_;
};

// The erased type of a step: AnyRnStep<N> on R^n, AnyPointStep on a manifold.
template <class S, bool = is_point_stepper<S>::value>
struct AnyStepOf {
  using type = AnyRnStep<S::N>;
};
template <class S>
struct AnyStepOf<S, true> {
  using type = AnyPointStep<typename S::M, S::n, typename S::Point, typename S::Covector>;
};

// Whether a view runs its steps erased (AnyRnStep, AnyPointStep).
template <class View, class = void>
struct view_erases_steps : std::false_type {};
template <class View>
struct view_erases_steps<View, std::void_t<decltype(View::erase_steps)>> : std::bool_constant<View::erase_steps> {};

// Whether a view follows the steps (void after_step(k, t_k) const, after step k - 1 -> k
// and with k = 0 before the first: the run-time-sized systems, whose tabulated controls
// hold u_k over step k and whose L(t, q, v) is monitored at t_k).
template <class View, class = void>
struct has_after_step : std::false_type {};
template <class View>
struct has_after_step<View, std::void_t<decltype(std::declval<const View&>().after_step(std::int64_t{0}, 0.0))>>
    : std::true_type {};

// Whether a view reports constraint residuals (bool constraint_residuals(t, q, p, g,
// hidden) const: the run-time-sized systems, true where they have constraints).
template <class View, class = void>
struct has_constraint_residuals : std::false_type {};
template <class View>
struct has_constraint_residuals<
    View, std::void_t<decltype(std::declval<const View&>().constraint_residuals(
              0.0, std::declval<const typename View::Point&>(), std::declval<const typename View::Covector&>(),
              std::declval<double&>(), std::declval<double&>()))>> : std::true_type {};

// Linearizable: the run records its step's derivative where the output asks for it
// (--linearize), and the step's derivative code is compiled with the run; false for the
// runs validate() keeps --linearize from (their steps' derivatives would be compiled for
// nothing), which refuse the file if it reaches them.
template <class View, class Stepper, bool Linearizable = false>
class StepperRun final : public Run {
 public:
  using Point = typename View::Point;
  using Covector = typename View::Covector;

  StepperRun(View view, Stepper stepper, Point q0, Covector p0, Covector v0, RunReport base, std::int64_t steps)
      : view_(std::move(view)),
        stepper_(std::move(stepper)),
        q0_(std::move(q0)),
        p0_(std::move(p0)),
        v0_(std::move(v0)),
        base_(std::move(base)),
        steps_(steps) {
    E0_ = view_.energy(q0_, p0_);
  }

  double initial_energy() const override { return E0_; }
  bool exact(double t, std::vector<double>& q, std::vector<double>& p) const override {
    return view_.exact(t, q0_, p0_, q, p);
  }

  RunReport execute(Recorder* rec) override {
    RunReport r = base_;
    const double h = stepper_.step_size();
    // with forces, a last column: the work W_k done by them since t = 0
    const bool forced = r.forced;
    const std::size_t row_size = static_cast<std::size_t>(view_.row_size());
    std::vector<double> row_values(row_size + (forced ? 1 : 0));
    if (rec) {
      std::vector<std::string> columns = view_.columns();
      if (forced) columns.push_back("work");
      rec->open(columns, output_rows(steps_, rec->every()));
      view_.fill_row(row_values.data(), 0.0, q0_, p0_, E0_);
      if (forced) row_values[row_size] = 0.0;
      rec->row(row_values.data());
    }
    StepDerivatives<Stepper, Linearizable && gives_step_derivative_v<Stepper>> derivatives(rec, stepper_, q0_, p0_,
                                                                                           steps_);
    if constexpr (has_after_step<View>::value) view_.after_step(0, 0.0);
    const int n_inv = view_.invariant_count();
    double I0[kMaxInvariantValues] = {}, Ik[kMaxInvariantValues] = {}, Ierr[kMaxInvariantValues] = {};
    view_.invariants(q0_, p0_, I0);
    double max_energy_error = 0.0, E = E0_, defect = view_.point_defect(q0_);
    double W = 0.0, W_c = 0.0, max_balance = 0.0;  // the work (compensated sum) and |E - E0 - W|
    Point q = q0_;
    Covector p = p0_;
    const std::int64_t monitor_every = rec ? std::max<std::int64_t>(1, rec->spec().monitor_every) : 1;
    std::int64_t monitored = 0;  // the last step whose energy and invariants were evaluated
    double max_g = 0.0, max_hidden = 0.0;  // the constraint residuals (system.constraints)
    auto monitor = [&](std::int64_t k, const Point& qk, const Covector& pk) {
      if constexpr (has_constraint_residuals<View>::value) {
        double g, hidden;
        if (view_.constraint_residuals(static_cast<double>(k) * h, qk, pk, g, hidden)) {
          max_g = std::fmax(max_g, g);
          max_hidden = std::fmax(max_hidden, hidden);
        }
      }
      E = view_.energy(qk, pk);
      max_energy_error = std::fmax(max_energy_error, std::fabs(E - E0_));
      if (forced) max_balance = std::fmax(max_balance, std::fabs((E - E0_) - W));
      if (n_inv > 0) {
        view_.invariants(qk, pk, Ik);
        for (int i = 0; i < n_inv; ++i) Ierr[i] = std::fmax(Ierr[i], std::fabs(Ik[i] - I0[i]));
      }
      if (defect >= 0.0) defect = std::fmax(defect, view_.point_defect(qk));
      monitored = k;
    };
    const auto start = std::chrono::steady_clock::now();
    // the next step that writes a row and the next one monitored (rec->wants and
    // k % monitor_every, counted instead of divided: two integer divisions a step are
    // visible in the cost of a short step; bench_galerkin_kepler times one)
    const bool rows = rec && rec->writes_rows();
    const std::int64_t every = rec ? std::max<std::int64_t>(1, rec->every()) : 1;
    std::int64_t next_row = rows ? every : -1, next_monitor = monitor_every;
    auto observer = [&](std::int64_t k, double t, const Point& qk, const Covector& pk, const StepSummary& s) {
      derivatives.record(k, static_cast<double>(k - 1) * h, qk, pk);
      if constexpr (has_after_step<View>::value) view_.after_step(k, t);  // (the next step is k -> k + 1)
      if (forced) {  // (Kahan-Babuska, as the state's sums)
        const double y = s.work - W_c, sum = W + y;
        W_c = (sum - W) - y;
        W = sum;
      }
      const bool row = rows && (k == next_row || k == steps_);
      if (row && k == next_row) next_row += every;
      const bool due = k == next_monitor;
      if (due) next_monitor += monitor_every;
      if (row || due || k == steps_) monitor(k, qk, pk);
      if (rec) {
        if (row) {
          view_.fill_row(row_values.data(), t, qk, pk, E);
          if (forced) row_values[row_size] = W;
          rec->row(row_values.data());
        }
        rec->progress(k, steps_, h);
      }
    };
    r.loop = integrate(stepper_, 0.0, q, p, v0_, steps_, observer);
    if constexpr (has_newton_steps<Stepper>::value) r.newton_steps = stepper_.newton_steps();
    if (monitored != r.loop.steps_done) {
      // a failed run stopped between monitored steps: its last state, where it can be evaluated
      try {
        monitor(r.loop.steps_done, q, p);
      } catch (const std::domain_error&) {
      }
    }
    r.monitor_every = monitor_every;
    r.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    r.failed = r.loop.failed;
    r.steps = r.loop.steps_done;
    r.t_final = static_cast<double>(r.loop.steps_done) * h;
    r.energy_initial = E0_;
    r.energy_final = E;
    r.max_abs_energy_error = max_energy_error;
    r.work = W;
    r.max_abs_energy_balance = max_balance;
    r.max_constraint_residual = max_g;
    r.max_hidden_constraint_residual = max_hidden;
    r.solver_iterations = r.loop.solver_iterations;
    r.jacobians = r.loop.jacobians;
    r.max_step_iterations = r.loop.max_step_iterations;
    r.max_point_defect = defect;
    {
      RunReport first;
      view_.finish_report(first, q0_, p0_);
      r.q_initial = std::move(first.q_final);
      r.p_initial = std::move(first.p_final);
    }
    r.invariants = view_.invariant_reports(I0);
    {
      int k = 0;
      for (InvariantReport& inv : r.invariants)
        for (std::size_t c = 0; c < inv.initial.size(); ++c, ++k) inv.max_abs_error = std::fmax(inv.max_abs_error, Ierr[k]);
    }
    view_.finish_report(r, q, p);
    if (r.failed && r.loop.failure.iterations > 0 && std::isfinite(r.loop.failure.residual))
      view_.diagnose(r.loop.failure.message, q, p);
    if (rec) {
      if (!rec->finish(!r.failed, r.kept)) r.output_error = true;
      if (!r.failed && !r.output_error) {
        if (!rec->spec().csv.empty()) r.written.push_back(rec->spec().csv);
        if (!rec->spec().npy.empty()) r.written.push_back(rec->spec().npy);
      }
      if (!derivatives.finish(!r.failed && !r.output_error, r.kept, r.written)) r.output_error = true;
    }
    return r;
  }

 private:
  View view_;
  Stepper stepper_;
  Point q0_;
  Covector p0_, v0_;
  RunReport base_;
  std::int64_t steps_;
  double E0_ = 0.0;
};

// stepper_run<true>: a run that --linearize may reach (StepperRun's Linearizable).
// The views that erase their steps (view_erases_steps) run them as AnyRnStep or
// AnyPointStep.
template <bool Linearizable = false, class View, class Stepper>
std::unique_ptr<Run> stepper_run(const View& view, Stepper stepper, const typename View::Point& q0,
                                 const typename View::Covector& p0, const typename View::Covector& v0,
                                 const RunReport& base, std::int64_t steps) {
  if constexpr (view_erases_steps<View>::value && erasable_step_v<Stepper>) {
    using Any = typename AnyStepOf<Stepper>::type;
    return std::make_unique<StepperRun<View, Any, Linearizable>>(view, Any::template of<Linearizable>(std::move(stepper)),
                                                                  q0, p0, v0, base, steps);
  } else {
    return std::make_unique<StepperRun<View, Stepper, Linearizable>>(view, std::move(stepper), q0, p0, v0, base,
                                                                      steps);
  }
}

// ---- compositions: the map of each stage --------------------------------------------
// The substeps of the method's composition ({{1, false}} for none). A splitting into
// kicks and drifts (validate() admits it with the explicit Euler maps only) is the same
// method from either map: from the adjoint Euler map (theta 1) its substeps are flipped.
inline std::vector<Substep> method_substeps(const Method& me, bool map_symmetric) {
  if (me.composition == "none") return single_substep();
  const CompositionScheme s = me.scheme();
  if (s.kind == CompositionKind::rkn_splitting && me.theta == 1.0) return adjoint_substeps(substeps(s, map_symmetric));
  return substeps(s, map_symmetric);
}

// A stage of a composition: its fraction of the step and the map (or other basic step
// description) it takes.
template <class Map>
struct Stage {
  double weight;
  Map map;
};

// The stages of the method's composition: the substeps of its scheme, each with the map
// R or its adjoint (adjoint(R), the map at 1 - theta for the theta families, Prop. 2.4);
// with integrator.thetas (composition "dirk") stage i is at_theta(theta_i) of weight b_i,
// the partitioned pair of solvers/partitioned_dirk.h. `symmetric`: R is its own adjoint.
template <class Map, class Adjoint, class AtTheta>
std::vector<Stage<Map>> composition_stages(const Method& me, const Map& R, bool symmetric, const Adjoint& adjoint,
                                           const AtTheta& at_theta) {
  std::vector<Stage<Map>> out;
  if (!me.thetas.empty()) {
    for (std::size_t i = 0; i < me.thetas.size(); ++i) out.push_back({me.weights.at(i), at_theta(me.thetas[i])});
    return out;
  }
  for (const Substep& s : method_substeps(me, symmetric)) out.push_back({s.weight, s.adjoint ? adjoint(R) : R});
  return out;
}

// The composed step of the stages (Composed: ComposedStep<Step> on R^n,
// ComposedPointStep<Step> on manifolds), make(hk, map) building the step of size hk.
template <class Composed, class Map, class Make>
Composed compose_stages(double h, const std::vector<Stage<Map>>& stages, const Make& make) {
  std::vector<Substep> subs;
  for (const Stage<Map>& s : stages) subs.push_back({s.weight, false});
  std::size_t k = 0;  // the composed types build their stages in order
  auto next = [&](double hk) { return make(hk, stages.at(k++).map); };
  return Composed(h, subs, next, next);
}

// The basic method's run (composition "none"), or its composition's; composable_run<true>:
// runs that --linearize may reach (StepperRun's Linearizable).
template <bool Linearizable = false, class View, class Map, class Make>
std::unique_ptr<Run> composable_run(const View& view, const Method& me, double h, const std::vector<Stage<Map>>& stages,
                                    const Make& make, const typename View::Point& q0,
                                    const typename View::Covector& p0, const typename View::Covector& v0,
                                    const RunReport& base, std::int64_t steps) {
  if (me.composition == "none")
    return stepper_run<Linearizable>(view, make(h, stages.front().map), q0, p0, v0, base, steps);
  using Step = decltype(make(h, stages.front().map));
  return stepper_run<Linearizable>(view, compose_stages<ComposedStep<Step>>(h, stages, make), q0, p0, v0, base, steps);
}

// The stages of a theta-family map on R^n (ThetaMap, WrittenMap).
inline ThetaMap at_theta(const ThetaMap& R, double th) { return ThetaMap(th, R.name()); }
inline WrittenMap at_theta(const WrittenMap& R, double th) { return R.at_theta(th); }
template <class Map>
std::vector<Stage<Map>> rn_stages(const Method& me, const Map& R) {
  return composition_stages(
      me, R, R.symmetric(), [](const Map& m) { return same_type_adjoint(m); },
      [&](double th) { return at_theta(R, th); });
}

// The structure of S into the report: its declaration, checked at points around the
// initial state (a declaration the Lagrangian does not satisfy is refused), or, for a
// system that declares none, the class read off the Lagrangian at those points.
template <class S, class V>
void report_structure(RunReport& r, const S& L, const V& q, const V& v0, const Problem& pr) {
  if constexpr (has_declared_structure<S>::value) {
    try {
      check_structure(L, q, v0);
    } catch (const StructureError& e) {
      throw InputError(pr.origin + ": system: " + e.what());
    }
    r.structure = structure_name(declared_structure<S>::value);
    r.structure_source = "declared";
  } else {
    Structure s = Structure::general;
    try {
      s = sampled_structure(L, q, v0);
    } catch (const std::exception&) {
      // a sample outside the Lagrangian's domain: nothing read off, "general"
    }
    r.structure = structure_name(s);
    r.structure_source = "sampled";
  }
  r.step_path = StepPath::generic;
}

// A splitting into kicks and drifts (CompositionKind::rkn_splitting) has its order on a
// separable system only: refused, naming the key, on a system whose structure (as
// reported) is another.
inline void require_splitting_structure(const RunReport& r, const Method& me, const Problem& pr) {
  if (me.composition == "none" || me.composition == "dirk" || me.scheme().kind != CompositionKind::rkn_splitting) return;
  if (r.structure != "separable")
    throw InputError(pr.origin + ": key 'integrator.composition': \"" + me.composition +
                     "\" is a splitting for separable systems (L = v^T M v / 2 - V(q), M constant): its order "
                     "conditions need T quadratic in p; this system's structure is \"" + r.structure + "\" (" +
                     r.structure_source + ")");
}

// Whether the method is an explicit Euler map (theta 0 or 1, composed or not) that a
// separable system steps by kicks and drifts (Method::use_structure).
inline bool splitting_applies(const Method& me, const ThetaMap& R) {
  return me.use_structure && me.solver == SolverKind::newton && me.thetas.empty() &&
         (R.theta() == 0.0 || R.theta() == 1.0);
}

// An explicit Euler map (theta 0 or 1), alone or composed, on a separable system: kicks
// and drifts, no solve (Map is ThetaMap; a template parameter so that a call inside a
// generic lambda names this only for separable systems).
template <class View, class S, class Map>
std::unique_ptr<Run> splitting_run(const View& view, const S& L, const Map& R, const Method& me, double h,
                                   const typename View::Point& q, const typename View::Covector& p,
                                   const typename View::Covector& v0, RunReport base, std::int64_t steps) {
  base.step_path = StepPath::explicit_splitting;
  return stepper_run(view, ExplicitSplittingStep<S>(L, R.theta(), h, method_substeps(me, R.symmetric()), q), q, p, v0,
                     base, steps);
}

// Whether a theta map (any theta, composed or not) on a separable system of fixed size
// steps by Newton's method on the structured equation (solvers/separable_theta_step.h):
// Method::use_structure with Newton's method (solver = "tiny" keeps the generic path).
// The kernels take it from 3 coordinates on: with 2 (Kepler) its gain over the generic
// step is small, and instantiating it beside the explicit step made GCC's
// Stormer-Verlet there slower.
inline bool separable_newton_applies(const Method& me) {
  return me.use_structure && me.solver == SolverKind::newton;
}

// Whether a Galerkin method is Gauss collocation on the stage forces when the system is
// separable (solvers/collocation_step.h): Gauss quadrature, Method::use_structure.
inline bool collocation_applies(const Method& me) {
  return me.galerkin && me.use_structure && me.quadrature == QuadratureKind::gauss;
}

// Galerkin Gauss on a separable system: the stages iterated to a fixed point on their
// forces (Step: SeparableGaussStep<...>; a template parameter for the same reason as
// splitting_run's Map).
template <class View, class Step>
std::unique_ptr<Run> collocation_run(const View& view, Step step, const typename View::Point& q,
                                     const typename View::Covector& p, const typename View::Covector& v0,
                                     RunReport base, std::int64_t steps) {
  base.step_path = StepPath::gauss_collocation;
  return stepper_run(view, std::move(step), q, p, v0, base, steps);
}

// ---- boundary-value problems: one solve of every interior node -------------------------
// Solver is BoundaryValueProblem<S, Map> (R^n) or SphereBoundaryValueProblem<S, Map>
// (S^2): solve(qa, qb, K, options) -> nodes q_k, p_k. The nodes are written through the
// recorder as a run's rows (its room checked before the solve); the report gives the
// ends, the energy's spread, and on a manifold the distance from it and (spread = true)
// the spread of the vertical angular momentum J3 (the view's last invariant) along the
// solution. The recorder's poll hook is called as poll(iteration, max_iterations) after
// every iteration of the solve; an exception it throws stops the solve and leaves
// execute (the recorder's temporaries are removed, as an initial-value run's are).
template <class View, class Solver>
class BoundaryValueRun final : public Run {
 public:
  using Point = typename View::Point;
  BoundaryValueRun(View view, Solver solver, Point qa, Point qb, std::int64_t steps, double h, int max_iterations,
                   RunReport base, bool spread)
      : view_(std::move(view)),
        solver_(std::move(solver)),
        qa_(std::move(qa)),
        qb_(std::move(qb)),
        steps_(steps),
        h_(h),
        max_iterations_(max_iterations),
        base_(std::move(base)),
        spread_(spread) {}

  double initial_energy() const override { return 0.0; }
  bool exact(double, std::vector<double>&, std::vector<double>&) const override { return false; }

  RunReport execute(Recorder* rec) override {
    RunReport r = base_;
    if (rec) rec->open(view_.columns(), output_rows(steps_, rec->every()));
    BoundaryValueOptions bo;
    bo.max_iterations = max_iterations_;
    if (rec && rec->spec().poll)  // the recorder's hook, after every iteration of the solve
      bo.poll = [&](int iteration) { rec->spec().poll(iteration, max_iterations_); };
    const auto start = std::chrono::steady_clock::now();
    const auto res = solver_.solve(qa_, qb_, static_cast<int>(steps_), bo);
    r.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::vector<double> row(static_cast<std::size_t>(view_.row_size()));
    double emin = INFINITY, emax = -INFINITY, E0 = 0.0, EK = 0.0, jmin = INFINITY, jmax = -INFINITY;
    double defect = view_.point_defect(res.q.front());
    double inv[kMaxInvariantValues] = {};
    for (std::size_t k = 0; k <= static_cast<std::size_t>(steps_); ++k) {
      const double E = view_.energy(res.q[k], res.p[k]);
      if (k == 0) E0 = E;
      EK = E;
      emin = std::fmin(emin, E);
      emax = std::fmax(emax, E);
      if (spread_) {  // J3, the last of the view's invariants
        view_.invariants(res.q[k], res.p[k], inv);
        const double J = inv[std::max(0, view_.invariant_count() - 1)];
        jmin = std::fmin(jmin, J);
        jmax = std::fmax(jmax, J);
      }
      if (defect >= 0.0) defect = std::fmax(defect, view_.point_defect(res.q[k]));
      if (rec && rec->wants(static_cast<std::int64_t>(k), steps_)) {
        view_.fill_row(row.data(), static_cast<double>(k) * h_, res.q[k], res.p[k], E);
        rec->row(row.data());
      }
    }
    r.failed = !res.converged;
    r.steps = steps_;
    r.t_final = static_cast<double>(steps_) * h_;
    RunReport first;
    view_.finish_report(first, res.q.front(), res.p.front());
    r.q_initial = first.q_final;
    r.p_initial = first.p_final;
    view_.finish_report(r, res.q.back(), res.p.back());
    r.energy_initial = E0;
    r.energy_final = EK;
    r.max_abs_energy_error = std::fmax(emax - E0, E0 - emin);
    r.max_point_defect = defect;
    if (spread_) r.momentum_spread = jmax - jmin;
    r.max_del_residual = res.max_residual;
    r.residual_scale = res.scale;
    r.solver_iterations = r.jacobians = res.iterations;
    r.message = res.message;
    if (rec) {
      if (!rec->finish(res.converged, r.kept)) r.output_error = true;
      if (res.converged && !r.output_error) {
        if (!rec->spec().csv.empty()) r.written.push_back(rec->spec().csv);
        if (!rec->spec().npy.empty()) r.written.push_back(rec->spec().npy);
      }
    }
    return r;
  }

 private:
  View view_;
  Solver solver_;
  Point qa_, qb_;
  std::int64_t steps_;
  double h_;
  int max_iterations_;
  RunReport base_;
  bool spread_;
};

// The fields every report shares, from the problem and the method.
RunReport base_report(const Problem& pr, const Method& me, const std::string& system_name);

// The keys that give the initial state, for messages about it.
inline std::string initial_state_keys(const Problem& pr) {
  return std::string("initial.q and ") + (pr.momentum_given ? "initial.p" : "initial.v");
}

// The largest relative residual of the initial state the constrained runs accept
// (WrittenConstraints::relative_residuals on R^n, ManifoldConstraints::relative_residuals
// on S^2 and SO(3)), for the position and for the velocity.
constexpr double kConstraintStartTolerance = 1e-10;

// The checks of a constrained run's initial state that every space shares
// (kernels_sparse_constrained.cc), each throwing InputError that names the key:
//   require_constraint_rank       D (Dg's rows at t = 0, m x dim) of rank m by its singular
//                                 values (those above 1e-10 of the largest); `along` names
//                                 where D's columns are (" along S^2": in a chart), or "";
//   check_constraint_start_terms  per constraint i, g_i, |grad g_i| and grad g_i . v +
//                                 dg_i/dt: refuses a value or derivative that is not finite
//                                 and a position off a constraint (|g_i| / (|grad g_i| qn)
//                                 beyond kConstraintStartTolerance, naming position_key);
//                                 returns the first constraint whose velocity is off its
//                                 hidden constraint (relative to |grad g_i| vn), or -1;
//   refuse_velocity_off_constraint  that constraint's refusal, naming velocity_key and
//                                 initial.project_velocity.
void require_constraint_rank(const Problem& pr, const Eigen::MatrixXd& D, const std::string& along);
int check_constraint_start_terms(const Problem& pr, const Eigen::VectorXd& g, const Eigen::VectorXd& norms,
                                 const Eigen::VectorXd& across, double qn, double vn, const std::string& position_key);
[[noreturn]] void refuse_velocity_off_constraint(const Problem& pr, int i, double across, double vn, double norm,
                                                 const std::string& velocity_key);

// Refuses an initial state where the energy is not finite (an overflow, a division by
// zero in the system's expressions there).
[[noreturn]] inline void refuse_nonfinite_energy(const Problem& pr) {
  const std::string where = pr.written ? pr.written_where : pr.origin + ": system";
  throw InputError(where + ": the energy is not finite at the initial state (keys " + initial_state_keys(pr) +
                   "): an overflow or a division by zero there; expected a state where it is finite");
}

// The names of the velocities of a Lagrangian written on R^n, in the order of the
// state ("x_dot", "q_dot[3]"); empty for other systems (run.cc).
std::vector<std::string> velocity_names(const Problem& pr);

// "the Lagrangian is degenerate at the initial state" when the velocity Hessian is
// singular there, "not finite at the initial state" when it overflows; `where` names
// the system's text or the scene. With the velocities' names (one per row of H), the
// message names those along which d2L/dv2 vanishes (its null direction). Compiled once
// (run.cc): its SVD is a dynamic-size Eigen instantiation that every kernel file would
// otherwise compile again.
void require_regular_hessian(const Eigen::MatrixXd& H, const std::string& where,
                             const std::vector<std::string>& velocities = {});

}  // namespace dvm::kernels
