#include "gear_damping_id/quadrature.hpp"

#include <cstring>

#include "gear_sim/simd_clones.hpp"

namespace gear_damping_id {

bool heldChanges(const double* k, long lo, long hi, bool check_pairs, std::vector<long>* changes) {
  return heldChangesAfter(k, lo, hi, check_pairs, {}, lo, changes);
}

namespace {

// Intervals [j0, j1) one at a time: appends those where k changes; false at two adjacent ones
// (with check_pairs). *prev: whether interval j0 - 1 changes, then j1 - 1.
inline bool scanIntervals(const double* k, long j0, long j1, bool check_pairs, bool* prev,
                          std::vector<long>* changes) {
  for (long j = j0; j < j1; ++j) {
    const bool c = k[j] != k[j + 1];
    if (c && check_pairs && *prev) return false;
    if (c) changes->push_back(j);
    *prev = c;
  }
  return true;
}

}  // namespace

// Blocks of 16 intervals without a change are passed branch-free (vectorised; AVX2 clone, chosen
// at load time). The blocks before `from` were searched already: only those listed in `flagged`
// hold a change, and they are scanned here one interval at a time, as the loop below would.
GEAR_AVX2_CLONES
bool heldChangesAfter(const double* k, long lo, long hi, bool check_pairs,
                      const std::vector<long>& flagged, long from, std::vector<long>* changes) {
  const long last = hi - 1;  // intervals j < last
  bool prev = false;         // interval j - 1 changes
  long next = lo;            // the block after the last one scanned
  for (const long b : flagged) {
    if (b != next) prev = false;  // a block without a change in between
    if (!scanIntervals(k, b, b + 16, check_pairs, &prev, changes)) return false;
    next = b + 16;
  }
  if (from != next) prev = false;
  long j = from;
  for (; j + 16 <= last; j += 16) {
    if (!changesIn16(k + j)) {
      prev = false;
      continue;
    }
    if (!scanIntervals(k, j, j + 16, check_pairs, &prev, changes)) return false;
  }
  return scanIntervals(k, j, last, check_pairs, &prev, changes);
}

namespace {

// integral_0^u of sum_p c[p] v^p and of sum_p c[p] (1 - v) v^p.
double polyArea(const double* c, double u) {
  double s = 0.0, up = u;
  for (int p = 0; p < 4; ++p, up *= u) s += c[p] * up / (p + 1);
  return s;
}

double polyMoment(const double* c, double u) {
  double s = 0.0, up = u;
  for (int p = 0; p < 4; ++p, up *= u) s += c[p] * (up / (p + 1) - up * u / (p + 2));
  return s;
}

}  // namespace

CubicIntervalRule::CubicIntervalRule(int offset) : offset_(offset) {
  // Lagrange basis on the nodes x_m = offset + m, expanded into monomial coefficients.
  for (int k = 0; k < 4; ++k) {
    double c[4] = {1.0, 0.0, 0.0, 0.0};  // running product, degree grows by one per factor
    double denom = 1.0;
    const double xk = offset + k;
    for (int m = 0; m < 4; ++m) {
      if (m == k) continue;
      const double xm = offset + m;
      denom *= xk - xm;
      // multiply c by (u - xm)
      for (int p = 3; p >= 1; --p) c[p] = c[p - 1] - xm * c[p];
      c[0] = -xm * c[0];
    }
    for (int p = 0; p < 4; ++p) coef_[k][p] = c[p] / denom;
  }
  full_area_ = area(0.0, 1.0);
  full_moment_ = moment(0.0, 1.0);
}

CubicIntervalRule::Weights CubicIntervalRule::area(double u0, double u1) const {
  Weights w;
  for (int k = 0; k < 4; ++k) w[k] = polyArea(coef_[k], u1) - polyArea(coef_[k], u0);
  return w;
}

CubicIntervalRule::Weights CubicIntervalRule::moment(double u0, double u1) const {
  Weights w;
  for (int k = 0; k < 4; ++k) w[k] = polyMoment(coef_[k], u1) - polyMoment(coef_[k], u0);
  return w;
}

CubicIntervalRule::Weights CubicIntervalRule::value(double u) const {
  Weights w;
  for (int k = 0; k < 4; ++k) {
    w[k] = coef_[k][0] + u * (coef_[k][1] + u * (coef_[k][2] + u * coef_[k][3]));
  }
  return w;
}

int CubicRules::parts(long j, long lo, long hi, const QuadratureBreak* near, int n_near,
                      IntervalPart out[2]) const {
  double here = -1.0;  // this interval's break fraction, or -1
  for (int k = 0; k < n_near; ++k) {
    if (near[k].j == j) here = near[k].th;
  }
  // Whether the stencil starting at sample b reaches across no break (a break on a stencil
  // sample is on both sides at once).
  auto fits = [&](long b) {
    if (b < lo || b + 3 >= hi) return false;
    for (int k = 0; k < n_near; ++k) {
      const double x = static_cast<double>(near[k].j - b) + near[k].th;
      if (x > 0.0 && x < 3.0) return false;
    }
    return true;
  };
  const CubicIntervalRule& fallback = forInterval(j, lo, hi);
  if (here > 0.0 && here < 1.0) {
    // Split: each side by the cubic of its own samples (extrapolated over less than a step).
    out[0] = {fits(j - 3) ? &before : &fallback, 0.0, here, false};
    out[1] = {fits(j + 1) ? &after : &fallback, here, 1.0, true};
    return 2;
  }
  const CubicIntervalRule* r = &fallback;
  if (fits(j - 1)) {
    r = &interior;
  } else if (fits(j)) {
    r = &first;
  } else if (fits(j - 2)) {
    r = &last;
  }
  out[0] = {r, 0.0, 1.0, here == 0.0};  // a break at t_j: the whole interval lies after it
  return 1;
}

}  // namespace gear_damping_id
