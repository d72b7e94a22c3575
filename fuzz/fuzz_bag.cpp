// libFuzzer target: the bag reader (scanSignalBag, then readSignalBag and a streamed read of
// every other segment-sized range). The input is written to a temporary .bag file; the seed is
// a small bag from `simulate`, so mutations hit headers, chunk records and SignalChunk payloads.
// Beyond scanSignalBag's limits nothing may be allocated: a record it accepts spans at most
// twice its real samples (kMaxGapRatio), which the input's size bounds.
#include <cstdint>
#include <string>

#include "fuzz_support.hpp"
#include "gear_sim_ros/bag_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  static const std::string path = gear_fuzz::tempPath("bag");
  if (!gear_fuzz::writeFile(path, data, size)) return 0;
  gear_sim_ros::BagSignalInfo info;
  std::string error;
  if (!gear_sim_ros::scanSignalBag(path, "", &info, &error)) {
    gear_fuzz::checkMessage(error);  // rosbag's own texts are quoted too
    return 0;
  }
  if (info.samples < 0 || static_cast<double>(info.gap_samples) >
                              gear_sim_ros::kMaxGapRatio * static_cast<double>(info.real_samples))
    std::abort();
  gear_sim::SignalTable t;
  if (gear_sim_ros::readSignalBag(info, &t, &error) && t.size() != info.samples) std::abort();
  std::vector<std::pair<Eigen::Index, Eigen::Index>> ranges;
  const Eigen::Index step = 37;
  for (Eigen::Index b = 0; b + step <= info.samples; b += 2 * step)
    ranges.emplace_back(b, b + step);
  gear_sim_ros::streamSignalBag(
      info, ranges, [](const gear_sim::SignalTable& block, size_t) { return block.size() > 0; },
      &error);
  return 0;
}
