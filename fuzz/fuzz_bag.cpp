// libFuzzer target: the bag readers. A rig bag (JointState + WrenchStamped, `analyze --input`
// takes it) goes through isRigBag and readRigBag; anything else through scanSignalBag, then
// readSignalBag and streamed reads (every other segment-sized range, then overlapping ranges:
// each block equal to the whole read's samples). The input is written to
// a temporary .bag file; the seeds are small bags from `simulate` (a signal bag and a rig bag),
// so mutations hit headers, chunk records and SignalChunk / JointState / WrenchStamped payloads.
// The one-pass reading of `analyze` (previewSignalBag, scanStreamSignalBag) is checked against
// scanSignalBag (the preview's default-window prefix mean too). Beyond scanSignalBag's limits
// nothing may be allocated: a record it accepts spans at most twice its real samples
// (kMaxGapRatio), which the input's size bounds.
#include <cstdint>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

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
  // The one-pass reading (previewSignalBag, then scanStreamSignalBag) allocates no more than the
  // input's size bounds and accepts only what scanSignalBag accepts, with its numbers.
  gear_sim_ros::BagSignalInfo one;
  bool one_ok = false, previewed = false;
  double preview_mean = 0.0;  // the default window's prefix, read before the pass
  if (gear_sim_ros::previewSignalBag(path, "", &one)) {
    previewed = true;
    preview_mean = one.stiffness_mean;
    if (one.samples < 0 || static_cast<std::uint64_t>(one.samples) > size / 4 + 1) std::abort();
    std::vector<std::pair<Eigen::Index, Eigen::Index>> parts;
    for (Eigen::Index b = 0; b + 41 <= one.samples; b += 82) parts.emplace_back(b, b + 41);
    one_ok = gear_test::ok(
        gear_sim_ros::scanStreamSignalBag(
            &one, parts, [](const gear_sim::SignalTable&, size_t) { return gear_sim::Status(); }),
        &error);
  }
  gear_sim_ros::BagSignalInfo info;
  if (!gear_test::ok(gear_sim_ros::scanSignalBag(path, "", &info), &error)) {
    if (one_ok) std::abort();
    gear_fuzz::checkMessage(error);  // rosbag's own texts are quoted too
    return 0;
  }
  // A bag the scan accepts and the preview read has the scan's prefix mean in the preview: its
  // one pass does not start again.
  if (previewed && std::memcmp(&preview_mean, &info.stiffness_mean, sizeof(double)) != 0)
    std::abort();
  if (one_ok && (one.samples != info.samples || one.real_samples != info.real_samples ||
                 one.chunks != info.chunks || one.gaps != info.gaps ||
                 one.warnings != info.warnings || one.first_index != info.first_index ||
                 std::memcmp(&one.stiffness_mean, &info.stiffness_mean, sizeof(double)) != 0))
    std::abort();
  if (info.samples < 0 || static_cast<double>(info.gap_samples) >
                              gear_sim_ros::kMaxGapRatio * static_cast<double>(info.real_samples))
    std::abort();
  gear_sim::SignalTable t;
  const bool whole = gear_test::ok(gear_sim_ros::readSignalBag(info, &t), &error);
  if (whole && t.size() != info.samples) std::abort();
  // Streamed reads: every other range of 37 samples, then ranges that overlap (each beginning 8
  // samples before the previous one ends, as analyze's groups with their left context). Each
  // block holds the whole read's samples bit for bit (gaps and implausible values as the same
  // NaN), the overlap in both blocks.
  const auto same = [](const Eigen::VectorXd& block, const Eigen::VectorXd& all, Eigen::Index a) {
    if (block.size() == 0) return all.size() == 0;
    return a + block.size() <= all.size() &&
           std::memcmp(block.data(), all.data() + a,
                       sizeof(double) * static_cast<size_t>(block.size())) == 0;
  };
  for (const Eigen::Index stride : {Eigen::Index{74}, Eigen::Index{29}}) {
    std::vector<std::pair<Eigen::Index, Eigen::Index>> ranges;
    for (Eigen::Index b = 0; b + 37 <= info.samples; b += stride) ranges.emplace_back(b, b + 37);
    gear_test::ok(gear_sim_ros::streamSignalBag(
                      info, ranges,
                      [&](const gear_sim::SignalTable& block, size_t r) {
                        if (block.size() == 0) return gear_sim::Status::internal("empty");
                        const Eigen::Index a = ranges[r].first;
                        if (whole && !(same(block.time, t.time, a) && same(block.dte, t.dte, a) &&
                                       same(block.stiffness, t.stiffness, a) &&
                                       same(block.torque, t.torque, a) &&
                                       same(block.mesh_state, t.mesh_state, a) &&
                                       same(block.mesh_phase, t.mesh_phase, a)))
                          std::abort();
                        return gear_sim::Status();
                      }),
                  &error);
  }
  return 0;
}
