// libFuzzer target: the simulator's YAML loader (loadSimConfig, with validation) and the gear-
// parameter loader (loadGearModel) on any document yaml-cpp parses. Syntax errors are yaml-cpp's
// (reported by loadSimConfigFile as such); past parsing no exception may escape the loaders.
// A relative load.file resolves in a directory with no CSV, so no file is read.
#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <string>

#include "../test/unit/support/status_support.hpp"
#include "fuzz_support.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  YAML::Node root;
  try {
    root = YAML::Load(std::string(reinterpret_cast<const char*>(data), size));
  } catch (const YAML::Exception&) {
    return 0;  // a syntax error: the file loaders report it with its line
  }
  std::string error;
  gear_sim::SimConfig config;
  if (gear_test::ok(gear_sim::loadSimConfig(root, &config, "/nonexistent"), &error)) {
    // A valid configuration stays within the documented sizes.
    if (!(config.simulation.duration * config.simulation.sample_rate <=
          gear_sim::kMaxSimulationSamples))
      std::abort();
  } else {
    gear_fuzz::checkMessage(error);
  }
  error.clear();
  gear_sim::GearModel model;
  if (!gear_test::ok(gear_sim::loadGearModel(root, &model), &error)) gear_fuzz::checkMessage(error);
  return 0;
}
