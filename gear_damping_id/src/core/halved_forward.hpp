// The per-mode path's forward FFT of the record in two halves (not installed): the r2c spectrum
// of the mean-removed record zero-padded to an even N from two transforms of N/2 points, the
// even samples' and the odd samples', and one pass that joins them (docs/wavelet.md "Speed").
// The two halves touch nothing in common, so two threads can take one each; the arithmetic is
// the same whatever the threads, so are the bits.
#pragma once

#include <fftw3.h>

#include <complex>
#include <vector>

#include "gear_damping_id/morlet_cwt.hpp"

namespace gear_damping_id {
namespace wavelet_detail {

// With x the record y - mean zero-padded to N = 2M, e_j = x_{2j} and o_j = x_{2j+1}
// (j = 0..M-1), E and O their r2c spectra and W = e^{-2 pi i/N}, the spectrum of x is
//   X_k = E_k + W^k O_k,   X_{M-k} = conj(E_k - W^k O_k),   k = 0..M/2
// (E and O have period M and are conjugate-symmetric; W^{M-k} = -conj(W^k)). Each half is an
// in-place r2c of M points on a buffer of its own (about half the time of the whole transform
// on a core; the pair runs on two cores in about 0.4 of it, measured at N ~ 1e6). W^k is the
// phasor of the start of its block of kTwiddleBlock bins (cos and sin of the angle) times the
// phasor of its offset in the block (a table), ~2 ulp: the joined spectrum agrees with FFTW's
// whole transform to ~1e-16 of its largest bin.
class HalvedForward {
 public:
  HalvedForward() = default;
  HalvedForward(const HalvedForward&) = delete;
  HalvedForward& operator=(const HalvedForward&) = delete;
  ~HalvedForward();

  // Plans (by `planning`) and buffers for an even n_fft >= 4 (none kept otherwise). False when
  // n_fft is odd or too small, out of memory, or FFTW cannot plan: the caller then takes the
  // whole transform. Kept while the length is the same (with the plans first made).
  bool configure(long n_fft, FftPlanning planning = FftPlanning::Estimate);
  long size() const { return n_fft_; }

  // Half p (0: samples 0, 2, 4, ...; 1: samples 1, 3, 5, ...) of y[0..n) - mean zero-padded to
  // the configured length, transformed in place. Writes half p's buffer only.
  void transformHalf(int p, const double* y, long n, double mean);

  // The whole spectrum, bins 0..N/2, into X from the two transformed halves.
  void join(std::complex<double>* X) const;

 private:
  static constexpr long kTwiddleBlock = 1024;
  fftw_plan plans_[2] = {nullptr, nullptr};
  double* half_[2] = {nullptr, nullptr};    // 2 (M/2 + 1) doubles each: M samples, then M/2+1 bins
  std::vector<std::complex<double>> step_;  // W^j, j < kTwiddleBlock
  long n_fft_ = 0;
  void release();
};

}  // namespace wavelet_detail
}  // namespace gear_damping_id
