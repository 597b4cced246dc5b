// Bad input at the boundary of the runtime layer (solvers/runtime): an unknown name, a
// value out of range, a combination of choices that is not supported, an output path
// that cannot be written. The message names the key (as a scene writes it, e.g.
// 'integrator.composition'), the value and what was expected. Programs map it to exit
// status 2; numerical failures during a run are reported in the run's report instead.
#pragma once

#include <stdexcept>
#include <string>

namespace dvm {

struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace dvm
