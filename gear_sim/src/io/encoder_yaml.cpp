#include "gear_sim/encoder_yaml.hpp"

#include <set>

#include "gear_sim/message_text.hpp"

namespace gear_sim {

namespace {
Status loadImpl(const YAML::Node& root, EncoderOptions* out) {
  EncoderOptions e;
  const YAML::Node node = root["encoder"];
  if (node) {
    if (!node.IsMap()) return Status::invalidInput("encoder: must be a mapping of keys", "encoder");
    const std::set<std::string> known{"enabled", "counts_per_rev1", "counts_per_rev2", "zero1",
                                      "zero2",   "torque_noise",    "edge_clock",      "seed"};
    for (const auto& kv : node) {
      if (!kv.first.IsScalar() || !known.count(kv.first.Scalar())) {
        const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : "?";
        return Status::invalidInput(
            "encoder." + quoteForMessage(key) +
                ": unknown key (known: enabled, counts_per_rev1, counts_per_rev2, zero1, zero2, "
                "torque_noise, edge_clock, seed)",
            "encoder." + key);
      }
    }
    Status s;
    auto get = [&](const char* key, auto* v) {
      if (!node[key]) return true;
      try {
        *v = node[key].as<std::decay_t<decltype(*v)>>();
        return true;
      } catch (const YAML::Exception&) {
        const std::string field = std::string("encoder.") + key;
        s = Status::invalidInput(field + ": wrong type", field);
        return false;
      }
    };
    if (!get("enabled", &e.enabled) || !get("counts_per_rev1", &e.counts_per_rev1) ||
        !get("counts_per_rev2", &e.counts_per_rev2) || !get("zero1", &e.zero1) ||
        !get("zero2", &e.zero2) || !get("torque_noise", &e.torque_noise) ||
        !get("edge_clock", &e.edge_clock) || !get("seed", &e.seed))
      return s;
  }
  if (Status v = e.check(); !v.ok()) return v;
  *out = e;
  return {};
}
}  // namespace

Status loadEncoderOptions(const YAML::Node& root, EncoderOptions* out) {
  try {
    if (!root || !root.IsMap())
      return Status::invalidInput("the configuration must be a YAML mapping of sections");
    return loadImpl(root, out);
  } catch (const YAML::Exception& x) {
    return Status::invalidInput("malformed YAML: " + quoteForMessage(x.what()));
  }
}

Status loadEncoderOptionsFile(const std::string& path, EncoderOptions* out) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& x) {
    return Status::ioError(path + ": " + quoteForMessage(x.what()));
  }
  return loadEncoderOptions(root, out).withContext(path);
}

}  // namespace gear_sim
