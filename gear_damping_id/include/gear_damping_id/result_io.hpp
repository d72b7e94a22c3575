// Analysis outputs of the `analyze` tool (docs/method.md §6): the result JSON, the readable segment
// table and the CSV tables. No ROS (nlohmann::json only), so the tests and the tools share it.
#pragma once

#include <nlohmann/json.hpp>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/wavelet.hpp"
#include "gear_sim/status.hpp"

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

/// Outputs committed together: each output is written complete to a temporary file first, and
/// only once every one has been written are they all renamed over their targets, so a run that
/// fails writing its third output leaves the previous results of all three in place. Destroyed
/// without commit() (an error path), it removes the temporary files.
class OutputStage {
 public:
  OutputStage() = default;
  OutputStage(const OutputStage&) = delete;
  OutputStage& operator=(const OutputStage&) = delete;
  ~OutputStage();
  /// Registers the complete temporary file `tmp`, to be renamed over `path` by commit().
  void add(const std::string& tmp, const std::string& path);
  /// Renames every registered file over its target. IoError naming the first that failed (the
  /// temporaries not renamed yet are removed).
  gear_sim::Status commit();

 private:
  std::vector<std::pair<std::string, std::string>> files_;  // (tmp, target)
};

/// JSON of one segment estimate (docs/method.md §6 keys: t_start, t_end, C, C_std, c, xi, k_min,
/// k_max, plus identifiable/reason/samples/windows/condition/refined). Non-finite numbers become
/// null.
nlohmann::json segmentJson(const SegmentEstimate& s, Formulation f);

/// JSON of one run: formulation, model, options, segments[], constant, load_law, warnings and
/// response {nrmse, fit_percent}. Without `segments`, "segments" is null (a placeholder that
/// writeAnalysisJsonAtomically fills).
nlohmann::json runJson(const AnalysisRun& run, bool segments = true);

/// The docs/method.md §6 document: `identification` and `response` from the primary (first) run,
/// with the `constant` and `load_law` blocks taken from whichever run computed them, and
/// `runs[]` with every run in full. `input` describes the analysed record.
/// Without `segments`, every run's (and identification's) "segments" is a null placeholder.
nlohmann::json analysisJson(const std::vector<AnalysisRun>& runs, const nlohmann::json& input,
                            bool segments = true);

/// Readable tables on `os`: one per run (segments with C, its standard error, c, xi, k levels)
/// and a summary line per run (constant / load-law estimates, fit %).
void printRunTables(std::ostream& os, const std::vector<AnalysisRun>& runs);

/// Writes `dir`/segments.csv (all runs, long format), `dir`/summary.csv (one row per run) and
/// `dir`/response_<run>.csv (time, observed, modeled). Creates `dir`. IoError when a file or
/// the directory cannot be written. With `stage`, the files are only staged (renamed by
/// stage->commit()).
gear_sim::Status writeRunCsv(const std::string& dir, const std::vector<AnalysisRun>& runs,
                             OutputStage* stage = nullptr);

/// JSON of a wavelet validation (docs/method.md §6 `wavelet`): modes[] with frequency_hz,
/// damping_ratio, r2, t_start, t_end, sigma, spectrum_frequency_hz, omega0,
/// integral_damping_ratio, warning; plus warnings, noise_std and the scalogram's omega0.
nlohmann::json waveletJson(const WaveletResult& w);

/// Adds t0 [s] to every time of `w` (decay regions, scalogram columns): analyzeWavelet counts
/// time from the first sample it was given, the outputs use the record's time axis.
void shiftWaveletTimes(WaveletResult* w, double t0);

/// The modes as a table like the paper's Table 2 (frequency, xi wavelet, xi integral, R^2,
/// decay region, warning).
void printWaveletTable(std::ostream& os, const WaveletResult& w);

/// Writes `dir`/wavelet_modes.csv, wavelet_spectrum.csv, wavelet_scalogram.csv (when the
/// result holds a scalogram) and wavelet_envelopes.csv: `mode,time,envelope` with the envelope
/// |W(f_mode, t)| of each fitted mode at the omega0 of its fit, recomputed from the record
/// y[0, n) sampled at `sample_rate` with its first sample at time t0 (times in the file are
/// t0 + j/fs, so `w`'s times should be shifted by t0 too: see shiftWaveletTimes), every d-th
/// sample so that at most `max_points` rows per mode remain. IoError when a file cannot be
/// written; the writers' InvalidArgument for an unusable result.
gear_sim::Status writeWaveletCsv(const std::string& dir, const WaveletResult& w, const double* y,
                                 long n, double sample_rate, double t0, long max_points,
                                 OutputStage* stage = nullptr);

/// Writes `text` to `path` atomically (a temporary file renamed on success), so a failed run
/// never leaves a partial file that looks complete. IoError ("<path>: cannot write"). With
/// `stage`, the complete temporary file is registered there instead of renamed.
gear_sim::Status writeFileAtomically(const std::string& path, const std::string& text,
                                     OutputStage* stage = nullptr);

/// writeFileAtomically of `doc.dump(2)` and a newline, serialised straight into the file (the
/// text is never held in memory). ioError (field "path") when the file cannot be written.
gear_sim::Status writeJsonAtomically(const std::string& path, const nlohmann::json& doc,
                                     OutputStage* stage = nullptr);

/// writeJsonAtomically of the document analysisJson(runs, input) would give, from
/// `doc` = analysisJson(runs, input, false) (and keys added to it): the null "segments" of
/// doc["runs"][k] and doc["identification"] are written from runs[k] and runs[0] with the same
/// bytes, without building their tree (a 1e7-sample record has 1e4 segments per run).
gear_sim::Status writeAnalysisJsonAtomically(const std::string& path, const nlohmann::json& doc,
                                             const std::vector<AnalysisRun>& runs,
                                             OutputStage* stage = nullptr);

}  // namespace gear_damping_id
