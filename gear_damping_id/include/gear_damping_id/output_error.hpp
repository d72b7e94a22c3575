// Output-error refinement of the integral-method estimate, and the modeled response. No ROS.
//
// Refinement: with measurement noise on y, the integral method's regressors (integrals of the
// noisy y) are noisy too, which biases C and inflates its scatter (about 1 % at 40 dB SNR and
// 10 % at 20 dB on the default case). The maximum-likelihood estimate minimises the output error
// of the model y'' + C(t) y' + K(t) y = F(t) on each damping segment [T_i, T_i+1) from a free
// initial state (y0_i, v0_i), with
//   C(t) = C_i (piecewise) | C (constant) | theta0 + theta1 T1(t) (load_law),
//   K(t) = k(t)/Me (known)  | K0_i + dK_i s(t) (greybox),   F(t) = force_factor T1(t),
// where K(t), s(t) and T1(t) are the channels as the integral method's quadrature sees them
// (forward_model.hpp: held values split at the switches located from mesh_phase, smooth
// stiffness and the torque by the quadrature's local cubic, kinks located from the samples), so
// that both estimators fit one and the same model.
//
// Noise: white noise first (sum of squared residuals); then an autoregressive model AR(p),
// p <= 6 chosen by BIC, is fitted to the residuals (per segment for the piecewise model, pooled
// for shared damping) and the prewhitened output error sum_n e_n^2, e_n = r_n + sum a_k r_{n-k},
// is minimised (generalised least squares, conditional on the first p samples), refitting the AR
// model until it settles. With white noise BIC keeps p = 0 and the estimate is the plain output
// error (maximum likelihood, at the Cramer-Rao bound); with coloured noise (anti-aliasing
// filters, encoder interpolation) the standard errors stay honest.
//
// Iteration: Gauss-Newton with step halving, started from the integral-method estimate, per
// segment for the piecewise model (the segments are independent problems) and jointly with the
// segment-local unknowns eliminated (Schur complement) for shared damping. Jacobian from the
// forward sensitivity equations (z_p = dyhat/dp):  z_p'' + C z_p' + K z_p = -(dC/dp) yhat' -
// (dK/dp) yhat, integrated with eq. (4) by classical RK4 on the sample grid with every step split
// at the switch instants and kinks. The look-ups that do not depend on the unknowns (stage
// torques, held K values, smooth K stage values) are tabled once per segment. Where K is held
// over a whole sample interval and C is constant (piecewise/constant damping, one step per
// sample), the RK4 step is an affine map of the state and the three stage torques, formed once
// per held K value and applied in its block structure; with a smooth K or a load-varying C the
// state's RK4 step is taken first and each sensitivity pair stepped from its stage values (same
// numbers to rounding; the generic RK4 with per-stage look-ups is kept as the reference path).
// With an STE the basis values at the stages of every whole sample interval are tabled per
// segment on first use (within a memory budget), not re-evaluated per iteration. On the tabled
// path an evaluation (3 to 6 unknowns) is one fused loop: the sensitivity pairs stepped as AVX2
// lanes, the residual row prewhitened and added to the Gram matrix as it is produced (the same
// operations in the same order: bit-identical); a new noise round starts from the rows the last
// accepted evaluation kept.
// Standard errors: sigma^2 (J^T J)^-1 of the prewhitened problem, sigma^2 = prewhitened RSS /
// (rows - unknowns) (per segment for segment-local unknowns, pooled for shared ones), plus the
// torque-meter noise: the model takes the torque as the exact forcing, so white noise w on the
// torque samples (level estimated per segment by torqueNoiseEstimate) moves the estimate by the
// Gauss-Newton solve map applied to the response G w of the model to it. Its covariance
// A G Sigma_w G^T A^T is exact: the segments' right-hand sides Jw^T W G w (W the prewhitening)
// are independent with covariance sigma^2 M M^T, M = Jw^T W G from one backward (adjoint) pass
// through the converged model's per-step maps (zero initial state, no STE forcing), and the
// Schur-complement solve is linear. Where the per-step maps are not tabled (a greybox stiffness
// shape, several RK4 steps per sample) it is estimated from random draws of w (Rademacher
// +-sigma, seeded by the segment's first sample, so the same on every path), in batches of 16
// until the Monte Carlo standard error of the added variance is below 10 % of C's total
// variance (at most 64 draws: the added variance then within sqrt(2/64) = 18 % relative, the
// Gaussian-draw bound; less with Rademacher draws). Not for the load_law model.
#pragma once

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "gear_damping_id/forward_model.hpp"
#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/signal_view.hpp"
#include "gear_sim/status.hpp"
#include "gear_sim/ste.hpp"

namespace gear_damping_id {

/// The static transmission error e(t) = sum_j theta_j b_j(mesh phase) (ste_model.hpp) in the
/// refinement: the model becomes y'' + C (y' - e') + K (y - e) = F (`relative`) or
/// y'' + C y' + K (y - e) = F, the coefficients theta are unknowns shared by all segments (one
/// joint problem, the segment-local unknowns eliminated as for shared damping), started from
/// `theta`. The basis is evaluated at the local cubic of the mesh phase, e' with the phase rate
/// from the chord of the mesh phase over up to +-16 samples.
struct SteRefinement {
  static constexpr int kMaxTerms = 25;  ///< offset + 12 harmonic pairs
  gear_sim::SteBasis basis;
  bool relative = true;           ///< damping on y' - e' (else on y')
  std::vector<double> theta;      ///< in: start values [m]; out: the refined coefficients
  std::vector<double> theta_std;  ///< out [m]: sigma^2 (J^T J)^-1, pooled innovation variance
};

/// Refines `result` (an IntegralMethod result for the same `signal`, `ranges` and `options`) in
/// place: C, C_std, c, xi (and the greybox k levels) of every identifiable segment, the constant
/// and load-law estimates, and result->windows (one per segment: the refined initial states).
/// Keeps the integral estimate in C_integral/C_integral_std and fills each refined segment's
/// `residuals`; a segment (or the shared estimate) whose iteration hit max_iterations gets the
/// warning "refine_not_converged". Sets result->estimator = "output_error", iterations,
/// noise_std, noise_ar and noise_innovation_std. Only the known and greybox
/// formulations are refined; for the others it returns ok and leaves `result` as it is.
/// NotIdentifiable when the iteration diverges or nothing can be refined (the integral estimate
/// is then kept); InvalidArgument/InvalidInput when options or channels do not allow it.
/// `reference_integration` (for tests): step every sample interval with the generic RK4 of the
/// state and sensitivities instead of the closed-form affine maps, and sum the torque noise's
/// covariance over one torque impulse per sample instead of the adjoint (same numbers to
/// rounding; the impulses cost O(samples^2) per segment: short records only).
/// `ste` (null: no STE): identify the STE coefficients jointly (SteRefinement); the square
/// stiffness (known or greybox) and piecewise or constant damping only.
gear_sim::Status refineOutputError(const SignalView& signal,
                                   const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
                                   const GearConstants& gear, const IdentificationOptions& options,
                                   IdentificationResult* result, bool reference_integration = false,
                                   SteRefinement* ste = nullptr);

/// Model-free estimate [N*m] of white noise on `n` torque samples: a robust scale (1.4826 x the
/// median absolute value) of the fourth differences, over sqrt(70) (white noise: the fourth
/// difference has variance 70 sigma^2; a smooth load contributes (omega dt)^4 of its amplitude,
/// nothing at the sampling rates the method needs, and the median ignores isolated steps). NaN
/// for fewer than 5 samples.
double torqueNoiseEstimate(const double* torque, Eigen::Index n);

/// Whether options.refine asks for the output-error refinement: Auto and Always for the known and
/// greybox formulations, never for paper and legacy (kept as printed, for comparison). Auto
/// refines clean data too: there the integral method's C_std describe only its residual, while
/// its quadrature error and damping that varies within a segment bias C by more (held-out
/// noise-free cases: 0.05-0.7 % at 5-50 C_std; docs/trust.md "integral_std").
bool wantsRefinement(const IdentificationOptions& options);

/// Extremes over a mesh cycle (720 phases) of the stiffness curve [N/m] of a fourier/table shape.
void curveExtremes(const StiffnessShape& shape, const std::vector<double>& curve, double* k_min,
                   double* k_max);
/// The curve's stiffness [N/m] at mesh phase `phase`.
double shapeStiffness(const StiffnessShape& shape, const std::vector<double>& curve, double phase);

/// Modeled response (paper Figs. 6, 7, 9): eq. (4) re-simulated over samples [begin, end) of
/// `signal` with the identified damping (and, for greybox/paper/legacy, the identified stiffness
/// and forcing), from the identified state at the first sample, with gear_sim's RK4 driver
/// stepping onto every switch instant, kink and segment boundary; K(t) and F(t) from the same
/// forward model as the refinement (forward_model.hpp).
struct ModeledResponse {
  Eigen::Index begin = 0;     ///< first sample index
  Eigen::VectorXd observed;   ///< [m]
  Eigen::VectorXd modeled;    ///< [m]
  double nrmse = kNaN;        ///< ||y - yhat|| / ||y - mean(y)||
  double fit_percent = kNaN;  ///< 100 (1 - nrmse)
  /// Samples of `modeled` left NaN up to the next segment with an identified state, where the
  /// re-simulation started again: it turned non-finite (a NaN or absurd input sample) or beyond
  /// the plausible |DTE| of 1 m (a diverging estimate) there, or a segment had no state to start
  /// from. 0 when the response covers every sample.
  Eigen::Index unmodeled = 0;
};

/// Computes the modeled response of `result` over the range of its segments. Where the simulation
/// turns non-finite or implausible it is started again at the next segment with an identified
/// state (those samples NaN, counted in `unmodeled`). NotIdentifiable if no segment is identifiable
/// or no sample could be modeled. With `fit_metrics` false, out->nrmse and out->fit_percent are
/// left NaN (for a caller that sums its own fit over many responses, as `analyze` does for a record
/// analysed streaming).
gear_sim::Status modeledResponse(const SignalView& signal, const GearConstants& gear,
                                 const IdentificationResult& result, ModeledResponse* out,
                                 bool fit_metrics = true);

/// NRMSE and fit % of `modeled` against `observed` (equal lengths) over the samples where both
/// are finite; NaN when none are or observed is constant there.
void fitMetrics(const Eigen::VectorXd& observed, const Eigen::VectorXd& modeled, double* nrmse,
                double* fit_percent);

}  // namespace gear_damping_id
