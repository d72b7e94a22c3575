// A progress line on a terminal for the command-line tools' long jobs (simulate, analyze). No
// ROS. Nothing is drawn when the stream is not a terminal (pipes, files, CI logs, tests), when
// disabled (--quiet), or before `delay` has passed, so a job that finishes quickly prints
// nothing. A background thread redraws the line every `period`, so elapsed time keeps moving
// while one long call (a whole-record identification) runs between two updates.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <string>
#include <thread>

namespace gear_sim {

/// Progress of one job in abstract work units (samples, steps, ...). Thread-safe: set() and
/// step() may be called from any thread while the line is drawn.
class ProgressBar {
 public:
  struct Options {
    std::string label;      ///< prefix of the line, e.g. the tool's name
    bool enabled = true;    ///< false: draw nothing (--quiet)
    bool force = false;     ///< draw even if `stream` is not a terminal (tests)
    double delay_s = 1.0;   ///< [s] nothing is drawn before this much time has passed
    double period_s = 0.2;  ///< [s] redraw period
    std::FILE* stream = stderr;
    int width = 28;  ///< characters of the bar itself
  };

  ProgressBar(std::string label, double total, bool enabled);
  ProgressBar(Options options, double total);
  ~ProgressBar();  ///< finish()
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  /// Work done so far (0..total) and, optionally, what is being done now.
  void set(double done);
  void set(double done, const std::string& what);
  /// Changes the total (e.g. once it is known); <= 0 draws an elapsed-time line without a bar.
  void setTotal(double total);
  /// Stops drawing and erases the line, so that what follows on the terminal starts clean.
  /// Idempotent. Call it before printing results to stdout (which shares the terminal).
  void finish();
  /// Whether anything may be drawn at all (enabled and a terminal, or forced).
  bool active() const { return active_; }

  /// The line for `done` of `total` after `elapsed_s`, e.g.
  /// "analyze [#######.......]  25 %  3.1 s, ~9 s left  known_piecewise" (no bar when
  /// total <= 0; the time left only when total >= 100 units, i.e. fine-grained work such as
  /// samples, not a few steps of unequal length). Exposed for tests.
  static std::string render(const std::string& label, double done, double total,
                            const std::string& what, double elapsed_s, int width);

  /// Whether `stream` is a terminal.
  static bool isTerminal(std::FILE* stream);

 private:
  void run();

  Options options_;
  bool active_ = false;
  std::atomic<double> done_{0.0}, total_{0.0};
  std::mutex mutex_;  // guards what_, stop_, drawn_width_ and the stream
  std::condition_variable wake_;
  std::string what_;
  bool stop_ = false;
  std::size_t drawn_width_ = 0;
  std::chrono::steady_clock::time_point start_;
  std::thread thread_;
};

}  // namespace gear_sim
