// The load step of rig records for `analyze` (docs/rig.md): a rig CSV (time, theta1, theta2,
// torque) or edge-time files are read and passed through the encoder front end, giving the
// analysable table (time, dte, torque, stiffness, mesh_state, mesh_phase). Part of
// gear_damping_id_io; no ROS.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "gear_damping_id/encoder_frontend.hpp"
#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"

namespace gear_damping_id {

struct RigInputOptions {
  std::string edges1, edges2;  ///< edge-time files of the pinion and the gear (empty: uniform)
  long edge_counts1 = 0, edge_counts2 = 0;  ///< counts per revolution of the edge records
  EncoderFrontEndOptions front_end;
};

/// True when `csv` is a rig record (theta1, theta2 and no dte in its header) or edge files are set.
bool isRigInput(const std::string& csv, const RigInputOptions& options);

/// Reads the rig record `csv` (uniform: time, theta1, theta2, torque; with edge files: the
/// torque file time, torque giving the time grid) and runs the front end. A failed Status names
/// the file and the reason (a refused record says why it is not a gear pair).
gear_sim::Status loadRigInput(const std::string& csv, const RigInputOptions& options,
                              const gear_sim::GearModel& model, gear_sim::SignalTable* out,
                              EncoderFrontEndReport* report);

/// A rig table already read (time, theta1, theta2, torque; e.g. from a rig bag) through the
/// front end; `name` prefixes the message.
gear_sim::Status rigTableToSignalTable(const gear_sim::SignalTable& rig, const std::string& name,
                                       const RigInputOptions& options,
                                       const gear_sim::GearModel& model, gear_sim::SignalTable* out,
                                       EncoderFrontEndReport* report);

/// The report as JSON (`input.encoder` of the result).
nlohmann::json toJson(const EncoderFrontEndReport& report);

}  // namespace gear_damping_id
