#include "solvers/runtime/scene_written.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <vector>

#include "mechanics/written_lagrangian.h"

namespace dvm {

// The largest control table ([system] controls = { u = { csv = ... } }) read: 1 GiB of
// text, some 10^8 values (a device or a file of another kind is refused before it).
constexpr std::uintmax_t kMaxControlTableBytes = std::uintmax_t{1} << 30;

namespace {

std::vector<std::string> read_lines(const std::string& path) {
  std::ifstream f(path);
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(f, line)) lines.push_back(line);
  return lines;
}

std::string key_where(const std::string& path, const toml::node& n, const std::string& key) {
  std::ostringstream out;
  out << path;
  if (n.source().begin.line > 0)
    out << ":" << n.source().begin.line << ":" << n.source().begin.column;
  else
    out << " (from --set)";
  out << ": key '" << key << "'";
  return out.str();
}

}  // namespace

std::string string_location(const std::string& path, const toml::node& n, std::size_t offset) {
  const auto begin = n.source().begin;
  if (begin.line == 0) return path + " (from --set): character " + std::to_string(offset + 1) + " of the value";
  const std::vector<std::string> lines = read_lines(path);
  std::size_t line = begin.line - 1, col = begin.column - 1;  // 0-based, at the opening quote
  auto at = [&](std::size_t l, std::size_t c) -> int {
    if (l >= lines.size()) return -1;
    if (c == lines[l].size()) return '\n';
    if (c > lines[l].size()) return -1;
    return static_cast<unsigned char>(lines[l][c]);
  };
  auto advance = [&]() {
    if (at(line, col) == '\n') {
      ++line;
      col = 0;
    } else {
      ++col;
    }
  };
  auto here = [&]() { return path + ":" + std::to_string(line + 1) + ":" + std::to_string(col + 1); };
  const int quote = at(line, col);
  if (quote != '"' && quote != '\'') return path + ":" + std::to_string(begin.line) + ":" + std::to_string(begin.column);
  const bool basic = quote == '"';
  const bool multi = at(line, col + 1) == quote && at(line, col + 2) == quote;
  for (int i = 0; i < (multi ? 3 : 1); ++i) advance();
  if (multi && at(line, col) == '\n') advance();  // a newline right after """ is trimmed
  // Walk the raw text, counting decoded characters until `offset`.
  for (std::size_t decoded = 0; decoded < offset;) {
    const int ch = at(line, col);
    if (ch < 0) break;
    if (basic && ch == '\\') {
      const int e = at(line, col + 1);
      if (multi && (e == '\n' || e == ' ' || e == '\t')) {
        // line-ending backslash: skips whitespace and newlines
        advance();
        while (at(line, col) == ' ' || at(line, col) == '\t' || at(line, col) == '\n') advance();
        continue;
      }
      const int skip = e == 'u' ? 6 : e == 'U' ? 10 : 2;
      for (int i = 0; i < skip; ++i) advance();
      ++decoded;
      continue;
    }
    advance();
    ++decoded;
  }
  return here();
}

void read_written_system(const std::string& path, const toml::table& sys, Problem& pr) {
  auto w = std::make_shared<WrittenSystem>();
  if (sys.get("builtin"))
    throw InputError(key_where(path, *sys.get("builtin"), "system.builtin") +
                     ": give either system.builtin or system.lagrangian, not both");
  if (const toml::node* n = sys.get("masses"))
    throw InputError(key_where(path, *n, "system.masses") + ": masses belong to builtin = \"nbody\"");
  if (const toml::node* n = sys.get("name")) {
    const auto v = n->value<std::string>();
    if (!v || v->empty()) throw InputError(key_where(path, *n, "system.name") + ": expected a non-empty string");
    w->name = *v;
  }
  Space space = Space::euclidean;
  const toml::node* sp = sys.get("space");
  if (sp) {
    const auto v = sp->value<std::string>();
    // "(S^2)^K": K unit vectors, K = 1..4 (the sizes the spherical chain's steps are built for)
    const bool power = sp->is_string() && v->size() == 7 && v->compare(0, 6, "(S^2)^") == 0 && (*v)[6] >= '1' &&
                       (*v)[6] <= '4';
    if (!sp->is_string() || !(*v == "R^n" || *v == "S^2" || *v == "SO(3)" || power))
      throw InputError(key_where(path, *sp, "system.space") +
                       ": expected \"R^n\", \"S^2\", \"(S^2)^K\" with K from 1 to 4, or \"SO(3)\"" +
                       (sp->is_string() ? ", got \"" + *v + "\"" : ""));
    space = *v == "S^2" || power ? Space::sphere : *v == "SO(3)" ? Space::rotation : Space::euclidean;
    if (power) w->factors = (*v)[6] - '0';
  }
  if (const toml::node* n = sys.get("compile")) {
    if (!n->is_boolean()) throw InputError(key_where(path, *n, "system.compile") + ": expected true or false");
    pr.compile = *n->value<bool>();
  }
  w->space = space == Space::sphere     ? WrittenSystem::Space::sphere
             : space == Space::rotation ? WrittenSystem::Space::rotation
                                        : WrittenSystem::Space::euclidean;
  // the parameters first: an array's size may name one
  if (const toml::node* params = sys.get("params")) {
    if (!params->is_table())
      throw InputError(key_where(path, *params, "system.params") + ": expected a table of numbers or lists of numbers");
    for (const auto& [k, v] : *params->as_table()) {
      const std::string name(k.str());
      if (const toml::array* list = v.as_array()) {
        ExpressionSymbols::ConstantArray a{name, {}};
        for (std::size_t i = 0; i < list->size(); ++i) {
          const toml::node& e = *list->get(i);
          const auto x = e.value<double>();
          if (!e.is_number() || !x || !std::isfinite(*x))
            throw InputError(key_where(path, e, "system.params." + name + "[" + std::to_string(i) + "]") +
                             ": expected a finite number");
          a.values.push_back(*x);
        }
        if (a.values.empty())
          throw InputError(key_where(path, v, "system.params." + name) + ": expected a non-empty list of numbers");
        w->param_arrays.push_back(std::move(a));
        continue;
      }
      const auto x = v.value<double>();
      if (!(v.is_number()) || !x || !std::isfinite(*x))
        throw InputError(key_where(path, v, "system.params." + name) + ": expected a finite number or a list of numbers");
      w->params.emplace_back(name, *x);
      pr.params[name] = *x;
    }
  }
  // what an array's index 0 and size + 1 mean
  std::map<std::string, ExpressionSymbols::Boundary> ends;
  const toml::node* ends_node = sys.get("ends");
  if (ends_node) {
    if (!ends_node->is_table())
      throw InputError(key_where(path, *ends_node, "system.ends") +
                       ": expected a table naming arrays of coordinates, e.g. ends = { q = \"fixed\" }");
    for (const auto& [k, v] : *ends_node->as_table()) {
      const std::string name(k.str());
      const auto e = v.value<std::string>();
      if (!v.is_string() || !(*e == "none" || *e == "fixed" || *e == "periodic"))
        throw InputError(key_where(path, v, "system.ends." + name) + ": expected \"none\", \"fixed\" or \"periodic\"");
      ends[name] = *e == "fixed" ? ExpressionSymbols::Boundary::fixed
                   : *e == "periodic" ? ExpressionSymbols::Boundary::periodic
                                     : ExpressionSymbols::Boundary::none;
    }
  }
  const toml::node* c = sys.get("coordinates");
  if (c && space == Space::rotation)
    throw InputError(key_where(path, *c, "system.coordinates") +
                     ": on SO(3) the names are fixed: R11 ... R33 (the rotation matrix), w1 w2 w3 (the body angular "
                     "velocity), pi1 pi2 pi3 (the body angular momentum)");
  if (!c && space == Space::euclidean)
    throw InputError(path + ": missing key 'system.coordinates' (the names of the coordinates, e.g. "
                            "coordinates = [\"theta\"]; velocities are then named theta_dot)");
  if (!c && space == Space::sphere && w->factors == 1) w->coordinates = {"x", "y", "z"};
  for (int k = 1; !c && space == Space::sphere && w->factors > 1 && k <= w->factors; ++k)
    for (const char* n : {"x", "y", "z"}) w->coordinates.push_back(n + std::to_string(k));
  if (c) {
    const toml::array* ca = c->as_array();
    if (!ca || ca->empty())
      throw InputError(key_where(path, *c, "system.coordinates") + ": expected a non-empty array of names");
    for (std::size_t i = 0; i < ca->size(); ++i) {
      const auto v = ca->get(i)->value<std::string>();
      const std::string key = "system.coordinates[" + std::to_string(i) + "]";
      if (!ca->get(i)->is_string())
        throw InputError(key_where(path, *ca->get(i), key) + ": expected a name (a string)");
      // "q[1000]" or "q[n]" (n a parameter): an array of coordinates
      const std::size_t open = v->find('[');
      if (open == std::string::npos) {
        w->coordinates.push_back(*v);
        continue;
      }
      if (space != Space::euclidean)
        throw InputError(key_where(path, *ca->get(i), key) + ": arrays of coordinates are written on R^n only");
      const std::string name = v->substr(0, open);
      const bool closed = v->size() > open + 2 && v->back() == ']';
      const std::string size_text = closed ? v->substr(open + 1, v->size() - open - 2) : "";
      // the size: an expression in the (scalar) parameters
      double size = -1.0;
      if (closed) {
        ExpressionSymbols sizes;
        sizes.constants = w->params;
        try {
          const Expression e = Expression::parse(size_text, sizes);
          if (e.tape().size() == 1 && e.tape()[0].op == Expression::Op::Const) size = e.tape()[0].c;
        } catch (const ExpressionError& err) {
          throw InputError(string_location(path, *ca->get(i), open + 1 + err.offset) + ": in " + key +
                           ", the size of '" + v->substr(0, open) + "': " + err.what());
        }
      }
      if (!closed || !(size >= 1.0 && size <= 1e7 && size == std::floor(size)))
        throw InputError(key_where(path, *ca->get(i), key) + ": '" + *v +
                         "' is not a coordinate array; expected name[size], the size a whole number from 1 to 10^7 "
                         "made of numbers and parameters (e.g. \"q[n]\" with params = { n = 1000 }, or \"r[3*n]\")");
      auto e = ends.find(name);
      w->add_array(name, static_cast<int>(size), e == ends.end() ? ExpressionSymbols::Boundary::none : e->second);
    }
  }
  for (const auto& [name, b] : ends) {
    bool found = false;
    for (const auto& a : w->arrays) found = found || a.name == name;
    if (!found)
      throw InputError(key_where(path, *ends_node, "system.ends." + name) + ": '" + name +
                       "' is not an array of coordinates (declare it as coordinates = [\"" + name + "[n]\"])");
  }
  // definitions = ["r = sqrt(x^2 + y^2)", ...]: name = text, each checked here where it
  // is written (in the names of the energy: coordinates, velocities and momenta)
  const toml::node* defs = sys.get("definitions");
  if (defs) {
    const toml::array* da = defs->as_array();
    if (!da) throw InputError(key_where(path, *defs, "system.definitions") + ": expected an array of \"name = expression\"");
    for (std::size_t i = 0; i < da->size(); ++i) {
      const toml::node& d = *da->get(i);
      const std::string key = "system.definitions[" + std::to_string(i) + "]";
      const auto text = d.value<std::string>();
      const std::size_t eq = d.is_string() ? text->find('=') : std::string::npos;
      if (eq == std::string::npos)
        throw InputError(key_where(path, d, key) + ": expected a string \"name = expression\"");
      std::string name = text->substr(0, eq);
      name.erase(0, name.find_first_not_of(" \t"));
      name.erase(name.find_last_not_of(" \t") + 1);
      w->definitions.emplace_back(name, text->substr(eq + 1));
    }
  }
  // [system] controls: their names now (checked with the others), their values below
  const toml::node* controls = sys.get("controls");
  if (controls) {
    if (!controls->is_table())
      throw InputError(key_where(path, *controls, "system.controls") +
                       ": expected a table of name = \"expression in t\" or name = { csv = \"file\" }");
    if (w->space == WrittenSystem::Space::sphere && w->factors > 1)
      throw InputError(key_where(path, *controls, "system.controls") +
                       ": controls enter forces on R^n, S^2 and SO(3); on (S^2)^" + std::to_string(w->factors) +
                       " a written system is conservative");
    for (const auto& [name, node] : *controls->as_table()) w->controls.push_back({std::string(name.str()), {}, {}, {}, {}});
  }
  try {
    w->check_names();
  } catch (const WrittenSystem::NameError& e) {
    // blamed on the key that gave the name: a parameter (or list) on its own key, a
    // definition on its entry, a coordinate (or the velocity or momentum named after
    // it) on system.coordinates
    const toml::node* params = sys.get("params");
    const toml::node* at = nullptr;
    std::string key;
    if (e.role.rfind("parameter", 0) == 0 && params && params->is_table() && params->as_table()->get(e.name)) {
      at = params->as_table()->get(e.name);
      key = "system.params." + e.name;
    } else if (e.role == "control" && controls) {
      at = controls->as_table()->get(e.name);
      key = "system.controls." + e.name;
    } else if (e.role == "definition" && defs && defs->is_array()) {
      for (std::size_t i = 0; i < w->definitions.size() && !at; ++i)
        if (w->definitions[i].first == e.name) {
          at = defs->as_array()->get(i);
          key = "system.definitions[" + std::to_string(i) + "]";
        }
    }
    if (!at) {
      at = c ? c : params ? params : sys.get("lagrangian");
      key = c ? "system.coordinates" : params ? "system.params" : "system.lagrangian";
    }
    throw InputError(key_where(path, *at, key) + ": " + e.what());
  } catch (const std::invalid_argument& e) {  // the number of coordinates for the space
    const toml::node* at = c ? c : sys.get("params") ? sys.get("params") : sys.get("lagrangian");
    throw InputError(key_where(path, *at, c ? "system.coordinates" : "system.params") + ": " + e.what());
  }
  for (std::size_t i = 0; i < w->definitions.size(); ++i) {
    ExpressionSymbols before = w->symbols(WrittenSystem::Kind::energy);
    before.definitions.resize(i);
    const toml::node& d = *defs->as_array()->get(i);
    const std::string& text = w->definitions[i].second;
    try {
      Expression::parse(text, before);
    } catch (const ExpressionError& e) {
      const std::size_t start = d.value<std::string>()->find('=') + 1;
      throw InputError(string_location(path, d, start + e.offset) + ": in system.definitions[" + std::to_string(i) +
                       "] ('" + w->definitions[i].first + "'): " + e.what());
    }
  }
  auto parse = [&](const char* key, WrittenSystem::Kind kind, Expression& out, bool required) {
    const toml::node* n = sys.get(key);
    if (!n) {
      if (required) throw InputError(path + ": missing key 'system." + std::string(key) + "'");
      return;
    }
    if (!n->is_string()) throw InputError(key_where(path, *n, std::string("system.") + key) + ": expected a string");
    const std::string text = *n->value<std::string>();
    try {
      out = Expression::parse(text, w->symbols(kind));
    } catch (const ExpressionError& e) {
      throw InputError(string_location(path, *n, e.offset) + ": in system." + key + ": " + e.what());
    }
  };
  parse("lagrangian", WrittenSystem::Kind::lagrangian, w->lagrangian, true);
  parse("energy", WrittenSystem::Kind::energy, w->energy, false);
  parse("hamiltonian", WrittenSystem::Kind::hamiltonian, w->hamiltonian, false);
  if (w->time_dependent() && !w->hamiltonian.empty())
    throw InputError(key_where(path, *sys.get("hamiltonian"), "system.hamiltonian") +
                     ": the Lagrangian depends on t (system.lagrangian reads it), so a Hamiltonian H(q, p) is not its "
                     "Legendre transform; a Lagrangian L(t, q, v) runs in the lagrangian form, without one");
  // [system] invariants = { name = "expression in q, v and p", ... }: monitored and
  // reported like the energy (Lagrangians written on R^n)
  if (const toml::node* inv = sys.get("invariants")) {
    const std::string key = "system.invariants";
    if (!inv->is_table())
      throw InputError(key_where(path, *inv, key) + ": expected a table of name = \"expression\" (in the "
                                                    "coordinates, their velocities _dot and momenta p_)");
    if (w->space != WrittenSystem::Space::euclidean)
      throw InputError(key_where(path, *inv, key) +
                       ": invariants of one's own are monitored for Lagrangians written on R^n; on S^2 and SO(3) "
                       "the runs monitor the momentum maps of the symmetries found in the text");
    const toml::table& t = *inv->as_table();
    if (t.size() > static_cast<std::size_t>(kMaxWrittenInvariants))
      throw InputError(key_where(path, *inv, key) + ": got " + std::to_string(t.size()) + " invariants, expected at most " +
                       std::to_string(kMaxWrittenInvariants));
    for (const auto& [name, node] : t) {
      const std::string k = key + "." + std::string(name.str());
      if (!node.is_string()) throw InputError(key_where(path, node, k) + ": expected a string (an expression)");
      // each names a CSV column: not one the run already writes
      bool taken = name.str() == "t" || name.str() == "energy";
      for (const std::string& coordinate : w->coordinates)
        taken = taken || name.str() == coordinate || name.str() == "p_" + coordinate;
      if (taken)
        throw InputError(key_where(path, node, k) + ": '" + std::string(name.str()) +
                         "' names a column the run writes already (t, the coordinates, their momenta p_..., energy)");
      try {
        w->invariants.emplace_back(std::string(name.str()),
                                   Expression::parse(*node.value<std::string>(), w->symbols(WrittenSystem::Kind::energy)));
      } catch (const ExpressionError& e) {
        throw InputError(string_location(path, node, e.offset) + ": in " + k + ": " + e.what());
      }
    }
  }
  // [system] controls = { u = "expression in t", w = { csv = "file" } }: inputs the forces
  // read (mechanics/written_force.h, ControlSignal); a file holds one number per line,
  // one line per step (an optional first line naming the control), and is found
  // beside the scene
  if (controls) {
    std::size_t j = 0;
    for (const auto& [name, node] : *controls->as_table()) {
      WrittenSystem::Control& ctl = w->controls[j++];
      const std::string k = "system.controls." + ctl.name;
      ctl.where = key_where(path, node, k);
      if (node.is_string()) {
        ExpressionSymbols sym;
        sym.variables.push_back({"t", 0, 0});
        sym.constants = w->params;
        sym.constant_arrays = w->param_arrays;
        try {
          ctl.expression = Expression::parse(*node.value<std::string>(), sym);
        } catch (const ExpressionError& e) {
          throw InputError(string_location(path, node, e.offset) + ": in " + k + ": " + e.what() +
                           " (a control written as an expression is u(t): t and the parameters)");
        }
        continue;
      }
      const toml::table* tab = node.as_table();
      const toml::node* csv = tab ? tab->get("csv") : nullptr;
      if (!csv || !csv->is_string() || tab->size() != 1)
        throw InputError(key_where(path, node, k) + ": expected \"expression in t\" or { csv = \"file\" } (one value per step)");
      const std::string file = *csv->value<std::string>();
      const std::filesystem::path at = std::filesystem::path(file).is_absolute()
                                           ? std::filesystem::path(file)
                                           : std::filesystem::path(path).parent_path() / file;
      ctl.source = at.string();
      std::error_code ec;
      const bool regular = std::filesystem::is_regular_file(at, ec);
      const auto bytes = regular ? std::filesystem::file_size(at, ec) : 0;
      if (!regular || ec)
        throw InputError(key_where(path, *csv, k + ".csv") + ": cannot read '" + ctl.source + "' (not a regular file)");
      if (bytes > kMaxControlTableBytes)
        throw InputError(key_where(path, *csv, k + ".csv") + ": '" + ctl.source + "' holds " + std::to_string(bytes) +
                         " bytes, beyond the " + std::to_string(kMaxControlTableBytes) + " a control table may hold");
      std::ifstream in(at);
      if (!in) throw InputError(key_where(path, *csv, k + ".csv") + ": cannot read '" + ctl.source + "'");
      std::string line;
      for (std::size_t ln = 1; std::getline(in, line); ++ln) {
        line.erase(0, line.find_first_not_of(" \t\r"));
        line.erase(line.find_last_not_of(" \t\r") + 1);
        if (line.empty()) continue;
        if (ln == 1 && ctl.table.empty() && line == ctl.name) continue;  // the header
        std::size_t used = 0;
        double x = NAN;
        try {
          x = std::stod(line, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != line.size() || !std::isfinite(x))
          throw InputError(key_where(path, *csv, k + ".csv") + ": " + ctl.source + ":" + std::to_string(ln) + ": '" +
                           line.substr(0, 40) + "' is not a finite number (one value of " + ctl.name +
                           " per line, one line per step, an optional first line '" + ctl.name + "')");
        ctl.table.push_back(x);
      }
      if (ctl.table.empty()) throw InputError(key_where(path, *csv, k + ".csv") + ": " + ctl.source + " holds no values");
    }
  }
  // [system] forces = { coordinate = "F_i(t, q, v)", ... }: generalized forces, by the
  // discrete Lagrange-d'Alembert principle (mechanics/written_force.h)
  if (const toml::node* f = sys.get("forces")) {
    const std::string key = "system.forces";
    if (!f->is_table())
      throw InputError(key_where(path, *f, key) + ": expected a table of coordinate = \"expression\" (the generalized "
                                                  "force along that coordinate, in t, the coordinates and velocities)");
    if (w->space == WrittenSystem::Space::sphere && w->factors > 1)
      throw InputError(key_where(path, *f, key) + ": forces are written on R^n, S^2 and SO(3); on (S^2)^" +
                       std::to_string(w->factors) + " a written system is conservative");
    const bool rotation = w->space == WrittenSystem::Space::rotation;
    // the keys: the coordinates (R^n; S^2: the embedding's x, y, z), on SO(3) the body
    // axes named by the angular velocity's components
    const std::vector<std::string> axes = rotation ? std::vector<std::string>{"w1", "w2", "w3"} : w->coordinates;
    for (const auto& [name, node] : *f->as_table()) {
      const std::string k = key + "." + std::string(name.str());
      int index = -1;
      for (std::size_t i = 0; i < axes.size(); ++i)
        if (axes[i] == name.str()) index = static_cast<int>(i);
      if (index < 0) {
        std::string known;
        for (std::size_t i = 0; i < axes.size() && i < 12; ++i) known += (i ? ", " : "") + axes[i];
        if (axes.size() > 12) known += ", ...";
        throw InputError(key_where(path, node, k) + ": '" + std::string(name.str()) + "' is not " +
                         (rotation ? "a body axis; on SO(3) a force is a body torque keyed by the axis it turns "
                                     "about ("
                                   : "a coordinate; a force is keyed by the coordinate it acts along (") +
                         known + ")");
      }
      if (!node.is_string()) throw InputError(key_where(path, node, k) + ": expected a string (an expression)");
      try {
        w->forces.emplace_back(index, Expression::parse(*node.value<std::string>(), w->symbols(WrittenSystem::Kind::force)));
      } catch (const ExpressionError& e) {
        throw InputError(string_location(path, node, e.offset) + ": in " + k + ": " + e.what());
      }
    }
    std::sort(w->forces.begin(), w->forces.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    if (!w->forces.empty()) pr.forces_where = key_where(path, *f, key);
  }
  for (std::size_t j = 0; j < w->controls.size(); ++j) {
    bool read = false;
    for (const auto& f : w->forces) read = read || f.second.uses(0, w->control_index(j));
    if (!read)
      throw InputError(key_where(path, *controls->as_table()->get(w->controls[j].name), "system.controls." + w->controls[j].name) +
                       ": no force reads the control '" + w->controls[j].name + "' (system.forces)");
  }
  // [system] constraints = ["g_1(t, q)", ...]: holonomic constraints g = 0
  // (mechanics/written_constraints.h)
  if (const toml::node* cs = sys.get("constraints")) {
    const std::string key = "system.constraints";
    const std::string shape = ": expected a list of expressions g(t, q), each constrained to 0 (e.g. [\"x^2 + y^2 - l^2\"])";
    if (!cs->is_array()) throw InputError(key_where(path, *cs, key) + shape);
    if (w->space == WrittenSystem::Space::sphere && w->factors > 1)
      throw InputError(key_where(path, *cs, key) + ": constraints are written on R^n, S^2 and SO(3); on (S^2)^" +
                       std::to_string(w->factors) + " a written system takes none");
    const toml::array& a = *cs->as_array();
    if (a.empty()) throw InputError(key_where(path, *cs, key) + ": an empty list" + shape.substr(1));
    for (std::size_t i = 0; i < a.size(); ++i) {
      const toml::node& node = a[i];
      const std::string k = key + "[" + std::to_string(i + 1) + "]";
      if (!node.is_string())
        throw InputError(key_where(path, node, k) + ": expected a string (an expression in t and " +
                         (w->space == WrittenSystem::Space::rotation ? "R11 ... R33" : "q") + ")");
      try {
        w->constraints.push_back(Expression::parse(*node.value<std::string>(), w->symbols(WrittenSystem::Kind::constraint)));
      } catch (const ExpressionError& e) {
        throw InputError(string_location(path, node, e.offset) + ": in " + k + ": " + e.what() +
                         (w->space == WrittenSystem::Space::rotation
                              ? " (a constraint on SO(3) is g(t, R): the entries R11 ... R33, t, the parameters and "
                                "the definitions)"
                              : " (a constraint is g(t, q): the coordinates, t, the parameters and the definitions)"));
      }
    }
    // the dimension the constraints cut down: R^n's coordinates, 2 on S^2, 3 on SO(3)
    const std::size_t dim = w->space == WrittenSystem::Space::euclidean ? w->coordinates.size()
                            : w->space == WrittenSystem::Space::sphere  ? 2
                                                                        : 3;
    if (a.size() >= dim)
      throw InputError(key_where(path, *cs, key) + ": " + std::to_string(a.size()) + " constraints on " +
                       (w->space == WrittenSystem::Space::euclidean ? std::to_string(dim) + " coordinates"
                        : w->space == WrittenSystem::Space::sphere  ? std::string("S^2 (dimension 2)")
                                                                    : std::string("SO(3) (dimension 3)")) +
                       " leave no motion; expected fewer constraints than " +
                       (w->space == WrittenSystem::Space::euclidean ? "coordinates" : "the space's dimension"));
    pr.constraints_where = key_where(path, *cs, key);
  }
  const toml::node* L = sys.get("lagrangian");
  pr.written_where = key_where(path, *L, "system.lagrangian");
  if (const toml::node* H = sys.get("hamiltonian")) pr.hamiltonian_where = key_where(path, *H, "system.hamiltonian");
  pr.system = &written_system_entry(space, w->factors, !w->forces.empty(), !w->constraints.empty(), w->time_dependent());
  pr.dim = w->dim();
  pr.written = std::move(w);
}

}  // namespace dvm
