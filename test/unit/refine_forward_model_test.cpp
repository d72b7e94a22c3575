// One forward model for the integral method and the output-error refinement: on every stiffness
// shape the simulator offers (square, trapezoid, fourier, constant) and on a sampled stiffness
// table of a rig (piecewise linear in the mesh phase with jumps into and out of double contact)
// the refinement integrates the K(t) the integral method's quadrature integrates (both split at
// the switches, jumps and kinks located from mesh_phase and from the samples, with every
// quadrature stencil on one side of them; held or smooth decided from the samples), so that
// - noise-free, the refined C equals the integral estimate and the truth to 1e-5 relative,
//   segment by segment, on every shape;
// - at 40 dB white noise the truth lies within +-2 reported standard errors in 90-99 % of the
//   segments over 30 seeds.
// Simulated truth from gear_sim on a gear pair of this test's own (none of the package defaults).
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <utility>
#include <vector>

#include "gear_damping_id/forward_model.hpp"
#include "gear_sim/sdof_integrator.hpp"
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

// A rig's sampled stiffness: a periodic table of the mesh phase f, linear between its nodes,
// jumping up into double contact at f = 0 and down out of it at f = eps - 1 (as a tooth pair
// enters and leaves), with kinks at the other nodes. Not a model of the simulator: the DTE is
// integrated here (RK4, 16 steps per sample, every step split at the jumps, kinks and the
// damping segments' boundaries) and the stiffness channel holds the table at each sample.
struct TableNode {
  double f, k;  // phase in [0, 1), stiffness [N/m] (the right limit at a jump)
};
std::vector<TableNode> rigTable(double eps) {
  return {{0.0, 3.2e8}, {0.2, 3.45e8}, {0.4, 3.3e8}, {eps - 1.0, 2.0e8}, {0.75, 2.25e8}};
}
// Left limits at the jumps: 3.25e8 just before eps - 1, 2.1e8 just before 1.
double rigTableAt(const std::vector<TableNode>& tab, double eps, double f_ref, double f) {
  // The piece holding f_ref (in [0, 1)), evaluated (extrapolated linearly) at f.
  size_t i = 0;
  while (i + 1 < tab.size() && tab[i + 1].f <= f_ref) ++i;
  const double fa = tab[i].f, ka = tab[i].k;
  const double fb = i + 1 < tab.size() ? tab[i + 1].f : 1.0;
  const double kb = tab[i + 1 < tab.size() ? i + 1 : 0].k;
  // End values of the pieces that end in a jump.
  const double kend = std::abs(fb - (eps - 1.0)) < 1e-12 ? 3.25e8 : (fb == 1.0 ? 2.1e8 : kb);
  return ka + (kend - ka) * (f - fa) / (fb - fa);
}

SignalTable simulateRigTable(const SimConfig& c) {
  const auto gm = c.gearModel();
  const double me = c.gears.equivalentMass(), ff = c.gears.forceFactor();
  const double eps = c.mesh.contact_ratio;
  const auto tab = rigTable(eps);
  const double fm = c.gears.pinion.teeth * c.speed.pinion_rpm / 60.0;  // mesh frequency [Hz]
  const double dt = 1.0 / c.simulation.sample_rate;
  const auto n = static_cast<Eigen::Index>(std::llround(c.simulation.duration / dt)) + 1;
  const double phi0 = c.mesh.initial_phase;
  auto phase = [&](double t) { return phi0 + fm * t; };
  auto torque = [&](double t) {
    return c.load.mean + c.load.amplitude * std::sin(2.0 * M_PI * c.load.frequency * t);
  };
  double kmean = 0.0;  // time-mean of the table over a cycle
  for (int g = 0; g < 20000; ++g) {
    const double f = (g + 0.5) / 20000.0;
    kmean += rigTableAt(tab, eps, f, f) / 20000.0;
  }
  const double w0 = std::sqrt(kmean / me);
  const double seg = 1e-3;
  auto dampingC = [&](double t) {
    const double last = std::round(c.simulation.duration / seg) - 1.0;  // the final sample too
    const auto i = static_cast<size_t>(std::clamp(std::floor(t / seg), 0.0, last));
    const std::vector<double> ratios = piecewiseRatios(static_cast<int>(i) + 1);
    return 2.0 * ratios[i] * w0;
  };
  auto coeffs = [&](double t, double t_ref) {
    const double pr = phase(t_ref);
    const double cyc = std::floor(pr);
    gear_sim::SdofCoefficients k;
    k.K = rigTableAt(tab, eps, pr - cyc, phase(t) - cyc) / me;
    k.C = dampingC(t_ref);
    k.F = ff * torque(t);
    return k;
  };
  std::vector<double> bps;
  const double t_end = (n - 1) * dt;
  for (double cyc = std::floor(phase(0.0)); cyc < phase(t_end) + 1.0; cyc += 1.0) {
    for (const auto& node : tab) bps.push_back((cyc + node.f - phi0) / fm);
  }
  for (double t = seg; t < t_end; t += seg) bps.push_back(t);
  SignalTable t;
  t.time.resize(n);
  t.dte.resize(n);
  t.stiffness.resize(n);
  t.torque.resize(n);
  t.mesh_phase.resize(n);
  t.damping.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double ti = i * dt;
    t.time[i] = ti;
    const double p = phase(ti), f = p - std::floor(p);
    t.stiffness[i] = rigTableAt(tab, eps, f, f);
    t.torque[i] = torque(ti);
    t.mesh_phase[i] = p;
    t.damping[i] = dampingC(ti) * me;
  }
  const std::string e =
      gear_sim::integrateSdof(coeffs, bps, 0.0, dt, n, {0.0, 0.0}, gear_sim::Integrator::Rk4, 16,
                              t.dte.data(), nullptr)
          .message();
  EXPECT_TRUE(e.empty()) << e;
  (void)gm;
  return t;
}

struct Shape {
  const char* name;
  StiffnessModel model;
  bool smooth;     // K without jumps or kinks
  bool rig_table;  // the sampled rig table above instead of the simulator's model
};
const Shape kShapes[] = {{"square", StiffnessModel::Square, false, false},
                         {"trapezoid", StiffnessModel::Trapezoid, false, false},
                         {"fourier", StiffnessModel::Fourier, true, false},
                         {"constant", StiffnessModel::Constant, true, false},
                         {"sampled_table", StiffnessModel::Trapezoid, false, true}};

SignalTable simulateShape(const Shape& shape, const SimConfig& c) {
  return shape.rig_table ? simulateRigTable(c) : simulateOrFail(c);
}

class RefineForwardModel : public ::testing::TestWithParam<Shape> {};

TEST_P(RefineForwardModel, NoiseFreeRefinedEqualsTruthAndIntegralEstimate) {
  const Shape shape = GetParam();
  const SimConfig c = ownCase(shape.model);
  const SignalTable t = simulateShape(shape, c);
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
    EXPECT_LT(rel, kNoiseFreeAgreement) << shape.name << " segment at " << e.t_start << ": refined "
                                        << e.C << " integral " << e.C_integral;
    worst = std::max(worst, rel);
    const double truth = trueC(t, c, e.t_start, e.t_end);
    EXPECT_LT(std::abs(e.C - truth) / truth, kNoiseFreeAgreement)
        << shape.name << " segment at " << e.t_start << ": refined " << e.C << " truth " << truth;
    worst_truth = std::max(worst_truth, std::abs(e.C - truth) / truth);
    worst_integral = std::max(worst_integral, std::abs(e.C_integral - truth) / truth);
    EXPECT_TRUE(e.warnings.empty())
        << shape.name << " segment at " << e.t_start << ": " << e.warnings.front().text
        << " (residual " << e.residuals.rms / e.signal_std << " of the signal)";
  }
  std::cout << "[ measured ] " << shape.name << " noise-free: max |refined - integral| / integral "
            << worst << ", max |refined - truth| / truth " << worst_truth
            << ", max |integral - truth| / truth " << worst_integral << "\n";
}

TEST_P(RefineForwardModel, StandardErrorsCoverTheTruthAt40dB) {
  const Shape shape = GetParam();
  const SimConfig c = ownCase(shape.model);
  const SignalTable clean = simulateShape(shape, c);
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
    if (shape.model == StiffnessModel::Square || shape.model == StiffnessModel::Constant ||
        shape.rig_table) {
      continue;
    }
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

namespace {

// Held or smooth is decided from the samples; the rig table's jumps are located from mesh_phase
// at the switch phases (0 and eps - 1) and its kinks (0.2, 0.4, 0.75) from the samples.
TEST(RefineForwardModelBreaks, HeldOrSmoothAndRigTableBreaksFromTheData) {
  namespace gd = gear_damping_id;
  for (const Shape& shape : kShapes) {
    const SimConfig c = ownCase(shape.model);
    const SignalTable t = simulateShape(shape, c);
    const bool held = gd::channelIsHeld(t.stiffness.data(), 0, t.size());
    EXPECT_EQ(held,
              shape.model == StiffnessModel::Square || shape.model == StiffnessModel::Constant)
        << shape.name;
    if (!shape.rig_table) continue;
    const auto view = gd::SignalView::of(t);
    const auto gear = gd::gearConstants(c.gearModel());
    const gd::ForwardModel fm(view, gear, Formulation::Known);
    EXPECT_EQ(fm.unlocated(), 0);
    const double eps = c.mesh.contact_ratio;
    const double nodes[] = {0.0, 0.2, 0.4, eps - 1.0, 0.75};
    const double cycles = t.mesh_phase[t.size() - 1] - t.mesh_phase[0];
    EXPECT_NEAR(static_cast<double>(fm.breaks().size()), 5.0 * cycles, 5.0);
    for (const auto& b : fm.breaks()) {
      const double u = t.mesh_phase[b.j] + b.th * (t.mesh_phase[b.j + 1] - t.mesh_phase[b.j]);
      const double f = u - std::floor(u);
      double best = 1.0;
      for (double x : nodes) best = std::min({best, std::abs(f - x), 1.0 - std::abs(f - x)});
      EXPECT_LT(best, 1e-6) << "break at interval " << b.j << " phase " << f;
    }
  }
}

// cubicWeights (the torque noise's adjoint pass): its weights on the samples give cubic()'s value
// exactly, at the stages of whole intervals and elsewhere, interior and at both ends of a range,
// and on a range too short for the cubic (linear between the samples).
TEST(RefineForwardModelWeights, CubicWeightsReproduceTheCubic) {
  namespace gd = gear_damping_id;
  SimConfig c = table1Config();
  c.simulation.duration = 2e-5;  // about 20 samples
  const SignalTable t = simulateOrFail(c);
  const auto view = gd::SignalView::of(t);
  const auto gear = gd::gearConstants(c.gearModel());
  const gd::ForwardModel fm(view, gear, Formulation::Known);
  std::vector<double> ch(static_cast<size_t>(t.size()));
  for (size_t k = 0; k < ch.size(); ++k) ch[k] = std::sin(0.7 * static_cast<double>(k)) + 0.1 * k;
  const std::pair<Eigen::Index, Eigen::Index> ranges[] = {{0, t.size()}, {3, 6}, {5, 16}};
  int checked = 0;
  for (const auto& [lo, hi] : ranges) {
    for (Eigen::Index j = lo; j + 1 < hi; ++j) {
      for (double u : {0.0, 0.5, 1.0, 0.3, 0.85}) {
        Eigen::Index first = -1;
        double w[4];
        const int nw = fm.cubicWeights(j, u, lo, hi, &first, w);
        ASSERT_GE(nw, 1);
        ASSERT_LE(nw, 4);
        ASSERT_GE(first, lo);
        ASSERT_LE(first + nw, hi);
        double sum = 0.0;  // against unit samples, as the adjoint pass uses the weights
        for (int k = 0; k < nw; ++k) {
          std::vector<double> unit(ch.size(), 0.0);
          unit[static_cast<size_t>(first + k)] = 1.0;
          EXPECT_EQ(w[k], fm.cubic(unit.data(), j, u, lo, hi)) << j << " " << u << " " << k;
          sum += w[k] * ch[static_cast<size_t>(first + k)];
        }
        EXPECT_NEAR(sum, fm.cubic(ch.data(), j, u, lo, hi), 1e-12 * (1.0 + std::abs(sum)));
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 100);
}

}  // namespace
