// libFuzzer target: the rig inputs (docs/rig.md). The first byte selects the path: even, a rig CSV
// (time, theta1, theta2, torque) through readRigCsv and the encoder front end (offline, and
// streamed in chunks whose sizes come from the input); odd, an edge-time file through
// readEdgeCsv and edgeTimesToAngles onto a grid across the edges. The rest is the file. Any
// crash, sanitizer report, leak or allocation beyond libFuzzer's limit is a finding.
#include <cstdint>
#include <string>
#include <vector>

#include "../test/unit/support/status_support.hpp"
#include "fuzz_support.hpp"
#include "gear_damping_id/encoder_frontend.hpp"
#include "gear_sim/rig_csv.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const std::string path = gear_fuzz::tempPath("rig");
  if (!gear_fuzz::writeFile(path, data + 1, size - 1)) return 0;
  std::string error;
  gear_sim::GearModel model;  // the Table 1 pair
  if ((data[0] & 1) == 0) {
    gear_sim::SignalTable rig;
    if (!gear_test::ok(gear_sim::readRigCsv(path, &rig), &error)) {
      gear_fuzz::checkMessage(error);
      return 0;
    }
    gear_damping_id::EncoderFrontEndOptions o;
    if (data[0] & 2) o.mesh_offset = 0.25, o.dte_offset = 0.0;  // skip the estimation
    o.refine_offset = false;
    gear_sim::SignalTable out;
    gear_damping_id::EncoderFrontEndReport report;
    if (!gear_test::ok(gear_damping_id::encoderToSignalTable(rig, model, o, &out, &report), &error))
      gear_fuzz::checkMessage(error);
    // Streamed, in chunks of 1 + data[0] / 4 samples.
    o.mesh_offset = 0.25, o.dte_offset = 0.0, o.calibration_samples = 16;
    gear_damping_id::EncoderFrontEnd fe(model, o);
    const Eigen::Index chunk = 1 + data[0] / 4;
    const bool torque = rig.torque.size() == rig.size();
    for (Eigen::Index b = 0; b < rig.size(); b += chunk) {
      const Eigen::Index n = std::min(chunk, rig.size() - b);
      if (!gear_test::ok(fe.push(1e6, static_cast<std::uint64_t>(b), rig.theta1.data() + b,
                                 rig.theta2.data() + b, torque ? rig.torque.data() + b : nullptr,
                                 static_cast<size_t>(n)),
                         &error)) {
        gear_fuzz::checkMessage(error);
        break;
      }
      std::uint64_t first;
      while (fe.pop(&out, &first)) {
      }
    }
  } else {
    std::vector<double> edges;
    if (!gear_test::ok(gear_sim::readEdgeCsv(path, &edges), &error)) {
      gear_fuzz::checkMessage(error);
      return 0;
    }
    if (edges.empty()) return 0;
    Eigen::VectorXd grid = Eigen::VectorXd::LinSpaced(32, edges.front(), edges.back());
    Eigen::VectorXd theta;
    if (!gear_test::ok(gear_damping_id::edgeTimesToAngles(edges, 1 + data[0] / 2, grid, &theta),
                       &error))
      gear_fuzz::checkMessage(error);
  }
  return 0;
}
