// SegmentDriver's STE mode (segment_driver.hpp, docs/ste.md "The STE in the segment pipeline"):
// a joint calibration of the STE on the first segments, then every segment fitted given it.
#include <algorithm>
#include <cmath>

#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/segment_driver.hpp"

namespace gear_damping_id {

namespace {

// The segment [begin, end) of `v` with up to kStencilContext samples either side, as its own view.
SignalView contextView(const SignalView& v, Eigen::Index begin, Eigen::Index end,
                       Eigen::Index* offset) {
  const Eigen::Index lo = std::max<Eigen::Index>(begin - kStencilContext, 0);
  const Eigen::Index hi = std::min<Eigen::Index>(end + kStencilContext, v.n);
  SignalView s = v;
  s.t0 = v.time(lo);
  s.n = hi - lo;
  const double** cols[5] = {&s.dte, &s.stiffness, &s.torque, &s.mesh_state, &s.mesh_phase};
  for (const double** c : cols)
    if (*c != nullptr) *c += lo;
  *offset = lo;
  return s;
}

std::string pendingReason(size_t have, size_t need, double cycles, double need_cycles) {
  std::string r = "awaiting the STE calibration (" + std::to_string(have) + " of at least " +
                  std::to_string(need) + " segments";
  if (need_cycles > 0.0)
    r += ", " + std::to_string(static_cast<long>(cycles)) + " of " +
         std::to_string(static_cast<long>(need_cycles)) +
         " mesh cycles: a revolution of each shaft whose orders are modelled";
  return r + ")";
}

}  // namespace

gear_sim::Status SegmentDriver::setSte(const SteModelOptions& ste, size_t calibration_segments) {
  if (gear_sim::Status s = ste.check(); !s.ok()) return s;
  if (gear_sim::Status s = checkSteOptions(options_); !s.ok()) return s;
  ste_on_ = true;
  ste_options_ = ste;
  ste_calibration_ = options_.model == DampingModel::Constant
                         ? std::numeric_limits<size_t>::max()
                         : std::max<size_t>(calibration_segments, 1);
  shared_ = false;  // the STE path handles the constant model's shared C itself
  return {};
}

// Mesh cycles the calibration must span: one revolution of each shaft whose orders are
// modelled (Z mesh cycles), else none. A shorter span cannot tell a shaft order from the offset
// and a trend (docs/ste.md "Separability").
double SegmentDriver::calibrationCycles() const {
  double z = 0.0;
  if (ste_options_.pinion_orders > 0)
    z = std::max(z, static_cast<double>(ste_options_.pinion_teeth));
  if (ste_options_.gear_orders > 0) z = std::max(z, static_cast<double>(ste_options_.gear_teeth));
  return z;
}

bool SegmentDriver::calibrationComplete() const {
  return calib_.ranges.size() >= ste_calibration_ &&
         calib_.phase_max - calib_.phase_min >= calibrationCycles();
}

void SegmentDriver::bufferCalibrationSegment(const SignalView& v, Eigen::Index begin,
                                             Eigen::Index end) {
  Calibration& c = calib_;
  const Eigen::Index lo = std::max<Eigen::Index>(begin - kStencilContext, 0);
  const Eigen::Index hi = std::min<Eigen::Index>(end + kStencilContext, v.n);
  if (c.next_abs < 0) {
    c.origin = v.time(lo);
    c.t0 = c.origin;
    c.dt = v.dt;
  }
  // Record sample numbers from the first view's time axis (views of one record share it).
  const auto abs = [&](Eigen::Index i) { return std::llround((v.time(i) - c.origin) / c.dt); };
  const double* src[5] = {v.dte, v.stiffness, v.torque, v.mesh_state, v.mesh_phase};
  Eigen::Index from = lo;  // contiguous with the buffer: append only the new samples
  if (c.next_abs >= 0 && abs(lo) <= c.next_abs && abs(hi) > c.next_abs)
    from = lo + static_cast<Eigen::Index>(c.next_abs - abs(lo));
  const Eigen::Index buffer_lo = static_cast<Eigen::Index>(c.col[0].size()) - (from - lo);
  for (int k = 0; k < 5; ++k) {
    c.present[k] = src[k] != nullptr;
    if (src[k] != nullptr) c.col[k].insert(c.col[k].end(), src[k] + from, src[k] + hi);
  }
  c.next_abs = abs(hi);
  c.ranges.emplace_back(buffer_lo + (begin - lo), buffer_lo + (end - lo));
  for (Eigen::Index i = begin; i < end; ++i) {
    c.phase_min = std::min(c.phase_min, v.mesh_phase[i]);
    c.phase_max = std::max(c.phase_max, v.mesh_phase[i]);
  }
  c.times.emplace_back(v.time(begin), v.time(end - 1));
  c.added_at.push_back(added_);
}

// The joint fit of the buffered segments; their kept estimates and the run summary are replaced
// by its results, and the buffer is released.
void SegmentDriver::calibrate() {
  Calibration& c = calib_;
  ste_ready_ = true;
  if (c.ranges.empty()) return;
  SignalView v;
  v.t0 = c.t0;
  v.dt = c.dt;
  v.n = static_cast<Eigen::Index>(c.col[0].size());
  const double** dst[5] = {&v.dte, &v.stiffness, &v.torque, &v.mesh_state, &v.mesh_phase};
  for (int k = 0; k < 5; ++k) *dst[k] = c.present[k] ? c.col[k].data() : nullptr;
  IdentificationResult joint;
  const gear_sim::Status calibrated =
      identifySteSegments(v, c.ranges, gear_, options_, ste_options_, &joint, &ste_);
  const bool ok = calibrated.ok();
  if (!ok || joint.segments.size() != c.ranges.size()) {
    ste_ = SteResult{};  // no STE to hold: later segments are reported not identifiable
    ste_.options = ste_options_;
    const std::string why = ok ? "a calibration segment has too few samples" : calibrated.message();
    for (auto& s : joint.segments) s = SegmentEstimate();
    joint.segments.resize(c.ranges.size());
    for (auto& s : joint.segments) s.reason = "STE calibration failed: " + why;
  }
  for (size_t i = 0; i < c.ranges.size(); ++i) {
    SegmentEstimate& e = joint.segments[i];
    e.t_start = c.times[i].first;
    e.t_end = c.times[i].second;
    if (!ok) e.samples = static_cast<long>(c.ranges[i].second - c.ranges[i].first);
  }
  if (joint.constant) {
    joint.constant->t_start = joint.segments.front().t_start;
    joint.constant->t_end = joint.segments.back().t_end;
  }
  // Each calibration segment recorded as if added now (run summary), its kept entry replaced.
  const size_t n_cal = c.ranges.size();
  for (size_t i = 0; i < n_cal; ++i) {
    SegmentOutput out;
    out.result = joint;
    out.result.segments = {joint.segments[i]};
    out.result.constant.reset();
    if (i > 0) out.result.warnings.clear();  // the record's warnings once
    const SegmentEstimate& e = joint.segments[i];
    out.result.omega0 = e.identifiable && e.xi != 0.0 ? e.C / (2.0 * e.xi) : joint.omega0;
    out.estimate = e;
    const unsigned long back = added_ - c.added_at[i];
    recordPiecewise(out, 0, c.dt, /*keep_estimate=*/false);
    if (back <= kept_.size()) kept_[kept_.size() - back] = {e, {}};
  }
  if (joint.constant) shared_solve_ = joint;
  ste_calibrated_ = {n_cal, c.times.front().first, c.times.back().second};
  c = Calibration();
}

SegmentDriver::SegmentOutput SegmentDriver::heldSteSegment(const SignalView& v, Eigen::Index begin,
                                                           Eigen::Index end,
                                                           bool refine_allowed) const {
  SegmentOutput out;
  Eigen::Index lo = 0;
  const SignalView s = contextView(v, begin, end, &lo);
  IdentificationOptions o = options_;
  if (!refine_allowed && o.refine != IdentificationOptions::Refine::Never) {
    o.refine = IdentificationOptions::Refine::Never;
    out.refinement_skipped = true;
  }
  const bool held = !ste_.theta.empty() && ste_.theta_cov.size() != 0 && ste_.theta_cov.allFinite();
  const gear_sim::Status fit =
      held ? identifySegmentWithHeldSte(s, begin - lo, end - lo, gear_, o, ste_, &out.result)
           : gear_sim::Status::notIdentifiable("no STE to hold (the calibration gave none)");
  if (!fit.ok()) {
    out.result = unusableSegment(v, begin, end).result;
    out.result.segments[0].reason = ste_.theta.empty() || !ste_.theta_cov.allFinite()
                                        ? "no STE to hold (the calibration gave none)"
                                        : "held-STE fit failed: " + fit.message();
  }
  SegmentEstimate& e = out.result.segments[0];
  e.t_start = v.time(begin);
  e.t_end = v.time(end - 1);
  if (e.identifiable && !ste_.separable)  // the held STE carries its calibration's flag
    e.warnings.push_back({quality_code::kSteNotSeparable,
                          "the STE held here was not separable from the damping on its "
                          "calibration span"});
  out.estimate = e;
  return out;
}

SegmentDriver::SegmentOutput SegmentDriver::addSte(const SignalView& v, Eigen::Index begin,
                                                   Eigen::Index end, bool refine_allowed) {
  std::string missing = checkChannels(v, options_.formulation, options_.model).field();
  if (missing.empty() && (v.mesh_phase == nullptr || v.torque == nullptr))
    missing = v.mesh_phase == nullptr ? "mesh_phase" : "torque";
  Eigen::Index lo = 0;
  const bool unusable =
      end - begin < 8 || !missing.empty() ||
      nonFiniteSteInput(contextView(v, begin, end, &lo), options_.formulation) >= 0;
  if (unusable) {
    SegmentOutput out = unusableSegment(v, begin, end);
    if (missing.empty())
      out.result.segments[0].reason = end - begin < 8
                                          ? "too few samples for the STE fit (fewer than 8)"
                                          : "non-finite input (the STE fit needs clean samples)";
    else
      out.result.segments[0].reason = "missing channel " + missing + " (needed by the STE model)";
    out.estimate = out.result.segments[0];
    keep({out.estimate, {}});
    return out;
  }
  if (ste_ready_) {
    SegmentOutput out = heldSteSegment(v, begin, end, refine_allowed);
    recordPiecewise(out, 0, v.dt);
    return out;
  }
  bufferCalibrationSegment(v, begin, end);
  SegmentOutput out = unusableSegment(v, begin, end);
  SegmentEstimate& e = out.result.segments[0];
  e.t_end = v.time(end - 1);
  e.reason = pendingReason(calib_.ranges.size(), ste_calibration_,
                           calib_.phase_max - calib_.phase_min, calibrationCycles());
  out.estimate = e;
  out.ste_pending = true;
  keep({e, {}});
  if (calibrationComplete()) {
    out.ste_pending = false;
    calibrate();
    out.estimate = kept_.back().estimate;
    out.result.segments = {out.estimate};
  }
  return out;
}

}  // namespace gear_damping_id
