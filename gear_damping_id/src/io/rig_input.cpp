#include "gear_damping_id/rig_input.hpp"

#include <cmath>

#include "gear_sim/rig_csv.hpp"
#include "gear_sim/signal_csv.hpp"

namespace gear_damping_id {

bool isRigInput(const std::string& csv, const RigInputOptions& o) {
  return !o.edges1.empty() || !o.edges2.empty() || gear_sim::isRigCsv(csv);
}

gear_sim::Status loadRigInput(const std::string& csv, const RigInputOptions& o,
                              const gear_sim::GearModel& model, gear_sim::SignalTable* out,
                              EncoderFrontEndReport* report) {
  using gear_sim::Status;
  gear_sim::SignalTable rig;
  std::string resampling = "none (uniform input at the output rate)";
  if (o.edges1.empty() != o.edges2.empty())
    return Status::invalidArgument("edge times need both files (--edges1 and --edges2)",
                                   o.edges1.empty() ? "edges1" : "edges2");
  if (!o.edges1.empty()) {
    if (o.edge_counts1 <= 0 || o.edge_counts2 <= 0)
      return Status::invalidArgument(
          "edge times need the counts per revolution (--edge-counts N or N1,N2)", "edge_counts");
    gear_sim::SignalTable grid;
    if (Status s = gear_sim::readSignalCsv(csv, &grid, {"time", "torque"}); !s.ok()) return s;
    std::vector<double> e1, e2;
    if (Status s = gear_sim::readEdgeCsv(o.edges1, &e1); !s.ok()) return s;
    if (Status s = gear_sim::readEdgeCsv(o.edges2, &e2); !s.ok()) return s;
    if (Status s = edgesToRigTable(e1, o.edge_counts1, e2, o.edge_counts2, grid, &rig, &resampling);
        !s.ok())
      return s.withContext(o.edges1 + ", " + o.edges2);
  } else if (Status s = gear_sim::readRigCsv(csv, &rig); !s.ok()) {
    return s;
  }
  if (Status s = rigTableToSignalTable(rig, csv, o, model, out, report); !s.ok()) return s;
  if (report) report->resampling = resampling;
  return {};
}

gear_sim::Status rigTableToSignalTable(const gear_sim::SignalTable& rig, const std::string& name,
                                       const RigInputOptions& o, const gear_sim::GearModel& model,
                                       gear_sim::SignalTable* out, EncoderFrontEndReport* report) {
  if (gear_sim::Status s = encoderToSignalTable(rig, model, o.front_end, out, report); !s.ok())
    return s.withContext(name);
  if (report) report->resampling = "none (uniform input at the output rate)";
  return {};
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
