#include "gear_damping_id/forward_model.hpp"

#include <algorithm>
#include <cmath>

namespace gear_damping_id {

namespace {
// A kink's two second differences against their neighbours': a smooth curve sampled at 1e2-1e3
// points per mesh cycle gives a ratio near 1; a slope jump between straight (or gently curved)
// pieces gives a ratio of ds / (h K'') >> 10.
constexpr double kKinkRatio = 20.0;
// Second differences below this fraction of |K| are rounding (K ~ 1e8 N/m carries ~1e-8 N/m).
constexpr double kKinkFloor = 1e-12;
}  // namespace

ForwardModel::ForwardModel(const SignalView& s, const GearConstants& g, Formulation f)
    : signal_(s),
      gear_(g),
      formulation_(f),
      smooth_(f == Formulation::Known && !g.piecewise_constant_stiffness),
      inv_me_(1.0 / g.equivalent_mass),
      mid_first_(rules_.first.value(0.5)),
      mid_interior_(rules_.interior.value(0.5)),
      mid_last_(rules_.last.value(0.5)) {
  if (!smooth_ || s.stiffness == nullptr || s.n < 8) return;
  const double* k = s.stiffness;
  auto d2 = [&](Index i) { return k[i + 1] - 2.0 * k[i] + k[i - 1]; };
  for (Index j = 2; j + 3 < s.n; ++j) {
    const double a = d2(j), b = d2(j + 1);
    const double floor = kKinkFloor * std::abs(k[j]);
    if (!(std::abs(a) + std::abs(b) > floor) || a * b < 0.0) continue;
    const double outer = std::abs(d2(j - 1)) + std::abs(d2(j + 2));
    if (!(std::abs(a) + std::abs(b) > kKinkRatio * outer + floor)) continue;
    kinks_.push_back(j);
    kink_th_.push_back(std::clamp(b / (a + b), 0.0, 1.0));
    ++j;  // one kink per pair of intervals (a kink on a sample shows in both)
  }
}

double ForwardModel::kink(Index j) const {
  const auto it = std::lower_bound(kinks_.begin(), kinks_.end(), j);
  return (it != kinks_.end() && *it == j) ? kink_th_[it - kinks_.begin()] : 1.0;
}

int ForwardModel::kinkSide(Index j) const {
  const auto it = std::lower_bound(kinks_.begin(), kinks_.end(), j - 1);
  if (it == kinks_.end()) return 0;
  if (*it == j + 1) return -1;
  if (*it == j - 1) return +1;
  if (std::next(it) != kinks_.end() && *std::next(it) == j + 1) return -1;
  return 0;
}

double switchFractionFromPhase(const double* phase, Eigen::Index j, Eigen::Index n, bool rising,
                               double contact_ratio) {
  // The held value changes between samples j and j+1: the switch lies in (t_j, t_{j+1}].
  if (phase == nullptr || j + 1 >= n) return 1.0;
  const double ua = phase[j], ub = phase[j + 1];
  if (!(ub > ua)) return 1.0;
  // Switch phases: integers (into the stiffer, double-contact phase: rising) and m + eps - 1.
  const double off = rising ? 0.0 : contact_ratio - 1.0;
  const double tol = 1e-9 * std::max(1.0, std::abs(ua));
  const double c = std::ceil(ua - off - tol) + off;  // first switch phase >= ua (to rounding)
  if (c > ub + (ub - ua)) return kNaN;               // the phase disagrees with the samples
  return std::clamp((c - ua) / (ub - ua), 0.0, 1.0);
}

double ForwardModel::switchFraction(const double* ch, Index j) const {
  if (ch == nullptr || j + 1 >= signal_.n || ch[j] == ch[j + 1]) return 1.0;
  const double th = switchFractionFromPhase(signal_.mesh_phase, j, signal_.n, ch[j + 1] > ch[j],
                                            gear_.contact_ratio);
  return std::isnan(th) ? 1.0 : th;  // unlocated: sample and hold
}

double ForwardModel::cubic(const double* ch, Index j, double u, Index lo, Index hi) const {
  if (u == 0.0) return ch[j];
  if (u == 1.0 && j + 1 < signal_.n) return ch[j + 1];
  if (hi - lo < 4) {
    const double b = j + 1 < signal_.n ? ch[j + 1] : ch[j];
    return (1.0 - u) * ch[j] + u * b;
  }
  const CubicIntervalRule& r = rules_.forInterval(j, lo, hi);
  // The midpoint (every RK4 step over a whole interval) from precomputed weights.
  const auto w = u != 0.5                 ? r.value(u)
                 : &r == &rules_.interior ? mid_interior_
                 : &r == &rules_.first    ? mid_first_
                                          : mid_last_;
  const Index b = j + r.offset();
  return w[0] * ch[b] + w[1] * ch[b + 1] + w[2] * ch[b + 2] + w[3] * ch[b + 3];
}

double ForwardModel::heldSplit(Index j) const {
  if (formulation_ == Formulation::Greybox) return switchFraction(signal_.mesh_state, j);
  if (formulation_ == Formulation::Known && !smooth_) return switchFraction(signal_.stiffness, j);
  if (smooth_ && !kinks_.empty()) return kink(j);
  return 1.0;
}

double ForwardModel::knownStiffness(Index j, double u, bool right, Index lo, Index hi) const {
  const double* k = signal_.stiffness;
  if (smooth_) {
    if (kinks_.empty()) return cubic(k, j, u, lo, hi) * inv_me_;
    if (kink(j) < 1.0) {
      // On the kink interval: the line through the two samples on the piece's side.
      if (!right && j - 1 >= lo) return (k[j] + u * (k[j] - k[j - 1])) * inv_me_;
      if (right && j + 2 < hi) return (k[j + 1] + (u - 1.0) * (k[j + 2] - k[j + 1])) * inv_me_;
      return ((1.0 - u) * k[j] + u * k[j + 1]) * inv_me_;
    }
    const int side = kinkSide(j);
    if (side != 0) {
      // Next to a kink: the one-sided cubic (samples j-2..j+1 before it, j..j+3 after it),
      // else the line between the interval's samples.
      const CubicIntervalRule& r = side < 0 ? rules_.last : rules_.first;
      const Index b = j + r.offset();
      if (b >= lo && b + 3 < hi) {
        const auto w = r.value(u);
        return (w[0] * k[b] + w[1] * k[b + 1] + w[2] * k[b + 2] + w[3] * k[b + 3]) * inv_me_;
      }
      return ((1.0 - u) * k[j] + u * k[j + 1]) * inv_me_;
    }
    return cubic(k, j, u, lo, hi) * inv_me_;
  }
  const double v = right && j + 1 < signal_.n ? k[j + 1] : k[j];
  return v * inv_me_;
}

double ForwardModel::meshState(Index j, bool right) const {
  const double* st = signal_.mesh_state;
  return right && j + 1 < signal_.n ? st[j + 1] : st[j];
}

}  // namespace gear_damping_id
