// Encoder front end (docs/rig.md): from the shaft angles a test rig records to the DTE and the
// mesh signals the identification needs. No ROS.
//
// Input: theta1, theta2 [rad], each positive in its own wheel's direction of rotation, as uniform
// samples (optionally quantised to counts per revolution) or as edge times of an incremental
// encoder (one edge every 2 pi / counts_per_rev); the pinion torque T1 [N*m] on the same grid.
//
// Kinematics. The tooth ratio g = Z1/Z2 is exact (teeth are counted), so the rigid-body rotation
// is theta2 = g * theta1. The base radii Rb1, Rb2 of the gear YAML define the line of action. When
// Rb1/Rb2 != g (paper Table 1: 0.05/0.11 against 20/40) the ratio check and the rigid-body removal
// use the teeth; the radii only scale the DTE and enter Me and the force factor, as in the model.
//
//   rigid-body angle   Theta = (I1 theta1 + g I2 theta2) / (I1 + g^2 I2)   (inertia-weighted,
//                      pinion rotation; the DESIGN form with Rb1/Rb2 replaced by g)
//   DTE                y = Rb1 theta1 - Rb2 theta2 - (Rb1 - g Rb2) Theta - y0
//   mesh phase         u = Z1 Theta / (2 pi) + u0   [mesh cycles; u0 = double-contact start]
//
// With theta1 = Theta + d1, theta2 = g Theta + d2 this is y = Rb1 d1 - Rb2 d2 - y0 exactly: the
// rigid rotation drops out whatever the radii. The encoder zeros are arbitrary, so y carries an
// unknown constant; y0 is estimated by the mean force balance mean(K (y + y0)) = mean(F) (the
// record mean of y'' + C y' vanishes up to boundary terms) or given; it is the STE's order-0 term.
// u0 is estimated by minimising the residual of the `known` integral method over u0 (grid, then
// golden section), or given.
//
// Quantisation: an angle read as q floor(theta / q), q = 2 pi / counts, has an error uniform on
// [0, q): std q / sqrt(12). The DTE noise is the linear combination of the two angle errors given
// by the formula above (reported as quantisation_noise_std).
//
// Refusals (the record is not a gear pair): the rotation differs from the tooth ratio by more than
// ratio_tolerance * |rotation| + twist_allowance, an angle runs backwards by more than
// reversal_allowance + two counts (a reversal or a sign convention error), or no rotation at all.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "gear_damping_id/ste_model.hpp"
#include "gear_sim/option_status.hpp"
#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"
#include "gear_sim/status.hpp"

namespace gear_damping_id {

struct EncoderFrontEndOptions {
  /// Relative tolerance of the rotation ratio against Z2/Z1.
  double ratio_tolerance = 1e-3;
  /// [rad] pinion-angle slack of the ratio and reversal checks: dynamic twist (a twist of
  /// 0.01 rad is 500 um of DTE at Rb1 = 0.05 m, far beyond any gear).
  double twist_allowance = 0.01;
  /// [rad] backwards motion of the pinion (gear: times Z1/Z2) beyond two counts that counts as a
  /// reversal (at running speed no dynamic twist moves a shaft backwards).
  double reversal_allowance = 1e-3;
  /// Counts per revolution of each encoder (0 = not quantised / unknown): the noise model.
  long counts_per_rev1 = 0, counts_per_rev2 = 0;
  /// [mesh cycles] the double-contact start offset u0; NaN = estimate it from the data.
  double mesh_offset = std::numeric_limits<double>::quiet_NaN();
  /// Refine the estimated mesh offset below a sample with the output-error residual (slower,
  /// needed with noisy encoders: the refinement places the switches by the mesh phase).
  bool refine_offset = true;
  /// [m] the DTE constant y0; NaN = estimate it (mean force balance).
  double dte_offset = std::numeric_limits<double>::quiet_NaN();
  /// Model the static transmission error in the offset estimates (docs/ste.md): the mesh
  /// offset minimises the residual of the joint damping/STE fit (`ste`; tooth counts from the
  /// gear model), and the DTE offset is the force balance's (the rest is the STE's order-0
  /// term). Without it the estimate ignores an STE the record holds (measured: up to 0.036 mesh
  /// cycles off on the tested STE cases).
  bool model_ste = false;
  SteModelOptions ste;
  /// Streaming: samples buffered before the offsets are estimated (0 = the whole record, until
  /// finish()). Offline analysis uses the whole record.
  long calibration_samples = 0;
  gear_sim::OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// What the front end found; written to the JSON (`input.encoder`).
struct EncoderFrontEndReport {
  double ratio_expected = 0.0;                                       ///< Z2/Z1
  double ratio_measured = std::numeric_limits<double>::quiet_NaN();  ///< rotation1 / rotation2
  double dte_offset = std::numeric_limits<double>::quiet_NaN();      ///< [m] y0 removed
  bool dte_offset_estimated = false;
  double mesh_offset = std::numeric_limits<double>::quiet_NaN();  ///< [mesh cycles] u0 in [0, 1)
  bool mesh_offset_estimated = false;
  double quantisation_noise_std = 0.0;  ///< [m] model DTE noise from the encoder counts
  double noise_std = std::numeric_limits<double>::quiet_NaN();  ///< [m] model-free (3rd diff.)
  double sample_rate = 0.0;                                     ///< [Hz] output grid
  long samples = 0;
  std::string resampling;  ///< what was done to reach the grid ("none", "edge times: ...")
};

/// Coefficients of y = a1 theta1 + a2 theta2 (+ const) after the rigid-body removal.
struct DteCoefficients {
  double a1 = 0.0, a2 = 0.0;  ///< [m/rad]
  double w1 = 0.0, w2 = 0.0;  ///< Theta = w1 theta1 + w2 theta2
};
DteCoefficients dteCoefficients(const gear_sim::GearPair& gears);

/// DTE noise std [m] of angles quantised to the given counts per revolution (0: exact).
double quantisationNoiseStd(const gear_sim::GearPair& gears, long counts1, long counts2);

/// Streaming front end: push uniform samples chunk by chunk, pop the converted samples. The
/// offsets are estimated once, from the first `calibration_samples` (or at finish()), unless given.
class EncoderFrontEnd {
 public:
  EncoderFrontEnd(const gear_sim::GearModel& model, const EncoderFrontEndOptions& options);

  /// Appends n uniform samples starting at global sample `first_index` (time first_index /
  /// sample_rate). `torque` may be null when the offsets are given. InvalidInput when the
  /// record is refused (not a gear pair, reversal, rate change, non-finite value); the front end
  /// then stays refused.
  gear_sim::Status push(double sample_rate, std::uint64_t first_index, const double* theta1,
                        const double* theta2, const double* torque, size_t n);
  /// End of the record: estimates the offsets from what was buffered, if not done yet.
  gear_sim::Status finish();
  /// Moves the converted samples out (time, dte, torque, stiffness, mesh_state, mesh_phase,
  /// theta1, theta2); `first_index` of its first sample. False when none are ready.
  bool pop(gear_sim::SignalTable* out, std::uint64_t* first_index);

  bool calibrated() const { return calibrated_; }
  const EncoderFrontEndReport& report() const { return report_; }

 private:
  gear_sim::Status check(const double* th1, const double* th2, size_t n);
  gear_sim::Status calibrate();
  bool calibrationTable(gear_sim::SignalTable* t, Eigen::VectorXd* u_raw, double* y_shift) const;
  void convert(size_t begin, size_t end);

  gear_sim::GearModel model_;
  EncoderFrontEndOptions o_;
  DteCoefficients coef_;
  EncoderFrontEndReport report_;
  bool calibrated_ = false, refused_ = false, started_ = false;
  std::string refusal_;
  double rate_ = 0.0;
  double th1_first_ = 0.0, th2_first_ = 0.0, th1_max_ = 0.0, th2_max_ = 0.0;
  double th1_last_ = 0.0, th2_last_ = 0.0;
  // Buffered raw samples (before calibration) and converted samples ready to pop.
  std::vector<std::uint64_t> index_;
  std::vector<double> th1_, th2_, torque_;
  bool has_torque_ = false;
  size_t converted_ = 0;  // samples of the buffers converted into out_
  std::uint64_t last_index_ = 0;
  bool has_last_ = false;
  std::vector<std::uint64_t> o_idx_;
  std::vector<double> o_dte_, o_torque_, o_k_, o_s_, o_u_, o_t_, o_th1_, o_th2_;
};

/// Offline: a whole uniform rig table (time, theta1, theta2, torque) to an analysable table.
gear_sim::Status encoderToSignalTable(const gear_sim::SignalTable& rig,
                                      const gear_sim::GearModel& model,
                                      const EncoderFrontEndOptions& options,
                                      gear_sim::SignalTable* out, EncoderFrontEndReport* report);

/// Edge times to angles on a uniform grid: edge k (k = 0, 1, ...) of a shaft is at angle
/// 2 pi k / counts_per_rev; the angle between edges is the local cubic through the four nearest
/// edges (the anti-aliasing/reconstruction filter of docs/rig.md; exact for cubics in time). The
/// grid must lie within [edges.front(), edges.back()]. InvalidInput (times not strictly
/// increasing, too few edges, grid outside, edge gaps longer than max_gap_edges mean intervals).
gear_sim::Status edgeTimesToAngles(const std::vector<double>& edges, long counts_per_rev,
                                   const Eigen::VectorXd& grid, Eigen::VectorXd* theta,
                                   double max_gap_ratio = 20.0);

/// A uniform rig table from edge-time records: the grid is `grid` (e.g. the torque file's time
/// column, with its torque) cropped to the span both edge records cover; theta1/theta2 by
/// edgeTimesToAngles. `resampling` describes it for the report.
gear_sim::Status edgesToRigTable(const std::vector<double>& edges1, long counts1,
                                 const std::vector<double>& edges2, long counts2,
                                 const gear_sim::SignalTable& grid, gear_sim::SignalTable* rig,
                                 std::string* resampling);

/// Decimation by an integer factor with a linear-phase anti-aliasing FIR (windowed sinc, Blackman
/// window, cutoff 0.4 of the output rate, 16 taps per factor either side; unit DC gain, so a
/// linear ramp such as a rotating angle passes unchanged). The first and last half-filter spans
/// are dropped. Columns time, theta1, theta2 and torque of `in`; others are dropped.
gear_sim::Status decimateRig(const gear_sim::SignalTable& in, int factor,
                             gear_sim::SignalTable* out);

}  // namespace gear_damping_id
