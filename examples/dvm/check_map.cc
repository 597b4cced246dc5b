// `dvm check-map`: the identity checks of a map (solvers/runtime/check_map.h), printed
// as JSON; exit status 0 when they pass, 1 when not.
#include <iostream>

#include "examples/dvm/commands.h"
#include "solvers/runtime/check_map.h"

namespace dvm::cli {

namespace {

int print_check(const MapCheck& c) {
  std::cout << map_check_json(c) << "\n";
  return c.passed ? 0 : 1;
}

}  // namespace

int check_map_command(const std::string& name, double theta, int dim, double tolerance,
                      const std::shared_ptr<const WrittenRetraction>& written) {
  return print_check(check_map(name, theta, dim, tolerance, written));
}

int check_scene_map_command(const std::string& path, const std::vector<std::string>& overrides, int dim,
                            double tolerance) {
  // the scene's map (load_scene refuses a written map that breaks Def. 2.2, exit 2)
  return print_check(check_scene_map(load_scene(path, overrides), dim, tolerance));
}

}  // namespace dvm::cli
