// The per-mode wavelet path's contract (docs/wavelet.md "Speed"): it is its own estimator,
// required to be statistically indistinguishable from the full-scalogram path, not equal to it.
// Over noise seeds, the full path's seed-to-seed standard deviation of each mode's xi and f_d is
// the method's own noise; on every seed the per-mode result must lie within kPerModeShareOfScatter
// of that standard deviation of the full path's result (its deviation is < 10 % of the noise).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "gear_damping_id/wavelet.hpp"

namespace gear_test {

constexpr double kPerModeShareOfScatter = 0.1;

// One record's pair of results for one mode: full path (a), per-mode path (b).
struct ModePair {
  double xi_a, xi_b, fd_a, fd_b;
};

// pairs[seed][mode] over noisy seeds: per mode the full path's sample standard deviation of xi
// and f_d, and the largest |b - a| / sd over seeds and modes (extra: records, e.g. the clean one,
// checked against the same sd but not part of it).
struct PerModeAgreement {
  std::vector<double> sd_xi, sd_fd;  // per mode
  double worst_xi = 0.0, worst_fd = 0.0;
};

inline double sampleStd(const std::vector<double>& v) {
  double mean = 0.0, ss = 0.0;
  for (double x : v) mean += x;
  mean /= static_cast<double>(v.size());
  for (double x : v) ss += (x - mean) * (x - mean);
  return v.size() > 1 ? std::sqrt(ss / static_cast<double>(v.size() - 1)) : 0.0;
}

inline PerModeAgreement perModeAgreement(const std::vector<std::vector<ModePair>>& noisy,
                                         const std::vector<std::vector<ModePair>>& extra = {}) {
  PerModeAgreement out;
  const size_t modes = noisy.empty() ? 0 : noisy.front().size();
  for (size_t i = 0; i < modes; ++i) {
    std::vector<double> xi, fd;
    for (const std::vector<ModePair>& s : noisy) {
      xi.push_back(s[i].xi_a);
      fd.push_back(s[i].fd_a);
    }
    out.sd_xi.push_back(sampleStd(xi));
    out.sd_fd.push_back(sampleStd(fd));
  }
  for (const auto* set : {&noisy, &extra}) {
    for (const std::vector<ModePair>& s : *set) {
      for (size_t i = 0; i < modes && i < s.size(); ++i) {
        out.worst_xi = std::max(out.worst_xi, std::abs(s[i].xi_b - s[i].xi_a) / out.sd_xi[i]);
        out.worst_fd = std::max(out.worst_fd, std::abs(s[i].fd_b - s[i].fd_a) / out.sd_fd[i]);
      }
    }
  }
  return out;
}

// A mode's decisions: free decay, damping ratio given or not, and its warning codes (the fit's
// omega0 follows xi and the spectral amplitudes continuously: not a decision).
inline std::string modeDecisions(const gear_damping_id::WaveletMode& m) {
  std::string s = std::string(m.free_decay ? "free" : "forced") +
                  (std::isnan(m.damping_ratio) ? " no-xi" : " xi");
  for (const auto& w : m.warnings) s += " " + w.code;
  return s;
}

}  // namespace gear_test
