// Morlet-wavelet validation core: see wavelet.hpp for the conventions and contracts.
#include "gear_damping_id/wavelet.hpp"

#include <fftw3.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace gear_damping_id {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Psi(s*w) = 2*exp(-(s*w - omega0)^2/2) is below 1e-16 of its peak when |s*w - omega0| > 8.6
// (exp(-8.6^2/2) = 8.7e-17): those bins are set to zero, not multiplied.
constexpr double kBandHalfWidth = 8.6;
// Zero padding of 8 scales after the record: the wavelet's Gaussian exp(-u^2/2) is exp(-32) =
// 1.3e-14 where it would wrap around the circular convolution.
constexpr double kPadScales = 8.0;
// The Gaussian multiplier is advanced by a two-multiplication recurrence and recomputed with
// exp() every kRecurrenceBlock bins (relative drift < kRecurrenceBlock * 2 eps = 3e-14).
constexpr long kRecurrenceBlock = 64;
constexpr double kMinOmega0 = 1.0, kMaxOmega0 = 1000.0;
// Automatic fit omega0: neighbours leak < kLeakTarget into a mode's row; a warning is given
// when the leakage at the omega0 used exceeds kLeakWarn.
constexpr double kLeakTarget = 1e-3;
constexpr double kLeakWarn = 1e-2;
// Automatic fit omega0 is lowered until xi*omega0 <= kMaxXiOmega0 (sigma*s <= 0.25: the
// wavelet's Gaussian spans a quarter of an envelope time constant), but not below
// kMinFitOmega0 (below 3 the analytic Morlet's cut at zero frequency is no longer negligible:
// Psi(0) = 2 exp(-4.5) = 2 % of its peak).
constexpr double kMaxXiOmega0 = 0.25;
constexpr double kMinFitOmega0 = 3.0;
constexpr long kMinSamples = 64;
// The pruned |W| of a row (MorletCwt::prunedModulus) is used when its band fits in M <= N/16
// bins (at least 16 batched transforms: measured, wider bands gain nothing over the full
// inverse FFT, whose size-M transforms then no longer fit in cache); they take the full path.
constexpr long kMinPrunedBatches = 16;
constexpr long kPrunedChunk = 8192;  // complex values per chunk of batches (128 KiB, in L2)
constexpr double kMeasureTimeLimitS = 5.0;  // FFTW_MEASURE planning cap per plan [s]
constexpr long kMinRegionSamples = 16;

std::mutex& plannerMutex() {
  static std::mutex m;
  return m;
}

// FFTW flags of a planning choice. Sets FFTW's (global) planner time limit for the next plan,
// so call it with plannerMutex() held: kMeasure planning is capped at kMeasureTimeLimitS
// (an unlimited FFTW_MEASURE search for N = 1764000 = 2^5 3^2 5^3 7^2 takes > 5 minutes on the
// reference machine; capped at 5 s its plan is within 7 % of the estimate's speed or better).
unsigned fftwFlags(FftPlanning planning) {
  fftw_set_timelimit(planning == FftPlanning::kMeasure ? kMeasureTimeLimitS : FFTW_NO_TIMELIMIT);
  return planning == FftPlanning::kMeasure ? FFTW_MEASURE : FFTW_ESTIMATE;
}

void setError(std::string* error, const std::string& message) {
  if (error) *error = message;
}

std::string num(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

// |w| of n complex values (interleaved re, im) into out. sqrt(re^2 + im^2): exact to 1 ulp for
// |w| in [1e-150, 1e150]. SSE2 (x86-64 baseline) computes two square roots per instruction;
// plain std::sqrt does not vectorise without -fno-math-errno.
template <typename T>
void modulusOf(const double* w, long n, T* out) {
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
  for (; i < n; ++i) out[i] = static_cast<T>(std::sqrt(w[2 * i] * w[2 * i] + w[2 * i + 1] * w[2 * i + 1]));
}

// out[i] = sqrt(sq[i]) for n non-negative values, two per SSE2 instruction (see modulusOf).
template <typename T>
void sqrtOf(const double* sq, long n, T* out) {
  long i = 0;
#if defined(__SSE2__)
  for (; i + 1 < n; i += 2) {
    alignas(16) double tmp[2];
    _mm_store_pd(tmp, _mm_sqrt_pd(_mm_loadu_pd(sq + i)));
    out[i] = static_cast<T>(tmp[0]);
    out[i + 1] = static_cast<T>(tmp[1]);
  }
#endif
  for (; i < n; ++i) out[i] = static_cast<T>(std::sqrt(sq[i]));
}

// Bins [lo, hi] of the band where Psi(s*w_k) > 1e-16 of its peak, with a = s * 2*pi*fs/N
// (so s*w_k = a*k), clipped to the positive frequencies 1..N/2. lo > hi when empty.
void bandOf(double a, double omega0, long n_fft, long* lo, long* hi) {
  const double k_lo = std::ceil((omega0 - kBandHalfWidth) / a);
  const double k_hi = std::floor((omega0 + kBandHalfWidth) / a);
  *lo = static_cast<long>(std::max(1.0, k_lo));
  *hi = static_cast<long>(std::min(static_cast<double>(n_fft / 2), k_hi));
}

template <typename T>
double median(std::vector<T> v) {
  if (v.empty()) return kNaN;
  const auto mid = v.begin() + static_cast<long>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return static_cast<double>(*mid);
}

}  // namespace

// ------------------------------------------------------------------------------------------
// Free helpers

long fastFftLength(long min_length) {
  if (min_length < 1) return -1;
  if (min_length > (1L << 52)) return -1;
  long best = -1;
  // Enumerate 2^a 3^b 5^c 7^d >= min_length, keep the smallest.
  for (long p7 = 1;; p7 *= 7) {
    for (long p5 = p7;; p5 *= 5) {
      for (long p3 = p5;; p3 *= 3) {
        long v = p3;
        while (v < min_length) v *= 2;
        if (best < 0 || v < best) best = v;
        if (p3 >= min_length) break;
      }
      if (p5 >= min_length) break;
    }
    if (p7 >= min_length) break;
  }
  return best;
}

double morletScale(double frequency_hz, double omega0) {
  return omega0 / (2.0 * kPi * frequency_hz);
}

double morletConeOfInfluence(double frequency_hz, double omega0) {
  return std::sqrt(2.0) * morletScale(frequency_hz, omega0);
}

double morletLeakage(double f_signal_hz, double f_row_hz, double omega0) {
  const double x = omega0 * (f_signal_hz / f_row_hz - 1.0);
  return std::exp(-0.5 * x * x);
}

std::vector<double> logSpacedFrequencies(double f_min_hz, double f_max_hz, int n) {
  std::vector<double> f;
  if (n < 1 || !(f_min_hz > 0.0) || !(f_max_hz >= f_min_hz) || !std::isfinite(f_max_hz)) return f;
  f.resize(static_cast<size_t>(n));
  const double l0 = std::log(f_min_hz), l1 = std::log(f_max_hz);
  for (int i = 0; i < n; ++i) {
    f[static_cast<size_t>(i)] = n == 1 ? f_min_hz : std::exp(l0 + (l1 - l0) * i / (n - 1));
  }
  if (n > 1) f.back() = f_max_hz;
  return f;
}

double ridgeFrequency(const double* frequencies_hz, const double* values, int count) {
  if (count < 3 || !frequencies_hz || !values) return kNaN;
  int m = 0;
  for (int i = 0; i < count; ++i) {
    if (!(values[i] > 0.0) || !std::isfinite(values[i]) || !(frequencies_hz[i] > 0.0)) return kNaN;
    if (values[i] > values[m]) m = i;
  }
  if (m == 0 || m == count - 1) return kNaN;
  const double x0 = std::log(frequencies_hz[m - 1]), x1 = std::log(frequencies_hz[m]),
               x2 = std::log(frequencies_hz[m + 1]);
  const double y0 = std::log(values[m - 1]), y1 = std::log(values[m]), y2 = std::log(values[m + 1]);
  // Vertex of the parabola through three (possibly unevenly spaced) points.
  const double d01 = (y1 - y0) / (x1 - x0), d12 = (y2 - y1) / (x2 - x1);
  const double curv = (d12 - d01) / (x2 - x0);
  if (!(curv < 0.0)) return frequencies_hz[m];
  const double xv = 0.5 * (x0 + x1) - d01 / (2.0 * curv);
  return std::exp(std::min(std::max(xv, x0), x2));
}

// ------------------------------------------------------------------------------------------
// MorletCwt

struct MorletCwt::Fftw {
  // spec: r2c output, N/2+1 bins, kept for all rows. in: the band-limited product (zero outside
  // [band_lo, band_hi]). out: c2c output; its first N doubles also hold the r2c input.
  fftw_complex* spec = nullptr;
  fftw_complex* in = nullptr;
  fftw_complex* out = nullptr;
  fftw_plan r2c = nullptr;
  fftw_plan c2c = nullptr;
  long band_lo = 1, band_hi = 0;
  // Pruned |W| of narrow-band rows (see prunedModulus): divisors of N (ascending), the batch
  // buffer of N values (allocated on first use) and one batched size-M plan per M used.
  std::vector<long> divisors;
  fftw_complex* batch = nullptr;  // one chunk of batches
  std::vector<double> tw;         // twiddle phasors and steps (4 * max band), C squares
  std::map<long, fftw_plan> batch_plans;
  ~Fftw() {
    std::lock_guard<std::mutex> lock(plannerMutex());
    if (r2c) fftw_destroy_plan(r2c);
    if (c2c) fftw_destroy_plan(c2c);
    for (auto& p : batch_plans) fftw_destroy_plan(p.second);
    fftw_free(spec);
    fftw_free(in);
    fftw_free(out);
    fftw_free(batch);
  }
};

MorletCwt::MorletCwt() = default;
MorletCwt::~MorletCwt() = default;
MorletCwt::MorletCwt(MorletCwt&&) noexcept = default;
MorletCwt& MorletCwt::operator=(MorletCwt&&) noexcept = default;

void MorletCwt::release() {
  fftw_.reset();
  n_ = n_fft_ = 0;
  fs_ = mean_ = 0.0;
  has_signal_ = false;
  frequencies_.clear();
  omega0s_.clear();
}

bool MorletCwt::configure(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                          const std::vector<double>& omega0s, FftPlanning planning,
                          std::string* error) {
  release();
  if (n < 2) return setError(error, "MorletCwt: n = " + std::to_string(n) + " must be >= 2"), false;
  if (!(sample_rate > 0.0) || !std::isfinite(sample_rate)) {
    return setError(error, "MorletCwt: sample_rate = " + num(sample_rate) +
                               " Hz must be finite and > 0"),
           false;
  }
  if (omega0s.size() != 1 && omega0s.size() != frequencies_hz.size()) {
    return setError(error, "MorletCwt: omega0s has " + std::to_string(omega0s.size()) +
                               " values; it must have 1 or one per frequency (" +
                               std::to_string(frequencies_hz.size()) + ")"),
           false;
  }
  for (double w : omega0s) {
    if (!(w >= kMinOmega0 && w <= kMaxOmega0)) {
      return setError(error, "MorletCwt: omega0 = " + num(w) + " must be in [1, 1000]"), false;
    }
  }
  const double nyquist = 0.5 * sample_rate;
  double s_max = 0.0;  // [samples]
  for (size_t i = 0; i < frequencies_hz.size(); ++i) {
    const double f = frequencies_hz[i];
    if (!(f > 0.0 && f < nyquist)) {
      return setError(error, "MorletCwt: frequencies[" + std::to_string(i) + "] = " + num(f) +
                                 " Hz must be in (0, sample_rate/2 = " + num(nyquist) + " Hz)"),
             false;
    }
    const double w = omega0s.size() == 1 ? omega0s[0] : omega0s[i];
    s_max = std::max(s_max, morletScale(f, w) * sample_rate);
  }
  const double padded = static_cast<double>(n) + std::ceil(kPadScales * s_max);
  const long n_fft = padded < 4e15 ? fastFftLength(static_cast<long>(padded)) : -1;
  if (n_fft < 0 || n_fft > (1L << 40)) {
    return setError(error, "MorletCwt: padded length for n = " + std::to_string(n) +
                               " and the lowest frequency is too large"),
           false;
  }
  auto f = std::make_unique<Fftw>();
  const size_t nc = static_cast<size_t>(n_fft);
  f->spec = fftw_alloc_complex(nc / 2 + 1);
  f->in = fftw_alloc_complex(nc);
  f->out = fftw_alloc_complex(nc);
  if (!f->spec || !f->in || !f->out) {
    return setError(error, "MorletCwt: out of memory for N = " + std::to_string(n_fft)), false;
  }
  {
    std::lock_guard<std::mutex> lock(plannerMutex());
    const unsigned flags = fftwFlags(planning);
    f->r2c = fftw_plan_dft_r2c_1d(static_cast<int>(n_fft), reinterpret_cast<double*>(f->out),
                                  f->spec, flags);
  }
  if (!f->r2c) return setError(error, "MorletCwt: FFTW could not plan the forward FFT"), false;
  // First touch of every buffer here, not in the first transform (FFTW_MEASURE scribbles on
  // them, so zero them after planning).
  std::memset(f->spec, 0, sizeof(fftw_complex) * (nc / 2 + 1));
  std::memset(f->in, 0, sizeof(fftw_complex) * nc);
  std::memset(f->out, 0, sizeof(fftw_complex) * nc);
  for (long d = 1; d * d <= n_fft; ++d) {
    if (n_fft % d == 0) {
      f->divisors.push_back(d);
      if (d * d != n_fft) f->divisors.push_back(n_fft / d);
    }
  }
  std::sort(f->divisors.begin(), f->divisors.end());
  fftw_ = std::move(f);
  n_ = n;
  n_fft_ = n_fft;
  fs_ = sample_rate;
  planning_ = planning;
  frequencies_ = frequencies_hz;
  omega0s_.assign(frequencies_hz.size(), omega0s.empty() ? 6.0 : omega0s[0]);
  if (omega0s.size() == frequencies_hz.size()) omega0s_ = omega0s;
  return true;
}

bool MorletCwt::setSignal(const double* y, std::string* error) {
  has_signal_ = false;
  if (!configured()) return setError(error, "MorletCwt: not configured"), false;
  if (!y) return setError(error, "MorletCwt: null signal"), false;
  double sum = 0.0;
  for (long j = 0; j < n_; ++j) {
    if (!std::isfinite(y[j])) {
      return setError(error, "MorletCwt: sample " + std::to_string(j) + " is not finite (" +
                                 num(y[j]) + ")"),
             false;
    }
    sum += y[j];
  }
  mean_ = sum / static_cast<double>(n_);
  double* r = reinterpret_cast<double*>(fftw_->out);
  for (long j = 0; j < n_; ++j) r[j] = y[j] - mean_;
  std::memset(r + n_, 0, sizeof(double) * static_cast<size_t>(n_fft_ - n_));
  fftw_execute(fftw_->r2c);
  has_signal_ = true;
  return true;
}

bool MorletCwt::fitsPadding(double frequency_hz, double omega0) const {
  return kPadScales * morletScale(frequency_hz, omega0) * fs_ <=
         static_cast<double>(n_fft_ - n_) + 1e-9;
}

const std::complex<double>* MorletCwt::computeRow(double frequency_hz, double omega0) {
  if (!fillRow(frequency_hz, omega0)) return nullptr;
  fftw_execute(fftw_->c2c);
  return reinterpret_cast<const std::complex<double>*>(fftw_->out);
}

bool MorletCwt::fillRow(double frequency_hz, double omega0) {
  Fftw& f = *fftw_;
  if (!f.c2c) {
    std::lock_guard<std::mutex> lock(plannerMutex());
    const unsigned flags = fftwFlags(planning_);
    // Out-of-place, input preserved (FFTW's default for c2c): only the band changes per row.
    // FFTW_MEASURE overwrites both arrays while planning: zero `in` again afterwards; `out`
    // (which holds the r2c input) is not needed once the spectrum is computed.
    f.c2c = fftw_plan_dft_1d(static_cast<int>(n_fft_), f.in, f.out, FFTW_BACKWARD, flags);
    if (!f.c2c) return false;
    std::memset(f.in, 0, sizeof(fftw_complex) * static_cast<size_t>(n_fft_));
    f.band_lo = 1;
    f.band_hi = 0;
  }
  const double a = omega0 * fs_ / (frequency_hz * static_cast<double>(n_fft_));  // s*w_k = a*k
  long lo = 0, hi = 0;
  bandOf(a, omega0, n_fft_, &lo, &hi);
  // Zero what the previous row left outside the new band.
  if (f.band_lo <= f.band_hi) {
    if (lo > hi) {
      std::memset(f.in + f.band_lo, 0, sizeof(fftw_complex) * size_t(f.band_hi - f.band_lo + 1));
    } else {
      if (f.band_lo < lo) {
        const long e = std::min(f.band_hi, lo - 1);
        std::memset(f.in + f.band_lo, 0, sizeof(fftw_complex) * size_t(e - f.band_lo + 1));
      }
      if (f.band_hi > hi) {
        const long b = std::max(f.band_lo, hi + 1);
        std::memset(f.in + b, 0, sizeof(fftw_complex) * size_t(f.band_hi - b + 1));
      }
    }
  }
  f.band_lo = lo;
  f.band_hi = hi;
  // in_k = Y_k * Psi(a*k) / N (the 1/N normalises FFTW's unnormalised backward transform).
  const double scale = 2.0 / static_cast<double>(n_fft_);
  const double q = std::exp(-a * a);
  const double* y = reinterpret_cast<const double*>(f.spec);
  double* p = reinterpret_cast<double*>(f.in);
  for (long k0 = lo; k0 <= hi; k0 += kRecurrenceBlock) {
    const long k1 = std::min(hi + 1, k0 + kRecurrenceBlock);
    const double x = a * static_cast<double>(k0) - omega0;
    double g = scale * std::exp(-0.5 * x * x);  // Psi(a*k)/N at k
    double r = std::exp(-a * x - 0.5 * a * a);  // g(k+1)/g(k)
    for (long k = k0; k < k1; ++k) {
      p[2 * k] = y[2 * k] * g;
      p[2 * k + 1] = y[2 * k + 1] * g;
      g *= r;
      r *= q;
    }
  }
  return true;
}

// |W| of the row whose band fillRow left in in[lo..hi], without the full inverse FFT.
// With B = hi - lo + 1 nonzero bins, M a divisor of N with M >= B and P = N/M, sample
// j = q*P + p (0 <= p < P, 0 <= q < M) of the inverse DFT is
//   W_j = e^{2 pi i lo j/N} * sum_{k<M} (in_{lo+k} e^{2 pi i k p/N}) e^{2 pi i k q/M},
// i.e. P inverse FFTs of size M of twiddled copies of the band, and |W_j| drops the leading
// phase. Cost ~ N log M + N twiddles instead of N log N. The P batches are processed in
// chunks of C (C*M <= kPrunedChunk values) so twiddling, the FFTs and the transposition into
// time order all stay in cache. Returns false when no divisor makes it worthwhile
// (M > N/kMinPrunedBatches): the caller then uses the full inverse FFT.
template <typename T>
bool MorletCwt::prunedModulus(T* out) {
  Fftw& f = *fftw_;
  const long lo = f.band_lo, hi = f.band_hi;
  if (lo > hi) {
    std::fill(out, out + n_, T(0));
    return true;
  }
  const long B = hi - lo + 1;
  const auto it = std::lower_bound(f.divisors.begin(), f.divisors.end(), B);
  if (it == f.divisors.end() || *it * kMinPrunedBatches > n_fft_) return false;
  const long M = *it, P = n_fft_ / M;
  long C = std::max(1L, std::min(P, kPrunedChunk / M));
  while (P % C != 0) --C;  // chunks of equal size: one plan
  fftw_plan plan = nullptr;
  {
    std::lock_guard<std::mutex> lock(plannerMutex());
    if (!f.batch) {
      // One chunk: C*M <= kPrunedChunk values, or one batch of M <= N/kMinPrunedBatches.
      f.batch = fftw_alloc_complex(
          static_cast<size_t>(std::max(kPrunedChunk, n_fft_ / kMinPrunedBatches)));
      if (!f.batch) return false;
      f.tw.resize(static_cast<size_t>(4 * (n_fft_ / kMinPrunedBatches + 1) + n_fft_));
    }
    auto found = f.batch_plans.find(M);
    if (found == f.batch_plans.end()) {
      // FFTW_ESTIMATE always: up to one plan per row size, each planned in ~1 ms.
      fftw_set_timelimit(FFTW_NO_TIMELIMIT);
      const int m = static_cast<int>(M);
      fftw_plan pl = fftw_plan_many_dft(1, &m, static_cast<int>(C), f.batch, nullptr, 1, m,
                                        f.batch, nullptr, 1, m, FFTW_BACKWARD, FFTW_ESTIMATE);
      if (!pl) return false;
      found = f.batch_plans.emplace(M, pl).first;
    }
    plan = found->second;
  }
  // Twiddles e^{2 pi i k p/N} for k < B, kept per k (structure of arrays: tr, ti) and advanced
  // along p by the per-k step e^{2 pi i k/N} (sr, si): independent per k, so the loop
  // vectorises; re-seeded exactly (integer phase k*p mod N) every kRecurrenceBlock batches.
  double* tr = f.tw.data();
  double* ti = tr + B;
  double* sr = ti + B;
  double* si = sr + B;
  double* sq = si + B;  // C squared moduli
  const double two_pi_over_n = 2.0 * kPi / static_cast<double>(n_fft_);
  for (long k = 0; k < B; ++k) {
    sr[k] = std::cos(two_pi_over_n * static_cast<double>(k));
    si[k] = std::sin(two_pi_over_n * static_cast<double>(k));
  }
  const double* x = reinterpret_cast<const double*>(f.in + lo);
  double* b = reinterpret_cast<double*>(f.batch);
  const long q_end = (n_ + P - 1) / P;  // q with some q*P + p < n
  for (long p0 = 0; p0 < P; p0 += C) {
    for (long c = 0; c < C; ++c) {
      const long p = p0 + c;
      if (p % kRecurrenceBlock == 0) {
        for (long k = 0; k < B; ++k) {
          const double ph = two_pi_over_n * static_cast<double>((k * p) % n_fft_);
          tr[k] = std::cos(ph);
          ti[k] = std::sin(ph);
        }
      }
      double* bc = b + 2 * c * M;
      for (long k = 0; k < B; ++k) {
        const double xr = x[2 * k], xi = x[2 * k + 1], ar = tr[k], ai = ti[k];
        bc[2 * k] = xr * ar - xi * ai;
        bc[2 * k + 1] = xr * ai + xi * ar;
        tr[k] = ar * sr[k] - ai * si[k];
        ti[k] = ar * si[k] + ai * sr[k];
      }
      std::memset(bc + 2 * B, 0, sizeof(fftw_complex) * static_cast<size_t>(M - B));
    }
    fftw_execute(plan);
    // out[q*P + p] = |chunk[(p - p0)*M + q]| (squares gathered, then vector square roots).
    for (long q = 0; q < q_end; ++q) {
      const long j0 = q * P + p0;
      const long ce = std::min(C, n_ - j0);
      for (long c = 0; c < ce; ++c) {
        const double re = b[2 * (c * M + q)], im = b[2 * (c * M + q) + 1];
        sq[c] = re * re + im * im;
      }
      if (ce > 0) sqrtOf(sq, ce, out + j0);
    }
  }
  return true;
}

const std::complex<double>* MorletCwt::row(int i) {
  if (!has_signal_ || i < 0 || i >= rows()) return nullptr;
  return computeRow(frequencies_[static_cast<size_t>(i)], omega0s_[static_cast<size_t>(i)]);
}

const std::complex<double>* MorletCwt::rowAt(double frequency_hz, double omega0) {
  if (!has_signal_ || !(frequency_hz > 0.0 && frequency_hz < 0.5 * fs_)) return nullptr;
  if (!(omega0 >= kMinOmega0 && omega0 <= kMaxOmega0) || !fitsPadding(frequency_hz, omega0)) {
    return nullptr;
  }
  return computeRow(frequency_hz, omega0);
}

template <typename T>
bool MorletCwt::rowModulusImpl(int i, T* out) {
  if (!has_signal_ || i < 0 || i >= rows() || !out) return false;
  if (!fillRow(frequencies_[static_cast<size_t>(i)], omega0s_[static_cast<size_t>(i)])) {
    return false;
  }
  if (pruned_ && prunedModulus(out)) return true;
  fftw_execute(fftw_->c2c);
  modulusOf(reinterpret_cast<const double*>(fftw_->out), n_, out);
  return true;
}

bool MorletCwt::rowModulus(int i, double* out) { return rowModulusImpl(i, out); }
bool MorletCwt::rowModulus(int i, float* out) { return rowModulusImpl(i, out); }

bool MorletCwt::transform(const double* y, std::complex<double>* out, std::string* error) {
  if (!out) return setError(error, "MorletCwt: null output"), false;
  if (!setSignal(y, error)) return false;
  for (int i = 0; i < rows(); ++i) {
    const std::complex<double>* w = row(i);
    if (!w) return setError(error, "MorletCwt: FFTW could not plan the inverse FFT"), false;
    std::memcpy(out + static_cast<size_t>(i) * static_cast<size_t>(n_), w,
                sizeof(std::complex<double>) * static_cast<size_t>(n_));
  }
  return true;
}

namespace {
// Both transformModulus overloads: setSignal, then |W| of every row into out (row-major).
template <typename T>
bool transformModulusInto(MorletCwt* cwt, const double* y, T* out, std::string* error) {
  if (!out) return setError(error, "MorletCwt: null output"), false;
  if (!cwt->setSignal(y, error)) return false;
  for (int i = 0; i < cwt->rows(); ++i) {
    if (!cwt->rowModulus(i, out + static_cast<size_t>(i) * static_cast<size_t>(cwt->size()))) {
      return setError(error, "MorletCwt: FFTW could not plan the inverse FFT"), false;
    }
  }
  return true;
}
}  // namespace

bool MorletCwt::transformModulus(const double* y, double* out, std::string* error) {
  return transformModulusInto(this, y, out, error);
}

bool MorletCwt::transformModulus(const double* y, float* out, std::string* error) {
  return transformModulusInto(this, y, out, error);
}

namespace {
// sum_k weight_k * Psi(a*k)^2 over the band, Psi(x)^2 = 4 exp(-(x - omega0)^2), advanced by the
// same blocked recurrence as the row multiplier. weight(k) is |Y_k|^2 or 1.
template <typename Weight>
double bandSumPsi2(double a, double omega0, long n_fft, Weight weight) {
  long lo = 0, hi = 0;
  bandOf(a, omega0, n_fft, &lo, &hi);
  const double q = std::exp(-2.0 * a * a);
  double sum = 0.0;
  for (long k0 = lo; k0 <= hi; k0 += kRecurrenceBlock) {
    const long k1 = std::min(hi + 1, k0 + kRecurrenceBlock);
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
}  // namespace

double MorletCwt::meanPowerAt(double frequency_hz, double omega0) const {
  if (!has_signal_ || !(frequency_hz > 0.0) || !(omega0 > 0.0)) return kNaN;
  const double a = omega0 * fs_ / (frequency_hz * static_cast<double>(n_fft_));
  const double* y = reinterpret_cast<const double*>(fftw_->spec);
  const double sum = bandSumPsi2(a, omega0, n_fft_, [y](long k) {
    return y[2 * k] * y[2 * k] + y[2 * k + 1] * y[2 * k + 1];
  });
  return sum / (static_cast<double>(n_) * static_cast<double>(n_fft_));
}

double MorletCwt::meanPower(int i) const {
  if (i < 0 || i >= rows()) return kNaN;
  return meanPowerAt(frequencies_[static_cast<size_t>(i)], omega0s_[static_cast<size_t>(i)]);
}

double MorletCwt::noiseGainAt(double frequency_hz, double omega0) const {
  if (!configured() || !(frequency_hz > 0.0) || !(omega0 > 0.0)) return kNaN;
  const double a = omega0 * fs_ / (frequency_hz * static_cast<double>(n_fft_));
  return bandSumPsi2(a, omega0, n_fft_, [](long) { return 1.0; }) / static_cast<double>(n_fft_);
}

const std::complex<double>* MorletCwt::spectrum() const {
  return has_signal_ ? reinterpret_cast<const std::complex<double>*>(fftw_->spec) : nullptr;
}

// ------------------------------------------------------------------------------------------
// Options

std::string WaveletOptions::validate() const {
  auto bad = [](const std::string& field, double v, const std::string& rule) {
    return "WaveletOptions." + field + " = " + num(v) + ": " + rule;
  };
  if (!std::isfinite(f_min) || f_min < 0.0) return bad("f_min", f_min, "must be >= 0 (0 = auto)");
  if (!std::isfinite(f_max) || f_max < 0.0) return bad("f_max", f_max, "must be >= 0 (0 = auto)");
  if (f_min > 0.0 && f_max > 0.0 && !(f_min < f_max)) {
    return bad("f_min", f_min, "must be < f_max = " + num(f_max));
  }
  if (n_scales < 3) return bad("n_scales", n_scales, "must be >= 3");
  for (size_t i = 0; i < frequencies.size(); ++i) {
    const double f = frequencies[i];
    if (!std::isfinite(f) || f <= 0.0) {
      return bad("frequencies[" + std::to_string(i) + "]", f, "must be finite and > 0");
    }
    if (i > 0 && !(f > frequencies[i - 1])) {
      return bad("frequencies[" + std::to_string(i) + "]", f, "must be > the previous value");
    }
  }
  if (!frequencies.empty() && frequencies.size() < 3) {
    return bad("frequencies.size()", static_cast<double>(frequencies.size()),
               "must be 0 (log-spaced grid) or >= 3");
  }
  if (!(omega0 >= 3.0 && omega0 <= 100.0)) return bad("omega0", omega0, "must be in [3, 100]");
  if (!(peak_omega0 >= 3.0 && peak_omega0 <= 100.0)) {
    return bad("peak_omega0", peak_omega0, "must be in [3, 100]");
  }
  if (!(max_fit_omega0 >= 3.0 && max_fit_omega0 <= 100.0)) {
    return bad("max_fit_omega0", max_fit_omega0, "must be in [3, 100]");
  }
  if (!(fit_omega0 == 0.0 || (fit_omega0 >= 3.0 && fit_omega0 <= max_fit_omega0))) {
    return bad("fit_omega0", fit_omega0,
               "must be 0 (auto) or in [3, max_fit_omega0 = " + num(max_fit_omega0) + "]");
  }
  for (size_t i = 0; i < mode_frequencies.size(); ++i) {
    const double f = mode_frequencies[i];
    if (!std::isfinite(f) || f <= 0.0) {
      return bad("mode_frequencies[" + std::to_string(i) + "]", f, "must be finite and > 0");
    }
  }
  if (decay_regions.size() > 1 && decay_regions.size() != mode_frequencies.size()) {
    return bad("decay_regions.size()", static_cast<double>(decay_regions.size()),
               "must be 0, 1 or mode_frequencies.size() = " +
                   std::to_string(mode_frequencies.size()));
  }
  for (size_t i = 0; i < decay_regions.size(); ++i) {
    const auto& r = decay_regions[i];
    const bool automatic = std::isnan(r.first) && std::isnan(r.second);
    if (!automatic && !(std::isfinite(r.first) && std::isfinite(r.second) && r.first < r.second)) {
      return bad("decay_regions[" + std::to_string(i) + "].first", r.first,
                 "must be < .second = " + num(r.second) + ", both finite (or both NaN = auto)");
    }
  }
  if (!(peak_prominence > 0.0 && peak_prominence < 1.0)) {
    return bad("peak_prominence", peak_prominence, "must be in (0, 1)");
  }
  if (!std::isfinite(min_separation_hz) || min_separation_hz < 0.0) {
    return bad("min_separation_hz", min_separation_hz, "must be >= 0 (0 = auto)");
  }
  if (max_modes < 1) return bad("max_modes", max_modes, "must be >= 1");
  if (!(coi_factor >= 1.0) || !std::isfinite(coi_factor)) {
    return bad("coi_factor", coi_factor, "must be finite and >= 1");
  }
  if (!(floor_factor >= 1.0) || !std::isfinite(floor_factor)) {
    return bad("floor_factor", floor_factor, "must be finite and >= 1");
  }
  if (max_scalogram_columns < 0) {
    return bad("max_scalogram_columns", static_cast<double>(max_scalogram_columns),
               "must be >= 0 (0 = every sample)");
  }
  return "";
}

// ------------------------------------------------------------------------------------------
// Analysis

namespace {

struct Peak {
  int index;
  double frequency, amplitude, prominence;
};

// Local maxima of v with their topographic prominence (height above the higher of the lowest
// points between the peak and higher terrain, or the end of the array, on either side).
std::vector<Peak> findPeaks(const std::vector<double>& f, const std::vector<double>& v) {
  std::vector<Peak> peaks;
  const int n = static_cast<int>(v.size());
  for (int i = 1; i + 1 < n; ++i) {
    if (!(v[i] > v[i - 1] && v[i] >= v[i + 1])) continue;
    double left_min = v[i], right_min = v[i];
    for (int j = i - 1; j >= 0 && v[j] <= v[i]; --j) left_min = std::min(left_min, v[j]);
    for (int j = i + 1; j < n && !(v[j] > v[i]); ++j) right_min = std::min(right_min, v[j]);
    peaks.push_back({i, f[static_cast<size_t>(i)], v[i], v[i] - std::max(left_min, right_min)});
  }
  return peaks;
}

// Weighted least-squares line y = a + b*x; returns slope b and weighted R^2.
struct LineFit {
  double slope = kNaN, intercept = kNaN, r2 = kNaN;
};
LineFit fitLine(const double* x, const double* y, const double* w, long n) {
  LineFit out;
  double sw = 0, sx = 0, sy = 0;
  for (long i = 0; i < n; ++i) sw += w[i], sx += w[i] * x[i], sy += w[i] * y[i];
  if (!(sw > 0.0)) return out;
  const double mx = sx / sw, my = sy / sw;
  double sxx = 0, sxy = 0, syy = 0;
  for (long i = 0; i < n; ++i) {
    const double dx = x[i] - mx, dy = y[i] - my;
    sxx += w[i] * dx * dx;
    sxy += w[i] * dx * dy;
    syy += w[i] * dy * dy;
  }
  if (!(sxx > 0.0)) return out;
  out.slope = sxy / sxx;
  out.intercept = my - out.slope * mx;
  double sres = 0;
  for (long i = 0; i < n; ++i) {
    const double r = y[i] - out.intercept - out.slope * x[i];
    sres += w[i] * r * r;
  }
  out.r2 = syy > 0.0 ? 1.0 - sres / syy : 1.0;
  return out;
}

struct RowFit {
  bool ok = false;
  std::string why;
  double sigma = kNaN, xi = kNaN, fd = kNaN, r2 = kNaN, t0 = kNaN, t1 = kNaN;
  double peak = kNaN, floor = kNaN;
};

// Decay region and fits on one row W (n samples at fs), for frequency f, omega0.
RowFit fitRow(const std::complex<double>* w, long n, double fs, double f, double omega0,
              double sigma_guess, const std::pair<double, double>* region, double noise_gain,
              double noise_std, const WaveletOptions& opt, std::vector<double>* env_scratch,
              std::vector<double>* work) {
  RowFit out;
  std::vector<double>& env = *env_scratch;
  env.resize(static_cast<size_t>(n));
  modulusOf(reinterpret_cast<const double*>(w), n, env.data());
  const double dt = 1.0 / fs;
  const double s = morletScale(f, omega0);
  const double coi = std::sqrt(2.0) * s;
  const double t_last = static_cast<double>(n - 1) * dt;
  const long j_peak = static_cast<long>(std::max_element(env.begin(), env.end()) - env.begin());
  out.peak = env[static_cast<size_t>(j_peak)];
  const double lo_coi = opt.coi_factor * coi, hi_coi = t_last - opt.coi_factor * coi;
  // Noise floor (RMS of |W| for noise alone), see analyzeWavelet's documentation.
  const double floor_spec = std::sqrt(noise_gain) * noise_std;
  double floor_env = kNaN;
  {
    const long a = static_cast<long>(std::ceil(std::max(0.0, lo_coi) * fs));
    const long b = static_cast<long>(std::floor(std::max(0.0, hi_coi) * fs));
    if (b > a) {
      std::vector<double>& tmp = *work;
      tmp.assign(env.begin() + a, env.begin() + b + 1);
      floor_env = median(tmp) / std::sqrt(std::log(2.0));
    }
  }
  out.floor = std::isnan(floor_env) ? floor_spec : std::min(floor_spec, floor_env);
  double t0 = 0, t1 = 0;
  if (region) {
    t0 = std::max(0.0, region->first);
    t1 = std::min(t_last, region->second);
    if (!(t1 > t0)) {
      out.why = "decay region [" + num(region->first) + ", " + num(region->second) +
                "] s lies outside the record [0, " + num(t_last) + "] s";
      return out;
    }
  } else {
    if (!(hi_coi > lo_coi)) {
      out.why = "record too short: the cone of influence (" + num(opt.coi_factor) + " x " +
                num(coi) + " s at each end) covers it";
      return out;
    }
    const double t_peak = static_cast<double>(j_peak) * dt;
    const double shift = std::isfinite(sigma_guess) ? std::max(0.0, sigma_guess) * s * s : 0.0;
    t0 = std::max(lo_coi, t_peak + coi) + shift;
    t1 = hi_coi;
    const double limit = opt.floor_factor * out.floor;
    const long j0 = static_cast<long>(std::ceil(t0 * fs));
    const long j1 = static_cast<long>(std::floor(t1 * fs));
    if (j0 <= j1 && j0 < n && env[static_cast<size_t>(j0)] < limit) {
      out.why = "envelope is below " + num(opt.floor_factor) + " x noise floor (" +
                num(out.floor) + ") at the start of the decay region (" + num(t0) + " s)";
      return out;
    }
    for (long j = std::max(0L, j0); j <= j1 && j < n; ++j) {
      if (env[static_cast<size_t>(j)] < limit) {
        t1 = static_cast<double>(j - 1) * dt;
        break;
      }
    }
  }
  out.t0 = t0;
  out.t1 = t1;
  const long j0 = std::max(0L, static_cast<long>(std::ceil(t0 * fs)));
  const long j1 = std::min(n - 1, static_cast<long>(std::floor(t1 * fs)));
  const long m = j1 - j0 + 1;
  if (m < kMinRegionSamples || (!region && (t1 - t0) < s)) {
    out.why = "decay region [" + num(t0) + ", " + num(t1) + "] s is too short (" +
              std::to_string(std::max(0L, m)) + " samples; needs >= " +
              std::to_string(kMinRegionSamples) + " and >= one wavelet scale " + num(s) + " s)";
    return out;
  }
  // Weighted fits: x = t, ln|W| and unwrapped phase, weights |W|^2 / max|W|^2.
  std::vector<double>& buf = *work;
  buf.resize(static_cast<size_t>(4 * m));
  double* x = buf.data();
  double* ly = x + m;
  double* ph = ly + m;
  double* wt = ph + m;
  double emax = 0.0;
  for (long j = j0; j <= j1; ++j) emax = std::max(emax, env[static_cast<size_t>(j)]);
  if (!(emax > 0.0)) {
    out.why = "envelope is zero in the decay region";
    return out;
  }
  double prev = 0.0, offset = 0.0;
  for (long i = 0; i < m; ++i) {
    const long j = j0 + i;
    const double e = env[static_cast<size_t>(j)];
    x[i] = static_cast<double>(j) * dt;
    ly[i] = std::log(std::max(e, 1e-300));
    wt[i] = (e / emax) * (e / emax);
    const double p = std::arg(w[j]);
    if (i > 0) {
      const double d = p - prev;
      if (d > kPi) offset -= 2.0 * kPi;
      if (d < -kPi) offset += 2.0 * kPi;
    }
    prev = p;
    ph[i] = p + offset;
  }
  const LineFit amp = fitLine(x, ly, wt, m);
  const LineFit phase = fitLine(x, ph, wt, m);
  out.sigma = -amp.slope;
  out.r2 = amp.r2;
  out.fd = phase.slope / (2.0 * kPi);
  if (!(out.sigma > 0.0) || !std::isfinite(out.sigma)) {
    out.why = "envelope does not decay in [" + num(t0) + ", " + num(t1) +
              "] s (fitted sigma = " + num(out.sigma) + " 1/s)";
    return out;
  }
  if (!(out.fd > 0.0)) {
    out.why = "ridge phase does not advance (f_d = " + num(out.fd) + " Hz)";
    return out;
  }
  const double wd = 2.0 * kPi * out.fd;
  out.xi = out.sigma / std::sqrt(out.sigma * out.sigma + wd * wd);
  out.ok = true;
  return out;
}

}  // namespace

bool analyzeWavelet(const double* y, long n, double sample_rate, const WaveletOptions& options,
                    WaveletResult* result, std::string* error) {
  if (!result) return setError(error, "analyzeWavelet: null result"), false;
  *result = WaveletResult{};
  const std::string bad = options.validate();
  if (!bad.empty()) return setError(error, bad), false;
  if (!y) return setError(error, "analyzeWavelet: null signal"), false;
  if (n < kMinSamples) {
    return setError(error, "analyzeWavelet: n = " + std::to_string(n) + " samples; at least " +
                               std::to_string(kMinSamples) + " are needed"),
           false;
  }
  if (!(sample_rate > 0.0) || !std::isfinite(sample_rate)) {
    return setError(error, "analyzeWavelet: sample_rate = " + num(sample_rate) +
                               " Hz must be finite and > 0"),
           false;
  }
  for (long j = 0; j < n; ++j) {
    if (!std::isfinite(y[j])) {
      return setError(error, "analyzeWavelet: sample " + std::to_string(j) + " is not finite (" +
                                 num(y[j]) + ")"),
             false;
    }
  }
  const double fs = sample_rate, nyquist = 0.5 * fs;
  const std::string nyq = " the Nyquist frequency sample_rate/2 = " + num(nyquist) + " Hz";
  // Frequency grid.
  std::vector<double> grid = options.frequencies;
  if (grid.empty()) {
    const double f_min = options.f_min > 0.0 ? options.f_min : 10.0 * fs / static_cast<double>(n);
    const double f_max = options.f_max > 0.0 ? options.f_max : 0.4 * fs;
    if (!(f_max < nyquist)) {
      return setError(error, "WaveletOptions.f_max = " + num(f_max) + " Hz must be below" + nyq),
             false;
    }
    if (!(f_min < f_max)) {
      return setError(error, "WaveletOptions.f_min = " + num(f_min) + " Hz (" +
                                 (options.f_min > 0.0 ? "given" : "auto: 10 cycles per record") +
                                 ") must be < f_max = " + num(f_max) + " Hz"),
             false;
    }
    grid = logSpacedFrequencies(f_min, f_max, options.n_scales);
  } else if (!(grid.back() < nyquist)) {
    return setError(error, "WaveletOptions.frequencies.back() = " + num(grid.back()) +
                               " Hz must be below" + nyq),
           false;
  }
  for (size_t i = 0; i < options.mode_frequencies.size(); ++i) {
    if (!(options.mode_frequencies[i] < nyquist)) {
      return setError(error, "WaveletOptions.mode_frequencies[" + std::to_string(i) +
                                 "] = " + num(options.mode_frequencies[i]) + " Hz must be below" +
                                 nyq),
             false;
    }
  }
  const double w0 = options.omega0;
  WaveletResult& res = *result;
  res.frequencies = grid;
  res.omega0 = w0;
  res.coi.resize(grid.size());
  for (size_t i = 0; i < grid.size(); ++i) res.coi[i] = morletConeOfInfluence(grid[i], w0);

  // (1) Spectrum and time-averaged scalogram from one FFT.
  MorletCwt scal;
  if (!scal.configure(n, fs, grid, w0,
                      options.full_scalogram ? options.fft_planning : FftPlanning::kEstimate,
                      error) ||
      !scal.setSignal(y, error)) {
    return false;
  }
  const long N = scal.paddedSize();
  const std::complex<double>* Y = scal.spectrum();
  {
    const long kmax = N / 2;
    res.spectrum_freq.resize(static_cast<size_t>(kmax + 1));
    res.spectrum_power.resize(static_cast<size_t>(kmax + 1));
    std::vector<double> p2(static_cast<size_t>(kmax));
    for (long k = 0; k <= kmax; ++k) {
      const double p = std::norm(Y[k]);
      const bool edge = k == 0 || (N % 2 == 0 && k == kmax);
      res.spectrum_freq[static_cast<size_t>(k)] = static_cast<double>(k) * fs / N;
      res.spectrum_power[static_cast<size_t>(k)] = (edge ? 1.0 : 2.0) * p / (n * fs);
      if (k >= 1) p2[static_cast<size_t>(k - 1)] = p;
    }
    res.noise_std = std::sqrt(median(std::move(p2)) / (static_cast<double>(n) * std::log(2.0)));
  }
  res.scalogram_power.resize(grid.size());
  for (int i = 0; i < scal.rows(); ++i) res.scalogram_power[size_t(i)] = scal.meanPower(i);

  // Full scalogram, block-averaged in time.
  if (options.full_scalogram) {
    const long maxc = options.max_scalogram_columns;
    const long d = (maxc > 0 && n > maxc) ? (n + maxc - 1) / maxc : 1;
    const long cols = (n + d - 1) / d;
    res.scalogram_decimation = d;
    res.modulus.resize(static_cast<Eigen::Index>(grid.size()), cols);
    res.scalogram_times.resize(static_cast<size_t>(cols));
    for (long c = 0; c < cols; ++c) {
      const long e = std::min(n, (c + 1) * d);
      res.scalogram_times[static_cast<size_t>(c)] = 0.5 * static_cast<double>(c * d + e - 1) / fs;
    }
    std::vector<double> row(static_cast<size_t>(n));
    for (int i = 0; i < scal.rows(); ++i) {
      if (!scal.rowModulus(i, row.data())) {
        return setError(error, "analyzeWavelet: FFTW could not plan the inverse FFT"), false;
      }
      for (long c = 0; c < cols; ++c) {
        const long b = c * d, e = std::min(n, b + d);
        double sum = 0.0;
        for (long j = b; j < e; ++j) sum += row[static_cast<size_t>(j)];
        res.modulus(i, c) = static_cast<float>(sum / static_cast<double>(e - b));
      }
    }
  }

  // (2) Modes.
  struct ModeSeed {
    double f_spec, amplitude;
    const std::pair<double, double>* region;
  };
  std::vector<ModeSeed> seeds;
  auto regionFor = [&](size_t i) -> const std::pair<double, double>* {
    if (options.decay_regions.empty()) return nullptr;
    const auto& r = options.decay_regions.size() == 1 ? options.decay_regions[0]
                                                      : options.decay_regions[i];
    return std::isnan(r.first) ? nullptr : &r;
  };
  const double wp = options.peak_omega0;
  {
    // Peak-picking spectrum: time-averaged scalogram at peak_omega0 on a log grid fine enough
    // (relative step <= 1/(4*peak_omega0)) to sample its narrowest peak.
    const double f0 = grid.front(), f1 = grid.back();
    const int m = std::max(options.n_scales,
                           static_cast<int>(std::ceil(std::log(f1 / f0) * 4.0 * wp)) + 1);
    res.peak_freq = logSpacedFrequencies(f0, f1, m);
    res.peak_power.resize(res.peak_freq.size());
    for (size_t i = 0; i < res.peak_freq.size(); ++i) {
      res.peak_power[i] = scal.meanPowerAt(res.peak_freq[i], wp);
    }
  }
  if (!options.mode_frequencies.empty()) {
    for (size_t i = 0; i < options.mode_frequencies.size(); ++i) {
      const double f = options.mode_frequencies[i];
      seeds.push_back({f, std::sqrt(std::max(0.0, scal.meanPowerAt(f, wp))), regionFor(i)});
    }
  } else {
    std::vector<double> amp(res.peak_freq.size());
    for (size_t i = 0; i < amp.size(); ++i) amp[i] = std::sqrt(std::max(0.0, res.peak_power[i]));
    std::vector<Peak> peaks = findPeaks(res.peak_freq, amp);
    double highest = 0.0;
    for (const Peak& p : peaks) highest = std::max(highest, p.amplitude);
    std::vector<Peak> cand;
    for (const Peak& p : peaks) {
      if (p.prominence >= options.peak_prominence * highest && p.amplitude > 0.0) cand.push_back(p);
    }
    std::sort(cand.begin(), cand.end(),
              [](const Peak& a, const Peak& b) { return a.amplitude > b.amplitude; });
    std::vector<Peak> kept;
    for (const Peak& p : cand) {
      bool ok = true;
      for (const Peak& q : kept) {
        const double sep = options.min_separation_hz > 0.0 ? options.min_separation_hz
                                                           : q.frequency / wp;
        if (std::abs(p.frequency - q.frequency) < sep) ok = false;
      }
      if (ok && static_cast<int>(kept.size()) < options.max_modes) kept.push_back(p);
    }
    if (kept.empty()) res.warnings.push_back("no spectral peak found: no mode to fit");
    // Refine on the PSD: largest bin within one wavelet bandwidth, parabola through ln|Y|^2.
    for (const Peak& p : kept) {
      const long kc = std::lround(p.frequency * N / fs);
      const long half = std::max(1L, std::lround(p.frequency / wp * N / fs));
      const long a = std::max(1L, kc - half), b = std::min(N / 2 - 1, kc + half);
      long km = std::max(a, std::min(kc, b));
      for (long k = a; k <= b; ++k) {
        if (std::norm(Y[k]) > std::norm(Y[km])) km = k;
      }
      double f_spec = p.frequency;
      if (km > 1 && km < N / 2 - 1) {
        const double l0 = std::log(std::norm(Y[km - 1]) + 1e-300);
        const double l1 = std::log(std::norm(Y[km]) + 1e-300);
        const double l2 = std::log(std::norm(Y[km + 1]) + 1e-300);
        const double den = l0 - 2.0 * l1 + l2;
        const double delta = den < 0.0 ? std::max(-0.5, std::min(0.5, 0.5 * (l0 - l2) / den)) : 0.0;
        f_spec = (static_cast<double>(km) + delta) * fs / N;
      }
      seeds.push_back({f_spec, p.amplitude, regionFor(0)});
    }
    std::sort(seeds.begin(), seeds.end(),
              [](const ModeSeed& a, const ModeSeed& b) { return a.f_spec < b.f_spec; });
  }
  if (seeds.empty()) return true;

  // (3) omega0 per mode for the fit: need_sep[i] separates mode i from its neighbours.
  const bool auto_w = options.fit_omega0 == 0.0;
  std::vector<double> fit_w(seeds.size()), need_sep(seeds.size(), kMinFitOmega0);
  for (size_t i = 0; i < seeds.size(); ++i) {
    for (size_t j = 0; j < seeds.size(); ++j) {
      if (j == i) continue;
      const double r = std::abs(seeds[j].f_spec / seeds[i].f_spec - 1.0);
      const double ratio = seeds[i].amplitude > 0.0 ? seeds[j].amplitude / seeds[i].amplitude : 1.0;
      const double l = std::log(std::max(ratio, 1e-6) / kLeakTarget);
      if (l > 0.0) need_sep[i] = std::max(need_sep[i], r > 0.0 ? std::sqrt(2.0 * l) / r : 1e9);
    }
    need_sep[i] = std::min(need_sep[i], options.max_fit_omega0);
    fit_w[i] = auto_w ? std::max(w0, need_sep[i]) : options.fit_omega0;
  }
  std::vector<double> fit_f(seeds.size());
  for (size_t i = 0; i < seeds.size(); ++i) fit_f[i] = seeds[i].f_spec;
  MorletCwt fit;
  if (!fit.configure(n, fs, fit_f, fit_w, FftPlanning::kEstimate, error) ||
      !fit.setSignal(y, error)) {
    return false;
  }
  std::vector<double> env, work;
  // Noise estimate from the wavelet row at 0.45*fs (far above the modes for omega0 >= 3: a mode
  // at <= 0.3*fs leaks < exp(-4.5) into it): the median of its modulus outside its COI is the
  // Rayleigh median sqrt(ln 2) * sqrt(gain) * sigma_n for white noise. Skipped when a mode lies
  // within 3 wavelet bandwidths of that row.
  {
    const double f_hf = 0.45 * fs;
    bool clear = true;
    for (const ModeSeed& m : seeds) clear = clear && m.f_spec < f_hf * (1.0 - 3.0 / w0);
    const std::complex<double>* w = clear ? fit.rowAt(f_hf, w0) : nullptr;
    const double edge = options.coi_factor * morletConeOfInfluence(f_hf, w0) * fs;
    const long a = static_cast<long>(std::ceil(edge)), b = n - 1 - a;
    if (w && b - a >= kMinRegionSamples) {
      env.resize(static_cast<size_t>(n));
      modulusOf(reinterpret_cast<const double*>(w), n, env.data());
      work.assign(env.begin() + a, env.begin() + b + 1);
      const double hf = median(work) / std::sqrt(std::log(2.0) * fit.noiseGainAt(f_hf, w0));
      if (hf > 0.0 && hf < res.noise_std) res.noise_std = hf;
    }
  }
  for (size_t i = 0; i < seeds.size(); ++i) {
    const double f = fit_f[i];
    const double sn = res.noise_std;
    auto run = [&](double omega, double sigma_guess) -> RowFit {
      const std::complex<double>* w = fit.rowAt(f, omega);
      if (!w) {
        RowFit r;
        r.why = "could not compute the wavelet row";
        return r;
      }
      RowFit r = fitRow(w, n, fs, f, omega, sigma_guess, seeds[i].region, fit.noiseGainAt(f, omega),
                        sn, options, &env, &work);
      if (r.ok && !seeds[i].region) {
        // Second pass: shift the start by sigma*s^2 now that sigma is known.
        RowFit r2 = fitRow(w, n, fs, f, omega, r.sigma, nullptr, fit.noiseGainAt(f, omega), sn,
                           options, &env, &work);
        if (r2.ok) r = r2;
      }
      return r;
    };
    double omega = fit_w[i];
    RowFit r = run(omega, kNaN);
    if (!r.ok && auto_w && omega > w0) {
      omega = w0;
      r = run(omega, kNaN);
    }
    if (r.ok && auto_w && r.xi * omega > kMaxXiOmega0) {
      // Lower omega0 for time resolution, but not below what separation needs.
      const double lower = std::max(need_sep[i], kMaxXiOmega0 / r.xi);
      if (lower < omega) {
        RowFit r2 = run(lower, r.sigma);
        if (r2.ok) {
          r = r2;
          omega = lower;
        }
      }
    }
    WaveletMode m;
    m.spectrum_frequency_hz = f;
    m.omega0 = omega;
    m.peak_amplitude = r.peak;
    m.noise_floor = r.floor;
    m.t_start = r.t0;
    m.t_end = r.t1;
    if (r.ok) {
      m.frequency_hz = r.fd;
      m.damping_ratio = r.xi;
      m.sigma = r.sigma;
      m.r2 = r.r2;
    } else {
      m.frequency_hz = f;
      m.warning = r.why;
    }
    // Separation warning at the omega0 used.
    double worst = 0.0, f_worst = 0.0;
    for (size_t j = 0; j < seeds.size(); ++j) {
      if (j == i) continue;
      const double ratio = seeds[i].amplitude > 0.0 ? seeds[j].amplitude / seeds[i].amplitude : 1.0;
      const double l = ratio * morletLeakage(seeds[j].f_spec, f, omega);
      if (l > worst) worst = l, f_worst = seeds[j].f_spec;
    }
    if (worst > kLeakWarn) {
      const std::string w = "mode at " + num(f_worst) + " Hz is closer than the wavelet (omega0 = " +
                            num(omega) + ") can separate: it leaks " + num(100.0 * worst) +
                            " % into this mode's envelope";
      m.warning += (m.warning.empty() ? "" : "; ") + w;
    }
    res.modes.push_back(m);
  }
  return true;
}

bool analyzeWavelet(const std::vector<double>& y, double sample_rate,
                    const WaveletOptions& options, WaveletResult* result, std::string* error) {
  return analyzeWavelet(y.data(), static_cast<long>(y.size()), sample_rate, options, result, error);
}

bool analyzeWavelet(const Eigen::VectorXd& y, double sample_rate, const WaveletOptions& options,
                    WaveletResult* result, std::string* error) {
  return analyzeWavelet(y.data(), static_cast<long>(y.size()), sample_rate, options, result, error);
}

// ------------------------------------------------------------------------------------------
// High-level entry point and the integral-method comparison

WaveletResult validateWavelet(const double* y, size_t n, double sample_rate,
                              const WaveletOptions& options) {
  WaveletResult result;
  std::string error;
  if (n > static_cast<size_t>(std::numeric_limits<long>::max())) {
    result.error = "validateWavelet: n = " + std::to_string(n) + " samples is too large";
    return result;
  }
  if (!analyzeWavelet(y, static_cast<long>(n), sample_rate, options, &result, &error)) {
    result = WaveletResult{};
    result.error = error.empty() ? std::string("validateWavelet: analysis failed") : error;
  }
  return result;
}

WaveletResult validateWavelet(const std::vector<double>& y, double sample_rate,
                              const WaveletOptions& options) {
  return validateWavelet(y.data(), y.size(), sample_rate, options);
}

double integralDampingRatio(double C_per_s, double omega0_rad_s) {
  if (!std::isfinite(C_per_s) || !std::isfinite(omega0_rad_s) || !(omega0_rad_s > 0.0)) {
    return kNaN;
  }
  return C_per_s / (2.0 * omega0_rad_s);
}

void attachIntegralDampingRatio(WaveletResult* result, double xi_integral) {
  if (!result) return;
  for (WaveletMode& m : result->modes) m.integral_xi = xi_integral;
}

// ------------------------------------------------------------------------------------------
// CSV export: each writer formats into a std::ostream; the path overloads open the file,
// delegate, and name the path in I/O errors.

namespace {

template <typename Writer>
std::string writeToFile(const std::string& path, const char* what, Writer write) {
  std::ofstream out(path);
  if (!out) return std::string(what) + ": cannot open '" + path + "' for writing";
  const std::string e = write(out);
  if (!e.empty()) return e;
  out.flush();
  if (!out) return std::string(what) + ": write to '" + path + "' failed";
  return "";
}

std::string csvNumber(double v, const char* format) {
  if (std::isnan(v)) return "nan";
  char buf[40];
  std::snprintf(buf, sizeof(buf), format, v);
  return buf;
}

}  // namespace

std::string writeScalogramCsv(const WaveletResult& result, std::ostream& out, long max_columns) {
  const long rows = result.modulus.rows(), cols = result.modulus.cols();
  if (rows == 0 || cols == 0) return "writeScalogramCsv: the result holds no scalogram";
  if (static_cast<size_t>(rows) != result.frequencies.size() ||
      static_cast<size_t>(cols) != result.scalogram_times.size()) {
    return "writeScalogramCsv: inconsistent result (modulus is " + std::to_string(rows) + "x" +
           std::to_string(cols) + ")";
  }
  if (max_columns < 1) {
    return "writeScalogramCsv: max_columns = " + std::to_string(max_columns) + " must be >= 1";
  }
  const long d = cols > max_columns ? (cols + max_columns - 1) / max_columns : 1;
  const long oc = (cols + d - 1) / d;
  out << "# gear_damping Morlet scalogram |W| (omega0 = " << num(result.omega0)
      << "). Row 1: NaN, NaN, times [s]; then per frequency: frequency [Hz], cone-of-influence "
         "half-width [s], |W| per time\n";
  out << "nan,nan";
  for (long c = 0; c < oc; ++c) {
    const long b = c * d, e = std::min(cols, b + d);
    double t = 0.0;
    for (long j = b; j < e; ++j) t += result.scalogram_times[static_cast<size_t>(j)];
    out << ',' << csvNumber(t / static_cast<double>(e - b), "%.9g");
  }
  out << '\n';
  for (long r = 0; r < rows; ++r) {
    out << csvNumber(result.frequencies[static_cast<size_t>(r)], "%.9g") << ','
        << csvNumber(r < static_cast<long>(result.coi.size()) ? result.coi[static_cast<size_t>(r)]
                                                             : kNaN,
                     "%.9g");
    for (long c = 0; c < oc; ++c) {
      const long b = c * d, e = std::min(cols, b + d);
      double v = 0.0;
      for (long j = b; j < e; ++j) v += result.modulus(r, j);
      out << ',' << csvNumber(v / static_cast<double>(e - b), "%.7g");
    }
    out << '\n';
  }
  return out ? "" : "writeScalogramCsv: write failed";
}

std::string writeScalogramCsv(const WaveletResult& result, const std::string& path,
                              long max_columns) {
  return writeToFile(path, "writeScalogramCsv", [&](std::ostream& out) {
    return writeScalogramCsv(result, out, max_columns);
  });
}

std::string writeSpectrumCsv(const WaveletResult& result, std::ostream& out) {
  if (result.spectrum_freq.size() != result.spectrum_power.size() ||
      result.frequencies.size() != result.scalogram_power.size()) {
    return "writeSpectrumCsv: inconsistent result (spectrum and frequency sizes differ)";
  }
  if (result.spectrum_freq.empty() && result.frequencies.empty()) {
    return "writeSpectrumCsv: the result holds no spectrum";
  }
  const double f_top = result.frequencies.empty() ? std::numeric_limits<double>::infinity()
                                                  : result.frequencies.back();
  out << "kind,frequency_hz,power\n";
  for (size_t k = 0; k < result.spectrum_freq.size(); ++k) {
    if (result.spectrum_freq[k] > f_top) break;
    out << "psd," << csvNumber(result.spectrum_freq[k], "%.9g") << ','
        << csvNumber(result.spectrum_power[k], "%.9g") << '\n';
  }
  for (size_t i = 0; i < result.frequencies.size(); ++i) {
    out << "scalogram," << csvNumber(result.frequencies[i], "%.9g") << ','
        << csvNumber(result.scalogram_power[i], "%.9g") << '\n';
  }
  return out ? "" : "writeSpectrumCsv: write failed";
}

std::string writeSpectrumCsv(const WaveletResult& result, const std::string& path) {
  return writeToFile(path, "writeSpectrumCsv",
                     [&](std::ostream& out) { return writeSpectrumCsv(result, out); });
}

std::string writeModesCsv(const WaveletResult& result, std::ostream& out) {
  out << "frequency_hz,spectrum_frequency_hz,damping_ratio,integral_damping_ratio,sigma_per_s,"
         "r2,t_start_s,t_end_s,omega0,peak_amplitude,noise_floor,warning\n";
  for (const WaveletMode& m : result.modes) {
    for (double v : {m.frequency_hz, m.spectrum_frequency_hz, m.damping_ratio, m.integral_xi,
                     m.sigma, m.r2, m.t_start, m.t_end, m.omega0, m.peak_amplitude,
                     m.noise_floor}) {
      out << csvNumber(v, "%.9g") << ',';
    }
    out << '"';
    for (char ch : m.warning) out << (ch == '"' ? "\"\"" : std::string(1, ch));
    out << "\"\n";
  }
  return out ? "" : "writeModesCsv: write failed";
}

std::string writeModesCsv(const WaveletResult& result, const std::string& path) {
  return writeToFile(path, "writeModesCsv",
                     [&](std::ostream& out) { return writeModesCsv(result, out); });
}

}  // namespace gear_damping_id
