// The one segment-by-segment identification pipeline: the batch identify() of a whole record,
// `analyze`'s bounded-memory streaming of long bags and the live node's LiveIdentification all
// feed their damping segments to a SegmentDriver, which runs the integral method
// (integral_method.hpp), decides and runs the output-error refinement (output_error.hpp),
// applies the quality flags (quality_flags.hpp) and assembles the run summary (omega0, xi, run
// warnings). No ROS. docs/architecture.md draws the data flow.
//
// Semantics (the same for every caller, so batch, streamed and live results are identical when
// the driver sees the same samples, whatever the chunking; a test states it for every
// formulation x damping model):
// - A segment is samples [begin, end) of a view; up to kStencilContext samples on either side,
//   when the view holds them, serve the quadrature stencils only. Callers give the same
//   neighbours the record has (StreamAssembler keeps them; SegmentFeeder's blocks hold them).
// - piecewise model (known, greybox, paper): each segment is its own problem: identified, then,
//   when options.refine asks for it (Auto: on the segment's own relative standard error),
//   refined by output error, on its own. The record's omega0 (for xi) is the duration-weighted
//   mean of the segments' mean normalised stiffness, accumulated in segment order; xi and the
//   flags are recomputed with it when a result is formed.
// - shared unknowns (constant, load_law, and legacy's one stiffness): every segment's normal
//   equations are accumulated (memory: a small Gram matrix per segment); the shared unknowns are
//   solved when a result is formed. Their output-error refinement needs the whole record
//   (finish() with the record): a streamed run reports refine_skipped instead; the live driver
//   never refines them. With DriverLimits::shared_segments finite the problem slides (live): it
//   spans the last shared_segments to 2 * shared_segments - 1 segments.
// - legacy: the mean forcing Fbar of the analysed range must be set before the first segment
//   (setLegacyForcing; batch and streaming compute it first); when never set, Fbar is an extra
//   shared unknown (the live node, which cannot look ahead).
// - A segment lacking a channel the formulation needs, or with no samples, is reported as not
//   identifiable (the reason names the channel) and takes no part in any estimate.
// - STE (setSte, docs/ste.md "The STE in the segment pipeline"): the STE coefficients are a
//   property of the gears, shared by the record, but a streamed or live run cannot wait for the
//   record's end. The driver buffers the first `calibration_segments` usable segments, and more
//   until they span a revolution of each shaft whose orders are modelled (with their stencil
//   context; memory bounded by them), identifies C and the STE jointly on them
//   (identifySteSegments, refined as options.refine asks) and then HOLDS the STE: every later
//   segment is fitted on its own given it (identifySegmentWithHeldSte), its C_std including the
//   STE's covariance. Until the calibration completes add() returns the segments as pending
//   (not identifiable, reason "awaiting the STE calibration"); result() lists them with their
//   joint estimates once it has. finish() calibrates on what arrived when the record ended
//   first. With calibration_segments >= the record's segment count the result is the batch
//   identifyWithSte of the whole record. The constant model shares C: its calibration is the
//   whole record (not bounded; the live node refuses it).
// - threads > 1 (addAll): segments are processed in parallel, each by its own integral-method
//   object, and recorded in segment order: the results equal those of one thread bit for bit.
#pragma once

#include <deque>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/ste_model.hpp"

namespace gear_damping_id {

/// Samples the integral method reads on either side of a segment (quadrature stencils).
constexpr int kStencilContext = 2;

/// Memory bounds and parallelism of a SegmentDriver.
struct DriverLimits {
  /// Per-segment estimates kept for result() (>= 1; live: bounded, batch: all).
  size_t history_segments = std::numeric_limits<size_t>::max();
  /// Shared models: the sliding problem's span (>= 1; see the header comment).
  size_t shared_segments = std::numeric_limits<size_t>::max();
  /// Shared models: solve the shared unknowns after every segment, so that add() returns the
  /// current shared value (live). Otherwise they are solved by result()/finish() only.
  bool solve_shared_each_segment = false;
  /// Worker threads of addAll (>= 1).
  int threads = 1;
};

class SegmentDriver {
 public:
  /// `options` and `gear` must be valid (check()); a window_length of 0 is resolved from the
  /// first view given (defaultWindowLength), so callers that want the record's default resolve
  /// it first.
  SegmentDriver(const IdentificationOptions& options, const GearConstants& gear,
                const DriverLimits& limits = DriverLimits());

  /// Legacy formulation: the mean forcing Fbar [m/s^2] of the analysed record (before add()).
  void setLegacyForcing(double fbar);

  /// Identify the STE with the damping (before add(); header comment): jointly on the first
  /// `calibration_segments` usable segments (>= 1; the constant model: all), then held. `ste`
  /// must be valid, options known/greybox (checkSteOptions). Ok or why not.
  gear_sim::Status setSte(const SteModelOptions& ste, size_t calibration_segments);
  /// The STE once calibrated (else null).
  const SteResult* steResult() const { return ste_ready_ ? &ste_ : nullptr; }
  /// The STE's calibration span once calibrated: the segments it was identified on (the first
  /// usable ones) and their time span [s] (t_start of the first, t_end of the last).
  struct SteCalibration {
    size_t segments = 0;
    double t_start = kNaN, t_end = kNaN;
  };
  const SteCalibration& steCalibration() const { return ste_calibrated_; }
  /// STE mode, a record that ended before the calibration span: calibrates on the segments that
  /// arrived now (finish() does it on a copy), so that steResult() has the record's STE.
  void completeSteCalibration() {
    if (ste_on_ && !ste_ready_) calibrate();
  }

  struct SegmentOutput {
    SegmentEstimate estimate;  ///< final for piecewise; shared: the current shared value when
                               ///< solve_shared_each_segment, else provisional (NaN C)
    /// This segment alone (formulation, model, Me, omega0, the segment and its windows): what
    /// modeledResponse() needs for the segment's re-simulation.
    IdentificationResult result;
    std::string warning;  ///< e.g. a refinement that failed (the integral estimate is kept)
    bool refinement_skipped = false;  ///< the options asked for it, refine_allowed was false
    /// Pending: buffered for the STE calibration (setSte), not yet identified; the estimate is
    /// not identifiable with the reason "awaiting the STE calibration (...)" until then. Not a
    /// failure: diagnostics count these apart from the segments that are not identifiable.
    bool ste_pending = false;
  };

  /// Identifies samples [begin, end) of `view` as the next damping segment. Never throws on any
  /// sample values.
  SegmentOutput add(const SignalView& view, Eigen::Index begin, Eigen::Index end,
                    bool refine_allowed = true);

  /// add() for every range of `view` (ascending), with DriverLimits::threads workers. With
  /// `outputs` false the per-segment outputs are not collected (an empty vector is returned;
  /// result()/finish() are the same): for callers that only want the run's result.
  std::vector<SegmentOutput> addAll(const SignalView& view, const SampleRanges& ranges,
                                    bool outputs = true);

  /// The last `last` segments kept, with the shared unknowns solved, xi from the record's
  /// omega0 so far, the flags applied and the run warnings. Not refined for shared models.
  IdentificationResult result(size_t last = std::numeric_limits<size_t>::max()) const;

  /// The run's final result. Shared models: refined as options.refine asks when `record` (the
  /// view every segment was taken from) and `ranges` (the segments' ranges in it) are given;
  /// without them (a streamed record) a wanted refinement is reported as refine_skipped.
  IdentificationResult finish(const SignalView* record = nullptr,
                              const SampleRanges* ranges = nullptr) const;

  /// Forgets every segment (keeps options, constants and the resolved window length).
  void reset();
  size_t segmentCount() const { return kept_.size(); }
  unsigned long segmentsAdded() const { return added_; }
  const IdentificationOptions& options() const { return options_; }
  const DriverLimits& limits() const { return limits_; }
  bool sharedModel() const { return shared_; }

 private:
  struct Kept {
    SegmentEstimate estimate;
    std::vector<WindowEstimate> windows;  // piecewise: the segment's windows
  };
  // The piecewise work of one segment (thread-safe: `method` is the worker's own).
  SegmentOutput piecewiseSegment(IntegralMethod* method, const SignalView& v, Eigen::Index begin,
                                 Eigen::Index end, bool refine_allowed) const;
  SegmentOutput unusableSegment(const SignalView& v, Eigen::Index begin, Eigen::Index end) const;
  void recordPiecewise(const SegmentOutput& out, long unlocated, double dt,
                       bool keep_estimate = true);
  void recordPiecewise(SegmentOutput&& out, long unlocated, double dt);  // moves into kept_
  void recordParallelOutput(SegmentOutput* out, const std::pair<Eigen::Index, Eigen::Index>& range,
                            long unlocated, double dt, bool outputs);
  SegmentOutput addOne(const SignalView& v, Eigen::Index begin, Eigen::Index end,
                       bool refine_allowed, bool consume);
  SegmentOutput addShared(const SignalView& v, Eigen::Index begin, Eigen::Index end);
  void addSharedParallel(const SignalView& v, const SampleRanges& ranges);
  IdentificationResult sharedResult(size_t last) const;
  IdentificationResult piecewiseResult(size_t last) const;
  IntegralMethod newMethod() const;
  void resolveWindow(const SignalView& v);
  void keep(Kept k);
  // STE mode (segment_driver_ste.cpp).
  SegmentOutput addSte(const SignalView& v, Eigen::Index begin, Eigen::Index end,
                       bool refine_allowed);
  void bufferCalibrationSegment(const SignalView& v, Eigen::Index begin, Eigen::Index end);
  void calibrate();
  double calibrationCycles() const;
  bool calibrationComplete() const;
  SegmentOutput heldSteSegment(const SignalView& v, Eigen::Index begin, Eigen::Index end,
                               bool refine_allowed) const;

  IdentificationOptions options_;
  GearConstants gear_;
  DriverLimits limits_;
  bool shared_ = false;
  double legacy_fbar_ = kNaN;
  IntegralMethod method_;  // shared: the (older half of the sliding) problem; piecewise: worker
  IntegralMethod newer_;   // shared, sliding: the segments since method_ was last replaced
  std::deque<Kept> kept_;
  IdentificationResult shared_solve_;  // shared, solve_shared_each_segment: the latest solve
  // Piecewise run summary, accumulated in segment order.
  double k_time_ = 0.0, duration_ = 0.0;  // sum of kmean * T, sum of T over segments
  long unlocated_ = 0;                    // switches mesh_phase could not locate
  QualityWarnings run_warnings_;          // one per code, counted in run_warning_count_
  std::vector<int> run_warning_count_;
  int iterations_ = 0;
  double noise_sq_ = 0.0, innovation_sq_ = 0.0, noise_samples_ = 0.0;
  unsigned long added_ = 0;
  // STE mode: options, the calibration buffer (record columns of the calibration segments with
  // their context, merged where contiguous) and the held STE.
  bool ste_on_ = false, ste_ready_ = false;
  SteModelOptions ste_options_;
  size_t ste_calibration_ = 0;
  SteResult ste_;
  SteCalibration ste_calibrated_;
  struct Calibration {
    std::vector<double> col[5];  // dte, stiffness, torque, mesh_state, mesh_phase
    bool present[5] = {false, false, false, false, false};
    double t0 = 0.0, dt = 0.0, origin = 0.0;       // buffer sample 0's time; record sample 0's time
    long long next_abs = -1;                       // record sample after the buffer's last
    SampleRanges ranges;                           // in buffer samples
    std::vector<std::pair<double, double>> times;  // each segment's t_start, time(end - 1)
    std::vector<unsigned long> added_at;           // added_ when each was kept
    double phase_min = std::numeric_limits<double>::infinity();  // mesh phase span [cycles]
    double phase_max = -std::numeric_limits<double>::infinity();
  } calib_;
};

/// Legacy formulation: the mean forcing Fbar = force_factor * mean(T1) [m/s^2] over the samples
/// from the first range's begin to the last range's end (summed in sample order, so a streamed
/// record that sums its blocks in order gets the same number); NaN without a torque channel.
double legacyForcing(const SignalView& view, const SampleRanges& ranges, const GearConstants& gear);

/// Streams the damping segments `ranges` (record sample numbers, ascending) of a long record to
/// `sink` in groups of up to `group` segments (for parallel workers). The record is read in order
/// as one block a group (heldRanges()), holding the group's segments with kStencilContext samples
/// of context; the sink's view is on the block itself, so memory is bounded by one group's block.
/// Views are on the record's time axis: sample i at t0 + i dt.
class SegmentFeeder {
 public:
  using Sink =
      std::function<bool(const SignalView& view, const SampleRanges& ranges, size_t first_range)>;
  SegmentFeeder(SampleRanges ranges, Eigen::Index record_samples, double t0, double dt,
                size_t group);
  /// The new samples each group reads (contiguous, non-overlapping, in order): its segments with
  /// their context, from where the previous group's read ended. Empty for a group whose samples
  /// were all read before (e.g. a last segment of at most kStencilContext samples).
  SampleRanges readRanges() const;
  /// The sample range each group's block must hold: its read range with the samples before it
  /// that the group needs (its left stencil context, already read for the previous group), so
  /// every segment of the group with its context. Ascending; a range may begin before the
  /// previous one ends.
  SampleRanges heldRanges() const;
  /// Takes the block that holds heldRanges()[index] (its columns; `time` is ignored; an empty
  /// column is an absent channel): the sink's view is on the block's columns, not on a copy.
  /// Returns false when the sink did.
  bool pushHeld(const gear_sim::SignalTable& block, size_t index, const Sink& sink);

 private:
  SampleRanges ranges_;
  Eigen::Index samples_;
  double t0_, dt_;
  size_t group_;
  std::vector<std::pair<size_t, size_t>> groups_;  // [first, last) segment of each read range
  SampleRanges reads_, held_;                      // readRanges(), heldRanges()
  SampleRanges makeReadRanges() const;
  SampleRanges makeHeldRanges() const;
};

}  // namespace gear_damping_id
