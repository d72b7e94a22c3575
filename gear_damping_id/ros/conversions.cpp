#include "gear_damping_id_ros/conversions.hpp"

namespace gear_damping_id_ros {

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

gear_damping::DampingSegment toMsg(const gd::SegmentEstimate& e) {
  gear_damping::DampingSegment s;
  s.t_start = e.t_start;
  s.t_end = e.t_end;
  s.C = e.C;
  s.C_std = e.C_std;
  s.c = e.c;
  s.xi = e.xi;
  s.k_min = e.k_min;
  s.k_max = e.k_max;
  s.identifiable = e.identifiable;
  s.reason = e.reason;
  return s;
}

gear_damping::DampingArray toMsg(const gd::IdentificationResult& r) {
  gear_damping::DampingArray a;
  a.formulation = gd::toString(r.formulation);
  a.model = gd::toString(r.model);
  a.equivalent_mass = r.equivalent_mass;
  a.omega0 = r.omega0;
  for (const auto& e : r.segments) a.segments.push_back(toMsg(e));
  a.c0 = a.c0_std = a.c1 = a.c1_std = gd::kNaN;
  if (r.load_law) {
    a.c0 = r.load_law->c0;
    a.c0_std = r.load_law->c0_std;
    a.c1 = r.load_law->c1;
    a.c1_std = r.load_law->c1_std;
  }
  return a;
}

gear_damping::ModeledResponse toMsg(const gd::ModeledResponse& m, double sample_rate,
                                    std::uint64_t first_index) {
  gear_damping::ModeledResponse msg;
  msg.sample_rate = sample_rate;
  msg.first_index = first_index;
  msg.observed.assign(m.observed.data(), m.observed.data() + m.observed.size());
  msg.modeled.assign(m.modeled.data(), m.modeled.data() + m.modeled.size());
  msg.nrmse = m.nrmse;
  msg.fit_percent = m.fit_percent;
  return msg;
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

}  // namespace gear_damping_id_ros
