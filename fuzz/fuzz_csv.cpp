// libFuzzer target: the signal CSV reader and the record checks the analysers apply after it
// (the plausibility masking, uniform time step, sample rate against the gear model, record length).
// The input is written to a temporary file (the reader takes a path). Any crash, sanitizer report,
// leak or allocation beyond libFuzzer's limit is a finding.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "../test/unit/support/status_support.hpp"
#include "fuzz_support.hpp"
#include "gear_damping_id/input_checks.hpp"
#include "gear_sim/signal_csv.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  static const std::string path = gear_fuzz::tempPath("csv");
  if (!gear_fuzz::writeFile(path, data, size)) return 0;
  gear_sim::SignalTable t;
  std::string error;
  const bool allow_non_finite = size > 0 && (data[size - 1] & 1);
  if (!gear_test::ok(gear_sim::readSignalCsv(path, &t, {"time", "dte"}, allow_non_finite),
                     &error)) {
    gear_fuzz::checkMessage(error);
    return 0;
  }
  // `analyze`'s plausibility masking (implausible values read as NaN) and its warnings.
  const gear_sim::ImplausibleCounts counts = gear_sim::maskImplausible(&t);
  for (const std::string& w : gear_sim::implausibleWarnings(counts, "in the file"))
    gear_fuzz::checkMessage(w);
  // The analysers' checks on what was read: a mean step, a rate, the record length.
  const Eigen::Index n = t.size();
  const double dt = (t.time[n - 1] - t.time[0]) / static_cast<double>(n - 1);
  gear_damping_id::GearConstants gear;  // the default gear pair
  std::string warning;
  gear_fuzz::checkMessage(gear_damping_id::checkSampleRate(1.0 / dt, gear, &warning).message());
  gear_damping_id::IdentificationOptions options;
  gear_fuzz::checkMessage(
      gear_damping_id::checkRecordLength(t.time[n - 1] - t.time[0] + dt, options).message());
  return 0;
}
