#include "gear_damping_id/result_io.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <memory>
#include <sstream>
#include <type_traits>

#include "gear_damping_id/quality_flags.hpp"
#include "gear_sim/async.hpp"
#include "gear_sim/signal_csv.hpp"

namespace gear_damping_id {
namespace {

using nlohmann::json;

json num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

bool hasStiffnessLevels(Formulation f) { return f != Formulation::Known; }

// Full precision for the CSV tables; empty field for a non-finite value.
std::string csvNum(double v) {
  if (!std::isfinite(v)) return "";
  std::ostringstream o;
  o << std::setprecision(std::numeric_limits<double>::max_digits10) << v;
  return o.str();
}

// Field quoting for free text (reasons): quotes doubled, field quoted.
std::string csvText(const std::string& s) {
  std::string q = "\"";
  for (char ch : s) q += ch == '"' ? std::string("\"\"") : std::string(1, ch);
  return q + "\"";
}

// Quality warnings as [{code, text}] (empty array when clean).
json warningsJson(const QualityWarnings& ws) {
  json a = json::array();
  for (const auto& w : ws) a.push_back({{"code", w.code}, {"text", w.text}});
  return a;
}

const SegmentEstimate* sharedEstimate(const IdentificationResult& r) {
  return r.constant ? &*r.constant : nullptr;
}

std::string fmt(double v, int precision, bool fixed = false) {
  if (!std::isfinite(v)) return "-";
  std::ostringstream o;
  if (fixed) o << std::fixed;
  o << std::setprecision(precision) << v;
  return o.str();
}

}  // namespace

std::string AnalysisRun::name() const {
  return toString(options.formulation) + "_" + toString(options.model);
}

namespace {

// A segment's stiffness curve and its standard errors (NaN where the latter is missing): JSON
// arrays of num() values, stiffness_curve.size() long.
struct SegmentCurve {
  const std::vector<double>& values;
  size_t n;
  double at(size_t i) const { return i < values.size() ? values[i] : kNaN; }
};

// segmentJson's fields, the one list of them: emit(key, value) in bytewise key order (the
// order of nlohmann's std::map, so AnalysisJsonWriter streams the same bytes as dump()). A
// double becomes num(value) (null when not finite), a SegmentCurve an array of those; other
// values are written as json(value).
template <class Emit>
void segmentFields(const SegmentEstimate& s, Formulation f, Emit&& emit) {
  const bool levels = hasStiffnessLevels(f);
  const size_t n = s.stiffness_curve.size();
  emit("C", s.C);
  if (std::isfinite(s.C_integral)) {
    emit("C_integral", s.C_integral);
    emit("C_integral_std", s.C_integral_std);
  }
  emit("C_std", s.C_std);
  if (std::isfinite(s.C_torque_std)) emit("C_torque_std", s.C_torque_std);
  if (std::isfinite(s.variation_z) && std::isfinite(s.C_weighted)) {  // not the constant's
    emit("C_weighted", s.C_weighted);
    emit("C_weighted_std", s.C_weighted_std);
  }
  emit("c", s.c);
  emit("condition", s.condition);
  if (std::isfinite(s.forcing)) emit("forcing", s.forcing);
  emit("identifiable", s.identifiable);
  if (std::isfinite(s.information_share)) emit("information_share", s.information_share);
  if (levels) {
    emit("k_max", s.k_max);
    emit("k_max_std", s.k_max_std);
    emit("k_min", s.k_min);
    emit("k_min_std", s.k_min_std);
  }
  if (std::isfinite(s.mean_torque)) emit("mean_torque", s.mean_torque);
  emit("noise_std", s.noise_std);
  if (!s.identifiable) emit("reason", s.reason);
  emit("refined", s.refined);
  emit("residual_rms", s.residual_rms);
  emit("samples", s.samples);
  if (std::isfinite(s.shape_z)) emit("shape_z", s.shape_z);
  emit("signal_std", s.signal_std);
  if (n > 0) {
    emit("stiffness_curve", SegmentCurve{s.stiffness_curve, n});
    emit("stiffness_curve_std", SegmentCurve{s.stiffness_curve_std, n});
  }
  emit("t_end", s.t_end);
  emit("t_start", s.t_start);
  if (std::isfinite(s.torque_glitch)) {
    emit("torque_glitch", s.torque_glitch);
    emit("torque_glitch_response", s.torque_glitch_response);
    if (std::isfinite(s.torque_glitch_shift)) emit("torque_glitch_shift", s.torque_glitch_shift);
    emit("torque_glitch_time", s.torque_glitch_time);
    emit("torque_glitches", s.torque_glitches);
  }
  if (std::isfinite(s.torque_noise_std)) emit("torque_noise_std", s.torque_noise_std);
  if (std::isfinite(s.torque_quantum)) {
    emit("torque_quantisation_fit", s.torque_quantisation_fit);
    emit("torque_quantisation_fit_std", s.torque_quantisation_fit_std);
    emit("torque_quantisation_shift", s.torque_quantisation_shift);
    emit("torque_quantum", s.torque_quantum);
  }
  if (std::isfinite(s.torque_step)) {
    emit("torque_step", s.torque_step);
    emit("torque_step_response", s.torque_step_response);
    emit("torque_step_time", s.torque_step_time);
  }
  if (std::isfinite(s.variation_spread)) emit("variation_spread", s.variation_spread);
  if (std::isfinite(s.variation_z)) emit("variation_z", s.variation_z);
  emit("warnings", s.warnings);
  emit("windows", s.windows);
  emit("xi", s.xi);
}

}  // namespace

json segmentJson(const SegmentEstimate& s, Formulation f) {
  json j = json::object();
  segmentFields(s, f, [&j](const char* key, const auto& v) {
    using V = std::decay_t<decltype(v)>;
    if constexpr (std::is_same_v<V, double>) {
      j[key] = num(v);
    } else if constexpr (std::is_same_v<V, SegmentCurve>) {
      json a = json::array();
      for (size_t i = 0; i < v.n; ++i) a.push_back(num(v.at(i)));
      j[key] = std::move(a);
    } else if constexpr (std::is_same_v<V, QualityWarnings>) {
      j[key] = warningsJson(v);
    } else {
      j[key] = v;
    }
  });
  return j;
}

namespace {

json loadLawJson(const LoadLawEstimate& l) {
  json j = {{"c0", num(l.c0)},
            {"c0_std", num(l.c0_std)},
            {"c1", num(l.c1)},
            {"c1_std", num(l.c1_std)},
            {"identifiable", l.identifiable}};
  if (std::isfinite(l.curvature_z)) j["curvature_z"] = num(l.curvature_z);
  if (std::isfinite(l.curvature_spread)) j["curvature_spread"] = num(l.curvature_spread);
  if (std::isfinite(l.variation_z)) j["variation_z"] = num(l.variation_z);
  if (std::isfinite(l.variation_spread)) j["variation_spread"] = num(l.variation_spread);
  if (!l.identifiable) j["reason"] = l.reason;
  return j;
}

}  // namespace

json runJson(const AnalysisRun& run, bool segments) {
  const IdentificationResult& r = run.result;
  json j;
  j["formulation"] = toString(r.formulation);
  j["model"] = toString(r.model);
  j["estimator"] = r.estimator;
  j["iterations"] = r.iterations;
  j["noise_std"] = num(r.noise_std);
  j["equivalent_mass"] = num(r.equivalent_mass);
  j["omega0"] = num(r.omega0);
  j["window_length"] = num(r.window_length);
  j["segment_length"] = num(run.options.segment_length);
  if (r.formulation == Formulation::Greybox) {
    j["stiffness_shape"] = toString(run.options.stiffness_shape);
  }
  j["segments"] = segments ? json::array() : json(nullptr);  // null: written by the writer
  if (segments)
    for (const auto& s : r.segments) j["segments"].push_back(segmentJson(s, r.formulation));
  if (const SegmentEstimate* c = sharedEstimate(r)) j["constant"] = segmentJson(*c, r.formulation);
  if (r.load_law) j["load_law"] = loadLawJson(*r.load_law);
  j["warnings"] = warningsJson(r.warnings);
  if (run.response_error.empty()) {
    j["response"] = {{"nrmse", num(run.response.nrmse)},
                     {"fit_percent", num(run.response.fit_percent)}};
    if (run.response.unmodeled > 0) j["response"]["unmodeled_samples"] = run.response.unmodeled;
  } else {
    j["response"] = {{"nrmse", nullptr}, {"fit_percent", nullptr}, {"error", run.response_error}};
  }
  return j;
}

json analysisJson(const std::vector<AnalysisRun>& runs, const json& input, bool segments) {
  json doc;
  doc["input"] = input;
  if (runs.empty()) return doc;
  // Each run's JSON is built once; `identification` is the primary run's copy (a record of 1e7
  // samples has 1e4 segments: every extra copy of their DOM costs ~20 MB of peak memory).
  json& all = doc["runs"] = json::array();
  for (const auto& run : runs) all.push_back(runJson(run, segments));
  json id = all.front();
  doc["response"] = id["response"];
  id.erase("response");
  // The constant / load-law blocks of docs/method.md §6 come from the run that computed them.
  for (const auto& run : runs) {
    if (run.options.formulation != runs.front().options.formulation) continue;
    const IdentificationResult& r = run.result;
    const SegmentEstimate* c = sharedEstimate(r);
    if (!id.contains("constant") && c) id["constant"] = segmentJson(*c, r.formulation);
    if (!id.contains("load_law") && r.load_law) id["load_law"] = loadLawJson(*r.load_law);
  }
  doc["identification"] = std::move(id);
  return doc;
}

void printRunTables(std::ostream& os, const std::vector<AnalysisRun>& runs) {
  for (const auto& run : runs) {
    const IdentificationResult& r = run.result;
    const bool levels = hasStiffnessLevels(r.formulation);
    os << "== " << toString(r.formulation) << " formulation, " << toString(r.model) << " model ("
       << r.estimator << ", window " << fmt(r.window_length * 1e3, 4) << " ms, omega0 "
       << fmt(r.omega0, 6) << " rad/s, Me " << fmt(r.equivalent_mass, 6) << " kg)\n";
    if (r.model == DampingModel::Piecewise) {
      os << "  seg   t_start[ms]  t_end[ms]      C[1/s]   C_std[1/s]     c[N*s/m]       xi[-]";
      if (levels) os << "   k_min[N/m]   k_max[N/m]";
      os << "\n";
      int i = 0;
      for (const auto& s : r.segments) {
        os << "  " << std::setw(3) << i++ << "  " << std::setw(11) << fmt(s.t_start * 1e3, 4, true)
           << "  " << std::setw(9) << fmt(s.t_end * 1e3, 4, true);
        if (!s.identifiable) {
          os << "   not identifiable: " << s.reason << "\n";
          continue;
        }
        os << "  " << std::setw(10) << fmt(s.C, 6) << "  " << std::setw(11) << fmt(s.C_std, 3)
           << "  " << std::setw(11) << fmt(s.c, 6) << "  " << std::setw(10) << fmt(s.xi, 5);
        if (levels)
          os << "  " << std::setw(11) << fmt(s.k_min, 6) << "  " << std::setw(11)
             << fmt(s.k_max, 6);
        if (!s.warnings.empty()) os << "  flagged: " << joinCodes(s.warnings, ",");
        os << "\n";
      }
    }
    if (const SegmentEstimate* c = sharedEstimate(r)) {
      os << "  constant: C = " << fmt(c->C, 6) << " +- " << fmt(c->C_std, 3)
         << " 1/s, c = " << fmt(c->c, 6) << " N*s/m, xi = " << fmt(c->xi, 5);
      if (!c->identifiable) os << " (not identifiable: " << c->reason << ")";
      if (!c->warnings.empty()) os << "  flagged: " << joinCodes(c->warnings, ",");
      os << "\n";
    }
    if (r.load_law) {
      const LoadLawEstimate& l = *r.load_law;
      os << "  load law: c(t) = c0 + c1*T1(t), c0 = " << fmt(l.c0, 6) << " +- " << fmt(l.c0_std, 3)
         << " N*s/m, c1 = " << fmt(l.c1, 6) << " +- " << fmt(l.c1_std, 3) << " N*s/m/(N*m)";
      if (!l.identifiable) os << " (not identifiable: " << l.reason << ")";
      os << "\n";
    }
    if (run.response_error.empty()) {
      os << "  modeled response: fit " << fmt(run.response.fit_percent, 4, true) << " %, NRMSE "
         << fmt(run.response.nrmse, 4);
      if (run.response.unmodeled > 0)
        os << " (" << run.response.unmodeled
           << " samples not modeled: a bad input sample, a diverging estimate or a missing state "
              "stopped the re-simulation up to the next segment)";
      os << "\n";
    } else {
      os << "  modeled response: not available (" << run.response_error << ")\n";
    }
    for (const auto& w : r.warnings) os << "  warning [" << w.code << "]: " << w.text << "\n";
  }
}

namespace {
json waveletWarningsJson(const QualityWarnings& warnings) {
  json a = json::array();
  for (const auto& q : warnings) a.push_back({{"code", q.code}, {"text", q.text}});
  return a;
}
}  // namespace

json waveletJson(const WaveletResult& w) {
  json j;
  j["omega0"] = num(w.omega0);
  j["noise_std"] = num(w.noise_std);
  j["warnings"] = w.warnings;
  j["modes"] = json::array();
  for (const auto& m : w.modes) {
    j["modes"].push_back({{"frequency_hz", num(m.frequency_hz)},
                          {"spectrum_frequency_hz", num(m.spectrum_frequency_hz)},
                          {"damping_ratio", num(m.damping_ratio)},
                          {"r2", num(m.r2)},
                          {"sigma", num(m.sigma)},
                          {"t_start", num(m.t_start)},
                          {"t_end", num(m.t_end)},
                          {"omega0", num(m.omega0)},
                          {"peak_amplitude", num(m.peak_amplitude)},
                          {"noise_floor", num(m.noise_floor)},
                          {"integral_damping_ratio", num(m.integral_xi)},
                          {"free_decay", m.free_decay},
                          {"warnings", waveletWarningsJson(m.warnings)}});
  }
  return j;
}

void shiftWaveletTimes(WaveletResult* w, double t0) {
  for (auto& m : w->modes) m.t_start += t0, m.t_end += t0;
  for (auto& t : w->scalogram_times) t += t0;
}

void printWaveletTable(std::ostream& os, const WaveletResult& w) {
  os << "== wavelet validation (Morlet, omega0 " << fmt(w.omega0, 3) << "): " << w.modes.size()
     << " mode(s)\n"
     << "  mode  f[Hz]        xi_wavelet  xi_integral  R^2       decay region [ms]  free decay\n";
  int i = 0, clean = 0;
  for (const auto& m : w.modes) {
    os << "  " << std::setw(4) << i++ << "  " << std::setw(11) << fmt(m.frequency_hz, 6) << "  "
       << std::setw(10) << fmt(m.damping_ratio, 4) << "  " << std::setw(11) << fmt(m.integral_xi, 4)
       << "  " << std::setw(8) << fmt(m.r2, 4) << "  " << std::setw(8) << fmt(m.t_start * 1e3, 4)
       << " - " << std::setw(8) << fmt(m.t_end * 1e3, 4) << "  "
       << (m.free_decay ? "yes" : "NO (forced line)") << "\n";
    for (const auto& q : m.warnings) os << "        warning [" << q.code << "]: " << q.text << "\n";
    clean += m.warnings.empty() ? 1 : 0;
  }
  for (const auto& s : w.warnings) os << "  warning: " << s << "\n";
  os << "  " << clean << " of " << w.modes.size() << " modes clean";
  if (clean < static_cast<int>(w.modes.size())) {
    std::string codes;
    for (const auto& m : w.modes)
      for (const auto& q : m.warnings)
        if (codes.find(q.code) == std::string::npos) codes += (codes.empty() ? "" : ", ") + q.code;
    os << ", " << w.modes.size() - static_cast<size_t>(clean) << " flagged (" << codes << ")";
  }
  os << "\n";
}

gear_sim::Status writeWaveletCsv(const std::string& dir, const WaveletResult& w, const double* y,
                                 long n, double sample_rate, double t0, long max_points,
                                 OutputStage* stage) {
  using gear_sim::Status;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Status::ioError(dir + ": cannot create directory (" + ec.message() + ")");
  std::ostringstream modes, spectrum, scalogram;
  Status s = writeModesCsv(w, modes);
  if (s.ok()) s = writeSpectrumCsv(w, spectrum);
  if (s.ok()) s = writeFileAtomically(dir + "/wavelet_modes.csv", modes.str(), stage);
  if (s.ok()) s = writeFileAtomically(dir + "/wavelet_spectrum.csv", spectrum.str(), stage);
  if (s.ok() && w.modulus.size() > 0) {
    s = writeScalogramCsv(w, scalogram);
    if (s.ok()) s = writeFileAtomically(dir + "/wavelet_scalogram.csv", scalogram.str(), stage);
  }
  if (!s.ok()) return s;
  // Envelopes of the fitted modes, each at the omega0 of its fit.
  std::vector<double> freqs, omegas;
  std::vector<int> index;
  for (size_t k = 0; k < w.modes.size(); ++k) {
    const WaveletMode& m = w.modes[k];
    if (std::isfinite(m.frequency_hz) && std::isfinite(m.omega0)) {
      freqs.push_back(m.frequency_hz);
      omegas.push_back(m.omega0);
      index.push_back(static_cast<int>(k));
    }
  }
  std::ostringstream env;
  env << "mode,time,envelope\n";
  if (!freqs.empty()) {
    MorletCwt cwt;
    s = cwt.configure(n, sample_rate, freqs, omegas, FftPlanning::Estimate);
    if (s.ok()) s = cwt.setSignal(y);
    if (!s.ok()) return s.withContext("wavelet envelopes");
    std::vector<double> row(static_cast<size_t>(n));
    const long step = std::max<long>(1, (n + max_points - 1) / std::max<long>(1, max_points));
    for (size_t r = 0; r < freqs.size(); ++r) {
      if (!cwt.rowModulus(static_cast<int>(r), row.data())) continue;
      for (long j = 0; j < n; j += step)
        env << index[r] << "," << csvNum(t0 + static_cast<double>(j) / sample_rate) << ","
            << csvNum(row[static_cast<size_t>(j)]) << "\n";
    }
  }
  return writeFileAtomically(dir + "/wavelet_envelopes.csv", env.str(), stage);
}

OutputStage::~OutputStage() {
  for (const auto& f : files_) std::remove(f.first.c_str());
}

void OutputStage::add(const std::string& tmp, const std::string& path) {
  files_.emplace_back(tmp, path);
}

gear_sim::Status OutputStage::commit() {
  gear_sim::Status s;
  for (const auto& [tmp, path] : files_) {
    if (!s.ok())
      std::remove(tmp.c_str());
    else
      s = gear_sim::commitFile(tmp, path);
  }
  files_.clear();
  return s;
}

namespace {

// Writes the temporary file of `path` (gear_sim::partialPath: `path` + ".partial" for a regular
// file) with `write(stream)` (false or a failed stream: IoError with `field`, the partial file
// removed), then stages it in `stage` or, without one, commits it into place.
template <class Write>
gear_sim::Status writeThroughPartial(const std::string& path, OutputStage* stage,
                                     const std::string& field, Write write) {
  const gear_sim::Result<std::string> partial = gear_sim::partialPath(path);
  if (!partial.ok()) return gear_sim::Status::ioError(partial.status().message(), field);
  const std::string& tmp = *partial;
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f || !write(f) || !f.flush()) {
      std::remove(tmp.c_str());
      return gear_sim::Status::ioError(path + ": cannot write", field);
    }
  }
  if (stage) {
    stage->add(tmp, path);
    return {};
  }
  return gear_sim::commitFile(tmp, path);
}

}  // namespace

gear_sim::Status writeFileAtomically(const std::string& path, const std::string& text,
                                     OutputStage* stage) {
  return writeThroughPartial(path, stage, "",
                             [&](std::ostream& f) { return static_cast<bool>(f << text); });
}

namespace {

// nlohmann's serializer writing into a 1 MiB buffer passed on to the stream when full: the
// stream adapter of `f << doc` makes an ostream call per token (a sentry each), most of the
// time of writing a long record's document.
class BufferedJsonOutput : public nlohmann::detail::output_adapter_protocol<char> {
 public:
  explicit BufferedJsonOutput(std::ostream& f) : f_(f) { buffer_.reserve(kSize); }
  void write_character(char c) override {
    buffer_.push_back(c);
    if (buffer_.size() >= kSize) flush();
  }
  void write_characters(const char* s, std::size_t n) override {
    buffer_.append(s, n);
    if (buffer_.size() >= kSize) flush();
  }
  void flush() {
    f_.write(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
    buffer_.clear();
  }

 private:
  static constexpr std::size_t kSize = std::size_t{1} << 20;
  std::ostream& f_;
  std::string buffer_;
};

}  // namespace

gear_sim::Status writeJsonAtomically(const std::string& path, const json& doc, OutputStage* stage) {
  // Serialised into the file through a 1 MiB buffer: the text of a long record's document (tens
  // of MB) is never held in memory whole. The same serializer and settings as
  // `f << std::setw(2) << doc` (dump(2): pretty, indent 2 with ' ', UTF-8 as is), so the same
  // bytes.
  return writeThroughPartial(path, stage, "path", [&](std::ostream& f) {
    const auto out = std::make_shared<BufferedJsonOutput>(f);
    nlohmann::detail::serializer<json> s(out, ' ');
    s.dump(doc, true, false, 2);
    out->write_character('\n');
    out->flush();
    return static_cast<bool>(f);
  });
}

namespace {

// Text as nlohmann's serializer writes it (dump(..., true, false, 2): pretty, indent 2 with ' '),
// into any of its output adapters: the pieces AnalysisJsonWriter writes around the segments.
class JsonText {
 public:
  explicit JsonText(nlohmann::detail::output_adapter_t<char> out) : out_(out), s_(out, ' ') {}

 protected:
  // After an element: ",\n" when another follows, else "\n".
  void separator(bool more) { out_->write_characters(more ? ",\n" : "\n", more ? 2 : 1); }
  void indent(unsigned n) {
    static const std::string spaces(64, ' ');
    out_->write_characters(spaces.data(), n);
  }
  // Any value as the serializer writes it at indentation `at`.
  void scalar(const json& v, unsigned at) { s_.dump(v, true, false, 2, at); }

  nlohmann::detail::output_adapter_t<char> out_;
  nlohmann::detail::serializer<json> s_;
};

// The elements of a `segments` array appended to a string, segmentJson's bytes as the
// serializer writes them (dump(..., true, false, 2)) but straight into the string's buffer: a
// double as its dump_float (null when not finite, else its to_chars), a bool, an
// integer (decimal, as its dump_integer) and an empty warnings array as their text; only a
// reason and non-empty warnings (text to escape) go through the serializer.
class SegmentText {
 public:
  // Writing from the start of `buffer` (grown as needed, its bytes beyond size() unspecified).
  explicit SegmentText(std::string* buffer)
      : text_(*buffer), s_(std::make_shared<StringOut>(scratch_), ' ') {}
  // The length of the text written.
  size_t size() const { return used_; }

  // The elements [a, b) of a `segments` array of n at indentation `at`, each with its
  // separator.
  void elements(const std::vector<SegmentEstimate>& segs, size_t a, size_t b, Formulation f,
                unsigned at) {
    for (size_t i = a; i < b; ++i) {
      put(kSpaces, at);
      segment(segs[i], f, at);
      i + 1 < segs.size() ? put(",\n", 2) : put("\n", 1);
    }
  }

 private:
  using StringOut = nlohmann::detail::output_string_adapter<char>;
  static constexpr const char* kSpaces =
      "                                                                ";
  static constexpr size_t kNumberRoom = 64;  // the serializer's number buffer

  // Room for n more bytes at the end of the text written so far.
  char* room(size_t n) {
    if (text_.size() - used_ < n) text_.resize(std::max(2 * text_.size(), used_ + n + 4096));
    return &text_[used_];
  }
  void put(const char* s, size_t n) {
    std::memcpy(room(n), s, n);
    used_ += n;
  }
  void number(double v) {
    if (!std::isfinite(v)) return put("null", 4);
    char* p = room(kNumberRoom);
    used_ += static_cast<size_t>(nlohmann::detail::to_chars(p, p + kNumberRoom, v) - p);
  }
  template <class Int>
  void integer(Int v) {
    char* p = room(kNumberRoom);
    used_ += static_cast<size_t>(std::to_chars(p, p + kNumberRoom, v).ptr - p);
  }
  // Any value through the serializer at indentation `at`.
  void serialized(const json& v, unsigned at) {
    scratch_.clear();
    s_.dump(v, true, false, 2, at);
    put(scratch_.data(), scratch_.size());
  }
  // One field of a segment object: separator, indentation, key.
  void field(const char* key, unsigned at, bool* first) {
    *first ? put("\n", 1) : put(",\n", 2);
    *first = false;
    put(kSpaces, at);
    put("\"", 1);
    put(key, std::strlen(key));
    put("\": ", 3);
  }
  void curve(const SegmentCurve& c, unsigned at) {
    put("[\n", 2);
    for (size_t i = 0; i < c.n; ++i) {
      put(kSpaces, at + 2);
      number(c.at(i));
      i + 1 < c.n ? put(",\n", 2) : put("\n", 1);
    }
    put(kSpaces, at);
    put("]", 1);
  }
  // segmentJson(s, f) at indentation `at`: its keys in the order of a std::map (bytewise).
  void segment(const SegmentEstimate& s, Formulation f, unsigned at);

  std::string& text_;
  size_t used_ = 0;
  std::string scratch_;
  nlohmann::detail::serializer<json> s_;
};

void SegmentText::segment(const SegmentEstimate& s, Formulation f, unsigned at) {
  const unsigned in = at + 2;
  bool first = true;
  put("{", 1);
  segmentFields(s, f, [&](const char* key, const auto& v) {
    using V = std::decay_t<decltype(v)>;
    field(key, in, &first);
    if constexpr (std::is_same_v<V, double>) {
      number(v);
    } else if constexpr (std::is_same_v<V, SegmentCurve>) {
      curve(v, in);
    } else if constexpr (std::is_same_v<V, bool>) {
      v ? put("true", 4) : put("false", 5);
    } else if constexpr (std::is_integral_v<V>) {
      integer(v);
    } else if constexpr (std::is_same_v<V, QualityWarnings>) {
      if (v.empty()) return put("[]", 2);
      serialized(warningsJson(v), in);
    } else {
      serialized(json(v), in);
    }
  });
  put("\n", 1);
  put(kSpaces, at);
  put("}", 1);
}

// The document as serializer::dump(doc, true, false, 2) writes it (nlohmann's pretty printer:
// objects with their keys sorted, "{}" / "[]" when empty, indent 2), except that a null
// "segments" of runs[k] or of identification (analysisJson(..., false)) is written straight
// from runs[k] / runs[0] with the bytes segmentJson's array would have: the 2e4 segment
// objects of a 1e7-sample record are never built as a tree. Scalars go through nlohmann's
// serializer, so every number is formatted by it (or by its to_chars, the same bytes).
class AnalysisJsonWriter : JsonText {
 public:
  AnalysisJsonWriter(std::shared_ptr<BufferedJsonOutput> out, const std::vector<AnalysisRun>& runs)
      : JsonText(out), runs_(runs) {}

  void document(const json& doc) {
    if (!doc.is_object() || doc.empty()) return scalar(doc, 0);
    out_->write_characters("{\n", 2);
    size_t left = doc.size();
    for (auto it = doc.begin(); it != doc.end(); ++it) {
      const std::string& key = it.key();
      const json& value = it.value();
      keyText(key, 2);
      if (key == "runs" && value.is_array() && !value.empty()) {
        out_->write_characters("[\n", 2);
        for (size_t k = 0; k < value.size(); ++k) {
          indent(4);
          run(value[k], k < runs_.size() ? &runs_[k] : nullptr, 4);
          separator(k + 1 < value.size());
        }
        indent(2);
        out_->write_character(']');
      } else if (key == "identification") {
        run(value, runs_.empty() ? nullptr : &runs_.front(), 2);
      } else {
        scalar(value, 2);
      }
      separator(--left > 0);
    }
    out_->write_character('}');
  }

 private:
  void keyText(const std::string& key, unsigned at) {
    indent(at);
    s_.dump(json(key), true, false, 2, at);
    out_->write_characters(": ", 2);
  }

  // A run object at indentation `at`, its null "segments" from `r`.
  void run(const json& v, const AnalysisRun* r, unsigned at) {
    if (!v.is_object() || v.empty() || r == nullptr) return scalar(v, at);
    out_->write_characters("{\n", 2);
    size_t left = v.size();
    for (auto it = v.begin(); it != v.end(); ++it) {
      const std::string& key = it.key();
      const json& value = it.value();
      keyText(key, at + 2);
      if (key == "segments" && value.is_null())
        segments(*r, at + 2);
      else
        scalar(value, at + 2);
      separator(--left > 0);
    }
    indent(at);
    out_->write_character('}');
  }

  // The segment objects in batches of kBatch, every second batch formatted on a thread of its
  // own into a string written after this thread's batch (the order and bytes of one thread; the
  // text held is two batches, ~0.3 MB, whatever the record's length).
  void segments(const AnalysisRun& r, unsigned at) {
    constexpr size_t kBatch = 256;
    const auto& segs = r.result.segments;
    const Formulation f = r.result.formulation;
    if (segs.empty()) return out_->write_characters("[]", 2);
    out_->write_characters("[\n", 2);
    std::string mine, later;  // (reused: the batches' text)
    for (size_t a = 0; a < segs.size(); a += 2 * kBatch) {
      const size_t b = std::min(a + kBatch, segs.size()), c = std::min(b + kBatch, segs.size());
      size_t later_size = 0;
      std::future<void> other;
      if (c > b)
        other = gear_sim::startAsync([&] {
          SegmentText text(&later);
          text.elements(segs, b, c, f, at + 2);
          later_size = text.size();
        });
      SegmentText text(&mine);
      text.elements(segs, a, b, f, at + 2);
      out_->write_characters(mine.data(), text.size());
      if (other.valid()) {
        other.get();
        out_->write_characters(later.data(), later_size);
      }
    }
    indent(at);
    out_->write_character(']');
  }

  const std::vector<AnalysisRun>& runs_;
};

}  // namespace

gear_sim::Status writeAnalysisJsonAtomically(const std::string& path, const json& doc,
                                             const std::vector<AnalysisRun>& runs,
                                             OutputStage* stage) {
  return writeThroughPartial(path, stage, "path", [&](std::ostream& f) {
    const auto out = std::make_shared<BufferedJsonOutput>(f);
    AnalysisJsonWriter(out, runs).document(doc);
    out->write_character('\n');
    out->flush();
    return static_cast<bool>(f);
  });
}

gear_sim::Status writeRunCsv(const std::string& dir, const std::vector<AnalysisRun>& runs,
                             OutputStage* stage) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec)
    return gear_sim::Status::ioError(dir + ": cannot create directory (" + ec.message() + ")");
  std::ostringstream seg, sum;
  seg << "formulation,model,segment,t_start,t_end,C,C_std,c,xi,k_min,k_max,identifiable,reason,"
         "warnings,stiffness_curve\n";
  sum << "formulation,model,estimator,C,C_std,c,xi,c0,c0_std,c1,c1_std,nrmse,fit_percent,"
         "warnings\n";
  for (const auto& run : runs) {
    const IdentificationResult& r = run.result;
    const std::string head = toString(r.formulation) + "," + toString(r.model) + ",";
    int i = 0;
    for (const auto& s : r.segments) {
      seg << head << i++ << "," << csvNum(s.t_start) << "," << csvNum(s.t_end) << "," << csvNum(s.C)
          << "," << csvNum(s.C_std) << "," << csvNum(s.c) << "," << csvNum(s.xi) << ","
          << csvNum(s.k_min) << "," << csvNum(s.k_max) << "," << (s.identifiable ? 1 : 0) << ","
          << (s.identifiable ? std::string() : csvText(s.reason)) << ","
          << joinCodes(s.warnings, ";") << ",";
      for (size_t k = 0; k < s.stiffness_curve.size(); ++k) {
        seg << (k > 0 ? ";" : "") << csvNum(s.stiffness_curve[k]);
      }
      seg << "\n";
    }
    const SegmentEstimate* c = sharedEstimate(r);
    const LoadLawEstimate* l = r.load_law ? &*r.load_law : nullptr;
    sum << head << r.estimator << "," << csvNum(c ? c->C : kNaN) << ","
        << csvNum(c ? c->C_std : kNaN) << "," << csvNum(c ? c->c : kNaN) << ","
        << csvNum(c ? c->xi : kNaN) << "," << csvNum(l ? l->c0 : kNaN) << ","
        << csvNum(l ? l->c0_std : kNaN) << "," << csvNum(l ? l->c1 : kNaN) << ","
        << csvNum(l ? l->c1_std : kNaN) << "," << csvNum(run.response.nrmse) << ","
        << csvNum(run.response.fit_percent) << "," << joinCodes(r.warnings, ";") << "\n";
    if (run.response_error.empty() && run.response.observed.size() > 0) {
      std::ostringstream resp;
      resp << "time,observed,modeled\n";
      for (Eigen::Index k = 0; k < run.response.observed.size(); ++k) {
        const double t = run.t0 + static_cast<double>(run.response.begin + k) * run.dt;
        resp << csvNum(t) << "," << csvNum(run.response.observed[k]) << ","
             << csvNum(run.response.modeled[k]) << "\n";
      }
      if (gear_sim::Status s =
              writeFileAtomically(dir + "/response_" + run.name() + ".csv", resp.str(), stage);
          !s.ok())
        return s;
    }
  }
  if (gear_sim::Status s = writeFileAtomically(dir + "/segments.csv", seg.str(), stage); !s.ok())
    return s;
  return writeFileAtomically(dir + "/summary.csv", sum.str(), stage);
}

}  // namespace gear_damping_id
