// wavelet_node: Morlet-wavelet damping validation (docs/method.md §5) on a stream of
// gear_damping/SignalChunk messages.
//
// Topic names are relative (under the node's namespace; gear_sim_ros/topics.hpp):
// Subscribes:  gear/signal (SignalChunk; remappable, e.g. gear/signal:=/rig/signal),
//              gear/damping (DampingArray, for the integral-method xi shown beside each mode)
// Publishes:   gear/wavelet_modes (WaveletModes): one per analysed window; /diagnostics (global)
// dynamic_reconfigure (cfg/Wavelet.cfg): f_min, f_max (the band) and window. A change applies
// from the next window (the window being filled is analysed with the old settings) and is
// logged; a new window length closes the window being filled early (analysed if long enough).
// Services:    ~analyze (std_srvs/Trigger): analyse what is buffered now (closes the window)
//              ~reset (std_srvs/Empty)
// Windows: ~window [s] > 0 (default 0.1): consecutive windows of that length from sample 0 (the
// stream assembler's segments, so gaps, duplicates, restarts are handled as in damping_id_node:
// a gap, a restart, the end of the stream (no chunk for ~end_of_stream_timeout [s] of wall time)
// or ~analyze closes the window early, and it is analysed if long enough). Only the current
// window is buffered (memory bounded by ~window). Windows shorter than ~min_window_samples are
// skipped and counted. While the analysis costs more than ~analysis_budget of one core (per
// second of wall time, see LoadGovernor), only every k-th window is analysed (k = ceil(load /
// budget)), the others
// are counted as skipped and the status is WARN.
// Gear context (docs/live.md "Wavelet node"): when ~order_frequencies is empty, each window's
// order frequencies come from the chunks' mesh_phase over that window (its mean mesh frequency,
// with the shaft orders once the tooth counts are known), so that forced lines, side lines at
// f0 +- k f_mesh and decays shorter than two mesh periods are flagged as in `analyze --wavelet`;
// with the gear parameters (~gear_config, a YAML file, or the latched gear/params) also the
// parametric growth rate of the mesh stiffness per 1/32 of the window (parametric_resonance).
// A window without mesh_phase has none of these checks; one whose mesh_phase is not usable
// (not finite, decreasing, not advancing, a corrupt jump) is analysed without them, counted and
// named in /diagnostics.
// Threading: one thread; the analysis (only the rows the fits need, no full scalogram) runs in
// the callback that completes a window, the subscriber queue absorbs chunks meanwhile.
#include <dynamic_reconfigure/server.h>
#include <gear_damping/DampingArray.h>
#include <gear_damping/WaveletConfig.h>
#include <gear_damping/WaveletModes.h>
#include <std_srvs/Empty.h>
#include <std_srvs/Trigger.h>

#include <map>
#include <memory>
#include <optional>

#include "gear_damping_id/result_io.hpp"
#include "gear_damping_id/wavelet.hpp"
#include "gear_damping_id/wavelet_context.hpp"
#include "gear_damping_ros/id_conversions.hpp"
#include "gear_sim_ros/topics.hpp"
#include "node_common.hpp"
#include "wavelet_params.hpp"

namespace gd = gear_damping_id;
namespace nodes = gear_damping_nodes;

namespace {

using NodeOptions = nodes::WaveletNodeOptions;
using nodes::kStreamParams;

bool loadParameters(const ros::NodeHandle& pnh, NodeOptions* o) {
  nodes::ParamReader p(pnh);
  return nodes::readWaveletParameters(p, o);
}

class WaveletNode {
 public:
  WaveletNode(ros::NodeHandle& nh, ros::NodeHandle& pnh, NodeOptions o)
      : o_(std::move(o)), intake_(o_.stream), updater_(nh, pnh), load_(o_.analysis_budget) {
    modes_pub_ =
        nh.advertise<gear_damping::WaveletModes>(gear_sim_ros::kWaveletModesTopic, 10, true);
    analyze_srv_ = pnh.advertiseService("analyze", &WaveletNode::onAnalyze, this);
    reset_srv_ = pnh.advertiseService("reset", &WaveletNode::onReset, this);
    updater_.setHardwareID("wavelet");
    updater_.add("stream", this, &WaveletNode::diagnoseStream);
    updater_.add("wavelet", this, &WaveletNode::diagnoseWavelet);
    signal_sub_ = nodes::subscribeChunks(nh, gear_sim_ros::kSignalTopic, o_.intake,
                                         &WaveletNode::onChunk, this);
    damping_sub_ = nh.subscribe(gear_sim_ros::kDampingTopic, 1, &WaveletNode::onDamping, this);
    if (o_.gear_config.empty())
      params_sub_ = nh.subscribe(gear_sim_ros::kParamsTopic, 1, &WaveletNode::onParams, this);
    timer_ = nh.createWallTimer(ros::WallDuration(0.05), &WaveletNode::onTimer, this);
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<gear_damping::WaveletConfig>>(
        reconfigure_mutex_, pnh);
    gear_damping::WaveletConfig c;
    c.f_min = o_.wavelet.f_min;
    c.f_max = o_.wavelet.f_max;
    c.window = o_.window;
    reconfigure_->setConfigDefault(c);  // the node's parameters, not the .cfg defaults
    reconfigure_->updateConfig(c);
    reconfigure_->setCallback(
        [this](gear_damping::WaveletConfig& cfg, uint32_t) { onReconfigure(cfg); });
  }

  // The gear model from ~gear_config (if set); false after ROS_FATAL when it cannot be used.
  bool loadGearConfig() {
    if (o_.gear_config.empty()) return true;
    gear_sim::GearModel model;
    if (!nodes::loadGearConfig(o_.gear_config, &model)) return false;
    gear_ = model;
    return true;
  }

 private:
  void onParams(const gear_damping::GearParams::ConstPtr& msg) {
    gear_sim::GearModel model;
    if (nodes::gearModelOf(*msg, &model)) gear_ = model;
  }

  void onChunk(const gear_damping::SignalChunk::ConstPtr& msg) {
    intake_.push(*msg);
    processReady();
  }

  void onDamping(const gear_damping::DampingArray::ConstPtr& msg) {
    double sum = 0.0;
    int n = 0;
    for (const auto& s : msg->segments) {
      if (s.identifiable && std::isfinite(s.xi)) sum += s.xi, ++n;
    }
    xi_integral_ = n > 0 ? sum / n : gd::kNaN;
  }

  void onTimer(const ros::WallTimerEvent&) {
    if (intake_.idle(o_.intake.end_of_stream_timeout)) {
      intake_.assembler().endOfStream();
      processReady();
      updater_.force_update();
    }
    updater_.update();
  }

  bool onAnalyze(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    const unsigned long before = windows_analysed_;
    intake_.assembler().endOfStream();
    processReady();
    res.success = windows_analysed_ > before;
    res.message =
        res.success
            ? "analysed " + std::to_string(windows_analysed_ - before) + " window(s), last with " +
                  std::to_string(last_modes_) + " mode(s)"
            : "nothing analysed: " +
                  (last_problem_.empty() ? std::string("no samples buffered") : last_problem_);
    return true;
  }

  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
    intake_.reset();
    ROS_INFO("wavelet_node: reset");
    return true;
  }

  void processReady() {
    gd::StreamSegment s;
    while (intake_.assembler().nextSegment(&s)) {
      analyse(s);
      if (pending_) applyReconfigure();  // at a window boundary
    }
  }

  // dynamic_reconfigure: validates a request (an invalid one is logged and the current values
  // are put back), then applies it at the next window boundary (at once when nothing is
  // buffered).
  void onReconfigure(gear_damping::WaveletConfig& c) {
    const Pending before = pending_ ? *pending_ : Pending{o_.wavelet, o_.window};
    Pending p = before;
    p.wavelet.f_min = c.f_min;
    p.wavelet.f_max = c.f_max;
    p.window = c.window;
    gd::StreamOptions stream = o_.stream;
    stream.segment_length = p.window;
    gear_sim::OptionStatus e = p.wavelet.check();
    if (e.ok()) e = stream.check();
    if (!e.ok()) {
      ROS_ERROR("reconfigure refused: %s", nodes::paramError(e, kStreamParams).c_str());
      p = before;
    }
    c.f_min = p.wavelet.f_min;  // what the server reports back
    c.f_max = p.wavelet.f_max;
    c.window = p.window;
    if (p.wavelet.f_min == o_.wavelet.f_min && p.wavelet.f_max == o_.wavelet.f_max &&
        p.window == o_.window) {
      pending_.reset();
      return;
    }
    pending_ = p;
    ROS_INFO(
        "reconfigure: f_min %g Hz, f_max %g Hz, window %g s requested; applies from the "
        "next window",
        p.wavelet.f_min, p.wavelet.f_max, p.window);
    if (intake_.assembler().bufferedSamples() == 0) applyReconfigure();
  }

  void applyReconfigure() {
    const Pending p = *pending_;
    pending_.reset();
    if (p.window != o_.window) {
      // The window being filled is closed now (analysed with the old settings if long enough);
      // the new windows start with the next chunk.
      intake_.assembler().endOfStream();
      gd::StreamSegment s;
      while (intake_.assembler().nextSegment(&s)) analyse(s);
      o_.window = p.window;
      o_.stream.segment_length = p.window;
      intake_.assembler() = gd::StreamAssembler(o_.stream);
    }
    o_.wavelet = p.wavelet;
    ROS_INFO("reconfigured: f_min %g Hz, f_max %g Hz, window %g s", o_.wavelet.f_min,
             o_.wavelet.f_max, o_.window);
  }

  void analyse(const gd::StreamSegment& s) {
    const long n = static_cast<long>(s.end - s.begin);
    const double t_start = static_cast<double>(s.first_index + s.begin) / s.sample_rate;
    if (n < o_.min_window_samples) {
      ++windows_skipped_;
      last_problem_ = "window at " + std::to_string(t_start) + " s has " + std::to_string(n) +
                      " samples (< ~min_window_samples)";
      ROS_WARN_THROTTLE(2.0, "%s", last_problem_.c_str());
      return;
    }
    if (!load_.allow()) {
      ++windows_shed_;
      load_.record(0.0, true);
      return;
    }
    const ros::WallTime t0 = ros::WallTime::now();
    const double cpu0 = nodes::busySeconds();
    // The analyzer keeps its FFTW plans and buffers from window to window (same results as
    // validateWavelet; 1e6 samples: ~0.14 s instead of ~0.65 s per window).
    const gd::WaveletOptions options = withGearContext(s, n);
    gd::WaveletResult r;
    const gear_sim::Status st =
        analyzer_.analyze(s.dte.data() + s.begin, n, s.sample_rate, options, &r);
    last_ms_ = (ros::WallTime::now() - t0).toSec() * 1e3;
    load_.record(nodes::busySeconds() - cpu0, false);
    if (!st.ok()) {
      ++windows_failed_;
      last_problem_ = st.message();
      ROS_WARN_THROTTLE(2.0, "wavelet analysis of the window at %.6f s failed: %s", t_start,
                        last_problem_.c_str());
      return;
    }
    gd::attachIntegralDampingRatio(&r, xi_integral_);
    gd::shiftWaveletTimes(&r, t_start);  // onto the record's time axis
    auto msg =
        gear_damping_ros::toMsg(r, t_start, t_start + static_cast<double>(n) / s.sample_rate);
    msg.header.stamp = ros::Time::now();
    modes_pub_.publish(msg);
    ++windows_analysed_;
    last_modes_ = r.modes.size();
    if (!r.modes.empty()) {
      last_frequency_ = r.modes.front().frequency_hz;
      last_xi_ = r.modes.front().damping_ratio;
    }
  }

  // The window's options with the gear's context from its mesh_phase (order frequencies, growth
  // rates; gd::applyGearContext), or as they are without a usable mesh_phase.
  gd::WaveletOptions withGearContext(const gd::StreamSegment& s, long n) {
    gd::WaveletOptions options = o_.wavelet;
    last_mesh_hz_ = gd::kNaN;
    if (s.mesh_phase.empty()) return options;
    const std::string problem =
        gd::applyGearContext(s.mesh_phase.data() + s.begin, static_cast<size_t>(n), s.sample_rate,
                             gear_ ? &*gear_ : nullptr, &options, &last_mesh_hz_);
    if (!problem.empty()) {
      ++windows_phase_unusable_;
      last_phase_problem_ = problem;
      ROS_WARN_THROTTLE(2.0, "mesh_phase of the window not usable (%s): analysed %s",
                        problem.c_str(), contextLoss());
    }
    return options;
  }

  // What a window without a usable mesh_phase is analysed without.
  const char* contextLoss() const {
    return o_.wavelet.order_frequencies.empty()
               ? "without the gear's order frequencies"
               : "with ~order_frequencies only (no parametric growth rates)";
  }

  void diagnoseStream(diagnostic_updater::DiagnosticStatusWrapper& s) {
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, "receiving");
    intake_.report(s);
  }

  void diagnoseWavelet(diagnostic_updater::DiagnosticStatusWrapper& s) {
    s.summary(diagnostic_msgs::DiagnosticStatus::OK, "analysing");
    if (windows_failed_ + windows_skipped_ != reported_problems_) {
      s.summary(diagnostic_msgs::DiagnosticStatus::WARN, "window not analysable: " + last_problem_);
    }
    reported_problems_ = windows_failed_ + windows_skipped_;
    if (load_.degraded()) {
      s.mergeSummary(
          diagnostic_msgs::DiagnosticStatus::WARN,
          "analysis cannot keep up: analysing 1 window in " + std::to_string(load_.stride()));
    }
    if (windows_phase_unusable_ != reported_phase_unusable_) {
      s.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN,
                     std::string("mesh_phase not usable: window analysed ") + contextLoss());
    }
    reported_phase_unusable_ = windows_phase_unusable_;
    s.add("analysis load [core fraction]", load_.load());
    s.add("analysis stride [windows]", load_.stride());
    s.add("analysis budget [core fraction]", load_.budget());
    s.add("windows skipped (load)", windows_shed_);
    s.add("windows analysed", windows_analysed_);
    s.add("windows failed", windows_failed_);
    s.add("windows skipped (too short)", windows_skipped_);
    s.add("last problem", last_problem_);
    s.add("processing time last window [ms]", last_ms_);
    s.add("modes in last window", last_modes_);
    s.add("lowest mode frequency [Hz]", last_frequency_);
    s.add("lowest mode damping ratio", last_xi_);
    s.add("mesh frequency last window [Hz]", last_mesh_hz_);
    s.add("gear parameters",
          gear_ ? (o_.gear_config.empty() ? "gear/params" : o_.gear_config) : std::string("none"));
    s.add("windows with unusable mesh_phase", windows_phase_unusable_);
    s.add("last mesh_phase problem", last_phase_problem_);
  }

  NodeOptions o_;
  nodes::ChunkIntake intake_;
  diagnostic_updater::Updater updater_;
  ros::Publisher modes_pub_;
  struct Pending {
    gd::WaveletOptions wavelet;
    double window;
  };
  std::optional<Pending> pending_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<gear_damping::WaveletConfig>> reconfigure_;
  ros::Subscriber signal_sub_, damping_sub_, params_sub_;
  std::optional<gear_sim::GearModel> gear_;  // ~gear_config or gear/params
  double last_mesh_hz_ = gd::kNaN;
  unsigned long windows_phase_unusable_ = 0, reported_phase_unusable_ = 0;
  std::string last_phase_problem_;
  ros::ServiceServer analyze_srv_, reset_srv_;
  ros::WallTimer timer_;
  double xi_integral_ = gd::kNaN, last_ms_ = 0, last_frequency_ = gd::kNaN, last_xi_ = gd::kNaN;
  unsigned long windows_analysed_ = 0, windows_failed_ = 0, windows_skipped_ = 0;
  unsigned long reported_problems_ = 0, windows_shed_ = 0;
  nodes::LoadGovernor load_;
  gd::WaveletAnalyzer analyzer_;  // plans and buffers reused across windows
  size_t last_modes_ = 0;
  std::string last_problem_;
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "wavelet_node");
  ros::NodeHandle nh, pnh("~");
  NodeOptions options;
  if (!loadParameters(pnh, &options)) return 1;
  WaveletNode node(nh, pnh, std::move(options));
  if (!node.loadGearConfig()) return 1;
  ros::spin();
  return 0;
}
