// rosrun gear_damping analyze --input FILE.csv|FILE.bag [--params GEAR.yaml] [--output result.json]
//     [--formulation known|greybox|paper|legacy]... [--model piecewise|constant|load_law]...
//     [--segment S] [--window S] [--t-start S] [--t-end S] [--refine auto|always|never]
//     [--stiffness-shape square|fourier:H|table:N]
//     [--topic T] [--csv-out DIR] [--bag-out OUT.bag]
//     [--wavelet [--f-min HZ] [--f-max HZ] [--scales N] [--omega0 W] [--mode-freq HZ]...
//                [--decay-region T0,T1]...]
//     [--threads N (default: one per core)] [--summary | --table] [--quiet]
//
// Identifies the mesh damping of a DTE record (CSV with the docs/method.md §6 columns, or a bag of
// gear_damping/SignalChunk messages) with the integral method (docs/method.md §4) for every
// requested formulation x damping model, re-simulates the modeled response of each, prints a table
// per run on stdout and writes the docs/method.md §6 JSON, CSV tables and a bag of results on
// request.
// --wavelet adds the Morlet wavelet validation (docs/method.md §5: modes, their damping ratios
// beside the integral method's); without gear parameters (a `time,dte` record and no --params) the
// wavelet validation runs alone.
// Bags longer than --max-in-memory samples are analysed streaming, one segment at a time (with
// --ste: the STE calibrated on the first segments and held, docs/ste.md), read once when the
// options allow it (Analysis::loadInOnePass; the outputs are the same either way).
// Each run's table ends with a count of clean and flagged segments; above 50 segments a summary
// (statistics, flags, worst segments) replaces the rows. A progress line is drawn on stderr when
// it is a terminal and the job takes more than a second (--quiet: never).
// Exit codes (README "analyze"): 0 success, 1 invalid command line or option value, 2 invalid
// input (file, columns, numbers, time axis, chunks, gear parameters, sample rate, length),
// 3 an output could not be written, 4 nothing identifiable in the record, 5 internal error (an
// exception, out of memory included). Messages on stderr. All outputs (--output, --csv-out,
// --bag-out) are staged and renamed together once every one has been written.
#include <gear_damping/DampingArray.h>
#include <gear_damping/ModeledResponse.h>
#include <gear_damping/WaveletModes.h>
#include <rosbag/bag.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <exception>
#include <iomanip>
#include <iostream>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "gear_damping_id/input_checks.hpp"
#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/result_io.hpp"
#include "gear_damping_id/rig_input.hpp"
#include "gear_damping_id/run_metadata.hpp"
#include "gear_damping_id/run_summary.hpp"
#include "gear_damping_id/segment_driver.hpp"
#include "gear_damping_id/ste_io.hpp"
#include "gear_damping_id/wavelet.hpp"
#include "gear_damping_id/wavelet_context.hpp"
#include "gear_damping_ros/id_conversions.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/message_text.hpp"
#include "gear_sim/models.hpp"
#include "gear_sim/progress.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim/status.hpp"
#include "gear_sim/tool_main.hpp"
#include "gear_sim_ros/bag_io.hpp"
#include "gear_sim_ros/rig_bag_io.hpp"

namespace gd = gear_damping_id;
using Ranges = std::vector<std::pair<Eigen::Index, Eigen::Index>>;

namespace {

constexpr int kExitUsage = 1, kExitInput = 2, kExitOutput = 3, kExitNothing = 4, kExitInternal = 5;
// Segments per read of a streamed bag (memory: this many segments; the --threads workers share
// them).
constexpr size_t kStreamGroup = 64;
// Largest --scales (README "Limits"): each scale is one inverse FFT of the analysed samples.
constexpr int kMaxScales = 2000;

// Messages held instead of printed while a bag is read in one pass (Analysis::loadInOnePass):
// printed once the pass succeeded, dropped when the bag is then analysed the usual way.
std::vector<std::string>* held_messages = nullptr;

void print(const std::string& line) {
  if (held_messages != nullptr)
    held_messages->push_back(line);
  else
    std::cerr << line;
}

int fail(int code, const std::string& message) {
  print("analyze: " + message + "\n");
  return code;
}
// A failed step exits with its step's code (reading the input: kExitInput, writing an output:
// kExitOutput), whatever the StatusCode; docs/limits.md "Exit codes".
int fail(int code, const gear_sim::Status& s) { return fail(code, s.message()); }

void warn(const std::string& message) { print("analyze: warning: " + message + "\n"); }

// What is written to the stderr file descriptor while it lives (ROS's and rosbag's own messages
// about a bag they open) is captured instead: release() gives it back. Inactive (everything
// printed) when the descriptor cannot be redirected.
class StderrCapture {
 public:
  StderrCapture() {
    std::cerr.flush();
    std::fflush(stderr);
    file_ = std::tmpfile();
    saved_ = file_ != nullptr ? ::dup(2) : -1;
    if (saved_ >= 0 && ::dup2(::fileno(file_), 2) < 0) {
      ::close(saved_);
      saved_ = -1;
    }
  }
  ~StderrCapture() { release(); }
  StderrCapture(const StderrCapture&) = delete;
  StderrCapture& operator=(const StderrCapture&) = delete;

  std::string release() {
    std::string text;
    std::fflush(stderr);
    if (saved_ >= 0) {
      ::dup2(saved_, 2);
      ::close(saved_);
      saved_ = -1;
      std::rewind(file_);
      char buf[4096];
      for (size_t n; (n = std::fread(buf, 1, sizeof buf, file_)) > 0;) text.append(buf, n);
    }
    if (file_ != nullptr) std::fclose(file_);
    file_ = nullptr;
    return text;
  }

 private:
  std::FILE* file_ = nullptr;
  int saved_ = -1;
};

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool anyIdentifiable(const gd::IdentificationResult& r) {
  if (r.constant && r.constant->identifiable) return true;
  if (r.load_law && r.load_law->identifiable) return true;
  for (const auto& s : r.segments)
    if (s.identifiable) return true;
  return false;
}

// Streaming sums for the NRMSE of a response assembled from blocks (Chan's parallel update),
// over the samples where both series are finite (as fitMetrics); the samples of segments without
// a response and a response's own non-finite (restarted) samples are counted as not modeled.
struct FitAccumulator {
  double n = 0, mean = 0, m2 = 0, sse = 0;
  Eigen::Index unmodeled = 0;
  void add(const gd::ModeledResponse& r) {
    unmodeled += r.unmodeled;
    // (a response without unmodeled samples is finite: modeledResponse checked it; the observed
    // samples of an identifiable segment are)
    if (r.unmodeled == 0) return addFinite(r.observed, r.modeled);
    Eigen::VectorXd y(r.observed.size()), yh(r.observed.size());
    Eigen::Index m = 0;
    for (Eigen::Index i = 0; i < r.observed.size(); ++i) {
      if (!std::isfinite(r.observed[i]) || !std::isfinite(r.modeled[i])) continue;
      y[m] = r.observed[i];
      yh[m++] = r.modeled[i];
    }
    addFinite(y.head(m), yh.head(m));
  }
  void skip(Eigen::Index samples) { unmodeled += samples; }
  void finish(gd::ModeledResponse* out) const {
    out->nrmse = n > 0 && m2 > 0 ? std::sqrt(sse / m2) : gd::kNaN;
    out->fit_percent = 100.0 * (1.0 - out->nrmse);
    out->unmodeled = unmodeled;
  }

 private:
  void addFinite(const Eigen::Ref<const Eigen::VectorXd>& y,
                 const Eigen::Ref<const Eigen::VectorXd>& yh) {
    const Eigen::Index m = y.size();
    if (m == 0) return;
    const double bm = y.mean();
    const double bm2 = (y.array() - bm).square().sum();
    const double nb = static_cast<double>(m), nt = n + nb, d = bm - mean;
    mean += d * nb / nt;
    m2 += bm2 + d * d * n * nb / nt;
    n = nt;
    sse += (y - yh).squaredNorm();
  }
};

// The optional bag of results (written to a temporary file, renamed when complete).
class ResultBag {
 public:
  gear_sim::Status open(const std::string& path) {
    path_ = path;
    const gear_sim::Result<std::string> partial = gear_sim::partialPath(path);
    if (!partial.ok()) return partial.status();
    tmp_ = *partial;
    try {
      bag_ = std::make_unique<rosbag::Bag>(tmp_, rosbag::bagmode::Write);
    } catch (const std::exception& e) {
      std::remove(tmp_.c_str());
      return gear_sim::Status::ioError(path + ": cannot write (" + e.what() + ")");
    }
    return {};
  }
  bool active() const { return bag_ != nullptr; }
  // A failed write (a full disk, a file size limit) is kept as the bag's error, reported by
  // close(); nothing more is written.
  template <class M>
  void write(const std::string& topic, double t, M msg) {
    if (!bag_ || !error_.empty()) return;
    const ros::Time stamp = ros::Time(1.0) + ros::Duration(std::max(0.0, t));
    msg.header.stamp = stamp;
    try {
      bag_->write(topic, stamp, msg);
    } catch (const std::exception& e) {
      error_ = e.what();
    }
  }
  // Closes the bag and stages it (renamed by stage->commit() with the other outputs).
  gear_sim::Status close(gd::OutputStage* stage) {
    if (!bag_) return {};
    if (error_.empty()) {
      try {
        bag_->close();
      } catch (const std::exception& e) {
        error_ = e.what();
      }
    }
    if (!error_.empty()) {
      discard();
      return gear_sim::Status::ioError(path_ + ": cannot write (" + error_ + ")");
    }
    bag_.reset();
    stage->add(tmp_, path_);
    return {};
  }
  ~ResultBag() { discard(); }  // not closed: an error path; leave nothing that looks complete

 private:
  // Closes (gear_sim_ros::discardBag: nothing throws, even on a full disk) and removes the
  // partial file.
  void discard() noexcept {
    if (!bag_) return;
    gear_sim_ros::discardBag(std::move(bag_), tmp_);
    std::remove(tmp_.c_str());
  }

  std::string path_, tmp_;  // the target and the temporary file written first
  std::unique_ptr<rosbag::Bag> bag_;
  std::string error_;  // the first write or close error
};

std::string topicOf(const gd::AnalysisRun& run, bool primary, const char* leaf) {
  return primary ? std::string("/gear/") + leaf : "/gear/" + run.name() + "/" + leaf;
}

// Legacy forcing of a streamed bag: the mean load over the analysed range (one extra pass,
// summed in order). NaN without a legacy run or a torque channel.
gear_sim::Status streamedLegacyForcing(const gear_sim_ros::BagSignalInfo& info,
                                       const gd::GearConstants& gear,
                                       const std::vector<gd::AnalysisRun>& runs,
                                       const Ranges& ranges, double* fbar) {
  *fbar = gd::kNaN;
  bool legacy = false;
  for (const auto& r : runs) legacy = legacy || r.options.formulation == gd::Formulation::Legacy;
  if (!legacy || !info.torque) return gear_sim::Status();
  double sum = 0.0;
  if (gear_sim::Status s =
          gear_sim_ros::streamSignalBag(info, {{ranges.front().first, ranges.back().second}},
                                        [&](const gear_sim::SignalTable& t, size_t) {
                                          for (Eigen::Index i = 0; i < t.torque.size(); ++i)
                                            sum += t.torque[i];
                                          return gear_sim::Status();
                                        });
      !s.ok())
    return s;
  *fbar =
      gear.force_factor * sum / static_cast<double>(ranges.back().second - ranges.front().first);
  return gear_sim::Status();
}

// --ste on a streamed bag (docs/ste.md "The STE in the segment pipeline"): each run's driver
// calibrates the STE on its first `calibration` segments and holds it; `results` gets each run's
// STE and calibration span.
struct StreamSte {
  const gd::SteModelOptions* options = nullptr;  // null: no STE
  size_t calibration = 10;
  std::vector<gd::SteResult>* results = nullptr;
  std::vector<gd::SegmentDriver::SteCalibration>* spans = nullptr;
};

// A streamed STE run's closing: its STE and span collected, the modeled response (no STE
// forcing, as in memory) and, when segments were held, a run warning saying so (docs/ste.md).
void finishStreamedSte(const gd::SegmentDriver& driver, const StreamSte& ste,
                       gd::AnalysisRun* run) {
  ste.results->push_back(driver.steResult() ? *driver.steResult() : gd::SteResult{});
  const gd::SegmentDriver::SteCalibration span = driver.steCalibration();
  ste.spans->push_back(span);
  run->response = gd::ModeledResponse{};
  run->response_error = "the modeled response does not include the STE (--ste)";
  const size_t held =
      run->result.segments.size() - std::min(span.segments, run->result.segments.size());
  if (held == 0) return;
  using gear_sim::formatNumber;
  run->result.warnings.push_back(
      {gd::quality_code::kSteHeld,
       "the record was analysed streaming (beyond --max-in-memory): the STE was identified "
       "jointly with C on the first " +
           std::to_string(span.segments) + " segments (" + formatNumber(span.t_start) + " to " +
           formatNumber(span.t_end) + " s, --ste-calibration-segments) and held for the other " +
           std::to_string(held) + "; the whole record's joint fit needs the record in memory"});
}

// The `calibration` key of a streamed run's STE (docs/ste.md): the span the STE was identified
// on and how many segments held it.
nlohmann::json steCalibrationJson(const gd::SegmentDriver::SteCalibration& span,
                                  const gd::IdentificationResult& result) {
  const auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  const size_t n = result.segments.size(), cal = std::min(span.segments, n);
  return {{"segments", cal},
          {"t_start", num(span.t_start)},
          {"t_end", num(span.t_end)},
          {"held_segments", n - cal},
          {"whole_record", cal == n}};
}

// The default window of a streamed record: from the mean stiffness of its prefix (the scan's or
// the preview's), as for a record read whole.
double streamedWindow(const gear_sim_ros::BagSignalInfo& info, const gd::GearConstants& gear,
                      gd::SignalView whole) {
  whole.n = info.stiffness_mean > 0.0 ? 1 : 0;
  whole.stiffness = &info.stiffness_mean;
  return gd::defaultWindowLength(whole, gear);
}

// The modeled responses of a streamed record's groups (issue 18) on this thread and one helper
// created once per record: the caller publishes a group's segments as the driver identifies them
// (a batch at a time), the helper computes their responses meanwhile, and finish() has this
// thread claim the rest with it, one segment at a time, then waits for the helper's last. Each
// response is from its own segment's state and stored by index, so the responses are those of
// one after the other whatever the scheduling. Each response's own NRMSE and fit only with
// `fit_metrics` (the record's fit is FitAccumulator's). The group's view must stay valid until
// finish() or quiesce() has returned.
class GroupResponses {
 public:
  GroupResponses(const gd::GearConstants& gear, bool fit_metrics)
      : gear_(gear), fit_metrics_(fit_metrics), helper_([this] { helperLoop(); }) {}
  GroupResponses(const GroupResponses&) = delete;
  GroupResponses& operator=(const GroupResponses&) = delete;
  ~GroupResponses() {
    quiesce();
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
      work_cv_.notify_one();
    }
    helper_.join();
  }
  // A group of n segments on `view` (the previous group finished or quiesced).
  void begin(const gd::SignalView& view, size_t n) {
    const std::lock_guard<std::mutex> lock(mutex_);
    view_ = view;
    ready_ = next_ = done_ = 0;
    outs_.resize(n);
    if (resps_.size() < n) resps_.resize(n);  // (reused: their vectors keep their storage)
    have_.assign(n, 0);
  }
  // The group's next identified segments (in order).
  void publish(std::vector<gd::SegmentDriver::SegmentOutput>&& outs) {
    const size_t at = ready_;  // (written by this thread only)
    // (Slots from `ready_` on are read by no one until ready_ passes them.)
    std::move(outs.begin(), outs.end(), outs_.begin() + static_cast<std::ptrdiff_t>(at));
    const std::lock_guard<std::mutex> lock(mutex_);
    ready_ = at + outs.size();
    work_cv_.notify_one();  // (under the lock, as drd and helgrind expect)
  }
  // Every published segment's response computed (this thread helping); an exception of one
  // rethrown once none is being computed.
  void finish() {
    for (size_t j; claim(&j);) compute(j);
    quiesce();
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  }
  // No new claims, and none being computed on return.
  void quiesce() {
    std::unique_lock<std::mutex> lock(mutex_);
    done_ += ready_ - next_;  // the unclaimed ones count as done (no response)
    next_ = ready_;
    done_cv_.wait(lock, [&] { return done_ == next_; });
  }
  const gd::ModeledResponse& response(size_t j) const { return resps_[j]; }
  bool has(size_t j) const { return have_[j] != 0; }

 private:
  bool claim(size_t* j) {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (next_ >= ready_) return false;
    *j = next_++;
    return true;
  }
  void compute(size_t j) {
    std::exception_ptr error;
    try {
      const gd::SegmentDriver::SegmentOutput& o = outs_[j];
      have_[j] = o.estimate.identifiable &&
                 gd::modeledResponse(view_, gear_, o.result, &resps_[j], fit_metrics_).ok();
    } catch (...) {
      error = std::current_exception();
    }
    const std::lock_guard<std::mutex> lock(mutex_);
    if (error && !error_) error_ = std::move(error);
    ++done_;
    done_cv_.notify_one();
  }
  void helperLoop() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      work_cv_.wait(lock, [&] { return stop_ || next_ < ready_; });
      if (stop_) return;
      const size_t j = next_++;
      lock.unlock();
      compute(j);
      lock.lock();
    }
  }

  const gd::GearConstants& gear_;
  const bool fit_metrics_;
  gd::SignalView view_;
  std::vector<gd::SegmentDriver::SegmentOutput> outs_;
  std::vector<gd::ModeledResponse> resps_;
  std::vector<char> have_;
  std::mutex mutex_;
  std::condition_variable work_cv_, done_cv_;
  size_t ready_ = 0, next_ = 0, done_ = 0;  // published, claimed, computed (or skipped)
  bool stop_ = false;
  std::exception_ptr error_;
  std::thread helper_;  // last: started once the members above exist
};

// A group's segments `segs` of `view` identified by `driver` and their responses computed
// (GroupResponses): with one identification thread in batches of kPublishBatch segments, each
// published as it is identified (the driver's add() one after the other, as addAll of the
// group), so the helper computes responses while the next batch is identified; with more, the
// group at once (addAll's workers). The responses are computed when this returns, also when it
// throws (the view is then no longer read).
void identifyPublishing(gd::SegmentDriver* driver, const gd::SignalView& view, const Ranges& segs,
                        int threads, GroupResponses* responses) {
  constexpr size_t kPublishBatch = 8;
  struct Quiesce {
    GroupResponses* r;
    ~Quiesce() { r->quiesce(); }
  } quiesce{responses};
  responses->begin(view, segs.size());
  const size_t step = threads <= 1 ? kPublishBatch : segs.size();
  Ranges part;
  for (size_t a = 0; a < segs.size(); a += step) {
    const auto from = segs.begin() + static_cast<std::ptrdiff_t>(a);
    part.assign(from, from + static_cast<std::ptrdiff_t>(std::min(step, segs.size() - a)));
    responses->publish(driver->addAll(view, part));
  }
  responses->finish();
}

// Streaming analysis of a long bag through the segment driver (segment_driver.hpp), the
// pipeline of the whole-record identify(): the bag is read in groups of kStreamGroup segments with
// their stencil context (SegmentFeeder), each run's driver takes them, so the segment results
// equal those of the record read whole. Memory: a group of segments per read. The piecewise
// modeled response is per segment (from its identified state); shared-unknown runs are not
// refined and have no modeled response (both need the whole record), with a warning. With
// --ste each driver calibrates the STE on the first segments and holds it (StreamSte).
// `one_pass` (the same object as `info`, from previewSignalBag; null: scanned): the bag is
// scanned in the same pass (scanStreamSignalBag), the default window from the preview's prefix
// (the scan's); an error when the scan fails or differs from the preview (the caller then
// analyses the bag the usual way).
gear_sim::Status analyzeStreaming(const gear_sim_ros::BagSignalInfo& info,
                                  const gd::GearConstants& gear, int threads,
                                  std::vector<gd::AnalysisRun>* runs, ResultBag* bag,
                                  std::vector<double>* wavelet_dte, size_t wavelet_max,
                                  const StreamSte& ste, gear_sim::ProgressBar* progress,
                                  gear_sim_ros::BagSignalInfo* one_pass = nullptr) {
  gd::SignalView whole;
  whole.dt = 1.0 / info.sample_rate;
  whole.t0 = static_cast<double>(info.first_index) * whole.dt;
  whole.n = static_cast<Eigen::Index>(info.samples);
  const Ranges ranges = gd::segmentRanges(whole, runs->front().options);
  if (ranges.empty())
    return gear_sim::Status::invalidInput("no samples in the analysed time range");
  double fbar = gd::kNaN;
  if (const gear_sim::Status st = streamedLegacyForcing(info, gear, *runs, ranges, &fbar); !st)
    return st;
  const double window = runs->front().options.window_length > 0.0
                            ? runs->front().options.window_length
                            : streamedWindow(info, gear, whole);
  std::vector<gd::SegmentDriver> drivers;
  std::vector<FitAccumulator> fits(runs->size());
  gd::DriverLimits limits;
  limits.threads = threads;
  for (auto& run : *runs) {
    gd::IdentificationOptions o = run.options;
    o.window_length = window;
    drivers.emplace_back(o, gear, limits);
    if (o.formulation == gd::Formulation::Legacy && info.torque)
      drivers.back().setLegacyForcing(fbar);
    if (ste.options != nullptr) {
      if (const gear_sim::Status s = drivers.back().setSte(*ste.options, ste.calibration); !s)
        return s.withContext("--ste");
    }
  }
  // Reads of kStreamGroup segments whatever --threads is: the views (and so every time stamp)
  // are the same for any number of threads, so the output is too.
  gd::SegmentFeeder feeder(ranges, whole.n, whole.t0, whole.dt, kStreamGroup);
  // Each block holds its group's samples with their left context (overlapping the previous
  // block's end), so the feeder hands on views of the blocks themselves (pushHeld, no copy).
  const Ranges reads = feeder.heldRanges();
  progress->setTotal(static_cast<double>(ranges.back().second - ranges.front().first));
  // (each response's own fit only for the bag's messages, which carry it)
  GroupResponses responses(gear, bag->active());
  const auto sink = [&](const gd::SignalView& view, const Ranges& segs, size_t first) {
    if (wavelet_dte != nullptr && wavelet_dte->size() < wavelet_max) {
      for (const auto& r : segs) {  // the analysed samples, in order
        const size_t take =
            std::min(wavelet_max - wavelet_dte->size(), static_cast<size_t>(r.second - r.first));
        wavelet_dte->insert(wavelet_dte->end(), view.dte + r.first, view.dte + r.first + take);
      }
    }
    for (size_t k = 0; k < runs->size(); ++k) {
      if (drivers[k].sharedModel() || ste.options != nullptr) {  // no response
        drivers[k].addAll(view, segs);
        continue;
      }
      identifyPublishing(&drivers[k], view, segs, threads, &responses);
      for (size_t j = 0; j < segs.size(); ++j) {  // in order: the fit's sums and the bag
        if (!responses.has(j)) {
          fits[k].skip(segs[j].second - segs[j].first);
          continue;
        }
        fits[k].add(responses.response(j));
        if (bag->active())  // the message only when a bag is written
          bag->write(topicOf((*runs)[k], k == 0, "modeled_response"), view.time(segs[j].first),
                     gear_damping_ros::toMsg(
                         responses.response(j), info.sample_rate,
                         info.first_index + static_cast<std::uint64_t>(ranges[first + j].first)));
      }
    }
    progress->set(
        static_cast<double>(ranges[first + segs.size() - 1].second - ranges.front().first),
        "segment " + std::to_string(first + segs.size()) + " of " + std::to_string(ranges.size()));
    return true;
  };
  // (The sink never stops the feeder: every read range is fed.)
  const auto feed = [&](const gear_sim::SignalTable& block, size_t r) {
    feeder.pushHeld(block, r, sink);
    return gear_sim::Status();
  };
  // (the views hold no time, dte_velocity or damping column: the blocks need none)
  gear_sim_ros::StreamColumns columns;
  columns.time = columns.dte_velocity = columns.damping = false;
  if (gear_sim::Status s = one_pass != nullptr
                               ? gear_sim_ros::scanStreamSignalBag(one_pass, reads, feed, columns)
                               : gear_sim_ros::streamSignalBag(info, reads, feed, columns);
      !s.ok())
    return s;
  for (size_t k = 0; k < runs->size(); ++k) {
    gd::AnalysisRun& run = (*runs)[k];
    if (ste.options != nullptr) drivers[k].completeSteCalibration();
    run.result = drivers[k].finish();
    if (ste.options != nullptr) {
      finishStreamedSte(drivers[k], ste, &run);
    } else if (!drivers[k].sharedModel()) {
      fits[k].finish(&run.response);
      run.response.observed.resize(0);
    } else {
      run.response_error = "not computed for a record analysed streaming (" +
                           std::to_string(info.samples) +
                           " samples): the shared model's response needs the whole record";
    }
  }
  return {};
}

// The integral method's xi set beside a wavelet mode: the shared estimate of a constant model,
// else the segments' xi averaged over the mode's decay region [t_start, t_end] with the fit's
// weight exp(-2 sigma t) (the wavelet measures the decay there; with load-dependent damping a
// record-wide mean would compare different things). NaN when nothing overlaps.
double integralXiOver(const gd::IdentificationResult& r, const gd::WaveletMode& m) {
  if (r.constant) return r.constant->identifiable ? r.constant->xi : gd::kNaN;
  const double sigma = std::isfinite(m.sigma) ? m.sigma : 0.0;
  auto weight = [&](double a, double b) {  // integral of exp(-2 sigma (t - t_start)) over [a, b]
    if (std::abs(sigma) < 1e-12) return b - a;
    return (std::exp(-2.0 * sigma * (a - m.t_start)) - std::exp(-2.0 * sigma * (b - m.t_start))) /
           (2.0 * sigma);
  };
  double sum = 0.0, wsum = 0.0;
  for (const auto& s : r.segments) {
    const double a = std::max(s.t_start, m.t_start), b = std::min(s.t_end, m.t_end);
    if (!s.identifiable || !(b > a)) continue;
    const double w = weight(a, b);
    sum += w * s.xi;
    wsum += w;
  }
  return wsum > 0.0 ? sum / wsum : gd::kNaN;
}

// Splits "T0,T1" into a decay region [s].
bool parseRegion(const std::string& text, std::pair<double, double>* out) {
  const auto comma = text.find(',');
  if (comma == std::string::npos) return false;
  try {
    size_t a = 0, b = 0;
    out->first = std::stod(text.substr(0, comma), &a);
    out->second = std::stod(text.substr(comma + 1), &b);
    return a == comma && b == text.size() - comma - 1;
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace

// One run of the tool: parse -> check options -> load -> identify -> wavelet -> write, each step
// returning kContinue or the exit code to stop with; the state they share is the members.
class Analysis {
 public:
  static constexpr int kContinue = -1;
  static constexpr int kAgain = -2;  // loadInOnePass: analyse the bag the usual way
  int parse(int argc, char** argv);
  int checkOptions();
  int loadInOnePass();
  int load();
  int identify();
  int waveletStep();
  int write();

 private:
  // parse's steps: the command-line options, group by group (in the order --help lists them).
  void declareInputOptions(CLI::App& app);
  void declareIdentificationOptions(CLI::App& app);
  void declareOutputOptions(CLI::App& app);
  void declareSteOptions(CLI::App& app);
  void declareWaveletOptions(CLI::App& app);
  void declareTerminalOptions(CLI::App& app);
  // load's steps, each returning kContinue or the exit code.
  // --ste on a streamed bag: the options the streaming analysis needs (null options: none).
  StreamSte streamSte() {
    StreamSte s;
    if (ste_spec.empty()) return s;
    s.options = &ste_options;
    s.calibration = static_cast<size_t>(ste_calibration_segments);
    s.results = &ste_results;
    s.spans = &ste_spans;
    return s;
  }
  bool onePassOptions() const;
  int readRecord();
  int readRigRecord(bool rig_bag, const gear_sim_ros::RigBagTopics& rig_topics);
  int readGearParameters();
  int checkRecord();
  int checkAnalysedRange();
  // Whether the wavelet's samples take their mesh phase from the record (waveletMeshPhase).
  bool wavelet_phase_from_record = false;
  std::string wavelet_context_warning;  // waveletMeshPhase's, also in the JSON
  void waveletMeshPhase();
  std::string wavelet_stretch_warning;  // waveletFiniteStretch's, also in the JSON
  void waveletFiniteStretch();
  // The mesh phase [cycles] at the wavelet record's sample k: the record's mesh_phase when
  // usable (wavelet_phase_from_record), else the gear parameters' speed profile at the sample's
  // time.
  double meshPhaseAt(size_t k) const {
    if (wavelet_phase_from_record)
      return table.mesh_phase[first + static_cast<Eigen::Index>(wavelet_skip + k)];
    const gear_sim::MeshTiming timing(model.speed, model.gears.pinion.teeth, 0.0);
    return timing.phase(wavelet_t0 + static_cast<double>(k) / wavelet_rate);
  }
  // Command line.
  std::string input, params, output, csv_out, bag_out, topic;
  std::vector<std::string> formulations{"known"}, models{"piecewise"};
  std::string refine = "auto", stiffness_shape = "square";
  gd::IdentificationOptions base;
  std::optional<double> t_start, t_end;
  long max_in_memory = 1000000;
  int threads = 0;  // 0: one per core (checkOptions)
  bool wavelet = false;
  gd::WaveletOptions wopt;
  std::vector<std::string> regions;
  long wavelet_max = 1L << 18;
  std::string wavelet_input;
  std::string ste_spec, ste_damping = gear_sim::steDampingName(gear_sim::SteDamping::Relative);
  gd::SteModelOptions ste_options;
  std::vector<gd::SteResult> ste_results;
  long ste_calibration_segments = 10;                        // streamed bags (docs/ste.md)
  std::vector<gd::SegmentDriver::SteCalibration> ste_spans;  // streamed: each run's span
  bool quiet = false, summary = false, table_mode = false;
  nlohmann::json given = nlohmann::json::object();  // the options set on the command line
  std::vector<std::string> command_line;
  // Rig records (docs/rig.md): the front end's options and what it reported.
  gd::RigInputOptions rig_opts;
  std::vector<long> edge_counts, counts_per_rev;
  std::optional<double> mesh_offset, dte_offset;
  gd::EncoderFrontEndReport rig_report;
  bool rig_input = false;
  // Options.
  bool is_bag = false;
  std::vector<gd::IdentificationOptions> runs_options;
  // Input.
  gear_sim::SignalTable table;
  gear_sim_ros::BagSignalInfo bag_info;
  bool streaming = false;
  bool one_pass = false;          // bag_info is previewSignalBag's until identify()'s pass
  std::vector<std::string> held;  // messages held meanwhile (held_messages)
  gear_sim::GearModel model;
  std::string params_source;
  bool identification = true;
  gd::GearConstants gear;
  double sample_rate = 0.0;
  gd::SignalView whole;
  Ranges analysed;
  double duration = 0.0;
  // Identification.
  ResultBag bag;
  std::vector<gd::AnalysisRun> runs;
  std::vector<double> wavelet_dte;
  Eigen::Index first = 0;
  size_t wavelet_n_record = 0;
  bool wavelet_on_record = false;
  bool identifiable = false;
  // Wavelet validation.
  gd::WaveletResult wres;
  double t_first = 0.0, wavelet_rate = 0.0;
  size_t wavelet_n = 0;
  // The wavelet's samples: wavelet_dte, its first one the wavelet record's sample wavelet_skip
  // (waveletFiniteStretch), at time wavelet_t0 [s].
  size_t wavelet_skip = 0;
  double wavelet_t0 = 0.0;
};

// The record, the gear parameters, the topic and the result file; rig records (docs/rig.md):
// encoder angles or edge times through the encoder front end.
void Analysis::declareInputOptions(CLI::App& app) {
  app.add_option(
         "--input", input,
         "signal record: CSV with the docs/method.md §6 columns, or a bag of SignalChunk messages")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--params", params,
                 "gear parameters: the simulator's YAML (pinion, gear, mesh, speed sections); "
                 "default for a bag: its GearParams message; none: wavelet validation only")
      ->check(CLI::ExistingFile);
  app.add_option("--edges1", rig_opts.edges1,
                 "rig: edge-time file of the pinion encoder (column time); --input is then the "
                 "torque file (time, torque) whose time column is the analysis grid")
      ->check(CLI::ExistingFile);
  app.add_option("--edges2", rig_opts.edges2, "rig: edge-time file of the gear encoder")
      ->check(CLI::ExistingFile);
  app.add_option("--edge-counts", edge_counts,
                 "rig: counts per revolution of the edge records (N, or N1 N2)")
      ->expected(1, 2)
      ->check(CLI::PositiveNumber);
  app.add_option("--counts-per-rev", counts_per_rev,
                 "rig: counts per revolution of quantised uniform angles (N, or N1 N2): the "
                 "quantisation-noise model of the report")
      ->expected(1, 2)
      ->check(CLI::NonNegativeNumber);
  app.add_option("--mesh-offset", mesh_offset,
                 "rig: mesh phase [cycles] at zero inertia-weighted encoder angle (the double-"
                 "contact start); default: estimated from the data");
  app.add_option("--dte-offset", dte_offset,
                 "rig: the constant [m] removed from the encoder DTE; default: estimated");
  app.add_option("--ratio-tolerance", rig_opts.front_end.ratio_tolerance,
                 "rig: relative tolerance of the rotation ratio against Z2/Z1 (default 1e-3)");
  app.add_option("--topic", topic, "bag input: the SignalChunk topic (default: the only one)");
  app.add_option("--output", output, "write the result JSON (docs/method.md §6) to this file");
}

// The identification runs (formulations x models) and their options.
void Analysis::declareIdentificationOptions(CLI::App& app) {
  app.add_option("--formulation", formulations,
                 "known | greybox | paper | legacy (repeat for several; default known)")
      ->check(CLI::IsMember(gd::formulationNames()))
      ->take_all();
  app.add_option("--model", models,
                 "piecewise | constant | load_law (repeat for several; default piecewise)")
      ->check(CLI::IsMember(gd::dampingModelNames()))
      ->take_all();
  app.add_option("--segment", base.segment_length,
                 "damping segment length [s] (0 or inf: the whole record; default 1e-3)");
  app.add_option("--window", base.window_length,
                 "integration window [s] (default: two natural periods from the data)");
  app.add_option("--t-start", t_start, "analyse from this time [s]");
  app.add_option("--t-end", t_end, "analyse up to this time [s]");
  app.add_option(
         "--refine", refine,
         "output-error refinement of the known and greybox estimates: auto (= always, clean data "
         "too, docs/trust.md) | always | never")
      ->check(CLI::IsMember({"auto", "always", "never"}));
  app.add_option(
         "--stiffness-shape", stiffness_shape,
         "greybox stiffness: square (two levels switched by mesh_state) | fourier:H (mean + "
         "H harmonics of mesh_phase) | table:N (periodic piecewise linear over N nodes of "
         "mesh_phase), refined jointly with C (default square; square assumes the stiffness "
         "switches at once: flag shape_mismatch, docs/trust.md)")
      ->check([](const std::string& v) {
        gd::StiffnessShape s;
        return gd::parseStiffnessShape(v, &s) ? std::string()
                                              : "expected square, fourier:H (1..16) or table:N "
                                                "(3..32), got '" +
                                                    v + "'";
      });
  app.add_option("--max-condition", base.max_condition,
                 "largest condition number of an identifiable segment (default 1e6)");
  app.add_option("--time-tolerance", base.time_tolerance,
                 "relative tolerance on the uniformity of the time column (default 1e-6; never "
                 "finer than the time stamps' rounding, docs/limits.md)");
  app.add_option("--max-in-memory", max_in_memory,
                 "bags with more samples are analysed streaming, one segment at a time "
                 "(default 1e6); a rig bag (JointState), read whole, with more messages "
                 "per topic is refused")
      ->check(CLI::PositiveNumber);
  app.add_option("--threads", threads,
                 "identify this many segments in parallel, and compute the wavelet scalogram's "
                 "rows on this many threads (same results as 1; default 0: one per core)")
      ->check(CLI::Range(0, 256));
}

// The output directories and bags.
void Analysis::declareOutputOptions(CLI::App& app) {
  app.add_option("--csv-out", csv_out,
                 "write segments.csv, summary.csv, response_<run>.csv and the wavelet tables "
                 "into this directory");
  app.add_option("--bag-out", bag_out,
                 "write the results as gear_damping messages (DampingArray, ModeledResponse, "
                 "WaveletModes) to this bag");
}

// The static transmission error identified jointly (docs/ste.md).
void Analysis::declareSteOptions(CLI::App& app) {
  app.add_option("--ste", ste_spec,
                 "identify the static transmission error jointly with the damping (docs/ste.md): "
                 "comma-separated mesh:H, shaft:S (or pinion:S, gear:S), nooffset; known and "
                 "greybox formulations, piecewise or constant damping; needs mesh_phase");
  app.add_option("--ste-damping", ste_damping,
                 "with --ste: damping on the deflection rate y' - e' (relative, default) or on "
                 "y' alone (dte)")
      ->check([](const std::string& name) {
        return gear_sim::parseSteDamping(name).ok() ? "" : "must be relative or dte";
      });
  app.add_option("--ste-calibration-segments", ste_calibration_segments,
                 "with --ste on a bag beyond --max-in-memory (analysed streaming): identify the "
                 "STE jointly on the first N segments, and more until they span a revolution of "
                 "each shaft whose orders are modelled, then hold it (default 10; docs/ste.md)")
      ->check(CLI::PositiveNumber);
}

// The Morlet wavelet validation (docs/method.md §5).
void Analysis::declareWaveletOptions(CLI::App& app) {
  app.add_flag("--wavelet", wavelet, "also run the Morlet wavelet validation (docs/method.md §5)");
  app.add_option("--f-min", wopt.f_min,
                 "wavelet: lowest frequency [Hz] (default 10 cycles per record)");
  app.add_option("--f-max", wopt.f_max, "wavelet: highest frequency [Hz] (default 0.4 fs)");
  app.add_option("--scales", wopt.n_scales,
                 "wavelet: number of log-spaced frequencies (default 200)")
      ->check(CLI::Range(3, kMaxScales));
  app.add_option("--omega0", wopt.omega0,
                 "wavelet: Morlet centre frequency of the scalogram (default 6; 3..100)");
  app.add_option("--fit-omega0", wopt.fit_omega0,
                 "wavelet: Morlet centre frequency of the damping fits (default 0 = automatic)");
  app.add_option("--mode-freq", wopt.mode_frequencies,
                 "wavelet: explicit mode frequency [Hz] (repeat; default: picked peaks)")
      ->take_all();
  app.add_option("--order-freq", wopt.order_frequencies,
                 "wavelet: known forcing base frequency [Hz] (mesh, shafts; repeat): lines at its "
                 "harmonics are forced, weaker lines k of it from a free decay its side lines "
                 "(default: from mesh_phase, else the gear parameters' speed)")
      ->take_all();
  app.add_option("--decay-region", regions,
                 "wavelet: decay region T0,T1 [s from the analysed record's start] (once for all "
                 "modes, or once per --mode-freq)")
      ->take_all();
  app.add_option("--prominence", wopt.peak_prominence,
                 "wavelet: minimum peak prominence, fraction of the highest peak (default 0: "
                 "adapts to the noise floor)");
  app.add_option("--wavelet-input", wavelet_input,
                 "wavelet: analyse the dte of this record (CSV or bag, e.g. a free decay from "
                 "`simulate --free-response`) instead of the identification record")
      ->check(CLI::ExistingFile);
  app.add_option("--wavelet-max-samples", wavelet_max,
                 "wavelet: analyse at most this many samples from the start of the analysed "
                 "record (default 2^18 = 262144: a free decay of a 10 kHz mode lasts milliseconds)")
      ->check(CLI::PositiveNumber);
}

// The output of the run on the terminal (docs/method.md §6 "Trust fields").
void Analysis::declareTerminalOptions(CLI::App& app) {
  app.add_flag("--quiet,-q", quiet,
               "no progress line on stderr (warnings and errors are still printed)");
  auto* summary_opt = app.add_flag(
      "--summary", summary,
      "print statistics of C and xi over all segments, flags by code and the worst segments "
      "instead of one line per segment (default above " +
          std::to_string(gd::kSummaryAboveSegments) + " segments)");
  app.add_flag("--table,--no-summary", table_mode, "print one line per segment, however many")
      ->excludes(summary_opt);
}

int Analysis::parse(int argc, char** argv) {
  CLI::App app{
      "Identify the mesh damping of a spur gear pair from its dynamic transmission error "
      "(integral method, Yousfi et al. 2022), re-simulate the modeled response, and validate "
      "the damping with Morlet wavelets."};
  declareInputOptions(app);
  declareIdentificationOptions(app);
  declareOutputOptions(app);
  declareSteOptions(app);
  declareWaveletOptions(app);
  declareTerminalOptions(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);  // prints the help or the message naming the option
    return rc == 0 ? 0 : kExitUsage;
  }
  for (const CLI::Option* o : app.get_options())  // the options set on the command line
    if (o->count() > 0) given[o->get_name()] = o->results();
  command_line.assign(argv, argv + argc);
  return kContinue;
}

// Options: validated before any file is read, each message naming the option.
int Analysis::checkOptions() {
  is_bag = endsWith(input, ".bag");
  if (threads == 0)  // the results are the same for any count (docs/architecture.md)
    threads = static_cast<int>(std::clamp(std::thread::hardware_concurrency(), 1u, 256u));
  if (!is_bag && !endsWith(input, ".csv"))
    return fail(kExitUsage, "--input " + input + ": must end in .csv or .bag");
  if (!bag_out.empty() && !endsWith(bag_out, ".bag"))
    return fail(kExitUsage, "--bag-out " + bag_out + ": must end in .bag");
  if (!is_bag && !topic.empty()) return fail(kExitUsage, "--topic applies to bag input only");
  if (is_bag && (!rig_opts.edges1.empty() || !rig_opts.edges2.empty()))
    return fail(kExitUsage, "--edges1/--edges2 take a CSV torque file as --input");
  if (t_start) base.t_start = *t_start;
  if (t_end) base.t_end = *t_end;
  base.refine = refine == "always"  ? gd::IdentificationOptions::Refine::Always
                : refine == "never" ? gd::IdentificationOptions::Refine::Never
                                    : gd::IdentificationOptions::Refine::Auto;
  gd::parseStiffnessShape(stiffness_shape, &base.stiffness_shape);  // checked by the option
  for (const auto& f : formulations) {
    for (const auto& m : models) {
      gd::IdentificationOptions o = base;
      gd::parseFormulation(f, &o.formulation);
      gd::parseDampingModel(m, &o.model);
      if (const gear_sim::Status s = o.check(); !s.ok()) return fail(kExitUsage, s);
      runs_options.push_back(o);
    }
  }
  for (const auto& r : regions) {
    std::pair<double, double> region;
    if (!parseRegion(r, &region))
      return fail(kExitUsage, "--decay-region " + r + ": expected T0,T1 in seconds");
    wopt.decay_regions.push_back(region);
  }
  wopt.full_scalogram = !csv_out.empty();  // only wavelet_scalogram.csv needs every row
  wopt.threads = threads;
  if (const gear_sim::Status s = wopt.check(); !s.ok())
    return fail(kExitUsage, s.withContext("wavelet"));
  if (!ste_spec.empty()) {
    if (const gear_sim::Status s = gd::parseSteSpec(ste_spec, &ste_options); !s.ok())
      return fail(kExitUsage, "--ste: " + s.message());
    ste_options.damping = *gear_sim::parseSteDamping(ste_damping);  // checked by CLI11
  }

  return kContinue;
}

// Input: a CSV is read whole; a bag is scanned (validated) first, then read whole or streamed.
// A bag of JointState (+ torque) messages is a rig record (docs/rig.md).
int Analysis::readRecord() {
  const gear_sim_ros::RigBagTopics rig_topics;
  const bool rig_bag = is_bag && topic.empty() && gear_sim_ros::isRigBag(input, rig_topics);
  if (is_bag && !rig_bag) {
    if (const gear_sim::Status s = gear_sim_ros::scanSignalBag(input, topic, &bag_info); !s.ok())
      return fail(kExitInput, s);
    for (const auto& w : bag_info.warnings) warn(input + ": " + w);
    streaming = bag_info.samples > max_in_memory;
    if (!streaming)
      if (const gear_sim::Status s = gear_sim_ros::readSignalBag(bag_info, &table); !s.ok())
        return fail(kExitInput, s);
  } else if (rig_bag || gd::isRigInput(input, rig_opts)) {
    return readRigRecord(rig_bag, rig_topics);
  } else if (const gear_sim::Status s = gear_sim::readSignalCsv(input, &table, {"time", "dte"},
                                                                /*allow_non_finite=*/true);
             !s.ok()) {
    return fail(kExitInput, s);
  } else {
    // NaN/Inf samples are kept and implausible values read as NaN (as a bag's): the segments
    // holding them are reported as not identifiable.
    for (const auto& w :
         gear_sim::implausibleWarnings(gear_sim::maskImplausible(&table), "in the file"))
      warn(input + ": " + w);
  }
  return kContinue;
}

// A rig record: the encoder front end first, with the gear parameters (required).
int Analysis::readRigRecord(bool rig_bag, const gear_sim_ros::RigBagTopics& rig_topics) {
  if (params.empty())
    return fail(kExitUsage, "--params GEAR.yaml is required for a rig record (encoder input)");
  gear_sim::GearModel rig_model;
  if (const gear_sim::Status s = gear_sim::loadGearModelFile(params, &rig_model); !s.ok())
    return fail(kExitInput, s);
  if (!edge_counts.empty()) {
    rig_opts.edge_counts1 = edge_counts.front();
    rig_opts.edge_counts2 = edge_counts.back();
  }
  if (!counts_per_rev.empty()) {
    rig_opts.front_end.counts_per_rev1 = counts_per_rev.front();
    rig_opts.front_end.counts_per_rev2 = counts_per_rev.back();
  }
  if (mesh_offset) rig_opts.front_end.mesh_offset = *mesh_offset;
  if (dte_offset) rig_opts.front_end.dte_offset = *dte_offset;
  if (!ste_spec.empty()) {  // the offsets are estimated with the STE modelled (docs/ste.md)
    rig_opts.front_end.model_ste = true;
    rig_opts.front_end.ste = ste_options;
  }
  if (rig_bag) {
    gear_sim::SignalTable rig;
    gear_sim::Status s =
        gear_sim_ros::readRigBag(input, rig_topics, &rig, static_cast<size_t>(max_in_memory));
    if (s.ok()) s = gd::rigTableToSignalTable(rig, input, rig_opts, rig_model, &table, &rig_report);
    if (!s.ok()) return fail(kExitInput, s);
    bag_info.topic = rig_topics.joints;
  } else if (const gear_sim::Status s =
                 gd::loadRigInput(input, rig_opts, rig_model, &table, &rig_report);
             !s.ok()) {
    return fail(kExitInput, s);
  }
  rig_input = true;
  return kContinue;
}

// Gear parameters: --params, else the bag's GearParams; none: the wavelet validation alone.
int Analysis::readGearParameters() {
  params_source = params;
  if (!params.empty()) {
    if (const gear_sim::Status s = gear_sim::loadGearModelFile(params, &model); !s.ok())
      return fail(kExitInput, s);
  } else if (is_bag && bag_info.has_params) {
    model = bag_info.params;
    params_source = input + ":" + bag_info.params_topic;
  } else {
    // Without gear parameters the wavelet validation runs alone, if asked for (--wavelet) or
    // if the record has nothing but time and dte; a record made for the identification is
    // not silently analysed otherwise.
    const bool id_columns = is_bag ? (bag_info.stiffness || bag_info.torque || bag_info.mesh_state)
                                   : (table.stiffness.size() > 0 || table.torque.size() > 0 ||
                                      table.mesh_state.size() > 0);
    if (id_columns && !wavelet && wavelet_input.empty())
      return fail(kExitUsage, "--params GEAR.yaml is required for the identification" +
                                  std::string(is_bag ? (bag_info.params_error.empty()
                                                            ? " (the bag has no GearParams message)"
                                                            : " (" + bag_info.params_error + ")")
                                                     : "") +
                                  "; --wavelet runs the wavelet validation alone");
    identification = false;
    wavelet = true;
    warn("no gear parameters (--params" +
         std::string(is_bag
                         ? (bag_info.params_error.empty() ? ", or a GearParams message in the bag"
                                                          : "; " + bag_info.params_error)
                         : "") +
         "): running the wavelet validation only");
  }
  gear = identification ? gd::gearConstants(model) : gd::GearConstants{};
  if (!ste_spec.empty()) {  // docs/ste.md
    if (!identification) return fail(kExitUsage, "--ste needs --params GEAR.yaml");
    for (const auto& o : runs_options)  // streamed: the calibration must be bounded
      if (streaming && o.model == gd::DampingModel::Constant)
        return fail(kExitUsage,
                    "--ste with the constant model on a bag beyond --max-in-memory: the "
                    "constant model shares C with the STE, so its calibration would be the whole "
                    "record; use the piecewise model or a larger --max-in-memory (docs/ste.md)");
    ste_options.pinion_teeth = model.gears.pinion.teeth;
    ste_options.gear_teeth = model.gears.gear.teeth;
    if (const gear_sim::Status s = ste_options.check(); !s.ok()) return fail(kExitUsage, s);
  }
  if (identification) {
    if (const gear_sim::Status s = gear.check(); !s.ok())
      return fail(kExitInput, s.withContext(params_source));
  }
  return kContinue;
}

// Record-level checks: time axis and columns (tables), sample rate, analysed range, length.
int Analysis::checkRecord() {
  sample_rate = streaming ? bag_info.sample_rate
                          : static_cast<double>(table.size() - 1) /
                                (table.time[table.size() - 1] - table.time[0]);
  whole.dt = 1.0 / sample_rate;
  whole.t0 = streaming ? static_cast<double>(bag_info.first_index) * whole.dt : table.time[0];
  whole.n = streaming ? static_cast<Eigen::Index>(bag_info.samples) : table.size();
  if (!streaming) {
    for (const auto& o : runs_options) {
      const gear_sim::Status s = gd::checkSignalTable(
          table, identification ? o.formulation : gd::Formulation::Paper,  // Paper: dte only
          identification ? o.model : gd::DampingModel::Piecewise, o.time_tolerance,
          /*first_line=*/is_bag ? -1 : 2);
      if (!s.ok()) return fail(kExitInput, s.withContext(input));
    }
  } else if (identification) {
    gd::ChannelSet present;
    present.stiffness = bag_info.stiffness;
    present.torque = bag_info.torque;
    present.mesh_state = bag_info.mesh_state;
    present.mesh_phase = bag_info.mesh_phase;
    for (const auto& o : runs_options)
      if (const gear_sim::Status s = gd::checkChannels(present, o.formulation, o.model); !s.ok())
        return fail(kExitInput, s.withContext(input));
  }
  if (const int rc = checkAnalysedRange(); rc != kContinue) return rc;
  if (identification) {
    std::string rate_warning;
    if (const gear_sim::Status s = gd::checkSampleRate(sample_rate, gear, &rate_warning); !s.ok())
      return fail(kExitInput, s.withContext(input));
    if (!rate_warning.empty()) warn(input + ": " + rate_warning);
    for (const auto& o : runs_options)
      if (const gear_sim::Status s = gd::checkRecordLength(duration, o); !s.ok())
        return fail(kExitInput, s.withContext(input));
  }
  return kContinue;
}

// The analysed segments and their duration; an error says which numbers leave nothing: the
// range, the step, the segment.
int Analysis::checkAnalysedRange() {
  analysed = gd::segmentRanges(whole, runs_options.front());
  if (analysed.empty()) {
    using gear_sim::formatNumber;
    const auto& o = runs_options.front();
    if (o.segment_length > 0.0 && o.segment_length * sample_rate < 1.0)
      return fail(kExitInput, input + ": --segment " + formatNumber(o.segment_length) +
                                  " s is shorter than one sample step (" + formatNumber(whole.dt) +
                                  " s, " + formatNumber(sample_rate) +
                                  " Hz): a segment would hold no sample");
    return fail(kExitInput,
                input + ": no samples in the analysed time range (record " +
                    formatNumber(whole.t0) + " to " +
                    formatNumber(whole.t0 + static_cast<double>(whole.n - 1) * whole.dt) +
                    " s, sample step " + formatNumber(whole.dt) + " s, --segment " +
                    formatNumber(o.segment_length) +
                    " s = " + formatNumber(o.segment_length * sample_rate) + " samples)");
  }
  duration = static_cast<double>(analysed.back().second - analysed.front().first) * whole.dt;
  return kContinue;
}

// Whether the options allow reading the bag in one pass: nothing is written or printed during the
// pass but the progress line (no --bag-out, wavelet, --ste or legacy forcing's extra pass).
bool Analysis::onePassOptions() const {
  if (!is_bag || !bag_out.empty() || wavelet || !wavelet_input.empty() || !ste_spec.empty())
    return false;
  for (const auto& o : runs_options)
    if (o.formulation == gd::Formulation::Legacy) return false;
  return true;
}

// load() and identify() reading a streamed bag once (issue 18): the bag previewed
// (previewSignalBag), then scanned while it is analysed; the messages held until the scan
// succeeded. kAgain (nothing printed or written) when that is not possible or anything
// differs: the caller analyses the bag the usual way (an error is then reported as before). Else
// identify()'s outcome.
int Analysis::loadInOnePass() {
  if (!onePassOptions()) return kAgain;
  StderrCapture capture;  // ROS's messages of the opening: once, whichever way the bag is read
  const gear_sim_ros::RigBagTopics rig_topics;
  // The preview first: it constructs its rosbag::Bag on a thread of its own while this one walks
  // the file's structure, which the rig check then finds walked (checkBagStructure keeps it).
  if (!gear_sim_ros::previewSignalBag(input, topic, &bag_info)) return kAgain;
  if (topic.empty() && gear_sim_ros::isRigBag(input, rig_topics)) {
    bag_info = gear_sim_ros::BagSignalInfo{};  // a rig bag is read as before the preview
    return kAgain;
  }
  if (!(bag_info.samples > max_in_memory)) return kAgain;
  held.push_back(capture.release());
  streaming = true;
  one_pass = true;
  held_messages = &held;
  try {
    for (int (Analysis::*step)() :
         {&Analysis::readGearParameters, &Analysis::checkRecord, &Analysis::identify}) {
      if (const int rc = (this->*step)(); rc != kContinue || !identification) {
        if (held_messages == nullptr) return rc;  // the pass succeeded: identify()'s outcome
        held_messages = nullptr;
        return kAgain;
      }
    }
  } catch (...) {  // (out of memory, say) the usual way meets it after the same messages
    if (held_messages == nullptr) throw;
    held_messages = nullptr;
    return kAgain;
  }
  return kContinue;
}

int Analysis::load() {
  for (int (Analysis::*step)() :
       {&Analysis::readRecord, &Analysis::readGearParameters, &Analysis::checkRecord}) {
    if (const int rc = (this->*step)(); rc != kContinue) return rc;
  }
  return kContinue;
}

int Analysis::identify() {
  if (!bag_out.empty())
    if (const gear_sim::Status s = bag.open(bag_out); !s.ok()) return fail(kExitOutput, s);

  // Identification (table or streaming); the wavelet's samples are collected on the way.
  first = analysed.front().first;
  wavelet_n_record =
      static_cast<size_t>(std::min<Eigen::Index>(wavelet_max, analysed.back().second - first));
  wavelet_on_record = wavelet && wavelet_input.empty();
  if (identification) {
    for (const auto& o : runs_options) {
      gd::AnalysisRun run;
      run.options = o;
      run.dt = whole.dt;
      run.t0 = whole.t0;
      runs.push_back(std::move(run));
    }
  }
  gear_sim::ProgressBar progress("analyze", 2.0 * static_cast<double>(runs.size()), !quiet);
  if (streaming && identification) {
    if (const gear_sim::Status s = analyzeStreaming(
            bag_info, gear, threads, &runs, &bag, wavelet_on_record ? &wavelet_dte : nullptr,
            wavelet_n_record, streamSte(), &progress, one_pass ? &bag_info : nullptr);
        !s.ok())
      return fail(kExitInput, s.withContext(input));
    if (one_pass) {  // the scan's warnings first, as a scan before the analysis prints them
      held_messages = nullptr;
      progress.finish();          // (a terminal's progress line erased first, not written over)
      std::cerr << held.front();  // ROS's own messages, first as before
      for (const auto& w : bag_info.warnings) warn(input + ": " + w);
      for (size_t k = 1; k < held.size(); ++k) std::cerr << held[k];
    }
  } else if (streaming && wavelet_on_record) {
    if (const gear_sim::Status s = gear_sim_ros::streamSignalBag(
            bag_info, {{first, first + static_cast<Eigen::Index>(wavelet_n_record)}},
            [&](const gear_sim::SignalTable& t, size_t) {
              wavelet_dte.assign(t.dte.data(), t.dte.data() + t.dte.size());
              return gear_sim::Status();
            });
        !s.ok())
      return fail(kExitInput, s);
  } else {
    const gd::SignalView view = gd::SignalView::of(table);
    for (size_t k = 0; k < runs.size(); ++k) {
      gd::AnalysisRun& run = runs[k];
      progress.set(2.0 * static_cast<double>(k), run.name() + ": identification");
      if (!ste_spec.empty()) {
        ste_results.emplace_back();
        if (const gear_sim::Status s = gd::identifyWithSte(table, gear, run.options, ste_options,
                                                           &run.result, &ste_results.back());
            !s.ok())
          return fail(kExitInput, s.withContext(input));
      } else if (const gear_sim::Status s =
                     gd::identify(table, gear, run.options, &run.result, threads);
                 !s.ok()) {
        return fail(kExitInput, s.withContext(input));
      }
      progress.set(2.0 * static_cast<double>(k) + 1.0, run.name() + ": modeled response");
      if (!ste_spec.empty()) {  // the forward model has no STE forcing (docs/ste.md)
        run.response = gd::ModeledResponse{};
        run.response_error = "the modeled response does not include the STE (--ste)";
      } else if (const gear_sim::Status s =
                     gd::modeledResponse(view, gear, run.result, &run.response);
                 !s.ok()) {
        run.response = gd::ModeledResponse{};
        run.response_error = s.message();
      } else {
        const double tr = table.time[run.response.begin];
        bag.write(
            topicOf(run, k == 0, "modeled_response"), tr,
            gear_damping_ros::toMsg(run.response, sample_rate,
                                    static_cast<std::uint64_t>(std::llround(tr * sample_rate))));
      }
    }
    if (wavelet_on_record)
      wavelet_dte.assign(table.dte.data() + first, table.dte.data() + first + wavelet_n_record);
  }
  identifiable = false;
  for (size_t k = 0; k < runs.size(); ++k) {
    identifiable = identifiable || anyIdentifiable(runs[k].result);
    bag.write(topicOf(runs[k], k == 0, "damping"), whole.t0 + duration,
              gear_damping_ros::toMsg(runs[k].result));
  }
  progress.finish();  // the terminal is clean before the tables
  if (!runs.empty())
    gd::printRuns(std::cout, runs,
                  summary      ? gd::RunPrintMode::Summary
                  : table_mode ? gd::RunPrintMode::Table
                               : gd::RunPrintMode::Auto);

  return kContinue;
}

// The record's mesh_phase serves the wavelet (order frequencies, growth rates) where
// meshPhaseProblem finds nothing wrong with it over the wavelet's samples; otherwise it is set
// aside with a warning, on stderr and in the JSON's wavelet.warnings (before, a column that did
// not advance left every parametric check off without a word), and the gear parameters' speed
// profile, when given, takes its place.
void Analysis::waveletMeshPhase() {
  wavelet_phase_from_record = wavelet_on_record && !streaming && table.mesh_phase.size() > 0;
  if (!wavelet_phase_from_record || wavelet_n < 2) return;
  const std::string problem = gd::meshPhaseProblem(
      table.mesh_phase.data() + first + static_cast<Eigen::Index>(wavelet_skip), wavelet_n,
      wavelet_rate);
  if (problem.empty()) return;
  wavelet_phase_from_record = false;
  const bool given = !wopt.order_frequencies.empty();  // --order-freq
  wavelet_context_warning =
      "mesh_phase not usable over the wavelet's samples (" + problem +
      (wavelet_skip > 0 ? "; samples counted from the finite stretch's first" : "") + "): " +
      std::string(identification ? (given ? "the growth rates are taken from the gear parameters' "
                                            "speed profile instead (order frequencies: "
                                            "--order-freq)"
                                          : "the wavelet's mesh frequency is taken from the gear "
                                            "parameters' speed profile instead")
                  : given ? "the order frequencies of --order-freq are used, without growth rates"
                          : "no mesh frequency, so forced and modulated lines are not flagged");
  warn(wavelet_context_warning);
}

// A wavelet record holding NaN/Inf DTE samples (a bag's gap, a bad value) is validated on its
// longest stretch without any, with a warning (the transform needs every sample).
void Analysis::waveletFiniteStretch() {
  const size_t n = wavelet_dte.size();
  size_t best_a = 0, best_len = 0, bad = 0;
  for (size_t a = 0; a < n;) {
    for (; a < n && !std::isfinite(wavelet_dte[a]); ++a) ++bad;
    size_t b = a;
    while (b < n && std::isfinite(wavelet_dte[b])) ++b;
    if (b - a > best_len) best_a = a, best_len = b - a;
    a = b;
  }
  if (best_len == n) return;
  if (best_len == 0) {  // (the validation then fails, naming sample 0)
    wavelet_stretch_warning =
        "none of the wavelet's " + std::to_string(n) + " DTE samples is finite";
    warn(wavelet_stretch_warning);
    return;
  }
  std::ostringstream t;  // (9 digits: the same text whole and streamed, whose t0 differ by ulps)
  t << std::setprecision(9) << wavelet_t0 + static_cast<double>(best_a) / wavelet_rate;
  wavelet_stretch_warning =
      std::to_string(bad) + " of the wavelet's " + std::to_string(n) +
      " DTE samples are NaN/Inf (gaps, bad values): validated on the longest stretch without "
      "any, " +
      std::to_string(best_len) + " samples from t = " + t.str() + " s";
  warn(wavelet_stretch_warning);
  wavelet_dte.erase(wavelet_dte.begin() + static_cast<std::ptrdiff_t>(best_a + best_len),
                    wavelet_dte.end());
  wavelet_dte.erase(wavelet_dte.begin(), wavelet_dte.begin() + static_cast<std::ptrdiff_t>(best_a));
  wavelet_skip = best_a;
  wavelet_n = best_len;
  const double skip_t = static_cast<double>(best_a) / wavelet_rate;
  wavelet_t0 += skip_t;
  // --decay-region is measured from the wavelet record's first sample: onto the stretch's axis
  // (a region before the stretch is then reported outside the record).
  for (auto& r : wopt.decay_regions) r = {r.first - skip_t, r.second - skip_t};
}

int Analysis::waveletStep() {
  // Wavelet validation of the analysed record's first wavelet_n samples (or of --wavelet-input).
  t_first = whole.t0 + static_cast<double>(first) * whole.dt;
  wavelet_rate = sample_rate;
  wavelet_n = wavelet_n_record;
  if (!wavelet_input.empty()) {
    wavelet = true;
    gear_sim::SignalTable w;
    if (endsWith(wavelet_input, ".bag")) {
      gear_sim_ros::BagSignalInfo wi;
      gear_sim::Status s = gear_sim_ros::scanSignalBag(wavelet_input, "", &wi);
      if (s.ok())
        s = gear_sim_ros::streamSignalBag(wi,
                                          {{0, std::min<Eigen::Index>(wavelet_max, wi.samples)}},
                                          [&](const gear_sim::SignalTable& t, size_t) {
                                            w = t;
                                            return gear_sim::Status();
                                          });
      if (!s.ok()) return fail(kExitInput, s.withContext("--wavelet-input"));
    } else if (const gear_sim::Status s =
                   gear_sim::readSignalCsv(wavelet_input, &w, {"time", "dte"}, true);
               !s.ok()) {
      return fail(kExitInput, s.withContext("--wavelet-input"));
    }
    if (const gear_sim::Status s =
            gd::checkSignalTable(w, gd::Formulation::Paper, gd::DampingModel::Piecewise, 1e-6,
                                 endsWith(wavelet_input, ".bag") ? -1 : 2);
        !s.ok())
      return fail(kExitInput, s.withContext(wavelet_input));
    wavelet_n = static_cast<size_t>(std::min<Eigen::Index>(wavelet_max, w.size()));
    wavelet_dte.assign(w.dte.data(), w.dte.data() + wavelet_n);
    wavelet_rate = static_cast<double>(w.size() - 1) / (w.time[w.size() - 1] - w.time[0]);
    t_first = w.time[0];
  }
  wavelet_t0 = t_first;
  if (wavelet) {
    if (wavelet_on_record && wavelet_n < static_cast<size_t>(analysed.back().second - first))
      warn("wavelet validation on the first " + std::to_string(wavelet_n) +
           " samples of the analysed record (--wavelet-max-samples)");
    waveletFiniteStretch();
    // Forced lines: mesh frequency from the record's mesh_phase, else the gear parameters.
    waveletMeshPhase();
    if (wavelet_phase_from_record || identification)
      gd::applyGearContext([this](size_t k) { return meshPhaseAt(k); }, wavelet_n, wavelet_rate,
                           identification ? &model : nullptr, &wopt);
    gear_sim::ProgressBar wavelet_progress("analyze", 0.0, !quiet);
    wavelet_progress.set(
        0.0, "wavelet validation of " + std::to_string(wavelet_dte.size()) + " samples");
    wres = gd::validateWavelet(wavelet_dte.data(), wavelet_dte.size(), wavelet_rate, wopt);
    wavelet_progress.finish();
    if (!wres.ok()) {
      if (!identification) return fail(kExitInput, input + ": wavelet: " + wres.status.message());
      warn("wavelet validation not possible: " + wres.status.message());
    } else {
      gd::shiftWaveletTimes(&wres, wavelet_t0);  // onto the record's time axis
      if (!wavelet_context_warning.empty()) wres.warnings.push_back(wavelet_context_warning);
      if (!wavelet_stretch_warning.empty()) wres.warnings.push_back(wavelet_stretch_warning);
      if (identification && !runs.empty())
        for (auto& m : wres.modes) m.integral_xi = integralXiOver(runs.front().result, m);
      gd::printWaveletTable(std::cout, wres);
      const double w_end = wavelet_t0 + static_cast<double>(wavelet_n) / wavelet_rate;
      bag.write("/gear/wavelet_modes", w_end, gear_damping_ros::toMsg(wres, wavelet_t0, w_end));
    }
  }

  return kContinue;
}

int Analysis::write() {
  nlohmann::json in = {
      {"file", input},
      {"params", identification ? nlohmann::json(params_source) : nlohmann::json(nullptr)},
      {"samples", static_cast<std::int64_t>(whole.n)},
      {"sample_rate", sample_rate},
      {"t_start", t_first},
      {"duration", duration},
      {"streaming", streaming},
      {"topic", is_bag ? nlohmann::json(bag_info.topic) : nlohmann::json(nullptr)},
      {"gaps", is_bag ? bag_info.gaps : 0}};
  if (rig_input) in["encoder"] = gd::toJson(rig_report);
  // The segments are written from `runs` by writeAnalysisJsonAtomically (no tree of them).
  nlohmann::json doc = gd::analysisJson(runs, in, /*segments=*/false);
  if (!ste_results.empty()) {  // the STE of the primary run, and of every run (docs/ste.md)
    doc["identification"]["ste"] = gd::steJson(ste_results.front());
    for (size_t k = 0; k < ste_results.size() && k < doc["runs"].size(); ++k) {
      doc["runs"][k]["ste"] = gd::steJson(ste_results[k]);
      if (k < ste_spans.size())  // streamed: the span the STE was identified on
        doc["runs"][k]["ste"]["calibration"] = steCalibrationJson(ste_spans[k], runs[k].result);
    }
    if (!doc["runs"].empty()) doc["identification"]["ste"] = doc["runs"][0]["ste"];
  }
  doc["metadata"] = gd::runMetadata(command_line, input, given, GEAR_DAMPING_VERSION);
  if (wavelet) {
    doc["wavelet"] =
        wres.ok() ? gd::waveletJson(wres) : nlohmann::json{{"error", wres.status.message()}};
    if (!wres.ok() && !wavelet_stretch_warning.empty())
      doc["wavelet"]["warnings"] = nlohmann::json::array({wavelet_stretch_warning});
    if (wres.ok()) {
      doc["wavelet"]["samples"] = wavelet_n;
      doc["wavelet"]["input"] = wavelet_input.empty() ? input : wavelet_input;
    }
  }
  gd::OutputStage stage;  // every output renamed only once all are written
  gear_sim::Status s;
  if (!output.empty()) s = gd::writeAnalysisJsonAtomically(output, doc, runs, &stage);
  doc = nullptr;  // the tables below and the bag do not need the document
  if (s.ok() && !csv_out.empty()) {
    if (!runs.empty()) s = gd::writeRunCsv(csv_out, runs, &stage);
    if (s.ok() && !ste_results.empty()) s = gd::writeSteCsv(csv_out, ste_results.front(), &stage);
    if (s.ok() && wavelet && wres.ok())
      s = gd::writeWaveletCsv(csv_out, wres, wavelet_dte.data(), static_cast<long>(wavelet_n),
                              wavelet_rate, wavelet_t0, 4000, &stage);
  }
  if (s.ok()) s = bag.close(&stage);
  if (s.ok()) s = stage.commit();
  if (!s.ok()) return fail(kExitOutput, s);
  if (identification && !identifiable)
    return fail(kExitNothing, "no segment of " + input + " is identifiable (see the table)");
  return 0;
}

int run(int argc, char** argv) {
  auto a = std::make_unique<Analysis>();
  if (const int rc = a->parse(argc, argv); rc != Analysis::kContinue) return rc;
  if (const int rc = a->checkOptions(); rc != Analysis::kContinue) return rc;
  int rc = a->loadInOnePass();
  if (rc == Analysis::kAgain) {  // the usual way, from a fresh start (nothing was printed)
    a = std::make_unique<Analysis>();
    if (rc = a->parse(argc, argv); rc == Analysis::kContinue) rc = a->checkOptions();
    if (rc == Analysis::kContinue) rc = a->load();
    if (rc == Analysis::kContinue) rc = a->identify();
  }
  for (int (Analysis::*step)() : {&Analysis::waveletStep, &Analysis::write}) {
    if (rc != Analysis::kContinue) return rc;
    rc = (a.get()->*step)();
  }
  return rc == Analysis::kContinue ? 0 : rc;
}

int main(int argc, char** argv) {
  return gear_sim::runToolMain("analyze", kExitInternal, [&] { return run(argc, argv); });
}
