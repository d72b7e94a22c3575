// Quality flags (issue 13): every estimate is right within its standard error or visibly
// flagged. Cases simulated with parameters of our own, each with a held-out variant:
//  - the Table 1 case (square stiffness, sine load, load-dependent damping) stays clean: the
//    false-flag rate over noise seeds is measured and bounded;
//  - greybox (square-wave stiffness levels) on a stiffness it cannot represent (trapezoid,
//    Fourier) is flagged in every segment;
//  - a free transient that sinks under the noise (constant stiffness and load) gives segments
//    that are not identifiable once the transient is below the noise;
//  - in every case no clean identifiable segment is further than kCleanSE standard errors from
//    the truth;
//  - batch identify(), a segment identified as a record of its own (what a streamed block was) and
//    LiveIdentification flag each segment alike.
#include "gear_damping_id/quality_flags.hpp"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <iostream>
#include <map>
#include <set>

#include "gear_damping_id/live_identification.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/message_text.hpp"
#include "id_test_support.hpp"

namespace {

using namespace gear_id_test;
using gear_damping_id::SegmentEstimate;
namespace gd = gear_damping_id;
namespace qc = gear_damping_id::quality_code;

constexpr int kSeeds = 10;
// Flags on the home case (noise-free and white noise at 40 / 20 dB) must stay rare: measured
// 1 of 100 segments per formulation and SNR (a refined estimate 5 SE from its integral one).
// Allowed: 1 in 20, above which a flag would no longer single out a suspect estimate.
constexpr double kMaxFalseFlagRate = 0.05;
// A clean estimate with an honest standard error is within 4 SE of the truth except with
// probability 6e-5 per segment (normal); the truth of a segment is the time-mean of the true
// C(t) over it, which the piecewise model's estimate differs from by well under 1 SE here.
constexpr double kCleanSE = 4.0;
// Noise-free data carry the simulator's integration error, which no standard error describes:
// there a clean estimate is held to the method's noise-free accuracy bar instead (the known
// formulation's 0.05 %, identification_accuracy_test).
constexpr double kNoiseFreeRel = 5e-4;

struct Tally {
  int segments = 0, flagged = 0, not_identifiable = 0, clean_wrong = 0;
  std::map<std::string, int> codes;
  void add(const IdentificationResult& r, const SignalTable& t, const SimConfig& c) {
    for (const auto& s : r.segments) {
      ++segments;
      if (!s.identifiable) ++not_identifiable;
      if (!s.warnings.empty()) ++flagged;
      for (const auto& w : s.warnings) ++codes[w.code];
      if (s.identifiable && s.warnings.empty()) {
        const double truth = trueC(t, c, s.t_start, s.t_end);
        const bool ok =
            std::abs(s.C - truth) <= std::max(kCleanSE * s.C_std, kNoiseFreeRel * std::abs(truth));
        EXPECT_TRUE(ok) << "clean segment [" << s.t_start << ", " << s.t_end << "): C = " << s.C
                        << " +- " << s.C_std << ", truth " << truth;
        clean_wrong += !ok;
      }
    }
  }
  double flagRate() const { return segments > 0 ? double(flagged) / segments : 0.0; }
  std::string str() const {
    std::string o = std::to_string(flagged) + " of " + std::to_string(segments) + " flagged, " +
                    std::to_string(not_identifiable) + " not identifiable, " +
                    std::to_string(clean_wrong) + " clean but > 4 SE off;";
    for (const auto& [code, n] : codes) o += " " + code + ":" + std::to_string(n);
    return o;
  }
};

SignalTable noisy(const SignalTable& clean, double snr_db, unsigned long seed,
                  double* sigma = nullptr) {
  SignalTable t = clean;
  const double s = addWhiteNoise(&t.dte, snr_db, seed);
  if (sigma) *sigma = s;
  return t;
}

// Noise-free and noisy runs of `c` over seeds; returns the tally of the noisy runs.
Tally overSeeds(const SimConfig& c, const SignalTable& clean, Formulation f, double db, int seeds) {
  IdentificationOptions o;
  o.formulation = f;
  Tally t;
  for (int s = 1; s <= seeds; ++s) {
    const SignalTable n = noisy(clean, db, 700 + s);
    t.add(identifyOrFail(n, c, o), n, c);
  }
  std::cout << "[ measured ] " << gd::toString(f) << " " << db << " dB over " << seeds
            << " seeds: " << t.str() << "\n";
  return t;
}

// The tally of the noise-free record.
Tally noiseFree(const SimConfig& c, const SignalTable& clean, Formulation f,
                const std::string& label) {
  IdentificationOptions o;
  o.formulation = f;
  Tally t0;
  t0.add(identifyOrFail(clean, c, o), clean, c);
  std::cout << "[ measured ] " << label << " " << gd::toString(f) << " noise-free: " << t0.str()
            << "\n";
  return t0;
}

void expectHomeCaseClean(const SimConfig& c, const std::string& label) {
  const SignalTable clean = simulateOrFail(c);
  for (Formulation f : {Formulation::Known, Formulation::Greybox}) {
    const Tally t0 = noiseFree(c, clean, f, label);
    EXPECT_EQ(t0.flagged, 0) << label << " noise-free " << gd::toString(f) << ": " << t0.str();
    for (double db : {40.0, 20.0}) {
      const Tally t = overSeeds(c, clean, f, db, kSeeds);
      EXPECT_LE(t.flagRate(), kMaxFalseFlagRate) << label << " " << db << " dB: " << t.str();
      EXPECT_EQ(t.not_identifiable, 0) << label << " " << db << " dB: " << t.str();
    }
  }
}

// Piecewise-constant true damping aligned with the 1 ms segments, so that each segment has one
// true C (with a load-dependent truth the segment's C(t) varies within it).
SimConfig piecewise(SimConfig c) {
  setPiecewiseTruth(&c, 1e-3);
  return c;
}

TEST(QualityFlags, Table1CaseStaysClean) {
  expectHomeCaseClean(piecewise(table1Config()), "table1");
}

// The text of the run warning `code`, or "" when the result does not carry it.
std::string warningText(const IdentificationResult& r, const std::string& code) {
  for (const auto& w : r.warnings)
    if (w.code == code) return w.text;
  return "";
}

// The integral method's standard errors leave out the noise inside the integrals: on noisy data
// they understate the scatter, and a run reporting them says so (run code integral_std); the
// refined run's standard errors are calibrated (coverage tests) and carry no such warning. A
// noise-free integral run carries it too, worded for clean data (CleanDataAreRefined below).
// Piecewise-constant truth aligned to the segments, so the integral estimate's only error is
// the noise's; 20 seeds at 40 dB.
TEST(QualityFlags, IntegralStandardErrorsOfNoisyDataAreFlagged) {
  SimConfig c = table1Config();
  setPiecewiseTruth(&c, 1e-3);
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions never, automatic;
  never.refine = IdentificationOptions::Refine::Never;
  EXPECT_NE(warningText(identifyOrFail(clean, c, never), qc::kIntegralStd).find("clean data"),
            std::string::npos);
  int covered = 0, n = 0;
  for (unsigned long seed = 1; seed <= 20; ++seed) {
    SignalTable t = clean;
    addWhiteNoise(&t.dte, 40.0, seed);
    const IdentificationResult r = identifyOrFail(t, c, never);
    EXPECT_NE(warningText(r, qc::kIntegralStd).find("noisy data"), std::string::npos)
        << "seed " << seed;
    for (const SegmentEstimate& e : r.segments) {
      if (!e.identifiable) continue;
      covered += std::abs(e.C - trueC(t, c, e.t_start, e.t_end)) <= 2.0 * e.C_std ? 1 : 0;
      ++n;
    }
    EXPECT_FALSE(gd::hasCode(identifyOrFail(t, c, automatic).warnings, qc::kIntegralStd))
        << "seed " << seed;
  }
  ASSERT_GT(n, 150);
  const double coverage = static_cast<double>(covered) / n;
  std::cout << "[ measured ] integral estimates at 40 dB, " << n << " segments: +-2 C_std covers "
            << coverage * 100 << " % (flagged integral_std)\n";
  EXPECT_LT(coverage, 0.9);  // the understatement the warning states (95 % if calibrated)
}

// Clean data are refined too (--refine auto). On them the integral equations' residual is
// quadrature error, so the integral C_std leave out the method's discretisation error and, with
// a load varying within a segment, the gap between the integral fit's sensitivity-weighted mean
// of C(t) and the damping at the mean load. Held-out case from a random sweep (another gear,
// contact ratio 1.89, 1 MHz, a slow sine load, strongly load-dependent damping), noise-free:
// there the integral estimates (what auto reported before 2026-11-27) were up to 0.7 % and
// 40 C_std from the truth, unflagged; refined, every clean segment is within the tally's
// bounds (4 SE, or the 0.05 % noise-free bar) and the rest are flagged.
TEST(QualityFlags, CleanDataAreRefined) {
  SimConfig c = table1Config();
  c.gears.pinion = {22, 6e-4, 0.063};
  c.gears.gear = {40, 0.0185, 0.115};
  c.mesh.k_max = 7.0e8;
  c.mesh.k_min = 4.5e8;
  c.mesh.contact_ratio = 1.89;
  c.mesh.initial_phase = 0.52;
  c.speed.pinion_rpm = 3742.0;
  c.load.mean = 250.0;
  c.load.amplitude = 90.0;
  c.load.frequency = 15.7;
  c.damping.ratio = 0.058;
  c.damping.load_sensitivity = 0.93;
  c.simulation.sample_rate = 1e6;
  c.simulation.duration = 0.012;
  const SignalTable clean = simulateOrFail(c);
  const IdentificationResult refined = identifyOrFail(clean, c, IdentificationOptions{});
  EXPECT_FALSE(gd::hasCode(refined.warnings, qc::kIntegralStd));
  Tally t;
  t.add(refined, clean, c);
  for (const auto& s : refined.segments) EXPECT_TRUE(s.refined) << s.t_start;
  EXPECT_EQ(t.clean_wrong, 0) << t.str();
  IdentificationOptions never;
  never.refine = IdentificationOptions::Refine::Never;
  const IdentificationResult integral = identifyOrFail(clean, c, never);
  EXPECT_NE(warningText(integral, qc::kIntegralStd).find("clean data"), std::string::npos);
  int wrong = 0;
  double worst = 0.0;
  for (const auto& s : integral.segments) {
    const double truth = trueC(clean, c, s.t_start, s.t_end), err = std::abs(s.C - truth);
    wrong += s.warnings.empty() && err > std::max(kCleanSE * s.C_std, kNoiseFreeRel * truth);
    worst = std::max(worst, err / truth);
  }
  std::cout << "[ measured ] clean held-out case: refined " << t.str()
            << " integral estimates: " << wrong << " of " << integral.segments.size()
            << " segments unflagged beyond 4 SE and 0.05 %, worst " << worst * 100 << " %\n";
  EXPECT_GT(wrong, 0);  // what the integral_std warning is for
}

// Held-out: another gear, speed, load, sample rate. Its refined estimates can be wrong by many
// SE (the refinement's forward model; issue 13 deliverable 1): those must be flagged, which the
// tally's clean-but-wrong check asserts; the false-flag rate is only reported here.
TEST(QualityFlags, HeldOutCaseIsRightOrFlagged) {
  const SimConfig c = piecewise(heldOutCase());
  const SignalTable clean = simulateOrFail(c);
  for (Formulation f : {Formulation::Known, Formulation::Greybox}) {
    noiseFree(c, clean, f, "held-out");
    overSeeds(c, clean, f, 40.0, kSeeds);
  }
}

// Greybox with square-wave levels on a stiffness shape it cannot represent.
void expectGreyboxFlagged(const SimConfig& c, const std::string& label) {
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  for (double db : {std::numeric_limits<double>::infinity(), 40.0}) {
    const SignalTable t = std::isfinite(db) ? noisy(clean, db, 11) : clean;
    const IdentificationResult r = identifyOrFail(t, c, o);
    Tally tally;
    tally.add(r, t, c);
    std::cout << "[ measured ] greybox on " << label << " at " << db << " dB: " << tally.str()
              << "\n";
    for (const auto& s : r.segments) {
      EXPECT_TRUE(!s.identifiable || !s.warnings.empty())
          << label << " " << db << " dB segment at " << s.t_start << ": C = " << s.C
          << " reported clean";
    }
    // The cause named: most segments say the model does not reproduce the data.
    EXPECT_GE(2 * tally.codes[qc::kModelMismatch], tally.segments) << label << " " << db;
  }
}

TEST(QualityFlags, GreyboxOnTrapezoidStiffnessIsFlagged) {
  SimConfig c = table1Config();
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = 0.12;
  expectGreyboxFlagged(c, "trapezoid (12 % transitions)");
  SimConfig h = heldOutCase();
  h.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  h.mesh.transition_fraction = 0.07;
  expectGreyboxFlagged(h, "held-out trapezoid (7 % transitions)");
}

// Greybox square levels on a trapezoid that the residual alone does not show (a held-out case of
// a random sweep, 2026-11-27: 34/74 teeth at 1360 rpm, so a mesh cycle outlasts a 1 ms segment;
// 6 % ramps; 30 dB): there C came out 1.3-3.7x the truth and 4-5 C_std off with no flag
// (model_mismatch needs a residual 5x the noise estimate, which coloured noise can give a right
// model; here it was 1-5x). The shape test's score (SegmentEstimate::shape_z) flags them. A
// statistical test misses some: over the sweep's 120 trapezoid cases it flagged 162 of the 163
// segments that were clean and > 4 C_std off before it. Here: of 3 seeds x 12 segments, the
// segments that only shape_mismatch flags and that are > 4 C_std off (what was reported clean
// before) must be many, those left clean and > 4 C_std off at most 1.
// A slow mesh on a trapezoid stiffness with 6 % ramps (the shape tests' case; constant damping
// ratio 0.0612, 500 kHz, 12 ms).
SimConfig slowTrapezoidCase() {
  SimConfig c = table1Config();
  c.gears.pinion = {34, 9.44e-4, 0.0585};
  c.gears.gear = {74, 9.49e-3, 0.1273};
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.k_max = 6.465e8;
  c.mesh.k_min = 3.796e8;
  c.mesh.contact_ratio = 1.3385;
  c.mesh.initial_phase = 0.356;
  c.mesh.transition_fraction = 0.0611;
  c.speed.pinion_rpm = 1360.0;
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  c.damping.ratio = 0.0612;
  c.simulation.sample_rate = 5e5;
  c.simulation.duration = 0.012;
  return c;
}

TEST(QualityFlags, GreyboxOnSlowTrapezoidIsFlaggedByTheShapeTest) {
  SimConfig c = slowTrapezoidCase();
  setStepLoad(&c, 83.5, 66.6, 0.0197);
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  int identifiable = 0, shape_flagged = 0, caught = 0, missed = 0;
  for (unsigned long seed : {21, 22, 23}) {
    const SignalTable t = noisy(clean, 30.0, seed);
    for (const auto& s : identifyOrFail(t, c, o).segments) {
      if (!s.identifiable) continue;
      ++identifiable;
      const bool shape = gd::hasCode(s.warnings, qc::kShapeMismatch);
      shape_flagged += shape ? 1 : 0;
      const double truth = trueC(t, c, s.t_start, s.t_end);
      const bool wrong = std::abs(s.C - truth) > kCleanSE * s.C_std;
      caught += wrong && shape && s.warnings.size() == 1 ? 1 : 0;
      missed += wrong && s.warnings.empty() ? 1 : 0;
    }
  }
  std::cout << "[ measured ] greybox on a slow 6 % trapezoid at 30 dB: " << identifiable
            << " identifiable segments, " << shape_flagged << " flagged shape_mismatch, " << caught
            << " > 4 C_std off flagged by it alone, " << missed << " clean and > 4 C_std off\n";
  EXPECT_GE(caught, 5);
  EXPECT_LE(missed, 1);
  EXPECT_GE(2 * shape_flagged, identifiable);
}

// The shape test's score is N(0, 1) where the stiffness does switch at once: on the Table 1 case
// (square stiffness; noise-free, no segment flagged) with white noise at 30 dB, AR(1) noise of
// rho 0.9 (which the refinement's AR model whitens) and white noise with 1 N*m of torque-meter
// noise (before the score's variance carried it: rms 1.5-2.0), 20 seeds each. The rms of n standard
// normal scores lies within 1 +- 3 / sqrt(2 n) (3 sigma); |z| > 3 has probability 0.27 %, so at
// most a few segments of each set are flagged shape_mismatch (Poisson mean n * 0.0027; 6 or more
// has probability < 1e-3 for n = 200).
TEST(QualityFlags, ShapeScoreIsStandardNormalOnSquareStiffness) {
  const SimConfig c = table1Config();
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  // Noise-free the residual is deterministic (discretisations, the load-dependent damping's
  // nonlinear part), the score large (3-8 on every segment of this record), and C right far
  // within the noise-free bar: not flagged, because the fitted ramp moves C by < 0.05 %.
  for (const auto& s : identifyOrFail(clean, c, o).segments) {
    EXPECT_FALSE(gd::hasCode(s.warnings, qc::kShapeMismatch))
        << "noise-free segment at " << s.t_start << ": shape_z " << s.shape_z << ", shift "
        << s.shape_shift;
  }
  // rho: AR(1) noise of that lag-1 correlation (0: white); torque: white torque-meter noise
  // [N*m], which the score's variance carries as C_std does (C_torque_std ~ C_std at 1 N*m).
  for (const auto& [rho, torque] : {std::pair{0.0, 0.0}, {0.9, 0.0}, {0.0, 1.0}}) {
    double sum2 = 0.0;
    int n = 0, flagged = 0;
    for (unsigned long seed = 1; seed <= 20; ++seed) {
      SignalTable t = clean;
      if (rho == 0.0) {
        addWhiteNoise(&t.dte, 30.0, 900 + seed);
      } else {
        addAr1Noise(&t.dte, 30.0, rho, 900 + seed);
      }
      if (torque > 0.0) addTorqueNoise(&t.torque, torque, 950 + seed);
      for (const auto& s : identifyOrFail(t, c, o).segments) {
        if (!s.identifiable || !std::isfinite(s.shape_z)) continue;
        sum2 += s.shape_z * s.shape_z;
        ++n;
        flagged += gd::hasCode(s.warnings, qc::kShapeMismatch) ? 1 : 0;
      }
    }
    ASSERT_GT(n, 150) << rho;
    const double rms = std::sqrt(sum2 / n);
    std::cout << "[ measured ] shape score on square stiffness, 30 dB, AR(1) rho " << rho
              << ", torque noise " << torque << " N*m: " << n << " segments, rms " << rms << ", "
              << flagged << " flagged shape_mismatch\n";
    EXPECT_NEAR(rms, 1.0, 3.0 / std::sqrt(2.0 * n)) << rho << " " << torque;
    EXPECT_LE(flagged, 5) << rho << " " << torque;
  }
}

// The record's segments together (QualityLimits::kShapePooledZ). A ramp about a natural period
// wide (the Table 1 gear with 10 % transitions, constant damping, 30 dB; a hostile test of
// 2026-11-27) scores only 2-3 in each segment, below the segment test's 3, while C comes out up
// to 8x the truth: 122 of 308 segments were clean and > 4 C_std off over 20 seeds. Pooled over a
// record of 50 segments the scores give 17-21 (20 seeds); every segment whose fitted ramp moves C
// is then flagged and the run says why. Here, 2 seeds: no segment is left clean and > 4 C_std off,
// and the run carries shape_mismatch.
TEST(QualityFlags, PooledShapeScoreFlagsARampTheSegmentsSeeWeakly) {
  SimConfig c = table1Config();
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = 0.1;
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  c.simulation.duration = 0.05;
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  int identifiable = 0, weak = 0, wrong = 0, missed = 0;
  for (unsigned long seed : {31, 32}) {
    const SignalTable t = noisy(clean, 30.0, seed);
    const IdentificationResult r = identifyOrFail(t, c, o);
    EXPECT_TRUE(gd::hasCode(r.warnings, qc::kShapeMismatch)) << seed;
    for (const auto& s : r.segments) {
      if (!s.identifiable) continue;
      ++identifiable;
      weak += std::abs(s.shape_z) <= gd::QualityLimits::kShapeZ ? 1 : 0;
      const double truth = trueC(t, c, s.t_start, s.t_end);
      const bool off = std::abs(s.C - truth) > kCleanSE * s.C_std;
      wrong += off ? 1 : 0;
      missed += off && s.warnings.empty() ? 1 : 0;
    }
  }
  std::cout << "[ measured ] greybox on a 10 % trapezoid at 30 dB: " << identifiable
            << " identifiable segments, " << weak << " with |shape_z| <= 3, " << wrong
            << " > 4 C_std off, " << missed << " of them clean\n";
  EXPECT_GE(weak, identifiable / 4);  // the case the segment test alone misses
  EXPECT_GE(wrong, identifiable / 4);
  EXPECT_EQ(missed, 0);
}

// The pooled rule itself, on estimates made up to isolate it: n segments scoring z each pool to
// z sqrt(n); beyond kShapePooledZ the segments whose ramp moves C by more than kShapeShift are
// flagged (not the others), the run carries the code once, and applying the flags again changes
// nothing. Scores of both signs that cancel, or one segment alone, add nothing.
TEST(QualityFlags, PooledShapeRuleFlagsOnlySegmentsWhoseRampMovesC) {
  auto record = [](const std::vector<double>& z, const std::vector<double>& shift) {
    IdentificationResult r;
    for (size_t i = 0; i < z.size(); ++i) {
      SegmentEstimate e;
      e.identifiable = e.refined = true;
      e.C = 1000.0, e.C_std = 1.0, e.xi = 0.05, e.samples = 1000;
      e.signal_std = 1e-6, e.residuals.rms = 1e-8, e.noise_std = 1e-8, e.residual_rms = 1e-8;
      e.residuals.whitened_lag1 = 0.0;
      e.shape_z = z[i], e.shape_shift = shift[i];
      r.segments.push_back(e);
    }
    return r;
  };
  const IdentificationOptions o;
  // 10 segments at 2.5: pooled 7.9; shifts above and below the bar alternate.
  std::vector<double> z(10, 2.5), shift(10);
  for (size_t i = 0; i < shift.size(); ++i) shift[i] = i % 2 ? 1e-3 : -1e-4;
  IdentificationResult r = record(z, shift);
  gd::applyQualityFlags(o, &r);
  for (int pass = 0; pass < 2; ++pass) {
    for (size_t i = 0; i < r.segments.size(); ++i) {
      EXPECT_EQ(gd::hasCode(r.segments[i].warnings, qc::kShapeMismatch), i % 2 == 1) << i;
      EXPECT_LE(r.segments[i].warnings.size(), 1u) << i;
    }
    ASSERT_EQ(r.warnings.size(), 1u) << pass;
    EXPECT_EQ(r.warnings[0].code, qc::kShapeMismatch);
    gd::applyQualityFlags(o, &r);  // idempotent
  }
  // Just below the limit: 10 segments at 1.2 pool to 3.79.
  r = record(std::vector<double>(10, 1.2), std::vector<double>(10, 1e-3));
  gd::applyQualityFlags(o, &r);
  EXPECT_TRUE(r.warnings.empty());
  for (const auto& s : r.segments) EXPECT_TRUE(s.warnings.empty());
  // Cancelling signs; a single segment (its own test: 2.5 < kShapeZ).
  for (const auto& zz : {std::vector<double>{2.5, -2.5, 2.5, -2.5}, std::vector<double>{2.5}}) {
    r = record(zz, std::vector<double>(zz.size(), 1e-3));
    gd::applyQualityFlags(o, &r);
    EXPECT_TRUE(r.warnings.empty()) << zz.size();
    for (const auto& s : r.segments) EXPECT_TRUE(s.warnings.empty()) << zz.size();
  }
}

// Greybox square levels on short ramps (a trapezoid of 3 % transitions, constant damping) with
// 1 N*m of torque-meter noise at 30 dB: C_torque_std is most of C_std there, which kept the
// shape test from being judged while its variance left the torque noise out (500 segments: 13
// flagged shape_mismatch, 164 clean and > 4 C_std off). Now the score carries the torque noise and
// is judged: no segment clean and > 4 C_std off, and most flagged (measured 492 of 500).
TEST(QualityFlags, GreyboxOnShortRampsWithTorqueNoiseIsFlagged) {
  SimConfig c = table1Config();
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = 0.03;
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  int identifiable = 0, shape_flagged = 0, clean_far = 0;
  double share = 0.0;
  for (unsigned long seed : {31, 32, 33}) {
    SignalTable t = noisy(clean, 30.0, seed);
    addTorqueNoise(&t.torque, 1.0, seed + 100);
    for (const auto& s : identifyOrFail(t, c, o).segments) {
      if (!s.identifiable) continue;
      ++identifiable;
      shape_flagged += gd::hasCode(s.warnings, qc::kShapeMismatch) ? 1 : 0;
      const double truth = trueC(t, c, s.t_start, s.t_end);
      clean_far += s.warnings.empty() && std::abs(s.C - truth) > kCleanSE * s.C_std ? 1 : 0;
      share = std::max(share, s.C_torque_std / s.C_std);
    }
  }
  std::cout << "[ measured ] greybox on a 3 % trapezoid, 30 dB, 1 N*m torque noise: "
            << identifiable << " identifiable segments, " << shape_flagged
            << " flagged shape_mismatch, " << clean_far << " clean and > 4 C_std off; largest "
            << "C_torque_std / C_std " << share << "\n";
  EXPECT_GT(share, 0.5);  // the case the gate excluded
  EXPECT_EQ(clean_far, 0);
  EXPECT_GE(2 * shape_flagged, identifiable);
}

TEST(QualityFlags, GreyboxOnFourierStiffnessIsFlagged) {
  SimConfig c = table1Config();
  c.mesh.model = gear_sim::StiffnessModel::Fourier;
  c.mesh.k_mean = 3.0e8;
  c.mesh.fourier_cos = {6.0e7, -1.5e7};
  c.mesh.fourier_sin = {2.0e7, 1.0e7};
  expectGreyboxFlagged(c, "fourier (2 harmonics)");
  SimConfig h = heldOutCase();
  h.mesh.model = gear_sim::StiffnessModel::Fourier;
  h.mesh.k_mean = 2.6e8;
  h.mesh.fourier_cos = {4.0e7, 0.0, 8.0e6};
  h.mesh.fourier_sin = {-3.0e7, 1.2e7, 0.0};
  expectGreyboxFlagged(h, "held-out fourier (3 harmonics)");
}

// Greybox square levels on a Fourier stiffness, slow and at 250 kHz (a held-out case of a random
// sweep, 2026-11-27): the refined model's damping comes out far below zero, its response grows by
// up to ~1e13 over a segment, and the covariance at that estimate underflowed, so segments were
// reported refined with C_std = 0 (or null) and k_min_std / k_max_std = 0: exact-looking numbers.
// Now such a refinement counts as failed (refine_failed, integral estimate kept) and every
// identifiable segment has positive finite standard errors; the segments stay flagged.
TEST(QualityFlags, DivergingRefinementKeepsPositiveStandardErrors) {
  SimConfig c = table1Config();
  c.gears.pinion = {17, 3.37e-4, 0.0590};
  c.gears.gear = {27, 0.01505, 0.0937};
  c.mesh.model = gear_sim::StiffnessModel::Fourier;
  c.mesh.contact_ratio = 1.208;
  c.mesh.initial_phase = 0.627;
  c.mesh.k_mean = 2.935e8;
  c.mesh.fourier_cos = {2.92e7, 1.14e7};
  c.mesh.fourier_sin = {5.1e6, 0.0};
  c.speed.pinion_rpm = 3696.0;
  setRampLoad(&c, 213.3, 161.6, 0.05);
  c.damping.ratio = 0.0532;
  c.damping.load_sensitivity = 0.80;
  c.simulation.sample_rate = 2.5e5;
  c.simulation.duration = 0.012;
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.formulation = Formulation::Greybox;
  int identifiable = 0, failed = 0;
  for (unsigned long seed : {3, 4}) {
    const IdentificationResult r = identifyOrFail(noisy(clean, 30.0, seed), c, o);
    for (const auto& s : r.segments) {
      if (!s.identifiable) continue;
      ++identifiable;
      failed += s.refined ? 0 : 1;
      EXPECT_TRUE(s.C_std > 0.0 && std::isfinite(s.C_std)) << seed << " " << s.t_start;
      EXPECT_TRUE(s.k_min_std > 0.0 && std::isfinite(s.k_min_std)) << seed << " " << s.t_start;
      EXPECT_TRUE(s.k_max_std > 0.0 && std::isfinite(s.k_max_std)) << seed << " " << s.t_start;
      EXPECT_FALSE(s.warnings.empty()) << seed << " " << s.t_start << ": C = " << s.C;
    }
    if (failed > 0) {
      EXPECT_TRUE(gd::hasCode(r.warnings, qc::kRefineFailed)) << seed;
    }
  }
  std::cout << "[ measured ] greybox on a slow Fourier-stiffness case at 30 dB: " << identifiable
            << " identifiable segments, " << failed << " with the refinement failed\n";
  EXPECT_GT(failed, 0);  // the case still reaches the diverging refinement
}

// A free transient (constant stiffness and load, start from rest away from the static
// deflection) that decays below white noise: once the envelope is below the noise, a segment is
// not identifiable or flagged (a pure-noise segment passes the 5 % significance test one time
// in 20; then C <= 0, xi >= 1 or the SE itself tell); every clean one is within kCleanSE.
void expectTransientHandled(const SimConfig& c, double db, const std::string& label) {
  const SignalTable clean = simulateOrFail(c);
  const double me = c.gears.equivalentMass();
  const double C = c.damping.ratio * 2.0 * std::sqrt(c.mesh.k_mean / me);
  const double static_dte = clean.dte[clean.size() - 1];  // settled
  Tally tally;
  int below = 0, clean_below = 0;
  for (int seed = 1; seed <= 5; ++seed) {
    double sigma = 0.0;
    const SignalTable t = noisy(clean, db, 40 + seed, &sigma);
    const IdentificationResult r = identifyOrFail(t, c, IdentificationOptions());
    tally.add(r, t, c);
    for (const auto& s : r.segments) {
      // Transient amplitude at the segment start (from rest: A0 = static deflection).
      const double envelope = std::abs(static_dte) * std::exp(-0.5 * C * s.t_start);
      if (envelope < sigma) {
        ++below;
        clean_below += s.identifiable && s.warnings.empty();
        EXPECT_TRUE(!s.identifiable || !s.warnings.empty())
            << label << " seed " << seed << " segment at " << s.t_start << ": transient "
            << envelope / sigma << " x noise, C = " << s.C << " +- " << s.C_std;
      }
    }
  }
  std::cout << "[ measured ] transient " << label << ": " << tally.str() << "; " << below
            << " segments below the noise, " << clean_below << " of them reported clean\n";
  EXPECT_GT(tally.codes[qc::kBelowNoise], 0) << label;
}

// `base` with constant stiffness k [N/m], constant load T [N*m] and damping ratio xi.
SimConfig transientCase(SimConfig base, double k, double T, double xi) {
  base.mesh.model = gear_sim::StiffnessModel::Constant;
  base.mesh.k_mean = k;
  base.load.profile = gear_sim::LoadProfile::Constant;
  base.load.mean = T;
  base.damping.model = gear_sim::DampingProfile::ConstantRatio;
  base.damping.ratio = xi;
  return base;
}

TEST(QualityFlags, TransientSinkingUnderNoiseIsNotIdentifiable) {
  expectTransientHandled(transientCase(table1Config(), 3.2e8, 100.0, 0.05), 40.0, "xi 0.05, 40 dB");
  // Held-out: other gear, stiffness, load, damping, sample rate and SNR.
  expectTransientHandled(transientCase(heldOutCase(), 2.5e8, 60.0, 0.08), 30.0,
                         "held-out xi 0.08, 30 dB");
}

// The sub-table of samples [b, e).
SignalTable slice(const SignalTable& t, Eigen::Index b, Eigen::Index e) {
  SignalTable s;
  auto cut = [&](const Eigen::VectorXd& v) {
    return v.size() > 0 ? Eigen::VectorXd(v.segment(b, e - b)) : Eigen::VectorXd();
  };
  s.time = cut(t.time), s.dte = cut(t.dte), s.stiffness = cut(t.stiffness);
  s.torque = cut(t.torque), s.mesh_state = cut(t.mesh_state), s.mesh_phase = cut(t.mesh_phase);
  s.damping = cut(t.damping);
  return s;
}

std::set<std::string> codesOf(const SegmentEstimate& s) {
  std::set<std::string> o;
  for (const auto& w : s.warnings) o.insert(w.code);
  return o;
}

// Batch, a segment as a record of its own, and live flags agree per segment.
// Without refinement, so that every path has the same estimates: the refinement iterates all
// segments of a batch together (one convergence test, one step length) and a streamed or live
// segment alone, so a poorly determined segment's refined numbers differ between the paths.
void expectPathsAgree(const SimConfig& c, Formulation f, double db) {
  const SignalTable t = noisy(simulateOrFail(c), db, 5);
  const gd::GearConstants gear = gd::gearConstants(c.gearModel());
  IdentificationOptions o;
  o.formulation = f;
  o.refine = IdentificationOptions::Refine::Never;
  const IdentificationResult batch = identifyOrFail(t, c, o);
  const gd::SignalView view = gd::SignalView::of(t);
  IdentificationOptions ow = o;
  ow.window_length = gd::defaultWindowLength(view, gear);
  const auto ranges = gd::segmentRanges(view, ow);
  ASSERT_EQ(ranges.size(), batch.segments.size());
  gd::LiveIdentification live(ow, gear);
  int flagged = 0;
  for (size_t i = 0; i < ranges.size(); ++i) {
    const auto [b, e] = ranges[i];
    const SegmentEstimate live_est = live.add(view, b, e).estimate;
    IdentificationOptions os = ow;
    os.segment_length = std::numeric_limits<double>::infinity();
    const IdentificationResult streamed = identifyOrFail(slice(t, b, e), c, os);
    ASSERT_EQ(streamed.segments.size(), 1u);
    const SegmentEstimate& a = batch.segments[i];
    flagged += !a.warnings.empty() || !a.identifiable;
    EXPECT_EQ(a.identifiable, live_est.identifiable) << "segment " << i;
    EXPECT_EQ(a.identifiable, streamed.segments[0].identifiable) << "segment " << i;
    EXPECT_EQ(codesOf(a), codesOf(live_est))
        << "segment " << i << ": batch [" << gd::joinCodes(a.warnings) << "] live ["
        << gd::joinCodes(live_est.warnings) << "]";
    EXPECT_EQ(codesOf(a), codesOf(streamed.segments[0]))
        << "segment " << i << ": batch [" << gd::joinCodes(a.warnings) << "] streamed ["
        << gd::joinCodes(streamed.segments[0].warnings) << "]";
  }
  EXPECT_GT(flagged, 0) << "the case must exercise the flags";
}

TEST(QualityFlags, BatchStreamedAndLiveAgree) {
  expectPathsAgree(transientCase(table1Config(), 3.2e8, 100.0, 0.05), Formulation::Known,
                   40.0);  // below_noise
  SimConfig tz = table1Config();
  tz.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  tz.mesh.transition_fraction = 0.1;
  expectPathsAgree(tz, Formulation::Greybox, 40.0);  // model_mismatch
}

// The flags are idempotent and re-derived from the numbers: a negative or overdamped estimate
// is flagged, a clean one is left alone.
TEST(QualityFlags, PhysicalRangeFlags) {
  IdentificationResult r;
  SegmentEstimate e;
  e.identifiable = true;
  e.C = 6000.0, e.C_std = 10.0, e.xi = 0.05;
  r.segments = {e, e, e};
  r.segments[1].C = -500.0, r.segments[1].xi = -0.004;
  r.segments[2].C = 2.0e5, r.segments[2].xi = 1.6, r.segments[2].C_std = 100.0;
  for (int pass = 0; pass < 2; ++pass) {
    gd::applyQualityFlags(IdentificationOptions(), &r);
    EXPECT_TRUE(r.segments[0].warnings.empty());
    EXPECT_EQ(gd::joinCodes(r.segments[1].warnings), qc::kNonpositiveDamping);
    EXPECT_EQ(gd::joinCodes(r.segments[2].warnings), qc::kOverdamped);
  }
  // Relative SE at the 5 % significance limit: 0.50 passes, 0.52 is below the noise.
  r.segments[0].C_std = 0.50 * r.segments[0].C;
  gd::applyQualityFlags(IdentificationOptions(), &r);
  EXPECT_TRUE(r.segments[0].identifiable);
  r.segments[0].C_std = 0.52 * r.segments[0].C;
  gd::applyQualityFlags(IdentificationOptions(), &r);
  EXPECT_FALSE(r.segments[0].identifiable);
  EXPECT_TRUE(std::isnan(r.segments[0].C));
  EXPECT_EQ(gd::joinCodes(r.segments[0].warnings), qc::kBelowNoise);
}

// Issue 19 (b): the spans of a live record whose torque was paired without stamps (chunks marked
// by rig_frontend_node): adjacent chunks merge into one span, a segment overlapping a span gets
// torque_unstamped once (marking twice adds nothing), one outside it stays clean, a recomputation
// of the owned flags keeps it, and clear() forgets the spans.
TEST(QualityFlags, UnstampedTorqueSpansFlagTheirSegments) {
  gd::UnstampedTorqueSpans spans;
  const double dt = 1e-6;
  for (int k = 0; k < 5; ++k) spans.add(k * 1000 * dt, (k * 1000 + 999) * dt, 1.5 * dt);
  spans.add(0.010, 0.011, 1.5 * dt);  // a later, separate span
  gd::IdentificationResult r;
  const double edges[][2] = {{0.0, 0.001}, {0.004, 0.005}, {0.006, 0.007}, {0.0105, 0.0115}};
  for (const auto& e : edges) {
    SegmentEstimate s;
    s.t_start = e[0], s.t_end = e[1];
    s.identifiable = true, s.C = 5000.0, s.C_std = 10.0, s.xi = 0.05;
    r.segments.push_back(s);
  }
  spans.mark(&r);
  spans.mark(&r);
  const bool expected[] = {true, true, false, true};
  for (size_t i = 0; i < r.segments.size(); ++i) {
    EXPECT_EQ(gd::joinCodes(r.segments[i].warnings), expected[i] ? qc::kTorqueUnstamped : "") << i;
  }
  gd::applyQualityFlags(gd::IdentificationOptions(), &r);
  EXPECT_TRUE(gd::hasCode(r.segments[0].warnings, qc::kTorqueUnstamped));
  spans.clear();
  EXPECT_TRUE(spans.empty());
  SegmentEstimate later;
  later.t_start = 0.0, later.t_end = 0.001;
  spans.mark(&later);
  EXPECT_TRUE(later.warnings.empty());
}

// A record without mesh_phase: each switch is held to the sample where the new value is first
// seen. Where the switches fall between samples (the Table 1 gear at 3077 rpm, constant damping,
// 40 dB) that is half a sample late on average, which biased C by ~1.3 C_std (a hostile test of
// 2026-11-28: 20 seeds x 50 segments, rms (C - truth) / C_std 1.67 for `known`, 16 % of its 340
// clean segments beyond 1.96 C_std). The switch timing check must account for that bias: the
// run's mean error, in C_std, is the mean predicted one (every switch half a sample earlier)
// within its sampling scatter (4 / sqrt(n)) plus 0.3 C_std for the check's first order; the
// unflagged segments hold their C_std (at most one beyond 3 C_std, where 0.27 % are expected);
// the run says so. Where the switches lie on the samples (3000 rpm at 1 MHz) the held switches
// are exact: the segments' pooled scores put them there, and a segment is flagged only where its
// own score passes 3 (measured 2 of 500 segments; at most 3 of these 60, where 0.3 are expected
// and 3 has a chance of 3e-4 at 0.5 % per segment). With mesh_phase the check is not made.
TEST(QualityFlags, SwitchesBetweenSamplesWithoutMeshPhaseAreRightOrFlagged) {
  SimConfig c = table1Config();
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  c.simulation.duration = 0.02;
  for (const double rpm : {3077.0, 3000.0}) {
    const bool between = rpm != 3000.0;
    c.speed.pinion_rpm = rpm;
    c.mesh.initial_phase = between ? 0.00037 : 0.0;
    const SignalTable clean = simulateOrFail(c);
    for (Formulation f : {Formulation::Known, Formulation::Greybox}) {
      IdentificationOptions o;
      o.formulation = f;
      double err_sum = 0.0, pred_sum = 0.0;
      int n = 0, flagged = 0, clean_off3 = 0;
      for (unsigned long seed : {41, 42, 43}) {
        SignalTable t = noisy(clean, 40.0, seed);
        if (between) {
          for (const auto& s : identifyOrFail(t, c, o).segments) {
            EXPECT_TRUE(std::isnan(s.switch_timing_shift)) << seed;
            EXPECT_FALSE(gd::hasCode(s.warnings, qc::kSwitchTiming)) << seed;
          }
        }
        t.mesh_phase.resize(0);
        const IdentificationResult r = identifyOrFail(t, c, o);
        if (between) {
          EXPECT_TRUE(gd::hasCode(r.warnings, qc::kSwitchTiming)) << seed;
        }
        for (const auto& s : r.segments) {
          if (!s.identifiable) continue;
          const double z = (s.C - trueC(t, c, s.t_start, s.t_end)) / s.C_std;
          ASSERT_TRUE(std::isfinite(s.switch_timing_shift)) << seed << " " << s.t_start;
          err_sum += z, pred_sum += -s.switch_timing_shift * s.C / s.C_std, ++n;
          for (const auto& w : s.warnings) {
            if (w.code != qc::kSwitchTiming) continue;
            ++flagged;
            EXPECT_NE(w.text.find("mesh_phase"), std::string::npos);
          }
          if (s.warnings.empty() && std::abs(z) > 3.0) ++clean_off3;
        }
      }
      ASSERT_GE(n, 40);
      const double mean_err = err_sum / n, mean_pred = pred_sum / n;
      std::cout << "[ measured ] " << gd::toString(f) << " without mesh_phase at " << rpm
                << " rpm, 40 dB: " << n << " segments, mean error " << mean_err
                << " C_std (half a sample late: " << mean_pred << "), " << flagged
                << " flagged switch_timing, " << clean_off3 << " clean beyond 3 C_std\n";
      if (between) {
        EXPECT_GT(std::abs(mean_err), 0.5);  // the bias the case is about
        EXPECT_NEAR(mean_err, mean_pred, 4.0 / std::sqrt(double(n)) + 0.3);
      } else {
        EXPECT_LE(flagged, 3);  // measured 2 of 500 (the segments' own scores beyond 3)
        EXPECT_LT(std::abs(mean_err), 4.0 / std::sqrt(double(n)));
      }
      EXPECT_LE(clean_off3, 1);
    }
  }
}

// A shared damping is fitted to every segment, so one segment the model does not reproduce
// biases it for all. Held-out case 13139 (scripts/heldout_sweep.py --extras --check load_law,
// seed 13100 + 39): Fourier stiffness, 250 kHz, noise-free, load_linear damping under a load
// step at 10.80 ms, inside the segment [10, 11) ms. The piecewise fit is exact in every other
// segment (0.000 %) and flags that one model_mismatch; the load law was 1.8 % (10 standard
// errors) off at the high load and reported clean. Now its run carries model_mismatch naming the
// segment. With the step on a segment boundary (11 ms) the law is exact and the run clean.
TEST(QualityFlags, ASharedFitOverASegmentTheModelDoesNotReproduceIsFlagged) {
  const std::string yaml =
      R"(pinion: {teeth: 17, inertia: 0.0003927227136273641, base_radius: 0.0372990586305849}
gear: {teeth: 46, inertia: 0.017583170449531213, base_radius: 0.10092686452981796}
mesh:
  stiffness_model: fourier
  k_max: 521268318.9220197
  k_min: 226471471.38163254
  contact_ratio: 1.5561533408510413
  initial_phase: 0.6874291023468102
  k_mean: 373869895.15182614
  fourier_cos: [59338042.84032212, 34347008.01283242]
  fourier_sin: [2931005.1113376934, 0.0]
speed: {profile: ramp, pinion_rpm: 1361.912076502138, end_rpm: 1464.1916658100158, ramp_time: 0.05}
damping: {model: load_linear, c0: 195.38143949264582, c1: 2.75276372193115}
simulation: {duration: 0.05, sample_rate: 250000.0, integrator: rk4, substeps: 3}
)";
  for (const double step_time : {0.010804359325860591, 0.011}) {
    SCOPED_TRACE("load step at " + std::to_string(step_time) + " s");
    SimConfig c;
    std::string e;
    const std::string load =
        "load: {profile: step, initial: 382.43386818082587, final: "
        "514.2587549018868, step_time: " +
        gear_sim::formatNumber(step_time) + "}\n";
    ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfig(YAML::Load(yaml + load), &c), &e)) << e;
    const SignalTable t = simulateOrFail(c);
    IdentificationOptions o;
    o.model = gd::DampingModel::LoadLaw;
    const IdentificationResult r = identifyOrFail(t, c, o);
    ASSERT_TRUE(r.load_law && r.load_law->identifiable);
    double worst = 0.0;  // the law's error over the record's two loads
    for (double T : {c.load.initial, c.load.final_value}) {
      const double truth = c.damping.c0 + c.damping.c1 * T;
      worst = std::max(worst, std::abs(r.load_law->c0 + r.load_law->c1 * T - truth) / truth);
    }
    const bool flagged = gd::hasCode(r.warnings, qc::kModelMismatch);
    std::cout << "[ measured ] load law with the step at " << step_time << " s: error " << worst
              << ", run " << (flagged ? "flagged" : "clean") << "\n";
    EXPECT_TRUE(flagged || worst <= kNoiseFreeRel) << worst;
    if (step_time == 0.011) {
      EXPECT_LE(worst, kNoiseFreeRel);
      EXPECT_FALSE(flagged);
    } else {
      EXPECT_GT(worst, 10 * kNoiseFreeRel);  // the case this test is about
      EXPECT_TRUE(flagged);
    }
  }
}

// The shared-fit rule on results built by hand: only shared models, counted once however often
// the flags are applied, the constant estimate flagged too.
TEST(QualityFlags, SharedMismatchRuleAppliesToSharedModelsOnly) {
  IdentificationResult r;
  r.segments.resize(3);
  for (auto& e : r.segments) {
    e.identifiable = true;
    e.C = 100.0, e.C_std = 1.0, e.xi = 0.05;
  }
  r.segments[1].residual_rms = 1.0, r.segments[1].noise_std = 0.01, r.segments[1].signal_std = 2.0;
  gd::applyQualityFlags(IdentificationOptions{}, &r);
  ASSERT_TRUE(gd::hasCode(r.segments[1].warnings, qc::kModelMismatch));
  EXPECT_FALSE(gd::hasCode(r.warnings, qc::kModelMismatch));  // piecewise: that segment only
  r.constant = r.segments[0];
  gd::applyQualityFlags(IdentificationOptions{}, &r);
  gd::applyQualityFlags(IdentificationOptions{}, &r);
  int run = 0;
  for (const auto& w : r.warnings) run += w.code == qc::kModelMismatch ? 1 : 0;
  EXPECT_EQ(run, 1);
  EXPECT_TRUE(gd::hasCode(r.constant->warnings, qc::kModelMismatch));
  EXPECT_NE(r.warnings.front().text.find("1 of 3 segments"), std::string::npos)
      << r.warnings.front().text;
}

// The load law under a constant load: c1 is not identifiable; the reason says why (before, only
// "rank deficient or ill-conditioned (condition inf)", 5 of 40 held-out load_law records), and
// there is no refine_failed: nothing was there to refine.
TEST(QualityFlags, ALoadLawUnderAConstantLoadSaysWhyItIsNotIdentifiable) {
  SimConfig c = table1Config();
  c.load.profile = gear_sim::LoadProfile::Constant;
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  const SignalTable t = simulateOrFail(c);
  IdentificationOptions o;
  o.model = gd::DampingModel::LoadLaw;
  IdentificationResult r;
  gd::identify(t, gd::gearConstants(c.gearModel()), o, &r);
  ASSERT_TRUE(r.load_law);
  EXPECT_FALSE(r.load_law->identifiable);
  EXPECT_NE(r.load_law->reason.find("a load that varies"), std::string::npos) << r.load_law->reason;
  EXPECT_FALSE(gd::hasCode(r.warnings, qc::kRefineFailed));
}

// The square levels' shape test for a shared damping (constant model, load law) too: before,
// it ran for the piecewise model only, and a greybox load law on a trapezoid stiffness was 6.0
// and 4.4 standard errors off (c0, c1) without a warning (held-out seed 13618). On the slow
// trapezoid above (30 dB) both shared models' runs carry shape_mismatch; on the Table 1 case
// (square stiffness, the same noise) neither does, and the scores are N(0, 1) (pooled over the
// segments within 3 / sqrt(n) of 0 in mean).
TEST(QualityFlags, GreyboxSharedDampingOnATrapezoidIsFlaggedByTheShapeTest) {
  SimConfig trap = slowTrapezoidCase();  // (the Table 1 case's sine load)
  SimConfig square = table1Config();
  square.damping.model = gear_sim::DampingProfile::ConstantRatio;
  for (const auto model : {gd::DampingModel::Constant, gd::DampingModel::LoadLaw}) {
    for (const SimConfig* c : {&trap, &square}) {
      const bool ramps = c == &trap;
      const SignalTable t = noisy(simulateOrFail(*c), 30.0, 31);
      IdentificationOptions o;
      o.formulation = Formulation::Greybox;
      o.model = model;
      const IdentificationResult r = identifyOrFail(t, *c, o);
      double sum = 0.0;
      int n = 0;
      for (const auto& e : r.segments) {
        if (e.identifiable && std::isfinite(e.shape_z)) sum += e.shape_z, ++n;
      }
      const bool flagged = gd::hasCode(r.warnings, qc::kShapeMismatch);
      std::cout << "[ measured ] greybox " << gd::toString(model) << " on "
                << (ramps ? "a 6 % trapezoid" : "the square Table 1 stiffness")
                << " at 30 dB: " << n << " scores, mean " << (n > 0 ? sum / n : 0.0) << ", run "
                << (flagged ? "flagged" : "clean") << "\n";
      ASSERT_GE(n, 5);
      EXPECT_EQ(flagged, ramps);
      if (!ramps) {
        EXPECT_LT(std::abs(sum / n), 3.0 / std::sqrt(static_cast<double>(n)));
      }
    }
  }
}

}  // namespace
