// Integration test: every gear_damping message type, filled with non-trivial content, survives
// a trip through the ROS graph (publish -> subscribe over TCPROS) and through a rosbag file
// (write -> read), field by field. Runs under rostest (test/rostest/message_roundtrip.test).
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <boost/foreach.hpp>
#include <cmath>
#include <cstdio>
#include <string>

#include "gear_damping/DampingArray.h"
#include "gear_damping/GearParams.h"
#include "gear_damping/ModeledResponse.h"
#include "gear_damping/SignalChunk.h"
#include "gear_damping/WaveletModes.h"
#include "gear_sim_ros/topics.hpp"

namespace {

gear_damping::SignalChunk makeChunk() {
  gear_damping::SignalChunk m;
  m.header.stamp = ros::Time(12, 345);
  m.header.frame_id = "rig";
  m.sample_rate = 1e6;
  m.first_index = 123456789012ULL;  // beyond 32 bits: the index must be 64-bit
  for (int i = 0; i < 257; ++i) {
    const double t = i / m.sample_rate;
    m.dte.push_back(1e-6 * std::sin(2 * M_PI * 1e4 * t) + 3e-7);
    m.dte_velocity.push_back(2 * M_PI * 1e4 * 1e-6 * std::cos(2 * M_PI * 1e4 * t));
    m.stiffness.push_back((i % 10) < 6 ? 4e8 : 2e8);
    m.torque.push_back(100.0 * (1 + 0.5 * std::sin(2 * M_PI * 100 * t)));
    m.mesh_state.push_back((i % 10) < 6 ? 1 : 0);
    m.mesh_phase.push_back(i * 1e-3);
    m.damping.push_back(500.0 + i);
  }
  return m;
}

gear_damping::GearParams makeParams() {
  gear_damping::GearParams m;
  m.header.stamp = ros::Time(1, 2);
  m.pinion_teeth = 20;
  m.pinion_inertia = 0.00026;
  m.pinion_base_radius = 0.05;
  m.gear_teeth = 40;
  m.gear_inertia = 0.0045;
  m.gear_base_radius = 0.11;
  m.stiffness_model = "square";
  m.k_max = 4e8;
  m.k_min = 2e8;
  m.contact_ratio = 1.6;
  m.pinion_rpm = 3000;
  m.equivalent_mass = 0.08128;
  m.force_factor = 0.05 / 0.00026 + 0.11 / 0.0045;
  m.natural_frequency = 10047.0;
  return m;
}

gear_damping::DampingArray makeDamping() {
  gear_damping::DampingArray m;
  m.header.stamp = ros::Time(3, 4);
  m.formulation = "greybox";
  m.model = "piecewise";
  m.equivalent_mass = 0.0813;
  m.omega0 = 2 * M_PI * 1e4;
  for (int i = 0; i < 10; ++i) {
    gear_damping::DampingSegment s;
    s.t_start = i * 1e-3;
    s.t_end = (i + 1) * 1e-3;
    s.C = 6000.0 + 100 * i;
    s.C_std = 1.5 + i;
    s.c = s.C * m.equivalent_mass;
    s.xi = s.C / (2 * m.omega0);
    s.k_min = 2e8 + i;
    s.k_max = 4e8 - i;
    s.identifiable = (i != 3);
    s.reason = s.identifiable ? "" : "no motion";
    m.segments.push_back(s);
  }
  m.c0 = 100.0;
  m.c0_std = 0.5;
  m.c1 = 2.5;
  m.c1_std = 0.01;
  return m;
}

gear_damping::ModeledResponse makeResponse() {
  gear_damping::ModeledResponse m;
  m.header.stamp = ros::Time(5, 6);
  m.sample_rate = 1e6;
  m.first_index = 1000;
  for (int i = 0; i < 100; ++i) {
    m.observed.push_back(1e-6 * std::cos(i * 0.1));
    m.modeled.push_back(1e-6 * std::cos(i * 0.1) * 0.99);
  }
  m.nrmse = 0.0123;
  m.fit_percent = 98.77;
  return m;
}

gear_damping::WaveletModes makeModes() {
  gear_damping::WaveletModes m;
  m.header.stamp = ros::Time(7, 8);
  m.t_start = 0.0;
  m.t_end = 0.01;
  m.wavelet_parameter = 6.0;
  const double f[] = {1731.0, 7375.0, 14750.0};
  for (int i = 0; i < 3; ++i) {
    gear_damping::WaveletMode w;
    w.frequency_hz = f[i];
    w.damping_ratio = 0.01 * (i + 1);
    w.r2 = 0.99 - 0.01 * i;
    w.decay_t_start = 1e-3 * i;
    w.decay_t_end = 1e-3 * (i + 4);
    w.xi_integral = (i == 1) ? 0.05 : std::nan("");
    w.warning = (i == 2) ? "modes closer than the wavelet can separate" : "";
    m.modes.push_back(w);
  }
  return m;
}

// NaN != NaN, so compare doubles bitwise-equal or both NaN.
bool same(double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); }

void expectEqual(const gear_damping::SignalChunk& a, const gear_damping::SignalChunk& b) {
  EXPECT_EQ(a.header.stamp, b.header.stamp);
  EXPECT_EQ(a.header.frame_id, b.header.frame_id);
  EXPECT_EQ(a.sample_rate, b.sample_rate);
  EXPECT_EQ(a.first_index, b.first_index);
  EXPECT_EQ(a.dte, b.dte);
  EXPECT_EQ(a.dte_velocity, b.dte_velocity);
  EXPECT_EQ(a.stiffness, b.stiffness);
  EXPECT_EQ(a.torque, b.torque);
  EXPECT_EQ(a.mesh_state, b.mesh_state);
  EXPECT_EQ(a.mesh_phase, b.mesh_phase);
  EXPECT_EQ(a.damping, b.damping);
}

void expectEqual(const gear_damping::GearParams& a, const gear_damping::GearParams& b) {
  EXPECT_EQ(a.pinion_teeth, b.pinion_teeth);
  EXPECT_EQ(a.pinion_inertia, b.pinion_inertia);
  EXPECT_EQ(a.pinion_base_radius, b.pinion_base_radius);
  EXPECT_EQ(a.gear_teeth, b.gear_teeth);
  EXPECT_EQ(a.gear_inertia, b.gear_inertia);
  EXPECT_EQ(a.gear_base_radius, b.gear_base_radius);
  EXPECT_EQ(a.stiffness_model, b.stiffness_model);
  EXPECT_EQ(a.k_max, b.k_max);
  EXPECT_EQ(a.k_min, b.k_min);
  EXPECT_EQ(a.contact_ratio, b.contact_ratio);
  EXPECT_EQ(a.pinion_rpm, b.pinion_rpm);
  EXPECT_EQ(a.equivalent_mass, b.equivalent_mass);
  EXPECT_EQ(a.force_factor, b.force_factor);
  EXPECT_EQ(a.natural_frequency, b.natural_frequency);
}

void expectEqual(const gear_damping::DampingArray& a, const gear_damping::DampingArray& b) {
  EXPECT_EQ(a.header.stamp, b.header.stamp);
  EXPECT_EQ(a.formulation, b.formulation);
  EXPECT_EQ(a.model, b.model);
  EXPECT_EQ(a.equivalent_mass, b.equivalent_mass);
  EXPECT_EQ(a.omega0, b.omega0);
  ASSERT_EQ(a.segments.size(), b.segments.size());
  for (size_t i = 0; i < a.segments.size(); ++i) {
    const auto &x = a.segments[i], &y = b.segments[i];
    EXPECT_EQ(x.t_start, y.t_start);
    EXPECT_EQ(x.t_end, y.t_end);
    EXPECT_EQ(x.C, y.C);
    EXPECT_EQ(x.C_std, y.C_std);
    EXPECT_EQ(x.c, y.c);
    EXPECT_EQ(x.xi, y.xi);
    EXPECT_EQ(x.k_min, y.k_min);
    EXPECT_EQ(x.k_max, y.k_max);
    EXPECT_EQ(x.identifiable, y.identifiable);
    EXPECT_EQ(x.reason, y.reason);
  }
  EXPECT_EQ(a.c0, b.c0);
  EXPECT_EQ(a.c0_std, b.c0_std);
  EXPECT_EQ(a.c1, b.c1);
  EXPECT_EQ(a.c1_std, b.c1_std);
}

void expectEqual(const gear_damping::ModeledResponse& a, const gear_damping::ModeledResponse& b) {
  EXPECT_EQ(a.header.stamp, b.header.stamp);
  EXPECT_EQ(a.sample_rate, b.sample_rate);
  EXPECT_EQ(a.first_index, b.first_index);
  EXPECT_EQ(a.observed, b.observed);
  EXPECT_EQ(a.modeled, b.modeled);
  EXPECT_EQ(a.nrmse, b.nrmse);
  EXPECT_EQ(a.fit_percent, b.fit_percent);
}

void expectEqual(const gear_damping::WaveletModes& a, const gear_damping::WaveletModes& b) {
  EXPECT_EQ(a.header.stamp, b.header.stamp);
  EXPECT_EQ(a.t_start, b.t_start);
  EXPECT_EQ(a.t_end, b.t_end);
  EXPECT_EQ(a.wavelet_parameter, b.wavelet_parameter);
  ASSERT_EQ(a.modes.size(), b.modes.size());
  for (size_t i = 0; i < a.modes.size(); ++i) {
    const auto &x = a.modes[i], &y = b.modes[i];
    EXPECT_EQ(x.frequency_hz, y.frequency_hz);
    EXPECT_EQ(x.damping_ratio, y.damping_ratio);
    EXPECT_EQ(x.r2, y.r2);
    EXPECT_EQ(x.decay_t_start, y.decay_t_start);
    EXPECT_EQ(x.decay_t_end, y.decay_t_end);
    EXPECT_TRUE(same(x.xi_integral, y.xi_integral));
    EXPECT_EQ(x.warning, y.warning);
  }
}

// Publishes `sent` on `topic`, waits (bounded) for it to come back through a subscriber of
// the same node, and returns what arrived.
template <typename M>
M throughTopic(const M& sent, const std::string& topic) {
  ros::NodeHandle nh;
  M received;
  bool got = false;
  ros::Subscriber sub = nh.subscribe<M>(topic, 1, [&](const boost::shared_ptr<const M>& m) {
    received = *m;
    got = true;
  });
  ros::Publisher pub = nh.advertise<M>(topic, 1, /*latch=*/true);
  pub.publish(sent);
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(10.0);
  while (!got && ros::ok() && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.01).sleep();
  }
  EXPECT_TRUE(got) << "nothing arrived on " << topic << " within 10 s";
  return received;
}

template <typename M>
M readOnly(const std::string& path, const std::string& topic) {
  rosbag::Bag bag(path, rosbag::bagmode::Read);
  rosbag::View view(bag, rosbag::TopicQuery(topic));
  M out;
  int n = 0;
  for (const rosbag::MessageInstance& mi : view) {
    auto p = mi.instantiate<M>();
    EXPECT_TRUE(p != nullptr) << "wrong type on " << topic;
    if (p) out = *p;
    ++n;
  }
  EXPECT_EQ(n, 1) << topic;
  return out;
}

TEST(MessageRoundTrip, EveryMessageSurvivesTopicAndBag) {
  const auto chunk = makeChunk();
  const auto params = makeParams();
  const auto damping = makeDamping();
  const auto response = makeResponse();
  const auto modes = makeModes();

  const auto chunk_rx = throughTopic(chunk, "/roundtrip/signal");
  const auto params_rx = throughTopic(params, "/roundtrip/params");
  const auto damping_rx = throughTopic(damping, "/roundtrip/damping");
  const auto response_rx = throughTopic(response, "/roundtrip/modeled_response");
  const auto modes_rx = throughTopic(modes, "/roundtrip/wavelet_modes");
  expectEqual(chunk, chunk_rx);
  expectEqual(params, params_rx);
  expectEqual(damping, damping_rx);
  expectEqual(response, response_rx);
  expectEqual(modes, modes_rx);

  char name[] = "/tmp/gear_damping_roundtrip_XXXXXX";
  const int fd = mkstemp(name);
  ASSERT_GE(fd, 0);
  close(fd);
  const std::string path = std::string(name) + ".bag";
  {
    rosbag::Bag bag(path, rosbag::bagmode::Write);
    const ros::Time t(100, 0);
    bag.write(gear_sim_ros::bagTopic(gear_sim_ros::kSignalTopic), t, chunk_rx);
    bag.write(gear_sim_ros::bagTopic(gear_sim_ros::kParamsTopic), t, params_rx);
    bag.write(gear_sim_ros::bagTopic(gear_sim_ros::kDampingTopic), t, damping_rx);
    bag.write(gear_sim_ros::bagTopic(gear_sim_ros::kModeledResponseTopic), t, response_rx);
    bag.write(gear_sim_ros::bagTopic(gear_sim_ros::kWaveletModesTopic), t, modes_rx);
  }
  expectEqual(chunk, readOnly<gear_damping::SignalChunk>(
                         path, gear_sim_ros::bagTopic(gear_sim_ros::kSignalTopic)));
  expectEqual(params, readOnly<gear_damping::GearParams>(
                          path, gear_sim_ros::bagTopic(gear_sim_ros::kParamsTopic)));
  expectEqual(damping, readOnly<gear_damping::DampingArray>(
                           path, gear_sim_ros::bagTopic(gear_sim_ros::kDampingTopic)));
  expectEqual(response, readOnly<gear_damping::ModeledResponse>(
                            path, gear_sim_ros::bagTopic(gear_sim_ros::kModeledResponseTopic)));
  expectEqual(modes, readOnly<gear_damping::WaveletModes>(
                         path, gear_sim_ros::bagTopic(gear_sim_ros::kWaveletModesTopic)));
  std::remove(path.c_str());
  std::remove(name);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "message_roundtrip_tester");
  ros::NodeHandle nh;  // keeps the node alive for the whole test
  return RUN_ALL_TESTS();
}
