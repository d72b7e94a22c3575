// gear_sim::ProgressBar: the line it draws, and that it draws nothing where it must not (not a
// terminal, --quiet) and leaves the terminal line clean when finished.
#include "gear_sim/progress.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>

namespace {

// Long enough for several redraw periods of 10 ms (the bar's thread runs by itself; a loaded
// machine only draws fewer times, which the assertions allow).
constexpr auto kSeveralPeriods = std::chrono::milliseconds(120);

std::string contentOf(std::FILE* f) {
  std::fflush(f);
  std::rewind(f);
  std::string s;
  char buf[256];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) s.append(buf, n);
  return s;
}

gear_sim::ProgressBar::Options fastOptions(std::FILE* f) {
  gear_sim::ProgressBar::Options o;
  o.label = "job";
  o.stream = f;
  o.delay_s = 0.0;
  o.period_s = 0.01;
  return o;
}

TEST(ProgressBar, RenderShowsBarPercentElapsedAndStep) {
  const std::string line = gear_sim::ProgressBar::render("analyze", 25.0, 100.0, "run 1", 3.0, 8);
  EXPECT_EQ(line, "analyze [##......]  25 %  3.0 s, ~9.0 s left  run 1");
}

TEST(ProgressBar, RenderOfAFewCoarseStepsEstimatesNoTimeLeft) {
  EXPECT_EQ(gear_sim::ProgressBar::render("simulate", 1.0, 2.0, "writing", 1.5, 4),
            "simulate [##..]  50 %  1.5 s  writing");
}

TEST(ProgressBar, RenderWithoutTotalShowsElapsedTimeOnly) {
  EXPECT_EQ(gear_sim::ProgressBar::render("analyze", 0.0, 0.0, "wavelet", 75.0, 8),
            "analyze 1 min 15 s  wavelet");
}

TEST(ProgressBar, RenderClampsOutOfRangeWork) {
  EXPECT_EQ(gear_sim::ProgressBar::render("x", 250.0, 100.0, "", 1.0, 4), "x [####] 100 %  1.0 s");
  EXPECT_EQ(gear_sim::ProgressBar::render("x", -5.0, 100.0, "", 1.0, 4), "x [....]   0 %  1.0 s");
}

// Everything a bar with `o` (its stream replaced by a temporary file) writes while half of its
// work is done for several redraw periods and it is then destroyed.
std::string drawnBy(gear_sim::ProgressBar::Options o) {
  std::FILE* f = std::tmpfile();
  if (f == nullptr) return "tmpfile failed";
  o.stream = f;
  {
    gear_sim::ProgressBar bar(o, 10.0);
    bar.set(5.0, "half");
    std::this_thread::sleep_for(kSeveralPeriods);
  }
  const std::string s = contentOf(f);
  std::fclose(f);
  return s;
}

TEST(ProgressBar, DrawsNothingWhenTheStreamIsNotATerminal) {
  EXPECT_FALSE(gear_sim::ProgressBar::isTerminal(nullptr));
  EXPECT_EQ(drawnBy(fastOptions(nullptr)), "");  // a temporary file is no terminal
}

TEST(ProgressBar, DrawsNothingWhenDisabledEvenIfForced) {
  auto o = fastOptions(nullptr);
  o.force = true;
  o.enabled = false;  // --quiet
  EXPECT_EQ(drawnBy(o), "");
}

TEST(ProgressBar, DrawsNothingBeforeItsDelay) {
  auto o = fastOptions(nullptr);
  o.force = true;
  o.delay_s = 3600.0;  // a job shorter than the delay prints nothing
  EXPECT_EQ(drawnBy(o), "");
}

TEST(ProgressBar, ForcedBarDrawsOnAnyStream) {
  auto o = fastOptions(nullptr);
  o.force = true;
  EXPECT_NE(drawnBy(o).find("job ["), std::string::npos);  // the control of the tests above
}

TEST(ProgressBar, ForcedBarDrawsItsLineAndErasesItWhenFinished) {
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  auto o = fastOptions(f);
  o.force = true;
  gear_sim::ProgressBar bar(o, 10.0);
  bar.set(5.0, "half way");
  std::this_thread::sleep_for(kSeveralPeriods);
  bar.finish();
  bar.finish();  // idempotent
  const std::string s = contentOf(f);
  EXPECT_NE(s.find("\rjob ["), std::string::npos) << s;
  EXPECT_NE(s.find(" 50 %"), std::string::npos) << s;
  EXPECT_NE(s.find("half way"), std::string::npos) << s;
  // Erased: the last write is carriage return, blanks over the line, carriage return.
  ASSERT_GE(s.size(), 2u);
  EXPECT_EQ(s.back(), '\r');
  const size_t prev = s.rfind('\r', s.size() - 2);
  ASSERT_NE(prev, std::string::npos);
  EXPECT_EQ(s.substr(prev + 1, s.size() - prev - 2).find_first_not_of(' '), std::string::npos);
  std::fclose(f);
}

}  // namespace
