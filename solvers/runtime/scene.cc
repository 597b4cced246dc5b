#include "solvers/runtime/scene.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <utility>

#include <toml++/toml.h>

#include "solvers/runtime/scene_written.h"
#include "mechanics/written_lagrangian.h"
#include "mechanics/written_retraction.h"
#include "solvers/runtime/registry.h"

namespace dvm {

namespace {

std::string fmt(double x) {
  std::ostringstream out;
  out.precision(3);
  out << x;
  return out.str();
}

}  // namespace

namespace {

std::string join_names(const std::vector<std::string>& names) {
  std::string out;
  for (std::size_t i = 0; i < names.size(); ++i) out += (i ? ", " : "") + names[i];
  return out;
}

}  // namespace

namespace {

void check_toml_text(const std::string& text, const std::string& path);

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
    out << ": key '" << echo(key) << "'";
    return out.str();
  }

  // A value given by --set (overrides carry no source position).
  static bool from_override(const toml::node* n) { return n && n->source().begin.line == 0; }

  static std::string describe(const toml::node& n) {
    std::ostringstream out;
    if (n.is_string())
      out << '"' << echo(n.value<std::string>().value_or("")) << '"';
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
                         "] takes: " + join_names(names) + did_you_mean(std::string(k.str()), names));
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
    throw InputError("--set: expected section.key=value, got '" + echo(spec) + "'");
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
    throw InputError("--set: expected section.key=value, got '" + echo(spec) + "' (the key needs a section)");
  if (parts.size() > kMaxKeyParts)
    throw InputError("--set: the key '" + echo(key) + "' has " + std::to_string(parts.size()) + " parts; at most " +
                     std::to_string(kMaxKeyParts) + " are accepted");
  for (const auto& p : parts)
    if (p.empty()) throw InputError("--set: empty key component in '" + echo(spec) + "'");
  toml::table parsed;
  try {
    const std::string doc = "value = " + value;
    check_toml_text(doc, "--set " + echo(key));
    parsed = toml::parse(std::string_view(doc), std::string_view("--set"));
    // "0.5\njunk = 1" parses as a document of two keys: one value only
    if (parsed.size() != 1)
      throw InputError("--set " + echo(key) + ": value '" + echo(value) +
                       "' is not one TOML value (more text follows it, on another line); expected one value");
  } catch (const toml::parse_error& e) {
    // A bare word (--set integrator.map=theta) is taken as a string, so that shells
    // need no nested quotes; anything else must be a TOML value.
    const bool bare = !value.empty() && std::isalpha(static_cast<unsigned char>(value[0])) &&
                      value.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-./") ==
                          std::string::npos;
    if (!bare)
      throw InputError("--set " + echo(key) + ": value '" + echo(value) + "' is not a TOML value (" +
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
    if (!n->is_table()) throw InputError("--set " + echo(key) + ": '" + echo(parts[i]) + "' is not a table");
    t = n->as_table();
  }
  // Overrides carry no source position, which where() reports as "(from --set)".
  t->insert_or_assign(parts.back(), *parsed.get("value"));
}


// What a vector of the state holds, for messages: "the dimension of kepler", or for a
// written system its coordinates by name, "one per coordinate: r, phi" (an array as
// q[1] ... q[n]).
std::string dimension_of(const Problem& s) {
  const WrittenSystem* w = s.written.get();
  if (!w || w->coordinates.empty() || w->space == WrittenSystem::Space::rotation)
    return "the dimension of " + (s.system ? s.system->name : std::string("the system"));
  std::string names;
  int shown = 0;
  for (int i = 0; i < static_cast<int>(w->coordinates.size()); ++shown) {
    if (shown == 12) {
      names += ", ...";
      break;
    }
    names += shown ? ", " : "";
    if (const auto* a = w->array_of(i)) {
      names += a->size == 1 ? a->name + "[1]" : a->name + "[1] ... " + a->name + "[" + std::to_string(a->size) + "]";
      i = a->offset + a->size;
    } else {
      names += w->coordinates[static_cast<std::size_t>(i++)];
    }
  }
  return "one per coordinate: " + names;
}

// An initial vector of `dim` numbers: an array of numbers; on R^n a string, an
// expression in the index i = 1 ... dim and the system's parameters (lists included,
// for a written system), evaluated at each i: "0.1*sin(pi*i/(n+1))"; on (S^2)^n an
// array of three such strings, the x, y and z of link i = 1 ... dim / 3.
std::vector<double> initial_vector(const Reader& r, const std::string& path, const toml::node& n,
                                   const std::string& key, const Problem& s, Space space) {
  const toml::array* per_link = n.as_array();
  const bool link_strings = per_link && !per_link->empty() && per_link->front().is_string();
  if (!n.is_string() && !link_strings) return r.vector(n, key);
  if (n.is_string() && space != Space::euclidean)
    throw InputError(r.where(&n, key) + ": one expression in i is taken on R^n; on (S^2)^n give three, "
                     "[\"x\", \"y\", \"z\"] of link i, or the numbers");
  if (link_strings && (space != Space::sphere || per_link->size() != 3))
    throw InputError(r.where(&n, key) + ": a list of expressions is taken on S^2 and (S^2)^n, three of them "
                     "(x, y and z of link i); got " + std::to_string(per_link->size()) +
                     (space == Space::sphere ? "" : " on this space (R^n takes one string, SO(3) numbers)"));
  ExpressionSymbols sym;
  sym.variables.push_back({"i", 0, 0});
  for (const auto& [name, value] : s.params) {
    if (name == "i")
      throw InputError(r.where(&n, key) + ": the parameter 'i' would hide the index i of the expression; rename it");
    sym.constants.emplace_back(name, value);
  }
  if (s.written) sym.constant_arrays = s.written->param_arrays;
  for (const auto& a : sym.constant_arrays)
    if (a.name == "i")
      throw InputError(r.where(&n, key) + ": the parameter list 'i' would hide the index i of the expression; rename it");
  // each expression's node and text; a string alone gives every coordinate, a list
  // of three the components of every link
  std::vector<const toml::node*> nodes;
  if (link_strings)
    for (const toml::node& e : *per_link) {
      if (!e.is_string())
        throw InputError(r.where(&e, key) + ": expected three strings, expressions in the link index i");
      nodes.push_back(&e);
    }
  else
    nodes.push_back(&n);
  const int count = link_strings ? s.dim / 3 : s.dim;
  const std::string range = std::string("i = 1 ... ") + std::to_string(count);
  std::vector<double> out(static_cast<std::size_t>(s.dim));
  for (std::size_t c = 0; c < nodes.size(); ++c) {
    const toml::node& node = *nodes[c];
    const std::string text = *node.value<std::string>();
    Expression e;
    try {
      e = Expression::parse(text, sym);
    } catch (const ExpressionError& err) {
      throw InputError(string_location(path, node, err.offset) + ": in " + key + " (an expression in " + range +
                       " and the parameters): " + err.what());
    }
    for (int i = 1; i <= count; ++i) {
      const double x = static_cast<double>(i);
      const std::size_t k = static_cast<std::size_t>(link_strings ? 3 * (i - 1) + static_cast<int>(c) : i - 1);
      out[k] = e(&x);
      if (!std::isfinite(out[k]))
        throw InputError(r.where(&node, key) + ": the expression is not finite at i = " + std::to_string(i));
    }
  }
  return out;
}

// [initial] for systems on R^n and S^2: q and one of p, v, each of length dim (a
// boundary-value problem takes q only). On S^2 each block of 3 is a unit vector and
// p or v is tangent to it.
void read_vector_initial(const Reader& r, const toml::table& ini, const std::string& path, const SystemEntry& info,
                         int dim, bool boundary_value, Problem& s) {
  const int links = info.space == Space::sphere ? dim / 3 : 1;
  r.only_keys(ini, "initial", {"q", "p", "v", "project_velocity"});
  if (const toml::node* pv = ini.get("project_velocity")) {
    if (!pv->is_boolean()) throw InputError(r.where(pv, "initial.project_velocity") + ": expected true or false");
    s.project_velocity = *pv->value<bool>();
    s.project_velocity_where = r.where(pv, "initial.project_velocity");
  }
  const toml::node* q = ini.get("q");
  if (!q) throw InputError(path + ": missing key 'initial.q'");
  s.q = initial_vector(r, path, *q, "initial.q", s, info.space);
  const std::string n_expected = std::to_string(dim);
  if (static_cast<int>(s.q.size()) != dim)
    throw InputError(r.where(q, "initial.q") + ": got " + std::to_string(s.q.size()) + " numbers, expected " +
                     n_expected + " (" + dimension_of(s) + ")");
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
  (p ? s.p : s.v) = initial_vector(r, path, *pv, pv_key, s, info.space);
  s.momentum_given = p != nullptr;
  if (static_cast<int>((p ? s.p : s.v).size()) != dim)
    throw InputError(r.where(pv, pv_key) + ": got " + std::to_string((p ? s.p : s.v).size()) + " numbers, expected " +
                     n_expected + " (" + dimension_of(s) + ")");
  for (int k = 0; info.space == Space::sphere && k < links; ++k) {
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
void read_rotation_initial(const Reader& r, const toml::table& ini, const std::string& path, Problem& s) {
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


// The number of coordinates of a system whose size comes from its parameters.
// `params` is the scene's [system] params table (null when absent): messages point at
// the key when the scene gave it, else at the file (a default value).
int resolve_dimension(const Reader& r, const toml::node* params, const SystemEntry& info,
                      const std::map<std::string, double>& values) {
  auto where = [&](const std::string& name) {
    const toml::node* n = params && params->is_table() ? params->as_table()->get(name) : nullptr;
    return n ? r.where(n, "system.params." + name) : r.path() + ": key 'system.params." + name + "' (default)";
  };
  if (info.name == "chain") {
    const double n = values.at("n");
    if (!(n >= 1.0 && n <= 1e7) || n != std::floor(n))
      throw InputError(where("n") + ": got " + fmt(n) + ", expected a whole number of particles from 1 to 10000000");
    const double fixed = values.at("fixed");
    if (fixed != 0.0 && fixed != 1.0)
      throw InputError(where("fixed") + ": got " + fmt(fixed) + ", expected 1 (ends tied to walls) or 0 (free ends)");
    return static_cast<int>(n);
  }
  if (info.name == "spherical-chain") {
    const double n = values.at("n");
    if (n != std::floor(n) || n < 1 || n > 1e6)
      throw InputError(where("n") + ": got " + fmt(n) + ", expected a whole number of links from 1 to 1000000");
    return 3 * static_cast<int>(n);
  }
  return info.dim;
}

// [problem]: kind, and q_final and steps for a boundary-value problem.
void read_problem(const Reader& r, const toml::table& root, Problem& s, int dim) {
  const toml::table& pr = r.section(root, "problem", false);
  r.only_keys(pr, "problem", {"kind", "q_final", "steps"});
  if (const toml::node* k = pr.get("kind")) {
    const std::string kind = r.string(*k, "problem.kind");
    if (kind != "initial-value" && kind != "boundary-value")
      throw InputError(r.where(k, "problem.kind") + ": got \"" + echo(kind) +
                       "\", expected \"initial-value\" or \"boundary-value\"" +
                       did_you_mean(kind, {"initial-value", "boundary-value"}));
    s.boundary_value = kind == "boundary-value";
    if (s.boundary_value) {
      try {
        require_boundary_value(*s.system);
      } catch (const InputError& e) {
        const std::string msg = e.what();
        throw InputError(r.where(k, "problem.kind") + msg.substr(msg.find(':')));
      }
    }
  }
  const toml::node* qf = pr.get("q_final");
  const toml::node* st = pr.get("steps");
  if (!s.boundary_value) {
    if (qf) throw InputError(r.where(qf, "problem.q_final") + ": applies only to kind = \"boundary-value\"");
    if (st) throw InputError(r.where(st, "problem.steps") + ": applies only to kind = \"boundary-value\"");
    return;
  }
  if (!qf) throw InputError(r.path() + ": missing key 'problem.q_final' (the end point of a boundary-value problem)");
  if (!st) throw InputError(r.path() + ": missing key 'problem.steps' (the number of steps between the end points)");
  s.q_final = r.vector(*qf, "problem.q_final");
  if (static_cast<int>(s.q_final.size()) != dim)
    throw InputError(r.where(qf, "problem.q_final") + ": got " + std::to_string(s.q_final.size()) +
                     " numbers, expected " + std::to_string(dim) + " (" + dimension_of(s) + ")");
  s.steps = r.integer(*st, "problem.steps", 2);
  if (s.steps > 100000000)
    throw InputError(r.where(st, "problem.steps") + ": got " + Reader::describe(*st) +
                     ", expected a whole number from 2 to 100000000");
}

// [map]: the discretization map written in the scene (map = "written"), component by
// component in x and v: q0 and q1, or a retraction with integrator.theta. Checked
// against Def. 2.2 here (mechanics/written_map.h), so a map that breaks it is refused
// with exit 2 and the residual.
void read_written_map(const Reader& r, const toml::table& root, Method& me) {
  const toml::node* sec = root.get("map");
  const bool manifold = me.map && me.map->retraction == MapRetraction::written;  // sphere-written, so3-written
  const bool written = me.map && (me.map->family == MapFamily::written || manifold);
  if (!sec) {
    const toml::node* integ = root.get("integrator");
    const toml::node* key = integ && integ->is_table() ? integ->as_table()->get("map") : nullptr;
    const std::string at = key ? r.where(key, "integrator.map") : r.path() + ": key 'integrator.map'";
    if (manifold)
      throw InputError(at + ": map = \"" + me.map->name + "\" needs the section [map] (retraction = [" +
                       (me.map->space == Space::sphere ? "3" : "9") + " expressions])");
    if (written) throw InputError(at + ": map = \"written\" needs the section [map] (q0 and q1, or retraction)");
    return;
  }
  const toml::table& m = r.section(root, "map", true);
  r.only_keys(m, "map", {"q0", "q1", "retraction", "name", "params"});
  if (!written)
    throw InputError(r.where(sec, "map") + ": the section [map] belongs to integrator.map = \"written\", " +
                     "\"sphere-written\" or \"so3-written\", not \"" + (me.map ? me.map->name : std::string("none")) +
                     "\"");
  WrittenMap::Params params;
  if (const toml::node* ps = m.get("params")) {
    if (!ps->is_table()) throw InputError(r.where(ps, "map.params") + ": expected a table of numbers");
    // the names the map's expressions already give a meaning: a parameter of one of
    // them would be hidden by it (and never used)
    std::vector<std::string> taken = {"pi"};
    if (!manifold) {
      taken.insert(taken.end(), {"x", "v"});
    } else if (me.map->space == Space::sphere) {
      for (const char* n : {"x1", "x2", "x3", "v1", "v2", "v3"}) taken.push_back(n);
    } else {
      for (int i = 1; i <= 3; ++i)
        for (int j = 1; j <= 3; ++j) taken.push_back("R" + std::to_string(i) + std::to_string(j));
      for (const char* n : {"w1", "w2", "w3"}) taken.push_back(n);
    }
    const std::size_t variables = taken.size();
    for (const auto& f : expression_detail::functions()) taken.push_back(f.name);
    for (const auto& [k, v] : *ps->as_table()) {
      const std::string name(k.str());
      const auto at = std::find(taken.begin(), taken.end(), name);
      if (at != taken.end())
        throw InputError(r.where(&v, "map.params." + name) + ": the name '" + echo(name) + "' is " +
                         (name == "pi"                                                ? "reserved for the constant"
                          : static_cast<std::size_t>(at - taken.begin()) >= variables ? "a function name"
                                                                                       : "a variable of the map's "
                                                                                         "expressions") +
                         "; expected another name");
      params.push_back({name, r.number(v, "map.params." + name)});
    }
  }
  std::string name = "written";
  if (const toml::node* n = m.get("name")) name = r.string(*n, "map.name");
  if (manifold) {
    // retraction = ["...", ...]: f(x, v) in the embedding, 3 components on S^2, 9 on SO(3)
    const bool sphere = me.map->space == Space::sphere;
    for (const char* k : {"q0", "q1"})
      if (const toml::node* n = m.get(k))
        throw InputError(r.where(n, std::string("map.") + k) + ": map = \"" + me.map->name +
                         "\" is written as a retraction (map.retraction), not as q0 and q1");
    const toml::node* rt = m.get("retraction");
    const std::string expect = sphere ? "an array of 3 strings: f(x, v) in x1 x2 x3 and v1 v2 v3"
                                      : "an array of 9 strings: f(R, w) row by row in R11 ... R33 and w1 w2 w3";
    if (!rt) throw InputError(r.path() + ": missing key 'map.retraction' (" + expect + ")");
    const toml::array* a = rt->as_array();
    std::vector<std::string> texts;
    for (std::size_t i = 0; a && i < a->size(); ++i) {
      if (!a->get(i)->is_string()) break;
      texts.push_back(*a->get(i)->value<std::string>());
    }
    if (!a || texts.size() != a->size() || texts.size() != (sphere ? 3u : 9u))
      throw InputError(r.where(rt, "map.retraction") + ": expected " + expect);
    try {
      me.written_retraction = std::make_shared<const WrittenRetraction>(
          sphere ? WrittenRetraction::Space::sphere : WrittenRetraction::Space::rotation, texts, params, name);
    } catch (const std::invalid_argument& e) {
      // "retraction[i]: ..." (a parse error in component i) or "retraction: ..." (an axiom)
      const std::string what = e.what();
      const std::size_t close = what.find("]: ");
      const toml::node* at = rt;
      if (what.rfind("retraction[", 0) == 0 && close != std::string::npos)
        at = a->get(static_cast<std::size_t>(std::stoul(what.substr(11, close - 11))));
      throw InputError(r.where(at, "map.retraction") + ": " + what);
    }
    return;
  }
  const toml::node* q0 = m.get("q0");
  const toml::node* q1 = m.get("q1");
  const toml::node* rt = m.get("retraction");
  if (rt && (q0 || q1))
    throw InputError(r.where(rt, "map.retraction") + ": give either map.retraction or map.q0 and map.q1, not both");
  if (!rt && !(q0 && q1))
    throw InputError(r.path() + ": missing key '" + std::string(q0 ? "map.q1" : q1 ? "map.q0" : "map.q0") +
                     "' (a written map is q0 and q1 in x and v, or a retraction)");
  const toml::node* at = rt ? rt : q0;
  // theta belongs to the retraction form; written with q0 and q1 it would do nothing
  const toml::node* integ = root.get("integrator");
  const toml::node* th = integ && integ->is_table() ? integ->as_table()->get("theta") : nullptr;
  if (th && !rt)
    throw InputError(r.where(th, "integrator.theta") +
                     ": theta applies to a written retraction (map.retraction), not to a map written as q0 and q1");
  try {
    me.written_map = std::make_shared<const WrittenMap>(
        rt ? WrittenMap::retraction(name, r.string(*rt, "map.retraction"), me.theta, params)
           : WrittenMap::points(name, r.string(*q0, "map.q0"), r.string(*q1, "map.q1"), params));
  } catch (const std::invalid_argument& e) {
    // the message starts with the key it is about: q0, q1 or retraction
    const std::string what = e.what();
    const toml::node* n = what.rfind("q1", 0) == 0 ? q1 : at;
    const std::string key = rt ? "map.retraction" : n == q1 ? "map.q1" : "map.q0";
    throw InputError(r.where(n, key) + ": " + what);
  }
}

// method = "galerkin" and form = "newmark" use no map. The scene's own map and theta
// are then set aside (checked, unused; the report says map "none" or "newmark"), so
// that one --set switches the method of any scene. A map or theta given with --set
// beside such a method, or a theta written in the same file as the method, would
// change nothing: refused, naming the keys (after every rule between values, which
// says what is wrong with the method itself first).
void refuse_unused_map_keys(const Reader& r, const toml::table& in, const Method& me) {
  if (!(me.galerkin || me.form == Form::newmark)) return;
  const toml::node* m = in.get("map");
  const toml::node* th = in.get("theta");
  const toml::node* chooser = me.galerkin ? in.get("method") : in.get("form");
  const bool chooser_in_file = chooser && !Reader::from_override(chooser);
  std::vector<std::pair<const toml::node*, std::string>> unused;
  if (m && Reader::from_override(m)) unused.push_back({m, "integrator.map"});
  if (th && (Reader::from_override(th) || chooser_in_file)) unused.push_back({th, "integrator.theta"});
  if (unused.empty()) return;
  const bool one = unused.size() == 1;
  const std::string keys = one ? unused[0].second : unused[0].second + " and " + unused[1].second;
  throw InputError(r.where(unused[0].first, unused[0].second) + ": " +
                   (me.galerkin ? "method = \"galerkin\" takes no map (its discrete Lagrangian is built from "
                                  "polynomial curves and quadrature)"
                                : "form = \"newmark\" steps by its own map on TQ (integrator.gamma and "
                                  "integrator.beta)") +
                   ", so " + keys + " would change nothing; " + (one ? "it applies" : "they apply") + " to " +
                   (me.galerkin ? "method = \"map\"" : "the other forms") +
                   " (a map written in the scene file is kept, unused, when --set switches the method)");
}

// [integrator]: the method's keys whose presence matters (a key that applies only to
// another choice is refused where it is written); the rules between values are
// validate()'s.
void read_integrator(const Reader& r, const toml::table& in, Problem& pr, Method& me) {
  r.only_keys(in, "integrator", {"map", "theta", "step", "steps", "t_end", "solver", "max_iterations", "tolerance",
                                  "composition", "weights", "thetas", "form", "lift", "gamma", "beta", "method",
                                  "stages", "quadrature", "use_structure"});
  if (const toml::node* f = in.get("form")) me.form = find_form(r.string(*f, "integrator.form"), r.where(f, "integrator.form"));
  for (const char* key : {"gamma", "beta"}) {
    const toml::node* n = in.get(key);
    if (!n) continue;
    const std::string name = std::string("integrator.") + key;
    if (me.form != Form::newmark)
      throw InputError(r.where(n, name) + ": " + key + " applies only to form = \"newmark\", not \"" +
                       to_string(me.form) + "\"");
    (std::string(key) == "gamma" ? me.newmark_gamma : me.newmark_beta) = r.number(*n, name);
  }
  if (const toml::node* m = in.get("method")) {
    const std::string method = r.string(*m, "integrator.method");
    if (method != "map" && method != "galerkin")
      throw InputError(r.where(m, "integrator.method") + ": got \"" + echo(method) +
                       "\", expected \"map\" (the map's own step) or \"galerkin\" (Galerkin discrete Lagrangians)" +
                       did_you_mean(method, {"map", "galerkin"}));
    me.galerkin = method == "galerkin";
  }
  for (const char* key : {"stages", "quadrature"}) {
    const toml::node* n = in.get(key);
    if (n && !me.galerkin)
      throw InputError(r.where(n, std::string("integrator.") + key) + ": " + key +
                       " applies only to method = \"galerkin\", not \"map\"");
  }
  if (const toml::node* st = in.get("stages")) {
    const std::int64_t k = r.integer(*st, "integrator.stages", 1);
    if (k > kGalerkinStagesMax)
      throw InputError(r.where(st, "integrator.stages") + ": got " + Reader::describe(*st) +
                       ", expected a whole number from 1 to " + std::to_string(kGalerkinStagesMax));
    me.stages = static_cast<int>(k);
  }
  if (const toml::node* qu = in.get("quadrature")) {
    const std::string q = r.string(*qu, "integrator.quadrature");
    if (q != "gauss" && q != "lobatto")
      throw InputError(r.where(qu, "integrator.quadrature") + ": got \"" + echo(q) +
                       "\", expected \"gauss\" (s points) or \"lobatto\" (s + 1 points)" +
                       did_you_mean(q, {"gauss", "lobatto"}));
    me.quadrature = q == "gauss" ? QuadratureKind::gauss : QuadratureKind::lobatto;
  }
  // the map: needed by every form but newmark and by every method but galerkin, which
  // validate a map named in the scene and do not use it (so that --set
  // integrator.form=newmark works on any scene without hiding a typo)
  const toml::node* m = in.get("map");
  if (!m && me.form != Form::newmark && !me.galerkin) throw InputError(r.path() + ": missing key 'integrator.map'");
  if (m) {
    me.map = &find_map_entry(r.string(*m, "integrator.map"), r.where(m, "integrator.map"));
    me.theta = me.map->theta;
  }
  if (const toml::node* th = in.get("theta")) {
    if (!me.map || !me.map->takes_theta)
      throw InputError(r.where(th, "integrator.theta") + ": theta applies only to " + theta_map_names() + ", not \"" +
                       (me.map ? me.map->name : std::string("none")) + "\"");
    me.theta = r.number(*th, "integrator.theta");
  }
  if (const toml::node* co = in.get("composition")) me.composition = r.string(*co, "integrator.composition");
  if (const toml::node* w = in.get("weights")) {
    if (me.composition != "dirk")
      throw InputError(r.where(w, "integrator.weights") + ": weights apply only to composition = \"dirk\", not \"" +
                       echo(me.composition) + "\"");
    me.weights = r.vector(*w, "integrator.weights");
  }
  if (const toml::node* t = in.get("thetas")) {
    if (me.composition != "dirk")
      throw InputError(r.where(t, "integrator.thetas") + ": thetas apply only to composition = \"dirk\", not \"" +
                       echo(me.composition) + "\"");
    if (const toml::node* th = in.get("theta"))
      throw InputError(r.where(th, "integrator.theta") +
                       ": with integrator.thetas each stage has its own theta; give thetas only");
    me.thetas = r.vector(*t, "integrator.thetas");
  }
  if (const toml::node* l = in.get("lift"))
    me.lift = find_lift(r.string(*l, "integrator.lift"), r.where(l, "integrator.lift"));
  const toml::node* h = in.get("step");
  if (!h) throw InputError(r.path() + ": missing key 'integrator.step'");
  pr.step = r.number(*h, "integrator.step");
  if (!(pr.step > 0.0))
    throw InputError(r.where(h, "integrator.step") + ": got " + Reader::describe(*h) + ", expected a positive number");
  const toml::node* n = in.get("steps");
  const toml::node* te = in.get("t_end");
  if (n && te)
    throw InputError(r.where(te, "integrator.t_end") + ": give either integrator.steps or integrator.t_end, not both");
  if (pr.boundary_value && (n || te))
    throw InputError(r.where(n ? n : te, n ? "integrator.steps" : "integrator.t_end") +
                     ": a boundary-value problem takes its number of steps from problem.steps");
  if (!n && !te && !pr.boundary_value)
    throw InputError(r.path() + ": missing key 'integrator.steps' or 'integrator.t_end'");
  if (n) {
    pr.steps = r.integer(*n, "integrator.steps", 1);
  } else if (te) {
    const double t_end = r.number(*te, "integrator.t_end");
    if (!(t_end > 0.0))
      throw InputError(r.where(te, "integrator.t_end") + ": got " + Reader::describe(*te) + ", expected a positive number");
    const double count = std::round(t_end / pr.step);
    if (!(count >= 1.0) || count > 9e15)
      throw InputError(r.where(te, "integrator.t_end") + ": t_end / step = " + fmt(t_end / pr.step) +
                       ", expected between 1 and 9e15 steps");
    if (std::fabs(count * pr.step - t_end) > 1e-9 * t_end)
      throw InputError(r.where(te, "integrator.t_end") + ": t_end = " + Reader::describe(*te) +
                       " is not a whole number of steps of " + Reader::describe(*h) +
                       "; expected t_end = k * step (or give integrator.steps)");
    pr.steps = static_cast<std::int64_t>(count);
  }
  if (const toml::node* so = in.get("solver")) {
    const std::string solver = r.string(*so, "integrator.solver");
    if (solver != "newton" && solver != "tiny")
      throw InputError(r.where(so, "integrator.solver") + ": got \"" + echo(solver) + "\", expected \"newton\" or \"tiny\"" +
                       did_you_mean(solver, {"newton", "tiny"}));
    me.solver = solver == "tiny" ? SolverKind::tiny : SolverKind::newton;
  }
  if (const toml::node* mi = in.get("max_iterations")) {
    const std::int64_t it = r.integer(*mi, "integrator.max_iterations", 1);
    if (it > 1000)
      throw InputError(r.where(mi, "integrator.max_iterations") + ": got " + Reader::describe(*mi) +
                       ", expected a whole number from 1 to 1000");
    me.max_iterations = static_cast<int>(it);
  }
  if (const toml::node* tol = in.get("tolerance")) {
    if (pr.boundary_value)
      throw InputError(r.where(tol, "integrator.tolerance") + ": a boundary-value problem is solved to its own "
                       "tolerance on the discrete Euler-Lagrange residuals (1e-14 of their scale); integrator.tolerance "
                       "applies to the steps of initial-value problems");
    me.tolerance = r.number(*tol, "integrator.tolerance");
  }
  if (const toml::node* us = in.get("use_structure")) {
    if (pr.boundary_value)
      throw InputError(r.where(us, "integrator.use_structure") + ": a boundary-value problem is one solve of every "
                       "node by Ceres' sparse least squares, whatever the system's structure; "
                       "integrator.use_structure applies to the steps of initial-value problems");
    if (!us->is_boolean())
      throw InputError(r.where(us, "integrator.use_structure") + ": got " + Reader::describe(*us) +
                       ", expected true or false");
    me.use_structure = us->as_boolean()->get();
  }
  // a boundary-value problem is one large solve: 100 iterations unless the scene says
  if (pr.boundary_value && !in.get("max_iterations")) me.max_iterations = 100;
}

}  // namespace

namespace {

void check_toml_text(const std::string& text, const std::string& path);
Scene validate_scene(toml::table& root, const std::string& path, const std::vector<std::string>& overrides);

// "file:line:column: " of a byte offset (columns in code points, as toml++ counts).
std::string text_position(const std::string& text, std::size_t at, const std::string& path) {
  std::size_t line = 1, column = 1;
  for (std::size_t i = 0; i < at && i < text.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\n') {
      ++line;
      column = 1;
    } else if ((c & 0xC0) != 0x80) {
      ++column;
    }
  }
  return path + ":" + std::to_string(line) + ":" + std::to_string(column) + ": ";
}

// toml++ 3.3 records the source region of a dotted key (a.b.c = 1, [a.b.c]) by a
// recursion as deep as the key has parts: a key of some ten thousand parts overflows the
// stack (found by fuzzing). Keys of more than kMaxKeyParts parts are refused before
// toml++ sees the text. The scan skips strings and comments and counts the dots of each
// run of bare or quoted key parts joined by dots (a number such as 1.5 is one dot).
void check_dotted_keys(const std::string& text, const std::string& path) {
  const std::size_t n = text.size();
  std::size_t dots = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const char c = text[i];
    if (c == '#') {
      while (i < n && text[i] != '\n') ++i;
      dots = 0;
    } else if (c == '"' || c == '\'') {
      const bool triple = i + 2 < n && text[i + 1] == c && text[i + 2] == c;
      std::size_t j = i + (triple ? 3 : 1);
      while (j < n) {
        if (c == '"' && text[j] == '\\') {
          j += 2;
          continue;
        }
        if (!triple && text[j] == '\n') break;  // unterminated: toml++ says so
        if (text[j] == c && (!triple || (j + 2 < n && text[j + 1] == c && text[j + 2] == c))) break;
        ++j;
      }
      i = triple ? j + 2 : j;  // a quoted part: the run goes on
    } else if (c == '.') {
      if (++dots > kMaxKeyParts - 1)
        throw InputError(text_position(text, i, path) + "a dotted key of more than " + std::to_string(kMaxKeyParts) +
                         " parts; expected at most " + std::to_string(kMaxKeyParts));
    } else if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == ' ' || c == '\t' ||
                 c == '+')) {
      dots = 0;
    }
  }
}

// toml++ 3.3 (Debian bookworm's) reaches TOML_UNREACHABLE - undefined behaviour - in
// is_non_ascii_horizontal_whitespace for the code points U+00A1..U+0499,
// U+2C5E..U+2FFF, U+3001..U+3057 and U+FB26..U+FEFE (its generated range table misses
// them; the list is every code point for which that function's branches reach it), which
// its parser asks about wherever whitespace may stand: in a valid scene at a line's
// start, in a malformed one after almost any token. Found by fuzzing (tests/fuzz).
// Text holding one of them, or a NUL (never valid TOML), is refused here, before the
// parser sees it, with the line and column (in code points, as toml++ counts).
void check_toml_text(const std::string& text, const std::string& path) {
  check_dotted_keys(text, path);
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
    // (the position's text only for a message: formed for every character, it was most
    // of the time of reading a large scene)
    auto where = [&] { return path + ":" + std::to_string(line) + ":" + std::to_string(column) + ": "; };
    if (cp == 0) throw InputError(where() + "a NUL character; expected TOML text");
    if ((cp >= 0xA1 && cp <= 0x499) || (cp >= 0x2C5E && cp <= 0x2FFF) || (cp >= 0x3001 && cp <= 0x3057) ||
        (cp >= 0xFB26 && cp <= 0xFEFE)) {
      char u[16];
      std::snprintf(u, sizeof u, "U+%04X", static_cast<unsigned>(cp));
      throw InputError(where() + "the character " + u + ", which the TOML parser in use (toml++ 3.3) cannot read "
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
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw InputError(path + ": is a directory; expected a scene file (TOML text)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open the scene file (" + std::strerror(errno) + ")");
  // read in chunks and stop past the limit: /dev/zero or a huge file is refused without
  // being loaded. (A buffer of the limit's size, zeroed for every scene, cost each run
  // thousands of page faults, more than a short run itself.)
  std::string text;
  char chunk[1 << 16];
  for (;;) {
    in.read(chunk, sizeof chunk);
    const auto got = static_cast<std::size_t>(in.gcount());
    text.append(chunk, got);
    if (text.size() > kMaxSceneBytes)
      throw InputError(path + ": the scene is larger than " + std::to_string(kMaxSceneBytes) +
                       " bytes (16 MiB), the most dvm reads; expected a smaller scene");
    if (got < sizeof chunk) break;  // the end of the file, or an error
  }
  if (in.bad()) throw InputError(path + ": cannot read the scene file");
  return load_scene_text(text, path, overrides);
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

// The key a message of validate() starts with ("integrator.form: ..."), or "".
std::string leading_key(const std::string& msg) {
  const auto colon = msg.find(": ");
  if (colon == std::string::npos) return "";
  const std::string key = msg.substr(0, colon);
  const auto dot = key.find('.');
  if (dot == std::string::npos || dot == 0 || dot + 1 == key.size()) return "";
  for (char c : key)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.')) return "";
  return key;
}

Scene validate_scene(toml::table& root, const std::string& path, const std::vector<std::string>& overrides) {
  for (const auto& o : overrides) apply_override(root, o);

  Reader r(path);
  Scene s;
  s.path = path;
  Problem& pr = s.problem;
  Method& me = s.method;
  pr.origin = path;
  for (const auto& [k, v] : root) {
    const std::string name(k.str());
    if (name != "system" && name != "initial" && name != "integrator" && name != "output" && name != "problem" &&
        name != "map")
      throw InputError(r.where(&v, name) +
                       ": unknown section; expected system, initial, integrator, map, output, problem" +
                       did_you_mean(name, {"system", "initial", "integrator", "map", "output", "problem"}));
  }

  // [system]
  const toml::table& sys = r.section(root, "system", true);
  r.only_keys(sys, "system",
              {"builtin", "params", "lagrangian", "coordinates", "energy", "hamiltonian", "name", "masses", "space",
               "ends", "definitions", "compile", "invariants", "forces", "constraints", "controls"});
  if (sys.get("lagrangian")) read_written_system(path, sys, pr);
  const toml::node* b = sys.get("builtin");
  if (!b && !pr.written)
    throw InputError(path + ": missing key 'system.builtin' (a built-in system name) or 'system.lagrangian'");
  if (!pr.written) {
    for (const char* k :
         {"coordinates", "energy", "hamiltonian", "name", "space", "ends", "definitions", "compile", "invariants",
          "forces", "constraints", "controls"})
      if (const toml::node* n = sys.get(k))
        throw InputError(r.where(n, std::string("system.") + k) + ": belongs to a written system (system.lagrangian)");
    pr.system = &find_system_entry(r.string(*b, "system.builtin"), r.where(b, "system.builtin"));
    pr.dim = pr.system->dim;
    const toml::node* ms = sys.get("masses");
    if (pr.system->name == "nbody") {
      if (!ms) throw InputError(path + ": missing key 'system.masses' (nbody: one mass per body, 2 or more bodies)");
      pr.masses = r.vector(*ms, "system.masses");
      if (pr.masses.size() < 2 || pr.masses.size() > 1000000)
        throw InputError(r.where(ms, "system.masses") + ": got " + std::to_string(pr.masses.size()) +
                         " masses, expected 2 to 1000000 bodies");
      for (double m : pr.masses)
        if (!(m > 0.0)) throw InputError(r.where(ms, "system.masses") + ": expected positive masses");
      pr.dim = 3 * static_cast<int>(pr.masses.size());
    } else if (ms) {
      throw InputError(r.where(ms, "system.masses") + ": only builtin = \"nbody\" takes masses");
    }
    for (const auto& p : pr.system->params) pr.params[p.name] = p.default_value;
    if (const toml::node* params = sys.get("params")) {
      if (!params->is_table()) throw InputError(r.where(params, "system.params") + ": expected a table of numbers");
      for (const auto& [k, v] : *params->as_table()) {
        const std::string name(k.str());
        if (!pr.params.count(name)) {
          std::string names;
          for (const auto& p : pr.system->params) names += (names.empty() ? "" : ", ") + p.name;
          std::vector<std::string> known;
          for (const auto& p : pr.system->params) known.push_back(p.name);
          throw InputError(r.where(&v, "system.params." + name) + ": unknown parameter of " + pr.system->name +
                           "; expected one of: " + names + did_you_mean(name, known));
        }
        pr.params[name] = r.number(v, "system.params." + name);
      }
    }
    if (pr.dim == 0 || pr.system->name == "spherical-chain")
      pr.dim = resolve_dimension(r, sys.get("params"), *pr.system, pr.params);
  }
  const SystemEntry& info = *pr.system;

  read_problem(r, root, pr, info.space == Space::rotation ? 4 : pr.dim);

  // [initial]
  const toml::table& ini = r.section(root, "initial", true);
  if (info.space == Space::rotation)
    read_rotation_initial(r, ini, path, pr);
  else
    read_vector_initial(r, ini, path, info, pr.dim, pr.boundary_value, pr);
  if (pr.boundary_value && info.space == Space::sphere) {
    // both end points on the sphere, not projected onto it
    for (const auto* end : {&pr.q, &pr.q_final}) {
      const auto& x = *end;
      const double defect = std::fabs(std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - 1.0);
      const std::string key = end == &pr.q ? "initial.q" : "problem.q_final";
      if (!(defect <= 1e-12))
        throw InputError(r.where(root.at_path(key).node(), key) + ": not a unit vector (| |q| - 1 | = " + fmt(defect) +
                         "); expected a point of S^2 to 1e-12");
    }
  }

  // [integrator], and [map] for map = "written"
  read_integrator(r, r.section(root, "integrator", true), pr, me);
  read_written_map(r, root, me);

  // [output]
  const toml::table& out = r.section(root, "output", false);
  r.only_keys(out, "output", {"csv", "every", "npy", "monitor_every"});
  if (const toml::node* c = out.get("npy")) {
    s.npy = r.string(*c, "output.npy");
    if (s.npy.empty())
      throw InputError(r.where(c, "output.npy") +
                       ": expected a file name, got an empty string (dvm run --no-output writes no rows)");
  }
  if (const toml::node* c = out.get("csv")) {
    s.csv = r.string(*c, "output.csv");
    if (s.csv.empty())
      throw InputError(r.where(c, "output.csv") +
                       ": expected a file name, got an empty string (dvm run --no-output writes no rows)");
  }
  if (const toml::node* e = out.get("every")) s.every = r.integer(*e, "output.every", 1);
  if (const toml::node* e = out.get("monitor_every")) {
    if (pr.boundary_value)
      throw InputError(r.where(e, "output.monitor_every") + ": a boundary-value problem evaluates the energy at "
                       "every node of its solution; output.monitor_every applies to initial-value runs");
    s.monitor_every = r.integer(*e, "output.monitor_every", 1);
  }

  // every rule between values, with the position of the key it names
  try {
    validate(pr, me);
  } catch (const InputError& e) {
    const std::string msg = e.what();
    const std::string key = leading_key(msg);
    if (key.empty()) throw InputError(path + ": " + msg);
    const toml::node* n = root.at_path(key).node();
    const std::string rest = msg.substr(key.size() + 2);
    throw InputError((n ? r.where(n, key) : path + ": key '" + key + "'") + ": " + rest);
  }
  refuse_unused_map_keys(r, r.section(root, "integrator", true), me);
  return s;
}

}  // namespace

}  // namespace dvm
