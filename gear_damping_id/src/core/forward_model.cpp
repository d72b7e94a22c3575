#include "gear_damping_id/forward_model.hpp"

#include <algorithm>
#include <cmath>

namespace gear_damping_id {

ForwardModel::ForwardModel(const SignalView& s, const GearConstants& g, Formulation f)
    : signal_(s),
      gear_(g),
      formulation_(f),
      smooth_(f == Formulation::Known && !g.piecewise_constant_stiffness),
      inv_me_(1.0 / g.equivalent_mass) {}

double ForwardModel::switchFraction(const double* ch, Index j) const {
  const SignalView& s = signal_;
  if (ch == nullptr || j + 1 >= s.n || ch[j] == ch[j + 1]) return 1.0;
  // The held value changes between samples j and j+1: the switch lies in (t_j, t_{j+1}].
  if (s.mesh_phase == nullptr) return 1.0;
  const double ua = s.mesh_phase[j], ub = s.mesh_phase[j + 1];
  if (!(ub > ua)) return 1.0;
  // Switch phases: integers (into the stiffer, double-contact phase: rising) and m + eps - 1.
  const bool rising = ch[j + 1] > ch[j];
  const double off = rising ? 0.0 : gear_.contact_ratio - 1.0;
  const double tol = 1e-9 * std::max(1.0, std::abs(ua));
  const double c = std::ceil(ua - off - tol) + off;  // first switch phase >= ua (to rounding)
  if (c > ub + (ub - ua)) return 1.0;  // the phase disagrees with the samples: sample and hold
  return std::clamp((c - ua) / (ub - ua), 0.0, 1.0);
}

double ForwardModel::cubic(const double* ch, Index j, double u, Index lo, Index hi) const {
  if (u == 0.0) return ch[j];
  if (u == 1.0 && j + 1 < signal_.n) return ch[j + 1];
  if (hi - lo < 4) {
    const double b = j + 1 < signal_.n ? ch[j + 1] : ch[j];
    return (1.0 - u) * ch[j] + u * b;
  }
  const CubicIntervalRule& r = rules_.forInterval(j, lo, hi);
  const auto w = r.value(u);
  const Index b = j + r.offset();
  return w[0] * ch[b] + w[1] * ch[b + 1] + w[2] * ch[b + 2] + w[3] * ch[b + 3];
}

double ForwardModel::heldSplit(Index j) const {
  if (formulation_ == Formulation::Greybox) return switchFraction(signal_.mesh_state, j);
  if (formulation_ == Formulation::Known && !smooth_) return switchFraction(signal_.stiffness, j);
  return 1.0;
}

double ForwardModel::knownStiffness(Index j, double u, bool right, Index lo, Index hi) const {
  const double* k = signal_.stiffness;
  if (smooth_) return cubic(k, j, u, lo, hi) * inv_me_;
  const double v = right && j + 1 < signal_.n ? k[j + 1] : k[j];
  return v * inv_me_;
}

double ForwardModel::meshState(Index j, bool right) const {
  const double* st = signal_.mesh_state;
  return right && j + 1 < signal_.n ? st[j + 1] : st[j];
}

}  // namespace gear_damping_id
