// The wavelet validation on the simulator's default gear case (config/table1.yaml, docs/method.md
// §3): the Morlet-envelope damping ratio at the natural frequency against the simulator's true
// ratio C/(2*omega0), and the table of modes. See docs/wavelet.md ("The default gear case").
//
// What the wavelet can see. The DTE of the default case is a forced, parametrically excited
// response: y'' + C(t) y' + K(t) y = F(t) with K = k(t)/Me a 1 kHz square wave (k_min..k_max)
// and F the load. Its spectrum is a line spectrum at the mesh harmonics (the 10th sits on the
// ~10 kHz natural frequency), and every stiffness switch (2 per mesh period) kicks a new
// transient: there is no long free decay in the raw DTE, and a line fit of ln|W| over it
// measures the forced lines, not the damping (checked below). The free decay is the part of
// the response that is not forced: because the equation is linear in y, the difference of two
// runs of the same case from two initial states is exactly the homogeneous (free) response
// y'' + C(t) y' + K(t) y = 0 of the default case, i.e. its start-up transient with the
// steady, forced part removed. That is the signal analysed here.
//
// The truth. C(t) = c(t)/Me from the simulator's `damping` column, omega0 = sqrt(k_mean/Me)
// (gear_sim::naturalFrequencyHz). The default damping is load-dependent (xi 0.035..0.065 over
// the 100 Hz load cycle), so the reference is C over the decay region the wavelet used,
// weighted like the fit (by |W|^2 ~ exp(-2*sigma*t)), divided by 2*omega0.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "gear_damping_id/wavelet.hpp"
#include "gear_damping_id/wavelet_context.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/models.hpp"
#include "gear_sim/simulator.hpp"
#include "heldout_cases.hpp"
#include "per_mode_agreement.hpp"
#include "status_support.hpp"

namespace {

using gear_damping_id::WaveletMode;
using gear_damping_id::WaveletOptions;
using gear_damping_id::WaveletResult;
using gear_test::HeldOut;
using gear_test::heldOutCases;

constexpr double kPi = 3.14159265358979323846;
// The brief's bar for the forced, parametrically excited gear case (measured: 1.5 % for the
// automatically picked mode, 7 % for the mode fitted at exactly the natural frequency). Why it
// is wider than the 2 % of analytic free decays: the square-wave stiffness makes the free
// oscillation hop between sqrt(k_max/Me) (11.2 kHz) and sqrt(k_min/Me) (7.9 kHz) every mesh
// switch, so the envelope is modulated at 1 kHz (by the amplitude change at each switch) and
// the rotation frequency (~10.1 kHz) differs from omega0; and the Floquet exponent of the
// undamped Hill equation is not exactly zero near the 20th parametric resonance (2 f0 / f_mesh
// = 19.97): with constant damping (xi = 0.05) the same analysis gives 0.047..0.053.
constexpr double kGearCaseXiTol = 0.10;
// The mode picked automatically lies within one wavelet bandwidth (1/omega0 ~ 25 % at the
// fit's omega0 ~ 4) of the natural frequency.
constexpr double kGearCaseFrequencyTol = 0.15;

struct GearCase {
  gear_sim::SimConfig config;
  gear_sim::SignalTable forced, shifted;
  Eigen::VectorXd free_decay;
  double me = 0.0, omega0 = 0.0, f0 = 0.0;
};

const GearCase& defaultGearCase() {
  static const GearCase g = [] {
    GearCase c;
    std::string error;
    const std::string path = std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml";
    EXPECT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(path, &c.config), &error)) << error;
    c.me = c.config.gears.equivalentMass();
    c.f0 = gear_sim::naturalFrequencyHz(c.config.gears, c.config.mesh);
    c.omega0 = 2.0 * kPi * c.f0;
    EXPECT_TRUE(gear_test::ok(gear_sim::simulate(c.config, &c.forced), &error)) << error;
    // Second run from the static deflection under the mean load instead of rest.
    gear_sim::SimConfig shifted = c.config;
    shifted.simulation.initial_dte =
        c.config.gears.forceFactor() * c.config.load.mean / (c.omega0 * c.omega0);
    EXPECT_TRUE(gear_test::ok(gear_sim::simulate(shifted, &c.shifted), &error)) << error;
    c.free_decay = c.shifted.dte - c.forced.dte;
    return c;
  }();
  return g;
}

// True xi = mean C / (2 omega0) over the mode's decay region, weighted by exp(-2 sigma t) as
// the fit's |W|^2 weights are.
double trueXiOver(const GearCase& g, const WaveletMode& m) {
  const double fs = g.config.simulation.sample_rate;
  const long j0 = std::lround(m.t_start * fs), j1 = std::lround(m.t_end * fs);
  double sum = 0.0, weight = 0.0;
  for (long j = std::max(0L, j0); j <= j1 && j < g.forced.size(); ++j) {
    const double w = std::exp(-2.0 * m.sigma * static_cast<double>(j - j0) / fs);
    sum += w * g.forced.damping[j] / g.me;  // C = c / Me [1/s]
    weight += w;
  }
  return gear_damping_id::integralDampingRatio(sum / weight, g.omega0);
}

// validateWavelet on a record of the case with the grid 2 kHz .. 0.4 fs (the automatic grid
// would start at 10 cycles per 10 ms record) and optional explicit mode frequencies.
// Peak picking with the fixed rule (prominence >= 5 % of the highest peak): the free decay of
// the square-wave Hill equation is a Floquet comb, lines at f_F + k * f_mesh of 3-20 % of the
// main line's amplitude that share its decay rate; they are real spectral peaks far above the
// (rounding) noise, so the noise-adaptive default picks them too, and separating them from the
// main line then needs omega0 ~ 18, too slow a wavelet for xi = 0.05 (see docs/wavelet.md).
WaveletResult analyzeCase(const GearCase& g, const Eigen::VectorXd& y, bool full_scalogram,
                          const std::vector<double>& mode_frequencies = {}) {
  const double fs = g.config.simulation.sample_rate;
  WaveletOptions o;
  o.peak_prominence = 0.05;
  o.f_min = 2000.0;
  o.f_max = 0.4 * fs;
  o.full_scalogram = full_scalogram;
  o.mode_frequencies = mode_frequencies;
  return gear_damping_id::validateWavelet(y.data(), static_cast<size_t>(y.size()), fs, o);
}

const WaveletMode* nearest(const WaveletResult& r, double f) {
  const WaveletMode* best = nullptr;
  for (const WaveletMode& m : r.modes) {
    if (!best ||
        std::abs(m.spectrum_frequency_hz - f) < std::abs(best->spectrum_frequency_hz - f)) {
      best = &m;
    }
  }
  return best;
}

TEST(WaveletGearCase, FreeDecayOfTheDefaultCaseGivesTheTrueDampingRatioWithinTenPercent) {
  const GearCase& g = defaultGearCase();
  ASSERT_EQ(g.free_decay.size(), g.forced.size());
  WaveletResult r = analyzeCase(g, g.free_decay, true);
  ASSERT_TRUE(r.ok()) << r.status.message();
  const WaveletMode* m = nearest(r, g.f0);
  ASSERT_NE(m, nullptr);
  ASSERT_TRUE(std::isfinite(m->damping_ratio)) << gear_damping_id::warningText(m->warnings);
  const double truth = trueXiOver(g, *m);
  gear_damping_id::attachIntegralDampingRatio(&r, truth);
  std::ostringstream table;
  ASSERT_EQ(gear_damping_id::writeModesCsv(r, table).message(), "");
  std::printf(
      "[ measured ] default gear case, free decay, automatic peak: f_d %.1f Hz "
      "(f0 %.1f Hz), xi %.5f vs true %.5f (error %+.2f %%), R^2 %.5f, region "
      "[%.4f, %.4f] s, omega0 %.2f\n[ table    ]\n%s",
      m->frequency_hz, g.f0, m->damping_ratio, truth, 100.0 * (m->damping_ratio / truth - 1.0),
      m->r2, m->t_start, m->t_end, m->omega0, table.str().c_str());
  EXPECT_NEAR(m->spectrum_frequency_hz, g.f0, kGearCaseFrequencyTol * g.f0);
  EXPECT_NEAR(m->damping_ratio, truth, kGearCaseXiTol * truth);
  EXPECT_GT(m->r2, 0.95);
  // The nominal ratio of the YAML (damping.ratio, the load-weighted mean) is within the bar too.
  EXPECT_NEAR(m->damping_ratio, g.config.damping.ratio, kGearCaseXiTol * g.config.damping.ratio);
}

TEST(WaveletGearCase, ExplicitNaturalFrequencyGivesTheTrueDampingRatioWithinTenPercent) {
  const GearCase& g = defaultGearCase();
  const WaveletResult r = analyzeCase(g, g.free_decay, false, {g.f0});
  ASSERT_TRUE(r.ok()) << r.status.message();
  ASSERT_EQ(r.modes.size(), 1u);
  const WaveletMode& m = r.modes[0];
  ASSERT_TRUE(std::isfinite(m.damping_ratio)) << gear_damping_id::warningText(m.warnings);
  const double truth = trueXiOver(g, m);
  std::printf(
      "[ measured ] default gear case, free decay, row at f0 = %.1f Hz: xi %.5f vs true "
      "%.5f (error %+.2f %%), f_d %.1f Hz, R^2 %.5f, region [%.4f, %.4f] s\n",
      g.f0, m.damping_ratio, truth, 100.0 * (m.damping_ratio / truth - 1.0), m.frequency_hz, m.r2,
      m.t_start, m.t_end);
  EXPECT_NEAR(m.damping_ratio, truth, kGearCaseXiTol * truth);
}

// The per-mode path (full_scalogram = false: fits, region ends and noise medians on decimated
// grids) against the full path on the gear case's row at f0, whose envelope jumps at every
// stiffness switch (the hardest case for the decimated fits, docs/wavelet.md "Speed"). The
// contract (gear_test::perModeAgreement): statistically indistinguishable from the full path.
// The free decay plus white noise at 40 dB (the trust tests' SNR) over 10 seeds gives the full
// path's seed-to-seed standard deviation of xi and f_d (measured: xi 1.87e-5, i.e. 3.7e-4
// relative, f_d 3.0 Hz); on every seed, and on the noise-free record, the per-mode xi and f_d lie
// within 1/10 of it (measured worst: 0.029 and 0.072 of it; 8 or 12 fit points per scale instead
// of 16 give 0.13 / 1.3: the region end follows the decimated grid), with the same decisions
// (free decay, damping ratio given, warning codes).
TEST(WaveletGearCase, PerModePathIsStatisticallyIndistinguishableFromTheFullPath) {
  const GearCase& g = defaultGearCase();
  const Eigen::VectorXd& clean = g.free_decay;
  const double rms = std::sqrt((clean.array() - clean.mean()).square().mean());
  const double sd = rms / std::pow(10.0, 40.0 / 20.0);
  std::vector<std::vector<gear_test::ModePair>> noisy, noise_free;
  for (unsigned seed = 0; seed <= 10; ++seed) {
    Eigen::VectorXd y = clean;
    if (seed > 0) {
      std::mt19937_64 rng(seed);
      std::normal_distribution<double> noise(0.0, sd);
      for (Eigen::Index j = 0; j < y.size(); ++j) y[j] += noise(rng);
    }
    const WaveletResult full = analyzeCase(g, y, true, {g.f0});
    const WaveletResult fast = analyzeCase(g, y, false, {g.f0});
    ASSERT_TRUE(full.ok()) << full.status.message();
    ASSERT_TRUE(fast.ok()) << fast.status.message();
    ASSERT_EQ(full.modes.size(), 1u);
    ASSERT_EQ(fast.modes.size(), 1u);
    const WaveletMode &a = full.modes[0], &b = fast.modes[0];
    EXPECT_EQ(gear_test::modeDecisions(a), gear_test::modeDecisions(b)) << "seed " << seed;
    ASSERT_TRUE(std::isfinite(a.damping_ratio)) << "seed " << seed;
    (seed == 0 ? noise_free : noisy)
        .push_back({{a.damping_ratio, b.damping_ratio, a.frequency_hz, b.frequency_hz}});
    if (seed == 0) {
      std::printf(
          "[ measured ] gear case row at f0, noise-free, per-mode vs full path: xi %.10g vs "
          "%.10g, f_d %.10g vs %.10g Hz, region end %.6g vs %.6g s\n",
          b.damping_ratio, a.damping_ratio, b.frequency_hz, a.frequency_hz, b.t_end, a.t_end);
    }
  }
  const gear_test::PerModeAgreement r = gear_test::perModeAgreement(noisy, noise_free);
  std::printf(
      "[ measured ] gear case at 40 dB, full path's scatter over 10 seeds: xi %.2e, f_d %.3g Hz; "
      "per-mode vs full path: worst |dxi|/sd %.3f, |df_d|/sd %.3f\n",
      r.sd_xi[0], r.sd_fd[0], r.worst_xi, r.worst_fd);
  EXPECT_LT(r.worst_xi, gear_test::kPerModeShareOfScatter);
  EXPECT_LT(r.worst_fd, gear_test::kPerModeShareOfScatter);
}

// The case of the issue "wavelet on a forced response": on the raw, forced DTE the peaks are
// mesh harmonics (multiples of 1 kHz) whose envelopes do not decay like the mode; their fitted
// "damping ratios" were far below the truth and reached the table unflagged. With the mesh
// frequency known (gear parameters or mesh_phase), every line is flagged as a forced line and
// carries no damping ratio; without it, the steady-envelope and R^2 checks keep every damping
// ratio out of the table too.
TEST(WaveletGearCase, RawForcedResponseIsFlaggedAsForcedLinesNotDamping) {
  const GearCase& g = defaultGearCase();
  const double fs = g.config.simulation.sample_rate;
  const double mesh_hz = g.config.speed.pinion_rpm / 60.0 * g.config.gears.pinion.teeth;
  for (const bool orders_known : {true, false}) {
    SCOPED_TRACE(orders_known ? "order frequencies known" : "no order frequencies");
    WaveletOptions o;  // default peak picking
    o.f_min = 2000.0;
    o.f_max = 0.4 * fs;
    if (orders_known) {
      o.order_frequencies = gear_damping_id::gearOrderFrequencies(
          mesh_hz, g.config.gears.pinion.teeth, g.config.gears.gear.teeth);
    }
    const WaveletResult r = gear_damping_id::validateWavelet(
        g.forced.dte.data(), static_cast<size_t>(g.forced.dte.size()), fs, o);
    ASSERT_TRUE(r.ok()) << r.status.message();
    ASSERT_FALSE(r.modes.empty());
    for (const WaveletMode& m : r.modes) {
      std::printf("[ measured ] forced DTE: line %.1f Hz (harmonic %.3f), R^2 %.3f, free %d: %s\n",
                  m.spectrum_frequency_hz, m.spectrum_frequency_hz / mesh_hz, m.r2, m.free_decay,
                  gear_damping_id::warningText(m.warnings).c_str());
      const double harmonic = m.spectrum_frequency_hz / mesh_hz;
      EXPECT_NEAR(harmonic, std::round(harmonic), 0.02) << m.spectrum_frequency_hz;
      // Known orders: every line is a forced line. Without them a line whose envelope happens
      // to fall by >= 1 neper over the short record (the load cycle) can pass the steady-envelope
      // check, but then its fit fails min_r2: no damping ratio either way.
      if (orders_known) {
        EXPECT_FALSE(m.free_decay) << m.spectrum_frequency_hz;
      }
      EXPECT_TRUE(std::isnan(m.damping_ratio)) << m.spectrum_frequency_hz;
      EXPECT_FALSE(m.warnings.empty()) << m.spectrum_frequency_hz;
    }
  }
}

// Case c simulated: *g with its config, the noise-free forced run and the run from the static
// deflection under the mean load; *y their difference (the free response) plus the noise of the
// case's SNR.
void buildHeldOut(const HeldOut& c, GearCase* g, Eigen::VectorXd* y) {
  std::string e;
  ASSERT_TRUE(gear_test::ok(
      gear_sim::loadSimConfig(YAML::Load(gear_test::heldOutConfig(c)), &g->config), &e))
      << e;
  g->me = g->config.gears.equivalentMass();
  g->f0 = gear_sim::naturalFrequencyHz(g->config.gears, g->config.mesh);
  g->omega0 = 2.0 * kPi * g->f0;
  gear_sim::SignalTable noisy;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(g->config, &noisy), &e)) << e;
  gear_sim::SimConfig quiet = g->config;
  quiet.simulation.noise_snr_db = std::numeric_limits<double>::infinity();
  gear_sim::SimConfig shifted = quiet;
  shifted.simulation.initial_dte +=
      g->config.gears.forceFactor() * noisy.torque.mean() / (g->omega0 * g->omega0);
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(quiet, &g->forced), &e)) << e;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(shifted, &g->shifted), &e)) << e;
  *y = g->shifted.dte - g->forced.dte + (noisy.dte - g->forced.dte);
}

// Held-out gear free responses (random gears of scripts/heldout_sweep.py, `--check wavelet`,
// seeds 8033, 9109, 9007 and 10020; `simulate --free-response`: the difference of two runs from two
// initial states plus the configured noise) on which the analysis once reported wrong damping
// ratios without a warning: a side line at f0 - f_mesh whose own fit decays 16 % faster than the
// main line (xi 0.078 against the true 0.044; 8033), two lines of a slow mesh (417 Hz) whose
// decay region spans a quarter of a mesh period (xi 0.043 and 0.045 against 0.029; 9109), and a
// side line in a region of one mesh period (0.056 against 0.028; 9007), and the main line of a
// noise-free record whose mesh stiffness is parametrically unstable at its speed (10020: Floquet
// growth 363 1/s, so the response decays at C/2 - 363 = 477 1/s: xi 0.0058 against 0.0103,
// -44 %). Right or flagged: every
// mode with a damping ratio and no warning is within the 10 % bar of its true ratio (C over its
// region, weighted like the fit, over 2 omega0), and those lines now carry their warnings.
TEST(WaveletGearCase, HeldOutFreeResponsesAreRightOrFlagged) {
  for (const HeldOut& c : heldOutCases()) {
    const std::string& name = c.name;
    SCOPED_TRACE("held-out case " + name);
    GearCase g;
    Eigen::VectorXd y;
    ASSERT_NO_FATAL_FAILURE(buildHeldOut(c, &g, &y));
    const double fs = g.config.simulation.sample_rate;
    const double f_mesh = g.config.speed.pinion_rpm / 60.0 * g.config.gears.pinion.teeth;
    WaveletOptions o;  // analyze's: default options, the gear's order frequencies
    o.order_frequencies = gear_damping_id::gearOrderFrequencies(f_mesh, g.config.gears.pinion.teeth,
                                                                g.config.gears.gear.teeth);
    o.parametric_growth_rate = {
        gear_sim::parametricGrowthRate(g.config.gears, g.config.mesh, f_mesh)};
    const WaveletResult r =
        gear_damping_id::validateWavelet(y.data(), static_cast<size_t>(y.size()), fs, o);
    ASSERT_TRUE(r.ok()) << r.status.message();
    int reported = 0;
    for (const WaveletMode& m : r.modes) {
      if (!std::isfinite(m.damping_ratio)) continue;
      const double truth = trueXiOver(g, m);
      std::printf("[ measured ] case %s: line %.0f Hz, xi %.4g, true %.4g (%+.1f %%): %s\n",
                  name.c_str(), m.frequency_hz, m.damping_ratio, truth,
                  100.0 * (m.damping_ratio / truth - 1.0),
                  gear_damping_id::warningText(m.warnings).c_str());
      ++reported;
      if (m.warnings.empty()) {
        EXPECT_NEAR(m.damping_ratio / truth, 1.0, kGearCaseXiTol) << m.frequency_hz << " Hz";
      }
    }
    EXPECT_GT(reported, 0);
    if (name == "10020") {  // inside an instability region: lambda 363 1/s, sigma 470 1/s
      EXPECT_GT(o.parametric_growth_rate[0], 300.0);
      for (const WaveletMode& m : r.modes) {
        if (!std::isfinite(m.damping_ratio)) continue;
        bool flagged = false;
        for (const auto& w : m.warnings) flagged = flagged || w.code == "parametric_resonance";
        EXPECT_TRUE(flagged) << m.frequency_hz << " Hz";
      }
    }
    if (name == "8033") {  // the side line at f0 - f_mesh: no damping ratio
      const double f_side = g.f0 - f_mesh;
      const WaveletMode* side = nullptr;
      for (const WaveletMode& m : r.modes) {
        if (!side || std::abs(m.frequency_hz - f_side) < std::abs(side->frequency_hz - f_side))
          side = &m;
      }
      ASSERT_NE(side, nullptr);
      EXPECT_NEAR(side->frequency_hz, f_side, 0.05 * f_mesh);
      EXPECT_TRUE(std::isnan(side->damping_ratio)) << side->frequency_hz;
      bool shared = false;
      for (const auto& w : side->warnings) shared = shared || w.code == "shared_decay";
      EXPECT_TRUE(shared) << gear_damping_id::warningText(side->warnings);
    }
  }
}

// The warning codes of each mode, in order.
std::vector<std::string> codesOf(const WaveletResult& r) {
  std::vector<std::string> out;
  for (const WaveletMode& m : r.modes) {
    std::string codes;
    for (const auto& w : m.warnings) codes += w.code + " ";
    out.push_back(codes);
  }
  return out;
}

// The live wavelet_node (and analyze on a record with mesh_phase) derives the gear's context
// from the samples' own mesh_phase (gear_damping_id::applyGearContext): with the gear parameters
// it must give the options, and so the flags and numbers, that the known speed gives (the
// held-out test above); without them (no gear/params on a rig) the order frequencies alone,
// which still flag the side line of 8033 but not the instability of 10020 (that needs the
// stiffness: docs/live.md). Before, the node analysed every window with ~order_frequencies
// (empty by default): 8033's side line at 4001 Hz was reported with xi 0.078 against a true
// 0.043 (+80 %) and no warning (printed below as "without a context").
TEST(WaveletGearCase, ALiveWindowsMeshPhaseGivesTheKnownSpeedsFlags) {
  for (const HeldOut& c : heldOutCases()) {
    SCOPED_TRACE("held-out case " + c.name);
    GearCase g;
    Eigen::VectorXd y;
    ASSERT_NO_FATAL_FAILURE(buildHeldOut(c, &g, &y));
    const double fs = g.config.simulation.sample_rate;
    const size_t n = static_cast<size_t>(y.size());
    const double f_mesh = g.config.speed.pinion_rpm / 60.0 * g.config.gears.pinion.teeth;
    ASSERT_EQ(g.forced.mesh_phase.size(), y.size());
    const gear_sim::GearModel model = g.config.gearModel();
    WaveletOptions known;  // from the known constant speed
    known.order_frequencies = gear_damping_id::gearOrderFrequencies(
        f_mesh, g.config.gears.pinion.teeth, g.config.gears.gear.teeth);
    known.parametric_growth_rate = {
        gear_sim::parametricGrowthRate(g.config.gears, g.config.mesh, f_mesh)};
    WaveletOptions live, bare;
    double f_live = 0.0, f_bare = 0.0;
    EXPECT_EQ(gear_damping_id::applyGearContext(g.forced.mesh_phase.data(), n, fs, &model, &live,
                                                &f_live),
              "");
    EXPECT_EQ(gear_damping_id::applyGearContext(g.forced.mesh_phase.data(), n, fs, nullptr, &bare,
                                                &f_bare),
              "");
    EXPECT_NEAR(f_live / f_mesh, 1.0, 1e-9);
    EXPECT_EQ(f_bare, f_live);
    ASSERT_EQ(live.order_frequencies.size(), 3u);
    for (size_t k = 0; k < 3; ++k)
      EXPECT_NEAR(live.order_frequencies[k] / known.order_frequencies[k], 1.0, 1e-9);
    ASSERT_EQ(bare.order_frequencies.size(), 1u);  // the mesh frequency alone
    EXPECT_TRUE(bare.parametric_growth_rate.empty());
    ASSERT_EQ(live.parametric_growth_rate.size(), gear_damping_id::kGrowthBlocks);
    EXPECT_NEAR(live.parametric_growth_rate[0], known.parametric_growth_rate[0],
                1e-6 * std::max(1.0, known.parametric_growth_rate[0]));
    for (double rate : live.parametric_growth_rate)  // constant speed: one evaluation for all
      EXPECT_EQ(rate, live.parametric_growth_rate[0]);
    const auto analyse = [&](const WaveletOptions& o) {
      return gear_damping_id::validateWavelet(y.data(), n, fs, o);
    };
    const WaveletResult rk = analyse(known), rl = analyse(live), rb = analyse(bare);
    ASSERT_TRUE(rk.ok() && rl.ok() && rb.ok());
    EXPECT_EQ(codesOf(rl), codesOf(rk));
    ASSERT_EQ(rl.modes.size(), rk.modes.size());
    for (size_t k = 0; k < rk.modes.size(); ++k) {
      const double a = rl.modes[k].damping_ratio, b = rk.modes[k].damping_ratio;
      EXPECT_TRUE(std::isnan(a) ? std::isnan(b) : std::abs(a - b) <= 1e-9 * std::abs(b))
          << rk.modes[k].frequency_hz << " Hz: " << a << " vs " << b;
    }
    if (c.name == "8033") {  // the side line at f0 - f_mesh, from the mesh frequency alone
      const WaveletResult none = analyse(WaveletOptions{});  // the node before: no context
      const WaveletMode* before = nearest(none, g.f0 - f_mesh);
      ASSERT_NE(before, nullptr);
      std::printf("[ measured ] 8033 side line %.0f Hz without a context: xi %.4g, warnings '%s'\n",
                  before->frequency_hz, before->damping_ratio,
                  gear_damping_id::warningText(before->warnings).c_str());
      const WaveletMode* side = nearest(rb, g.f0 - f_mesh);
      ASSERT_NE(side, nullptr);
      EXPECT_TRUE(std::isnan(side->damping_ratio)) << side->frequency_hz;
      EXPECT_NE(codesOf(rb)[static_cast<size_t>(side - rb.modes.data())].find("shared_decay"),
                std::string::npos);
    }
  }
}

// meshPhaseProblem: a phase that gives a mesh frequency, and each way one does not.
TEST(WaveletContext, AMeshPhaseIsUsableOnlyWhenItAdvancesPlausibly) {
  const double fs = 1e6;
  auto problem = [fs](const std::vector<double>& p) {
    return gear_damping_id::meshPhaseProblem(p.data(), p.size(), fs);
  };
  const size_t n = 1000;
  std::vector<double> constant(n), ramp(n), late(n), stair(n), fast(n);
  for (size_t k = 0; k < n; ++k) {
    const double x = static_cast<double>(k);
    constant[k] = 3.0 + 0.02 * x;
    ramp[k] = 1e-4 * x * x;  // from standstill over the record
    // Starts at 98 % of the record (review: against the mean step this was "corrupt").
    late[k] = k < 980 ? 7.0 : 7.0 + 1e-5 * (x - 980.0) * (x - 980.0);
    stair[k] = 0.2 * std::floor(x / 10.0);  // an encoder without interpolation
    fast[k] = 0.7 * x;  // above half a cycle per sample: cumulative, so not aliased
  }
  for (const auto* p : {&constant, &ramp, &late, &stair, &fast}) EXPECT_EQ(problem(*p), "");
  auto with = [&](size_t k, double v) {
    std::vector<double> p = constant;
    p[k] = v;
    return p;
  };
  EXPECT_NE(problem(with(7, std::nan(""))).find("not finite"), std::string::npos);
  EXPECT_NE(problem(with(7, INFINITY)).find("not finite"), std::string::npos);
  EXPECT_NE(problem(with(7, 0.0)).find("decreases"), std::string::npos);
  EXPECT_NE(problem(std::vector<double>(n, 5.0)).find("does not advance"), std::string::npos);
  // A jump half-way, finite and increasing, but no rotation: to 1e308, by 1e6 or by 5 cycles
  // (250 typical steps).
  std::vector<double> huge = constant, jump = constant, small_jump = constant;
  for (size_t k = n / 2; k < n; ++k) huge[k] = 1e308, jump[k] += 1e6, small_jump[k] += 5.0;
  EXPECT_NE(problem(huge).find("overflows"), std::string::npos) << problem(huge);
  for (const auto* p : {&jump, &small_jump})
    EXPECT_NE(problem(*p).find("corrupt"), std::string::npos) << problem(*p);
  // Uniform steps of 1e300 cycles: the frequency overflows (hostile test: the context was
  // dropped without a warning); a 64-sample record ending at 1e308 (no step ratio there before).
  std::vector<double> vast(n), short64(64);
  for (size_t k = 0; k < n; ++k) vast[k] = 1e300 * static_cast<double>(k);
  for (size_t k = 0; k < 64; ++k) short64[k] = 0.02 * static_cast<double>(k);
  short64[63] = 1e308;
  EXPECT_NE(problem(vast).find("overflows"), std::string::npos) << problem(vast);
  EXPECT_NE(problem(short64), "");
  EXPECT_NE(problem({1.0}), "");
}

// applyGearContext: the mean mesh frequency, one growth rate per block at that block's own mesh
// frequency over a speed ramp, explicit order frequencies kept, and nothing set without a
// rotation.
TEST(WaveletContext, GrowthRatesFollowTheBlocksMeshFrequencyAndExplicitOrdersAreKept) {
  const std::string path = std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml";
  gear_sim::SimConfig cfg;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(path, &cfg), &e)) << e;
  const gear_sim::GearModel model = cfg.gearModel();
  const double fs = 1e5;
  const size_t n = 32 * 100;
  // Mesh frequency rising linearly from 500 to 1500 Hz over the record.
  auto phase = [&](size_t k) {
    const double t = static_cast<double>(k) / fs, T = static_cast<double>(n - 1) / fs;
    return 500.0 * t + 0.5 * (1000.0 / T) * t * t;
  };
  WaveletOptions o;
  const double f = gear_damping_id::applyGearContext(phase, n, fs, &model, &o);
  EXPECT_NEAR(f, 1000.0, 1e-9 * 1000.0);
  ASSERT_EQ(o.order_frequencies.size(), 3u);
  EXPECT_NEAR(o.order_frequencies[1], f / cfg.gears.pinion.teeth, 1e-9);
  ASSERT_EQ(o.parametric_growth_rate.size(), 32u);
  EXPECT_NEAR(o.parametric_growth_block, 100.0 / fs, 1e-15);
  int unstable = 0;
  for (size_t b = 0; b < 32; ++b) {
    // The block's mesh frequency: the ramp's at the block's middle (the phase is quadratic).
    const double t_mid =
        0.5 * static_cast<double>(b * 100 + (b == 31 ? n - 1 : (b + 1) * 100)) / fs;
    const double fb = 500.0 + 1000.0 / (static_cast<double>(n - 1) / fs) * t_mid;
    const double expect = gear_sim::parametricGrowthRate(model.gears, model.mesh, fb);
    EXPECT_NEAR(o.parametric_growth_rate[b], std::isfinite(expect) ? expect : 0.0,
                1e-6 * std::max(1.0, std::abs(expect)))
        << b;
    unstable += o.parametric_growth_rate[b] > 0.0 ? 1 : 0;
  }
  EXPECT_GT(unstable, 0);  // the ramp crosses instability regions (measured: 4 of 32 blocks)
  WaveletOptions given;
  given.order_frequencies = {123.0};
  gear_damping_id::applyGearContext(phase, n, fs, nullptr, &given);
  EXPECT_EQ(given.order_frequencies, std::vector<double>{123.0});
  WaveletOptions still;
  EXPECT_EQ(gear_damping_id::applyGearContext([](size_t) { return 2.0; }, n, fs, &model, &still),
            0.0);
  EXPECT_TRUE(still.order_frequencies.empty());
  EXPECT_TRUE(still.parametric_growth_rate.empty());
  WaveletOptions short_record;  // fewer than 4 samples per block: one rate at the mean
  gear_damping_id::applyGearContext(phase, 100, fs, &model, &short_record);
  EXPECT_EQ(short_record.parametric_growth_rate.size(), 1u);
}

}  // namespace
