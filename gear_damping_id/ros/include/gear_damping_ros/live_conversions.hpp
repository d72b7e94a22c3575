// Message <-> core conversions only the live nodes need: an incoming chunk as StreamAssembler
// input, and a wavelet result as WaveletModes. (Damping arrays and modeled responses:
// id_conversions.hpp, shared with `analyze`; chunks <-> tables and gear parameters:
// gear_sim_ros/conversions.hpp.)
#pragma once

#include <gear_damping/SignalChunk.h>
#include <gear_damping/WaveletModes.h>

#include <string>
#include <vector>

#include "gear_damping_id/stream_assembler.hpp"
#include "gear_damping_id/wavelet.hpp"

namespace gear_damping_ros {

/// A chunk message as core ChunkData pointing into `msg` (and into `*mesh_state`, which receives
/// the 0/1 bytes as doubles). False with `*error` if an optional channel is present with a length
/// different from dte's (the chunk is then malformed and must be rejected).
bool toChunkData(const gear_damping::SignalChunk& msg, std::vector<double>* mesh_state,
                 gear_damping_id::ChunkData* out, std::string* error);

/// Wavelet modes of a window [t_start, t_end] [s] (record time; the core's decay regions are
/// relative to the window's first sample and are shifted by t_start).
gear_damping::WaveletModes toMsg(const gear_damping_id::WaveletResult& r, double t_start,
                                 double t_end);

}  // namespace gear_damping_ros
