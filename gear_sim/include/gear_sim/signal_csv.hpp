// The docs/method.md §6 CSV: a header row naming the columns (any order, any subset of the known
// names), then one row per sample, SI units. Part of gear_sim_io; no ROS.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "gear_sim/signal_table.hpp"
#include "gear_sim/status.hpp"

namespace gear_sim {

/// Column names in their canonical order: time, dte, dte_velocity, stiffness, torque,
/// mesh_state, mesh_phase, damping, theta1, theta2.
const std::vector<std::string>& signalColumnNames();

/// Writes the present columns of `table` (time and dte always) in canonical order with the
/// shortest text that reads back to the same double (std::to_chars), so a write/read round trip
/// is bit-exact. IoError if the file cannot be written, InvalidInput (field: the column) if
/// columns differ in length.
Status writeSignalCsv(const std::string& path, const SignalTable& table);

/// Longest line readSignalCsv accepts [bytes] (a row of ten numbers needs about 250).
constexpr size_t kMaxCsvLineBytes = 65536;

/// Reads a CSV into `out`. Accepts any order/subset of the known columns; `required` columns
/// must be present (default time and dte). Errors name the line and column: cannot open, empty
/// file, missing header, unknown or duplicate column, wrong field count, malformed number,
/// NaN/Inf (unless `allow_non_finite`: then NaN/Inf are kept in every column but time, for
/// analysers that report the affected segments as not identifiable), time not strictly
/// increasing, fewer than two rows, a line longer than kMaxCsvLineBytes. A UTF-8 byte-order
/// mark before the header is skipped. Messages quote file text escaped and truncated. (Uniformity
/// of the time step is the analysers' check.) IoError when the file cannot be opened, else
/// InvalidInput with the column concerned as the field when there is one.
Status readSignalCsv(const std::string& path, SignalTable* out,
                     const std::vector<std::string>& required = {"time", "dte"},
                     bool allow_non_finite = false);

/// The temporary file an atomic write of `path` goes through: `path` + ".partial", or, when
/// `path` names an existing file that is neither a regular file nor a directory (a device such as
/// /dev/null, a FIFO, a socket), a fresh file in the system's temporary directory (created
/// empty; IoError when it cannot be).
Result<std::string> partialPath(const std::string& path);

/// Finishes an atomic write: renames the complete temporary file `tmp` over `path`; when `path`
/// is a device, FIFO or socket (see partialPath), copies `tmp`'s bytes into it instead (a rename
/// would replace the device node by a regular file, as root) and removes `tmp`. On failure
/// removes `tmp` and returns IoError ("<path>: cannot write"): no partial file is left looking
/// complete.
Status commitFile(const std::string& tmp, const std::string& path);

/// An atomic write of `path`: `write(tmp)` fills the temporary file partialPath(path) gives,
/// commitFile puts it in place; on any failure (write's Status is returned as it is) the
/// temporary file is removed and `path` is left as it was.
Status writeAtomically(const std::string& path,
                       const std::function<Status(const std::string& tmp)>& write);

/// A load-torque file for the simulator's `load.profile: csv`: columns time and torque.
inline Status readTorqueCsv(const std::string& path, SignalTable* out) {
  return readSignalCsv(path, out, {"time", "torque"});
}

}  // namespace gear_sim
