// libFuzzer target: TOML text -> validated scene (solvers/runtime/scene.cc): a problem and a
// method of the runtime layer, validated by dvm::validate.
//
// Any input must end in a Scene or an InputError (bad input is expected and fine);
// anything else - a crash, undefined behaviour, a leak, another exception - is a
// finding. Run by `make fuzz`; seed corpus in tests/fuzz/corpus/scene.
#include <cstddef>
#include <cstdint>
#include <string>

#include "solvers/runtime/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const dvm::Scene s = dvm::load_scene_text(text, "fuzz.toml", {});
    // what the runners rely on after validation
    if (s.problem.step <= 0.0 || s.problem.steps < 1 || s.every < 1 || !s.problem.system) __builtin_trap();
  } catch (const dvm::InputError&) {
  }
  return 0;
}
