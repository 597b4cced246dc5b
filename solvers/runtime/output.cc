#include "solvers/runtime/output.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <climits>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <system_error>

#include "solvers/runtime/errors.h"

namespace dvm {

namespace fs = std::filesystem;

namespace {

// Bytes this process has promised to write, per filesystem (device id).
std::map<unsigned long long, double>& reserved() {
  static std::map<unsigned long long, double> r;
  return r;
}

// The temporaries of this process's open outputs, for the handler of SIGINT, SIGTERM
// and SIGHUP. The handler may only call async-signal-safe functions, so the paths live
// in fixed static buffers (no allocation, no std::string); a slot's path is complete
// before `used` is set and stays until after the file has been renamed or removed.
struct TempSlot {
  volatile std::sig_atomic_t used;
  char path[PATH_MAX];
};
constexpr int kTempSlots = 16;
TempSlot g_temp_slots[kTempSlots];

extern "C" void remove_temporaries_and_reraise(int sig) {
  for (TempSlot& t : g_temp_slots)
    if (t.used) unlink(t.path);
  // SA_RESETHAND restored the default action; the signal is blocked while this
  // handler runs, so it is delivered (and ends the process) when the handler returns
  raise(sig);
}

void install_signal_cleanup() {
  static bool installed = false;
  if (installed) return;
  installed = true;
  struct sigaction sa {};
  sa.sa_handler = remove_temporaries_and_reraise;
  sa.sa_flags = SA_RESETHAND;
  sigemptyset(&sa.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&sa.sa_mask, sig);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
    struct sigaction old {};
    // a signal the caller chose to ignore (nohup, a background job) stays ignored
    if (sigaction(sig, nullptr, &old) == 0 && old.sa_handler != SIG_IGN) sigaction(sig, &sa, nullptr);
  }
}

// Returns the slot holding `path`, or -1 when all are taken or the path is too long
// (that temporary is then not removed on a signal).
int register_temporary(const std::string& path) {
  if (path.size() >= PATH_MAX) return -1;
  for (int i = 0; i < kTempSlots; ++i) {
    TempSlot& t = g_temp_slots[i];
    if (t.used) continue;
    std::memcpy(t.path, path.c_str(), path.size() + 1);
    std::atomic_signal_fence(std::memory_order_seq_cst);  // the path is written before the flag
    t.used = 1;
    return i;
  }
  return -1;
}

void unregister_temporary(int& slot) {
  if (slot >= 0) g_temp_slots[slot].used = 0;
  slot = -1;
}

}  // namespace

double output_rows(std::int64_t steps, std::int64_t every) {
  return std::floor(static_cast<double>(steps) / static_cast<double>(every < 1 ? 1 : every)) + 2.0;
}

double csv_bytes(double rows, int columns) { return 64.0 * columns + rows * 25.0 * columns; }

double npy_bytes(double rows, int columns) { return 128.0 + rows * 8.0 * columns; }

std::string human_bytes(double bytes) {
  const char* units[] = {"bytes", "kB", "MB", "GB", "TB", "PB", "EB"};
  int u = 0;
  while (bytes >= 1000.0 && u < 6) bytes /= 1000.0, ++u;
  char buf[64];
  std::snprintf(buf, sizeof buf, u == 0 ? "%.0f %s" : "%.1f %s", bytes, units[u]);
  return buf;
}

int descriptor_path(const std::string& path) {
  if (path == "-" || path == "/dev/stdout") return 1;
  if (path == "/dev/stderr") return 2;
  for (const char* prefix : {"/dev/fd/", "/proc/self/fd/"}) {
    const std::size_t n = std::strlen(prefix);
    if (path.compare(0, n, prefix) != 0 || path.size() == n || path.size() > n + 6) continue;
    if (path.find_first_not_of("0123456789", n) != std::string::npos) continue;
    return std::atoi(path.c_str() + n);
  }
  return -1;
}

void OutputFile::open_stream(const std::string& path, const std::string& where, int fd) {
  f_ = fdopen(fd, "wb");
  if (!f_) {
    const int e = errno;
    ::close(fd);
    throw InputError(where + ": cannot write to it (" + std::strerror(e) + ")");
  }
  path_ = path;
  streamed_ = true;
}

bool OutputFile::seekable() const { return f_ && lseek(fileno(f_), 0, SEEK_CUR) != static_cast<off_t>(-1); }

void OutputFile::open(const std::string& path, const std::string& what, double bytes) {
  discard();
  const std::string where = what + " '" + echo(path) + "'";
  if (path.find('\0') != std::string::npos)
    throw InputError(what + ": the path contains a NUL character; expected a file name");
  // this process's descriptors, and existing paths that are not regular files: write
  // to them directly (renaming a temporary over a device node would replace it)
  if (const int d = descriptor_path(path); d >= 0) {
    const int fd = fcntl(d, F_DUPFD_CLOEXEC, 3);
    if (fd < 0) throw InputError(where + ": descriptor " + std::to_string(d) + " is not open (" + std::strerror(errno) + ")");
    open_stream(path, where, fd);
    return;
  }
  struct stat target {};
  if (::stat(path.c_str(), &target) == 0 && !S_ISREG(target.st_mode) && !S_ISDIR(target.st_mode)) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC);
    if (fd < 0) throw InputError(where + ": exists and is not a regular file, and cannot be opened for writing (" +
                                 std::strerror(errno) + ")");
    open_stream(path, where, fd);
    return;
  }
  const fs::path p(path);
  if (p.filename().empty()) throw InputError(where + ": expected a file name, got a directory path");
  const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw InputError(where + ": the directory '" + dir.string() + "' does not exist; expected a path in an existing directory");
  if (fs::is_directory(p, ec)) throw InputError(where + ": is a directory; expected a file name");
  if (fs::exists(p, ec) && access(path.c_str(), W_OK) != 0)
    throw InputError(where + ": the file exists and is not writable (" + std::strerror(errno) + ")");
  if (access(dir.c_str(), W_OK | X_OK) != 0)
    throw InputError(where + ": cannot create files in '" + dir.string() + "' (" + std::strerror(errno) + ")");

  std::string tmpl = (dir / ("." + p.filename().string() + ".XXXXXX")).string();
  // The handler is installed, and the signals it serves are held back, before the
  // temporary exists; they are let through once its path is registered, so a signal at
  // any moment finds either no file or a registered one.
  install_signal_cleanup();
  sigset_t cleanup_signals, previous;
  sigemptyset(&cleanup_signals);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&cleanup_signals, sig);
  pthread_sigmask(SIG_BLOCK, &cleanup_signals, &previous);
  const int fd = mkstemp(tmpl.data());
  const int mkstemp_errno = errno;
  if (fd >= 0) slot_ = register_temporary(tmpl);
  pthread_sigmask(SIG_SETMASK, &previous, nullptr);
  if (fd < 0)
    throw InputError(where + ": cannot create a file in '" + dir.string() + "' (" + std::strerror(mkstemp_errno) + ")");
  // mkstemp makes the file private (0600); give it the permissions a plain fopen would
  const mode_t mask = umask(0);
  umask(mask);
  fchmod(fd, 0666 & ~mask);
  f_ = fdopen(fd, "w+b");
  if (!f_) {
    ::close(fd);
    std::remove(tmpl.c_str());
    unregister_temporary(slot_);
    throw InputError(where + ": cannot open the temporary file '" + tmpl + "'");
  }
  path_ = path;
  temp_ = tmpl;

  // Room (checked once the path is known to be writable): this file plus the others this run writes to the same filesystem.
  struct stat st {};
  if (stat(dir.c_str(), &st) != 0)
    throw InputError(where + ": cannot inspect '" + dir.string() + "' (" + std::strerror(errno) + ")");
  device_ = static_cast<unsigned long long>(st.st_dev);
  const fs::space_info space = fs::space(dir, ec);
  const double total = reserved()[device_] + bytes;
  if (!ec && total > static_cast<double>(space.available)) {
    discard();
    char exact[64];
    std::snprintf(exact, sizeof exact, "%.0f", total);
    throw InputError(where + ": the run would write up to " + human_bytes(total) + " (" + exact +
                     " bytes) but the filesystem of '" +
                     dir.string() + "' has " + human_bytes(static_cast<double>(space.available)) +
                     " free; expected a run whose output fits (raise output.every, shorten the run, or "
                     "write elsewhere)");
  }
  reserved()[device_] = total;
  reserved_ = bytes;
}

std::string OutputFile::finish(bool complete) {
  if (!f_) return "";
  const bool write_error = std::fflush(f_) != 0 || std::ferror(f_) != 0;
  const int write_errno = errno;
  const bool close_error = std::fclose(f_) != 0;
  f_ = nullptr;
  if (streamed_) {
    if (write_error || close_error) return "error writing '" + path_ + "' (" + std::strerror(write_errno) + ")";
    return "";
  }
  if (write_error || close_error) {
    const std::string msg = "error writing '" + path_ + "' (" + std::strerror(write_errno) + "); nothing was kept";
    std::remove(temp_.c_str());
    unregister_temporary(slot_);
    temp_.clear();
    return msg;
  }
  const std::string target = complete ? path_ : path_ + ".partial";
  if (std::rename(temp_.c_str(), target.c_str()) != 0) {
    const std::string msg = "cannot rename '" + temp_ + "' to '" + target + "' (" + std::strerror(errno) + ")";
    std::remove(temp_.c_str());
    unregister_temporary(slot_);
    temp_.clear();
    return msg;
  }
  unregister_temporary(slot_);
  temp_.clear();
  return "";
}

void OutputFile::discard() {
  if (f_) std::fclose(f_);
  f_ = nullptr;
  streamed_ = false;
  if (!temp_.empty()) std::remove(temp_.c_str());
  unregister_temporary(slot_);  // after the removal: a signal in between finds no file
  temp_.clear();
  if (reserved_ > 0.0) reserved()[device_] -= reserved_;
  reserved_ = 0.0;
}

OutputFile::~OutputFile() { discard(); }

bool finish_outputs(bool complete, std::initializer_list<OutputFile*> files, std::string& kept) {
  bool ok = true;
  for (OutputFile* f : files) {
    if (!*f) continue;
    const std::string err = f->finish(complete);
    if (!err.empty()) {
      std::fprintf(stderr, "dvm: %s\n", err.c_str());
      ok = false;
    } else if (!complete) {
      kept += (kept.empty() ? "" : ", ") + f->path() + (f->streamed() ? " (as streamed)" : ".partial");
    }
  }
  return ok;
}

std::string output_source(const std::string& scene_path, const std::string& option_value, const char* option,
                          const char* key) {
  return option_value.empty() ? scene_path + ": key '" + key + "'" : std::string(option);
}

}  // namespace dvm
