// Internal helpers shared by morlet_cwt.cpp and wavelet_analysis.cpp (not installed).
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <vector>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace gear_damping_id {
namespace wavelet_detail {

constexpr double kPi = 3.14159265358979323846;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

inline std::string num(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

// |w| of n complex values (interleaved re, im) into out. sqrt(re^2 + im^2): exact to 1 ulp for
// |w| in [1e-150, 1e150]. SSE2 (x86-64 baseline) computes two square roots per instruction;
// plain std::sqrt does not vectorise without -fno-math-errno.
template <typename T>
inline void modulusOf(const double* w, long n, T* out) {
  long i = 0;
#if defined(__SSE2__)
  for (; i + 1 < n; i += 2) {
    const __m128d a = _mm_loadu_pd(w + 2 * i);
    const __m128d b = _mm_loadu_pd(w + 2 * i + 2);
    const __m128d sa = _mm_mul_pd(a, a), sb = _mm_mul_pd(b, b);
    const __m128d r = _mm_sqrt_pd(_mm_add_pd(_mm_unpacklo_pd(sa, sb), _mm_unpackhi_pd(sa, sb)));
    alignas(16) double tmp[2];
    _mm_store_pd(tmp, r);
    out[i] = static_cast<T>(tmp[0]);
    out[i + 1] = static_cast<T>(tmp[1]);
  }
#endif
  for (; i < n; ++i)
    out[i] = static_cast<T>(std::sqrt(w[2 * i] * w[2 * i] + w[2 * i + 1] * w[2 * i + 1]));
}

// Psi(s*w) = 2*exp(-(s*w - omega0)^2/2) is below 1e-16 of its peak when |s*w - omega0| > 8.6
// (exp(-8.6^2/2) = 8.7e-17): a row's band; the bins outside it are set to zero, not multiplied.
constexpr double kBandHalfWidth = 8.6;
// A row's Gaussian multiplier is advanced by a two-multiplication recurrence and recomputed with
// exp() every kRecurrenceBlock bins (relative drift < kRecurrenceBlock * 2 eps = 3e-14).
constexpr long kRecurrenceBlock = 64;

// Bins [lo, hi] of the band where |a k - omega0| <= half_width (by default: Psi(s*w_k) above
// 1e-16 of its peak), with a = s * 2*pi*fs/N (so s*w_k = a*k), clipped to the positive
// frequencies 1..N/2. lo > hi when empty.
inline void bandOf(double a, double omega0, long n_fft, long* lo, long* hi,
                   double half_width = kBandHalfWidth) {
  const double k_lo = std::ceil((omega0 - half_width) / a);
  const double k_hi = std::floor((omega0 + half_width) / a);
  *lo = static_cast<long>(std::max(1.0, k_lo));
  *hi = static_cast<long>(std::min(static_cast<double>(n_fft / 2), k_hi));
}

// Psi(s*w)^2 = 4*exp(-(s*w - omega0)^2) is below 1e-16 of its peak when |s*w - omega0| > 6.07
// (exp(-6.07^2) = 1e-16): the band of the Parseval sums (meanPower, noiseGain).
constexpr double kPowerBandHalfWidth = 6.07;
// Gaussian recurrences are re-seeded with exp() every kSumRecurrenceBlock bins.
constexpr long kSumRecurrenceBlock = 64;

// sum_{k=lo..hi} weight(k) * Psi(a*k)^2, Psi(x)^2 = 4 exp(-(x - omega0)^2), advanced by a
// blocked multiplicative recurrence (relative drift < 64 * 2 eps). The one implementation of
// the Parseval sums (MorletCwt::meanPowerAt / noiseGainAt and the per-mode path's narrow rows).
template <typename Weight>
inline double psi2Sum(double a, double omega0, long lo, long hi, Weight weight) {
  const double q = std::exp(-2.0 * a * a);
  double sum = 0.0;
  for (long k0 = lo; k0 <= hi; k0 += kSumRecurrenceBlock) {
    const long k1 = std::min(hi + 1, k0 + kSumRecurrenceBlock);
    const double x = a * static_cast<double>(k0) - omega0;
    double g = 4.0 * std::exp(-x * x);
    double r = std::exp(-2.0 * a * x - a * a);
    for (long k = k0; k < k1; ++k) {
      sum += weight(k) * g;
      g *= r;
      r *= q;
    }
  }
  return sum;
}

// Median (upper middle element) of *v, reordering *v in place (no copy).
template <typename T>
inline double medianInPlace(std::vector<T>* v) {
  if (v->empty()) return kNaN;
  const auto mid = v->begin() + static_cast<long>(v->size() / 2);
  std::nth_element(v->begin(), mid, v->end());
  return static_cast<double>(*mid);
}

template <typename T>
inline double median(std::vector<T> v) {
  return medianInPlace(&v);
}
}  // namespace wavelet_detail
}  // namespace gear_damping_id
