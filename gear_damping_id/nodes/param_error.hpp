// A node parameter's error from a core options status (no ROS, no message parsing): shared by
// every node's parameter reader (node_common.hpp) and rig_frontend_node.
#pragma once

#include <map>
#include <string>

#include "gear_sim/option_status.hpp"

namespace gear_damping_nodes {

/// A core options error in the node's "~param = value: violated `rule`" form, from the
/// structured status (no message parsing). `rename` maps a core field to the node parameter that
/// sets it where the names differ (wavelet_node's ~window sets StreamOptions::segment_length).
inline std::string paramError(const gear_sim::OptionStatus& s,
                              const std::map<std::string, std::string>& rename = {}) {
  const auto it = rename.find(s.field);
  const std::string& name = it == rename.end() ? s.field : it->second;
  return "~" + name + " = " + s.value + ": violated `" + s.rule + "`";
}

}  // namespace gear_damping_nodes
