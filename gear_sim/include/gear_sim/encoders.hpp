// Simulated shaft encoders (docs/rig.md): what a test rig would record of a simulated gear pair.
// No ROS; SI units.
//
// The simulated state is the DTE y(t) and the prescribed rigid-body rotation (the speed profile:
// mesh phase u(t)). With g = Z1/Z2 the rigid pinion angle is Theta(t) = 2 pi (u(t) - u(0)) / Z1
// and the gear's g Theta. The dynamic twist is shared between the shafts so that the
// inertia-weighted angle (I1 theta1 + g I2 theta2) / (I1 + g^2 I2) stays Theta (the 2-DOF model's
// relative mode) and Rb1 d1 - Rb2 d2 = y:
//
//   theta1 = zero1 + Theta + g I2 y / (g I2 Rb1 + I1 Rb2)
//   theta2 = zero2 + g Theta - I1 y / (g I2 Rb1 + I1 Rb2)
//
// Quantised encoders read q floor(theta / q), q = 2 pi / counts. Edge times are the instants at
// which theta crosses k q (k integer), optionally rounded to a counter clock.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "gear_sim/option_status.hpp"
#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"

namespace gear_sim {

/// YAML section `encoder` (config/rig_example.yaml).
struct EncoderOptions {
  bool enabled = false;        ///< write theta1, theta2 as encoder angles (rig output)
  long counts_per_rev1 = 0;    ///< pinion encoder counts per revolution (0 = exact angle)
  long counts_per_rev2 = 0;    ///< gear encoder counts per revolution (0 = exact angle)
  double zero1 = 0.0;          ///< [rad] pinion encoder reading at the rigid zero
  double zero2 = 0.0;          ///< [rad] gear encoder reading at the rigid zero
  double torque_noise = 0.0;   ///< [N*m] white noise std on the torque output
  double edge_clock = 0.0;     ///< [Hz] counter clock of edge times (0 = exact times)
  unsigned long seed = 7;      ///< torque-noise generator seed
  OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// Angles of the (noise-free) simulated record `sim` (time, dte, and dte_velocity for the edge
/// times) as the encoders read them. `config` gives the gears, mesh phase and speed.
void encoderAngles(const SimConfig& config, const EncoderOptions& enc, const SignalTable& sim,
                   Eigen::VectorXd* theta1, Eigen::VectorXd* theta2);

/// The rig record: time, theta1, theta2 (encoder angles), torque (with torque_noise).
SignalTable rigRecord(const SimConfig& config, const EncoderOptions& enc, const SignalTable& sim);

/// Edge times [s] of shaft 1 (pinion) or 2 (gear) with `counts` per revolution within the record
/// (cubic Hermite interpolation of y between samples, Newton on theta(t) = k q). Exact angles;
/// times rounded to 1 / edge_clock when edge_clock > 0.
std::vector<double> encoderEdges(const SimConfig& config, const EncoderOptions& enc,
                                 const SignalTable& sim, int shaft, long counts);

}  // namespace gear_sim
