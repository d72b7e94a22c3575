// Shared by the rostest testers: the simulator configuration as gear_sim_node read it, and a
// crafted chunk stream (the default case, published chunk by chunk as a rig would).
#pragma once

#include <ros/package.h>
#include <ros/ros.h>

#include <string>

#include "../unit/support/status_support.hpp"
#include "gear_damping/GearParams.h"
#include "gear_damping/SignalChunk.h"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "gear_sim_ros/topics.hpp"
#include "run_command.hpp"

namespace gear_test {

/// Keeps the latest message of a topic; `have` once one arrived. Not movable (the subscription
/// writes into this object).
template <class M>
struct LatestMessage {
  M msg;
  bool have = false;
  ros::Subscriber sub;
  LatestMessage(ros::NodeHandle& nh, const std::string& topic)
      : sub(nh.subscribe<M>(topic, 10, [this](const typename M::ConstPtr& m) {
          msg = *m;
          have = true;
        })) {}
  LatestMessage(const LatestMessage&) = delete;
  LatestMessage& operator=(const LatestMessage&) = delete;
};

/// The simulator configuration the way gear_sim_node reads it (from its private namespace `ns`).
inline bool simConfigFromParams(const std::string& ns, gear_sim::SimConfig* cfg, std::string* e) {
  YAML::Node root(YAML::NodeType::Map);
  XmlRpc::XmlRpcValue tree;
  for (const char* section : {"pinion", "gear", "mesh", "speed", "load", "damping", "simulation"}) {
    if (ros::param::get(ns + "/" + section, tree)) root[section] = gear_sim_ros::toYaml(tree);
  }
  return gear_test::ok(gear_sim::loadSimConfig(root, cfg), e);
}

/// Publishes chunks of the default case (config/table1.yaml) as a rig would, with the latched
/// gear parameters; chunk(k) is samples [1000 k, 1000 (k+1)), to be altered before publish().
class CraftedStream {
 public:
  CraftedStream() {
    std::string e;
    ok_ = gear_test::ok(gear_sim::loadSimConfigFile(
                            ros::package::getPath("gear_damping") + "/config/table1.yaml", &cfg_),
                        &e) &&
          gear_test::ok(gear_sim::simulate(cfg_, &table_), &e);
    error_ = e;
    signal_ = nh_.advertise<gear_damping::SignalChunk>(gear_sim_ros::kSignalTopic, 1000);
    params_ = nh_.advertise<gear_damping::GearParams>(gear_sim_ros::kParamsTopic, 1, true);
    params_.publish(gear_sim_ros::toMsg(cfg_.gearModel()));
  }
  bool ok() const { return ok_; }
  const std::string& error() const { return error_; }
  const gear_sim::SignalTable& table() const { return table_; }
  const gear_sim::SimConfig& config() const { return cfg_; }
  bool waitForSubscribers(int n) {
    return waitFor([&] { return signal_.getNumSubscribers() >= static_cast<uint32_t>(n); }, 30);
  }
  gear_damping::SignalChunk chunk(int k) const {
    gear_damping::SignalChunk c;
    gear_sim_ros::toChunk(table_, 1000 * k, 1000, cfg_.simulation.sample_rate,
                          static_cast<std::uint64_t>(1000 * k), &c);
    c.header.stamp = ros::Time::now();
    return c;
  }
  void publish(const gear_damping::SignalChunk& c) { signal_.publish(c); }

 private:
  ros::NodeHandle nh_;
  ros::Publisher signal_, params_;
  gear_sim::SimConfig cfg_;
  gear_sim::SignalTable table_;
  bool ok_ = false;
  std::string error_;
};

}  // namespace gear_test
