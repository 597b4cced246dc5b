// A mechanical system written as text: coordinates, a Lagrangian L(q, v), and
// optionally an energy E(q, v, p) to monitor and a Hamiltonian H(q, p).
//
// Naming convention on R^n. With coordinates = ["theta", "phi"]:
//   theta, phi             the coordinates q
//   theta_dot, phi_dot     the velocities v = dq/dt
//   p_theta, p_phi         the momenta p = dL/dv (energy and Hamiltonian only)
// On S^2 the three coordinates are the components of the embedded unit vector
// (default names x, y, z; velocities x_dot, ..., the stored covector p_x, ...). On
// SO(3) the names are fixed: R11 ... R33 the entries of the rotation matrix (row,
// column), w1 w2 w3 the body angular velocity, pi1 pi2 pi3 the body angular momentum
// (mechanics/written_manifold.h).
// Every expression may also use the parameters (constants with values), the constant
// pi and the functions of mechanics/expression.h.
//
// Arrays, on R^n. A coordinate declared as an array, say q with 1000 entries, names
// q[1] ... q[1000], velocities q_dot[i], momenta p_q[i] (the array's `ends` say what
// q[0] and q[1001] are: refused, fixed at 0, or periodic); a parameter may be a list,
// k[1] ... k[n]. Together with sum(i, first, last, term) (mechanics/expression.h) a
// chain or a lattice of any size is a few lines of text.
//
// WrittenLagrangian<N> is a Lagrangian in the sense of mechanics/lagrangian.h, with
// the dimension fixed at compile time; the text is parsed once into a WrittenSystem
// (a tape per expression) and shared by every copy.
#pragma once

#include <cctype>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "mechanics/derivative_program.h"
#include "mechanics/expression.h"
#include "mechanics/lagrangian.h"

namespace dvm {

// The most quantities a scene may ask to monitor ([system] invariants).
constexpr int kMaxWrittenInvariants = 8;

struct WrittenSystem {
  // Where the point lives: R^n (any number of coordinates), S^2 or a power (S^2)^K
  // (the embedded unit vectors, three coordinates each), SO(3) (the rotation matrix;
  // no coordinate names).
  enum class Space { euclidean, sphere, rotation };
  Space space = Space::euclidean;
  int factors = 1;  // K, the number of S^2 factors (space sphere)
  std::string name = "lagrangian";
  // One name per coordinate, in the order of the state: the declared names, with an
  // array's entries named q[1], q[2], ... (these name the columns).
  std::vector<std::string> coordinates;
  // The coordinates declared as arrays (block 0, offset into the state, size, ends);
  // their entries are not single names of the expressions.
  std::vector<ExpressionSymbols::Array> arrays;
  std::vector<std::pair<std::string, double>> params;
  std::vector<ExpressionSymbols::ConstantArray> param_arrays;
  // Named subexpressions {name, text}, usable in every expression (and in the
  // definitions after them); evaluated once per evaluation.
  std::vector<std::pair<std::string, std::string>> definitions;
  // In q (block 0) and v (block 1); on R^n it may read the time t (block 0, entry
  // dim(), after q), time_dependent() then.
  Expression lagrangian;
  Expression energy;       // optional: q, v, p (blocks 0, 1, 2)
  Expression hamiltonian;  // optional: q (block 0) and p (block 2)
  // Quantities the scene asks to monitor besides the energy ([system] invariants: a
  // name and an expression in q, v and p, blocks 0, 1, 2, as the energy's), in order.
  std::vector<std::pair<std::string, Expression>> invariants;
  // Generalized forces ([system] forces, R^n): {coordinate index, F_i(t, q, v)}, in the
  // coordinates' order, one per coordinate that has one (mechanics/written_force.h). An
  // expression of Kind::force: q (block 0, entries 0 .. dim() - 1), the time t (block 0,
  // entry dim()) and v (block 1).
  std::vector<std::pair<int, Expression>> forces;
  // Holonomic constraints g_i(t, q) = 0 ([system] constraints: R^n, S^2, SO(3)), in the
  // scene's order (mechanics/written_constraints.h; on S^2 and SO(3)
  // mechanics/written_manifold.h, ManifoldConstraints). An expression of
  // Kind::constraint: q (block 0, entries 0 .. dim() - 1; on SO(3) R's 9 entries) and the
  // time t (block 0, the entry after them).
  std::vector<Expression> constraints;
  // Control inputs ([system] controls, R^n), in the scene's order
  // (mechanics/written_force.h, ControlSignal): each an expression in t or a table of
  // one value per step. A force reads control j at block 0, entry dim() + 1 + j (after t).
  struct Control {
    std::string name;
    Expression expression;      // in t (block 0, entry 0) and the parameters, where written
    std::vector<double> table;  // else its values, one per step
    std::string source;         // where the table came from (a file), for messages
    std::string where;          // the scene key that gave it, for messages
  };
  std::vector<Control> controls;
  // Numbers per stored velocity: the coordinates (R^n, S^2), 3 on SO(3).
  int dim() const { return space == Space::rotation ? 3 : static_cast<int>(coordinates.size()); }
  // Where a force reads control j in the first block: after the time, which follows the
  // point's stored entries (the coordinates; R's nine entries on SO(3)).
  int control_index(std::size_t j) const {
    return (space == Space::rotation ? 9 : dim()) + 1 + static_cast<int>(j);
  }
  // Whether the Lagrangian reads the time t: L(t, q, v), whose energy is not conserved.
  bool time_dependent() const { return space == Space::euclidean && lagrangian.uses(0, dim()); }

  // Which expression a text is for (decides the names it may use): L in q and v (and t
  // on R^n); the energy and the invariants in q, v and p; H in q and p; a force in t, q
  // and v; a constraint in t and q.
  enum class Kind { lagrangian, energy, hamiltonian, force, constraint };

  // Appends the array `name` of `size` coordinates (q, v, p named name[i],
  // name_dot[i], p_name[i]) to the state.
  void add_array(const std::string& array, int size, ExpressionSymbols::Boundary ends) {
    if (size < 1) throw std::invalid_argument("the array '" + array + "' needs at least one entry");
    arrays.push_back({array, 0, static_cast<int>(coordinates.size()), size, ends});
    for (int i = 1; i <= size; ++i) coordinates.push_back(array + "[" + std::to_string(i) + "]");
  }
  // The array whose entries include coordinate i, or null.
  const ExpressionSymbols::Array* array_of(int i) const {
    for (const auto& a : arrays)
      if (i >= a.offset && i < a.offset + a.size) return &a;
    return nullptr;
  }

  ExpressionSymbols symbols(Kind kind) const {
    ExpressionSymbols s;
    if (space == Space::rotation) {
      // R stored column-major (Eigen's order): Rij at index 3 (j - 1) + (i - 1)
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) s.variables.push_back({rotation_entry(i, j), 0, 3 * j + i});
      for (int i = 0; i < 3; ++i) {
        if (kind != Kind::hamiltonian && kind != Kind::constraint)
          s.variables.push_back({"w" + std::to_string(i + 1), 1, i});
        if (kind != Kind::lagrangian && kind != Kind::force && kind != Kind::constraint)
          s.variables.push_back({"pi" + std::to_string(i + 1), 2, i});
      }
      // (a body torque and a constraint: t after R's entries; a torque's controls after t)
      if (kind == Kind::force || kind == Kind::constraint) s.variables.push_back({"t", 0, 9});
      if (kind == Kind::force)
        for (std::size_t j = 0; j < controls.size(); ++j) s.variables.push_back({controls[j].name, 0, control_index(j)});
      s.constants = params;
      s.definitions = definitions;
      return s;
    }
    const bool momenta = kind == Kind::energy || kind == Kind::hamiltonian;
    const bool velocities = kind != Kind::hamiltonian && kind != Kind::constraint;
    for (int i = 0; i < dim(); ++i) {
      if (array_of(i)) continue;
      const std::string& c = coordinates[static_cast<std::size_t>(i)];
      s.variables.push_back({c, 0, i});
      if (velocities) s.variables.push_back({c + "_dot", 1, i});
      if (momenta) s.variables.push_back({"p_" + c, 2, i});
    }
    for (const auto& a : arrays) {
      s.arrays.push_back({a.name, 0, a.offset, a.size, a.boundary});
      if (velocities) s.arrays.push_back({a.name + "_dot", 1, a.offset, a.size, a.boundary});
      if (momenta) s.arrays.push_back({"p_" + a.name, 2, a.offset, a.size, a.boundary});
    }
    if (kind == Kind::force || kind == Kind::constraint || (kind == Kind::lagrangian && space == Space::euclidean))
      s.variables.push_back({"t", 0, dim()});
    if (kind == Kind::force)
      for (std::size_t j = 0; j < controls.size(); ++j)
        s.variables.push_back({controls[j].name, 0, control_index(j)});
    s.constants = params;
    s.constant_arrays = param_arrays;
    s.definitions = definitions;
    return s;
  }

  // A name check_names() refuses, with the role it was given ("coordinate",
  // "velocity", "parameter", "parameter list", "definition", ...): the role tells a
  // reader which key to blame. A name given twice is blamed on its second role.
  struct NameError : std::invalid_argument {
    NameError(const std::string& message, std::string role_, std::string name_)
        : std::invalid_argument(message), role(std::move(role_)), name(std::move(name_)) {}
    std::string role, name;
  };

  // Checks the coordinate and parameter names; throws NameError.
  void check_names() const {
    auto identifier = [](const std::string& n) {
      if (n.empty() || !(std::isalpha(static_cast<unsigned char>(n[0])) || n[0] == '_')) return false;
      for (char ch : n)
        if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_')) return false;
      return true;
    };
    std::set<std::string> seen;
    auto claim = [&](const std::string& n, const char* what) {
      if (!identifier(n))
        throw NameError(std::string(what) + " name '" + n +
                            "' is not a name (letters, digits and '_', not starting with a digit)",
                        what, n);
      if (n == "pi") throw NameError(std::string(what) + " name 'pi' is reserved for the constant", what, n);
      for (const auto& f : expression_detail::functions())
        if (n == f.name) throw NameError(std::string(what) + " name '" + n + "' is a function name", what, n);
      if (n == "sum" || n == "t")
        throw NameError("the name '" + n + "' is reserved (" + (n == "sum" ? "sum(i, first, last, term)" : "time") +
                            ")",
                        what, n);
      if (!seen.insert(n).second) throw NameError("the name '" + n + "' is used twice", what, n);
    };
    if (space == Space::rotation) {
      if (!coordinates.empty())
        throw std::invalid_argument("on SO(3) the names are fixed (R11 ... R33, w1 w2 w3, pi1 pi2 pi3); no coordinates");
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) claim(rotation_entry(i, j), "matrix entry");
      for (int i = 1; i <= 3; ++i) {
        claim("w" + std::to_string(i), "angular velocity");
        claim("pi" + std::to_string(i), "angular momentum");
      }
    }
    if (space == Space::sphere && factors == 1 && coordinates.size() != 3)
      throw std::invalid_argument("on S^2 the coordinates are the 3 components of the embedded unit vector, got " +
                                  std::to_string(coordinates.size()) + " names");
    if (space == Space::sphere && static_cast<int>(coordinates.size()) != 3 * factors)
      throw std::invalid_argument("on (S^2)^" + std::to_string(factors) + " the coordinates are the 3 components of " +
                                  "each of the " + std::to_string(factors) + " embedded unit vectors (" +
                                  std::to_string(3 * factors) + " names), got " + std::to_string(coordinates.size()));
    if (space != Space::rotation && coordinates.empty()) throw std::invalid_argument("at least one coordinate is needed");
    if (space != Space::euclidean && !arrays.empty())
      throw std::invalid_argument("arrays of coordinates are written on R^n only");
    for (int i = 0; i < static_cast<int>(coordinates.size()); ++i) {
      if (array_of(i)) continue;
      const std::string& c = coordinates[static_cast<std::size_t>(i)];
      claim(c, "coordinate");
      claim(c + "_dot", "velocity");
      claim("p_" + c, "momentum");
    }
    for (const auto& a : arrays) {
      claim(a.name, "coordinate array");
      claim(a.name + "_dot", "velocity array");
      claim("p_" + a.name, "momentum array");
    }
    for (const auto& p : params) claim(p.first, "parameter");
    for (const auto& p : param_arrays) {
      claim(p.name, "parameter list");
      if (p.values.empty()) throw std::invalid_argument("the parameter list '" + p.name + "' is empty");
    }
    for (const auto& d : definitions) claim(d.first, "definition");
    for (const auto& c : controls) claim(c.name, "control");
    if (static_cast<int>(definitions.size()) > Expression::kMaxDefinitions)
      throw std::invalid_argument("at most " + std::to_string(Expression::kMaxDefinitions) + " definitions");
  }

  // "R11" ... "R33": the entry in row i, column j (0-based arguments).
  static std::string rotation_entry(int i, int j) { return "R" + std::to_string(i + 1) + std::to_string(j + 1); }
};

template <int N>
struct WrittenLagrangian {
  static constexpr int dim = N;
  std::shared_ptr<const WrittenSystem> system;
  // dL/dq, dL/dv as a straight-line program (mechanics/derivative_program.h), or null
  std::shared_ptr<const DerivativeProgram> program;

  explicit WrittenLagrangian(std::shared_ptr<const WrittenSystem> s) : system(std::move(s)) {
    if (!system || system->dim() != N) throw std::invalid_argument("WrittenLagrangian: dimension mismatch");
    if (system->space != WrittenSystem::Space::euclidean)
      throw std::invalid_argument("WrittenLagrangian: the system is written on S^2 or SO(3) (mechanics/written_manifold.h)");
    if (system->time_dependent())
      throw std::invalid_argument("WrittenLagrangian: the Lagrangian depends on t (WrittenDynamic takes it)");
    program = DerivativeProgram::build(system->lagrangian, N, false);
    if (program && program->has_blocks()) program = nullptr;  // (gradient_any runs no blocks)
  }
  std::string name() const { return system->name; }

  template <class T>
  T operator()(const Vec<T, N>& q, const Vec<T, N>& v) const {
    return system->lagrangian(q.data(), v.data());
  }

  // dL/dq and dL/dv for any scalar: the derivative program, evaluated in T (one Jet
  // level through it gives the Hessian the fixed-size steps need), or forward mode
  // through the tape where no program was built.
  template <class T>
  void gradient(const Vec<T, N>& q, const Vec<T, N>& v, Vec<T, N>& Lq, Vec<T, N>& Lv) const {
    if (!program) {  // forward mode through the text, as for a Lagrangian without a gradient
      lagrangian_gradient(GenericOnly<WrittenLagrangian>{*this}, q, v, Lq, Lv);
      return;
    }
    constexpr std::size_t kStack = 128;
    const std::size_t m = program->slots();
    alignas(T) unsigned char raw[kStack * sizeof(T)];
    T* slots = std::launder(reinterpret_cast<T*>(raw));
    if (m > kStack) {
      thread_local std::vector<T> buffer;
      if (buffer.size() < m) buffer.resize(m);
      slots = buffer.data();
    }
    program->gradient_any(q.data(), v.data(), Lq.data(), Lv.data(), slots);
  }

  // The monitored energy: the written one if given, else E_L = <dL/dv, v> - L.
  double energy_at(const Vec<double, N>& q, const Vec<double, N>& v, const Vec<double, N>& p) const {
    if (!system->energy.empty()) return system->energy(q.data(), v.data(), p.data());
    return energy(*this, q, v);
  }
  bool has_hamiltonian() const { return !system->hamiltonian.empty(); }
  double hamiltonian(const Vec<double, N>& q, const Vec<double, N>& p) const {
    return system->hamiltonian(q.data(), static_cast<const double*>(nullptr), p.data());
  }
  // A coordinate that L does not depend on is cyclic: its momentum is conserved.
  bool cyclic(int i) const { return !system->lagrangian.uses(0, i); }
};

// The Hamiltonian written in a scene, H(q, p), for the Hamiltonian form (Eq. 5.1):
// evaluated for any scalar like the written Lagrangian.
template <int N>
struct WrittenHamiltonian {
  static constexpr int dim = N;
  std::shared_ptr<const WrittenSystem> system;
  std::string name() const { return system->name.empty() ? "hamiltonian" : system->name; }
  template <class T>
  T operator()(const Vec<T, N>& q, const Vec<T, N>& p) const {
    return system->hamiltonian(q.data(), static_cast<const T*>(nullptr), p.data());
  }
};

}  // namespace dvm
