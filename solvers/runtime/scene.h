// Scenes: what `dvm run` and `dvm converge` read (a TOML file plus --set overrides),
// turned once into the runtime layer's typed values (solvers/runtime/problem.h). The one
// reader of scenes: the dvm program, C++ callers and bindings share it and its messages.
//
//   [system]      builtin = NAME   params = { ... }      (dvm systems)
//                 or a Lagrangian written in the scene (scene_written.h)
//   [initial]     q = [...] and p = [...] or v = [...]   (S^2: unit vector(s), tangent)
//                 SO(3): rotation = [w, x, y, z] or R = [[...], ...], omega or pi
//   [integrator]  map, theta, form, gamma, beta, composition, method, stages,
//                 quadrature, step, steps or t_end, solver, max_iterations, tolerance
//   [problem]     kind = "initial-value" | "boundary-value", q_final, steps
//   [output]      csv, npy, every
//
// The names are looked up in the registries (solvers/runtime/registry.h); every rule
// between values is dvm::validate's (solvers/runtime/problem.cc), whose messages name
// keys: the reader adds the file, line and column of the key. Points off the manifold
// and velocities that are not tangent are refused with the size of the defect (never
// projected).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "solvers/runtime/problem.h"

namespace dvm {

// A scene read and validated: the run it asks for, and its output.
struct Scene {
  std::string path;
  Problem problem;
  Method method;
  std::string csv, npy;  // [output] csv, npy (empty: none)
  std::int64_t every = 1;
  std::int64_t monitor_every = 1;  // [output] monitor_every
};

// The largest scene file dvm reads (16 MiB); a larger one is bad input.
constexpr std::size_t kMaxSceneBytes = std::size_t{16} << 20;
// The most parts a dotted key may have (a.b.c has 3), in a scene or in --set.
constexpr std::size_t kMaxKeyParts = 64;

// Loads and validates a scene; overrides are "section.key=value" with value written
// as in TOML (exactly one value). Throws InputError.
Scene load_scene(const std::string& path, const std::vector<std::string>& overrides);
// The same for a scene given as text; `path` names it in messages.
Scene load_scene_text(const std::string& text, const std::string& path, const std::vector<std::string>& overrides);

}  // namespace dvm
