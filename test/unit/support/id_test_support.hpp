// Shared fixtures of the identification tests (issue 4): the Table 1 default case read from the
// shipped config/table1.yaml, true damping laws the identification can be scored against, white
// measurement noise at a given SNR, and small statistics. Header-only; every test file that
// includes it is its own target.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "status_support.hpp"

namespace gear_id_test {

using gear_damping_id::DampingModel;
using gear_damping_id::Formulation;
using gear_damping_id::IdentificationOptions;
using gear_damping_id::IdentificationResult;
using gear_sim::SignalTable;
using gear_sim::SimConfig;

/// The docs/method.md §3 default case as shipped (sine load, 3000 rpm, 1 MHz, 10 ms, load-dependent
/// damping xi = 0.05 (1 + 0.6 (T1/Tbar - 1))).
inline SimConfig table1Config() {
  SimConfig c;
  std::string e;
  EXPECT_TRUE(gear_test::ok(
      gear_sim::loadSimConfigFile(std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml", &c), &e))
      << e;
  return c;
}

/// Ratios of a piecewise-constant true damping, one per segment: 0.03 .. 0.07, not monotone, so
/// that a method smoothing across segments or mixing them up is caught.
inline std::vector<double> piecewiseRatios(int segments) {
  static const double pattern[] = {0.05, 0.03, 0.07, 0.04, 0.06, 0.035, 0.065, 0.045, 0.055, 0.04};
  std::vector<double> r;
  for (int i = 0; i < segments; ++i) r.push_back(pattern[i % 10]);
  return r;
}

/// Makes `c`'s true damping piecewise constant on segments of `segment_length` [s] from t = 0.
/// A load step from `from` to `to` [N*m] at `at` [s].
inline void setStepLoad(SimConfig* c, double from, double to, double at) {
  c->load.profile = gear_sim::LoadProfile::Step;
  c->load.initial = from;
  c->load.final_value = to;
  c->load.step_time = at;
}

/// A load ramp from `from` to `to` [N*m] over [0, end] [s], constant after.
inline void setRampLoad(SimConfig* c, double from, double to, double end) {
  c->load.profile = gear_sim::LoadProfile::Ramp;
  c->load.initial = from;
  c->load.final_value = to;
  c->load.ramp_start = 0.0;
  c->load.ramp_end = end;
}

inline void setPiecewiseTruth(SimConfig* c, double segment_length) {
  const int n = static_cast<int>(std::lround(c->simulation.duration / segment_length));
  c->damping.model = gear_sim::DampingProfile::Piecewise;
  c->damping.times.clear();
  for (int i = 0; i < n; ++i) c->damping.times.push_back(i * segment_length);
  c->damping.ratios = piecewiseRatios(n);
}

/// A held-out case none of the defaults were chosen for: other gears (teeth, inertias, radii,
/// stiffness levels, contact ratio), a speed whose switch instants fall between samples, a mesh
/// phase offset, another load, another sample rate (750 kHz: dt = 1.33 us, w0 dt = 0.068) and a
/// longer record. Load-dependent true damping, as in the default case.
inline SimConfig heldOutCase() {
  SimConfig c = table1Config();
  c.gears.pinion.teeth = 23;
  c.gears.pinion.inertia = 0.0004;
  c.gears.pinion.base_radius = 0.055;
  c.gears.gear.teeth = 37;
  c.gears.gear.inertia = 0.003;
  c.gears.gear.base_radius = 0.09;
  c.mesh.k_max = 3.3e8;
  c.mesh.k_min = 1.9e8;
  c.mesh.contact_ratio = 1.43;
  c.mesh.initial_phase = 0.37;
  c.speed.pinion_rpm = 2717.0;  // mesh 1041.5 Hz: switches fall between samples
  c.load.mean = 80.0;
  c.load.amplitude = 30.0;
  c.load.frequency = 70.0;
  c.simulation.sample_rate = 750e3;  // dt = 1.333 us
  c.simulation.duration = 0.012;
  return c;
}

inline SignalTable simulateOrFail(const SimConfig& c) {
  SignalTable t;
  std::string e;
  EXPECT_TRUE(gear_test::ok(gear_sim::simulate(c, &t), &e)) << e;
  return t;
}

/// Runs identify() and fails the test (returning an empty result) on error.
inline IdentificationResult identifyOrFail(const SignalTable& t, const SimConfig& c,
                                           const IdentificationOptions& o) {
  IdentificationResult r;
  std::string e;
  EXPECT_TRUE(gear_test::ok(
      gear_damping_id::identify(t, gear_damping_id::gearConstants(c.gearModel()), o, &r), &e))
      << e;
  return r;
}

/// Time-mean of the true normalised damping C = c/Me [1/s] over samples with t in [t0, t1).
/// For a piecewise truth aligned to the segments it is the segment's constant value.
inline double trueC(const SignalTable& t, const SimConfig& c, double t0, double t1) {
  const double me = c.gears.equivalentMass();
  double sum = 0.0;
  long n = 0;
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    if (t.time[i] >= t0 - 1e-12 && t.time[i] < t1 - 1e-12) sum += t.damping[i] / me, ++n;
  }
  return n > 0 ? sum / static_cast<double>(n) : std::nan("");
}

/// White Gaussian noise at SNR = 20 log10(std(y - mean y) / sigma) [dB], std::mt19937_64(seed)
/// (written here, independently of the simulator's own noise option). Returns sigma.
inline double addWhiteNoise(Eigen::VectorXd* y, double snr_db, unsigned long seed) {
  const double mean = y->mean();
  const double sd = std::sqrt((y->array() - mean).square().sum() / static_cast<double>(y->size()));
  const double sigma = sd / std::pow(10.0, snr_db / 20.0);
  std::mt19937_64 gen(seed);
  std::normal_distribution<double> nd(0.0, sigma);
  for (Eigen::Index i = 0; i < y->size(); ++i) (*y)[i] += nd(gen);
  return sigma;
}

/// White Gaussian torque-meter noise of standard deviation `sd` [N*m] on y, std::mt19937_64(seed).
inline void addTorqueNoise(Eigen::VectorXd* y, double sd, unsigned long seed) {
  std::mt19937_64 gen(seed);
  std::normal_distribution<double> nd(0.0, sd);
  for (Eigen::Index i = 0; i < y->size(); ++i) (*y)[i] += nd(gen);
}

/// `clean` with white DTE noise at snr_db (seed) and, where torque_sd > 0, white torque-meter noise
/// of that standard deviation (torque_seed).
inline SignalTable noisyCopy(const SignalTable& clean, double snr_db, unsigned long seed,
                             double torque_sd, unsigned long torque_seed) {
  SignalTable t = clean;
  addWhiteNoise(&t.dte, snr_db, seed);
  if (torque_sd > 0.0) addTorqueNoise(&t.torque, torque_sd, torque_seed);
  return t;
}

/// The Table 1 case with a constant damping ratio instead of its load-dependent one.
inline SimConfig table1ConstantRatio(double ratio) {
  SimConfig c = table1Config();
  c.damping.model = gear_sim::DampingProfile::ConstantRatio;
  c.damping.ratio = ratio;
  return c;
}

// Stationary AR(1) noise x_n = rho x_{n-1} + sqrt(1 - rho^2) sigma w_n at SNR `snr_db` (std of
// x is sigma, as for white noise), std::mt19937_64(seed).
inline void addAr1Noise(Eigen::VectorXd* y, double snr_db, double rho, unsigned long seed) {
  const double mean = y->mean();
  const double sd = std::sqrt((y->array() - mean).square().sum() / static_cast<double>(y->size()));
  const double sigma = sd / std::pow(10.0, snr_db / 20.0);
  std::mt19937_64 gen(seed);
  std::normal_distribution<double> nd(0.0, 1.0);
  double x = sigma * nd(gen);
  const double innov = sigma * std::sqrt(1.0 - rho * rho);
  for (Eigen::Index i = 0; i < y->size(); ++i) {
    (*y)[i] += x;
    x = rho * x + innov * nd(gen);
  }
}

inline double median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  const size_t m = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + m, v.end());
  if (v.size() % 2 == 1) return v[m];
  const double hi = v[m];
  return 0.5 * (hi + *std::max_element(v.begin(), v.begin() + m));
}

/// Relative errors |C - C_true| / C_true of every segment (a non-identifiable or non-finite
/// segment fails the test and counts as an infinite error).
inline std::vector<double> segmentErrors(const IdentificationResult& r, const SignalTable& t,
                                         const SimConfig& c) {
  std::vector<double> e;
  for (const auto& s : r.segments) {
    EXPECT_TRUE(s.identifiable) << "segment [" << s.t_start << ", " << s.t_end << "): " << s.reason;
    EXPECT_TRUE(std::isfinite(s.C)) << "segment [" << s.t_start << ", " << s.t_end << ")";
    const double truth = trueC(t, c, s.t_start, s.t_end);
    e.push_back(s.identifiable && std::isfinite(s.C) ? std::abs(s.C - truth) / truth
                                                     : std::numeric_limits<double>::infinity());
  }
  return e;
}

/// Fixture: the noise-free default case with the piecewise truth aligned to the 1 ms segments,
/// simulated once per test suite (config_, clean_); tests copy clean_ to add noise or defects.
class PiecewiseDefaultCase : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    config_ = new SimConfig(table1Config());
    setPiecewiseTruth(config_, 1e-3);
    clean_ = new SignalTable(simulateOrFail(*config_));
  }
  static void TearDownTestSuite() {
    delete config_;
    delete clean_;
    config_ = nullptr;
    clean_ = nullptr;
  }
  inline static SimConfig* config_ = nullptr;
  inline static SignalTable* clean_ = nullptr;
};

inline double maxOf(const std::vector<double>& v) {
  return v.empty() ? std::nan("") : *std::max_element(v.begin(), v.end());
}

inline double minOf(const std::vector<double>& v) {
  return v.empty() ? std::nan("") : *std::min_element(v.begin(), v.end());
}

}  // namespace gear_id_test
