// Loading the simulator's YAML configuration (README "Simulator configuration") into the option
// structs of sim_config.hpp. Part of gear_sim_io (yaml-cpp), no ROS. Every error names the key
// (e.g. "load.amplitud: unknown key (known: profile, mean, ...)") and nothing is defaulted
// silently for a misspelt key.
#pragma once

#include <yaml-cpp/yaml.h>

#include <string>

#include "gear_sim/sim_config.hpp"

namespace gear_sim {

/// Fills `out` from a YAML mapping with the sections pinion, gear, mesh, speed, load, damping,
/// simulation (each optional: a missing section or key keeps the default of SimConfig). Unknown
/// sections/keys, wrong types and unknown profile names are errors; the result is validated
/// (SimConfig::validate). `base_dir` resolves a relative `load.file`.
bool loadSimConfig(const YAML::Node& root, SimConfig* out, std::string* error,
                   const std::string& base_dir = ".");

/// Reads and loads a YAML file (see loadSimConfig).
bool loadSimConfigFile(const std::string& path, SimConfig* out, std::string* error);

/// For analysers (`analyze --params`): reads only pinion, gear, mesh and speed (all four
/// required), ignores the other sections, validates the result.
bool loadGearModelFile(const std::string& path, GearModel* out, std::string* error);
bool loadGearModel(const YAML::Node& root, GearModel* out, std::string* error);

/// Writes `config` as YAML with every key (the inverse of loadSimConfig).
YAML::Node toYaml(const SimConfig& config);

}  // namespace gear_sim
