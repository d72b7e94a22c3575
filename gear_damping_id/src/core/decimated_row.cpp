// Decimated wavelet rows of the per-mode path: see decimated_row.hpp.
#include "decimated_row.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "wavelet_detail.hpp"

namespace gear_damping_id {
namespace wavelet_detail {
std::mutex& fftwPlannerMutex() {
  static std::mutex m;
  return m;
}

void adviseHugePages(void* p, size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  constexpr uintptr_t kPage = 4096, kHuge = uintptr_t(1) << 21;
  if (p && bytes >= kHuge) {
    const uintptr_t b = (reinterpret_cast<uintptr_t>(p) + kPage - 1) & ~(kPage - 1);
    const uintptr_t e = (reinterpret_cast<uintptr_t>(p) + bytes) & ~(kPage - 1);
    if (e > b) madvise(reinterpret_cast<void*>(b), e - b, MADV_HUGEPAGE);
  }
#endif
  (void)p;
  (void)bytes;
}

DecimatedRows::~DecimatedRows() {
  std::lock_guard<std::mutex> lock(fftwPlannerMutex());
  for (auto& p : plans_) fftw_destroy_plan(p.second);
  if (in_) fftw_free(in_);
  if (out_) fftw_free(out_);
}

void DecimatedRows::band(double a, double omega0, long n_fft, long* lo, long* hi) {
  bandOf(a, omega0, n_fft, lo, hi);
}

long DecimatedRows::divisorAtMost(long n_fft, long d) {
  for (d = std::max(1L, std::min(d, n_fft)); d > 1; --d) {
    if (n_fft % d == 0) return d;
  }
  return 1;
}

long DecimatedRows::bandDecimation(long n_fft, double a, double omega0) {
  long lo = 0, hi = 0;
  band(a, omega0, n_fft, &lo, &hi);
  const long bins = std::max(1L, hi - lo + 1);
  return divisorAtMost(n_fft, n_fft / bins);
}

double DecimatedRows::noiseGain(double a, double omega0, long n_fft) {
  // The Parseval sums' band (|a k - omega0| <= kPowerBandHalfWidth), clipped to 1..N/2.
  long lo = 0, hi = 0;
  bandOf(a, omega0, n_fft, &lo, &hi, kPowerBandHalfWidth);
  if (lo > hi) return 0.0;
  // sum_{k=lo..hi} 4 exp(-(a k - omega0)^2) ~ (4/a) (sqrt(pi)/2) [erf(x_hi) - erf(x_lo)].
  const double x_lo = a * (static_cast<double>(lo) - 0.5) - omega0;
  const double x_hi = a * (static_cast<double>(hi) + 0.5) - omega0;
  const double sqrt_pi = 1.7724538509055160273;
  return 2.0 * sqrt_pi / a * (std::erf(x_hi) - std::erf(x_lo)) / static_cast<double>(n_fft);
}

const std::complex<double>* DecimatedRows::row(const std::complex<double>* spectrum, long n_fft,
                                               double a, double omega0, long D) {
  if (D < 1 || n_fft % D != 0) return nullptr;
  const long L = n_fft / D;
  if (L > capacity_) {
    // The plans stay valid on the new arrays (fftw_malloc's alignment, out of place).
    if (in_) fftw_free(in_);
    if (out_) fftw_free(out_);
    const size_t bytes = sizeof(fftw_complex) * static_cast<size_t>(L);
    in_ = fftw_alloc_complex(static_cast<size_t>(L));
    out_ = fftw_alloc_complex(static_cast<size_t>(L));
    adviseHugePages(in_, bytes);
    adviseHugePages(out_, bytes);
    capacity_ = in_ && out_ ? L : 0;
    if (!capacity_) return nullptr;
  }
  fftw_plan& plan = plans_[L];
  if (!plan) {
    std::lock_guard<std::mutex> lock(fftwPlannerMutex());
    plan = fftw_plan_dft_1d(static_cast<int>(L), in_, out_, FFTW_BACKWARD, FFTW_ESTIMATE);
    if (!plan) {
      plans_.erase(L);
      return nullptr;
    }
  }
  double* c = reinterpret_cast<double*>(in_);
  long lo = 0, hi = 0;
  band(a, omega0, n_fft, &lo, &hi);
  // Positions the band's first L bins do not reach are zeroed; those bins are stored, the
  // rest (when the band is wider than L) added.
  const long bins = std::max(0L, hi - lo + 1), m_lo = lo % L;
  if (bins < L) {
    const long m_end = m_lo + bins;  // one past the last position, before wrapping
    if (m_end <= L) {
      std::memset(c, 0, sizeof(fftw_complex) * static_cast<size_t>(m_lo));
      std::memset(c + 2 * m_end, 0, sizeof(fftw_complex) * static_cast<size_t>(L - m_end));
    } else {
      std::memset(c + 2 * (m_end - L), 0, sizeof(fftw_complex) * static_cast<size_t>(L - bins));
    }
  }
  // C_{k mod L} (+)= Y_k Psi(a k)/N, Psi by MorletCwt::fillRow's recurrence (same values).
  const double scale = 2.0 / static_cast<double>(n_fft);
  const double q = std::exp(-a * a);
  const double* y = reinterpret_cast<const double*>(spectrum);
  long m = m_lo;
  for (long k0 = lo; k0 <= hi; k0 += kRecurrenceBlock) {
    const long k1 = std::min(hi + 1, k0 + kRecurrenceBlock);
    const double x = a * static_cast<double>(k0) - omega0;
    double g = scale * std::exp(-0.5 * x * x);
    double r = std::exp(-a * x - 0.5 * a * a);
    for (long k = k0; k < k1; ++k) {
      if (k - lo < L) {
        c[2 * m] = y[2 * k] * g;
        c[2 * m + 1] = y[2 * k + 1] * g;
      } else {
        c[2 * m] += y[2 * k] * g;
        c[2 * m + 1] += y[2 * k + 1] * g;
      }
      g *= r;
      r *= q;
      if (++m == L) m = 0;
    }
  }
  fftw_execute_dft(plan, in_, out_);
  return reinterpret_cast<const std::complex<double>*>(out_);
}

}  // namespace wavelet_detail
}  // namespace gear_damping_id
