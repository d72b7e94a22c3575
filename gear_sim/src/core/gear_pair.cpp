#include "gear_sim/gear_pair.hpp"

#include <cmath>

namespace gear_sim {

double GearPair::equivalentMass() const {
  const double i1 = pinion.inertia, i2 = gear.inertia;
  const double r1 = pinion.base_radius, r2 = gear.base_radius;
  return i1 * i2 / (i1 * r2 * r2 + i2 * r1 * r1);
}

double GearPair::forceFactor() const {
  return pinion.base_radius / pinion.inertia + gear.base_radius / gear.inertia;
}

namespace {
OptionStatus checkGear(const Gear& g, const std::string& name) {
  if (g.teeth < 1)
    return violated("GearPair", name + ".teeth", g.teeth, "must be a positive integer");
  if (!(std::isfinite(g.inertia) && g.inertia > 0.0))
    return violated("GearPair", name + ".inertia", g.inertia, "must be finite and > 0 [kg*m^2]");
  if (!(std::isfinite(g.base_radius) && g.base_radius > 0.0))
    return violated("GearPair", name + ".base_radius", g.base_radius, "must be finite and > 0 [m]");
  return {};
}
}  // namespace

OptionStatus GearPair::check() const {
  OptionStatus e = checkGear(pinion, "pinion");
  if (e.ok()) e = checkGear(gear, "gear");
  return e;
}

}  // namespace gear_sim
