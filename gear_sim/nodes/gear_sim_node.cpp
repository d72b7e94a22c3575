// gear_sim_node: simulates the gear pair configured in its private namespace (the YAML of
// `simulate --config`, loaded with `rosparam load FILE ~`) and publishes the record as
// gear_damping/SignalChunk messages on gear/signal and the gear parameters, latched, on
// gear/params (relative names: under the node's namespace, gear_sim_ros/topics.hpp).
//
// Private parameters (besides the YAML sections pinion, gear, mesh, speed, load, damping,
// simulation):
//   ~chunk_size [samples]   samples per chunk (default 1000)
//   ~pace       [string]    "realtime": at wall-clock speed (a chunk is published when the
//                           wall time since the start reaches the time of its last sample);
//                           "fast": as fast as possible (default). Both first wait for
//                           ~min_subscribers gear/signal subscribers (at most
//                           ~wait_for_subscribers).
//   ~repeat     [bool]      false: publish the record once, then stay up (latched params);
//                           true: publish it forever, restarting at index 0 each time (default
//                           false)
//   ~wait_for_subscribers [s]  how long to wait for ~min_subscribers gear/signal subscribers
//                           before publishing anyway (default 10)
//   ~min_subscribers        subscribers to wait for (default 1; the pipeline sets 2, or 3 with
//                           record:=true, so no subscriber misses the start of the stream)
//   ~start_delay [s]        wall time to wait after that, before the stream (default 0; the
//                           pipeline sets 2 with record:=true, so the recorder is connected to
//                           the nodes' outputs too)
// Parameters are read strictly: a wrong type or an unknown name (a typo) stops the node
// (ROS_FATAL naming it, exit 1) instead of falling back to a default.
// Stamps: header.stamp is ros::Time::now() at publication (sim time when /use_sim_time is set);
// the sample time itself is first_index / sample_rate.
#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include <string>

#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "gear_sim_ros/topics.hpp"
#include "node_common.hpp"  // ParamReader (gear_damping_id/nodes)

namespace {

struct NodeOptions {
  gear_sim::SimConfig sim;
  int chunk_size = 1000;
  std::string pace = "fast";
  bool repeat = false;
  double wait_for_subscribers = 10.0;
  double start_delay = 0.0;
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
  // The loader's message starts with the key ("load.amplitud: unknown key ..."), a parameter
  // under the private namespace here.
  if (const gear_sim::Status s = gear_sim::loadSimConfig(root, &o->sim); !s.ok()) {
    ROS_FATAL("~%s", s.message().c_str());
    return false;
  }
  gear_damping_nodes::ParamReader p(pnh);
  for (const char* section : {"pinion", "gear", "mesh", "speed", "load", "damping", "simulation"}) {
    p.allow(section);  // checked key by key by loadSimConfig
  }
  p.allow("diagnostic_period");  // read by diagnostic_updater
  if (!p.get("chunk_size", &o->chunk_size, "samples") || !p.get("pace", &o->pace) ||
      !p.get("repeat", &o->repeat) ||
      !p.getDouble("wait_for_subscribers", &o->wait_for_subscribers, "s") ||
      !p.get("min_subscribers", &o->min_subscribers) ||
      !p.getDouble("start_delay", &o->start_delay, "s") || !p.rejectUnknown()) {
    return false;
  }
  if (!(o->start_delay >= 0.0)) {
    ROS_FATAL("~start_delay = %g: must be >= 0 [s]", o->start_delay);
    return false;
  }
  if (!(o->wait_for_subscribers >= 0.0)) {
    ROS_FATAL("~wait_for_subscribers = %g: must be >= 0 [s]", o->wait_for_subscribers);
    return false;
  }
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
    signal_pub_ = nh.advertise<gear_damping::SignalChunk>(gear_sim_ros::kSignalTopic, 1000);
    params_pub_ =
        nh.advertise<gear_damping::GearParams>(gear_sim_ros::kParamsTopic, 1, /*latch=*/true);
    updater_.setHardwareID("gear_sim");
    updater_.add("simulator", this, &GearSimNode::diagnose);
  }

  bool simulate() {
    if (const gear_sim::Status s = gear_sim::simulate(o_.sim, &table_); !s.ok()) {
      ROS_FATAL("simulation failed: %s", s.message().c_str());
      return false;
    }
    return true;
  }

  void run() {
    auto params = gear_sim_ros::toMsg(o_.sim.gearModel());
    params.header.stamp = ros::Time::now();
    params_pub_.publish(params);
    const double fs = o_.sim.simulation.sample_rate;
    // Both paces wait for the subscribers (a realtime stream published before anyone listens
    // is lost as surely as a fast one).
    const ros::WallTime deadline =
        ros::WallTime::now() + ros::WallDuration(o_.wait_for_subscribers);
    while (ros::ok() &&
           signal_pub_.getNumSubscribers() < static_cast<uint32_t>(o_.min_subscribers) &&
           ros::WallTime::now() < deadline) {
      ros::WallDuration(0.01).sleep();
      updater_.update();
    }
    if (signal_pub_.getNumSubscribers() < static_cast<uint32_t>(o_.min_subscribers)) {
      ROS_WARN("gear_sim_node: %u of %d subscribers after %g s: publishing anyway",
               signal_pub_.getNumSubscribers(), o_.min_subscribers, o_.wait_for_subscribers);
    }
    const ros::WallTime go = ros::WallTime::now() + ros::WallDuration(o_.start_delay);
    while (ros::ok() && ros::WallTime::now() < go) {
      ros::WallDuration(0.01).sleep();
      updater_.update();
    }
    gear_damping::SignalChunk chunk;
    do {
      // Realtime: chunk [b, b+n) goes out when the wall time since the record's start reaches
      // the time of its last sample, (b+n)/fs.
      const ros::WallTime start = ros::WallTime::now();
      for (Eigen::Index b = 0; b < table_.size() && ros::ok(); b += o_.chunk_size) {
        const Eigen::Index n = std::min<Eigen::Index>(o_.chunk_size, table_.size() - b);
        if (o_.pace == "realtime") {
          ros::WallTime::sleepUntil(start + ros::WallDuration(static_cast<double>(b + n) / fs));
        }
        gear_sim_ros::toChunk(table_, b, n, fs, static_cast<std::uint64_t>(b), &chunk);
        chunk.header.stamp = ros::Time::now();
        chunk.header.seq = static_cast<std::uint32_t>(chunks_);
        signal_pub_.publish(chunk);
        ++chunks_;
        samples_ += static_cast<unsigned long>(n);
        updater_.update();
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
