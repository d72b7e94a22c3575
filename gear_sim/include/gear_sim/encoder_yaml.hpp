// The `encoder` section of the simulator's YAML (config/rig_example.yaml, docs/rig.md). Part of
// gear_sim_io; no ROS.
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>

#include "gear_sim/encoders.hpp"
#include "gear_sim/status.hpp"

namespace gear_sim {

/// Fills `out` from the `encoder` mapping of `root` (absent: defaults, encoder disabled).
/// Unknown keys and wrong types are InvalidInput naming the key (field "encoder.<key>"); the
/// result is validated (EncoderOptions::check, InvalidArgument). The file variant puts the path
/// in front of the message; an unreadable file is IoError.
Status loadEncoderOptions(const YAML::Node& root, EncoderOptions* out);
Status loadEncoderOptionsFile(const std::string& path, EncoderOptions* out);

}  // namespace gear_sim
