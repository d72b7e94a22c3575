// Message <-> core conversions (the only place the package translates between ROS messages and
// the cores' types; used by the `simulate` tool, the nodes and the bag readers).
#pragma once

#include <gear_damping/GearParams.h>
#include <gear_damping/SignalChunk.h>
#include <xmlrpcpp/XmlRpcValue.h>
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <string>
#include <vector>

#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"
#include "gear_sim/status.hpp"

namespace gear_sim_ros {

/// Samples [begin, begin + count) of `table` as a chunk whose first sample has global index
/// `first_index`. Every present optional column is copied; `mesh_state` becomes 0/1 bytes.
void toChunk(const gear_sim::SignalTable& table, Eigen::Index begin, Eigen::Index count,
             double sample_rate, std::uint64_t first_index, gear_damping::SignalChunk* msg);

/// Concatenates consecutive chunks into a table, time = first_index / sample_rate + i /
/// sample_rate. InvalidInput naming the chunk if the sample rate changes, indices are not
/// contiguous, an optional channel has the wrong length or is present in some chunks only.
gear_sim::Status chunksToTable(const std::vector<gear_damping::SignalChunk>& chunks,
                               gear_sim::SignalTable* out);

/// Gear model -> latched parameters message (with the derived Me, force factor, natural frequency).
gear_damping::GearParams toMsg(const gear_sim::GearModel& model);

/// Parameters message -> gear model (square/trapezoid/constant/fourier without harmonics);
/// validated: InvalidInput/InvalidArgument naming the field (Status::field()).
gear_sim::Status fromMsg(const gear_damping::GearParams& msg, gear_sim::GearModel* out);

/// A parameter tree (e.g. the node's private namespace after `rosparam load`) as YAML, so the
/// node goes through exactly the same loader and validation as the YAML file.
YAML::Node toYaml(const XmlRpc::XmlRpcValue& v);

}  // namespace gear_sim_ros
