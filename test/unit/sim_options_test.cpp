// Each simulator option against its defining property (issue 3).
#include <gtest/gtest.h>

#include <cmath>
#include <tuple>
#include <vector>

#include "gear_sim/models.hpp"
#include "gear_sim/simulator.hpp"
#include "status_support.hpp"

namespace {

using gear_sim::SignalTable;
using gear_sim::SimConfig;

SignalTable run(const SimConfig& c) {
  SignalTable t;
  std::string e;
  EXPECT_TRUE(gear_test::ok(gear_sim::simulate(c, &t), &e)) << e;
  return t;
}

// Time-mean of k over one mesh cycle by fine sampling (1e6 points: error ~1e-6 of the jump).
double cycleMean(const gear_sim::MeshStiffness& k) {
  const int n = 1000000;
  double s = 0.0;
  for (int i = 0; i < n; ++i) s += k.at((i + 0.5) / n);
  return s / n;
}

TEST(MeshStiffness, SquareWaveHoldsKmaxForTheContactRatioFractionAndHasTheRightMean) {
  gear_sim::MeshOptions o;  // Table 1
  const gear_sim::MeshStiffness k(o);
  EXPECT_NEAR(cycleMean(k), 0.6 * 4e8 + 0.4 * 2e8, 1e-5 * 4e8);
  EXPECT_DOUBLE_EQ(k.mean(), 0.6 * 4e8 + 0.4 * 2e8);
  EXPECT_EQ(k.at(0.0), 4e8);
  // The switch sits at eps - 1 as computed in doubles (1.6 - 1.0 = 0.6 + 1 ulp): probe 1e-12 away.
  EXPECT_EQ(k.at(0.6 - 1e-12), 4e8);
  EXPECT_EQ(k.at(0.6 + 1e-12), 2e8);
  EXPECT_EQ(k.at(0.9999), 2e8);
  EXPECT_EQ(k.at(7.3), 4e8);  // periodic in the mesh phase
}

TEST(MeshStiffness, TrapezoidKeepsTheSquareWaveMeanAndIsContinuous) {
  gear_sim::MeshOptions o;
  o.model = gear_sim::StiffnessModel::Trapezoid;
  o.transition_fraction = 0.1;
  const gear_sim::MeshStiffness k(o);
  EXPECT_NEAR(cycleMean(k), 0.6 * 4e8 + 0.4 * 2e8, 1e-5 * 4e8);
  EXPECT_NEAR(k.at(0.0), 3e8, 1.0);  // middle of the ramp up
  EXPECT_NEAR(k.at(0.6), 3e8, 1.0);  // middle of the ramp down
  double max_jump = 0.0;
  for (int i = 0; i < 100000; ++i)
    max_jump = std::max(max_jump, std::abs(k.at((i + 1) * 1e-5) - k.at(i * 1e-5)));
  EXPECT_LT(max_jump, 2e8 * 1e-5 / 0.1 * 1.01);  // slope dk/w per unit phase
}

// The simulator's block fills (issue 18): a table load filled interval by interval equals at()
// at every point (to rounding: at() divides per point), including points before, on and after
// the table's knots and a grid whose points fall exactly on knots; the sine load and the Fourier
// stiffness with a rotation table kept across calls give exactly the values of a fresh table,
// also after the step changes (the table is recomputed) and back.
TEST(LoadTorque, BlockFillsEqualTheirDefinitionsAndKeptRotationTablesChangeNothing) {
  gear_sim::LoadOptions o;
  o.profile = gear_sim::LoadProfile::Table;
  for (int i = 0; i <= 40; ++i) {
    o.times.push_back(1e-3 + 2.5e-4 * i);
    o.values.push_back(100.0 + 30.0 * std::sin(0.37 * i));
  }
  const gear_sim::LoadTorque tb(o);
  for (const auto& [t0, dt, n] : {std::tuple<double, double, long>{0.0, 1e-5, 1200},
                                  {0.0, 2.5e-4, 60},  // every knot on a grid point
                                  {1.3e-3, 3.7e-6, 2000},
                                  {0.0, 7e-4, 5}}) {
    std::vector<double> fast(static_cast<size_t>(n));
    tb.fillUniform(t0, dt, n, fast.data());
    for (long i = 0; i < n; ++i)
      ASSERT_NEAR(fast[i], tb.at(t0 + static_cast<double>(i) * dt), 1e-12 * 130.0)
          << "t0 " << t0 << " dt " << dt << " i " << i;
  }
  o.profile = gear_sim::LoadProfile::Sine;
  o.mean = 100;
  o.amplitude = 50;
  o.frequency = 130;
  const gear_sim::LoadTorque sine(o);
  gear_sim::MeshOptions m;
  m.model = gear_sim::StiffnessModel::Fourier;
  m.k_mean = 3e8;
  m.fourier_cos = {4e7, -1e7, 5e6};
  m.fourier_sin = {2e7, 8e6, -3e6};
  const gear_sim::MeshStiffness k(m);
  gear_sim::RotationTable load_table, k_table;
  std::vector<double> kept(4097), fresh(4097), u(4097);
  for (double step : {5e-7, 5e-7, 2.5e-7, 5e-7}) {
    sine.fillUniform(0.37, step, 4097, kept.data(), &load_table);
    sine.fillUniform(0.37, step, 4097, fresh.data());
    ASSERT_EQ(kept, fresh) << step;
    const double du = 1e3 * step;  // mesh cycles per point at 1 kHz
    for (size_t j = 0; j < u.size(); ++j) u[j] = 12.3 + du * static_cast<double>(j);
    k.fillPiece(12.3, u.data(), 4097, du, kept.data(), &k_table);
    k.fillPiece(12.3, u.data(), 4097, du, fresh.data());
    ASSERT_EQ(kept, fresh) << step;
    for (size_t j = 0; j < u.size(); j += 97) ASSERT_NEAR(kept[j], k.at(u[j]), 1e-6 * 3e8);
  }
}

TEST(MeshStiffness, FourierSeriesHasItsMeanAndHarmonic) {
  gear_sim::MeshOptions o;
  o.model = gear_sim::StiffnessModel::Fourier;
  o.k_mean = 3e8;
  o.fourier_cos = {5e7, 0.0};
  o.fourier_sin = {0.0, 2e7};
  const gear_sim::MeshStiffness k(o);
  EXPECT_NEAR(cycleMean(k), 3e8, 1.0);
  EXPECT_NEAR(k.at(0.0), 3e8 + 5e7, 1.0);
  EXPECT_NEAR(k.at(0.125), 3e8 + 5e7 * std::cos(M_PI / 4) + 2e7, 1.0);
}

TEST(Simulator, MeshStateFractionEqualsContactRatioMinusOne) {
  SimConfig c;  // 10 ms at 1 kHz mesh: 10 whole cycles, 600 of every 1000 samples in double contact
  const SignalTable t = run(c);
  EXPECT_NEAR(t.mesh_state.mean(), 0.6, 1e-3);
}

TEST(Simulator, RunUpMeshFrequencyFollowsTheIntegratedSpeed) {
  SimConfig c;
  c.speed.profile = gear_sim::SpeedProfile::Ramp;
  c.speed.pinion_rpm = 3000;
  c.speed.end_rpm = 6000;
  c.speed.ramp_time = 0.01;
  const SignalTable t = run(c);
  // Instantaneous mesh frequency from the phase column: 20 * rpm(t)/60.
  for (double tt : {0.002, 0.005, 0.008}) {
    const auto n = static_cast<Eigen::Index>(tt * 1e6);
    const double f = (t.mesh_phase[n + 1] - t.mesh_phase[n - 1]) / 2e-6;
    EXPECT_NEAR(f, 20.0 * (3000.0 + 3000.0 * tt / 0.01) / 60.0, 1e-6 * f) << tt;
  }
  // Total mesh cycles = 20 * mean rpm / 60 * duration = 20 * 75 * 0.01 = 15.
  EXPECT_NEAR(t.mesh_phase[t.size() - 1], 15.0, 20 * 100.0 * 1e-6);
  // Switch instants: the stiffness column changes exactly where the phase crosses n or n + 0.6.
  for (Eigen::Index n = 1; n < t.size(); ++n) {
    if (t.stiffness[n] == t.stiffness[n - 1]) continue;
    const double u0 = t.mesh_phase[n - 1], u1 = t.mesh_phase[n];
    const double crossing = t.stiffness[n] == 2e8 ? std::floor(u1) + 0.6 : std::floor(u1);
    EXPECT_TRUE(u0 < crossing && crossing <= u1 + 1e-9) << "n = " << n;
  }
}

TEST(Simulator, NoiseHasTheRequestedSnrAndIsReproducible) {
  SimConfig c;
  const SignalTable clean = run(c);
  c.simulation.noise_snr_db = 30.0;
  c.simulation.seed = 7;
  const SignalTable noisy = run(c), again = run(c);
  const Eigen::VectorXd noise = noisy.dte - clean.dte;
  auto stddev = [](const Eigen::VectorXd& v) {
    return std::sqrt((v.array() - v.mean()).square().mean());
  };
  const double snr = 20.0 * std::log10(stddev(clean.dte) / stddev(noise));
  EXPECT_NEAR(snr, 30.0, 0.5);  // issue 3: within 0.5 dB (1e4 samples: sampling error ~0.06 dB)
  EXPECT_EQ(noisy.dte, again.dte);
  EXPECT_EQ(noisy.dte_velocity, clean.dte_velocity);  // noise is on the measured DTE only
  c.simulation.seed = 8;
  EXPECT_NE(run(c).dte, noisy.dte);
}

TEST(LoadTorque, EveryProfileHasItsDefiningShape) {
  gear_sim::LoadOptions o;
  o.profile = gear_sim::LoadProfile::Step;
  o.initial = 50;
  o.final_value = 150;
  o.step_time = 0.004;
  EXPECT_EQ(gear_sim::LoadTorque(o).at(0.0039999), 50);
  EXPECT_EQ(gear_sim::LoadTorque(o).at(0.004), 150);
  o.profile = gear_sim::LoadProfile::Ramp;
  o.ramp_start = 0.002;
  o.ramp_end = 0.006;
  EXPECT_DOUBLE_EQ(gear_sim::LoadTorque(o).at(0.004), 100);
  EXPECT_DOUBLE_EQ(gear_sim::LoadTorque(o).at(0.001), 50);
  EXPECT_DOUBLE_EQ(gear_sim::LoadTorque(o).at(0.009), 150);
  EXPECT_NEAR(gear_sim::LoadTorque(o).mean(0.008), (50 * 0.002 + 100 * 0.004 + 150 * 0.002) / 0.008,
              1e-12);
  o.profile = gear_sim::LoadProfile::Trapezoid;
  o.low = 10;
  o.high = 20;
  o.period = 0.01;
  o.rise = 0.001;
  o.hold = 0.004;
  o.fall = 0.002;
  const gear_sim::LoadTorque tr(o);
  EXPECT_DOUBLE_EQ(tr.at(0.0005), 15);
  EXPECT_DOUBLE_EQ(tr.at(0.003), 20);
  EXPECT_DOUBLE_EQ(tr.at(0.006), 15);
  EXPECT_DOUBLE_EQ(tr.at(0.009), 10);
  EXPECT_DOUBLE_EQ(tr.at(0.013), 20);  // periodic
  o.profile = gear_sim::LoadProfile::Table;
  o.times = {0.0, 0.001, 0.003};
  o.values = {0.0, 10.0, 30.0};
  const gear_sim::LoadTorque tb(o);
  EXPECT_DOUBLE_EQ(tb.at(0.002), 20.0);
  EXPECT_DOUBLE_EQ(tb.at(0.01), 30.0);
  o.profile = gear_sim::LoadProfile::Sine;
  o.mean = 100;
  o.amplitude = 50;
  o.frequency = 100;
  o.phase = 0;
  EXPECT_NEAR(gear_sim::LoadTorque(o).mean(0.01), 100.0, 1e-9);
  std::vector<double> fast(1000);
  gear_sim::LoadTorque(o).fillUniform(0.0, 1e-5, 1000, fast.data());
  for (int i = 0; i < 1000; ++i)
    ASSERT_NEAR(fast[i], gear_sim::LoadTorque(o).at(i * 1e-5), 1e-12 * 150);
}

TEST(Simulator, EveryDampingLawGivesItsCoefficient) {
  SimConfig c;
  const double me = c.gears.equivalentMass();
  const double critical = 2.0 * std::sqrt((0.6 * 4e8 + 0.4 * 2e8) * me);
  c.damping.model = gear_sim::DampingProfile::ConstantCoefficient;
  c.damping.coefficient = 321.0;
  EXPECT_EQ(run(c).damping, Eigen::VectorXd::Constant(10000, 321.0));
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  c.damping.ratio = 0.03;
  EXPECT_NEAR(run(c).damping[1234], 0.03 * critical, 1e-12 * critical);
  c.damping.model = gear_sim::DampingProfile::Piecewise;
  c.damping.times = {0.0, 0.0035};
  c.damping.ratios = {0.02, 0.07};
  SignalTable t = run(c);
  EXPECT_NEAR(t.damping[3499], 0.02 * critical, 1e-9);
  EXPECT_NEAR(t.damping[3500], 0.07 * critical, 1e-9);
  c.damping.model = gear_sim::DampingProfile::LoadLinear;
  c.damping.c0 = 100;
  c.damping.c1 = 3;
  t = run(c);
  for (Eigen::Index n : {0, 2500, 7777}) EXPECT_NEAR(t.damping[n], 100 + 3 * t.torque[n], 1e-9);
}

TEST(SimConfig, InvalidValuesAreRejectedNamingTheKey) {
  auto error = [](const SimConfig& c) { return c.check().message(); };
  SimConfig c;
  EXPECT_EQ(error(c), "");
  c.mesh.contact_ratio = 1.0;
  EXPECT_NE(error(c).find("mesh.contact_ratio"), std::string::npos);
  c = SimConfig{};
  c.mesh.k_min = 5e8;
  EXPECT_NE(error(c).find("mesh.k_min"), std::string::npos);
  c = SimConfig{};
  c.speed.pinion_rpm = -1;
  EXPECT_NE(error(c).find("speed.pinion_rpm"), std::string::npos);
  c = SimConfig{};
  c.simulation.sample_rate = 1.5e5;  // below 20 x ~10 kHz
  EXPECT_NE(error(c).find("simulation.sample_rate"), std::string::npos);
  c = SimConfig{};
  c.gears.pinion.inertia = 0;
  EXPECT_NE(error(c).find("pinion.inertia"), std::string::npos);
  c = SimConfig{};
  c.damping.model = gear_sim::DampingProfile::Piecewise;
  c.damping.times = {0.001};
  c.damping.ratios = {0.05};
  EXPECT_NE(error(c).find("damping.times[0]"), std::string::npos);
}

}  // namespace
