// Shared harness of the end-to-end tests: run the built dvm binary, read its output,
// pick numbers out of its JSON. DVM_BINARY and DVM_SCENES come from CMake.
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

#include "tests/cli/temp_files.h"

namespace cli_test {

struct Output {
  int status;
  std::string out, err;
};

// Runs dvm with the arguments (each single-quoted for the shell).
inline Output dvm(const std::vector<std::string>& args) {
  std::string cmd = DVM_BINARY;
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

inline std::string scene(const std::string& name) { return std::string(DVM_SCENES) + "/" + name; }

inline std::string write_scene(const std::string& name, const std::string& text) {
  const std::string path = temp_dir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

// The number after "key": in a JSON text, searching from `from` (NaN if absent).
inline double json_number(const std::string& json, const std::string& key, std::size_t from = 0) {
  const auto pos = json.find("\"" + key + "\":", from);
  if (pos == std::string::npos) return NAN;
  return std::strtod(json.c_str() + pos + key.size() + 3, nullptr);
}

inline bool file_exists(const std::string& path) { return std::ifstream(path).good(); }

// The numbers of the array after "key": (empty if absent).
inline std::vector<double> json_array(const std::string& json, const std::string& key) {
  std::vector<double> out;
  const std::size_t at = json.find("\"" + key + "\": [");
  if (at == std::string::npos) return out;
  const char* c = json.c_str() + json.find('[', at) + 1;
  char* end = nullptr;
  for (;;) {
    const double x = std::strtod(c, &end);
    if (end == c) break;
    out.push_back(x);
    c = end;
    while (*c == ',' || *c == ' ' || *c == '\n') ++c;
  }
  return out;
}

// The string after "key": (without escapes; "" if absent), searching from `from`.
inline std::string json_string(const std::string& json, const std::string& key, std::size_t from = 0) {
  const auto pos = json.find("\"" + key + "\": \"", from);
  if (pos == std::string::npos) return "";
  const auto start = pos + key.size() + 5;
  return json.substr(start, json.find('"', start) - start);
}

}  // namespace cli_test
