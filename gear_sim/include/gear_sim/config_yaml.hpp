// Loading the simulator's YAML configuration (README "Simulator configuration") into the option
// structs of sim_config.hpp. Part of gear_sim_io (yaml-cpp), no ROS. Every error names the key
// (e.g. "load.amplitud: unknown key (known: profile, mean, ...)") and nothing is defaulted
// silently for a misspelt key.
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>

#include "gear_sim/sim_config.hpp"
#include "gear_sim/status.hpp"

namespace gear_sim {

/// Fills `out` from a YAML mapping with the sections pinion, gear, mesh, speed, load, damping,
/// simulation (each optional: a missing section or key keeps the default of SimConfig). Unknown
/// sections/keys, wrong types and unknown profile names are errors; the result is validated
/// (SimConfig::check). `base_dir` resolves a relative `load.file`. A broken key is InvalidInput
/// with the key ("load.amplitud") as Status::field(); a broken rule is InvalidArgument with the
/// options field; `out` is left unchanged on failure.
Status loadSimConfig(const YAML::Node& root, SimConfig* out, const std::string& base_dir = ".");

/// Reads and loads a YAML file (see loadSimConfig); the message starts with the path. A file
/// that cannot be opened is IoError.
Status loadSimConfigFile(const std::string& path, SimConfig* out);

/// For analysers (`analyze --params`): reads only pinion, gear, mesh and speed (all four
/// required), ignores the other sections, validates the result.
Status loadGearModelFile(const std::string& path, GearModel* out);
Status loadGearModel(const YAML::Node& root, GearModel* out);

/// Writes `config` as YAML with every key (the inverse of loadSimConfig).
YAML::Node toYaml(const SimConfig& config);

}  // namespace gear_sim
