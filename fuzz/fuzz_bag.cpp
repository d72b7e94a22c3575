// libFuzzer target: the bag readers. A rig bag (JointState + WrenchStamped, `analyze --input`
// takes it) goes through isRigBag and readRigBag; anything else through scanSignalBag, then
// readSignalBag and a streamed read of every other segment-sized range. The input is written to
// a temporary .bag file; the seeds are small bags from `simulate` (a signal bag and a rig bag),
// so mutations hit headers, chunk records and SignalChunk / JointState / WrenchStamped payloads.
// Beyond scanSignalBag's limits nothing may be allocated: a record it accepts spans at most
// twice its real samples (kMaxGapRatio), which the input's size bounds.
#include <cstdint>
#include <string>

#include "../test/unit/support/status_support.hpp"
#include "fuzz_support.hpp"
#include "gear_sim_ros/bag_io.hpp"
#include "gear_sim_ros/rig_bag_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  static const std::string path = gear_fuzz::tempPath("bag");
  if (!gear_fuzz::writeFile(path, data, size)) return 0;
  std::string error;
  const gear_sim_ros::RigBagTopics rig_topics;
  if (gear_sim_ros::isRigBag(path, rig_topics)) {
    gear_sim::SignalTable rig;
    if (!gear_test::ok(gear_sim_ros::readRigBag(path, rig_topics, &rig), &error)) {
      gear_fuzz::checkMessage(error);
    } else if (rig.size() == 0 || rig.theta1.size() != rig.size() ||
               rig.torque.size() != rig.size()) {
      std::abort();  // a read rig record has every column at its length
    }
    return 0;
  }
  gear_sim_ros::BagSignalInfo info;
  if (!gear_test::ok(gear_sim_ros::scanSignalBag(path, "", &info), &error)) {
    gear_fuzz::checkMessage(error);  // rosbag's own texts are quoted too
    return 0;
  }
  if (info.samples < 0 || static_cast<double>(info.gap_samples) >
                              gear_sim_ros::kMaxGapRatio * static_cast<double>(info.real_samples))
    std::abort();
  gear_sim::SignalTable t;
  if (gear_test::ok(gear_sim_ros::readSignalBag(info, &t), &error) && t.size() != info.samples)
    std::abort();
  std::vector<std::pair<Eigen::Index, Eigen::Index>> ranges;
  const Eigen::Index step = 37;
  for (Eigen::Index b = 0; b + step <= info.samples; b += 2 * step)
    ranges.emplace_back(b, b + step);
  gear_test::ok(gear_sim_ros::streamSignalBag(info, ranges,
                                              [](const gear_sim::SignalTable& block, size_t) {
                                                return block.size() > 0
                                                           ? gear_sim::Status()
                                                           : gear_sim::Status::internal("empty");
                                              }),
                &error);
  return 0;
}
