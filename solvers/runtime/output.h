// The output files of a run (CSV, NumPy .npy), written so that a file at the final
// path is always a complete run.
//
//   - Before the run starts, each file's size is bounded from above (rows x columns
//     x the widest number) and the sum over the run's files on one filesystem is
//     compared with the space free there (std::filesystem::space). A run that would
//     not fit is refused as bad input, with both numbers in the message. So is a
//     path whose directory is missing or not writable, or that names a directory.
//   - Rows go to a temporary file created in the final path's directory
//     (".NAME.XXXXXX.tmp"). When the run is complete the file is flushed, closed and
//     renamed onto the final path: rename(2) within one filesystem is atomic, so the
//     final path holds either what it held before (or nothing) or the whole new file.
//   - A run that stops on a numerical failure renames its rows to "PATH.partial"
//     instead; the final path is left as it was. A write error (a full disk) removes
//     the temporary. A run stopped by SIGINT, SIGTERM or SIGHUP removes its
//     temporaries (the handler unlinks paths kept in static buffers, then re-raises
//     the signal, so the process still ends by it). Only a run killed outright
//     (SIGKILL, a crash) leaves a hidden temporary behind.
//   - A path that is not a regular file is written directly, as a stream, and never
//     replaced: "-" and /dev/stdout (standard output), /dev/stderr, /dev/fd/N and
//     /proc/self/fd/N (this process's descriptors), and any existing character
//     device, FIFO or socket. There is no size check and no rename; a write error
//     (/dev/full) is reported when the file is finished, and a failed run's rows
//     stay where they were streamed.
#pragma once

#include <cstdint>
#include <cstdio>
#include <initializer_list>
#include <string>

namespace dvm {

// The rows a run writes: the initial state, every `every`-th step and the last.
double output_rows(std::int64_t steps, std::int64_t every);
// Upper bounds of a file's size in bytes (a CSV number "%.17g" takes at most 24
// characters plus its separator; the header is bounded generously).
double csv_bytes(double rows, int columns);
double npy_bytes(double rows, int columns);

class OutputFile {
 public:
  OutputFile() = default;
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;
  ~OutputFile();  // not finished: the temporary is removed

  // Checks the path and the free space for `bytes` more (beside this process's other
  // open outputs on the same filesystem) and creates the temporary file. Throws
  // InputError naming `what` (the option or scene key that gave the path).
  void open(const std::string& path, const std::string& what, double bytes);
  std::FILE* get() const { return f_; }
  explicit operator bool() const { return f_ != nullptr; }
  const std::string& path() const { return path_; }
  // Written directly (see the header comment), not through a temporary.
  bool streamed() const { return streamed_; }
  // Whether the file can be rewound (a .npy header is rewritten at the end).
  bool seekable() const;

  // Flushes and closes the file and renames it onto the final path (complete) or
  // onto path() + ".partial" (a failed run). Returns an empty string on success,
  // else a message saying what went wrong (the temporary is then removed).
  std::string finish(bool complete);

 private:
  void discard();
  void open_stream(const std::string& path, const std::string& where, int fd);
  std::FILE* f_ = nullptr;
  bool streamed_ = false;
  std::string path_, temp_;
  double reserved_ = 0.0;
  unsigned long long device_ = 0;
  int slot_ = -1;  // where the signal handler finds temp_ (-1: not registered)
};

// Finishes each open file of a run (see OutputFile::finish), printing any error to
// stderr; returns false if one failed. For a failed run `kept` lists the .partial
// files written.
bool finish_outputs(bool complete, std::initializer_list<OutputFile*> files, std::string& kept);

// The descriptor a path names when it is one of this process's (-, /dev/stdout,
// /dev/stderr, /dev/fd/N, /proc/self/fd/N), else -1.
int descriptor_path(const std::string& path);

// What gave an output path, for messages: the option (when given) or the scene key.
std::string output_source(const std::string& scene_path, const std::string& option_value, const char* option,
                          const char* key);

// "12.3 GB": a byte count for messages.
std::string human_bytes(double bytes);

}  // namespace dvm
