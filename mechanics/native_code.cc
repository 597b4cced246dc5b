// Derivative programs compiled to machine code at run time (mechanics/native_code.h).
#include "mechanics/native_code.h"

#include <dlfcn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>

namespace dvm {

std::string default_c_compiler() {
  const char* cc = std::getenv("DVM_CC");
  return cc && *cc ? cc : "cc";
}

namespace {

// A directory of its own under $TMPDIR, removed with what is in it.
class ScratchDirectory {
 public:
  ScratchDirectory() {
    const char* t = std::getenv("TMPDIR");
    std::string pattern = std::string(t && *t ? t : "/tmp") + "/dvm-native-XXXXXX";
    if (pattern.find('\'') != std::string::npos)
      throw NativeCodeError("compiled derivatives: TMPDIR contains a quote: " + pattern);
    if (!::mkdtemp(pattern.data())) throw NativeCodeError("compiled derivatives: cannot create a directory " + pattern);
    path_ = pattern;
  }
  ~ScratchDirectory() {
    for (const std::string& f : files_) ::unlink(f.c_str());
    ::rmdir(path_.c_str());
  }
  ScratchDirectory(const ScratchDirectory&) = delete;
  ScratchDirectory& operator=(const ScratchDirectory&) = delete;
  std::string file(const std::string& name) {
    files_.push_back(path_ + "/" + name);
    return files_.back();
  }

 private:
  std::string path_;
  std::vector<std::string> files_;
};

}  // namespace

std::vector<std::shared_ptr<const DerivativeProgram>> compile_programs(const std::vector<const DerivativeProgram*>& programs,
                                                                       const std::string& compiler, double* seconds) {
  const auto start = std::chrono::steady_clock::now();
  std::string src = "#define _GNU_SOURCE\n#include <math.h>\n";
  for (std::size_t k = 0; k < programs.size(); ++k) {
    const std::string s = programs[k]->c_source("dvm_program" + std::to_string(k));
    if (s.empty())
      throw NativeCodeError("compiled derivatives: a program with sums over arrays (blocks) has no C source; their "
                            "loops run interpreted");
    src += s;
  }
  ScratchDirectory dir;
  const std::string c = dir.file("programs.c"), so = dir.file("programs.so");
  {
    std::ofstream f(c);
    f << src;
    if (!f.flush()) throw NativeCodeError("compiled derivatives: cannot write " + c);
  }
  const std::string command =
      compiler + " -O2 -fPIC -shared -fno-math-errno -ffp-contract=off -o '" + so + "' '" + c + "' -lm 2>&1";
  std::string output;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) throw NativeCodeError("compiled derivatives: cannot run the C compiler: " + command);
  char buf[512];
  while (std::fgets(buf, sizeof buf, pipe))
    if (output.size() < 2000) output += buf;
  const int status = ::pclose(pipe);
  if (status != 0) {
    std::string why = status == -1 ? "could not be waited for"
                      : WIFEXITED(status) ? "exited with status " + std::to_string(WEXITSTATUS(status))
                                          : "was stopped by a signal";
    throw NativeCodeError("compiled derivatives: the C compiler (" + compiler + ", from $DVM_CC or cc) " + why +
                          (output.empty() ? std::string() : ":\n" + output));
  }
  void* handle = ::dlopen(so.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const char* e = ::dlerror();
    throw NativeCodeError(std::string("compiled derivatives: cannot load the compiled code: ") + (e ? e : "?"));
  }
  const std::shared_ptr<const void> code(handle, [](const void* h) { ::dlclose(const_cast<void*>(h)); });
  auto symbol = [&](const std::string& name) {
    void* f = ::dlsym(handle, name.c_str());
    if (!f) throw NativeCodeError("compiled derivatives: the compiled code has no " + name);
    return f;
  };
  std::vector<std::shared_ptr<const DerivativeProgram>> out;
  for (std::size_t k = 0; k < programs.size(); ++k) {
    const std::string prefix = "dvm_program" + std::to_string(k);
    auto g = reinterpret_cast<DerivativeProgram::GradientFn>(symbol(prefix + "_gradient"));
    auto h = programs[k]->has_hessian() ? reinterpret_cast<DerivativeProgram::HessianFn>(symbol(prefix + "_hessian"))
                                        : nullptr;
    out.push_back(programs[k]->with_native(g, h, code));
  }
  if (seconds) *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

}  // namespace dvm
