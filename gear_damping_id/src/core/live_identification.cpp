// Segment-by-segment identification for the live node (see live_identification.hpp).
#include "gear_damping_id/live_identification.hpp"

#include <cmath>

#include "gear_damping_id/input_checks.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/stream_assembler.hpp"

namespace gear_damping_id {

LiveIdentification::LiveIdentification(const IdentificationOptions& options,
                                       const GearConstants& gear)
    : options_(options), gear_(gear), method_(options, gear), single_(options, gear) {}

void LiveIdentification::reset() {
  method_.reset();
  single_.reset();
  segments_.clear();
  shared_ = IdentificationResult();
}

LiveIdentification::SegmentOutput LiveIdentification::add(const SignalView& v, Eigen::Index begin,
                                                          Eigen::Index end) {
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
    applyQualityFlags(options_, &seg);  // below-noise segments are not refined (as identify())
    if (seg.segments.size() == 1 && seg.segments[0].identifiable && options_.refinable() &&
        wantsRefinement(options_, seg)) {
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
    method_.addSegment(v, begin, end);  // for the cumulative omega0 (xi), as offline
  } else {
    method_.addSegment(v, begin, end);
    shared_ = method_.finish();
    applyQualityFlags(options_, &shared_);
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
  return out;
}

IdentificationResult LiveIdentification::cumulative() const {
  if (options_.model != DampingModel::Piecewise) {
    IdentificationResult r = shared_;
    r.formulation = options_.formulation;
    r.model = options_.model;
    // Segments that never reached the method (missing channels) are listed too, in order.
    if (r.segments.size() != segments_.size()) {
      std::vector<SegmentEstimate> all;
      size_t k = 0;
      for (const auto& e : segments_) {
        const bool in_method =
            k < r.segments.size() && std::abs(r.segments[k].t_start - e.t_start) < 1e-12;
        all.push_back(in_method ? r.segments[k++] : e);
      }
      r.segments = std::move(all);
    }
    return r;
  }
  IdentificationResult r = method_.segmentCount() > 0 ? method_.finish() : IdentificationResult();
  r.formulation = options_.formulation;
  r.model = options_.model;
  r.segments = segments_;
  if (std::isfinite(r.omega0) && r.omega0 > 0.0) {
    for (auto& e : r.segments) {
      if (e.identifiable) e.xi = e.C / (2.0 * r.omega0);
    }
  }
  applyQualityFlags(options_, &r);  // xi changed with the cumulative omega0
  return r;
}

}  // namespace gear_damping_id
