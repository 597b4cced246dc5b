// Bad input at the boundary of the runtime layer (solvers/runtime): an unknown name, a
// value out of range, a combination of choices that is not supported, an output path
// that cannot be written. The message names the key (as a scene writes it, e.g.
// 'integrator.composition'), the value and what was expected. Programs map it to exit
// status 2; numerical failures during a run are reported in the run's report instead.
#pragma once

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <vector>

namespace dvm {

struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A value as messages echo it: at most 80 bytes (then "... (N bytes)"), control
// characters and NUL written as \xNN, so that a huge or binary value neither floods
// the terminal nor cuts the message.
inline std::string echo(const std::string& value) {
  constexpr std::size_t kShown = 80;
  std::string out;
  for (std::size_t i = 0; i < value.size() && i < kShown; ++i) {
    const unsigned char c = static_cast<unsigned char>(value[i]);
    if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  if (value.size() > kShown) out += "... (" + std::to_string(value.size()) + " bytes)";
  return out;
}

// The edit distance between two names: insertions, deletions, substitutions and swaps
// of neighbouring characters each count 1 (optimal string alignment), letters compared
// without case and '-' equal to '_', so that "mid-point", "kahan_li8", "t_ned" and
// "lagrangain" are each 1 from the name meant.
inline std::size_t name_distance(const std::string& a, const std::string& b) {
  auto fold = [](char c) {
    return c == '-' ? '_' : static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  };
  const std::size_t n = a.size(), m = b.size();
  std::vector<std::vector<std::size_t>> d(n + 1, std::vector<std::size_t>(m + 1));
  for (std::size_t i = 0; i <= n; ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= m; ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= n; ++i)
    for (std::size_t j = 1; j <= m; ++j) {
      const std::size_t cost = fold(a[i - 1]) == fold(b[j - 1]) ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && fold(a[i - 1]) == fold(b[j - 2]) && fold(a[i - 2]) == fold(b[j - 1]))
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  return d[n][m];
}

// "; did you mean \"NAME\"?" for the one known name nearest to `got` when it is close:
// at most 2 edits, and fewer than half the name's length (a short name is not
// suggested for an unrelated one); "" when none is, or when two are equally near.
inline std::string did_you_mean(const std::string& got, const std::vector<std::string>& known) {
  if (got.empty() || got.size() > 80) return "";
  std::size_t best = 3;
  const std::string* pick = nullptr;
  bool tie = false;
  for (const std::string& k : known) {
    const std::size_t d = name_distance(got, k);
    if (k == got || 2 * d >= k.size()) continue;
    if (d < best) {
      best = d;
      pick = &k;
      tie = false;
    } else if (d == best && pick && *pick != k) {
      tie = true;
    }
  }
  return pick && !tie ? "; did you mean \"" + *pick + "\"?" : "";
}

}  // namespace dvm
