// The one result shape of an options check in the package (simulator configuration,
// identification, wavelet, stream intake, rig front end): ok, or the first rule broken with the
// options struct, the field, its value as printed and the rule. Callers that need the field
// (a node naming its ~parameter, a test) read it from here and never parse the message. Modelled
// on Ceres' Solver::Options::IsValid ("Options::field = value. Violated constraint: rule").
// No ROS.
#pragma once

#include <string>
#include <type_traits>
#include <utility>

#include "gear_sim/message_text.hpp"

namespace gear_sim {

/// Outcome of Options::check(): ok() or the first violated rule.
struct OptionStatus {
  std::string options;  ///< the struct the field belongs to ("IdentificationOptions")
  std::string field;    ///< "segment_length", "mesh.k_min", "frequencies[2]"; empty when ok
  std::string value;    ///< the offending value as printed ("-0.001", "[]", "nan")
  std::string rule;     ///< what the value must satisfy ("must be >= 0 [s]")

  bool ok() const { return field.empty(); }
  /// "`Options::field = value`: violated `rule`"; empty when ok.
  std::string message() const {
    if (ok()) return {};
    return "`" + options + "::" + field + " = " + value + "`: violated `" + rule + "`";
  }
};

/// A value as an option message prints it: doubles read back exactly (formatNumber), integers
/// in decimal, text as is.
inline std::string optionValue(double v) { return formatNumber(v); }
inline std::string optionValue(const std::string& v) { return v; }
inline std::string optionValue(const char* v) { return v; }
inline std::string optionValue(bool v) { return v ? "true" : "false"; }
template <class T, std::enable_if_t<std::is_integral_v<T>, int> = 0>
std::string optionValue(T v) {
  return std::to_string(v);
}

/// The status of `options`.`field` = `value` breaking `rule`.
template <class T>
OptionStatus violated(std::string options, std::string field, const T& value, std::string rule) {
  return OptionStatus{std::move(options), std::move(field), optionValue(value), std::move(rule)};
}

}  // namespace gear_sim
