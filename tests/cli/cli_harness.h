// Shared harness of the end-to-end tests: run the built dvm binary, read its output,
// parse its JSON. DVM_BINARY and DVM_SCENES come from CMake.
#pragma once

#include <boost/test/unit_test.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>

#include "tests/address_sanitizer.h"
#include "tests/cli/temp_files.h"

namespace cli_test {

struct Output {
  int status;
  std::string out, err;
};

// The program under test: DVM_BINARY, or $DVM_TEST_BINARY where set (to run the suites
// against another build, e.g. that of an earlier revision).
inline std::string dvm_binary() {
  const char* other = std::getenv("DVM_TEST_BINARY");
  return other && *other ? other : DVM_BINARY;
}

// Runs a program with the arguments (each single-quoted for the shell).
inline Output run_program(const std::string& program, const std::vector<std::string>& args) {
  std::string cmd = "'" + program + "'";
  for (const auto& a : args) {
    std::string q = "'";
    for (char c : a) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    cmd += " " + q + "'";
  }
  const std::string err_path = temp_dir() + "/stderr.txt";
  cmd += " 2>" + err_path;
  FILE* pipe = popen(cmd.c_str(), "r");
  BOOST_REQUIRE(pipe);
  std::string out;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  const int st = pclose(pipe);
  return {WIFEXITED(st) ? WEXITSTATUS(st) : -1, out, slurp(err_path)};
}

// Runs dvm with the arguments.
inline Output dvm(const std::vector<std::string>& args) { return run_program(dvm_binary(), args); }

// Runs dvm with its address space limited to `mebibytes` (the shell's ulimit -v): a run
// that forms matrices its method does not need fails (dvm exits 3, std::bad_alloc).
// Under AddressSanitizer, whose shadow memory alone reserves terabytes of address space,
// no such limit can be set: there it runs unlimited, and `make test` checks the limit.
inline Output dvm_within(long mebibytes, const std::vector<std::string>& args) {
  if (dvm_tests::kAddressSanitizer) return dvm(args);
  std::vector<std::string> shell = {"-c", "ulimit -v " + std::to_string(mebibytes * 1024) + " && exec \"$0\" \"$@\"",
                                    dvm_binary()};
  shell.insert(shell.end(), args.begin(), args.end());
  return run_program("/bin/sh", shell);
}

inline std::string scene(const std::string& name) { return std::string(DVM_SCENES) + "/" + name; }

inline std::string write_scene(const std::string& name, const std::string& text) {
  const std::string path = temp_dir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

inline bool file_exists(const std::string& path) { return std::ifstream(path).good(); }

// ---- reading the program's JSON ---------------------------------------------------------
// Every JSON text the program prints is parsed (nlohmann::json, in document order): a
// text that is not JSON fails the test that reads it.
using Json = nlohmann::ordered_json;

// The parsed text; the test stops with the text when it is not JSON.
inline Json parse_json(const std::string& text) {
  Json j = Json::parse(text, nullptr, false);
  BOOST_REQUIRE_MESSAGE(!j.is_discarded(), "not a JSON text:\n" << text);
  return j;
}

// The order `dvm converge` fits, run with `args` (the command and its options), --json and
// --set for each of `sets`; the test stops with its error where it does not exit 0 or
// fits none.
inline double fitted_order(std::vector<std::string> args, const std::vector<std::string>& sets) {
  args.push_back("--json");
  for (const std::string& s : sets) {
    args.push_back("--set");
    args.push_back(s);
  }
  const Output o = dvm(args);
  BOOST_REQUIRE_MESSAGE(o.status == 0, o.err);
  const Json j = parse_json(o.out);
  BOOST_REQUIRE_MESSAGE(j.at("fitted_order").is_number(), o.out);
  return j.at("fitted_order").get<double>();
}

// The first member named `key` in document order, depth first (a top-level member before
// the members of the objects before it only where it comes first); nullptr if none.
inline const Json* json_find(const Json& j, const std::string& key) {
  if (j.is_object()) {
    const auto it = j.find(key);
    for (auto m = j.begin(); m != j.end(); ++m) {
      if (m == it) return &*m;
      if (const Json* inner = json_find(*m, key)) return inner;
    }
  } else if (j.is_array()) {
    for (const Json& e : j)
      if (const Json* inner = json_find(e, key)) return inner;
  }
  return nullptr;
}

// A JSON number as a double: null (how the program writes NaN) is NaN.
inline double json_double(const Json& j) {
  BOOST_REQUIRE_MESSAGE(j.is_number() || j.is_null(), "not a number: " << j.dump());
  return j.is_null() ? NAN : j.get<double>();
}

// The number of the first member `key` of a JSON text (NaN if absent or null).
inline double json_number(const std::string& text, const std::string& key) {
  const Json j = parse_json(text);
  const Json* m = json_find(j, key);
  return m ? json_double(*m) : NAN;
}

// The numbers of the array of the first member `key` (empty if absent).
inline std::vector<double> json_array(const std::string& text, const std::string& key) {
  const Json j = parse_json(text);
  const Json* m = json_find(j, key);
  std::vector<double> out;
  if (!m) return out;
  BOOST_REQUIRE_MESSAGE(m->is_array(), key << " is not an array: " << m->dump());
  for (const Json& x : *m) out.push_back(json_double(x));
  return out;
}

// A conserved quantity of the report's "invariants" object, by name: its max_abs_error,
// and its initial value (one number, or the components of an array). NaN or empty where
// the report has no such quantity.
inline double invariant_error(const std::string& text, const std::string& name) {
  const Json j = parse_json(text);
  const auto inv = j.find("invariants");
  if (inv == j.end() || !inv->contains(name)) return NAN;
  return json_double((*inv)[name].at("max_abs_error"));
}
inline std::vector<double> invariant_initial(const std::string& text, const std::string& name) {
  const Json j = parse_json(text);
  const auto inv = j.find("invariants");
  std::vector<double> out;
  if (inv == j.end() || !inv->contains(name)) return out;
  const Json& x = (*inv)[name].at("initial");
  if (x.is_array())
    for (const Json& e : x) out.push_back(json_double(e));
  else
    out.push_back(json_double(x));
  return out;
}

// The string of the first member `key` ("" if absent; the test fails if it is not a string).
inline std::string json_string(const std::string& text, const std::string& key) {
  const Json j = parse_json(text);
  const Json* m = json_find(j, key);
  if (!m) return "";
  BOOST_REQUIRE_MESSAGE(m->is_string(), key << " is not a string: " << m->dump());
  return m->get<std::string>();
}

}  // namespace cli_test
