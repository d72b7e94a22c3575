// Identification results <-> gear_damping messages (shared by the analyze tool and the nodes).
#pragma once

#include <gear_damping/DampingArray.h>
#include <gear_damping/DampingSegment.h>
#include <gear_damping/ModeledResponse.h>
#include <gear_damping/WaveletModes.h>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/wavelet.hpp"

namespace gear_damping_ros {

/// One segment estimate as a message (k levels NaN for the known formulation).
gear_damping::DampingSegment toMsg(const gear_damping_id::SegmentEstimate& s,
                                   gear_damping_id::Formulation f);

/// A whole result: its segments (piecewise), or the shared constant estimate as one segment
/// spanning the analysed record (constant model), and c0/c1 (load_law; NaN otherwise).
gear_damping::DampingArray toMsg(const gear_damping_id::IdentificationResult& r);

/// A modeled response; sample i of the series is global sample first_index + i.
gear_damping::ModeledResponse toMsg(const gear_damping_id::ModeledResponse& m, double sample_rate,
                                    std::uint64_t first_index);

/// Wavelet modes of a window [t_start, t_end] [s]; the result's times must already be on the
/// record's time axis (shiftWaveletTimes), they are copied as they are.
gear_damping::WaveletModes toMsg(const gear_damping_id::WaveletResult& r, double t_start,
                                 double t_end);

}  // namespace gear_damping_ros
