// The signals the identification reads and the gear constants it needs, in one place: the
// SignalView of a uniformly sampled record, GearConstants, and which channels each formulation
// and damping model requires. No ROS; SI units.
//
// Channels (docs/method.md §6): dte [m] (always), stiffness [N/m], torque [N*m], mesh_state [0/1],
// mesh_phase [mesh cycles]. Requirements:
//   known    stiffness, torque         greybox  mesh_state (square shape) or mesh_phase
//   paper    -                                  (fourier/table shapes, checked by the options),
//   legacy   - (torque for its mean forcing when present)            and torque
//   load_law model: torque, whatever the formulation.
#pragma once

#include <Eigen/Core>
#include <string>

#include "gear_damping_id/identification_types.hpp"
#include "gear_sim/option_status.hpp"
#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"
#include "gear_sim/status.hpp"

namespace gear_damping_id {

/// What the identification needs of the gear pair (from the simulator's YAML or the latched
/// GearParams message).
struct GearConstants {
  double equivalent_mass = kNaN;  ///< Me [kg]
  double force_factor = kNaN;     ///< R1/I1 + R2/I2 [1/(kg*m)]: F = force_factor * T1
  double contact_ratio = kNaN;    ///< eps [-]: switch phases n and n + eps - 1 (square model)
  double mean_stiffness = kNaN;   ///< [N/m] model time-mean stiffness
  /// true for the square and constant stiffness models. Informational: the identification
  /// decides held or smooth stiffness from the samples (forward_model.hpp), not from this flag.
  bool piecewise_constant_stiffness = true;
  gear_sim::OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// Constants of a gear model (validated GearModel).
GearConstants gearConstants(const gear_sim::GearModel& model);

/// Pointers into one contiguous, gap-free, uniformly sampled record: sample n at t0 + n*dt.
/// Optional channels are null when absent. Values are read, never written.
struct SignalView {
  double t0 = 0.0;  ///< [s]
  double dt = 0.0;  ///< [s]
  Eigen::Index n = 0;
  const double* dte = nullptr;         ///< [m] required
  const double* stiffness = nullptr;   ///< [N/m] held from each sample on (known)
  const double* torque = nullptr;      ///< [N*m] (known, greybox, load_law, legacy's mean)
  const double* mesh_state = nullptr;  ///< [0/1] (greybox)
  const double* mesh_phase = nullptr;  ///< [mesh cycles] locates switches between samples
  double time(Eigen::Index i) const { return t0 + static_cast<double>(i) * dt; }
  /// View of a table's columns (dt from the first and last time stamps).
  static SignalView of(const gear_sim::SignalTable& table);
};

/// Which optional channels a record holds (dte is always required).
struct ChannelSet {
  bool dte = true, stiffness = false, torque = false, mesh_state = false, mesh_phase = false;
  static ChannelSet of(const SignalView& view);
  static ChannelSet of(const gear_sim::SignalTable& table);
};

/// Channels a formulation / damping model needs.
bool needsStiffness(Formulation f);
bool needsTorque(Formulation f, DampingModel m);
bool needsMeshState(Formulation f);

/// Ok when `present` holds every channel `formulation`/`model` need (stiffness and torque for
/// known; mesh_state and torque for greybox; torque for load_law), else InvalidInput with the
/// first missing channel as Status::field() and the message "column 'x' is required by
/// formulation 'known' but missing" (or "by model 'load_law'").
gear_sim::Status checkChannels(const ChannelSet& present, Formulation formulation,
                               DampingModel model);
/// The same for a view (the integral method must not be given a view without them).
gear_sim::Status checkChannels(const SignalView& view, Formulation formulation, DampingModel model);

}  // namespace gear_damping_id
