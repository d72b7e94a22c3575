// Message -> core conversion only the live nodes need: an incoming chunk as StreamAssembler
// input. (Damping arrays, modeled responses, wavelet modes: id_conversions.hpp, shared with
// `analyze`; chunks <-> tables and gear parameters: gear_sim_ros/conversions.hpp.)
#pragma once

#include <gear_damping/SignalChunk.h>

#include <string>
#include <vector>

#include "gear_damping_id/stream_assembler.hpp"
#include "gear_sim/status.hpp"

namespace gear_damping_ros {

/// A chunk message as core ChunkData pointing into `msg` (and into `*mesh_state`, which receives
/// the 0/1 bytes as doubles). InvalidInput (field: the channel) if an optional channel is present
/// with a length different from dte's (the chunk is then malformed and must be rejected).
gear_sim::Status toChunkData(const gear_damping::SignalChunk& msg, std::vector<double>* mesh_state,
                             gear_damping_id::ChunkData* out);

}  // namespace gear_damping_ros
