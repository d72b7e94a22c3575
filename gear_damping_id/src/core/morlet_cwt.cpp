// Morlet CWT engine: see morlet_cwt.hpp for the conventions and contracts.
#include "gear_damping_id/morlet_cwt.hpp"

#include <fftw3.h>
#if defined(__x86_64__)
#include <immintrin.h>
#endif
#if defined(__linux__)
#include <sys/mman.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <numeric>
#include <thread>
#include <type_traits>

#include "decimated_row.hpp"
#include "wavelet_detail.hpp"

namespace gear_damping_id {
namespace {

using gear_sim::Status;
using wavelet_detail::kNaN;
using wavelet_detail::kPi;
using wavelet_detail::modulusOf;
using wavelet_detail::num;

using wavelet_detail::bandOf;
using wavelet_detail::kBandHalfWidth;
using wavelet_detail::kPowerBandHalfWidth;
// Zero padding of 8 scales after the record: the wavelet's Gaussian exp(-u^2/2) is exp(-32) =
// 1.3e-14 where it would wrap around the circular convolution.
constexpr double kPadScales = 8.0;
using wavelet_detail::kRecurrenceBlock;
// The pruned rows' twiddle phasors are advanced by one complex multiplication per batch and
// re-seeded with sin/cos every kTwiddleSeedBlock batches (drift < 256 * 4 eps = 2.3e-13 of the
// row's peak, inside PrunedComplexRowsEqualTheFullInverseFft's 1e-12; the seeds were 5 % of
// a scalogram's instructions at 64).
constexpr long kTwiddleSeedBlock = 256;
constexpr double kMinOmega0 = 1.0, kMaxOmega0 = 1000.0;
// The pruned |W| of a row (MorletCwt::prunedRow) is used when its band fits in M <= N/16
// bins (at least 16 batched transforms: measured, wider bands gain nothing over the full
// inverse FFT, whose size-M transforms then no longer fit in cache); they take the full path.
constexpr long kMinPrunedBatches = 16;
constexpr long kPrunedChunk = 8192;  // complex values per chunk of batches (128 KiB, in L2)
// Blocked rows (MorletScalogram::Blocks): a row whose wavelet spans K = ceil(8 s) samples either
// side is computed in blocks of L samples, L the smallest power of two >= kMinBlock and >=
// kBlockOverlap * (2K + 1) (at least 7/8 of each block kept), when L <= kMaxBlock and L is at
// most half the row's own FFT length. Measured (CPU time, 1e5 x 200 rows): kMaxBlock 16384
// beat 8192 and 32768, kBlockOverlap 8 beat 4 and 6.
constexpr long kMinBlock = 1024, kMaxBlock = 16384;
constexpr double kBlockOverlap = 8.0;

// Transparent huge pages for a large buffer (wavelet_detail::adviseHugePages).
template <typename P>
P* hugePages(P* p, size_t bytes) {
  wavelet_detail::adviseHugePages(p, bytes);
  return p;
}

std::mutex& plannerMutex() { return wavelet_detail::fftwPlannerMutex(); }

using wavelet_detail::fftwFlags;
using wavelet_detail::kMeasureTimeLimitS;

// |w| of n complex floats (interleaved re, im) into out, four per SSE instruction (computed in
// float: relative error ~1e-7, the precision of the single-precision path).
template <typename T>
void modulusOfFloats(const float* w, long n, T* out) {
  long i = 0;
#if defined(__SSE2__)
  for (; i + 3 < n; i += 4) {
    const __m128 a = _mm_loadu_ps(w + 2 * i), b = _mm_loadu_ps(w + 2 * i + 4);
    const __m128 sa = _mm_mul_ps(a, a), sb = _mm_mul_ps(b, b);
    const __m128 re = _mm_shuffle_ps(sa, sb, _MM_SHUFFLE(2, 0, 2, 0));
    const __m128 im = _mm_shuffle_ps(sa, sb, _MM_SHUFFLE(3, 1, 3, 1));
    alignas(16) float tmp[4];
    _mm_store_ps(tmp, _mm_sqrt_ps(_mm_add_ps(re, im)));
    for (int k = 0; k < 4; ++k) out[i + k] = static_cast<T>(tmp[k]);
  }
#endif
  for (; i < n; ++i)
    out[i] = static_cast<T>(std::sqrt(w[2 * i] * w[2 * i] + w[2 * i + 1] * w[2 * i + 1]));
}

// The element-wise loops below are built for AVX-512 and AVX2 too where the compiler supports it
// (runtime dispatch, GCC target_clones), with FP contraction off: the same operations in the
// same order in every clone, so results do not depend on the clone (no FMA in any of them).
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define GD_CWT_CLONES \
  __attribute__((target_clones("avx512f", "avx2", "default"), optimize("fp-contract=off")))
#else
#define GD_CWT_CLONES
#endif

// bc[k] = x[k] * (tr[k] + i ti[k]) for k < count (interleaved complex x and bc), then the
// twiddles advance one step: t[k] *= (sr[k] + i si[k]) (GD_CWT_CLONES).
GD_CWT_CLONES
void twiddleBand(const double* __restrict x, double* __restrict tr, double* __restrict ti,
                 const double* __restrict sr, const double* __restrict si, double* __restrict bc,
                 long count) {
  for (long k = 0; k < count; ++k) {
    const double xr = x[2 * k], xi = x[2 * k + 1], ar = tr[k], ai = ti[k];
    bc[2 * k] = xr * ar - xi * ai;
    bc[2 * k + 1] = xr * ai + xi * ar;
    tr[k] = ar * sr[k] - ai * si[k];
    ti[k] = ar * si[k] + ai * sr[k];
  }
}

// bc[k] = u[k] * (sr[k] + i si[k]) for k < count (interleaved complex u, bc; distinct arrays),
// and the same in place (u[k] *= ...): the pruned |W|'s band of batch p from batch p-1's.
// GD_CWT_CLONES.
GD_CWT_CLONES
void advanceBand(const double* __restrict u, const double* __restrict sr,
                 const double* __restrict si, double* __restrict bc, long count) {
  for (long k = 0; k < count; ++k) {
    const double ur = u[2 * k], ui = u[2 * k + 1];
    bc[2 * k] = ur * sr[k] - ui * si[k];
    bc[2 * k + 1] = ur * si[k] + ui * sr[k];
  }
}
GD_CWT_CLONES
void advanceBand(double* __restrict u, const double* __restrict sr, const double* __restrict si,
                 long count) {
  for (long k = 0; k < count; ++k) {
    const double ur = u[2 * k], ui = u[2 * k + 1];
    u[2 * k] = ur * sr[k] - ui * si[k];
    u[2 * k + 1] = ur * si[k] + ui * sr[k];
  }
}

// p[k] = x[k] * g[k] for count complex x, p (interleaved) and real g; and w[i] += c[i] for n
// doubles w, floats c: a blocked row's band and its cut's part (MorletScalogram::blockedRow).
// GD_CWT_CLONES.
GD_CWT_CLONES
void bandTimes(const double* __restrict x, const double* __restrict g, double* __restrict p,
               long count) {
  for (long k = 0; k < count; ++k) {
    p[2 * k] = x[2 * k] * g[k];
    p[2 * k + 1] = x[2 * k + 1] * g[k];
  }
}
GD_CWT_CLONES
void addFloats(double* __restrict w, const float* __restrict c, long n) {
  for (long i = 0; i < n; ++i) w[i] += static_cast<double>(c[i]);
}

// out[i] = |w_i| = sqrt(re^2 + im^2) for n complex doubles w (interleaved), bit-identical to
// modulusOf (no FMA; IEEE square root): eight per instruction with AVX-512 or four with AVX2
// where the CPU has it (runtime check), else modulusOf's SSE2.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target("avx2"))) void modulusAvx2(const double* w, long n, double* out) {
  long i = 0;
  for (; i + 3 < n; i += 4) {
    const __m256d a = _mm256_loadu_pd(w + 2 * i), b = _mm256_loadu_pd(w + 2 * i + 4);
    // (|w0|^2, |w2|^2, |w1|^2, |w3|^2), each re^2 + im^2, then in order.
    const __m256d h = _mm256_hadd_pd(_mm256_mul_pd(a, a), _mm256_mul_pd(b, b));
    _mm256_storeu_pd(out + i, _mm256_sqrt_pd(_mm256_permute4x64_pd(h, 0xD8)));
  }
  modulusOf(w + 2 * i, n - i, out + i);
}
// modulusOf compiled for the baseline and not inlined into the wider targets below, where a
// compiler may contract its scalar re*re + im*im into an FMA (AVX-512 implies FMA): the ends of
// runs keep modulusOf's bits.
__attribute__((noinline)) void modulusTail(const double* w, long n, double* out) {
  modulusOf(w, n, out);
}
// Same with AVX-512, eight per instruction: the squares are formed before the shuffle that
// pairs re^2 with im^2, so no compiler can contract them into an FMA (the same bits as
// modulusOf). About half the time of the AVX2 version, whose lane-crossing shuffle limits it.
// out[0, 8) = moduli of the 8 complex values whose (re, im) pairs fill a then b.
__attribute__((target("avx512f"))) inline void modulus8(__m512d a, __m512d b, double* out) {
  const __m512i re = _mm512_set_epi64(14, 12, 10, 8, 6, 4, 2, 0);
  const __m512i im = _mm512_set_epi64(15, 13, 11, 9, 7, 5, 3, 1);
  const __m512d sa = _mm512_mul_pd(a, a), sb = _mm512_mul_pd(b, b);
  const __m512d h =
      _mm512_add_pd(_mm512_permutex2var_pd(sa, re, sb), _mm512_permutex2var_pd(sa, im, sb));
  // The masked form (all lanes): GCC 12's _mm512_sqrt_pd trips -Wmaybe-uninitialized.
  _mm512_storeu_pd(out, _mm512_mask_sqrt_pd(h, static_cast<__mmask8>(0xFF), h));
}
__attribute__((target("avx512f"))) void modulusAvx512(const double* w, long n, double* out) {
  long i = 0;
  for (; i + 7 < n; i += 8) {
    modulus8(_mm512_loadu_pd(w + 2 * i), _mm512_loadu_pd(w + 2 * i + 8), out + i);
  }
  modulusTail(w + 2 * i, n - i, out + i);
}
void modulusRun(const double* w, long n, double* out) {
  static const int level =
      __builtin_cpu_supports("avx512f") ? 2 : (__builtin_cpu_supports("avx2") ? 1 : 0);
  if (level == 2) {
    modulusAvx512(w, n, out);
  } else if (level == 1) {
    modulusAvx2(w, n, out);
  } else {
    modulusOf(w, n, out);
  }
}
#else
void modulusRun(const double* w, long n, double* out) { modulusOf(w, n, out); }
#endif

// out[i] = |w_i + c_i| for n complex doubles w and complex floats c (interleaved): w is w + c
// (addFloats) and then out its modulus (modulusRun), bit for bit. With AVX-512 in one pass
// (a blocked row's block plus the cut's part: one read of each instead of two of w).
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target("avx512f"))) void modulusPlusAvx512(double* w, const float* c, long n,
                                                          double* out) {
  const __mmask8 all = 0xFF;  // masked forms: GCC 12's unmasked ones trip -Wmaybe-uninitialized
  long i = 0;
  for (; i + 7 < n; i += 8) {
    modulus8(_mm512_add_pd(_mm512_loadu_pd(w + 2 * i),
                           _mm512_maskz_cvtps_pd(all, _mm256_loadu_ps(c + 2 * i))),
             _mm512_add_pd(_mm512_loadu_pd(w + 2 * i + 8),
                           _mm512_maskz_cvtps_pd(all, _mm256_loadu_ps(c + 2 * i + 8))),
             out + i);
  }
  addFloats(w + 2 * i, c + 2 * i, 2 * (n - i));
  modulusTail(w + 2 * i, n - i, out + i);
}
void modulusPlusRun(double* w, const float* c, long n, double* out) {
  static const bool avx512 = __builtin_cpu_supports("avx512f");
  if (avx512) {
    modulusPlusAvx512(w, c, n, out);
  } else {
    addFloats(w, c, 2 * n);
    modulusRun(w, n, out);
  }
}
#else
void modulusPlusRun(double* w, const float* c, long n, double* out) {
  addFloats(w, c, 2 * n);
  modulusRun(w, n, out);
}
#endif

// Output of one chunk of a pruned row (MorletCwt::prunedRow): the transforms of batches
// p0..p0+C-1 are o[q*C + c] = W_{q*P + p0 + c}, so each q gives C contiguous samples of the row
// out (n samples; complex W, or |W| as double or float). mod: scratch for C * M moduli.
template <typename T>
void writeChunk(const double* o, long C, long P, long p0, long n, double* mod, T* out) {
  if (p0 >= n) return;
  const long q_hi = (n - p0 + P - 1) / P;  // q with q*P + p0 < n
  if constexpr (std::is_same<T, std::complex<double>>::value) {
    for (long q = 0; q < q_hi; ++q) {
      const long j0 = q * P + p0, ce = std::min(C, n - j0);
      for (long c = 0; c < ce; ++c) out[j0 + c] = {o[2 * (q * C + c)], o[2 * (q * C + c) + 1]};
    }
  } else {
    // The moduli of the whole chunk in one vectorised pass, then runs of C values to their
    // places (single values P apart when C = 1).
    modulusRun(o, q_hi * C, mod);
    if (C == 1) {
      for (long q = 0; q < q_hi; ++q) out[q * P + p0] = static_cast<T>(mod[q]);
      return;
    }
    for (long q = 0; q < q_hi; ++q) {
      const long j0 = q * P + p0, ce = std::min(C, n - j0);
      if constexpr (std::is_same<T, double>::value) {
        std::memcpy(out + j0, mod + q * C, sizeof(double) * static_cast<size_t>(ce));
      } else {
        for (long c = 0; c < ce; ++c) out[j0 + c] = static_cast<T>(mod[q * C + c]);
      }
    }
  }
}

// e^{2 pi i m/N} for integers m in [0, N) from two tables of correctly rounded phasors,
// m = 512 h + l: hi[h] * lo[l] (within ~2 eps of the correctly rounded value). The pruned |W|'s
// twiddle steps and seeds without a sin/cos per bin (they were ~2 % of a scalogram).
class Phasors {
 public:
  // re[k] + i im[k] = e^{2 pi i ((m0 + k*dm) mod N)/N} for k < count.
  void fill(long n_fft, long m0, long dm, long count, double* re, double* im) {
    if (n_ != n_fft) build(n_fft);
    long m = m0 % n_;
    dm %= n_;
    for (long k = 0; k < count; ++k) {
      const double* a = &hi_[2 * static_cast<size_t>(m >> kBits)];
      const double* b = &lo_[2 * static_cast<size_t>(m & kMask)];
      re[k] = a[0] * b[0] - a[1] * b[1];
      im[k] = a[0] * b[1] + a[1] * b[0];
      m += dm;
      if (m >= n_) m -= n_;
    }
  }

 private:
  static constexpr long kBits = 9, kMask = (1L << kBits) - 1;
  void build(long n_fft) {
    n_ = n_fft;
    const double w = 2.0 * kPi / static_cast<double>(n_fft);
    lo_.resize(2 * static_cast<size_t>(kMask + 1));
    hi_.resize(2 * static_cast<size_t>((n_fft >> kBits) + 1));
    for (size_t l = 0; l < lo_.size() / 2; ++l) {
      lo_[2 * l] = std::cos(w * static_cast<double>(l));
      lo_[2 * l + 1] = std::sin(w * static_cast<double>(l));
    }
    for (size_t h = 0; h < hi_.size() / 2; ++h) {
      const double ph = w * static_cast<double>(static_cast<long>(h) << kBits);
      hi_[2 * h] = std::cos(ph);
      hi_[2 * h + 1] = std::sin(ph);
    }
  }
  long n_ = 0;
  std::vector<double> lo_, hi_;
};

// Smallest multiple of `factor` (>= 1) >= min_length (>= 1) whose only prime factors are 2, 3,
// 5 and 7 (factor's among them): fastFftLength (factor 1) and the scalogram's group lengths (8).
long smoothLength(long min_length, long factor) {
  long best = -1;
  // Enumerate factor 2^a 3^b 5^c 7^d >= min_length, keep the smallest.
  for (long p7 = factor;; p7 *= 7) {
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

// Batch length M of the pruned inverse of a band of `band` bins (MorletCwt::prunedRow): the
// smallest divisor of n_fft (divisors ascending) >= band, or -1 when there is none with at least
// kMinPrunedBatches batches (the full inverse FFT is then as fast).
long prunedBatchLength(const std::vector<long>& divisors, long n_fft, long band) {
  const auto it = std::lower_bound(divisors.begin(), divisors.end(), band);
  return it == divisors.end() || *it * kMinPrunedBatches > n_fft ? -1 : *it;
}

}  // namespace

// ------------------------------------------------------------------------------------------
// Free helpers

long fastFftLength(long min_length) {
  if (min_length < 1) return -1;
  if (min_length > (1L << 52)) return -1;
  return smoothLength(min_length, 1);
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

// The FFT buffers of a MorletCwt, sized for `capacity` complex values (at least its padded
// length N), and the state of what they hold. A MorletCwt allocates its own; the row groups of
// a MorletScalogram share one set per thread (sized for the largest group), used in turn, so
// memory does not grow with the number of groups. Indices into `in` are bins (the same for any
// N), so the band bookkeeping carries over from one object to the next.
struct MorletCwt::Buffers {
  long capacity = 0;
  // spec: r2c output, capacity/2+1 bins. in: the band-limited product (zero outside
  // [band_lo, band_hi] once in_clean). out: c2c output; its first N doubles also hold the r2c
  // input.
  fftw_complex* spec = nullptr;
  fftw_complex* in = nullptr;
  fftw_complex* out = nullptr;
  long band_lo = 1, band_hi = 0;
  bool in_clean = false;  // `in` is zero outside [band_lo, band_hi] (over the whole capacity)
  // Pruned |W| (see prunedRow): one chunk of batches, then its transforms (transposed),
  // allocated on first use for 2 * batchCapacity() values; twiddle phasors and steps (4 * max
  // band), C squares.
  fftw_complex* batch = nullptr;
  std::vector<double> tw;
  // Precision::Single: the band rounded to float (in_f, zero outside [band_lo_f, band_hi_f])
  // and the float inverse FFT's output (out_f).
  fftwf_complex* in_f = nullptr;
  fftwf_complex* out_f = nullptr;
  long band_lo_f = 1, band_hi_f = 0;
  long batchCapacity() const { return std::max(kPrunedChunk, capacity / kMinPrunedBatches); }
  ~Buffers() {
    fftw_free(spec);
    fftw_free(in);
    fftw_free(out);
    fftw_free(batch);
    fftwf_free(in_f);
    fftwf_free(out_f);
  }
};

// The plans of a MorletCwt (made for its own padded length N on its Buffers).
struct MorletCwt::Fftw {
  std::shared_ptr<Buffers> buf;
  fftw_plan r2c = nullptr;
  fftw_plan c2c = nullptr;
  // Pruned |W| of narrow-band rows (see prunedRow): divisors of N (ascending) and one batched
  // size-M plan per M used.
  std::vector<long> divisors;
  std::map<long, fftw_plan> batch_plans;
  // Precision::Single: the float inverse FFT (in_f into out_f).
  fftwf_plan c2c_f = nullptr;
  Phasors phasors;  // the pruned |W|'s twiddles
  ~Fftw() {
    std::lock_guard<std::mutex> lock(plannerMutex());
    if (r2c) fftw_destroy_plan(r2c);
    if (c2c) fftw_destroy_plan(c2c);
    for (auto& p : batch_plans) fftw_destroy_plan(p.second);
    if (c2c_f) fftwf_destroy_plan(c2c_f);
  }
};

// Buffers for `capacity` complex values: spec, in and out allocated (not touched: fresh pages
// cost the kernel's zeroing, and a spectrum-only or pruned-rows use never faults most of them
// in), the rest on first use. Null when out of memory.
std::shared_ptr<MorletCwt::Buffers> MorletCwt::makeBuffers(long capacity) {
  auto b = std::make_shared<Buffers>();
  const size_t nc = static_cast<size_t>(capacity);
  b->capacity = capacity;
  b->spec = hugePages(fftw_alloc_complex(nc / 2 + 1), sizeof(fftw_complex) * (nc / 2 + 1));
  b->in = hugePages(fftw_alloc_complex(nc), sizeof(fftw_complex) * nc);
  b->out = hugePages(fftw_alloc_complex(nc), sizeof(fftw_complex) * nc);
  if (!b->spec || !b->in || !b->out) return nullptr;
  return b;
}

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

Status MorletCwt::configure(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                            const std::vector<double>& omega0s, FftPlanning planning) {
  return configureOn(nullptr, n, sample_rate, frequencies_hz, omega0s, planning);
}

namespace {
// n + 8 scales of the widest row [samples], before rounding up to a fast FFT length.
double paddedExtent(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                    const std::vector<double>& omega0s) {
  double s_max = 0.0;  // [samples]
  for (size_t i = 0; i < frequencies_hz.size(); ++i) {
    const double w = omega0s.size() == 1 ? omega0s[0] : omega0s[i];
    s_max = std::max(s_max, morletScale(frequencies_hz[i], w) * sample_rate);
  }
  return static_cast<double>(n) + std::ceil(kPadScales * s_max);
}

// The fast FFT length for a padded extent; -1 when it is beyond any FFT.
long fftLengthFor(double padded) {
  return padded < 4e15 ? fastFftLength(static_cast<long>(padded)) : -1;
}
}  // namespace

long MorletCwt::paddedLength(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                             const std::vector<double>& omega0s) {
  return fftLengthFor(paddedExtent(n, sample_rate, frequencies_hz, omega0s));
}

Status MorletCwt::configureOn(std::shared_ptr<Buffers>* shared, long n, double sample_rate,
                              const std::vector<double>& frequencies_hz,
                              const std::vector<double>& omega0s, FftPlanning planning,
                              long fft_length) {
  release();
  if (n < 2)
    return Status::invalidArgument("MorletCwt: n = " + std::to_string(n) + " must be >= 2", "n");
  if (!(sample_rate > 0.0) || !std::isfinite(sample_rate)) {
    return Status::invalidArgument(
        "MorletCwt: sample_rate = " + num(sample_rate) + " Hz must be finite and > 0",
        "sample_rate");
  }
  if (omega0s.size() != 1 && omega0s.size() != frequencies_hz.size()) {
    return Status::invalidArgument("MorletCwt: omega0s has " + std::to_string(omega0s.size()) +
                                       " values; it must have 1 or one per frequency (" +
                                       std::to_string(frequencies_hz.size()) + ")",
                                   "omega0s");
  }
  for (double w : omega0s) {
    if (!(w >= kMinOmega0 && w <= kMaxOmega0)) {
      return Status::invalidArgument("MorletCwt: omega0 = " + num(w) + " must be in [1, 1000]",
                                     "omega0");
    }
  }
  const double nyquist = 0.5 * sample_rate;
  for (size_t i = 0; i < frequencies_hz.size(); ++i) {
    const double f = frequencies_hz[i];
    if (!(f > 0.0 && f < nyquist)) {
      return Status::invalidArgument(
          "MorletCwt: frequencies[" + std::to_string(i) + "] = " + num(f) +
              " Hz must be in (0, sample_rate/2 = " + num(nyquist) + " Hz)",
          "frequencies");
    }
  }
  const double padded = paddedExtent(n, sample_rate, frequencies_hz, omega0s);
  long n_fft = fftLengthFor(padded);
  if (n_fft > 0 && fft_length > static_cast<long>(padded)) n_fft = fft_length;
  // FFTW's one-dimensional plans take an int length.
  if (n_fft < 0 || n_fft > std::numeric_limits<int>::max()) {
    return Status::resourceLimit("MorletCwt: padded length for n = " + std::to_string(n) +
                                 " and the lowest frequency is too large (" + num(padded) +
                                 " samples; FFTW's transforms take at most 2^31 - 1)");
  }
  auto f = std::make_unique<Fftw>();
  // Shared buffers large enough, or new ones (then shared from here on).
  if (shared && *shared && (*shared)->capacity >= n_fft) {
    f->buf = *shared;
  } else {
    f->buf = makeBuffers(n_fft);
    if (!f->buf) {
      return Status::resourceLimit("MorletCwt: out of memory for N = " + std::to_string(n_fft));
    }
    if (shared) *shared = f->buf;
  }
  {
    std::lock_guard<std::mutex> lock(plannerMutex());
    const unsigned flags = fftwFlags(planning);
    f->r2c = fftw_plan_dft_r2c_1d(static_cast<int>(n_fft), reinterpret_cast<double*>(f->buf->out),
                                  f->buf->spec, flags);
  }
  if (!f->r2c) return Status::internal("MorletCwt: FFTW could not plan the forward FFT");
  // No buffer is touched here: setSignal writes `out`'s first N doubles and `spec`; `in` is
  // written only in each row's band, and zeroed outside it on the first full inverse FFT
  // (in_clean). A spectrum-only or pruned-rows use (the damping fits) never faults in most
  // of the pages (fresh pages cost the kernel's zeroing, ~1/3 of an analysis of 1e6 samples).
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
  return {};
}

Status MorletCwt::setSignal(const double* y) {
  has_signal_ = false;
  if (!configured()) return Status::internal("MorletCwt: not configured");
  double mean = 0.0;
  if (Status st = checkedMean(y, n_, &mean); !st.ok()) return st;
  return setCheckedSignal(y, mean);
}

Status MorletCwt::setCheckedSignal(const double* y, double mean) {
  has_signal_ = false;
  if (!configured()) return Status::internal("MorletCwt: not configured");
  if (!y) return Status::internal("MorletCwt: null signal");
  loadChecked(y, mean);
  return {};
}

Status MorletCwt::setCheckedSpectrum(double mean,
                                     const std::function<void(std::complex<double>*)>& fill) {
  has_signal_ = false;
  if (!configured()) return Status::internal("MorletCwt: not configured");
  mean_ = mean;
  fill(reinterpret_cast<std::complex<double>*>(fftw_->buf->spec));
  has_signal_ = true;
  return {};
}

// Eight partial sums (independent chains: the loop runs at the adder's throughput, not its
// latency) with no test per sample: a sum that is finite had no sample that is not (a NaN or an
// infinity stays in the sum). Otherwise the first non-finite sample is named, or, when every
// sample is finite and only the sum overflowed, the mean is summed from y/n instead.
Status MorletCwt::checkedMean(const double* y, long n, double* mean, const char* who,
                              double* max_abs) {
  if (!y) return Status::internal(std::string(who) + ": null signal");
  double s[8] = {0, 0, 0, 0, 0, 0, 0, 0}, m[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  long j = 0;
  for (; j + 8 <= n; j += 8) {
    for (int q = 0; q < 8; ++q) s[q] += y[j + q], m[q] = std::max(m[q], std::fabs(y[j + q]));
  }
  for (int q = 0; j < n; ++j, ++q) s[q] += y[j], m[q] = std::max(m[q], std::fabs(y[j]));
  const double sum = ((s[0] + s[4]) + (s[1] + s[5])) + ((s[2] + s[6]) + (s[3] + s[7]));
  if (max_abs) *max_abs = *std::max_element(m, m + 8);
  if (std::isfinite(sum)) {
    *mean = sum / static_cast<double>(n);
    return {};
  }
  double scaled = 0.0;
  for (j = 0; j < n; ++j) {
    if (!std::isfinite(y[j])) {
      return Status::invalidInput(std::string(who) + ": sample " + std::to_string(j) +
                                  " is not finite (" + num(y[j]) + ")");
    }
    scaled += y[j] / static_cast<double>(n);
  }
  *mean = scaled;
  return {};
}

void MorletCwt::loadChecked(const double* y, double mean) {
  mean_ = mean;
  double* r = reinterpret_cast<double*>(fftw_->buf->out);
  for (long j = 0; j < n_; ++j) r[j] = y[j] - mean_;
  std::memset(r + n_, 0, sizeof(double) * static_cast<size_t>(n_fft_ - n_));
  fftw_execute(fftw_->r2c);
  has_signal_ = true;
}

bool MorletCwt::fitsPadding(double frequency_hz, double omega0) const {
  return kPadScales * morletScale(frequency_hz, omega0) * fs_ <=
         static_cast<double>(n_fft_ - n_) + 1e-9;
}

const std::complex<double>* MorletCwt::computeRow(double frequency_hz, double omega0) {
  if (!fillRow(frequency_hz, omega0)) return nullptr;
  // The r2c input in `out` is no longer needed once the spectrum is computed.
  auto* w = reinterpret_cast<std::complex<double>*>(fftw_->buf->out);
  if (pruned_ && prunedRow(w)) return w;
  if (!fullInverse()) return nullptr;
  return w;
}

// The full inverse FFT of the band fillRow left in `in` (into `out`); zeroes `in` outside the
// band first if it has not been yet (the buffer is not touched until a row needs it). fillRow
// plans the inverse FFT for rows that need it; a row that was to take the pruned path but could
// not (no memory for its batches) is planned here with FFTW_ESTIMATE, which leaves the band in
// `in` intact. False if FFTW cannot plan.
bool MorletCwt::fullInverse() {
  Fftw& f = *fftw_;
  Buffers& b = *f.buf;
  if (!f.c2c) {
    std::lock_guard<std::mutex> lock(plannerMutex());
    f.c2c = fftw_plan_dft_1d(static_cast<int>(n_fft_), b.in, b.out, FFTW_BACKWARD,
                             fftwFlags(FftPlanning::Estimate));
    if (!f.c2c) return false;
  }
  if (!b.in_clean) {
    double* p = reinterpret_cast<double*>(b.in);
    if (b.band_lo <= b.band_hi) {
      std::fill(p, p + 2 * b.band_lo, 0.0);
      std::fill(p + 2 * (b.band_hi + 1), p + 2 * b.capacity, 0.0);
    } else {
      std::fill(p, p + 2 * b.capacity, 0.0);
    }
    b.in_clean = true;
  }
  fftw_execute(f.c2c);
  return true;
}

bool MorletCwt::fillRow(double frequency_hz, double omega0) {
  Fftw& f = *fftw_;
  Buffers& b = *f.buf;
  const double a = omega0 * fs_ / (frequency_hz * static_cast<double>(n_fft_));  // s*w_k = a*k
  long lo = 0, hi = 0;
  bandOf(a, omega0, n_fft_, &lo, &hi);
  // The double inverse FFT is planned on the first row that needs it (a full-length double row:
  // not prunable, or pruning off), so a group of pruned rows never plans it nor touches `in`.
  const bool pruned_only =
      pruned_ && (lo > hi || prunedBatchLength(f.divisors, n_fft_, hi - lo + 1) > 0);
  if (!setBand(lo, hi, !pruned_only && precision_ == Precision::Double)) return false;
  // in_k = Y_k * Psi(a*k) / N (the 1/N normalises FFTW's unnormalised backward transform).
  const double scale = 2.0 / static_cast<double>(n_fft_);
  const double q = std::exp(-a * a);
  const double* y = reinterpret_cast<const double*>(b.spec);
  double* p = reinterpret_cast<double*>(b.in);
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

// Makes [lo, hi] the band of `in` (zeroing what the previous band left outside it), after
// planning the double inverse FFT if a full-length double row needs it (full_double). False if
// FFTW cannot plan.
bool MorletCwt::setBand(long lo, long hi, bool full_double) {
  Fftw& f = *fftw_;
  Buffers& b = *f.buf;
  if (!f.c2c && full_double) {
    std::lock_guard<std::mutex> lock(plannerMutex());
    const unsigned flags = fftwFlags(planning_);
    // Out-of-place, input preserved (FFTW's default for c2c): only the band changes per row.
    // FFTW_MEASURE overwrites both arrays while planning: `in` is zeroed again before the
    // first full inverse FFT (in_clean); `out` (which holds the r2c input) is not needed once
    // the spectrum is computed.
    f.c2c = fftw_plan_dft_1d(static_cast<int>(n_fft_), b.in, b.out, FFTW_BACKWARD, flags);
    if (!f.c2c) return false;
    b.in_clean = false;
    b.band_lo = 1;
    b.band_hi = 0;
  }
  // Zero what the previous row left outside the new band.
  if (b.band_lo <= b.band_hi) {
    if (lo > hi) {
      std::memset(b.in + b.band_lo, 0, sizeof(fftw_complex) * size_t(b.band_hi - b.band_lo + 1));
    } else {
      if (b.band_lo < lo) {
        const long e = std::min(b.band_hi, lo - 1);
        std::memset(b.in + b.band_lo, 0, sizeof(fftw_complex) * size_t(e - b.band_lo + 1));
      }
      if (b.band_hi > hi) {
        const long k0 = std::max(b.band_lo, hi + 1);
        std::memset(b.in + k0, 0, sizeof(fftw_complex) * size_t(b.band_hi - k0 + 1));
      }
    }
  }
  b.band_lo = lo;
  b.band_hi = hi;
  return true;
}

// The inverse FFT of the loaded spectrum times g[k - lo] over the bins [lo, hi] (zero
// elsewhere), its first n samples into out: MorletScalogram's jump parts. False if FFTW cannot
// plan.
bool MorletCwt::bandRow(long lo, long hi, const double* g, std::complex<double>* out) {
  if (!setBand(lo, hi, true)) return false;
  const double* y = reinterpret_cast<const double*>(fftw_->buf->spec);
  double* p = reinterpret_cast<double*>(fftw_->buf->in);
  for (long k = lo; k <= hi; ++k) {
    p[2 * k] = y[2 * k] * g[k - lo];
    p[2 * k + 1] = y[2 * k + 1] * g[k - lo];
  }
  if (!fullInverse()) return false;
  std::memcpy(static_cast<void*>(out), fftw_->buf->out,
              sizeof(std::complex<double>) * static_cast<size_t>(n_));
  return true;
}

// W (T = std::complex<double>) or |W| (T = double, float) of the row whose band fillRow left in
// in[lo..hi], without the full inverse FFT. With B = hi - lo + 1 nonzero bins, M a divisor of N
// with M >= B and P = N/M, sample j = q*P + p (0 <= p < P, 0 <= q < M) of the inverse DFT is
//   W_j = sum_{k<B} (in_{lo+k} e^{2 pi i (lo+k) p/N}) e^{2 pi i ((lo+k) mod M) q/M},
// i.e. P inverse FFTs of size M of twiddled copies of the band, each bin placed at its index
// modulo M (exact: e^{2 pi i (lo+k) q P/N} = e^{2 pi i (lo+k) q/M}). Cost ~ N log M + N
// twiddles instead of N log N. The P batches are processed in chunks of C (C*M <= kPrunedChunk
// values) so twiddling, the FFTs and the transposition into time order all stay in cache.
// Returns false when no divisor makes it worthwhile (M > N/kMinPrunedBatches): the caller then
// uses the full inverse FFT.
template <typename T>
bool MorletCwt::prunedRow(T* out) {
  Fftw& f = *fftw_;
  Buffers& buf = *f.buf;
  const long lo = buf.band_lo, hi = buf.band_hi;
  if (lo > hi) {
    std::fill(out, out + n_, T(0));
    return true;
  }
  const long B = hi - lo + 1;
  const long M = prunedBatchLength(f.divisors, n_fft_, B);
  if (M < 0) return false;
  const long P = n_fft_ / M;
  long C = std::max(1L, std::min(P, kPrunedChunk / M));
  while (P % C != 0) --C;  // chunks of equal size: one plan
  fftw_plan plan = nullptr;
  fftw_complex*& batch = buf.batch;
  // One chunk: C*M <= kPrunedChunk values, or one batch of M <= N/kMinPrunedBatches; the
  // chunk's transforms go after chunk_capacity values (this object's own, so the plans' arrays
  // keep their alignment whatever the shared buffers' capacity).
  const long chunk_capacity = std::max(kPrunedChunk, n_fft_ / kMinPrunedBatches);
  {
    std::lock_guard<std::mutex> lock(plannerMutex());
    if (!batch) {
      batch = fftw_alloc_complex(static_cast<size_t>(2 * buf.batchCapacity()));
      if (!batch) return false;
    }
    if (buf.tw.empty()) {
      buf.tw.resize(static_cast<size_t>(4 * (buf.capacity / kMinPrunedBatches + 1) + buf.capacity));
    }
    auto& plans = f.batch_plans;
    auto found = plans.find(M);
    if (found == plans.end()) {
      // The object's planning: FFTW_MEASURE times the batch's algorithms (up to one plan per row
      // size, a few ms each: the sizes are small), FFTW_ESTIMATE plans in ~1 ms.
      // howmany = C transforms of size M, out of place: input c at batch[c*M..], output c
      // strided at out[c], out[C + c], ... (transposed: element q of every transform contiguous).
      const int m = static_cast<int>(M);
      const fftw_plan pl = fftw_plan_many_dft(1, &m, static_cast<int>(C), batch, nullptr, 1, m,
                                              batch + chunk_capacity, nullptr, static_cast<int>(C),
                                              1, FFTW_BACKWARD, fftwFlags(planning_));
      if (!pl) return false;
      found = plans.emplace(M, pl).first;
    }
    plan = found->second;
  }
  // Twiddles e^{2 pi i (lo+k) p/N} for k < B, kept per k (structure of arrays: tr, ti) and
  // advanced along p by the per-k step e^{2 pi i (lo+k)/N} (sr, si): independent per k, so the
  // loop vectorises; re-seeded exactly (integer phase (lo+k)*p mod N) every kTwiddleSeedBlock
  // batches. The modulus does not depend on the common phase e^{2 pi i lo j/N}, but keeping it
  // costs nothing and makes the complex row exact.
  double* tr = buf.tw.data();
  double* ti = tr + B;
  double* sr = ti + B;
  double* si = sr + B;
  double* sq = si + B;  // the chunk's moduli (C * M values at most)
  // |W| (kChained): the phasors from tables; complex W: sin/cos per bin.
  constexpr bool kChained = std::is_arithmetic<T>::value;
  const double two_pi_over_n = 2.0 * kPi / static_cast<double>(n_fft_);
  if constexpr (kChained) {
    f.phasors.fill(n_fft_, lo, 1, B, sr, si);
  } else {
    for (long k = 0; k < B; ++k) {
      sr[k] = std::cos(two_pi_over_n * static_cast<double>((lo + k) % n_fft_));
      si[k] = std::sin(two_pi_over_n * static_cast<double>((lo + k) % n_fft_));
    }
  }
  // Bin k of the band goes to index (r0 + k) mod M of each batch: [r0, r0 + B1) then [0, B - B1).
  const long r0 = lo % M, B1 = std::min(B, M - r0);
  const double* x = reinterpret_cast<const double*>(buf.in + lo);
  double* b = reinterpret_cast<double*>(batch);
  const double* o =
      reinterpret_cast<const double*>(batch + chunk_capacity);  // o[q*C + c]: W_{q*P+p0+c}
  // Outside the band's slots every batch is zero: cleared once per row (the out-of-place
  // transforms leave their input as it is).
  for (long c = 0; c < C; ++c) {
    double* bc = b + 2 * c * M;
    if (B1 == B) {
      std::fill(bc, bc + 2 * r0, 0.0);
      std::fill(bc + 2 * (r0 + B), bc + 2 * M, 0.0);
    } else {
      std::fill(bc + 2 * (B - B1), bc + 2 * r0, 0.0);
    }
  }
  // |W|: between seeds, batch p's band is batch p-1's times the step (one complex
  // multiplication per bin instead of two; the same drift bound). W (the fits' complex rows):
  // the band times the twiddles.
  for (long p0 = 0; p0 < P; p0 += C) {
    for (long c = 0; c < C; ++c) {
      const long p = p0 + c;
      double* bc = b + 2 * c * M;
      if (p % kTwiddleSeedBlock == 0 && kChained) {
        f.phasors.fill(n_fft_, (lo % n_fft_) * p, p, B, tr, ti);
      } else if (p % kTwiddleSeedBlock == 0) {
        for (long k = 0; k < B; ++k) {
          const double ph = two_pi_over_n * static_cast<double>(((lo + k) * p) % n_fft_);
          tr[k] = std::cos(ph);
          ti[k] = std::sin(ph);
        }
      } else if constexpr (kChained) {
        if (C == 1) {
          advanceBand(bc + 2 * r0, sr, si, B1);
          advanceBand(bc, sr + B1, si + B1, B - B1);
        } else {
          const double* u = b + 2 * ((c + C - 1) % C) * M;  // batch p-1 (the previous chunk's last)
          advanceBand(u + 2 * r0, sr, si, bc + 2 * r0, B1);
          advanceBand(u, sr + B1, si + B1, bc, B - B1);
        }
        continue;
      }
      twiddleBand(x, tr, ti, sr, si, bc + 2 * r0, B1);
      twiddleBand(x + 2 * B1, tr + B1, ti + B1, sr + B1, si + B1, bc, B - B1);
    }
    fftw_execute(plan);
    writeChunk(o, C, P, p0, n_, sq, out);
  }
  return true;
}

const std::complex<double>* MorletCwt::row(int i) {
  if (!has_signal_ || i < 0 || i >= rows()) return nullptr;
  return computeRow(frequencies_[static_cast<size_t>(i)], omega0s_[static_cast<size_t>(i)]);
}

bool MorletCwt::rowAtAllowed(double frequency_hz, double omega0) const {
  if (!has_signal_ || !(frequency_hz > 0.0 && frequency_hz < 0.5 * fs_)) return false;
  return omega0 >= kMinOmega0 && omega0 <= kMaxOmega0 && fitsPadding(frequency_hz, omega0);
}

const std::complex<double>* MorletCwt::rowAt(double frequency_hz, double omega0) {
  return rowAtAllowed(frequency_hz, omega0) ? computeRow(frequency_hz, omega0) : nullptr;
}

template <typename T>
bool MorletCwt::rowModulusImpl(int i, T* out) {
  if (!has_signal_ || i < 0 || i >= rows() || !out) return false;
  if (!fillRow(frequencies_[static_cast<size_t>(i)], omega0s_[static_cast<size_t>(i)])) {
    return false;
  }
  if (precision_ == Precision::Single) {
    // Pruned rows stay double: their size-M transforms are in cache, where float gains little
    // (the double path also advances the twiddles by table).
    if (pruned_ && prunedRow(out)) return true;
    if (!fullRowSingle()) return false;
    modulusOfFloats(reinterpret_cast<const float*>(fftw_->buf->out_f), n_, out);
    return true;
  }
  if (pruned_ && prunedRow(out)) return true;
  if (!fullInverse()) return false;
  if constexpr (std::is_same<T, double>::value) {
    modulusRun(reinterpret_cast<const double*>(fftw_->buf->out), n_, out);
  } else {
    modulusOf(reinterpret_cast<const double*>(fftw_->buf->out), n_, out);
  }
  return true;
}

// The full inverse FFT of the band fillRow left in `in`, in single precision: the band rounded
// to float into in_f (zero elsewhere; only what the previous row set is cleared), then c2c_f.
bool MorletCwt::fullRowSingle() {
  Fftw& f = *fftw_;
  Buffers& b = *f.buf;
  const size_t nc = static_cast<size_t>(b.capacity);
  if (!f.c2c_f) {
    if (!b.in_f) b.in_f = hugePages(fftwf_alloc_complex(nc), sizeof(fftwf_complex) * nc);
    if (!b.out_f) b.out_f = hugePages(fftwf_alloc_complex(nc), sizeof(fftwf_complex) * nc);
    if (!b.in_f || !b.out_f) return false;
    {
      std::lock_guard<std::mutex> lock(plannerMutex());
      const unsigned flags = fftwFlags(planning_);
      fftwf_set_timelimit(planning_ == FftPlanning::Measure ? kMeasureTimeLimitS
                                                            : FFTW_NO_TIMELIMIT);
      f.c2c_f = fftwf_plan_dft_1d(static_cast<int>(n_fft_), b.in_f, b.out_f, FFTW_BACKWARD, flags);
    }
    if (!f.c2c_f) return false;
    // Planning may have written both arrays (FFTW_MEASURE), of this or another object.
    std::memset(b.in_f, 0, sizeof(fftwf_complex) * nc);
    std::memset(b.out_f, 0, sizeof(fftwf_complex) * nc);
    b.band_lo_f = 1;
    b.band_hi_f = 0;
  }
  float* p = reinterpret_cast<float*>(b.in_f);
  if (b.band_lo_f <= b.band_hi_f) std::fill(p + 2 * b.band_lo_f, p + 2 * (b.band_hi_f + 1), 0.0f);
  const double* x = reinterpret_cast<const double*>(b.in);
  for (long k = 2 * b.band_lo; k < 2 * (b.band_hi + 1); ++k) p[k] = static_cast<float>(x[k]);
  b.band_lo_f = b.band_lo;
  b.band_hi_f = b.band_hi;
  fftwf_execute(f.c2c_f);
  return true;
}

bool MorletCwt::rowModulus(int i, double* out) { return rowModulusImpl(i, out); }
bool MorletCwt::rowModulus(int i, float* out) { return rowModulusImpl(i, out); }

Status MorletCwt::transform(const double* y, std::complex<double>* out) {
  if (!out) return Status::internal("MorletCwt: null output");
  if (Status st = setSignal(y); !st.ok()) return st;
  for (int i = 0; i < rows(); ++i) {
    const std::complex<double>* w = row(i);
    if (!w) return Status::internal("MorletCwt: FFTW could not plan the inverse FFT");
    std::memcpy(out + static_cast<size_t>(i) * static_cast<size_t>(n_), w,
                sizeof(std::complex<double>) * static_cast<size_t>(n_));
  }
  return {};
}

namespace {
// Both transformModulus overloads: setSignal, then |W| of every row into out (row-major).
template <typename T>
Status transformModulusInto(MorletCwt* cwt, const double* y, T* out) {
  if (!out) return Status::internal("MorletCwt: null output");
  if (Status st = cwt->setSignal(y); !st.ok()) return st;
  for (int i = 0; i < cwt->rows(); ++i) {
    if (!cwt->rowModulus(i, out + static_cast<size_t>(i) * static_cast<size_t>(cwt->size()))) {
      return Status::internal("MorletCwt: FFTW could not plan the inverse FFT");
    }
  }
  return {};
}
}  // namespace

Status MorletCwt::transformModulus(const double* y, double* out) {
  return transformModulusInto(this, y, out);
}

Status MorletCwt::transformModulus(const double* y, float* out) {
  return transformModulusInto(this, y, out);
}

namespace {
// sum_k weight_k * Psi(a*k)^2 over the band (wavelet_detail::psi2Sum). weight(k) is |Y_k|^2
// or 1.
template <typename Weight>
double bandSumPsi2(double a, double omega0, long n_fft, Weight weight) {
  long lo = 0, hi = 0;
  bandOf(a, omega0, n_fft, &lo, &hi, kPowerBandHalfWidth);
  return wavelet_detail::psi2Sum(a, omega0, lo, hi, weight);
}
}  // namespace

double MorletCwt::meanPowerAt(double frequency_hz, double omega0) const {
  if (!has_signal_ || !(frequency_hz > 0.0) || !(omega0 > 0.0)) return kNaN;
  const double a = omega0 * fs_ / (frequency_hz * static_cast<double>(n_fft_));
  const double* y = reinterpret_cast<const double*>(fftw_->buf->spec);
  const double sum = bandSumPsi2(
      a, omega0, n_fft_, [y](long k) { return y[2 * k] * y[2 * k] + y[2 * k + 1] * y[2 * k + 1]; });
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
  return has_signal_ ? reinterpret_cast<const std::complex<double>*>(fftw_->buf->spec) : nullptr;
}

// ------------------------------------------------------------------------------------------
// MorletScalogram

// Rows computed in overlapping blocks (overlap-save): a row whose wavelet spans K = ceil(8 s)
// samples either side needs, for the outputs [b*H, b*H + H), the samples [b*H - A, b*H - A + L)
// with A >= K and H = L - 2A: one circular convolution of length L per block gives them with
// the same 8-scale margin as the row's own padding (the wrap-around of the Gaussian at e^-32).
// Per class of rows with the same L, the blocks' r2c spectra are computed once per signal and
// shared by the class's rows and all threads; per row and block, the band times the row's
// Psi(a*k)/L, one inverse FFT of L (in cache) and |W| of the H samples kept.
struct MorletScalogram::Blocks {
  struct Class {
    long L = 0, A = 0, H = 0, nb = 0, stride = 0;  // stride: bins between two blocks' spectra
    double* seg = nullptr;                         // one block's samples (L doubles)
    fftw_complex* spectra = nullptr;               // nb spectra of L/2 + 1 bins
    fftw_plan r2c = nullptr;
  };
  struct Row {
    int row = 0, cls = 0;
    double s = 0.0;           // scale [samples]
    long lo = 0, hi = 0;      // bins of the band
    std::vector<double> psi;  // the block's multiplier over [lo, hi] (see multipliers())
  };
  struct Thread {
    fftw_complex* in = nullptr;  // zero outside [lo, hi]
    fftw_complex* out = nullptr;
    long lo = 1, hi = 0;
    std::vector<fftw_plan> c2c;  // per class
  };
  long n = 0;
  std::vector<Class> classes;
  std::vector<Row> rows;
  std::vector<Thread> threads;
  // The analytic cut (Psi jumps from 0 to Psi(0) = 2 e^{-omega0^2/2} at zero frequency; for
  // omega0 = 6, 1.5e-8 of the peak) rings over the whole record: blocks alone would lose that
  // ringing beyond their margin (measured up to 4.8e-8 of the record's largest |W| at 1e6
  // samples). Its part, Psi(0) G(w) with G = e^{-(sigma w)^2/2} (sigma = the smallest blocked
  // scale [samples]) for w > 0, is transformed once per signal on the lowest group's FFT length
  // N0 (that of one MorletCwt over all rows) and added to every blocked row; the blocks
  // transform the rest, Psi(s w) - Psi(0) G(w), continuous at zero frequency, whose kernel
  // decays within the margin. Off when omega0 > kBandHalfWidth (Psi(0) < e^-37).
  bool cut = false;
  double sigma = 0.0, cut_weight = 0.0;     // cut_weight = Psi(0)
  long n0 = 0, cut_lo = 1, cut_hi = 0;      // N0 and G's bins on it (G > e^-18.4)
  std::vector<double> cut_g;                // G(w_k)/N0 over [cut_lo, cut_hi]
  std::vector<std::complex<double>> cut_w;  // its transform (n samples)
  // Psi(0) times it in float (interleaved): ~1e-8 of the peak, so float rounding moves |W| by
  // ~1e-15 of it; read by every blocked row, so half the memory traffic.
  std::vector<float> cut_f;

  // G's bins on N0 and each row's block multiplier (Psi(s w_k) - Psi(0) G(w_k)) / L over the
  // union of its band and G's bins.
  void multipliers(double omega0) {
    cut = omega0 <= kBandHalfWidth;
    cut_weight = cut ? 2.0 * std::exp(-0.5 * omega0 * omega0) : 0.0;
    const double w_hi = 6.07 / sigma;  // G = e^-18.4 (1e-8)
    if (cut) {
      const double d = 2.0 * kPi / static_cast<double>(n0);
      cut_hi = std::min(n0 / 2, static_cast<long>(std::floor(w_hi / d)));
      for (long k = cut_lo; k <= cut_hi; ++k) {
        const double z = sigma * d * static_cast<double>(k);
        cut_g.push_back(std::exp(-0.5 * z * z) / static_cast<double>(n0));
      }
      cut_w.resize(static_cast<size_t>(n));
      cut_f.resize(2 * static_cast<size_t>(n));
    }
    for (Row& r : rows) {
      const long L = classes[size_t(r.cls)].L;
      const double a = r.s * 2.0 * kPi / static_cast<double>(L);  // s*w_k = a*k
      const double c = sigma * 2.0 * kPi / static_cast<double>(L);
      bandOf(a, omega0, L, &r.lo, &r.hi);
      if (cut) r.hi = std::min(L / 2, std::max(r.hi, static_cast<long>(std::floor(w_hi / c))));
      r.psi.clear();
      for (long k = r.lo; k <= r.hi; ++k) {
        const double x = a * static_cast<double>(k) - omega0, z = c * static_cast<double>(k);
        const double g = cut ? cut_weight * std::exp(-0.5 * z * z) : 0.0;
        r.psi.push_back((2.0 * std::exp(-0.5 * x * x) - g) / static_cast<double>(L));
      }
    }
  }

  // The blocks' spectra of the checked samples y minus their mean (zero outside [0, n)).
  void load(const double* y, double mean) {
    for (Class& c : classes) {
      for (long b = 0; b < c.nb; ++b) {
        const long j0 = b * c.H - c.A;
        const long i0 = std::max(0L, -j0), i1 = std::min(c.L, n - j0);
        std::fill(c.seg, c.seg + i0, 0.0);
        for (long i = i0; i < i1; ++i) c.seg[i] = y[j0 + i] - mean;
        std::fill(c.seg + std::max(i0, i1), c.seg + c.L, 0.0);
        fftw_execute_dft_r2c(c.r2c, c.seg, c.spectra + b * c.stride);
      }
    }
  }
  // Plans the classes' r2c FFTs and the threads' inverse FFTs, allocates their buffers.
  Status plan(FftPlanning planning, int n_threads) {
    long l_max = 0;
    std::lock_guard<std::mutex> lock(plannerMutex());
    for (Class& c : classes) {
      c.H = c.L - 2 * c.A;
      c.nb = (n + c.H - 1) / c.H;
      c.stride = c.L / 2 + 2;  // even: every block's spectrum as aligned as the first
      c.seg = fftw_alloc_real(static_cast<size_t>(c.L));
      c.spectra = fftw_alloc_complex(static_cast<size_t>(c.nb * c.stride));
      if (!c.seg || !c.spectra) return Status::resourceLimit("MorletScalogram: out of memory");
      c.r2c = fftw_plan_dft_r2c_1d(static_cast<int>(c.L), c.seg, c.spectra, fftwFlags(planning));
      if (!c.r2c) return Status::internal("MorletScalogram: FFTW could not plan a block FFT");
      l_max = std::max(l_max, c.L);
    }
    threads.resize(static_cast<size_t>(n_threads));
    for (Thread& t : threads) {
      t.in = fftw_alloc_complex(static_cast<size_t>(l_max));
      t.out = fftw_alloc_complex(static_cast<size_t>(l_max));
      if (!t.in || !t.out) return Status::resourceLimit("MorletScalogram: out of memory");
      for (const Class& c : classes) {
        t.c2c.push_back(fftw_plan_dft_1d(static_cast<int>(c.L), t.in, t.out, FFTW_BACKWARD,
                                         fftwFlags(planning)));
        if (!t.c2c.back()) {
          return Status::internal("MorletScalogram: FFTW could not plan a block FFT");
        }
      }
      std::fill(reinterpret_cast<double*>(t.in), reinterpret_cast<double*>(t.in + l_max), 0.0);
    }
    return {};
  }
  ~Blocks() {
    std::lock_guard<std::mutex> lock(plannerMutex());
    for (Class& c : classes) {
      if (c.r2c) fftw_destroy_plan(c.r2c);
      fftw_free(c.seg);
      fftw_free(c.spectra);
    }
    for (Thread& t : threads) {
      for (fftw_plan p : t.c2c) {
        if (p) fftw_destroy_plan(p);
      }
      fftw_free(t.in);
      fftw_free(t.out);
    }
  }
};

int MorletScalogram::blockedRows() const {
  return blocks_ ? static_cast<int>(blocks_->rows.size()) : 0;
}

// Chooses the blocked rows (marked -2 in own) and plans their blocks.
Status MorletScalogram::configureBlocks(long n, double sample_rate,
                                        const std::vector<double>& frequencies_hz, double omega0,
                                        FftPlanning planning, int threads, std::vector<long>* own) {
  auto bl = std::make_shared<Blocks>();
  bl->n = n;
  std::map<long, int> class_of;  // L -> class
  for (size_t i = 0; i < frequencies_hz.size(); ++i) {
    if ((*own)[i] < 0) continue;
    const double f = frequencies_hz[i], s = morletScale(f, omega0) * sample_rate;  // [samples]
    // A band that reaches the Nyquist frequency is cut there too: that row rings over the whole
    // record and keeps the lowest row's padding.
    if (s * kPi - omega0 < kBandHalfWidth) continue;
    const long K = static_cast<long>(std::ceil(kPadScales * s));
    long L = kMinBlock;
    while (static_cast<double>(L) < kBlockOverlap * static_cast<double>(2 * K + 1)) L *= 2;
    if (L > kMaxBlock || 2 * L > (*own)[i]) continue;
    auto it = class_of.find(L);
    if (it == class_of.end()) {
      it = class_of.emplace(L, static_cast<int>(bl->classes.size())).first;
      bl->classes.emplace_back();
      bl->classes.back().L = L;
    }
    Blocks::Class& c = bl->classes[size_t(it->second)];
    c.A = std::max(c.A, K);
    Blocks::Row r;
    r.row = static_cast<int>(i);
    r.cls = it->second;
    r.s = s;
    bl->sigma = bl->rows.empty() ? s : std::min(bl->sigma, s);
    bl->rows.push_back(std::move(r));
  }
  // At least one row left for the groups: the lowest group's FFT length N0 (that of one
  // MorletCwt over all rows) carries the cut's part.
  bl->n0 = -1;
  for (size_t i = 0; i < own->size(); ++i) {
    const bool blocked = std::any_of(bl->rows.begin(), bl->rows.end(),
                                     [i](const Blocks::Row& r) { return size_t(r.row) == i; });
    if (!blocked) bl->n0 = std::max(bl->n0, (*own)[i]);
  }
  if (bl->rows.empty() || bl->n0 < 0) return {};
  for (const Blocks::Row& r : bl->rows) (*own)[size_t(r.row)] = -2;
  bl->multipliers(omega0);
  if (Status st = bl->plan(planning, threads); !st.ok()) return st;
  blocks_ = std::move(bl);
  return {};
}

// |W| of blocked row b (index into blocks_->rows) on thread `thread` into out (n values).
template <typename T>
void MorletScalogram::blockedRow(int thread, int b, T* out) {
  Blocks& bl = *blocks_;
  const Blocks::Row& r = bl.rows[size_t(b)];
  const Blocks::Class& c = bl.classes[size_t(r.cls)];
  Blocks::Thread& th = bl.threads[size_t(thread)];
  double* in = reinterpret_cast<double*>(th.in);
  if (th.lo <= th.hi) std::fill(in + 2 * th.lo, in + 2 * (th.hi + 1), 0.0);
  th.lo = r.lo;
  th.hi = r.hi;
  double* w = reinterpret_cast<double*>(th.out) + 2 * c.A;
  const long count = r.hi - r.lo + 1;
  const double* psi = r.psi.data();
  for (long q = 0; q < c.nb; ++q) {
    const double* sp = reinterpret_cast<const double*>(c.spectra + q * c.stride) + 2 * r.lo;
    bandTimes(sp, psi, in + 2 * r.lo, count);
    fftw_execute(th.c2c[size_t(r.cls)]);
    const long j0 = q * c.H, m = std::min(c.H, bl.n - j0);
    if constexpr (std::is_same<T, double>::value) {
      if (bl.cut) {
        modulusPlusRun(w, bl.cut_f.data() + 2 * j0, m, out + j0);
      } else {
        modulusRun(w, m, out + j0);
      }
    } else {
      if (bl.cut) addFloats(w, bl.cut_f.data() + 2 * j0, 2 * m);
      modulusOf(w, m, out + j0);
    }
  }
}

Status MorletScalogram::configure(long n, double sample_rate,
                                  const std::vector<double>& frequencies_hz, double omega0,
                                  FftPlanning planning, int threads, Precision precision) {
  n_ = 0;
  frequencies_.clear();
  group_rows_.clear();
  workers_.clear();
  blocks_.reset();
  if (threads < 1 || threads > 256) {
    return Status::invalidArgument(
        "MorletScalogram: threads = " + std::to_string(threads) + " must be in [1, 256]",
        "threads");
  }
  // Each row's own FFT length: its 8-scale padding; rows whose band reaches the Nyquist
  // frequency (a band-limited wavelet, whose cut rings far beyond 8 scales) keep the padding of
  // the lowest row, as in one MorletCwt over all rows. Rows by descending length.
  const size_t m = frequencies_hz.size();
  std::vector<long> own(m, -1);
  double s_max = 0.0;
  for (double f : frequencies_hz) s_max = std::max(s_max, f > 0.0 ? morletScale(f, omega0) : 0.0);
  for (size_t i = 0; i < m; ++i) {
    const double f = frequencies_hz[i];
    if (!(f > 0.0 && f < 0.5 * sample_rate)) continue;  // configure() below names it
    const double s = morletScale(f, omega0);
    const bool at_nyquist = s * kPi * sample_rate - omega0 < kBandHalfWidth;
    const double pad = std::ceil(kPadScales * (at_nyquist ? s_max : s) * sample_rate);
    own[i] = pad < 4e15 ? fastFftLength(n + static_cast<long>(pad)) : -1;
  }
  // Below the lowest row's length N0 (kept: the cut's part and the Nyquist rows use it), a
  // multiple of 8: the smallest 7-smooth length can be odd (165375 = 3^3 5^3 7^2 at 1e5
  // samples), whose r2c FFT took 1.8 ms against 0.47 ms for the next group's even length.
  const long n0 = *std::max_element(own.begin(), own.end());
  for (long& len : own) {
    if (len > 0 && len < n0) len = std::min(n0, smoothLength(len, 8));
  }
  // Blocked rows in either precision (their in-cache double transforms are faster than the
  // float full-length or pruned rows they replace, and more accurate).
  if (Status st = configureBlocks(n, sample_rate, frequencies_hz, omega0, planning, threads, &own);
      !st.ok()) {
    blocks_.reset();
    return st;
  }
  std::vector<int> order(m);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return own[size_t(a)] > own[size_t(b)]; });
  std::vector<std::vector<int>> groups;
  long group_length = 0;
  for (int i : order) {
    if (own[size_t(i)] == -2) continue;  // blocked
    if (groups.empty() || static_cast<double>(group_length) > kGroupLengthRatio * own[size_t(i)]) {
      groups.emplace_back();
      group_length = own[size_t(i)];
    }
    groups.back().push_back(i);
  }
  // One buffer set per thread, shared by its groups (the first, longest group sizes it).
  std::vector<std::vector<MorletCwt>> workers(static_cast<size_t>(threads));
  for (auto& w : workers) {
    std::shared_ptr<MorletCwt::Buffers> buffers;
    for (const auto& g : groups) {
      std::vector<double> f;
      for (int i : g) f.push_back(frequencies_hz[size_t(i)]);
      MorletCwt cwt;
      if (Status st = cwt.configureOn(&buffers, n, sample_rate, f, {omega0}, planning,
                                      own[size_t(g.front())]);
          !st.ok()) {
        return st;
      }
      cwt.setPrecision(precision);
      w.push_back(std::move(cwt));
    }
  }
  n_ = n;
  frequencies_ = frequencies_hz;
  group_rows_ = std::move(groups);
  workers_ = std::move(workers);
  return {};
}

long MorletScalogram::groupLength(int g) const {
  if (workers_.empty() || g < 0 || g >= groups()) return -1;
  return workers_[0][size_t(g)].paddedSize();
}

// Every row of signal y on the worker threads: each row's |W| is written to dest(t, row) (a
// T* of n values) on thread t, then done(t, row, that pointer) is called on the same thread.
template <typename T, typename Dest, typename Done>
Status MorletScalogram::runRows(const double* y, Dest dest, Done done) {
  if (workers_.empty()) return Status::internal("MorletScalogram: not configured");
  // Work items (group, local row), dealt round-robin over the threads; each thread transforms
  // the signal once per group it has rows in.
  std::vector<std::pair<int, int>> items;
  for (int g = 0; g < groups(); ++g) {
    for (int k = 0; k < static_cast<int>(group_rows_[size_t(g)].size()); ++k) {
      items.push_back({g, k});
    }
  }
  for (int b = 0; b < blockedRows(); ++b) items.push_back({-1, b});
  // The samples are checked and their mean computed once (as MorletCwt::setSignal does), not
  // once per group and thread.
  double mean = 0.0;
  if (Status st = MorletCwt::checkedMean(y, n_, &mean); !st.ok()) return st;
  bool group0_loaded = false;  // thread 0's first group holds the signal's spectrum already
  if (blocks_) {
    Blocks& bl = *blocks_;
    if (bl.cut) {
      MorletCwt& lowest = workers_[0][0];
      lowest.loadChecked(y, mean);
      if (!lowest.bandRow(bl.cut_lo, bl.cut_hi, bl.cut_g.data(), bl.cut_w.data())) {
        return Status::internal("MorletScalogram: FFTW could not plan the inverse FFT");
      }
      group0_loaded = true;
      const double* w = reinterpret_cast<const double*>(bl.cut_w.data());
      for (size_t i = 0; i < bl.cut_f.size(); ++i) {
        bl.cut_f[i] = static_cast<float>(bl.cut_weight * w[i]);
      }
    }
    blocks_->load(y, mean);
  }
  const int nt = threads();
  std::vector<Status> errors(static_cast<size_t>(nt));
  auto work = [&](int t) {
    std::vector<MorletCwt>& cwts = workers_[size_t(t)];
    // The thread's groups share one buffer set: the signal is loaded (its spectrum computed)
    // whenever the group changes; items come in group order, so once per group.
    int loaded = t == 0 && group0_loaded ? 0 : -1;
    for (size_t it = static_cast<size_t>(t); it < items.size(); it += static_cast<size_t>(nt)) {
      const int g = items[it].first, k = items[it].second;
      if (g < 0) {
        const int row = blocks_->rows[size_t(k)].row;
        T* d = dest(t, row);
        blockedRow(t, k, d);
        done(t, row, d);
        continue;
      }
      if (g != loaded) {
        cwts[size_t(g)].loadChecked(y, mean);
        loaded = g;
      }
      const int row = group_rows_[size_t(g)][size_t(k)];
      T* d = dest(t, row);
      if (!cwts[size_t(g)].rowModulus(k, d)) {
        errors[size_t(t)] =
            Status::internal("MorletScalogram: FFTW could not plan the inverse FFT");
        return;
      }
      done(t, row, d);
    }
  };
  if (nt == 1) {
    work(0);
  } else {
    std::vector<std::thread> pool;
    for (int t = 0; t < nt; ++t) pool.emplace_back(work, t);
    for (auto& th : pool) th.join();
  }
  for (const Status& e : errors) {
    if (!e.ok()) return e;
  }
  return {};
}

template <typename T>
Status MorletScalogram::modulusImpl(const double* y, T* out) {
  if (!out) return Status::internal("MorletScalogram: null output");
  const size_t n = static_cast<size_t>(n_);
  return runRows<T>(
      y, [&](int, int row) { return out + static_cast<size_t>(row) * n; },
      [](int, int, const T*) {});
}

Status MorletScalogram::forEachRow(const double* y,
                                   const std::function<void(int, const double*)>& sink) {
  // One row buffer per thread, kept between calls (fresh pages cost the kernel's zeroing).
  row_buffers_.resize(static_cast<size_t>(std::max(1, threads())));
  for (auto& b : row_buffers_) b.resize(static_cast<size_t>(n_));
  return runRows<double>(
      y, [&](int t, int) { return row_buffers_[size_t(t)].data(); },
      [&](int, int row, const double* d) { sink(row, d); });
}

Status MorletScalogram::modulus(const double* y, double* out) { return modulusImpl(y, out); }

Status MorletScalogram::modulus(const double* y, float* out) { return modulusImpl(y, out); }

}  // namespace gear_damping_id
