// The refinement's closed-form affine maps (held stiffness, constant damping per segment, one
// RK4 step per sample) give the same estimates and standard errors as the generic RK4 of the
// state and sensitivities they replace: the RK4 step of a linear system with held coefficients
// is exactly affine in the state and the stage torques, so the two differ by rounding only.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "gear_damping_id/quality_flags.hpp"
#include "id_test_support.hpp"
#include "status_support.hpp"

namespace {

using namespace gear_id_test;
using gear_damping_id::SegmentEstimate;

// Rounding differences of ~1e-16 per step grow through ~1e3 steps per segment and the
// Gauss-Newton solve (condition ~1e2): 1e-9 relative leaves a wide margin and is the bar.
constexpr double kSameTol = 1e-9;

void expectSame(double a, double b, const std::string& what) {
  EXPECT_LE(std::abs(a - b), kSameTol * std::abs(b)) << what << ": " << a << " vs " << b;
}

// Both refined, with the same C and C_std.
void expectSameC(const SegmentEstimate& a, const SegmentEstimate& b, const std::string& label) {
  ASSERT_TRUE(a.refined && b.refined) << label;
  expectSame(a.C, b.C, label + " C");
  expectSame(a.C_std, b.C_std, label + " C_std");
}

// The integral estimate of `t` refined by the fast path and by the reference (generic RK4).
void refineBoth(const SignalTable& t, const gear_damping_id::GearConstants& gear,
                const IdentificationOptions& o, IdentificationResult* fast,
                IdentificationResult* reference) {
  const auto view = gear_damping_id::SignalView::of(t);
  IdentificationResult start;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_damping_id::identify(t, gear, o, &start), &e)) << e;
  const auto ranges = gear_damping_id::segmentRanges(view, o);
  *fast = start, *reference = start;
  ASSERT_TRUE(
      gear_test::ok(gear_damping_id::refineOutputError(view, ranges, gear, o, fast, false), &e))
      << e;
  ASSERT_TRUE(
      gear_test::ok(gear_damping_id::refineOutputError(view, ranges, gear, o, reference, true), &e))
      << e;
  ASSERT_EQ(fast->segments.size(), reference->segments.size());
}

// `rho` > 0: AR(1) measurement noise of that lag-1 correlation (the prewhitened problem).
void compare(Formulation f, DampingModel m, double snr_db, unsigned long seed, double rho = 0.0) {
  SimConfig c = table1Config();
  c.simulation.duration = 0.005;
  if (m == DampingModel::Piecewise) setPiecewiseTruth(&c, 1e-3);
  SignalTable t = simulateOrFail(c);
  if (rho > 0.0)
    addAr1Noise(&t.dte, snr_db, rho, seed);
  else
    addWhiteNoise(&t.dte, snr_db, seed);
  const auto gear = gear_damping_id::gearConstants(c.gearModel());
  const auto view = gear_damping_id::SignalView::of(t);
  IdentificationOptions o;
  o.formulation = f;
  o.model = m;
  o.refine = IdentificationOptions::Refine::Never;
  o.window_length = gear_damping_id::defaultWindowLength(view, gear);
  IdentificationResult fast, reference;
  ASSERT_NO_FATAL_FAILURE(refineBoth(t, gear, o, &fast, &reference));
  const std::string label = gear_damping_id::toString(f) + " " + gear_damping_id::toString(m);
  EXPECT_EQ(fast.noise_ar.size(), reference.noise_ar.size()) << label;
  for (size_t i = 0; i < fast.segments.size(); ++i) {
    const SegmentEstimate& a = fast.segments[i];
    const SegmentEstimate& b = reference.segments[i];
    ASSERT_NO_FATAL_FAILURE(expectSameC(a, b, label));
    if (f == Formulation::Greybox) {
      expectSame(a.k_min, b.k_min, label + " k_min");
      expectSame(a.k_max_std, b.k_max_std, label + " k_max_std");
    }
  }
  expectSame(fast.noise_std, reference.noise_std, label + " noise_std");
  if (rho > 0.0) {
    EXPECT_FALSE(reference.noise_ar.empty()) << label << ": no AR model fitted";
  }
  if (m == DampingModel::LoadLaw) {
    ASSERT_TRUE(fast.load_law && reference.load_law) << label;
    expectSame(fast.load_law->c0, reference.load_law->c0, label + " c0");
    expectSame(fast.load_law->c1, reference.load_law->c1, label + " c1");
    expectSame(fast.load_law->c0_std, reference.load_law->c0_std, label + " c0_std");
    expectSame(fast.load_law->c1_std, reference.load_law->c1_std, label + " c1_std");
  }
}

// The tabled look-ups (issue 18): every stiffness model, the variation test and the greybox
// unknowns give the reference's numbers. `mesh` sets the stiffness model; `shape` (greybox) the
// stiffness shape ("" for the square levels).
void compareModel(const std::string& label, void (*mesh)(SimConfig*), Formulation f,
                  const std::string& shape, unsigned long seed) {
  SimConfig c = table1Config();  // load-dependent damping: the variation test iterates
  c.simulation.duration = 0.005;
  mesh(&c);
  SignalTable t = simulateOrFail(c);
  addWhiteNoise(&t.dte, 40.0, seed);
  const auto gear = gear_damping_id::gearConstants(c.gearModel());
  const auto view = gear_damping_id::SignalView::of(t);
  IdentificationOptions o;
  o.formulation = f;
  if (!shape.empty()) {
    ASSERT_TRUE(gear_damping_id::parseStiffnessShape(shape, &o.stiffness_shape));
  }
  o.refine = IdentificationOptions::Refine::Never;
  o.window_length = gear_damping_id::defaultWindowLength(view, gear);
  IdentificationResult fast, reference;
  ASSERT_NO_FATAL_FAILURE(refineBoth(t, gear, o, &fast, &reference));
  int varied = 0;
  for (size_t i = 0; i < fast.segments.size(); ++i) {
    const SegmentEstimate& a = fast.segments[i];
    const SegmentEstimate& b = reference.segments[i];
    ASSERT_NO_FATAL_FAILURE(expectSameC(a, b, label));
    expectSame(a.C_weighted, b.C_weighted, label + " C_weighted");
    ASSERT_EQ(std::isfinite(a.variation_z), std::isfinite(b.variation_z)) << label;
    if (std::isfinite(b.variation_z)) expectSame(a.variation_z, b.variation_z, label + " z");
    varied += std::abs(b.variation_z) > gear_damping_id::QualityLimits::kVariationZ;
    ASSERT_EQ(a.stiffness_curve.size(), b.stiffness_curve.size()) << label;
    for (size_t k = 0; k < a.stiffness_curve.size(); ++k) {
      expectSame(a.stiffness_curve[k], b.stiffness_curve[k], label + " curve");
      expectSame(a.stiffness_curve_std[k], b.stiffness_curve_std[k], label + " curve_std");
    }
    if (f == Formulation::Greybox && shape.empty()) {
      expectSame(a.k_min, b.k_min, label + " k_min");
      expectSame(a.k_max, b.k_max, label + " k_max");
      expectSame(a.k_min_std, b.k_min_std, label + " k_min_std");
      expectSame(a.k_max_std, b.k_max_std, label + " k_max_std");
    }
  }
  expectSame(fast.noise_std, reference.noise_std, label + " noise_std");
  std::cout << "[ measured ] " << label << ": " << varied << " of " << fast.segments.size()
            << " segments with |variation_z| > " << gear_damping_id::QualityLimits::kVariationZ
            << " (the enlarged fit iterated)\n";
}

void squareMesh(SimConfig*) {}
void trapezoidMesh(SimConfig* c) {
  c->mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c->mesh.transition_fraction = 0.12;
}
void fourierMesh(SimConfig* c) {
  c->mesh.model = gear_sim::StiffnessModel::Fourier;
  c->mesh.k_mean = 3.0e8;
  c->mesh.fourier_cos = {6.0e7, -1.5e7};
  c->mesh.fourier_sin = {2.0e7, 1.0e7};
}

TEST(RefineFastPath, SameAsTheReferenceOnEveryStiffnessModelWithTheVariationTest) {
  compareModel("square known", squareMesh, Formulation::Known, "", 31);
  compareModel("trapezoid known", trapezoidMesh, Formulation::Known, "", 32);
  compareModel("fourier known", fourierMesh, Formulation::Known, "", 33);
  compareModel("square greybox", squareMesh, Formulation::Greybox, "", 34);
  compareModel("fourier greybox fourier:2", fourierMesh, Formulation::Greybox, "fourier:2", 35);
}

TEST(RefineFastPath, SameEstimatesAsTheGenericRk4) {
  compare(Formulation::Known, DampingModel::Piecewise, 40.0, 11);
  compare(Formulation::Known, DampingModel::Piecewise, 20.0, 12);
  compare(Formulation::Greybox, DampingModel::Piecewise, 40.0, 13);
  compare(Formulation::Known, DampingModel::Constant, 40.0, 14);
}

// The fused pass (issue 18) with a fitted AR noise model (prewhitened rows) and with the load
// law (C varying within each step: the RK4 step in lanes) against the generic RK4.
TEST(RefineFastPath, SameWithColouredNoiseAndTheLoadLaw) {
  compare(Formulation::Known, DampingModel::Piecewise, 40.0, 16, 0.8);
  compare(Formulation::Greybox, DampingModel::Piecewise, 40.0, 17, 0.8);
  compare(Formulation::Known, DampingModel::LoadLaw, 40.0, 18);
  compare(Formulation::Known, DampingModel::LoadLaw, 40.0, 19, 0.8);
}

}  // namespace

namespace {

// The integral estimate is kept beside the refined one, and a refinement stopped by the
// iteration limit says so on every segment it touched.
TEST(RefineBookkeeping, KeepsTheIntegralEstimateAndFlagsNonConvergence) {
  SimConfig c = table1Config();
  c.simulation.duration = 0.004;
  setPiecewiseTruth(&c, 1e-3);
  SignalTable t = simulateOrFail(c);
  addWhiteNoise(&t.dte, 30.0, 21);
  IdentificationOptions o;
  o.refine = IdentificationOptions::Refine::Never;
  const IdentificationResult integral = identifyOrFail(t, c, o);
  o.refine = IdentificationOptions::Refine::Always;
  const IdentificationResult refined = identifyOrFail(t, c, o);
  ASSERT_EQ(refined.segments.size(), integral.segments.size());
  for (size_t i = 0; i < refined.segments.size(); ++i) {
    const SegmentEstimate& e = refined.segments[i];
    EXPECT_TRUE(e.refined);
    EXPECT_EQ(e.C_integral, integral.segments[i].C);
    EXPECT_EQ(e.C_integral_std, integral.segments[i].C_std);
    EXPECT_TRUE(e.warnings.empty());
    EXPECT_TRUE(std::isfinite(e.residuals.rms) && e.residuals.rms > 0.0);
  }
  // One Gauss-Newton step from the integral estimate at 30 dB cannot reach 1e-10.
  o.max_iterations = 1;
  const IdentificationResult stopped = identifyOrFail(t, c, o);
  int flagged = 0;
  for (const SegmentEstimate& e : stopped.segments) {
    for (const auto& w : e.warnings) flagged += w.code == "refine_not_converged";
  }
  EXPECT_EQ(flagged, static_cast<int>(stopped.segments.size()));
}

}  // namespace
