// Segment-by-segment identification for the live node (see live_identification.hpp).
#include "gear_damping_id/live_identification.hpp"

#include <algorithm>

namespace gear_damping_id {

namespace {

DriverLimits liveLimits(const LiveLimits& l) {
  DriverLimits d;
  d.history_segments = std::max<size_t>(l.history_segments, 1);
  d.shared_segments = std::max<size_t>(l.shared_segments, 1);
  d.solve_shared_each_segment = true;
  return d;
}

}  // namespace

LiveIdentification::LiveIdentification(const IdentificationOptions& options,
                                       const GearConstants& gear, const LiveLimits& limits)
    : limits_(limits), driver_(options, gear, liveLimits(limits)) {
  limits_.history_segments = std::max<size_t>(limits_.history_segments, 1);
  limits_.shared_segments = std::max<size_t>(limits_.shared_segments, 1);
}

IdentificationResult LiveIdentification::cumulative(size_t last) const {
  IdentificationResult r = driver_.result(last);
  r.windows.clear();
  return r;
}

}  // namespace gear_damping_id
