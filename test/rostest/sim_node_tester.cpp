// Integration test of gear_sim_node (started by the .test file from launch/sim.launch):
// the chunks on /gear/signal cover the configured record contiguously, the latched
// /gear/params describe the configured gears, and the samples equal the core's own
// simulation of the same YAML. With ~bad_params_check, also checks that invalid parameters keep
// a second node from coming up (non-zero exit, message naming the parameter).
#include <gtest/gtest.h>
#include <ros/package.h>
#include <ros/ros.h>

#include <array>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "../unit/support/status_support.hpp"
#include "gear_damping/GearParams.h"
#include "gear_damping/SignalChunk.h"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "gear_sim_ros/topics.hpp"
#include "run_command.hpp"

namespace {

std::string configPath() { return ros::package::getPath("gear_damping") + "/config/table1.yaml"; }

TEST(GearSimNode, PublishesTheWholeRecordContiguouslyWithLatchedParameters) {
  ros::NodeHandle nh;
  std::vector<gear_damping::SignalChunk> chunks;
  gear_damping::GearParams params;
  bool got_params = false;
  auto s1 = nh.subscribe<gear_damping::SignalChunk>(
      gear_sim_ros::kSignalTopic, 2000,
      [&](const gear_damping::SignalChunk::ConstPtr& m) { chunks.push_back(*m); });
  auto s2 = nh.subscribe<gear_damping::GearParams>(
      gear_sim_ros::kParamsTopic, 1, [&](const gear_damping::GearParams::ConstPtr& m) {
        params = *m;
        got_params = true;
      });
  gear_sim::SimConfig cfg;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(configPath(), &cfg), &e)) << e;
  gear_sim::SignalTable expected;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(cfg, &expected), &e)) << e;

  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(30.0);
  size_t samples = 0;
  while (ros::ok() && ros::WallTime::now() < deadline &&
         (samples < static_cast<size_t>(expected.size()) || !got_params)) {
    ros::spinOnce();
    ros::WallDuration(0.005).sleep();
    samples = 0;
    for (const auto& c : chunks) samples += c.dte.size();
  }
  ASSERT_TRUE(got_params) << "no /gear/params within 30 s";
  ASSERT_EQ(samples, static_cast<size_t>(expected.size()))
      << "received " << chunks.size() << " chunks";
  EXPECT_EQ(params.pinion_teeth, 20u);
  EXPECT_DOUBLE_EQ(params.equivalent_mass, cfg.gears.equivalentMass());
  EXPECT_DOUBLE_EQ(params.k_max, 4e8);

  gear_sim::SignalTable received;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::chunksToTable(chunks, &received), &e))
      << e;  // contiguity is checked here
  EXPECT_EQ(chunks.front().first_index, 0u);
  EXPECT_EQ(chunks.front().sample_rate, 1e6);
  EXPECT_EQ(chunks.front().dte.size(), 1000u);  // launch default chunk size
  EXPECT_EQ(received.dte, expected.dte);        // bit-identical: same core, same configuration
  EXPECT_EQ(received.stiffness, expected.stiffness);
  EXPECT_EQ(received.mesh_state, expected.mesh_state);
  EXPECT_EQ(received.torque, expected.torque);
}

using gear_test::runCommand;

TEST(GearSimNode, InvalidParametersStopTheNodeNamingTheParameter) {
  // Missing configuration.
  auto r = runCommand("timeout 20 rosrun gear_damping gear_sim_node __name:=bad_sim_a");
  EXPECT_NE(r.first, 0);
  EXPECT_NE(r.first, 124) << "timed out instead of exiting";
  EXPECT_NE(r.second.find("~pinion: missing"), std::string::npos) << r.second;
  // A valid configuration with one invalid value.
  ASSERT_EQ(runCommand("rosparam load " + configPath() + " /bad_sim_b").first, 0);
  ros::param::set("/bad_sim_b/mesh/contact_ratio", 2.5);
  r = runCommand("timeout 20 rosrun gear_damping gear_sim_node __name:=bad_sim_b");
  EXPECT_NE(r.first, 0);
  EXPECT_NE(r.first, 124);
  EXPECT_NE(r.second.find("mesh.contact_ratio = 2.5"), std::string::npos) << r.second;
  // An unknown key (a typo must not fall back to a default).
  ASSERT_EQ(runCommand("rosparam load " + configPath() + " /bad_sim_c").first, 0);
  ros::param::set("/bad_sim_c/load/amplitud", 10.0);
  r = runCommand("timeout 20 rosrun gear_damping gear_sim_node __name:=bad_sim_c");
  EXPECT_NE(r.first, 0);
  EXPECT_NE(r.second.find("load.amplitud: unknown key"), std::string::npos) << r.second;
  ros::param::set("/bad_sim_d/chunk_size", 0);
  ASSERT_EQ(runCommand("rosparam load " + configPath() + " /bad_sim_d").first, 0);
  r = runCommand("timeout 20 rosrun gear_damping gear_sim_node __name:=bad_sim_d");
  EXPECT_NE(r.first, 0);
  EXPECT_NE(r.second.find("~chunk_size = 0"), std::string::npos) << r.second;
  // The node's own parameters are read strictly too: a misspelt name or a wrong type stops it
  // instead of falling back to a default.
  ASSERT_EQ(runCommand("rosparam load " + configPath() + " /bad_sim_e").first, 0);
  ros::param::set("/bad_sim_e/chunk_sise", 500);
  r = runCommand("timeout 20 rosrun gear_damping gear_sim_node __name:=bad_sim_e");
  EXPECT_NE(r.first, 0);
  EXPECT_NE(r.first, 124);
  EXPECT_NE(r.second.find("~chunk_sise: unknown parameter"), std::string::npos) << r.second;
  ASSERT_EQ(runCommand("rosparam load " + configPath() + " /bad_sim_f").first, 0);
  ros::param::set("/bad_sim_f/repeat", std::string("yes"));
  r = runCommand("timeout 20 rosrun gear_damping gear_sim_node __name:=bad_sim_f");
  EXPECT_NE(r.first, 0);
  EXPECT_NE(r.first, 124);
  EXPECT_NE(r.second.find("~repeat: wrong type"), std::string::npos) << r.second;
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "sim_node_tester");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
