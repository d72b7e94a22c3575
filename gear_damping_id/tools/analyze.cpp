// rosrun gear_damping analyze --input FILE.csv|FILE.bag [--params GEAR.yaml] [--output result.json]
//     [--formulation known|greybox|paper|legacy]... [--model piecewise|constant|load_law]...
//     [--segment S] [--window S] [--t-start S] [--t-end S] [--refine auto|always|never]
//     [--topic T] [--csv-out DIR] [--bag-out OUT.bag]
//
// Identifies the mesh damping of a DTE record (CSV with the DESIGN §6 columns, or a bag of
// gear_damping/SignalChunk messages) with the integral method (DESIGN §4) for every requested
// formulation x damping model, re-simulates the modeled response of each, prints a table per
// run on stdout and writes the DESIGN §6 JSON, CSV tables and a bag of results on request.
// Bags longer than --max-in-memory samples are analysed streaming, one segment at a time.
// Exit codes (README "analyze"): 0 success, 1 invalid command line or option value, 2 invalid
// input (file, columns, numbers, time axis, chunks, gear parameters, sample rate, length),
// 3 an output could not be written, 4 nothing identifiable in the record. Messages on stderr.
#include <gear_damping/DampingArray.h>
#include <gear_damping/ModeledResponse.h>
#include <rosbag/bag.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "gear_damping_id/input_checks.hpp"
#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/result_io.hpp"
#include "gear_damping_ros/id_conversions.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim_ros/bag_io.hpp"

namespace gd = gear_damping_id;
using Ranges = std::vector<std::pair<Eigen::Index, Eigen::Index>>;

namespace {

constexpr int kExitUsage = 1, kExitInput = 2, kExitOutput = 3, kExitNothing = 4;

int fail(int code, const std::string& message) {
  std::cerr << "analyze: " << message << "\n";
  return code;
}

void warn(const std::string& message) { std::cerr << "analyze: warning: " << message << "\n"; }

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool anyIdentifiable(const gd::IdentificationResult& r) {
  if (r.constant && r.constant->identifiable) return true;
  if (r.load_law && r.load_law->identifiable) return true;
  for (const auto& s : r.segments)
    if (s.identifiable) return true;
  return false;
}

// Progress on stderr for long records, only when stderr is a terminal.
class Progress {
 public:
  explicit Progress(std::int64_t total) : total_(total), on_(isatty(2) && total >= 1000000) {}
  void update(std::int64_t done) {
    if (!on_) return;
    const int pct = static_cast<int>(100.0 * static_cast<double>(done) / static_cast<double>(total_));
    if (pct == last_) return;
    last_ = pct;
    std::fprintf(stderr, "\ranalyze: %3d %% (%lld of %lld samples)", pct,
                 static_cast<long long>(done), static_cast<long long>(total_));
    std::fflush(stderr);
  }
  ~Progress() {
    if (on_ && last_ >= 0) std::fprintf(stderr, "\n");
  }

 private:
  std::int64_t total_;
  bool on_;
  int last_ = -1;
};

// Streaming sums for the NRMSE of a response assembled from blocks (Chan's parallel update).
struct FitAccumulator {
  double n = 0, mean = 0, m2 = 0, sse = 0;
  void add(const gd::ModeledResponse& r) {
    const Eigen::Index m = r.observed.size();
    if (m == 0) return;
    const double bm = r.observed.mean();
    const double bm2 = (r.observed.array() - bm).square().sum();
    const double nb = static_cast<double>(m), nt = n + nb, d = bm - mean;
    mean += d * nb / nt;
    m2 += bm2 + d * d * n * nb / nt;
    n = nt;
    sse += (r.observed - r.modeled).squaredNorm();
  }
  void finish(gd::ModeledResponse* out) const {
    out->nrmse = n > 0 && m2 > 0 ? std::sqrt(sse / m2) : gd::kNaN;
    out->fit_percent = 100.0 * (1.0 - out->nrmse);
  }
};

// The optional bag of results (written to a temporary file, renamed when complete).
class ResultBag {
 public:
  bool open(const std::string& path, std::string* error) {
    path_ = path;
    try {
      bag_ = std::make_unique<rosbag::Bag>(path + ".partial", rosbag::bagmode::Write);
    } catch (const std::exception& e) {
      *error = path + ": cannot write (" + e.what() + ")";
      return false;
    }
    return true;
  }
  bool active() const { return bag_ != nullptr; }
  template <class M>
  void write(const std::string& topic, double t, M msg) {
    if (!bag_) return;
    const ros::Time stamp = ros::Time(1.0) + ros::Duration(std::max(0.0, t));
    msg.header.stamp = stamp;
    bag_->write(topic, stamp, msg);
  }
  bool close(std::string* error) {
    if (!bag_) return true;
    try {
      bag_->close();
    } catch (const std::exception& e) {
      *error = path_ + ": cannot write (" + e.what() + ")";
      return false;
    }
    bag_.reset();
    if (std::rename((path_ + ".partial").c_str(), path_.c_str()) != 0) {
      *error = path_ + ": cannot write";
      return false;
    }
    return true;
  }
  ~ResultBag() {
    if (bag_) {  // not closed: an error path; leave nothing that looks complete
      try {
        bag_->close();
      } catch (...) {
      }
      std::remove((path_ + ".partial").c_str());
    }
  }

 private:
  std::string path_;
  std::unique_ptr<rosbag::Bag> bag_;
};

std::string topicOf(const gd::AnalysisRun& run, bool primary, const char* leaf) {
  return primary ? std::string("/gear/") + leaf : "/gear/" + run.name() + "/" + leaf;
}

// Streaming analysis of a long bag: segment by segment, memory bounded by a segment.
// Piecewise known/greybox/paper runs treat each segment as its own record (the unknowns are
// segment-local, so this is the whole-record estimate; refinement and modeled response are per
// segment, each response starting from its segment's identified state). Runs with shared
// unknowns (constant, load_law, legacy) accumulate their normal equations with IntegralMethod;
// their output-error refinement and modeled response need the whole record and are skipped
// with a warning.
bool analyzeStreaming(const gear_sim_ros::BagSignalInfo& info, const gd::GearConstants& gear,
                      std::vector<gd::AnalysisRun>* runs, ResultBag* bag, std::string* error) {
  gd::SignalView whole;
  whole.dt = 1.0 / info.sample_rate;
  whole.t0 = static_cast<double>(info.first_index) * whole.dt;
  whole.n = static_cast<Eigen::Index>(info.samples);
  const Ranges ranges = gd::segmentRanges(whole, runs->front().options);
  if (ranges.empty()) {
    *error = "no samples in the analysed time range";
    return false;
  }
  // Legacy forcing: the mean load over the analysed range (one extra pass).
  double fbar = gd::kNaN;
  bool legacy = false;
  for (const auto& r : *runs) legacy = legacy || r.options.formulation == gd::Formulation::Legacy;
  if (legacy && info.torque) {
    double sum = 0.0;
    long long cnt = 0;
    if (!gear_sim_ros::streamSignalBag(info, ranges,
                                       [&](const gear_sim::SignalTable& t, size_t) {
                                         sum += t.torque.sum();
                                         cnt += t.torque.size();
                                         return true;
                                       },
                                       error))
      return false;
    fbar = gear.force_factor * sum / static_cast<double>(cnt);
  }
  struct State {
    std::unique_ptr<gd::IntegralMethod> method;  // shared-unknown runs
    FitAccumulator fit;
    bool per_segment = false;
  };
  std::vector<State> states(runs->size());
  // The default window from the record's mean stiffness, as for a record read whole.
  double window = runs->front().options.window_length;
  if (!(window > 0.0)) {
    gd::SignalView mean_k = whole;
    mean_k.n = info.stiffness_mean > 0.0 ? 1 : 0;
    mean_k.stiffness = &info.stiffness_mean;
    window = gd::defaultWindowLength(mean_k, gear);
  }
  Progress progress(static_cast<std::int64_t>(ranges.back().second - ranges.front().first));
  const bool ok = gear_sim_ros::streamSignalBag(
      info, ranges, [&](const gear_sim::SignalTable& block, size_t r) {
        const gd::SignalView view = gd::SignalView::of(block);
        for (size_t k = 0; k < runs->size(); ++k) {
          gd::AnalysisRun& run = (*runs)[k];
          State& st = states[k];
          gd::IdentificationOptions o = run.options;
          o.window_length = window;
          const gd::Formulation f = o.formulation;
          st.per_segment = o.model == gd::DampingModel::Piecewise && f != gd::Formulation::Legacy;
          if (!st.per_segment) {
            if (!st.method) {
              st.method = std::make_unique<gd::IntegralMethod>(o, gear);
              if (f == gd::Formulation::Legacy) st.method->setLegacyForcing(fbar);
            }
            st.method->addSegment(view, 0, view.n);
            continue;
          }
          o.segment_length = std::numeric_limits<double>::infinity();
          o.t_start = -std::numeric_limits<double>::infinity();
          o.t_end = std::numeric_limits<double>::infinity();
          gd::IdentificationResult seg;
          std::string e;
          if (!gd::identify(block, gear, o, &seg, &e)) {
            *error = e;
            return false;
          }
          if (run.result.segments.empty()) run.result = seg;  // formulation, Me, omega0, ...
          else run.result.segments.push_back(seg.segments.front());
          for (const auto& w : seg.warnings) run.result.warnings.push_back(w);
          gd::ModeledResponse resp;
          std::string why;
          if (seg.segments.front().identifiable &&
              gd::modeledResponse(view, gear, seg, &resp, &why)) {
            st.fit.add(resp);
            bag->write(topicOf(run, k == 0, "modeled_response"), block.time[0],
                       gear_damping_ros::toMsg(resp, info.sample_rate,
                                               info.first_index +
                                                   static_cast<std::uint64_t>(ranges[r].first)));
          }
        }
        progress.update(ranges[r].second - ranges.front().first);
        return true;
      },
      error);
  if (!ok) return false;
  for (size_t k = 0; k < runs->size(); ++k) {
    gd::AnalysisRun& run = (*runs)[k];
    if (states[k].per_segment) {
      states[k].fit.finish(&run.response);
      run.response.observed.resize(0);
      run.result.window_length = window;
    } else {
      run.result = states[k].method->finish();
      run.response_error = "not computed for a record analysed streaming (" +
                           std::to_string(info.samples) +
                           " samples): the shared model's response needs the whole record";
      run.result.warnings.push_back(
          "output-error refinement skipped: a record analysed streaming is refined per segment "
          "only for the piecewise model");
    }
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Identify the mesh damping of a spur gear pair from its dynamic transmission error "
      "(integral method, Yousfi et al. 2022) and re-simulate the modeled response."};
  std::string input, params, output, csv_out, bag_out, topic;
  std::vector<std::string> formulations{"known"}, models{"piecewise"};
  std::string refine = "auto";
  gd::IdentificationOptions base;
  std::optional<double> t_start, t_end;
  long max_in_memory = 1000000;
  app.add_option("--input", input,
                 "signal record: CSV with the DESIGN §6 columns, or a bag of SignalChunk messages")
      ->required()
      ->check(CLI::ExistingFile);
  app.add_option("--params", params,
                 "gear parameters: the simulator's YAML (pinion, gear, mesh, speed sections); "
                 "default for a bag: its GearParams message")
      ->check(CLI::ExistingFile);
  app.add_option("--topic", topic, "bag input: the SignalChunk topic (default: the only one)");
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
  app.add_option("--max-in-memory", max_in_memory,
                 "bags with more samples are analysed streaming, one segment at a time "
                 "(default 1e6)")
      ->check(CLI::PositiveNumber);
  app.add_option("--csv-out", csv_out,
                 "write segments.csv, summary.csv and response_<run>.csv into this directory");
  app.add_option("--bag-out", bag_out,
                 "write the results as gear_damping messages (DampingArray, ModeledResponse) "
                 "to this bag");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);  // prints the help or the message naming the option
    return rc == 0 ? 0 : kExitUsage;
  }

  // Options: validated before any file is read, each message naming the option.
  const bool is_bag = endsWith(input, ".bag");
  if (!is_bag && !endsWith(input, ".csv"))
    return fail(kExitUsage, "--input " + input + ": must end in .csv or .bag");
  if (!bag_out.empty() && !endsWith(bag_out, ".bag"))
    return fail(kExitUsage, "--bag-out " + bag_out + ": must end in .bag");
  if (t_start) base.t_start = *t_start;
  if (t_end) base.t_end = *t_end;
  base.refine = refine == "always"  ? gd::IdentificationOptions::Refine::Always
                : refine == "never" ? gd::IdentificationOptions::Refine::Never
                                    : gd::IdentificationOptions::Refine::Auto;
  std::vector<gd::IdentificationOptions> runs_options;
  for (const auto& f : formulations) {
    for (const auto& m : models) {
      gd::IdentificationOptions o = base;
      gd::parseFormulation(f, &o.formulation);
      gd::parseDampingModel(m, &o.model);
      if (const std::string e = o.validate(); !e.empty()) return fail(kExitUsage, e);
      runs_options.push_back(o);
    }
  }

  // Input: a CSV is read whole; a bag is scanned (validated) first, then read whole or streamed.
  std::string error;
  gear_sim::SignalTable table;
  gear_sim_ros::BagSignalInfo bag_info;
  bool streaming = false;
  if (is_bag) {
    if (!gear_sim_ros::scanSignalBag(input, topic, &bag_info, &error))
      return fail(kExitInput, error);
    for (const auto& w : bag_info.warnings) warn(input + ": " + w);
    streaming = bag_info.samples > max_in_memory;
    if (!streaming && !gear_sim_ros::readSignalBag(bag_info, &table, &error))
      return fail(kExitInput, error);
  } else {
    if (!topic.empty()) return fail(kExitUsage, "--topic applies to bag input only");
    // NaN/Inf samples are kept: the segments holding them are reported as not identifiable.
    if (!gear_sim::readSignalCsv(input, &table, &error, {"time", "dte"},
                                 /*allow_non_finite=*/true))
      return fail(kExitInput, error);
  }

  gear_sim::GearModel model;
  std::string params_source = params;
  if (!params.empty()) {
    if (!gear_sim::loadGearModelFile(params, &model, &error)) return fail(kExitInput, error);
  } else if (is_bag && bag_info.has_params) {
    model = bag_info.params;
    params_source = input + ":" + bag_info.params_topic;
  } else {
    return fail(kExitUsage,
                "--params GEAR.yaml is required" +
                    std::string(is_bag ? (bag_info.params_error.empty()
                                              ? " (the bag has no GearParams message)"
                                              : " (" + bag_info.params_error + ")")
                                       : ""));
  }
  const gd::GearConstants gear = gd::gearConstants(model);
  if (const std::string e = gear.validate(); !e.empty())
    return fail(kExitInput, params_source + ": " + e);

  // Record-level checks: columns and time axis (tables), sample rate, length.
  double sample_rate, duration;
  if (streaming) {
    sample_rate = bag_info.sample_rate;
    gd::SignalView whole;
    whole.dt = 1.0 / sample_rate;
    whole.t0 = static_cast<double>(bag_info.first_index) * whole.dt;
    whole.n = static_cast<Eigen::Index>(bag_info.samples);
    const Ranges r = gd::segmentRanges(whole, runs_options.front());
    duration = r.empty() ? 0.0 : static_cast<double>(r.back().second - r.front().first) * whole.dt;
    for (const auto& o : runs_options) {
      gear_sim::SignalTable shape;  // columns present, for the formulation check
      shape.time = Eigen::VectorXd::LinSpaced(2, 0.0, whole.dt);
      shape.dte.resize(2);
      if (bag_info.stiffness) shape.stiffness.resize(2);
      if (bag_info.torque) shape.torque.resize(2);
      if (bag_info.mesh_state) shape.mesh_state.resize(2);
      if (const std::string e = gd::checkSignalTable(shape, o.formulation, o.model); !e.empty())
        return fail(kExitInput, input + ": " + e);
    }
  } else {
    for (const auto& o : runs_options) {
      const std::string e = gd::checkSignalTable(table, o.formulation, o.model, o.time_tolerance,
                                                 /*first_line=*/is_bag ? -1 : 2);
      if (!e.empty()) return fail(kExitInput, input + ": " + e);
    }
    const gd::SignalView view = gd::SignalView::of(table);
    sample_rate = 1.0 / view.dt;
    const Ranges r = gd::segmentRanges(view, runs_options.front());
    duration = r.empty() ? 0.0 : static_cast<double>(r.back().second - r.front().first) * view.dt;
  }
  std::string rate_warning;
  if (const std::string e = gd::checkSampleRate(sample_rate, gear, &rate_warning); !e.empty())
    return fail(kExitInput, input + ": " + e);
  if (!rate_warning.empty()) warn(input + ": " + rate_warning);
  if (duration <= 0.0) return fail(kExitInput, input + ": no samples in the analysed time range");
  for (const auto& o : runs_options)
    if (const std::string e = gd::checkRecordLength(duration, o); !e.empty())
      return fail(kExitInput, input + ": " + e);

  ResultBag bag;
  if (!bag_out.empty() && !bag.open(bag_out, &error)) return fail(kExitOutput, error);

  std::vector<gd::AnalysisRun> runs;
  for (const auto& o : runs_options) {
    gd::AnalysisRun run;
    run.options = o;
    run.dt = 1.0 / sample_rate;
    run.t0 = streaming ? static_cast<double>(bag_info.first_index) * run.dt : table.time[0];
    runs.push_back(std::move(run));
  }
  if (streaming) {
    if (!analyzeStreaming(bag_info, gear, &runs, &bag, &error))
      return fail(kExitInput, input + ": " + error);
  } else {
    const gd::SignalView view = gd::SignalView::of(table);
    for (size_t k = 0; k < runs.size(); ++k) {
      gd::AnalysisRun& run = runs[k];
      if (!gd::identify(table, gear, run.options, &run.result, &error))
        return fail(kExitInput, input + ": " + error);
      if (!gd::modeledResponse(view, gear, run.result, &run.response, &run.response_error))
        run.response = gd::ModeledResponse{};
      else
        bag.write(topicOf(run, k == 0, "modeled_response"), table.time[run.response.begin],
                  gear_damping_ros::toMsg(run.response, sample_rate,
                                          static_cast<std::uint64_t>(std::llround(
                                              table.time[run.response.begin] * sample_rate))));
    }
  }
  bool identifiable = false;
  for (size_t k = 0; k < runs.size(); ++k) {
    identifiable = identifiable || anyIdentifiable(runs[k].result);
    bag.write(topicOf(runs[k], k == 0, "damping"), duration + runs[k].t0,
              gear_damping_ros::toMsg(runs[k].result));
  }
  gd::printRunTables(std::cout, runs);

  const nlohmann::json in = {
      {"file", input},
      {"params", params_source},
      {"samples", streaming ? static_cast<std::int64_t>(bag_info.samples)
                            : static_cast<std::int64_t>(table.size())},
      {"sample_rate", sample_rate},
      {"streaming", streaming},
      {"topic", is_bag ? nlohmann::json(bag_info.topic) : nlohmann::json(nullptr)},
      {"gaps", is_bag ? bag_info.gaps : 0}};
  if (!output.empty() &&
      !gd::writeFileAtomically(output, gd::analysisJson(runs, in).dump(2) + "\n", &error))
    return fail(kExitOutput, error);
  if (!csv_out.empty() && !gd::writeRunCsv(csv_out, runs, &error))
    return fail(kExitOutput, error);
  if (!bag.close(&error)) return fail(kExitOutput, error);
  if (!identifiable)
    return fail(kExitNothing, "no segment of " + input + " is identifiable (see the table)");
  return 0;
}
