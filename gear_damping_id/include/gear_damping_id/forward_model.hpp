// The forward model of eq. (4), y'' + C(t) y' + K(t) y = F(t), as the integral method's
// quadrature sees the sampled channels, shared by the output-error refinement and the modeled
// response (output_error.hpp) so that the three integrate one and the same K(t) and F(t). No ROS.
//
// On sample interval j = [t_j, t_j + h] of a record segment with samples [lo, hi):
// - held stiffness (square and constant models, GearConstants::piecewise_constant_stiffness) and
//   the greybox mesh state: the value of sample j holds up to the switch instant located from
//   `mesh_phase` (switch phases n and n + eps - 1), the value of sample j+1 after it; without a
//   phase channel, or when the phase does not place a switch in the interval, the new value holds
//   from sample j+1 on (sample and hold). A channel changes only where its samples change.
// - smooth stiffness (trapezoid, fourier, a rig's measured channel): the local four-point cubic
//   through the samples, on the same stencil as the quadrature (quadrature.hpp), bounded by the
//   segment so that a segment reads no sample outside itself. Kinks (a jump of the slope, as at
//   the ends of a trapezoid's ramps) are located from the samples: a kink at t_j + th h between
//   straight pieces makes the second differences d_j = h ds (1 - th) and d_{j+1} = h ds th, both
//   of the sign of ds, while the neighbouring d_{j-1}, d_{j+2} see no kink; an interval is a kink
//   interval when |d_j| + |d_{j+1}| exceeds kKinkRatio times |d_{j-1}| + |d_{j+2}| (a smooth
//   curve gives a ratio near 1). On it K follows the line through the two samples on each side
//   up to th = d_{j+1} / (d_j + d_{j+1}) and from there, and the intervals next to it use the
//   one-sided cubic that does not reach across the kink.
// - forcing F = force_factor T1 with T1 the same local cubic of the torque samples.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/quadrature.hpp"
#include "gear_damping_id/signal_view.hpp"

namespace gear_damping_id {

/// Split fraction th in [0, 1] of sample interval j at which `mesh_phase` reaches the next switch
/// phase of the square-wave mesh (rising, into double contact: an integer; falling:
/// m + contact_ratio - 1): 1 without a phase channel or with a non-increasing phase; NaN when the
/// phase places no switch within the interval (the caller then holds the sample value, th = 1).
/// Shared by the integral method's quadrature and the forward model.
double switchFractionFromPhase(const double* mesh_phase, Eigen::Index j, Eigen::Index n,
                               bool rising, double contact_ratio);

class ForwardModel {
 public:
  using Index = Eigen::Index;
  /// `signal` and `gear` must outlive the model.
  ForwardModel(const SignalView& signal, const GearConstants& gear, Formulation formulation);

  /// Split fraction th in (0, 1] of interval j for a held channel whose value changes between
  /// samples j and j+1 (rising: into the stiffer phase); 1 when it does not change or the
  /// switch cannot be located.
  double switchFraction(const double* channel, Index j) const;
  /// Value at local coordinate u in [0, 1] of interval j of the local cubic through the samples
  /// of `channel`, stencil within [lo, hi) (hi - lo >= 4; fewer: linear between the samples).
  double cubic(const double* channel, Index j, double u, Index lo, Index hi) const;
  /// Torque T1 [N*m] at u of interval j (0 without a torque channel).
  double torque(Index j, double u, Index lo, Index hi) const {
    return signal_.torque == nullptr ? 0.0 : cubic(signal_.torque, j, u, lo, hi);
  }
  /// Whether the known stiffness is interpolated (true) or held between switch instants.
  bool smoothStiffness() const { return smooth_; }
  /// Split fraction of interval j: the switch of the held channel of the formulation (known
  /// stiffness when held, greybox mesh state) or the kink of a smooth stiffness; 1 when none.
  double heldSplit(Index j) const;
  /// Intervals j whose smooth stiffness has a kink (sorted), and their kink fractions.
  const std::vector<Index>& kinkIntervals() const { return kinks_; }
  /// Known stiffness K = k/Me [1/s^2] at u of interval j; `right` picks the held value after
  /// the split (ignored for smooth stiffness).
  double knownStiffness(Index j, double u, bool right, Index lo, Index hi) const;
  /// Greybox mesh state (0/1) of interval j before (right = false) or after the split.
  double meshState(Index j, bool right) const;

  const SignalView& signal() const { return signal_; }
  const GearConstants& gear() const { return gear_; }
  Formulation formulation() const { return formulation_; }

 private:
  const SignalView& signal_;
  const GearConstants& gear_;
  Formulation formulation_;
  bool smooth_;
  double inv_me_;
  double kink(Index j) const;   // kink fraction of interval j, or 1
  int kinkSide(Index j) const;  // -1: interval j is just before a kink, +1: just after, 0: no
  CubicRules rules_;
  std::vector<Index> kinks_;
  std::vector<double> kink_th_;
  CubicIntervalRule::Weights mid_first_, mid_interior_, mid_last_;  // value(0.5) of each rule
};

}  // namespace gear_damping_id
