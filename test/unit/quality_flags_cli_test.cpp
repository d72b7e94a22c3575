// Quality flags and greybox stiffness shapes through the real `analyze` executable: the
// warnings in the JSON (segments[] and runs[] as [{code, text}]), in segments.csv / summary.csv
// and in the printed table; --stiffness-shape with the curve in the JSON; the exit codes (0 for
// flagged estimates, 4 when every segment is below the noise, 1 for an invalid shape).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "gear_sim/config_yaml.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim/simulator.hpp"
#include "status_support.hpp"
#include "tool_runner.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kParams = std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml";

gear_sim::SimConfig baseConfig() {
  gear_sim::SimConfig c;
  std::string e;
  EXPECT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(kParams, &c), &e)) << e;
  c.simulation.duration = 4e-3;  // four 1 ms segments
  return c;
}

// Simulates `c` into dir/name.csv and writes its mesh section as dir/name.yaml (analyze's
// --params must describe the record's stiffness model).
std::pair<std::string, std::string> record(const gear_sim::SimConfig& c, const fs::path& dir,
                                           const std::string& name, double noise_rel = 0.0) {
  gear_sim::SignalTable t;
  std::string e;
  EXPECT_TRUE(gear_test::ok(gear_sim::simulate(c, &t), &e)) << e;
  if (noise_rel > 0.0) {  // white noise of noise_rel times the mean |DTE| (seeded)
    std::mt19937_64 gen(7);
    std::normal_distribution<double> nd(0.0, noise_rel * t.dte.cwiseAbs().mean());
    for (Eigen::Index i = 0; i < t.size(); ++i) t.dte[i] += nd(gen);
  }
  const std::string csv = (dir / (name + ".csv")).string();
  EXPECT_TRUE(gear_test::ok(gear_sim::writeSignalCsv(csv, t), &e)) << e;
  return {csv, kParams};
}

nlohmann::json readJson(const fs::path& p) { return nlohmann::json::parse(gear_test::readText(p)); }

TEST(AnalyzeQualityFlags, GreyboxOnTrapezoidIsFlaggedEverywhereAndExitsZero) {
  gear_test::ScratchDir dir("quality_flags_cli_trapezoid");
  gear_sim::SimConfig c = baseConfig();
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = 0.1;
  const auto [csv, params] = record(c, dir.path(), "trap");
  const fs::path out = dir.path() / "r.json", tables = dir.path() / "tables";
  const gear_test::ToolRun r = gear_test::runTool(
      "analyze",
      "--input " + csv + " --params " + params + " --formulation greybox --output " + out.string() +
          " --csv-out " + tables.string(),
      dir.path());
  ASSERT_EQ(r.code, 0) << r.err;  // flagged but computed
  const nlohmann::json j = readJson(out);
  const auto& segs = j["runs"][0]["segments"];
  ASSERT_EQ(segs.size(), 4u);
  for (const auto& s : segs) {
    bool mismatch = false;
    for (const auto& w : s["warnings"]) {
      EXPECT_TRUE(w.contains("code") && w.contains("text"));
      mismatch |= w["code"] == "model_mismatch";
      EXPECT_FALSE(w["text"].get<std::string>().empty());
    }
    EXPECT_TRUE(mismatch) << s.dump();
  }
  EXPECT_TRUE(j["runs"][0]["warnings"].is_array());
  EXPECT_NE(r.out.find("flagged: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("model_mismatch"), std::string::npos) << r.out;
  const std::string seg_csv = gear_test::readText(tables / "segments.csv");
  EXPECT_NE(seg_csv.find(",warnings,stiffness_curve\n"), std::string::npos) << seg_csv;
  EXPECT_NE(seg_csv.find("model_mismatch"), std::string::npos) << seg_csv;
  EXPECT_NE(gear_test::readText(tables / "summary.csv").find(",warnings\n"), std::string::npos);
}

TEST(AnalyzeQualityFlags, TableShapeGivesTheCurveAndACleanEstimate) {
  gear_test::ScratchDir dir("quality_flags_cli_table");
  gear_sim::SimConfig c = baseConfig();
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = 0.1;  // corners on the nodes j/20
  // Damping constant on each segment, as the piecewise model holds it (the shipped
  // load-dependent damping varies within a segment, which the refinement honestly flags).
  c.damping.model = gear_sim::DampingProfile::Piecewise;
  c.damping.times = {0.0, 1e-3, 2e-3, 3e-3};
  c.damping.ratios = {0.05, 0.03, 0.07, 0.04};
  const auto [csv, params] = record(c, dir.path(), "trap");
  const fs::path out = dir.path() / "r.json";
  const gear_test::ToolRun r = gear_test::runTool(
      "analyze",
      "--input " + csv + " --params " + params +
          " --formulation greybox --stiffness-shape table:20 --output " + out.string(),
      dir.path());
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = readJson(out);
  EXPECT_EQ(j["runs"][0]["stiffness_shape"], "table:20");
  for (const auto& s : j["runs"][0]["segments"]) {
    ASSERT_EQ(s["stiffness_curve"].size(), 20u) << s.dump();
    EXPECT_EQ(s["warnings"].size(), 0u) << s.dump();
    // Node 5 (phase 0.25) lies in the double-contact plateau: k_max.
    EXPECT_NEAR(s["stiffness_curve"][5].get<double>(), c.mesh.k_max, 1e-3 * c.mesh.k_max);
  }
  EXPECT_EQ(r.out.find("flagged: "), std::string::npos) << r.out;
  const gear_test::ToolRun bad = gear_test::runTool(
      "analyze", "--input " + csv + " --params " + params + " --stiffness-shape fourier:0",
      dir.path());
  EXPECT_EQ(bad.code, 1);
  EXPECT_NE(bad.err.find("fourier:H"), std::string::npos) << bad.err;
}

TEST(AnalyzeQualityFlags, NoiseWithoutMotionIsNotIdentifiableAndExitsFour) {
  gear_test::ScratchDir dir("quality_flags_cli_noise");
  gear_sim::SimConfig c = baseConfig();
  c.mesh.model = gear_sim::StiffnessModel::Constant;
  c.load.profile = gear_sim::LoadProfile::Constant;
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  // Start at the static deflection: no transient, the record is the deflection plus noise.
  const double me = c.gears.equivalentMass();
  c.simulation.initial_dte = c.gears.forceFactor() * c.load.mean * me / c.mesh.k_mean;
  const auto [csv, params] = record(c, dir.path(), "still", 1e-3);
  const gear_test::ToolRun r =
      gear_test::runTool("analyze", "--input " + csv + " --params " + params, dir.path());
  EXPECT_EQ(r.code, 4) << r.out << r.err;
  EXPECT_NE(r.out.find("below noise"), std::string::npos) << r.out;
}

}  // namespace
