// Rig records in rosbag files as a real rig would record them (docs/rig.md): the two shaft angles
// as sensor_msgs/JointState and the pinion torque as geometry_msgs/WrenchStamped, one message
// per sample each, stamped 1 s + the sample time; the gear parameters as GearParams.
#pragma once

#include <string>

#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"
#include "gear_sim/status.hpp"

namespace gear_sim_ros {

/// Default bound on the messages per topic readRigBag holds in memory (about 100 bytes each).
constexpr size_t kMaxRigBagMessages = 20000000;

struct RigBagTopics {
  std::string joints = "/rig/joint_states";
  std::string torque = "/rig/torque";
  std::string params = "/gear/params";
  std::string joint1 = "pinion_joint";  ///< JointState name of the pinion shaft
  std::string joint2 = "gear_joint";    ///< JointState name of the gear shaft
  char axis = 'z';                      ///< torque component of the WrenchStamped carrying T1
};

/// Writes `rig` (time, theta1, theta2, torque) as JointState + WrenchStamped messages (and the
/// gear parameters when `params` is not null). Temporary file renamed on success.
gear_sim::Status writeRigBag(const std::string& path, const gear_sim::SignalTable& rig,
                             const gear_sim::GearModel* params, const RigBagTopics& topics);

/// Whether the bag at `path` holds sensor_msgs/JointState messages on `topics.joints` (a rig bag,
/// for `analyze --input`). False for an unreadable or corrupt file (checked record by record
/// first; the caller's reader reports why).
bool isRigBag(const std::string& path, const RigBagTopics& topics);

/// Reads a rig bag: per JointState message on `topics.joints` the positions of the joints named
/// `joint1`, `joint2`, and the torque with the same stamp on `topics.torque`
/// (geometry_msgs/WrenchStamped, component `axis`, or std_msgs/Float64); time = stamp minus the
/// first JointState stamp. Stamps must increase. InvalidInput naming the bag and the reason (a
/// missing joint or torque, a corrupt file). The bag is read whole: ResourceLimit (field
/// "max_in_memory"), before anything is read, when either topic holds more than `max_messages`
/// messages (analyze passes --max-in-memory).
gear_sim::Status readRigBag(const std::string& path, const RigBagTopics& topics,
                            gear_sim::SignalTable* rig, size_t max_messages = kMaxRigBagMessages);

}  // namespace gear_sim_ros
