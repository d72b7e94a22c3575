#include "gear_sim/progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

namespace gear_sim {

ProgressBar::ProgressBar(std::string label, double total, bool enabled)
    : ProgressBar(
          [&] {
            Options o;
            o.label = std::move(label);
            o.enabled = enabled;
            return o;
          }(),
          total) {}

ProgressBar::ProgressBar(Options options, double total)
    : options_(std::move(options)), total_(total), start_(std::chrono::steady_clock::now()) {
  active_ = options_.enabled && options_.stream != nullptr &&
            (options_.force || isTerminal(options_.stream));
  if (active_) thread_ = std::thread([this] { run(); });
}

ProgressBar::~ProgressBar() { finish(); }

bool ProgressBar::isTerminal(std::FILE* stream) {
  return stream != nullptr && isatty(fileno(stream)) == 1;
}

void ProgressBar::set(double done) { done_.store(done); }

void ProgressBar::set(double done, const std::string& what) {
  done_.store(done);
  std::lock_guard<std::mutex> lock(mutex_);
  what_ = what;
}

void ProgressBar::setTotal(double total) { total_.store(total); }

void ProgressBar::finish() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stop_) return;
    stop_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::lock_guard<std::mutex> lock(mutex_);
  if (drawn_width_ > 0) {  // erase the line
    std::fprintf(options_.stream, "\r%s\r", std::string(drawn_width_, ' ').c_str());
    std::fflush(options_.stream);
    drawn_width_ = 0;
  }
}

void ProgressBar::run() {
  const auto period = std::chrono::duration<double>(std::max(0.01, options_.period_s));
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stop_) {
    wake_.wait_for(lock, period);
    if (stop_) break;
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    if (elapsed < options_.delay_s) continue;
    const std::string line =
        render(options_.label, done_.load(), total_.load(), what_, elapsed, options_.width);
    // Pad over the previous line's tail, then return to the line's start.
    const std::size_t pad = drawn_width_ > line.size() ? drawn_width_ - line.size() : 0;
    std::fprintf(options_.stream, "\r%s%s", line.c_str(), std::string(pad, ' ').c_str());
    std::fflush(options_.stream);
    drawn_width_ = std::max(drawn_width_, line.size());
  }
}

namespace {

constexpr double kEtaMinUnits = 100.0;

std::string seconds(double s) {
  char buf[32];
  if (s < 60.0)
    std::snprintf(buf, sizeof buf, "%.1f s", s);
  else
    std::snprintf(buf, sizeof buf, "%d min %02d s", static_cast<int>(s / 60.0),
                  static_cast<int>(std::fmod(s, 60.0)));
  return buf;
}

}  // namespace

std::string ProgressBar::render(const std::string& label, double done, double total,
                                const std::string& what, double elapsed_s, int width) {
  std::string line = label;
  if (total > 0.0 && std::isfinite(total)) {
    const double f = std::clamp(std::isfinite(done) ? done / total : 0.0, 0.0, 1.0);
    const int w = std::max(1, width);
    const int full = static_cast<int>(std::floor(f * w));
    char pct[16];
    std::snprintf(pct, sizeof pct, " %3d %%", static_cast<int>(std::floor(100.0 * f)));
    line += " [" + std::string(full, '#') + std::string(w - full, '.') + "]" + pct + "  " +
            seconds(elapsed_s);
    // A time estimate only for fine-grained work (samples); a few coarse steps rarely take
    // equal times.
    if (total >= kEtaMinUnits && f > 0.02 && f < 1.0)
      line += ", ~" + seconds(elapsed_s * (1.0 - f) / f) + " left";
  } else {
    line += " " + seconds(elapsed_s);
  }
  if (!what.empty()) line += "  " + what;
  return line;
}

}  // namespace gear_sim
