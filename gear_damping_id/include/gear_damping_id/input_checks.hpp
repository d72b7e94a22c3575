// Plausibility checks of a record against the gear model and the options, shared by the
// analyze tool and the nodes (no ROS). Each returns ok when fine, else InvalidInput with a
// one-line message naming the problem and the numbers (field: the quantity concerned).
#pragma once

#include <string>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/signal_view.hpp"
#include "gear_sim/status.hpp"

namespace gear_damping_id {

/// Samples per natural period below which the identification is refused: the integrals of
/// eq. (4) cannot follow an oscillation sampled this coarsely (omega0*dt > 2*pi/8).
constexpr double kMinSamplesPerPeriod = 8.0;
/// Below this many samples per natural period a warning is given: the quadrature error,
/// which grows with (omega0*dt)^4, is then no longer negligible against 0.1 %.
constexpr double kWarnSamplesPerPeriod = 30.0;

/// Natural frequency [Hz] of the gear model: sqrt(mean stiffness / Me) / (2 pi).
double naturalFrequencyHz(const GearConstants& gear);

/// Error when sample_rate gives fewer than kMinSamplesPerPeriod samples per natural period
/// (field "sample_rate"); sets *warning (if not null) below kWarnSamplesPerPeriod.
gear_sim::Status checkSampleRate(double sample_rate, const GearConstants& gear,
                                 std::string* warning);

/// Error when the analysed part of a record of `duration` [s] is shorter than one damping
/// segment of the piecewise model (options.segment_length finite and positive; field
/// "segment_length").
gear_sim::Status checkRecordLength(double duration, const IdentificationOptions& options);

}  // namespace gear_damping_id
