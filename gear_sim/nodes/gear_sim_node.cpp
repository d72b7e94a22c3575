// gear_sim_node: simulates the gear pair configured in its private namespace (the YAML of
// `simulate --config`, loaded with `rosparam load FILE ~`) and publishes the record as
// gear_damping/SignalChunk messages on /gear/signal and the gear parameters, latched, on
// /gear/params.
//
// Private parameters (besides the YAML sections pinion, gear, mesh, speed, load, damping,
// simulation):
//   ~chunk_size [samples]   samples per chunk (default 1000)
//   ~pace       [string]    "realtime": one chunk per chunk_size/sample_rate of wall time;
//                           "fast": as fast as possible once a subscriber is connected (default)
//   ~repeat     [bool]      false: publish the record once, then stay up (latched params);
//                           true: publish it forever, restarting at index 0 each time (default
//                           false)
//   ~wait_for_subscribers [s]  in "fast" mode, how long to wait for ~min_subscribers
//                           /gear/signal subscribers before publishing anyway (default 10)
//   ~min_subscribers        in "fast" mode, subscribers to wait for (default 1; the pipeline
//                           sets 2, so the wavelet node does not miss a burst that the first
//                           connected subscriber triggered)
// Stamps: header.stamp is ros::Time::now() at publication (sim time when /use_sim_time is set);
// the sample time itself is first_index / sample_rate.
#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include <string>

#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim_ros/conversions.hpp"

namespace {

struct NodeOptions {
  gear_sim::SimConfig sim;
  int chunk_size = 1000;
  std::string pace = "fast";
  bool repeat = false;
  double wait_for_subscribers = 10.0;
  int min_subscribers = 1;
};

// Loads and validates every parameter; false (after ROS_FATAL naming the parameter) if invalid.
bool loadParameters(ros::NodeHandle& pnh, NodeOptions* o) {
  XmlRpc::XmlRpcValue tree;
  YAML::Node root(YAML::NodeType::Map);
  for (const char* section : {"pinion", "gear", "mesh", "speed", "load", "damping", "simulation"}) {
    if (pnh.getParam(section, tree)) root[section] = gear_sim_ros::toYaml(tree);
  }
  for (const char* required : {"pinion", "gear", "mesh"}) {
    if (!root[required]) {
      ROS_FATAL(
          "~%s: missing (load the gear configuration, e.g. <rosparam command=\"load\" "
          "file=\"$(find "
          "gear_damping)/config/table1.yaml\"/> inside the node)",
          required);
      return false;
    }
  }
  std::string error;
  if (!gear_sim::loadSimConfig(root, &o->sim, &error)) {
    ROS_FATAL("~%s", error.c_str());
    return false;
  }
  pnh.param("chunk_size", o->chunk_size, o->chunk_size);
  pnh.param("pace", o->pace, o->pace);
  pnh.param("repeat", o->repeat, o->repeat);
  pnh.param("wait_for_subscribers", o->wait_for_subscribers, o->wait_for_subscribers);
  pnh.param("min_subscribers", o->min_subscribers, o->min_subscribers);
  if (o->min_subscribers < 1) {
    ROS_FATAL("~min_subscribers = %d: must be >= 1", o->min_subscribers);
    return false;
  }
  if (o->chunk_size < 1) {
    ROS_FATAL("~chunk_size = %d: must be >= 1 [samples]", o->chunk_size);
    return false;
  }
  if (o->pace != "fast" && o->pace != "realtime") {
    ROS_FATAL("~pace = '%s': must be 'fast' or 'realtime'", o->pace.c_str());
    return false;
  }
  ROS_INFO("gear_sim_node: %.6g s at %.6g Hz, chunk_size %d, pace %s, repeat %s",
           o->sim.simulation.duration, o->sim.simulation.sample_rate, o->chunk_size,
           o->pace.c_str(), o->repeat ? "true" : "false");
  return true;
}

class GearSimNode {
 public:
  GearSimNode(ros::NodeHandle& nh, NodeOptions o) : o_(std::move(o)), updater_(nh) {
    // Queue sized for a whole second of chunks at the default settings, so a subscriber that
    // keeps up on average never loses one; drops, if any, show as index gaps downstream.
    signal_pub_ = nh.advertise<gear_damping::SignalChunk>("/gear/signal", 1000);
    params_pub_ = nh.advertise<gear_damping::GearParams>("/gear/params", 1, /*latch=*/true);
    updater_.setHardwareID("gear_sim");
    updater_.add("simulator", this, &GearSimNode::diagnose);
  }

  bool simulate() {
    std::string error;
    if (!gear_sim::simulate(o_.sim, &table_, &error)) {
      ROS_FATAL("simulation failed: %s", error.c_str());
      return false;
    }
    return true;
  }

  void run() {
    auto params = gear_sim_ros::toMsg(o_.sim.gearModel());
    params.header.stamp = ros::Time::now();
    params_pub_.publish(params);
    const double fs = o_.sim.simulation.sample_rate;
    if (o_.pace == "fast") {
      const ros::WallTime deadline =
          ros::WallTime::now() + ros::WallDuration(o_.wait_for_subscribers);
      while (ros::ok() &&
             signal_pub_.getNumSubscribers() < static_cast<uint32_t>(o_.min_subscribers) &&
             ros::WallTime::now() < deadline) {
        ros::WallDuration(0.01).sleep();
        updater_.update();
      }
    }
    ros::WallRate rate(fs / o_.chunk_size);
    gear_damping::SignalChunk chunk;
    do {
      for (Eigen::Index b = 0; b < table_.size() && ros::ok(); b += o_.chunk_size) {
        const Eigen::Index n = std::min<Eigen::Index>(o_.chunk_size, table_.size() - b);
        gear_sim_ros::toChunk(table_, b, n, fs, static_cast<std::uint64_t>(b), &chunk);
        chunk.header.stamp = ros::Time::now();
        chunk.header.seq = static_cast<std::uint32_t>(chunks_);
        signal_pub_.publish(chunk);
        ++chunks_;
        samples_ += static_cast<unsigned long>(n);
        updater_.update();
        if (o_.pace == "realtime") rate.sleep();
      }
      ++records_;
    } while (o_.repeat && ros::ok());
    finished_ = true;
    ROS_INFO("gear_sim_node: published %lu chunks (%lu samples)", chunks_, samples_);
    while (ros::ok()) {  // stay up: the parameters stay latched, diagnostics keep coming
      updater_.update();
      ros::WallDuration(0.1).sleep();
      ros::spinOnce();
    }
  }

 private:
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& s) {
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, finished_ ? "record published" : "publishing");
    s.add("chunks published", chunks_);
    s.add("samples published", samples_);
    s.add("records published", records_);
    s.add("subscribers", signal_pub_.getNumSubscribers());
  }

  NodeOptions o_;
  gear_sim::SignalTable table_;
  ros::Publisher signal_pub_, params_pub_;
  diagnostic_updater::Updater updater_;
  unsigned long chunks_ = 0, samples_ = 0, records_ = 0;
  bool finished_ = false;
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "gear_sim_node");
  ros::NodeHandle nh, pnh("~");
  NodeOptions options;
  if (!loadParameters(pnh, &options)) return 1;
  GearSimNode node(nh, std::move(options));
  if (!node.simulate()) return 1;
  node.run();
  return 0;
}
