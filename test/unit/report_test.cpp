// The report script on a small real result (simulate -> analyze with every model and the
// wavelet on the free decay -> report): every figure exists, is a PNG of the documented size,
// and index.html shows it with the run's metadata; flagged values are highlighted; headless
// Chromium renders the page with every image loaded (a screenshot is kept beside the test
// results); a missing result gives exit code 2 with a message.
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

#include "tool_runner.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kParams = std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml";
const std::string kReport =
    "/usr/bin/python3 " + std::string(GEAR_SOURCE_DIR) + "/gear_damping_id/scripts/report ";

const char* const kFigures[] = {
    "fig04_load_stiffness.png",     "fig05_dte.png",       "fig06_response_legacy.png",
    "fig07_response_constant.png",  "fig08_damping.png",   "fig09_response_piecewise.png",
    "fig09b_response_load_law.png", "fig10_scalogram.png", "fig11_spectrum.png",
    "fig12_envelopes.png"};
constexpr size_t kFigureCount = sizeof kFigures / sizeof kFigures[0];

// Width and height from a PNG's IHDR chunk (0 x 0 if not a PNG).
std::array<std::uint32_t, 2> pngSize(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  unsigned char b[24] = {};
  f.read(reinterpret_cast<char*>(b), sizeof b);
  const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (!f || !std::equal(sig, sig + 8, b)) return {0, 0};
  auto be = [&](int o) {
    return (std::uint32_t(b[o]) << 24) | (std::uint32_t(b[o + 1]) << 16) |
           (std::uint32_t(b[o + 2]) << 8) | std::uint32_t(b[o + 3]);
  };
  return {be(16), be(20)};
}

int shell(const std::string& cmd) {
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Where catkin collects this binary's results (--gtest_output=xml:DIR/file.xml), else the temp
// dir: the browser screenshot is kept there for a human to look at.
fs::path testOutputDir() {
  const std::string out = ::testing::GTEST_FLAG(output);
  if (out.rfind("xml:", 0) == 0) {
    const fs::path p = fs::path(out.substr(4)).parent_path();
    if (!p.empty() && fs::is_directory(p)) return p;
  }
  return fs::temp_directory_path();
}

// One small real result shared by the tests (simulating and analysing takes a few seconds).
class Report : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new gear_test::ScratchDir("report_test");
    const fs::path dir = scratch_->path(), res = dir / "result";
    fs::create_directories(res);
    const std::string sim = " --config " + kParams + " --duration 0.004";
    ASSERT_EQ(
        gear_test::runTool("simulate", sim + " --output " + (res / "signal.csv").string(), dir)
            .code,
        0);
    ASSERT_EQ(gear_test::runTool(
                  "simulate",
                  sim + " --free-response --output " + (res / "free_response.csv").string(), dir)
                  .code,
              0);
    const gear_test::ToolRun a = gear_test::runTool(
        "analyze",
        "--input " + (res / "signal.csv").string() + " --params " + kParams +
            " --formulation known --formulation legacy --model piecewise --model constant"
            " --model load_law --wavelet-input " +
            (res / "free_response.csv").string() + " --output " + (res / "result.json").string() +
            " --csv-out " + (res / "tables").string(),
        dir);
    ASSERT_EQ(a.code, 0) << a.err;
    report_rc_ = shell(kReport + res.string() + " >" + (dir / "out.txt").string() + " 2>&1");
  }
  static void TearDownTestSuite() {
    delete scratch_;
    scratch_ = nullptr;
  }
  static fs::path result() { return scratch_->path() / "result"; }
  static std::string index() { return gear_test::readText(result() / "report" / "index.html"); }

  static gear_test::ScratchDir* scratch_;
  static int report_rc_;
};
gear_test::ScratchDir* Report::scratch_ = nullptr;
int Report::report_rc_ = -1;

TEST_F(Report, DrawsEveryFigureOfASmallResult) {
  ASSERT_EQ(report_rc_, 0) << gear_test::readText(scratch_->path() / "out.txt");
  const std::string html = index();
  for (const char* fig : kFigures) {
    const fs::path p = result() / "report" / fig;
    ASSERT_TRUE(fs::is_regular_file(p)) << fig;
    EXPECT_GT(fs::file_size(p), 10000u) << fig;  // a drawn figure, not an empty canvas
    const auto size = pngSize(p);
    EXPECT_EQ(size[0], 1200u) << fig;
    EXPECT_EQ(size[1], 750u) << fig;
    EXPECT_NE(html.find(fig), std::string::npos) << fig;
  }
  EXPECT_NE(html.find("Wavelet modes"), std::string::npos);
  EXPECT_NE(html.find("ξ integral method"), std::string::npos);  // the Table 2 comparison
  EXPECT_EQ(html.find("not drawn"), std::string::npos) << html;
}

TEST_F(Report, HeaderCarriesTheRunMetadataAndTheInputHash) {
  ASSERT_EQ(report_rc_, 0);
  const std::string html = index();
  const fs::path signal = result() / "signal.csv";
  EXPECT_NE(html.find("command line"), std::string::npos);
  EXPECT_NE(html.find("--formulation known --formulation legacy"), std::string::npos) << html;
  EXPECT_NE(html.find(fs::absolute(signal).string()), std::string::npos);
  std::string size = std::to_string(fs::file_size(signal));  // printed in groups of three
  for (int i = static_cast<int>(size.size()) - 3; i > 0; i -= 3) size.insert(i, " ");
  EXPECT_NE(html.find(size + " bytes"), std::string::npos) << size;
  // The SHA-256 from coreutils, independent of the report's Python.
  const fs::path sum = scratch_->path() / "sha.txt";
  ASSERT_EQ(shell("sha256sum " + signal.string() + " >" + sum.string()), 0);
  const std::string digest = gear_test::readText(sum).substr(0, 64);
  EXPECT_NE(html.find(digest), std::string::npos) << digest;
  EXPECT_TRUE(std::regex_search(html, std::regex("gear_damping [0-9]+\\.[0-9]+\\.[0-9]+")));
}

TEST_F(Report, RendersInHeadlessChromiumWithEveryImageLoaded) {
  ASSERT_EQ(report_rc_, 0);
  ASSERT_EQ(shell("command -v chromium >/dev/null"), 0)
      << "Debian's chromium is needed (scripts/common.sh installs it)";
  const fs::path dir = scratch_->path(), shot = testOutputDir() / "report_test_screenshot.png";
  // Chromium as root needs --no-sandbox; a private profile keeps runs independent.
  const std::string chrome =
      "timeout 120 chromium --headless --no-sandbox --disable-gpu "
      "--hide-scrollbars --user-data-dir=" +
      (dir / "chromium").string() + " --virtual-time-budget=10000 ";
  auto render = [&](const fs::path& page, const fs::path& dom) {
    return shell(chrome + "--dump-dom file://" + page.string() + " >" + dom.string() +
                 " 2>/dev/null");
  };
  ASSERT_EQ(render(result() / "report" / "index.html", dir / "dom.html"), 0);
  const std::string dom = gear_test::readText(dir / "dom.html");
  EXPECT_NE(dom.find("data-images=\"" + std::to_string(kFigureCount) + "\""), std::string::npos)
      << dom.substr(0, 2000);
  EXPECT_NE(dom.find("data-images-broken=\"0\""), std::string::npos) << dom.substr(0, 2000);
  fs::remove(shot);
  ASSERT_EQ(shell(chrome + "--window-size=1300,2400 --screenshot=" + shot.string() + " file://" +
                  (result() / "report" / "index.html").string() + " >/dev/null 2>&1"),
            0);
  const auto size = pngSize(shot);
  EXPECT_EQ(size[0], 1300u) << shot;
  EXPECT_EQ(size[1], 2400u) << shot;
  EXPECT_GT(fs::file_size(shot), 50000u) << shot;  // text, tables and figures, not a blank page
  std::cout << "screenshot: " << shot.string() << "\n";

  // The check can fail: the same page with one figure missing reports it broken.
  const fs::path copy = dir / "broken_report";
  fs::copy(result() / "report", copy, fs::copy_options::recursive);
  fs::remove(copy / kFigures[3]);
  ASSERT_EQ(render(copy / "index.html", dir / "dom_broken.html"), 0);
  const std::string broken = gear_test::readText(dir / "dom_broken.html");
  EXPECT_NE(broken.find("data-images-broken=\"1\""), std::string::npos) << broken.substr(0, 2000);
  EXPECT_NE(broken.find(std::string("figure failed to load: ") + kFigures[3]), std::string::npos);
}

// A result with every kind of doubtful value (written by hand: the flags must be highlighted
// whatever produced them).
TEST(ReportFlags, HighlightsEveryKindOfDoubtfulValue) {
  gear_test::ScratchDir scratch("report_flags_test");
  const fs::path res = scratch.path();
  gear_test::writeText(res / "result.json", R"({
  "input": {"file": "rig.csv", "samples": 4000, "sample_rate": 1e6, "duration": 0.004},
  "identification": {"formulation": "known", "model": "piecewise", "segments": [
    {"t_start": 0.000, "t_end": 0.001, "C": 6275.0, "C_std": 1.0, "c": 510.0, "xi": 0.05,
     "identifiable": true, "warnings": []},
    {"t_start": 0.001, "t_end": 0.002, "C": null, "C_std": null, "c": null, "xi": null,
     "identifiable": false, "reason": "no motion", "warnings": []},
    {"t_start": 0.002, "t_end": 0.003, "C": -42.0, "C_std": 3.0, "c": -3.4, "xi": -0.0003,
     "identifiable": true, "warnings": []},
    {"t_start": 0.003, "t_end": 0.004, "C": 130000.0, "C_std": 9.0, "c": 10569.0, "xi": 1.04,
     "identifiable": true, "warnings": [{"code": "refine_disagrees", "text": "by 9 SE"}]}]},
  "runs": [
    {"formulation": "legacy", "model": "constant", "estimator": "integral",
     "constant": {"C": 6000.0, "C_std": 5.0, "xi": 0.048, "identifiable": true},
     "response": {"fit_percent": -425812.0, "nrmse": 4259.12}, "warnings": []}],
  "wavelet": {"modes": [
    {"frequency_hz": 1000.0, "damping_ratio": 0.002, "integral_damping_ratio": 0.05, "r2": 0.99,
     "t_start": 0.001, "t_end": 0.003, "free_decay": false, "warnings": []},
    {"frequency_hz": 9990.0, "damping_ratio": 0.051, "integral_damping_ratio": 0.05, "r2": 0.999,
     "t_start": 0.0005, "t_end": 0.002, "free_decay": true,
     "warnings": [{"code": "close_modes", "text": "a neighbour leaks 2 %"}]}]}
})");
  const fs::path out = res / "out.txt";
  ASSERT_EQ(shell(kReport + res.string() + " >" + out.string() + " 2>&1"), 0)
      << gear_test::readText(out);
  const std::string html = gear_test::readText(res / "report" / "index.html");
  auto has = [&](const std::string& s) { return html.find(s) != std::string::npos; };
  EXPECT_TRUE(has("1 of 4 segments clean, 3 flagged")) << html;
  EXPECT_TRUE(has("not_identifiable: no motion"));
  EXPECT_TRUE(has("nonpositive_damping: C = -42 1/s &lt;= 0"));
  EXPECT_TRUE(has("overdamped: xi = 1.04 &gt;= 1"));
  EXPECT_TRUE(has("refine_disagrees: by 9 SE"));
  EXPECT_TRUE(has("negative_fit: fit -425812.0 %"));
  EXPECT_TRUE(has("forced line: no damping"));
  EXPECT_TRUE(has("close_modes: a neighbour leaks 2 %"));
  EXPECT_TRUE(has("none in result.json"));  // no metadata: said, not invented
  // Each flagged row (3 segments, the run, 2 modes) is marked; the clean segment is not.
  size_t rows = 0;
  for (size_t p = html.find("<tr class=flagged>"); p != std::string::npos;
       p = html.find("<tr class=flagged>", p + 1))
    ++rows;
  EXPECT_EQ(rows, 6u) << html;
}

// A greybox fourier/table run: the identified stiffness curve of every segment over a mesh
// cycle is drawn (a flagged segment dashed); without such a run the figure is left out silently.
TEST(ReportStiffnessCurve, DrawsTheGreyboxShapeCurve) {
  gear_test::ScratchDir scratch("report_curve_test");
  const fs::path res = scratch.path();
  gear_test::writeText(res / "result.json", R"({
  "input": {"file": "rig.csv", "samples": 2000, "sample_rate": 1e6, "duration": 0.002},
  "identification": {"formulation": "greybox", "model": "piecewise", "segments": []},
  "runs": [
    {"formulation": "greybox", "model": "piecewise", "estimator": "output_error",
     "stiffness_shape": "fourier:2", "warnings": [], "segments": [
      {"t_start": 0.000, "t_end": 0.001, "C": 6275.0, "C_std": 9.0, "identifiable": true,
       "stiffness_curve": [3.0e8, 6.0e7, 2.0e7, -1.5e7, 1.0e7], "warnings": []},
      {"t_start": 0.001, "t_end": 0.002, "C": 6100.0, "C_std": 9.0, "identifiable": true,
       "stiffness_curve": [3.1e8, 5.0e7, 2.5e7, -1.0e7, 0.5e7],
       "warnings": [{"code": "model_mismatch", "text": "residual 9x the noise"}]}]}]
})");
  const fs::path out = res / "out.txt";
  ASSERT_EQ(shell(kReport + res.string() + " >" + out.string() + " 2>&1"), 0)
      << gear_test::readText(out);
  const fs::path fig = res / "report" / "fig08b_stiffness_curve.png";
  ASSERT_TRUE(fs::is_regular_file(fig)) << gear_test::readText(out);
  EXPECT_GT(fs::file_size(fig), 10000u);
  const auto size = pngSize(fig);
  EXPECT_EQ(size[0], 1200u);
  EXPECT_EQ(size[1], 750u);
  EXPECT_NE(gear_test::readText(res / "report" / "index.html").find("fig08b_stiffness_curve.png"),
            std::string::npos);
}

// A response with samples not modeled (a NaN torque sample: response.unmodeled_samples, empty
// fields in response_known_piecewise.csv) is drawn, with its gap, not refused.
TEST(ReportResponse, DrawsAResponseWithUnmodeledSamples) {
  gear_test::ScratchDir scratch("report_gap_test");
  const fs::path dir = scratch.path(), res = dir / "result";
  fs::create_directories(res);
  ASSERT_EQ(gear_test::runTool("simulate",
                               " --config " + kParams + " --duration 0.004 --output " +
                                   (dir / "clean.csv").string(),
                               dir)
                .code,
            0);
  std::ifstream in(dir / "clean.csv");
  std::ofstream out(res / "signal.csv");
  std::string line;
  for (int k = 0; std::getline(in, line); ++k) {
    if (k == 1501) {  // sample 1500: the torque field (the fifth) NaN
      size_t at = 0;
      for (int f = 0; f < 4; ++f) at = line.find(',', at) + 1;
      line = line.substr(0, at) + "nan" + line.substr(line.find(',', at));
    }
    out << line << "\n";
  }
  out.close();
  const gear_test::ToolRun a = gear_test::runTool(
      "analyze",
      "--input " + (res / "signal.csv").string() + " --params " + kParams + " --output " +
          (res / "result.json").string() + " --csv-out " + (res / "tables").string(),
      dir);
  ASSERT_EQ(a.code, 0) << a.err;
  ASSERT_NE(gear_test::readText(res / "result.json").find("unmodeled_samples"), std::string::npos);
  EXPECT_EQ(shell(kReport + res.string() + " -q >" + (dir / "out.txt").string() + " 2>&1"), 0)
      << gear_test::readText(dir / "out.txt");
  const fs::path fig = res / "report" / "fig09_response_piecewise.png";
  ASSERT_TRUE(fs::is_regular_file(fig));
  EXPECT_GT(fs::file_size(fig), 10000u);
}

TEST(ReportErrors, ExitsWithTwoWithoutAResult) {
  gear_test::ScratchDir scratch("report_missing_test");
  const fs::path out = scratch.path() / "out.txt";
  EXPECT_EQ(shell(kReport + scratch.path().string() + " 2>" + out.string()), 2);
  EXPECT_NE(gear_test::readText(out).find("no result.json"), std::string::npos);
  EXPECT_EQ(shell(kReport + (scratch.path() / "nope").string() + " 2>" + out.string()), 2);
  EXPECT_NE(gear_test::readText(out).find("no such directory"), std::string::npos);
}

}  // namespace
