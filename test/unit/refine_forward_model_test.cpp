// One forward model for the integral method and the output-error refinement: on every stiffness
// shape the simulator offers (square, trapezoid, fourier, constant) the refinement integrates the
// K(t) the integral method's quadrature integrates, so that
// - noise-free, the refined C equals the truth to 1e-5 relative, segment by segment, on every
//   shape, and equals the integral estimate to 1e-5 where the quadrature is exact to that level
//   (smooth K: fourier, constant). Where K jumps (square) or has kinks (trapezoid) the integral
//   method's cubic of y (or of K y) across the switch/kink carries its own error, reported here;
//   the refinement locates the switches from mesh_phase and the kinks from the samples;
// - at 40 dB white noise the truth lies within +-2 reported standard errors in 90-99 % of the
//   segments over 30 seeds.
// Simulated truth from gear_sim on a gear pair of this test's own (none of the package defaults).
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "gear_damping_id/forward_model.hpp"
#include "id_test_support.hpp"

namespace {

using namespace gear_id_test;
using gear_damping_id::SegmentEstimate;
using gear_sim::StiffnessModel;

// Noise-free the two estimators differ only by their discretisation errors, which are fourth
// order in omega*dt (cubic quadrature, RK4 with the same K(t)): 1e-5 relative is the bar.
constexpr double kNoiseFreeAgreement = 1e-5;
constexpr int kSeeds = 30;
// +-2 SE covers 95.4 % for an honest Gaussian SE. With 30 seeds x 8 segments = 240 draws the
// binomial std of the coverage is 1.35 %: [90, 99] is > 2.5 sigma wide on each side.
constexpr double kMinCoverage = 0.90, kMaxCoverage = 0.99;

// A gear pair none of the defaults were chosen for: 8 segments of 1 ms at 800 kHz.
SimConfig ownCase(StiffnessModel shape) {
  SimConfig c = table1Config();
  c.gears.pinion.teeth = 24;
  c.gears.pinion.inertia = 0.0003;
  c.gears.pinion.base_radius = 0.052;
  c.gears.gear.teeth = 41;
  c.gears.gear.inertia = 0.004;
  c.gears.gear.base_radius = 0.088;
  c.mesh.model = shape;
  c.mesh.k_max = 3.5e8;
  c.mesh.k_min = 2.1e8;
  c.mesh.contact_ratio = 1.55;
  c.mesh.initial_phase = 0.21;
  c.mesh.transition_fraction = 0.12;
  c.mesh.k_mean = 2.8e8;
  c.mesh.fourier_cos = {4.0e7, 1.5e7, -6.0e6};
  c.mesh.fourier_sin = {2.0e7, -1.0e7, 5.0e6};
  c.speed.pinion_rpm = 2600.0;  // mesh 1040 Hz
  c.load.mean = 90.0;
  c.load.amplitude = 35.0;
  c.load.frequency = 120.0;
  if (shape == StiffnessModel::Constant) {
    // Constant stiffness: a load near the natural frequency excites the damped dynamics.
    const double wn = std::sqrt(c.mesh.k_mean / c.gears.equivalentMass());
    c.load.frequency = 0.85 * wn / (2.0 * M_PI);
  }
  c.simulation.sample_rate = 800e3;
  c.simulation.duration = 0.008;
  setPiecewiseTruth(&c, 1e-3);
  return c;
}

struct Shape {
  const char* name;
  StiffnessModel model;
  bool smooth;  // K without jumps or kinks
};
const Shape kShapes[] = {{"square", StiffnessModel::Square, false},
                         {"trapezoid", StiffnessModel::Trapezoid, false},
                         {"fourier", StiffnessModel::Fourier, true},
                         {"constant", StiffnessModel::Constant, true}};

class RefineForwardModel : public ::testing::TestWithParam<Shape> {};

TEST_P(RefineForwardModel, NoiseFreeRefinedEqualsTruthAndIntegralEstimate) {
  const Shape shape = GetParam();
  const SimConfig c = ownCase(shape.model);
  const SignalTable t = simulateOrFail(c);
  IdentificationOptions o;
  o.refine = IdentificationOptions::Refine::Always;
  const IdentificationResult r = identifyOrFail(t, c, o);
  ASSERT_EQ(r.estimator, "output_error");
  ASSERT_EQ(r.segments.size(), 8u);
  double worst = 0.0, worst_truth = 0.0, worst_integral = 0.0;
  for (const SegmentEstimate& e : r.segments) {
    ASSERT_TRUE(e.identifiable) << e.reason;
    ASSERT_TRUE(e.refined);
    ASSERT_TRUE(std::isfinite(e.C_integral) && std::isfinite(e.C_integral_std));
    const double rel = std::abs(e.C - e.C_integral) / std::abs(e.C_integral);
    if (shape.smooth) {
      EXPECT_LT(rel, kNoiseFreeAgreement) << shape.name << " segment at " << e.t_start
                                          << ": refined " << e.C << " integral " << e.C_integral;
    }
    worst = std::max(worst, rel);
    const double truth = trueC(t, c, e.t_start, e.t_end);
    EXPECT_LT(std::abs(e.C - truth) / truth, kNoiseFreeAgreement)
        << shape.name << " segment at " << e.t_start << ": refined " << e.C << " truth " << truth;
    worst_truth = std::max(worst_truth, std::abs(e.C - truth) / truth);
    worst_integral = std::max(worst_integral, std::abs(e.C_integral - truth) / truth);
    EXPECT_TRUE(e.warnings.empty()) << e.warnings.front().code;
  }
  std::cout << "[ measured ] " << shape.name << " noise-free: max |refined - integral| / integral "
            << worst << ", max |refined - truth| / truth " << worst_truth
            << ", max |integral - truth| / truth " << worst_integral << "\n";
}

TEST_P(RefineForwardModel, StandardErrorsCoverTheTruthAt40dB) {
  const Shape shape = GetParam();
  const SimConfig c = ownCase(shape.model);
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;  // default: Auto refinement
  long covered = 0, total = 0;
  double sum_z2 = 0.0;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    SignalTable t = clean;
    addWhiteNoise(&t.dte, 40.0, 7100 + seed);
    const IdentificationResult r = identifyOrFail(t, c, o);
    ASSERT_EQ(r.estimator, "output_error") << shape.name << " seed " << seed;
    for (const SegmentEstimate& e : r.segments) {
      ASSERT_TRUE(e.identifiable) << e.reason;
      ASSERT_TRUE(std::isfinite(e.C_std) && e.C_std > 0.0);
      const double z = (e.C - trueC(t, c, e.t_start, e.t_end)) / e.C_std;
      covered += std::abs(z) <= 2.0;
      sum_z2 += z * z;
      ++total;
    }
  }
  const double coverage = static_cast<double>(covered) / static_cast<double>(total);
  std::cout << "[ measured ] " << shape.name << " 40 dB: +-2 SE coverage " << coverage * 100
            << " % of " << total << " segments, rms z " << std::sqrt(sum_z2 / total) << "\n";
  EXPECT_GE(coverage, kMinCoverage) << shape.name;
  EXPECT_LE(coverage, kMaxCoverage) << shape.name;
}

// The kinks of a sampled trapezoid stiffness are found from the samples alone: four per mesh
// cycle (the ends of the two ramps), located within the interval where the ramps' lines meet;
// a smooth (Fourier) stiffness has none.
TEST(RefineForwardModelKinks, LocatedFromTheSamples) {
  for (const Shape& shape : kShapes) {
    if (shape.model == StiffnessModel::Square || shape.model == StiffnessModel::Constant) continue;
    const SimConfig c = ownCase(shape.model);
    const SignalTable t = simulateOrFail(c);
    const auto view = gear_damping_id::SignalView::of(t);
    const auto gear = gear_damping_id::gearConstants(c.gearModel());
    const gear_damping_id::ForwardModel fm(view, gear, Formulation::Known);
    const double cycles = t.mesh_phase[t.size() - 1] - t.mesh_phase[0];
    if (shape.smooth) {
      EXPECT_TRUE(fm.kinkIntervals().empty()) << shape.name << ": " << fm.kinkIntervals().size();
      continue;
    }
    // Every kink of the whole cycles in the record: 4 per cycle, +-4 at the record's ends.
    EXPECT_NEAR(static_cast<double>(fm.kinkIntervals().size()), 4.0 * cycles, 4.0);
    const double w = c.mesh.transition_fraction, e = c.mesh.contact_ratio - 1.0;
    const double breaks[] = {0.5 * w, e - 0.5 * w, e + 0.5 * w, 1.0 - 0.5 * w};
    for (const auto j : fm.kinkIntervals()) {
      // The kink's phase from its split fraction, against the nearest ramp end.
      const double th = fm.heldSplit(j);
      const double u = t.mesh_phase[j] + th * (t.mesh_phase[j + 1] - t.mesh_phase[j]);
      const double f = u - std::floor(u);
      double best = 1.0;
      for (double b : breaks) best = std::min({best, std::abs(f - b), 1.0 - std::abs(f - b)});
      // Located to rounding of the samples (the lines meet exactly at the kink).
      EXPECT_LT(best, 1e-6) << "kink at interval " << j << " phase " << f;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Shapes, RefineForwardModel, ::testing::ValuesIn(kShapes),
                         [](const auto& info) { return std::string(info.param.name); });

}  // namespace
