// Decimated wavelet rows of the per-mode path (not installed): W of one Morlet row at every D-th
// sample, from the spectrum of the zero-padded record, by one inverse FFT of length N/D of the
// row's band folded modulo N/D (docs/wavelet.md "Speed").
#pragma once

#include <fftw3.h>

#include <complex>
#include <cstddef>
#include <map>
#include <mutex>

namespace gear_damping_id {
namespace wavelet_detail {

// The mutex that serialises FFTW planning (and plan destruction) for every wavelet object.
std::mutex& fftwPlannerMutex();

// Asks the kernel for transparent huge pages on a large buffer (where THP is in `madvise`
// mode): its first touch then faults once per 2 MiB instead of once per 4 KiB page (fresh
// pages cost ~10 us each on the reference machines; a one-shot analysis of 1e6 samples touches
// ~100 MB). Advisory only: contents and results are unchanged; ignored where unsupported.
void adviseHugePages(void* p, size_t bytes);

// With Y the r2c spectrum (k = 0..N/2) of the mean-removed record zero-padded to N, the row
// (frequency f, omega0; a = s * 2 pi fs / N, so s*w_k = a*k) at sample j is
//   W_j = sum_k B_k e^{2 pi i k j/N},  B_k = Y_k Psi(a k) / N  (k in the band, MorletCwt's row).
// With L = N/D (D a divisor of N) and C_q = sum_{k = q mod L} B_k:
//   W_{mD} = sum_q C_q e^{2 pi i q m/L},
// exact for any D (e^{2 pi i k mD/N} = e^{2 pi i (k mod L) m/L}): one inverse FFT of length L
// instead of N, plus one pass over the band. Plans (FFTW_ESTIMATE, one per L) and the buffers are
// kept between calls.
class DecimatedRows {
 public:
  DecimatedRows() = default;
  DecimatedRows(const DecimatedRows&) = delete;
  DecimatedRows& operator=(const DecimatedRows&) = delete;
  ~DecimatedRows();

  // Bins [lo, hi] of the row's band (Psi above 1e-16 of its peak, 1 <= k <= N/2; MorletCwt's).
  static void band(double a, double omega0, long n_fft, long* lo, long* hi);
  // The largest divisor of n_fft that is <= max(1, d).
  static long divisorAtMost(long n_fft, long d);
  // The largest D dividing n_fft whose N/D holds the band's bins without overlap (band-pass
  // sampling: the decimated row still determines the row; nothing is lost).
  static long bandDecimation(long n_fft, double a, double omega0);

  // MorletCwt::noiseGainAt's sum_k Psi(a k)^2 / N over its band [lo, hi] (Psi^2 above 1e-16
  // of its peak, clipped to 1..N/2), as the midpoint rule's integral of the Gaussian over
  // [lo - 1/2, hi + 1/2] (erf): the rule's error is ~a^2/24 of the sum (a = s*2*pi*fs/N, the
  // Gaussian's spacing per bin: 1e-5 for a 1e6-sample record), O(1) instead of one term per bin.
  static double noiseGain(double a, double omega0, long n_fft);

  // W at samples 0, D, 2D, ... (the first ceil(n/D) values of the result), D dividing n_fft.
  // nullptr if FFTW cannot plan or no memory. Valid until the next call.
  const std::complex<double>* row(const std::complex<double>* spectrum, long n_fft, double a,
                                  double omega0, long D);

 private:
  std::map<long, fftw_plan> plans_;
  fftw_complex* in_ = nullptr;   // the folded band C
  fftw_complex* out_ = nullptr;  // the decimated row
  long capacity_ = 0;
};

}  // namespace wavelet_detail
}  // namespace gear_damping_id
