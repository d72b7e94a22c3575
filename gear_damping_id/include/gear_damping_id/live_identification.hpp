// Segment-by-segment identification for the live node (damping_id_node): a SegmentDriver
// (segment_driver.hpp, the pipeline batch and streamed runs use too) with bounded memory, fed one
// completed segment at a time, re-solving shared unknowns after each segment so every segment
// output carries the current estimate. No ROS; the node only converts and publishes.
//
// Semantics: those of SegmentDriver, so the cumulative result equals identify() over the same
// segments (with the same neighbouring samples, as StreamAssembler keeps them), bit for bit:
// - piecewise model: each segment identified and (options.refine) refined on its own; xi in
//   the cumulative result uses omega0 of all segments so far.
// - constant / load_law: the shared unknowns are re-solved after each segment over the last
//   limits.shared_segments to 2 * limits.shared_segments - 1 segments (over all of them while
//   fewer than 2 * shared_segments arrived); they are not refined live.
// - legacy: without setLegacyForcing (the node cannot look ahead for the record's mean load),
//   the mean forcing is an extra shared unknown.
// - Memory is bounded for any run length: the per-segment estimates kept for cumulative() are
//   the last limits.history_segments; the shared-model problems hold at most
//   2 * shared_segments segments; the piecewise problem one segment.
// - add(..., refine_allowed = false) skips a refinement the options would apply (the caller
//   cannot keep up): the integral estimate is returned and refinement_skipped is set.
// - A segment lacking a channel the formulation needs, or sampled too coarsely for the gear's
//   natural frequency (input_checks.hpp), is reported as not identifiable (the reason says
//   which) and takes no part in any estimate.
#pragma once

#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "gear_damping_id/segment_driver.hpp"

namespace gear_damping_id {

/// Memory bounds of LiveIdentification (both >= 1).
struct LiveLimits {
  size_t history_segments = 100000;  ///< per-segment estimates kept for cumulative()
  size_t shared_segments = 1000;     ///< constant/load_law: the sliding problem's span (see above)
};

class LiveIdentification {
 public:
  /// `options` and `gear` must be valid (check()); limits fields >= 1.
  LiveIdentification(const IdentificationOptions& options, const GearConstants& gear,
                     const LiveLimits& limits = LiveLimits());

  using SegmentOutput = SegmentDriver::SegmentOutput;

  /// Identifies samples [begin, end) of `view` as the next damping segment (samples outside the
  /// range, if any, serve as stencil context). Never throws on any sample values.
  SegmentOutput add(const SignalView& view, Eigen::Index begin, Eigen::Index end,
                    bool refine_allowed = true) {
    return driver_.add(view, begin, end, refine_allowed);
  }

  /// Legacy formulation: the record's mean forcing [m/s^2], when known in advance.
  void setLegacyForcing(double fbar) { driver_.setLegacyForcing(fbar); }
  /// Identify the STE too (SegmentDriver::setSte): jointly on the first `calibration_segments`
  /// segments, then held. Ok or why not (checkSte).
  gear_sim::Status setSte(const SteModelOptions& ste, size_t calibration_segments) {
    if (gear_sim::Status s = checkSte(driver_.options()); !s.ok()) return s;
    return driver_.setSte(ste, calibration_segments);
  }
  /// Whether `options` can identify the STE live: checkSteOptions, and not the constant model
  /// (its calibration would be the whole run). The node checks its parameters with it at start.
  static gear_sim::Status checkSte(const IdentificationOptions& options) {
    if (gear_sim::Status s = checkSteOptions(options); !s.ok()) return s;
    if (options.model == DampingModel::Constant)
      return gear_sim::Status::invalidArgument(
          "the STE with the constant damping model needs the whole record (not live)", "model");
    return {};
  }
  /// The held STE once calibrated (else null).
  const SteResult* steResult() const { return driver_.steResult(); }

  /// The last `last` segments kept (at most limits.history_segments; piecewise: per-segment
  /// estimates, refined where applied). No integration windows (they are per segment, in add()).
  IdentificationResult cumulative(size_t last = static_cast<size_t>(-1)) const;

  /// Forgets every segment (keeps options, constants and the resolved window length).
  void reset() { driver_.reset(); }
  /// Segments kept (at most limits.history_segments).
  size_t segmentCount() const { return driver_.segmentCount(); }
  /// Segments added since construction/reset.
  unsigned long segmentsAdded() const { return driver_.segmentsAdded(); }
  const IdentificationOptions& options() const { return driver_.options(); }
  const LiveLimits& limits() const { return limits_; }

 private:
  LiveLimits limits_;
  SegmentDriver driver_;
};

}  // namespace gear_damping_id
