#include "solvers/runtime/recorder.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <new>
#include <stdexcept>
#include <utility>

#include "solvers/runtime/errors.h"
#include "solvers/runtime/json.h"

namespace dvm {

namespace {

// Whether two paths name the same file: the same descriptor, the same existing file
// (through links), or the same normalised path for files not yet there.
bool same_file(const std::string& a, const std::string& b) {
  namespace fs = std::filesystem;
  const int da = descriptor_path(a), db = descriptor_path(b);
  if (da >= 0 || db >= 0) return da == db;
  std::error_code ec;
  if (fs::exists(a, ec) && fs::exists(b, ec)) return fs::equivalent(a, b, ec);
  return fs::absolute(a, ec).lexically_normal() == fs::absolute(b, ec).lexically_normal();
}

}  // namespace

void Recorder::open(const std::vector<std::string>& columns, double rows) {
  columns_ = static_cast<int>(columns.size());
  names_ = columns;
  if (spec_.memory) {
    // the whole table reserved now: refused before the run if it cannot be held
    const double bytes = rows * static_cast<double>(columns_) * sizeof(double);
    const double memory = static_cast<double>(sysconf(_SC_PHYS_PAGES)) * static_cast<double>(sysconf(_SC_PAGE_SIZE));
    char what[160];
    std::snprintf(what, sizeof what, "the run's %.0f rows of %d columns kept in memory (%.3g bytes)", rows, columns_,
                  bytes);
    if (memory > 0.0 && bytes > memory) {
      char more[240];
      std::snprintf(more, sizeof more, "%s are more than this machine's memory (%.3g bytes)", what, memory);
      throw InputError(std::string("output.every: ") + more +
                       "; expected fewer rows (a larger output.every, or fewer steps)");
    }
    memory_.clear();
    try {
      memory_.reserve(static_cast<std::size_t>(rows) * static_cast<std::size_t>(columns_));
    } catch (const std::bad_alloc&) {
      throw InputError(std::string("output.every: ") + what +
                       " could not be allocated; expected fewer rows (a larger output.every, or fewer steps)");
    } catch (const std::length_error&) {
      throw InputError(std::string("output.every: ") + what +
                       " could not be allocated; expected fewer rows (a larger output.every, or fewer steps)");
    }
  }
  if (!spec_.csv.empty() && !spec_.npy.empty() && same_file(spec_.csv, spec_.npy))
    throw InputError(spec_.csv_source + " '" + spec_.csv + "' and " + spec_.npy_source + " '" + spec_.npy +
                     "' name the same file; expected two different paths");
  for (const std::string& in : spec_.inputs)
    for (const auto& [path, source] : {std::pair{spec_.csv, spec_.csv_source}, std::pair{spec_.npy, spec_.npy_source}})
      if (!path.empty() && same_file(path, in))
        throw InputError(source + " '" + path + "' is the scene file '" + in +
                         "' this run reads; expected another path for the output");
  if (!spec_.csv.empty()) {
    csv_.open(spec_.csv, spec_.csv_source, csv_bytes(rows, columns_));
    for (std::size_t i = 0; i < columns.size(); ++i)
      std::fprintf(csv_.get(), "%s%s", i ? "," : "", columns[i].c_str());
    std::fputc('\n', csv_.get());
  }
  if (!spec_.npy.empty()) {
    npy_.open(spec_.npy, spec_.npy_source, npy_bytes(rows, columns_));
    if (npy_.streamed() && !npy_.seekable()) {
      // (the destructors remove what open() created)
      throw InputError(spec_.npy_source + " '" + spec_.npy +
                       "': cannot be rewound (a pipe or a terminal), and a .npy file's header holds the row count "
                       "written at the end; expected a regular file or a seekable device");
    }
    write_npy_header();
    if (!npy_.streamed()) {
      // the column names beside the array, in PATH.json (a .npy header holds none)
      const std::string names_path = npy_names_path(spec_.npy);
      if (!spec_.csv.empty() && same_file(spec_.csv, names_path))
        throw InputError(spec_.csv_source + " '" + spec_.csv + "' is the file of the .npy's column names ('" +
                         names_path + "', written beside " + spec_.npy_source + "); expected another path");
      std::string list = "[";
      for (std::size_t i = 0; i < columns.size(); ++i) list += (i ? ", " : "") + Json::string(columns[i]);
      list += "]";
      Json::Object j;
      j.raw("columns", list).str("npy", std::filesystem::path(spec_.npy).filename().string());
      const std::string text = j.dump() + "\n";
      npy_names_.open(names_path, spec_.npy_source + " (its column names, " + names_path + ")",
                      static_cast<double>(text.size()));
      std::fwrite(text.data(), 1, text.size(), npy_names_.get());
    }
  }
  if (spec_.progress && isatty(fileno(stderr))) {
    progress_on_ = true;
    start_ = last_ = std::chrono::steady_clock::now();
    // DVM_PROGRESS_INTERVAL: the least time in seconds between two progress lines (see
    // recorder.h); a value that is not a finite number >= 0 leaves the default
    if (const char* s = std::getenv("DVM_PROGRESS_INTERVAL")) {
      char* end = nullptr;
      const double v = std::strtod(s, &end);
      if (end != s && *end == '\0' && std::isfinite(v) && v >= 0.0) progress_interval_ = v;
    }
  }
}

void Recorder::row(const double* x) {
  if (spec_.memory) memory_.insert(memory_.end(), x, x + columns_);
  if (csv_) {
    for (int i = 0; i < columns_; ++i) std::fprintf(csv_.get(), i ? ",%.17g" : "%.17g", x[i]);
    std::fputc('\n', csv_.get());
  }
  if (npy_) {
    std::fwrite(x, sizeof(double), static_cast<std::size_t>(columns_), npy_.get());
    ++npy_rows_;
  }
  if (sink_) sink_(names_, x);
}

// Magic, version 1.0, header length (little endian), then a Python dict literal padded
// with spaces to a 16-byte-aligned total of 128 bytes, ending in '\n'. The shape is
// unknown until the end: the header is written with room to spare and rewritten.
void Recorder::write_npy_header() {
  char dict[128];
  std::snprintf(dict, sizeof dict, "{'descr': '<f8', 'fortran_order': False, 'shape': (%20lld, %d), }", npy_rows_,
                columns_);
  std::string h(dict);
  const std::size_t total = 128, len = total - 10;
  h.resize(len - 1, ' ');
  h += '\n';
  const unsigned char pre[10] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, static_cast<unsigned char>(len & 0xff),
                                 static_cast<unsigned char>(len >> 8)};
  std::fwrite(pre, 1, 10, npy_.get());
  std::fwrite(h.data(), 1, h.size(), npy_.get());
}

bool Recorder::finish(bool complete, std::string& kept) {
  end_progress();
  if (npy_) {
    std::fseek(npy_.get(), 0, SEEK_SET);
    write_npy_header();
  }
  return finish_outputs(complete, {&csv_, &npy_, &npy_names_}, kept);
}

void Recorder::progress(std::int64_t k, std::int64_t total, double h) {
  if (spec_.poll && (k & (kPollSteps - 1)) == 0) spec_.poll(k, total);
  if (!progress_on_ || k == 0 || (k & 1023) != 0) return;
  const auto now = std::chrono::steady_clock::now();
  if (std::chrono::duration<double>(now - last_).count() < progress_interval_) return;
  last_ = now;
  const double el = std::chrono::duration<double>(now - start_).count();
  const double rate = static_cast<double>(k) / el;
  const double left = static_cast<double>(total - k) / rate;
  std::fprintf(stderr, "\r  step %lld/%lld  t = %.6g  %.3g steps/s  %.0f s left   ", static_cast<long long>(k),
               static_cast<long long>(total), static_cast<double>(k) * h, rate, left);
  std::fflush(stderr);
  progress_shown_ = true;
}

void Recorder::end_progress() {
  if (progress_shown_) std::fprintf(stderr, "\r%*s\r", 78, "");
  progress_shown_ = false;
}

}  // namespace dvm
