// Segment-by-segment identification for the live node (damping_id_node): the integral method
// (integral_method.hpp) fed one completed segment at a time, with the per-segment output-error
// refinement and the cumulative estimate. No ROS; the node only converts and publishes.
//
// Semantics (compared with identify() over the whole record with the same options):
// - piecewise model: each segment is identified on its own (its own IntegralMethod problem, so
//   exactly the numbers identify() gives when the segment sees the same samples and stencil
//   context) and, when options.refine asks for it, refined by output error on its own. Refine
//   Never/Always give the offline result; Auto decides per segment (offline: on the median over
//   the record), so on data whose segments straddle the threshold the choice can differ.
//   xi in the cumulative result uses omega0 of all segments so far (offline: of the record),
//   kept as two running sums (the time integral of the mean stiffness and the duration).
// - constant / load_law: the shared unknowns are re-solved after each segment over the last
//   limits.shared_segments to 2 * limits.shared_segments - 1 segments (the cumulative result
//   equals identify() over those segments with Refine::Never; over all of them while fewer
//   than 2 * shared_segments arrived); they are not refined live.
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

#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"

namespace gear_damping_id {

/// Memory bounds of LiveIdentification (both >= 1).
struct LiveLimits {
  size_t history_segments = 100000;  ///< per-segment estimates kept for cumulative()
  size_t shared_segments = 1000;     ///< constant/load_law: the sliding problem's span (see above)
};

class LiveIdentification {
 public:
  /// `options` and `gear` must be valid (validate()); limits fields >= 1.
  LiveIdentification(const IdentificationOptions& options, const GearConstants& gear,
                     const LiveLimits& limits = LiveLimits());

  struct SegmentOutput {
    SegmentEstimate estimate;  ///< final for piecewise; the current shared value otherwise
    /// This segment alone (formulation, model, Me, omega0, the segment and its windows): what
    /// modeledResponse() needs for the segment's re-simulation.
    IdentificationResult result;
    std::string warning;  ///< e.g. a refinement that failed (the integral estimate is kept)
    bool refinement_skipped = false;  ///< the options asked for it, refine_allowed was false
  };

  /// Identifies samples [begin, end) of `view` as the next damping segment (samples outside the
  /// range, if any, serve as stencil context). Never throws on any sample values.
  SegmentOutput add(const SignalView& view, Eigen::Index begin, Eigen::Index end,
                    bool refine_allowed = true);

  /// The last `last` segments kept (at most limits.history_segments; piecewise: per-segment
  /// estimates, refined where applied). No integration windows (they are per segment, in add()).
  IdentificationResult cumulative(size_t last = static_cast<size_t>(-1)) const;

  /// Forgets every segment (keeps options, constants and the resolved window length).
  void reset();
  /// Segments kept (at most limits.history_segments).
  size_t segmentCount() const { return segments_.size(); }
  /// Segments added since construction/reset.
  unsigned long segmentsAdded() const { return added_; }
  const IdentificationOptions& options() const { return options_; }
  const LiveLimits& limits() const { return limits_; }

 private:
  IdentificationOptions options_;
  GearConstants gear_;
  LiveLimits limits_;
  IntegralMethod method_;  // shared models: the older half of the sliding problem
  IntegralMethod newer_;   // shared models: the segments since method_ was last replaced
  IntegralMethod single_;  // piecewise: one segment at a time (its windows)
  std::deque<SegmentEstimate> segments_;
  IdentificationResult shared_;           // constant / load_law: latest solve
  double k_time_ = 0.0, duration_ = 0.0;  // piecewise omega0: sum kmean * T, sum T
  unsigned long added_ = 0;
};

}  // namespace gear_damping_id
