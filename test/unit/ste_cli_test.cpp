// Issue 19 (STE part) through the tools: simulate config/ste_example.yaml -> analyze --ste ->
// the identification.ste JSON block, tables/ste.csv and the report's STE figure; the simulator
// without an `ste` section is bit-identical to one with an empty section; bad --ste specs are
// usage errors.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "status_support.hpp"
#include "tool_runner.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kSte = std::string(GEAR_SOURCE_DIR) + "/config/ste_example.yaml";

TEST(SteCli, AnalyzeWritesTheSteSpectrumAndTheReportDrawsIt) {
  gear_test::ScratchDir scratch("ste_cli_test");
  const fs::path dir = scratch.path(), res = dir / "result";
  fs::create_directories(res);
  ASSERT_EQ(
      gear_test::runTool(
          "simulate",
          "-q --config " + kSte + " --duration 0.02 --output " + (res / "signal.csv").string(), dir)
          .code,
      0);
  const gear_test::ToolRun a = gear_test::runTool(
      "analyze",
      "-q --input " + (res / "signal.csv").string() + " --params " + kSte +
          " --ste mesh:3,shaft:1 --refine never --output " + (res / "result.json").string() +
          " --csv-out " + (res / "tables").string(),
      dir);
  ASSERT_EQ(a.code, 0) << a.err;
  const auto doc = nlohmann::json::parse(gear_test::readText(res / "result.json"));
  const auto& ste = doc["identification"]["ste"];
  ASSERT_TRUE(ste.is_object()) << doc.dump(1);
  EXPECT_EQ(ste["damping"], "relative");
  EXPECT_TRUE(ste["separable"].get<bool>());
  ASSERT_EQ(ste["mesh"].size(), 3u);
  ASSERT_EQ(ste["shaft"].size(), 2u);
  EXPECT_EQ(ste["shaft"][0]["shaft"], "pinion");
  EXPECT_EQ(ste["shaft"][1]["shaft"], "gear");
  // The shipped spectrum (config/ste_example.yaml), within 0.5 % (the load-dependent true damping
  // varies inside each 1 ms segment here, so the piecewise model is only nearly exact). The
  // integral fit: the output-error refinement, which Auto runs on this model error, moves the
  // shaft orders by up to 2.2 % under the same misspecification (docs/ste.md).
  EXPECT_NEAR(ste["offset"]["value"].get<double>(), 3.0e-6, 1.5e-8);
  EXPECT_NEAR(ste["mesh"][0]["cos"].get<double>(), 1.0e-6, 5e-9);
  EXPECT_NEAR(ste["mesh"][0]["sin"].get<double>(), -0.4e-6, 5e-9);
  EXPECT_NEAR(ste["shaft"][0]["cos"].get<double>(), 2.0e-6, 1e-8);
  EXPECT_NEAR(ste["shaft"][1]["sin"].get<double>(), 1.5e-6, 1e-8);
  EXPECT_GT(ste["mesh"][0]["cos_std"].get<double>(), 0.0);
  EXPECT_EQ(doc["runs"][0]["ste"], ste);
  const std::string csv = gear_test::readText(res / "tables" / "ste.csv");
  EXPECT_EQ(csv.rfind("kind,order,cos,sin,cos_std,sin_std,amplitude,phase\n", 0), 0u) << csv;
  EXPECT_NE(csv.find("\npinion,1,"), std::string::npos) << csv;

  const gear_test::ToolRun r =
      gear_test::runShell("/usr/bin/python3 " + std::string(GEAR_SOURCE_DIR) +
                              "/gear_damping_id/scripts/report -q " + res.string(),
                          dir, "report");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::is_regular_file(res / "report" / "fig13_ste.png"));
  EXPECT_GT(fs::file_size(res / "report" / "fig13_ste.png"), 10000u);
  EXPECT_NE(gear_test::readText(res / "report" / "index.html").find("fig13_ste.png"),
            std::string::npos);
}

TEST(SteCli, BadSpecsAreUsageErrors) {
  gear_test::ScratchDir scratch("ste_cli_bad");
  const fs::path dir = scratch.path();
  ASSERT_EQ(
      gear_test::runTool(
          "simulate",
          "-q --config " + kSte + " --duration 0.002 --output " + (dir / "s.csv").string(), dir)
          .code,
      0);
  for (const char* spec : {"mesh:x", "bogus:3", "mesh:99"}) {
    const gear_test::ToolRun a = gear_test::runTool(
        "analyze",
        "-q --input " + (dir / "s.csv").string() + " --params " + kSte + " --ste " + spec, dir);
    EXPECT_NE(a.code, 0) << spec;
    EXPECT_NE(a.err.find("--ste"), std::string::npos) << spec << ": " << a.err;
  }
}

TEST(SteSim, NoSteSectionIsBitIdenticalAndAnEmptyOneToo) {
  gear_sim::SimConfig c;
  std::string e;
  ASSERT_TRUE(gear_test::ok(
      gear_sim::loadSimConfigFile(std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml", &c), &e))
      << e;
  c.simulation.duration = 0.003;
  gear_sim::SignalTable a, b;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(c, &a), &e)) << e;
  c.ste = gear_sim::SteOptions{};  // present but empty
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(c, &b), &e)) << e;
  EXPECT_EQ(a.dte, b.dte);
  EXPECT_EQ(a.dte_velocity, b.dte_velocity);
  // A YAML round trip keeps an STE.
  gear_sim::SimConfig s;
  ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(kSte, &s), &e)) << e;
  gear_sim::SimConfig back;
  ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfig(gear_sim::toYaml(s), &back), &e)) << e;
  EXPECT_EQ(back.ste.mesh_cos, s.ste.mesh_cos);
  EXPECT_EQ(back.ste.gear_sin, s.ste.gear_sin);
  EXPECT_EQ(back.ste.offset, s.ste.offset);
}

// The STE enters the torsional model as the same mesh-force term: with the reduced and the
// torsional dynamics the DTE agrees (the reduced model is exact for the torsional one's DTE).
TEST(SteSim, TorsionalAndReducedAgreeWithAnSte) {
  gear_sim::SimConfig c;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(kSte, &c), &e)) << e;
  c.simulation.duration = 0.003;
  gear_sim::SignalTable red, tor;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(c, &red), &e)) << e;
  c.simulation.dynamics = gear_sim::DynamicsModel::Torsional;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(c, &tor), &e)) << e;
  const double scale = red.dte.cwiseAbs().maxCoeff();
  EXPECT_LT((red.dte - tor.dte).cwiseAbs().maxCoeff(), 1e-6 * scale);
}

}  // namespace
