#include "gear_damping_id/rig_input.hpp"

#include <cmath>

#include "gear_sim/rig_csv.hpp"
#include "gear_sim/signal_csv.hpp"

namespace gear_damping_id {

bool isRigInput(const std::string& csv, const RigInputOptions& o) {
  return !o.edges1.empty() || !o.edges2.empty() || gear_sim::isRigCsv(csv);
}

bool loadRigInput(const std::string& csv, const RigInputOptions& o,
                  const gear_sim::GearModel& model, gear_sim::SignalTable* out,
                  EncoderFrontEndReport* report, std::string* error) {
  gear_sim::SignalTable rig;
  std::string resampling = "none (uniform input at the output rate)";
  if (o.edges1.empty() != o.edges2.empty()) {
    *error = "edge times need both files (--edges1 and --edges2)";
    return false;
  }
  if (!o.edges1.empty()) {
    if (o.edge_counts1 <= 0 || o.edge_counts2 <= 0) {
      *error = "edge times need the counts per revolution (--edge-counts N or N1,N2)";
      return false;
    }
    gear_sim::SignalTable grid;
    if (!gear_sim::readSignalCsv(csv, &grid, error, {"time", "torque"})) return false;
    std::vector<double> e1, e2;
    if (!gear_sim::readEdgeCsv(o.edges1, &e1, error) ||
        !gear_sim::readEdgeCsv(o.edges2, &e2, error))
      return false;
    std::string e;
    if (!edgesToRigTable(e1, o.edge_counts1, e2, o.edge_counts2, grid, &rig, &resampling, &e)) {
      *error = o.edges1 + ", " + o.edges2 + ": " + e;
      return false;
    }
  } else if (!gear_sim::readRigCsv(csv, &rig, error)) {
    return false;
  }
  if (!rigTableToSignalTable(rig, csv, o, model, out, report, error)) return false;
  if (report) report->resampling = resampling;
  return true;
}

bool rigTableToSignalTable(const gear_sim::SignalTable& rig, const std::string& name,
                           const RigInputOptions& o, const gear_sim::GearModel& model,
                           gear_sim::SignalTable* out, EncoderFrontEndReport* report,
                           std::string* error) {
  std::string e;
  if (!encoderToSignalTable(rig, model, o.front_end, out, report, &e)) {
    *error = name + ": " + e;
    return false;
  }
  if (report) report->resampling = "none (uniform input at the output rate)";
  return true;
}

nlohmann::json toJson(const EncoderFrontEndReport& r) {
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  return {{"ratio_expected", num(r.ratio_expected)},
          {"ratio_measured", num(r.ratio_measured)},
          {"dte_offset", num(r.dte_offset)},
          {"dte_offset_estimated", r.dte_offset_estimated},
          {"mesh_offset", num(r.mesh_offset)},
          {"mesh_offset_estimated", r.mesh_offset_estimated},
          {"quantisation_noise_std", num(r.quantisation_noise_std)},
          {"noise_std", num(r.noise_std)},
          {"sample_rate", num(r.sample_rate)},
          {"samples", r.samples},
          {"resampling", r.resampling}};
}

}  // namespace gear_damping_id
