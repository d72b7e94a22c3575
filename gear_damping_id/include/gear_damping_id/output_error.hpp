// Output-error refinement of the integral-method estimate, and the modeled response
// (DESIGN.md §4). No ROS.
//
// Refinement: with white measurement noise on y, the integral method's regressors (integrals of
// the noisy y) are noisy too, which biases C and inflates its scatter (about 1 % at 40 dB SNR and
// 10 % at 20 dB on the default case). The maximum-likelihood estimate for white noise minimises
// the output error sum_n (y_n - yhat_n)^2, where yhat solves eq. (4) on each damping segment
// [T_i, T_i+1) from a free initial state (y0_i, v0_i), with
//   C(t) = C_i (piecewise) | C (constant) | theta0 + theta1 T1(t) (load_law),
//   K(t) = k(t)/Me (known)  | K0_i + dK_i s(t) (greybox),   F(t) = force_factor T1(t).
// It is minimised by Gauss-Newton started from the integral-method estimate (which is close, so
// the iteration converges in a few steps), with the Jacobian from the forward sensitivity
// equations (z_p = dyhat/dp):  z_p'' + C z_p' + K z_p = -(dC/dp) yhat' - (dK/dp) yhat,
// integrated together with eq. (4) by classical RK4 on the sample grid, every step split at the
// stiffness switch instants (as the simulator does), the load interpolated at the stage times by
// the local cubic of quadrature.hpp. Step halving guards against a cost increase. Standard errors
// are sigma^2 (J^T J)^-1 with sigma^2 = RSS / (N - unknowns) (per segment for segment-local
// unknowns, pooled for shared ones): honest for white noise, which a test checks over many seeds.
#pragma once

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/integral_method.hpp"

namespace gear_damping_id {

/// Refines `result` (an IntegralMethod result for the same `signal`, `ranges` and `options`) in
/// place: C, C_std, c, xi (and the greybox k levels) of every identifiable segment, the constant
/// and load-law estimates, and result->windows (one per segment: the refined initial states).
/// Sets result->estimator = "output_error", iterations and noise_std. Only the known and greybox
/// formulations are refined; for the others it returns true and leaves `result` as it is.
/// Returns false with `*error` when the iteration diverges (the integral estimate is then kept).
/// `reference_integration` (for tests): step every sample interval with the generic RK4 of the
/// state and sensitivities instead of the closed-form affine maps (same numbers to rounding).
bool refineOutputError(const SignalView& signal,
                       const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
                       const GearConstants& gear, const IdentificationOptions& options,
                       IdentificationResult* result, std::string* error,
                       bool reference_integration = false);

/// Whether options.refine asks for refinement of this result (Auto: the median relative standard
/// error of C over the identifiable segments, or of the shared C, exceeds refine_threshold, i.e.
/// the data are noisy; never for the paper and legacy formulations).
bool wantsRefinement(const IdentificationOptions& options, const IdentificationResult& result);

/// Modeled response (paper Figs. 6, 7, 9): eq. (4) re-simulated over samples [begin, end) of
/// `signal` with the identified damping (and, for greybox/paper/legacy, the identified stiffness
/// and forcing), from the identified state at the first sample, with gear_sim's RK4 driver
/// stepping onto every switch instant and segment boundary.
struct ModeledResponse {
  Eigen::Index begin = 0;     ///< first sample index
  Eigen::VectorXd observed;   ///< [m]
  Eigen::VectorXd modeled;    ///< [m]
  double nrmse = kNaN;        ///< ||y - yhat|| / ||y - mean(y)||
  double fit_percent = kNaN;  ///< 100 (1 - nrmse)
};

/// Computes the modeled response of `result` over the range of its segments. False with
/// `*error` if no segment is identifiable or the simulation produced a non-finite value.
bool modeledResponse(const SignalView& signal, const GearConstants& gear,
                     const IdentificationResult& result, ModeledResponse* out, std::string* error);

/// NRMSE and fit % of `modeled` against `observed` (equal lengths) over the samples where both
/// are finite; NaN when none are or observed is constant there.
void fitMetrics(const Eigen::VectorXd& observed, const Eigen::VectorXd& modeled, double* nrmse,
                double* fit_percent);

}  // namespace gear_damping_id
