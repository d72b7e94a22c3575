// The forward model of eq. (4), y'' + C(t) y' + K(t) y = F(t), as the integral method's
// quadrature sees the sampled channels, shared by the integral method (its breaks), the
// output-error refinement and the modeled response (output_error.hpp) so that the three integrate
// one and the same K(t) and F(t). No ROS.
//
// Held or smooth is decided from the samples of each damping segment, never from the stiffness
// model's name: a stiffness channel whose value never changes on two adjacent sample intervals
// is held (piecewise constant: a square wave, a constant); any other is smooth (trapezoid,
// Fourier, a rig's measured channel). The greybox mesh state is always held.
//
// Breaks (quadrature.hpp) are where the sampled data lose smoothness; every stencil of the
// quadrature (and of the interpolated stiffness) stays on one side of them:
// - held channels: every change of value between samples j and j+1. The switch instant is
//   located from `mesh_phase` (switch phases n and n + eps - 1); without a phase channel, or when
//   the phase places no switch in the interval, the new value holds from sample j+1 on (sample
//   and hold). The value of sample j holds before the switch, that of sample j+1 after it.
// - smooth channels: jumps, where a first difference exceeds kBreakRatio times the sum of its
//   two neighbours (a smooth curve gives about 1/2), located like the switches of a held channel;
//   and kinks (a jump of the slope, as at the ends of a trapezoid's ramps): a kink at t_j + th h
//   between straight pieces makes the second differences d_j = h ds (1 - th) and
//   d_{j+1} = h ds th, both of the sign of ds, while the neighbouring d_{j-1}, d_{j+2} see no
//   kink; an interval is a kink interval when |d_j| + |d_{j+1}| exceeds kBreakRatio times
//   |d_{j-1}| + |d_{j+2}|, with th = d_{j+1} / (d_j + d_{j+1}).
// A smooth stiffness is the cubic of the quadrature's stencil for the interval (or for the part
// of a split interval) through the samples; the forcing F = force_factor T1 with T1 the local
// cubic of the torque samples. All stencils are bounded by the segment, so that a segment reads
// no sample outside itself.
#pragma once

#include <Eigen/Core>
#include <utility>
#include <vector>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/quadrature.hpp"
#include "gear_damping_id/signal_view.hpp"

namespace gear_damping_id {

/// Split fraction th in [0, 1] of sample interval j at which `mesh_phase` reaches the next switch
/// phase of the square-wave mesh (rising, into double contact: an integer; falling:
/// m + contact_ratio - 1): 1 without a phase channel or with a non-increasing phase; NaN when the
/// phase places no switch within the interval (the caller then holds the sample value, th = 1).
double switchFractionFromPhase(const double* mesh_phase, Eigen::Index j, Eigen::Index n,
                               bool rising, double contact_ratio);

/// Whether the samples [lo, hi) of a stiffness channel are held (no change of value on two
/// adjacent intervals) rather than smooth.
bool channelIsHeld(const double* channel, Eigen::Index lo, Eigen::Index hi);

/// Appends the breaks of `channel` on the intervals j of samples [lo, hi) (j + 1 < hi) to `out`
/// (in order of j), held or smooth as described above. Returns the number of switches/jumps
/// that `mesh_phase` could not locate (held from the sample on instead).
long findBreaks(const SignalView& signal, const double* channel, bool held, double contact_ratio,
                Eigen::Index lo, Eigen::Index hi, std::vector<QuadratureBreak>* out);

/// Appends the switches of a held channel on the intervals `changes` (ascending, as heldChanges
/// lists them) to `out`, as findBreaks (held) appends them: each located by `mesh_phase`
/// (switchFractionFromPhase), at th = 1 where it cannot be. Returns the number not located.
long locateHeldSwitches(const SignalView& signal, const double* channel, double contact_ratio,
                        const std::vector<long>& changes, std::vector<QuadratureBreak>* out);

class ForwardModel {
 public:
  using Index = Eigen::Index;
  using Ranges = std::vector<std::pair<Index, Index>>;
  /// `signal` and `gear` must outlive the model. `ranges`: the damping segments [lo, hi) whose
  /// breaks are found (each on its own samples); empty: the whole record as one.
  ForwardModel(const SignalView& signal, const GearConstants& gear, Formulation formulation,
               const Ranges& ranges = {});

  /// Value at local coordinate u in [0, 1] of interval j of the local cubic through the samples
  /// of `channel`, stencil within [lo, hi) (hi - lo >= 4; fewer: linear between the samples).
  double cubic(const double* channel, Index j, double u, Index lo, Index hi) const;
  /// The weights of cubic(channel, j, u, lo, hi) on the samples: its value is the sum over
  /// k < the returned count (at most 4) of w[k] * channel[*first + k], each w[k] the value
  /// cubic() gives for a unit sample there and zeros elsewhere.
  int cubicWeights(Index j, double u, Index lo, Index hi, Index* first, double* w) const;
  /// The weights of cubic() at u = 0.5 of an interval whose stencil is the centred one
  /// (samples j - 1 .. j + 2), which cubic() applies.
  const CubicIntervalRule::Weights& interiorMidpointWeights() const { return mid_interior_; }
  /// Torque T1 [N*m] at u of interval j (0 without a torque channel).
  double torque(Index j, double u, Index lo, Index hi) const {
    return signal_.torque == nullptr ? 0.0 : cubic(signal_.torque, j, u, lo, hi);
  }
  /// Whether the known stiffness of the segment holding sample j is interpolated (true) or held.
  bool smoothStiffness(Index j) const;
  /// Split fraction of interval j at its break (switch of the held channel of the formulation:
  /// known stiffness when held, greybox mesh state; jump or kink of a smooth stiffness); 1 when
  /// the interval holds none.
  double heldSplit(Index j) const;
  /// A copy whose switches of a held channel lie at u = th of their interval where the record has
  /// no `mesh_phase` (there each is held from the sample where its new value is first seen, th =
  /// 1): the refinement's switch timing check. With `mesh_phase`, and for a smooth stiffness's
  /// jumps and kinks, the same breaks.
  ForwardModel withUnlocatedSwitchesAt(double th) const;
  /// Every break (sorted by interval).
  const std::vector<QuadratureBreak>& breaks() const { return breaks_; }
  /// Intervals j whose smooth stiffness has a kink or jump (sorted).
  std::vector<Index> kinkIntervals() const;
  /// Known stiffness K = k/Me [1/s^2] at u of interval j; `right` picks the part after the
  /// interval's break (the held value of sample j+1, or the cubic of the samples after it).
  double knownStiffness(Index j, double u, bool right, Index lo, Index hi) const;
  /// knownStiffness of a segment whose stiffness is held (smoothStiffness false): the value of
  /// sample j (right: of sample j + 1), without looking up the segment.
  double heldStiffness(Index j, bool right) const;
  /// Greybox mesh state (0/1) of interval j before (right = false) or after the split.
  double meshState(Index j, bool right) const;

  const SignalView& signal() const { return signal_; }
  const GearConstants& gear() const { return gear_; }
  Formulation formulation() const { return formulation_; }
  /// Unlocated switches and jumps over all segments (see findBreaks).
  long unlocated() const { return unlocated_; }

 private:
  const SignalView& signal_;
  const GearConstants& gear_;
  Formulation formulation_;
  double inv_me_;
  CubicRules rules_;
  Ranges ranges_;
  std::vector<char> smooth_;  // per range
  std::vector<QuadratureBreak> breaks_;
  long unlocated_ = 0;
  CubicIntervalRule::Weights mid_first_, mid_interior_, mid_last_;  // value(0.5) of each rule
  // Breaks of intervals j-2..j+2 (at most 5) into near; returns their count.
  int nearBreaks(Index j, QuadratureBreak* near) const;
};

}  // namespace gear_damping_id
