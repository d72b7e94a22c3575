#include "gear_sim/encoder_yaml.hpp"

#include <set>

#include "gear_sim/message_text.hpp"

namespace gear_sim {

namespace {
bool loadImpl(const YAML::Node& root, EncoderOptions* out, std::string* error) {
  EncoderOptions e;
  const YAML::Node node = root["encoder"];
  if (node) {
    if (!node.IsMap()) {
      *error = "encoder: must be a mapping of keys";
      return false;
    }
    const std::set<std::string> known{"enabled", "counts_per_rev1", "counts_per_rev2", "zero1",
                                      "zero2",   "torque_noise",    "edge_clock",      "seed"};
    for (const auto& kv : node) {
      if (!kv.first.IsScalar() || !known.count(kv.first.Scalar())) {
        *error = "encoder." + quoteForMessage(kv.first.IsScalar() ? kv.first.Scalar() : "?") +
                 ": unknown key (known: enabled, counts_per_rev1, counts_per_rev2, zero1, zero2, "
                 "torque_noise, edge_clock, seed)";
        return false;
      }
    }
    auto get = [&](const char* key, auto* v) {
      if (!node[key]) return true;
      try {
        *v = node[key].as<std::decay_t<decltype(*v)>>();
        return true;
      } catch (const YAML::Exception&) {
        *error = std::string("encoder.") + key + ": wrong type";
        return false;
      }
    };
    if (!get("enabled", &e.enabled) || !get("counts_per_rev1", &e.counts_per_rev1) ||
        !get("counts_per_rev2", &e.counts_per_rev2) || !get("zero1", &e.zero1) ||
        !get("zero2", &e.zero2) || !get("torque_noise", &e.torque_noise) ||
        !get("edge_clock", &e.edge_clock) || !get("seed", &e.seed))
      return false;
  }
  if (std::string v = e.validate(); !v.empty()) {
    *error = v;
    return false;
  }
  *out = e;
  return true;
}
}  // namespace

bool loadEncoderOptions(const YAML::Node& root, EncoderOptions* out, std::string* error) {
  std::string e;
  bool ok = false;
  try {
    ok = root && root.IsMap() && loadImpl(root, out, &e);
    if (!ok && e.empty()) e = "the configuration must be a YAML mapping of sections";
  } catch (const YAML::Exception& x) {
    e = "malformed YAML: " + quoteForMessage(x.what());
    ok = false;
  }
  if (!ok && error) *error = e;
  return ok;
}

bool loadEncoderOptionsFile(const std::string& path, EncoderOptions* out, std::string* error) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& x) {
    if (error) *error = path + ": " + quoteForMessage(x.what());
    return false;
  }
  std::string e;
  if (!loadEncoderOptions(root, out, &e)) {
    if (error) *error = path + ": " + e;
    return false;
  }
  return true;
}

}  // namespace gear_sim
