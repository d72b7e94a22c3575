// A torque channel quantised without dither (an ADC's or a meter's levels q apart under a slowly
// varying load; flag torque_quantised, Refinement::loadSteps and quantisationShifts in
// output_error.cpp). The torque noise estimate is zero on the staircase, so the torque counted
// as exact, and its rounding error (a sawtooth of +-q/2, not white) biased C: 12-24 of 100 clean
// segments beyond 3 C_std at 30-40 dB (hostile review, 2026-11-28). Checked on simulated truth
// (the Table 1 gear, constant damping, the torque rounded to multiples of q):
// - right or flagged: no clean segment beyond 4 C_std, and +-1.96 C_std covers the clean ones as
//   it should;
// - the flagged segments' computed shift is their bias;
// - an unquantised torque (and one with dither, whose noise the torque-noise propagation
//   carries) is never taken for a staircase.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <string>

#include "gear_damping_id/quality_flags.hpp"
#include "id_test_support.hpp"

namespace {

using namespace gear_id_test;
using gear_damping_id::SegmentEstimate;
namespace qc = gear_damping_id::quality_code;

constexpr int kSeeds = 10;

struct QuantTally {
  int segments = 0, staircase = 0, flagged = 0, clean = 0, clean_within = 0, clean_beyond3 = 0;
  int glitches =
      0;  // segments with a torque_glitch found (a level toggled for one sample is rounding)
  double sum_fit = 0.0, sum_fit_z = 0.0;  // of the staircase segments' torque_quantisation_fit
  double worst_clean = 0.0, sum_unexplained = 0.0, sum_z2_unexplained = 0.0, sum_shift2 = 0.0;
};

// Each seed's record at snr_db with the torque rounded to multiples of q (0: not), after white
// dither of sd `dither`; with `toggles`, every 97th sample inside a level raised by q (the load
// touching the levels' midpoint for one sample).
QuantTally overSeeds(const SimConfig& c, double q, double dither, double snr_db,
                     const std::string& label, bool toggles = false) {
  const SignalTable clean = simulateOrFail(c);
  QuantTally s;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    SignalTable t = noisyCopy(clean, snr_db, 6100 + seed, dither, 6200 + seed);
    if (q > 0.0) t.torque = (t.torque / q).array().round() * q;
    for (Eigen::Index n = 1; toggles && n + 1 < t.torque.size(); n += 97) {
      if (t.torque[n - 1] == t.torque[n] && t.torque[n] == t.torque[n + 1]) t.torque[n] += q;
    }
    const IdentificationResult r = identifyOrFail(t, c, IdentificationOptions{});
    for (const SegmentEstimate& e : r.segments) {
      if (!e.identifiable) continue;
      ++s.segments;
      const double z = (e.C - trueC(t, c, e.t_start, e.t_end)) / e.C_std;
      s.glitches += std::isfinite(e.torque_glitch);
      if (std::isfinite(e.torque_quantum)) {
        ++s.staircase;
        s.sum_fit += e.torque_quantisation_fit;
        s.sum_fit_z += e.torque_quantisation_fit / e.torque_quantisation_fit_std;
      }
      if (gear_damping_id::hasCode(e.warnings, qc::kTorqueQuantised)) {
        ++s.flagged;
        const double shift = e.torque_quantisation_shift / e.C_std;
        s.sum_unexplained += z - shift;
        s.sum_z2_unexplained += (z - shift) * (z - shift);
        s.sum_shift2 += shift * shift;
      }
      if (!e.warnings.empty()) continue;
      ++s.clean;
      s.clean_within += std::abs(z) <= 1.96;
      s.clean_beyond3 += std::abs(z) > 3.0;
      s.worst_clean = std::max(s.worst_clean, std::abs(z));
    }
  }
  const int f = std::max(s.flagged, 1);
  std::cout << "[ measured ] " << label << ": " << s.segments << " segments, " << s.staircase
            << " staircases (mean torque_quantisation_fit " << s.sum_fit / std::max(s.staircase, 1)
            << ", mean fit / its std " << s.sum_fit_z / std::max(s.staircase, 1)
            << "), torque_quantised on " << s.flagged << ", a glitch found on " << s.glitches
            << " (rms shift / C_std " << std::sqrt(s.sum_shift2 / f)
            << ", mean and rms of z - shift / C_std " << s.sum_unexplained / f << ", "
            << std::sqrt(s.sum_z2_unexplained / f) << "); clean " << s.clean << ", within 1.96 "
            << s.clean_within << ", beyond 3 " << s.clean_beyond3 << ", largest |z| "
            << s.worst_clean << "\n";
  return s;
}

TEST(TorqueQuantisation, AQuantisedTorqueIsRightOrFlagged) {
  const SimConfig c = table1ConstantRatio(0.05);
  for (const double q : {0.5, 1.0}) {
    for (const double snr : {30.0, 40.0, 60.0}) {
      const QuantTally s = overSeeds(
          c, q, 0.0, snr, "q " + std::to_string(q) + " N*m, " + std::to_string(snr) + " dB");
      // Right or flagged: an unflagged bias below half a C_std plus the noise (before the flag
      // 15-22 of 100 clean segments were beyond 3 C_std, up to 12.6).
      EXPECT_LT(s.worst_clean, 4.0);
      EXPECT_LE(s.clean_beyond3, 3);
      EXPECT_GT(s.flagged, 0);
      EXPECT_EQ(s.glitches, 0);
      // The computed shift is the flagged segments' bias: the rest averages out, within 3.5
      // standard errors of its mean (its rms, 1.1-2.3, holds the staircase reconstruction's error).
      const double n = s.flagged, mean = s.sum_unexplained / n;
      const double rms = std::sqrt(s.sum_z2_unexplained / n);
      EXPECT_LT(std::abs(mean), 3.5 * rms / std::sqrt(n));
    }
  }
}

// A load that really steps by 5 N*m every 0.25 ms (up and down between 100 and 150 N*m, each step
// between two samples): the same lattice as a quantised ramp, but the DTE holds each step's free
// vibration, so the staircase is the load (torque_quantisation_fit near 0): no torque_quantised
// (before the fit test: 20 of 20 segments flagged with "shifts" of 1-34 C_std, hostile review).
TEST(TorqueQuantisation, ALoadThatReallyStepsIsNotTakenForAQuantiser) {
  SimConfig c = table1ConstantRatio(0.05);
  c.load.profile = gear_sim::LoadProfile::Table;
  c.load.times.clear();
  c.load.values.clear();
  double level = 100.0, dir = 5.0;
  for (int k = 0; k < 40; ++k) {
    const double at = 0.25e-3 * k + 0.3e-6;
    c.load.times.push_back(at);
    c.load.values.push_back(level);
    if (level + dir > 150.0 || level + dir < 100.0) dir = -dir;
    level += dir;
    c.load.times.push_back(at + 1e-9);
    c.load.values.push_back(level);
  }
  const QuantTally s = overSeeds(c, 0.0, 0.0, 40.0, "a load stepping by 5 N*m");
  EXPECT_GT(s.staircase, s.segments / 2);                 // the lattice is there,
  EXPECT_LT(s.sum_fit / std::max(s.staircase, 1), 0.25);  // and the DTE says the steps are real
  EXPECT_EQ(s.flagged, 0);
  EXPECT_LT(s.worst_clean, 4.0);
}

// A quantised load that touches a level's midpoint for one sample toggles that sample by q:
// rounding, not a glitch (found as one of size q before, its shift counted twice).
TEST(TorqueQuantisation, ALevelToggledForOneSampleIsNoGlitch) {
  const QuantTally s =
      overSeeds(table1ConstantRatio(0.05), 0.5, 0.0, 40.0, "q 0.5 N*m, one-sample toggles", true);
  EXPECT_GT(s.staircase, s.segments / 2);
  EXPECT_EQ(s.glitches, 0);
}

TEST(TorqueQuantisation, AnUnquantisedOrDitheredTorqueIsNotAStaircase) {
  const SimConfig c = table1ConstantRatio(0.05);
  EXPECT_EQ(overSeeds(c, 0.0, 0.0, 40.0, "not quantised").flagged, 0);
  EXPECT_EQ(overSeeds(c, 0.5, 0.3, 40.0, "q 0.5 N*m, 0.3 N*m dither").flagged, 0);
}

}  // namespace
