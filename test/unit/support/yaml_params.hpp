// A node's private parameters from a YAML file, typed as `rosparam load` types them (PyYAML:
// plain true/false/yes/no/on/off are booleans, plain integers are integers, other plain
// numbers including .inf/-.inf/.nan are doubles, quoted or other scalars are strings), read with
// roscpp getParam's rules (ParamSource). Lets a test run a node's parameter reader on a shipped
// configuration without a parameter server.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cctype>
#include <regex>
#include <string>
#include <vector>

#include "node_common.hpp"

namespace gear_test {

class YamlParams : public gear_damping_nodes::ParamSource {
 public:
  explicit YamlParams(YAML::Node root) : root_(std::move(root)) {}

  bool has(const std::string& name) const override { return static_cast<bool>(root_[name]); }
  bool get(const std::string& name, double* v) const override {
    const YAML::Node n = root_[name];
    const Kind k = kind(n);
    if (k != Kind::Int && k != Kind::Double) return false;
    *v = n.as<double>();
    return true;
  }
  bool get(const std::string& name, int* v) const override {
    const YAML::Node n = root_[name];
    if (kind(n) != Kind::Int) return false;
    *v = n.as<int>();
    return true;
  }
  bool get(const std::string& name, bool* v) const override {
    const YAML::Node n = root_[name];
    if (kind(n) != Kind::Bool) return false;
    *v = n.as<bool>();
    return true;
  }
  bool get(const std::string& name, std::string* v) const override {
    const YAML::Node n = root_[name];
    if (kind(n) != Kind::String) return false;
    *v = n.as<std::string>();
    return true;
  }
  bool get(const std::string& name, std::vector<double>* v) const override {
    const YAML::Node n = root_[name];
    if (!n || !n.IsSequence()) return false;
    std::vector<double> out;
    for (const auto& e : n) {
      const Kind k = kind(e);
      if (k != Kind::Int && k != Kind::Double) return false;
      out.push_back(e.as<double>());
    }
    *v = out;
    return true;
  }
  std::vector<std::string> names() const override {
    std::vector<std::string> out;
    for (const auto& kv : root_) out.push_back(kv.first.as<std::string>());
    return out;
  }

 private:
  enum class Kind { None, Bool, Int, Double, String, Other };
  static Kind kind(const YAML::Node& n) {
    if (!n || !n.IsScalar()) return n ? Kind::Other : Kind::None;
    const std::string s = n.Scalar();
    if (n.Tag() == "!") return Kind::String;  // quoted
    static const std::regex kBool(
        "true|True|TRUE|false|False|FALSE|yes|Yes|YES|no|No|NO|on|On|ON|off|Off|OFF");
    static const std::regex kInt("[-+]?[0-9]+");
    static const std::regex kDouble(
        "[-+]?([0-9]+\\.?[0-9]*|\\.[0-9]+)([eE][-+]?[0-9]+)?|[-+]?\\.(inf|Inf|INF)|\\.(nan|NaN|"
        "NAN)");
    if (std::regex_match(s, kBool)) return Kind::Bool;
    if (std::regex_match(s, kInt)) return Kind::Int;
    if (std::regex_match(s, kDouble)) return Kind::Double;
    return Kind::String;
  }
  YAML::Node root_;
};

}  // namespace gear_test
