#include "gear_sim_ros/rig_bag_io.hpp"

#include <geometry_msgs/WrenchStamped.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Float64.h>

#include <algorithm>
#include <map>
#include <vector>

#include "gear_sim/message_text.hpp"
#include "gear_sim_ros/bag_format.hpp"
#include "gear_sim_ros/bag_io.hpp"

namespace gear_sim_ros {
using gear_sim::Status;

Status writeRigBag(const std::string& path, const gear_sim::SignalTable& t,
                   const gear_sim::GearModel* params, const RigBagTopics& topics) {
  const Eigen::Index n = t.size();
  if (n == 0 || t.theta1.size() != n || t.theta2.size() != n || t.torque.size() != n) {
    return Status::invalidInput(path + ": a rig bag needs time, theta1, theta2 and torque");
  }
  if (!(t.time[0] >= 0.0) || !(t.time[n - 1] <= kMaxBagTime - 1.0)) {
    return Status::invalidInput(path + ": sample times outside [0, " +
                                std::to_string(kMaxBagTime - 1.0) + "] s");
  }
  return writeBagStaged(path, params, topics.params, [&](rosbag::Bag& bag, const ros::Time& base) {
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
  });
}

namespace {

constexpr const char* kJointStateType = "sensor_msgs/JointState";

// Index of `name` in the JointState's names, -1 when absent.
int jointIndex(const sensor_msgs::JointState& js, const std::string& name) {
  const auto it = std::find(js.name.begin(), js.name.end(), name);
  return it == js.name.end() ? -1 : static_cast<int>(it - js.name.begin());
}

double wrenchAxis(const geometry_msgs::WrenchStamped& w, char axis) {
  return axis == 'x' ? w.wrench.torque.x : axis == 'y' ? w.wrench.torque.y : w.wrench.torque.z;
}

// InvalidInput when message `m` claims arrays longer than its bytes (checkMessageLayout).
Status layoutFits(const std::string& path, const rosbag::MessageInstance& m) {
  const Status bad = checkMessageLayout(m);
  if (bad.ok()) return {};
  return Status::invalidInput(path + ": " + gear_sim::quoteForMessage(m.getTopic()) + ": corrupt " +
                              gear_sim::quoteForMessage(m.getDataType()) + " (" + bad.message() +
                              ")");
}

}  // namespace

bool isRigBag(const std::string& path, const RigBagTopics& topics) {
  // rosbag trusts the lengths in the file: a corrupt bag is not opened here (the signal-bag
  // reader then refuses it with the reason).
  BagStructure structure;
  if (!checkBagStructure(path, &structure).ok()) return false;
  // rosbag's connections are connection records the walk saw (with the same field parsing): a
  // bag none of whose connection records is the joints topic's JointState is not a rig bag, and
  // is not opened a second time only to find that out.
  const auto joints = [&](const BagStructure::Connection& c) {
    return c.topic == topics.joints && c.type == kJointStateType;
  };
  if (std::none_of(structure.connections.begin(), structure.connections.end(), joints))
    return false;
  try {
    rosbag::Bag bag;
    bag.open(path, rosbag::bagmode::Read);
    rosbag::View all(bag);
    for (const rosbag::ConnectionInfo* c : all.getConnections())
      if (c->topic == topics.joints && c->datatype == kJointStateType) return true;
  } catch (const std::exception&) {
  }
  return false;
}

// ResourceLimit when `view` (the messages of `topic`) holds more than `max_messages` (View::size
// is not const).
Status checkMessageCount(const std::string& path, const std::string& topic, rosbag::View& view,
                         size_t max_messages) {
  if (view.size() <= max_messages) return {};
  return Status::resourceLimit(path + ": " + std::to_string(view.size()) + " messages on " +
                                   gear_sim::quoteForMessage(topic) + ", more than the " +
                                   std::to_string(max_messages) +
                                   " a rig bag may hold (it is read whole; --max-in-memory)",
                               "max_in_memory");
}

Status readRigBag(const std::string& path, const RigBagTopics& topics, gear_sim::SignalTable* rig,
                  size_t max_messages) {
  if (Status s = checkBagStructure(path); !s.ok()) return s;
  std::vector<ros::Time> stamps;
  std::vector<double> th1, th2, tq;
  try {
    rosbag::Bag bag;
    bag.open(path, rosbag::bagmode::Read);
    std::map<ros::Time, double> torque;  // by stamp
    rosbag::View tv(bag, rosbag::TopicQuery(topics.torque));
    rosbag::View jv(bag, rosbag::TopicQuery(topics.joints));
    if (Status s = checkMessageCount(path, topics.torque, tv, max_messages); !s.ok()) return s;
    if (Status s = checkMessageCount(path, topics.joints, jv, max_messages); !s.ok()) return s;
    for (const rosbag::MessageInstance& m : tv) {
      if (Status s = layoutFits(path, m); !s.ok()) return s;
      if (const auto w = m.instantiate<geometry_msgs::WrenchStamped>()) {
        torque[w->header.stamp] = wrenchAxis(*w, topics.axis);
      } else if (const auto f = m.instantiate<std_msgs::Float64>()) {
        torque[m.getTime()] = f->data;  // no header: the bag's receipt time
      }
    }
    for (const rosbag::MessageInstance& m : jv) {
      if (Status s = layoutFits(path, m); !s.ok()) return s;
      const auto js = m.instantiate<sensor_msgs::JointState>();
      if (!js) continue;
      const int i1 = jointIndex(*js, topics.joint1), i2 = jointIndex(*js, topics.joint2);
      if (i1 < 0 || i2 < 0 || static_cast<size_t>(std::max(i1, i2)) >= js->position.size()) {
        return Status::invalidInput(path + ": a JointState message lacks the position of " +
                                    topics.joint1 + " or " + topics.joint2);
      }
      const ros::Time stamp = js->header.stamp.isZero() ? m.getTime() : js->header.stamp;
      const auto t = torque.find(stamp);
      if (t == torque.end()) {
        return Status::invalidInput(path + ": no torque on " + topics.torque + " with the stamp " +
                                    std::to_string(stamp.toSec()) + " s of a JointState message");
      }
      if (!stamps.empty() && !(stamp > stamps.back())) {
        return Status::invalidInput(path + ": the JointState stamps do not increase");
      }
      stamps.push_back(stamp);
      th1.push_back(js->position[static_cast<size_t>(i1)]);
      th2.push_back(js->position[static_cast<size_t>(i2)]);
      tq.push_back(t->second);
    }
  } catch (const std::exception& e) {
    return Status::invalidInput(path + ": cannot read the rig bag (" + e.what() + ")");
  }
  if (stamps.empty()) {
    return Status::invalidInput(path + ": no JointState message on " + topics.joints);
  }
  const Eigen::Index n = static_cast<Eigen::Index>(stamps.size());
  *rig = gear_sim::SignalTable{};
  rig->time.resize(n);
  rig->theta1.resize(n);
  rig->theta2.resize(n);
  rig->torque.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const size_t k = static_cast<size_t>(i);
    rig->time[i] = (stamps[k] - stamps.front()).toSec();
    rig->theta1[i] = th1[k];
    rig->theta2[i] = th2[k];
    rig->torque[i] = tq[k];
  }
  return {};
}

}  // namespace gear_sim_ros
