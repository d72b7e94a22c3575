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
//   xi in the cumulative result uses omega0 of all segments so far (offline: of the record).
// - constant / load_law: the shared unknowns are re-solved over all segments so far after each
//   segment (the cumulative result equals identify() over the same segments with Refine::Never);
//   they are not refined live.
// - A segment lacking a channel the formulation needs, or sampled too coarsely for the gear's
//   natural frequency (input_checks.hpp), is reported as not identifiable (the reason says
//   which) and takes no part in any estimate.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"

namespace gear_damping_id {

class LiveIdentification {
 public:
  /// `options` and `gear` must be valid (validate()).
  LiveIdentification(const IdentificationOptions& options, const GearConstants& gear);

  struct SegmentOutput {
    SegmentEstimate estimate;  ///< final for piecewise; the current shared value otherwise
    /// This segment alone (formulation, model, Me, omega0, the segment and its windows): what
    /// modeledResponse() needs for the segment's re-simulation.
    IdentificationResult result;
    std::string warning;  ///< e.g. a refinement that failed (the integral estimate is kept)
  };

  /// Identifies samples [begin, end) of `view` as the next damping segment (samples outside the
  /// range, if any, serve as stencil context). Never throws on any sample values.
  SegmentOutput add(const SignalView& view, Eigen::Index begin, Eigen::Index end);

  /// Every segment so far (piecewise: per-segment estimates, refined where applied).
  IdentificationResult cumulative() const;

  /// Forgets every segment (keeps options, constants and the resolved window length).
  void reset();
  size_t segmentCount() const { return segments_.size(); }
  const IdentificationOptions& options() const { return options_; }

 private:
  IdentificationOptions options_;
  GearConstants gear_;
  IntegralMethod method_;  // all segments (shared unknowns; omega0)
  IntegralMethod single_;  // piecewise: one segment at a time (its windows)
  std::vector<SegmentEstimate> segments_;
  IdentificationResult shared_;  // constant / load_law: latest cumulative solve
};

}  // namespace gear_damping_id
