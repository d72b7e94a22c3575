// The time-stamp resolution rule shared by every reader of a SignalTable (signal_table.hpp).
#include "gear_sim/signal_table.hpp"

#include <algorithm>
#include <cmath>
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

}  // namespace gear_sim
