// run_summary: counting clean and flagged segments by code, statistics of C and xi, the worst
// segments, and the switch from tables to summaries for long records.
#include "gear_damping_id/run_summary.hpp"

#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

namespace gd = gear_damping_id;

namespace {

gd::SegmentEstimate segment(double t0, double C, double C_std) {
  gd::SegmentEstimate s;
  s.t_start = t0;
  s.t_end = t0 + 1e-3;
  s.C = C;
  s.C_std = C_std;
  s.xi = C / (2.0 * 62748.0);
  s.identifiable = true;
  return s;
}

std::vector<gd::SegmentEstimate> tenSegments() {
  std::vector<gd::SegmentEstimate> v;
  for (int i = 0; i < 10; ++i) v.push_back(segment(1e-3 * i, 6000.0 + 100.0 * i, 1.0));
  v[3].identifiable = false;
  v[3].reason = "no motion";
  v[3].C = v[3].xi = gd::kNaN;
  v[7].warnings.push_back({"refine_disagrees", "refined C differs from the integral C by 9 SE"});
  v[7].warnings.push_back({"negative_damping", "C < 0"});
  return v;
}

TEST(RunSummary, CountsCleanAndFlaggedSegmentsByCode) {
  const gd::SegmentSummary s = gd::summarizeSegments(tenSegments());
  EXPECT_EQ(s.total, 10u);
  EXPECT_EQ(s.clean, 8u);
  EXPECT_EQ(s.flagged, 2u);
  EXPECT_EQ(s.identifiable, 9u);
  EXPECT_EQ(s.codes.at("not_identifiable"), 1u);
  EXPECT_EQ(s.codes.at("refine_disagrees"), 1u);
  EXPECT_EQ(s.codes.at("negative_damping"), 1u);
  EXPECT_EQ(gd::summaryLine(s),
            "8 of 10 segments clean, 2 flagged (negative_damping 1, not_identifiable 1, "
            "refine_disagrees 1)");
}

TEST(RunSummary, CleanRunSaysSo) {
  std::vector<gd::SegmentEstimate> v{segment(0.0, 6000.0, 1.0)};
  EXPECT_EQ(gd::summaryLine(gd::summarizeSegments(v)), "1 of 1 segment clean");
}

TEST(RunSummary, StatisticsCoverTheIdentifiableSegmentsOnly) {
  const gd::SegmentSummary s = gd::summarizeSegments(tenSegments());
  // C = 6000 + 100 i over i = 0..9 without i = 3: nine values, median at i = 5.
  EXPECT_EQ(s.C.count, 9u);
  EXPECT_DOUBLE_EQ(s.C.min, 6000.0);
  EXPECT_DOUBLE_EQ(s.C.max, 6900.0);
  EXPECT_DOUBLE_EQ(s.C.median, 6500.0);
  EXPECT_DOUBLE_EQ(s.C.mean, (45.0 - 3.0) / 9.0 * 100.0 + 6000.0);
  EXPECT_DOUBLE_EQ(s.xi.median, 6500.0 / (2.0 * 62748.0));
}

TEST(RunSummary, WorstSegmentsAreFlaggedFirstThenByRelativeError) {
  auto v = tenSegments();
  v[5].C_std = 300.0;  // the least precise clean segment
  const gd::SegmentSummary s = gd::summarizeSegments(v, 3);
  ASSERT_EQ(s.worst.size(), 3u);
  EXPECT_EQ(s.worst[0], 3u);  // not identifiable
  EXPECT_EQ(s.worst[1], 7u);  // warnings
  EXPECT_EQ(s.worst[2], 5u);  // largest C_std / C
}

gd::AnalysisRun runWith(size_t n) {
  gd::AnalysisRun run;
  run.result.estimator = "integral";
  for (size_t i = 0; i < n; ++i) run.result.segments.push_back(segment(1e-3 * i, 6000.0, 1.0));
  run.response.fit_percent = 99.0;
  run.response.nrmse = 0.01;
  return run;
}

size_t count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

TEST(RunSummary, ShortRunsPrintTheirTableEndingWithTheSummaryLine) {
  std::ostringstream os;
  gd::printRuns(os, {runWith(gd::kSummaryAboveSegments)}, gd::RunPrintMode::Auto);
  const std::string out = os.str();
  EXPECT_GT(count(out, "\n"), gd::kSummaryAboveSegments) << out;  // one row per segment
  EXPECT_EQ(out.substr(out.rfind('\n', out.size() - 2) + 1), "  50 of 50 segments clean\n");
  EXPECT_EQ(out.find("summary of"), std::string::npos);
}

TEST(RunSummary, LongRunsPrintASummaryInsteadOfOneLinePerSegment) {
  std::ostringstream os;
  gd::printRuns(os, {runWith(5000)}, gd::RunPrintMode::Auto);
  const std::string out = os.str();
  EXPECT_NE(out.find("summary of 5000 segments"), std::string::npos) << out;
  EXPECT_NE(out.find("modeled response: fit"), std::string::npos) << out;
  EXPECT_NE(out.find("5000 of 5000 segments clean"), std::string::npos) << out;
  EXPECT_LT(count(out, "\n"), 20u) << out;  // a screenful, not 5000 rows
}

TEST(RunSummary, TableModeForcesTheRowsAndSummaryModeForcesTheSummary) {
  std::ostringstream table, summary;
  gd::printRuns(table, {runWith(60)}, gd::RunPrintMode::Table);
  gd::printRuns(summary, {runWith(3)}, gd::RunPrintMode::Summary);
  EXPECT_GT(count(table.str(), "\n"), 60u);
  EXPECT_NE(summary.str().find("summary of 3 segments"), std::string::npos);
}

}  // namespace
