// Rig record files (docs/rig.md): the uniform rig CSV `time, theta1, theta2, torque` and the
// edge-time files (one column `time`, one file per shaft). Part of gear_sim_io; no ROS.
#pragma once

#include <string>
#include <vector>

#include "gear_sim/signal_table.hpp"
#include "gear_sim/status.hpp"

namespace gear_sim {

/// Writes time, theta1, theta2 and (when present) torque, shortest round-trip text.
Status writeRigCsv(const std::string& path, const SignalTable& rig);

/// Reads a rig CSV: columns time, theta1, theta2 required, torque optional (the reader of
/// signal_csv.hpp: same checks and messages). A `dte` column makes it an ordinary record, not a
/// rig record: refused here.
Status readRigCsv(const std::string& path, SignalTable* out);

/// True when the CSV header names theta1 and theta2 and no dte (a rig record). False when the
/// header cannot be read (the reader then reports why).
bool isRigCsv(const std::string& path);

/// Edge-time file: header `time`, one edge instant [s] per row, strictly increasing.
Status writeEdgeCsv(const std::string& path, const std::vector<double>& edges);
Status readEdgeCsv(const std::string& path, std::vector<double>* edges);

}  // namespace gear_sim
