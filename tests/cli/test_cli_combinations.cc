// Every combination the registries can name, run as `dvm run` runs a scene: for each system of
// `dvm systems` (and the written ones on R^n, with and without forces or constraints or t, S^2 and SO(3), with and
// without forces), each map of its space
// (and none), each form, compositions of each kind, each Galerkin method, and boundary
// values, a run of three steps must either
//   - exit 0 with the method it asked for (the JSON's map, form, composition, method and
//     order are the ones requested) and a displacement that agrees with an accurate
//     reference to the method's order (tests/displacement_check.h: a step that returns
//     its input, or a composition that drops a stage, fails it), and end where the
//     regression record says it ended (below), or
//   - exit 2 with a message naming a key of the scene ('integrator.*', 'problem.*'),
// and which of the two is decided by what the registry says the system runs (the
// capabilities `dvm systems --json` lists) and the rules of dvm::validate (written out
// below as the specification). No combination may do something else and exit 0.
//
// The reference of a system is the space's midpoint map composed by kahan-li8 (order 8)
// on the same grid; every other method agrees with it to its own order, so the
// reference is checked by the agreement of all the others.
//
// The regression record (combinations_record.txt beside this file) holds the final
// states of every run that exits 0, made by the program at a known revision: every run
// must end there to 1e-12 relative (|q - q_rec|_inf <= 1e-12 |q_rec|_inf, the same for
// p, and p_initial of boundary values). It guards refactorings: a change that moves a
// number by more than round-off must say which bug it fixes and remake the record. To
// remake it, run this program with DVM_COMBINATIONS_RECORD set to the
// file to write; a run missing from the record fails, naming this comment.
// DVM_TEST_BINARY runs the listings and the reference runs against another build of dvm.
//
// Each scene is read by the library's scene reader and run in this process (load_scene_text,
// make_run, execute, report_json: what `dvm run --json` does, without starting a process
// for each of the thousands of runs); a run refused with InputError counts as exit 2 with
// its message, a failed one as exit 3. The registries are read from the program's
// listings, and every reference run also through the program, whose JSON must equal the
// library's. The convergence studies run in this process too (converge, converge_json),
// each system's first also through `dvm converge`.
#define BOOST_TEST_MODULE cli_combinations
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "solvers/runtime/converge.h"
#include "solvers/runtime/run.h"
#include "solvers/runtime/scene.h"
#include "tests/address_sanitizer.h"
#include "tests/cli/cli_harness.h"
#include "tests/displacement_check.h"

namespace {

using namespace cli_test;

// The initial state of each system: a scene's [system] and [initial] sections, each a
// state that moves (a nonzero velocity and a nonzero force), so that three steps displace
// it well beyond round-off. A system added to the registry without an entry here fails
// the test (every system is walked).
const std::map<std::string, std::string>& heads() {
  static const std::map<std::string, std::string> h = {
      {"harmonic", "[system]\nbuiltin = \"harmonic\"\n[initial]\nq = [1.0]\np = [0.5]\n"},
      {"pendulum", "[system]\nbuiltin = \"pendulum\"\n[initial]\nq = [1.0]\np = [0.3]\n"},
      {"kepler", "[system]\nbuiltin = \"kepler\"\n[initial]\nq = [0.4, 0.0]\np = [0.0, 2.0]\n"},
      {"double-pendulum", "[system]\nbuiltin = \"double-pendulum\"\n[initial]\nq = [0.5, 0.3]\nv = [0.3, -0.2]\n"},
      {"henon-heiles", "[system]\nbuiltin = \"henon-heiles\"\n[initial]\nq = [0.0, 0.1]\np = [0.4, 0.2]\n"},
      {"fpu",
       "[system]\nbuiltin = \"fpu\"\n[initial]\nq = [0.69, 0.72, 0.0, 0.0, 0.0, 0.0]\np = [0.0, 1.41, 0.0, 0.0, 0.0, 0.0]\n"},
      {"duffing", "[system]\nbuiltin = \"duffing\"\n[initial]\nq = [1.5]\np = [0.4]\n"},
      {"charged-particle", "[system]\nbuiltin = \"charged-particle\"\n[initial]\nq = [1.0, 0.0]\nv = [0.0, 0.5]\n"},
      {"nbody",
       "[system]\nbuiltin = \"nbody\"\nmasses = [1.0, 1.0, 1.0]\n[initial]\n"
       "q = [0.97000436, -0.24308753, 0.0, -0.97000436, 0.24308753, 0.0, 0.0, 0.0, 0.0]\n"
       "v = [0.466203685, 0.43236573, 0.0, 0.466203685, 0.43236573, 0.0, -0.93240737, -0.86473146, 0.0]\n"},
      {"chain",
       "[system]\nbuiltin = \"chain\"\nparams = { n = 4, alpha = 0.25, beta = 1.0 }\n[initial]\n"
       "q = [0.5, 0.0, 0.0, 0.0]\np = [0.1, 0.2, 0.0, -0.1]\n"},
      {"lagrangian",
       "[system]\ncoordinates = [\"a\", \"b\"]\nlagrangian = \"a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + "
       "2*cos(a) + cos(b)\"\nhamiltonian = \"(p_a^2 + 2*p_b^2 - 2*p_a*p_b*cos(a - b))/(2*(1 + sin(a - b)^2)) - "
       "2*cos(a) - cos(b)\"\n[initial]\nq = [0.5, 0.3]\nv = [0.3, -0.2]\n"},
      {"lagrangian with forces",
       "[system]\ncoordinates = [\"a\", \"b\"]\nlagrangian = \"a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + "
       "2*cos(a) + cos(b)\"\nforces = { a = \"-0.3*a_dot + 0.5*cos(2*t)\", b = \"-0.2*(b_dot - a_dot)\" }\n"
       "[initial]\nq = [0.5, 0.3]\nv = [0.3, -0.2]\n"},
      // (M constant and not diagonal; the force reads t, q and the velocities)
      {"lagrangian, separable",
       "[system]\ncoordinates = [\"a\", \"b\"]\nlagrangian = \"a_dot^2 + a_dot*b_dot/2 + b_dot^2/2 + 2*cos(a) + "
       "cos(b) - 0.3*a*b\"\n[initial]\nq = [0.5, 0.3]\nv = [0.3, -0.2]\n"},
      {"lagrangian with forces, separable",
       "[system]\ncoordinates = [\"a\", \"b\"]\nlagrangian = \"a_dot^2 + a_dot*b_dot/2 + b_dot^2/2 + 2*cos(a) + "
       "cos(b) - 0.3*a*b\"\nforces = { a = \"-0.3*a_dot + 0.5*cos(2*t)\", b = \"-0.2*(b_dot - a_dot) + 0.1*a\" }\n"
       "[initial]\nq = [0.5, 0.3]\nv = [0.3, -0.2]\n"},
      {"lagrangian with constraints",
       "[system]\ncoordinates = [\"x\", \"y\"]\nlagrangian = \"(x_dot^2 + y_dot^2)/2 - y\"\n"
       "constraints = [\"x^2 + y^2 - 1\"]\n[initial]\nq = [0.6, -0.8]\nv = [0.4, 0.3]\n"},
      {"lagrangian depending on time",
       "[system]\ncoordinates = [\"a\", \"b\"]\nlagrangian = \"exp(0.2*t)*(a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + "
       "2*cos(a) + cos(b)) + 0.3*sin(3*t)*a\"\n[initial]\nq = [0.5, 0.3]\nv = [0.3, -0.2]\n"},
      // (M constant and not diagonal, U(t, q))
      {"lagrangian depending on time, separable",
       "[system]\ncoordinates = [\"a\", \"b\"]\nlagrangian = \"a_dot^2 + a_dot*b_dot/2 + b_dot^2/2 + "
       "(2 + 0.5*sin(3*t))*cos(a) + cos(b) - 0.3*a*b + 0.4*cos(2*t)*b\"\n[initial]\nq = [0.5, 0.3]\n"
       "v = [0.3, -0.2]\n"},
      {"lagrangian on S^2",
       "[system]\nspace = \"S^2\"\nlagrangian = \"(x_dot^2 + y_dot^2 + z_dot^2)/2 - z\"\n"
       "hamiltonian = \"(p_x^2 + p_y^2 + p_z^2)/2 + z\"\n[initial]\nq = [0.6, 0.0, -0.8]\nv = [0.0, 0.5, 0.0]\n"},
      {"lagrangian with forces on S^2",
       "[system]\nspace = \"S^2\"\nlagrangian = \"(x_dot^2 + y_dot^2 + z_dot^2)/2 - z\"\n"
       "hamiltonian = \"(p_x^2 + p_y^2 + p_z^2)/2 + z\"\n"
       "forces = { x = \"-0.3*x_dot + 0.5*cos(2*t)\", z = \"-0.2*z_dot\" }\n"
       "[initial]\nq = [0.6, 0.0, -0.8]\nv = [0.0, 0.5, 0.0]\n"},
      {"lagrangian with forces on SO(3)",
       "[system]\nspace = \"SO(3)\"\nlagrangian = \"(w1^2 + w2^2 + w3^2/2)/2 - R33\"\n"
       "hamiltonian = \"(pi1^2 + pi2^2 + 2*pi3^2)/2 + R33\"\n"
       "forces = { w1 = \"-0.3*w1 + 0.5*cos(2*t)\", w3 = \"-0.2*w3*R33\" }\n[initial]\n"
       "rotation = [0.9689124217106447, 0.24740395925452294, 0.0, 0.0]\nomega = [0.0, 0.3, 5.0]\n"},
      {"lagrangian on (S^2)^2",
       "[system]\nspace = \"(S^2)^2\"\nlagrangian = \"(x1_dot^2 + y1_dot^2 + z1_dot^2) + (x1_dot*x2_dot + y1_dot*y2_dot + "
       "z1_dot*z2_dot) + (x2_dot^2 + y2_dot^2 + z2_dot^2)/2 - 2*z1 - z2\"\n[initial]\n"
       "q = [0.6, 0.0, -0.8, 0.0, 0.6, -0.8]\nv = [0.0, 0.5, 0.0, 0.4, 0.4, 0.3]\n"},
      {"lagrangian on SO(3)",
       "[system]\nspace = \"SO(3)\"\nlagrangian = \"(w1^2 + w2^2 + w3^2/2)/2 - R33\"\n"
       "hamiltonian = \"(pi1^2 + pi2^2 + 2*pi3^2)/2 + R33\"\n[initial]\n"
       "rotation = [0.9689124217106447, 0.24740395925452294, 0.0, 0.0]\nomega = [0.0, 0.3, 5.0]\n"},
      {"spherical-pendulum",
       "[system]\nbuiltin = \"spherical-pendulum\"\n[initial]\nq = [0.6, 0.0, -0.8]\nv = [0.0, 0.5, 0.0]\n"},
      {"spherical-chain",
       "[system]\nbuiltin = \"spherical-chain\"\nparams = { n = 2 }\n[initial]\n"
       "q = [0.6, 0.0, -0.8, 0.0, 0.6, -0.8]\nv = [0.0, 0.5, 0.0, 0.3, 0.0, 0.0]\n"},
      {"rigid-body", "[system]\nbuiltin = \"rigid-body\"\n[initial]\nrotation = [1.0, 0.0, 0.0, 0.0]\nomega = [0.05, 1.0, 0.02]\n"},
      {"heavy-top",
       "[system]\nbuiltin = \"heavy-top\"\n[initial]\nrotation = [0.9689124217106447, 0.24740395925452294, 0.0, 0.0]\n"
       "omega = [0.0, 0.3, 5.0]\n"},
  };
  return h;
}

constexpr double kStep = 0.001;

// The end of a scene: three steps of 1e-3.
std::string integrator(const std::string& keys) {
  return "[integrator]\nstep = 0.001\nsteps = 3\n" + keys;
}

struct SystemCaps {
  std::string name, space;
  std::set<std::string> forms;
  bool retraction = false, composition = false, galerkin = false, boundary_value = false, written_maps = false;
  bool galerkin_gauss = true;  // Galerkin with Gauss quadrature too (where galerkin), not only Lobatto
};

// What `dvm systems --json` says each system runs.
std::vector<SystemCaps> registry_systems() {
  const Output o = cli_test::dvm({"systems", "--json"});
  BOOST_REQUIRE(o.status == 0);
  const Json listed = parse_json(o.out);
  BOOST_REQUIRE(listed.is_array());
  std::vector<SystemCaps> out;
  for (const Json& e : listed) {
    SystemCaps c;
    c.name = e.at("name").get<std::string>();
    c.space = e.at("space").get<std::string>();
    for (const Json& f : e.at("forms")) c.forms.insert(f.get<std::string>());
    c.retraction = e.at("retraction_maps").get<bool>();
    c.written_maps = e.at("written_maps").get<bool>();
    c.composition = e.at("composition").get<bool>();
    c.galerkin = e.at("galerkin").get<bool>();
    c.boundary_value = e.at("boundary_value").get<bool>();
    out.push_back(c);
  }
  // the written system: the run-time-sized capabilities
  SystemCaps w;
  w.name = "lagrangian";
  w.space = "R^n";
  w.forms = {"lagrangian", "hamiltonian"};
  w.retraction = w.composition = w.galerkin = true;  // written maps: no (run-time-sized steps)
  SystemCaps plain = w;  // (boundary values: the run-time-sized problem, not with forces, constraints or t)
  plain.boundary_value = true;
  out.push_back(plain);
  // written on R^n with forces: the lagrangian form (the forced theta step, its
  // compositions, Galerkin) and the hamiltonian form
  SystemCaps f = w;
  f.name = "lagrangian with forces";
  out.push_back(f);
  // written on R^n and separable (v^T M v / 2 - U(q), M constant), with forces or not:
  // every form, the SODE and Newmark forms too (the run-time-sized SODE step)
  for (const char* name : {"lagrangian, separable", "lagrangian with forces, separable"}) {
    SystemCaps sep = w;
    sep.name = name;
    sep.boundary_value = sep.name.find("forces") == std::string::npos;
    sep.forms = {"lagrangian", "hamiltonian", "sode1", "sode2", "newmark"};
    out.push_back(sep);
  }
  // written on R^n with constraints: the lagrangian form of the theta-family maps,
  // composed or not (the constrained theta step), its hamiltonian form (the cotangent
  // lift with multipliers), and Lobatto Galerkin (the constraints at its nodes)
  SystemCaps k = w;
  k.name = "lagrangian with constraints";
  k.forms = {"lagrangian", "hamiltonian"};
  k.galerkin_gauss = false;
  out.push_back(k);
  // written on R^n in t: the lagrangian form (the theta step, its compositions, Galerkin)
  // and the hamiltonian form
  SystemCaps td = w;
  td.name = "lagrangian depending on time";
  td.forms = {"lagrangian", "hamiltonian"};
  out.push_back(td);
  // and with M constant (v^T M v / 2 - U(t, q)): the SODE and Newmark forms too
  td.name = "lagrangian depending on time, separable";
  td.forms = {"lagrangian", "hamiltonian", "sode1", "sode2", "newmark"};
  out.push_back(td);
  // written on S^2 and SO(3): the capabilities of the spherical pendulum and the top
  for (const char* space : {"S^2", "SO(3)"}) {
    SystemCaps c = w;
    c.space = space;
    c.name = "lagrangian on " + c.space;
    c.boundary_value = c.space == "S^2";
    c.written_maps = true;  // sphere-written, so3-written
    out.push_back(c);
  }
  // written on S^2 and SO(3) with forces: the lagrangian form of the space's maps,
  // composed or not (the forced ManifoldStep), their hamiltonian form (the forced
  // ManifoldHamiltonianStep) and Galerkin (the forced ManifoldGalerkinStep)
  for (const char* space : {"S^2", "SO(3)"}) {
    SystemCaps c = w;
    c.space = space;
    c.name = "lagrangian with forces on " + c.space;
    c.forms = {"lagrangian", "hamiltonian"};
    c.galerkin = true;
    c.written_maps = true;
    out.push_back(c);
  }
  // written on (S^2)^K: the spherical chain's capabilities
  SystemCaps c = w;
  c.space = "S^2";
  c.name = "lagrangian on (S^2)^2";
  c.forms = {"lagrangian"};
  c.galerkin = false;
  c.written_maps = true;  // sphere-written on each factor
  out.push_back(c);
  return out;
}

std::vector<std::pair<std::string, std::string>> registry_maps() {  // (name, space)
  const Output o = cli_test::dvm({"maps", "--json"});
  BOOST_REQUIRE(o.status == 0);
  const Json listed = parse_json(o.out);
  BOOST_REQUIRE(listed.is_array());
  std::vector<std::pair<std::string, std::string>> out;
  for (const Json& e : listed) out.push_back({e.at("name").get<std::string>(), e.at("space").get<std::string>()});
  return out;
}

// The orders `dvm methods --json` gives: compositions by name, Galerkin methods by
// "galerkin <quadrature> s=<stages>".
const std::map<std::string, int>& registry_orders() {
  static const std::map<std::string, int> orders = [] {
    const Output o = cli_test::dvm({"methods", "--json"});
    BOOST_REQUIRE(o.status == 0);
    std::map<std::string, int> out;
    for (const Json& e : parse_json(o.out)) {
      const std::string name = e.at("name").get<std::string>();
      if (!e.contains("order") || !e.at("order").is_number()) continue;  // "none": the map's order
      const int order = e.at("order").get<int>();
      if (name == "galerkin")
        out["galerkin " + e.at("quadrature").get<std::string>() + " s=" + std::to_string(e.at("stages").get<int>())] =
            order;
      else
        out[name] = order;
    }
    return out;
  }();
  return orders;
}

// The maps of `dvm maps --json` whose basic step has order 2: the symmetric ones, and those
// that take integrator.theta, which the scenes here leave at its default 1/2.
const std::set<std::string>& second_order_maps() {
  static const std::set<std::string> maps = [] {
    const Output o = cli_test::dvm({"maps", "--json"});
    BOOST_REQUIRE(o.status == 0);
    std::set<std::string> out;
    for (const Json& e : parse_json(o.out))
      if (e.at("symmetric").get<bool>() || e.at("takes_theta").get<bool>()) out.insert(e.at("name").get<std::string>());
    return out;
  }();
  return maps;
}

// The order a map-based method is built to have: the composition's, else the map's (2 for
// the maps above and Newmark at gamma = 1/2; none given: the form's own, the midpoint map).
int expected_order(const std::string& map, const std::string& composition) {
  if (composition != "none") {
    if (composition.rfind("triple-jump:", 0) == 0) return std::stoi(composition.substr(12));
    const auto it = registry_orders().find(composition);
    BOOST_REQUIRE_MESSAGE(it != registry_orders().end(), "no order listed for composition " << composition);
    return it->second;
  }
  return map.empty() || map == "newmark" || second_order_maps().count(map) ? 2 : 1;
}

// `dvm run SCENE --json --quiet` on a scene text, in this process: status 0 (the report's
// JSON on out), 2 (bad input: the message on err), or 3 (a failed run).
Output run_scene_text(const std::string& text) {
  Output o{0, "", ""};
  try {
    const dvm::Scene s = dvm::load_scene_text(text, "combination.toml", {});
    const auto run = dvm::make_run(s.problem, s.method);
    dvm::OutputSpec spec;
    spec.every = s.every;
    spec.monitor_every = s.monitor_every;
    dvm::Recorder rec(spec);
    const dvm::RunReport r = run->execute(&rec);
    o.out = dvm::report_json(r) + "\n";
    o.status = r.failed || r.output_error ? 3 : 0;
  } catch (const dvm::InputError& e) {
    o.status = 2;
    o.err = std::string("dvm: ") + e.what() + "\n";
  }
  return o;
}

// `dvm converge SCENE --steps-list N1,N2,... --json` on a scene text, in this process
// (what the program does for it: load_scene_text, converge, converge_json): status 0
// (the study's JSON on out), 2 (bad input: the message on err), or 3 (a run failed).
Output converge_scene_text(const std::string& text, const std::vector<std::int64_t>& steps) {
  Output o{0, "", ""};
  try {
    const dvm::Scene s = dvm::load_scene_text(text, "conv.toml", {});
    dvm::ConvergeOptions options;
    options.steps_list = steps;
    const dvm::ConvergeReport r = dvm::converge(s.problem, s.method, options);
    o.out = dvm::converge_json(r) + "\n";
    o.status = r.failure.empty() ? 0 : 3;
  } catch (const dvm::InputError& e) {
    o.status = 2;
    o.err = std::string("dvm: ") + e.what() + "\n";
  }
  return o;
}

bool names_a_key(const std::string& err) {
  return err.find("key 'integrator.") != std::string::npos || err.find("key 'problem.") != std::string::npos;
}

// ---- the regression record -------------------------------------------------------------
using Record = std::map<std::string, std::vector<double>>;

const char* record_out() {
  const char* path = std::getenv("DVM_COMBINATIONS_RECORD");
  return path && *path ? path : nullptr;
}

const Record& record() {
  static const Record r = [] {
    Record out;
    if (record_out()) return out;
    std::ifstream in(COMBINATIONS_RECORD);
    BOOST_REQUIRE_MESSAGE(in, "cannot read the regression record " << COMBINATIONS_RECORD);
    std::string line;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      const auto tab = line.find('\t');
      BOOST_REQUIRE_MESSAGE(tab != std::string::npos, "bad record line: " << line);
      std::vector<double> values;
      std::istringstream numbers(line.substr(tab + 1));
      for (double x; numbers >> x;) values.push_back(x);
      out[line.substr(0, tab)] = values;
    }
    return out;
  }();
  return r;
}

// What a run that exits 0 is recorded by: its final state, and the solved first momentum
// of a boundary-value problem.
std::vector<double> recorded_values(const Json& j) {
  std::vector<double> v;
  for (const char* key : {"q_final", "p_final"})
    for (const Json& x : j.at(key)) v.push_back(json_double(x));
  if (j.at("problem") == "boundary-value")
    for (const Json& x : j.at("p_initial")) v.push_back(json_double(x));
  return v;
}

void check_record(const std::string& what, const Json& j) {
  const std::vector<double> v = recorded_values(j);
  if (const char* path = record_out()) {
    std::ofstream out(path, std::ios::app);
    out.precision(17);
    out << what;
    for (std::size_t i = 0; i < v.size(); ++i) out << (i == 0 ? "\t" : " ") << v[i];
    out << "\n";
    return;
  }
  const auto it = record().find(what);
  BOOST_REQUIRE_MESSAGE(it != record().end(),
                        "not in the regression record: a combination added since it was made (remake it as the "
                        "opening comment of this file says)");
  const std::vector<double>& r = it->second;
  BOOST_TEST_REQUIRE(r.size() == v.size());
  // q_final, p_final (and p_initial) each to 1e-12 relative
  const std::size_t nq = j.at("q_final").size(), np = j.at("p_final").size();
  std::size_t from = 0;
  for (std::size_t len : {nq, np, v.size() - nq - np}) {
    if (len == 0) continue;
    const std::vector<double> a(v.begin() + from, v.begin() + from + len), b(r.begin() + from, r.begin() + from + len);
    const double diff = dvm_test::relative_difference(a, b);
    BOOST_TEST(diff <= 1e-12, "values " << from << ".." << from + len << " differ from the record by " << diff
                                        << " relative");
    from += len;
  }
}

// ---- one run, judged ------------------------------------------------------------------
// The reference of a system: its initial state and the displacement of the space's
// midpoint map composed to order 8, on the same grid.
struct Reference {
  std::vector<double> q0, p0, dq, dp;
};

int g_runs = 0, g_ok = 0, g_refused = 0;
double g_worst_margin = 0.0;  // the largest error / tolerance of a run that passed
std::string g_worst;

// Runs the scene and checks the outcome against `supported`. `order` is the order the run
// must report and be accurate to (0: none checked); `ref` the reference (null: the
// displacement is not checked).
void check(const std::string& what, const std::string& text, bool supported, const Reference* ref, int order,
           const std::map<std::string, std::string>& expect) {
  const Output o = run_scene_text(text);
  ++g_runs;
  BOOST_TEST_CONTEXT(what << "\n" << o.err << o.out) {
    if (!supported) {
      ++g_refused;
      BOOST_TEST(o.status == 2);
      BOOST_TEST(names_a_key(o.err));
      BOOST_TEST(o.out.empty());
      return;
    }
    ++g_ok;
    BOOST_TEST_REQUIRE(o.status == 0);
    const Json j = parse_json(o.out);
    BOOST_TEST(j.at("status") == "ok");
    for (const auto& [key, value] : expect) BOOST_TEST(j.at(key).get<std::string>() == value, key);
    BOOST_TEST(std::isfinite(json_double(j.at("energy_final"))));
    check_record(what, j);
    if (record_out()) return;  // (an older program may report no initial state or order)
    if (order > 0) BOOST_TEST(j.at("order").get<int>() == order);
    if (!ref) return;
    std::vector<double> q, p, q0, p0;
    for (const Json& x : j.at("q_final")) q.push_back(json_double(x));
    for (const Json& x : j.at("p_final")) p.push_back(json_double(x));
    for (const Json& x : j.at("q_initial")) q0.push_back(json_double(x));
    for (const Json& x : j.at("p_initial")) p0.push_back(json_double(x));
    // the run started where the reference did
    BOOST_TEST(dvm_test::relative_difference(q0, ref->q0) <= 1e-15);
    BOOST_TEST(dvm_test::relative_difference(p0, ref->p0) <= 1e-12);
    const auto verdict = dvm_test::judge_displacement(q0, p0, q, p, ref->dq, ref->dp, order, kStep);
    BOOST_TEST(verdict.ok, verdict.message);
    const double margin = std::fmax(verdict.error_q, verdict.error_p) / verdict.tol;
    if (verdict.ok && margin > g_worst_margin) {
      g_worst_margin = margin;
      g_worst = what;
    }
  }
}

// map = "written": the midpoint map written in the scene (its [map] section follows the
// [integrator] keys)
const char* kWrittenMidpoint = "[map]\nq0 = \"x - v/2\"\nq1 = \"x + v/2\"\n";
// map = "sphere-written": the projection retraction; "so3-written": R (I + hat(w)),
// orthonormalised (a retraction of its own)
const char* kWrittenSphere = "[map]\nretraction = [\"x1 + v1\", \"x2 + v2\", \"x3 + v3\"]\n";
const char* kWrittenRotation =
    "[map]\nretraction = [\"R11 + R12*w3 - R13*w2\", \"R12 - R11*w3 + R13*w1\", \"R13 + R11*w2 - R12*w1\",\n"
    "  \"R21 + R22*w3 - R23*w2\", \"R22 - R21*w3 + R23*w1\", \"R23 + R21*w2 - R22*w1\",\n"
    "  \"R31 + R32*w3 - R33*w2\", \"R32 - R31*w3 + R33*w1\", \"R33 + R31*w2 - R32*w1\"]\n";
// The [map] section a map needs (none for the built-in maps).
std::string map_section(const std::string& map) {
  return map == "written" ? kWrittenMidpoint : map == "sphere-written" ? kWrittenSphere
                                             : map == "so3-written"    ? kWrittenRotation
                                                                       : "";
}
bool is_written_map(const std::string& map) {
  return map == "written" || map == "sphere-written" || map == "so3-written";
}

const char* kCompositions[] = {"none", "stormer-verlet", "mclachlan4", "kahan-li8", "triple-jump:6"};
// Under AddressSanitizer the compositions of most stages are left out: the four are
// symmetric compositions of one kind (solvers/composition_methods.h), each run as the
// same ComposedStep of the same step type, a stage (and on a map that is not symmetric a
// half stage of its adjoint) per coefficient; only the coefficients differ. So
// stormer-verlet (1 coefficient) and mclachlan4 (5) take every path the sanitizers
// check, and kahan-li8 (17) and triple-jump:6 (9) would take them again. (Each system's
// reference, kahan-li8 of its space's midpoint map, still runs under the sanitizers.)
bool sanitized_composition_skipped(const std::string& c) {
  return dvm_tests::kAddressSanitizer && (c == "kahan-li8" || c == "triple-jump:6");
}
const char* kForms[] = {"lagrangian", "hamiltonian", "sode1", "sode2", "newmark"};

std::string midpoint_map(const std::string& space) {
  return space == "S^2" ? "sphere-exp" : space == "SO(3)" ? "so3-exp" : "midpoint";
}

// The reference run of a system (see the opening comment).
Reference reference_of(const std::string& head, const std::string& space) {
  const std::string text =
      head + integrator("map = \"" + midpoint_map(space) + "\"\ncomposition = \"kahan-li8\"\n");
  const Output o = cli_test::dvm({"run", write_scene("ref.toml", text), "--json", "--quiet"});
  BOOST_REQUIRE_MESSAGE(o.status == 0, o.err);
  if (!std::getenv("DVM_TEST_BINARY")) {  // the program and the library: one result
    Json a = parse_json(o.out), b = parse_json(run_scene_text(text).out);
    a.erase("wall_seconds");
    b.erase("wall_seconds");
    BOOST_TEST(a == b, "dvm run and the library differ:\n" << a.dump(2) << "\n" << b.dump(2));
  }
  Reference r;
  if (record_out()) return r;
  const Json j = parse_json(o.out);
  std::vector<double> q, p;
  for (const Json& x : j.at("q_initial")) r.q0.push_back(json_double(x));
  for (const Json& x : j.at("p_initial")) r.p0.push_back(json_double(x));
  for (const Json& x : j.at("q_final")) q.push_back(json_double(x));
  for (const Json& x : j.at("p_final")) p.push_back(json_double(x));
  r.dq = dvm_test::displacement(r.q0, q);
  r.dp = dvm_test::displacement(r.p0, p);
  return r;
}

// The final q of the space's plain midpoint run (the end of the boundary-value problems).
std::vector<double> midpoint_end(const std::string& head, const std::string& space) {
  const Output o = run_scene_text(head + integrator("map = \"" + midpoint_map(space) + "\"\n"));
  BOOST_REQUIRE_MESSAGE(o.status == 0, o.err);
  return json_array(o.out, "q_final");
}

}  // namespace

BOOST_AUTO_TEST_CASE(every_combination_runs_or_is_refused_naming_the_keys) {
  const std::vector<SystemCaps> systems = registry_systems();
  const auto maps = registry_maps();
  BOOST_REQUIRE(systems.size() >= 15);
  BOOST_REQUIRE(maps.size() >= 13);
  for (const SystemCaps& sys : systems) {
    BOOST_TEST_CONTEXT("system " << sys.name) {
      const auto h = heads().find(sys.name);
      BOOST_REQUIRE_MESSAGE(h != heads().end(), "no initial state for system " << sys.name << " in this test");
      const std::string head = h->second;
      const Reference ref = reference_of(head, sys.space);
      const Reference* r = record_out() ? nullptr : &ref;

      std::vector<std::string> space_maps = {""};  // "": no map key
      for (const auto& [name, space] : maps)
        if (space == sys.space) space_maps.push_back(name);
      for (const std::string& map : space_maps)
        for (const char* form : kForms)
          for (const char* comp : kCompositions) {
            const std::string f = form, c = comp;
            if (sanitized_composition_skipped(c)) continue;
            std::string keys = "form = \"" + f + "\"\n";
            if (!map.empty()) keys += "map = \"" + map + "\"\n";
            if (c != "none") keys += "composition = \"" + c + "\"\n";
            keys += map_section(map);
            const bool map_ok = f == "newmark" || !map.empty();
            const bool supported = sys.forms.count(f) && map_ok && (c == "none" || sys.composition) &&
                                   (map != "retraction-theta" || sys.retraction) &&
                                   (!is_written_map(map) || (sys.retraction && sys.written_maps));
            std::map<std::string, std::string> expect = {{"form", f}, {"composition", c}, {"method", "map"}};
            if (f == "newmark")
              expect["map"] = "newmark";
            else if (map == "retraction-theta")
              expect["map"] = "retraction-theta(euclidean)";
            else
              expect["map"] = map;
            check(sys.name + " map=" + map + " form=" + f + " composition=" + c, head + integrator(keys), supported, r,
                  expected_order(f == "newmark" ? "newmark" : map, c), expect);
          }
      // Galerkin: every quadrature and stage count; with another form or a composition
      for (const char* quad : {"gauss", "lobatto"})
        for (int s = 1; s <= 6; ++s) {
          const std::string name = "galerkin " + std::string(quad) + " s=" + std::to_string(s);
          const auto order = registry_orders().find(name);
          BOOST_REQUIRE_MESSAGE(order != registry_orders().end(), "no order listed for " << name);
          check(sys.name + " " + name,
                head + integrator("method = \"galerkin\"\nquadrature = \"" + std::string(quad) +
                                  "\"\nstages = " + std::to_string(s) + "\n"),
                sys.galerkin && (sys.galerkin_gauss || std::string(quad) == "lobatto"), r, order->second,
                {{"method", "galerkin"}, {"map", "none"}, {"quadrature", quad}});
        }
      check(sys.name + " galerkin hamiltonian", head + integrator("method = \"galerkin\"\nform = \"hamiltonian\"\n"),
            false, nullptr, 0, {});
      check(sys.name + " galerkin composed", head + integrator("method = \"galerkin\"\ncomposition = \"triple-jump\"\n"),
            false, nullptr, 0, {});
      // boundary values between the initial point and where the midpoint run ends
      const std::vector<double> q_end = midpoint_end(head, sys.space);
      std::string qf = "[";
      for (std::size_t i = 0; i < q_end.size(); ++i) {
        char buf[40];
        std::snprintf(buf, sizeof buf, "%s%.17g", i ? ", " : "", q_end[i]);
        qf += buf;
      }
      qf += "]";
      const std::size_t qat = head.find("\nq = ");  // (SO(3) systems give a rotation: no boundary values)
      const std::string q0 = qat == std::string::npos ? "" : head.substr(qat + 1, head.find('\n', qat + 1) - qat - 1);
      const std::string sys_section = head.substr(0, head.find("[initial]"));
      for (const std::string& map : space_maps)
        for (const char* form : {"lagrangian", "hamiltonian"}) {
          if (map.empty()) continue;
          if (q0.empty()) {
            check(sys.name + " boundary-value map=" + map + " form=" + form,
                  head + "[problem]\nkind = \"boundary-value\"\nq_final = [1.0, 0.0, 0.0, 0.0]\nsteps = 3\n" +
                      "[integrator]\nstep = 0.001\nmap = \"" + map + "\"\n",
                  sys.boundary_value, nullptr, 0, {{"problem", "boundary-value"}});
            continue;
          }
          const std::string f = form;
          const std::string text = sys_section + "[initial]\n" + q0 + "\n[problem]\nkind = \"boundary-value\"\n" +
                                   "q_final = " + qf + "\nsteps = 3\n[integrator]\nstep = 0.001\nmap = \"" + map +
                                   "\"\nform = \"" + f + "\"\n" + map_section(map);
          const bool supported = sys.boundary_value && f == "lagrangian" &&
                                 (map != "retraction-theta" || sys.retraction) &&
                                 (!is_written_map(map) || sys.written_maps);
          check(sys.name + " boundary-value map=" + map + " form=" + f, text, supported, nullptr, 0,
                {{"problem", "boundary-value"}});
          if (!supported || record_out()) continue;
          // The solved first momentum is that of the initial state the midpoint run started
          // from, to the map's order (exactly, to round-off, for the midpoint map itself).
          const Output o = run_scene_text(text);
          const std::vector<double> p_initial = json_array(o.out, "p_initial");
          const int order = expected_order(map, "none");
          const double tol = map == midpoint_map(sys.space) ? 1e-9 : dvm_test::displacement_tolerance(order, kStep);
          BOOST_TEST(dvm_test::relative_difference(p_initial, ref.p0) <= tol,
                     sys.name << " boundary-value map=" << map << ": p_initial " << o.out);
        }
    }
  }
  BOOST_TEST_MESSAGE(g_runs << " runs: " << g_ok << " ran, " << g_refused << " refused; the closest to its tolerance: "
                            << g_worst << " at " << g_worst_margin << " of it");
}

// A splitting into kicks and drifts on every system: with each Euler map (and the
// theta map at 0), the space's midpoint map, in the lagrangian, hamiltonian and sode1
// forms. They run on R^n, on a system that composes and is separable (not the double
// pendulum, the charged particle or the written double pendulum), in the lagrangian or
// hamiltonian form, with an Euler map; every other case is refused naming a key.
BOOST_AUTO_TEST_CASE(every_splitting_runs_or_is_refused) {
  // (with forces: kicks are the gradient of a potential, which a force is not)
  // (with constraints: the drifts leave them; in t: no structure is read off the text)
  const std::set<std::string> not_separable = {"double-pendulum", "charged-particle", "lagrangian",
                                               "lagrangian with forces", "lagrangian with forces, separable",
                                               "lagrangian with constraints", "lagrangian depending on time",
                                               "lagrangian depending on time, separable"};
  for (const SystemCaps& sys : registry_systems()) {
    const std::string head = heads().at(sys.name);
    const Reference ref = reference_of(head, sys.space);
    for (const char* comp : {"blanes-moan4"})  // (blanes-moan6 takes the same path and rules)
      for (const std::string& map : {std::string("explicit-euler"), std::string("adjoint-euler"), std::string("theta"),
                                     midpoint_map(sys.space)})
        for (const char* form : {"lagrangian", "hamiltonian", "sode1"}) {
          const std::string f = form;
          const bool euler = map != midpoint_map(sys.space);
          const bool supported = sys.space == "R^n" && sys.composition && sys.forms.count(f) &&
                                 (f == "lagrangian" || f == "hamiltonian") && euler && !not_separable.count(sys.name);
          const std::string keys = "form = \"" + f + "\"\nmap = \"" + map + "\"\ncomposition = \"" + comp + "\"\n" +
                                   (map == "theta" ? "theta = 0.0\n" : "");
          check(sys.name + " map=" + map + " form=" + f + " composition=" + comp, head + integrator(keys), supported,
                record_out() ? nullptr : &ref, expected_order(map, comp),
                {{"form", f}, {"composition", comp}, {"map", map}});
        }
  }
}

// integrator.lift and integrator.thetas on every system: each lift of the registry in
// the forms it names and in one it does not, with the space's midpoint map and its
// theta map, and a theta per stage of a dirk composition. Runs where the rules say it
// applies (the JSON names the lift asked for), is refused naming a key otherwise:
//   lift: the form is one of the lift's (cotangent, none: hamiltonian; tangent,
//   legendre: sode1, sode2), none only on R^n, none and legendre only with the theta
//   maps of R^n; thetas: a map that takes theta and a system that composes.
// The theta maps run at their default theta (1/2: the midpoint map of their space,
// order 2); the dirk pair of thetas 0.4 and 0.6 over weights 1/2, 1/2 is a symmetric
// pair, order 2.
BOOST_AUTO_TEST_CASE(every_lift_and_theta_per_stage_runs_or_is_refused) {
  const std::map<std::string, std::set<std::string>> lift_forms = {{"cotangent", {"hamiltonian"}},
                                                                   {"none", {"hamiltonian"}},
                                                                   {"tangent", {"sode1", "sode2"}},
                                                                   {"legendre", {"sode1", "sode2"}}};
  const Output listed = cli_test::dvm({"methods"});
  BOOST_REQUIRE(listed.status == 0);
  for (const auto& [lift, forms] : lift_forms) BOOST_TEST(listed.out.find("  " + lift + " ") != std::string::npos);
  const int runs_before = g_runs;
  for (const SystemCaps& sys : registry_systems()) {
    const std::string head = heads().at(sys.name);
    const Reference ref = reference_of(head, sys.space);
    const Reference* r = record_out() ? nullptr : &ref;
    const std::string theta_map = sys.space == "S^2" ? "sphere-exp-theta" : sys.space == "SO(3)" ? "so3-exp-theta" : "theta";
    for (const std::string& map : {midpoint_map(sys.space), theta_map})
      for (const char* form : {"lagrangian", "hamiltonian", "sode2"}) {
        const std::string f = form;
        const std::string base = "form = \"" + f + "\"\nmap = \"" + map + "\"\n";
        for (const auto& [lift, forms] : lift_forms) {
          const bool theta_family = sys.space == "R^n";  // midpoint and theta are theta maps there
          // (lift = "none", the map on T*Q itself, takes no constraints)
          const bool supported = sys.forms.count(f) && forms.count(f) && (lift != "none" || sys.space == "R^n") &&
                                 ((lift != "none" && lift != "legendre") || theta_family) &&
                                 (lift != "none" || sys.name != "lagrangian with constraints");
          check(sys.name + " map=" + map + " form=" + f + " lift=" + lift,
                head + integrator(base + "lift = \"" + lift + "\"\n"), supported, r, 2,
                {{"form", f}, {"lift", lift}, {"map", map}});
        }
        const bool takes_theta = map == theta_map;
        check(sys.name + " map=" + map + " form=" + f + " thetas",
              head + integrator(base + "composition = \"dirk\"\nweights = [0.5, 0.5]\nthetas = [0.4, 0.6]\n"),
              sys.forms.count(f) && sys.composition && takes_theta, r, 2,
              {{"form", f}, {"composition", "dirk"}, {"map", map}});
      }
  }
  BOOST_TEST_MESSAGE(g_runs - runs_before << " runs of lifts and thetas");
}

// dvm converge on every form, on every space, composed: a table whose runs used the
// method asked for (the order measured is the method's), or exit 2 naming the keys. The
// studies run in this process, as the scenes of the cross product do; each system's
// first combination also through `dvm converge`, whose JSON must equal the library's
// (the runs' wall times aside) and whose exit status must be the same.
BOOST_AUTO_TEST_CASE(converge_runs_every_combination_or_refuses_it) {
  int studied = 0, refused = 0, through = 0;
  for (const SystemCaps& sys : registry_systems()) {
    const std::string head = heads().at(sys.name);
    bool through_dvm = true;
    for (const char* form : kForms)
      for (const char* comp : {"none", "stormer-verlet"}) {
        const std::string f = form, c = comp;
        std::string keys = "form = \"" + f + "\"\nmap = \"" + midpoint_map(sys.space) + "\"\n";
        if (c != "none") keys += "composition = \"" + c + "\"\n";
        const bool supported = sys.forms.count(f) && (c == "none" || sys.composition);
        const std::string text = head + integrator(keys);
        const Output o = converge_scene_text(text, {2, 4});
        if (through_dvm) {
          through_dvm = false;
          ++through;
          const Output d = cli_test::dvm({"converge", write_scene("conv.toml", text), "--steps-list", "2,4", "--json"});
          BOOST_TEST_CONTEXT(sys.name << " dvm converge form=" << f << " composition=" << c << "\n" << d.err) {
            BOOST_TEST(d.status == o.status);
            BOOST_TEST(d.err.find(o.err) != std::string::npos, o.err);
            if (d.status == 0 && !std::getenv("DVM_TEST_BINARY")) {  // another build may differ
              Json a = parse_json(d.out), b = parse_json(o.out);
              for (Json* j : {&a, &b})
                for (Json& row : j->at("runs")) row.erase("wall_seconds");
              BOOST_TEST(a == b, "dvm converge and the library differ:\n" << a.dump(2) << "\n" << b.dump(2));
            }
          }
        }
        BOOST_TEST_CONTEXT(sys.name << " converge form=" << f << " composition=" << c << "\n" << o.err << o.out) {
          if (supported) {
            BOOST_TEST(o.status == 0);
            const Json j = parse_json(o.out);
            BOOST_TEST(j.at("form") == f);
            BOOST_TEST(j.at("composition") == c);
            BOOST_TEST(j.contains("fitted_order"));
            ++studied;
          } else {
            BOOST_TEST(o.status == 2);
            BOOST_TEST(names_a_key(o.err));
            ++refused;
          }
        }
      }
  }
  BOOST_TEST_MESSAGE(studied << " studies, " << refused << " refused, " << through << " through dvm converge");
  BOOST_TEST(studied >= 100);
  BOOST_TEST(refused >= 10);
  BOOST_TEST(through == static_cast<int>(registry_systems().size()));
}

// The check itself, on a real run's numbers: it passes the run and fails the same run
// reported by a step that returns its input (the final state equal to the initial one),
// which passes every other check of this suite. (A composition that drops a stage is
// shown to fail it in tests/solvers/test_composition.cc, on the step itself.)
BOOST_AUTO_TEST_CASE(the_displacement_check_fails_a_step_that_does_nothing) {
  if (record_out()) return;
  const std::string head = heads().at("kepler");
  const Reference ref = reference_of(head, "R^n");
  const Output good = cli_test::dvm({"run", write_scene("k.toml", head + integrator("map = \"midpoint\"\n")), "--json", "--quiet"});
  BOOST_REQUIRE(good.status == 0);
  const Json j = parse_json(good.out);
  auto numbers = [&](const char* key) { return j.at(key).get<std::vector<double>>(); };
  const auto q0 = numbers("q_initial"), p0 = numbers("p_initial");
  BOOST_TEST(dvm_test::judge_displacement(q0, p0, numbers("q_final"), numbers("p_final"), ref.dq, ref.dp, 2, kStep).ok);
  const auto idle = dvm_test::judge_displacement(q0, p0, q0, p0, ref.dq, ref.dp, 2, kStep);
  BOOST_TEST(!idle.ok);
  BOOST_TEST(idle.error_q == 1.0);
  BOOST_TEST(idle.error_p == 1.0);
}
