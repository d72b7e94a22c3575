// rosrun gear_damping convert --input IN.csv|IN.bag --output OUT.bag|OUT.csv
//     [--params GEAR.yaml] [--topic T] [--chunk-size N]
//
// Converts a signal record between the CSV of docs/method.md §6 and a bag of
// gear_damping/SignalChunk messages (rig data from a DAQ becomes a bag and back). CSV -> bag: the
// sample rate comes from the time column (uniform within 1e-6 relative), the gear parameters
// (--params) are written as a GearParams message when given. Bag -> CSV: gaps are written as NaN
// rows (a warning counts them). Exit codes: 0 success, 1 invalid command line, 2 invalid input
// (also beyond the limits of README "Limits", or times a bag cannot stamp), 3 output not written, 4
// internal error (an exception, out of memory included; message on stderr). A rig CSV (time,
// theta1, theta2, torque; docs/rig.md) becomes a bag of sensor_msgs/JointState (/rig/joint_states)
// and geometry_msgs/WrenchStamped (/rig/torque).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "gear_sim/config_yaml.hpp"
#include "gear_sim/message_text.hpp"
#include "gear_sim/rig_csv.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim/tool_main.hpp"
#include "gear_sim_ros/bag_io.hpp"
#include "gear_sim_ros/rig_bag_io.hpp"

namespace {

constexpr int kExitUsage = 1, kExitInput = 2, kExitOutput = 3, kExitInternal = 4;

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

int fail(int code, const std::string& message) {
  std::cerr << "convert: " << message << "\n";
  return code;
}
// A failed step exits with the step's code (reading: kExitInput, writing: kExitOutput),
// whatever the StatusCode (docs/limits.md "Exit codes").
int fail(int code, const gear_sim::Status& s) { return fail(code, s.message()); }

}  // namespace

int run(int argc, char** argv) {
  CLI::App app{"Convert a gear signal record between CSV (docs/method.md §6 columns) and a bag."};
  std::string input, output, params, topic;
  long chunk_size = 1000;
  app.add_option("--input", input, "IN.csv or IN.bag")->required()->check(CLI::ExistingFile);
  app.add_option("--output", output, "OUT.bag or OUT.csv (the other format)")->required();
  app.add_option("--params", params, "CSV -> bag: gear parameters YAML to store as GearParams")
      ->check(CLI::ExistingFile);
  app.add_option("--topic", topic, "bag input: the SignalChunk topic (default: the only one)");
  app.add_option("--chunk-size", chunk_size, "CSV -> bag: samples per chunk (default 1000)")
      ->check(CLI::Range(1L, gear_sim_ros::kMaxChunkSize));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : kExitUsage;
  }
  const bool to_bag = endsWith(input, ".csv") && endsWith(output, ".bag");
  const bool to_csv = endsWith(input, ".bag") && endsWith(output, ".csv");
  if (!to_bag && !to_csv)
    return fail(kExitUsage, "convert .csv to .bag or .bag to .csv (got " +
                                gear_sim::quoteForMessage(input) + " -> " +
                                gear_sim::quoteForMessage(output) + ")");
  gear_sim::SignalTable table;
  if (to_bag) {
    gear_sim::GearModel model;
    if (!params.empty())
      if (const gear_sim::Status s = gear_sim::loadGearModelFile(params, &model); !s.ok())
        return fail(kExitInput, s);
    if (gear_sim::isRigCsv(input)) {
      // A rig record (time, theta1, theta2, torque; docs/rig.md): a bag of JointState and
      // WrenchStamped messages, one per sample, as a rig's drivers would record it.
      if (const gear_sim::Status s = gear_sim::readRigCsv(input, &table); !s.ok())
        return fail(kExitInput, s);
      if (table.torque.size() != table.size())
        return fail(kExitInput, input + ": a rig bag needs the torque column");
      if (const gear_sim::Status s =
              gear_sim_ros::writeRigBag(output, table, params.empty() ? nullptr : &model, {});
          !s.ok())
        return fail(kExitOutput, s);
      std::cerr << "convert: " << table.size() << " rig samples " << input << " -> " << output
                << " (/rig/joint_states, /rig/torque)\n";
      return 0;
    }
    if (const gear_sim::Status s = gear_sim::readSignalCsv(input, &table, {"time", "dte"}, true);
        !s.ok())
      return fail(kExitInput, s);
    const Eigen::Index n = table.size();
    const double dt = (table.time[n - 1] - table.time[0]) / static_cast<double>(n - 1);
    const double t_abs_max = std::max(std::abs(table.time[0]), std::abs(table.time[n - 1]));
    if (const gear_sim::Status s = gear_sim::checkTimeResolution(t_abs_max, dt); !s.ok())
      return fail(kExitInput, input + ": " + s.message());
    const double tol = gear_sim::stepTolerance(1e-6, dt, t_abs_max);
    for (Eigen::Index i = 1; i < n; ++i) {
      const double d = table.time[i] - table.time[i - 1];
      if (std::abs(d - dt) > tol)
        return fail(kExitInput, input + ": time is not uniformly sampled at line " +
                                    std::to_string(i + 2) + " (step " + gear_sim::formatNumber(d) +
                                    " s, mean step " + gear_sim::formatNumber(dt) +
                                    " s): a bag needs a uniform sample rate");
    }
    if (const gear_sim::Status s = gear_sim_ros::checkBagTimes(table, 1.0 / dt); !s.ok())
      return fail(kExitInput, s.withContext(input));
    if (const gear_sim::Status s = gear_sim_ros::writeSignalBag(
            output, table, 1.0 / dt, params.empty() ? nullptr : &model, chunk_size);
        !s.ok())
      return fail(kExitOutput, s);
  } else {
    gear_sim_ros::BagSignalInfo info;
    if (const gear_sim::Status s = gear_sim_ros::scanSignalBag(input, topic, &info); !s.ok())
      return fail(kExitInput, s);
    for (const auto& w : info.warnings) std::cerr << "convert: warning: " << w << "\n";
    if (const gear_sim::Status s = gear_sim_ros::readSignalBag(info, &table); !s.ok())
      return fail(kExitInput, s);
    if (const gear_sim::Status s = gear_sim::writeAtomically(
            output, [&](const std::string& p) { return gear_sim::writeSignalCsv(p, table); });
        !s.ok())
      return fail(kExitOutput, s);
  }
  std::cerr << "convert: " << table.size() << " samples " << input << " -> " << output << "\n";
  return 0;
}

int main(int argc, char** argv) {
  return gear_sim::runToolMain("convert", kExitInternal, [&] { return run(argc, argv); });
}
