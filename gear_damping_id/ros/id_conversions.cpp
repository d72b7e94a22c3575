#include "gear_damping_ros/id_conversions.hpp"

#include <cmath>

namespace gear_damping_ros {

namespace gd = gear_damping_id;

namespace {

// Quality warnings (segment or run) as messages.
std::vector<gear_damping::QualityWarning> warningMsgs(const gd::QualityWarnings& ws) {
  std::vector<gear_damping::QualityWarning> out;
  for (const auto& w : ws) {
    gear_damping::QualityWarning m;
    m.code = w.code;
    m.text = w.text;
    out.push_back(m);
  }
  return out;
}

}  // namespace

gear_damping::DampingSegment toMsg(const gd::SegmentEstimate& s, gd::Formulation f) {
  gear_damping::DampingSegment m;
  m.t_start = s.t_start;
  m.t_end = s.t_end;
  m.identifiable = s.identifiable;
  m.reason = s.identifiable ? std::string() : s.reason;
  // Never a number for a non-identifiable segment.
  m.C = s.identifiable ? s.C : gd::kNaN;
  m.C_std = s.identifiable ? s.C_std : gd::kNaN;
  m.c = s.identifiable ? s.c : gd::kNaN;
  m.xi = s.identifiable ? s.xi : gd::kNaN;
  const bool levels = s.identifiable && f != gd::Formulation::Known;
  m.k_min = levels ? s.k_min : gd::kNaN;
  m.k_max = levels ? s.k_max : gd::kNaN;
  m.warnings = warningMsgs(s.warnings);
  if (s.identifiable) m.stiffness_curve = s.stiffness_curve;
  return m;
}

gear_damping::DampingArray toMsg(const gd::IdentificationResult& r) {
  gear_damping::DampingArray a;
  a.formulation = gd::toString(r.formulation);
  a.model = gd::toString(r.model);
  a.equivalent_mass = r.equivalent_mass;
  a.omega0 = r.omega0;
  if (r.constant) {
    a.segments.push_back(toMsg(*r.constant, r.formulation));
  } else {
    for (const auto& s : r.segments) a.segments.push_back(toMsg(s, r.formulation));
  }
  a.c0 = a.c0_std = a.c1 = a.c1_std = gd::kNaN;
  if (r.load_law && r.load_law->identifiable) {
    a.c0 = r.load_law->c0;
    a.c0_std = r.load_law->c0_std;
    a.c1 = r.load_law->c1;
    a.c1_std = r.load_law->c1_std;
  }
  a.warnings = warningMsgs(r.warnings);
  return a;
}

gear_damping::ModeledResponse toMsg(const gd::ModeledResponse& m, double sample_rate,
                                    std::uint64_t first_index) {
  gear_damping::ModeledResponse out;
  out.sample_rate = sample_rate;
  out.first_index = first_index;
  out.observed.assign(m.observed.data(), m.observed.data() + m.observed.size());
  out.modeled.assign(m.modeled.data(), m.modeled.data() + m.modeled.size());
  out.nrmse = m.nrmse;
  out.fit_percent = m.fit_percent;
  return out;
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
    w.decay_t_start = m.t_start;
    w.decay_t_end = m.t_end;
    w.xi_integral = m.integral_xi;
    w.warning = gd::warningText(m.warnings);
    w.free_decay = m.free_decay;
    for (const auto& q : m.warnings) {
      gear_damping::QualityWarning qm;
      qm.code = q.code;
      qm.text = q.text;
      w.warnings.push_back(qm);
    }
    msg.modes.push_back(w);
  }
  return msg;
}

}  // namespace gear_damping_ros
