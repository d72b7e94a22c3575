// The generalised integral method of docs/method.md §4 (paper §3): least-squares identification of
// the damping of
//
//     y'' + C(t) y' + K(t) y = F(t)                                            (eq. 4)
//
// from the sampled DTE y. Integrating eq. (4) twice from the start T of an integration window to
// t gives, for every sample t of the window,
//
//     y(t) = y_T + alpha (t - T) - C P(t) - IIKy(t) + IIF(t)
//     P(t) = int_T^t y,  IIKy(t) = int_T^t int_T^s K y,  IIF(t) = int_T^t int_T^s F,
//     alpha = y'(T) + C(T) y(T)
//
// which is linear in the unknowns. Each window has its own nuisance unknowns (y_T, alpha); each
// damping segment of length dT holds one or more windows sharing its damping. The formulations
// differ in what is known of K and F (every unknown below is constant on the set named):
//
//   known    b = y + IIKy - IIF;     columns -P [C]                        K, F known series
//   greybox  b = y - IIF;            columns -P [C], -IIy [K0], -IIsy [dK]  K = K0 + dK s(t),
//                                     s = mesh state (0/1) known, K0, dK unknown per segment
//   paper    b = y;                  columns -P [C], -IIy [K_i], (t-T)^2/2 [F_i]  per segment
//                                     (paper eqs. 11-16 as printed)
//   legacy   b = y - Fbar (t-T)^2/2; columns -P [C], -IIy [K] with one K for the whole record
//                                     and Fbar the record-mean forcing (the constant-load method
//                                     that the paper's §4.1 shows failing)
//
// and the damping models in what C(t) is:
//   piecewise  C_i per segment;  constant  one C for all segments;
//   load_law   C(t) = theta0 + theta1 T1(t), i.e. c(t) = c0 + c1 T1(t) with c = C Me. For a
//              time-varying C the damping term integrates by parts to
//              int_T^t int_T^s C y' = theta0 (P - y_T (t-T)) + theta1 (T_c (P - y_T (t-T)) + D_r)
//              with T_c = T1(T) and D_r = int int (T1 - T_c) dy (Stieltjes trapezoid; T1 - T_c is
//              small within a window, so its second-order error is negligible); the y_T terms are
//              absorbed by alpha, so alpha = y'(T) + C(T) y_T as before.
//
// Greybox stiffness shapes (IdentificationOptions::stiffness_shape): square uses the mesh state as
// above; fourier:H and table:N replace the two stiffness columns by one column -IIb_j(u) y per
// basis function b_j of the mesh phase u (2H+1 or N unknowns per segment), K y integrated as a
// smooth product of the samples.
//
// Quadrature (see quadrature.hpp): the samples are interpolated by local cubics and integrated
// exactly. Held or smooth stiffness is decided from each segment's samples, and the breaks of
// the data (switches of a held K or s, jumps and kinks of a smooth K: forward_model.hpp) are
// located from `mesh_phase` or from the samples; the interval holding a break is split there
// (each part with its own K, integrated by the cubic of the samples on its side) and no stencil
// reaches across a break. This keeps the method fourth-order accurate up to the breaks, and the
// refinement's forward model integrates the same K(t).
//
// Solution (numerically sound without forming the full design matrix): within each window the
// nuisance columns 1 and (t - T) are removed exactly by projecting every data column onto the
// orthogonal complement of the discrete orthogonal polynomials {1, t - tbar}, in a second pass over
// the window's cached rows (modified Gram-Schmidt = the first two Householder steps of a QR of the
// window's design matrix, so no cancellation between large trend terms). What remains per segment
// is a tiny Gram matrix of the projected columns (1-3 local + 0-2 shared unknowns). It is
// equilibrated (unit diagonal) and factored by a symmetric eigendecomposition, which gives both
// the solution and the 2-norm condition number used for the identifiability check; squaring the
// condition of an equilibrated <= 5-column problem whose condition is checked to be <=
// max_condition (default 1e6) leaves >= 4 significant digits in the worst accepted case and
// ~12 on the default case (cond ~ 1e2). A test checks the result against a column-pivoting
// Householder QR of the explicit full design matrix. Shared unknowns (constant, load_law, legacy
// K) are found by eliminating each segment's local unknowns (Schur complement), so the method
// streams over segments with memory bounded by one segment.
//
// Standard errors: the least-squares covariance sigma^2 (X^T X)^-1 of the reduced problem (which
// equals that of the full problem including nuisance unknowns), sigma^2 = RSS / (rows - unknowns),
// per segment for segment-local unknowns and pooled for shared ones. They describe the equation
// error of the integral equations; with measurement noise the integral method is biased (noise
// enters the regressors) and the output-error refinement (output_error.hpp) supplies the
// maximum-likelihood estimate and honest standard errors.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/quadrature.hpp"
#include "gear_damping_id/signal_view.hpp"
#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"
#include "gear_sim/status.hpp"

namespace gear_damping_id {

/// Checks that `table` can be analysed: the channels `formulation`/`model` need present (names the
/// missing column), every present stiffness, torque, mesh_state and mesh_phase column as long as
/// the time column, needed or not (names the column and both lengths), and a uniform time step
/// within `rel_tolerance` of the sampling step (names the first offending sample, and its file line
/// `first_line + sample` when `first_line` >= 0, e.g. 2 for a CSV with one header line). Non-finite
/// values are not an error here: the segments that hold them are reported as not identifiable. Ok
/// when fine, else InvalidInput with the column concerned as Status::field() ("time" for the time
/// axis).
gear_sim::Status checkSignalTable(const gear_sim::SignalTable& table, Formulation formulation,
                                  DampingModel model, double rel_tolerance = 1e-6,
                                  Eigen::Index first_line = -1);

/// checkSignalTable (without file lines) and, when options.window_length is 0, the default window
/// of defaultWindowLength in one pass over the time and stiffness columns, in blocks shared by
/// up to `threads` threads (the same results for any count). *window_length receives the window
/// (options.window_length when set) when the check passes.
gear_sim::Status checkRecord(const gear_sim::SignalTable& table, const GearConstants& gear,
                             const IdentificationOptions& options, int threads,
                             double* window_length);

/// The sample ranges of the damping segments of [t_start, t_end] within a record: segment i starts
/// at the first sample at or after t_start + i*dT. A final partial segment shorter than half dT
/// is merged into the previous one. Returns pairs [begin, end) of sample indices.
std::vector<std::pair<Eigen::Index, Eigen::Index>> segmentRanges(const SignalView& signal,
                                                                 const IdentificationOptions& o);

/// Default integration window [s]: two natural periods 2 * 2 pi / sqrt(Kbar), Kbar the mean
/// normalised stiffness: the mean of the finite stiffness samples among the record's first
/// gear_sim::kWindowPrefixSamples (all of a record that short; summed as a bag's scan sums them
/// beyond that, so a bag read whole, streamed or in one pass gets the same window), else the gear
/// model's mean stiffness.
double defaultWindowLength(const SignalView& signal, const GearConstants& gear);

/// The streaming integral method. Feed the damping segments in time order with addSegment (the
/// node does so as data arrives, `analyze` over a whole record); finish() solves the shared
/// unknowns and returns the result. Memory: one segment's rows plus a few numbers per window.
class IntegralMethod {
 public:
  /// Most columns of the least-squares rows (unknowns of one problem).
  static constexpr int kMaxColumns = 2 + 2 * StiffnessShape::kMaxHarmonics + 1;

  /// `options` and `gear` must be valid (check()); window_length 0 is resolved by the caller
  /// (defaultWindowLength) or, if still 0 at the first segment, from that segment's data.
  IntegralMethod(const IdentificationOptions& options, const GearConstants& gear);

  /// Processes samples [begin, end) of `signal` as one damping segment (samples begin - 1 and
  /// end, when inside the view, serve the interpolation stencils only). Returns the segment's
  /// estimate: final for the piecewise model; for shared-damping models a provisional estimate
  /// of the segment alone is not formed, and the segment reports identifiable = true with NaN C
  /// until finish(). A segment with NaN/Inf input, too few samples or no motion is reported as
  /// not identifiable with the reason, and takes no part in shared estimates.
  /// With `estimate` false the piecewise estimate is not formed here (C stays NaN until
  /// finish()): for callers that call finish() anyway, such as identify().
  SegmentEstimate addSegment(const SignalView& signal, Eigen::Index begin, Eigen::Index end,
                             bool estimate = true);

  /// Solves the shared unknowns and fills every estimate. Can be called repeatedly (e.g. for a
  /// cumulative live estimate); later addSegment calls continue the same problem.
  IdentificationResult finish() const;

  /// Forgets every segment (keeps options, constants and the window length).
  void reset();

  /// Legacy formulation: the mean forcing Fbar = force_factor * mean(T1) [m/s^2] of the analysed
  /// record. When never set (no torque channel), Fbar is an extra shared unknown.
  void setLegacyForcing(double fbar);

  const IdentificationOptions& options() const { return options_; }
  /// Effective integration window [s] (0 until resolved by the first segment).
  double windowLength() const { return window_length_; }
  size_t segmentCount() const { return segments_.size(); }
  /// Stiffness switches that mesh_phase could not locate so far (values held from the sample).
  long unlocatedSwitches() const { return unlocated_switches_; }
  /// Appends the segments of `later` (same options and constants, segments after this one's):
  /// lets segments be accumulated by several objects in parallel (SegmentDriver) with the result
  /// of one object fed them all in order.
  void append(IntegralMethod&& later);

 private:
  // StiffBasis: the greybox fourier/table shape's unknowns, StiffnessShape::unknowns() adjacent
  // columns; every other kind appears at most once.
  enum class Column { DampC, DampLoad, StiffK0, StiffDK, ForceConst, StiffBasis };
  struct WindowRecord {
    double t_start = 0, t_end = 0, dt = 0;  // [s]
    Eigen::Index rows = 0;
    double torque_T = kNaN;                               // T1 at the window start (load law)
    std::array<double, kMaxColumns + 1> mean{}, slope{};  // per column and b: mean, p1 coeff.
  };
  struct SegmentRecord {
    SegmentEstimate estimate;
    Eigen::MatrixXd gram;  // (q+1)x(q+1) projected Gram over [locals, shared, b]
    long rows = 0;
    int windows = 0;
    double mean_torque = kNaN;
    double mean_state = kNaN;        // time-mean of the mesh state (greybox)
    double k_integral = 0.0;         // integral of K over the segment [1/s] (known: for omega0)
    double duration = 0.0;           // [s]
    std::vector<double> basis_mean;  // time-means of the shape's basis functions (greybox)
    std::vector<WindowRecord> window_records;
    // The local block's solve from addSegment's identifiability check, reused by finish()
    // (empty without local unknowns): its inverse and the locals without shared unknowns.
    Eigen::MatrixXd local_inverse;
    Eigen::VectorXd local_solution;
    // Exchanges the heap buffers (gram, window records, local solve) with o's: reset() keeps
    // its last record's for the next addSegment, which overwrites every value it reads (the
    // local solve's only when solveLocals succeeds, the only case in which it is read).
    void swapBuffers(SegmentRecord* o) {
      gram.swap(o->gram);
      window_records.swap(o->window_records);
      local_inverse.swap(o->local_inverse);
      local_solution.swap(o->local_solution);
    }
  };

  void buildColumns();
  int columnIndex(Column c) const { return column_index_[static_cast<size_t>(c)]; }
  void windowRows(const SignalView& s, Eigen::Index w0, Eigen::Index w1, double fbar);
  IdentificationResult finishRange(size_t s_begin, size_t s_end) const;
  // What the segment's first read of its samples (checkFiniteInputs) leaves for segmentMeans:
  // the channel sums, and the fused loop's work on the samples before `end` (a sample of the
  // record; the segment's begin when the loop did not run).
  struct FirstTouch {
    double sum[4] = {0, 0, 0, 0};  // dte, stiffness, torque, mesh_state (channels read)
    double d3[4] = {0, 0, 0, 0};   // the DTE's third differences: segmentLevels' accumulators
    const double* held = nullptr;  // the channel searched for held changes (nullptr: none;
                                   // the blocks with a change: held_blocks_)
    Eigen::Index end = 0;
  };
  // addSegment's named steps (integral_method.cpp): each returns ok when the segment may go on,
  // else NotIdentifiable saying why (the segment's reason).
  gear_sim::Status checkFiniteInputs(const SignalView& s, Eigen::Index begin, Eigen::Index end,
                                     FirstTouch* touch);
  // The channel whose breaks the segment's quadrature splits at (nullptr: none): the stiffness
  // (known) or the greybox square's mesh state.
  const double* breakChannel(const SignalView& s) const;
  gear_sim::Status segmentMeans(const SignalView& s, Eigen::Index begin, Eigen::Index end,
                                const FirstTouch& touch, SegmentRecord* rec);
  double accumulateWindows(const SignalView& s, Eigen::Index begin, long rows, int windows,
                           SegmentRecord* rec);
  gear_sim::Status solveLocals(SegmentRecord* rec) const;
  // finishRange's named steps (integral_method.cpp).
  struct SharedSolution;
  struct SegmentParams;
  SharedSolution solveShared(size_t s_begin, size_t s_end) const;
  std::vector<SegmentParams> segmentParams(size_t s_begin, size_t s_end, const SharedSolution& sh,
                                           double* omega0) const;
  SegmentEstimate segmentEstimate(const SegmentRecord& rec, const SegmentParams& p,
                                  const SharedSolution& sh, double omega0,
                                  std::vector<WindowEstimate>* windows) const;
  void stiffnessEstimate(const SegmentParams& p, SegmentEstimate* e) const;
  void sharedSummaries(const SharedSolution& sh, double omega0, IdentificationResult* res) const;

  IdentificationOptions options_;
  GearConstants gear_;
  double window_length_ = 0.0;
  CubicRules rules_;
  int n_local_ = 0, n_shared_ = 0;
  std::vector<Column> columns_;        // locals first, then shared
  std::array<int, 6> column_index_{};  // per Column: its first index in columns_, or -1
  std::vector<SegmentRecord> segments_;
  SegmentRecord spare_;   // reset()'s last record's buffers (swapBuffers), for addSegment
  Eigen::MatrixXd rows_;  // one window's rows (scratch, reused)
  Eigen::MatrixXd inc_;   // one window's per-interval increments (scratch)
  std::vector<QuadratureBreak> breaks_;   // current segment's breaks (forward_model.hpp)
  std::vector<Eigen::Index> changes_;     // current segment: intervals where a held value changes
  std::vector<long> held_blocks_;         // current segment: FirstTouch's blocks with a change
  bool held_k_ = false;                   // current segment's known stiffness is held
  bool shape_ = false;                    // greybox fourier/table stiffness shape
  int n_basis_ = 0;                       // its unknowns
  Eigen::MatrixXd basis_;                 // current segment: basis values, one column per sample
  Eigen::MatrixXd basis_inc_;             // one window's per-interval basis increments (scratch)
  double legacy_fbar_ = kNaN;             // [m/s^2]
  Eigen::Index seg_lo_ = 0, seg_hi_ = 0;  // current segment's samples (quadrature stencils)
  mutable long unlocated_switches_ = 0;
};

/// The run warning for `count` switches that mesh_phase could not locate.
QualityWarning switchesUnlocatedWarning(long count);

/// Identifies the damping over a whole table (segments of options.segment_length, window
/// options.window_length or the default) in one call, through the segment driver
/// (segment_driver.hpp, which defines it): the batch run. `threads` workers identify segments in
/// parallel (same result as one). A failed Status names the problem: InvalidArgument for an
/// invalid option (its field), InvalidInput for a missing column or non-uniform time (the
/// column), NotIdentifiable when no sample lies in the analysed range.
gear_sim::Status identify(const gear_sim::SignalTable& table, const GearConstants& gear,
                          const IdentificationOptions& options, IdentificationResult* result,
                          int threads = 1);

}  // namespace gear_damping_id
