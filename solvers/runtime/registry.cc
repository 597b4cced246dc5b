#include "solvers/runtime/registry.h"

#include <utility>

#include "solvers/runtime/factories.h"

namespace dvm {

const char* to_string(Space s) {
  switch (s) {
    case Space::euclidean: return "R^n";
    case Space::sphere: return "S^2";
    case Space::rotation: return "SO(3)";
  }
  return "?";
}

const char* to_string(Form f) {
  switch (f) {
    case Form::lagrangian: return "lagrangian";
    case Form::hamiltonian: return "hamiltonian";
    case Form::sode1: return "sode1";
    case Form::sode2: return "sode2";
    case Form::newmark: return "newmark";
  }
  return "?";
}

namespace {

std::string join(const std::vector<std::string>& names) {
  std::string out;
  for (std::size_t i = 0; i < names.size(); ++i) out += (i ? ", " : "") + names[i];
  return out;
}

const std::vector<Form> kAllForms = {Form::lagrangian, Form::hamiltonian, Form::sode1, Form::sode2, Form::newmark};

// Built-in systems on R^n of fixed size: every form, map, composition, Galerkin and
// boundary values; --linearize (the run-time-sized steps that give their derivative,
// make_run_time_sized_run).
SystemCapabilities fixed_rn() {
  SystemCapabilities c{kAllForms, true, true, true, true, ""};
  c.linearize = true;
  return c;
}

// Systems whose size is known only at run time (N bodies, written Lagrangians); the
// SODE and Newmark forms on separable ones (make_dynamic_run refuses the others), and
// boundary values where `boundary_value` (a written Lagrangian: the run-time-sized
// problem of the theta-family maps); --linearize.
SystemCapabilities run_time_sized(bool boundary_value) {
  SystemCapabilities c{kAllForms,
          true,
          true,
          true,
          boundary_value,
          boundary_value ? "the SODE and Newmark forms run on separable Lagrangians (v^T M v / 2 - U(q), M constant); "
                           "boundary-value problems take the theta-family maps; solver = \"tiny\" and written maps "
                           "are built for the fixed-size systems"
                         : "the SODE and Newmark forms run on separable Lagrangians (v^T M v / 2 - U(q), M constant); "
                           "boundary-value problems run on the fixed-size systems and written Lagrangians, solver = "
                           "\"tiny\" and written maps on the fixed-size systems",
          false,
          false};
  c.linearize = true;
  return c;
}

// Systems on S^2, (S^2)^K and SO(3): every map and composition of the space in the
// lagrangian form, and the parts its kernels build (factories.h, the one statement of
// them); `note` says why the rest is missing.
SystemCapabilities manifold_caps(const factories::KernelParts& parts, std::string note) {
  SystemCapabilities c;
  c.forms = {Form::lagrangian};
  if (parts.hamiltonian) c.forms.push_back(Form::hamiltonian);
  c.galerkin = parts.galerkin;
  c.boundary_value = parts.boundary_value;
  c.note = std::move(note);
  return c;
}

}  // namespace

const std::vector<FormEntry>& form_registry() {
  static const std::vector<FormEntry> list = {
      {Form::lagrangian, "lagrangian",
       "position-momentum step of L_d(q0, q1) = h L(R_d^{-1}(q0, q1)/h): p0 = -D1 L_d, p1 = D2 L_d (Sec. 5.3)", true},
      {Form::hamiltonian, "hamiltonian",
       "Eq. 5.1: the inverse cotangent lift of the map equals h X_H at its base point (symplectic for any map)", true},
      {Form::sode1, "sode1", "Eq. 4.1: the tangent lift of the map, R^2(Y0, h Gamma(Y0)) = R^1(Y1, h Gamma(Y1)) (the first option)", true},
      {Form::sode2, "sode2", "Eq. 4.2: the tangent lift of the map, the SODE sampled at its base point", true},
      {Form::newmark, "newmark", "Newmark's family (gamma, beta): sode1 through the paper's map on TQ (Sec. 4.1), not integrator.map", false},
  };
  return list;
}

Form find_form(const std::string& name, const std::string& key) {
  std::vector<std::string> names;
  for (const FormEntry& f : form_registry()) {
    if (f.name == name) return f.form;
    names.push_back(f.name);
  }
  throw InputError(key + ": got \"" + echo(name) + "\", expected one of: " + join(names) +
                   did_you_mean(name, names));
}

const char* to_string(Lift l) {
  switch (l) {
    case Lift::automatic: return "automatic";
    case Lift::cotangent: return "cotangent";
    case Lift::none: return "none";
    case Lift::tangent: return "tangent";
    case Lift::legendre: return "legendre";
  }
  return "?";
}

const std::vector<LiftEntry>& lift_registry() {
  static const std::vector<LiftEntry> list = {
      {Lift::cotangent, "cotangent", {Form::hamiltonian},
       "R_d^{T*}, the cotangent lift of the map (Prop. 3.4, inverse Eq. 3.6): symplectic for any map (Prop. 5.1); "
       "the default of the hamiltonian form"},
      {Lift::none, "none", {Form::hamiltonian},
       "the map itself on T*Q = R^{2n}, applied to z = (q, p) (Eq. 5.1 with a map given on T*Q): the theta map gives "
       "z1 - z0 = h X_H(z0 + theta (z1 - z0)), symplectic only at theta = 1/2; R^n only"},
      {Lift::tangent, "tangent", {Form::sode1, Form::sode2},
       "R_d^T = T R_d o kappa_Q, the tangent lift of the map (Prop. 3.2); the default of the sode forms"},
      {Lift::legendre, "legendre", {Form::sode1, Form::sode2},
       "R_d^L = (FL^{-1}, FL^{-1}) o R_d^{T*} o TFL (Prop. 5.3): with sode2 (Eq. 5.2) the method of the hamiltonian "
       "form carried to TQ by the Legendre map, symplectic; equal to the tangent lift for a constant mass matrix and "
       "the midpoint map (Cor. 5.4)"},
  };
  return list;
}

Lift find_lift(const std::string& name, const std::string& key) {
  std::vector<std::string> names;
  for (const LiftEntry& l : lift_registry()) {
    if (l.name == name) return l.lift;
    names.push_back(l.name);
  }
  throw InputError(key + ": got \"" + echo(name) + "\", expected one of: " + join(names) +
                   did_you_mean(name, names));
}

Lift default_lift(Form f) {
  switch (f) {
    case Form::hamiltonian: return Lift::cotangent;
    case Form::sode1:
    case Form::sode2: return Lift::tangent;
    case Form::lagrangian:
    case Form::newmark: break;
  }
  return Lift::automatic;
}

const std::vector<MapEntry>& map_registry() {
  using F = MapFamily;
  using R = MapRetraction;
  static const std::vector<MapEntry> list = {
      {"explicit-euler", "R_d(x, v) = (x, x + v)", Space::euclidean, F::theta, R::none, 0.0, false, true, "theta = 0"},
      {"adjoint-euler", "R_d(x, v) = (x - v, x)", Space::euclidean, F::theta, R::none, 1.0, false, true,
       "theta = 1; the adjoint of explicit-euler"},
      {"midpoint", "R_d(x, v) = (x - v/2, x + v/2)", Space::euclidean, F::theta, R::none, 0.5, false, true,
       "theta = 1/2; self-adjoint"},
      {"theta", "R_d(x, v) = (x - theta v, x + (1 - theta) v)", Space::euclidean, F::theta, R::none, 0.5, true, true,
       "symmetric and of order 2 only at theta = 1/2"},
      {"retraction-theta", "R_d(x, v) = (R_x(-theta v), R_x((1 - theta) v)), R_x(v) = x + v", Space::euclidean,
       F::retraction_theta, R::none, 0.5, true, false,
       "Prop. 2.3 from the flat retraction; inverted by Newton's method (the generic path)"},
      {"written", "the scene's [map]: q0 = \"...\", q1 = \"...\" in x and v, or retraction = \"R(x, v)\"",
       Space::euclidean, F::written, R::none, 0.5, true, false,
       "applied to each coordinate; checked against Def. 2.2 when read; inverted by Newton's method"},
      {"sphere-exp", "(exp_x(-v/2), exp_x(v/2)), exp_x(v) = cos|v| x + sin|v| v/|v|", Space::sphere, F::sphere, R::exp,
       0.5, false, true, "midpoint form on S^2 (Eq. 2.3)"},
      {"sphere-projection", "((x - v/2)/|x - v/2|, (x + v/2)/|x + v/2|)", Space::sphere, F::sphere, R::projection, 0.5,
       false, true, "projection midpoint on S^2"},
      {"sphere-exp-fixed", "(x, exp_x(v))", Space::sphere, F::sphere, R::exp, 0.0, false, true,
       "fixed-first-point form on S^2"},
      {"sphere-projection-fixed", "(x, (x + v)/|x + v|)", Space::sphere, F::sphere, R::projection, 0.0, false, true,
       "fixed-first-point projection map; inverse (x0, x1/(x0.x1) - x0) needs x0.x1 > 0"},
      {"sphere-exp-theta", "(exp_x(-theta v), exp_x((1 - theta) v))", Space::sphere, F::sphere, R::exp, 0.5, true,
       false, "Prop. 2.3 with any theta; Newton's method in a chart except at theta in {0, 1/2, 1}"},
      {"sphere-projection-theta", "((x - theta v)/|x - theta v|, (x + (1 - theta) v)/|x + (1 - theta) v|)",
       Space::sphere, F::sphere, R::projection, 0.5, true, false,
       "Prop. 2.3 with any theta; Newton's method in a chart except at theta in {0, 1/2, 1}"},
      {"so3-exp", "(R exp(-w/2), R exp(w/2))", Space::rotation, F::rotation, R::exp, 0.5, false, true,
       "group exponential midpoint on SO(3)"},
      {"so3-cayley", "(R cay(-w/2), R cay(w/2))", Space::rotation, F::rotation, R::cayley, 0.5, false, true,
       "Cayley midpoint on SO(3) (Ex. 2.8)"},
      {"so3-exp-fixed", "(R, R exp(w))", Space::rotation, F::rotation, R::exp, 0.0, false, true,
       "fixed-first-point form on SO(3)"},
      {"so3-cayley-fixed", "(R, R cay(w))", Space::rotation, F::rotation, R::cayley, 0.0, false, true,
       "fixed-first-point Cayley map; undefined for relative rotations by pi"},
      {"so3-exp-theta", "(R exp(-theta w), R exp((1 - theta) w))", Space::rotation, F::rotation, R::exp, 0.5, true, true,
       "Prop. 2.3 with any theta; inverse w = log(R0^T R1), R = R0 exp(theta w)"},
      {"so3-cayley-theta", "(R cay(-theta w), R cay((1 - theta) w))", Space::rotation, F::rotation, R::cayley, 0.5,
       true, false, "Prop. 2.3 with any theta; Newton's method in a chart except at theta in {0, 1/2, 1}"},
      {"sphere-written", "(R_x(-theta v), R_x((1 - theta) v)), R_x(v) = f(x, v)/|f(x, v)|, f from the scene's [map]",
       Space::sphere, F::sphere, R::written, 0.5, true, false,
       "retraction = [3 expressions in x1 x2 x3, v1 v2 v3]; its axioms checked when read; Newton's method in a chart"},
      {"so3-written", "(R_R(-theta w), R_R((1 - theta) w)), R_R(w) = f(R, w) orthonormalised, f from the scene's [map]",
       Space::rotation, F::rotation, R::written, 0.5, true, false,
       "retraction = [9 expressions, row by row, in R11 ... R33, w1 w2 w3]; its axioms checked when read; Newton's "
       "method in a chart"},
  };
  return list;
}

std::string theta_map_names() {
  std::string out;
  for (const MapEntry& m : map_registry())
    if (m.takes_theta) out += (out.empty() ? "map = \"" : ", \"") + m.name + "\"";
  return out;
}

const MapEntry& find_map_entry(const std::string& name, const std::string& where) {
  std::vector<std::string> names;
  for (const MapEntry& m : map_registry()) {
    if (m.name == name) return m;
    names.push_back(m.name);
  }
  throw InputError(where + ": unknown map \"" + echo(name) + "\"; expected one of: " + join(names) +
                   did_you_mean(name, names));
}

const std::vector<GalerkinEntry>& galerkin_registry() {
  static const std::vector<GalerkinEntry> list = [] {
    std::vector<GalerkinEntry> out;
    for (QuadratureKind kind : {QuadratureKind::gauss, QuadratureKind::lobatto})
      for (int s = 1; s <= kGalerkinStagesMax; ++s)
        out.push_back({kind, s, Quadrature(kind, s).points, 2 * s,
                       "Marsden & West, Acta Numerica 2001, Sec. 2.6; equals Gauss collocation (gauss) or "
                       "Lobatto IIIA-IIIB (lobatto)",
                       s != 1 ? "" : kind == QuadratureKind::gauss ? "s = 1: the midpoint discrete Lagrangian"
                                                                   : "s = 1: the trapezoidal discrete Lagrangian"});
    return out;
  }();
  return list;
}

const std::vector<SystemEntry>& system_registry() {
  static const std::vector<SystemEntry> list = {
      {"harmonic", "L = v^2/2 - omega^2 q^2/2", Space::euclidean, 1, {{"omega", 1.0, "angular frequency"}}, fixed_rn(),
       factories::harmonic, ""},
      {"pendulum",
       "L = m l^2 v^2/2 + m g l cos(q)   (q from the downward vertical)",
       Space::euclidean,
       1,
       {{"m", 1.0, "mass"}, {"l", 1.0, "length"}, {"g", 1.0, "gravitational acceleration"}},
       fixed_rn(),
       factories::pendulum,
       ""},
      {"kepler", "L = |v|^2/2 + mu/|q|   (q in the plane)", Space::euclidean, 2,
       {{"mu", 1.0, "gravitational parameter"}}, fixed_rn(), factories::kepler, ""},
      {"spherical-pendulum",
       "L = m l^2 |v|^2/2 - m g l x_3   (x a unit vector, x_3 upward)",
       Space::sphere,
       3,
       {{"m", 1.0, "mass"}, {"l", 1.0, "length"}, {"g", 1.0, "gravitational acceleration"}},
       manifold_caps(factories::kSphereParts, "on S^2 the forms are lagrangian and hamiltonian (the SODE and Newmark forms are built on R^n)"),
       factories::spherical_pendulum,
       ""},
      {"spherical-chain",
       "L = sum_i m |dr_i/dt|^2/2 - g sum_i m (r_i)_3,  r_i = l (x_1 + ... + x_i)   (n links, x_i unit vectors)",
       Space::sphere,
       3,
       {{"n", 2.0, "number of links"},
        {"m", 1.0, "mass at the end of each link"},
        {"l", 1.0, "length of each link"},
        {"g", 1.0, "gravitational acceleration"}},
       manifold_caps(factories::kSpherePowerParts,
                     "the spherical chain runs the lagrangian form only (it has no written-out Hamiltonian) and no Galerkin "
        "method (the chart step is built for the spherical pendulum, the rigid body and the heavy top)"),
       factories::spherical_chain,
       "3 per link"},
      {"rigid-body",
       "L = (I1 w1^2 + I2 w2^2 + I3 w3^2)/2   (w the body angular velocity)",
       Space::rotation,
       3,
       {{"I1", 1.0, "principal moment of inertia"},
        {"I2", 2.0, "principal moment of inertia"},
        {"I3", 3.0, "principal moment of inertia"}},
       manifold_caps(factories::kRotationParts, "on SO(3) the forms are lagrangian and hamiltonian; boundary-value problems run on R^n and S^2"),
       factories::rigid_body,
       ""},
      {"heavy-top",
       "L = w.I w/2 - m g e3.(R chi)   (chi the centre of mass in the body frame)",
       Space::rotation,
       3,
       {{"I1", 1.0, "principal moment of inertia"},
        {"I2", 1.0, "principal moment of inertia"},
        {"I3", 0.5, "principal moment of inertia"},
        {"m", 1.0, "mass"},
        {"g", 1.0, "gravitational acceleration"},
        {"chi1", 0.0, "centre of mass, body frame"},
        {"chi2", 0.0, "centre of mass, body frame"},
        {"chi3", 1.0, "centre of mass, body frame"}},
       manifold_caps(factories::kRotationParts, "on SO(3) the forms are lagrangian and hamiltonian; boundary-value problems run on R^n and S^2"),
       factories::heavy_top,
       ""},
      {"chain",
       "L = sum m v_i^2/2 - sum_bonds (k r^2/2 + alpha r^3/3 + beta r^4/4),  r = q_i - q_{i-1}",
       Space::euclidean,
       0,
       {{"n", 8.0, "number of particles"},
        {"m", 1.0, "mass of each particle"},
        {"k", 1.0, "linear spring constant"},
        {"alpha", 0.0, "cubic (FPU-alpha) coefficient"},
        {"beta", 0.0, "quartic (FPU-beta) coefficient"},
        {"fixed", 1.0, "1: ends tied to walls; 0: free ends (total momentum conserved)"}},
       {{Form::lagrangian}, false, true, false, false,
        "the chain's step solves its tridiagonal equations by its own Newton iteration, for the theta-family maps in "
        "the lagrangian form only",
        false,
        false,
        true},
       factories::chain,
       "params.n"},
      {"double-pendulum",
       "L = (m1+m2) l1^2 w1^2/2 + m2 l2^2 w2^2/2 + m2 l1 l2 w1 w2 cos(q1-q2) + (m1+m2) g l1 cos q1 + m2 g l2 cos q2",
       Space::euclidean,
       2,
       {{"m1", 1.0, "upper mass"},
        {"m2", 1.0, "lower mass"},
        {"l1", 1.0, "upper rod length"},
        {"l2", 1.0, "lower rod length"},
        {"g", 1.0, "gravitational acceleration"}},
       fixed_rn(),
       factories::double_pendulum,
       ""},
      {"henon-heiles", "L = |v|^2/2 - (x^2 + y^2)/2 - lambda (x^2 y - y^3/3)", Space::euclidean, 2,
       {{"lambda", 1.0, "coupling"}}, fixed_rn(), factories::henon_heiles, ""},
      {"fpu",
       "GNI Sec. I.5.1, m = 3: L = |v|^2/2 - omega^2/4 sum (q_2i - q_2i-1)^2 - sum (q_2i+1 - q_2i)^4",
       Space::euclidean,
       6,
       {{"omega", 50.0, "stiff spring frequency"}},
       fixed_rn(),
       factories::fpu,
       ""},
      {"duffing", "L = v^2/2 - alpha q^2/2 - beta q^4/4", Space::euclidean, 1,
       {{"alpha", 1.0, "linear stiffness"}, {"beta", 1.0, "cubic stiffness"}}, fixed_rn(), factories::duffing, ""},
      {"charged-particle",
       "L = m |v|^2/2 + (c B/2)(x v_y - y v_x) - k |q|^2/2   (uniform field B normal to the plane)",
       Space::euclidean,
       2,
       {{"m", 1.0, "mass"}, {"c", 1.0, "charge"}, {"B", 1.0, "magnetic field"}, {"k", 0.0, "electric potential k |q|^2/2"}},
       fixed_rn(),
       factories::charged_particle,
       ""},
      {"nbody",
       "L = sum m_i |v_i|^2/2 + G sum_{i<j} m_i m_j/|q_i - q_j|   (in R^3; [system] masses = [...], 2 or more bodies)",
       Space::euclidean,
       0,
       {{"G", 1.0, "gravitational constant"}},
       run_time_sized(false),
       factories::nbody,
       "3 x bodies"},
  };
  return list;
}

const SystemEntry& find_system_entry(const std::string& name, const std::string& where) {
  std::vector<std::string> names;
  for (const SystemEntry& s : system_registry()) {
    if (s.name == name) return s;
    names.push_back(s.name);
  }
  throw InputError(where + ": unknown system \"" + echo(name) + "\"; expected one of: " + join(names) +
                   did_you_mean(name, names));
}

const SystemEntry& written_system_entry(Space space, int factors, bool forced, bool constrained, bool time_dependent) {
  static const SystemEntry rn = {"lagrangian", "written in the scene", Space::euclidean, 0, {}, run_time_sized(true),
                                 factories::written, "the coordinates"};
  // With forces: the lagrangian form (the theta-family maps composed or not, Galerkin),
  // the hamiltonian form and, on a separable Lagrangian, the SODE and Newmark forms (the
  // forced steps of solvers/dynamic_step.h, dynamic_galerkin_step.h and
  // dynamic_sode_step.h); the rest takes no force term.
  static const SystemEntry rn_forced = {
      "lagrangian with forces",
      "written in the scene, with generalized forces",
      Space::euclidean,
      0,
      {},
      {kAllForms,
       true,
       true,
       true,
       false,
       "system.forces enter the lagrangian form (the theta-family maps, their compositions, Galerkin), the "
       "hamiltonian form and, on a separable Lagrangian (v^T M v / 2 - U(q), M constant), the SODE and Newmark "
       "forms; boundary values, solver = \"tiny\" and written maps take no forces",
       false,
       false},
      factories::written,
      "the coordinates"};
  // With constraints (and forces or not): the constrained theta step (the lagrangian
  // form of the theta-family maps, composed or not; solvers/constrained_step.h), its
  // Hamiltonian form (the cotangent lift; solvers/constrained_hamiltonian_step.h) and
  // Galerkin with Lobatto quadrature (solvers/constrained_galerkin_step.h; validate
  // refuses Gauss).
  static const SystemEntry rn_constrained = {
      "lagrangian with constraints",
      "written in the scene, with holonomic constraints",
      Space::euclidean,
      0,
      {},
      {{Form::lagrangian, Form::hamiltonian},
       true,
       true,
       true,
       false,
       "system.constraints enter the lagrangian form of the theta-family maps and their compositions (the "
       "constrained discrete Euler-Lagrange equations with multipliers), their hamiltonian form with the "
       "cotangent lift (the Hamiltonian step from the momentum moved by the multipliers, then projected) and "
       "Galerkin with quadrature = \"lobatto\" (the constraints at its nodes); Gauss Galerkin, lift = \"none\", the "
       "SODE and Newmark forms, boundary values, solver = \"tiny\" and written maps take no constraints",
       false,
       false},
      factories::written,
      "the coordinates"};
  // A Lagrangian L(t, q, v) (forces or not): the steps that evaluate L at their nodes'
  // times (the theta step, composed or not, Galerkin, the Hamiltonian theta step, H
  // from L at its node's time, and on v^T M v / 2 - U(t, q) with M constant the SODE
  // and Newmark steps); with constraints, the constrained step above, which does too.
  static const SystemEntry rn_timed = {
      "lagrangian depending on time",
      "written in the scene, L(t, q, v)",
      Space::euclidean,
      0,
      {},
      {kAllForms,
       true,
       true,
       true,
       false,
       "a Lagrangian that reads t runs in the lagrangian form (the theta-family maps, their compositions, "
       "Galerkin), the hamiltonian form (H(t, q, p) from L at each step's node time) and, on v^T M v / 2 - "
       "U(t, q) with M constant, the SODE and Newmark forms (L at each sample point's time); boundary values, "
       "solver = \"tiny\" and written maps take none",
       false,
       false},
      factories::written,
      "the coordinates"};
  if (constrained && space == Space::euclidean) return rn_constrained;
  if (time_dependent && space == Space::euclidean) return rn_timed;
  if (forced && space == Space::euclidean) return rn_forced;
  // On S^2 and SO(3) a written Lagrangian runs the steps of the built-in systems there;
  // its Hamiltonian form needs the written H (validate checks that it is given).
  static const SystemEntry sphere = {
      "lagrangian", "written in the scene in x, x_dot (the embedded unit vector)", Space::sphere, 3, {},
      manifold_caps(factories::kSphereParts, "on S^2 the forms are lagrangian and hamiltonian (the SODE and Newmark forms are built on R^n)"),
      factories::written_sphere, ""};
  static const SystemEntry rotation = {
      "lagrangian", "written in the scene in R, w (the body angular velocity)", Space::rotation, 3, {},
      manifold_caps(factories::kRotationParts, "on SO(3) the forms are lagrangian and hamiltonian; boundary-value problems run on R^n and S^2"),
      factories::written_rotation, ""};
  // On (S^2)^K it runs the spherical chain's steps, and what they run.
  static const SystemEntry sphere_power = {
      "lagrangian", "written in the scene in x1, x1_dot, ..., xK, xK_dot (K embedded unit vectors)", Space::sphere,
      0, {},
      manifold_caps(factories::kSpherePowerParts,
                    "on (S^2)^K the written Lagrangian runs the spherical chain's steps: the lagrangian form with every S^2 map "
       "and composition; no hamiltonian form, Galerkin method or boundary values"),
      factories::written_sphere_power, "3 per factor"};
  // With forces (S^2 and SO(3)): the lagrangian form of the space's maps, composed or
  // not (ManifoldStep with its force, solvers/manifold_step.h), their hamiltonian form
  // (ManifoldHamiltonianStep with its force, solvers/manifold_hamiltonian_step.h) and
  // Galerkin (ManifoldGalerkinStep with its force, solvers/manifold_galerkin_step.h)
  auto forced_caps = [](const char* note) {
    SystemCapabilities c;
    c.forms = {Form::lagrangian, Form::hamiltonian};
    c.galerkin = true;
    c.boundary_value = false;
    c.note = note;
    return c;
  };
  static const SystemEntry sphere_forced = {
      "lagrangian with forces on S^2", "written in the scene in x, x_dot, with a force in the embedding",
      Space::sphere, 3, {},
      forced_caps("system.forces on S^2 enter the lagrangian and hamiltonian forms of the S^2 maps, composed or "
                  "not, and Galerkin (the force at its quadrature nodes); boundary values take none"),
      factories::written_sphere, ""};
  static const SystemEntry rotation_forced = {
      "lagrangian with forces on SO(3)", "written in the scene in R, w, with a body torque", Space::rotation, 3, {},
      forced_caps("system.forces on SO(3) (a body torque) enter the lagrangian and hamiltonian forms of the SO(3) "
                  "maps, composed or not, and Galerkin (the torque at its quadrature nodes)"),
      factories::written_rotation, ""};
  // With constraints (forces or not; S^2 and SO(3)): the lagrangian form of the space's
  // maps, composed or not (ConstrainedManifoldStep, solvers/manifold_constrained_step.h,
  // solved by the one Newton driver: no solver = "tiny")
  auto constrained_caps = [&](const char* note) {
    SystemCapabilities c = forced_caps(note);
    c.forms = {Form::lagrangian};
    c.galerkin = false;
    c.tiny_solver = false;
    return c;
  };
  static const SystemEntry sphere_constrained = {
      "lagrangian with constraints on S^2", "written in the scene in x, x_dot, with holonomic constraints",
      Space::sphere, 3, {},
      constrained_caps("system.constraints on S^2 enter the lagrangian form of the S^2 maps, composed or not (the "
                       "constrained discrete Euler-Lagrange equations with multipliers, in the chart); Galerkin, "
                       "the hamiltonian form, boundary values and solver = \"tiny\" take none"),
      factories::written_sphere, ""};
  static const SystemEntry rotation_constrained = {
      "lagrangian with constraints on SO(3)", "written in the scene in R, w, with holonomic constraints",
      Space::rotation, 3, {},
      constrained_caps("system.constraints on SO(3) enter the lagrangian form of the SO(3) maps, composed or not "
                       "(the constrained discrete Euler-Lagrange equations with multipliers, in the chart); "
                       "Galerkin, the hamiltonian form and solver = \"tiny\" take none"),
      factories::written_rotation, ""};
  if (constrained && space == Space::sphere && factors == 1) return sphere_constrained;
  if (constrained && space == Space::rotation) return rotation_constrained;
  if (forced && space == Space::sphere && factors == 1) return sphere_forced;
  if (forced && space == Space::rotation) return rotation_forced;
  switch (space) {
    case Space::euclidean: return rn;
    case Space::sphere: return factors > 1 ? sphere_power : sphere;
    case Space::rotation: return rotation;
  }
  return rn;
}

}  // namespace dvm
