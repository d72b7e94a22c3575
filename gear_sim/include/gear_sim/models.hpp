// The time functions of the simulator, built from the option structs of sim_config.hpp: mesh
// stiffness k(u) over the mesh phase u, mesh timing u(t) from the speed profile, load T1(t) and
// damping c(t). Each lists the instants where it jumps or loses smoothness, so the integrator
// can step onto them. No ROS; SI units. Construct only from validated options.
#pragma once

#include <cmath>
#include <vector>

#include "gear_sim/sim_config.hpp"

namespace gear_sim {

/// A table of rotations cos/sin(j * step), j < kSize, for one step, kept by a caller that fills
/// many blocks with the same step (the simulator): the sine load's of LoadTorque::fillUniform
/// (step w dt, key w dt) and the Fourier stiffness's of MeshStiffness::fillPiece (step 2 pi du,
/// key du).
struct RotationTable {
  static constexpr long kSize = 256;
  double key = 0.0;  ///< the table holds the rotations of this key (0: none yet)
  double c[kSize], s[kSize];
};

/// k as a function of the cumulative mesh phase u [mesh cycles] (u = 0 at a switch into the
/// double-contact phase).
class MeshStiffness {
 public:
  explicit MeshStiffness(const MeshOptions& o);
  /// k [N/m] at phase u, on the smooth piece containing u_ref (pass u_ref = u away from
  /// switches). At a switch instant the value of the piece that starts there is the one "from
  /// that instant on".
  double at(double u, double u_ref) const;
  double at(double u) const { return at(u, u); }
  /// 1 while the stiffer, double-contact phase holds (fractional phase < eps - 1), else 0.
  int state(double u) const { return u - std::floor(u) < o_.contact_ratio - 1.0 ? 1 : 0; }
  /// Time-mean stiffness over a mesh cycle [N/m].
  double mean() const { return mean_; }
  /// Fractional phases in [0, 1) where k jumps or has a kink (empty for smooth models).
  const std::vector<double>& cycleBreakpoints() const { return breaks_; }
  /// True when k is constant on each smooth piece (square and constant models).
  bool piecewiseConstant() const { return piecewise_constant_; }
  /// True, with the value in *k, when k is constant on the smooth piece that contains u_ref
  /// (square and constant models everywhere, the trapezoid's flat parts).
  bool constantOnPiece(double u_ref, double* k) const;
  /// out[i] = at(u[i], u_ref) for phases u[0..n) on the smooth piece that contains u_ref (the
  /// simulator's block evaluation: the piece is found once, trapezoid ramps are a linear
  /// formula). When du > 0 the phases are uniform, u[i] = u[0] + i du, and the Fourier model
  /// rotates exact anchors instead of calling cos/sin per point (agrees to ~1e-15 relative).
  void fillPiece(double u_ref, const double* u, long n, double du, double* out) const;
  /// The same values, the Fourier series' rotation table kept in *table (recomputed when du
  /// changes).
  void fillPiece(double u_ref, const double* u, long n, double du, double* out,
                 RotationTable* table) const;

 private:
  MeshOptions o_;
  double mean_ = 0.0;
  std::vector<double> breaks_;
  bool piecewise_constant_ = false;
};

/// Mesh timing: u(t) = initial_phase + Z1 * (pinion revolutions since t = 0).
class MeshTiming {
 public:
  MeshTiming(const SpeedOptions& speed, int pinion_teeth, double initial_phase);
  /// Cumulative mesh phase [mesh cycles] at t [s].
  double phase(double t) const { return ramp_ ? rampPhase(t) : u0_ + z1_ * f0_ * t; }
  /// Mesh frequency [Hz] at t.
  double meshFrequency(double t) const;
  /// True when the phase is linear in t (constant speed): phase(t) = phase(0) + meshFrequency * t.
  bool linear() const { return !ramp_; }
  /// The time t >= 0 at which phase(t) == u (u >= phase(0)); closed form (phase is linear or
  /// quadratic in t).
  double timeOfPhase(double u) const;

 private:
  double rampPhase(double t) const;
  double u0_, z1_, f0_, f1_, t_ramp_;  // f in rev/s
  bool ramp_;
};

/// Load torque T1(t) [N*m].
class LoadTorque {
 public:
  explicit LoadTorque(const LoadOptions& o);
  double at(double t) const;
  /// T1 at t_n = t0 + n*dt for n = 0..n-1 (sine: phasor recurrence, exact to ~1e-15).
  void fillUniform(double t0, double dt, long n, double* out) const;
  /// The same values, the sine's rotation table kept in *table (recomputed when dt changes).
  void fillUniform(double t0, double dt, long n, double* out, RotationTable* table) const;
  /// Kinks/jumps in (0, duration).
  std::vector<double> breakpoints(double duration) const;
  /// Time-mean of T1 over [0, duration] (exact for the piecewise-linear profiles and the sine).
  double mean(double duration) const;

 private:
  LoadOptions o_;
};

/// c(t) = a(t) + b(t) * T1(t) [N*s/m]: every damping model of DampingOptions has this form
/// with a, b piecewise constant in time.
class DampingLaw {
 public:
  /// `k_mean` [N/m] and `me` [kg] fix the ratio convention xi = c / (2 sqrt(k_mean Me));
  /// `t1_mean` [N*m] is the time-mean load for the load-dependent model.
  DampingLaw(const DampingOptions& o, double k_mean, double me, double t1_mean);
  /// c [N*s/m] at time t on the piece containing t_ref, given the load there.
  double at(double t_ref, double t1) const {
    const Piece& p = piece(t_ref);
    return p.a + p.b * t1;
  }
  /// The law's (a, b) [N*s/m, N*s/m per N*m] on the piece containing t_ref.
  void coefficients(double t_ref, double* a, double* b) const {
    const Piece& p = piece(t_ref);
    *a = p.a;
    *b = p.b;
  }
  std::vector<double> breakpoints(double duration) const;

 private:
  struct Piece {
    double start, a, b;
  };
  const Piece& piece(double t) const;
  std::vector<Piece> pieces_;
};

}  // namespace gear_sim
