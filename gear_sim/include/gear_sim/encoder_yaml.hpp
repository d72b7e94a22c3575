// The `encoder` section of the simulator's YAML (config/rig_example.yaml, docs/rig.md). Part of
// gear_sim_io; no ROS.
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>

#include "gear_sim/encoders.hpp"

namespace gear_sim {

/// Fills `out` from the `encoder` mapping of `root` (absent: defaults, encoder disabled).
/// Unknown keys and wrong types are errors naming the key; the result is validated.
bool loadEncoderOptions(const YAML::Node& root, EncoderOptions* out, std::string* error);
bool loadEncoderOptionsFile(const std::string& path, EncoderOptions* out, std::string* error);

}  // namespace gear_sim
