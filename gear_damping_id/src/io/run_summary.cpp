#include "gear_damping_id/run_summary.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <set>
#include <sstream>

namespace gear_damping_id {
namespace {

// The codes of everything doubtful about a segment: not identifiable, a physically impossible
// value (C <= 0, xi >= 1: the report flags the same), and its warnings; each code once.
std::set<std::string> flagCodes(const SegmentEstimate& s) {
  std::set<std::string> codes;
  if (!s.identifiable) {
    codes.insert(kNotIdentifiableCode);
  } else {
    if (s.C <= 0.0) codes.insert(kNonPositiveDampingCode);
    if (s.xi >= 1.0) codes.insert(kOverdampedCode);
  }
  for (const auto& w : s.warnings) codes.insert(w.code);
  return codes;
}

ValueStats statsOf(std::vector<double> v) {
  ValueStats st;
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  st.count = v.size();
  if (v.empty()) return st;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  st.min = v.front();
  st.max = v.back();
  st.median = n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  double sum = 0.0;
  for (double x : v) sum += x;
  st.mean = sum / static_cast<double>(n);
  double ss = 0.0;
  for (double x : v) ss += (x - st.mean) * (x - st.mean);
  st.std = n > 1 ? std::sqrt(ss / static_cast<double>(n - 1)) : 0.0;
  return st;
}

// Sort key of a segment's badness: larger is worse.
double badness(const SegmentEstimate& s) {
  if (!s.identifiable) return 3.0;
  if (s.C <= 0.0 || s.xi >= 1.0) return 2.5;
  const double rel = std::abs(s.C_std / s.C);
  const double r = std::isfinite(rel) ? rel / (1.0 + rel) : 1.0;  // in [0, 1]
  return (s.warnings.empty() ? 0.0 : 1.0) + r;
}

std::string num(double v, int precision) {
  if (!std::isfinite(v)) return "-";
  std::ostringstream o;
  o << std::setprecision(precision) << v;
  return o.str();
}

void printStats(std::ostream& os, const char* name, const ValueStats& s, int precision) {
  os << "  " << std::left << std::setw(12) << name << std::right << " median "
     << num(s.median, precision) << ", mean " << num(s.mean, precision) << ", std " << num(s.std, 3)
     << ", min " << num(s.min, precision) << ", max " << num(s.max, precision) << "  (" << s.count
     << " segments)\n";
}

std::string flagsOf(const SegmentEstimate& s) {
  std::string out;
  for (const auto& code : flagCodes(s)) out += (out.empty() ? "" : "; ") + code;
  if (!s.identifiable) out += " (" + s.reason + ")";
  return out;
}

void printSummaryBlock(std::ostream& os, const AnalysisRun& run, const SegmentSummary& sum) {
  const IdentificationResult& r = run.result;
  os << "== " << toString(r.formulation) << " formulation, " << toString(r.model) << " model ("
     << r.estimator << "): summary of " << sum.total << " segments\n";
  printStats(os, "C [1/s]", sum.C, 6);
  printStats(os, "C_std [1/s]", sum.C_std, 3);
  printStats(os, "xi [-]", sum.xi, 5);
  if (!sum.worst.empty()) {
    os << "  worst segments (flagged first, then by relative standard error):\n"
       << "    seg   t_start[ms]  t_end[ms]      C[1/s]   C_std[1/s]       xi[-]  flags\n";
    for (std::size_t i : sum.worst) {
      const SegmentEstimate& s = r.segments[i];
      os << "  " << std::setw(5) << i << "  " << std::setw(11) << num(s.t_start * 1e3, 6) << "  "
         << std::setw(9) << num(s.t_end * 1e3, 6) << "  " << std::setw(10) << num(s.C, 6) << "  "
         << std::setw(11) << num(s.C_std, 3) << "  " << std::setw(10) << num(s.xi, 5);
      const std::string flags = flagsOf(s);
      os << (flags.empty() ? "" : "  ") << flags << "\n";
    }
  }
  // The run-level lines (constant, load law, response, warnings) of the table, without its rows.
  AnalysisRun shared = run;
  shared.result.segments.clear();
  std::ostringstream table;
  printRunTables(table, {shared});
  std::istringstream lines(table.str());
  std::string line;
  while (std::getline(lines, line))
    if (line.rfind("  constant:", 0) == 0 || line.rfind("  load law:", 0) == 0 ||
        line.rfind("  modeled response:", 0) == 0 || line.rfind("  warning", 0) == 0)
      os << line << "\n";
}

}  // namespace

SegmentSummary summarizeSegments(const std::vector<SegmentEstimate>& segments,
                                 std::size_t worst_count) {
  SegmentSummary sum;
  sum.total = segments.size();
  std::vector<double> C, C_std, xi;
  for (const auto& s : segments) {
    const std::set<std::string> codes = flagCodes(s);
    if (!codes.empty()) {
      ++sum.flagged;
      for (const auto& c : codes) ++sum.codes[c];
    } else {
      ++sum.clean;
    }
    if (!s.identifiable) continue;
    ++sum.identifiable;
    C.push_back(s.C);
    C_std.push_back(s.C_std);
    xi.push_back(s.xi);
  }
  sum.C = statsOf(std::move(C));
  sum.C_std = statsOf(std::move(C_std));
  sum.xi = statsOf(std::move(xi));
  std::vector<std::size_t> order(segments.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  const std::size_t k = std::min(worst_count, order.size());
  std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(k), order.end(),
                    [&](std::size_t a, std::size_t b) {
                      const double ba = badness(segments[a]), bb = badness(segments[b]);
                      return ba != bb ? ba > bb : a < b;
                    });
  sum.worst.assign(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(k));
  return sum;
}

std::string summaryLine(const SegmentSummary& s) {
  std::ostringstream o;
  o << s.clean << " of " << s.total << " segment" << (s.total == 1 ? "" : "s") << " clean";
  if (s.flagged > 0) {
    o << ", " << s.flagged << " flagged (";
    bool first = true;
    for (const auto& [code, n] : s.codes) {
      o << (first ? "" : ", ") << code << " " << n;
      first = false;
    }
    o << ")";
  }
  return o.str();
}

void printRuns(std::ostream& os, const std::vector<AnalysisRun>& runs, RunPrintMode mode) {
  std::size_t most = 0;
  for (const auto& run : runs) most = std::max(most, run.result.segments.size());
  const bool summary =
      mode == RunPrintMode::Summary || (mode == RunPrintMode::Auto && most > kSummaryAboveSegments);
  for (const auto& run : runs) {
    const SegmentSummary sum = summarizeSegments(run.result.segments);
    if (summary)
      printSummaryBlock(os, run, sum);
    else
      printRunTables(os, {run});
    os << "  " << summaryLine(sum) << "\n";
  }
}

}  // namespace gear_damping_id
