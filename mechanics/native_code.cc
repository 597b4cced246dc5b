// Derivative programs compiled to machine code at run time (mechanics/native_code.h).
#include "mechanics/native_code.h"

#include <dlfcn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cfenv>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <fstream>
#include <mutex>
#if defined(__x86_64__) || defined(__i386__)
#include <xmmintrin.h>
#endif

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
    if (pattern[0] != '/') pattern = "./" + pattern;  // a relative TMPDIR "-x" is no option
    if (pattern.find('\'') != std::string::npos)
      throw NativeCodeError("compiled derivatives: TMPDIR contains a quote: " + pattern);
    if (!::mkdtemp(pattern.data()))
      throw NativeCodeError("compiled derivatives: cannot create a directory " + pattern + " (" +
                            std::strerror(errno) + "); set TMPDIR to a writable directory");
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

// The floating-point control modes: the rounding mode and, on x86, the SSE control and
// status register (compared without its status flags, bits 0 to 5: flush-to-zero,
// denormals-are-zero, rounding and the exception masks).
struct FpControls {
  int round = 0;
  unsigned csr = 0;
  static FpControls now() {
    FpControls c;
    c.round = std::fegetround();
#if defined(__x86_64__) || defined(__i386__)
    c.csr = _mm_getcsr();
#endif
    return c;
  }
  bool same_modes(const FpControls& o) const { return round == o.round && (csr & ~0x3Fu) == (o.csr & ~0x3Fu); }
  void restore() const {
    std::fesetround(round);
#if defined(__x86_64__) || defined(__i386__)
    _mm_setcsr(csr);
#endif
  }
};

// The objects this process compiled and loaded, the most recently used first, each with
// what it was compiled from (the compiler's command and the C source): a later call
// for the same source and compiler loads the same object again instead of compiling it
// (the runs of a sweep, of a convergence study, of a test). At most kKept stay loaded.
class LoadedObjects {
 public:
  static constexpr std::size_t kKept = 16;
  std::shared_ptr<const void> find(const std::string& key) {
    const std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = kept_.begin(); it != kept_.end(); ++it)
      if (it->first == key) {
        auto found = *it;
        kept_.erase(it);
        kept_.push_front(found);
        return found.second;
      }
    return nullptr;
  }
  void add(const std::string& key, const std::shared_ptr<const void>& code) {
    const std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& k : kept_)
      if (k.first == key) return;  // loaded by another thread meanwhile
    kept_.emplace_front(key, code);
    if (kept_.size() > kKept) kept_.pop_back();
  }

 private:
  std::mutex mutex_;
  std::deque<std::pair<std::string, std::shared_ptr<const void>>> kept_;
};

LoadedObjects& loaded_objects() {
  static LoadedObjects objects;
  return objects;
}

// The programs calling the functions of the loaded object `code`.
std::vector<std::shared_ptr<const DerivativeProgram>> bind(const std::vector<const DerivativeProgram*>& programs,
                                                           const std::shared_ptr<const void>& code) {
  void* handle = const_cast<void*>(code.get());
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
  return out;
}

}  // namespace

std::vector<std::shared_ptr<const DerivativeProgram>> compile_programs(const std::vector<const DerivativeProgram*>& programs,
                                                                       const std::string& compiler, double* seconds) {
  const auto start = std::chrono::steady_clock::now();
  std::string src = "#define _GNU_SOURCE\n#include <math.h>\n";
  for (std::size_t k = 0; k < programs.size(); ++k) {
    const std::string s = programs[k]->c_source("dvm_program" + std::to_string(k));
    if (s.empty())
      throw NativeCodeError("compiled derivatives: the text has blocks (a sum over an array, or 16 or more terms "
                            "of one shape written out), which have no C source; their loops run interpreted");
    src += s;
  }
  const std::string key = compiler + '\n' + src;
  auto elapsed = [&] {
    if (seconds) *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  if (const std::shared_ptr<const void> code = loaded_objects().find(key)) {
    auto out = bind(programs, code);
    elapsed();
    return out;
  }
  ScratchDirectory dir;
  const std::string c = dir.file("programs.c"), so = dir.file("programs.so");
  {
    std::ofstream f(c);
    f << src;
    if (!f.flush()) throw NativeCodeError("compiled derivatives: cannot write " + c);
  }
  // Our flags come after the compiler's own (a $DVM_CC of "gcc -ffast-math" is undone):
  // -fno-fast-math also keeps crtfastmath.o (flush-to-zero for the whole process) out
  // of the link, and -fno-builtin-pow keeps pow(x, -1.0) and pow(x, 2.0) calls to libm,
  // as the interpreter makes them, where gcc would write 1/x and x*x.
  const std::string command = compiler +
                              " -O2 -fPIC -shared -fno-math-errno -ffp-contract=off -fno-fast-math -fno-builtin-pow -o '" +
                              so + "' '" + c + "' -lm 2>&1";
  std::string output;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) throw NativeCodeError("compiled derivatives: cannot run the C compiler: " + command);
  char buf[512];
  while (std::fgets(buf, sizeof buf, pipe))
    if (output.size() < 2000) output += buf;
  const int status = ::pclose(pipe);
  if (status != 0) {
    std::string why = status == -1 ? "could not be waited for"
                      : WIFEXITED(status)   ? "exited with status " + std::to_string(WEXITSTATUS(status))
                      : WIFSIGNALED(status) ? "was killed by signal " + std::to_string(WTERMSIG(status))
                                            : "did not exit";
    throw NativeCodeError("compiled derivatives: the C compiler (" + compiler + ", from $DVM_CC or cc) " + why +
                          (output.empty() ? std::string() : ":\n" + output));
  }
  // Loading runs the object's initialisers; one that changes the floating-point control
  // modes (crtfastmath.o's flush-to-zero, linked by flags of $DVM_CC) would change every
  // later operation of the process, interpreted or not: such code is refused and the
  // modes restored.
  const FpControls controls = FpControls::now();
  void* handle = ::dlopen(so.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!handle) {
    const char* e = ::dlerror();
    throw NativeCodeError(std::string("compiled derivatives: cannot load the compiled code: ") + (e ? e : "?") +
                          " (a TMPDIR mounted noexec cannot load code; set TMPDIR to another directory)");
  }
  const std::shared_ptr<const void> code(handle, [](const void* h) { ::dlclose(const_cast<void*>(h)); });
  if (!FpControls::now().same_modes(controls)) {
    controls.restore();
    throw NativeCodeError("compiled derivatives: loading the compiled code changed the floating-point control modes "
                          "(flush-to-zero or rounding; from flags such as -ffast-math in the compiler command '" +
                          compiler + "'); refused, and the modes restored");
  }
  auto out = bind(programs, code);
  loaded_objects().add(key, code);
  elapsed();
  return out;
}

}  // namespace dvm
