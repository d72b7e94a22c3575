// Message <-> core conversions of the identification and wavelet results (the nodes' only
// translation layer; the signal and gear-parameter conversions are in gear_sim_ros).
#pragma once

#include <gear_damping/DampingArray.h>
#include <gear_damping/ModeledResponse.h>
#include <gear_damping/SignalChunk.h>
#include <gear_damping/WaveletModes.h>

#include <string>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/stream_assembler.hpp"
#include "gear_damping_id/wavelet.hpp"

namespace gear_damping_id_ros {

/// A chunk message as core ChunkData pointing into `msg` (and into `*mesh_state`, which receives
/// the 0/1 bytes as doubles). False with `*error` if an optional channel is present with a length
/// different from dte's (the chunk is then malformed and must be rejected).
bool toChunkData(const gear_damping::SignalChunk& msg, std::vector<double>* mesh_state,
                 gear_damping_id::ChunkData* out, std::string* error);

gear_damping::DampingSegment toMsg(const gear_damping_id::SegmentEstimate& e);

/// Segments, model, Me, omega0 and (load_law) c0/c1 of `r`; header left default.
gear_damping::DampingArray toMsg(const gear_damping_id::IdentificationResult& r);

/// Modeled response over samples starting at global index `first_index`.
gear_damping::ModeledResponse toMsg(const gear_damping_id::ModeledResponse& m, double sample_rate,
                                    std::uint64_t first_index);

/// Wavelet modes of a window [t_start, t_end] [s].
gear_damping::WaveletModes toMsg(const gear_damping_id::WaveletResult& r, double t_start,
                                 double t_end);

}  // namespace gear_damping_id_ros
