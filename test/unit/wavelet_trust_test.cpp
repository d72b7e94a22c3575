// When to trust a wavelet mode (docs/wavelet.md, "When to trust the numbers"): the
// noise-adaptive peak picking finds every mode of a multi-sine free decay with default options,
// free decays are told from forced lines (steady envelopes, harmonics of known order
// frequencies), fits below the documented minimum R^2 give no damping ratio, and close modes
// are flagged. Each case has held-out variants (other frequencies, damping, amplitudes, seeds).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "gear_damping_id/wavelet_analysis.hpp"

namespace gear_damping_id {
namespace {

constexpr double kPi = 3.14159265358979323846;

// --- Named tolerances (with the reason for their size) ------------------------------------
// The bar for the multi-sine case: each xi within 5 % with default options. Expected
// error: < 1 % clean (the analytic free decays of wavelet_test), a few % at 40 dB SNR for the
// weakest mode (its envelope spends fewer samples above 3x the noise floor).
constexpr double kMultiSineXiTol = 0.05;
// At 40 dB the weakest mode's decay region holds only ~4 wavelet scales above 3x the noise
// floor (the 800 Hz mode of the unequal case: omega0 ~ 15 to separate it from 600 Hz, region
// 13-27 ms), so a single record scatters by ~7 % (measured 3-11 %): each seed within 3 such
// standard errors, and the median over the seeds (the estimator's bias) within the 5 % bar.
constexpr double kNoisyScatterTol = 0.20;
// A mode is "found" when a picked mode's frequency (f_d from the ridge phase) is within 2 % of
// it, or 1.5 xi for heavier damping: the spectral peak of a decay is a Lorentzian of relative
// half-width xi, within which noise moves the picked peak; both are below the closest pair's
// relative spacing (600/800 Hz: 29 %) and 2 % is above the PSD's bin (1 Hz at 100 Hz = 1 %).
constexpr double kFoundTol = 0.02;
constexpr double kFoundXiFactor = 1.5;

struct Mode {
  double f;   // damped frequency f_d [Hz]
  double xi;  // damping ratio
  double amplitude;
  double phase;  // [rad]
};

// Free decay sum_i A_i exp(-sigma_i t) cos(2 pi f_i t + phi_i), sigma = xi * omega_n, plus white
// Gaussian noise of standard deviation noise_std (0: none).
std::vector<double> freeDecay(const std::vector<Mode>& modes, double fs, long n,
                              double noise_std = 0.0, unsigned seed = 1) {
  std::vector<double> y(static_cast<size_t>(n), 0.0);
  for (const Mode& m : modes) {
    const double s = m.xi * 2.0 * kPi * m.f / std::sqrt(1.0 - m.xi * m.xi);
    for (long j = 0; j < n; ++j) {
      const double t = static_cast<double>(j) / fs;
      y[size_t(j)] += m.amplitude * std::exp(-s * t) * std::cos(2.0 * kPi * m.f * t + m.phase);
    }
  }
  if (noise_std > 0.0) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> noise(0.0, noise_std);
    for (double& v : y) v += noise(rng);
  }
  return y;
}

// Noise standard deviation for an SNR [dB] relative to the RMS of the clean record.
double noiseFor(const std::vector<double>& clean, double snr_db) {
  double s2 = 0.0;
  for (double v : clean) s2 += v * v;
  return std::sqrt(s2 / static_cast<double>(clean.size())) / std::pow(10.0, snr_db / 20.0);
}

const WaveletMode* found(const WaveletResult& r, double f, double xi = 0.0) {
  const WaveletMode* best = nullptr;
  const double tol = std::max(kFoundTol, kFoundXiFactor * xi);
  for (const WaveletMode& m : r.modes) {
    const double e = std::abs(m.frequency_hz / f - 1.0);
    if (e < tol && (!best || e < std::abs(best->frequency_hz / f - 1.0))) best = &m;
  }
  return best;
}

std::string describe(const WaveletResult& r) {
  std::string s;
  for (const WaveletMode& m : r.modes) {
    s += "  f " + std::to_string(m.spectrum_frequency_hz) + " w0 " + std::to_string(m.omega0) +
         " region " + std::to_string(m.t_start) + "-" + std::to_string(m.t_end) + " peak " +
         std::to_string(m.peak_amplitude) + " floor " + std::to_string(m.noise_floor) + " xi " +
         std::to_string(m.damping_ratio) + " R2 " + std::to_string(m.r2) + " free " +
         (m.free_decay ? "1" : "0") + " " + warningText(m.warnings) + "\n";
  }
  return s;
}

// Every mode found, a free decay, xi within tol; returns the xi per mode (NaN when missing).
std::vector<double> expectAllModes(const std::vector<Mode>& modes, const WaveletResult& r,
                                   double tol = kMultiSineXiTol) {
  std::vector<double> xi(modes.size(), NAN);
  EXPECT_TRUE(r.ok()) << r.status.message();
  for (size_t i = 0; i < modes.size(); ++i) {
    const Mode& m = modes[i];
    const WaveletMode* w = found(r, m.f, m.xi);
    EXPECT_NE(w, nullptr) << m.f << " Hz not found; modes:\n" << describe(r);
    if (!w) continue;
    EXPECT_TRUE(w->free_decay) << m.f << " Hz: " << warningText(w->warnings);
    EXPECT_NEAR(w->damping_ratio, m.xi, tol * m.xi) << m.f << " Hz:\n" << describe(r);
    xi[i] = w->damping_ratio;
  }
  return xi;
}

// Over seeds at snr_db: every mode found in every record, each xi within kNoisyScatterTol and
// the median per mode within kMultiSineXiTol.
void expectModesOverSeeds(const std::vector<Mode>& modes, double fs, long n, double snr_db,
                          unsigned first_seed, unsigned seeds) {
  const double sd = noiseFor(freeDecay(modes, fs, n), snr_db);
  std::vector<std::vector<double>> xi(modes.size());
  for (unsigned seed = first_seed; seed < first_seed + seeds; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const WaveletResult r = validateWavelet(freeDecay(modes, fs, n, sd, seed), fs);
    const std::vector<double> x = expectAllModes(modes, r, kNoisyScatterTol);
    for (size_t i = 0; i < modes.size(); ++i) xi[i].push_back(x[i]);
  }
  for (size_t i = 0; i < modes.size(); ++i) {
    std::sort(xi[i].begin(), xi[i].end());
    EXPECT_NEAR(xi[i][xi[i].size() / 2], modes[i].xi, kMultiSineXiTol * modes[i].xi)
        << modes[i].f << " Hz: median over " << seeds << " seeds";
  }
}

// The multi-sine test signal of the mwdi project: free decays at 100/300/600/800 Hz, fs 5 kHz,
// 1 s. Case 1: equal amplitudes, xi 0.01..0.03. Case 2: amplitudes falling 10:1 with
// frequency, damping rising (the higher modes' time-averaged amplitudes are 2-4 % of the
// lowest's, below the fixed 5 % prominence rule of earlier versions).
const std::vector<Mode> kEqualAmplitudes = {{100.0, 0.01, 1.0, 0.3},
                                            {300.0, 0.015, 1.0, 1.1},
                                            {600.0, 0.02, 1.0, 2.0},
                                            {800.0, 0.03, 1.0, 0.7}};
const std::vector<Mode> kUnequalAmplitudes = {{100.0, 0.01, 1.0, 0.3},
                                              {300.0, 0.02, 0.5, 1.1},
                                              {600.0, 0.025, 0.2, 2.0},
                                              {800.0, 0.03, 0.1, 0.7}};
constexpr double kMwdiFs = 5000.0;
constexpr long kMwdiN = 5000;

TEST(WaveletTrust, FindsAllFourModesOfTheMultiSineSignalWithDefaultOptions) {
  for (const auto* modes : {&kEqualAmplitudes, &kUnequalAmplitudes}) {
    const std::vector<double> y = freeDecay(*modes, kMwdiFs, kMwdiN);
    const WaveletResult r = validateWavelet(y, kMwdiFs);
    expectAllModes(*modes, r);
    EXPECT_EQ(r.modes.size(), modes->size()) << describe(r);
  }
}

TEST(WaveletTrust, TheFixedFivePercentProminenceRuleMissesTheWeakModes) {
  // The reproduction of the issue: the old default misses the weak high modes; the adaptive
  // default (above) finds them.
  const std::vector<double> y = freeDecay(kUnequalAmplitudes, kMwdiFs, kMwdiN);
  WaveletOptions o;
  o.peak_prominence = 0.05;
  const WaveletResult r = validateWavelet(y, kMwdiFs, o);
  ASSERT_TRUE(r.ok()) << r.status.message();
  EXPECT_EQ(found(r, 800.0), nullptr) << describe(r);
}

TEST(WaveletTrust, FindsTheMultiSineModesAt40dBOverSeeds) {
  expectModesOverSeeds(kEqualAmplitudes, kMwdiFs, kMwdiN, 40.0, 1, 9);
  expectModesOverSeeds(kUnequalAmplitudes, kMwdiFs, kMwdiN, 40.0, 1, 9);
}

// Held out: other frequencies, damping ratios, amplitudes and a sample rate, clean and noisy.
TEST(WaveletTrust, HeldOutMultiModeSignalsAreFoundWithDefaultOptions) {
  const std::vector<std::vector<Mode>> cases = {
      {{150.0, 0.005, 1.0, 0.0}, {420.0, 0.02, 0.3, 1.0}, {1100.0, 0.02, 0.3, 2.0}},
      {{60.0, 0.02, 0.5, 0.5},
       {250.0, 0.01, 1.0, 0.1},
       {900.0, 0.015, 0.2, 2.5},
       {1500.0, 0.01, 0.1, 1.5}},
  };
  const double fs = 6000.0;
  const long n = 9000;
  for (size_t c = 0; c < cases.size(); ++c) {
    SCOPED_TRACE("case " + std::to_string(c));
    expectAllModes(cases[c], validateWavelet(freeDecay(cases[c], fs, n), fs));
    expectModesOverSeeds(cases[c], fs, n, 40.0, 101, 9);
  }
}

TEST(WaveletTrust, PureNoiseGivesNoModeOverSeeds) {
  // The noise-adaptive threshold (6 standard deviations of the noise's time average) keeps
  // white noise out of the modes table.
  for (unsigned seed = 1; seed <= 10; ++seed) {
    const std::vector<double> y = freeDecay({}, kMwdiFs, kMwdiN, 1.0, seed);
    const WaveletResult r = validateWavelet(y, kMwdiFs);
    ASSERT_TRUE(r.ok()) << r.status.message();
    EXPECT_TRUE(r.modes.empty()) << "seed " << seed << ":\n" << describe(r);
  }
}

// --- Forced lines -----------------------------------------------------------------------------

// A steady line A (1 + depth sin(2 pi f_am t)) cos(2 pi f t) added to y.
void addLine(std::vector<double>* y, double fs, double f, double a, double depth = 0.0,
             double f_am = 0.0) {
  for (size_t j = 0; j < y->size(); ++j) {
    const double t = static_cast<double>(j) / fs;
    (*y)[j] += a * (1.0 + depth * std::sin(2.0 * kPi * f_am * t)) * std::cos(2.0 * kPi * f * t);
  }
}

const WaveletMode* nearestMode(const WaveletResult& r, double f) {
  const WaveletMode* best = nullptr;
  for (const WaveletMode& m : r.modes) {
    if (!best || std::abs(m.spectrum_frequency_hz - f) < std::abs(best->spectrum_frequency_hz - f))
      best = &m;
  }
  return best;
}

bool hasCode(const WaveletMode& m, const std::string& code) {
  for (const QualityWarning& w : m.warnings) {
    if (w.code == code) return true;
  }
  return false;
}

// A steady line beside a free decay: the line is flagged not_free_decay with no damping ratio,
// the decay keeps its xi. Variants: frequencies, a 10 % amplitude modulation of the line (a
// load cycle), noise seeds.
TEST(WaveletTrust, ASteadyLineIsAForcedLineWithoutDampingRatio) {
  struct Case {
    double fs, f_line, f_decay, xi, depth, f_am;
  };
  const std::vector<Case> cases = {{5000.0, 400.0, 150.0, 0.01, 0.0, 0.0},
                                   {5000.0, 240.0, 700.0, 0.02, 0.1, 3.0},
                                   {8000.0, 1250.0, 330.0, 0.005, 0.1, 7.0}};
  for (const Case& c : cases) {
    for (unsigned seed = 1; seed <= 3; ++seed) {
      SCOPED_TRACE("line " + std::to_string(c.f_line) + " Hz, seed " + std::to_string(seed));
      const long n = static_cast<long>(c.fs);  // 1 s
      std::vector<double> y = freeDecay({{c.f_decay, c.xi, 1.0, 0.4}}, c.fs, n, 0.003, seed);
      addLine(&y, c.fs, c.f_line, 0.3, c.depth, c.f_am);
      const WaveletResult r = validateWavelet(y, c.fs);
      ASSERT_TRUE(r.ok()) << r.status.message();
      const WaveletMode* line = nearestMode(r, c.f_line);
      const WaveletMode* decay = nearestMode(r, c.f_decay);
      ASSERT_TRUE(line && decay && line != decay) << describe(r);
      EXPECT_FALSE(line->free_decay) << describe(r);
      EXPECT_TRUE(hasCode(*line, "not_free_decay")) << describe(r);
      EXPECT_TRUE(std::isnan(line->damping_ratio)) << describe(r);
      EXPECT_TRUE(decay->free_decay) << describe(r);
      EXPECT_NEAR(decay->damping_ratio, c.xi, kMultiSineXiTol * c.xi) << describe(r);
    }
  }
}

// Steady lines at harmonics of a known order frequency (mesh frequency) are forced lines, even
// when a slow amplitude change (a run-up: +-30 % over the record) would pass the steady-envelope
// check; a free decay between the harmonics is not flagged, and a free decay at a harmonic that
// decays into the noise within the record is a transient: it keeps its xi with a warning.
TEST(WaveletTrust, HarmonicsOfAKnownOrderFrequencyAreForcedLines) {
  for (const double f_mesh : {250.0, 310.0}) {
    SCOPED_TRACE("mesh " + std::to_string(f_mesh) + " Hz");
    const double fs = 5000.0;
    const double f_free = 2.5 * f_mesh;  // half-way between harmonics 2 and 3
    std::vector<double> y =
        freeDecay({{f_free, 0.01, 0.7, 2.0}, {4.0 * f_mesh, 0.01, 1.0, 0.5}}, fs, 5000, 1e-3, 7);
    addLine(&y, fs, f_mesh, 1.0, 0.3, 0.5);
    addLine(&y, fs, 2.0 * f_mesh, 0.5);
    WaveletOptions o;
    o.order_frequencies = gearOrderFrequencies(f_mesh, 0, 0);
    ASSERT_EQ(o.order_frequencies.size(), 1u);
    const WaveletResult r = validateWavelet(y, fs, o);
    ASSERT_TRUE(r.ok()) << r.status.message();
    for (double f : {f_mesh, 2.0 * f_mesh}) {
      const WaveletMode* m = nearestMode(r, f);
      ASSERT_NE(m, nullptr);
      EXPECT_FALSE(m->free_decay) << describe(r);
      EXPECT_TRUE(hasCode(*m, "order_harmonic")) << describe(r);
      EXPECT_TRUE(std::isnan(m->damping_ratio)) << describe(r);
    }
    const WaveletMode* m = nearestMode(r, f_free);
    ASSERT_NE(m, nullptr);
    EXPECT_TRUE(m->free_decay) << describe(r);
    EXPECT_TRUE(m->warnings.empty()) << describe(r);
    EXPECT_NEAR(m->damping_ratio, 0.01, kMultiSineXiTol * 0.01) << describe(r);
    const WaveletMode* h = nearestMode(r, 4.0 * f_mesh);
    ASSERT_NE(h, nullptr);
    EXPECT_TRUE(h->free_decay) << describe(r);
    EXPECT_TRUE(hasCode(*h, "near_order_harmonic")) << describe(r);
    EXPECT_NEAR(h->damping_ratio, 0.01, kMultiSineXiTol * 0.01) << describe(r);
  }
  // Shaft orders whose harmonics the record cannot resolve are skipped with a global warning.
  WaveletOptions o;
  o.order_frequencies = gearOrderFrequencies(1000.0, 50, 0);  // shaft: 20 Hz
  ASSERT_EQ(o.order_frequencies.size(), 2u);
  const WaveletResult r =
      validateWavelet(freeDecay({{730.0, 0.02, 1.0, 0.0}}, 5000.0, 500), 5000.0, o);
  ASSERT_TRUE(r.ok()) << r.status.message();
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("order frequency 20 Hz"), std::string::npos) << r.warnings[0];
  ASSERT_EQ(r.modes.size(), 1u);
  EXPECT_TRUE(r.modes[0].free_decay) << describe(r);
}

// A modulated mode is also seen at side lines k order frequencies from its main line; a side
// line's own fit can decay faster or slower than the main line's (here 30 % faster, beyond the
// 15 % of the decay-rate rule), and sigma / omega there is no modal damping ratio: with the order
// frequency known it is flagged `shared_decay` by its position, without a damping ratio. The same
// weaker decay half-way between the first and second side-line positions is an independent mode:
// it keeps its xi. Held-out variants: two order frequencies, side lines below and above the main
// line.
TEST(WaveletTrust, SideLinesOfAStrongerLineAreFlaggedWhateverTheirOwnDecay) {
  const double fs = 5000.0, f_main = 1000.0, xi_main = 0.01;
  const double sigma_main = xi_main * 2.0 * kPi * f_main / std::sqrt(1.0 - xi_main * xi_main);
  for (const double f_order : {230.0, 310.0}) {
    for (const double side : {-1.0, 1.0}) {
      for (const bool at_side_line : {true, false}) {
        SCOPED_TRACE("order " + std::to_string(f_order) + " Hz, side " + std::to_string(side) +
                     (at_side_line ? ", at the side line" : ", between side lines"));
        const double f_weak = f_main + side * (at_side_line ? 1.0 : 1.5) * f_order;
        const double sigma_weak = 1.3 * sigma_main;  // outside the decay-rate rule's 15 %
        const double xi_weak = sigma_weak / std::hypot(sigma_weak, 2.0 * kPi * f_weak);
        const std::vector<double> y =
            freeDecay({{f_main, xi_main, 1.0, 0.3}, {f_weak, xi_weak, 0.5, 1.1}}, fs, 5000);
        WaveletOptions o;
        o.order_frequencies = {f_order};
        const WaveletResult r = validateWavelet(y, fs, o);
        ASSERT_TRUE(r.ok()) << r.status.message();
        const WaveletMode* main = nearestMode(r, f_main);
        const WaveletMode* weak = nearestMode(r, f_weak);
        ASSERT_TRUE(main && weak && main != weak) << describe(r);
        EXPECT_TRUE(main->warnings.empty()) << describe(r);
        EXPECT_NEAR(main->damping_ratio, xi_main, kMultiSineXiTol * xi_main) << describe(r);
        EXPECT_NEAR(weak->sigma, sigma_weak, kMultiSineXiTol * sigma_weak) << describe(r);
        EXPECT_EQ(hasCode(*weak, "shared_decay"), at_side_line) << describe(r);
        if (at_side_line) {
          EXPECT_TRUE(std::isnan(weak->damping_ratio)) << describe(r);
        } else {
          EXPECT_NEAR(weak->damping_ratio, xi_weak, kMultiSineXiTol * xi_weak) << describe(r);
        }
      }
    }
  }
}

// Under known order frequencies a decay region shorter than two periods of the highest of them
// (the mesh frequency: fewer than four switches of a square stiffness) keeps its xi with
// `slow_modulation`; the same decay with a faster order frequency (a region of many periods)
// carries no warning. At 60 dB below the initial amplitude the region is about 6 envelope time
// constants (1 / sigma = 8 ms here): 0.7 and 1.4 periods of 15 and 30 Hz, 20 of 430 Hz.
TEST(WaveletTrust, DecaysShorterThanTwoModulationPeriodsAreFlaggedButKept) {
  const double fs = 5000.0, f = 1000.0, xi = 0.02;
  const std::vector<double> y = freeDecay({{f, xi, 1.0, 0.2}}, fs, 2500, 1e-3, 5);
  for (const double f_order : {15.0, 30.0, 430.0}) {
    SCOPED_TRACE("order " + std::to_string(f_order) + " Hz");
    WaveletOptions o;
    o.order_frequencies = {f_order};
    const WaveletResult r = validateWavelet(y, fs, o);
    ASSERT_TRUE(r.ok()) << r.status.message();
    ASSERT_EQ(r.modes.size(), 1u) << describe(r);
    const WaveletMode& m = r.modes[0];
    EXPECT_NEAR(m.damping_ratio, xi, kMultiSineXiTol * xi) << describe(r);
    const double periods = f_order * (m.t_end - m.t_start);
    EXPECT_EQ(hasCode(m, "slow_modulation"), periods < 2.0) << periods << "\n" << describe(r);
    EXPECT_EQ(m.warnings.size(), periods < 2.0 ? 1u : 0u) << describe(r);
    if (f_order < 100.0) {
      EXPECT_LT(periods, 2.0) << describe(r);
    } else {
      EXPECT_GT(periods, 2.0) << describe(r);
    }
  }
}

// A parametric instability's growth rate lambda (the gear's Floquet exponent at the mesh
// frequency) flags a reported xi with `parametric_resonance`, kept, when it exceeds 5 % of the
// mode's sigma over its decay region: sigma = 125.7 1/s here, so 8 1/s flags and 5 does not; with
// one rate per block of the record, only the blocks the decay region overlaps count (the region
// lies in the first 0.1 s).
TEST(WaveletTrust, AParametricInstabilityOverTheDecayRegionIsFlaggedButKept) {
  const double fs = 5000.0, f = 1000.0, xi = 0.02;
  const double sigma = xi * 2.0 * kPi * f / std::sqrt(1.0 - xi * xi);
  const std::vector<double> y = freeDecay({{f, xi, 1.0, 0.2}}, fs, 2500, 1e-3, 5);
  struct Case {
    std::vector<double> rates;
    bool flagged;
  };
  for (const Case& c : std::vector<Case>{{{5.0}, false},
                                         {{8.0}, true},
                                         {{0.0, 0.0, 0.0, 0.0, 1000.0}, false},
                                         {{1000.0, 0.0, 0.0, 0.0, 0.0}, true}}) {
    SCOPED_TRACE("rates " + std::to_string(c.rates.size()) + ", first " +
                 std::to_string(c.rates.front()));
    WaveletOptions o;
    o.parametric_growth_rate = c.rates;
    o.parametric_growth_block = 0.1;
    const WaveletResult r = validateWavelet(y, fs, o);
    ASSERT_TRUE(r.ok()) << r.status.message();
    ASSERT_EQ(r.modes.size(), 1u) << describe(r);
    const WaveletMode& m = r.modes[0];
    EXPECT_LT(m.t_end, 0.1) << describe(r);
    EXPECT_NEAR(m.sigma, sigma, kMultiSineXiTol * sigma) << describe(r);
    EXPECT_NEAR(m.damping_ratio, xi, kMultiSineXiTol * xi) << describe(r);
    EXPECT_EQ(hasCode(m, "parametric_resonance"), c.flagged) << describe(r);
  }
}

// A decaying envelope that a line does not describe (two unresolved modes beating through zero:
// the analysis is forced to one row with a wavelet too short to separate them) fits with R^2
// below min_r2: no damping ratio, `low_r2`, and `close_modes` names the neighbour.
TEST(WaveletTrust, AFitBelowTheMinimumRSquaredGivesNoDampingRatio) {
  for (const double df : {25.0, 40.0}) {
    SCOPED_TRACE("beat " + std::to_string(df) + " Hz");
    const double fs = 5000.0;
    const std::vector<double> y =
        freeDecay({{1000.0, 0.001, 1.0, 0.0}, {1000.0 + df, 0.001, 1.0, 0.0}}, fs, 5000);
    WaveletOptions o;
    o.mode_frequencies = {1000.0, 1000.0 + df};
    o.fit_omega0 = 3.0;
    const WaveletResult r = validateWavelet(y, fs, o);
    ASSERT_TRUE(r.ok()) << r.status.message();
    for (const WaveletMode& m : r.modes) {
      EXPECT_LT(m.r2, o.min_r2) << describe(r);
      EXPECT_TRUE(std::isnan(m.damping_ratio)) << describe(r);
      EXPECT_TRUE(hasCode(m, "low_r2") || hasCode(m, "not_free_decay")) << describe(r);
      EXPECT_TRUE(hasCode(m, "close_modes")) << describe(r);
    }
  }
}

TEST(WaveletTrust, NewOptionsAreCheckedWithTheFieldNamed) {
  WaveletOptions o;
  EXPECT_TRUE(o.check().ok());
  o.min_r2 = 1.0;
  EXPECT_EQ(o.check().field, "min_r2");
  EXPECT_EQ(o.check().message().rfind("`WaveletOptions::min_r2 = 1`: violated `", 0), 0u)
      << o.check().message();
  o = WaveletOptions{};
  o.min_decay_nepers = 0.0;
  EXPECT_EQ(o.check().field, "min_decay_nepers");
  o = WaveletOptions{};
  o.order_frequencies = {100.0, -1.0};
  EXPECT_EQ(o.check().field, "order_frequencies[1]");
  for (const double bad : {-1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    o = WaveletOptions{};
    o.parametric_growth_rate = {0.0, bad};
    o.parametric_growth_block = 0.1;
    EXPECT_EQ(o.check().field, "parametric_growth_rate[1]") << bad;
  }
  o = WaveletOptions{};
  o.parametric_growth_rate = {1.0};  // one value: no block length needed
  EXPECT_TRUE(o.check().ok());
  o.parametric_growth_rate = {1.0, 2.0};
  EXPECT_EQ(o.check().field, "parametric_growth_block");
  EXPECT_EQ(o.check().message(), o.check().message());
  o = WaveletOptions{};
  o.peak_prominence = 0.0;  // noise-adaptive (the default)
  EXPECT_TRUE(o.check().ok());
  o.peak_prominence = -0.1;
  EXPECT_EQ(o.check().field, "peak_prominence");
}

}  // namespace
}  // namespace gear_damping_id
