// ste_live.test (docs/ste.md, "The STE in the segment pipeline"): a record of
// config/ste_example.yaml (three mesh harmonics, a run-out of each shaft, an offset; 50 ms, white
// DTE noise at 40 dB) published chunk by chunk to damping_id_node with ~ste. The node's
// cumulative damping must equal the offline SegmentDriver with the same STE options (batch =
// live, segment by segment) and cover the simulation's truth.
#include <gtest/gtest.h>
#include <ros/package.h>
#include <ros/ros.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "../unit/support/status_support.hpp"
#include "gear_damping/DampingArray.h"
#include "gear_damping/GearParams.h"
#include "gear_damping/SignalChunk.h"
#include "gear_damping_id/segment_driver.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "gear_sim_ros/topics.hpp"
#include "tester_support.hpp"

namespace gd = gear_damping_id;

TEST(SteLive, LiveDampingWithTheSteEqualsTheOfflineDriverAndCoversTheTruth) {
  ros::NodeHandle nh;
  gear_sim::SimConfig c;
  std::string e;
  ASSERT_TRUE(
      gear_test::ok(gear_sim::loadSimConfigFile(
                        ros::package::getPath("gear_damping") + "/config/ste_example.yaml", &c),
                    &e))
      << e;
  c.simulation.duration = 0.05;  // a gear revolution of calibration (40 ms), then held segments
  gear_sim::SignalTable t;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(c, &t), &e)) << e;
  const double rms = std::sqrt(t.dte.squaredNorm() / static_cast<double>(t.size()));
  std::mt19937_64 gen(7);
  std::normal_distribution<double> nd(0.0, rms * std::pow(10.0, -40.0 / 20.0));
  for (Eigen::Index i = 0; i < t.size(); ++i) t.dte[i] += nd(gen);

  // Offline: the same driver, options and STE as the node (config/damping_id.yaml + ste_live.yaml).
  const gd::GearConstants gear = gd::gearConstants(c.gearModel());
  gd::IdentificationOptions o;
  o.segment_length = 1e-3;
  const gd::SignalView v = gd::SignalView::of(t);
  o.window_length = gd::defaultWindowLength(v, gear);
  gd::SteModelOptions so;
  std::string why;
  ASSERT_TRUE(gear_test::ok(gd::parseSteSpec("mesh:3,shaft:1", &so), &why)) << why;
  so.pinion_teeth = c.gears.pinion.teeth;
  so.gear_teeth = c.gears.gear.teeth;
  const gd::SampleRanges ranges = gd::segmentRanges(v, o);
  gd::SegmentDriver driver(o, gear);
  ASSERT_EQ(driver.setSte(so, 3).message(), "");
  driver.addAll(v, ranges);
  const gd::IdentificationResult offline = driver.finish();

  gear_test::LatestMessage<gear_damping::DampingArray> latest(nh, gear_sim_ros::kDampingTopic);
  const gear_damping::DampingArray& live = latest.msg;
  const bool& have = latest.have;
  ros::Publisher params =
      nh.advertise<gear_damping::GearParams>(gear_sim_ros::kParamsTopic, 1, true);
  ros::Publisher signal = nh.advertise<gear_damping::SignalChunk>(gear_sim_ros::kSignalTopic, 1000);
  params.publish(gear_sim_ros::toMsg(c.gearModel()));
  ASSERT_TRUE(gear_test::waitFor([&] { return signal.getNumSubscribers() >= 1; }, 30.0));
  constexpr Eigen::Index kChunk = 1000;
  for (Eigen::Index b = 0; b < t.size(); b += kChunk) {
    gear_damping::SignalChunk m;
    gear_sim_ros::toChunk(t, b, std::min(kChunk, t.size() - b), c.simulation.sample_rate,
                          static_cast<std::uint64_t>(b), &m);
    m.header.stamp = ros::Time::now();
    signal.publish(m);
    ros::WallDuration(0.002).sleep();
  }
  const size_t n = offline.segments.size();
  ASSERT_EQ(n, 50u);
  ASSERT_TRUE(gear_test::waitFor(
      [&] { return have && live.segments.size() >= n && live.segments[n - 1].identifiable; },
      120.0))
      << "live segments: " << live.segments.size() << " of " << n;
  const double me = c.gears.equivalentMass();
  int inside = 0, held = 0;
  for (size_t i = 0; i < n; ++i) {
    const auto& l = live.segments[i];
    const auto& off = offline.segments[i];
    ASSERT_TRUE(l.identifiable) << "segment " << i << ": " << l.reason;
    EXPECT_NEAR(l.t_start, off.t_start, 1e-9);
    // Same samples and arithmetic; the live time step is 1 / sample_rate (last-bit differences).
    EXPECT_NEAR(l.C, off.C, 1e-9 * std::abs(off.C)) << "segment " << i;
    EXPECT_NEAR(l.C_std, off.C_std, 1e-9 * off.C_std) << "segment " << i;
    double truth = 0.0;
    long m = 0;
    for (Eigen::Index k = 0; k < t.size(); ++k)
      if (t.time[k] >= l.t_start - 1e-12 && t.time[k] < l.t_start + o.segment_length - 1e-12)
        truth += t.damping[k] / me, ++m;
    truth /= static_cast<double>(m);
    // The true damping follows the load inside a segment (config/ste_example.yaml): as in
    // pipeline.test, 3 % of the truth, or 3 SE when larger.
    const bool in = std::abs(l.C - truth) <= std::max(3.0 * l.C_std, 0.03 * truth);
    inside += in;
    held += i > 40 ? 1 : 0;  // the calibration ends with segment 40 (40 mesh cycles spanned)
    std::printf("segment %zu: live C %.6g, offline %.6g, truth %.6g, SE %.3g%s\n", i, l.C, off.C,
                truth, l.C_std, in ? "" : "  <- outside");
  }
  EXPECT_EQ(inside, static_cast<int>(n));
  EXPECT_EQ(held, 9) << "the case must hold the STE for the last segments";
  // The held segments' standard errors include the STE's covariance: larger than the last
  // calibration segments'.
  EXPECT_GT(live.segments[n - 1].C_std, live.segments[n - 11].C_std);
}

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "ste_live_tester");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
