// Message <-> core conversions of gear_sim/ros and gear_damping_id/ros as plain GoogleTests (no
// roscore): a record through chunks and back, gear parameters through GearParams and back, and
// every field of the identification and wavelet results as it appears in its message.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "gear_damping_ros/id_conversions.hpp"
#include "gear_damping_ros/live_conversions.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "status_support.hpp"

namespace {

namespace gd = gear_damping_id;

gear_sim::SimConfig table1() {
  gear_sim::SimConfig c;
  std::string e;
  EXPECT_TRUE(gear_test::ok(
      gear_sim::loadSimConfigFile(std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml", &c), &e))
      << e;
  c.simulation.duration = 2e-3;
  return c;
}

// Same value, NaN included.
void expectSame(double a, double b, const std::string& what) {
  if (std::isnan(b))
    EXPECT_TRUE(std::isnan(a)) << what;
  else
    EXPECT_EQ(a, b) << what;
}

TEST(RosConversions, ARecordThroughChunksAndBackIsTheSameRecord) {
  const gear_sim::SimConfig c = table1();
  gear_sim::SignalTable t;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(c, &t), &e)) << e;
  const double rate = c.simulation.sample_rate;
  std::vector<gear_damping::SignalChunk> chunks;
  for (Eigen::Index b = 0; b < t.size(); b += 333) {
    gear_damping::SignalChunk m;
    gear_sim_ros::toChunk(t, b, std::min<Eigen::Index>(333, t.size() - b), rate,
                          static_cast<std::uint64_t>(b), &m);
    chunks.push_back(m);
  }
  gear_sim::SignalTable back;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::chunksToTable(chunks, &back), &e)) << e;
  ASSERT_EQ(back.size(), t.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    EXPECT_EQ(back.dte[i], t.dte[i]) << i;
    EXPECT_EQ(back.stiffness[i], t.stiffness[i]) << i;
    EXPECT_EQ(back.torque[i], t.torque[i]) << i;
    EXPECT_EQ(back.mesh_state[i], t.mesh_state[i]) << i;
    EXPECT_EQ(back.mesh_phase[i], t.mesh_phase[i]) << i;
    // time = index / sample_rate (the chunk convention), the simulator's own time to rounding.
    EXPECT_NEAR(back.time[i], t.time[i], 1e-15 + 1e-12 * std::abs(t.time[i])) << i;
  }
}

TEST(RosConversions, AChunkAsCoreDataPointsAtTheSameSamples) {
  const gear_sim::SimConfig c = table1();
  gear_sim::SignalTable t;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(c, &t), &e)) << e;
  gear_damping::SignalChunk m;
  gear_sim_ros::toChunk(t, 100, 250, c.simulation.sample_rate, 1000100, &m);
  std::vector<double> state;
  gd::ChunkData d;
  ASSERT_TRUE(gear_test::ok(gear_damping_ros::toChunkData(m, &state, &d), &e)) << e;
  EXPECT_EQ(d.first_index, 1000100u);
  EXPECT_EQ(d.sample_rate, c.simulation.sample_rate);
  ASSERT_EQ(d.n, 250u);
  for (size_t i = 0; i < d.n; ++i) {
    const Eigen::Index k = 100 + static_cast<Eigen::Index>(i);
    EXPECT_EQ(d.dte[i], t.dte[k]);
    EXPECT_EQ(d.stiffness[i], t.stiffness[k]);
    EXPECT_EQ(d.torque[i], t.torque[k]);
    EXPECT_EQ(d.mesh_state[i], t.mesh_state[k]);
    EXPECT_EQ(d.mesh_phase[i], t.mesh_phase[k]);
  }
  m.torque.pop_back();  // a channel of the wrong length is refused
  EXPECT_FALSE(gear_test::ok(gear_damping_ros::toChunkData(m, &state, &d), &e));
}

TEST(RosConversions, GearParametersThroughTheMessageAndBackAreTheSameModel) {
  const gear_sim::GearModel model = table1().gearModel();
  gear_sim::GearModel back;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::fromMsg(gear_sim_ros::toMsg(model), &back), &e)) << e;
  EXPECT_EQ(back.gears.pinion.teeth, model.gears.pinion.teeth);
  EXPECT_EQ(back.gears.gear.teeth, model.gears.gear.teeth);
  EXPECT_EQ(back.gears.pinion.inertia, model.gears.pinion.inertia);
  EXPECT_EQ(back.gears.gear.inertia, model.gears.gear.inertia);
  EXPECT_EQ(back.gears.pinion.base_radius, model.gears.pinion.base_radius);
  EXPECT_EQ(back.gears.gear.base_radius, model.gears.gear.base_radius);
  EXPECT_EQ(back.mesh.k_max, model.mesh.k_max);
  EXPECT_EQ(back.mesh.k_min, model.mesh.k_min);
  EXPECT_EQ(back.mesh.contact_ratio, model.mesh.contact_ratio);
  EXPECT_EQ(back.mesh.model, model.mesh.model);
  EXPECT_EQ(back.gears.equivalentMass(), model.gears.equivalentMass());
  EXPECT_EQ(back.gears.forceFactor(), model.gears.forceFactor());
}

TEST(RosConversions, EveryFieldOfAnIdentificationResultIsInItsMessage) {
  gd::IdentificationResult r;
  r.formulation = gd::Formulation::Greybox;
  r.model = gd::DampingModel::LoadLaw;
  r.equivalent_mass = 0.0813;
  r.omega0 = 6.28e4;
  gd::SegmentEstimate s;
  s.t_start = 1e-3;
  s.t_end = 2e-3;
  s.C = 610.0;
  s.C_std = 1.5;
  s.c = 49.6;
  s.xi = 0.0049;
  s.k_min = 2e8;
  s.k_max = 4e8;
  s.identifiable = true;
  s.warnings.push_back({"refine_disagrees", "text"});
  gd::SegmentEstimate bad;
  bad.t_start = 2e-3;
  bad.t_end = 3e-3;
  bad.reason = "NaN in input";
  r.segments = {s, bad};
  gd::LoadLawEstimate l;
  l.c0 = 10.0, l.c0_std = 0.5, l.c1 = 0.2, l.c1_std = 0.01, l.identifiable = true;
  r.load_law = l;
  r.warnings.push_back({"refine_not_converged", "run text"});
  const gear_damping::DampingArray m = gear_damping_ros::toMsg(r);
  EXPECT_EQ(m.formulation, "greybox");
  EXPECT_EQ(m.model, "load_law");
  EXPECT_EQ(m.equivalent_mass, r.equivalent_mass);
  EXPECT_EQ(m.omega0, r.omega0);
  EXPECT_EQ(m.c0, l.c0);
  EXPECT_EQ(m.c0_std, l.c0_std);
  EXPECT_EQ(m.c1, l.c1);
  EXPECT_EQ(m.c1_std, l.c1_std);
  ASSERT_EQ(m.warnings.size(), 1u);
  EXPECT_EQ(m.warnings[0].code, "refine_not_converged");
  EXPECT_EQ(m.warnings[0].text, "run text");
  ASSERT_EQ(m.segments.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    const gd::SegmentEstimate& e = r.segments[i];
    const gear_damping::DampingSegment& g = m.segments[i];
    const std::string at = "segment " + std::to_string(i);
    expectSame(g.t_start, e.t_start, at);
    expectSame(g.t_end, e.t_end, at);
    expectSame(g.C, e.C, at);
    expectSame(g.C_std, e.C_std, at);
    expectSame(g.c, e.c, at);
    expectSame(g.xi, e.xi, at);
    expectSame(g.k_min, e.k_min, at);
    expectSame(g.k_max, e.k_max, at);
    EXPECT_EQ(g.identifiable, e.identifiable) << at;
    EXPECT_EQ(g.reason, e.reason) << at;
    ASSERT_EQ(g.warnings.size(), e.warnings.size()) << at;
    for (size_t k = 0; k < e.warnings.size(); ++k) {
      EXPECT_EQ(g.warnings[k].code, e.warnings[k].code) << at;
      EXPECT_EQ(g.warnings[k].text, e.warnings[k].text) << at;
    }
  }
}

TEST(RosConversions, AModeledResponseKeepsItsSamplesAndIndex) {
  gd::ModeledResponse r;
  r.begin = 10;
  r.observed = Eigen::VectorXd::LinSpaced(50, -1e-6, 1e-6);
  r.modeled = r.observed * 0.99;
  r.nrmse = 0.01;
  r.fit_percent = 99.0;
  const gear_damping::ModeledResponse m = gear_damping_ros::toMsg(r, 1e6, 12345);
  EXPECT_EQ(m.first_index, 12345u);
  EXPECT_EQ(m.sample_rate, 1e6);
  ASSERT_EQ(m.observed.size(), 50u);
  ASSERT_EQ(m.modeled.size(), 50u);
  for (Eigen::Index i = 0; i < 50; ++i) {
    EXPECT_EQ(m.observed[static_cast<size_t>(i)], r.observed[i]);
    EXPECT_EQ(m.modeled[static_cast<size_t>(i)], r.modeled[i]);
  }
  EXPECT_EQ(m.nrmse, r.nrmse);
  EXPECT_EQ(m.fit_percent, r.fit_percent);
}

TEST(RosConversions, EveryFieldOfAWaveletModeIsInItsMessage) {
  gd::WaveletResult r;
  r.omega0 = 6.0;
  gd::WaveletMode md;
  md.frequency_hz = 9876.5;
  md.damping_ratio = 0.021;
  md.r2 = 0.998;
  md.t_start = 1e-3;
  md.t_end = 4e-3;
  md.integral_xi = 0.02;
  md.free_decay = false;
  md.warnings.push_back({"not_free_decay", "forced"});
  r.modes.push_back(md);
  const gear_damping::WaveletModes m = gear_damping_ros::toMsg(r, 0.5, 0.75);
  EXPECT_EQ(m.t_start, 0.5);
  EXPECT_EQ(m.t_end, 0.75);
  ASSERT_EQ(m.modes.size(), 1u);
  const auto& g = m.modes[0];
  EXPECT_EQ(g.frequency_hz, md.frequency_hz);
  EXPECT_EQ(g.damping_ratio, md.damping_ratio);
  EXPECT_EQ(g.r2, md.r2);
  EXPECT_EQ(g.decay_t_start, md.t_start);
  EXPECT_EQ(g.decay_t_end, md.t_end);
  EXPECT_EQ(g.xi_integral, md.integral_xi);
  EXPECT_EQ(g.free_decay, md.free_decay);
  ASSERT_EQ(g.warnings.size(), 1u);
  EXPECT_EQ(g.warnings[0].code, "not_free_decay");
}

}  // namespace
