#include "gear_damping_ros/live_conversions.hpp"

namespace gear_damping_ros {

namespace gd = gear_damping_id;

bool toChunkData(const gear_damping::SignalChunk& msg, std::vector<double>* mesh_state,
                 gd::ChunkData* out, std::string* error) {
  const size_t n = msg.dte.size();
  auto check = [&](size_t len, const char* name) {
    if (len == 0 || len == n) return true;
    *error =
        std::string(name) + " has " + std::to_string(len) + " samples, dte " + std::to_string(n);
    return false;
  };
  if (!check(msg.stiffness.size(), "stiffness") || !check(msg.torque.size(), "torque") ||
      !check(msg.mesh_state.size(), "mesh_state") || !check(msg.mesh_phase.size(), "mesh_phase") ||
      !check(msg.dte_velocity.size(), "dte_velocity") || !check(msg.damping.size(), "damping")) {
    return false;
  }
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
  return true;
}

gear_damping::WaveletModes toMsg(const gd::WaveletResult& r, double t_start, double t_end) {
  gear_damping::WaveletModes msg;
  msg.t_start = t_start;
  msg.t_end = t_end;
  msg.wavelet_parameter = r.omega0;
  for (const auto& m : r.modes) {
    gear_damping::WaveletMode w;
    w.frequency_hz = m.frequency_hz;
    w.damping_ratio = m.damping_ratio;
    w.r2 = m.r2;
    // The core's decay region is relative to the window start (t = 0 at its first sample).
    w.decay_t_start = t_start + m.t_start;
    w.decay_t_end = t_start + m.t_end;
    w.xi_integral = m.integral_xi;
    w.warning = m.warning;
    msg.modes.push_back(w);
  }
  return msg;
}

}  // namespace gear_damping_ros
