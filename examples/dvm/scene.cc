#include "examples/dvm/scene.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include <toml++/toml.h>

#include "solvers/composition_methods.h"
#include "examples/dvm/scene_written.h"

namespace dvm::cli {

const std::vector<SystemInfo>& systems() {
  static const std::vector<SystemInfo> list = {
      {"harmonic", 1, "L = v^2/2 - omega^2 q^2/2", {{"omega", 1.0, "angular frequency"}}},
      {"pendulum",
       1,
       "L = m l^2 v^2/2 + m g l cos(q)   (q from the downward vertical)",
       {{"m", 1.0, "mass"}, {"l", 1.0, "length"}, {"g", 1.0, "gravitational acceleration"}}},
      {"kepler", 2, "L = |v|^2/2 + mu/|q|   (q in the plane)", {{"mu", 1.0, "gravitational parameter"}}},
      {"spherical-pendulum",
       3,
       "L = m l^2 |v|^2/2 - m g l x_3   (x a unit vector, x_3 upward)",
       {{"m", 1.0, "mass"}, {"l", 1.0, "length"}, {"g", 1.0, "gravitational acceleration"}},
       "S^2"},
      {"spherical-chain",
       3,
       "L = sum_i m |dr_i/dt|^2/2 - g sum_i m (r_i)_3,  r_i = l (x_1 + ... + x_i)   (n links, x_i unit vectors)",
       {{"n", 2.0, "number of links (1 to 4)"}, {"m", 1.0, "mass at the end of each link"},
        {"l", 1.0, "length of each link"}, {"g", 1.0, "gravitational acceleration"}},
       "S^2"},
      {"rigid-body",
       3,
       "L = (I1 w1^2 + I2 w2^2 + I3 w3^2)/2   (w the body angular velocity)",
       {{"I1", 1.0, "principal moment of inertia"},
        {"I2", 2.0, "principal moment of inertia"},
        {"I3", 3.0, "principal moment of inertia"}},
       "SO(3)"},
      {"heavy-top",
       3,
       "L = w.I w/2 - m g e3.(R chi)   (chi the centre of mass in the body frame)",
       {{"I1", 1.0, "principal moment of inertia"},
        {"I2", 1.0, "principal moment of inertia"},
        {"I3", 0.5, "principal moment of inertia"},
        {"m", 1.0, "mass"},
        {"g", 1.0, "gravitational acceleration"},
        {"chi1", 0.0, "centre of mass, body frame"},
        {"chi2", 0.0, "centre of mass, body frame"},
        {"chi3", 1.0, "centre of mass, body frame"}},
       "SO(3)"},
      // dim 0: the dimension is params.n (a dynamic-size system)
      {"chain",
       0,
       "L = sum m v_i^2/2 - sum_bonds (k r^2/2 + alpha r^3/3 + beta r^4/4),  r = q_i - q_{i-1}",
       {{"n", 8.0, "number of particles"},
        {"m", 1.0, "mass of each particle"},
        {"k", 1.0, "linear spring constant"},
        {"alpha", 0.0, "cubic (FPU-alpha) coefficient"},
        {"beta", 0.0, "quartic (FPU-beta) coefficient"},
        {"fixed", 1.0, "1: ends tied to walls; 0: free ends (total momentum conserved)"}}},
      // the classic systems (mechanics/systems_classic.h)
      {"double-pendulum",
       2,
       "L = (m1+m2) l1^2 w1^2/2 + m2 l2^2 w2^2/2 + m2 l1 l2 w1 w2 cos(q1-q2) + (m1+m2) g l1 cos q1 + m2 g l2 cos q2",
       {{"m1", 1.0, "upper mass"},
        {"m2", 1.0, "lower mass"},
        {"l1", 1.0, "upper rod length"},
        {"l2", 1.0, "lower rod length"},
        {"g", 1.0, "gravitational acceleration"}}},
      {"henon-heiles", 2, "L = |v|^2/2 - (x^2 + y^2)/2 - lambda (x^2 y - y^3/3)", {{"lambda", 1.0, "coupling"}}},
      {"fpu",
       6,
       "GNI Sec. I.5.1, m = 3: L = |v|^2/2 - omega^2/4 sum (q_2i - q_2i-1)^2 - sum (q_2i+1 - q_2i)^4",
       {{"omega", 50.0, "stiff spring frequency"}}},
      {"duffing", 1, "L = v^2/2 - alpha q^2/2 - beta q^4/4",
       {{"alpha", 1.0, "linear stiffness"}, {"beta", 1.0, "cubic stiffness"}}},
      {"charged-particle",
       2,
       "L = m |v|^2/2 + (c B/2)(x v_y - y v_x) - k |q|^2/2   (uniform field B normal to the plane)",
       {{"m", 1.0, "mass"}, {"c", 1.0, "charge"}, {"B", 1.0, "magnetic field"}, {"k", 0.0, "electric potential k |q|^2/2"}}},
      {"nbody",
       0,
       "L = sum m_i |v_i|^2/2 + G sum_{i<j} m_i m_j/|q_i - q_j|   (in R^3; [system] masses = [...], 2 to 6 bodies)",
       {{"G", 1.0, "gravitational constant"}}},
  };
  return list;
}

const std::vector<MapInfo>& maps() {
  static const std::vector<MapInfo> list = {
      {"explicit-euler", "R_d(x, v) = (x, x + v)", false, 1, true, "theta = 0"},
      {"adjoint-euler", "R_d(x, v) = (x - v, x)", false, 1, true, "theta = 1; the adjoint of explicit-euler"},
      {"midpoint", "R_d(x, v) = (x - v/2, x + v/2)", true, 2, true, "theta = 1/2; self-adjoint"},
      {"theta", "R_d(x, v) = (x - theta v, x + (1 - theta) v)", false, 1, true,
       "symmetric and of order 2 only at theta = 1/2"},
      {"retraction-theta", "R_d(x, v) = (R_x(-theta v), R_x((1 - theta) v)), R_x(v) = x + v", false, 1, false,
       "Prop. 2.3 from the flat retraction; inverted by Newton's method (the generic path)"},
      {"sphere-exp", "(exp_x(-v/2), exp_x(v/2)), exp_x(v) = cos|v| x + sin|v| v/|v|", true, 2, true,
       "midpoint form on S^2 (Eq. 2.3)", "S^2"},
      {"sphere-projection", "((x - v/2)/|x - v/2|, (x + v/2)/|x + v/2|)", true, 2, true,
       "projection midpoint on S^2", "S^2"},
      {"sphere-exp-fixed", "(x, exp_x(v))", false, 1, true, "fixed-first-point form on S^2", "S^2"},
      {"sphere-projection-fixed", "(x, (x + v)/|x + v|)", false, 1, true,
       "fixed-first-point projection map; inverse (x0, x1/(x0.x1) - x0) needs x0.x1 > 0", "S^2"},
      {"so3-exp", "(R exp(-w/2), R exp(w/2))", true, 2, true, "group exponential midpoint on SO(3)", "SO(3)"},
      {"so3-cayley", "(R cay(-w/2), R cay(w/2))", true, 2, true, "Cayley midpoint on SO(3) (Ex. 2.8)", "SO(3)"},
      {"so3-exp-fixed", "(R, R exp(w))", false, 1, true, "fixed-first-point form on SO(3)", "SO(3)"},
      {"so3-cayley-fixed", "(R, R cay(w))", false, 1, true,
       "fixed-first-point Cayley map; undefined for relative rotations by pi", "SO(3)"},
  };
  return list;
}

namespace {

std::string fmt(double x) {
  std::ostringstream out;
  out.precision(3);
  out << x;
  return out.str();
}

std::string join_names(const std::vector<std::string>& names) {
  std::string out;
  for (std::size_t i = 0; i < names.size(); ++i) out += (i ? ", " : "") + names[i];
  return out;
}

}  // namespace

const SystemInfo& find_system(const std::string& name, const std::string& where) {
  std::vector<std::string> names;
  for (const auto& s : systems()) {
    if (s.name == name) return s;
    names.push_back(s.name);
  }
  throw InputError(where + ": unknown system \"" + name + "\"; expected one of: " + join_names(names));
}

const MapInfo& find_map(const std::string& name, const std::string& where) {
  std::vector<std::string> names;
  for (const auto& m : maps()) {
    if (m.name == name) return m;
    names.push_back(m.name);
  }
  throw InputError(where + ": unknown map \"" + name + "\"; expected one of: " + join_names(names));
}

namespace {

class Reader {
 public:
  explicit Reader(std::string path) : path_(std::move(path)) {}

  // "file:line:column: key 'section.key'" (or "(from --set)" for overrides).
  std::string where(const toml::node* node, const std::string& key) const {
    std::ostringstream out;
    out << path_;
    if (node && node->source().begin.line > 0)
      out << ":" << node->source().begin.line << ":" << node->source().begin.column;
    else if (node)
      out << " (from --set)";
    out << ": key '" << key << "'";
    return out.str();
  }

  static std::string describe(const toml::node& n) {
    std::ostringstream out;
    if (n.is_string())
      out << '"' << n.value<std::string>().value_or("") << '"';
    else if (n.is_array())
      out << "an array";
    else if (n.is_table())
      out << "a table";
    else if (n.is_floating_point())
      out << n.value<double>().value_or(NAN);
    else if (n.is_integer())
      out << n.value<std::int64_t>().value_or(0);
    else if (n.is_boolean())
      out << (n.value<bool>().value_or(false) ? "true" : "false");
    else
      out << "a value of another type";
    return out.str();
  }

  double number(const toml::node& n, const std::string& key) const {
    double x;
    if (auto f = n.as_floating_point())
      x = f->get();
    else if (auto i = n.as_integer())
      x = static_cast<double>(i->get());
    else
      throw InputError(where(&n, key) + ": got " + describe(n) + ", expected a number");
    if (!std::isfinite(x)) throw InputError(where(&n, key) + ": got " + describe(n) + ", expected a finite number");
    return x;
  }

  std::int64_t integer(const toml::node& n, const std::string& key, std::int64_t min_value) const {
    auto i = n.as_integer();
    if (!i) throw InputError(where(&n, key) + ": got " + describe(n) + ", expected a whole number");
    if (i->get() < min_value)
      throw InputError(where(&n, key) + ": got " + describe(n) + ", expected a whole number >= " +
                       std::to_string(min_value));
    return i->get();
  }

  std::string string(const toml::node& n, const std::string& key) const {
    auto s = n.as_string();
    if (!s) throw InputError(where(&n, key) + ": got " + describe(n) + ", expected a string");
    return s->get();
  }

  std::vector<double> vector(const toml::node& n, const std::string& key) const {
    auto a = n.as_array();
    if (!a) throw InputError(where(&n, key) + ": got " + describe(n) + ", expected an array of numbers");
    std::vector<double> out;
    for (std::size_t i = 0; i < a->size(); ++i) out.push_back(number(*a->get(i), key + "[" + std::to_string(i) + "]"));
    return out;
  }

  const toml::table& section(const toml::table& root, const std::string& name, bool required) const {
    static const toml::table empty;
    const toml::node* n = root.get(name);
    if (!n) {
      if (required) throw InputError(path_ + ": missing section [" + name + "]");
      return empty;
    }
    if (!n->is_table()) throw InputError(where(n, name) + ": expected a table [" + name + "]");
    return *n->as_table();
  }

  void only_keys(const toml::table& t, const std::string& section, const std::set<std::string>& allowed) const {
    for (const auto& [k, v] : t) {
      if (!allowed.count(std::string(k.str()))) {
        std::vector<std::string> names(allowed.begin(), allowed.end());
        throw InputError(where(&v, section + "." + std::string(k.str())) + ": unknown key; [" + section +
                         "] takes: " + join_names(names));
      }
    }
  }

  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// Applies one "a.b.c=value" override, value written as in TOML.
void apply_override(toml::table& root, const std::string& spec) {
  const auto eq = spec.find('=');
  if (eq == std::string::npos || eq == 0)
    throw InputError("--set: expected section.key=value, got '" + spec + "'");
  const std::string key = spec.substr(0, eq), value = spec.substr(eq + 1);
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (true) {
    const auto dot = key.find('.', start);
    parts.push_back(key.substr(start, dot - start));
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  if (parts.size() < 2)
    throw InputError("--set: expected section.key=value, got '" + spec + "' (the key needs a section)");
  for (const auto& p : parts)
    if (p.empty()) throw InputError("--set: empty key component in '" + spec + "'");
  toml::table parsed;
  try {
    const std::string doc = "value = " + value;
    parsed = toml::parse(std::string_view(doc), std::string_view("--set"));
  } catch (const toml::parse_error& e) {
    // A bare word (--set integrator.map=theta) is taken as a string, so that shells
    // need no nested quotes; anything else must be a TOML value.
    const bool bare = !value.empty() && std::isalpha(static_cast<unsigned char>(value[0])) &&
                      value.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-./") ==
                          std::string::npos;
    if (!bare)
      throw InputError("--set " + key + ": value '" + value + "' is not a TOML value (" +
                       std::string(e.description()) + ")");
    parsed.insert_or_assign("value", value);
  }
  toml::table* t = &root;
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) {
    toml::node* n = t->get(parts[i]);
    if (!n) {
      t->insert(parts[i], toml::table{});
      n = t->get(parts[i]);
    }
    if (!n->is_table()) throw InputError("--set " + key + ": '" + parts[i] + "' is not a table");
    t = n->as_table();
  }
  // Overrides carry no source position, which where() reports as "(from --set)".
  t->insert_or_assign(parts.back(), *parsed.get("value"));
}

// [initial] for systems on R^n and S^2: q and one of p, v, each of length dim (a
// boundary-value problem takes q only).
void read_vector_initial(const Reader& r, const toml::table& ini, const std::string& path, const SystemInfo& info,
                         int dim, bool boundary_value, Scene& s) {
  const int links = info.space == "S^2" ? dim / 3 : 1;
  r.only_keys(ini, "initial", {"q", "p", "v"});
  const toml::node* q = ini.get("q");
  if (!q) throw InputError(path + ": missing key 'initial.q'");
  s.q = r.vector(*q, "initial.q");
  const std::string n_expected = std::to_string(dim);
  if (static_cast<int>(s.q.size()) != dim)
    throw InputError(r.where(q, "initial.q") + ": got " + std::to_string(s.q.size()) + " numbers, expected " +
                     n_expected + " (the dimension of " + info.name + ")");
  const toml::node* p = ini.get("p");
  const toml::node* v = ini.get("v");
  if (p && v) throw InputError(r.where(v, "initial.v") + ": give either initial.p or initial.v, not both");
  if (boundary_value && (p || v))
    throw InputError(r.where(p ? p : v, p ? "initial.p" : "initial.v") +
                     ": a boundary-value problem takes initial.q and problem.q_final only");
  if (boundary_value) return;
  if (!p && !v) throw InputError(path + ": missing key 'initial.p' or 'initial.v'");
  const toml::node* pv = p ? p : v;
  const std::string pv_key = p ? "initial.p" : "initial.v";
  (p ? s.p : s.v) = r.vector(*pv, pv_key);
  s.momentum_given = p != nullptr;
  if (static_cast<int>((p ? s.p : s.v).size()) != dim)
    throw InputError(r.where(pv, pv_key) + ": got " + std::to_string((p ? s.p : s.v).size()) + " numbers, expected " +
                     n_expected + " (the dimension of " + info.name + ")");
  for (int k = 0; info.space == "S^2" && k < links; ++k) {
    // on the manifold, not projected onto it: the defect is reported
    const std::size_t o = 3 * static_cast<std::size_t>(k);
    const std::string which = links > 1 ? " (link " + std::to_string(k + 1) + ")" : "";
    const double n2 = s.q[o] * s.q[o] + s.q[o + 1] * s.q[o + 1] + s.q[o + 2] * s.q[o + 2];
    const double defect = std::fabs(std::sqrt(n2) - 1.0);
    if (!(defect <= 1e-12))
      throw InputError(r.where(q, "initial.q") + which + ": not a unit vector (| |q| - 1 | = " + fmt(defect) +
                       "); expected a point of S^2 to 1e-12");
    const auto& w = p ? s.p : s.v;
    const double t = std::fabs(s.q[o] * w[o] + s.q[o + 1] * w[o + 1] + s.q[o + 2] * w[o + 2]);
    if (!(t <= 1e-12))
      throw InputError(r.where(pv, pv_key) + which + ": not tangent to S^2 at q (|q . " + (p ? "p" : "v") +
                       "| = " + fmt(t) + "); expected a vector orthogonal to q to 1e-12");
  }
}

// [initial] for systems on SO(3): rotation (unit quaternion) or R (3x3 matrix), and
// omega (body angular velocity) or pi (body angular momentum).
void read_rotation_initial(const Reader& r, const toml::table& ini, const std::string& path, Scene& s) {
  r.only_keys(ini, "initial", {"rotation", "R", "omega", "pi"});
  const toml::node* quat = ini.get("rotation");
  const toml::node* mat = ini.get("R");
  if (quat && mat) throw InputError(r.where(mat, "initial.R") + ": give either initial.rotation or initial.R, not both");
  if (!quat && !mat) throw InputError(path + ": missing key 'initial.rotation' (quaternion [w, x, y, z]) or 'initial.R'");
  if (quat) {
    s.q = r.vector(*quat, "initial.rotation");
    if (s.q.size() != 4)
      throw InputError(r.where(quat, "initial.rotation") + ": got " + std::to_string(s.q.size()) +
                       " numbers, expected 4 (a unit quaternion [w, x, y, z])");
    const double n = std::sqrt(s.q[0] * s.q[0] + s.q[1] * s.q[1] + s.q[2] * s.q[2] + s.q[3] * s.q[3]);
    if (!(std::fabs(n - 1.0) <= 1e-12))
      throw InputError(r.where(quat, "initial.rotation") + ": not a unit quaternion (| |q| - 1 | = " +
                       fmt(std::fabs(n - 1.0)) + "); expected norm 1 to 1e-12");
  } else {
    auto rows = mat->as_array();
    if (!rows || rows->size() != 3)
      throw InputError(r.where(mat, "initial.R") + ": expected a 3x3 matrix [[r11, r12, r13], [...], [...]]");
    double R[3][3];
    for (std::size_t i = 0; i < 3; ++i) {
      const std::vector<double> row = r.vector(*rows->get(i), "initial.R[" + std::to_string(i) + "]");
      if (row.size() != 3) throw InputError(r.where(mat, "initial.R") + ": expected 3 numbers in each row");
      for (int j = 0; j < 3; ++j) R[i][j] = row[static_cast<std::size_t>(j)];
    }
    double defect = 0.0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double d = (i == j) ? -1.0 : 0.0;
        for (int k = 0; k < 3; ++k) d += R[k][i] * R[k][j];
        defect = std::fmax(defect, std::fabs(d));
      }
    const double det = R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1]) -
                       R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0]) +
                       R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]);
    if (!(defect <= 1e-12) || !(std::fabs(det - 1.0) <= 1e-12))
      throw InputError(r.where(mat, "initial.R") + ": not a rotation (|R^T R - I| = " + fmt(defect) +
                       ", det R = " + fmt(det) + "); expected an orthogonal matrix with determinant 1 to 1e-12");
    // store as the quaternion (w >= 0) of R
    const double w = 0.5 * std::sqrt(std::fmax(0.0, 1.0 + R[0][0] + R[1][1] + R[2][2]));
    double x, y, z;
    if (w > 0.1) {
      x = (R[2][1] - R[1][2]) / (4 * w);
      y = (R[0][2] - R[2][0]) / (4 * w);
      z = (R[1][0] - R[0][1]) / (4 * w);
    } else {  // near a half turn: from the largest diagonal entry
      const int k = R[0][0] >= R[1][1] && R[0][0] >= R[2][2] ? 0 : (R[1][1] >= R[2][2] ? 1 : 2);
      const int i1 = (k + 1) % 3, i2 = (k + 2) % 3;
      double a[3];
      a[k] = 0.5 * std::sqrt(std::fmax(0.0, 1.0 + R[k][k] - R[i1][i1] - R[i2][i2]));
      a[i1] = (R[i1][k] + R[k][i1]) / (4 * a[k]);
      a[i2] = (R[i2][k] + R[k][i2]) / (4 * a[k]);
      const double ww = (R[i2][i1] - R[i1][i2]) / (4 * a[k]);
      x = a[0];
      y = a[1];
      z = a[2];
      const double sign = ww < 0 ? -1.0 : 1.0;
      s.q = {sign * ww, sign * x, sign * y, sign * z};
    }
    if (w > 0.1) s.q = {w, x, y, z};
  }
  const toml::node* om = ini.get("omega");
  const toml::node* pi = ini.get("pi");
  if (om && pi) throw InputError(r.where(pi, "initial.pi") + ": give either initial.omega or initial.pi, not both");
  if (!om && !pi) throw InputError(path + ": missing key 'initial.omega' (body angular velocity) or 'initial.pi'");
  const toml::node* n = om ? om : pi;
  const std::string key = om ? "initial.omega" : "initial.pi";
  (om ? s.v : s.p) = r.vector(*n, key);
  s.momentum_given = pi != nullptr;
  if ((om ? s.v : s.p).size() != 3)
    throw InputError(r.where(n, key) + ": got " + std::to_string((om ? s.v : s.p).size()) + " numbers, expected 3");
}

// The dimension of the scene's system: fixed, or params.n for the chain.
int resolve_dimension(const std::string& path, const SystemInfo& info, const std::map<std::string, double>& params) {
  if (info.dim > 0) return info.dim;
  const double n = params.at("n");
  if (!(n >= 1.0 && n <= 1e7) || n != std::floor(n))
    throw InputError(path + ": key 'system.params.n': got " + std::to_string(n) +
                     ", expected a whole number of particles from 1 to 10000000");
  const double fixed = params.at("fixed");
  if (fixed != 0.0 && fixed != 1.0)
    throw InputError(path + ": key 'system.params.fixed': got " + std::to_string(fixed) +
                     ", expected 1 (ends tied to walls) or 0 (free ends)");
  return static_cast<int>(n);
}

// [problem] (issue 3): kind, and q_final and steps for a boundary-value problem.
void read_problem(const Reader& r, const toml::table& root, Scene& s, int dim) {
  const toml::table& pr = r.section(root, "problem", false);
  r.only_keys(pr, "problem", {"kind", "q_final", "steps"});
  if (const toml::node* k = pr.get("kind")) {
    s.problem = r.string(*k, "problem.kind");
    if (s.problem != "initial-value" && s.problem != "boundary-value")
      throw InputError(r.where(k, "problem.kind") + ": got \"" + s.problem +
                       "\", expected \"initial-value\" or \"boundary-value\"");
  }
  const toml::node* qf = pr.get("q_final");
  const toml::node* st = pr.get("steps");
  if (s.problem == "initial-value") {
    if (qf) throw InputError(r.where(qf, "problem.q_final") + ": applies only to kind = \"boundary-value\"");
    if (st) throw InputError(r.where(st, "problem.steps") + ": applies only to kind = \"boundary-value\"");
    return;
  }
  if (!qf) throw InputError(r.path() + ": missing key 'problem.q_final' (the end point of a boundary-value problem)");
  if (!st) throw InputError(r.path() + ": missing key 'problem.steps' (the number of steps between the end points)");
  s.q_final = r.vector(*qf, "problem.q_final");
  if (static_cast<int>(s.q_final.size()) != dim)
    throw InputError(r.where(qf, "problem.q_final") + ": got " + std::to_string(s.q_final.size()) +
                     " numbers, expected " + std::to_string(dim) + " (the dimension of " + s.system + ")");
  s.steps = r.integer(*st, "problem.steps", 2);
  if (s.steps > 100000000)
    throw InputError(r.where(st, "problem.steps") + ": got " + Reader::describe(*st) +
                     ", expected a whole number from 2 to 100000000");
}

// [integrator] form, gamma, beta (issue 3).
// [integrator] method, stages, quadrature (Galerkin discrete Lagrangians). Read after
// the form and the problem, whose values it checks.
void read_galerkin(const Reader& r, const toml::table& in, const SystemInfo& info, Scene& s) {
  const toml::node* me = in.get("method");
  if (me) {
    s.method = r.string(*me, "integrator.method");
    if (s.method != "map" && s.method != "galerkin")
      throw InputError(r.where(me, "integrator.method") + ": got \"" + s.method +
                       "\", expected \"map\" (the map's own step) or \"galerkin\" (Galerkin discrete Lagrangians)");
  }
  const bool galerkin = s.method == "galerkin";
  for (const char* key : {"stages", "quadrature"}) {
    const toml::node* n = in.get(key);
    if (n && !galerkin)
      throw InputError(r.where(n, std::string("integrator.") + key) + ": " + key +
                       " applies only to method = \"galerkin\", not \"" + s.method + "\"");
  }
  if (!galerkin) return;
  if (const toml::node* st = in.get("stages")) {
    const std::int64_t k = r.integer(*st, "integrator.stages", 1);
    if (k > 6)
      throw InputError(r.where(st, "integrator.stages") + ": got " + Reader::describe(*st) +
                       ", expected a whole number from 1 to 6");
    s.stages = static_cast<int>(k);
  }
  if (const toml::node* qu = in.get("quadrature")) {
    s.quadrature = r.string(*qu, "integrator.quadrature");
    if (s.quadrature != "gauss" && s.quadrature != "lobatto")
      throw InputError(r.where(qu, "integrator.quadrature") + ": got \"" + s.quadrature +
                       "\", expected \"gauss\" (s points) or \"lobatto\" (s + 1 points)");
  }
  std::string why;
  // on S^2 and SO(3) the step is solved in the chart centred at the current point
  // (solvers/manifold_galerkin_step.h); the chain of spherical pendulums is refused
  if (info.name == "spherical-chain")
    why = "the spherical chain takes no method = \"galerkin\" (the chart step is built for the spherical pendulum, "
          "the rigid body and the heavy top; the chain's 2n-dimensional chart Lagrangian is not wired)";
  else if (s.form != "lagrangian")
    why = "method = \"galerkin\" is a discrete Lagrangian: it runs the lagrangian form only, not form = \"" + s.form +
          "\"";
  else if (s.problem != "initial-value")
    why = "a boundary-value problem takes no method = \"galerkin\"";
  else if (s.system == "chain")
    why = "the chain (a dynamic-size system) takes no method = \"galerkin\"";
  if (!why.empty()) throw InputError(r.where(me, "integrator.method") + ": " + why);
}

void read_form(const Reader& r, const toml::table& in, Scene& s) {
  if (const toml::node* f = in.get("form")) {
    s.form = r.string(*f, "integrator.form");
    if (s.form != "lagrangian" && s.form != "hamiltonian" && s.form != "sode1" && s.form != "sode2" &&
        s.form != "newmark")
      throw InputError(r.where(f, "integrator.form") + ": got \"" + s.form +
                       "\", expected one of: lagrangian, hamiltonian, sode1, sode2, newmark");
  }
  for (const char* key : {"gamma", "beta"}) {
    const toml::node* n = in.get(key);
    if (!n) continue;
    const std::string name = std::string("integrator.") + key;
    if (s.form != "newmark")
      throw InputError(r.where(n, name) + ": " + key + " applies only to form = \"newmark\", not \"" + s.form +
                       "\"");
    const double x = r.number(*n, name);
    const bool gamma = std::string(key) == "gamma";
    if (gamma ? !(x >= 0.0 && x <= 1.0) : !(x >= 0.0 && x <= 0.5))
      throw InputError(r.where(n, name) + ": got " + Reader::describe(*n) + ", expected a number in " +
                       (gamma ? "[0, 1]" : "[0, 0.5]"));
    (gamma ? s.newmark_gamma : s.newmark_beta) = x;
  }
  if (s.problem == "boundary-value" && s.form != "lagrangian")
    throw InputError(r.path() + ": key 'integrator.form': a boundary-value problem solves the discrete "
                                "Euler-Lagrange equations; expected form = \"lagrangian\", got \"" +
                     s.form + "\"");
  if (s.system == "chain") {
    if (s.form != "lagrangian")
      throw InputError(r.path() + ": key 'integrator.form': the chain (a dynamic-size system) runs the "
                                  "lagrangian form only, got \"" + s.form + "\"");
    if (s.problem != "initial-value")
      throw InputError(r.path() + ": key 'problem.kind': the chain runs initial-value problems only");
  }
}

}  // namespace

namespace {

void check_toml_text(const std::string& text, const std::string& path);
Scene validate_scene(toml::table& root, const std::string& path, const std::vector<std::string>& overrides);

// toml++ 3.3 (Debian bookworm's) reaches TOML_UNREACHABLE - undefined behaviour - in
// is_non_ascii_horizontal_whitespace for the code points U+00A1..U+0499,
// U+2C5E..U+2FFF, U+3001..U+3057 and U+FB26..U+FEFE (its generated range table misses
// them; the list is every code point for which that function's branches reach it), which
// its parser asks about wherever whitespace may stand: in a valid scene at a line's
// start, in a malformed one after almost any token. Found by fuzzing (tests/fuzz).
// Text holding one of them, or a NUL (never valid TOML), is refused here, before the
// parser sees it, with the line and column (in code points, as toml++ counts).
void check_toml_text(const std::string& text, const std::string& path) {
  std::size_t line = 1, column = 1;
  const std::size_t n = text.size();
  auto cont = [&](std::size_t k) { return k < n && (static_cast<unsigned char>(text[k]) & 0xC0) == 0x80; };
  for (std::size_t i = 0; i < n;) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    std::uint32_t cp = c;
    std::size_t len = 1;
    if (c >= 0xC0 && c < 0xE0 && cont(i + 1)) {
      cp = ((c & 0x1Fu) << 6) | (static_cast<unsigned char>(text[i + 1]) & 0x3Fu), len = 2;
    } else if (c >= 0xE0 && c < 0xF0 && cont(i + 1) && cont(i + 2)) {
      cp = ((c & 0x0Fu) << 12) | ((static_cast<unsigned char>(text[i + 1]) & 0x3Fu) << 6) |
           (static_cast<unsigned char>(text[i + 2]) & 0x3Fu), len = 3;
    } else if (c >= 0xF0 && c < 0xF8 && cont(i + 1) && cont(i + 2) && cont(i + 3)) {
      cp = ((c & 0x07u) << 18) | ((static_cast<unsigned char>(text[i + 1]) & 0x3Fu) << 12) |
           ((static_cast<unsigned char>(text[i + 2]) & 0x3Fu) << 6) | (static_cast<unsigned char>(text[i + 3]) & 0x3Fu),
      len = 4;
    }
    const std::string where = path + ":" + std::to_string(line) + ":" + std::to_string(column) + ": ";
    if (cp == 0) throw InputError(where + "a NUL character; expected TOML text");
    if ((cp >= 0xA1 && cp <= 0x499) || (cp >= 0x2C5E && cp <= 0x2FFF) || (cp >= 0x3001 && cp <= 0x3057) ||
        (cp >= 0xFB26 && cp <= 0xFEFE)) {
      char u[16];
      std::snprintf(u, sizeof u, "U+%04X", static_cast<unsigned>(cp));
      throw InputError(where + "the character " + u + ", which the TOML parser in use (toml++ 3.3) cannot read "
                       "safely (nor any in U+00A1-U+0499, U+2C5E-U+2FFF, U+3001-U+3057, U+FB26-U+FEFE); expected other "
                       "text (ASCII is always fine)");
    }
    if (cp == '\n') ++line, column = 0;
    ++column;
    i += len;
  }
}

InputError parse_failure(const std::string& path, const toml::parse_error& e) {
  std::ostringstream msg;
  msg << path;
  if (e.source().begin.line > 0) msg << ":" << e.source().begin.line << ":" << e.source().begin.column;
  msg << ": " << e.description();
  return InputError(msg.str());
}

}  // namespace

Scene load_scene(const std::string& path, const std::vector<std::string>& overrides) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open the scene file (" + std::strerror(errno) + ")");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw InputError(path + ": cannot read the scene file");
  return load_scene_text(text.str(), path, overrides);
}

Scene load_scene_text(const std::string& text, const std::string& path, const std::vector<std::string>& overrides) {
  check_toml_text(text, path);
  toml::table root;
  try {
    root = toml::parse(std::string_view(text), std::string_view(path));
  } catch (const toml::parse_error& e) {
    throw parse_failure(path, e);
  }
  return validate_scene(root, path, overrides);
}

namespace {

Scene validate_scene(toml::table& root, const std::string& path, const std::vector<std::string>& overrides) {
  for (const auto& o : overrides) apply_override(root, o);

  Reader r(path);
  Scene s;
  s.path = path;
  for (const auto& [k, v] : root) {
    const std::string name(k.str());
    if (name != "system" && name != "initial" && name != "integrator" && name != "output" && name != "problem")
      throw InputError(r.where(&v, name) + ": unknown section; expected system, initial, integrator, output, problem");
  }

  // [system]
  const toml::table& sys = r.section(root, "system", true);
  r.only_keys(sys, "system", {"builtin", "params", "lagrangian", "coordinates", "energy", "hamiltonian", "name", "masses"});
  if (sys.get("lagrangian")) read_written_system(path, sys, s);
  const toml::node* b = sys.get("builtin");
  if (!b && !s.written)
    throw InputError(path + ": missing key 'system.builtin' (a built-in system name) or 'system.lagrangian'");
  static const SystemInfo written_info{"lagrangian", 0, "", {}};
  const SystemInfo& info =
      s.written ? written_info : find_system(r.string(*b, "system.builtin"), r.where(b, "system.builtin"));
  if (!s.written) {
    for (const char* k : {"coordinates", "energy", "hamiltonian", "name"})
      if (const toml::node* n = sys.get(k))
        throw InputError(r.where(n, std::string("system.") + k) + ": belongs to a written system (system.lagrangian)");
    s.system = info.name;
    s.dim = info.dim;
    const toml::node* ms = sys.get("masses");
    if (info.name == "nbody") {
      if (!ms) throw InputError(path + ": missing key 'system.masses' (nbody: one mass per body, 2 to 6 bodies)");
      s.masses = r.vector(*ms, "system.masses");
      if (s.masses.size() < 2 || s.masses.size() > 6)
        throw InputError(r.where(ms, "system.masses") + ": got " + std::to_string(s.masses.size()) +
                         " masses, expected 2 to 6 bodies");
      for (double m : s.masses)
        if (!(m > 0.0)) throw InputError(r.where(ms, "system.masses") + ": expected positive masses");
      s.dim = 3 * static_cast<int>(s.masses.size());
    } else if (ms) {
      throw InputError(r.where(ms, "system.masses") + ": only builtin = \"nbody\" takes masses");
    }
  }
  for (const auto& p : info.params) s.params[p.name] = p.default_value;
  if (const toml::node* params = s.written ? nullptr : sys.get("params")) {
    if (!params->is_table()) throw InputError(r.where(params, "system.params") + ": expected a table of numbers");
    for (const auto& [k, v] : *params->as_table()) {
      const std::string name(k.str());
      if (!s.params.count(name)) {
        std::vector<std::string> names;
        for (const auto& p : info.params) names.push_back(p.name);
        throw InputError(r.where(&v, "system.params." + name) + ": unknown parameter of " + info.name +
                         "; expected one of: " + join_names(names));
      }
      s.params[name] = r.number(v, "system.params." + name);
    }
  }

  if (info.name == "chain") s.dim = resolve_dimension(path, info, s.params);
  if (info.space != "R^n") {
    const auto kind = root["problem"]["kind"].value<std::string>();
    if (kind && *kind == "boundary-value" && info.name != "spherical-pendulum")
      throw InputError(r.where(root["problem"]["kind"].node(), "problem.kind") +
                       ": boundary-value problems run on R^n systems and the spherical pendulum only, not on " +
                       info.space + " (" + info.name + ")");
  }
  read_problem(r, root, s, s.dim);
  const bool boundary_value = s.problem == "boundary-value";
  int links = 1;
  if (info.name == "spherical-chain") {
    const double n = s.params["n"];
    if (n != std::floor(n) || n < 1 || n > 4)
      throw InputError(path + ": key 'system.params.n': got " + fmt(n) + ", expected a whole number from 1 to 4");
    links = static_cast<int>(n);
  }

  // [initial]
  s.space = info.space;
  const toml::table& ini = r.section(root, "initial", true);
  if (info.space == "SO(3)")
    read_rotation_initial(r, ini, path, s);
  else
    read_vector_initial(r, ini, path, info, s.dim * links, boundary_value, s);
  if (boundary_value && info.space == "S^2") {
    // both end points on the sphere, not projected onto it
    for (const auto* end : {&s.q, &s.q_final}) {
      const auto& x = *end;
      const double defect = std::fabs(std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - 1.0);
      if (!(defect <= 1e-12))
        throw InputError(path + ": key '" + (end == &s.q ? "initial.q" : "problem.q_final") +
                         "': not a unit vector (| |q| - 1 | = " + fmt(defect) + "); expected a point of S^2 to 1e-12");
    }
  }

  // [integrator]
  const toml::table& in = r.section(root, "integrator", true);
  r.only_keys(in, "integrator", {"map", "theta", "step", "steps", "t_end", "solver", "max_iterations", "tolerance",
                                  "composition", "form", "gamma", "beta", "method", "stages", "quadrature"});
  read_form(r, in, s);
  read_galerkin(r, in, info, s);
  if (info.space != "R^n" && s.form != "lagrangian" && s.form != "hamiltonian")
    throw InputError(path + ": key 'integrator.form': systems on " + info.space +
                     " run the lagrangian and hamiltonian forms only, got \"" + s.form + "\"");
  const toml::node* m = in.get("map");
  if (!m && s.form != "newmark" && s.method != "galerkin") throw InputError(path + ": missing key 'integrator.map'");
  if (m) {
    // newmark is its own discretization (gamma, beta) and uses no map; a map named in
    // the scene is still validated, so that --set integrator.form=newmark works on
    // any scene without hiding a typo.
    const MapInfo& map_info = find_map(r.string(*m, "integrator.map"), r.where(m, "integrator.map"));
    s.map = map_info.name;
    if (map_info.space != info.space) {
      std::vector<std::string> fitting;
      for (const auto& mi : maps())
        if (mi.space == info.space) fitting.push_back(mi.name);
      throw InputError(r.where(m, "integrator.map") + ": map \"" + s.map + "\" lives on " + map_info.space + " but " +
                       info.name + " lives on " + info.space + "; expected one of: " + join_names(fitting));
    }
    if (s.system == "chain" && s.map == "retraction-theta")
      throw InputError(r.where(m, "integrator.map") +
                       ": the chain runs the theta-family maps (explicit-euler, adjoint-euler, midpoint, theta), "
                       "got \"retraction-theta\"");
  }
  if (const toml::node* th = in.get("theta")) {
    if (s.map != "theta" && s.map != "retraction-theta")
      throw InputError(r.where(th, "integrator.theta") + ": theta applies only to map = \"theta\" or "
                                                         "\"retraction-theta\", not \"" + s.map + "\"");
    s.theta = r.number(*th, "integrator.theta");
    if (!(s.theta >= 0.0 && s.theta <= 1.0))
      throw InputError(r.where(th, "integrator.theta") + ": got " + Reader::describe(*th) +
                       ", expected a number in [0, 1]");
  }
  const toml::node* h = in.get("step");
  if (!h) throw InputError(path + ": missing key 'integrator.step'");
  s.step = r.number(*h, "integrator.step");
  if (!(s.step > 0.0))
    throw InputError(r.where(h, "integrator.step") + ": got " + Reader::describe(*h) + ", expected a positive number");
  const toml::node* n = in.get("steps");
  const toml::node* te = in.get("t_end");
  if (n && te) throw InputError(r.where(te, "integrator.t_end") + ": give either integrator.steps or integrator.t_end, not both");
  if (boundary_value && (n || te))
    throw InputError(r.where(n ? n : te, n ? "integrator.steps" : "integrator.t_end") +
                     ": a boundary-value problem takes its number of steps from problem.steps");
  if (!n && !te && !boundary_value) throw InputError(path + ": missing key 'integrator.steps' or 'integrator.t_end'");
  if (boundary_value) {
    // s.steps was read from problem.steps
  } else if (n) {
    s.steps = r.integer(*n, "integrator.steps", 1);
  } else {
    const double t_end = r.number(*te, "integrator.t_end");
    if (!(t_end > 0.0))
      throw InputError(r.where(te, "integrator.t_end") + ": got " + Reader::describe(*te) + ", expected a positive number");
    const double count = std::round(t_end / s.step);
    if (!(count >= 1.0) || count > 9e15)
      throw InputError(r.where(te, "integrator.t_end") + ": t_end / step = " + std::to_string(t_end / s.step) +
                       ", expected between 1 and 9e15 steps");
    if (std::fabs(count * s.step - t_end) > 1e-9 * t_end)
      throw InputError(r.where(te, "integrator.t_end") + ": t_end = " + Reader::describe(*te) +
                       " is not a whole number of steps of " + Reader::describe(*h) +
                       "; expected t_end = k * step (or give integrator.steps)");
    s.steps = static_cast<std::int64_t>(count);
  }
  if (!boundary_value) {
    // t_k = k h is formed from k as a double: beyond 2^53 steps k is not exact, and
    // k h must stay finite
    const toml::node* count_node = n ? n : te;
    const std::string count_key = n ? "integrator.steps" : "integrator.t_end";
    if (s.steps > kMaxSteps)
      throw InputError(r.where(count_node, count_key) + ": got " + std::to_string(s.steps) +
                       " steps, expected at most 2^53 = " + std::to_string(kMaxSteps) +
                       " (beyond that the step index is not exact in t = k h)");
    if (!std::isfinite(static_cast<double>(s.steps) * s.step))
      throw InputError(r.where(count_node, count_key) + ": " + std::to_string(s.steps) + " steps of " +
                       Reader::describe(*h) + " overflow the time (t_end = inf); expected a finite t_end");
  }
  if (const toml::node* so = in.get("solver")) {
    s.solver = r.string(*so, "integrator.solver");
    if (s.solver != "newton" && s.solver != "tiny")
      throw InputError(r.where(so, "integrator.solver") + ": got \"" + s.solver + "\", expected \"newton\" or \"tiny\"");
  }

  if (const toml::node* mi = in.get("max_iterations")) {
    const std::int64_t m_it = r.integer(*mi, "integrator.max_iterations", 1);
    if (m_it > 1000)
      throw InputError(r.where(mi, "integrator.max_iterations") + ": got " + Reader::describe(*mi) +
                       ", expected a whole number from 1 to 1000");
    s.max_iterations = static_cast<int>(m_it);
  }
  if (const toml::node* tol = in.get("tolerance")) {
    s.tolerance = r.number(*tol, "integrator.tolerance");
    if (!(s.tolerance > 0.0 && s.tolerance < 1.0))
      throw InputError(r.where(tol, "integrator.tolerance") + ": got " + Reader::describe(*tol) +
                       ", expected a number in (0, 1) (relative residual tolerance)");
  }
  if (const toml::node* co = in.get("composition")) {
    s.composition = r.string(*co, "integrator.composition");
    if (s.composition != "none") {
      try {
        find_composition(s.composition);
      } catch (const std::invalid_argument& e) {
        throw InputError(r.where(co, "integrator.composition") + ": got \"" + s.composition + "\"; " + e.what());
      }
      // compositions compose one-step maps: every initial-value form on R^n and the
      // (lagrangian-form) steps on S^2, (S^2)^n and SO(3); not whole trajectories, and
      // not the dynamic-size chain
      std::string why;
      if (s.problem != "initial-value") why = "a boundary-value problem takes no composition";
      else if (s.system == "chain") why = "the chain (a dynamic-size system) takes no composition yet";
      else if (info.space != "R^n" && s.form != "lagrangian")
        why = "on " + info.space + " compositions compose the lagrangian form's step only, not form = \"" + s.form + "\"";
      if (!why.empty()) throw InputError(r.where(co, "integrator.composition") + ": " + why);
      if (s.method == "galerkin")
        throw InputError(r.where(co, "integrator.composition") + ": method = \"galerkin\" takes no composition (it "
                                                                 "reaches high order itself: order 2 stages)");
    }
  }

  // [output]
  const toml::table& out = r.section(root, "output", false);
  r.only_keys(out, "output", {"csv", "every", "npy"});
  if (const toml::node* c = out.get("npy")) {
    s.npy = r.string(*c, "output.npy");
    if (s.npy.empty()) throw InputError(r.where(c, "output.npy") + ": expected a file name, got an empty string");
  }
  if (const toml::node* c = out.get("csv")) {
    s.csv = r.string(*c, "output.csv");
    if (s.csv.empty()) throw InputError(r.where(c, "output.csv") + ": expected a file name, got an empty string");
  }
  if (const toml::node* e = out.get("every")) s.every = r.integer(*e, "output.every", 1);
  return s;
}

}  // namespace

}  // namespace dvm::cli
