// Analysis outputs of the `analyze` tool (DESIGN.md §6): the result JSON, the readable segment
// table and the CSV tables. No ROS (nlohmann::json only), so the tests and the tools share it.
#pragma once

#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/output_error.hpp"

namespace gear_damping_id {

/// One identification run (one formulation x damping model) and its modeled response.
struct AnalysisRun {
  IdentificationOptions options;
  IdentificationResult result;
  ModeledResponse response;    ///< empty when `response_error` is set
  std::string response_error;  ///< why no modeled response could be computed
  double t0 = 0.0, dt = 0.0;   ///< [s] time of sample 0 and sample step (for response times)
  std::string name() const;    ///< "<formulation>_<model>", e.g. "known_piecewise"
};

/// JSON of one segment estimate (DESIGN §6 keys: t_start, t_end, C, C_std, c, xi, k_min, k_max,
/// plus identifiable/reason/samples/windows/condition/refined). Non-finite numbers become null.
nlohmann::json segmentJson(const SegmentEstimate& s, Formulation f);

/// JSON of one run: formulation, model, options, segments[], constant, load_law, warnings and
/// response {nrmse, fit_percent}.
nlohmann::json runJson(const AnalysisRun& run);

/// The DESIGN §6 document: `identification` and `response` from the primary (first) run,
/// with the `constant` and `load_law` blocks taken from whichever run computed them, and
/// `runs[]` with every run in full. `input` describes the analysed record.
nlohmann::json analysisJson(const std::vector<AnalysisRun>& runs, const nlohmann::json& input);

/// Readable tables on `os`: one per run (segments with C, its standard error, c, xi, k levels)
/// and a summary line per run (constant / load-law estimates, fit %).
void printRunTables(std::ostream& os, const std::vector<AnalysisRun>& runs);

/// Writes `dir`/segments.csv (all runs, long format), `dir`/summary.csv (one row per run) and
/// `dir`/response_<run>.csv (time, observed, modeled). Creates `dir`. False with `*error`.
bool writeRunCsv(const std::string& dir, const std::vector<AnalysisRun>& runs, std::string* error);

/// Writes `text` to `path` atomically (a temporary file renamed on success), so a failed run
/// never leaves a partial file that looks complete. False with `*error`.
bool writeFileAtomically(const std::string& path, const std::string& text, std::string* error);

}  // namespace gear_damping_id
