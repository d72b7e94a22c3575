// gear_sim_io: YAML configuration and the docs/method.md §6 CSV.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>

#include "gear_sim/config_yaml.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim/simulator.hpp"
#include "scratch_dir.hpp"
#include "status_support.hpp"

namespace {

// In the binary's scratch directory (removed at exit; the CSV-load case names its table
// relative to the YAML beside it).
std::string tempPath(const std::string& name) {
  return (gear_test::processScratch("gear_sim_io_test") / ("gear_sim_io_test_" + name)).string();
}

std::string writeFile(const std::string& name, const std::string& text) {
  const std::string p = tempPath(name);
  std::ofstream(p) << text;
  return p;
}

std::string loadError(const std::string& yaml) {
  gear_sim::SimConfig c;
  std::string e;
  EXPECT_FALSE(gear_test::ok(gear_sim::loadSimConfig(YAML::Load(yaml), &c), &e)) << yaml;
  return e;
}

TEST(ConfigYaml, EveryShippedConfigurationLoadsAndValidates) {
  int n = 0;
  for (const auto& f :
       std::filesystem::directory_iterator(std::string(GEAR_SOURCE_DIR) + "/config")) {
    if (f.path().extension() != ".yaml") continue;
    ++n;
    YAML::Node root = YAML::LoadFile(f.path().string());
    std::string e;
    // Simulator files have a simulation section; node/analysis files are checked by their users.
    if (!root["simulation"]) continue;
    gear_sim::SimConfig c;
    EXPECT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(f.path().string(), &c), &e))
        << f.path() << ": " << e;
  }
  EXPECT_GE(n, 1);
}

TEST(ConfigYaml, Table1FileIsTheDefaultCase) {
  gear_sim::SimConfig c;
  std::string e;
  ASSERT_TRUE(gear_test::ok(
      gear_sim::loadSimConfigFile(std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml", &c), &e))
      << e;
  const gear_sim::SimConfig d;
  EXPECT_EQ(c.gears.pinion.inertia, d.gears.pinion.inertia);
  EXPECT_EQ(c.gears.gear.base_radius, d.gears.gear.base_radius);
  EXPECT_EQ(c.mesh.k_max, 4e8);
  EXPECT_EQ(c.speed.pinion_rpm, 3000);
  EXPECT_EQ(c.load.amplitude, 50);
  EXPECT_EQ(c.damping.load_sensitivity, 0.6);
  EXPECT_TRUE(std::isinf(c.simulation.noise_snr_db));
}

// A directory (or a device) given as a configuration file is an I/O error naming it, not an
// exception or a hang: a directory opens as a stream whose first read throws (a hostile test of
// wavelet_node's ~gear_config: the node aborted with exit 134 instead of a fatal message naming
// the parameter), /dev/zero was read until memory ran out.
TEST(ConfigYaml, ADirectoryIsAnIoErrorNotAnException) {
  const std::string dir = std::string(GEAR_SOURCE_DIR) + "/config";
  gear_sim::SimConfig c;
  gear_sim::GearModel m;
  const gear_sim::Status s = gear_sim::loadSimConfigFile(dir, &c);
  EXPECT_EQ(s.code(), gear_sim::StatusCode::IoError) << s.message();
  EXPECT_NE(s.message().find("is a directory"), std::string::npos) << s.message();
  EXPECT_EQ(gear_sim::loadGearModelFile(dir, &m).code(), gear_sim::StatusCode::IoError);
  // Nor a device (read until memory runs out) or a FIFO (blocks).
  const gear_sim::Status z = gear_sim::loadSimConfigFile("/dev/zero", &c);
  EXPECT_EQ(z.code(), gear_sim::StatusCode::IoError) << z.message();
  EXPECT_NE(z.message().find("not a regular file"), std::string::npos) << z.message();
}

TEST(ConfigYaml, MisspeltKeysWrongTypesAndUnknownNamesAreErrorsNamingTheKey) {
  EXPECT_NE(loadError("mesh: {k_maxx: 1}").find("mesh.k_maxx: unknown key"), std::string::npos);
  EXPECT_NE(loadError("loads: {mean: 1}").find("loads: unknown section"), std::string::npos);
  EXPECT_NE(loadError("load: {profile: sinus}").find("load.profile: unknown name 'sinus'"),
            std::string::npos);
  EXPECT_NE(loadError("simulation: {duration: abc}").find("simulation.duration: expected a number"),
            std::string::npos);
  EXPECT_NE(loadError("damping: {model: constant, ratio: 0.1, coefficient: 3}")
                .find("damping.coefficient"),
            std::string::npos);
  EXPECT_NE(loadError("mesh: {contact_ratio: 2.5}").find("mesh.contact_ratio = 2.5"),
            std::string::npos);
  EXPECT_NE(loadError("simulation: {sample_rate: 1.0e5}").find("simulation.sample_rate"),
            std::string::npos);
}

TEST(ConfigYaml, YamlRoundTripKeepsEveryValue) {
  gear_sim::SimConfig c;
  c.damping.model = gear_sim::DampingProfile::Piecewise;
  c.damping.times = {0.0, 0.004};
  c.damping.ratios = {0.02, 0.04};
  c.speed.profile = gear_sim::SpeedProfile::Ramp;
  c.speed.end_rpm = 4000;
  gear_sim::SimConfig back;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfig(gear_sim::toYaml(c), &back), &e)) << e;
  EXPECT_EQ(back.damping.ratios, c.damping.ratios);
  EXPECT_EQ(back.speed.end_rpm, 4000);
  EXPECT_EQ(back.speed.profile, gear_sim::SpeedProfile::Ramp);
}

TEST(ConfigYaml, GearModelLoaderNeedsOnlyTheGearSectionsAndIgnoresTheRest) {
  const std::string p =
      writeFile("gm.yaml",
                "pinion: {teeth: 20, inertia: 0.00026, base_radius: 0.05}\n"
                "gear: {teeth: 40, inertia: 0.0045, base_radius: 0.11}\n"
                "mesh: {k_max: 4.0e8}\nspeed: {pinion_rpm: 2500}\nanything: {x: 1}\n");
  gear_sim::GearModel m;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::loadGearModelFile(p, &m), &e)) << e;
  EXPECT_EQ(m.speed.pinion_rpm, 2500);
  const std::string q =
      writeFile("gm2.yaml", "pinion: {teeth: 20, inertia: 0.00026, base_radius: 0.05}\n");
  EXPECT_FALSE(gear_test::ok(gear_sim::loadGearModelFile(q, &m), &e));
  EXPECT_NE(e.find("gear: missing section"), std::string::npos) << e;
}

TEST(ConfigYaml, LoadFromCsvFileBecomesATable) {
  writeFile("torque.csv", "time,torque\n0,10\n0.005,20\n0.01,10\n");
  gear_sim::SimConfig c;
  std::string e;
  const std::string p =
      writeFile("csvload.yaml", "load: {profile: csv, file: gear_sim_io_test_torque.csv}\n");
  ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(p, &c), &e)) << e;
  EXPECT_EQ(c.load.profile, gear_sim::LoadProfile::Table);
  EXPECT_EQ(c.load.values, (std::vector<double>{10, 20, 10}));
}

TEST(SignalCsv, WriteThenReadIsBitExact) {
  gear_sim::SimConfig c;
  c.simulation.noise_snr_db = 20;
  gear_sim::SignalTable t, back;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(c, &t), &e)) << e;
  const std::string p = tempPath("roundtrip.csv");
  ASSERT_TRUE(gear_test::ok(gear_sim::writeSignalCsv(p, t), &e)) << e;
  ASSERT_TRUE(gear_test::ok(gear_sim::readSignalCsv(p, &back), &e)) << e;
  EXPECT_EQ(back.time, t.time);
  EXPECT_EQ(back.dte, t.dte);
  EXPECT_EQ(back.dte_velocity, t.dte_velocity);
  EXPECT_EQ(back.stiffness, t.stiffness);
  EXPECT_EQ(back.torque, t.torque);
  EXPECT_EQ(back.mesh_state, t.mesh_state);
  EXPECT_EQ(back.mesh_phase, t.mesh_phase);
  EXPECT_EQ(back.damping, t.damping);
  EXPECT_EQ(back.theta1.size(), 0);
}

TEST(SignalCsv, AnySubsetAndOrderOfKnownColumnsIsAccepted) {
  gear_sim::SignalTable t;
  std::string e;
  ASSERT_TRUE(gear_test::ok(
      gear_sim::readSignalCsv(writeFile("sub.csv", "dte, time\n1e-6,0\n2e-6,1e-6\n"), &t), &e))
      << e;
  EXPECT_EQ(t.time[1], 1e-6);
  EXPECT_EQ(t.dte[1], 2e-6);
  EXPECT_EQ(t.torque.size(), 0);
}

// Numbers beyond the double range are numbers, not malformed text: an overflow reads as +-Inf
// (refused as not finite, or kept for an analyser that reports NaN/Inf samples, like "inf"), an
// underflow as +-0; an explicit plus sign is accepted.
TEST(SignalCsv, NumbersBeyondTheDoubleRangeAndPlusSigns) {
  const std::string text =
      "time,dte,torque\n0,+1e-6,1e309\n+1e-6,1e-400,-1e309\n2e-6,-1e-400,"
      "0.00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000"
      "00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000"
      "00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000"
      "00000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000"
      "0000001\n";
  gear_sim::SignalTable t;
  std::string e;
  const std::string path = writeFile("range.csv", text);
  ASSERT_TRUE(gear_test::ok(gear_sim::readSignalCsv(path, &t, {"time", "dte"}, true), &e)) << e;
  EXPECT_EQ(t.time[1], 1e-6);
  EXPECT_EQ(t.dte[0], 1e-6);
  EXPECT_EQ(t.torque[0], std::numeric_limits<double>::infinity());
  EXPECT_EQ(t.torque[1], -std::numeric_limits<double>::infinity());
  EXPECT_EQ(t.dte[1], 0.0);
  EXPECT_TRUE(t.dte[2] == 0.0 && std::signbit(t.dte[2]));
  EXPECT_EQ(t.torque[2], 0.0);
  EXPECT_FALSE(gear_test::ok(gear_sim::readSignalCsv(path, &t), &e));
  EXPECT_NE(e.find("line 2, column 3 (torque): value is not finite (inf)"), std::string::npos) << e;
  EXPECT_FALSE(gear_test::ok(
      gear_sim::readSignalCsv(writeFile("plus.csv", "time,dte\n0,+-1\n1,2\n"), &t), &e));
  EXPECT_NE(e.find("malformed number '+-1'"), std::string::npos) << e;
}

// The plausibility ranges (the bag reader's) applied to a table read from a CSV: a value outside
// its channel's range reads as NaN and is counted; the range's own ends are plausible; NaN/Inf
// already there are counted, not changed; time is not ranged.
TEST(SignalTable, ImplausibleValuesReadAsNaNAndAreCounted) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  gear_sim::SignalTable t;
  t.time = Eigen::VectorXd::LinSpaced(6, 0.0, 5e-6);
  t.dte.resize(6);
  t.dte << 1e-6, -1.0, 1.0, std::nextafter(1.0, 2.0), nan, 2e-6;  // the ends kept, 1 + ulp not
  t.stiffness.resize(6);
  t.stiffness << 4e8, 0.0, 1e13, -1.0, 1.5e13, 4e8;  // a negative stiffness is out of range
  t.torque.resize(6);
  t.torque << 100.0, 1e300, -1e9, -inf, -1.0000001e9, 100.0;
  t.mesh_state.resize(6);
  t.mesh_state << 0.0, 1.0, 0.5, 2.0, nan, 1.0;
  const Eigen::VectorXd time = t.time;
  const gear_sim::ImplausibleCounts c = gear_sim::maskImplausible(&t);
  EXPECT_EQ(c.out_of_range, 5);  // dte 1 + ulp; stiffness -1, 1.5e13; torque 1e300, -1.0000001e9
  EXPECT_EQ(c.non_finite, 3);    // dte NaN, torque -Inf, mesh_state NaN
  EXPECT_EQ(c.bad_mesh_states, 2);
  const auto masked = [](const Eigen::VectorXd& v, std::initializer_list<int> at) {
    for (int i = 0; i < v.size(); ++i) {
      const bool want = std::find(at.begin(), at.end(), i) != at.end();
      if (want != std::isnan(v[i])) return false;
    }
    return true;
  };
  EXPECT_TRUE(masked(t.dte, {3, 4}));
  EXPECT_TRUE(masked(t.stiffness, {3, 4}));
  EXPECT_TRUE(masked(t.torque, {1, 4}));  // -Inf stays -Inf (not NaN: counted as non-finite)
  EXPECT_EQ(t.torque[3], -inf);
  EXPECT_TRUE(masked(t.mesh_state, {2, 3, 4}));
  EXPECT_EQ(t.dte[1], -1.0);
  EXPECT_EQ(t.stiffness[2], 1e13);
  EXPECT_EQ(t.torque[2], -1e9);
  EXPECT_EQ(t.time, time);
  const std::vector<std::string> w = gear_sim::implausibleWarnings(c, "in the file");
  ASSERT_EQ(w.size(), 3u);
  EXPECT_EQ(w[0].rfind("3 NaN/Inf values in the file", 0), 0u) << w[0];
  EXPECT_EQ(w[1].rfind("5 values outside their channel's plausible range", 0), 0u) << w[1];
  EXPECT_EQ(w[2].rfind("2 mesh_state values other than 0 or 1", 0), 0u) << w[2];
  EXPECT_TRUE(gear_sim::implausibleWarnings(gear_sim::ImplausibleCounts{}, "x").empty());
}

TEST(SignalCsv, BadFilesAreRejectedNamingLineAndColumn) {
  auto err = [](const std::string& name, const std::string& text) {
    gear_sim::SignalTable t;
    std::string e;
    EXPECT_FALSE(gear_test::ok(gear_sim::readSignalCsv(writeFile(name, text), &t), &e)) << text;
    return e;
  };
  EXPECT_NE(err("e1.csv", "").find("empty file"), std::string::npos);
  EXPECT_NE(err("e2.csv", "time,dte\n0,1\n1e-6,abc\n")
                .find("line 3, column 2 (dte): malformed number 'abc'"),
            std::string::npos);
  EXPECT_NE(err("e3.csv", "time,dte\n0,1\n1e-6\n").find("line 3"), std::string::npos);
  EXPECT_NE(err("e4.csv", "time,dtee\n0,1\n").find("column 2: unknown column 'dtee'"),
            std::string::npos);
  EXPECT_NE(err("e5.csv", "time,torque\n0,1\n1,2\n").find("missing required column 'dte'"),
            std::string::npos);
  EXPECT_NE(err("e6.csv", "time,dte\n0,1\n0,2\n").find("line 3: time"), std::string::npos);
  EXPECT_NE(err("e7.csv", "time,dte\n0,nan\n1,2\n").find("not finite"), std::string::npos);
  EXPECT_NE(err("e8.csv", "time,dte\n0,1\n1,2,3\n").find("line 3: more fields"), std::string::npos);
  EXPECT_NE(err("e9.csv", "time,dte\n0,1\n").find("fewer than two data rows"), std::string::npos);
  gear_sim::SignalTable t;
  std::string e;
  EXPECT_FALSE(gear_test::ok(gear_sim::readSignalCsv("/nonexistent/x.csv", &t), &e));
  EXPECT_NE(e.find("cannot open"), std::string::npos);
}

}  // namespace
