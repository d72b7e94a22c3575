// Decimated wavelet rows of the per-mode path (not installed): W of one Morlet row at every D-th
// sample, from the spectrum of the zero-padded record, by one inverse FFT of length N/D of the
// row's band folded modulo N/D (docs/wavelet.md "Speed").
#pragma once

#include <fftw3.h>

#include <complex>
#include <cstddef>
#include <map>
#include <mutex>
#include <vector>

#include "gear_damping_id/morlet_cwt.hpp"

namespace gear_damping_id {
namespace wavelet_detail {

// The mutex that serialises FFTW planning (and plan destruction) for every wavelet object.
std::mutex& fftwPlannerMutex();

// FFTW_MEASURE planning cap per plan [s] (an unlimited FFTW_MEASURE search for N = 1764000 =
// 2^5 3^2 5^3 7^2 takes > 5 minutes on the reference machine; capped at 5 s its plan is within
// 7 % of the estimate's speed or better).
constexpr double kMeasureTimeLimitS = 5.0;

// FFTW flags of a planning choice. Sets FFTW's (global) planner time limit for the next plan,
// so call it with fftwPlannerMutex() held: Measure planning is capped at kMeasureTimeLimitS.
unsigned fftwFlags(FftPlanning planning);

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

  // The planning of the transforms planned from here on (Estimate until set; a length already
  // planned keeps its plan).
  void setPlanning(FftPlanning planning) { planning_ = planning; }

  // W at samples 0, D, 2D, ... (the first ceil(n/D) values of the result), D dividing n_fft.
  // nullptr if FFTW cannot plan or no memory. Valid until the next call.
  const std::complex<double>* row(const std::complex<double>* spectrum, long n_fft, double a,
                                  double omega0, long D);

 private:
  std::map<long, fftw_plan> plans_;
  FftPlanning planning_ = FftPlanning::Estimate;
  fftw_complex* in_ = nullptr;   // the folded band C
  fftw_complex* out_ = nullptr;  // the decimated row
  long capacity_ = 0;
};

// Per-mode path: W of one row at every sample of the ranges asked for, computed from the record
// itself in overlapping blocks (overlap-save) instead of one inverse FFT of the padded length: a
// fit row whose grid is every sample (s*fs < 2*kFitSamplesPerScale) needs every sample only over
// its peak and its decay region (docs/wavelet.md "Speed"). A block of L samples (the smallest
// power of two >= kMinBlock and >= 8 (2K + 1), K = ceil(8 s fs) the wavelet's half-span) gives
// its L - 2K middle samples: r2c of the mean-removed samples (zero outside [0, n)), the band
// times Psi(s w_q) (q = 0..L/2, the row's multiplier on L bins), one inverse FFT of L. Equal to
// the padded row up to the wavelet's tail beyond 8 scales (e^-32) and the ringing of the
// analytic cut at zero frequency (Psi(0) = 2 e^-18 at omega0 = 6; ~1e-8 of the row's peak).
class BlockedRow {
 public:
  BlockedRow() = default;
  BlockedRow(const BlockedRow&) = delete;
  BlockedRow& operator=(const BlockedRow&) = delete;
  ~BlockedRow();

  // The row (scale s_samples = s*fs [samples], omega0) of the record y[0..n) with mean `mean`.
  // False (and nothing computed) when its band reaches the Nyquist frequency or its block would
  // exceed kMaxBlock, or FFTW cannot plan: the caller computes the full row instead.
  bool configure(const double* y, long n, double mean, double s_samples, double omega0);
  // As DecimatedRows::setPlanning.
  void setPlanning(FftPlanning planning) { planning_ = planning; }
  // Makes w()[j] and env()[j] = |w()[j]| valid for j in [j0, j1] (clipped to [0, n)).
  void ensure(long j0, long j1);
  const std::complex<double>* w() const { return w_; }
  const std::vector<double>& env() const { return env_; }

  static constexpr long kMinBlock = 1024, kMaxBlock = 16384;

 private:
  void computeBlock(long b);

  struct Plans {
    fftw_plan r2c = nullptr, c2c = nullptr;
  };
  std::map<long, Plans> plans_;
  FftPlanning planning_ = FftPlanning::Estimate;
  Plans plan_;
  double* seg_ = nullptr;              // one block's samples (L doubles)
  fftw_complex* spec_ = nullptr;       // their r2c spectrum (L/2 + 1)
  fftw_complex* band_ = nullptr;       // the band times the multiplier (L, zero outside it)
  fftw_complex* out_ = nullptr;        // the block's row (L)
  long cap_ = 0;                       // length the block buffers hold
  std::complex<double>* w_ = nullptr;  // the row at every sample (valid where computed)
  long w_cap_ = 0;
  std::vector<double> env_;  // |W| (valid where computed)
  std::vector<double> psi_;  // multiplier over [lo_, hi_]
  std::vector<char> done_;   // per block: computed
  const double* y_ = nullptr;
  long n_ = 0, L_ = 0, A_ = 0, H_ = 0, lo_ = 0, hi_ = -1;
  double mean_ = 0.0;
};

// Per-mode path: the first K bins Y_0..Y_{K-1} of the length-N r2c DFT of the mean-removed
// record zero-padded to N (the grid's padding), for the low rows whose 8-scale padding exceeds
// the shared transform's (docs/wavelet.md "Speed"). Two ways, the first where it applies:
//
// Decimation (D >= 3 a divisor of N with 6 D K <= N): the record through a linear-phase
// lowpass FIR h (Kaiser-windowed sinc, cutoff pi/D, stopband attenuation kStopbandDb, centred:
// zero phase), kept at every D-th sample (z_m = sum_j h_j x_{mD-j}, m < 0 wrapped to the end of
// its length-N/D buffer), and one r2c DFT of length N/D:
//   Z_k = (1/D) sum_{r<D} H(w_k - 2 pi r/D) X(w_k - 2 pi r/D),  w_k = 2 pi k/N,
// so Y_k = X(w_k) = D Z_k / H(w_k) up to the aliases r != 0, which lie in the stopband (the
// passband edge w_{K-1} <= 2 pi/(6D), the stopband from 2 pi/D - w_{K-1}): their share is below
// 10^(-kStopbandDb/20) of the aliased bins' amplitude. H(w_k) is real (the taps are symmetric),
// evaluated per bin by Clenshaw's recurrence. About 20 multiply-adds per sample and one
// transform of N/D points instead of transforms of N points in all.
//
// Polyphase (otherwise; exact to rounding). With the record's R = N/M polyphase
// components x_v[a] = y[aR + v] (a = 0..M-1, zero beyond the record),
//   Y_k = sum_{v<R} e^{-2 pi i k v/N} X_v[k],  X_v the length-M r2c DFT of x_v (k <= M/2):
// R transforms of length M (in cache) and K*R products instead of one memory-bound transform of
// length N. M is a divisor of N with M/2 >= K (see compute); the sum over v runs by Horner's rule
// in e^{-2 pi i k/N} within chunks of kChunk components, the twiddles advance by recurrences
// re-seeded every kTwiddleBlock bins (relative drift < kTwiddleBlock * 2 eps).
class LowBand {
 public:
  LowBand() = default;
  LowBand(const LowBand&) = delete;
  LowBand& operator=(const LowBand&) = delete;
  ~LowBand();

  // Y_0..Y_{K-1} of y[0..n) - mean zero-padded to N (K <= N/2 + 1). False when FFTW cannot plan
  // or no memory. `exact`: the polyphase way always (tests compare the two).
  bool compute(const double* y, long n, double mean, long N, long K, bool exact = false);
  // As DecimatedRows::setPlanning.
  void setPlanning(FftPlanning planning) { planning_ = planning; }
  const std::complex<double>* spectrum() const { return Y_.data(); }
  // The decimation factor of the last compute (0: the polyphase way).
  long decimation() const { return D_; }

  static constexpr double kStopbandDb = 200.0;

 private:
  static constexpr long kChunk = 8;  // components per batch of transforms
  static constexpr long kTwiddleBlock = 64;
  static constexpr long kMaxDecimation = 64;
  static constexpr long kFirBlock = 2048;  // outputs per block of the FIR
  bool polyphase(const double* y, long n, double mean, long N, long K);
  void accumulate(long v0, long c, long K, long N);
  // The decimation way: false (nothing changed) when no factor applies.
  bool decimated(const double* y, long n, double mean, long N, long K);
  bool designDecimation(long n, long N, long K);
  void filterBlock(const double* y, long n, double mean, long m0, long m1);
  // Decimation: D_, the half length H_ (taps -H_..H_, stored from -H_ and zero-padded to a
  // multiple of 4), the per-bin gains D/H(w_k) and the length-N/D transform.
  FftPlanning planning_ = FftPlanning::Estimate;
  long D_ = 0, H_ = 0, dN_ = 0, dn_ = 0, dK_ = 0;
  std::vector<double> taps_, gain_, buf_;
  fftw_plan dplan_ = nullptr;
  double* din_ = nullptr;
  fftw_complex* dout_ = nullptr;
  fftw_plan plan_ = nullptr;
  long M_ = 0, R_ = 0, N_ = 0, K_ = 0;  // K_, N_: the last call's (M_ chosen for them)
  double* in_ = nullptr;                // kChunk components of M samples
  fftw_complex* out_ = nullptr;         // their spectra, M/2 + 1 bins each
  std::vector<std::complex<double>> Y_, step_;
};

}  // namespace wavelet_detail
}  // namespace gear_damping_id
