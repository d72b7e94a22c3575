#include "gear_sim_ros/rig_bag_io.hpp"

#include <geometry_msgs/WrenchStamped.h>
#include <rosbag/bag.h>
#include <sensor_msgs/JointState.h>

#include "gear_sim_ros/bag_io.hpp"

namespace gear_sim_ros {

bool writeRigBag(const std::string& path, const gear_sim::SignalTable& t,
                 const gear_sim::GearModel* params, const RigBagTopics& topics,
                 std::string* error) {
  const Eigen::Index n = t.size();
  if (n == 0 || t.theta1.size() != n || t.theta2.size() != n || t.torque.size() != n) {
    *error = path + ": a rig bag needs time, theta1, theta2 and torque";
    return false;
  }
  if (!(t.time[0] >= 0.0) || !(t.time[n - 1] <= kMaxBagTime - 1.0)) {
    *error = path + ": sample times outside [0, " + std::to_string(kMaxBagTime - 1.0) + "] s";
    return false;
  }
  return writeBagStaged(
      path, params, topics.params,
      [&](rosbag::Bag& bag, const ros::Time& base) {
        sensor_msgs::JointState js;
        js.name = {topics.joint1, topics.joint2};
        js.position.resize(2);
        geometry_msgs::WrenchStamped w;
        for (Eigen::Index i = 0; i < n; ++i) {
          const ros::Time stamp = base + ros::Duration(t.time[i]);
          js.header.seq = w.header.seq = static_cast<std::uint32_t>(i);
          js.header.stamp = w.header.stamp = stamp;
          js.position[0] = t.theta1[i];
          js.position[1] = t.theta2[i];
          w.wrench.torque.x = topics.axis == 'x' ? t.torque[i] : 0.0;
          w.wrench.torque.y = topics.axis == 'y' ? t.torque[i] : 0.0;
          w.wrench.torque.z = topics.axis == 'z' ? t.torque[i] : 0.0;
          bag.write(topics.joints, stamp, js);
          bag.write(topics.torque, stamp, w);
        }
      },
      error);
}

}  // namespace gear_sim_ros
