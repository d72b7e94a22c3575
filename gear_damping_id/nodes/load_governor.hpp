// LoadGovernor: keeps a node's callback thread within a budget of one core by thinning an
// optional, costly stage (the refinement of a segment, the analysis of a wavelet window).
// ROS-free, so that it is unit-tested with a synthetic clock (test/unit/load_governor_test.cpp).
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>

namespace gear_damping_nodes {

/// Monotonic wall-clock time [s]: what a stage costs the node's (single) callback thread,
/// including the time the machine did not give it a core, which is what decides whether the
/// node keeps up.
inline double busySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Every item (segment, window) costs the node a base (intake, integral estimate, messages);
/// the optional stage adds to it. The governor keeps the node's whole load, base plus stage,
/// within `budget` (a fraction of one core), so that the base work is never late:
///   rate       = items arriving per second of wall time (decayed over kTau = 10 s);
///   full, base = wall time of an item with / without the stage (busySeconds), each smoothed
///                over about 20 items (base 0 until an item without the stage was seen);
///   load       = full * rate (what the node would need if every item got the stage);
///   the stage runs on every stride-th item, stride = ceil((full - base) * rate /
///   (budget - base * rate)); no item gets it while base * rate alone reaches the budget.
/// Then base * rate + (full - base) * rate / stride <= budget. Short bursts (a test, a few
/// windows) never reach the budget; a sustained stream that needs more is thinned at once,
/// before the subscriber queue grows.
class LoadGovernor {
 public:
  explicit LoadGovernor(double budget) : budget_(budget) {}
  /// Whether the next item gets the stage.
  bool allow() {
    ++count_;
    return stride_ <= 1 || count_ % stride_ == 0;
  }
  /// One item was processed: it took `cost` [s] (busySeconds), `skipped`: allow() was false,
  /// so it had the base cost only. `now` [s]: its time (monotonic; busySeconds() by default).
  void record(double cost, bool skipped, double now = busySeconds()) {
    arrivals_ = (last_ > 0.0 ? arrivals_ * std::exp(-(now - last_) / kTau) : 0.0) + 1.0;
    last_ = now;
    if (cost >= 0.0) {
      double& c = skipped ? base_ : full_;
      bool& have = skipped ? have_base_ : have_full_;
      c = have ? kAlpha * cost + (1.0 - kAlpha) * c : cost;
      have = true;
    }
    const double rate = arrivals_ / kTau;
    const double base = have_base_ ? std::min(base_, full_) : 0.0;
    load_ = full_ * rate;
    base_load_ = base * rate;
    const double extra = (full_ - base) * rate, room = budget_ - base_load_;
    double k = 1.0;
    if (load_ > budget_) k = room > 0.0 ? std::ceil(extra / room) : kMaxStride;
    stride_ = k > 1.0 ? static_cast<unsigned long>(std::min(k, kMaxStride)) : 1;
  }
  bool degraded() const { return stride_ > 1; }
  unsigned long stride() const { return stride_; }
  /// Fraction of a core the node would need if every item got the stage.
  double load() const { return load_; }
  /// Fraction of a core the items cost without the stage.
  double baseLoad() const { return base_load_; }
  double budget() const { return budget_; }

 private:
  static constexpr double kAlpha = 0.05;     // cost smoothing (about 20 items)
  static constexpr double kTau = 10.0;       // [s] arrival-rate memory
  static constexpr double kMaxStride = 1e6;  // "none": the base alone fills the budget
  double budget_;
  double full_ = 0.0, base_ = 0.0, arrivals_ = 0.0, last_ = 0.0, load_ = 0.0, base_load_ = 0.0;
  bool have_full_ = false, have_base_ = false;
  unsigned long stride_ = 1, count_ = 0;
};

}  // namespace gear_damping_nodes
