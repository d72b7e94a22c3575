// Outputs of the joint damping/STE identification (ste_model.hpp, docs/ste.md): the
// `identification.ste` JSON block and the `ste.csv` table. No ROS (nlohmann::json only).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "gear_damping_id/result_io.hpp"
#include "gear_damping_id/ste_model.hpp"

namespace gear_damping_id {

/// {"damping": "relative"|"dte", "offset": {value, std}, "mesh": [{order, cos, sin, cos_std,
/// sin_std, amplitude, phase}], "shaft": [{shaft: "pinion"|"gear", order, cos, sin, cos_std,
/// sin_std, amplitude, phase}], "condition", "max_correlation", "separable", "iterations",
/// "residual_rms", "shared": true}. Units: m, rad. Non-finite numbers become null.
nlohmann::json steJson(const SteResult& s);

/// Writes `dir`/ste.csv: kind,order,cos,sin,cos_std,sin_std,amplitude,phase (one row per term;
/// kind offset, mesh, pinion, gear). `dir` must exist. IoError when it cannot be written.
gear_sim::Status writeSteCsv(const std::string& dir, const SteResult& s,
                             OutputStage* stage = nullptr);

}  // namespace gear_damping_id
