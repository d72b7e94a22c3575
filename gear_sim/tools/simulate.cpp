// rosrun gear_damping simulate --config FILE.yaml [--duration S] [--sample-rate HZ]
//     [--noise-snr DB] [--seed N] [--chunk-size N] --output OUT.csv|OUT.bag
//
// Simulates the gear pair described by FILE.yaml (README "Simulator configuration") and writes
// the docs/method.md §6 CSV (with --free-response: the free decay of the same case, see below), or
// a bag with gear_damping/SignalChunk messages on /gear/signal and the gear parameters
// (gear_damping/GearParams) on /gear/params. Exit codes: 0 success, 1 invalid input (message on
// stderr naming the key/option; also a bad command line and a run beyond the size limits of README
// "Limits"), 2 output could not be written, 3 internal error (an exception, out of memory included;
// message on stderr).
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <optional>

#include "gear_sim/config_yaml.hpp"
#include "gear_sim/encoder_yaml.hpp"
#include "gear_sim/encoders.hpp"
#include "gear_sim/message_text.hpp"
#include "gear_sim/progress.hpp"
#include "gear_sim/rig_csv.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim/tool_main.hpp"
#include "gear_sim_ros/bag_io.hpp"
#include "gear_sim_ros/rig_bag_io.hpp"

namespace {

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// The command line.
struct Options {
  std::string config_path, output;
  std::optional<double> duration, sample_rate, snr;
  std::optional<unsigned long> seed;
  long chunk_size = 1000;
  bool free_response = false;
  bool rig = false;  // rig output (docs/rig.md): what shaft encoders and a torque meter record
  std::string edges_prefix;
  std::optional<long> counts;
  bool no_output = false;
};

// Each step returns an exit code: kContinue to go on, else what run() returns. A failed Status
// exits with the code of its step: reading the configuration and simulating are invalid input,
// writing is the output (docs/limits.md "Exit codes").
constexpr int kContinue = -1, kExitInput = 1, kExitOutput = 2;

int parse(int argc, char** argv, Options* o) {
  CLI::App app{"Simulate a spur gear pair (Yousfi et al. 2022) and write its DTE and signals."};
  app.add_option("--config", o->config_path, "YAML configuration (see config/table1.yaml)")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--output", o->output, "output file: .csv (docs/method.md §6 columns) or .bag")
      ->required();
  app.add_option("--duration", o->duration, "override simulation.duration [s]");
  app.add_option("--sample-rate", o->sample_rate, "override simulation.sample_rate [Hz]");
  app.add_option("--noise-snr", o->snr, "override simulation.noise_snr_db [dB] (inf = no noise)");
  app.add_option("--seed", o->seed, "override simulation.seed");
  app.add_option("--chunk-size", o->chunk_size, "samples per SignalChunk in a bag (default 1000)")
      ->check(CLI::Range(1L, gear_sim_ros::kMaxChunkSize));
  app.add_flag("--free-response", o->free_response,
               "write the free (homogeneous) response y'' + C y' + K y = 0 of the case instead: "
               "the difference of two runs, from the static deflection under the mean load and "
               "from the configured initial state (the start-up transient without the forced "
               "part; what the wavelet validation needs, docs/wavelet.md)");
  app.add_flag("--rig", o->rig,
               "write the rig record instead (also when the YAML says encoder.enabled: true): "
               "CSV columns time, theta1, theta2, torque, or a bag of sensor_msgs/JointState "
               "(/rig/joint_states, joints pinion_joint, gear_joint) and "
               "geometry_msgs/WrenchStamped (/rig/torque, torque.z) messages, one per sample; "
               "the encoder section sets quantisation, zeros and torque noise");
  app.add_option("--edges", o->edges_prefix,
                 "also write the encoders' edge times to PREFIX1.csv and PREFIX2.csv (column "
                 "time; counts per revolution from encoder.counts_per_rev1/2 or --counts-per-rev)");
  app.add_option("--counts-per-rev", o->counts,
                 "override encoder.counts_per_rev1 and 2 (0 = exact angles)")
      ->check(CLI::Range(0L, 1L << 40));
  app.add_flag("--quiet,-q", o->no_output, "no progress line and no closing note on stderr");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 1;  // --help is 0; every CLI11 error is invalid input
  }
  if (!endsWith(o->output, ".csv") && !endsWith(o->output, ".bag")) {
    std::cerr << "simulate: --output " << gear_sim::quoteForMessage(o->output)
              << ": must end in .csv or .bag\n";
    return 1;
  }
  return kContinue;
}

// The configuration and the encoder section, with the command line's overrides.
int load(Options* o, gear_sim::SimConfig* c, gear_sim::EncoderOptions* enc) {
  gear_sim::Status s = gear_sim::loadSimConfigFile(o->config_path, c);
  if (s.ok()) s = gear_sim::loadEncoderOptionsFile(o->config_path, enc);
  if (!s.ok()) {
    std::cerr << "simulate: " << s.message() << "\n";
    return kExitInput;
  }
  if (o->counts) enc->counts_per_rev1 = enc->counts_per_rev2 = *o->counts;
  o->rig = o->rig || enc->enabled;
  if (o->rig && o->free_response) {
    std::cerr << "simulate: --rig and --free-response exclude each other\n";
    return 1;
  }
  if (!o->edges_prefix.empty() && (enc->counts_per_rev1 <= 0 || enc->counts_per_rev2 <= 0)) {
    std::cerr << "simulate: --edges needs counts per revolution (encoder.counts_per_rev1/2 or "
                 "--counts-per-rev)\n";
    return 1;
  }
  if (o->duration) c->simulation.duration = *o->duration;
  if (o->sample_rate) c->simulation.sample_rate = *o->sample_rate;
  if (o->snr) c->simulation.noise_snr_db = *o->snr;
  if (o->seed) c->simulation.seed = *o->seed;
  return kContinue;
}

// The case's record, or with --free-response its free decay: eq. (4) is linear in y, so two
// runs differing only in the initial state differ by exactly the free response. Noise, if
// configured, is left out of the difference and added once.
int simulateCase(const Options& o, const gear_sim::SimConfig& c, gear_sim::ProgressBar* progress,
                 gear_sim::SignalTable* t) {
  progress->set(0.0, "simulating " + std::to_string(c.simulation.duration) + " s");
  if (const gear_sim::Status s = gear_sim::simulate(c, t); !s.ok()) {  // checks the overrides too
    std::cerr << "simulate: " << s.message() << "\n";
    return kExitInput;
  }
  if (!o.free_response) return kContinue;
  gear_sim::SimConfig quiet = c, shifted;
  quiet.simulation.noise_snr_db = std::numeric_limits<double>::infinity();
  shifted = quiet;
  const double w0 = 2.0 * M_PI * gear_sim::naturalFrequencyHz(c.gears, c.mesh);
  shifted.simulation.initial_dte =
      c.simulation.initial_dte + c.gears.forceFactor() * t->torque.mean() / (w0 * w0);
  gear_sim::SignalTable a, b;
  progress->set(1.0, "free response");
  gear_sim::Status s = gear_sim::simulate(quiet, &a);
  if (s.ok()) s = gear_sim::simulate(shifted, &b);
  if (!s.ok()) {
    std::cerr << "simulate: " << s.message() << "\n";
    return kExitInput;
  }
  const Eigen::VectorXd noise = t->dte - a.dte;  // the configured measurement noise (or 0)
  t->dte = b.dte - a.dte + noise;
  t->dte_velocity = b.dte_velocity - a.dte_velocity;
  t->torque.setZero();  // no forcing in the free response
  return kContinue;
}

// The edge files (--edges), then the record: rig or signal, CSV or bag.
int write(const Options& o, const gear_sim::SimConfig& c, const gear_sim::EncoderOptions& enc,
          const gear_sim::SignalTable& t) {
  const gear_sim::GearModel model = c.gearModel();
  if (!o.edges_prefix.empty()) {
    for (int shaft : {1, 2}) {
      const auto e = gear_sim::encoderEdges(c, enc, t, shaft,
                                            shaft == 1 ? enc.counts_per_rev1 : enc.counts_per_rev2);
      const std::string path = o.edges_prefix + std::to_string(shaft) + ".csv";
      if (const gear_sim::Status s = gear_sim::writeEdgeCsv(path, e); !s.ok()) {
        std::cerr << "simulate: " << s.message() << "\n";
        return kExitOutput;
      }
    }
  }
  // A CSV is written atomically here (no partial file that looks complete); the bag writers do
  // so themselves.
  const bool csv = endsWith(o.output, ".csv");
  gear_sim::Status s;
  if (o.rig) {
    const gear_sim::SignalTable r = gear_sim::rigRecord(c, enc, t);
    s = csv ? gear_sim::writeAtomically(
                  o.output, [&](const std::string& p) { return gear_sim::writeRigCsv(p, r); })
            : gear_sim_ros::writeRigBag(o.output, r, &model, {});
  } else {
    s = csv ? gear_sim::writeAtomically(
                  o.output, [&](const std::string& p) { return gear_sim::writeSignalCsv(p, t); })
            : gear_sim_ros::writeSignalBag(o.output, t, c.simulation.sample_rate, &model,
                                           o.chunk_size);
  }
  if (!s.ok()) {
    std::cerr << "simulate: " << s.message() << "\n";
    return kExitOutput;
  }
  return kContinue;
}

}  // namespace

// parse -> load -> simulate -> write, each step returning an exit code.
int run(int argc, char** argv) {
  Options o;
  if (const int code = parse(argc, argv, &o); code != kContinue) return code;
  gear_sim::SimConfig c;
  gear_sim::EncoderOptions enc;
  if (const int code = load(&o, &c, &enc); code != kContinue) return code;
  // Progress on a terminal for long runs: simulation (x3 for --free-response), then writing.
  const double steps = o.free_response ? 4.0 : 2.0;
  gear_sim::ProgressBar progress("simulate", steps, !o.no_output);
  gear_sim::SignalTable t;
  if (const int code = simulateCase(o, c, &progress, &t); code != kContinue) return code;
  progress.set(steps - 1.0, "writing " + o.output);
  const int code = write(o, c, enc, t);
  progress.finish();
  if (code != kContinue) return code;
  if (!o.no_output)
    std::cerr << "simulate: " << t.size() << " samples (" << c.simulation.duration << " s at "
              << c.simulation.sample_rate << " Hz) -> " << o.output << "\n";
  return 0;
}

int main(int argc, char** argv) {
  return gear_sim::runToolMain("simulate", 3, [&] { return run(argc, argv); });
}
