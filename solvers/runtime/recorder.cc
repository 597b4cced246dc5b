#include "solvers/runtime/recorder.h"

#include <unistd.h>

#include <cstdio>

namespace dvm {

void Recorder::open(const std::vector<std::string>& columns, double rows) {
  columns_ = static_cast<int>(columns.size());
  if (!spec_.csv.empty()) {
    csv_.open(spec_.csv, spec_.csv_source, csv_bytes(rows, columns_));
    for (std::size_t i = 0; i < columns.size(); ++i)
      std::fprintf(csv_.get(), "%s%s", i ? "," : "", columns[i].c_str());
    std::fputc('\n', csv_.get());
  }
  if (!spec_.npy.empty()) {
    npy_.open(spec_.npy, spec_.npy_source, npy_bytes(rows, columns_));
    write_npy_header();
  }
  if (spec_.progress && isatty(fileno(stderr))) {
    progress_on_ = true;
    start_ = last_ = std::chrono::steady_clock::now();
  }
}

void Recorder::row(const double* x) {
  if (csv_) {
    for (int i = 0; i < columns_; ++i) std::fprintf(csv_.get(), i ? ",%.17g" : "%.17g", x[i]);
    std::fputc('\n', csv_.get());
  }
  if (npy_) {
    std::fwrite(x, sizeof(double), static_cast<std::size_t>(columns_), npy_.get());
    ++npy_rows_;
  }
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
  return finish_outputs(complete, {&csv_, &npy_}, kept);
}

void Recorder::progress(std::int64_t k, std::int64_t total, double h) {
  if (!progress_on_ || (k & 1023) != 0) return;
  const auto now = std::chrono::steady_clock::now();
  if (std::chrono::duration<double>(now - last_).count() < 0.25) return;
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
