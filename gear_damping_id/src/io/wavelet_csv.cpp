// CSV writers of a wavelet validation: see wavelet_io.hpp. Each writer formats into a
// std::ostream; the path overloads open the file, delegate, and name the path in I/O errors.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>

#include "gear_damping_id/wavelet_io.hpp"

namespace gear_damping_id {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string num(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

void quoted(std::ostream& out, const std::string& text) {
  out << '"';
  for (char ch : text) out << (ch == '"' ? "\"\"" : std::string(1, ch));
  out << '"';
}

using gear_sim::Status;

template <typename Writer>
Status writeToFile(const std::string& path, const char* what, Writer write) {
  std::ofstream out(path);
  if (!out) return Status::ioError(std::string(what) + ": cannot open '" + path + "' for writing");
  if (Status s = write(out); !s.ok()) return s;
  out.flush();
  if (!out) return Status::ioError(std::string(what) + ": write to '" + path + "' failed");
  return {};
}

std::string csvNumber(double v, const char* format) {
  if (std::isnan(v)) return "nan";
  char buf[40];
  std::snprintf(buf, sizeof(buf), format, v);
  return buf;
}

}  // namespace

gear_sim::Status writeScalogramCsv(const WaveletResult& result, std::ostream& out,
                                   long max_columns) {
  const long rows = result.modulus.rows(), cols = result.modulus.cols();
  if (rows == 0 || cols == 0)
    return Status::invalidArgument("writeScalogramCsv: the result holds no scalogram");
  if (static_cast<size_t>(rows) != result.frequencies.size() ||
      static_cast<size_t>(cols) != result.scalogram_times.size()) {
    return Status::invalidArgument("writeScalogramCsv: inconsistent result (modulus is " +
                                   std::to_string(rows) + "x" + std::to_string(cols) + ")");
  }
  if (max_columns < 1) {
    return Status::invalidArgument(
        "writeScalogramCsv: max_columns = " + std::to_string(max_columns) + " must be >= 1",
        "max_columns");
  }
  const long d = cols > max_columns ? (cols + max_columns - 1) / max_columns : 1;
  const long oc = (cols + d - 1) / d;
  out << "# gear_damping Morlet scalogram |W| (omega0 = " << num(result.omega0)
      << "). Row 1: NaN, NaN, times [s]; then per frequency: frequency [Hz], cone-of-influence "
         "half-width [s], |W| per time\n";
  out << "nan,nan";
  for (long c = 0; c < oc; ++c) {
    const long b = c * d, e = std::min(cols, b + d);
    double t = 0.0;
    for (long j = b; j < e; ++j) t += result.scalogram_times[static_cast<size_t>(j)];
    out << ',' << csvNumber(t / static_cast<double>(e - b), "%.9g");
  }
  out << '\n';
  for (long r = 0; r < rows; ++r) {
    out << csvNumber(result.frequencies[static_cast<size_t>(r)], "%.9g") << ','
        << csvNumber(
               r < static_cast<long>(result.coi.size()) ? result.coi[static_cast<size_t>(r)] : kNaN,
               "%.9g");
    for (long c = 0; c < oc; ++c) {
      const long b = c * d, e = std::min(cols, b + d);
      double v = 0.0;
      for (long j = b; j < e; ++j) v += result.modulus(r, j);
      out << ',' << csvNumber(v / static_cast<double>(e - b), "%.7g");
    }
    out << '\n';
  }
  return out ? Status() : Status::ioError("writeScalogramCsv: write failed");
}

gear_sim::Status writeScalogramCsv(const WaveletResult& result, const std::string& path,
                                   long max_columns) {
  return writeToFile(path, "writeScalogramCsv", [&](std::ostream& out) {
    return writeScalogramCsv(result, out, max_columns);
  });
}

gear_sim::Status writeSpectrumCsv(const WaveletResult& result, std::ostream& out) {
  if (result.spectrum_freq.size() != result.spectrum_power.size() ||
      result.frequencies.size() != result.scalogram_power.size()) {
    return Status::invalidArgument(
        "writeSpectrumCsv: inconsistent result (spectrum and frequency sizes differ)");
  }
  if (result.spectrum_freq.empty() && result.frequencies.empty()) {
    return Status::invalidArgument("writeSpectrumCsv: the result holds no spectrum");
  }
  const double f_top = result.frequencies.empty() ? std::numeric_limits<double>::infinity()
                                                  : result.frequencies.back();
  out << "kind,frequency_hz,power\n";
  for (size_t k = 0; k < result.spectrum_freq.size(); ++k) {
    if (result.spectrum_freq[k] > f_top) break;
    out << "psd," << csvNumber(result.spectrum_freq[k], "%.9g") << ','
        << csvNumber(result.spectrum_power[k], "%.9g") << '\n';
  }
  for (size_t i = 0; i < result.frequencies.size(); ++i) {
    out << "scalogram," << csvNumber(result.frequencies[i], "%.9g") << ','
        << csvNumber(result.scalogram_power[i], "%.9g") << '\n';
  }
  return out ? Status() : Status::ioError("writeSpectrumCsv: write failed");
}

gear_sim::Status writeSpectrumCsv(const WaveletResult& result, const std::string& path) {
  return writeToFile(path, "writeSpectrumCsv",
                     [&](std::ostream& out) { return writeSpectrumCsv(result, out); });
}

gear_sim::Status writeModesCsv(const WaveletResult& result, std::ostream& out) {
  out << "frequency_hz,spectrum_frequency_hz,damping_ratio,integral_damping_ratio,sigma_per_s,"
         "r2,t_start_s,t_end_s,omega0,peak_amplitude,noise_floor,free_decay,warning_codes,"
         "warnings\n";
  for (const WaveletMode& m : result.modes) {
    for (double v :
         {m.frequency_hz, m.spectrum_frequency_hz, m.damping_ratio, m.integral_xi, m.sigma, m.r2,
          m.t_start, m.t_end, m.omega0, m.peak_amplitude, m.noise_floor}) {
      out << csvNumber(v, "%.9g") << ',';
    }
    std::string codes;
    for (const QualityWarning& w : m.warnings) codes += (codes.empty() ? "" : ";") + w.code;
    out << (m.free_decay ? "true" : "false") << ',' << codes << ',';
    quoted(out, warningText(m.warnings));
    out << '\n';
  }
  return out ? Status() : Status::ioError("writeModesCsv: write failed");
}

gear_sim::Status writeModesCsv(const WaveletResult& result, const std::string& path) {
  return writeToFile(path, "writeModesCsv",
                     [&](std::ostream& out) { return writeModesCsv(result, out); });
}

}  // namespace gear_damping_id
