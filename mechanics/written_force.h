// A generalized force F(t, q, v) on R^n written in a scene ([system] forces): one
// expression per coordinate that has a component, the others 0. A force that is not
// the gradient of a potential (damping, a drive, friction) enters the discrete
// equations by the discrete Lagrange-d'Alembert principle (Marsden and West, Acta
// Numerica 2001, Sec. 3.2; solvers/dynamic_step.h).
//
// Each component is parsed with WrittenSystem::Kind::force: the coordinates, their
// velocities (name_dot), the time t, the parameters and the definitions. Evaluated in
// doubles; its Jacobians F_q = dF/dq and F_v = dF/dv by reverse mode on each
// component's tape (Expression::gradient), one pass per component. The time sits at
// entry dim() of the first block, so one gradient call also gives dF/dt (unused).
//
// A force may read control inputs u ([system] controls, ControlSignal below): each an
// expression in t, or a table of one value per step. A tabulated control is piecewise
// constant, u_k over the step from t_k to t_{k+1}, whatever substep of a composition
// evaluates the force (some of whose nodes lie outside [t_k, t_{k+1}]): the run sets the
// index k before each step (ControlSignal::set_step), and every force that shares the
// signal reads u_k. Controls follow t in the first block (entries dim() + 1 ...), so
// one gradient call also gives F_u, the Jacobian the step's derivative in u reads.
//
// Workspace is held per object: one object must not be used from two threads at once
// (copies are independent; they share the control signal, which one run advances).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "mechanics/written_lagrangian.h"

namespace dvm {

// The control inputs of a run, in the order of WrittenSystem::controls, and the step
// the run is at.
class ControlSignal {
 public:
  explicit ControlSignal(std::vector<WrittenSystem::Control> controls) : controls_(std::move(controls)) {}
  int count() const { return static_cast<int>(controls_.size()); }
  // The step that the next evaluations belong to (tabulated controls: u_k for step k).
  void set_step(std::int64_t k) const { step_ = k; }
  std::int64_t step() const { return step_; }
  // u at time t of the current step, into u[0 .. count() - 1].
  void values(double t, double* u) const {
    for (std::size_t j = 0; j < controls_.size(); ++j) {
      const WrittenSystem::Control& c = controls_[j];
      if (c.table.empty()) {
        u[j] = c.expression(&t);
      } else {
        const std::int64_t last = static_cast<std::int64_t>(c.table.size()) - 1;
        u[j] = c.table[static_cast<std::size_t>(std::clamp<std::int64_t>(step_, 0, last))];
      }
    }
  }

 private:
  std::vector<WrittenSystem::Control> controls_;
  mutable std::int64_t step_ = 0;
};

class WrittenForce {
 public:
  // controls: the run's control signal, required where the system declares controls.
  explicit WrittenForce(std::shared_ptr<const WrittenSystem> s, std::shared_ptr<const ControlSignal> controls = nullptr)
      : system_(std::move(s)), controls_(std::move(controls)) {
    if (!system_ || system_->space != WrittenSystem::Space::euclidean)
      throw std::invalid_argument("WrittenForce: forces are written on R^n");
    if (system_->forces.empty()) throw std::invalid_argument("WrittenForce: the system writes no forces");
    const int c = static_cast<int>(system_->controls.size());
    if (c > 0 && (!controls_ || controls_->count() != c))
      throw std::invalid_argument("WrittenForce: the system declares " + std::to_string(c) +
                                  " controls; their signal is needed");
    const int n = system_->dim();
    qt_.setZero(n + 1 + c);
    gq_.resize(n + 1 + c);
    gv_.resize(n);
    sq_.setZero(n + 1 + c);
    sv_.setZero(n);
    // the coordinates and velocities each component reads, off its tape (a component
    // that reads a definition, which may read any, depends on all of them)
    for (const auto& [i, e] : system_->forces) {
      std::vector<char> rq(static_cast<std::size_t>(n), 0), rv(static_cast<std::size_t>(n), 0);
      bool all = false;
      e.for_each_variable([&](int block, int index) {
        if (block == 0 && index >= 0 && index < n)
          rq[static_cast<std::size_t>(index)] = 1;
        else if (block == 1 && index >= 0 && index < n)
          rv[static_cast<std::size_t>(index)] = 1;
        else if (!(block == 0 && index >= n && index < n + 1 + c))  // (t and the controls)
          all = true;
      });
      Row row{i, {}, {}};
      for (int j = 0; j < n; ++j) {
        if (all || rq[static_cast<std::size_t>(j)]) row.q.push_back(j);
        if (all || rv[static_cast<std::size_t>(j)]) row.v.push_back(j);
      }
      pattern_.push_back(std::move(row));
    }
  }

  // The entries of F_q and F_v that may be nonzero: for each component (in the order of
  // WrittenSystem::forces) its coordinate i and the coordinates q and velocities v it reads.
  struct Row {
    int i;
    std::vector<int> q, v;
  };
  const std::vector<Row>& pattern() const { return pattern_; }

  int dim() const { return system_->dim(); }
  int controls() const { return static_cast<int>(system_->controls.size()); }
  const ControlSignal* signal() const { return controls_.get(); }

  // F(t, q, v) into F (size dim()).
  template <class Q, class V, class Out>
  void value(double t, const Q& q, const V& v, Out& F) const {
    load(t, q);
    F.setZero();
    for (const auto& [i, e] : system_->forces) F[i] = e(qt_.data(), v.data());
  }

  // F and its Jacobians F_q(i, j) = dF_i/dq_j, F_v(i, j) = dF_i/dv_j (n x n, sized by
  // the caller), and where Fu is given F_u(i, j) = dF_i/du_j (n x controls()).
  template <class Q, class V, class Out, class Mat>
  void jacobian(double t, const Q& q, const V& v, Out& F, Mat& Fq, Mat& Fv, Eigen::MatrixXd* Fu = nullptr) const {
    load(t, q);
    F.setZero();
    Fq.setZero();
    Fv.setZero();
    const int n = dim(), c = controls();
    if (Fu) Fu->setZero(n, c);
    for (const auto& [i, e] : system_->forces) {
      F[i] = e(qt_.data(), v.data());
      gq_.setZero();
      gv_.setZero();
      e.gradient(qt_.data(), v.data(), gq_.data(), gv_.data());
      for (int j = 0; j < n; ++j) {
        Fq(i, j) = gq_[j];
        Fv(i, j) = gv_[j];
      }
      if (Fu)
        for (int j = 0; j < c; ++j) (*Fu)(i, j) = gq_[n + 1 + j];
    }
  }

  // The entries of F_q and F_v in the order of pattern() (row by row: a row's q entries
  // in Fq, its v entries in Fv), and F (size dim()) where F is given, by reverse mode on
  // each component's tape: O(the tapes' length), nothing of size dim() per component
  // (the sparse constrained step, solvers/sparse_constrained_step.h, which has F from
  // value() at the same point already). Where Fu is given, F_u as jacobian() gives it
  // (n x controls(): a few columns).
  template <class Q, class V>
  void sparse_jacobian(double t, const Q& q, const V& v, double* Fq, double* Fv, Eigen::VectorXd* F = nullptr,
                       Eigen::MatrixXd* Fu = nullptr) const {
    load(t, q);
    if (F) F->setZero();
    const int n = dim(), c = controls();
    if (Fu) Fu->setZero(n, c);
    std::size_t eq = 0, ev = 0, k = 0;
    for (const auto& [i, e] : system_->forces) {
      const Row& row = pattern_[k++];
      if (F) (*F)[i] = e(qt_.data(), v.data());
      // sq_ and sv_ are zero outside a call: the tape adds to them, the entries read are
      // cleared (t's and the controls' too)
      e.gradient(qt_.data(), v.data(), sq_.data(), sv_.data());
      for (int j : row.q) {
        Fq[eq++] = sq_[j];
        sq_[j] = 0.0;
      }
      for (int j : row.v) {
        Fv[ev++] = sv_[j];
        sv_[j] = 0.0;
      }
      if (Fu)
        for (int j = 0; j < c; ++j) (*Fu)(i, j) += sq_[n + 1 + j];
      for (int j = n; j < n + 1 + c; ++j) sq_[j] = 0.0;
    }
  }
  // The number of entries of sparse_jacobian's Fq and Fv.
  std::size_t q_entries() const {
    std::size_t e = 0;
    for (const Row& r : pattern_) e += r.q.size();
    return e;
  }
  std::size_t v_entries() const {
    std::size_t e = 0;
    for (const Row& r : pattern_) e += r.v.size();
    return e;
  }

 private:
  template <class Q>
  void load(double t, const Q& q) const {
    const int n = dim();
    for (int i = 0; i < n; ++i) qt_[i] = q[i];
    qt_[n] = t;
    if (controls_) controls_->values(t, qt_.data() + n + 1);
  }

  std::shared_ptr<const WrittenSystem> system_;
  std::shared_ptr<const ControlSignal> controls_;
  mutable Eigen::VectorXd qt_, gq_, gv_;  // (q, t), and one component's gradient
  mutable Eigen::VectorXd sq_, sv_;       // the same for sparse_jacobian, zero between calls
  std::vector<Row> pattern_;
};

}  // namespace dvm
