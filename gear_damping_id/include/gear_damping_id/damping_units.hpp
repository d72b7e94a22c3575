// Conversions between the three ways the package reports mesh damping (docs/method.md §3):
//   C  [1/s]     normalised damping of eq. (4):  y'' + C y' + K y = F
//   c  [N*s/m]   physical mesh damping of eq. (3): c = C * Me
//   xi [-]       damping ratio xi = C / (2*omega0), omega0 = sqrt(mean K) [rad/s] (eqs. 18-19)
#pragma once

namespace gear_damping_id {

/// c [N*s/m] from C [1/s] and the equivalent mass Me [kg].
inline double coefficientFromC(double C, double equivalent_mass) { return C * equivalent_mass; }

/// C [1/s] from c [N*s/m] and Me [kg].
inline double cFromCoefficient(double c, double equivalent_mass) { return c / equivalent_mass; }

/// xi [-] from C [1/s] and omega0 [rad/s] (eq. 18). omega0 must be > 0.
inline double ratioFromC(double C, double omega0) { return C / (2.0 * omega0); }

/// C [1/s] from xi [-] and omega0 [rad/s].
inline double cFromRatio(double xi, double omega0) { return 2.0 * xi * omega0; }

}  // namespace gear_damping_id
