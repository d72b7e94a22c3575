// Topic names of the package, in one place (used by gear_sim_node, damping_id_node, wavelet_node
// and the rostest testers). They are relative: they resolve under the node's namespace, so
// ROS_NAMESPACE=a, <group ns="a"> or the launch files' `ns` argument put a whole pipeline under
// /a/gear/... and two pipelines run side by side on one master. /diagnostics stays global (the
// diagnostic_updater convention), its status names carry the node's full name.
// Bags written by the tools use the same names with a leading '/' (bagTopic()).
#pragma once

#include <string>

namespace gear_sim_ros {

constexpr char kSignalTopic[] = "gear/signal";    // SignalChunk
constexpr char kParamsTopic[] = "gear/params";    // GearParams (latched)
constexpr char kDampingTopic[] = "gear/damping";  // DampingArray (latched, cumulative)
constexpr char kDampingSegmentTopic[] = "gear/damping_segment";    // DampingArray per segment
constexpr char kDampingSeriesTopic[] = "gear/damping_series";      // DampingSample per segment
constexpr char kModeledResponseTopic[] = "gear/modeled_response";  // ModeledResponse
constexpr char kDampingCTopic[] = "gear/damping_C";                // std_msgs/Float64 [1/s]
constexpr char kDampingXiTopic[] = "gear/damping_xi";              // std_msgs/Float64 [-]
constexpr char kWaveletModesTopic[] = "gear/wavelet_modes";        // WaveletModes

/// SignalChunk header.frame_id of a chunk whose torque channel was paired with the angles without
/// time stamps (rig_frontend_node, std_msgs/Float64 torque); damping_id_node flags the segments
/// built from such chunks `torque_unstamped`. Any other frame_id (empty by default): stamped or
/// simulated.
constexpr char kTorqueUnstampedFrame[] = "torque_unstamped";

/// The absolute name a bag written outside any namespace uses for `topic` ("/gear/signal").
inline std::string bagTopic(const char* topic) { return std::string("/") + topic; }

}  // namespace gear_sim_ros
