// Issue 19 through the tools: a rig bag (sensor_msgs/JointState + geometry_msgs/WrenchStamped, as
// `simulate --rig` writes it) is accepted by `analyze --input` and gives the same result as the
// rig CSV of the same record; with `--ste` on a rig record holding an STE, the offsets are
// estimated with the STE modelled and the identified spectrum covers the simulated one.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tool_runner.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kRig = std::string(GEAR_SOURCE_DIR) + "/config/rig_example.yaml";
const std::string kSte = std::string(GEAR_SOURCE_DIR) + "/config/ste_example.yaml";

nlohmann::json analyze(const fs::path& dir, const std::string& input, const std::string& params,
                       const std::string& extra, const std::string& out) {
  const gear_test::ToolRun a = gear_test::runTool("analyze",
                                                  "-q --input " + input + " --params " + params +
                                                      " --counts-per-rev 1048576 " + extra +
                                                      " --output " + (dir / out).string(),
                                                  dir);
  EXPECT_EQ(a.code, 0) << a.err;
  return a.code == 0 ? nlohmann::json::parse(gear_test::readText(dir / out)) : nlohmann::json();
}

TEST(RigCli, RigBagGivesTheSameResultAsTheRigCsv) {
  gear_test::ScratchDir scratch("rig_cli_test");
  const fs::path dir = scratch.path();
  for (const char* out : {"rig.csv", "rig.bag"})
    ASSERT_EQ(
        gear_test::runTool("simulate",
                           "-q --config " + kRig + " --rig --output " + (dir / out).string(), dir)
            .code,
        0);
  const auto csv = analyze(dir, (dir / "rig.csv").string(), kRig, "", "csv.json");
  const auto bag = analyze(dir, (dir / "rig.bag").string(), kRig, "", "bag.json");
  ASSERT_TRUE(bag["input"]["encoder"].is_object()) << bag.dump(1);
  const auto& sc = csv["identification"]["segments"];
  const auto& sb = bag["identification"]["segments"];
  ASSERT_EQ(sb.size(), sc.size());
  ASSERT_GT(sb.size(), 0u);
  // The bag's stamps are whole nanoseconds: the same samples, C equal far inside its SE.
  for (size_t i = 0; i < sb.size(); ++i)
    EXPECT_LE(std::abs(sb[i]["C"].get<double>() - sc[i]["C"].get<double>()),
              1e-6 * sc[i]["C_std"].get<double>())
        << "segment " << i;
  EXPECT_EQ(bag["input"]["encoder"]["mesh_offset"], csv["input"]["encoder"]["mesh_offset"]);
  // A bag without the joints' positions is refused with the reason.
  const gear_test::ToolRun bad = gear_test::runTool(
      "analyze",
      "-q --input " + (dir / "rig.bag").string() + " --params " + kRig + " --topic /rig/torque",
      dir);
  EXPECT_NE(bad.code, 0);
}

// A rig record with the STE of config/ste_example.yaml (20-bit encoders, 0.1 N*m torque noise):
// analyze --ste estimates the offsets with the STE modelled and refines; the mesh harmonics are
// within 4 of their standard errors of the simulated ones.
TEST(RigCli, RigBagWithSteIdentifiesTheSpectrum) {
  gear_test::ScratchDir scratch("rig_cli_ste_test");
  const fs::path dir = scratch.path();
  const std::string rig = gear_test::readText(kRig), ste = gear_test::readText(kSte);
  const fs::path cfg = dir / "rig_ste.yaml";
  gear_test::writeText(cfg, rig + "\n" + ste.substr(ste.find("\nste:") + 1));
  ASSERT_EQ(
      gear_test::runTool(
          "simulate",
          "-q --config " + cfg.string() + " --rig --output " + (dir / "rig.bag").string(), dir)
          .code,
      0);
  const auto doc =
      analyze(dir, (dir / "rig.bag").string(), cfg.string(), "--ste mesh:3,shaft:1", "ste.json");
  const auto& s = doc["identification"]["ste"];
  ASSERT_TRUE(s.is_object()) << doc.dump(1);
  EXPECT_TRUE(s["refined"].get<bool>());
  EXPECT_TRUE(doc["input"]["encoder"]["mesh_offset_estimated"].get<bool>());
  const double truth[3][2] = {{1.0e-6, -0.4e-6}, {0.3e-6, 0.25e-6}, {-0.12e-6, 0.08e-6}};
  ASSERT_EQ(s["mesh"].size(), 3u);
  for (int h = 0; h < 3; ++h) {
    const auto& m = s["mesh"][h];
    EXPECT_LE(std::abs(m["cos"].get<double>() - truth[h][0]), 4 * m["cos_std"].get<double>()) << h;
    EXPECT_LE(std::abs(m["sin"].get<double>() - truth[h][1]), 4 * m["sin_std"].get<double>()) << h;
  }
}

}  // namespace
