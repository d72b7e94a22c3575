// rig_frontend_node (docs/rig.md): the encoder front end live. Subscribes to the shaft encoders
// as sensor_msgs/JointState (two joints by name) and the pinion torque as
// geometry_msgs/WrenchStamped (one axis, time-synchronised with message_filters) or
// std_msgs/Float64 (latest value held), and publishes gear_damping/SignalChunk (dte, torque,
// stiffness, mesh_state, mesh_phase) on gear/signal for damping_id_node and wavelet_node, plus the
// gear parameters latched on gear/params. All numbers come from gear_damping_id::EncoderFrontEnd.
#include <geometry_msgs/WrenchStamped.h>
#include <message_filters/subscriber.h>
#include <message_filters/sync_policies/approximate_time.h>
#include <message_filters/synchronizer.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <std_msgs/Float64.h>

#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "gear_damping/GearParams.h"
#include "gear_damping/SignalChunk.h"
#include "gear_damping_id/encoder_frontend.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "gear_sim_ros/topics.hpp"
#include "param_error.hpp"

namespace gd = gear_damping_id;

namespace {

using SyncPolicy = message_filters::sync_policies::ApproximateTime<sensor_msgs::JointState,
                                                                   geometry_msgs::WrenchStamped>;

class RigFrontEndNode {
 public:
  bool init(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
    std::string gear_config, torque_type, axis;
    pnh.param<std::string>("gear_config", gear_config, "");
    pnh.param<std::string>("joint1", joint1_, "pinion_joint");
    pnh.param<std::string>("joint2", joint2_, "gear_joint");
    pnh.param<std::string>("torque_type", torque_type, "wrench");
    pnh.param<std::string>("torque_axis", axis, "z");
    pnh.param("sample_rate", rate_, 0.0);
    int chunk = 1000, calibration = 10000, queue = 1000, counts1 = 0, counts2 = 0;
    pnh.param("chunk_size", chunk, chunk);
    pnh.param("calibration_samples", calibration, calibration);
    pnh.param("sync_queue", queue, queue);
    pnh.param("counts_per_rev1", counts1, 0);
    pnh.param("counts_per_rev2", counts2, 0);
    pnh.param("end_of_stream_timeout", eos_timeout_, 1.0);
    double mesh_offset = std::numeric_limits<double>::quiet_NaN(), dte_offset = mesh_offset;
    if (pnh.hasParam("mesh_offset")) pnh.getParam("mesh_offset", mesh_offset);
    if (pnh.hasParam("dte_offset")) pnh.getParam("dte_offset", dte_offset);
    // The offsets estimated with the STE modelled (docs/rig.md): an `analyze --ste` spec.
    std::string model_ste;
    pnh.param<std::string>("model_ste", model_ste, "");
    const gear_sim::Status loaded =
        gear_config.empty()
            ? gear_sim::Status::invalidArgument("required (a gear YAML, config/table1.yaml layout)")
            : gear_sim::loadGearModelFile(gear_config, &model_);
    if (!loaded.ok()) {
      ROS_FATAL("~gear_config: %s", loaded.message().c_str());
      return false;
    }
    if (!(rate_ > 0.0 && std::isfinite(rate_))) {
      ROS_FATAL("~sample_rate = %g: required, the encoder sampling rate [Hz] (> 0)", rate_);
      return false;
    }
    if (chunk < 1 || calibration < 16 || queue < 1 || counts1 < 0 || counts2 < 0 ||
        !(eos_timeout_ > 0.0)) {
      ROS_FATAL(
          "~chunk_size/sync_queue >= 1, calibration_samples >= 16, counts_per_rev >= 0, "
          "end_of_stream_timeout > 0 required");
      return false;
    }
    if (axis != "x" && axis != "y" && axis != "z") {
      ROS_FATAL("~torque_axis = '%s': one of x, y, z", axis.c_str());
      return false;
    }
    axis_ = axis[0];
    chunk_ = static_cast<size_t>(chunk);
    opts_.calibration_samples = calibration;
    opts_.counts_per_rev1 = counts1;
    opts_.counts_per_rev2 = counts2;
    opts_.mesh_offset = mesh_offset;
    opts_.dte_offset = dte_offset;
    if (!model_ste.empty()) {
      if (const gear_sim::Status s = gd::parseSteSpec(model_ste, &opts_.ste); !s.ok()) {
        ROS_FATAL("~model_ste = '%s': %s", model_ste.c_str(), s.message().c_str());
        return false;
      }
      opts_.model_ste = true;
      opts_.ste.pinion_teeth = model_.gears.pinion.teeth;
      opts_.ste.gear_teeth = model_.gears.gear.teeth;
    }
    if (const gear_sim::OptionStatus s = opts_.check(); !s.ok()) {
      ROS_FATAL("%s", gear_damping_nodes::paramError(s).c_str());
      return false;
    }
    reset();
    signal_pub_ = nh.advertise<gear_damping::SignalChunk>(gear_sim_ros::kSignalTopic, 100);
    params_pub_ = nh.advertise<gear_damping::GearParams>(gear_sim_ros::kParamsTopic, 1, true);
    params_pub_.publish(gear_sim_ros::toMsg(model_));
    if (torque_type == "wrench") {
      joints_sub_.subscribe(nh, "rig/joint_states", queue);
      wrench_sub_.subscribe(nh, "rig/torque", queue);
      sync_ = std::make_unique<message_filters::Synchronizer<SyncPolicy>>(
          SyncPolicy(static_cast<uint32_t>(queue)), joints_sub_, wrench_sub_);
      sync_->registerCallback(&RigFrontEndNode::onSynced, this);
    } else if (torque_type == "float64") {
      // Latest torque held: no Nagle delay on either topic, so the pairing lags little.
      const ros::TransportHints hints = ros::TransportHints().tcpNoDelay();
      plain_joints_ =
          nh.subscribe("rig/joint_states", queue, &RigFrontEndNode::onJoints, this, hints);
      float_sub_ = nh.subscribe("rig/torque", queue, &RigFrontEndNode::onFloat, this, hints);
      ROS_WARN("%s", kFloat64Warning);
      unstamped_ = true;
      // Once a minute while joint states arrive (a wall timer: no check per message).
      warn_timer_ =
          nh.createWallTimer(ros::WallDuration(60.0), &RigFrontEndNode::onWarnTimer, this);
    } else {
      ROS_FATAL("~torque_type = '%s': wrench or float64", torque_type.c_str());
      return false;
    }
    timer_ = nh.createWallTimer(ros::WallDuration(0.1), &RigFrontEndNode::onTimer, this);
    ROS_INFO(
        "rig_frontend: joints %s, %s at %g Hz, torque %s (%c), calibration %d samples, offsets "
        "estimated %s",
        joint1_.c_str(), joint2_.c_str(), rate_, torque_type.c_str(), axis_, calibration,
        model_ste.empty() ? "without the STE" : ("with the STE " + model_ste).c_str());
    return true;
  }

 private:
  void reset() {
    fe_ = std::make_unique<gd::EncoderFrontEnd>(model_, opts_);
    started_ = false;
    finished_ = false;
    refused_ = false;
    pending_.clear();
  }

  void onSynced(const sensor_msgs::JointState::ConstPtr& js,
                const geometry_msgs::WrenchStamped::ConstPtr& w) {
    const auto& t = w->wrench.torque;
    add(*js, axis_ == 'x' ? t.x : axis_ == 'y' ? t.y : t.z);
  }
  // Float64: the latest torque is held; joint states before the first torque are skipped (a
  // NaN torque would make the front end refuse the record).
  void onJoints(const sensor_msgs::JointState::ConstPtr& js) {
    if (std::isnan(torque_)) {
      ROS_WARN_THROTTLE(5.0, "rig_frontend: no torque yet on rig/torque: joint states skipped");
      ++skipped_;
      return;
    }
    joints_since_warning_ = true;
    add(*js, torque_);
  }
  void onWarnTimer(const ros::WallTimerEvent&) {
    if (!joints_since_warning_) return;
    joints_since_warning_ = false;
    ROS_WARN("%s", kFloat64Warning);
  }
  void onFloat(const std_msgs::Float64::ConstPtr& f) { torque_ = f->data; }
  // Float64 carries no stamp: measured on a 20-bit rig bag relayed as Float64, live C was off the
  // stamp-synchronised chain by up to 10 % (7 SE) in the worst of 10 segments (docs/rig.md).
  static constexpr const char* kFloat64Warning =
      "rig_frontend: torque_type float64: std_msgs/Float64 has no time stamp, each joint state "
      "is paired with the latest torque received (one to several samples late, jittering). "
      "With a torque that varies within a mesh period C can be biased (measured up to 10 %); "
      "use geometry_msgs/WrenchStamped (torque_type wrench) for such torques. The chunks are "
      "marked and damping_id_node flags their segments torque_unstamped";

  void add(const sensor_msgs::JointState& js, double torque) {
    last_wall_ = ros::WallTime::now();
    if (finished_) reset();  // a new record after the end of the last one
    if (refused_) return;
    int i1 = -1, i2 = -1;
    for (size_t k = 0; k < js.name.size() && k < js.position.size(); ++k) {
      if (js.name[k] == joint1_) i1 = static_cast<int>(k);
      if (js.name[k] == joint2_) i2 = static_cast<int>(k);
    }
    if (i1 < 0 || i2 < 0) {
      ROS_WARN_THROTTLE(5.0, "rig_frontend: JointState without %s and %s (names: %zu): skipped",
                        joint1_.c_str(), joint2_.c_str(), js.name.size());
      ++skipped_;
      return;
    }
    const double stamp = js.header.stamp.toSec();
    if (!started_) {
      started_ = true;
      t0_ = stamp;
      next_ = 0;
    }
    const double pos = (stamp - t0_) * rate_;
    if (!(pos >= -0.5)) {
      ++skipped_;
      return;
    }
    const auto index = static_cast<std::uint64_t>(std::llround(pos));
    if (index < next_) {
      ++skipped_;  // duplicate or late: the front end needs increasing indices
      return;
    }
    if (index != next_ && !pending_.empty()) flush();
    if (pending_.empty()) pending_first_ = index;
    pending_.push_back(
        {js.position[static_cast<size_t>(i1)], js.position[static_cast<size_t>(i2)], torque});
    next_ = index + 1;
    if (pending_.size() >= chunk_) flush();
  }

  void flush() {
    if (pending_.empty() || refused_) return;
    std::vector<double> a(pending_.size()), b(a.size()), c(a.size());
    for (size_t k = 0; k < pending_.size(); ++k)
      a[k] = pending_[k][0], b[k] = pending_[k][1], c[k] = pending_[k][2];
    pending_.clear();
    if (const gear_sim::Status s =
            fe_->push(rate_, pending_first_, a.data(), b.data(), c.data(), a.size());
        !s.ok()) {
      ROS_ERROR("rig_frontend: %s", s.message().c_str());
      refused_ = true;
      return;
    }
    publishReady();
  }

  void publishReady() {
    gear_sim::SignalTable t;
    std::uint64_t first = 0;
    while (fe_->pop(&t, &first)) {
      if (!reported_) {
        const auto& r = fe_->report();
        ROS_INFO(
            "rig_frontend: mesh offset %.6f cycles (%s), DTE offset %.4g m (%s), ratio %.6f, "
            "quantisation noise %.3g m",
            r.mesh_offset, r.mesh_offset_estimated ? "estimated" : "given", r.dte_offset,
            r.dte_offset_estimated ? "estimated" : "given", r.ratio_measured,
            r.quantisation_noise_std);
        reported_ = true;
      }
      for (Eigen::Index b = 0; b < t.size(); b += static_cast<Eigen::Index>(chunk_)) {
        const Eigen::Index n =
            std::min<Eigen::Index>(static_cast<Eigen::Index>(chunk_), t.size() - b);
        gear_damping::SignalChunk msg;
        gear_sim_ros::toChunk(t, b, n, rate_, first + static_cast<std::uint64_t>(b), &msg);
        msg.header.stamp = ros::Time::now();
        // The segments built from these samples are flagged by damping_id_node.
        if (unstamped_) msg.header.frame_id = gear_sim_ros::kTorqueUnstampedFrame;
        signal_pub_.publish(msg);
      }
    }
  }

  void onTimer(const ros::WallTimerEvent&) {
    if (!started_ || finished_ || refused_) return;
    if ((ros::WallTime::now() - last_wall_).toSec() < eos_timeout_) return;
    flush();
    if (const gear_sim::Status s = refused_ ? gear_sim::Status() : fe_->finish(); !s.ok()) {
      ROS_ERROR("rig_frontend: %s", s.message().c_str());
      refused_ = true;
      return;
    }
    publishReady();
    finished_ = true;
    reported_ = false;
    ROS_INFO("rig_frontend: end of the record (%zu messages skipped)", skipped_);
  }

  gear_sim::GearModel model_;
  gd::EncoderFrontEndOptions opts_;
  std::unique_ptr<gd::EncoderFrontEnd> fe_;
  std::string joint1_, joint2_;
  char axis_ = 'z';
  double rate_ = 0.0, eos_timeout_ = 1.0, t0_ = 0.0,
         torque_ = std::numeric_limits<double>::quiet_NaN();
  size_t chunk_ = 1000, skipped_ = 0;
  bool started_ = false, finished_ = false, refused_ = false, reported_ = false;
  bool unstamped_ = false;             // Float64 torque: chunks marked kTorqueUnstampedFrame
  bool joints_since_warning_ = false;  // joint states since the last Float64 warning
  std::uint64_t next_ = 0, pending_first_ = 0;
  std::vector<std::array<double, 3>> pending_;
  ros::WallTime last_wall_;
  ros::Publisher signal_pub_, params_pub_;
  ros::Subscriber plain_joints_, float_sub_;
  message_filters::Subscriber<sensor_msgs::JointState> joints_sub_;
  message_filters::Subscriber<geometry_msgs::WrenchStamped> wrench_sub_;
  std::unique_ptr<message_filters::Synchronizer<SyncPolicy>> sync_;
  ros::WallTimer timer_, warn_timer_;
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "rig_frontend");
  ros::NodeHandle nh, pnh("~");
  RigFrontEndNode node;
  if (!node.init(nh, pnh)) return 1;
  ros::spin();
  return 0;
}
