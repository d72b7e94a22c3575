// What `analyze` prints and records about a run: the clean/flagged count that ends every run's
// table, the summary that replaces long tables, no progress line when stderr is not a
// terminal, the `metadata` object of the JSON (checked against the files themselves), and the
// document's shape (analysisJson) and its streamed writer (writeJsonAtomically).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>

#include "gear_damping_id/result_io.hpp"
#include "tool_runner.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kParams = std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml";

class AnalyzeOutput : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new gear_test::ScratchDir("analyze_output_test");
    // The default case: 10 ms, noise-free, so every 1 ms segment is clean.
    const gear_test::ToolRun s = gear_test::runTool(
        "simulate", "--config " + kParams + " --output " + signal().string(), scratch_->path());
    ASSERT_EQ(s.code, 0) << s.err;
  }
  static void TearDownTestSuite() {
    delete scratch_;
    scratch_ = nullptr;
  }
  static fs::path signal() { return scratch_->path() / "signal.csv"; }
  static gear_test::ToolRun analyze(const std::string& extra) {
    return gear_test::runTool("analyze",
                              "--input " + signal().string() + " --params " + kParams + " " + extra,
                              scratch_->path());
  }
  static gear_test::ScratchDir* scratch_;
};
gear_test::ScratchDir* AnalyzeOutput::scratch_ = nullptr;

size_t count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

TEST_F(AnalyzeOutput, EveryRunsTableEndsWithItsCleanAndFlaggedCount) {
  const gear_test::ToolRun r = analyze("--model piecewise --model constant --refine never");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(count(r.out, "  10 of 10 segments clean\n"), 2u) << r.out;
  EXPECT_NE(r.out.find("\n  seg   t_start"), std::string::npos);  // ten rows: a table
  EXPECT_EQ(r.out.find("summary of"), std::string::npos);
}

TEST_F(AnalyzeOutput, LegacyFormulationsFailureIsFlaggedInEverySegment) {
  // The constant-load method on a varying load (paper §4.1) fails: its segments come out with
  // C < 0 or not significantly different from zero (below_noise) or a model that cannot
  // reproduce the data (model_mismatch). None may be counted clean.
  const gear_test::ToolRun r = analyze("--formulation legacy --refine never");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::regex line("  ([0-9]+) of 10 segments clean, ([0-9]+) flagged \\(([^)]*)\\)\n");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.out, m, line)) << r.out;
  EXPECT_EQ(std::stoi(m[1]), 0) << r.out;
  EXPECT_EQ(std::stoi(m[2]), 10) << r.out;
  EXPECT_TRUE(m[3].str().find("model_mismatch") != std::string::npos ||
              m[3].str().find("nonpositive_damping") != std::string::npos)
      << m[3].str();
}

TEST_F(AnalyzeOutput, SummaryReplacesTheRowsOnRequestAndForLongRuns) {
  const gear_test::ToolRun asked = analyze("--summary --refine never");
  ASSERT_EQ(asked.code, 0) << asked.err;
  EXPECT_NE(asked.out.find("summary of 10 segments"), std::string::npos) << asked.out;
  EXPECT_NE(asked.out.find("C [1/s]"), std::string::npos);
  EXPECT_NE(asked.out.find("worst segments"), std::string::npos);
  EXPECT_EQ(asked.out.find("\n  seg   t_start"), std::string::npos);
  EXPECT_NE(asked.out.find("10 of 10 segments clean"), std::string::npos);

  // 0.1 ms segments: 100 of them, above the 50 where the summary becomes the default.
  const std::string fine = "--segment 1e-4 --window 1e-4 --refine never";
  const gear_test::ToolRun long_run = analyze(fine);
  ASSERT_EQ(long_run.code, 0) << long_run.err;
  EXPECT_NE(long_run.out.find("summary of 100 segments"), std::string::npos) << long_run.out;
  EXPECT_LT(count(long_run.out, "\n"), 30u);
  const gear_test::ToolRun table = analyze(fine + " --table");
  ASSERT_EQ(table.code, 0) << table.err;
  EXPECT_GT(count(table.out, "\n"), 100u);
  EXPECT_EQ(table.out.find("summary of"), std::string::npos);

  EXPECT_EQ(analyze("--summary --table").code, 1);  // contradictory
}

TEST_F(AnalyzeOutput, NoProgressLineWhenStderrIsNotATerminal) {
  const gear_test::ToolRun r = analyze("--wavelet");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.err.find('\r'), std::string::npos) << r.err;
  EXPECT_EQ(analyze("--quiet").code, 0);
}

TEST_F(AnalyzeOutput, JsonRecordsVersionCommandLineInputAndOptions) {
  const fs::path out = scratch_->path() / "result.json";
  const gear_test::ToolRun r = analyze("--segment 2e-3 --output " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json meta = nlohmann::json::parse(gear_test::readText(out)).at("metadata");
  // The version of package.xml, read here independently of the build.
  std::smatch m;
  const std::string xml = gear_test::readText(fs::path(GEAR_SOURCE_DIR) / "package.xml");
  ASSERT_TRUE(std::regex_search(xml, m, std::regex("<version>([^<]+)</version>")));
  EXPECT_EQ(meta.at("version"), m[1].str());
  EXPECT_EQ(meta.at("package"), "gear_damping");
  const std::string line = meta.at("command_line");
  EXPECT_NE(line.find("--segment 2e-3"), std::string::npos) << line;
  EXPECT_NE(line.find(signal().string()), std::string::npos) << line;
  EXPECT_EQ(meta.at("input").at("size_bytes"), fs::file_size(signal()));
  EXPECT_EQ(meta.at("input").at("absolute_path"), fs::absolute(signal()).string());
  EXPECT_EQ(meta.at("options").at("--segment"), nlohmann::json::array({"2e-3"}));
  EXPECT_TRUE(std::regex_match(meta.at("date").get<std::string>(),
                               std::regex("[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9:]{8}Z")));
}

double kNaNForTest() { return std::numeric_limits<double>::quiet_NaN(); }

gear_damping_id::AnalysisRun fakeRun(gear_damping_id::Formulation f,
                                     gear_damping_id::DampingModel m, int segments) {
  gear_damping_id::AnalysisRun run;
  run.options.formulation = run.result.formulation = f;
  run.options.model = run.result.model = m;
  for (int i = 0; i < segments; ++i) {
    gear_damping_id::SegmentEstimate s;
    s.t_start = 1e-3 * i;
    s.t_end = 1e-3 * (i + 1);
    s.C = 100.0 + i;
    s.identifiable = true;
    run.result.segments.push_back(s);
  }
  run.response.nrmse = 0.01 * (segments + 1);
  run.response.fit_percent = 99.0 - segments;
  return run;
}

// Two runs of one formulation (piecewise with 3 segments, then load_law with its block) and a
// constant run of another: `identification` is the primary run without its `response`, with
// the load_law block of the run that computed it (same formulation) and no constant block (that
// run's formulation differs); `response` is the primary run's; `runs` holds every run in full.
// writeJsonAtomically writes exactly dump(2) and a newline, and reports an unwritable path.
TEST(AnalysisJson, IdentificationIsThePrimaryRunPlusSharedBlocksAndTheWriterStreamsDump2) {
  namespace gd = gear_damping_id;
  std::vector<gd::AnalysisRun> runs{
      fakeRun(gd::Formulation::Known, gd::DampingModel::Piecewise, 3),
      fakeRun(gd::Formulation::Known, gd::DampingModel::LoadLaw, 2),
      fakeRun(gd::Formulation::Greybox, gd::DampingModel::Constant, 1)};
  gd::LoadLawEstimate law;
  law.c0 = 3.0;
  law.identifiable = false;
  law.reason = "why not";
  runs[1].result.load_law = law;
  runs[2].result.constant = runs[2].result.segments.front();
  const nlohmann::json input = {{"file", "x"}};
  const nlohmann::json doc = gd::analysisJson(runs, input);
  ASSERT_EQ(doc.at("runs").size(), 3u);
  for (size_t k = 0; k < runs.size(); ++k) EXPECT_EQ(doc["runs"][k], gd::runJson(runs[k])) << k;
  nlohmann::json id = gd::runJson(runs[0]);
  EXPECT_EQ(doc.at("response"), id.at("response"));
  id.erase("response");
  id["load_law"] = gd::runJson(runs[1]).at("load_law");
  EXPECT_EQ(id["load_law"].at("reason"), "why not");
  EXPECT_EQ(doc.at("identification"), id);
  EXPECT_FALSE(doc["identification"].contains("constant"));
  EXPECT_EQ(doc.at("input"), input);
  EXPECT_EQ(gd::analysisJson({}, input), nlohmann::json({{"input", input}}));

  gear_test::ScratchDir dir("analysis_json_writer");
  const fs::path out = dir.path() / "doc.json";
  ASSERT_TRUE(gd::writeJsonAtomically(out.string(), doc).ok());
  EXPECT_EQ(gear_test::readText(out), doc.dump(2) + "\n");
  const gear_sim::Status bad = gd::writeJsonAtomically((out / "not_a_dir.json").string(), doc);
  EXPECT_EQ(bad.code(), gear_sim::StatusCode::IoError);
  EXPECT_EQ(bad.field(), "path");
}

// writeAnalysisJsonAtomically (the segments written from the runs, no tree of them) writes the
// bytes of writeJsonAtomically(analysisJson(runs, input)): segments with every optional field
// present and absent (reason, stiffness levels, torque and its step, glitch and quantisation,
// integral/weighted estimates, curves,
// warnings, NaN and infinite values as null, a text needing escapes), runs without segments,
// and keys added to the document after analysisJson (as analyze adds metadata and STE blocks).
TEST(AnalysisJson, SegmentsWrittenFromTheRunsGiveTheBytesOfTheDocument) {
  namespace gd = gear_damping_id;
  std::vector<gd::AnalysisRun> runs{
      fakeRun(gd::Formulation::Greybox, gd::DampingModel::Piecewise, 4),
      fakeRun(gd::Formulation::Known, gd::DampingModel::LoadLaw, 0),
      fakeRun(gd::Formulation::Legacy, gd::DampingModel::Constant, 2)};
  std::vector<gd::SegmentEstimate>& s = runs[0].result.segments;
  s[0].C_std = 1.0 / 3.0, s[0].c = -2.5e-310, s[0].xi = 1e300, s[0].samples = 1234567890123;
  s[0].windows = 7, s[0].condition = std::numeric_limits<double>::infinity();
  s[0].refined = true, s[0].k_min = 1e7, s[0].k_max_std = 0.1;
  s[1].identifiable = false, s[1].reason = "a \"quoted\" reason\twith \\ and \u00e9";
  s[1].mean_torque = 3.25, s[1].forcing = -1.0, s[1].C_integral = 99.5;
  s[1].variation_z = 1.5, s[1].C_weighted = 98.0, s[1].C_torque_std = 0.5;
  s[1].torque_noise_std = 1e-3;
  s[2].stiffness_curve = {1.0, kNaNForTest(), 3.0};
  s[2].stiffness_curve_std = {0.1};
  s[2].warnings = {{"low_snr", "signal below noise"}, {"x", "y\n"}};
  s[3].noise_std = 0.25, s[3].signal_std = 2.0, s[3].residual_rms = 1e-17;
  // The torque channel's findings (their keys sort between and around torque_noise_std).
  s[3].torque_noise_std = 0.0, s[3].torque_step = 50.0, s[3].torque_step_time = 0.5;
  s[3].torque_step_response = 1e-9, s[3].torque_glitch = -20.0, s[3].torque_glitch_time = 0.25;
  s[3].torque_glitch_response = 2e-9, s[3].torque_glitch_shift = 3.5, s[3].torque_quantum = 0.5;
  s[3].torque_glitches = 2;
  s[3].torque_quantisation_shift = -1.5, s[3].torque_quantisation_fit = 0.9;
  s[3].torque_quantisation_fit_std = 0.1;
  runs[2].result.segments[1].identifiable = false;
  runs[2].result.constant = runs[2].result.segments.front();
  runs[2].response_error = "diverged";
  const nlohmann::json input = {{"file", "x"}, {"samples", 10}};
  nlohmann::json tree = gd::analysisJson(runs, input);
  nlohmann::json doc = gd::analysisJson(runs, input, /*segments=*/false);
  EXPECT_TRUE(doc["identification"]["segments"].is_null());
  for (nlohmann::json* d : {&tree, &doc}) {
    (*d)["metadata"] = {{"a", 1}};
    (*d)["identification"]["ste"] = {{"segments", {1, 2}}};
    (*d)["runs"][1]["ste"] = nlohmann::json::object();
  }
  gear_test::ScratchDir dir("analysis_json_segments");
  const fs::path a = dir.path() / "tree.json", b = dir.path() / "streamed.json";
  ASSERT_TRUE(gd::writeJsonAtomically(a.string(), tree).ok());
  ASSERT_TRUE(gd::writeAnalysisJsonAtomically(b.string(), doc, runs).ok());
  EXPECT_EQ(gear_test::readText(b), gear_test::readText(a));
  EXPECT_EQ(gear_test::readText(a), tree.dump(2) + "\n");
  // Each formulation's field set (stiffness levels for all but known), one run each.
  for (const gd::Formulation f : {gd::Formulation::Known, gd::Formulation::Greybox,
                                  gd::Formulation::Paper, gd::Formulation::Legacy}) {
    std::vector<gd::AnalysisRun> one{runs[0]};
    one[0].options.formulation = one[0].result.formulation = f;
    ASSERT_TRUE(gd::writeJsonAtomically(a.string(), gd::analysisJson(one, input)).ok());
    ASSERT_TRUE(
        gd::writeAnalysisJsonAtomically(b.string(), gd::analysisJson(one, input, false), one).ok());
    EXPECT_EQ(gear_test::readText(b), gear_test::readText(a)) << gd::toString(f);
  }
  const gear_sim::Status bad =
      gd::writeAnalysisJsonAtomically((b / "not_a_dir.json").string(), doc, runs);
  EXPECT_EQ(bad.code(), gear_sim::StatusCode::IoError);
}

// A long record's segments are written in batches, every second one formatted on a thread of
// its own (AnalysisJsonWriter::segments): for segment counts around the batch edges (256) and
// many batches, with values of every magnitude, NaN, curves and warnings spread over the
// batches, the bytes are still those of dump(2).
TEST(AnalysisJson, SegmentsFormattedInBatchesOnTwoThreadsGiveTheBytesOfTheDocument) {
  namespace gd = gear_damping_id;
  gear_test::ScratchDir dir("analysis_json_batches");
  const fs::path a = dir.path() / "tree.json", b = dir.path() / "batched.json";
  const nlohmann::json input = {{"file", "x"}};
  for (const int n : {255, 256, 257, 511, 512, 513, 2049}) {
    std::vector<gd::AnalysisRun> runs{
        fakeRun(gd::Formulation::Greybox, gd::DampingModel::Piecewise, n),
        fakeRun(gd::Formulation::Known, gd::DampingModel::Piecewise, n / 3)};
    std::vector<gd::SegmentEstimate>& s = runs[0].result.segments;
    for (int i = 0; i < n; ++i) {
      gd::SegmentEstimate& e = s[static_cast<size_t>(i)];
      e.C = std::ldexp(1.0 + i / 7.0, (i % 40) - 20);
      e.C_std = i % 97 == 0 ? kNaNForTest() : 1.0 / (i + 3.0);
      e.xi = -e.C * 1e-5;
      e.samples = 1000 + i;
      e.identifiable = i % 101 != 0;
      if (!e.identifiable) e.reason = "reason " + std::to_string(i);
      if (i % 255 == 0) e.stiffness_curve = {1.0 * i, kNaNForTest()};
      if (i % 256 == 1) e.warnings = {{"code", "text " + std::to_string(i)}};
    }
    ASSERT_TRUE(gd::writeJsonAtomically(a.string(), gd::analysisJson(runs, input)).ok());
    ASSERT_TRUE(
        gd::writeAnalysisJsonAtomically(b.string(), gd::analysisJson(runs, input, false), runs)
            .ok());
    EXPECT_EQ(gear_test::readText(b), gear_test::readText(a)) << n << " segments";
  }
}

}  // namespace
