// Joint identification of the damping and the static transmission error (STE), docs/ste.md.
// With the STE e(t) the normalised model is
//
//     y'' + C (y' - e') + K (y - e) = F        (damping on the deflection rate, default)
//     y'' + C  y'       + K (y - e) = F        (damping on the DTE rate, option)
//
// e = sum_j theta_j b_j(u): b_j the basis of gear_sim::SteBasis (offset, mesh orders of the mesh
// phase u, pinion and gear shaft orders of the rigid shaft angles 2 pi u / Z). Integrating twice
// from a window start T (as in integral_method.hpp):
//
//     y - IIF = y_T + alpha (t - T) - C (P_y - sum_j theta_j P_bj) - II[K (y - sum_j theta_j b_j)]
//
// P_g = int_T^t g, II[g] = int_T^t int_T^s g. The STE coefficients theta are SHARED by the whole
// record (they are a property of the gears), C is per damping segment (or one for the record),
// y_T and alpha are per integration window.
//   known:   K known -> linear in theta for the `dte` damping form; bilinear (C theta) for the
//            relative form.
//   greybox: K = K0 + dK s(t) per segment, unknown -> bilinear (K0 theta, dK theta).
// Both are solved by Gauss-Newton on the integral equations: at each iteration the products
// a*theta are linearised about the current estimate, which keeps every design column a fixed
// linear combination of "raw" integral columns. The raw columns' Gram matrix is accumulated once
// per segment (one pass over the data, the window's nuisance {1, t - T} projected out exactly as
// in the integral method) and every iteration is a small dense solve. Quadrature: local cubics
// (quadrature.hpp), intervals split at the stiffness switch instants located from `mesh_phase`.
// Standard errors: sigma^2 (J^T J)^-1 at the solution, sigma^2 = RSS / (rows - unknowns -
// 2 windows). Identifiability: the 2-norm condition number of the equilibrated normal matrix
// and the largest correlation between a damping unknown and an STE coefficient; above the
// limits the run carries the warning `ste_not_separable`. No ROS.
#pragma once

#include <string>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/integral_method.hpp"
#include "gear_sim/option_status.hpp"
#include "gear_sim/signal_table.hpp"
#include "gear_sim/ste.hpp"

namespace gear_damping_id {

namespace quality_code {
/// The damping and the STE coefficients cannot be told apart on this record (condition number
/// or a damping-STE correlation above the limits).
inline constexpr const char* kSteNotSeparable = "ste_not_separable";
/// Run code: the STE was identified on a calibration span of a streamed record and held for the
/// later segments (SegmentDriver::setSte), not jointly on the whole record.
inline constexpr const char* kSteHeld = "ste_held";
}  // namespace quality_code

/// What STE to identify.
struct SteModelOptions {
  int mesh_orders = 0;    ///< H: mesh harmonics 1..H of the mesh phase
  int pinion_orders = 0;  ///< shaft orders 1..S of the pinion angle (run-out)
  int gear_orders = 0;    ///< shaft orders 1..S of the gear angle
  bool offset = true;     ///< the order-0 term (encoder zeros: always on for rig data)
  gear_sim::SteDamping damping = gear_sim::SteDamping::Relative;
  int pinion_teeth = 0, gear_teeth = 0;  ///< Z1, Z2 (shaft angles from the mesh phase)
  int max_iterations = 30;               ///< Gauss-Newton iterations
  double max_correlation = 0.999;        ///< |corr(C, theta_j)| above: ste_not_separable
  bool active() const { return offset || mesh_orders + pinion_orders + gear_orders > 0; }
  gear_sim::SteBasis basis() const;
  gear_sim::OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};
/// Parses "mesh:H,shaft:S" (shaft: both shafts), "pinion:S", "gear:S", "offset", "none" in any
/// comma-separated combination; the offset is always included unless "nooffset" is given.
/// InvalidArgument naming the bad item (no option prefix: the CLI says "--ste: ", the nodes
/// "~ste = '...': "); `out` unchanged on failure.
gear_sim::Status parseSteSpec(const std::string& spec, SteModelOptions* out);

/// One identified STE term: e contribution cos * cos(order * angle) + sin * sin(order * angle).
struct SteTerm {
  std::string kind;  ///< "offset", "mesh", "pinion", "gear"
  int order = 0;
  double cos = kNaN, sin = kNaN;          ///< [m] (offset: value in cos, sin = 0)
  double cos_std = kNaN, sin_std = kNaN;  ///< [m]
};

struct SteResult {
  SteModelOptions options;
  std::vector<SteTerm> terms;            ///< offset first, then mesh, pinion, gear orders
  std::vector<double> theta, theta_std;  ///< the raw coefficients in SteBasis order [m]
  double condition = kNaN;               ///< of the equilibrated joint normal matrix
  double max_correlation = kNaN;         ///< largest |corr| between a damping and an STE unknown
  bool separable = false;
  int iterations = 0;
  double residual_rms = kNaN;  ///< [m] RMS residual of the integral equations
  bool refined = false;        ///< theta, theta_std from the output-error refinement
  long rows = 0;
  /// Covariance of theta [m^2] (refined: the integral fit's correlations scaled to theta_std);
  /// what the held-STE segments propagate into their C.
  Eigen::MatrixXd theta_cov;
};

/// Identifies C (per segment, or constant: options.model), greybox stiffness levels when
/// options.formulation is Greybox, and the STE jointly. `result` gets the damping estimates in
/// the usual shape (segments, constant), `ste` the STE. Needs `mesh_phase` (and `stiffness` for
/// known, `mesh_state` for greybox, `torque`). A failed Status when the options (InvalidArgument,
/// the field) or the input (InvalidInput, the column) cannot be used (the load_law model and the
/// paper/legacy formulations are refused), NotIdentifiable when the joint problem is rank
/// deficient.
gear_sim::Status identifyWithSte(const gear_sim::SignalTable& table, const GearConstants& gear,
                                 const IdentificationOptions& options,
                                 const SteModelOptions& ste_options, IdentificationResult* result,
                                 SteResult* ste);

using SampleRanges = std::vector<std::pair<Eigen::Index, Eigen::Index>>;

/// identifyWithSte on the segments `ranges` of a checked view (every channel present and
/// finite; samples next to a range serve as quadrature stencils, as in the integral method).
gear_sim::Status identifySteSegments(const SignalView& view, const SampleRanges& ranges,
                                     const GearConstants& gear,
                                     const IdentificationOptions& options,
                                     const SteModelOptions& ste_options,
                                     IdentificationResult* result, SteResult* ste);

/// One segment [begin, end) of `view` with the STE held at `ste` (a calibration's result, with
/// theta_cov): C (and the greybox levels) fitted given the STE by the integral equations, refined
/// when options.refine asks for it by output error on the record with the STE taken out
/// (z = y - e, forcing F - e'' (- C e' for the dte form), docs/ste.md); C_std includes theta's
/// covariance propagated through dC/dtheta. Estimator `integral_ste_held` or
/// `output_error_ste_held`. NotIdentifiable when the segment cannot be fitted.
gear_sim::Status identifySegmentWithHeldSte(const SignalView& view, Eigen::Index begin,
                                            Eigen::Index end, const GearConstants& gear,
                                            const IdentificationOptions& options,
                                            const SteResult& ste, IdentificationResult* result);

/// Ok when the formulation, model and stiffness shape can be used with the STE, else
/// InvalidArgument naming the IdentificationOptions field (no option prefix).
gear_sim::Status checkSteOptions(const IdentificationOptions& options);
/// First sample of `view` with a non-finite channel the STE fit reads, or -1.
Eigen::Index nonFiniteSteInput(const SignalView& view, Formulation formulation);

}  // namespace gear_damping_id
