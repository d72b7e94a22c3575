// Damping that varies with the load within a damping segment (issue 13, "right or flagged"):
// the piecewise model holds C constant in a segment, so where the true C(t) follows the load its
// estimate is a weighted mean of C(t), not the time mean the segment reports. The refinement
// tests the term C1 (T1 - mean T1) per segment (SegmentEstimate::variation_z) and flags
// `damping_varies` beyond QualityLimits::kVariationZ. Checked on simulated truth:
// - constant damping in every segment (piecewise truth aligned to the segments): the flag fires
//   at most at its nominal false-alarm rate (binomial bound over 30 seeds) and variation_z has
//   unit variance (chi-square bound), on trapezoid and Fourier stiffness, with white and with
//   AR(1) noise (rho 0.9);
// - the shipped load-dependent damping on trapezoid and Fourier stiffness at 40 dB over 30
//   seeds, and a held-out gear with other shapes, load and damping: every segment is right
//   (+-2 SE covers the time-mean truth in >= 90 % of the unflagged segments, none beyond
//   kCleanSE) or flagged.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <map>
#include <sstream>

#include "gear_damping_id/quality_flags.hpp"
#include "gear_sim/config_yaml.hpp"
#include "id_test_support.hpp"

namespace {

using namespace gear_id_test;
using gear_damping_id::DampingModel;
using gear_damping_id::QualityLimits;
using gear_damping_id::SegmentEstimate;
using gear_sim::StiffnessModel;
namespace qc = gear_damping_id::quality_code;

constexpr int kSeeds = 30;
constexpr double kSnrDb = 40.0;
// +-2 SE covers 95.4 % with an honest Gaussian SE; over >= 200 unflagged segments the binomial
// std of the coverage is <= 1.5 %, so an honest SE stays above 90 % with > 3 sigma margin.
constexpr double kMinCoverage = 0.90;
// No clean estimate beyond 4 SE (probability 6e-5 per segment for an honest SE).
constexpr double kCleanSE = 4.0;
// Constant damping: P(|z| > kVariationZ) = 2 (1 - Phi(kVariationZ)) per segment.
const double kNominalFalseAlarm = std::erfc(QualityLimits::kVariationZ / std::sqrt(2.0));
// Noise-free, the damping at the mean load against the time-mean truth: the method's noise-free
// accuracy bar (known formulation, piecewise C within 0.05 % of the truth). The constant-C fit
// misses it by 20-60x on these cases.
constexpr double kNoiseFreeMeanLoadTol = 5e-4;
// Probability of a false failure of the binomial and chi-square bounds below.
constexpr double kTestRisk = 1e-4;

// Smallest k with P(X > k) < kTestRisk for X ~ Binomial(n, p).
long binomialBound(long n, double p) {
  double pmf = std::pow(1.0 - p, static_cast<double>(n)), cdf = pmf;
  long k = 0;
  while (1.0 - cdf >= kTestRisk && k < n) {
    pmf *= static_cast<double>(n - k) / static_cast<double>(k + 1) * p / (1.0 - p);
    cdf += pmf;
    ++k;
  }
  return k;
}

SimConfig trapezoid(SimConfig c, double transition) {
  c.mesh.model = StiffnessModel::Trapezoid;
  c.mesh.transition_fraction = transition;
  return c;
}

SimConfig fourier(SimConfig c, double k_mean, std::vector<double> cos_h,
                  std::vector<double> sin_h) {
  c.mesh.model = StiffnessModel::Fourier;
  c.mesh.k_mean = k_mean;
  c.mesh.fourier_cos = std::move(cos_h);
  c.mesh.fourier_sin = std::move(sin_h);
  return c;
}

// The cases: the shipped Table 1 case (load-dependent damping) on smooth stiffness.
SimConfig table1Trapezoid() { return trapezoid(table1Config(), 0.12); }
SimConfig table1Fourier() {
  return fourier(table1Config(), 3.0e8, {6.0e7, -1.5e7}, {2.0e7, 1.0e7});
}
// Held out: another gear, speed, sample rate, load, stiffness shapes and a stronger damping law.
SimConfig heldOut(SimConfig c) {
  c.load.amplitude = 45.0;  // of 80 N*m
  c.load.frequency = 110.0;
  c.damping.ratio = 0.04;
  c.damping.load_sensitivity = 0.9;
  return c;
}

struct Score {
  long segments = 0, flagged = 0, varies = 0, covered = 0;
  long clean = 0, clean_covered = 0, clean_far = 0;
  long weighted = 0, weighted_covered = 0;  // the constant-C fit (the estimate before)
  double worst = 0.0, worst_clean = 0.0, worst_weighted = 0.0, sum_vz2 = 0.0, se_ratio = 0.0;
  long vz_count = 0;
  std::map<std::string, int> codes;

  void add(const IdentificationResult& r, const SignalTable& t, const SimConfig& c) {
    for (const SegmentEstimate& e : r.segments) {
      ++segments;
      if (!e.warnings.empty()) ++flagged;
      for (const auto& w : e.warnings) ++codes[w.code];
      varies += gear_damping_id::hasCode(e.warnings, qc::kDampingVaries);
      if (!e.identifiable) continue;
      const double truth = trueC(t, c, e.t_start, e.t_end);
      if (std::isfinite(e.variation_z)) {
        sum_vz2 += e.variation_z * e.variation_z, ++vz_count;
        const double zw = std::abs(e.C_weighted - truth) / e.C_weighted_std;
        ++weighted;
        weighted_covered += zw <= 2.0;
        worst_weighted = std::max(worst_weighted, zw);
        se_ratio += e.C_std / e.C_weighted_std;
      }
      const double z = std::abs(e.C - truth) / e.C_std;
      covered += z <= 2.0;
      worst = std::max(worst, z);
      if (e.warnings.empty()) {
        ++clean;
        clean_covered += z <= 2.0;
        clean_far += z > kCleanSE;
        worst_clean = std::max(worst_clean, z);
      }
    }
  }
  double coverage() const { return segments > 0 ? double(covered) / segments : 0.0; }
  double cleanCoverage() const { return clean > 0 ? double(clean_covered) / clean : 0.0; }
  std::string str() const {
    std::ostringstream o;
    o << segments << " segments: +-2 SE coverage " << 100.0 * coverage() << " % (worst " << worst
      << " SE); " << flagged << " flagged (" << varies << " damping_varies); clean " << clean
      << ": coverage " << 100.0 * cleanCoverage() << " % (worst " << worst_clean << " SE, "
      << clean_far << " beyond " << kCleanSE << " SE); constant-C fit (before): coverage "
      << 100.0 * weighted_covered / std::max(weighted, 1L) << " % of " << weighted << " (worst "
      << worst_weighted << " SE); SE / constant-C SE " << se_ratio / std::max(vz_count, 1L)
      << "; rms variation_z " << std::sqrt(sum_vz2 / std::max(vz_count, 1L)) << "; codes";
    for (const auto& [code, n] : codes) o << " " << code << ":" << n;
    return o.str();
  }
};

// `rho` > 0: AR(1) noise of that lag-1 correlation instead of white noise; `torque_sd` > 0: white
// torque-meter noise of that standard deviation [N*m] on the torque column.
Score overSeeds(const SimConfig& c, const std::string& label, unsigned long seed0, double rho = 0.0,
                double torque_sd = 0.0) {
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;  // defaults: known, piecewise, refinement when noisy
  Score s;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    SignalTable t = clean;
    const unsigned long noise_seed = seed0 + static_cast<unsigned long>(seed);
    if (rho > 0.0)
      addAr1Noise(&t.dte, kSnrDb, rho, noise_seed);
    else
      addWhiteNoise(&t.dte, kSnrDb, noise_seed);
    if (torque_sd > 0.0) addTorqueNoise(&t.torque, torque_sd, noise_seed);
    const IdentificationResult r = identifyOrFail(t, c, o);
    EXPECT_EQ(r.estimator, "output_error") << label << " seed " << seed;
    s.add(r, t, c);
  }
  std::cout << "[ measured ] " << label << " " << kSnrDb << " dB over " << kSeeds
            << " seeds: " << s.str() << "\n";
  return s;
}

// Right or flagged: the clean segments' +-2 SE cover the truth in >= 90 %, none beyond
// kCleanSE. The reported C (the damping at the segment's mean load) covers it in >= 90 % of all
// segments, flagged or not.
void expectRightOrFlagged(const Score& s, const std::string& label) {
  EXPECT_GE(s.cleanCoverage(), kMinCoverage) << label << ": " << s.str();
  EXPECT_EQ(s.clean_far, 0) << label << ": " << s.str();
  EXPECT_GE(s.coverage(), kMinCoverage) << label << ": " << s.str();
}

// Constant damping in every segment: the flag fires at its nominal rate, variation_z ~ N(0, 1).
void expectFalseAlarmsNominal(const Score& s, const std::string& label) {
  const long bound = binomialBound(s.segments, kNominalFalseAlarm);
  EXPECT_LE(s.varies, bound) << label << " (nominal " << kNominalFalseAlarm << "): " << s.str();
  // sum z^2 ~ chi-square(n): within +-4.5 sqrt(2 n) of n (normal approximation, risk ~1e-5).
  const double n = static_cast<double>(s.vz_count);
  ASSERT_GT(n, 0.5 * s.segments) << label << ": the test ran on too few segments";
  EXPECT_NEAR(s.sum_vz2, n, 4.5 * std::sqrt(2.0 * n)) << label << ": " << s.str();
}

TEST(DampingVariation, ConstantDampingIsFlaggedAtMostAtTheNominalRateOverSeeds) {
  for (const auto& [label, config] :
       {std::pair<std::string, SimConfig>{"trapezoid", table1Trapezoid()},
        {"fourier", table1Fourier()}}) {
    SimConfig c = config;
    setPiecewiseTruth(&c, 1e-3);
    expectFalseAlarmsNominal(overSeeds(c, label + " constant damping", 9100), label);
  }
}

// Coloured noise: variation_z uses the refinement's AR noise model, so it stays N(0, 1).
TEST(DampingVariation, ColouredNoiseConstantDampingIsFlaggedAtMostAtTheNominalRateOverSeeds) {
  SimConfig c = table1Trapezoid();
  setPiecewiseTruth(&c, 1e-3);
  expectFalseAlarmsNominal(overSeeds(c, "trapezoid constant damping, AR(1) rho 0.9", 9200, 0.9),
                           "AR(1) rho 0.9");
}

// Torque-meter noise (white, 1 N*m: most of C_std on this case) on constant damping: the
// variance of variation_z carries the noise's response as C_std does, so the flag keeps its
// nominal rate and variation_z unit variance, under the sine load and under a constant load, where
// the torque varies by the noise alone (a hostile test of 2026-11-27 had 438 of 2,000 such
// segments flagged before the noise entered the variance).
TEST(DampingVariation, TorqueNoiseConstantDampingIsFlaggedAtMostAtTheNominalRateOverSeeds) {
  SimConfig constant_load = table1Config();
  constant_load.load.profile = gear_sim::LoadProfile::Constant;
  for (const auto& [label, config] :
       {std::pair<std::string, SimConfig>{"sine load", table1Config()},
        {"constant load", constant_load}}) {
    SimConfig c = config;
    setPiecewiseTruth(&c, 1e-3);
    expectFalseAlarmsNominal(
        overSeeds(c, label + " constant damping, 1 N*m torque noise", 9400, 0.0, 1.0), label);
  }
}

TEST(DampingVariation, LoadDependentDampingIsRightOrFlaggedOverSeeds) {
  expectRightOrFlagged(overSeeds(table1Trapezoid(), "trapezoid load-dependent", 9300), "trapezoid");
  expectRightOrFlagged(overSeeds(table1Fourier(), "fourier load-dependent", 9500), "fourier");
}

TEST(DampingVariation, HeldOutLoadDependentDampingIsRightOrFlaggedOverSeeds) {
  const SimConfig h = heldOut(heldOutCase());
  expectRightOrFlagged(overSeeds(trapezoid(h, 0.07), "held-out trapezoid load-dependent", 9700),
                       "held-out trapezoid");
  expectRightOrFlagged(overSeeds(fourier(h, 2.6e8, {4.0e7, 0.0, 8.0e6}, {-3.0e7, 1.2e7, 0.0}),
                                 "held-out fourier load-dependent", 9900),
                       "held-out fourier");
}

// Noise-free, refined: the reported C is the damping at the segment's mean load, i.e. the
// segment's time mean of the (load-linear) true C(t), where the constant-C fit is a weighted
// mean 1-3 % from it (the variation is significant in every segment, so the enlarged problem is
// iterated to convergence).
TEST(DampingVariation, NoiseFreeCIsTheTimeMeanOfALoadLinearDamping) {
  IdentificationOptions o;
  o.refine = IdentificationOptions::Refine::Always;
  for (const auto& [label, c] : {std::pair<std::string, SimConfig>{"square", table1Config()},
                                 {"trapezoid", table1Trapezoid()},
                                 {"fourier", table1Fourier()},
                                 {"held-out trapezoid", trapezoid(heldOut(heldOutCase()), 0.07)}}) {
    const SignalTable t = simulateOrFail(c);
    const IdentificationResult r = identifyOrFail(t, c, o);
    double worst = 0.0, worst_weighted = 0.0;
    for (const SegmentEstimate& e : r.segments) {
      ASSERT_TRUE(e.identifiable) << label << ": " << e.reason;
      ASSERT_TRUE(std::isfinite(e.variation_z)) << label;
      const double truth = trueC(t, c, e.t_start, e.t_end);
      worst = std::max(worst, std::abs(e.C - truth) / truth);
      worst_weighted = std::max(worst_weighted, std::abs(e.C_weighted - truth) / truth);
    }
    std::cout << "[ measured ] " << label << " noise-free: max |C - truth| / truth " << worst
              << ", constant-C fit " << worst_weighted << "\n";
    EXPECT_LT(worst, kNoiseFreeMeanLoadTol) << label;
  }
}

// The constant model (one C for the record) on damping that varies between the segments: its
// refinement tests one C per segment against the shared C (a score test, chi-square with n - 1
// degrees of freedom under constancy, reported as a Wilson-Hilferty z in the constant's
// variation_z) and flags `damping_varies` beyond QualityLimits::kVariationZ. Before, the
// constant's C carried no warning at all: on 100 random held-out gears (scripts/heldout_sweep.py
// --check constant) 12 of 38 records whose damping varied got a clean C more than 4 C_std (up to
// 25) and 0.05 % from the truth's time mean.
struct SharedScore {
  long runs = 0, flagged = 0, judged = 0;
  long concentrated = 0;  // the constant flagged information_concentrated
  double sum_z = 0.0, sum_z2 = 0.0;
  double spread = 0.0, true_spread = 0.0;  // of the last run: variation_spread, the truth's
};

// The relative rms spread of the segments' time-mean true C about their mean (line: about their
// least-squares line in the segments' mean torque, the load law's view; relative to the mean C).
double trueSpread(const IdentificationResult& r, const SignalTable& t, const SimConfig& c,
                  bool line = false) {
  std::vector<double> v, torque;
  for (const SegmentEstimate& e : r.segments) {
    v.push_back(trueC(t, c, e.t_start, e.t_end));
    double sum = 0.0;
    long n = 0;
    for (Eigen::Index i = 0; i < t.size(); ++i) {
      if (t.time[i] >= e.t_start - 1e-12 && t.time[i] < e.t_end - 1e-12) sum += t.torque[i], ++n;
    }
    torque.push_back(sum / static_cast<double>(std::max(n, 1L)));
  }
  const double k = static_cast<double>(v.size());
  double mean = 0.0, mt = 0.0, stt = 0.0, stv = 0.0;
  for (size_t q = 0; q < v.size(); ++q) mean += v[q] / k, mt += torque[q] / k;
  for (size_t q = 0; q < v.size(); ++q) {
    stt += (torque[q] - mt) * (torque[q] - mt), stv += (torque[q] - mt) * (v[q] - mean);
  }
  const double slope = line && stt > 0.0 ? stv / stt : 0.0;
  double var = 0.0;
  for (size_t q = 0; q < v.size(); ++q) {
    const double d = v[q] - mean - slope * (torque[q] - mt);
    var += d * d / k;
  }
  return std::sqrt(var) / mean;
}

// `torque_sd` > 0: white torque-meter noise of that standard deviation [N*m] on the torque column.
// model LoadLaw: the load law's test (LoadLawEstimate::variation_z, the run's damping_varies).
SharedScore sharedOverSeeds(const SimConfig& c, const std::string& label, unsigned long seed0,
                            int seeds, double snr_db, double torque_sd = 0.0,
                            DampingModel model = DampingModel::Constant) {
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.model = model;
  const bool law = model == DampingModel::LoadLaw;
  SharedScore s;
  for (int seed = 1; seed <= seeds; ++seed) {
    SignalTable t = clean;
    if (std::isfinite(snr_db)) addWhiteNoise(&t.dte, snr_db, seed0 + seed);
    if (torque_sd > 0.0) addTorqueNoise(&t.torque, torque_sd, seed0 + seed);
    const IdentificationResult r = identifyOrFail(t, c, o);
    double z = NAN, spread = NAN;
    if (law) {
      EXPECT_TRUE(r.load_law && r.load_law->identifiable && r.estimator == "output_error") << label;
      if (!r.load_law) continue;
      z = r.load_law->variation_z, spread = r.load_law->variation_spread;
      s.flagged += gear_damping_id::hasCode(r.warnings, qc::kDampingVaries);
    } else {
      EXPECT_TRUE(r.constant.has_value()) << label;
      if (!r.constant) continue;
      const SegmentEstimate& e = *r.constant;
      EXPECT_TRUE(e.refined) << label;
      z = e.variation_z, spread = e.variation_spread;
      s.flagged += gear_damping_id::hasCode(e.warnings, qc::kDampingVaries);
      s.concentrated += gear_damping_id::hasCode(e.warnings, qc::kInformationConcentrated);
    }
    ++s.runs;
    if (std::isfinite(z)) ++s.judged, s.sum_z += z, s.sum_z2 += z * z;
    s.spread = spread, s.true_spread = trueSpread(r, t, c, law);
  }
  std::cout << "[ measured ] " << label << ", " << (law ? "load law" : "constant model") << " over "
            << seeds << " seeds: " << s.flagged << " flagged damping_varies, " << s.judged
            << " judged, mean z " << s.sum_z / std::max(s.judged, 1L) << ", rms z "
            << std::sqrt(s.sum_z2 / std::max(s.judged, 1L)) << "; last: spread " << s.spread
            << ", the truth's " << s.true_spread << "\n";
  return s;
}

SimConfig constantDamping(SimConfig c) {
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  c.damping.ratio = 0.05;
  return c;
}

// The constant model's test on constant damping, judged on every record: the flag at most at the
// binomial bound of its rate p, sum z^2 within the chi-square bound and the mean within
// 4.5 / sqrt(n) (z N(0, 1)).
void expectNominal(const SharedScore& s, double p, const std::string& what) {
  ASSERT_EQ(s.judged, s.runs) << what << ": noisy records are judged";
  const double n = static_cast<double>(s.judged);
  EXPECT_LE(s.flagged, binomialBound(s.runs, p)) << what;
  EXPECT_NEAR(s.sum_z2, n, 4.5 * std::sqrt(2.0 * n)) << what;
  EXPECT_NEAR(s.sum_z / n, 0.0, 4.5 / std::sqrt(n)) << what;
}

// Constant damping: the test statistic is N(0, 1) after the Wilson-Hilferty transform (sum z^2
// within the chi-square bound of expectFalseAlarmsNominal, the mean within 4.5 / sqrt(n)), and
// the flag (one-sided, z > kVariationZ: 0.135 %) fires at most at the binomial bound.
TEST(DampingVariation, ConstantModelOnConstantDampingIsFlaggedAtMostAtTheNominalRate) {
  const double p = 0.5 * std::erfc(QualityLimits::kVariationZ / std::sqrt(2.0));
  for (const auto& [label, c] :
       {std::pair<std::string, SimConfig>{"square", constantDamping(table1Config())},
        {"trapezoid", constantDamping(table1Trapezoid())},
        {"held-out fourier", constantDamping(fourier(heldOutCase(), 2.6e8, {4.0e7, 0.0, 8.0e6},
                                                     {-3.0e7, 1.2e7, 0.0}))}}) {
    expectNominal(sharedOverSeeds(c, label + " constant damping", 9400, kSeeds, kSnrDb), p, label);
  }
}

// Torque-meter noise (white, 0.3 and 1 N*m, under the sine load and a constant load, where the
// torque varies by the noise alone) on constant damping: each segment's score of its own C carries
// the noise's response in its variance (constancyTorqueVariance), so the statistic stays
// N(0, 1): sum z^2 within the chi-square bound (60 records: rms z within about 0.45-1.28), the
// mean within 4.5 / sqrt(n), the flag at most at the binomial bound of its one-sided 0.135 %.
// Before, these records were all flagged (rms variation_z 6-26 at 30 dB, 100 segments of 1 ms).
TEST(DampingVariation, ConstantModelWithTorqueNoiseIsFlaggedAtMostAtTheNominalRate) {
  const double p = 0.5 * std::erfc(QualityLimits::kVariationZ / std::sqrt(2.0));
  SimConfig constant_load = constantDamping(table1Config());
  constant_load.load.profile = gear_sim::LoadProfile::Constant;
  for (const auto& [label, c] :
       {std::pair<std::string, SimConfig>{"sine load", constantDamping(table1Config())},
        {"constant load", constant_load}}) {
    for (const double torque_sd : {0.3, 1.0}) {
      const std::string what = label + " constant damping, " + std::to_string(torque_sd) + " N*m";
      expectNominal(sharedOverSeeds(c, what, 9800, 2 * kSeeds, kSnrDb, torque_sd), p, what);
    }
  }
}

// Power kept under torque noise: the shipped load-dependent damping with 1 N*m torque noise at
// 40 dB is flagged on every record (variation_z 53 at 30 dB over 100 segments, 60 without the
// torque noise), and a piecewise-in-time damping under a constant load too.
TEST(DampingVariation, ConstantModelWithTorqueNoiseIsFlaggedWhereTheDampingVaries) {
  SimConfig piecewise = table1Config();
  piecewise.load.profile = gear_sim::LoadProfile::Constant;
  setPiecewiseTruth(&piecewise, 2e-3);
  for (const auto& [label, c] :
       {std::pair<std::string, SimConfig>{"load-dependent", table1Config()},
        {"piecewise in time, constant load", piecewise}}) {
    const SharedScore s = sharedOverSeeds(c, label + ", 1 N*m torque noise", 9900, 5, kSnrDb, 1.0);
    EXPECT_EQ(s.flagged, 5) << label;
  }
}

// Damping that varies between the segments is flagged on every record: the shipped load-dependent
// damping (xi 0.035-0.065 over the 100 Hz load cycle), a piecewise-in-time damping under a
// constant load (which no load law describes), both at 40 dB and noise-free; variation_spread
// estimates the size of the segments' spread of C (an information-weighted rms of one-step
// deviations: within a factor 2 of the truth's plain rms of the segments' time means; measured
// 0.53-1.07). Noise-free constant damping is not flagged: the score can be large there (a
// deterministic residual), but the spread is far below the noise-free bar. (A load step between
// samples misfits its segment, noise-free too; the shared C then moves beyond the bar and the
// test flags it: 0.47 % spread on the held-out gear with a step at 4.7 ms.)
TEST(DampingVariation, ConstantModelIsFlaggedWhereTheDampingVariesBetweenSegments) {
  SimConfig piecewise = table1Config();
  piecewise.load.profile = gear_sim::LoadProfile::Constant;
  setPiecewiseTruth(&piecewise, 2e-3);
  for (const auto& [label, c] :
       {std::pair<std::string, SimConfig>{"load-dependent", table1Config()},
        {"held-out load-dependent", heldOut(heldOutCase())},
        {"piecewise in time, constant load", piecewise}}) {
    for (const double snr : {kSnrDb, static_cast<double>(INFINITY)}) {
      const int seeds = std::isfinite(snr) ? 5 : 1;
      const SharedScore s =
          sharedOverSeeds(c, label + " " + std::to_string(snr) + " dB", 9600, seeds, snr);
      EXPECT_EQ(s.flagged, seeds) << label << " " << snr << " dB";
      EXPECT_GT(s.spread, s.true_spread / 2.0) << label << " " << snr << " dB";
      EXPECT_LT(s.spread, s.true_spread * 2.0) << label << " " << snr << " dB";
    }
  }
  for (const auto& [label, c] :
       {std::pair<std::string, SimConfig>{"square", constantDamping(table1Config())},
        {"trapezoid", constantDamping(table1Trapezoid())},
        {"held-out fourier",
         constantDamping(fourier(heldOutCase(), 2.6e8, {4.0e7, 0.0, 8.0e6}, {-3.0e7, 1.2e7, 0.0}))},
        {"held-out square", constantDamping(heldOutCase())}}) {
    const SharedScore s =
        sharedOverSeeds(c, "noise-free " + label + " constant damping", 0, 1, INFINITY);
    EXPECT_EQ(s.flagged, 0) << label;
  }
}

}  // namespace

// The load law (--model load_law) tests one C per segment against the law C0 + C1 T1 (a score
// test about a line in the load, chi-square with n - 2 degrees of freedom when the damping is
// linear in the load, LoadLawEstimate::variation_z) and flags the run `damping_varies` beyond
// kVariationZ with a spread beyond kVariationSpread. On damping linear in the load (the shipped
// load-dependent damping, constant damping under the sine load, the held-out gear's
// load-dependent damping) the statistic is N(0, 1) and the flag at its nominal rate.
TEST(DampingVariation, LoadLawOnDampingLinearInTheLoadIsFlaggedAtMostAtTheNominalRate) {
  const double p = 0.5 * std::erfc(QualityLimits::kVariationZ / std::sqrt(2.0));
  for (const auto& [label, c] :
       {std::pair<std::string, SimConfig>{"load-dependent", table1Config()},
        {"constant damping", constantDamping(table1Config())},
        {"held-out load-dependent", heldOut(heldOutCase())}}) {
    expectNominal(sharedOverSeeds(c, label, 9700, 4 * kSeeds, kSnrDb, 0.0, DampingModel::LoadLaw),
                  p, label);
  }
}

// A held-out gear of test/unit/data/heldout_SEED.yaml (noise-free: the tests add their own).
SimConfig heldOutFile(const std::string& seed) {
  SimConfig c;
  std::string e;
  EXPECT_TRUE(gear_test::ok(
      gear_sim::loadSimConfigFile(
          std::string(GEAR_SOURCE_DIR) + "/test/unit/data/heldout_" + seed + ".yaml", &c),
      &e))
      << e;
  return c;
}

// Damping that is not linear in the load is flagged on every record: piecewise in time under the
// shipped sine load (no line in the load describes it) and the held-out gear above, at 40 dB and
// noise-free; variation_spread within a factor 2 of the truth's rms departure of the segments'
// time-mean C from their least-squares line in the segments' mean torque.
TEST(DampingVariation, LoadLawIsFlaggedWhereTheDampingIsNotLinearInTheLoad) {
  SimConfig piecewise = table1Config();
  setPiecewiseTruth(&piecewise, 2e-3);
  for (const auto& [label, c] : {std::pair<std::string, SimConfig>{"piecewise in time", piecewise},
                                 {"held-out 13607", heldOutFile("13607")}}) {
    for (const double snr : {kSnrDb, static_cast<double>(INFINITY)}) {
      const int seeds = std::isfinite(snr) ? 5 : 1;
      const std::string what = label + " " + std::to_string(snr) + " dB";
      const SharedScore s = sharedOverSeeds(c, what, 9750, seeds, snr, 0.0, DampingModel::LoadLaw);
      EXPECT_EQ(s.flagged, seeds) << what;
      EXPECT_GT(s.spread, s.true_spread / 2.0) << what;
      EXPECT_LT(s.spread, s.true_spread * 2.0) << what;
    }
  }
}

// A constant model whose information lies in one segment (information_concentrated): the
// held-out gear 15714 (test/unit/data/heldout_15714.yaml: Fourier stiffness, speed and load
// ramps, load-dependent damping), whose start-up transient in the first segment holds nearly all
// the information about C. Its constant is that transient's damping, many C_std from the
// record's time mean, and the test of one damping for every segment cannot see it (variation_z
// below 3 at 30 dB); the constant carries information_concentrated on every record. The Table 1
// gear (square stiffness, sine load) spreads its information over the segments (share 0.19) and
// is not flagged. (Its trapezoid variant and the held-out Fourier gear, 10 ms from rest with a
// weakly excited steady state, are flagged: their constants are their start-up transients'
// damping too, right here because the damping is constant.)
TEST(DampingVariation, AConstantFromOneSegmentsTransientIsFlaggedInformationConcentrated) {
  const SimConfig c = heldOutFile("15714");
  const SignalTable clean = simulateOrFail(c);
  IdentificationOptions o;
  o.model = DampingModel::Constant;
  constexpr int kRecords = 5;
  for (int seed = 1; seed <= kRecords; ++seed) {
    SignalTable t = clean;
    addWhiteNoise(&t.dte, 30.0, 9300 + seed);
    const IdentificationResult r = identifyOrFail(t, c, o);
    ASSERT_TRUE(r.constant && r.constant->refined);
    const SegmentEstimate& k = *r.constant;
    const double truth = trueC(t, c, r.segments.front().t_start, r.segments.back().t_end);
    std::cout << "[ measured ] held-out 15714, 30 dB, seed " << seed << ": constant C " << k.C
              << " +- " << k.C_std << " against the time mean " << truth << " ("
              << (k.C - truth) / k.C_std << " C_std), information share " << k.information_share
              << ", variation_z " << k.variation_z << "\n";
    EXPECT_GT(k.information_share, QualityLimits::kInformationShare);
    EXPECT_NEAR(k.information_t_start, r.segments.front().t_start, 1e-12);
    EXPECT_TRUE(gear_damping_id::hasCode(k.warnings, qc::kInformationConcentrated));
  }
  const SharedScore spread = sharedOverSeeds(constantDamping(table1Config()),
                                             "Table 1, constant damping", 9400, kSeeds, kSnrDb);
  EXPECT_EQ(spread.concentrated, 0);
}

// A damping curved in the load (a parabola in the load of +-0.3 % about the line under a load
// ramp, 1 ms pieces): the chi-square test over all directions reached only variation_z 2.8-2.95
// on such laws, 4-5 SE off (hostile review, 2026-11-28); the directed test of a term in T^2
// (LoadLawEstimate::curvature_z) flags them. Measured on 20 seeds at 40 dB: 20 flagged.
TEST(DampingVariation, LoadLawCurvedInTheLoadIsFlagged) {
  SimConfig c = table1Config();
  setRampLoad(&c, 50.0, 150.0, 0.01);
  c.damping.model = gear_sim::DampingProfile::Piecewise;
  c.damping.times.clear();
  c.damping.ratios.clear();
  for (int i = 0; i < 10; ++i) {
    const double x = (i - 4.5) / 4.5;
    c.damping.times.push_back(i * 1e-3);
    c.damping.ratios.push_back(0.05 * (1.0 + 0.003 * (2.0 * x * x - 0.7)));
  }
  constexpr int kRuns = 20;
  const SharedScore s = sharedOverSeeds(c, "curved in the load, 40 dB", 9900, kRuns, kSnrDb, 0.0,
                                        DampingModel::LoadLaw);
  EXPECT_GE(s.flagged, kRuns - 4);
}
