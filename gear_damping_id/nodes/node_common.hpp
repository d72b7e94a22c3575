// Shared ROS glue of damping_id_node and wavelet_node: private-parameter reading with type and
// typo checks, and the chunk intake (message -> StreamAssembler, throttled warnings, input-rate
// and event diagnostics). Header-only; the sequencing logic itself is the ROS-free
// gear_damping_id::StreamAssembler.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <malloc.h>
#include <ros/ros.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "gear_damping/GearParams.h"
#include "gear_damping/SignalChunk.h"
#include "gear_damping_id/stream_assembler.hpp"
#include "gear_damping_ros/live_conversions.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/option_status.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "load_governor.hpp"
#include "param_error.hpp"

namespace gear_damping_nodes {

/// Where a node's private parameters come from: the parameter server (RosParams), or a YAML
/// file read the way `rosparam load` types it (the shipped-configuration test). The typed reads
/// follow roscpp's getParam: a number accepts an integer, an integer, a boolean and a string
/// accept only their own type.
class ParamSource {
 public:
  virtual ~ParamSource() = default;
  virtual bool has(const std::string& name) const = 0;
  virtual bool get(const std::string& name, double* v) const = 0;
  virtual bool get(const std::string& name, int* v) const = 0;
  virtual bool get(const std::string& name, bool* v) const = 0;
  virtual bool get(const std::string& name, std::string* v) const = 0;
  virtual bool get(const std::string& name, std::vector<double>* v) const = 0;
  /// Top-level names present (first path component under the private namespace).
  virtual std::vector<std::string> names() const = 0;
};

/// The private namespace `pnh` on the parameter server.
class RosParams : public ParamSource {
 public:
  explicit RosParams(const ros::NodeHandle& pnh) : pnh_(pnh) {}
  bool has(const std::string& name) const override { return pnh_.hasParam(name); }
  bool get(const std::string& name, double* v) const override { return pnh_.getParam(name, *v); }
  bool get(const std::string& name, int* v) const override { return pnh_.getParam(name, *v); }
  bool get(const std::string& name, bool* v) const override { return pnh_.getParam(name, *v); }
  bool get(const std::string& name, std::string* v) const override {
    return pnh_.getParam(name, *v);
  }
  bool get(const std::string& name, std::vector<double>* v) const override {
    return pnh_.getParam(name, *v);
  }
  std::vector<std::string> names() const override {
    std::vector<std::string> all, out;
    ros::param::getParamNames(all);
    const std::string prefix = pnh_.getNamespace() + "/";
    for (const auto& n : all) {
      if (n.compare(0, prefix.size(), prefix) != 0) continue;
      const std::string key = n.substr(prefix.size());
      out.push_back(key.substr(0, key.find('/')));
    }
    return out;
  }

 private:
  ros::NodeHandle pnh_;
};

/// Reads optional private parameters: absent -> the default (logged once in the summary);
/// present with the wrong type -> ROS_FATAL naming it (never a silent fallback). Parameter names
/// read are remembered, so unknown names (typos) in the private namespace can be rejected.
class ParamReader {
 public:
  explicit ParamReader(const ros::NodeHandle& pnh) : src_(std::make_shared<RosParams>(pnh)) {}
  explicit ParamReader(std::shared_ptr<const ParamSource> src) : src_(std::move(src)) {}

  template <class T>
  bool get(const std::string& name, T* value, const char* unit = "") {
    known_.insert(name);
    if (src_->has(name) && !src_->get(name, value)) {
      ROS_FATAL("~%s: wrong type (expected %s)", name.c_str(), typeName(*value));
      return false;
    }
    summary_ << " " << name << "=" << str(*value) << (unit[0] ? " " : "") << unit << ";";
    return true;
  }
  /// Doubles also accept ".inf"/"-.inf" strings (roslaunch <param> passes them as strings).
  bool getDouble(const std::string& name, double* value, const char* unit = "") {
    known_.insert(name);
    std::string s;
    if (src_->get(name, &s)) {
      if (s == ".inf" || s == "inf")
        *value = std::numeric_limits<double>::infinity();
      else if (s == "-.inf" || s == "-inf")
        *value = -std::numeric_limits<double>::infinity();
      else {
        ROS_FATAL("~%s = '%s': wrong type (expected a number [%s])", name.c_str(), s.c_str(), unit);
        return false;
      }
      summary_ << " " << name << "=" << *value << " " << unit << ";";
      return true;
    }
    return get(name, value, unit);
  }
  void allow(const std::string& name) { known_.insert(name); }
  /// ROS_FATAL naming the first private parameter that no get()/allow() asked for.
  bool rejectUnknown() const {
    for (const auto& top : src_->names()) {
      if (known_.count(top) == 0) {
        ROS_FATAL("~%s: unknown parameter (a typo would otherwise fall back to a default)",
                  top.c_str());
        return false;
      }
    }
    return true;
  }
  std::string summary() const { return summary_.str(); }

 private:
  static const char* typeName(double) { return "a number"; }
  static const char* typeName(int) { return "an integer"; }
  static const char* typeName(bool) { return "a boolean"; }
  static const char* typeName(const std::string&) { return "a string"; }
  static const char* typeName(const std::vector<double>&) { return "a list of numbers"; }
  template <class T>
  static std::string str(const T& v) {
    std::ostringstream o;
    o << v;
    return o.str();
  }
  static std::string str(const std::vector<double>& v) {
    std::ostringstream o;
    o << "[";
    for (size_t i = 0; i < v.size(); ++i) o << (i ? ", " : "") << v[i];
    o << "]";
    return o.str();
  }
  std::shared_ptr<const ParamSource> src_;
  std::set<std::string> known_;
  std::ostringstream summary_;
};

/// Parameters of the chunk intake shared by both nodes.
struct IntakeOptions {
  int reorder_chunks = 8;  // [chunks] held while waiting for a missing chunk
  // [chunks] subscriber queue: 5 s of a 2 MHz stream in 1000-sample chunks (10 s at 1 MHz).
  // roscpp drops the oldest message when it is full; the drop shows as a gap in the indices.
  int queue_size = 10000;
  bool tcp_nodelay = true;             // TCPROS transport hint (no Nagle batching)
  double end_of_stream_timeout = 0.5;  // [s] wall time without chunks that ends the stream
  double max_jump = 0.5;               // [s] implausible index jump (StreamOptions::max_jump)
  double magnitude_factor = 1e6;       // absurd magnitude vs the running scale (0: off)
  double max_abs_dte = 1.0;            // [m] absurd |dte|
};

/// Reads and validates ~reorder_chunks, ~queue_size, ~tcp_nodelay, ~end_of_stream_timeout,
/// ~max_jump, ~magnitude_factor, ~max_abs_dte (ROS_FATAL + false when invalid).
inline bool readIntakeParams(ParamReader& p, IntakeOptions* o) {
  if (!p.get("reorder_chunks", &o->reorder_chunks, "chunks") ||
      !p.get("queue_size", &o->queue_size, "chunks") || !p.get("tcp_nodelay", &o->tcp_nodelay) ||
      !p.getDouble("end_of_stream_timeout", &o->end_of_stream_timeout, "s") ||
      !p.getDouble("max_jump", &o->max_jump, "s") ||
      !p.getDouble("magnitude_factor", &o->magnitude_factor) ||
      !p.getDouble("max_abs_dte", &o->max_abs_dte, "m")) {
    return false;
  }
  if (o->queue_size < 1) {
    ROS_FATAL("~queue_size = %d: must be >= 1 [chunks]", o->queue_size);
    return false;
  }
  if (!(o->end_of_stream_timeout > 0.0)) {
    ROS_FATAL("~end_of_stream_timeout = %g: must be > 0 [s]", o->end_of_stream_timeout);
    return false;
  }
  return true;  // reorder_chunks, max_jump, magnitude_factor: StreamOptions::validate
}

/// Copies the intake's sequencing parameters into the assembler's options.
inline void applyIntake(const IntakeOptions& i, gear_damping_id::StreamOptions* o) {
  o->reorder_chunks = i.reorder_chunks;
  o->max_jump = i.max_jump;
  o->magnitude_factor = i.magnitude_factor;
  o->max_abs_dte = i.max_abs_dte;
}

/// Subscribes to the chunk topic with the intake's queue size and transport hints.
template <class T>
ros::Subscriber subscribeChunks(ros::NodeHandle& nh, const std::string& topic,
                                const IntakeOptions& o,
                                void (T::*callback)(const gear_damping::SignalChunk::ConstPtr&),
                                T* obj) {
  ros::TransportHints hints;
  if (o.tcp_nodelay) hints = hints.tcpNoDelay();
  return nh.subscribe(topic, static_cast<uint32_t>(o.queue_size), callback, obj, hints);
}

/// The gear model of the YAML file ~gear_config = `path` (config/table1.yaml layout) into *out;
/// false after ROS_FATAL naming the parameter and the reason.
inline bool loadGearConfig(const std::string& path, gear_sim::GearModel* out) {
  gear_sim::SimConfig cfg;
  if (const gear_sim::Status s = gear_sim::loadSimConfigFile(path, &cfg); !s.ok()) {
    ROS_FATAL("~gear_config = '%s': %s", path.c_str(), s.message().c_str());
    return false;
  }
  *out = cfg.gearModel();
  return true;
}

/// The gear model of a GearParams message (gear/params) into *out; false after a throttled
/// ROS_ERROR when the message is not a valid gear pair (the message is then ignored).
inline bool gearModelOf(const gear_damping::GearParams& msg, gear_sim::GearModel* out) {
  if (const gear_sim::Status s = gear_sim_ros::fromMsg(msg, out); !s.ok()) {
    ROS_ERROR_THROTTLE(5.0, "/gear/params ignored: %s", s.message().c_str());
    return false;
  }
  return true;
}

/// Resident set size of this process [MiB] (/proc/self/statm), NaN if unreadable.
inline double residentMiB() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (f == nullptr) return std::numeric_limits<double>::quiet_NaN();
  unsigned long size = 0, resident = 0;
  const int n = std::fscanf(f, "%lu %lu", &size, &resident);
  std::fclose(f);
  if (n != 2) return std::numeric_limits<double>::quiet_NaN();
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / 1048576.0;
}

/// Chunk intake: converts messages, feeds the assembler, warns (throttled) about rejections,
/// gaps and restarts, measures the input rate, and reports everything to diagnostics.
/// Times are wall-clock (ros::WallTime): input rate and idle detection concern the transport,
/// not the recorded signal, and must work whether or not /use_sim_time is set.
class ChunkIntake {
 public:
  explicit ChunkIntake(const gear_damping_id::StreamOptions& o) : assembler_(o) {}

  gear_damping_id::StreamAssembler& assembler() { return assembler_; }

  void push(const gear_damping::SignalChunk& msg) {
    last_chunk_ = ros::WallTime::now();
    ++messages_;
    gear_damping_id::ChunkData c;
    if (const gear_sim::Status s = gear_damping_ros::toChunkData(msg, &state_, &c); !s.ok()) {
      c = gear_damping_id::ChunkData();  // empty: the assembler counts it as malformed
      c.first_index = msg.first_index;
      c.sample_rate = msg.sample_rate;
      assembler_.push(c);
      ROS_WARN_THROTTLE(2.0, "chunk at index %lu rejected: malformed (%s)",
                        static_cast<unsigned long>(msg.first_index), s.message().c_str());
      return;
    }
    std::string why;  // the assembler's account of a classified chunk (ChunkStatus)
    const auto status = assembler_.push(c, &why);
    switch (status) {
      case gear_damping_id::ChunkStatus::Suspect:
        last_jump_ = why;
        ROS_WARN_THROTTLE(2.0, "%s", why.c_str());
        break;
      case gear_damping_id::ChunkStatus::RejectedNonFinite:
      case gear_damping_id::ChunkStatus::RejectedValue:
      case gear_damping_id::ChunkStatus::RejectedRate:
      case gear_damping_id::ChunkStatus::RejectedMalformed:
        ROS_WARN_THROTTLE(2.0, "%s: %s", toString(status), why.c_str());
        break;
      case gear_damping_id::ChunkStatus::Duplicate:
      case gear_damping_id::ChunkStatus::Late:
        ROS_WARN_THROTTLE(2.0, "chunk at index %lu ignored: %s",
                          static_cast<unsigned long>(msg.first_index), toString(status));
        break;
      default:
        if (!why.empty()) ROS_WARN_THROTTLE(2.0, "%s", why.c_str());  // gap or restart
    }
  }

  /// True once no chunk arrived for `timeout` [s] while samples are buffered or held.
  bool idle(double timeout) const {
    return messages_ > 0 && (ros::WallTime::now() - last_chunk_).toSec() >= timeout &&
           (assembler_.bufferedSamples() > 0 || assembler_.heldChunks() > 0 ||
            assembler_.hasSuspect());
  }

  /// Input statistics, sequencing events and losses; the status from LossMonitor (WARN after a
  /// loss, ERROR on sustained loss, persistent WARN after an implausible index jump).
  void report(diagnostic_updater::DiagnosticStatusWrapper& s) {
    const auto& k = assembler_.counters();
    const ros::WallTime now = ros::WallTime::now();
    const double span = last_report_.isZero() ? 0.0 : (now - last_report_).toSec();
    const double rate =
        span > 0.0 ? static_cast<double>(k.samples_accepted - last_samples_) / span : 0.0;
    const double chunk_rate =
        span > 0.0 ? static_cast<double>(k.chunks_received - last_chunks_) / span : 0.0;
    last_report_ = now;
    last_samples_ = k.samples_accepted;
    last_chunks_ = k.chunks_received;
    s.add("input rate [samples/s]", rate);
    s.add("input rate [chunks/s]", chunk_rate);
    s.add("chunks received", k.chunks_received);
    s.add("samples received", k.samples_accepted);
    s.add("samples in chunks received", k.samples_received);
    s.add("sample rate [Hz]", assembler_.sampleRate());
    s.add("samples lost", k.samplesLost());
    s.add("samples lost: never arrived (queue overflow, transport)", k.samplesNeverArrived());
    s.add("samples lost: rejected", k.samples_missing_rejected + k.samples_suspect_dropped);
    s.add("samples lost: late", k.samples_late);
    s.add("samples rejected", k.samples_rejected);
    s.add("samples duplicate", k.samples_duplicate);
    s.add("gaps", k.gaps);
    s.add("samples missing", k.samples_missing);
    s.add("duplicate chunks", k.duplicates);
    s.add("late chunks", k.late);
    s.add("overlapping chunks", k.overlaps);
    s.add("out-of-order chunks", k.out_of_order);
    s.add("rejected chunks (NaN/Inf)", k.rejected_nonfinite);
    s.add("rejected chunks (implausible value)", k.rejected_value);
    s.add("rejected chunks (sample rate)", k.rejected_rate);
    s.add("rejected chunks (malformed)", k.rejected_malformed);
    s.add("rejected chunks (index jump glitch)", k.rejected_jump);
    s.add("dropped chunks", k.rejected_nonfinite + k.rejected_value + k.rejected_rate +
                                k.rejected_malformed + k.rejected_jump);
    s.add("implausible index jumps", k.jumps);
    s.add("new records at a jump", k.jump_records);
    s.add("restarts", k.restarts);
    s.add("channel changes", k.channel_changes);
    s.add("held chunks", assembler_.heldChunks());
    s.add("buffered samples", assembler_.bufferedSamples());
    // Freed memory (a drained subscriber queue, a finished window) back to the system, so that
    // the resident size reports what is in use rather than the high-water mark.
    malloc_trim(0);
    s.add("resident memory [MiB]", residentMiB());
    s.add("process id", static_cast<long>(getpid()));
    const auto health = monitor_.update(k, now.toSec(), last_jump_);
    if (health.level != gear_damping_id::LossMonitor::Level::Ok) {
      s.mergeSummary(health.level == gear_damping_id::LossMonitor::Level::Error
                         ? diagnostic_msgs::DiagnosticStatus::ERROR
                         : diagnostic_msgs::DiagnosticStatus::WARN,
                     health.message);
    }
  }

  /// Forgets the assembler's state and the reported history (~reset).
  void reset() {
    assembler_.reset();
    last_samples_ = last_chunks_ = 0;
    monitor_.reset();
    last_jump_.clear();
  }

 private:
  gear_damping_id::StreamAssembler assembler_;
  std::vector<double> state_;
  unsigned long messages_ = 0;
  ros::WallTime last_chunk_, last_report_;
  unsigned long last_samples_ = 0, last_chunks_ = 0;
  gear_damping_id::LossMonitor monitor_;
  std::string last_jump_;
};

}  // namespace gear_damping_nodes
