// Helpers of the constrained-scene suites (test_cli_constraints, test_cli_constraints_long):
// a dvm run of a shipped scene with --set overrides, read as JSON.
#pragma once

#include <string>
#include <vector>

#include "tests/cli/cli_harness.h"

namespace cli_test {

inline std::vector<std::string> with_sets(std::vector<std::string> args, const std::vector<std::string>& sets) {
  for (const auto& s : sets) {
    args.push_back("--set");
    args.push_back(s);
  }
  return args;
}
inline Json run(const std::string& s, const std::vector<std::string>& sets) {
  const Output o = dvm(with_sets({"run", scene(s), "--json", "--no-output"}, sets));
  BOOST_TEST_REQUIRE(o.status == 0, s << ": " << o.err);
  return parse_json(o.out);
}
inline std::vector<double> vec(const Json& j, const char* key) { return j.at(key).get<std::vector<double>>(); }

}  // namespace cli_test
