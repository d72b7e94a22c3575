#include "gear_sim_ros/conversions.hpp"

#include <cmath>

#include "gear_sim/simulator.hpp"

namespace gear_sim_ros {

namespace {
template <class T>
void copyColumn(const Eigen::VectorXd& v, Eigen::Index begin, Eigen::Index count,
                std::vector<T>* out) {
  out->clear();
  if (v.size() == 0) return;
  out->resize(static_cast<size_t>(count));
  for (Eigen::Index i = 0; i < count; ++i)
    (*out)[static_cast<size_t>(i)] = static_cast<T>(v[begin + i]);
}
}  // namespace

void toChunk(const gear_sim::SignalTable& t, Eigen::Index begin, Eigen::Index count,
             double sample_rate, std::uint64_t first_index, gear_damping::SignalChunk* msg) {
  msg->sample_rate = sample_rate;
  msg->first_index = first_index;
  copyColumn(t.dte, begin, count, &msg->dte);
  copyColumn(t.dte_velocity, begin, count, &msg->dte_velocity);
  copyColumn(t.stiffness, begin, count, &msg->stiffness);
  copyColumn(t.torque, begin, count, &msg->torque);
  copyColumn(t.mesh_phase, begin, count, &msg->mesh_phase);
  copyColumn(t.damping, begin, count, &msg->damping);
  msg->mesh_state.clear();
  if (t.mesh_state.size())
    for (Eigen::Index i = 0; i < count; ++i)
      msg->mesh_state.push_back(t.mesh_state[begin + i] != 0.0 ? 1 : 0);
}

gear_sim::Status chunksToTable(const std::vector<gear_damping::SignalChunk>& chunks,
                               gear_sim::SignalTable* out) {
  auto fail = [&](size_t k, const std::string& what) {
    return gear_sim::Status::invalidInput("chunk " + std::to_string(k) + ": " + what);
  };
  if (chunks.empty()) return gear_sim::Status::invalidInput("no chunks");
  size_t n = 0;
  const auto& c0 = chunks.front();
  for (size_t k = 0; k < chunks.size(); ++k) {
    const auto& c = chunks[k];
    if (c.sample_rate != c0.sample_rate) return fail(k, "sample rate changed");
    if (c.first_index != c0.first_index + n)
      return fail(k, "first_index " + std::to_string(c.first_index) +
                         " does not follow on (expected " + std::to_string(c0.first_index + n) +
                         ")");
    const size_t m = c.dte.size();
    auto check = [&](size_t size, bool first_present, const char* name) {
      return (size == 0 && !first_present) || (size == m && first_present)
                 ? std::string()
                 : std::string(name) + " has a wrong length or is not in every chunk";
    };
    for (const std::string& e :
         {check(c.dte_velocity.size(), !c0.dte_velocity.empty(), "dte_velocity"),
          check(c.stiffness.size(), !c0.stiffness.empty(), "stiffness"),
          check(c.torque.size(), !c0.torque.empty(), "torque"),
          check(c.mesh_state.size(), !c0.mesh_state.empty(), "mesh_state"),
          check(c.mesh_phase.size(), !c0.mesh_phase.empty(), "mesh_phase"),
          check(c.damping.size(), !c0.damping.empty(), "damping")})
      if (!e.empty()) return fail(k, e);
    n += m;
  }
  gear_sim::SignalTable t;
  const Eigen::Index N = static_cast<Eigen::Index>(n);
  t.time.resize(N);
  t.dte.resize(N);
  auto alloc = [&](bool present, Eigen::VectorXd& v) {
    if (present) v.resize(N);
  };
  alloc(!c0.dte_velocity.empty(), t.dte_velocity);
  alloc(!c0.stiffness.empty(), t.stiffness);
  alloc(!c0.torque.empty(), t.torque);
  alloc(!c0.mesh_state.empty(), t.mesh_state);
  alloc(!c0.mesh_phase.empty(), t.mesh_phase);
  alloc(!c0.damping.empty(), t.damping);
  Eigen::Index i = 0;
  for (const auto& c : chunks)
    for (size_t j = 0; j < c.dte.size(); ++j, ++i) {
      t.time[i] = static_cast<double>(c.first_index + j) / c.sample_rate;
      t.dte[i] = c.dte[j];
      if (t.dte_velocity.size()) t.dte_velocity[i] = c.dte_velocity[j];
      if (t.stiffness.size()) t.stiffness[i] = c.stiffness[j];
      if (t.torque.size()) t.torque[i] = c.torque[j];
      if (t.mesh_state.size()) t.mesh_state[i] = c.mesh_state[j];
      if (t.mesh_phase.size()) t.mesh_phase[i] = c.mesh_phase[j];
      if (t.damping.size()) t.damping[i] = c.damping[j];
    }
  *out = std::move(t);
  return {};
}

gear_damping::GearParams toMsg(const gear_sim::GearModel& m) {
  gear_damping::GearParams p;
  p.pinion_teeth = static_cast<std::uint32_t>(m.gears.pinion.teeth);
  p.pinion_inertia = m.gears.pinion.inertia;
  p.pinion_base_radius = m.gears.pinion.base_radius;
  p.gear_teeth = static_cast<std::uint32_t>(m.gears.gear.teeth);
  p.gear_inertia = m.gears.gear.inertia;
  p.gear_base_radius = m.gears.gear.base_radius;
  p.stiffness_model = gear_sim::toString(m.mesh.model);
  p.k_max = m.mesh.k_max;
  p.k_min = m.mesh.k_min;
  p.contact_ratio = m.mesh.contact_ratio;
  p.pinion_rpm = m.speed.pinion_rpm;
  p.equivalent_mass = m.gears.equivalentMass();
  p.force_factor = m.gears.forceFactor();
  p.natural_frequency = gear_sim::naturalFrequencyHz(m.gears, m.mesh);
  return p;
}

gear_sim::Status fromMsg(const gear_damping::GearParams& p, gear_sim::GearModel* out) {
  gear_sim::GearModel m;
  m.gears.pinion = {static_cast<int>(p.pinion_teeth), p.pinion_inertia, p.pinion_base_radius};
  m.gears.gear = {static_cast<int>(p.gear_teeth), p.gear_inertia, p.gear_base_radius};
  if (!gear_sim::parse(p.stiffness_model, &m.mesh.model))
    return gear_sim::Status::invalidInput("stiffness_model = '" + p.stiffness_model + "': unknown",
                                          "stiffness_model");
  m.mesh.k_max = p.k_max;
  m.mesh.k_min = p.k_min;
  m.mesh.k_mean = p.contact_ratio > 1
                      ? (p.contact_ratio - 1) * p.k_max + (2 - p.contact_ratio) * p.k_min
                      : p.k_max;
  m.mesh.contact_ratio = p.contact_ratio;
  m.speed.pinion_rpm = p.pinion_rpm;
  m.speed.end_rpm = p.pinion_rpm;
  if (gear_sim::Status s = m.check(); !s.ok()) return s;
  *out = m;
  return {};
}

YAML::Node toYaml(const XmlRpc::XmlRpcValue& v) {
  XmlRpc::XmlRpcValue x = v;  // the accessors are non-const
  YAML::Node n;
  switch (x.getType()) {
    case XmlRpc::XmlRpcValue::TypeBoolean:
      n = static_cast<bool>(x);
      break;
    case XmlRpc::XmlRpcValue::TypeInt:
      n = static_cast<int>(x);
      break;
    case XmlRpc::XmlRpcValue::TypeDouble:
      n = static_cast<double>(x);
      break;
    case XmlRpc::XmlRpcValue::TypeString:
      n = static_cast<std::string>(x);
      break;
    case XmlRpc::XmlRpcValue::TypeArray:
      n = YAML::Node(YAML::NodeType::Sequence);
      for (int i = 0; i < x.size(); ++i) n.push_back(toYaml(x[i]));
      break;
    case XmlRpc::XmlRpcValue::TypeStruct:
      n = YAML::Node(YAML::NodeType::Map);
      for (auto it = x.begin(); it != x.end(); ++it) n[it->first] = toYaml(it->second);
      break;
    default:
      break;
  }
  return n;
}

}  // namespace gear_sim_ros
