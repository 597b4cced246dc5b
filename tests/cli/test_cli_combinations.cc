// Every combination the registries can name, through `dvm run`: for each system of
// `dvm systems` (and the written ones on R^n, S^2 and SO(3)), each map of its space
// (and none), each form, compositions of each kind, each Galerkin method, and boundary
// values, a run of three steps must either
//   - exit 0 with the method it asked for (the JSON's map, form, composition and
//     method are the ones requested) and a plausible result (finite, and within 1e-2
//     of the plain midpoint run of the same system), or
//   - exit 2 with a message naming a key of the scene ('integrator.*', 'problem.*'),
// and which of the two is decided by what the registry says the system runs (the
// capabilities `dvm systems --json` lists) and the rules of dvm::validate (written out
// below as the specification). No combination may do something else and exit 0.
// ctest runs it as two processes (`-- --shard=1/2` and `2/2`), each walking half of the
// systems; run by hand without the argument, it walks them all.
#define BOOST_TEST_MODULE cli_combinations
#include <boost/test/unit_test.hpp>

#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "tests/cli/cli_harness.h"

namespace {

using namespace cli_test;

// The initial state of each system: a scene's [system] and [initial] sections. A system
// added to the registry without an entry here fails the test (every system is walked).
const std::map<std::string, std::string>& heads() {
  static const std::map<std::string, std::string> h = {
      {"harmonic", "[system]\nbuiltin = \"harmonic\"\n[initial]\nq = [1.0]\np = [0.0]\n"},
      {"pendulum", "[system]\nbuiltin = \"pendulum\"\n[initial]\nq = [1.0]\np = [0.0]\n"},
      {"kepler", "[system]\nbuiltin = \"kepler\"\n[initial]\nq = [0.4, 0.0]\np = [0.0, 2.0]\n"},
      {"double-pendulum", "[system]\nbuiltin = \"double-pendulum\"\n[initial]\nq = [0.5, 0.3]\nv = [0.0, 0.0]\n"},
      {"henon-heiles", "[system]\nbuiltin = \"henon-heiles\"\n[initial]\nq = [0.0, 0.1]\np = [0.4, 0.2]\n"},
      {"fpu",
       "[system]\nbuiltin = \"fpu\"\n[initial]\nq = [0.69, 0.72, 0.0, 0.0, 0.0, 0.0]\np = [0.0, 1.41, 0.0, 0.0, 0.0, 0.0]\n"},
      {"duffing", "[system]\nbuiltin = \"duffing\"\n[initial]\nq = [1.5]\np = [0.0]\n"},
      {"charged-particle", "[system]\nbuiltin = \"charged-particle\"\n[initial]\nq = [1.0, 0.0]\nv = [0.0, 0.5]\n"},
      {"nbody",
       "[system]\nbuiltin = \"nbody\"\nmasses = [1.0, 1.0, 1.0]\n[initial]\n"
       "q = [0.97000436, -0.24308753, 0.0, -0.97000436, 0.24308753, 0.0, 0.0, 0.0, 0.0]\n"
       "v = [0.466203685, 0.43236573, 0.0, 0.466203685, 0.43236573, 0.0, -0.93240737, -0.86473146, 0.0]\n"},
      {"chain",
       "[system]\nbuiltin = \"chain\"\nparams = { n = 4, alpha = 0.25, beta = 1.0 }\n[initial]\n"
       "q = [0.5, 0.0, 0.0, 0.0]\np = [0.0, 0.0, 0.0, 0.0]\n"},
      {"lagrangian",
       "[system]\ncoordinates = [\"a\", \"b\"]\nlagrangian = \"a_dot^2 + b_dot^2/2 + a_dot*b_dot*cos(a - b) + "
       "2*cos(a) + cos(b)\"\nhamiltonian = \"(p_a^2 + 2*p_b^2 - 2*p_a*p_b*cos(a - b))/(2*(1 + sin(a - b)^2)) - "
       "2*cos(a) - cos(b)\"\n[initial]\nq = [0.5, 0.3]\nv = [0.0, 0.0]\n"},
      {"lagrangian on S^2",
       "[system]\nspace = \"S^2\"\nlagrangian = \"(x_dot^2 + y_dot^2 + z_dot^2)/2 - z\"\n"
       "hamiltonian = \"(p_x^2 + p_y^2 + p_z^2)/2 + z\"\n[initial]\nq = [0.6, 0.0, -0.8]\nv = [0.0, 0.5, 0.0]\n"},
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

// The end of a scene: three steps of 1e-3.
std::string integrator(const std::string& keys) {
  return "[integrator]\nstep = 0.001\nsteps = 3\n" + keys;
}

struct SystemCaps {
  std::string name, space;
  std::set<std::string> forms;
  bool retraction = false, composition = false, galerkin = false, boundary_value = false, written_maps = false;
};

bool json_bool(const std::string& json, const std::string& key, std::size_t from) {
  const auto pos = json.find("\"" + key + "\": ", from);
  return pos != std::string::npos && json.compare(pos + key.size() + 4, 4, "true") == 0;
}

// What `dvm systems --json` says each system runs.
std::vector<SystemCaps> registry_systems() {
  const Output o = dvm({"systems", "--json"});
  BOOST_REQUIRE(o.status == 0);
  std::vector<SystemCaps> out;
  std::size_t at = 0;
  while ((at = o.out.find("\"name\": \"", at)) != std::string::npos) {
    SystemCaps c;
    c.name = json_string(o.out, "name", at);
    c.space = json_string(o.out, "space", at);
    const auto f0 = o.out.find("\"forms\": [", at), f1 = o.out.find(']', f0);
    for (const char* f : {"lagrangian", "hamiltonian", "sode1", "sode2", "newmark"})
      if (o.out.substr(f0, f1 - f0).find(std::string("\"") + f + "\"") != std::string::npos) c.forms.insert(f);
    c.retraction = json_bool(o.out, "retraction_maps", at);
    c.written_maps = json_bool(o.out, "written_maps", at);
    c.composition = json_bool(o.out, "composition", at);
    c.galerkin = json_bool(o.out, "galerkin", at);
    c.boundary_value = json_bool(o.out, "boundary_value", at);
    out.push_back(c);
    at = f1;
  }
  // the written system: the run-time-sized capabilities
  SystemCaps w;
  w.name = "lagrangian";
  w.space = "R^n";
  w.forms = {"lagrangian", "hamiltonian"};
  w.retraction = w.composition = w.galerkin = true;  // written maps: no (run-time-sized steps)
  out.push_back(w);
  // written on S^2 and SO(3): the capabilities of the spherical pendulum and the top
  for (const char* space : {"S^2", "SO(3)"}) {
    SystemCaps c = w;
    c.space = space;
    c.name = "lagrangian on " + c.space;
    c.boundary_value = c.space == "S^2";
    c.written_maps = true;  // sphere-written, so3-written
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

// The systems this process walks: every one, or with `-- --shard=k/n` after the test
// program's own arguments, the k-th of each n in registry order (ctest runs the suite as
// n processes, which share the cores with the other suites).
std::vector<SystemCaps> shard_of(const std::vector<SystemCaps>& all) {
  int k = 1, n = 1;
  const auto& master = boost::unit_test::framework::master_test_suite();
  for (int i = 1; i < master.argc; ++i) {
    const std::string a = master.argv[i];
    if (a.rfind("--shard=", 0) != 0) continue;
    const bool ok = std::sscanf(a.c_str() + 8, "%d/%d", &k, &n) == 2 && n >= 1 && k >= 1 && k <= n;
    BOOST_REQUIRE_MESSAGE(ok, "bad argument '" << a << "': --shard=k/n with 1 <= k <= n");
  }
  std::vector<SystemCaps> out;
  for (std::size_t i = 0; i < all.size(); ++i)
    if (static_cast<int>(i % static_cast<std::size_t>(n)) == k - 1) out.push_back(all[i]);
  return out;
}

std::vector<std::pair<std::string, std::string>> registry_maps() {  // (name, space)
  const Output o = dvm({"maps", "--json"});
  BOOST_REQUIRE(o.status == 0);
  std::vector<std::pair<std::string, std::string>> out;
  std::size_t at = 0;
  while ((at = o.out.find("\"name\": \"", at)) != std::string::npos) {
    out.push_back({json_string(o.out, "name", at), json_string(o.out, "space", at)});
    at += 8;
  }
  return out;
}

bool names_a_key(const std::string& err) {
  return err.find("key 'integrator.") != std::string::npos || err.find("key 'problem.") != std::string::npos;
}

double max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.empty()) return INFINITY;
  double d = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::fmax(d, std::fabs(a[i] - b[i]));
  return d;
}

int g_runs = 0, g_ok = 0, g_refused = 0;

// Runs the scene and checks the outcome against `supported`.
void check(const std::string& what, const std::string& text, bool supported, const std::vector<double>& q_ref,
           const std::map<std::string, std::string>& expect) {
  const std::string path = write_scene("combination.toml", text);
  const Output o = dvm({"run", path, "--json", "--quiet"});
  ++g_runs;
  BOOST_TEST_CONTEXT(what << "\n" << o.err << o.out) {
    if (supported) {
      ++g_ok;
      BOOST_TEST(o.status == 0);
      BOOST_TEST(json_string(o.out, "status") == "ok");
      for (const auto& [key, value] : expect) BOOST_TEST(json_string(o.out, key) == value, key);
      const std::vector<double> q = json_array(o.out, "q_final");
      BOOST_TEST(!q.empty());
      for (double x : q) BOOST_TEST(std::isfinite(x));
      BOOST_TEST(std::isfinite(json_number(o.out, "energy_final")));
      if (!q_ref.empty()) BOOST_TEST(max_diff(q, q_ref) <= 1e-2);
    } else {
      ++g_refused;
      BOOST_TEST(o.status == 2);
      BOOST_TEST(names_a_key(o.err));
      BOOST_TEST(o.out.empty());
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
const char* kForms[] = {"lagrangian", "hamiltonian", "sode1", "sode2", "newmark"};

std::string midpoint_map(const std::string& space) {
  return space == "S^2" ? "sphere-exp" : space == "SO(3)" ? "so3-exp" : "midpoint";
}

}  // namespace

BOOST_AUTO_TEST_CASE(every_combination_runs_or_is_refused_naming_the_keys) {
  const std::vector<SystemCaps> systems = registry_systems();
  const auto maps = registry_maps();
  BOOST_REQUIRE(systems.size() >= 15);
  BOOST_REQUIRE(maps.size() >= 13);
  for (const SystemCaps& sys : shard_of(systems)) {
    BOOST_TEST_CONTEXT("system " << sys.name) {
      const auto h = heads().find(sys.name);
      BOOST_REQUIRE_MESSAGE(h != heads().end(), "no initial state for system " << sys.name << " in this test");
      const std::string head = h->second;
      // the reference: the plain midpoint run
      const Output ref =
          dvm({"run", write_scene("ref.toml", head + integrator("map = \"" + midpoint_map(sys.space) + "\"\n")),
               "--json", "--quiet"});
      BOOST_REQUIRE_MESSAGE(ref.status == 0, ref.err);
      const std::vector<double> q_ref = json_array(ref.out, "q_final");

      std::vector<std::string> space_maps = {""};  // "": no map key
      for (const auto& [name, space] : maps)
        if (space == sys.space) space_maps.push_back(name);
      for (const std::string& map : space_maps)
        for (const char* form : kForms)
          for (const char* comp : kCompositions) {
            const std::string f = form, c = comp;
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
            check(sys.name + " map=" + map + " form=" + f + " composition=" + c, head + integrator(keys), supported,
                  q_ref, expect);
          }
      // Galerkin: every quadrature and stage count; with another form or a composition
      for (const char* quad : {"gauss", "lobatto"})
        for (int s = 1; s <= 6; ++s)
          check(sys.name + " galerkin " + quad + " s=" + std::to_string(s),
                head + integrator("method = \"galerkin\"\nquadrature = \"" + std::string(quad) +
                                  "\"\nstages = " + std::to_string(s) + "\n"),
                sys.galerkin, q_ref, {{"method", "galerkin"}, {"map", "none"}, {"quadrature", quad}});
      check(sys.name + " galerkin hamiltonian",
            head + integrator("method = \"galerkin\"\nform = \"hamiltonian\"\n"), false, {}, {});
      check(sys.name + " galerkin composed", head + integrator("method = \"galerkin\"\ncomposition = \"triple-jump\"\n"),
            false, {}, {});
      // boundary values between the initial point and where the midpoint run ends
      std::string qf = "[";
      for (std::size_t i = 0; i < q_ref.size(); ++i) {
        char buf[40];
        std::snprintf(buf, sizeof buf, "%s%.17g", i ? ", " : "", q_ref[i]);
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
                  sys.boundary_value, {}, {{"problem", "boundary-value"}});
            continue;
          }
          const std::string f = form;
          const std::string text = sys_section + "[initial]\n" + q0 + "\n[problem]\nkind = \"boundary-value\"\n" +
                                   "q_final = " + qf + "\nsteps = 3\n[integrator]\nstep = 0.001\nmap = \"" + map +
                                   "\"\nform = \"" + f + "\"\n" + map_section(map);
          check(sys.name + " boundary-value map=" + map + " form=" + f, text,
                sys.boundary_value && f == "lagrangian" && (map != "retraction-theta" || sys.retraction) &&
                    (!is_written_map(map) || sys.written_maps),
                {}, {{"problem", "boundary-value"}});
        }
    }
  }
  BOOST_TEST_MESSAGE(g_runs << " runs: " << g_ok << " ran, " << g_refused << " refused");
}

// A splitting into kicks and drifts on every system: with each Euler map (and the
// theta map at 0), the space's midpoint map, in the lagrangian, hamiltonian and sode1
// forms. They run on R^n, on a system that composes and is separable (not the double
// pendulum, the charged particle or the written double pendulum), in the lagrangian or
// hamiltonian form, with an Euler map; every other case is refused naming a key.
BOOST_AUTO_TEST_CASE(every_splitting_runs_or_is_refused) {
  const std::set<std::string> not_separable = {"double-pendulum", "charged-particle", "lagrangian"};
  for (const SystemCaps& sys : shard_of(registry_systems())) {
    const std::string head = heads().at(sys.name);
    const Output ref =
        dvm({"run", write_scene("ref.toml", head + integrator("map = \"" + midpoint_map(sys.space) + "\"\n")),
             "--json", "--quiet"});
    BOOST_REQUIRE_MESSAGE(ref.status == 0, ref.err);
    const std::vector<double> q_ref = json_array(ref.out, "q_final");
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
                q_ref, {{"form", f}, {"composition", comp}, {"map", map}});
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
BOOST_AUTO_TEST_CASE(every_lift_and_theta_per_stage_runs_or_is_refused) {
  const std::map<std::string, std::set<std::string>> lift_forms = {{"cotangent", {"hamiltonian"}},
                                                                   {"none", {"hamiltonian"}},
                                                                   {"tangent", {"sode1", "sode2"}},
                                                                   {"legendre", {"sode1", "sode2"}}};
  const Output listed = dvm({"methods"});
  BOOST_REQUIRE(listed.status == 0);
  for (const auto& [lift, forms] : lift_forms) BOOST_TEST(listed.out.find("  " + lift + " ") != std::string::npos);
  const int runs_before = g_runs;
  for (const SystemCaps& sys : shard_of(registry_systems())) {
    const std::string head = heads().at(sys.name);
    const std::string theta_map = sys.space == "S^2" ? "sphere-exp-theta" : sys.space == "SO(3)" ? "so3-exp-theta" : "theta";
    for (const std::string& map : {midpoint_map(sys.space), theta_map})
      for (const char* form : {"lagrangian", "hamiltonian", "sode2"}) {
        const std::string f = form;
        const std::string base = "form = \"" + f + "\"\nmap = \"" + map + "\"\n";
        for (const auto& [lift, forms] : lift_forms) {
          const bool theta_family = sys.space == "R^n";  // midpoint and theta are theta maps there
          const bool supported = sys.forms.count(f) && forms.count(f) && (lift != "none" || sys.space == "R^n") &&
                                 ((lift != "none" && lift != "legendre") || theta_family);
          check(sys.name + " map=" + map + " form=" + f + " lift=" + lift,
                head + integrator(base + "lift = \"" + lift + "\"\n"), supported, {},
                {{"form", f}, {"lift", lift}, {"map", map}});
        }
        const bool takes_theta = map == theta_map;
        check(sys.name + " map=" + map + " form=" + f + " thetas",
              head + integrator(base + "composition = \"dirk\"\nweights = [0.5, 0.5]\nthetas = [0.4, 0.6]\n"),
              sys.forms.count(f) && sys.composition && takes_theta, {},
              {{"form", f}, {"composition", "dirk"}, {"map", map}});
      }
  }
  BOOST_TEST_MESSAGE(g_runs - runs_before << " runs of lifts and thetas");
}

// dvm converge on every form, on every space, composed: a table whose runs used the
// method asked for (the order measured is the method's), or exit 2 naming the keys.
BOOST_AUTO_TEST_CASE(converge_runs_every_combination_or_refuses_it) {
  for (const SystemCaps& sys : shard_of(registry_systems())) {
    const std::string head = heads().at(sys.name);
    for (const char* form : kForms)
      for (const char* comp : {"none", "stormer-verlet"}) {
        const std::string f = form, c = comp;
        std::string keys = "form = \"" + f + "\"\nmap = \"" + midpoint_map(sys.space) + "\"\n";
        if (c != "none") keys += "composition = \"" + c + "\"\n";
        const bool supported = sys.forms.count(f) && (c == "none" || sys.composition);
        const Output o = dvm({"converge", write_scene("conv.toml", head + integrator(keys)), "--steps-list", "2,4",
                              "--json"});
        BOOST_TEST_CONTEXT(sys.name << " converge form=" << f << " composition=" << c << "\n" << o.err << o.out) {
          if (supported) {
            BOOST_TEST(o.status == 0);
            BOOST_TEST(json_string(o.out, "form") == f);
            BOOST_TEST(json_string(o.out, "composition") == c);
            BOOST_TEST(o.out.find("\"fitted_order\": ") != std::string::npos);
          } else {
            BOOST_TEST(o.status == 2);
            BOOST_TEST(names_a_key(o.err));
          }
        }
      }
  }
}
