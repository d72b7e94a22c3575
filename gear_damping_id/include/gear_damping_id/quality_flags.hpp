// Quality flags of the damping identification: the one place that decides whether a segment's
// estimate is clean, flagged (computed, but with a stated reason not to trust it as is) or not
// identifiable (its dynamic content is below the noise). Applied by every path that produces
// segments: identify() (batch), `analyze`'s streaming path and LiveIdentification. No ROS.
//
// Segment codes (stable; docs/trust.md says what causes each and what to do):
//   below_noise          the segment is not identifiable: C is not significantly different from
//                        zero, i.e. C_std / |C| > 1 / z(1 - alpha/2) with alpha = 5 % (limit
//                        0.51). By the Cramer-Rao bound C_std / |C| = sigma / ||C dy/dC||, so
//                        this is the test "the energy of the damping-sensitive part of the
//                        response is below z^2 times the noise energy".
//   nonpositive_damping  C <= 0
//   overdamped           xi >= 1
//   model_mismatch       the model cannot reproduce the data: the integral equations' residual
//                        RMS exceeds kMismatchNoiseRatio times the model-free noise estimate (so
//                        it is model error, not noise) AND either kMismatchGross of the DTE's
//                        standard deviation, or kMismatchSignalFraction of it with a possible
//                        bias of C (sqrt(N) C_std) above kMismatchBias of C
//   refine_disagrees     the refined and integral estimates differ by more than
//                        kDisagreeSE combined standard errors and by more than
//                        kDisagreeRelative of C (the refinement's constant-C fit,
//                        SegmentEstimate::C_weighted, where C is the mean-load damping)
//   residuals_not_white  the refinement's residual, after prewhitening with its fitted AR noise
//                        model, still has a lag-1 autocorrelation beyond kWhitenessZ/sqrt(N):
//                        the model leaves structure in the data (wrong stiffness shape, forcing
//                        or damping law), so C_std understates the error
//   damping_varies       the damping varies with the load within the segment: the term
//                        C1 (T1 - mean T1) added to the refined segment's model is more than
//                        kVariationZ standard errors from zero (SegmentEstimate::variation_z);
//                        (C is then the damping at the segment's mean load, which the
//                        constant-C fit, a weighted mean of C(t), need not be); on the constant
//                        model's C: the damping differs between the segments (variation_z
//                        beyond kVariationZ, variation_spread beyond kVariationSpread); on the
//                        run of a load law (LoadLawEstimate::variation_z, variation_spread, the
//                        same limits): the segments' damping departs from the law
//   shape_mismatch       greybox square levels (any damping model: the segments of a shared
//                        damping are scored at the shared C or load law): a stiffness ramped
//                        around the mesh switches fits better than one switching at once,
//                        by more than kShapeZ standard
//                        errors (SegmentEstimate::shape_z) and moving C by more than kShapeShift
//                        (SegmentEstimate::shape_shift): C can be biased by several C_std;
//                        or, for the run's segments together, by more than kShapePooledZ
//                        (the pooled score; then every such segment whose ramp moves C by
//                        more than kShapeShift is flagged, and the run too)
//   load_step            the torque steps between two samples inside the (refined) segment:
//                        the model interpolates the torque across the sample interval, so the
//                        free vibration the step's unknown place leaves unmodelled
//                        (SegmentEstimate::torque_step_response) can move C by more than
//                        kLoadStepSE standard errors
//   torque_glitch        one torque sample inside the (refined) segment departs from both its
//                        neighbours (a spike): the model's interpolated torque turns it into an
//                        impulse whose free vibration moved C by more than kTorqueErrorShare
//                        standard errors (torque_glitch_shift, piecewise), or can move it by more
//                        than kLoadStepSE (torque_glitch_response's bound, shared models)
//   torque_quantised     the torque is a staircase of levels torque_quantum apart (quantised
//                        without dither; piecewise refined segments), and its rounding error moved
//                        C by more than kTorqueErrorShare standard errors
//                        (torque_quantisation_shift), unless the DTE shows the steps are the load
//                        (torque_quantisation_fit, kStairsRealZ)
//   information_concentrated  the constant model's C: one segment holds more than
//                        kInformationShare of the information about C (information_share)
// Each depends on the segment's own estimate and data only, so batch, streamed and live
// identification flag a segment alike; the pooled shape score depends on the result's segments
// (the whole record in batch and streamed analysis, the kept history in live identification).
// Live input code (added by damping_id_node, not by applyQualityFlags):
//   torque_unstamped     the segment's torque was paired with the joint states without time
//                        stamps (rig_frontend_node with a std_msgs/Float64 torque marks its
//                        chunks): C can be biased by the pairing's lag (measured up to 10 %)
// Run codes (IdentificationResult::warnings): shape_mismatch (the pooled shape score above),
// model_mismatch (a shared damping, the constant model's C or the load law, fitted over segments
// of which some are flagged model_mismatch: one segment the model does not reproduce biases the
// shared estimate of all; also on the constant estimate),
// refine_not_converged (the output-error refinement
// stopped without converging), refine_failed (it diverged: integral estimates reported),
// refine_skipped (a streamed shared-damping run is not refined), switches_unlocated (stiffness
// switches that mesh_phase could not locate), integral_std (the reported estimates are the
// integral method's: their C_std understate the error, on noisy and on clean data;
// flagIntegralStandardErrors).
#pragma once

#include <utility>
#include <vector>

#include "gear_damping_id/identification_types.hpp"

namespace gear_damping_id {

namespace quality_code {
inline constexpr const char* kBelowNoise = "below_noise";
inline constexpr const char* kNonpositiveDamping = "nonpositive_damping";
inline constexpr const char* kOverdamped = "overdamped";
inline constexpr const char* kModelMismatch = "model_mismatch";
inline constexpr const char* kRefineDisagrees = "refine_disagrees";
inline constexpr const char* kResidualsNotWhite = "residuals_not_white";
inline constexpr const char* kDampingVaries = "damping_varies";
inline constexpr const char* kShapeMismatch = "shape_mismatch";
inline constexpr const char* kSwitchTiming = "switch_timing";
inline constexpr const char* kLoadStep = "load_step";
inline constexpr const char* kTorqueGlitch = "torque_glitch";
inline constexpr const char* kTorqueQuantised = "torque_quantised";
inline constexpr const char* kInformationConcentrated = "information_concentrated";
inline constexpr const char* kRefineNotConverged = "refine_not_converged";
inline constexpr const char* kRefineFailed = "refine_failed";
inline constexpr const char* kRefineSkipped = "refine_skipped";
inline constexpr const char* kSwitchesUnlocated = "switches_unlocated";
inline constexpr const char* kTorqueUnstamped = "torque_unstamped";
inline constexpr const char* kIntegralStd = "integral_std";
}  // namespace quality_code

/// Limits of the tests (documented in docs/trust.md).
struct QualityLimits {
  /// Two-sided 5 % significance: C must differ from zero by this many standard errors.
  static constexpr double kSignificanceZ = 1.959963984540054;
  /// The integral equations' residual over the noise estimate above which the model is said
  /// not to reproduce the data. A correct model leaves the noise plus the noise the double
  /// integrals of K y carry (measured 1.0-2.4x the noise on the test cases at 20-40 dB).
  static constexpr double kMismatchNoiseRatio = 5.0;
  /// A residual above the noise is model error. Above this fraction of the DTE's standard
  /// deviation (fit below 95 %) it is flagged outright.
  static constexpr double kMismatchGross = 0.05;
  /// Below that, model error of RMS rho can move C by at most rho sqrt(N) / ||x_C|| =
  /// sqrt(N) C_std (Cauchy-Schwarz, x_C the damping regressor after the nuisance projection,
  /// N samples): flagged when that bound exceeds this fraction of C...
  static constexpr double kMismatchBias = 0.1;
  /// ... and the residual exceeds this fraction of the signal: on noise-free data the noise
  /// estimate is at the quadrature level, and a correct model's residual stays below 1e-5 of
  /// the signal (measured up to 7e-6 on the exact greybox shapes); 1e-3 leaves a margin.
  static constexpr double kMismatchSignalFraction = 1e-3;
  /// Refined vs integral estimate: combined standard errors allowed between them.
  static constexpr double kDisagreeSE = 5.0;
  /// ... and by more than this fraction of C: below it the difference is the integral method's
  /// own quadrature error, not a model problem (noise-free, its C is within 2.5e-5 of the truth
  /// on the square wave and 8e-4 on a trapezoid, whose kinks its cubic runs across; the refined
  /// estimate is within 1e-6 on both), and noise-free standard errors are too small to judge it.
  static constexpr double kDisagreeRelative = 2e-3;
  /// Whiteness of the refinement's prewhitened residual: its lag-1 autocorrelation is about
  /// N(0, 1/N) when the model and the noise model fit (N samples); beyond this many 1/sqrt(N)
  /// (false alarm 6e-5 per segment) the model leaves structure in the residual.
  static constexpr double kWhitenessZ = 4.0;
  /// ... judged only where the residual RMS exceeds this fraction of the DTE's standard
  /// deviation: below it the residual is the refinement's own discretisation error on
  /// noise-free data (RK4 at omega0 h <= 0.1 against a continuous-time response: ~1e-6 of the
  /// amplitude, measured 1-2e-6 on a sampled rig stiffness table), whose correlation says
  /// nothing about the model.
  static constexpr double kWhitenessFloor = 1e-5;
  /// Within-segment damping variation: |C1 / std(C1)| beyond this is flagged. C1 / std(C1) is
  /// N(0, 1) when the damping is constant in the segment (the refinement's prewhitened least
  /// squares; std(C1) carries the torque-meter noise as C_std does), so a constant damping is
  /// flagged with probability 2 (1 - Phi(3)) = 0.27 % per segment (one record of 10 segments in
  /// 37). Judged, like the whiteness, only where the residual RMS exceeds kWhitenessFloor of the
  /// DTE's standard deviation: on noise-free data the standard error of C1 describes the
  /// refinement's discretisation error, not noise.
  static constexpr double kVariationZ = 3.0;
  /// The constant model's C is flagged damping_varies where its constancy test
  /// (SegmentEstimate::variation_z, one-sided: 0.135 % false alarms) exceeds kVariationZ and the
  /// segments' C spread beyond the noise by more than this fraction of C (the noise-free
  /// accuracy bar): noise-free, the test's residual is deterministic and the score large while
  /// every segment's damping is right to far better than this.
  static constexpr double kVariationSpread = 5e-4;
  /// Greybox square levels: |SegmentEstimate::shape_z| beyond this is flagged shape_mismatch.
  /// shape_z is N(0, 1) when the stiffness switches at once (a score test of the refinement's
  /// prewhitened least squares; its variance carries the torque-meter noise as C_std does), so
  /// a square-wave stiffness is flagged with probability 0.27 % per segment; judged above
  /// kWhitenessFloor like the others.
  static constexpr double kShapeZ = 3.0;
  /// ... and only where the ramp, fitted, would move C by more than this fraction of C (the
  /// noise-free accuracy bar): noise-free, the residual is deterministic (the simulator's and the
  /// refinement's discretisations, a damping that varies nonlinearly within the segment), so
  /// the score is large while C is right to far better than this.
  static constexpr double kShapeShift = 5e-4;
  /// The record's segments together: where |sum(shape_z) / sqrt(n)| over the n judged segments of
  /// a run exceeds this, each of them whose fitted ramp would move C by more than kShapeShift is
  /// flagged shape_mismatch and the run carries shape_mismatch. The pooled score is N(0, 1) for a
  /// square-wave stiffness (independent segments); 4 is a false alarm of 6e-5 per run at rms 1
  /// (measured: rms 1.15 over 40 random square-stiffness records of 28-50 segments, |Z| <= 1.1 on
  /// Table 1 records of 200-500 segments; docs/trust.md), while a ramp that scores 2-3 in every
  /// segment pools to 12-21 over 50 segments.
  static constexpr double kShapePooledZ = 4.0;
  /// Without `mesh_phase` each switch is held to the sample where the new value is first seen,
  /// delta half-samples late on average (1 where the switches fall anywhere between samples, 0
  /// where they lie on the samples, drifting between segments where the mesh period is close to
  /// a whole number of samples); the run's segments estimate delta together from their
  /// switch_timing_z, and a segment whose own score exceeds kShapeZ estimates its own. A segment
  /// is flagged switch_timing where delta's upper bound (estimate + 2 standard errors) times its
  /// switch_timing_shift exceeds this many C_std (and kShapeShift of C): the bias left in C; half
  /// a C_std keeps the coverage of +-1.96 C_std at 93 % or more.
  static constexpr double kSwitchTimingShare = 0.5;
  /// A torque step inside a segment (SegmentEstimate::torque_step_response, a): the unmodelled
  /// free vibration a e^(-C t / 2) sin(omega0 t + phi) after it has the energy
  /// E = a^2 / 2 sum_k e^(-C k dt) over the samples after the step, and can move C by up to
  /// sqrt(E) / sigma standard errors (sigma the noise, not below kWhitenessFloor of the DTE's
  /// standard deviation). Flagged beyond this many.
  static constexpr double kLoadStepSE = 1.0;
  /// A torque glitch (one sample off both neighbours) or a torque quantised without dither
  /// moved a piecewise refined segment's C by SegmentEstimate::torque_glitch_shift /
  /// torque_quantisation_shift (computed, not bounded): flagged torque_glitch / torque_quantised
  /// beyond this many C_std (half a C_std keeps the coverage of +-1.96 C_std at 93 % or more).
  /// Other segments' glitches are flagged by the free vibration's bound (kLoadStepSE).
  static constexpr double kTorqueErrorShare = 0.5;
  /// A torque staircase is taken as the load itself (no torque_quantised) where the DTE supports
  /// it beyond doubt: SegmentEstimate::torque_quantisation_fit below 0.5 and 1 (a quantised
  /// smooth load) this many of its standard errors away. Not 3: the straight-line reconstruction
  /// is itself off between crossings, which the standard error leaves out, and held-out records
  /// quantised at 2 N*m gave fits of -0.21 +- 0.11 and 0.10 +- 0.12 with C 4-5 C_std off; a load
  /// that really steps by 5 N*m (Table 1, 40 dB) lies ~100 standard errors from 1.
  static constexpr double kStairsRealZ = 20.0;
  /// The constant model's C most of whose information comes from one segment
  /// (SegmentEstimate::information_share beyond this) is in effect that segment's damping, and
  /// its test of one damping for every segment has little power elsewhere (flag
  /// information_concentrated).
  static constexpr double kInformationShare = 0.5;
};

/// Flags every segment of `result` (and the shared constant estimate): adds the segment codes
/// above to SegmentEstimate::warnings, and makes a below-noise segment not identifiable (its
/// numbers NaN, `reason` says why). Idempotent: the codes it owns are recomputed, others kept.
void applyQualityFlags(const IdentificationOptions& options, IdentificationResult* result);

/// The run warning integral_std, recomputed (idempotent): when `result` reports the integral
/// method's estimates (estimator "integral": `--refine never`, the paper and legacy formulations,
/// a skipped or failed refinement) and some are identifiable and unrefined. Those C_std are the
/// integral equations' standard errors. On noisy data (median C_std / |C| above
/// options.refine_threshold) the noise inside the integrals (errors in the regressors) is not in
/// them, so they understate the scatter (Table 1 case at 40 dB SNR: errors 1.8 times C_std in
/// rms, +-2 C_std covering 74 % instead of 95 %); on clean data they measure the residual only,
/// while the quadrature error and damping varying within a segment bias C by more (noise-free
/// held-out gears: up to 16 % of C at 54 C_std). The text says which.
void flagIntegralStandardErrors(const IdentificationOptions& options, IdentificationResult* result);

/// After an output-error refinement of `integral` into `refined` (same segments), keeps the
/// integral method's C and C_std in C_integral / C_integral_std of every refined segment that
/// does not already carry them.
void keepIntegralEstimates(const IdentificationResult& integral, IdentificationResult* refined);

/// The spans of a live record [s, record time] whose torque was paired without time stamps
/// (SignalChunk header.frame_id kTorqueUnstampedFrame); mark() adds torque_unstamped to every
/// segment overlapping one. Adjacent spans merge, so a record marked throughout keeps one span;
/// at most kMaxSpans are kept (the oldest dropped).
class UnstampedTorqueSpans {
 public:
  static constexpr size_t kMaxSpans = 1000;
  /// Samples [t0, t1] [s] (t1 >= t0) were paired without stamps; `gap` [s]: spans closer than
  /// this merge (e.g. 1.5 sample intervals).
  void add(double t0, double t1, double gap);
  /// Adds the warning to the segments of `result` that overlap a span (once per segment).
  void mark(IdentificationResult* result) const;
  void mark(SegmentEstimate* e) const;
  bool overlaps(double t0, double t1) const;
  bool empty() const { return spans_.empty(); }
  void clear() { spans_.clear(); }

 private:
  std::vector<std::pair<double, double>> spans_;  // sorted by start
};

/// Whether `warnings` holds `code`.
bool hasCode(const QualityWarnings& warnings, const std::string& code);

/// The codes of `warnings` joined by `sep` (e.g. for a CSV cell or a printed table).
std::string joinCodes(const QualityWarnings& warnings, const std::string& sep = ";");

}  // namespace gear_damping_id
