// Gear-pair geometry and inertia (paper Table 1) and the quantities derived from them for the
// reduced DTE equation (paper eqs. 3-4). No ROS; SI units throughout.
#pragma once

#include <string>

#include "gear_sim/option_status.hpp"

namespace gear_sim {

/// One wheel of the pair.
struct Gear {
  int teeth = 0;             ///< Z [-]
  double inertia = 0.0;      ///< I [kg*m^2], > 0
  double base_radius = 0.0;  ///< R [m] base-circle radius, > 0
};

/// A spur gear pair: pinion (wheel 1, driven by T1) and gear (wheel 2).
struct GearPair {
  Gear pinion{20, 0.00026, 0.05};  ///< Table 1 pinion
  Gear gear{40, 0.0045, 0.11};     ///< Table 1 gear

  /// Equivalent mass Me = I1*I2 / (I1*R2^2 + I2*R1^2) [kg] (paper eq. 3).
  double equivalentMass() const;

  /// Force factor R1/I1 + R2/I2 [1/(kg*m)]: the normalised forcing of eq. (4) is
  /// F(t) = forceFactor() * T1(t) [m/s^2] for a pinion torque T1 [N*m].
  double forceFactor() const;

  /// Gear ratio Z2/Z1 [-].
  double ratio() const { return static_cast<double>(gear.teeth) / pinion.teeth; }

  /// The first rule broken, e.g. field "pinion.inertia", value "-1", rule "must be finite and > 0
  /// [kg*m^2]"; message() "`GearPair::pinion.inertia = -1`: violated `must be ...`".
  OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

}  // namespace gear_sim
