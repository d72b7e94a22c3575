// SignalView, GearConstants and the channel requirements (see signal_view.hpp).
#include "gear_damping_id/signal_view.hpp"

#include <cmath>
#include <sstream>

#include "gear_sim/models.hpp"

namespace gear_damping_id {

gear_sim::OptionStatus GearConstants::check() const {
  auto bad = [](const char* field, double value, const char* rule) {
    return gear_sim::violated("GearConstants", field, value, rule);
  };
  if (!(equivalent_mass > 0.0) || !std::isfinite(equivalent_mass))
    return bad("equivalent_mass", equivalent_mass, "must be finite and > 0 [kg]");
  if (!(force_factor > 0.0) || !std::isfinite(force_factor))
    return bad("force_factor", force_factor, "must be finite and > 0 [1/(kg*m)]");
  if (!(contact_ratio > 1.0 && contact_ratio <= 2.0))
    return bad("contact_ratio", contact_ratio, "must be in (1, 2]");
  if (!(mean_stiffness > 0.0) || !std::isfinite(mean_stiffness))
    return bad("mean_stiffness", mean_stiffness, "must be finite and > 0 [N/m]");
  return {};
}

GearConstants gearConstants(const gear_sim::GearModel& model) {
  GearConstants g;
  g.equivalent_mass = model.gears.equivalentMass();
  g.force_factor = model.gears.forceFactor();
  g.contact_ratio = model.mesh.contact_ratio;
  g.mean_stiffness = gear_sim::MeshStiffness(model.mesh).mean();
  g.piecewise_constant_stiffness = model.mesh.model == gear_sim::StiffnessModel::Square ||
                                   model.mesh.model == gear_sim::StiffnessModel::Constant;
  return g;
}

SignalView SignalView::of(const gear_sim::SignalTable& t) {
  SignalView v;
  v.n = t.size();
  if (v.n > 0) v.t0 = t.time[0];
  if (v.n > 1) v.dt = (t.time[v.n - 1] - t.time[0]) / static_cast<double>(v.n - 1);
  auto ptr = [](const Eigen::VectorXd& c) { return c.size() > 0 ? c.data() : nullptr; };
  v.dte = ptr(t.dte);
  v.stiffness = ptr(t.stiffness);
  v.torque = ptr(t.torque);
  v.mesh_state = ptr(t.mesh_state);
  v.mesh_phase = ptr(t.mesh_phase);
  return v;
}

bool needsStiffness(Formulation f) { return f == Formulation::Known; }
bool needsTorque(Formulation f, DampingModel m) {
  return f == Formulation::Known || f == Formulation::Greybox || m == DampingModel::LoadLaw;
}
bool needsMeshState(Formulation f) { return f == Formulation::Greybox; }

ChannelSet ChannelSet::of(const SignalView& v) {
  ChannelSet c;
  c.dte = v.dte != nullptr;
  c.stiffness = v.stiffness != nullptr;
  c.torque = v.torque != nullptr;
  c.mesh_state = v.mesh_state != nullptr;
  c.mesh_phase = v.mesh_phase != nullptr;
  return c;
}

ChannelSet ChannelSet::of(const gear_sim::SignalTable& t) {
  ChannelSet c;
  c.dte = t.dte.size() > 0;
  c.stiffness = t.stiffness.size() > 0;
  c.torque = t.torque.size() > 0;
  c.mesh_state = t.mesh_state.size() > 0;
  c.mesh_phase = t.mesh_phase.size() > 0;
  return c;
}

gear_sim::Status checkChannels(const ChannelSet& c, Formulation f, DampingModel m) {
  const char* name = !c.dte                               ? "dte"
                     : needsStiffness(f) && !c.stiffness  ? "stiffness"
                     : needsMeshState(f) && !c.mesh_state ? "mesh_state"
                     : needsTorque(f, m) && !c.torque     ? "torque"
                                                          : nullptr;
  if (name == nullptr) return {};
  const bool by_formulation =
      std::string(name) != "torque" || f == Formulation::Known || f == Formulation::Greybox;
  return gear_sim::Status::invalidInput(
      "column '" + std::string(name) + "' is required by " +
          (by_formulation ? "formulation '" + toString(f) + "'" : std::string("model 'load_law'")) +
          " but missing",
      name);
}

gear_sim::Status checkChannels(const SignalView& v, Formulation f, DampingModel m) {
  return checkChannels(ChannelSet::of(v), f, m);
}

}  // namespace gear_damping_id
