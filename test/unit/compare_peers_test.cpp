// bench/compare_peers' judgement of the speed bars (bar_checks): rows of known times in, the
// rates, ratios and met / missed statuses out, checked against the bars' arithmetic (no
// benchmark is run; the rows are what its rounds would have produced).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "tool_runner.hpp"

namespace {

using nlohmann::json;

// bar_checks(rows) of bench/compare_peers (loaded as a module by /usr/bin/python3) as JSON.
json barChecks(const json& rows, const gear_test::ScratchDir& dir) {
  const auto rows_file = dir.path() / "rows.json", driver = dir.path() / "driver.py";
  gear_test::writeText(rows_file, rows.dump());
  gear_test::writeText(
      driver,
      "import importlib.machinery, importlib.util, json, sys\n"
      "loader = importlib.machinery.SourceFileLoader('compare_peers', sys.argv[1])\n"
      "spec = importlib.util.spec_from_loader('compare_peers', loader)\n"
      "m = importlib.util.module_from_spec(spec)\n"
      "loader.exec_module(m)\n"
      "print(json.dumps(m.bar_checks(json.load(open(sys.argv[2])))))\n");
  const gear_test::ToolRun r = gear_test::runShell(
      "/usr/bin/python3 '" + driver.string() + "' '" + std::string(GEAR_SOURCE_DIR) +
          "/bench/compare_peers' '" + rows_file.string() + "'",
      dir.path(), "bar_checks");
  EXPECT_EQ(r.code, 0) << r.err;
  return r.code == 0 ? json::parse(r.out) : json::array();
}

// A row as compare_peers' main() builds it.
json row(const std::string& group, const std::string& contender, const std::string& scase,
         double median, double ratio = -1.0) {
  json r = {{"group", group},     {"contender", contender}, {"case", scase},
            {"median_s", median}, {"min_s", median * 0.9},  {"max_s", median * 1.2}};
  r["ratio_to_package"] = ratio > 0.0 ? json(ratio) : json(nullptr);
  return r;
}

// A bars-group row with Google Benchmark's CPU time of the benchmark's thread.
json barRow(const std::string& contender, int threads, double wall, double cpu) {
  json r = row("bars", contender, "n=1000000 threads=" + std::to_string(threads), wall);
  r["cpu_median_s"] = cpu;
  r["cpu_min_s"] = cpu * 0.95;
  r["cpu_max_s"] = cpu * 1.25;
  return r;
}

// The check whose bar text contains `what`; null when there is none.
json find(const json& checks, const std::string& what) {
  for (const auto& c : checks) {
    if (c.at("bar").get<std::string>().find(what) != std::string::npos) return c;
  }
  return nullptr;
}

class CompareBars : public ::testing::Test {
 protected:
  gear_test::ScratchDir dir_{"gear_compare_bars"};
};

TEST_F(CompareBars, RatesOnOneThreadAreCpuTimeOnTwoWallTimeAgainstTheirTargets) {
  const json rows = json::array({
      // 1e6 samples in 5.0 ms of CPU: exactly the 200 M samples/s bar (met); the wall time of
      // 9 ms is not the measure on one thread.
      barRow("identification, known piecewise", 1, 0.009, 0.005),
      // two threads: the wall time, 3.2 ms = 312.5 M samples/s against 350 (1.12x short)
      barRow("identification, known piecewise", 2, 0.0032, 0.0064),
      // 1e6 samples in 8.0 ms: 125 M samples/s against 120 (met)
      barRow("identification, greybox piecewise", 1, 0.008, 0.008),
      // 1e6 samples in 0.2 s: 5 M samples/s against 25 (5x short)
      barRow("refinement, known piecewise, 40 dB", 1, 0.2, 0.2),
  });
  const json checks = barChecks(rows, dir_);
  ASSERT_EQ(checks.size(), 4u) << checks.dump(1);  // bars without rows are left out
  const json one = find(checks, "known piecewise, 1e6 samples, 1 thread");
  ASSERT_FALSE(one.is_null());
  EXPECT_EQ(one["status"], "met");
  EXPECT_EQ(one["target"], ">= 200 M samples/s");
  // the range over the rounds from the CPU extremes: 1e6 / (1.25 * 5 ms) .. 1e6 / (0.95 * 5 ms)
  EXPECT_EQ(one["measured"], "200 M samples/s (160-211 M samples/s)");
  const json two = find(checks, "known piecewise, 1e6 samples, 2 threads");
  ASSERT_FALSE(two.is_null());
  EXPECT_EQ(two["status"], "missed (1.12x short)");
  EXPECT_EQ(find(checks, "greybox")["status"], "met");
  EXPECT_EQ(find(checks, "refinement")["status"], "missed (5.00x short)");
}

TEST_F(CompareBars, TimeBarsAreStrictlyBelowTheirTarget) {
  const json rows = json::array({
      barRow("per-mode wavelet damping, 3 modes", 1, 0.025, 0.025),
      barRow("per-mode wavelet damping, 3 modes", 2, 0.019, 0.030),
      // 24.9 M samples/s against 25: 1.004x short, three decimals where two would read 1.00
      barRow("refinement, known piecewise, 40 dB", 1, 0.0, 1e6 / 24.9e6),
  });
  const json checks = barChecks(rows, dir_);
  ASSERT_EQ(checks.size(), 3u) << checks.dump(1);
  EXPECT_EQ(find(checks, "3 modes, 1e6 samples, 1 thread")["status"], "missed (1.25x short)");
  EXPECT_EQ(find(checks, "refinement")["status"], "missed (1.004x short)");
  EXPECT_EQ(find(checks, "3 modes, 1e6 samples, 2 threads")["status"], "met");
  EXPECT_EQ(find(checks, "2 threads")["measured"], "19.0 ms (17.1-22.8 ms)");
}

TEST_F(CompareBars, PeerRatiosAreJudgedInTheirDirection) {
  const std::string pkg = "gear_damping MorletScalogram (double)";
  const json rows = json::array({
      row("cwt", pkg, "n=100000 threads=1", 0.10, 1.0),
      row("cwt", pkg, "n=100000 threads=2", 0.05, 1.0),
      // fCWT 0.9x the package's time: the package is slower (1.11x short of 1.0x)
      row("cwt", "fCWT (float)", "n=100000 threads=1", 0.09, 0.9),
      // PyWavelets 0.95 s: 9.5x the package on one thread (missed), 19x on two (met)
      row("cwt", "PyWavelets (float64)", "n=100000 threads=1", 0.95, 9.5),
      row("sim", "scipy solve_ivp DOP853 (matched accuracy)", "n=1000000 threads=1", 6.0, 600.0),
      // analyze: lower is better, against the bare read
      row("io", "gear_damping analyze (default options)", "n=10000000 threads=1", 1.2, 6.0),
      row("io", "gear_damping analyze --refine never", "n=10000000 threads=1", 0.38, 1.9),
  });
  json with_rss = rows;
  with_rss[5]["max_rss_mb"] = 200.0;
  with_rss[6]["max_rss_mb"] = 48.0;
  const json checks = barChecks(with_rss, dir_);
  EXPECT_EQ(find(checks, "vs fCWT (n=100000 threads=1)")["status"], "missed (1.11x short)");
  EXPECT_EQ(find(checks, "vs PyWavelets (n=100000 threads=1)")["status"], "missed (1.05x short)");
  const json two = find(checks, "vs PyWavelets (n=100000, the package on 2 threads)");
  ASSERT_FALSE(two.is_null()) << checks.dump(1);
  EXPECT_EQ(two["measured"], "19.00x");
  EXPECT_EQ(two["status"], "met");
  EXPECT_EQ(find(checks, "scipy")["status"], "met");
  const json dflt = find(checks, "analyze, default options, vs the bare read");
  ASSERT_FALSE(dflt.is_null());
  EXPECT_EQ(dflt["status"], "missed (1.20x short)");
  // analyze runs with its default --threads: the case names the bag, not a thread count
  EXPECT_NE(dflt["bar"].get<std::string>().find("1e7-sample bag"), std::string::npos);
  EXPECT_EQ(dflt["bar"].get<std::string>().find("threads=1"), std::string::npos);
  EXPECT_EQ(find(checks, "analyze --refine never, vs the bare read")["status"], "met");
  EXPECT_EQ(find(checks, "peak RSS, default options")["status"], "missed");
  EXPECT_EQ(find(checks, "peak RSS, --refine never")["status"], "met");
}

}  // namespace
