#include "gear_damping_id/input_checks.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace gear_damping_id {

double naturalFrequencyHz(const GearConstants& gear) {
  return std::sqrt(gear.mean_stiffness / gear.equivalent_mass) / (2.0 * M_PI);
}

gear_sim::Status checkSampleRate(double sample_rate, const GearConstants& gear,
                                 std::string* warning) {
  const double fn = naturalFrequencyHz(gear);
  std::ostringstream m;
  if (!(sample_rate > 0.0) || !std::isfinite(sample_rate)) {
    m << "sample rate " << sample_rate << " Hz is not a positive number";
    return gear_sim::Status::invalidInput(m.str(), "sample_rate");
  }
  if (!std::isfinite(fn) || !(fn > 0.0)) return {};  // the gear check reports it
  const double per_period = sample_rate / fn;
  if (per_period < kMinSamplesPerPeriod) {
    m << "sample rate " << sample_rate << " Hz is too low for the natural frequency " << fn
      << " Hz of the gear pair: " << per_period << " samples per period, need at least "
      << kMinSamplesPerPeriod << " (" << kMinSamplesPerPeriod * fn << " Hz)";
    return gear_sim::Status::invalidInput(m.str(), "sample_rate");
  }
  if (warning != nullptr && per_period < kWarnSamplesPerPeriod) {
    std::ostringstream w;
    w << "sample rate " << sample_rate << " Hz gives only " << per_period
      << " samples per natural period (" << fn << " Hz): expect quadrature errors above 0.1 %;"
      << " " << kWarnSamplesPerPeriod * fn << " Hz or more is recommended";
    *warning = w.str();
  }
  return {};
}

gear_sim::Status checkRecordLength(double duration, const IdentificationOptions& o) {
  if (o.model != DampingModel::Piecewise || !(o.segment_length > 0.0) ||
      !std::isfinite(o.segment_length))
    return {};
  if (duration < o.segment_length * (1.0 - 1e-9)) {
    std::ostringstream m;
    m << "the analysed record lasts " << duration << " s, shorter than one damping segment ("
      << o.segment_length << " s): shorten --segment or analyse a longer record";
    return gear_sim::Status::invalidInput(m.str(), "segment_length");
  }
  return {};
}

}  // namespace gear_damping_id
