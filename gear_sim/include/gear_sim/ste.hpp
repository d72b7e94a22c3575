// Static transmission error (STE), docs/ste.md: the no-load, quasi-static part of the DTE that the
// mesh force acts against,
//
//     Me y'' + c(t) (y' - e') + k(t) (y - e(t)) = Me F(t)        (default: damping on y' - e')
//     Me y'' + c(t)  y'       + k(t) (y - e(t)) = Me F(t)        (option: damping on y' alone)
//
//     e = e0 + sum_h (a_h cos 2 pi h u + b_h sin 2 pi h u)                       mesh orders
//            + sum_s (p_s cos s th1 + q_s sin s th1) + sum_s (g_s cos s th2 + r_s sin s th2)
//
// with u the cumulative mesh phase [mesh cycles] and th1 = 2 pi u / Z1, th2 = 2 pi u / Z2 the
// rigid-body shaft angles counted from the mesh-phase zero (shaft orders: run-out, eccentricity).
// The same basis serves the simulator (known truth) and the identification (unknown
// coefficients). No ROS; SI units.
#pragma once

#include <string>
#include <vector>

#include "gear_sim/option_status.hpp"
#include "gear_sim/status.hpp"

namespace gear_sim {

/// How the damping force acts when an STE is present.
enum class SteDamping {
  Relative,  ///< c (y' - e'): damping on the tooth deflection rate (default)
  Dte        ///< c y': damping on the DTE rate alone
};

/// "relative" or "dte": the one spelling of SteDamping in YAML, JSON, the CLI and the nodes.
const char* steDampingName(SteDamping d);
/// The SteDamping named `name`; InvalidArgument "unknown name 'x' (one of: relative, dte)".
Result<SteDamping> parseSteDamping(const std::string& name);

/// STE amplitudes [m]; every list may be empty (all empty and offset 0: no STE, the simulator
/// is bit-identical to one without the section).
struct SteOptions {
  double offset = 0.0;                         ///< [m] e0, order 0
  std::vector<double> mesh_cos, mesh_sin;      ///< [m] a_h, b_h for mesh orders h = 1..
  std::vector<double> pinion_cos, pinion_sin;  ///< [m] shaft orders s = 1.. of the pinion angle
  std::vector<double> gear_cos, gear_sin;      ///< [m] shaft orders s = 1.. of the gear angle
  SteDamping damping = SteDamping::Relative;
  bool active() const;
  OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// The harmonic structure of an STE model: how many mesh orders and pinion/gear shaft orders.
/// Basis functions, in this order: 1 (order 0), then cos, sin of each mesh order h = 1..H, then
/// cos, sin of each pinion order, then of each gear order.
struct SteBasis {
  int mesh_orders = 0, pinion_orders = 0, gear_orders = 0;
  int z1 = 1, z2 = 1;  ///< tooth counts (shaft angles from the mesh phase)
  bool with_offset = true;
  int size() const {
    return (with_offset ? 1 : 0) + 2 * (mesh_orders + pinion_orders + gear_orders);
  }
  /// Fills out[0..size()) with the basis functions at mesh phase u; when `du` is non-null also
  /// their derivatives with respect to u [1/mesh cycle].
  void eval(double u, double* out, double* du = nullptr) const;
  /// Description of basis function j: kind ("offset", "mesh", "pinion", "gear"), order, and
  /// whether it is the sine.
  void describe(int j, std::string* kind, int* order, bool* sine) const;
};

/// An STE with known coefficients (simulator).
class StaticTransmissionError {
 public:
  StaticTransmissionError(const SteOptions& o, int z1, int z2);
  bool active() const { return active_; }
  /// e(u) [m] and de/du [m per mesh cycle].
  double value(double u) const;
  double derivative(double u) const;
  const SteBasis& basis() const { return basis_; }
  const std::vector<double>& coefficients() const { return coef_; }

 private:
  SteBasis basis_;
  std::vector<double> coef_;
  bool active_ = false;
  mutable std::vector<double> scratch_, dscratch_;
};

}  // namespace gear_sim
