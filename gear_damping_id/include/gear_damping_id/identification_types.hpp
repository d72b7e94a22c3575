// Options and results of the integral-method damping identification (docs/method.md §4).
// Shared by the integral method (integral_method.hpp), the modeled response / output-error
// refinement and the `analyze` tool and nodes. No ROS; SI units.
#pragma once

#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "gear_damping_id/quality_warning.hpp"
#include "gear_sim/option_status.hpp"

namespace gear_damping_id {

/// What is known about stiffness and forcing (docs/method.md §4):
/// - Known:   K(t), F(t) known series; unknowns per window y_T, alpha; per segment C.
/// - Greybox: F known; K = K0 + dK*s(t) with mesh state s in {0,1} known, K0, dK unknown per
/// segment.
/// - Paper:   eqs. (11)-(16) as printed: K_i and F_i unknown constants per segment.
/// - Legacy:  the earlier constant-load formulation (forcing = its mean, one unknown constant
///            stiffness), kept to reproduce the paper's §4.1 failure.
enum class Formulation { Known, Greybox, Paper, Legacy };

/// How C varies: one per segment, one shared by all segments, or c(t) = c0 + c1*T1(t).
enum class DampingModel { Piecewise, Constant, LoadLaw };

/// Every formulation and damping model, in the order of their enums: the one list of names
/// (toString, parse*, the command line and the nodes use it).
inline constexpr Formulation kFormulations[] = {Formulation::Known, Formulation::Greybox,
                                                Formulation::Paper, Formulation::Legacy};
inline constexpr DampingModel kDampingModels[] = {DampingModel::Piecewise, DampingModel::Constant,
                                                  DampingModel::LoadLaw};
/// Their names ("known", ... / "piecewise", ...).
std::vector<std::string> formulationNames();
std::vector<std::string> dampingModelNames();

std::string toString(Formulation f);
std::string toString(DampingModel m);
/// Parses "known|greybox|paper|legacy" / "piecewise|constant|load_law"; false if unknown.
bool parseFormulation(const std::string& s, Formulation* out);
bool parseDampingModel(const std::string& s, DampingModel* out);

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// Parametrisation of the unknown stiffness of the greybox formulation, as a function of the
/// mesh phase u (mesh cycles, from the `mesh_phase` channel for fourier/table):
/// - square:     K = K0 + dK s(t), s the mesh state (0/1): the two levels of eq. (2);
/// - fourier:H:  K = a0 + sum_{h=1..H} (a_h cos(2 pi h u) + b_h sin(2 pi h u)), 2H+1 unknowns;
/// - table:N:    K periodic piecewise linear through N values at the phases u = j/N, j < N.
/// The unknowns enter the integral equations linearly: IIKy = sum_j theta_j IIb_j(u) y.
struct StiffnessShape {
  enum class Kind { Square, Fourier, Table } kind = Kind::Square;
  int n = 0;  ///< H (fourier) or N (table)
  static constexpr int kMaxHarmonics = 16, kMaxNodes = 32;
  /// Number of stiffness unknowns: 2 (square), 2H+1 (fourier), N (table).
  int unknowns() const;
  /// The basis functions at mesh phase u (fourier/table; `out` holds unknowns() values; NaN
  /// values for a non-finite u).
  void basis(double u, double* out) const;
};
std::string toString(const StiffnessShape& s);
/// Parses "square", "fourier:H" (1 <= H <= 16) or "table:N" (3 <= N <= 32); false if invalid.
bool parseStiffnessShape(const std::string& s, StiffnessShape* out);

struct IdentificationOptions {
  Formulation formulation = Formulation::Known;
  DampingModel model = DampingModel::Piecewise;
  /// Damping segment length dT [s] on which C is constant; 0 or inf: the whole analysed record.
  /// Negative is invalid.
  double segment_length = 1e-3;
  /// Integration window [s]: integrals restart with fresh (y_T, alpha) after this span.
  /// 0 = automatic: about two natural periods, derived from the data (mean K) or the gear
  /// parameters. Clipped to the segment length.
  double window_length = 0.0;
  /// Analysed time range [s]; defaults cover the whole record.
  double t_start = -std::numeric_limits<double>::infinity();
  double t_end = std::numeric_limits<double>::infinity();
  /// A segment whose equilibrated least-squares problem has a 2-norm condition number above
  /// this (or a rank deficiency) is reported as not identifiable. <= 1e7 so that the condition
  /// estimate itself (from the Gram matrix, whose condition is the square) stays meaningful.
  double max_condition = 1e6;
  /// Relative tolerance on the uniformity of the time step (|dt_i - dt| <= tol * dt).
  double time_tolerance = 1e-6;
  /// Output-error refinement of the integral-method estimate (output_error.hpp): Auto and Always
  /// refine, Never does not. Only the `known` and `greybox` formulations are refined (paper and
  /// legacy are kept as printed, for comparison). Auto once skipped clean data (the integral
  /// method's relative standard error of C below `refine_threshold`); it refines them too,
  /// because there its C_std leave out the quadrature error and damping varying within a
  /// segment (docs/trust.md, integral_std).
  enum class Refine { Auto, Always, Never } refine = Refine::Auto;
  /// The median relative standard error of C above which integral-method estimates count as
  /// noisy (the wording of the run warning integral_std, quality_flags.hpp).
  double refine_threshold = 2e-4;
  int max_iterations = 30;  ///< Gauss-Newton iterations of the refinement
  /// Greybox stiffness parametrisation (ignored by the other formulations). fourier/table need
  /// the `mesh_phase` channel; the refinement identifies C and the curve jointly.
  StiffnessShape stiffness_shape;
  /// Whether the output-error refinement can run on these options (every greybox shape and
  /// the known formulation can; kept for callers that check).
  bool refinable() const { return true; }

  /// The first rule broken: field, value and rule (gear_sim/option_status.hpp).
  gear_sim::OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// Statistics of the output-error refinement's residual r_n = y_n - yhat_n over one segment
/// (NaN when the segment was not refined), for the quality checks: a residual RMS well above the
/// noise level or a whitened residual that is still correlated means that the model cannot
/// reproduce the data.
struct ResidualStatistics {
  double rms = kNaN;             ///< [m] root mean square of r
  double lag1 = kNaN;            ///< [-] lag-1 autocorrelation of r (coloured noise: near rho)
  double whitened_lag1 = kNaN;   ///< [-] lag-1 autocorrelation of the prewhitened residual
                                 ///< (~ +-2/sqrt(samples) when the noise model fits)
  double innovation_std = kNaN;  ///< [m] std of the prewhitened residual (= rms when white)
  /// AR model of the noise the refinement prewhitened with, e_n = r_n + sum_k ar[k-1] r_{n-k}
  /// (empty: white noise), fitted to this segment's residual (piecewise model) or to all
  /// segments' (shared damping).
  std::vector<double> ar;
};

/// One damping segment's estimate. Every number is NaN when `identifiable` is false.
struct SegmentEstimate {
  double t_start = kNaN;  ///< [s]
  double t_end = kNaN;    ///< [s]
  double C = kNaN;        ///< [1/s]
  double C_std = kNaN;    ///< [1/s] standard error
  double c = kNaN;        ///< [N*s/m] = C * Me
  double xi = kNaN;       ///< [-] = C / (2*omega0)
  double k_min =
      kNaN;  ///< [N/m] greybox (and paper/legacy: the identified constant K*Me in k_min = k_max)
  double k_max = kNaN;                        ///< [N/m]
  double k_min_std = kNaN, k_max_std = kNaN;  ///< [N/m] standard errors (greybox)
  /// Greybox fourier/table shapes: the identified stiffness unknowns [N/m] in the order of
  /// StiffnessShape (fourier: a0, a1, b1, a2, b2, ...; table: the node values) and their
  /// standard errors; k_min/k_max are then the curve's extremes over a mesh cycle (no std).
  std::vector<double> stiffness_curve, stiffness_curve_std;
  long samples = 0;  ///< samples used
  int windows = 0;   ///< integration windows in the segment
  bool identifiable = false;
  std::string reason;     ///< why not identifiable ("no motion", "too few samples", "NaN in input",
                          ///< "rank deficient", ...)
  double forcing = kNaN;  ///< [m/s^2] identified constant forcing F_i (paper) / Fbar (legacy)
  double mean_torque = kNaN;  ///< [N*m] time-mean T1 over the segment (when known)
  double condition = kNaN;    ///< 2-norm condition number of the equilibrated problem
  bool refined = false;       ///< C (and k levels) from the output-error refinement
  /// The integral method's own estimate and standard error, kept when `refined` replaces C.
  double C_integral = kNaN, C_integral_std = kNaN;  ///< [1/s]
  /// Quality flags (quality_flags.hpp): what the segment's data and fit look like.
  double noise_std = kNaN;       ///< [m] model-free noise estimate: RMS third difference / sqrt(20)
  double signal_std = kNaN;      ///< [m] standard deviation of the DTE about its segment mean
  double residual_rms = kNaN;    ///< [m] RMS residual of the integral equations at the estimate
  QualityWarnings warnings;      ///< empty when the estimate is clean (codes: quality_flags.hpp)
  ResidualStatistics residuals;  ///< of the output-error refinement (when `refined`)
  /// Damping that varies with the load within the segment (refined piecewise estimates with a
  /// torque channel that varies in the segment; NaN otherwise): one Gauss-Newton step of the
  /// refinement's prewhitened problem with the extra unknown C1 of
  /// C(t) = C0 + C1 (T1(t) - mean_torque), from the converged constant-C fit.
  /// The constant model's C (IdentificationResult::constant) instead: the score test of one C per
  /// segment against the shared C, as a z-score (Wilson-Hilferty of its chi-square with n - 1
  /// degrees of freedom; N(0, 1) when the damping is the same in every segment), with
  /// variation_spread the estimated rms spread of the segments' C about the shared C beyond the
  /// noise, relative to C (Refinement::constancyTest in output_error.cpp).
  double variation_z = kNaN;       ///< [-] C1 / std(C1): N(0, 1) when C is constant in the segment
  double variation_spread = kNaN;  ///< [-] constant model only
  /// Greybox square levels (refined piecewise estimates): the score of a stiffness that ramps
  /// over part of the natural period around each switch instead of switching at once
  /// (output_error.cpp, Refinement::shapeScore). N(0, 1) when the square wave holds.
  double shape_z = kNaN;  ///< [-]
  /// The change of C that fit with the ramp's coefficient free would make, relative to C.
  double shape_shift = kNaN;  ///< [-]
  /// Without `mesh_phase` (held stiffness or mesh state, piecewise model, refined): the change of
  /// C, relative to C, when every switch of the segment lies half a sample earlier, the mean
  /// place of a switch that falls anywhere between samples (Refinement::switchTiming). The
  /// switches held to the sample where the new value is first seen can bias C by about this.
  double switch_timing_shift = kNaN;  ///< [-]
  /// The data's score for that shift: the response change it makes, projected off the
  /// unknowns' sensitivities, against the prewhitened residual (as shape_z): N(0, 1) when the
  /// switches lie at the samples, E = |d| / sigma when they lie half a sample earlier.
  double switch_timing_z = kNaN;  ///< [-]
  /// That score's expected value when the switches lie half a sample earlier, |d| / sigma: the
  /// run pools switch_timing_z weighted by it, and a segment's own lateness is z over it
  /// (QualityLimits::kSwitchTimingShare).
  double switch_timing_power = kNaN;  ///< [-]
  /// C0 of that model, the damping at the segment's mean load [1/s], and its standard error:
  /// then also C and C_std (the time mean of a C(t) linear in the load, constant included).
  double C_mean_load = kNaN, C_mean_load_std = kNaN;
  /// The refinement's constant-C fit [1/s] and its standard error: a mean of C(t) weighted by
  /// the response's sensitivity to it (C and C_std where C_mean_load is NaN).
  double C_weighted = kNaN, C_weighted_std = kNaN;
  /// Torque-meter noise (refined segments with a torque channel; NaN otherwise): the model-free
  /// estimate of the white noise on the segment's torque samples [N*m] (torqueNoiseEstimate,
  /// output_error.hpp), and the part of C_std it causes [1/s]: the refinement treats the torque
  /// as the exact forcing, so its response to the torque noise is propagated into C_std (and the
  /// stiffness and STE standard errors) as C_std^2 = C_std_dte^2 + C_torque_std^2.
  double torque_noise_std = kNaN;
  double C_torque_std = kNaN;
  /// A step of the torque between two samples inside the segment (refined segments; NaN where
  /// none stands out of the torque noise): its size [N*m] (the largest jump of an increment over
  /// the mean of its neighbours), the time it lies at (between two samples) [s], and the free
  /// vibration the step's unknown place inside its sample interval can leave unmodelled,
  /// force_factor |dT| dt / (2 omega0) [m] (Refinement::loadSteps; flag load_step).
  double torque_step = kNaN;
  double torque_step_time = kNaN;
  double torque_step_response = kNaN;
  /// A single torque sample that departs from both neighbours (a glitch: a spike of one sample,
  /// refined segments; NaN where none stands out of the torque noise): its size [N*m] (the
  /// sample minus the mean of its neighbours), its time [s], and the free vibration the spurious
  /// impulse force_factor g dt of the model's interpolated torque leaves in the response,
  /// force_factor |g| dt / omega0 [m] (Refinement::loadSteps; flag torque_glitch).
  double torque_glitch = kNaN;
  double torque_glitch_time = kNaN;
  double torque_glitch_response = kNaN;
  /// How far the glitches moved C [1/s] (piecewise refined segments: the first-order effect of
  /// all the segment's glitches' response through its fit; NaN otherwise, where the flag uses the
  /// largest one's bound), and how many glitches the segment holds (the fields above: the
  /// largest).
  double torque_glitch_shift = kNaN;
  long torque_glitches = 0;
  /// A torque channel quantised without dither in the segment (refined piecewise segments; NaN
  /// otherwise): its level step q [N*m] (the staircase's common increment), and how far the
  /// rounding error moved C [1/s] (the first-order effect of the difference between the torque
  /// reconstructed through the staircase's level crossings and the samples; flag
  /// torque_quantised).
  double torque_quantum = kNaN;
  double torque_quantisation_shift = kNaN;
  /// Which the DTE supports, the reconstructed smooth load or the staircase as the load: the
  /// share of their difference the residual holds (1: a quantised smooth load; 0: a load that
  /// really steps, whose steps' free vibrations are in the response), and its standard error.
  double torque_quantisation_fit = kNaN;
  double torque_quantisation_fit_std = kNaN;
  /// The constant model's C (refined): the largest share one segment has in the information
  /// about C [-], and that segment's span [s] (flag information_concentrated).
  double information_share = kNaN;
  double information_t_start = kNaN, information_t_end = kNaN;
};

/// c(t) = c0 + c1 * T1(t) (DampingModel::LoadLaw).
struct LoadLawEstimate {
  double c0 = kNaN, c0_std = kNaN;  ///< [N*s/m]
  double c1 = kNaN, c1_std = kNaN;  ///< [N*s/m per N*m]
  /// The refined law's test of one damping per segment against the law (the constant model's
  /// variation_z, variation_spread about a line in the load): N(0, 1) when the damping is linear
  /// in the load; the segments' rms spread about the law beyond the noise, relative to C. NaN
  /// where not judged (integral estimate, fewer than two segments, noise-free residuals).
  double variation_z = kNaN;       ///< [-]
  double variation_spread = kNaN;  ///< [-]
  /// The directed test of curvature in the load (refined, at least three segments whose torques
  /// spread): the score of a term in T^2, N(0, 1) when the damping is linear in the load, and
  /// the curvature's largest departure from the line, relative to C.
  double curvature_z = kNaN;       ///< [-]
  double curvature_spread = kNaN;  ///< [-]
  bool identifiable = false;
  std::string reason;
};

/// Per-window nuisance estimates; the first window of the record gives the initial state for
/// the modeled response: y(T) = y_T, y'(T) = alpha - C*y_T.
struct WindowEstimate {
  double t_start = kNaN, t_end = kNaN;  ///< [s]
  double y_T = kNaN;                    ///< [m]
  double alpha = kNaN;                  ///< [m/s]
  double velocity = kNaN;               ///< [m/s] y'(T) = alpha - C(T)*y_T
};

struct IdentificationResult {
  Formulation formulation = Formulation::Known;
  DampingModel model = DampingModel::Piecewise;
  StiffnessShape stiffness_shape;  ///< greybox: the shape of segments' stiffness_curve
  double equivalent_mass = kNaN;   ///< [kg] Me used for c = C*Me
  double omega0 = kNaN;            ///< [rad/s] sqrt(mean K) used for xi
  double window_length = kNaN;     ///< [s] effective integration window
  /// Piecewise: one per segment. Constant: one spanning the analysed range. LoadLaw: per
  /// segment, C evaluated at the segment's mean torque (for plots), plus `load_law`.
  std::vector<SegmentEstimate> segments;
  std::optional<SegmentEstimate> constant;  ///< set for DampingModel::Constant
  std::optional<LoadLawEstimate> load_law;  ///< set for DampingModel::LoadLaw
  std::vector<WindowEstimate> windows;
  /// "integral" or "output_error" (the estimator whose numbers are reported).
  std::string estimator = "integral";
  int iterations = 0;       ///< Gauss-Newton iterations of the refinement
  double noise_std = kNaN;  ///< [m] residual standard deviation of the refinement
  /// Autoregressive model of the refinement's residual fitted over all refined segments:
  /// e_n = r_n + sum_k noise_ar[k-1] r_{n-k} is white with std noise_innovation_std; empty for
  /// white noise. The model each segment was prewhitened with is in its `residuals.ar`.
  std::vector<double> noise_ar;
  double noise_innovation_std = kNaN;  ///< [m]
  /// Run-level warnings (codes: quality_flags.hpp), e.g. switches that mesh_phase could not
  /// locate, a refinement that failed or did not converge. Empty when all is well.
  QualityWarnings warnings;
};

}  // namespace gear_damping_id
