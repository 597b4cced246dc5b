// Bad input at the boundary of the runtime layer (solvers/runtime): an unknown name, a
// value out of range, a combination of choices that is not supported, an output path
// that cannot be written. The message names the key (as a scene writes it, e.g.
// 'integrator.composition'), the value and what was expected. Programs map it to exit
// status 2; numerical failures during a run are reported in the run's report instead.
#pragma once

#include <cstdio>
#include <stdexcept>
#include <string>

namespace dvm {

struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A value as messages echo it: at most 80 bytes (then "... (N bytes)"), control
// characters and NUL written as \xNN, so that a huge or binary value neither floods
// the terminal nor cuts the message.
inline std::string echo(const std::string& value) {
  constexpr std::size_t kShown = 80;
  std::string out;
  for (std::size_t i = 0; i < value.size() && i < kShown; ++i) {
    const unsigned char c = static_cast<unsigned char>(value[i]);
    if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  if (value.size() > kShown) out += "... (" + std::to_string(value.size()) + " bytes)";
  return out;
}

}  // namespace dvm
