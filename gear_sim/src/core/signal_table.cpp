// The time-stamp resolution rule and the plausibility ranges shared by every reader of a
// SignalTable (signal_table.hpp).
#include "gear_sim/signal_table.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>

#include "gear_sim/message_text.hpp"

namespace gear_sim {

namespace {
// A step must be resolved to this fraction of itself or finer.
constexpr double kMinStepResolution = 1e-3;
}  // namespace

double timeResolution(double t_abs_max) {
  const double t = std::abs(t_abs_max);
  return std::nextafter(t, std::numeric_limits<double>::infinity()) - t;
}

Status checkTimeResolution(double t_abs_max, double step) {
  const double u = timeResolution(t_abs_max);
  if (u <= kMinStepResolution * std::abs(step)) return {};
  return Status::invalidInput("time stamps near " + formatNumber(std::abs(t_abs_max)) +
                                  " s are resolved only to " + formatNumber(u) +
                                  " s in double precision, coarser than 1/1000 of the sampling "
                                  "step " +
                                  formatNumber(step) +
                                  " s: re-base the time (first_index, or the time column) nearer "
                                  "to 0",
                              "time");
}

double stepTolerance(double rel_tolerance, double step, double t_abs_max) {
  return std::max(rel_tolerance * std::abs(step), 3.0 * timeResolution(t_abs_max));
}

ImplausibleCounts maskImplausible(SignalTable* table) {
  ImplausibleCounts counts;
  Eigen::VectorXd* ranged[] = {&table->dte,    &table->dte_velocity, &table->stiffness,
                               &table->torque, &table->mesh_phase,   &table->damping};
  static_assert(std::size(ranged) == std::size(kPlausibleRanges), "one range per channel");
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  for (size_t k = 0; k < std::size(ranged); ++k) {
    const PlausibleRange& r = kPlausibleRanges[k];
    for (double& x : *ranged[k]) {
      if (!std::isfinite(x)) {
        ++counts.non_finite;
      } else if (x < r.low || x > r.high) {
        ++counts.out_of_range;
        x = kNaN;
      }
    }
  }
  for (double& x : table->mesh_state) {
    if (!std::isfinite(x)) {
      ++counts.non_finite;
    } else if (x != 0.0 && x != 1.0) {
      ++counts.bad_mesh_states;
      x = kNaN;
    }
  }
  return counts;
}

std::vector<std::string> implausibleWarnings(const ImplausibleCounts& counts,
                                             const std::string& where) {
  std::vector<std::string> lines;
  auto warn = [&](std::int64_t n, const std::string& what) {
    if (n > 0) lines.push_back(std::to_string(n) + " " + what);
  };
  warn(counts.non_finite, "NaN/Inf values " + where +
                              " (the segments whose analysis uses those samples are not "
                              "identifiable)");
  warn(counts.out_of_range,
       "values outside their channel's plausible range (|dte| <= 1 m, |dte_velocity| <= 1e4 "
       "m/s, stiffness in [0, 1e13] N/m, |torque| <= 1e9 N*m, |damping| <= 1e9 N*s/m, "
       "|mesh_phase| <= 2^53 cycles): read as NaN");
  warn(counts.bad_mesh_states, "mesh_state values other than 0 or 1: read as NaN");
  return lines;
}

}  // namespace gear_sim
