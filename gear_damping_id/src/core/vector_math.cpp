#include "vector_math.hpp"

#include <algorithm>
#include <cmath>

// GCC only: it passes the 256-bit arguments of these declarations in ymm registers, as the
// vector function ABI wants, from a function compiled for AVX2. Clang (the sanitizer build) does
// not always: its UBSan build passed them on the stack, and atan2 read garbage.
#if defined(GEAR_HAVE_LIBMVEC) && defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#include <immintrin.h>
#define GEAR_VECTOR_MATH 1
// glibc's libmvec, AVX2 variants (the vector function ABI's names: 'd' = AVX2, N4 = 4 lanes).
extern "C" {
__attribute__((target("avx2,fma"))) __m256d _ZGVdN4v_log(__m256d x);
__attribute__((target("avx2,fma"))) __m256d _ZGVdN4vv_atan2(__m256d y, __m256d x);
}
#endif

namespace gear_damping_id {
namespace wavelet_detail {

namespace {

void logEnvelopeAndPhaseScalar(const double* env, const std::complex<double>* w, long i0, long n,
                               double floor2, double* ly, double* arg) {
  for (long i = i0; i < n; ++i) {
    const double e = env[i];
    ly[i] = 0.5 * std::log(std::max(e * e - floor2, 1e-300));
    arg[i] = std::arg(w[i]);
  }
}

#ifdef GEAR_VECTOR_MATH
__attribute__((target("avx2,fma"))) void logEnvelopeAndPhaseAvx2(const double* env,
                                                                 const std::complex<double>* w,
                                                                 long n, double floor2, double* ly,
                                                                 double* arg) {
  const __m256d fl = _mm256_set1_pd(floor2), tiny = _mm256_set1_pd(1e-300),
                half = _mm256_set1_pd(0.5);
  const double* wd = reinterpret_cast<const double*>(w);
  long i = 0;
  for (; i + 4 <= n; i += 4) {
    const __m256d e = _mm256_loadu_pd(env + i);
    // max(tiny, x) returns x when x is NaN, as std::max(x, tiny) does.
    const __m256d e2 = _mm256_max_pd(tiny, _mm256_sub_pd(_mm256_mul_pd(e, e), fl));
    _mm256_storeu_pd(ly + i, _mm256_mul_pd(half, _ZGVdN4v_log(e2)));
    const __m256d w01 = _mm256_loadu_pd(wd + 2 * i), w23 = _mm256_loadu_pd(wd + 2 * i + 4);
    // re0 re2 re1 re3 and im0 im2 im1 im3, then lanes 1 and 2 swapped.
    const __m256d re = _mm256_permute4x64_pd(_mm256_unpacklo_pd(w01, w23), 0xD8);
    const __m256d im = _mm256_permute4x64_pd(_mm256_unpackhi_pd(w01, w23), 0xD8);
    _mm256_storeu_pd(arg + i, _ZGVdN4vv_atan2(im, re));
  }
  logEnvelopeAndPhaseScalar(env, w, i, n, floor2, ly, arg);
}
#endif

}  // namespace

bool vectorMathAvailable() {
#ifdef GEAR_VECTOR_MATH
  static const bool ok = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return ok;
#else
  return false;
#endif
}

void logEnvelopeAndPhase(const double* env, const std::complex<double>* w, long n, double floor2,
                         double* ly, double* arg) {
#ifdef GEAR_VECTOR_MATH
  if (vectorMathAvailable()) {
    logEnvelopeAndPhaseAvx2(env, w, n, floor2, ly, arg);
    return;
  }
#endif
  logEnvelopeAndPhaseScalar(env, w, 0, n, floor2, ly, arg);
}

}  // namespace wavelet_detail
}  // namespace gear_damping_id
