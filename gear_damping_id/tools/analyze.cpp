// rosrun gear_damping analyze --input FILE.csv --params GEAR.yaml [--output result.json]
//     [--formulation known|greybox|paper|legacy]... [--model piecewise|constant|load_law]...
//     [--segment S] [--window S] [--t-start S] [--t-end S] [--refine auto|always|never]
//     [--csv-out DIR]
//
// Identifies the mesh damping of the DTE record FILE.csv (DESIGN §6 columns) with the integral
// method (DESIGN §4) for every requested formulation x damping model, re-simulates the modeled
// response of each, prints a table per run on stdout and writes the DESIGN §6 JSON (and CSV
// tables on request). Exit codes (README "analyze"): 0 success, 1 invalid command line or option
// value, 2 invalid input (file, columns, numbers, time axis, gear parameters), 3 an output could
// not be written, 4 nothing identifiable in the record. Messages go to stderr.
#include <CLI/CLI.hpp>
#include <cmath>
#include <iostream>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/result_io.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/signal_csv.hpp"

namespace gd = gear_damping_id;

namespace {

constexpr int kExitUsage = 1, kExitInput = 2, kExitOutput = 3, kExitNothing = 4;

int fail(int code, const std::string& message) {
  std::cerr << "analyze: " << message << "\n";
  return code;
}

bool anyIdentifiable(const gd::IdentificationResult& r) {
  if (r.constant && r.constant->identifiable) return true;
  if (r.load_law && r.load_law->identifiable) return true;
  for (const auto& s : r.segments)
    if (s.identifiable) return true;
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Identify the mesh damping of a spur gear pair from its dynamic transmission error "
      "(integral method, Yousfi et al. 2022) and re-simulate the modeled response."};
  std::string input, params, output, csv_out;
  std::vector<std::string> formulations{"known"}, models{"piecewise"};
  std::string refine = "auto";
  gd::IdentificationOptions base;
  std::optional<double> t_start, t_end;
  app.add_option("--input", input, "signal record: CSV with the DESIGN §6 columns")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--params", params,
                 "gear parameters: the simulator's YAML (pinion, gear, mesh, speed sections)")
      ->check(CLI::ExistingFile);
  app.add_option("--output", output, "write the result JSON (DESIGN §6) to this file");
  app.add_option("--formulation", formulations,
                 "known | greybox | paper | legacy (repeat for several; default known)")
      ->check(CLI::IsMember({"known", "greybox", "paper", "legacy"}))
      ->take_all();
  app.add_option("--model", models,
                 "piecewise | constant | load_law (repeat for several; default piecewise)")
      ->check(CLI::IsMember({"piecewise", "constant", "load_law"}))
      ->take_all();
  app.add_option("--segment", base.segment_length,
                 "damping segment length [s] (0 or inf: the whole record; default 1e-3)");
  app.add_option("--window", base.window_length,
                 "integration window [s] (default: two natural periods from the data)");
  app.add_option("--t-start", t_start, "analyse from this time [s]");
  app.add_option("--t-end", t_end, "analyse up to this time [s]");
  app.add_option("--refine", refine,
                 "output-error refinement: auto (when the data are noisy) | always | never")
      ->check(CLI::IsMember({"auto", "always", "never"}));
  app.add_option("--max-condition", base.max_condition,
                 "largest condition number of an identifiable segment (default 1e6)");
  app.add_option("--time-tolerance", base.time_tolerance,
                 "relative tolerance on the uniformity of the time column (default 1e-6)");
  app.add_option("--csv-out", csv_out,
                 "write segments.csv, summary.csv and response_<run>.csv into this directory");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);  // prints the help or the message naming the option
    return rc == 0 ? 0 : kExitUsage;
  }

  // Options: validated before any file is read, each message naming the option.
  if (t_start) base.t_start = *t_start;
  if (t_end) base.t_end = *t_end;
  base.refine = refine == "always"  ? gd::IdentificationOptions::Refine::Always
                : refine == "never" ? gd::IdentificationOptions::Refine::Never
                                    : gd::IdentificationOptions::Refine::Auto;
  if (params.empty())
    return fail(kExitUsage, "--params GEAR.yaml is required for the identification");
  std::vector<gd::IdentificationOptions> runs_options;
  for (const auto& f : formulations) {
    for (const auto& m : models) {
      gd::IdentificationOptions o = base;
      gd::parseFormulation(f, &o.formulation);
      gd::parseDampingModel(m, &o.model);
      const std::string e = o.validate();
      if (!e.empty()) return fail(kExitUsage, e);
      runs_options.push_back(o);
    }
  }

  std::string error;
  gear_sim::GearModel model;
  if (!gear_sim::loadGearModelFile(params, &model, &error)) return fail(kExitInput, error);
  const gd::GearConstants gear = gd::gearConstants(model);
  if (const std::string e = gear.validate(); !e.empty())
    return fail(kExitInput, params + ": " + e);

  gear_sim::SignalTable table;
  // NaN/Inf samples are kept: the segments holding them are reported as not identifiable.
  if (!gear_sim::readSignalCsv(input, &table, &error, {"time", "dte"}, /*allow_non_finite=*/true))
    return fail(kExitInput, error);
  for (const auto& o : runs_options) {
    const std::string e =
        gd::checkSignalTable(table, o.formulation, o.model, o.time_tolerance, /*first_line=*/2);
    if (!e.empty()) return fail(kExitInput, input + ": " + e);
  }

  const gd::SignalView view = gd::SignalView::of(table);
  std::vector<gd::AnalysisRun> runs;
  bool identifiable = false;
  for (const auto& o : runs_options) {
    gd::AnalysisRun run;
    run.options = o;
    run.t0 = view.t0;
    run.dt = view.dt;
    if (!gd::identify(table, gear, o, &run.result, &error))
      return fail(kExitInput, input + ": " + error);
    identifiable = identifiable || anyIdentifiable(run.result);
    if (!gd::modeledResponse(view, gear, run.result, &run.response, &run.response_error))
      run.response = gd::ModeledResponse{};
    runs.push_back(std::move(run));
  }
  gd::printRunTables(std::cout, runs);

  nlohmann::json in = {{"file", input},
                       {"params", params},
                       {"samples", table.size()},
                       {"sample_rate", 1.0 / view.dt},
                       {"t_first", table.time[0]},
                       {"t_last", table.time[table.size() - 1]}};
  if (!output.empty()) {
    if (!gd::writeFileAtomically(output, gd::analysisJson(runs, in).dump(2) + "\n", &error))
      return fail(kExitOutput, error);
  }
  if (!csv_out.empty() && !gd::writeRunCsv(csv_out, runs, &error))
    return fail(kExitOutput, error);
  if (!identifiable)
    return fail(kExitNothing, "no segment of " + input + " is identifiable (see the table)");
  return 0;
}
