#include "gear_sim/sim_config.hpp"

#include <cmath>
#include <sstream>
#include <type_traits>

#include "gear_sim/message_text.hpp"
#include "gear_sim/simulator.hpp"

namespace gear_sim {
namespace {

// Every rule of the simulator configuration names its YAML key path (a SimConfig member path).
template <class T>
OptionStatus bad(const std::string& key, const T& value, const std::string& rule) {
  return violated("SimConfig", key, value, rule);
}

bool positive(double x) { return std::isfinite(x) && x > 0.0; }

OptionStatus checkIncreasing(const std::vector<double>& v, const std::string& key) {
  for (size_t i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v[i]))
      return bad(key + "[" + std::to_string(i) + "]", v[i], "must be finite");
    if (i > 0 && !(v[i] > v[i - 1]))
      return bad(key + "[" + std::to_string(i) + "]", v[i], "must be strictly increasing");
  }
  return {};
}

}  // namespace

OptionStatus MeshOptions::check() const {
  if (!(contact_ratio > 1.0 && contact_ratio <= 2.0))
    return bad("mesh.contact_ratio", contact_ratio, "must be in (1, 2]");
  if (!(initial_phase >= 0.0 && initial_phase < 1.0))
    return bad("mesh.initial_phase", initial_phase, "must be in [0, 1) [mesh cycles]");
  switch (model) {
    case StiffnessModel::Square:
    case StiffnessModel::Trapezoid:
      if (!positive(k_min)) return bad("mesh.k_min", k_min, "must be finite and > 0 [N/m]");
      if (!positive(k_max)) return bad("mesh.k_max", k_max, "must be finite and > 0 [N/m]");
      if (k_min > k_max) return bad("mesh.k_min", k_min, "must not exceed mesh.k_max");
      if (model == StiffnessModel::Trapezoid) {
        const double e = contact_ratio - 1.0;
        const double limit = std::min(e, 1.0 - e);
        if (!(transition_fraction > 0.0 && transition_fraction <= limit))
          return bad("mesh.transition_fraction", transition_fraction,
                     "must be in (0, min(eps-1, 2-eps)] = (0, " + std::to_string(limit) + "]");
      }
      break;
    case StiffnessModel::Fourier: {
      if (!positive(k_mean)) return bad("mesh.k_mean", k_mean, "must be finite and > 0 [N/m]");
      if (fourier_cos.size() != fourier_sin.size())
        return bad("mesh.fourier_sin", fourier_sin.size(),
                   "must have as many entries as mesh.fourier_cos");
      double amp = 0.0;
      for (size_t h = 0; h < fourier_cos.size(); ++h) {
        if (!std::isfinite(fourier_cos[h]) || !std::isfinite(fourier_sin[h]))
          return bad("mesh.fourier_cos/sin[" + std::to_string(h) + "]", "non-finite",
                     "must be finite");
        amp += std::hypot(fourier_cos[h], fourier_sin[h]);
      }
      if (!(amp < k_mean))
        return bad("mesh.fourier_cos/sin", amp,
                   "sum of harmonic amplitudes must stay below mesh.k_mean (k > 0)");
      break;
    }
    case StiffnessModel::Constant:
      if (!positive(k_mean)) return bad("mesh.k_mean", k_mean, "must be finite and > 0 [N/m]");
      break;
  }
  return {};
}

OptionStatus SpeedOptions::check() const {
  if (!positive(pinion_rpm))
    return bad("speed.pinion_rpm", pinion_rpm, "must be finite and > 0 [rpm]");
  if (profile == SpeedProfile::Ramp) {
    if (!positive(end_rpm)) return bad("speed.end_rpm", end_rpm, "must be finite and > 0 [rpm]");
    if (!positive(ramp_time))
      return bad("speed.ramp_time", ramp_time, "must be finite and > 0 [s]");
  }
  return {};
}

OptionStatus LoadOptions::check() const {
  auto finite = [](double x) { return std::isfinite(x); };
  switch (profile) {
    case LoadProfile::Constant:
      if (!finite(mean)) return bad("load.mean", mean, "must be finite [N*m]");
      break;
    case LoadProfile::Sine:
      if (!finite(mean)) return bad("load.mean", mean, "must be finite [N*m]");
      if (!finite(amplitude)) return bad("load.amplitude", amplitude, "must be finite [N*m]");
      if (!(finite(frequency) && frequency >= 0.0))
        return bad("load.frequency", frequency, "must be finite and >= 0 [Hz]");
      if (!finite(phase)) return bad("load.phase", phase, "must be finite [rad]");
      break;
    case LoadProfile::Step:
      if (!finite(initial)) return bad("load.initial", initial, "must be finite [N*m]");
      if (!finite(final_value)) return bad("load.final", final_value, "must be finite [N*m]");
      if (!finite(step_time)) return bad("load.step_time", step_time, "must be finite [s]");
      break;
    case LoadProfile::Ramp:
      if (!finite(initial)) return bad("load.initial", initial, "must be finite [N*m]");
      if (!finite(final_value)) return bad("load.final", final_value, "must be finite [N*m]");
      if (!finite(ramp_start)) return bad("load.ramp_start", ramp_start, "must be finite [s]");
      if (!(finite(ramp_end) && ramp_end > ramp_start))
        return bad("load.ramp_end", ramp_end, "must be > load.ramp_start [s]");
      break;
    case LoadProfile::Trapezoid:
      if (!finite(low)) return bad("load.low", low, "must be finite [N*m]");
      if (!finite(high)) return bad("load.high", high, "must be finite [N*m]");
      if (!positive(rise)) return bad("load.rise", rise, "must be > 0 [s]");
      if (!(finite(hold) && hold >= 0.0)) return bad("load.hold", hold, "must be >= 0 [s]");
      if (!positive(fall)) return bad("load.fall", fall, "must be > 0 [s]");
      if (!(finite(period) && period >= rise + hold + fall))
        return bad("load.period", period, "must be >= rise + hold + fall [s]");
      break;
    case LoadProfile::Table: {
      if (times.size() < 1) return bad("load.times", "[]", "needs at least one point");
      if (times.size() != values.size())
        return bad("load.values", values.size(), "must have as many entries as load.times");
      if (auto e = checkIncreasing(times, "load.times"); !e.ok()) return e;
      for (size_t i = 0; i < values.size(); ++i)
        if (!finite(values[i]))
          return bad("load.values[" + std::to_string(i) + "]", values[i], "must be finite [N*m]");
      break;
    }
  }
  return {};
}

OptionStatus DampingOptions::check() const {
  auto nonneg = [](double x) { return std::isfinite(x) && x >= 0.0; };
  const std::string ratio_rule =
      "must be finite and in [0, " + formatNumber(kMaxDampingRatio) + "]";
  auto ratioOk = [](double x) { return std::isfinite(x) && x >= 0.0 && x <= kMaxDampingRatio; };
  switch (model) {
    case DampingProfile::ConstantRatio:
      if (!ratioOk(ratio)) return bad("damping.ratio", ratio, ratio_rule);
      break;
    case DampingProfile::ConstantCoefficient:
      if (!nonneg(coefficient))
        return bad("damping.coefficient", coefficient, "must be finite and >= 0 [N*s/m]");
      break;
    case DampingProfile::Piecewise:
      if (times.empty()) return bad("damping.times", "[]", "needs at least one segment start");
      if (times.size() != ratios.size())
        return bad("damping.ratios", ratios.size(), "must have as many entries as damping.times");
      if (times[0] != 0.0)
        return bad("damping.times[0]", times[0], "must be 0 (first segment starts at t = 0)");
      if (auto e = checkIncreasing(times, "damping.times"); !e.ok()) return e;
      for (size_t i = 0; i < ratios.size(); ++i)
        if (!ratioOk(ratios[i]))
          return bad("damping.ratios[" + std::to_string(i) + "]", ratios[i], ratio_rule);
      break;
    case DampingProfile::LoadDependent:
      if (!ratioOk(ratio)) return bad("damping.ratio", ratio, ratio_rule);
      if (!std::isfinite(load_sensitivity))
        return bad("damping.load_sensitivity", load_sensitivity, "must be finite");
      break;
    case DampingProfile::LoadLinear:
      if (!std::isfinite(c0)) return bad("damping.c0", c0, "must be finite [N*s/m]");
      if (!std::isfinite(c1)) return bad("damping.c1", c1, "must be finite [N*s/m per N*m]");
      break;
  }
  return {};
}

OptionStatus SimulationOptions::check() const {
  if (!positive(duration))
    return bad("simulation.duration", duration, "must be finite and > 0 [s]");
  if (!positive(sample_rate))
    return bad("simulation.sample_rate", sample_rate, "must be finite and > 0 [Hz]");
  if (!(duration * sample_rate <= kMaxSimulationSamples))
    return bad("simulation.duration", duration,
               "gives " + formatNumber(duration * sample_rate) +
                   " samples at simulation.sample_rate = " + formatNumber(sample_rate) +
                   " Hz, more than the limit of " + formatNumber(kMaxSimulationSamples));
  if (std::llround(duration * sample_rate) < 2)
    return bad("simulation.duration", duration,
               "must span at least two samples at simulation.sample_rate");
  if (substeps < 1 || substeps > kMaxSubsteps)
    return bad("simulation.substeps", substeps,
               "must be in [1, " + std::to_string(kMaxSubsteps) + "]");
  if (!std::isfinite(initial_dte))
    return bad("simulation.initial_dte", initial_dte, "must be finite [m]");
  if (!std::isfinite(initial_velocity))
    return bad("simulation.initial_velocity", initial_velocity, "must be finite [m/s]");
  if (std::isnan(noise_snr_db))
    return bad("simulation.noise_snr_db", noise_snr_db, "must be a number or .inf [dB]");
  return {};
}

OptionStatus GearModel::check() const {
  if (auto e = gears.check(); !e.ok()) return e;
  if (auto e = mesh.check(); !e.ok()) return e;
  return speed.check();
}

OptionStatus SimConfig::check() const {
  if (auto e = gearModel().check(); !e.ok()) return e;
  if (auto e = load.check(); !e.ok()) return e;
  if (auto e = damping.check(); !e.ok()) return e;
  if (auto e = simulation.check(); !e.ok()) return e;
  if (auto e = ste.check(); !e.ok()) return e;
  const double max_rpm = speed.profile == SpeedProfile::Ramp
                             ? std::max(speed.pinion_rpm, speed.end_rpm)
                             : speed.pinion_rpm;
  const double mesh_hz = max_rpm / 60.0 * gears.pinion.teeth;
  if (!(mesh_hz <= simulation.sample_rate))
    return bad(speed.profile == SpeedProfile::Ramp && speed.end_rpm > speed.pinion_rpm
                   ? "speed.end_rpm"
                   : "speed.pinion_rpm",
               max_rpm,
               "gives a mesh frequency of " + formatNumber(mesh_hz) +
                   " Hz, above simulation.sample_rate (" + formatNumber(simulation.sample_rate) +
                   " Hz)");
  if (load.profile == LoadProfile::Trapezoid && !(load.period * simulation.sample_rate >= 1.0))
    return bad("load.period", load.period,
               "must be at least one sample step (1 / simulation.sample_rate)");
  const double fn = naturalFrequencyHz(gears, mesh);
  if (simulation.sample_rate < 20.0 * fn) {
    std::ostringstream os;
    os << "must be >= 20x the natural frequency " << fn << " Hz, i.e. >= " << 20.0 * fn << " Hz";
    return bad("simulation.sample_rate", simulation.sample_rate, os.str());
  }
  return {};
}

namespace {
template <class E, size_t N>
bool parseName(const std::string& s, const std::pair<const char*, E> (&names)[N], E* out) {
  for (const auto& [name, value] : names)
    if (s == name) {
      *out = value;
      return true;
    }
  return false;
}
template <class E, size_t N>
std::string nameOf(E v, const std::pair<const char*, E> (&names)[N]) {
  for (const auto& [name, value] : names)
    if (v == value) return name;
  return "?";
}
const std::pair<const char*, StiffnessModel> kStiffness[] = {
    {"square", StiffnessModel::Square},
    {"trapezoid", StiffnessModel::Trapezoid},
    {"fourier", StiffnessModel::Fourier},
    {"constant", StiffnessModel::Constant}};
const std::pair<const char*, SpeedProfile> kSpeed[] = {{"constant", SpeedProfile::Constant},
                                                       {"ramp", SpeedProfile::Ramp}};
const std::pair<const char*, LoadProfile> kLoad[] = {
    {"constant", LoadProfile::Constant},   {"sine", LoadProfile::Sine},
    {"step", LoadProfile::Step},           {"ramp", LoadProfile::Ramp},
    {"trapezoid", LoadProfile::Trapezoid}, {"table", LoadProfile::Table}};
const std::pair<const char*, DynamicsModel> kDynamics[] = {{"reduced", DynamicsModel::Reduced},
                                                           {"torsional", DynamicsModel::Torsional}};
const std::pair<const char*, Integrator> kIntegrator[] = {{"rk2", Integrator::Rk2},
                                                          {"rk4", Integrator::Rk4}};
}  // namespace

std::string toString(StiffnessModel m) { return nameOf(m, kStiffness); }
std::string toString(SpeedProfile p) { return nameOf(p, kSpeed); }
std::string toString(LoadProfile p) { return nameOf(p, kLoad); }
std::string toString(DynamicsModel m) { return nameOf(m, kDynamics); }
std::string toString(Integrator m) { return nameOf(m, kIntegrator); }
bool parse(const std::string& s, StiffnessModel* out) { return parseName(s, kStiffness, out); }
bool parse(const std::string& s, SpeedProfile* out) { return parseName(s, kSpeed, out); }
bool parse(const std::string& s, LoadProfile* out) { return parseName(s, kLoad, out); }
bool parse(const std::string& s, DynamicsModel* out) { return parseName(s, kDynamics, out); }
bool parse(const std::string& s, Integrator* out) { return parseName(s, kIntegrator, out); }

}  // namespace gear_sim
