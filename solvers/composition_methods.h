// Composition methods: tables of step-size fractions gamma_i (paper Sec. 6; Hairer,
// Lubich, Wanner, "Geometric Numerical Integration", 2nd ed., Sec. II.4 and V.3).
//
// Given a one-step method Phi_h, a composition method is
//
//   Psi_h = Phi_{gamma_s h} o ... o Phi_{gamma_1 h}        (gamma_1 h applied first).
//
// If Phi is symmetric of order 2 (the midpoint map, or Stormer-Verlet built below),
// Psi is of order p when the gammas satisfy the order conditions; for p = 2 that is
// sum gamma_i = 1 alone, every higher order adds sum gamma_i^3 = 0 and (from p = 6
// on) conditions that only a nonlinear problem can reveal. A composition is
// symmetric when gamma_i = gamma_{s+1-i}; then Psi_h^* = Psi_h and its order is even.
//
// A method Phi that is not symmetric enters through the symmetric method
// Phi_{h/2} o Phi^*_{h/2} (with Phi = explicit Euler this is Stormer-Verlet, paper
// Sec. 6), or, in McLachlan's form, through alternating stages of Phi and its
// adjoint (HLW Sec. V.3):
//
//   Psi_h = Phi_{alpha_s h} o Phi^*_{beta_s h} o ... o Phi_{alpha_1 h} o Phi^*_{beta_1 h}.
//
// Each method is one type carrying its order, stage count, symmetry, coefficients and
// a citation; closed forms are computed here, published decimals are quoted (to the
// digits published) with their source. The order conditions of every table are
// checked numerically in tests/solvers/test_composition.cc (sum gamma = 1, symmetry,
// measured local and global order).
//
// Symplectic diagonally implicit Runge-Kutta methods (paper Sec. 6.2): a DIRK with
// a_ij = b_j (j < i), a_ii = b_i / 2 is the composition of implicit midpoint steps of
// sizes b_1 h, ..., b_s h. With the midpoint map every table below is such a method;
// the triple jump with the midpoint map is the 3-stage order-4 symplectic DIRK
// b = (g, 1 - 2g, g), g = 1/(2 - 2^{1/3}).
#pragma once

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace dvm {

// How the stages use the basic method.
enum class CompositionKind {
  // gammas are the step fractions of a symmetric order-2 basic method
  of_symmetric,
  // pairs (beta_i, alpha_i): Phi^*_{beta_i h} then Phi_{alpha_i h}, i = 1..s
  with_adjoint,
  // a splitting method for H = T(p) + V(q) with T quadratic (Runge-Kutta-Nystrom
  // problems): kicks b_1 h, ..., b_{m+1} h and drifts a_1 h, ..., a_m h, kick first,
  // applied as a composition of the explicit Euler map (kick then drift) and its
  // adjoint (below). Its order holds for separable systems and the explicit Euler maps
  // only: the order conditions use [B, [B, [B, A]]] = 0 (T quadratic in p).
  rkn_splitting,
};

// A composition method as plain data (what the tables below produce).
struct CompositionScheme {
  std::string name;
  int order = 2;
  int stages = 1;  // evaluations of the basic method (of_symmetric) or of Phi/Phi^* pairs
  bool symmetric = true;
  CompositionKind kind = CompositionKind::of_symmetric;
  std::vector<double> gamma;        // of_symmetric: gamma_1..gamma_s
  std::vector<double> alpha, beta;  // with_adjoint
  std::string citation;
  std::vector<double> kick, drift;  // rkn_splitting: b_1..b_{m+1}, a_1..a_m
};

namespace composition_detail {
// gamma_1..gamma_m, gamma_0 .. mirrored: (w_m, ..., w_1, w_0, w_1, ..., w_m) with
// w_0 = 1 - 2 (w_1 + ... + w_m), Yoshida's (1990) arrangement.
inline std::vector<double> yoshida_arrangement(const std::vector<double>& w) {
  double s = 0.0;
  for (double x : w) s += x;
  std::vector<double> g(w.rbegin(), w.rend());
  g.push_back(1.0 - 2.0 * s);
  g.insert(g.end(), w.begin(), w.end());
  return g;
}
// (g_1, ..., g_m, g_{m+1}) mirrored to (g_1, ..., g_m, g_{m+1}, g_m, ..., g_1).
inline std::vector<double> mirror(const std::vector<double>& half) {
  std::vector<double> g = half;
  g.insert(g.end(), half.rbegin() + 1, half.rend());
  return g;
}
template <class M>
CompositionScheme describe() {
  CompositionScheme s;
  s.name = M::name;
  s.order = M::order;
  s.stages = M::stages;
  s.symmetric = M::symmetric;
  s.kind = CompositionKind::of_symmetric;
  s.gamma = M::gamma();
  s.citation = M::citation;
  return s;
}
}  // namespace composition_detail

// Phi_h itself: no composition.
struct NoComposition {
  static constexpr const char* name = "none";
  static constexpr int order = 0;  // that of the basic method
  static constexpr int stages = 1;
  static constexpr bool symmetric = false;  // that of the basic method
  static constexpr const char* citation = "the basic method alone";
};

// Stormer-Verlet as a composition: Phi_{h/2} o Phi^*_{h/2} (paper Sec. 6: with the
// maps (q, q + v) and (q - v, q) it is the Stormer-Verlet method).
struct StormerVerletComposition {
  static constexpr const char* name = "stormer-verlet";
  static constexpr int order = 2;
  static constexpr int stages = 1;
  static constexpr bool symmetric = true;
  static constexpr const char* citation =
      "Barbero-Linan & Martin de Diego 2022, Sec. 6; HLW GNI Sec. II.3 (Phi_{h/2} o Phi*_{h/2})";
  static CompositionScheme scheme() {
    CompositionScheme s;
    s.name = name;
    s.order = order;
    s.stages = stages;
    s.symmetric = symmetric;
    s.kind = CompositionKind::with_adjoint;
    s.alpha = {0.5};
    s.beta = {0.5};
    s.citation = citation;
    return s;
  }
};

// The triple jump of order 4: gamma = (g, 1 - 2g, g), g = 1/(2 - 2^{1/3}).
struct TripleJump4 {
  static constexpr const char* name = "triple-jump";
  static constexpr int order = 4;
  static constexpr int stages = 3;
  static constexpr bool symmetric = true;
  static constexpr const char* citation =
      "Yoshida, Phys. Lett. A 150 (1990) 262; Forest & Ruth, Physica D 43 (1990) 105; Creutz & Gocksch 1989";
  static std::vector<double> gamma() {
    const double c = std::cbrt(2.0), g = 1.0 / (2.0 - c);
    return {g, -c * g, g};
  }
};

// Suzuki's fractal of order 4: gamma = (g, g, 1 - 4g, g, g), g = 1/(4 - 4^{1/3}).
struct Suzuki5 {
  static constexpr const char* name = "suzuki5";
  static constexpr int order = 4;
  static constexpr int stages = 5;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Suzuki, Phys. Lett. A 146 (1990) 319";
  static std::vector<double> gamma() {
    const double c = std::cbrt(4.0), g = 1.0 / (4.0 - c);
    return {g, g, -c * g, g, g};
  }
};

// Yoshida's order-6 compositions (7 stages), solutions A, B, C of Yoshida 1990,
// (w_1, w_2, w_3 as published; w_0 = 1 - 2 (w_1 + w_2 + w_3)).
struct Yoshida6A {
  static constexpr const char* name = "yoshida6a";
  static constexpr int order = 6;
  static constexpr int stages = 7;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Yoshida, Phys. Lett. A 150 (1990) 262, solution A";
  static std::vector<double> gamma() {
    return composition_detail::yoshida_arrangement({-1.17767998417887, 0.235573213359357, 0.784513610477560});
  }
};
struct Yoshida6B {
  static constexpr const char* name = "yoshida6b";
  static constexpr int order = 6;
  static constexpr int stages = 7;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Yoshida, Phys. Lett. A 150 (1990) 262, solution B";
  static std::vector<double> gamma() {
    return composition_detail::yoshida_arrangement({-2.13228522200144, 0.426068187079180e-2, 1.43984816797678});
  }
};
struct Yoshida6C {
  static constexpr const char* name = "yoshida6c";
  static constexpr int order = 6;
  static constexpr int stages = 7;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Yoshida, Phys. Lett. A 150 (1990) 262, solution C";
  static std::vector<double> gamma() {
    return composition_detail::yoshida_arrangement({0.152886228424922e-2, -2.14403531630539, 1.44778256239930});
  }
};

// Yoshida's order-8 compositions (15 stages), solutions A to E of Yoshida 1990,
// (w_1..w_7 as published; w_0 = 1 - 2 sum w_i).
struct Yoshida8A {
  static constexpr const char* name = "yoshida8a";
  static constexpr int order = 8;
  static constexpr int stages = 15;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Yoshida, Phys. Lett. A 150 (1990) 262, solution A";
  static std::vector<double> gamma() {
    return composition_detail::yoshida_arrangement({-0.161582374150097e1, -0.244699182370524e1, -0.716989419708120e-2,
                                                    0.244002732616735e1, 0.157739928123617e0, 0.182020630970714e1,
                                                    0.104242620869991e1});
  }
};
struct Yoshida8B {
  static constexpr const char* name = "yoshida8b";
  static constexpr int order = 8;
  static constexpr int stages = 15;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Yoshida, Phys. Lett. A 150 (1990) 262, solution B";
  static std::vector<double> gamma() {
    return composition_detail::yoshida_arrangement({-0.169248587770116e-2, 0.289195744315849e1, 0.378039588360192e-2,
                                                    -0.289688250328827e1, 0.289105148970595e1, -0.233864815101035e1,
                                                    0.148819229202922e1});
  }
};
struct Yoshida8C {
  static constexpr const char* name = "yoshida8c";
  static constexpr int order = 8;
  static constexpr int stages = 15;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Yoshida, Phys. Lett. A 150 (1990) 262, solution C";
  static std::vector<double> gamma() {
    return composition_detail::yoshida_arrangement({0.311790812418427e0, -0.155946803821447e1, -0.167896928259640e1,
                                                    0.166335809963315e1, -0.106458714789183e1, 0.136934946416871e1,
                                                    0.629030650210433e0});
  }
};
struct Yoshida8D {
  static constexpr const char* name = "yoshida8d";
  static constexpr int order = 8;
  static constexpr int stages = 15;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Yoshida, Phys. Lett. A 150 (1990) 262, solution D";
  static std::vector<double> gamma() {
    return composition_detail::yoshida_arrangement({0.102799849391985e0, -0.196061023297549e1, 0.193813913762276e1,
                                                    -0.158240635368243e0, -0.144485223686048e1, 0.253693336566229e0,
                                                    0.914844246229740e0});
  }
};
struct Yoshida8E {
  static constexpr const char* name = "yoshida8e";
  static constexpr int order = 8;
  static constexpr int stages = 15;
  static constexpr bool symmetric = true;
  static constexpr const char* citation = "Yoshida, Phys. Lett. A 150 (1990) 262, solution E";
  static std::vector<double> gamma() {
    return composition_detail::yoshida_arrangement({0.227738840094906e-1, 0.252778927322839e1, -0.719180053552772e-1,
                                                    0.536018921307285e-2, -0.204809795887393e1, 0.107990467703699e0,
                                                    0.130300165760014e1});
  }
};

// Kahan & Li's order-6 composition with 9 stages (s9odr6a), decimals as in HLW GNI
// Sec. V.3.
struct KahanLi6 {
  static constexpr const char* name = "kahan-li6";
  static constexpr int order = 6;
  static constexpr int stages = 9;
  static constexpr bool symmetric = true;
  static constexpr const char* citation =
      "Kahan & Li, Math. Comp. 66 (1997) 1089, s9odr6a; decimals from HLW GNI Sec. V.3";
  static std::vector<double> gamma() {
    return composition_detail::mirror({0.39216144400731413928, 0.33259913678935943860, -0.70624617255763935981,
                                       0.08221359629355080023, 0.79854399093482996340});
  }
};

// Suzuki & Umeno's order-8 composition with 15 stages (found also by McLachlan 1995),
// decimals as in HLW GNI Sec. V.3.
struct SuzukiUmeno8 {
  static constexpr const char* name = "suzuki-umeno8";
  static constexpr int order = 8;
  static constexpr int stages = 15;
  static constexpr bool symmetric = true;
  static constexpr const char* citation =
      "Suzuki & Umeno, in Computer Simulation Studies in Condensed-Matter Physics VI, Springer (1993); McLachlan, SIAM "
      "J. Sci. Comput. 16 (1995) 151; decimals from HLW GNI Sec. V.3";
  static std::vector<double> gamma() {
    return composition_detail::mirror({0.74167036435061295345, -0.40910082580003159400, 0.19075471029623837995,
                                       -0.57386247111608226666, 0.29906418130365592384, 0.33462491824529818378,
                                       0.31529309239676659663, -0.79688793935291635402});
  }
};

// Kahan & Li's order-8 composition with 17 stages (s17odr8a), decimals as in HLW GNI
// Sec. V.3.
struct KahanLi8 {
  static constexpr const char* name = "kahan-li8";
  static constexpr int order = 8;
  static constexpr int stages = 17;
  static constexpr bool symmetric = true;
  static constexpr const char* citation =
      "Kahan & Li, Math. Comp. 66 (1997) 1089, s17odr8a; decimals from HLW GNI Sec. V.3";
  static std::vector<double> gamma() {
    return composition_detail::mirror({0.13020248308889008088, 0.56116298177510838456, -0.38947496264484728641,
                                       0.15884190655515560090, -0.39590389413323757734, 0.18453964097831570709,
                                       0.25837438768632204729, 0.29501172360931029887, -0.60550853383003451170});
  }
};

// McLachlan's symmetric composition of a method and its adjoint, order 4 with 5
// pairs (HLW GNI Sec. V.3); closed forms:
//   beta_1 = alpha_5 = (146 + 5 sqrt 19)/540,  beta_2 = alpha_4 = (-2 + 10 sqrt 19)/135,
//   beta_3 = alpha_3 = 1/5,  beta_4 = alpha_2 = (-23 - 20 sqrt 19)/270,
//   beta_5 = alpha_1 = (14 - sqrt 19)/108.
struct McLachlan4 {
  static constexpr const char* name = "mclachlan4";
  static constexpr int order = 4;
  static constexpr int stages = 5;
  static constexpr bool symmetric = true;
  static constexpr const char* citation =
      "McLachlan, SIAM J. Sci. Comput. 16 (1995) 151; HLW GNI Sec. V.3 (composition with the adjoint)";
  static CompositionScheme scheme() {
    const double r = std::sqrt(19.0);
    CompositionScheme s;
    s.name = name;
    s.order = order;
    s.stages = stages;
    s.symmetric = symmetric;
    s.kind = CompositionKind::with_adjoint;
    s.alpha = {(146.0 + 5.0 * r) / 540.0, (-2.0 + 10.0 * r) / 135.0, 0.2, (-23.0 - 20.0 * r) / 270.0,
               (14.0 - r) / 108.0};
    s.beta.assign(s.alpha.rbegin(), s.alpha.rend());
    s.citation = citation;
    return s;
  }
};

// Blanes & Moan's splitting methods for Runge-Kutta-Nystrom problems (J. Comput. Appl.
// Math. 142 (2002) 313, Table 3, SRKN_6^b and SRKN_11^b): symmetric, kick first,
//   e^{b_1 h B} e^{a_1 h A} e^{b_2 h B} ... e^{a_1 h A} e^{b_1 h B},
// B the kick p += c F(q), A the drift q += c M^{-1} p. FSAL: m + 1 kicks cost m forces
// a step. Their coefficients minimise the leading error terms among methods with that
// many forces; the order holds where T is quadratic in p and V depends on q alone.
namespace composition_detail {
// (b_1..b_k, a_1..a_j) of the first half to the whole palindromes: the middle kick
// (odd number of kicks) or drift is 1 - 2 (sum of the others in its half).
inline CompositionScheme rkn_palindrome(const char* name, int order, std::vector<double> b, std::vector<double> a,
                                        bool middle_kick, const char* citation) {
  auto close = [](std::vector<double> half, bool odd) {
    double sum = 0.0;
    for (double x : half) sum += x;
    if (odd) {
      half.push_back(1.0 - 2.0 * sum);
      return mirror(half);
    }
    half.back() = 0.5 - (sum - half.back());  // the last listed entry of an even half is 1/2 - the rest
    std::vector<double> whole = half;
    whole.insert(whole.end(), half.rbegin(), half.rend());
    return whole;
  };
  CompositionScheme s;
  s.name = name;
  s.order = order;
  s.symmetric = true;
  s.kind = CompositionKind::rkn_splitting;
  s.kick = close(std::move(b), middle_kick);
  s.drift = close(std::move(a), !middle_kick);
  s.stages = static_cast<int>(s.kick.size()) - 1;  // forces a step (first same as last)
  s.citation = citation;
  return s;
}
}  // namespace composition_detail

// SRKN_6^b, order 4, 6 forces: b_4 = 1 - 2 (b_1 + b_2 + b_3), a_3 = 1/2 - (a_1 + a_2).
struct BlanesMoan4 {
  static constexpr const char* name = "blanes-moan4";
  static CompositionScheme scheme() {
    return composition_detail::rkn_palindrome(
        name, 4, {0.0829844064174052, 0.396309801498368, -0.0390563049223486},
        {0.245298957184271, 0.604872665711080, 0.0}, true,
        "Blanes & Moan, J. Comput. Appl. Math. 142 (2002) 313, SRKN_6^b (Table 3); separable systems, explicit "
        "Euler maps");
  }
};

// SRKN_11^b, order 6, 11 forces: b_6 = 1/2 - (b_1 + ... + b_5), a_6 = 1 - 2 (a_1 + ... + a_5).
struct BlanesMoan6 {
  static constexpr const char* name = "blanes-moan6";
  static CompositionScheme scheme() {
    return composition_detail::rkn_palindrome(
        name, 6,
        {0.0414649985182624, 0.198128671918067, -0.0400061921041533, 0.0752539843015807, -0.0115113874206879, 0.0},
        {0.123229775946271, 0.290553797799558, -0.127049212625417, -0.246331761062075, 0.357208872795928}, false,
        "Blanes & Moan, J. Comput. Appl. Math. 142 (2002) 313, SRKN_11^b (Table 3); separable systems, explicit "
        "Euler maps");
  }
};

// The triple jump applied recursively (Yoshida 1990; Creutz & Gocksch 1989): from a
// symmetric method of order p (even), (g Psi, (1 - 2g) Psi, g Psi) with
// g = 1/(2 - 2^{1/(p+1)}) has order p + 2. Order 2k needs 3^{k-1} stages.
struct RecursiveTripleJump {
  static constexpr const char* citation =
      "Yoshida, Phys. Lett. A 150 (1990) 262; Creutz & Gocksch, Phys. Rev. Lett. 63 (1989) 9";
  static constexpr int max_order = 12;
  static CompositionScheme scheme(int order) {
    if (order < 2 || order > max_order || order % 2 != 0)
      throw std::invalid_argument("triple-jump: the order must be even and between 2 and " +
                                  std::to_string(max_order) + ", got " + std::to_string(order));
    std::vector<double> g = {1.0};
    for (int p = 2; p < order; p += 2) {
      const double c = std::pow(2.0, 1.0 / (p + 1)), a = 1.0 / (2.0 - c), b = -c * a;
      std::vector<double> next;
      for (double f : {a, b, a})
        for (double x : g) next.push_back(f * x);
      g = next;
    }
    CompositionScheme s;
    s.name = "triple-jump:" + std::to_string(order);
    s.order = order;
    s.stages = static_cast<int>(g.size());
    s.symmetric = true;
    s.kind = CompositionKind::of_symmetric;
    s.gamma = g;
    s.citation = citation;
    return s;
  }
};

// Every named method, in the order `dvm methods` lists them.
inline const std::vector<CompositionScheme>& composition_schemes() {
  using namespace composition_detail;
  static const std::vector<CompositionScheme> list = {
      StormerVerletComposition::scheme(),
      describe<TripleJump4>(),
      describe<Suzuki5>(),
      McLachlan4::scheme(),
      describe<Yoshida6A>(),
      describe<Yoshida6B>(),
      describe<Yoshida6C>(),
      describe<KahanLi6>(),
      describe<Yoshida8A>(),
      describe<Yoshida8B>(),
      describe<Yoshida8C>(),
      describe<Yoshida8D>(),
      describe<Yoshida8E>(),
      describe<SuzukiUmeno8>(),
      describe<KahanLi8>(),
      BlanesMoan4::scheme(),
      BlanesMoan6::scheme(),
  };
  return list;
}

// The scheme of a name: one of composition_schemes(), or "triple-jump:<order>".
// Throws std::invalid_argument for an unknown name ("none" is not a scheme).
inline CompositionScheme find_composition(const std::string& name) {
  for (const auto& s : composition_schemes())
    if (s.name == name) return s;
  // messages quote at most 80 bytes of the name
  const std::string shown =
      name.size() > 80 ? name.substr(0, 80) + "... (" + std::to_string(name.size()) + " bytes)" : name;
  const std::string prefix = "triple-jump:";
  if (name.rfind(prefix, 0) == 0) {
    const std::string digits = name.substr(prefix.size());
    if (!digits.empty() && digits.size() <= 3 && digits.find_first_not_of("0123456789") == std::string::npos)
      return RecursiveTripleJump::scheme(std::stoi(digits));
    throw std::invalid_argument("triple-jump: expected triple-jump:<even order>, got \"" + shown + "\"");
  }
  std::string names;
  for (const auto& s : composition_schemes()) names += ", " + s.name;
  throw std::invalid_argument("unknown composition \"" + shown + "\"; expected one of: none" + names +
                              ", triple-jump:<even order 2.." + std::to_string(RecursiveTripleJump::max_order) + ">");
}

// The symplectic DIRK with weights b_1..b_s (paper Sec. 6.2): the Runge-Kutta method
// a_ij = b_j (j < i), a_ii = b_i / 2 is the composition of implicit midpoint steps of
// sizes b_1 h, ..., b_s h, in that order, so its scheme has gamma = b. The weights must
// be nonzero and finite with sum 1. Its order as a composition of a symmetric method of
// order 2: 2; at least 3 when sum b_i^3 = 0 (the h^3 error terms cancel); at least 4 when
// b is moreover a palindrome (a symmetric method has even order).
inline CompositionScheme dirk_scheme(const std::vector<double>& b) {
  if (b.empty()) throw std::invalid_argument("dirk: expected at least one weight");
  double sum = 0.0, cubes = 0.0, size = 0.0;
  for (double x : b) {
    if (!(x != 0.0) || !std::isfinite(x)) throw std::invalid_argument("dirk: weights must be nonzero and finite");
    sum += x;
    cubes += x * x * x;
    size += std::fabs(x * x * x);
  }
  if (!(std::fabs(sum - 1.0) <= 1e-14 * static_cast<double>(b.size())))
    throw std::invalid_argument("dirk: the weights must sum to 1, got " + std::to_string(sum));
  CompositionScheme s;
  s.name = "dirk";
  s.stages = static_cast<int>(b.size());
  s.gamma = b;
  s.symmetric = std::equal(b.begin(), b.end(), b.rbegin());
  const bool third = std::fabs(cubes) <= 1e-14 * size;
  s.order = third ? (s.symmetric ? 4 : 3) : 2;
  s.citation = "symplectic DIRK as a composition of midpoint steps (Barbero-Linan, Martin de Diego, Sec. 6.2)";
  return s;
}

// Symplectic partitioned Runge-Kutta pairs from two DIRKs (paper Sec. 6.2, the remark
// after the DIRK composition; solvers/partitioned_dirk.h derives them): weights b_i and
// a theta per stage, stage i the Hamiltonian step of the theta map theta_i of size
// b_i h. All thetas 1/2 give the DIRK of weights b.
struct PartitionedDirk {
  std::vector<double> weight;  // b_i
  std::vector<double> theta;   // a_ii / b_i
  bool symmetric = false;      // b palindromic and theta_{s+1-i} = 1 - theta_i
  int order = 1;               // see above: a proved lower bound

  // The two tableaux: a (for q) when `momentum` is false, a^ (for p) when it is true.
  std::vector<std::vector<double>> tableau(bool momentum) const {
    const std::size_t s = weight.size();
    std::vector<std::vector<double>> a(s, std::vector<double>(s, 0.0));
    for (std::size_t i = 0; i < s; ++i) {
      for (std::size_t j = 0; j < i; ++j) a[i][j] = weight[j];
      a[i][i] = (momentum ? 1.0 - theta[i] : theta[i]) * weight[i];
    }
    return a;
  }
};

// The pair of weights b and thetas theta_i = a_ii / b_i. Throws std::invalid_argument for
// weights dirk_scheme refuses (empty, a zero, not summing to 1), thetas of another
// length, or a theta outside [0, 1] (where the theta map is defined).
inline PartitionedDirk partitioned_dirk_thetas(const std::vector<double>& b, const std::vector<double>& theta) {
  const CompositionScheme weights = dirk_scheme(b);  // validates b
  if (theta.size() != b.size())
    throw std::invalid_argument("partitioned dirk: " + std::to_string(b.size()) + " weights but " +
                                std::to_string(theta.size()) + " thetas");
  PartitionedDirk m;
  m.weight = b;
  double second = 0.0, size = 0.0;  // sum (theta_i - 1/2) b_i^2, and sum b_i^2 for its round-off
  for (std::size_t i = 0; i < b.size(); ++i) {
    const double th = theta[i];
    size += b[i] * b[i];
    if (!(th >= 0.0 && th <= 1.0))
      throw std::invalid_argument("partitioned dirk: theta_i = a_ii / b_i must lie in [0, 1], got " +
                                  std::to_string(th) + " at stage " + std::to_string(i + 1));
    m.theta.push_back(th);
    second += (th - 0.5) * b[i] * b[i];
  }
  m.symmetric = weights.symmetric;
  for (std::size_t i = 0; i < b.size(); ++i)  // (theta_i as a quotient carries one rounding)
    m.symmetric = m.symmetric && std::fabs(m.theta[i] + m.theta[b.size() - 1 - i] - 1.0) <= 4e-16;
  bool all_midpoint = true;
  for (double th : m.theta) all_midpoint = all_midpoint && th == 0.5;
  m.order = all_midpoint ? weights.order : std::fabs(second) <= 1e-14 * size ? 2 : 1;
  return m;
}

// The pair of weights b and q-tableau diagonal a_ii (theta_i = a_ii / b_i).
inline PartitionedDirk partitioned_dirk(const std::vector<double>& b, const std::vector<double>& a_diagonal) {
  if (a_diagonal.size() != b.size())
    throw std::invalid_argument("partitioned dirk: " + std::to_string(b.size()) + " weights but " +
                                std::to_string(a_diagonal.size()) + " diagonal entries");
  std::vector<double> theta;
  for (std::size_t i = 0; i < b.size(); ++i) theta.push_back(a_diagonal[i] / b[i]);
  return partitioned_dirk_thetas(b, theta);
}

// One substep of a composition: a step of fraction `weight` of h with the basic map
// (adjoint = false) or its adjoint (adjoint = true).
struct Substep {
  double weight;
  bool adjoint;
};

// The substeps of a scheme applied to a basic map whose symmetry is given: a
// symmetric map is its own symmetric basic method; any other map enters through
// Phi_{h/2} o Phi^*_{h/2} (adjoint half first).
//
// A splitting (rkn_splitting) takes Phi = the explicit Euler map, kick x then drift x,
// and Phi^* = drift y then kick y: Phi_{x_1}, Phi^*_{y_1}, Phi_{x_2}, ... gives kicks
// x_1, y_1 + x_2, ... and drifts x_1 + y_1, x_2 + y_2, ..., so x_1 = b_1,
// y_i = a_i - x_i, x_{i+1} = b_{i+1} - y_i (the correspondence of HLW GNI Sec. II.5).
// Called with map_symmetric, it throws std::invalid_argument: a symmetric map has no
// kicks and drifts. For the adjoint Euler map as Phi, flip every substep's adjoint.
inline std::vector<Substep> substeps(const CompositionScheme& s, bool map_symmetric) {
  std::vector<Substep> out;
  if (s.kind == CompositionKind::rkn_splitting) {
    if (map_symmetric)
      throw std::invalid_argument(s.name + " is a splitting into kicks and drifts: it composes the explicit Euler "
                                  "map with its adjoint, not a symmetric map");
    double x = s.kick.at(0);
    for (std::size_t i = 0; i < s.drift.size(); ++i) {
      const double y = s.drift[i] - x;
      out.push_back({x, false});
      out.push_back({y, true});
      x = s.kick.at(i + 1) - y;
    }
    return out;
  }
  if (s.kind == CompositionKind::with_adjoint) {
    for (std::size_t i = 0; i < s.alpha.size(); ++i) {
      out.push_back({s.beta[i], true});
      out.push_back({s.alpha[i], false});
    }
  } else {
    for (double g : s.gamma) {
      if (map_symmetric) {
        out.push_back({g, false});
      } else {
        out.push_back({0.5 * g, true});
        out.push_back({0.5 * g, false});
      }
    }
  }
  return out;
}

// The substeps with Phi and Phi^* exchanged (the same method from the adjoint map).
inline std::vector<Substep> adjoint_substeps(std::vector<Substep> s) {
  for (Substep& x : s) x.adjoint = !x.adjoint;
  return s;
}

}  // namespace dvm
