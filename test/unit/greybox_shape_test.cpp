// Greybox stiffness shapes (issue 13, deliverable 2): `fourier:H` and `table:N` identify C and
// the stiffness curve jointly. Noise-free, on a stiffness the shape represents exactly (Fourier
// with H or more harmonics; a trapezoid whose corners sit on table nodes), C is within 0.1 % and
// the curve is right; on one it cannot represent, each segment is within 0.1 % or flagged.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <iostream>

#include "gear_damping_id/quality_flags.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/models.hpp"
#include "id_test_support.hpp"
#include "status_support.hpp"

namespace {

using namespace gear_id_test;
namespace gd = gear_damping_id;
using gd::StiffnessShape;

// Issue 13 bar for the noise-free greybox shapes (as the square greybox's 0.1 %).
constexpr double kShapeCTol = 1e-3;
// Stiffness curve values against the truth, relative to the mean stiffness: the curve's
// unknowns are as well determined as the square levels (0.01 %, identification_accuracy_test)
// times the larger number of unknowns; 0.1 % of the mean.
constexpr double kCurveTol = 1e-3;

StiffnessShape shape(const std::string& text) {
  StiffnessShape s;
  EXPECT_TRUE(gd::parseStiffnessShape(text, &s)) << text;
  return s;
}

IdentificationResult identifyShape(const SignalTable& t, const SimConfig& c,
                                   const std::string& text, bool refine = false) {
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  o.stiffness_shape = shape(text);
  if (refine) o.refine = IdentificationOptions::Refine::Always;
  return identifyOrFail(t, c, o);
}

// The identified curve against the true stiffness over a mesh cycle (max abs difference).
double curveError(const gd::SegmentEstimate& s, const StiffnessShape& sh, const SimConfig& c) {
  const gear_sim::MeshStiffness truth(c.mesh);
  std::vector<double> b(sh.unknowns());
  double worst = 0.0;
  for (int g = 0; g < 200; ++g) {
    const double u = g / 200.0;
    sh.basis(u, b.data());
    double k = 0.0;
    for (size_t j = 0; j < b.size(); ++j) k += s.stiffness_curve[j] * b[j];
    worst = std::max(worst, std::abs(k - truth.at(u, u)));
  }
  return worst;
}

// Every segment within kShapeCTol of the truth, clean, and its curve within kCurveTol; with
// `refine` the output-error estimates (and the modeled response's fit).
void expectExact(const SimConfig& c, const std::string& text, const std::string& label,
                 bool refine = false) {
  const SignalTable t = simulateOrFail(c);
  const IdentificationResult r = identifyShape(t, c, text, refine);
  if (refine) {
    EXPECT_EQ(r.estimator, "output_error") << label;
  }
  const double kmean = gear_sim::MeshStiffness(c.mesh).mean();
  double worst_c = 0.0, worst_k = 0.0, worst_res = 0.0;
  ASSERT_FALSE(r.segments.empty());
  for (const auto& s : r.segments) {
    ASSERT_TRUE(s.identifiable) << label << ": " << s.reason;
    const double truth = trueC(t, c, s.t_start, s.t_end);
    const double ec = std::abs(s.C - truth) / truth;
    const double ek = curveError(s, shape(text), c) / kmean;
    worst_c = std::max(worst_c, ec), worst_k = std::max(worst_k, ek);
    EXPECT_LT(ec, kShapeCTol) << label << " segment at " << s.t_start;
    EXPECT_LT(ek, kCurveTol) << label << " segment at " << s.t_start;
    EXPECT_TRUE(s.warnings.empty()) << label << ": [" << gd::joinCodes(s.warnings) << "]";
    if (refine) {
      EXPECT_TRUE(s.refined);
    }
    worst_res = std::max(worst_res, s.residual_rms / s.signal_std);
  }
  if (refine) {
    gd::ModeledResponse m;
    std::string e;
    ASSERT_TRUE(gear_test::ok(
        gd::modeledResponse(gd::SignalView::of(t), gd::gearConstants(c.gearModel()), r, &m), &e))
        << e;
    EXPECT_GT(m.fit_percent, 99.0) << label;
  }
  std::cout << "[ measured ] " << (refine ? "refined " : "") << label << " with " << text
            << ": worst C error " << worst_c * 100 << " %, worst curve error " << worst_k * 100
            << " % of mean K, residual up to " << worst_res << " of the signal\n";
}

SimConfig fourierCase() {
  SimConfig c = table1Config();
  setPiecewiseTruth(&c, 1e-3);
  c.mesh.model = gear_sim::StiffnessModel::Fourier;
  c.mesh.k_mean = 3.0e8;
  c.mesh.fourier_cos = {6.0e7, -1.5e7};
  c.mesh.fourier_sin = {2.0e7, 1.0e7};
  return c;
}

// fourier:2 on fourierCase() with 2 ms segments (with five stiffness unknowns many 1 ms segments
// of the forced response are below the noise at 40 dB): f(seed, record, config, result) for 12
// records with white noise at 40 dB, seeds seed0 + 1 ... seed0 + 12.
void forEachNoisyFourier2Fit(unsigned long seed0,
                             const std::function<void(int, const SignalTable&, const SimConfig&,
                                                      const IdentificationResult&)>& f) {
  SimConfig c = fourierCase();
  setPiecewiseTruth(&c, 2e-3);
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  o.stiffness_shape = shape("fourier:2");
  o.segment_length = 2e-3;
  for (int seed = 1; seed <= 12; ++seed) {
    SignalTable t = clean;
    addWhiteNoise(&t.dte, 40.0, seed0 + seed);
    f(seed, t, c, identifyOrFail(t, c, o));
  }
}

TEST(GreyboxShape, FourierShapeOnFourierStiffness) {
  const SimConfig c = fourierCase();
  expectExact(c, "fourier:2", "fourier stiffness (2 harmonics)");
  expectExact(c, "fourier:4", "fourier stiffness (2 harmonics)");
  // Held-out: other gear, speed, sample rate, three harmonics.
  SimConfig h = heldOutCase();
  setPiecewiseTruth(&h, 1e-3);
  h.mesh.model = gear_sim::StiffnessModel::Fourier;
  h.mesh.k_mean = 2.6e8;
  h.mesh.fourier_cos = {4.0e7, 0.0, 8.0e6};
  h.mesh.fourier_sin = {-3.0e7, 1.2e7, 0.0};
  expectExact(h, "fourier:3", "held-out fourier stiffness (3 harmonics)");
}

TEST(GreyboxShape, TableShapeOnTrapezoidWithCornersOnNodes) {
  // eps = 1.6, ramps of 0.1 cycle centred on 0 and 0.6: corners at 0.05, 0.55, 0.65, 0.95,
  // all on the nodes j/20.
  SimConfig c = table1Config();
  setPiecewiseTruth(&c, 1e-3);
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = 0.1;
  expectExact(c, "table:20", "trapezoid (corners on nodes)");
  // Held-out: eps = 1.5, ramps of 0.125: corners at 1/16, 7/16, 9/16, 15/16.
  SimConfig h = heldOutCase();
  setPiecewiseTruth(&h, 1e-3);
  h.mesh.contact_ratio = 1.5;
  h.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  h.mesh.transition_fraction = 0.125;
  expectExact(h, "table:16", "held-out trapezoid (corners on nodes)");
}

// A shape the parametrisation cannot represent: each segment within kShapeCTol or flagged.
void expectRightOrFlagged(const SimConfig& c, const std::string& text, const std::string& label,
                          double db) {
  SignalTable t = simulateOrFail(c);
  if (std::isfinite(db)) addWhiteNoise(&t.dte, db, 21);
  const IdentificationResult r = identifyShape(t, c, text);
  int flagged = 0, right = 0;
  for (const auto& s : r.segments) {
    const double truth = trueC(t, c, s.t_start, s.t_end);
    const bool ok = s.identifiable && std::abs(s.C - truth) <= kShapeCTol * truth;
    const bool flag = !s.identifiable || !s.warnings.empty();
    flagged += flag, right += ok;
    EXPECT_TRUE(ok || flag) << label << " " << text << " segment at " << s.t_start
                            << ": C = " << s.C << " +- " << s.C_std << ", truth " << truth
                            << ", clean (residual " << s.residual_rms / s.noise_std << " x noise, "
                            << 100 * s.residual_rms / s.signal_std << " % of the signal)";
  }
  std::cout << "[ measured ] " << label << " with " << text << " at " << db << " dB: " << right
            << " of " << r.segments.size() << " within 0.1 %, " << flagged << " flagged\n";
}

TEST(GreyboxShape, UnrepresentableShapeIsRightOrFlagged) {
  const double inf = std::numeric_limits<double>::infinity();
  SimConfig c = table1Config();
  setPiecewiseTruth(&c, 1e-3);
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = 0.1;
  for (const char* s : {"fourier:1", "fourier:3", "fourier:8", "table:8", "table:12"}) {
    expectRightOrFlagged(c, s, "trapezoid", inf);
  }
  // Held-out: corners at 0.03, 0.40, 0.46, 0.97 (no table of <= 32 nodes holds them).
  SimConfig h = heldOutCase();
  setPiecewiseTruth(&h, 1e-3);
  h.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  h.mesh.transition_fraction = 0.06;
  for (const char* s : {"fourier:2", "fourier:10", "table:10", "table:32"}) {
    expectRightOrFlagged(h, s, "held-out trapezoid", inf);
  }
  // Fourier stiffness with fewer harmonics than it has.
  expectRightOrFlagged(fourierCase(), "fourier:1", "fourier stiffness (2 harmonics)", inf);
  expectRightOrFlagged(fourierCase(), "fourier:1", "fourier stiffness (2 harmonics)", 40.0);
}

// The output-error refinement identifies C and the curve jointly for the fourier/table shapes:
// noise-free on a stiffness the shape represents, C within 0.1 % and the curve right (and the
// modeled response follows the identified curve); at 40 dB the refined C lies within a few of
// its standard errors of the truth.
TEST(GreyboxShape, RefinedJointlyWithTheCurve) {
  expectExact(fourierCase(), "fourier:2", "fourier stiffness (2 harmonics)", true);
  SimConfig c = table1Config();
  setPiecewiseTruth(&c, 1e-3);
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = 0.1;
  expectExact(c, "table:20", "trapezoid (corners on nodes)", true);
}

TEST(GreyboxShape, RefinedAt40dBWithinItsStandardErrors) {
  long covered = 0, total = 0;
  forEachNoisyFourier2Fit(
      4400, [&](int seed, const SignalTable& t, const SimConfig& c, const IdentificationResult& r) {
        ASSERT_EQ(r.estimator, "output_error");
        for (const auto& s : r.segments) {
          // Where the forced response holds too little damping information against the noise (the
          // stiffness curve's unknowns absorb much of it), the segment is honestly below_noise.
          if (!s.identifiable) continue;
          const double z = (s.C - trueC(t, c, s.t_start, s.t_end)) / s.C_std;
          covered += std::abs(z) <= 2.0;
          ++total;
          EXPECT_LT(std::abs(z), 4.5) << "seed " << seed << " segment at " << s.t_start;
        }
      });
  std::cout << "[ measured ] refined fourier:2 at 40 dB: +-2 SE coverage "
            << 100.0 * covered / total << " % of " << total << " segments\n";
  // An honest SE covers 95 %; with >= 30 draws 80 % is > 3.7 binomial standard deviations below.
  ASSERT_GE(total, 30);
  EXPECT_GE(static_cast<double>(covered) / total, 0.8);
}

// The curve shapes' shape test (output_error.cpp, Refinement::curveScore): the held-out
// trapezoid of docs/limits.md (scripts/heldout_sweep.py seed 7060: 40 dB, xi 0.03 at 5,325 rpm,
// ramps of 0.28 of a cycle; before the test table:8 left 46 of its 50 segments clean at
// 2.8-3.9x the truth, 4-17 C_std off) is flagged wherever C is wrong: no clean segment more than
// 4 C_std and 0.05 % from the truth, over three noise draws.
SimConfig sweepTrapezoid() {
  const char* yaml = R"(
pinion: {teeth: 32, inertia: 0.0006678259180524169, base_radius: 0.0660306015725896}
gear: {teeth: 33, inertia: 0.010864728589724442, base_radius: 0.06809405787173302}
mesh: {stiffness_model: trapezoid, k_max: 298653861.5186588, k_min: 129103833.41917977,
       contact_ratio: 1.360777359292162, initial_phase: 0.8490746012060254,
       transition_fraction: 0.2803015475099431}
speed: {profile: constant, pinion_rpm: 5325.358976209697}
load: {profile: sine, mean: 364.32770100287127, amplitude: 83.65982212504775,
       frequency: 18.905138868312868}
damping: {model: constant, ratio: 0.030011381641471484}
simulation: {duration: 0.05, sample_rate: 500000.0, integrator: rk4, substeps: 1,
             dynamics: reduced}
)";
  SimConfig c;
  std::string e;
  EXPECT_TRUE(gear_test::ok(gear_sim::loadSimConfig(YAML::Load(yaml), &c), &e)) << e;
  return c;
}

TEST(GreyboxShape, CurveShapeTestFlagsTheWrongTable) {
  const SimConfig c = sweepTrapezoid();
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  o.stiffness_shape = shape("table:8");
  int wrong_clean = 0, wrong = 0, total = 0;
  for (unsigned long seed : {1, 2, 3}) {
    SignalTable t = clean;
    addWhiteNoise(&t.dte, 40.0, 7060 + seed);
    const IdentificationResult r = identifyOrFail(t, c, o);
    for (const auto& s : r.segments) {
      if (!s.identifiable) continue;
      const double truth = trueC(t, c, s.t_start, s.t_end), d = std::abs(s.C - truth);
      const bool far = d > 4.0 * s.C_std && d > 5e-4 * truth;
      wrong += far, ++total;
      const bool flagged = !s.warnings.empty() || !r.warnings.empty();
      wrong_clean += far && !flagged;
      EXPECT_FALSE(far && !flagged)
          << "seed " << seed << " segment at " << s.t_start << ": C " << s.C << " +- " << s.C_std
          << ", truth " << truth << ", shape_z " << s.shape_z;
    }
  }
  std::cout << "[ measured ] table:8 on the sweep's trapezoid (seed 7060) at 40 dB: " << wrong
            << " of " << total << " segments > 4 C_std and 0.05 % off, " << wrong_clean
            << " of them clean\n";
  EXPECT_GT(wrong, 0);  // the case still shows the bias the test has to catch
}

// Where the curve is right (fourier:2 on a two-harmonic Fourier stiffness, 40 dB), the score is
// N(0, 1): its rms over the judged segments within 1 +- 3 / sqrt(2 n), and no pooled alarm.
TEST(GreyboxShape, CurveShapeScoreCalibratedWhereTheCurveIsRight) {
  double sum2 = 0.0;
  long n = 0, flagged = 0;
  forEachNoisyFourier2Fit(
      5500, [&](int seed, const SignalTable&, const SimConfig&, const IdentificationResult& r) {
        EXPECT_FALSE(gd::hasCode(r.warnings, gd::quality_code::kShapeMismatch)) << "seed " << seed;
        for (const auto& s : r.segments) {
          if (!std::isfinite(s.shape_z)) continue;
          sum2 += s.shape_z * s.shape_z, ++n;
          flagged += gd::hasCode(s.warnings, gd::quality_code::kShapeMismatch);
        }
      });
  ASSERT_GE(n, 30);
  const double rms = std::sqrt(sum2 / n);
  std::cout << "[ measured ] fourier:2 on a Fourier stiffness at 40 dB: shape_z rms " << rms
            << " over " << n << " segments, " << flagged << " flagged shape_mismatch\n";
  EXPECT_NEAR(rms, 1.0, 3.0 / std::sqrt(2.0 * n));
}

TEST(GreyboxShape, ParseAndValidate) {
  StiffnessShape s;
  EXPECT_TRUE(gd::parseStiffnessShape("square", &s));
  EXPECT_EQ(s.unknowns(), 2);
  EXPECT_TRUE(gd::parseStiffnessShape("fourier:3", &s));
  EXPECT_EQ(s.unknowns(), 7);
  EXPECT_EQ(gd::toString(s), "fourier:3");
  EXPECT_TRUE(gd::parseStiffnessShape("table:12", &s));
  EXPECT_EQ(s.unknowns(), 12);
  for (const char* bad : {"", "fourier", "fourier:", "fourier:0", "fourier:17", "table:2",
                          "table:33", "table:-4", "spline:4", "fourier:2x", "square:2"}) {
    EXPECT_FALSE(gd::parseStiffnessShape(bad, &s)) << bad;
  }
  // Table basis: periodic hats summing to one, interpolating the nodes.
  ASSERT_TRUE(gd::parseStiffnessShape("table:4", &s));
  double b[4];
  s.basis(0.25, b);
  EXPECT_DOUBLE_EQ(b[1], 1.0);
  s.basis(0.875, b);  // between node 3 (0.75) and node 0 (1.0 = 0.0)
  EXPECT_DOUBLE_EQ(b[3], 0.5);
  EXPECT_DOUBLE_EQ(b[0], 0.5);
  s.basis(-0.125, b);  // the same phase one cycle earlier
  EXPECT_DOUBLE_EQ(b[3], 0.5);
  IdentificationOptions o;
  o.stiffness_shape.kind = StiffnessShape::Kind::Table;
  o.stiffness_shape.n = 99;
  EXPECT_NE(o.check().message().find("stiffness_shape"), std::string::npos);
}

}  // namespace
