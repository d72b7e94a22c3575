// The one segment pipeline of batch, streamed and live identification (see segment_driver.hpp).
#include "gear_damping_id/segment_driver.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <mutex>
#include <thread>

#include "gear_damping_id/damping_units.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/stream_assembler.hpp"

namespace gear_damping_id {

namespace {

bool sharedUnknowns(const IdentificationOptions& o) {
  return o.model != DampingModel::Piecewise || o.formulation == Formulation::Legacy;
}

// Runs work(i) for i in [0, n) on `threads` threads, the calling thread being worker 0 (work
// items claimed in order; each result is stored by index, so the outcome does not depend on the
// scheduling).
void parallelFor(size_t n, int threads, const std::function<void(size_t, int)>& work) {
  const int t = static_cast<int>(std::min<size_t>(static_cast<size_t>(std::max(threads, 1)), n));
  if (t <= 1) {
    for (size_t i = 0; i < n; ++i) work(i, 0);
    return;
  }
  std::atomic<size_t> next{0};
  auto claim = [&](int w) {
    for (size_t i = next++; i < n; i = next++) work(i, w);
  };
  std::vector<std::thread> pool;
  for (int w = 1; w < t; ++w) pool.emplace_back(claim, w);
  claim(0);
  for (auto& th : pool) th.join();
}

}  // namespace

SegmentDriver::SegmentDriver(const IdentificationOptions& options, const GearConstants& gear,
                             const DriverLimits& limits)
    : options_(options),
      gear_(gear),
      limits_(limits),
      shared_(sharedUnknowns(options)),
      method_(options, gear),
      newer_(options, gear) {
  limits_.history_segments = std::max<size_t>(limits_.history_segments, 1);
  limits_.shared_segments = std::max<size_t>(limits_.shared_segments, 1);
  limits_.threads = std::max(limits_.threads, 1);
}

void SegmentDriver::setLegacyForcing(double fbar) {
  legacy_fbar_ = fbar;
  method_.setLegacyForcing(fbar);
  newer_.setLegacyForcing(fbar);
}

void SegmentDriver::reset() {
  method_.reset();
  newer_.reset();
  kept_.clear();
  shared_solve_ = IdentificationResult();
  k_time_ = duration_ = 0.0;
  unlocated_ = 0;
  run_warnings_.clear();
  run_warning_count_.clear();
  iterations_ = 0;
  noise_sq_ = innovation_sq_ = noise_samples_ = 0.0;
  added_ = 0;
  ste_ready_ = false;
  ste_ = SteResult();
  ste_calibrated_ = SteCalibration();
  calib_ = Calibration();
}

IntegralMethod SegmentDriver::newMethod() const {
  IntegralMethod m(options_, gear_);
  if (std::isfinite(legacy_fbar_)) m.setLegacyForcing(legacy_fbar_);
  return m;
}

void SegmentDriver::resolveWindow(const SignalView& v) {
  if (options_.window_length > 0.0) return;
  options_.window_length = defaultWindowLength(v, gear_);
  method_ = IntegralMethod(options_, gear_);
  newer_ = IntegralMethod(options_, gear_);
  if (std::isfinite(legacy_fbar_)) setLegacyForcing(legacy_fbar_);
}

void SegmentDriver::keep(Kept k) {
  kept_.push_back(std::move(k));
  while (kept_.size() > limits_.history_segments) kept_.pop_front();
  ++added_;
}

SegmentDriver::SegmentOutput SegmentDriver::unusableSegment(const SignalView& v, Eigen::Index begin,
                                                            Eigen::Index end) const {
  SegmentOutput out;
  SegmentEstimate& est = out.estimate;
  est.t_start = v.time(begin);
  est.t_end = v.time(std::max(begin, end - 1)) + v.dt;
  est.samples = static_cast<long>(std::max<Eigen::Index>(end - begin, 0));
  const std::string missing = checkChannels(v, options_.formulation, options_.model).field();
  est.reason = end - begin < 1
                   ? "too few samples (0 in the segment)"
                   : "missing channel " + missing + " (needed by " +
                         toString(options_.formulation) + "/" + toString(options_.model) + ")";
  out.result.formulation = options_.formulation;
  out.result.model = options_.model;
  out.result.stiffness_shape = options_.stiffness_shape;
  out.result.equivalent_mass = gear_.equivalent_mass;
  out.result.segments.push_back(est);
  return out;
}

// ---------------------------------------------------------------------------------------------
// Piecewise: every segment its own problem.

SegmentDriver::SegmentOutput SegmentDriver::piecewiseSegment(IntegralMethod* m, const SignalView& v,
                                                             Eigen::Index begin, Eigen::Index end,
                                                             bool refine_allowed) const {
  SegmentOutput out;
  IdentificationResult& seg = out.result;
  m->reset();
  m->addSegment(v, begin, end, /*estimate=*/false);
  seg = m->finish();
  seg.warnings.clear();  // switches_unlocated: counted by the driver (recordPiecewise)
  // Below-noise segments are not identifiable before the refinement (which leaves them alone).
  applyQualityFlags(options_, &seg);
  const bool wants =
      seg.segments.size() == 1 && seg.segments[0].identifiable && wantsRefinement(options_);
  if (wants && !options_.refinable()) {
    seg.warnings.push_back(
        {quality_code::kRefineSkipped,
         "output-error refinement skipped: not available for the greybox stiffness shape " +
             toString(options_.stiffness_shape) + " (integral-method estimates reported)"});
  } else if (wants && !refine_allowed) {
    out.refinement_skipped = true;
  } else if (wants) {
    IdentificationResult refined = seg;
    if (const gear_sim::Status refine =
            refineOutputError(v, {{begin, end}}, gear_, options_, &refined);
        refine.ok()) {
      keepIntegralEstimates(seg, &refined);
      seg = std::move(refined);
    } else {
      out.warning =
          "output-error refinement failed (" + refine.message() + "): integral estimate kept";
      seg.warnings.push_back({quality_code::kRefineFailed, out.warning});
    }
  }
  applyQualityFlags(options_, &seg);
  if (!seg.segments.empty()) out.estimate = seg.segments.front();
  return out;
}

void SegmentDriver::recordPiecewise(SegmentOutput&& out, long unlocated, double dt) {
  recordPiecewise(out, unlocated, dt, /*keep_estimate=*/false);
  keep({std::move(out.estimate), std::move(out.result.windows)});
}

void SegmentDriver::recordPiecewise(const SegmentOutput& out, long unlocated, double dt,
                                    bool keep_estimate) {
  const IdentificationResult& seg = out.result;
  unlocated_ += unlocated;
  // omega0 of the record: the duration-weighted mean of the segments' mean stiffness.
  if (seg.segments.size() == 1 && seg.segments[0].identifiable && std::isfinite(seg.omega0)) {
    const double t = static_cast<double>(seg.segments[0].samples) * dt;
    k_time_ += seg.omega0 * seg.omega0 * t;
    duration_ += t;
  }
  for (const auto& w : seg.warnings) {
    size_t k = 0;
    while (k < run_warnings_.size() && run_warnings_[k].code != w.code) ++k;
    if (k == run_warnings_.size()) {
      run_warnings_.push_back(w);
      run_warning_count_.push_back(0);
    }
    ++run_warning_count_[k];
  }
  if (seg.estimator == "output_error" && !seg.segments.empty() && seg.segments[0].refined) {
    iterations_ += seg.iterations;
    const double n = static_cast<double>(seg.segments[0].samples);
    noise_sq_ += seg.noise_std * seg.noise_std * n;
    innovation_sq_ += seg.noise_innovation_std * seg.noise_innovation_std * n;
    noise_samples_ += n;
  }
  if (keep_estimate) keep({out.estimate, seg.windows});
}

// addAll's record of a segment done by a worker: as addOne records it (consume: moved into the
// kept history, and the output's one-segment list freed by the recorder, not by the serial end).
void SegmentDriver::recordParallelOutput(SegmentOutput* out,
                                         const std::pair<Eigen::Index, Eigen::Index>& range,
                                         long unlocated, double dt, bool outputs) {
  if (range.second - range.first < 1) {
    keep({out->estimate, {}});
  } else if (outputs) {
    recordPiecewise(*out, unlocated, dt);
  } else {
    recordPiecewise(std::move(*out), unlocated, dt);
    std::vector<SegmentEstimate>().swap(out->result.segments);  // (its heap block freed here)
  }
}

IdentificationResult SegmentDriver::piecewiseResult(size_t last) const {
  IdentificationResult r;
  r.formulation = options_.formulation;
  r.model = options_.model;
  r.stiffness_shape = options_.stiffness_shape;
  r.equivalent_mass = gear_.equivalent_mass;
  r.window_length = options_.window_length;
  r.omega0 = duration_ > 0.0 && k_time_ > 0.0
                 ? std::sqrt(k_time_ / duration_)
                 : std::sqrt(gear_.mean_stiffness / gear_.equivalent_mass);
  const size_t n = std::min(last, kept_.size());
  const auto first = kept_.end() - static_cast<std::ptrdiff_t>(n);
  size_t windows = 0;
  for (auto it = first; it != kept_.end(); ++it) windows += it->windows.size();
  r.segments.reserve(n);
  r.windows.reserve(windows);
  for (auto it = first; it != kept_.end(); ++it) {
    r.segments.push_back(it->estimate);
    r.windows.insert(r.windows.end(), it->windows.begin(), it->windows.end());
  }
  // (The STE fits give each segment's xi with its own omega0, as identifyWithSte does.)
  if (std::isfinite(r.omega0) && r.omega0 > 0.0 && !ste_on_) {
    for (auto& e : r.segments)
      if (e.identifiable) e.xi = ratioFromC(e.C, r.omega0);
  }
  if (noise_samples_ > 0.0) {
    r.estimator = "output_error";
    r.iterations = iterations_;
    r.noise_std = std::sqrt(noise_sq_ / noise_samples_);
    r.noise_innovation_std = std::sqrt(innovation_sq_ / noise_samples_);
  }
  for (size_t k = 0; k < run_warnings_.size(); ++k) {
    QualityWarning w = run_warnings_[k];
    if (run_warning_count_[k] > 1)
      w.text += " (" + std::to_string(run_warning_count_[k]) + " segments)";
    r.warnings.push_back(w);
  }
  if (unlocated_ > 0) r.warnings.push_back(switchesUnlocatedWarning(unlocated_));
  if (ste_on_) {  // segment_driver_ste.cpp
    r.estimator = ste_.refined ? "output_error_ste" : "integral_ste";
    if (shared_solve_.constant) r.constant = shared_solve_.constant;
  }
  applyQualityFlags(options_, &r);  // xi changed with the record's omega0
  return r;
}

// ---------------------------------------------------------------------------------------------
// Shared unknowns: normal equations accumulated, solved when a result is formed.

SegmentDriver::SegmentOutput SegmentDriver::addShared(const SignalView& v, Eigen::Index begin,
                                                      Eigen::Index end) {
  SegmentOutput out;
  const bool sliding = limits_.shared_segments != std::numeric_limits<size_t>::max();
  out.estimate = method_.addSegment(v, begin, end, /*estimate=*/false);
  if (sliding) newer_.addSegment(v, begin, end, /*estimate=*/false);
  if (limits_.solve_shared_each_segment) {
    shared_solve_ = method_.finish();
    applyQualityFlags(options_, &shared_solve_);
    out.estimate = shared_solve_.segments.back();
    IdentificationResult& seg = out.result;
    seg = shared_solve_;
    seg.segments = {out.estimate};
    seg.constant.reset();  // this segment, with the current shared value
    seg.windows.clear();
    for (const auto& w : shared_solve_.windows) {
      if (w.t_start >= out.estimate.t_start - 0.5 * v.dt && w.t_start < out.estimate.t_end)
        seg.windows.push_back(w);
    }
  } else {
    out.result.formulation = options_.formulation;
    out.result.model = options_.model;
    out.result.stiffness_shape = options_.stiffness_shape;
    out.result.segments = {out.estimate};
  }
  // Sliding problem: method_ holds the older segments, newer_ the latest ones (both get every
  // segment); when newer_ reaches shared_segments it replaces method_ and starts over.
  if (sliding && newer_.segmentCount() >= limits_.shared_segments) {
    std::swap(method_, newer_);
    newer_.reset();
  }
  keep({out.estimate, {}});
  return out;
}

void SegmentDriver::addSharedParallel(const SignalView& v, const SampleRanges& ranges) {
  // Contiguous blocks of segments, one integral-method object each, appended in order.
  const size_t blocks = std::min<size_t>(static_cast<size_t>(limits_.threads), ranges.size());
  std::vector<IntegralMethod> parts;
  for (size_t b = 0; b < blocks; ++b) parts.push_back(newMethod());
  std::vector<std::vector<SegmentEstimate>> estimates(blocks);
  parallelFor(blocks, limits_.threads, [&](size_t b, int) {
    const size_t lo = ranges.size() * b / blocks, hi = ranges.size() * (b + 1) / blocks;
    for (size_t i = lo; i < hi; ++i)
      estimates[b].push_back(
          parts[b].addSegment(v, ranges[i].first, ranges[i].second, /*estimate=*/false));
  });
  for (size_t b = 0; b < blocks; ++b) {
    method_.append(std::move(parts[b]));
    for (auto& e : estimates[b]) keep({std::move(e), {}});
  }
}

IdentificationResult SegmentDriver::sharedResult(size_t last) const {
  IdentificationResult r = limits_.solve_shared_each_segment ? shared_solve_ : method_.finish();
  if (!limits_.solve_shared_each_segment) applyQualityFlags(options_, &r);
  r.formulation = options_.formulation;
  r.model = options_.model;
  r.stiffness_shape = options_.stiffness_shape;
  // The kept segments, with the latest shared solve where it covers them (segments that never
  // reached the method, e.g. a missing channel, are listed as they were reported).
  const size_t n = std::min(last, kept_.size());
  std::vector<SegmentEstimate> all;
  all.reserve(n);
  size_t k = 0;
  for (auto it = kept_.end() - static_cast<std::ptrdiff_t>(n); it != kept_.end(); ++it) {
    const double t = it->estimate.t_start;
    while (k < r.segments.size() && r.segments[k].t_start < t - 1e-12) ++k;
    const bool in_method = k < r.segments.size() && std::abs(r.segments[k].t_start - t) < 1e-12;
    all.push_back(in_method ? r.segments[k++] : it->estimate);
  }
  r.segments = std::move(all);
  return r;
}

// ---------------------------------------------------------------------------------------------

SegmentDriver::SegmentOutput SegmentDriver::add(const SignalView& v, Eigen::Index begin,
                                                Eigen::Index end, bool refine_allowed) {
  return addOne(v, begin, end, refine_allowed, /*consume=*/false);
}

// add(); consume: the output is not wanted, so a piecewise segment's estimate and windows are
// moved into the kept history instead of copied (the returned output then lacks them).
SegmentDriver::SegmentOutput SegmentDriver::addOne(const SignalView& v, Eigen::Index begin,
                                                   Eigen::Index end, bool refine_allowed,
                                                   bool consume) {
  resolveWindow(v);
  if (ste_on_) return addSte(v, begin, end, refine_allowed);
  if (end - begin < 1 || !checkChannels(v, options_.formulation, options_.model).ok()) {
    SegmentOutput out = unusableSegment(v, begin, end);
    keep({out.estimate, {}});
    return out;
  }
  if (shared_) return addShared(v, begin, end);
  SegmentOutput out = piecewiseSegment(&method_, v, begin, end, refine_allowed);
  if (consume) {
    recordPiecewise(std::move(out), method_.unlocatedSwitches(), v.dt);
    return {};
  }
  recordPiecewise(out, method_.unlocatedSwitches(), v.dt);
  return out;
}

std::vector<SegmentDriver::SegmentOutput> SegmentDriver::addAll(const SignalView& v,
                                                                const SampleRanges& ranges,
                                                                bool outputs) {
  resolveWindow(v);
  const bool missing = !checkChannels(v, options_.formulation, options_.model).ok();
  const bool sliding = limits_.shared_segments != std::numeric_limits<size_t>::max();
  std::vector<SegmentOutput> outs;
  if (limits_.threads <= 1 || ranges.size() < 2 || missing || sliding ||
      limits_.solve_shared_each_segment || ste_on_) {
    // (Each output is ~1.5 kB: collected only when asked for, into storage reserved once.)
    if (outputs) outs.reserve(ranges.size());
    for (const auto& r : ranges) {
      SegmentOutput out = addOne(v, r.first, r.second, /*refine_allowed=*/true, !outputs);
      if (outputs) outs.push_back(std::move(out));
    }
    return outs;
  }
  if (shared_) {
    addSharedParallel(v, ranges);
    if (!outputs) return outs;
    for (auto it = kept_.end() - static_cast<std::ptrdiff_t>(ranges.size()); it != kept_.end();
         ++it) {
      SegmentOutput o;
      o.estimate = it->estimate;
      o.result.formulation = options_.formulation;
      o.result.model = options_.model;
      o.result.stiffness_shape = options_.stiffness_shape;
      o.result.segments = {o.estimate};
      outs.push_back(std::move(o));
    }
    return outs;
  }
  std::vector<IntegralMethod> workers;
  for (int w = 0; w < limits_.threads; ++w) workers.push_back(newMethod());
  outs.resize(ranges.size());
  std::vector<long> unlocated(ranges.size(), 0);
  // Runs of run_len consecutive segments per claim: a worker's next segment is then mostly its
  // own (its samples are in that core's caches). A refined segment takes ~30 times an integral
  // one, so there one segment per claim: with runs of 8, the workers' last claims of a group
  // left a core idle for up to 8 refinements before the group's join.
  const size_t run_len = wantsRefinement(options_) ? 1 : 8;
  const size_t chunks = (ranges.size() + run_len - 1) / run_len;
  // The chunks are recorded in segment order while the workers run (not after them): a worker
  // that finished a chunk and finds the recorder free records every finished chunk from the first
  // one not yet recorded on (done[c], set after chunk c's outputs were written); the calling
  // thread records what is left after the join.
  std::vector<std::atomic<bool>> done(chunks);
  std::mutex recorder;
  size_t recorded = 0;  // chunks recorded (by the holder of `recorder`)
  auto recordFinished = [&] {
    for (; recorded < chunks && done[recorded].load(std::memory_order_acquire); ++recorded) {
      for (size_t i = recorded * run_len; i < std::min(ranges.size(), (recorded + 1) * run_len);
           ++i)
        recordParallelOutput(&outs[i], ranges[i], unlocated[i], v.dt, outputs);
    }
  };
  parallelFor(chunks, limits_.threads, [&](size_t chunk, int w) {
    for (size_t i = chunk * run_len; i < std::min(ranges.size(), (chunk + 1) * run_len); ++i) {
      const auto& r = ranges[i];
      if (r.second - r.first < 1) {
        outs[i] = unusableSegment(v, r.first, r.second);
        continue;
      }
      outs[i] = piecewiseSegment(&workers[static_cast<size_t>(w)], v, r.first, r.second, true);
      unlocated[i] = workers[static_cast<size_t>(w)].unlocatedSwitches();
    }
    done[chunk].store(true, std::memory_order_release);
    if (recorder.try_lock()) {
      recordFinished();
      recorder.unlock();
    }
  });
  recordFinished();
  if (!outputs) outs.clear();
  return outs;
}

IdentificationResult SegmentDriver::result(size_t last) const {
  IdentificationResult r = shared_ ? sharedResult(last) : piecewiseResult(last);
  flagIntegralStandardErrors(options_, &r);
  return r;
}

IdentificationResult SegmentDriver::finish(const SignalView* record,
                                           const SampleRanges* ranges) const {
  if (ste_on_ && !ste_ready_) {  // the record ended before the calibration span
    SegmentDriver done = *this;
    done.calibrate();
    return done.finish(record, ranges);
  }
  IdentificationResult r = result();
  if (!shared_ || !wantsRefinement(options_)) return r;
  auto integral = [&]() {  // the integral estimates reported: their run warnings again
    flagIntegralStandardErrors(options_, &r);
    return r;
  };
  // Nothing to refine when the integral method could not identify the shared estimate (its
  // `reason` says why, e.g. a constant load for the load law): no refine_failed then.
  if ((r.load_law && !r.load_law->identifiable) || (r.constant && !r.constant->identifiable))
    return integral();
  if (!options_.refinable()) {
    r.warnings.push_back(
        {quality_code::kRefineSkipped,
         "output-error refinement skipped: not available for the greybox stiffness shape " +
             toString(options_.stiffness_shape) + " (integral-method estimates reported)"});
    return integral();
  }
  if (record == nullptr || ranges == nullptr) {
    r.warnings.push_back({quality_code::kRefineSkipped,
                          "output-error refinement skipped: a record analysed streaming is "
                          "refined per segment only for the piecewise model"});
    return integral();
  }
  IdentificationResult refined = r;
  if (const gear_sim::Status refine =
          refineOutputError(*record, *ranges, gear_, options_, &refined);
      refine.ok()) {
    keepIntegralEstimates(r, &refined);
    r = std::move(refined);
  } else {
    r.warnings.push_back(
        {quality_code::kRefineFailed, "output-error refinement failed (" + refine.message() +
                                          "): integral-method estimates reported"});
  }
  applyQualityFlags(options_, &r);
  flagIntegralStandardErrors(options_, &r);
  return r;
}

// ---------------------------------------------------------------------------------------------
// Batch

double legacyForcing(const SignalView& v, const SampleRanges& ranges, const GearConstants& gear) {
  if (v.torque == nullptr || ranges.empty()) return kNaN;
  double sum = 0.0;
  const Eigen::Index b = ranges.front().first, e = ranges.back().second;
  for (Eigen::Index i = b; i < e; ++i) sum += v.torque[i];
  return gear.force_factor * sum / static_cast<double>(e - b);
}

gear_sim::Status identify(const gear_sim::SignalTable& table, const GearConstants& gear,
                          const IdentificationOptions& options, IdentificationResult* result,
                          int threads) {
  if (gear_sim::Status s = options.check(); !s.ok()) return s;
  if (gear_sim::Status s = gear.check(); !s.ok()) return s;
  IdentificationOptions o = options;
  if (gear_sim::Status s = checkRecord(table, gear, options, threads, &o.window_length); !s.ok())
    return s;
  const SignalView view = SignalView::of(table);
  const SampleRanges ranges = segmentRanges(view, o);
  if (ranges.empty())
    return gear_sim::Status::notIdentifiable("no samples in the analysed time range [" +
                                                 std::to_string(o.t_start) + ", " +
                                                 std::to_string(o.t_end) + "] s",
                                             "t_start");
  DriverLimits limits;
  limits.threads = threads;
  SegmentDriver driver(o, gear, limits);
  if (o.formulation == Formulation::Legacy && view.torque != nullptr)
    driver.setLegacyForcing(legacyForcing(view, ranges, gear));
  driver.addAll(view, ranges, /*outputs=*/false);
  *result = driver.finish(&view, &ranges);
  return {};
}

// ---------------------------------------------------------------------------------------------
// SegmentFeeder

SegmentFeeder::SegmentFeeder(SampleRanges ranges, Eigen::Index record_samples, double t0, double dt,
                             size_t group)
    : ranges_(std::move(ranges)),
      samples_(record_samples),
      t0_(t0),
      dt_(dt),
      group_(std::max<size_t>(group, 1)) {
  for (size_t a = 0; a < ranges_.size(); a += group_)
    groups_.emplace_back(a, std::min(a + group_, ranges_.size()));
  reads_ = makeReadRanges();
  held_ = makeHeldRanges();
}

SampleRanges SegmentFeeder::readRanges() const { return reads_; }
SampleRanges SegmentFeeder::heldRanges() const { return held_; }

SampleRanges SegmentFeeder::makeReadRanges() const {
  SampleRanges out;
  Eigen::Index at = 0;
  for (const auto& [a, b] : groups_) {
    const Eigen::Index lo = std::max<Eigen::Index>(ranges_[a].first - kStencilContext, 0);
    const Eigen::Index hi =
        std::min<Eigen::Index>(ranges_[b - 1].second + kStencilContext, samples_);
    const Eigen::Index start = std::max(at, lo);
    out.emplace_back(start, std::max(start, hi));
    at = std::max(start, hi);
  }
  return out;
}

SampleRanges SegmentFeeder::makeHeldRanges() const {
  // The samples held before a group: drop those before its left context, then append its read.
  const SampleRanges& reads = reads_;
  SampleRanges out;
  Eigen::Index first = 0, size = 0;
  for (size_t i = 0; i < groups_.size(); ++i) {
    const Eigen::Index lo =
        std::max<Eigen::Index>(ranges_[groups_[i].first].first - kStencilContext, 0);
    size -= std::min(std::max<Eigen::Index>(lo - first, 0), size);
    size += reads[i].second - reads[i].first;
    first = reads[i].second - size;
    out.emplace_back(first, reads[i].second);
  }
  return out;
}

bool SegmentFeeder::pushHeld(const gear_sim::SignalTable& block, size_t index, const Sink& sink) {
  const Eigen::Index first = held_[index].first;
  const auto [a, b] = groups_[index];
  const auto column = [](const Eigen::VectorXd& x) { return x.size() > 0 ? x.data() : nullptr; };
  SignalView v;
  v.dt = dt_;
  v.t0 = t0_ + static_cast<double>(first) * dt_;
  v.n = block.dte.size();
  v.dte = column(block.dte), v.stiffness = column(block.stiffness);
  v.torque = column(block.torque), v.mesh_state = column(block.mesh_state);
  v.mesh_phase = column(block.mesh_phase);
  SampleRanges local;
  for (size_t i = a; i < b; ++i)
    local.emplace_back(ranges_[i].first - first, ranges_[i].second - first);
  return sink(v, local, a);
}

}  // namespace gear_damping_id
