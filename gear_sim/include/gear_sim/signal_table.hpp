// The signal table of docs/method.md §6: uniformly sampled gear-pair signals, one column per
// channel. This is the type the simulator produces, the CSV/bag readers fill and the identification
// and wavelet cores consume. No ROS; SI units.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "gear_sim/status.hpp"

namespace gear_sim {

/// Columns of the docs/method.md §6 CSV. `time` and `dte` are required; every other column is
/// either empty (absent) or exactly as long as `time`.
///
/// Sample-and-hold convention: a sampled `stiffness` or `mesh_state` value is the one holding
/// from that sample's instant on (until the next switch). `mesh_phase` is continuous and locates
/// switch instants between samples (a switch happens where the phase crosses n or n + (eps - 1)
/// for the square-wave model).
struct SignalTable {
  Eigen::VectorXd time;          ///< [s] strictly increasing, uniform within tolerance
  Eigen::VectorXd dte;           ///< [m] y = R1*theta1 - R2*theta2
  Eigen::VectorXd dte_velocity;  ///< [m/s] optional (simulation)
  Eigen::VectorXd stiffness;     ///< [N/m] optional, k holding from each sample's instant on
  Eigen::VectorXd torque;        ///< [N*m] optional, pinion torque T1
  Eigen::VectorXd mesh_state;    ///< [0/1] optional, 1 while the stiffer phase holds
  Eigen::VectorXd mesh_phase;    ///< [mesh cycles] optional, cumulative, continuous
  Eigen::VectorXd damping;       ///< [N*s/m] optional, true c(t) (simulation)
  Eigen::VectorXd theta1;        ///< [rad] optional, pinion angle (torsional model)
  Eigen::VectorXd theta2;        ///< [rad] optional, gear angle (torsional model)

  Eigen::Index size() const { return time.size(); }
  static bool has(const Eigen::VectorXd& column) { return column.size() > 0; }
};

/// Physical plausibility ranges of a record's channels (magnitudes, SI units): a DTE of a metre,
/// a stiffness of 1e13 N/m or a torque of 1e9 N*m is a corrupt value, not a gear. The record
/// readers read a value outside its channel's range as NaN (a bag's chunks as they are read, a
/// CSV record in `analyze` through maskImplausible), so its segment is reported as not
/// identifiable instead of giving an absurd estimate.
struct PlausibleRange {
  const char* channel;
  double low, high;
};
constexpr PlausibleRange kPlausibleRanges[] = {
    {"dte", -1.0, 1.0},
    {"dte_velocity", -1e4, 1e4},
    {"stiffness", 0.0, 1e13},
    {"torque", -1e9, 1e9},
    {"mesh_phase", -9.007199254740992e15, 9.007199254740992e15},
    {"damping", -1e9, 1e9}};

/// Counts of a record's implausible values.
struct ImplausibleCounts {
  std::int64_t non_finite = 0;       ///< NaN/Inf values of the ranged channels and mesh_state
  std::int64_t out_of_range = 0;     ///< finite values outside their channel's range
  std::int64_t bad_mesh_states = 0;  ///< finite mesh_state values other than 0 or 1
};

/// Reads as NaN the values of `table`'s ranged channels (kPlausibleRanges) outside their range
/// and the mesh_state values other than 0 or 1, and counts them; the NaN/Inf values already there
/// are counted as non-finite. The time, theta1 and theta2 columns are left as they are.
ImplausibleCounts maskImplausible(SignalTable* table);

/// One warning line per non-zero count of `counts` (the bag reader's and `analyze`'s wording);
/// `where` says where the NaN/Inf values were found ("in the chunks", "in the file").
std::vector<std::string> implausibleWarnings(const ImplausibleCounts& counts,
                                             const std::string& where);

/// Time stamps are doubles: near |t| = t_abs_max they are resolved to one unit in the last place,
/// ulp(t_abs_max) (1.2e-10 s near 1e6 s). A check of uniform steps cannot ask for more than that.
double timeResolution(double t_abs_max);

/// Ok while the time stamps (the largest |t| is t_abs_max) resolve the sampling step to 1/1000 or
/// finer; otherwise invalid input ("time") naming both and asking for the time to be re-based
/// (a bag's first_index, a CSV's time column, nearer to 0). Every reader applies this one rule,
/// so a record is accepted or refused the same way whole, streamed or converted.
Status checkTimeResolution(double t_abs_max, double step);

/// The tolerance of one step against the reference step: rel_tolerance * step, widened to the
/// rounding of the stamps (3 ulps of t_abs_max: the two stamps and the reference step).
double stepTolerance(double rel_tolerance, double step, double t_abs_max);

}  // namespace gear_sim
