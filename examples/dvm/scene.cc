#include "examples/dvm/scene.h"

#include <cctype>
#include <cmath>
#include <limits>
#include <set>
#include <sstream>

#include <toml++/toml.h>

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
  };
  return list;
}

namespace {

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

}  // namespace

Scene load_scene(const std::string& path, const std::vector<std::string>& overrides) {
  toml::table root;
  try {
    root = toml::parse_file(path);
  } catch (const toml::parse_error& e) {
    std::ostringstream msg;
    msg << path;
    if (e.source().begin.line > 0) msg << ":" << e.source().begin.line << ":" << e.source().begin.column;
    msg << ": " << e.description();
    throw InputError(msg.str());
  }
  for (const auto& o : overrides) apply_override(root, o);

  Reader r(path);
  Scene s;
  s.path = path;
  for (const auto& [k, v] : root) {
    const std::string name(k.str());
    if (name != "system" && name != "initial" && name != "integrator" && name != "output")
      throw InputError(r.where(&v, name) + ": unknown section; expected system, initial, integrator, output");
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

  // [initial]
  const toml::table& ini = r.section(root, "initial", true);
  r.only_keys(ini, "initial", {"q", "p", "v"});
  const toml::node* q = ini.get("q");
  if (!q) throw InputError(path + ": missing key 'initial.q'");
  s.q = r.vector(*q, "initial.q");
  const std::string n_expected = std::to_string(s.dim);
  if (static_cast<int>(s.q.size()) != s.dim)
    throw InputError(r.where(q, "initial.q") + ": got " + std::to_string(s.q.size()) + " numbers, expected " +
                     n_expected + " (the dimension of " + info.name + ")");
  const toml::node* p = ini.get("p");
  const toml::node* v = ini.get("v");
  if (p && v) throw InputError(r.where(v, "initial.v") + ": give either initial.p or initial.v, not both");
  if (!p && !v) throw InputError(path + ": missing key 'initial.p' or 'initial.v'");
  const toml::node* pv = p ? p : v;
  const std::string pv_key = p ? "initial.p" : "initial.v";
  (p ? s.p : s.v) = r.vector(*pv, pv_key);
  s.momentum_given = p != nullptr;
  if (static_cast<int>((p ? s.p : s.v).size()) != s.dim)
    throw InputError(r.where(pv, pv_key) + ": got " + std::to_string((p ? s.p : s.v).size()) + " numbers, expected " +
                     n_expected + " (the dimension of " + info.name + ")");

  // [integrator]
  const toml::table& in = r.section(root, "integrator", true);
  r.only_keys(in, "integrator", {"map", "theta", "step", "steps", "t_end", "solver", "max_iterations", "tolerance"});
  const toml::node* m = in.get("map");
  if (!m) throw InputError(path + ": missing key 'integrator.map'");
  s.map = find_map(r.string(*m, "integrator.map"), r.where(m, "integrator.map")).name;
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
  if (!n && !te) throw InputError(path + ": missing key 'integrator.steps' or 'integrator.t_end'");
  if (n) {
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

}  // namespace dvm::cli
