// damping_id_node: live mesh-damping identification (docs/method.md §4) on a stream of
// gear_damping/SignalChunk messages.
//
// Topic names are relative (under the node's namespace; gear_sim_ros/topics.hpp):
// Subscribes:  gear/signal (SignalChunk; remap e.g. gear/signal:=/rig/signal), gear/params
//              (GearParams, latched), unless ~gear_config names a YAML file.
// Publishes:   gear/damping (DampingArray, latched): cumulative estimate since
//              start/reset/restart/reconfigure
//              gear/damping_segment (DampingArray): one per completed segment
//              gear/damping_series (DampingSample): one per completed segment, stamped with the
//              segment's sample time (record start + t_end), for plotting
//              gear/modeled_response (ModeledResponse): per completed segment
//              gear/damping_C (std_msgs/Float64) [1/s], gear/damping_xi (std_msgs/Float64) [-]
//              /diagnostics (global)
// dynamic_reconfigure (cfg/DampingId.cfg): segment_length, window_length, refine, max_condition.
// A change applies at the next segment boundary (segments already completed keep the old
// settings), is logged, and starts a new cumulative estimate; a new segment_length closes the
// segment being filled early (identified as a partial segment, as at a gap) and the new grid
// continues from there.
// Services:    ~reset (std_srvs/Empty), ~get_damping (gear_damping/GetDamping)
// Parameters:  see loadParameters() and docs/live.md.
//
// Live semantics (gear_damping_id/live_identification.hpp): segments are those of the offline
// analysis (boundaries at multiples of ~segment_length from sample 0 or ~t_start, see
// StreamAssembler); each is identified by the streaming IntegralMethod as soon as its samples (plus
// two of stencil context) have arrived, so with ~refine never the numbers equal
// `analyze`/identify() on the same record. With the piecewise model a segment is refined by output
// error on its own (auto: when noisy, as offline; segment problems are independent, so this equals
// the offline refinement up to the solver's convergence tolerance). The shared-damping models
// (constant, load_law) publish the cumulative integral-method estimate, updated per segment; they
// are not refined live. Differences from offline: the default window comes from the first segment's
// mean stiffness (offline: the record's), legacy's mean forcing is an unknown (offline: the record
// mean), and a final partial segment is identified on its own (offline merges a tail shorter than
// half a segment into the previous one, unless ~t_end is finite, where live does the same).
//
// Threading: one thread (ros::spin). Callbacks convert and buffer; identification of a segment
// (~0.1 ms for 1000 samples) runs in the chunk callback, and the subscriber queue (~queue_size
// chunks, default 10000 = 10 s at the simulator's full speed) absorbs any burst meanwhile.
#include <dynamic_reconfigure/server.h>
#include <gear_damping/DampingIdConfig.h>
#include <gear_damping/DampingSample.h>
#include <gear_damping/GearParams.h>
#include <gear_damping/GetDamping.h>
#include <std_msgs/Float64.h>
#include <std_srvs/Empty.h>

#include <deque>
#include <limits>
#include <memory>
#include <optional>

#include "damping_id_params.hpp"
#include "gear_damping_id/live_identification.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_ros/id_conversions.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "gear_sim_ros/topics.hpp"
#include "node_common.hpp"

namespace gd = gear_damping_id;
namespace nodes = gear_damping_nodes;
namespace topics = gear_sim_ros;

namespace {
// cfg/DampingId.cfg's maximum segment_length [s]: stands for +inf (one segment per run).
constexpr double kSegmentLengthMax = 1e9;
}  // namespace

namespace {

using NodeOptions = nodes::DampingIdNodeOptions;

bool loadParameters(const ros::NodeHandle& pnh, NodeOptions* o) {
  nodes::ParamReader p(pnh);
  return nodes::readDampingIdParameters(p, o);
}

class DampingIdNode {
 public:
  DampingIdNode(ros::NodeHandle& nh, ros::NodeHandle& pnh, NodeOptions o)
      : o_(std::move(o)), intake_(o_.stream), updater_(nh, pnh), refine_(o_.refine_budget) {
    damping_pub_ = nh.advertise<gear_damping::DampingArray>(topics::kDampingTopic, 1, true);
    // Outgoing queues of the per-segment topics: 10000 messages (10 s of 1-ms segments, a few
    // MB) per subscriber. roscpp drops a slow subscriber's oldest outgoing messages beyond its
    // queue without telling the publisher: a 30-min soak at 1 MHz with 100 lost 52 of 1.8e6
    // segments to a tester stalled for up to 5 s by other load.
    constexpr uint32_t kSegmentQueue = 10000;
    segment_pub_ =
        nh.advertise<gear_damping::DampingArray>(topics::kDampingSegmentTopic, kSegmentQueue);
    series_pub_ =
        nh.advertise<gear_damping::DampingSample>(topics::kDampingSeriesTopic, kSegmentQueue);
    response_pub_ = nh.advertise<gear_damping::ModeledResponse>(topics::kModeledResponseTopic, 100);
    c_pub_ = nh.advertise<std_msgs::Float64>(topics::kDampingCTopic, kSegmentQueue);
    xi_pub_ = nh.advertise<std_msgs::Float64>(topics::kDampingXiTopic, kSegmentQueue);
    reset_srv_ = pnh.advertiseService("reset", &DampingIdNode::onReset, this);
    get_srv_ = pnh.advertiseService("get_damping", &DampingIdNode::onGet, this);
    updater_.setHardwareID("damping_id");
    updater_.add("stream", this, &DampingIdNode::diagnoseStream);
    updater_.add("identification", this, &DampingIdNode::diagnoseIdentification);
    // Relative names, remappable (e.g. gear/signal:=/rig/chunks).
    signal_sub_ =
        nodes::subscribeChunks(nh, topics::kSignalTopic, o_.intake, &DampingIdNode::onChunk, this);
    timer_ = nh.createWallTimer(ros::WallDuration(0.05), &DampingIdNode::onTimer, this);
    if (o_.gear_config.empty()) {
      params_sub_ = nh.subscribe(topics::kParamsTopic, 1, &DampingIdNode::onParams, this);
    }
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<gear_damping::DampingIdConfig>>(
        reconfigure_mutex_, pnh);
    gear_damping::DampingIdConfig c;
    c.segment_length = std::min(o_.id.segment_length, kSegmentLengthMax);
    c.window_length = o_.id.window_length;
    c.refine = refineName(o_.id.refine);
    c.max_condition = o_.id.max_condition;
    reconfigure_->setConfigDefault(c);  // the node's parameters, not the .cfg defaults
    reconfigure_->updateConfig(c);
    reconfigure_->setCallback(
        [this](gear_damping::DampingIdConfig& cfg, uint32_t) { onReconfigure(cfg); });
  }

  // Gear constants from ~gear_config (if set); false after ROS_FATAL when it cannot be used.
  bool loadGearConfig() {
    if (o_.gear_config.empty()) return true;
    gear_sim::GearModel model;
    if (!nodes::loadGearConfig(o_.gear_config, &model)) return false;
    return setGear(gd::gearConstants(model), model.gears.pinion.teeth, model.gears.gear.teeth);
  }

 private:
  bool setGear(const gd::GearConstants& g, int z1, int z2) {
    if (const gear_sim::Status s = g.check(); !s.ok()) {
      ROS_ERROR_THROTTLE(5.0, "gear parameters ignored: %s", s.message().c_str());
      return false;
    }
    if (gear_ && z1 == o_.ste_options.pinion_teeth && z2 == o_.ste_options.gear_teeth &&
        gear_->equivalent_mass == g.equivalent_mass && gear_->force_factor == g.force_factor &&
        gear_->contact_ratio == g.contact_ratio && gear_->mean_stiffness == g.mean_stiffness) {
      return true;  // unchanged (e.g. the latched message again)
    }
    if (gear_) ROS_WARN("gear parameters changed: estimates reset");
    gear_ = std::make_unique<gd::GearConstants>(g);
    o_.ste_options.pinion_teeth = z1;
    o_.ste_options.gear_teeth = z2;
    if (!makeLive()) return false;
    clearEstimates();
    ROS_INFO("gear constants: Me = %.6g kg, mean stiffness %.6g N/m", g.equivalent_mass,
             g.mean_stiffness);
    while (!early_.empty()) {  // chunks that came before the parameters
      intake_.push(*early_.front());
      early_.pop_front();
    }
    processReady();
    return true;
  }

  void onParams(const gear_damping::GearParams::ConstPtr& msg) {
    gear_sim::GearModel model;
    if (!nodes::gearModelOf(*msg, &model)) return;
    setGear(gd::gearConstants(model), model.gears.pinion.teeth, model.gears.gear.teeth);
  }

  // The live identification for the current options and gear (with the STE when ~ste is set).
  bool makeLive() {
    gd::LiveLimits limits;
    limits.history_segments = static_cast<size_t>(o_.history_segments);
    limits.shared_segments = static_cast<size_t>(o_.shared_segments);
    live_ = std::make_unique<gd::LiveIdentification>(o_.id, *gear_, limits);
    if (o_.ste.empty()) return true;
    const gear_sim::Status s =
        live_->setSte(o_.ste_options, static_cast<size_t>(o_.ste_calibration_segments));
    if (!s.ok()) {
      ROS_ERROR_THROTTLE(5.0, "~ste = '%s' cannot be used with this gear: %s", o_.ste.c_str(),
                         s.message().c_str());
      live_.reset();
      gear_.reset();
      return false;
    }
    ROS_INFO(
        "STE %s: calibrated on at least the first %d segments and a revolution of each shaft "
        "whose orders are modelled, then held",
        o_.ste.c_str(), o_.ste_calibration_segments);
    return true;
  }

  void onChunk(const gear_damping::SignalChunk::ConstPtr& msg) {
    noteRecordStart(*msg);
    noteUnstampedTorque(*msg);
    if (!gear_) {  // keep until the gear parameters arrive
      if (early_.size() >= static_cast<size_t>(o_.intake.queue_size)) {
        early_.pop_front();
        ++dropped_early_;
      }
      early_.push_back(msg);
      ROS_WARN_THROTTLE(5.0, "waiting for gear parameters (%s): chunks buffered",
                        params_sub_ ? params_sub_.getTopic().c_str() : "~gear_config");
      return;
    }
    intake_.push(*msg);
    processReady();
  }

  void onTimer(const ros::WallTimerEvent&) {
    if (gear_ && intake_.idle(o_.intake.end_of_stream_timeout)) {
      intake_.assembler().endOfStream();  // the publisher paused or stopped: flush
      processReady();
      publishCumulative(true);
      updater_.force_update();
    }
    if (dirty_ && (ros::WallTime::now() - last_cumulative_).toSec() >= o_.cumulative_period) {
      publishCumulative(true);
    }
    updater_.update();
  }

  // Identifies every segment the assembler has completed.
  void processReady() {
    gd::StreamSegment s;
    bool any = false;
    while (intake_.assembler().nextSegment(&s)) {
      if (s.epoch != epoch_) {  // the publisher restarted: a new record
        publishCumulative(true);
        epoch_ = s.epoch;
        clearEstimates();
        ROS_WARN("stream restarted (epoch %lu): estimates reset", epoch_);
      }
      identify(s);
      any = true;
      if (pending_) applyReconfigure();  // at a segment boundary
    }
    if (any) publishCumulative(false);
  }

  // --- time series (gear/damping_series) -------------------------------------------------------
  // The record's start on the ROS clock: the stamp of a chunk minus its samples' offset. Taken
  // from the first chunk of the stream, again after a restart (index 0) or a reset.
  // Chunks whose torque was paired without stamps (rig_frontend_node, Float64 torque): their
  // segments carry torque_unstamped. A new record (first_index 0) starts over.
  void noteUnstampedTorque(const gear_damping::SignalChunk& m) {
    if (m.first_index == 0) unstamped_.clear();
    if (m.header.frame_id != gear_sim_ros::kTorqueUnstampedFrame || !(m.sample_rate > 0.0) ||
        m.dte.empty())
      return;
    const double t0 = static_cast<double>(m.first_index) / m.sample_rate;
    const double t1 = static_cast<double>(m.first_index + m.dte.size() - 1) / m.sample_rate;
    unstamped_.add(t0, t1, 1.5 / m.sample_rate);
  }

  void noteRecordStart(const gear_damping::SignalChunk& m) {
    if ((have_record_start_ && m.first_index != 0) || !(m.sample_rate > 0.0)) return;
    const double offset = static_cast<double>(m.first_index) / m.sample_rate;
    const double start = m.header.stamp.toSec() - offset;
    record_start_ = start > 0.0 ? ros::Time(start) : ros::Time(0);
    have_record_start_ = true;
  }

  void publishSample(const gd::SegmentEstimate& est, double fit_percent) {
    gear_damping::DampingSample m;
    m.header.stamp = record_start_ + ros::Duration(std::isfinite(est.t_end) ? est.t_end : 0.0);
    m.segment = gear_damping_ros::toMsg(est, o_.id.formulation);
    m.fit_percent = fit_percent;
    m.refined = est.refined;
    series_pub_.publish(m);
  }

  // --- dynamic_reconfigure ----------------------------------------------------------------------
  static std::string refineName(gd::IdentificationOptions::Refine r) {
    using R = gd::IdentificationOptions::Refine;
    return r == R::Always ? "always" : r == R::Never ? "never" : "auto";
  }

  // Validates a request; an invalid one is logged and the server's values are put back.
  void onReconfigure(gear_damping::DampingIdConfig& c) {
    gd::IdentificationOptions id = pending_ ? pending_->id : o_.id;
    const gd::IdentificationOptions before = id;
    using R = gd::IdentificationOptions::Refine;
    // The .cfg's maximum stands for +inf (dynamic_reconfigure clamps an inf to its maximum).
    id.segment_length = c.segment_length >= kSegmentLengthMax
                            ? std::numeric_limits<double>::infinity()
                            : c.segment_length;
    id.window_length = c.window_length;
    id.max_condition = c.max_condition;
    id.refine = c.refine == "always" ? R::Always : c.refine == "never" ? R::Never : R::Auto;
    if (c.refine != "always" && c.refine != "never" && c.refine != "auto") {
      ROS_ERROR("reconfigure refine = '%s' refused: must be auto, always or never",
                c.refine.c_str());
      id.refine = before.refine;
    }
    gd::StreamOptions stream = o_.stream;
    stream.segment_length = id.segment_length;
    gear_sim::OptionStatus e = id.check();
    if (e.ok()) e = stream.check();
    if (!e.ok()) {
      ROS_ERROR("reconfigure refused: %s", nodes::paramError(e).c_str());
      id = before;
    }
    c.segment_length = std::min(id.segment_length, kSegmentLengthMax);  // reported back
    c.window_length = id.window_length;
    c.max_condition = id.max_condition;
    c.refine = refineName(id.refine);
    if (id.segment_length == o_.id.segment_length && id.window_length == o_.id.window_length &&
        id.max_condition == o_.id.max_condition && id.refine == o_.id.refine) {
      pending_.reset();
      return;
    }
    pending_ = Pending{id};
    ROS_INFO(
        "reconfigure: segment_length %g s, window_length %g s, refine %s, max_condition %g "
        "requested; applies at the next segment boundary",
        id.segment_length, id.window_length, c.refine.c_str(), id.max_condition);
    if (!gear_ || intake_.assembler().bufferedSamples() == 0) applyReconfigure();
  }

  void applyReconfigure() {
    const gd::IdentificationOptions id = pending_->id;
    pending_.reset();
    if (id.segment_length != o_.id.segment_length) {
      // The segment being filled is closed now (a partial segment, identified with the old
      // settings), the new grid starts with the next chunk.
      intake_.assembler().endOfStream();
      gd::StreamSegment s;
      while (gear_ && intake_.assembler().nextSegment(&s)) identify(s);
      o_.stream.segment_length = id.segment_length;
      intake_.assembler() = gd::StreamAssembler(o_.stream);
      epoch_ = intake_.assembler().epoch();
    }
    publishCumulative(true);
    o_.id = id;
    if (gear_) makeLive();
    clearEstimates();
    ROS_INFO(
        "reconfigured: segment_length %g s, window_length %g s, refine %s, max_condition %g "
        "(new cumulative estimate from here)",
        o_.id.segment_length, o_.id.window_length, refineName(o_.id.refine).c_str(),
        o_.id.max_condition);
  }

  void identify(const gd::StreamSegment& s) {
    const ros::WallTime t0 = ros::WallTime::now();
    const double cpu0 = nodes::busySeconds();
    const gd::SignalView v = s.view();
    // Refinement only while it keeps up with real time (see LoadGovernor); else the integral
    // estimate is published at once and the skip is counted and flagged.
    gd::LiveIdentification::SegmentOutput out = live_->add(v, s.begin, s.end, refine_.allow());
    unstamped_.mark(&out.estimate);
    unstamped_.mark(&out.result);
    if (out.refinement_skipped) ++refine_skipped_;
    const gd::SegmentEstimate& est = out.estimate;
    const gd::IdentificationResult& seg = out.result;
    if (!out.warning.empty()) ROS_WARN_THROTTLE(5.0, "%s", out.warning.c_str());
    if (est.identifiable) {
      ++identified_;
    } else if (out.ste_pending) {
      ++pending_ste_;  // buffered for the STE calibration: not a failure
    } else {
      ++not_identifiable_;
      last_reason_ = est.reason;
      ROS_WARN_THROTTLE(2.0, "segment [%.6f, %.6f] s not identifiable: %s", est.t_start, est.t_end,
                        est.reason.c_str());
    }
    if (s.partial) ++partial_;
    latest_ = est;
    dirty_ = true;

    gear_damping::DampingArray one = gear_damping_ros::toMsg(seg);
    one.header.stamp = ros::Time::now();
    segment_pub_.publish(one);
    double fit = gd::kNaN;
    if (est.identifiable && std::isfinite(est.C)) {
      std_msgs::Float64 m;
      m.data = est.C;
      c_pub_.publish(m);
      m.data = est.xi;
      xi_pub_.publish(m);
    }
    if (o_.publish_modeled_response && est.identifiable && std::isfinite(est.C)) {
      gd::ModeledResponse mr;
      if (const gear_sim::Status made = gd::modeledResponse(v, *gear_, seg, &mr); made.ok()) {
        auto msg = gear_damping_ros::toMsg(mr, s.sample_rate,
                                           s.first_index + static_cast<std::uint64_t>(mr.begin));
        msg.header.stamp = ros::Time::now();
        response_pub_.publish(msg);
        last_fit_ = mr.fit_percent;
        fit = mr.fit_percent;
      } else {
        ROS_WARN_THROTTLE(5.0, "modeled response: %s", made.message().c_str());
      }
    }
    publishSample(est, fit);
    const double ms = (ros::WallTime::now() - t0).toSec() * 1e3;
    refine_.record(nodes::busySeconds() - cpu0, out.refinement_skipped);
    last_ms_ = ms;
    max_ms_ = std::max(max_ms_, ms);
    sum_ms_ += ms;
  }

  // /gear/damping: the last ~cumulative_segments segments.
  gear_damping::DampingArray cumulative() const {
    return cumulative(static_cast<size_t>(o_.cumulative_segments));
  }
  // The last `last` segments (at most ~history_segments).
  gear_damping::DampingArray cumulative(size_t last) const {
    gear_damping::DampingArray a;
    if (live_) {
      gd::IdentificationResult r = live_->cumulative(last);
      unstamped_.mark(&r);
      a = gear_damping_ros::toMsg(r);
    }
    a.header.stamp = ros::Time::now();
    return a;
  }

  void publishCumulative(bool force) {
    if (!dirty_) return;
    if (!force && (ros::WallTime::now() - last_cumulative_).toSec() < o_.cumulative_period) return;
    damping_pub_.publish(cumulative());
    last_cumulative_ = ros::WallTime::now();
    dirty_ = false;
  }

  void clearEstimates() {
    if (live_) live_->reset();
    dirty_ = true;
  }

  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
    intake_.reset();
    have_record_start_ = false;
    epoch_ = 0;
    clearEstimates();
    identified_ = not_identifiable_ = partial_ = pending_ste_ = 0;
    unstamped_.clear();
    last_reason_.clear();
    publishCumulative(true);
    ROS_INFO("damping_id_node: reset");
    return true;
  }

  bool onGet(gear_damping::GetDamping::Request&, gear_damping::GetDamping::Response& res) {
    res.damping = cumulative(static_cast<size_t>(o_.history_segments));
    return true;
  }

  void diagnoseStream(diagnostic_updater::DiagnosticStatusWrapper& s) {
    s.summary(diagnostic_msgs::DiagnosticStatus::OK,
              gear_ ? "receiving" : "waiting for gear parameters");
    intake_.report(s);
    s.add("chunks dropped waiting for gear parameters", dropped_early_);
  }

  void diagnoseIdentification(diagnostic_updater::DiagnosticStatusWrapper& s) {
    const unsigned long n = identified_ + not_identifiable_ + pending_ste_;
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, "identifying");
    if (not_identifiable_ != reported_not_identifiable_) {
      s.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                "segments not identifiable: " + last_reason_);
    }
    reported_not_identifiable_ = not_identifiable_;
    if (refine_.degraded()) {
      s.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN,
                     "refinement cannot keep up: refining 1 segment in " +
                         std::to_string(refine_.stride()) + ", integral estimates published");
    }
    s.add("refinement degraded", refine_.degraded() ? 1 : 0);
    s.add("refinement stride [segments]", refine_.stride());
    s.add("refinement load [core fraction]", refine_.load());  // if every segment were refined
    s.add("load without refinement [core fraction]", refine_.baseLoad());
    s.add("refinement budget [core fraction]", refine_.budget());
    s.add("segments with refinement skipped", refine_skipped_);
    s.add("segments since start/reset/restart", live_ ? live_->segmentsAdded() : 0);
    s.add("formulation", gd::toString(o_.id.formulation));
    s.add("model", gd::toString(o_.id.model));
    s.add("segments identified", identified_);
    s.add("segments not identifiable", not_identifiable_);
    s.add("segments pending (STE calibration)", pending_ste_);
    s.add("last not identifiable reason", last_reason_);
    s.add("partial segments (cut by gap/restart/end)", partial_);
    s.add("segments in current estimate", live_ ? live_->segmentCount() : 0);
    s.add("processing time last segment [ms]", last_ms_);
    s.add("processing time mean [ms]", n ? sum_ms_ / static_cast<double>(n) : 0.0);
    s.add("processing time max [ms]", max_ms_);
    s.add("last fit [%]", last_fit_);
    if (latest_.identifiable) {
      s.add("latest C [1/s]", latest_.C);
      s.add("latest xi", latest_.xi);
    }
  }

  NodeOptions o_;
  nodes::ChunkIntake intake_;
  diagnostic_updater::Updater updater_;
  ros::Publisher damping_pub_, segment_pub_, series_pub_, response_pub_, c_pub_, xi_pub_;
  ros::Time record_start_;
  bool have_record_start_ = false;
  struct Pending {
    gd::IdentificationOptions id;
  };
  std::optional<Pending> pending_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<gear_damping::DampingIdConfig>> reconfigure_;
  ros::Subscriber signal_sub_, params_sub_;
  ros::ServiceServer reset_srv_, get_srv_;
  ros::WallTimer timer_;
  std::unique_ptr<gd::GearConstants> gear_;
  std::unique_ptr<gd::LiveIdentification> live_;
  std::deque<gear_damping::SignalChunk::ConstPtr> early_;
  nodes::LoadGovernor refine_;
  unsigned long refine_skipped_ = 0;
  gd::SegmentEstimate latest_;
  unsigned long epoch_ = 0, identified_ = 0, not_identifiable_ = 0, partial_ = 0;
  unsigned long pending_ste_ = 0;       // segments buffered for the STE calibration
  gd::UnstampedTorqueSpans unstamped_;  // record spans with an unstamped torque
  unsigned long reported_not_identifiable_ = 0, dropped_early_ = 0;
  std::string last_reason_;
  double last_fit_ = gd::kNaN;
  double last_ms_ = 0, max_ms_ = 0, sum_ms_ = 0;
  bool dirty_ = false;
  ros::WallTime last_cumulative_;
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "damping_id_node");
  ros::NodeHandle nh, pnh("~");
  NodeOptions options;
  if (!loadParameters(pnh, &options)) return 1;
  DampingIdNode node(nh, pnh, std::move(options));
  if (!node.loadGearConfig()) return 1;
  ros::spin();
  return 0;
}
