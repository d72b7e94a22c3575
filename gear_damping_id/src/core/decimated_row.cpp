// Decimated wavelet rows of the per-mode path: see decimated_row.hpp.
#include "decimated_row.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "gear_sim/simd_clones.hpp"
#include "wavelet_detail.hpp"

namespace gear_damping_id {
namespace wavelet_detail {
std::mutex& fftwPlannerMutex() {
  static std::mutex m;
  return m;
}

unsigned fftwFlags(FftPlanning planning) {
  fftw_set_timelimit(planning == FftPlanning::Measure ? kMeasureTimeLimitS : FFTW_NO_TIMELIMIT);
  return planning == FftPlanning::Measure ? FFTW_MEASURE : FFTW_ESTIMATE;
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
    plan = fftw_plan_dft_1d(static_cast<int>(L), in_, out_, FFTW_BACKWARD, fftwFlags(planning_));
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

LowBand::~LowBand() {
  std::lock_guard<std::mutex> lock(fftwPlannerMutex());
  if (plan_) fftw_destroy_plan(plan_);
  if (dplan_) fftw_destroy_plan(dplan_);
  if (in_) fftw_free(in_);
  if (out_) fftw_free(out_);
  if (din_) fftw_free(din_);
  if (dout_) fftw_free(dout_);
}

bool LowBand::compute(const double* y, long n, double mean, long N, long K, bool exact) {
  if (K < 1 || K > N / 2 + 1) return false;
  if (!exact && decimated(y, n, mean, N, K)) return true;
  D_ = 0;
  return polyphase(y, n, mean, N, K);
}

namespace {
typedef double V4d __attribute__((vector_size(32)));  // a GCC vector: one AVX or two SSE2 registers

// The FIR's outputs out[m] = sum_{q<T} taps[q] buf[mD + q], m < count (T a multiple of 4).
GEAR_FMA_CLONES void firDots(const double* taps, long T, const double* buf, long D, long count,
                             double* out) {
  for (long m = 0; m < count; ++m) {
    const double* b = buf + m * D;
    V4d s0 = {0, 0, 0, 0}, s1 = s0;
    long q = 0;
    for (; q + 8 <= T; q += 8) {
      V4d t0, t1, x0, x1;
      std::memcpy(&t0, taps + q, sizeof(V4d));
      std::memcpy(&t1, taps + q + 4, sizeof(V4d));
      std::memcpy(&x0, b + q, sizeof(V4d));
      std::memcpy(&x1, b + q + 4, sizeof(V4d));
      s0 += t0 * x0;
      s1 += t1 * x1;
    }
    if (q < T) {
      V4d t0, x0;
      std::memcpy(&t0, taps + q, sizeof(V4d));
      std::memcpy(&x0, b + q, sizeof(V4d));
      s0 += t0 * x0;
    }
    s0 += s1;
    out[m] = (s0[0] + s0[1]) + (s0[2] + s0[3]);
  }
}

// H(w_k) = c_0 + sum_{j=1..H} c_j cos(j w_k) (c_j = 2 h_j, j >= 1) for k < K, w_k = 2 pi k/N, by
// Clenshaw's recurrence in x = cos(w_k), four bins in lanes.
GEAR_FMA_CLONES void cosineSums(const double* c, long H, long N, long K, double* out) {
  const double w = 2.0 * kPi / static_cast<double>(N);
  for (long k0 = 0; k0 < K; k0 += 4) {
    V4d x2, x;
    for (int l = 0; l < 4; ++l) x[l] = std::cos(w * static_cast<double>(k0 + l));
    x2 = x + x;
    V4d b1 = {0, 0, 0, 0}, b2 = b1;
    for (long j = H; j >= 1; --j) {
      const V4d b = c[j] + x2 * b1 - b2;
      b2 = b1;
      b1 = b;
    }
    const V4d sum = c[0] + x * b1 - b2;
    for (int l = 0; l < 4 && k0 + l < K; ++l) out[k0 + l] = sum[l];
  }
}
}  // namespace

// The decimation way's factor, filter, gains and transform for (n, N, K), kept between calls.
bool LowBand::designDecimation(long n, long N, long K) {
  if (dplan_ && N == dN_ && K == dK_ && n == dn_) return true;
  long D = 0;
  for (long d = std::min(kMaxDecimation, N / (6 * K)); d >= 3 && D == 0; --d) {
    if (N % d == 0) D = d;
  }
  if (D == 0) return false;
  // Kaiser's rules: transition width delta (the passband edge w_{K-1} to the stopband edge
  // 2 pi/D - w_{K-1}), length (A - 8)/(2.285 delta) + 1, beta = 0.1102 (A - 8.7).
  const double w_p = 2.0 * kPi * static_cast<double>(K - 1) / static_cast<double>(N);
  const double delta = 2.0 * kPi / static_cast<double>(D) - 2.0 * w_p;
  const long H = static_cast<long>(std::ceil((kStopbandDb - 8.0) / (2.285 * delta) / 2.0)) + 1;
  const long Nd = N / D, m_lo = -(H / D), m_hi = (n - 1 + H) / D;
  if (m_hi - m_lo + 1 > Nd) return false;
  const double beta = 0.1102 * (kStopbandDb - 8.7), i0 = std::cyl_bessel_i(0.0, beta);
  std::vector<double> h(static_cast<size_t>(H + 1)), c(static_cast<size_t>(H + 1));
  for (long j = 0; j <= H; ++j) {
    const double r = static_cast<double>(j) / static_cast<double>(H);
    const double win = std::cyl_bessel_i(0.0, beta * std::sqrt(std::max(0.0, 1.0 - r * r))) / i0;
    const double x = kPi * static_cast<double>(j) / static_cast<double>(D);
    h[static_cast<size_t>(j)] =
        (j == 0 ? 1.0 / static_cast<double>(D) : std::sin(x) / (kPi * static_cast<double>(j))) *
        win;
    c[static_cast<size_t>(j)] = (j == 0 ? 1.0 : 2.0) * h[static_cast<size_t>(j)];
  }
  const long T = (2 * H + 1 + 3) / 4 * 4;
  taps_.assign(static_cast<size_t>(T), 0.0);
  for (long q = 0; q <= 2 * H; ++q)
    taps_[static_cast<size_t>(q)] = h[static_cast<size_t>(std::labs(q - H))];
  gain_.resize(static_cast<size_t>(K + 3));
  cosineSums(c.data(), H, N, K, gain_.data());
  for (long k = 0; k < K; ++k)
    gain_[static_cast<size_t>(k)] = static_cast<double>(D) / gain_[static_cast<size_t>(k)];
  buf_.resize(static_cast<size_t>(kFirBlock * D + T));
  {
    std::lock_guard<std::mutex> lock(fftwPlannerMutex());
    if (dplan_) fftw_destroy_plan(dplan_);
    if (din_) fftw_free(din_);
    if (dout_) fftw_free(dout_);
    dplan_ = nullptr;
    dN_ = 0;
    din_ = fftw_alloc_real(static_cast<size_t>(Nd));
    dout_ = fftw_alloc_complex(static_cast<size_t>(Nd / 2 + 1));
    if (!din_ || !dout_) return false;
    dplan_ = fftw_plan_dft_r2c_1d(static_cast<int>(Nd), din_, dout_, fftwFlags(planning_));
    if (!dplan_) return false;
  }
  D_ = D, H_ = H, dN_ = N, dK_ = K, dn_ = n;
  return true;
}

// Outputs m0..m1-1 of the FIR (z_m = sum_j h_j x_{mD-j}, x = y - mean on [0, n), zero outside)
// into din_ (m < 0 at dN_/D_ + m).
void LowBand::filterBlock(const double* y, long n, double mean, long m0, long m1) {
  const long T = static_cast<long>(taps_.size()), t0 = m0 * D_ - H_;
  const long len = (m1 - 1 - m0) * D_ + T;
  double* b = buf_.data();
  for (long i = 0; i < len; ++i) {
    const long t = t0 + i;
    b[i] = t >= 0 && t < n ? y[t] - mean : 0.0;
  }
  const long Nd = dN_ / D_;
  if (m0 >= 0) {
    firDots(taps_.data(), T, b, D_, m1 - m0, din_ + m0);
  } else {
    double out[kFirBlock];
    firDots(taps_.data(), T, b, D_, m1 - m0, out);
    for (long m = m0; m < m1; ++m) din_[m < 0 ? Nd + m : m] = out[m - m0];
  }
}

bool LowBand::decimated(const double* y, long n, double mean, long N, long K) {
  if (!designDecimation(n, N, K)) return false;
  const long Nd = N / D_, m_lo = -(H_ / D_), m_hi = (n - 1 + H_) / D_;
  if (m_hi + 1 < Nd + m_lo) {
    std::memset(din_ + m_hi + 1, 0, sizeof(double) * static_cast<size_t>(Nd + m_lo - m_hi - 1));
  }
  // Blocks never straddle m = 0 except the first, which filterBlock stores in two parts.
  for (long m0 = m_lo; m0 <= m_hi; m0 += kFirBlock) {
    filterBlock(y, n, mean, m0, std::min(m_hi + 1, m0 + kFirBlock));
  }
  fftw_execute(dplan_);
  Y_.resize(static_cast<size_t>(K));
  const double* z = reinterpret_cast<const double*>(dout_);
  for (long k = 0; k < K; ++k) {
    const double g = gain_[static_cast<size_t>(k)];
    Y_[static_cast<size_t>(k)] = std::complex<double>(g * z[2 * k], g * z[2 * k + 1]);
  }
  return true;
}

bool LowBand::polyphase(const double* y, long n, double mean, long N, long K) {
  // The divisor of N in [2K, 3K] with the most factors of 2 (FFTW's cheapest per point here:
  // 28 instructions per point at 70560 = 2^5 3^2 5 7^2 against 33 at 63000 = 2^3 3^2 5^3 7),
  // else the smallest divisor >= 2K.
  long M = N == N_ && K == K_ ? M_ : 0;
  int twos = M > 0 ? 64 : -1;
  for (long m = 2 * K; twos < 64 && m <= std::min(N, 3 * K); ++m) {
    if (N % m != 0) continue;
    const int t = __builtin_ctzl(static_cast<unsigned long>(m));
    if (t > twos) M = m, twos = t;
  }
  if (M == 0) {
    M = 2 * K;
    while (M < N && N % M != 0) ++M;
    if (N % M != 0) M = N;
  }
  const long R = N / M, bins = M / 2 + 1;
  if (M != M_ || R != R_) {
    std::lock_guard<std::mutex> lock(fftwPlannerMutex());
    if (plan_) fftw_destroy_plan(plan_);
    if (in_) fftw_free(in_);
    if (out_) fftw_free(out_);
    plan_ = nullptr;
    M_ = R_ = 0;
    in_ = fftw_alloc_real(static_cast<size_t>(kChunk * M));
    out_ = fftw_alloc_complex(static_cast<size_t>(kChunk * bins));
    if (!in_ || !out_) return false;
    const int m = static_cast<int>(M);
    plan_ = fftw_plan_many_dft_r2c(1, &m, static_cast<int>(kChunk), in_, nullptr, 1, m, out_,
                                   nullptr, 1, static_cast<int>(bins), fftwFlags(planning_));
    if (!plan_) return false;
    // Rows a >= ceil(n/R) stay zero: only rows below are written (per chunk), and the r2c is
    // out of place (FFTW preserves its input). Zeroed after planning: FFTW_MEASURE planning
    // overwrites the arrays.
    std::memset(in_, 0, sizeof(double) * static_cast<size_t>(kChunk * M));
    M_ = M;
    R_ = R;
  }
  N_ = N;
  K_ = K;
  // e^{-2 pi i k/N} per bin (re-seeded every kTwiddleBlock bins) and e^{-2 pi i k v0/N} per
  // chunk's first component.
  const double w_n = -2.0 * kPi / static_cast<double>(N);
  step_.resize(static_cast<size_t>(K));
  for (long k0 = 0; k0 < K; k0 += kTwiddleBlock) {
    const long k1 = std::min(K, k0 + kTwiddleBlock);
    std::complex<double> w = std::polar(1.0, w_n * static_cast<double>(k0));
    const std::complex<double> r = std::polar(1.0, w_n);
    for (long k = k0; k < k1; ++k, w *= r) step_[static_cast<size_t>(k)] = w;
  }
  Y_.assign(static_cast<size_t>(K), std::complex<double>(0.0, 0.0));
  const long rows = std::min(M, (n + R - 1) / R);
  for (long v0 = 0; v0 < R; v0 += kChunk) {
    const long c = std::min(kChunk, R - v0);
    for (long a = 0; a < rows; ++a) {
      const long t0 = a * R + v0;
      for (long j = 0; j < c; ++j) in_[j * M + a] = t0 + j < n ? y[t0 + j] - mean : 0.0;
    }
    fftw_execute(plan_);
    accumulate(v0, c, K, N);
  }
  return true;
}

// Y_k += e^{-2 pi i k v0/N} sum_{j<c} (e^{-2 pi i k/N})^j X_{v0+j}[k] (Horner over j).
void LowBand::accumulate(long v0, long c, long K, long N) {
  const long bins = M_ / 2 + 1;
  const double w_n = -2.0 * kPi / static_cast<double>(N);
  for (long k0 = 0; k0 < K; k0 += kTwiddleBlock) {
    const long k1 = std::min(K, k0 + kTwiddleBlock);
    const double ph = w_n * static_cast<double>((k0 * v0) % N);
    std::complex<double> t = std::polar(1.0, ph);
    const std::complex<double> r = std::polar(1.0, w_n * static_cast<double>(v0));
    for (long k = k0; k < k1; ++k, t *= r) {
      const double* x = reinterpret_cast<const double*>(out_) + 2 * k;
      const std::complex<double> w = step_[static_cast<size_t>(k)];
      double hr = x[2 * bins * (c - 1)], hi = x[2 * bins * (c - 1) + 1];
      for (long j = c - 2; j >= 0; --j) {
        const double u = hr * w.real() - hi * w.imag() + x[2 * bins * j];
        hi = hr * w.imag() + hi * w.real() + x[2 * bins * j + 1];
        hr = u;
      }
      Y_[static_cast<size_t>(k)] += t * std::complex<double>(hr, hi);
    }
  }
}

BlockedRow::~BlockedRow() {
  std::lock_guard<std::mutex> lock(fftwPlannerMutex());
  for (auto& p : plans_) {
    fftw_destroy_plan(p.second.r2c);
    fftw_destroy_plan(p.second.c2c);
  }
  fftw_free(seg_);
  fftw_free(spec_);
  fftw_free(band_);
  fftw_free(out_);
  fftw_free(w_);
}

bool BlockedRow::configure(const double* y, long n, double mean, double s_samples, double omega0) {
  const long K = static_cast<long>(std::ceil(8.0 * s_samples));
  long L = kMinBlock;
  while (L < 8 * (2 * K + 1)) L *= 2;
  if (L > kMaxBlock || n < 1) return false;
  const double a = 2.0 * 3.14159265358979323846 * s_samples / static_cast<double>(L);
  if (std::floor((omega0 + kBandHalfWidth) / a) >= static_cast<double>(L / 2)) return false;
  if (!seg_) {  // the largest block's buffers, once: every plan points into them
    seg_ = fftw_alloc_real(static_cast<size_t>(kMaxBlock));
    spec_ = fftw_alloc_complex(static_cast<size_t>(kMaxBlock / 2 + 1));
    band_ = fftw_alloc_complex(static_cast<size_t>(kMaxBlock));
    out_ = fftw_alloc_complex(static_cast<size_t>(kMaxBlock));
    if (!seg_ || !spec_ || !band_ || !out_) return false;
  }
  Plans& p = plans_[L];
  if (!p.r2c || !p.c2c) {
    std::lock_guard<std::mutex> lock(fftwPlannerMutex());
    if (!p.r2c)
      p.r2c = fftw_plan_dft_r2c_1d(static_cast<int>(L), seg_, spec_, fftwFlags(planning_));
    if (!p.c2c)
      p.c2c =
          fftw_plan_dft_1d(static_cast<int>(L), band_, out_, FFTW_BACKWARD, fftwFlags(planning_));
    if (!p.r2c || !p.c2c) return false;
  }
  if (n > w_cap_) {
    fftw_free(w_);
    w_ = reinterpret_cast<std::complex<double>*>(fftw_alloc_complex(static_cast<size_t>(n)));
    adviseHugePages(w_, sizeof(fftw_complex) * static_cast<size_t>(n));
    w_cap_ = w_ ? n : 0;
    if (!w_) return false;
  }
  if (static_cast<long>(env_.size()) < n) env_.resize(static_cast<size_t>(n));
  plan_ = p;
  y_ = y;
  n_ = n;
  mean_ = mean;
  L_ = L;
  A_ = K;
  H_ = L - 2 * K;
  bandOf(a, omega0, L, &lo_, &hi_);
  psi_.resize(static_cast<size_t>(std::max(0L, hi_ - lo_ + 1)));
  for (long q = lo_; q <= hi_; ++q) {  // MorletCwt's multiplier on L bins (2 Psi / L)
    const double x = a * static_cast<double>(q) - omega0;
    psi_[static_cast<size_t>(q - lo_)] = 2.0 / static_cast<double>(L) * std::exp(-0.5 * x * x);
  }
  std::memset(band_, 0, sizeof(fftw_complex) * static_cast<size_t>(L));
  done_.assign(static_cast<size_t>((n + H_ - 1) / H_), 0);
  return true;
}

void BlockedRow::ensure(long j0, long j1) {
  j0 = std::max(0L, j0);
  j1 = std::min(n_ - 1, j1);
  for (long b = j0 / H_; b <= j1 / H_ && j0 <= j1; ++b) {
    if (!done_[static_cast<size_t>(b)]) computeBlock(b);
  }
}

void BlockedRow::computeBlock(long b) {
  done_[static_cast<size_t>(b)] = 1;
  const long first = b * H_ - A_;  // sample of seg_[0]
  const long i0 = std::max(0L, -first), i1 = std::min(L_, n_ - first);
  for (long i = 0; i < std::min(i0, L_); ++i) seg_[i] = 0.0;
  for (long i = i0; i < i1; ++i) seg_[i] = y_[first + i] - mean_;
  for (long i = std::max(i0, i1); i < L_; ++i) seg_[i] = 0.0;
  fftw_execute_dft_r2c(plan_.r2c, seg_, spec_);
  for (long q = lo_; q <= hi_; ++q) {
    const double g = psi_[static_cast<size_t>(q - lo_)];
    band_[q][0] = spec_[q][0] * g;
    band_[q][1] = spec_[q][1] * g;
  }
  fftw_execute_dft(plan_.c2c, band_, out_);
  const long j0 = b * H_, m = std::min(H_, n_ - j0);
  std::memcpy(reinterpret_cast<double*>(w_ + j0), out_ + A_,
              sizeof(fftw_complex) * static_cast<size_t>(m));
  modulusOf(reinterpret_cast<const double*>(w_ + j0), m, env_.data() + j0);
}

}  // namespace wavelet_detail
}  // namespace gear_damping_id
