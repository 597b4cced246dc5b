// Reading a written system from a scene's [system] table:
//
//   [system]
//   name = "double pendulum"                     # optional, shown in the output
//   space = "R^n"                                # optional: "R^n", "S^2", "(S^2)^K" (K = 1..4)
//                                                # or "SO(3)"
//   coordinates = ["a", "b"]                     # S^2: three (default x, y, z); (S^2)^K: 3K
//                                                # (default x1, y1, z1, x2, ...); SO(3): none
//                                                # R^n: "q[n]" or "q[1000]" is an array q[1..n]
//   ends = { q = "fixed" }                       # optional, per array: "none", "fixed", "periodic"
//   lagrangian = "... a, b, a_dot, b_dot, parameters ..."
//   params = { m1 = 1.0, k = [1.0, 2.0], ... }   # any names: numbers, or lists (k[1], k[2])
//   definitions = ["r = sqrt(x^2 + y^2)"]        # optional: named subexpressions
//   energy = "..."                               # optional: q, q_dot and p_q names
//   hamiltonian = "..."                          # optional: q and p_q names
//
// Errors in an expression are reported at the line and column of the scene file
// where they are: the string's own position plus the offset inside it, following
// the TOML string syntax (escapes, multi-line strings).
#pragma once

#include <string>

#include <toml++/toml.h>

#include "solvers/runtime/scene.h"

namespace dvm {

// Fills the problem's system, params, written system and dimension from `sys`.
// Throws InputError.
void read_written_system(const std::string& path, const toml::table& sys, Problem& pr);

// "file:line:column" of the character at `offset` of the string value `n` (or a
// description of the --set override when the value did not come from the file).
std::string string_location(const std::string& path, const toml::node& n, std::size_t offset);

}  // namespace dvm
