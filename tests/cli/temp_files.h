// Scratch files of the end-to-end tests: a private temporary folder removed when the
// test program exits, and reading a whole file.
#pragma once

#include <boost/test/unit_test.hpp>

#include <sys/types.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <system_error>

namespace cli_test {

// A folder /tmp/dvm_cli_XXXXXX, removed with everything in it when the object is
// destroyed, by the process that created it only (a forked child that exits does
// not remove its parent's folder).
class TempDir {
 public:
  TempDir() : owner_(getpid()) {
    char tmpl[] = "/tmp/dvm_cli_XXXXXX";
    const char* d = mkdtemp(tmpl);
    BOOST_REQUIRE(d);
    path_ = d;
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  ~TempDir() {
    std::error_code ec;
    if (getpid() == owner_) std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  pid_t owner_;
};

// A private temporary folder for this test program, removed when it exits.
inline std::string temp_dir() {
  static const TempDir dir;
  return dir.path();
}

inline std::string slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

}  // namespace cli_test
