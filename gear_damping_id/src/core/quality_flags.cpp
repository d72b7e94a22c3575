// Quality flags of the damping identification (see quality_flags.hpp).
#include "gear_damping_id/quality_flags.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace gear_damping_id {

namespace {

using L = QualityLimits;

bool ownedCode(const std::string& c) {
  return c == quality_code::kNonpositiveDamping || c == quality_code::kOverdamped ||
         c == quality_code::kModelMismatch || c == quality_code::kRefineDisagrees ||
         c == quality_code::kResidualsNotWhite || c == quality_code::kDampingVaries ||
         c == quality_code::kShapeMismatch || c == quality_code::kSwitchTiming ||
         c == quality_code::kLoadStep || c == quality_code::kTorqueGlitch ||
         c == quality_code::kTorqueQuantised || c == quality_code::kInformationConcentrated;
}

// How many standard errors of C an unmodelled free vibration of amplitude `response` starting at
// `time` (a torque step's, a torque glitch's) can move C by at most (QualityLimits::kLoadStepSE);
// NaN without one.
double freeVibrationSE(const SegmentEstimate& e, double response, double time) {
  if (!std::isfinite(response) || e.samples <= 0 || !std::isfinite(e.C)) return kNaN;
  const double dt = (e.t_end - e.t_start) / static_cast<double>(e.samples);
  const double after = std::max(e.t_end - time, 0.0);
  const double rate = std::max(e.C, 0.0);  // the energy's decay rate, C
  const double sum =
      rate * dt > 0.0 ? std::expm1(-rate * after) / std::expm1(-rate * dt) : after / dt;
  const double noise = std::isfinite(e.noise_std) ? e.noise_std : 0.0;
  const double sigma = std::max(noise, L::kWhitenessFloor * e.signal_std);
  return response * std::sqrt(0.5 * sum) / sigma;
}

// Removes the warnings whose code `drop` accepts, keeping the others' order.
template <class Drop>
void eraseWarnings(QualityWarnings* w, Drop&& drop) {
  w->erase(
      std::remove_if(w->begin(), w->end(), [&](const QualityWarning& q) { return drop(q.code); }),
      w->end());
}

// Removes the warnings of `code` (hasCode finds them).
void eraseCode(QualityWarnings* w, const std::string& code) {
  eraseWarnings(w, [&](const std::string& c) { return c == code; });
}

std::string num(double v) {
  std::ostringstream s;
  s.precision(4);
  s << v;
  return s.str();
}

// Whether the shape test judges the estimate: its score exists and means what it says (above
// the discretisation floor).
bool shapeJudged(const SegmentEstimate& e) {
  return e.identifiable && e.refined && std::isfinite(e.shape_z) &&
         e.residuals.rms > L::kWhitenessFloor * e.signal_std;
}

const char* const kShapeAdvice =
    "C can be biased by several C_std: use the measured stiffness (--formulation known) or a "
    "--stiffness-shape that ramps (table:N, fourier:H)";
const char* const kCurveAdvice =
    "C can be biased by several C_std: use the measured stiffness (--formulation known) or a "
    "finer --stiffness-shape (more table nodes or harmonics, or nodes on the stiffness' corners)";

// A fourier/table curve's shape test (curveScore) rather than the square levels' (shapeScore).
bool curveShape(const SegmentEstimate& e) { return !e.stiffness_curve.empty(); }

// load_step (QualityLimits::kLoadStepSE): the torque step's unmodelled vibration can move C.
void flagLoadStep(const SegmentEstimate& e, QualityWarnings* w) {
  if (const double se = freeVibrationSE(e, e.torque_step_response, e.torque_step_time);
      se > L::kLoadStepSE) {
    w->push_back(
        {quality_code::kLoadStep,
         "the torque steps by " + num(e.torque_step) +
             " N*m between two samples inside the segment (at t = " + num(e.torque_step_time) +
             " s): the model interpolates the torque across the sample interval, so the "
             "step's impulse is placed within +-1/2 of it and the response can miss a "
             "free vibration of up to " +
             num(e.torque_step_response) + " m, which can move C by up to " + num(se) +
             " standard errors (> " + num(L::kLoadStepSE) +
             "): treat C as biased, or start a segment at the step (--t-start)"});
  }
}

// How many of C's standard errors a computed shift of C is (torque_glitch_shift,
// torque_quantisation_shift); NaN where the shift or C_std is missing.
double shiftSE(const SegmentEstimate& e, double shift) {
  return std::isfinite(shift) && e.C_std > 0.0 && std::isfinite(e.C_std) ? std::abs(shift) / e.C_std
                                                                         : kNaN;
}

// torque_glitch: the glitch's spurious impulse moved C by more than kTorqueErrorShare C_std
// (its computed shift), or can move it by more than kLoadStepSE (the bound, without a shift).
void flagTorqueGlitch(const SegmentEstimate& e, QualityWarnings* w) {
  if (!std::isfinite(e.torque_glitch)) return;
  std::string effect;
  if (const double se = shiftSE(e, e.torque_glitch_shift); std::isfinite(se)) {
    if (!(se > L::kTorqueErrorShare)) return;
    effect = "moved C by " + num(e.torque_glitch_shift) + " 1/s (" + num(se) +
             " standard errors, > " + num(L::kTorqueErrorShare) + ")";
  } else {
    const double bound = freeVibrationSE(e, e.torque_glitch_response, e.torque_glitch_time);
    if (!(bound > L::kLoadStepSE)) return;
    effect =
        "can move C by up to " + num(bound) + " standard errors (> " + num(L::kLoadStepSE) + ")";
  }
  const std::string which =
      e.torque_glitches > 1 ? std::to_string(e.torque_glitches) +
                                  " torque samples depart from both their neighbours, the largest "
                            : "one torque sample departs from both its neighbours ";
  w->push_back({quality_code::kTorqueGlitch,
                which + "(at t = " + num(e.torque_glitch_time) + " s) by " + num(e.torque_glitch) +
                    " N*m, spikes the torque cannot make in one sample: the model's interpolated "
                    "torque turns them into impulses whose free vibration (up to " +
                    num(e.torque_glitch_response) + " m for the largest) " + effect +
                    ": treat C as biased, or repair the torque samples (a meter or transmission "
                    "glitch)"});
}

// torque_quantised: the rounding error of a torque quantised without dither moved C by more than
// kTorqueErrorShare C_std.
void flagTorqueQuantised(const SegmentEstimate& e, QualityWarnings* w) {
  if (!std::isfinite(e.torque_quantum)) return;
  // (no shift computed, or no C_std to compare it with: the flag, the staircase being there)
  const double se = shiftSE(e, e.torque_quantisation_shift);
  if (std::isfinite(se) && !(se > L::kTorqueErrorShare)) return;
  // The DTE shows the steps' own free vibrations: the staircase is the load, not a quantiser's.
  const double fit = e.torque_quantisation_fit, fit_sd = e.torque_quantisation_fit_std;
  if (fit < 0.5 && 1.0 - fit > L::kStairsRealZ * fit_sd) return;
  const std::string effect =
      std::isfinite(se) ? "moved C by about " + num(e.torque_quantisation_shift) + " 1/s (" +
                              num(se) + " standard errors, > " + num(L::kTorqueErrorShare) +
                              "; estimated through the levels' crossings)"
                        : "moved C by an amount that could not be estimated";
  w->push_back({quality_code::kTorqueQuantised,
                "the torque is a staircase of levels " + num(e.torque_quantum) +
                    " N*m apart (quantised without dither), which the model takes as the load: "
                    "the rounding error " +
                    effect +
                    ": treat C as biased, or record the torque with finer resolution or dither"});
}

// information_concentrated: one segment holds most of the constant model's information about C
// (QualityLimits::kInformationShare).
void flagInformationConcentrated(const SegmentEstimate& e, QualityWarnings* w) {
  if (!(e.information_share > L::kInformationShare)) return;
  w->push_back(
      {quality_code::kInformationConcentrated,
       "the segment from t = " + num(e.information_t_start) + " to " + num(e.information_t_end) +
           " s holds " + num(100.0 * e.information_share) + " % of the information about C (> " +
           num(100.0 * L::kInformationShare) +
           " %): C is in effect that segment's damping (a start-up transient or a resonance "
           "crossing), and the test of one damping for every segment (variation_z) has little "
           "power elsewhere, so a damping that varies over the record need not show: --model "
           "piecewise gives each segment's C with its own standard error"});
}

// A segment found below the noise keeps no estimate: every number about C and the tests on it.
void clearEstimates(SegmentEstimate* e) {
  e->C = e->C_std = e->c = e->xi = kNaN;
  e->k_min = e->k_max = e->k_min_std = e->k_max_std = kNaN;
  e->C_integral = e->C_integral_std = kNaN;
  e->variation_z = e->C_mean_load = e->C_mean_load_std = e->shape_z = e->shape_shift = kNaN;
  e->variation_spread = e->switch_timing_shift = e->switch_timing_z = kNaN;
  e->switch_timing_power = kNaN;
  e->C_weighted = e->C_weighted_std = kNaN;
  e->C_torque_std = kNaN;
  e->torque_step = e->torque_step_time = e->torque_step_response = kNaN;
  e->torque_glitch = e->torque_glitch_time = e->torque_glitch_response = kNaN;
  e->torque_glitch_shift = e->torque_quantum = e->torque_quantisation_shift = kNaN;
  e->torque_glitches = 0;
  e->torque_quantisation_fit = e->torque_quantisation_fit_std = kNaN;
  e->information_share = e->information_t_start = e->information_t_end = kNaN;
  e->refined = false;
}

// Flags one identifiable estimate in place; `shared`: the constant model's C.
void flagEstimate(SegmentEstimate* e, bool shared) {
  if (!e->identifiable || !std::isfinite(e->C)) return;
  auto& w = e->warnings;
  eraseWarnings(&w, ownedCode);
  // Below the noise: C not significantly different from zero.
  const double max_rel = 1.0 / L::kSignificanceZ;
  if (std::isfinite(e->C_std) && !(e->C_std <= max_rel * std::abs(e->C))) {
    const std::string why = "below noise: C = " + num(e->C) + " +- " + num(e->C_std) +
                            " 1/s is not significantly different from zero (relative standard "
                            "error " +
                            num(e->C_std / std::abs(e->C)) + " > " + num(max_rel) +
                            "): the damping-sensitive part of the response is below the noise";
    e->identifiable = false;
    e->reason = why;
    clearEstimates(e);
    w.push_back({quality_code::kBelowNoise, why});
    return;
  }
  if (!(e->C > 0.0)) {
    w.push_back({quality_code::kNonpositiveDamping,
                 "C = " + num(e->C) + " 1/s <= 0: no physical damping fits the data"});
  }
  if (e->xi >= 1.0) {
    w.push_back({quality_code::kOverdamped, "damping ratio xi = " + num(e->xi) +
                                                " >= 1: an overdamped mesh is not plausible"});
  }
  const double bias_bound = std::sqrt(static_cast<double>(e->samples)) * e->C_std;
  if (std::isfinite(e->residual_rms) && std::isfinite(e->noise_std) &&
      std::isfinite(e->signal_std) && e->residual_rms > L::kMismatchNoiseRatio * e->noise_std &&
      (e->residual_rms > L::kMismatchGross * e->signal_std ||
       (e->residual_rms > L::kMismatchSignalFraction * e->signal_std &&
        !(bias_bound <= L::kMismatchBias * std::abs(e->C))))) {
    w.push_back({quality_code::kModelMismatch,
                 "the model does not reproduce the data: residual RMS " + num(e->residual_rms) +
                     " m is " + num(e->residual_rms / e->noise_std) + "x the noise estimate and " +
                     num(100.0 * e->residual_rms / e->signal_std) +
                     " % of the DTE's standard deviation; it can move C by up to " +
                     num(100.0 * bias_bound / std::abs(e->C)) +
                     " % (wrong stiffness shape, forcing or damping model?)"});
  }
  flagLoadStep(*e, &w);
  flagTorqueGlitch(*e, &w);
  flagTorqueQuantised(*e, &w);
  if (e->refined && std::isfinite(e->residuals.whitened_lag1) && e->samples > 0 &&
      e->residuals.rms > L::kWhitenessFloor * e->signal_std &&
      std::abs(e->residuals.whitened_lag1) >
          L::kWhitenessZ / std::sqrt(static_cast<double>(e->samples))) {
    w.push_back({quality_code::kResidualsNotWhite,
                 "the refinement's prewhitened residual has lag-1 autocorrelation " +
                     num(e->residuals.whitened_lag1) + " (white: within +-" +
                     num(L::kWhitenessZ / std::sqrt(static_cast<double>(e->samples))) +
                     "): the model leaves structure in the data, C_std understates the error"});
  }
  if (shared && e->refined) flagInformationConcentrated(*e, &w);
  if (shared && e->refined && e->variation_z > L::kVariationZ &&
      e->variation_spread > L::kVariationSpread) {
    w.push_back({quality_code::kDampingVaries,
                 "the damping is not the same in every segment: the test of one C per segment "
                 "against the shared C is " +
                     num(e->variation_z) + " standard errors beyond constancy (> " +
                     num(L::kVariationZ) + "), the segments' C spread by about " +
                     num(100.0 * e->variation_spread) +
                     " % rms beyond the noise (or some segments' model misfits: see their flags); "
                     "C is a weighted mean of the segments' damping and C_std leaves the "
                     "variation out: --model piecewise or load_law describe it"});
  }
  if (!shared && e->refined && e->residuals.rms > L::kWhitenessFloor * e->signal_std &&
      std::abs(e->variation_z) > L::kVariationZ) {
    w.push_back({quality_code::kDampingVaries,
                 "the damping varies with the load within the segment: a term C1 (T1 - mean T1) "
                 "is " +
                     num(e->variation_z) + " standard errors from zero (> " + num(L::kVariationZ) +
                     "); C is the damping at the segment's mean load, the constant-C fit (a "
                     "weighted mean of C(t)) gives " +
                     num(e->C_weighted) + " +- " + num(e->C_weighted_std) +
                     " 1/s; --model load_law describes the law"});
  }
  if (shapeJudged(*e) && std::abs(e->shape_z) > L::kShapeZ &&
      std::abs(e->shape_shift) > L::kShapeShift) {
    const bool curve = curveShape(*e);
    w.push_back({quality_code::kShapeMismatch,
                 std::string(curve ? "greybox stiffness shape: a finer curve (twice the table "
                                     "nodes or harmonics) fits better"
                                   : "greybox square levels: the data favour a stiffness that "
                                     "ramps around the mesh switches over one that switches at "
                                     "once") +
                     " (score " + num(e->shape_z) + " standard errors, > " + num(L::kShapeZ) +
                     "; fitted, " + (curve ? "the finer curve" : "the ramp") + " would move C by " +
                     num(100.0 * e->shape_shift) +
                     " %): " + (curve ? kCurveAdvice : kShapeAdvice)});
  }
  if (e->refined && std::isfinite(e->C_integral)) {
    // Like with like: the refinement's constant-C fit where C is the mean-load damping.
    const bool weighted = std::isfinite(e->C_weighted);
    const double C = weighted ? e->C_weighted : e->C;
    const double C_std = weighted ? e->C_weighted_std : e->C_std;
    const double se = std::hypot(C_std, std::isfinite(e->C_integral_std) ? e->C_integral_std : 0.0);
    const double d = std::abs(C - e->C_integral);
    if (!(d <= L::kDisagreeSE * se) && !(d <= L::kDisagreeRelative * std::abs(e->C_integral))) {
      w.push_back({quality_code::kRefineDisagrees,
                   std::string(weighted ? "refined constant-C fit " : "refined C ") + "= " +
                       num(C) + " 1/s and integral C = " + num(e->C_integral) + " 1/s differ by " +
                       num(se > 0.0 ? d / se : INFINITY) + " combined standard errors (> " +
                       num(L::kDisagreeSE) + ") and " + num(100.0 * d / std::abs(e->C_integral)) +
                       " % (> " + num(100.0 * L::kDisagreeRelative) + " %)"});
    }
  }
}

// The shape test of the record's segments together: their scores pooled, Z = sum z / sqrt(n),
// are N(0, 1) for a square-wave stiffness (the segments' noise is independent), while a ramp
// the test sees weakly in each segment adds up. Beyond kShapePooledZ each judged segment whose
// fitted ramp would move C by more than kShapeShift is flagged, and the run says so (the
// stiffness shape is the gear pair's, so the model is wrong for the whole record).
void flagPooledShape(IdentificationResult* r) {
  auto& rw = r->warnings;
  eraseCode(&rw, quality_code::kShapeMismatch);
  double sum = 0.0;
  long n = 0;
  for (const auto& e : r->segments) {
    if (shapeJudged(e)) sum += e.shape_z, ++n;
  }
  if (n < 2) return;
  const double Z = sum / std::sqrt(static_cast<double>(n));
  if (!(std::abs(Z) > L::kShapePooledZ)) return;
  const bool curve = std::any_of(r->segments.begin(), r->segments.end(),
                                 [](const SegmentEstimate& e) { return curveShape(e); });
  const std::string what = curve ? "greybox stiffness shape: " : "greybox square levels: ";
  const std::string advice = curve ? kCurveAdvice : kShapeAdvice;
  const std::string moved =
      curve ? ", its finer curve would move C by " : ", its fitted ramp would move C by ";
  const std::string pooled =
      "the record's " + std::to_string(n) +
      (curve ? " judged segments together favour a finer curve (twice the table nodes or "
               "harmonics; pooled shape score sum(shape_z)/sqrt(n) = " +
                   num(Z) + ", > " + num(L::kShapePooledZ) + ")"
             : " judged segments together favour a stiffness that ramps around "
               "the mesh switches (pooled shape score sum(shape_z)/sqrt(n) = " +
                   num(Z) + ", > " + num(L::kShapePooledZ) +
                   "; without mesh_phase, switches between samples do too)");
  long flagged = 0;
  for (auto& e : r->segments) {
    if (!shapeJudged(e) || !(std::abs(e.shape_shift) > L::kShapeShift)) continue;
    ++flagged;
    if (hasCode(e.warnings, quality_code::kShapeMismatch)) continue;
    e.warnings.push_back(
        {quality_code::kShapeMismatch, what + pooled + "; this segment's score " + num(e.shape_z) +
                                           moved + num(100.0 * e.shape_shift) + " %: " + advice});
  }
  if (flagged == 0) return;
  rw.push_back({quality_code::kShapeMismatch,
                what + pooled + "; " + std::to_string(flagged) + " segments whose " +
                    (curve ? "finer curve" : "fitted ramp") + " would move C by more than " +
                    num(100.0 * L::kShapeShift) + " % are flagged shape_mismatch: " + advice});
}

bool timingJudged(const SegmentEstimate& e) {
  return e.identifiable && e.refined && std::isfinite(e.switch_timing_shift) &&
         std::isfinite(e.switch_timing_z) && e.switch_timing_power > 0.0 && e.C_std > 0.0;
}

// Without mesh_phase each switch is held to the sample where the new value is first seen, late
// by delta half-samples on average over a segment's switches: 1 where they fall anywhere between
// samples, 0 where they lie on the samples, from 0 to 2 from segment to segment where the mesh
// period is close to a whole number of samples (the lateness then drifts). A segment's score z
// (switch_timing_z) has mean delta a (a = switch_timing_power), and its C is biased by about
// delta times its switch_timing_shift. The run's segments estimate delta together, sum(a z) /
// sum(a^2) with standard error 1 / sqrt(sum a^2); a segment is flagged where the bias at that
// estimate's upper bound (+ 2 SE), or, where its own score shows late switches (z beyond
// kShapeZ), at its own bound (z + 2) / a, exceeds kSwitchTimingShare C_std and kShapeShift of C.
// The run says how many.
void flagSwitchTiming(IdentificationResult* r) {
  auto& rw = r->warnings;
  eraseCode(&rw, quality_code::kSwitchTiming);
  double az = 0.0, aa = 0.0;
  for (const auto& e : r->segments) {
    if (!timingJudged(e)) continue;
    az += e.switch_timing_power * e.switch_timing_z;
    aa += e.switch_timing_power * e.switch_timing_power;
  }
  if (!(aa > 0.0)) return;
  const double pooled = az / aa, pooled_se = 1.0 / std::sqrt(aa);
  const std::string why =
      "the record has no mesh_phase, so each stiffness switch is placed at the sample where the "
      "new value is first seen, up to a sample late where it falls between samples; the run's "
      "segments put the switches " +
      num(pooled) + " +- " + num(pooled_se) +
      " half-samples earlier (0: on the samples, 1: anywhere between them)";
  const std::string advice =
      ": give mesh_phase (cumulative mesh cycles, e.g. from the encoders) to locate the switches";
  long flagged = 0;
  for (auto& e : r->segments) {
    if (!timingJudged(e)) continue;
    const double a = e.switch_timing_power, z = e.switch_timing_z;
    double up = std::max(0.0, pooled + 2.0 * pooled_se);
    if (z > L::kShapeZ) up = std::max(up, (z + 2.0) / a);
    const double shift = up * std::abs(e.switch_timing_shift);
    if (!(shift * std::abs(e.C) > L::kSwitchTimingShare * e.C_std && shift > L::kShapeShift))
      continue;
    ++flagged;
    e.warnings.push_back(
        {quality_code::kSwitchTiming,
         why + "; this segment's own residual puts them " + num(z / a) + " +- " + num(1.0 / a) +
             " half-samples earlier, and with every switch half a sample earlier its C moves "
             "by " +
             num(100.0 * e.switch_timing_shift) + " %, so C can be biased by up to " +
             num(shift * std::abs(e.C) / e.C_std) + " C_std" + advice});
  }
  if (flagged > 0) {
    rw.push_back({quality_code::kSwitchTiming,
                  why + "; " + std::to_string(flagged) +
                      " segments whose C can be biased by more than " + num(L::kSwitchTimingShare) +
                      " C_std by it are flagged switch_timing" + advice});
  }
}

// A shared damping (the constant model's C, the load law) is fitted to every identifiable
// segment, so a segment the model does not reproduce (model_mismatch: a load step, a speed or
// stiffness change inside it) biases the shared estimate of all of them. Measured (held-out
// 13139: Fourier stiffness, 250 kHz, a load step inside the segment at 10.8 ms): the load law
// was 1.8 % (10 standard errors) off at the high load, unflagged, while the piecewise fit of
// every other segment was exact. The run (and the constant estimate) says so, naming the first.
void flagSharedMismatch(IdentificationResult* r) {
  auto& rw = r->warnings;
  eraseCode(&rw, quality_code::kModelMismatch);
  if (!r->constant && !r->load_law) return;
  long n = 0, judged = 0;
  const SegmentEstimate* first = nullptr;
  for (const auto& e : r->segments) {
    if (!e.identifiable) continue;
    ++judged;
    if (!hasCode(e.warnings, quality_code::kModelMismatch)) continue;
    if (++n == 1) first = &e;
  }
  if (n == 0) return;
  const QualityWarning w{
      quality_code::kModelMismatch,
      std::to_string(n) + " of " + std::to_string(judged) +
          " segments are not reproduced by the model (flagged model_mismatch, the first from t = " +
          num(first->t_start) + " to " + num(first->t_end) + " s): the shared " +
          (r->load_law ? "load law" : "C") +
          " is fitted to them too and can be biased by them (a load step, a speed or stiffness "
          "change inside a segment): analyse the record without them (--t-start, --t-end), or "
          "use --model piecewise, where they do not affect the other segments"};
  rw.push_back(w);
  if (r->constant && r->constant->identifiable &&
      !hasCode(r->constant->warnings, quality_code::kModelMismatch))
    r->constant->warnings.push_back(w);
}

// The load law's test of one damping per segment against the law (output_error.cpp,
// sharedDampingTest): the damping is not linear in the load, or changes in time. Before it a
// damping piecewise in time gave a load law 5.8 standard errors off without a warning
// (held-out seed 13607). A run-level warning, as the law has none of its own.
void flagLoadLawVaries(IdentificationResult* r) {
  auto& rw = r->warnings;
  eraseCode(&rw, quality_code::kDampingVaries);
  if (!r->load_law || !r->load_law->identifiable) return;
  const LoadLawEstimate& l = *r->load_law;
  const bool varies = l.variation_z > L::kVariationZ && l.variation_spread > L::kVariationSpread;
  const bool curved =
      std::abs(l.curvature_z) > L::kVariationZ && l.curvature_spread > L::kVariationSpread;
  if (curved && !varies) {  // one warning: the general test's when both fire
    rw.push_back({quality_code::kDampingVaries,
                  "the damping is curved in the load: a term in T1^2 added to the load law is " +
                      num(l.curvature_z) + " standard errors from zero (> " + num(L::kVariationZ) +
                      "), departing from the line by up to about " +
                      num(100.0 * l.curvature_spread) +
                      " %: c0 and c1 are a weighted fit of a line to a curve, and their standard "
                      "errors leave that out: --model piecewise gives each segment's C (the "
                      "damping at its mean load)"});
    return;
  }
  if (!varies) return;
  rw.push_back({quality_code::kDampingVaries,
                "the damping is not linear in the load: the test of one C per segment against the "
                "load law is " +
                    num(l.variation_z) + " standard errors beyond the law (> " +
                    num(L::kVariationZ) + "), the segments' C depart from it by about " +
                    num(100.0 * l.variation_spread) +
                    " % rms beyond the noise (or some segments' model misfits: see their flags); "
                    "c0 and c1 are a weighted fit of a line to a damping that is not one, and "
                    "their standard errors leave that out: --model piecewise gives each segment's "
                    "C (the damping at its mean load)"});
}

}  // namespace

bool hasCode(const QualityWarnings& warnings, const std::string& code) {
  return std::any_of(warnings.begin(), warnings.end(),
                     [&](const QualityWarning& w) { return w.code == code; });
}

std::string joinCodes(const QualityWarnings& warnings, const std::string& sep) {
  std::string out;
  for (const auto& w : warnings) {
    if (!out.empty()) out += sep;
    out += w.code;
  }
  return out;
}

void applyQualityFlags(const IdentificationOptions& /*options*/, IdentificationResult* r) {
  for (auto& e : r->segments) flagEstimate(&e, false);
  if (r->constant) flagEstimate(&*r->constant, true);
  flagPooledShape(r);
  flagSwitchTiming(r);
  flagSharedMismatch(r);
  flagLoadLawVaries(r);
}

void flagIntegralStandardErrors(const IdentificationOptions& options, IdentificationResult* r) {
  auto& w = r->warnings;
  eraseCode(&w, quality_code::kIntegralStd);
  if (r->estimator != "integral") return;
  std::vector<double> rel;
  auto add = [&](const SegmentEstimate& e) {
    if (e.identifiable && !e.refined && std::isfinite(e.C_std) && e.C != 0.0)
      rel.push_back(std::abs(e.C_std / e.C));
  };
  for (const auto& e : r->segments) add(e);
  if (r->constant) add(*r->constant);
  if (rel.empty()) return;
  std::nth_element(rel.begin(), rel.begin() + rel.size() / 2, rel.end());
  const double median = rel[rel.size() / 2];
  std::ostringstream t;
  t << "C_std are the integral equations' standard errors (median C_std/|C| " << median;
  if (median > options.refine_threshold) {
    t << ", noisy data): the noise inside the integrals is not in them, so they understate the "
         "scatter (Table 1 case at 40 dB SNR: errors 1.8 times C_std, +-2 C_std covering 74 %)";
  } else {
    t << ", clean data): they measure the integral equations' residual only, while the "
         "method's quadrature error and damping that varies within a segment move C by more "
         "(noise-free held-out gears: up to 16 % of C, 54 C_std)";
  }
  t << "; the output-error refinement (--refine auto, known and greybox formulations) reports "
       "calibrated standard errors";
  w.push_back({quality_code::kIntegralStd, t.str()});
}

void keepIntegralEstimates(const IdentificationResult& integral, IdentificationResult* refined) {
  if (integral.segments.size() == refined->segments.size()) {
    for (size_t i = 0; i < integral.segments.size(); ++i) {
      SegmentEstimate& e = refined->segments[i];
      if (e.refined && std::isnan(e.C_integral)) {
        e.C_integral = integral.segments[i].C;
        e.C_integral_std = integral.segments[i].C_std;
      }
    }
  }
  if (integral.constant && refined->constant && refined->constant->refined &&
      std::isnan(refined->constant->C_integral)) {
    refined->constant->C_integral = integral.constant->C;
    refined->constant->C_integral_std = integral.constant->C_std;
  }
}

void UnstampedTorqueSpans::add(double t0, double t1, double gap) {
  if (!(t1 >= t0)) return;
  if (!spans_.empty() && t0 <= spans_.back().second + gap && t0 >= spans_.back().first) {
    spans_.back().second = std::max(spans_.back().second, t1);
    return;
  }
  auto at = std::lower_bound(spans_.begin(), spans_.end(), std::make_pair(t0, t1));
  spans_.insert(at, {t0, t1});
  if (spans_.size() > kMaxSpans) spans_.erase(spans_.begin());
}

bool UnstampedTorqueSpans::overlaps(double t0, double t1) const {
  for (const auto& s : spans_)
    if (s.first <= t1 && t0 <= s.second) return true;
  return false;
}

void UnstampedTorqueSpans::mark(IdentificationResult* result) const {
  for (SegmentEstimate& e : result->segments) mark(&e);
}

void UnstampedTorqueSpans::mark(SegmentEstimate* e) const {
  if (spans_.empty() || !overlaps(e->t_start, e->t_end) ||
      hasCode(e->warnings, quality_code::kTorqueUnstamped))
    return;
  e->warnings.push_back(
      {quality_code::kTorqueUnstamped,
       "the torque was paired with the joint states without time stamps (std_msgs/Float64): "
       "C can be biased by the pairing's lag (measured up to 10 %); use "
       "geometry_msgs/WrenchStamped"});
}

}  // namespace gear_damping_id
