// Segment-by-segment identification for the live node (see live_identification.hpp).
#include "gear_damping_id/live_identification.hpp"

#include <algorithm>
#include <cmath>

#include "gear_damping_id/input_checks.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/stream_assembler.hpp"

namespace gear_damping_id {

LiveIdentification::LiveIdentification(const IdentificationOptions& options,
                                       const GearConstants& gear, const LiveLimits& limits)
    : options_(options),
      gear_(gear),
      limits_(limits),
      method_(options, gear),
      newer_(options, gear),
      single_(options, gear) {
  limits_.history_segments = std::max<size_t>(limits_.history_segments, 1);
  limits_.shared_segments = std::max<size_t>(limits_.shared_segments, 1);
}

void LiveIdentification::reset() {
  method_.reset();
  newer_.reset();
  single_.reset();
  segments_.clear();
  shared_ = IdentificationResult();
  k_time_ = duration_ = 0.0;
  added_ = 0;
}

LiveIdentification::SegmentOutput LiveIdentification::add(const SignalView& v, Eigen::Index begin,
                                                          Eigen::Index end, bool refine_allowed) {
  SegmentOutput out;
  SegmentEstimate& est = out.estimate;
  IdentificationResult& seg = out.result;
  seg.formulation = options_.formulation;
  seg.model = options_.model;
  const std::string missing = missingChannel(v, options_.formulation, options_.model);
  if (!missing.empty() || end - begin < 1) {
    est.t_start = v.time(begin);
    est.t_end = v.time(std::max(begin, end - 1)) + v.dt;
    est.samples = static_cast<long>(end - begin);
    est.reason = end - begin < 1
                     ? "too few samples (0 in the segment)"
                     : "missing channel " + missing + " (needed by " +
                           toString(options_.formulation) + "/" + toString(options_.model) + ")";
    seg.segments.push_back(est);
  } else if (options_.model == DampingModel::Piecewise) {
    single_.reset();
    single_.addSegment(v, begin, end);
    seg = single_.finish();
    // omega0 of the segments so far (as IntegralMethod::finish over all of them): the
    // duration-weighted mean of each segment's mean normalised stiffness omega0_i^2.
    if (seg.segments.size() == 1 && seg.segments[0].identifiable && std::isfinite(seg.omega0)) {
      const double t = static_cast<double>(seg.segments[0].samples) * v.dt;
      k_time_ += seg.omega0 * seg.omega0 * t;
      duration_ += t;
    }
    applyQualityFlags(options_, &seg);  // below-noise segments are not refined (as identify())
    const bool wants = seg.segments.size() == 1 && seg.segments[0].identifiable &&
                       options_.refinable() && wantsRefinement(options_, seg);
    if (wants && !refine_allowed) {
      out.refinement_skipped = true;
    } else if (wants) {
      IdentificationResult refined = seg;
      std::string why;
      if (refineOutputError(v, {{begin, end}}, gear_, options_, &refined, &why)) {
        keepIntegralEstimates(seg, &refined);
        seg = std::move(refined);
      } else {
        out.warning = "output-error refinement failed (" + why + "): integral estimate kept";
        seg.warnings.push_back({quality_code::kRefineFailed, out.warning});
      }
    }
    applyQualityFlags(options_, &seg);
    if (!seg.segments.empty()) est = seg.segments.front();
  } else {
    // Sliding problem: method_ holds the older segments, newer_ the latest ones (both get every
    // segment); when newer_ reaches shared_segments it replaces method_ and starts over.
    method_.addSegment(v, begin, end);
    newer_.addSegment(v, begin, end);
    shared_ = method_.finish();
    applyQualityFlags(options_, &shared_);
    if (newer_.segmentCount() >= limits_.shared_segments) {
      std::swap(method_, newer_);
      newer_.reset();
    }
    est = shared_.segments.back();
    seg = shared_;
    seg.segments = {est};
    seg.constant.reset();  // this segment, with the current shared value
    seg.windows.clear();
    for (const auto& w : shared_.windows) {
      if (w.t_start >= est.t_start - 0.5 * v.dt && w.t_start < est.t_end) seg.windows.push_back(w);
    }
  }
  segments_.push_back(est);
  while (segments_.size() > limits_.history_segments) segments_.pop_front();
  ++added_;
  return out;
}

IdentificationResult LiveIdentification::cumulative(size_t last) const {
  const size_t n = std::min(last, segments_.size());
  const auto first = segments_.end() - static_cast<std::ptrdiff_t>(n);
  if (options_.model != DampingModel::Piecewise) {
    IdentificationResult r = shared_;
    r.formulation = options_.formulation;
    r.model = options_.model;
    r.windows.clear();
    // The kept segments, with the latest shared solve where it covers them (segments that never
    // reached the method, e.g. a missing channel, are listed as they were reported).
    std::vector<SegmentEstimate> all;
    all.reserve(n);
    size_t k = 0;
    for (auto it = first; it != segments_.end(); ++it) {
      while (k < r.segments.size() && r.segments[k].t_start < it->t_start - 1e-12) ++k;
      const bool in_method =
          k < r.segments.size() && std::abs(r.segments[k].t_start - it->t_start) < 1e-12;
      all.push_back(in_method ? r.segments[k++] : *it);
    }
    r.segments = std::move(all);
    return r;
  }
  IdentificationResult r;
  r.formulation = options_.formulation;
  r.model = options_.model;
  r.equivalent_mass = gear_.equivalent_mass;
  r.window_length = single_.windowLength();
  r.omega0 = duration_ > 0.0 && k_time_ > 0.0
                 ? std::sqrt(k_time_ / duration_)
                 : std::sqrt(gear_.mean_stiffness / gear_.equivalent_mass);
  r.segments.assign(first, segments_.end());
  if (std::isfinite(r.omega0) && r.omega0 > 0.0) {
    for (auto& e : r.segments) {
      if (e.identifiable) e.xi = e.C / (2.0 * r.omega0);
    }
  }
  applyQualityFlags(options_, &r);  // xi changed with the cumulative omega0
  return r;
}

}  // namespace gear_damping_id
