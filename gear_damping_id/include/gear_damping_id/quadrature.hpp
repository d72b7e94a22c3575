// Quadrature of sampled signals for the integral method (docs/method.md §4): local four-point cubic
// (Lagrange) interpolation of the samples, integrated exactly over one sample interval or over
// a part of it. Splitting an interval at a stiffness switch instant and integrating each part
// with its own stiffness keeps the quadrature fourth-order accurate where a plain trapezoid across
// the switch would bias C by 10-50 %. No ROS.
#pragma once

#include <array>
#include <cstring>
#include <vector>

namespace gear_damping_id {

/// Weights of the cubic through four samples y[j+o], ..., y[j+o+3] (o = -1 in the interior, 0
/// at a record's first interval, -2 at its last) for integrals over (a part of) the interval
/// [t_j, t_j + h], in units of the local coordinate u = (t - t_j)/h in [0, 1]:
///   area(u0, u1)[k]   = integral_{u0}^{u1} L_k(u) du              (multiply by h)
///   moment(u0, u1)[k] = integral_{u0}^{u1} (1 - u) L_k(u) du      (multiply by h^2)
/// `moment` is the first moment about the interval's end t_j + h, which is what a cumulative
/// double integral needs: Q(t_{j+1}) = Q(t_j) + h G(t_j) + integral (t_{j+1} - s) g(s) ds.
/// The cubic is exact for polynomials of degree <= 3 (tested), so the rule is fourth order.
class CubicIntervalRule {
 public:
  using Weights = std::array<double, 4>;
  /// `offset` in {-2, -1, 0}: index of the first stencil sample relative to j.
  explicit CubicIntervalRule(int offset);
  int offset() const { return offset_; }
  /// Weights over the whole interval (precomputed).
  const Weights& area() const { return full_area_; }
  const Weights& moment() const { return full_moment_; }
  /// Weights over [u0, u1], 0 <= u0 <= u1 <= 1.
  Weights area(double u0, double u1) const;
  Weights moment(double u0, double u1) const;
  /// Interpolation weights at u (value of the cubic at u).
  Weights value(double u) const;

 private:
  int offset_;
  double coef_[4][4];  // L_k(u) = sum_p coef_[k][p] u^p
  Weights full_area_, full_moment_;
};

/// A break of smoothness of the sampled data at t_j + th h (th in [0, 1]): a switch of a held
/// channel, a jump or a kink of a smooth one. There the second derivative of y (a switch, a
/// jump) or its third (a kink) and the integrand K y jump, so a cubic through samples on both
/// sides would carry an O(h^2) interpolation error into every integral that crosses it.
struct QuadratureBreak {
  long j = 0;
  double th = 1.0;
};

/// One pass over the samples [lo, hi) of a channel for what channelIsHeld and findBreaks (held)
/// (forward_model.hpp) find in two: appends every interval j (lo <= j < hi - 1) on which the
/// value changes to *changes, in order. With check_pairs, returns false at the first two adjacent
/// changing intervals (the channel is then smooth, not held, and *changes incomplete); else true.
bool heldChanges(const double* channel, long lo, long hi, bool check_pairs,
                 std::vector<long>* changes);

/// Whether the channel changes on any of the 16 intervals from k: k[q] != k[q + 1] for some q in
/// [0, 16) (four compares of four lanes, or-ed: branch-free, vectorised by the caller's target).
inline bool changesIn16(const double* k) {
  typedef double V4 __attribute__((vector_size(32)));
  typedef long M4 __attribute__((vector_size(32)));
  M4 changed = {0, 0, 0, 0};
  for (int q = 0; q < 16; q += 4) {
    V4 a, b;
    std::memcpy(&a, k + q, sizeof(V4));
    std::memcpy(&b, k + q + 1, sizeof(V4));
    changed |= a != b;
  }
  return (changed[0] | changed[1] | changed[2] | changed[3]) != 0;
}

/// heldChanges, the blocks of 16 intervals before `from` (from - lo a multiple of 16) searched
/// already by the caller: `flagged` lists, ascending, the starts of those in which the value
/// changes (IntegralMethod's first read of a segment does this search). The same result.
bool heldChangesAfter(const double* channel, long lo, long hi, bool check_pairs,
                      const std::vector<long>& flagged, long from, std::vector<long>* changes);

/// One part [u0, u1] of a sample interval, integrated with `rule`; `right`: the part lies after
/// the interval's break (a held channel takes the value of sample j+1 there).
struct IntervalPart {
  const CubicIntervalRule* rule = nullptr;
  double u0 = 0.0, u1 = 1.0;
  bool right = false;
};

/// The rules of a record: interior (-1), first interval (0), last interval (-2), and for an
/// interval split by a break the parts before it (samples j-3..j, -3) and after it (j+1..j+4, +1).
struct CubicRules {
  CubicIntervalRule first{0}, interior{-1}, last{-2}, before{-3}, after{1};
  /// Rule for interval j of a record whose samples are [lo, hi) (needs hi - lo >= 4).
  const CubicIntervalRule& forInterval(long j, long lo, long hi) const {
    if (j - 1 < lo) return first;
    if (j + 2 >= hi) return last;
    return interior;
  }
  /// Parts of interval j of the record [lo, hi) (hi - lo >= 4) given the breaks of `near` (at
  /// least those of intervals j-2..j+2): one part with the interior rule when no stencil sample
  /// lies beyond a break; else the rule of {-1, 0, -2} whose samples all lie on one side of every
  /// break, and an interval holding a break strictly inside is split there into a part before it
  /// (samples j-3..j) and one after it (j+1..j+4). Where the record's ends leave no such stencil,
  /// the part falls back to forInterval. Returns the number of parts (1 or 2).
  int parts(long j, long lo, long hi, const QuadratureBreak* near, int n_near,
            IntervalPart out[2]) const;
};

}  // namespace gear_damping_id
