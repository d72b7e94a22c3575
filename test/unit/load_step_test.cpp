// A load step between two samples inside a segment (flag load_step, Refinement::loadSteps in
// output_error.cpp, loadStepSE in quality_flags.cpp). The forward model interpolates the torque
// linearly across each sample interval, so it cannot place a step inside one: the step's segment
// keeps an unmodelled free vibration, and its C was up to 8 standard errors off without a
// warning at 40 dB (held-out sweeps, seeds 15282 and 17666). Checked on simulated truth:
// - the Table 1 gear with its load stepping inside a segment, 40 dB, over seeds: the step's
//   segment carries load_step on every record with the step's size and time, no other segment
//   does;
// - no load_step where there is no step: the step on a segment boundary, the shipped sine load
//   with 1 N*m of white torque-meter noise, a trapezoid load (kinks, not steps).
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

constexpr int kSeeds = 20;
constexpr double kSnrDb = 40.0;

// The Table 1 gear under a load stepping from 100 to 150 N*m at `step_time`, constant damping.
SimConfig stepped(double step_time) {
  SimConfig c = table1Config();
  setStepLoad(&c, 100.0, 150.0, step_time);
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  c.damping.ratio = 0.05;
  return c;
}

struct StepTally {
  int records = 0, step_flagged = 0, other_flagged = 0;
  double sum_z2 = 0.0;  // of the step's segment (its error over C_std), for the record
};

// Identifies each seed's record (white noise at snr_db; torque noise of sd torque_sd) and counts
// load_step on the segment holding `step_time` (none: -1) and on the others.
StepTally overSeeds(const SimConfig& c, double step_time, double snr_db, double torque_sd,
                    const std::string& label) {
  const SignalTable clean = simulateOrFail(c);
  StepTally s;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    SignalTable t = clean;
    addWhiteNoise(&t.dte, snr_db, 5100 + seed);
    if (torque_sd > 0.0) addTorqueNoise(&t.torque, torque_sd, 5200 + seed);
    const IdentificationResult r = identifyOrFail(t, c, IdentificationOptions{});
    ++s.records;
    for (const SegmentEstimate& e : r.segments) {
      const bool flagged = gear_damping_id::hasCode(e.warnings, qc::kLoadStep);
      const bool holds = step_time >= e.t_start && step_time < e.t_end;
      if (!holds) {
        s.other_flagged += flagged;
        continue;
      }
      s.step_flagged += flagged;
      EXPECT_TRUE(e.refined) << label;
      const double truth = trueC(t, c, e.t_start, e.t_end);
      s.sum_z2 += (e.C - truth) * (e.C - truth) / (e.C_std * e.C_std);
      if (!flagged) continue;
      EXPECT_NEAR(e.torque_step, c.load.final_value - c.load.initial, 1e-9 * c.load.final_value)
          << label;
      EXPECT_NEAR(e.torque_step_time, step_time, t.time[1] - t.time[0]) << label;
      EXPECT_GT(e.torque_step_response, 0.0) << label;
    }
  }
  std::cout << "[ measured ] " << label << ": load_step on the step's segment " << s.step_flagged
            << " of " << s.records << ", on other segments " << s.other_flagged
            << "; the step's segment rms (C - truth) / C_std "
            << std::sqrt(s.sum_z2 / std::max(s.records, 1)) << "\n";
  return s;
}

// The step at 3.5 ms + 0.3 us (between two samples of the 1 MHz record, inside the fourth 1 ms
// segment): flagged on every record, on no other segment.
TEST(LoadStep, AStepInsideASegmentIsFlaggedThereOnly) {
  const double step_time = 3.5003e-3;
  const StepTally s = overSeeds(stepped(step_time), step_time, kSnrDb, 0.0, "step at 3.5003 ms");
  EXPECT_EQ(s.step_flagged, kSeeds);
  EXPECT_EQ(s.other_flagged, 0);
}

// No step inside a segment: the step at 3 ms + 0.3 us, between the last sample of one segment
// and the first of the next (the interval no segment's model spans); the shipped sine load with
// 1 N*m of white torque noise; a trapezoid load (its corners are kinks the interpolation follows).
TEST(LoadStep, NoStepInsideASegmentIsNeverFlagged) {
  const double boundary = 3.0e-3 - 0.3e-6;
  const StepTally between =
      overSeeds(stepped(boundary), boundary, kSnrDb, 0.0, "step between segments");
  EXPECT_EQ(between.step_flagged + between.other_flagged, 0);
  SimConfig sine = table1Config();
  EXPECT_EQ(overSeeds(sine, -1.0, kSnrDb, 1.0, "sine load, 1 N*m torque noise").other_flagged, 0);
  SimConfig trapezoid = table1Config();
  trapezoid.load.profile = gear_sim::LoadProfile::Trapezoid;
  trapezoid.load.low = 80.0;
  trapezoid.load.high = 160.0;
  trapezoid.load.rise = 0.6e-3;
  trapezoid.load.hold = 1.1e-3;
  trapezoid.load.fall = 0.6e-3;
  trapezoid.load.period = 3.0e-3;
  EXPECT_EQ(overSeeds(trapezoid, -1.0, kSnrDb, 0.0, "trapezoid load").other_flagged, 0);
}

}  // namespace
