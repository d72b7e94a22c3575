#include "gear_damping_ros/live_conversions.hpp"

namespace gear_damping_ros {

namespace gd = gear_damping_id;

gear_sim::Status toChunkData(const gear_damping::SignalChunk& msg, std::vector<double>* mesh_state,
                             gd::ChunkData* out) {
  const size_t n = msg.dte.size();
  const std::pair<size_t, const char*> channels[] = {
      {msg.stiffness.size(), "stiffness"},       {msg.torque.size(), "torque"},
      {msg.mesh_state.size(), "mesh_state"},     {msg.mesh_phase.size(), "mesh_phase"},
      {msg.dte_velocity.size(), "dte_velocity"}, {msg.damping.size(), "damping"}};
  for (const auto& [len, name] : channels)
    if (len != 0 && len != n)
      return gear_sim::Status::invalidInput(
          std::string(name) + " has " + std::to_string(len) + " samples, dte " + std::to_string(n),
          name);
  auto ptr = [n](const std::vector<double>& v) { return n > 0 && !v.empty() ? v.data() : nullptr; };
  *out = gd::ChunkData();
  out->first_index = msg.first_index;
  out->sample_rate = msg.sample_rate;
  out->n = n;
  out->dte = n > 0 ? msg.dte.data() : nullptr;
  out->stiffness = ptr(msg.stiffness);
  out->torque = ptr(msg.torque);
  out->mesh_phase = ptr(msg.mesh_phase);
  mesh_state->assign(msg.mesh_state.begin(), msg.mesh_state.end());
  out->mesh_state = ptr(*mesh_state);
  return {};
}

}  // namespace gear_damping_ros
