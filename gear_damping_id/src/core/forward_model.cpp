#include "gear_damping_id/forward_model.hpp"

#include <algorithm>
#include <cmath>

namespace gear_damping_id {

namespace {
// A jump's first difference, or a kink's two second differences, against their neighbours': a
// smooth curve sampled at 1e2-1e3 points per mesh cycle gives a ratio near 1/2 (jump) or 1
// (kink); a jump of size dk on a slope s gives dk / (2 h s), a slope jump ds between straight (or
// gently curved) pieces ds / (h K''), both >> 10.
constexpr double kBreakRatio = 20.0;
// Differences below this fraction of |K| are rounding (K ~ 1e8 N/m carries ~1e-8 N/m).
constexpr double kBreakFloor = 1e-12;
}  // namespace

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

bool channelIsHeld(const double* k, Eigen::Index lo, Eigen::Index hi) {
  // Blocks of 16 intervals are first tested as a whole (branch-free): a held channel changes a
  // few times per mesh period, a smooth one at once.
  Eigen::Index j = lo;
  for (; j + 17 < hi; j += 16) {
    bool pair = false;
    for (int q = 0; q < 16; ++q) {
      pair |= (k[j + q] != k[j + q + 1]) & (k[j + q + 1] != k[j + q + 2]);
    }
    if (pair) return false;
  }
  for (; j + 2 < hi; ++j) {
    if (k[j] != k[j + 1] && k[j + 1] != k[j + 2]) return false;
  }
  return true;
}

namespace {
// The switch of k on interval j appended to `out`: located by `mesh_phase`
// (switchFractionFromPhase), at th = 1 where it cannot be. 1 when it cannot, else 0.
long appendSwitch(const SignalView& s, const double* k, double contact_ratio, long j,
                  std::vector<QuadratureBreak>* out) {
  const double th = switchFractionFromPhase(s.mesh_phase, j, s.n, k[j + 1] > k[j], contact_ratio);
  out->push_back({j, std::isnan(th) ? 1.0 : th});
  return std::isnan(th) ? 1 : 0;
}
}  // namespace

long findBreaks(const SignalView& s, const double* k, bool held, double contact_ratio,
                Eigen::Index lo, Eigen::Index hi, std::vector<QuadratureBreak>* out) {
  using Index = Eigen::Index;
  long unlocated = 0;
  const Index last = std::min(hi, s.n) - 1;  // intervals j < last
  auto located = [&](Index j) {
    unlocated += appendSwitch(s, k, contact_ratio, static_cast<long>(j), out);
  };
  if (held) {
    Index j = lo;
    for (; j + 16 <= last; j += 16) {
      bool change = false;
      for (int q = 0; q < 16; ++q) change |= k[j + q] != k[j + q + 1];
      if (!change) continue;
      for (int q = 0; q < 16; ++q) {
        if (k[j + q] != k[j + q + 1]) located(j + q);
      }
    }
    for (; j < last; ++j) {
      if (k[j] != k[j + 1]) located(j);
    }
    return unlocated;
  }
  auto d1 = [&](Index i) { return k[i + 1] - k[i]; };
  auto d2 = [&](Index i) { return k[i + 1] - 2.0 * k[i] + k[i - 1]; };
  for (Index j = lo + 1; j < last; ++j) {
    const double floor = kBreakFloor * std::abs(k[j]);
    // Jump: needs the neighbouring intervals j-1 and j+1 within the segment.
    if (j + 2 < hi) {
      const double a = std::abs(d1(j));
      if (a > floor && a > kBreakRatio * (std::abs(d1(j - 1)) + std::abs(d1(j + 1))) + floor) {
        located(j);
        ++j;
        continue;
      }
    }
    // Kink: second differences at j-1..j+2 (samples j-2..j+3).
    if (j - 2 < lo || j + 3 >= hi) continue;
    const double a = d2(j), b = d2(j + 1);
    if (!(std::abs(a) + std::abs(b) > floor) || a * b < 0.0) continue;
    const double outer = std::abs(d2(j - 1)) + std::abs(d2(j + 2));
    if (!(std::abs(a) + std::abs(b) > kBreakRatio * outer + floor)) continue;
    out->push_back({static_cast<long>(j), std::clamp(b / (a + b), 0.0, 1.0)});
    ++j;  // one kink per pair of intervals (a kink on a sample shows in both)
  }
  return unlocated;
}

long locateHeldSwitches(const SignalView& s, const double* k, double contact_ratio,
                        const std::vector<long>& changes, std::vector<QuadratureBreak>* out) {
  long unlocated = 0;
  for (const long j : changes) unlocated += appendSwitch(s, k, contact_ratio, j, out);
  return unlocated;
}

ForwardModel::ForwardModel(const SignalView& s, const GearConstants& g, Formulation f,
                           const Ranges& ranges)
    : signal_(s),
      gear_(g),
      formulation_(f),
      inv_me_(1.0 / g.equivalent_mass),
      ranges_(ranges),
      mid_first_(rules_.first.value(0.5)),
      mid_interior_(rules_.interior.value(0.5)),
      mid_last_(rules_.last.value(0.5)) {
  if (ranges_.empty()) ranges_.emplace_back(0, s.n);
  smooth_.assign(ranges_.size(), 0);
  const double* ch = f == Formulation::Known     ? s.stiffness
                     : f == Formulation::Greybox ? s.mesh_state
                                                 : nullptr;
  if (ch == nullptr) return;
  // One scan per range finds whether the stiffness is held and where it switches (heldChanges:
  // what channelIsHeld and findBreaks find in two, as the integral method reads a segment); a
  // smooth stiffness (known only) is searched for jumps and kinks.
  std::vector<long> changes;
  for (size_t r = 0; r < ranges_.size(); ++r) {
    const auto [lo, hi] = ranges_[r];
    if (hi - lo < 2) continue;
    changes.clear();
    const bool held = heldChanges(ch, lo, std::min(hi, s.n), f == Formulation::Known, &changes);
    smooth_[r] = !held;
    unlocated_ += held ? locateHeldSwitches(s, ch, g.contact_ratio, changes, &breaks_)
                       : findBreaks(s, ch, false, g.contact_ratio, lo, hi, &breaks_);
  }
}

bool ForwardModel::smoothStiffness(Index j) const {
  if (formulation_ != Formulation::Known) return false;
  // The last range starting at or before j.
  const auto it = std::upper_bound(ranges_.begin(), ranges_.end(), j,
                                   [](Index v, const auto& r) { return v < r.first; });
  return it != ranges_.begin() && smooth_[std::prev(it) - ranges_.begin()];
}

ForwardModel ForwardModel::withUnlocatedSwitchesAt(double th) const {
  ForwardModel m(*this);
  if (signal_.mesh_phase != nullptr) return m;
  for (auto& b : m.breaks_) {
    if (!smoothStiffness(b.j)) b.th = th;
  }
  return m;
}

std::vector<Eigen::Index> ForwardModel::kinkIntervals() const {
  std::vector<Index> out;
  for (const auto& b : breaks_) {
    if (smoothStiffness(b.j)) out.push_back(b.j);
  }
  return out;
}

int ForwardModel::nearBreaks(Index j, QuadratureBreak* near) const {
  auto it = std::lower_bound(breaks_.begin(), breaks_.end(), j - 2,
                             [](const QuadratureBreak& b, Index v) { return b.j < v; });
  int n = 0;
  for (; it != breaks_.end() && it->j <= j + 2 && n < 5; ++it) near[n++] = *it;
  return n;
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

int ForwardModel::cubicWeights(Index j, double u, Index lo, Index hi, Index* first,
                               double* w) const {
  *first = j;
  if (u == 0.0) return w[0] = 1.0, 1;
  if (u == 1.0 && j + 1 < signal_.n) return *first = j + 1, w[0] = 1.0, 1;
  if (hi - lo < 4) {
    if (j + 1 < signal_.n) return w[0] = (1.0 - u) * 1.0 + u * 0.0, w[1] = (1.0 - u) * 0.0 + u, 2;
    return w[0] = (1.0 - u) * 1.0 + u * 1.0, 1;  // both terms are sample j
  }
  const CubicIntervalRule& r = rules_.forInterval(j, lo, hi);
  const auto c = u != 0.5                 ? r.value(u)
                 : &r == &rules_.interior ? mid_interior_
                 : &r == &rules_.first    ? mid_first_
                                          : mid_last_;
  *first = j + r.offset();
  for (int k = 0; k < 4; ++k) w[k] = c[k];
  return 4;
}

double ForwardModel::heldSplit(Index j) const {
  const auto it = std::lower_bound(breaks_.begin(), breaks_.end(), j,
                                   [](const QuadratureBreak& b, Index v) { return b.j < v; });
  return (it != breaks_.end() && it->j == j) ? it->th : 1.0;
}

double ForwardModel::knownStiffness(Index j, double u, bool right, Index lo, Index hi) const {
  const double* k = signal_.stiffness;
  if (!smoothStiffness(j)) return heldStiffness(j, right);
  QuadratureBreak near[5];
  const int nn = nearBreaks(j, near);
  if (nn == 0 || hi - lo < 4) return cubic(k, j, u, lo, hi) * inv_me_;
  // Near a break: the cubic of the quadrature's stencil for the part holding u.
  IntervalPart parts[2];
  const int np = rules_.parts(j, lo, hi, near, nn, parts);
  const IntervalPart& p = (np == 2 && right) ? parts[1] : parts[0];
  const auto w = p.rule->value(u);
  const Index b = j + p.rule->offset();
  return (w[0] * k[b] + w[1] * k[b + 1] + w[2] * k[b + 2] + w[3] * k[b + 3]) * inv_me_;
}

double ForwardModel::heldStiffness(Index j, bool right) const {
  const double* k = signal_.stiffness;
  const double v = right && j + 1 < signal_.n ? k[j + 1] : k[j];
  return v * inv_me_;
}

double ForwardModel::meshState(Index j, bool right) const {
  const double* st = signal_.mesh_state;
  return right && j + 1 < signal_.n ? st[j + 1] : st[j];
}

}  // namespace gear_damping_id
