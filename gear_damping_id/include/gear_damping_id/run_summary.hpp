// Summaries of identification runs for the `analyze` tool's stdout: the per-segment table of
// every run ends with a one-line count of clean and flagged segments, and a `--summary` block
// (statistics of C and xi over all segments, flags by code, the worst segments) replaces the
// table for long records. No ROS.
#pragma once

#include <cstddef>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/result_io.hpp"

namespace gear_damping_id {

/// Above this many segments in any run, `analyze` prints summaries instead of tables unless
/// told otherwise (--table / --no-summary): a 5 s record at 1 ms segments has 5000 rows.
constexpr std::size_t kSummaryAboveSegments = 50;

/// Codes counted beside the segments' own warning codes: not identifiable (it has a `reason`),
/// C <= 0 and xi >= 1 (physically impossible for a damped mesh; the report flags the same).
inline constexpr const char* kNotIdentifiableCode = "not_identifiable";
/// The same codes as the quality flags (quality_flags.hpp), so a segment is counted once.
inline constexpr const char* kNonPositiveDampingCode = quality_code::kNonpositiveDamping;
inline constexpr const char* kOverdampedCode = quality_code::kOverdamped;

/// Order statistics of one quantity over the identifiable segments (NaN when there are none).
struct ValueStats {
  std::size_t count = 0;
  double min = kNaN, median = kNaN, mean = kNaN, max = kNaN, std = kNaN;
};

/// What a run's segments say, counted. A segment is *flagged* when it is not identifiable, has
/// C <= 0 or xi >= 1, or carries at least one warning; otherwise it is *clean*.
struct SegmentSummary {
  std::size_t total = 0, clean = 0, flagged = 0, identifiable = 0;
  /// Flagged segments per code (each code once per segment).
  std::map<std::string, std::size_t> codes;
  ValueStats C, C_std, xi;  ///< over the identifiable segments with finite values
  /// Indices of the worst segments, worst first: not identifiable, then C <= 0 or xi >= 1, then
  /// with warnings, then by relative standard error C_std/|C| (largest first); at most
  /// `worst_count`.
  std::vector<std::size_t> worst;
};

SegmentSummary summarizeSegments(const std::vector<SegmentEstimate>& segments,
                                 std::size_t worst_count = 5);

/// "8 of 10 segments clean, 2 flagged (not_identifiable 1, refine_disagrees 1)", or
/// "10 of 10 segments clean".
std::string summaryLine(const SegmentSummary& s);

/// How the runs are printed.
enum class RunPrintMode {
  Auto,     ///< Table up to kSummaryAboveSegments segments per run, Summary above
  Table,    ///< one line per segment
  Summary,  ///< statistics, flags and worst segments instead of the segment rows
};

/// Prints every run on `os`: its table (printRunTables) or its summary block, each ending with
/// summaryLine() of its segments.
void printRuns(std::ostream& os, const std::vector<AnalysisRun>& runs, RunPrintMode mode);

}  // namespace gear_damping_id
