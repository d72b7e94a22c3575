// Issue 19 (a): torque-meter noise. The identification takes the torque as the exact forcing, so
// white noise on the torque samples drives the model like a force; the output-error refinement
// estimates its level from the torque channel (model-free) and propagates its response into the
// standard errors (output_error.hpp, docs/trust.md). Checked here: the level estimate against
// the simulated truth, the coverage of C by 2 SE with torque noise on the plain refinement and
// on rig records (quantised encoders, the STE modelled), and that an exact torque adds nothing.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>
#include <vector>

#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"
#include "id_test_support.hpp"
#include "rig_test_support.hpp"
#include "status_support.hpp"
#include "ste_rig_support.hpp"
#include "ste_test_support.hpp"

using namespace gear_ste_test;

namespace {

namespace gd = gear_damping_id;

// The level estimate: white noise on a smooth load (a 100 N*m mean with a 20 % sine at 150 Hz,
// 1 MHz samples) within 3 % of the truth over 50 000 samples (measured 1.6 %) and within 20 % on
// every 1 000-sample segment (the refinement estimates per segment: the median of the correlated
// |4th differences| scatters by about 5 % there; measured worst of 50: 12.5 %); the load alone
// gives a level below 1e-9 of it (measured 2e-12 N*m: rounding).
TEST(TorqueNoise, EstimateOfWhiteNoiseOnASmoothLoad) {
  const long n = 50000;
  const double sigma = 0.2, dt = 1e-6;
  std::vector<double> load(n), noisy(n);
  std::mt19937_64 gen(42);
  std::normal_distribution<double> nd(0.0, sigma);
  for (long i = 0; i < n; ++i) {
    load[i] = 100.0 + 20.0 * std::sin(2 * M_PI * 150.0 * i * dt);
    noisy[i] = load[i] + nd(gen);
  }
  const double whole = gd::torqueNoiseEstimate(noisy.data(), n);
  EXPECT_NEAR(whole / sigma, 1.0, 0.03);
  double worst = 0.0;
  for (long b = 0; b + 1000 <= n; b += 1000)
    worst = std::max(worst, std::abs(gd::torqueNoiseEstimate(noisy.data() + b, 1000) / sigma - 1));
  EXPECT_LT(worst, 0.2);
  const double clean = gd::torqueNoiseEstimate(load.data(), n);
  EXPECT_LT(clean, 1e-9 * sigma);
  EXPECT_TRUE(std::isnan(gd::torqueNoiseEstimate(noisy.data(), 4)));
  std::cout << "[ measured ] torque noise estimate / truth: " << whole / sigma
            << " (50 000 samples), worst 1 000-sample segment off by " << worst
            << "; smooth load alone " << clean << " N*m\n";
}

// The plain identification (no STE, known stiffness, piecewise, default refinement) on the
// Table 1 case with 40 dB DTE noise and white torque noise of 0.2 % and 0.5 % of the mean load,
// 30 seeds x 10 segments each: C within 2 SE in >= 90 %. (Without the torque noise's part of
// C_std, as before its propagation, fewer: printed.)
TEST(TorqueNoise, PlainRefinementCoverage) {
  SimConfig c = table1Config();
  c.simulation.duration = 0.01;
  setPiecewiseTruth(&c, 1e-3);
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Known;
  for (double frac : {2e-3, 5e-3}) {
    long inside = 0, total = 0, inside_without = 0;
    std::vector<double> share;
    for (int seed = 1; seed <= 30; ++seed) {
      SignalTable t = clean;
      addWhiteNoise(&t.dte, 40.0, 1000 + seed);
      std::mt19937_64 gen(5000 + seed);
      std::normal_distribution<double> nd(0.0, frac * c.load.mean);
      for (Eigen::Index i = 0; i < t.size(); ++i) t.torque[i] += nd(gen);
      const IdentificationResult r = identifyOrFail(t, c, o);
      for (const auto& e : r.segments) {
        ++total;
        if (!e.identifiable) continue;
        const double err = std::abs(e.C - trueC(t, c, e.t_start, e.t_end));
        inside += err <= 2.0 * e.C_std;
        // Without the torque noise's part: the standard error reported before it was propagated.
        inside_without +=
            err <=
            2.0 * std::sqrt(std::max(e.C_std * e.C_std - e.C_torque_std * e.C_torque_std, 0.0));
        share.push_back(e.C_torque_std / e.C_std);
      }
    }
    std::cout << "[ measured ] plain refinement, 40 dB + " << 100 * frac
              << " % torque noise, 30 seeds: " << inside << " of " << total
              << " within 2 SE (without the torque noise's part of C_std: " << inside_without
              << "); median C_torque_std / C_std " << median(share) << "\n";
    EXPECT_GE(inside, 0.9 * total) << frac;
  }
}

// The torque noise's covariance in closed form (one backward pass per unknown through the
// converged model's step maps, output_error.hpp) equals the reference path's brute-force sum
// over unit impulses of the torque, one per sample (each response by the generic RK4, each
// through the solve map): C, C_std and C_torque_std to 1e-9 relative (rounding through ~1e3
// steps and the solve), piecewise (per-segment problems), constant (one joint problem: the
// segments' cross terms) and greybox; likewise the scores variation_z and shape_z, whose variance
// carries the torque noise's response projected on their direction.
TEST(TorqueNoise, ExactPropagationEqualsTheImpulseSum) {
  // The scores (variation_z, shape_z) are O(1) ratios of residual projections; the paths differ
  // beyond the torque noise only in rounding and, for shape_z, in the ramp's response (the tabled
  // stage torques against the cubic; measured 8e-9 here): both far below this.
  constexpr double kScoreTol = 1e-7;
  struct Run {
    Formulation f;
    DampingModel m;
  };
  for (const Run& run : {Run{Formulation::Known, DampingModel::Piecewise},
                         Run{Formulation::Known, DampingModel::Constant},
                         Run{Formulation::Greybox, DampingModel::Piecewise}}) {
    SimConfig c = table1Config();
    c.simulation.duration = 0.003;
    if (run.m == DampingModel::Piecewise) setPiecewiseTruth(&c, 1e-3);
    SignalTable t = simulateOrFail(c);
    addWhiteNoise(&t.dte, 40.0, 77);
    std::mt19937_64 gen(78);
    std::normal_distribution<double> nd(0.0, 5e-3 * c.load.mean);
    for (Eigen::Index i = 0; i < t.size(); ++i) t.torque[i] += nd(gen);
    const auto gear = gd::gearConstants(c.gearModel());
    const auto view = gd::SignalView::of(t);
    IdentificationOptions o;
    o.formulation = run.f;
    o.model = run.m;
    o.refine = IdentificationOptions::Refine::Never;
    o.window_length = gd::defaultWindowLength(view, gear);
    IdentificationResult start;
    std::string e;
    ASSERT_TRUE(gear_test::ok(gd::identify(t, gear, o, &start), &e)) << e;
    const auto ranges = gd::segmentRanges(view, o);
    IdentificationResult fast = start, reference = start;
    ASSERT_TRUE(gear_test::ok(gd::refineOutputError(view, ranges, gear, o, &fast, false), &e)) << e;
    ASSERT_TRUE(gear_test::ok(gd::refineOutputError(view, ranges, gear, o, &reference, true), &e))
        << e;
    const std::string label = gd::toString(run.f) + " " + gd::toString(run.m);
    auto same = [&](double a, double b, const std::string& what) {
      EXPECT_LE(std::abs(a - b), 1e-9 * std::abs(b))
          << label << " " << what << ": " << a << " vs " << b;
    };
    ASSERT_EQ(fast.segments.size(), reference.segments.size());
    double share = 0.0, worst_z = 0.0;
    for (size_t i = 0; i < fast.segments.size(); ++i) {
      const gd::SegmentEstimate& a = fast.segments[i];
      const gd::SegmentEstimate& b = reference.segments[i];
      ASSERT_TRUE(a.refined && b.refined) << label;
      ASSERT_GT(b.C_torque_std, 0.0) << label;
      same(a.C, b.C, "C");
      same(a.C_std, b.C_std, "C_std");
      same(a.C_torque_std, b.C_torque_std, "C_torque_std");
      // The scores' torque-noise variance (one projected direction through the backward pass
      // against the impulses): z is O(1), compared to kScoreTol absolute.
      if (run.m == DampingModel::Piecewise) {
        ASSERT_TRUE(std::isfinite(b.variation_z)) << label;
        EXPECT_NEAR(a.variation_z, b.variation_z, kScoreTol) << label << " variation_z";
      }
      if (run.f == Formulation::Greybox) {
        ASSERT_TRUE(std::isfinite(b.shape_z)) << label;
        EXPECT_NEAR(a.shape_z, b.shape_z, kScoreTol) << label << " shape_z";
      }
      worst_z = std::max(
          {worst_z, std::abs(a.variation_z - b.variation_z), std::abs(a.shape_z - b.shape_z)});
      share = std::max(share, b.C_torque_std / b.C_std);
    }
    if (run.m == DampingModel::Constant) {
      same(fast.constant->C, reference.constant->C, "constant C");
      same(fast.constant->C_std, reference.constant->C_std, "constant C_std");
      // The constancy test's per-segment torque variance: the kept right-hand-side covariance
      // (fast) against impulses on the score's direction (reference).
      ASSERT_TRUE(std::isfinite(reference.constant->variation_z)) << label;
      EXPECT_NEAR(fast.constant->variation_z, reference.constant->variation_z, kScoreTol)
          << label << " constant variation_z";
      worst_z =
          std::max(worst_z, std::abs(fast.constant->variation_z - reference.constant->variation_z));
    }
    std::cout << "[ measured ] " << label << ": largest C_torque_std / C_std " << share
              << ", largest score difference " << worst_z << "\n";
  }
}

// Acceptance: 20-bit and 16-bit encoders with torque noise of 0.1 %, 0.2 % and 0.5 % of the mean
// load, the STE modelled (3 mesh harmonics, run-out), the three gear cases in turn, 30 seeds
// each (10 ms records, 1 ms segments): C within 2 SE in >= 90 % of the reported segments. CI time:
// the mesh offset given (ste_rig_test estimates it; docs/rig.md).
TEST(TorqueNoise, RigCoverage) {
  for (long counts : {1L << 20, 1L << 16}) {
    for (double frac : {1e-3, 2e-3, 5e-3}) {
      const Coverage cv =
          steCoverage(counts, 30, true, IdentificationOptions::Refine::Auto, frac, 0.01);
      EXPECT_GE(cv.inside, 0.9 * cv.reported) << counts << " counts, " << frac;
      // 16 bit: 251 of 300 reported (measured; the rest are below the noise by an integral fit
      // whose C is not positive, which the refinement cannot start from). Guards that level.
      EXPECT_GE(cv.reported, cv.total * 4 / 5) << counts << " counts, " << frac;
      // The level is estimated per 1 ms segment from its torque samples.
      EXPECT_NEAR(median(cv.torque_ratio), 1.0, 0.05) << counts << " counts, " << frac;
    }
  }
}

// An exact torque adds nothing: with no torque noise (20-bit encoders, mesh offset given) the
// torque part of every reported C_std is zero (the estimated level is at rounding, below 1e-12 of
// the load, and not propagated).
TEST(TorqueNoise, ExactTorqueAddsNothing) {
  const Coverage cv =
      steCoverage(1L << 20, 6, true, IdentificationOptions::Refine::Auto, 0.0, 0.004);
  ASSERT_GT(cv.reported, 0);
  EXPECT_EQ(maxOf(cv.torque_share), 0.0);
}

}  // namespace
