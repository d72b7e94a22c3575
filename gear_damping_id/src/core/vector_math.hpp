// Element-wise logarithms and phases of the wavelet fits, four at a time where the processor
// allows (not installed).
#pragma once

#include <complex>

namespace gear_damping_id {
namespace wavelet_detail {

// For i < n: ly[i] = 0.5 ln(max(env[i]^2 - floor2, 1e-300)) (the noise-corrected envelope's
// logarithm) and arg[i] = arg w[i] (atan2 of its imaginary and real parts). In a GCC build where
// glibc's vector math library (libmvec) was found and on a processor with AVX2 and FMA, four
// values at a time by its AVX2 log and atan2 (within 4 ulp of the exact values); else (clang,
// the sanitizer build) by libm one at a time (within 1 ulp). Either way the same on every
// thread and every run of a build on a machine.
void logEnvelopeAndPhase(const double* env, const std::complex<double>* w, long n, double floor2,
                         double* ly, double* arg);

// Whether logEnvelopeAndPhase takes the vector path on this machine.
bool vectorMathAvailable();

}  // namespace wavelet_detail
}  // namespace gear_damping_id
