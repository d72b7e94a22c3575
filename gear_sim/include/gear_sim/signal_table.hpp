// The signal table of docs/method.md §6: uniformly sampled gear-pair signals, one column per
// channel. This is the type the simulator produces, the CSV/bag readers fill and the identification
// and wavelet cores consume. No ROS; SI units.
#pragma once

#include <Eigen/Core>
#include <string>

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

}  // namespace gear_sim
