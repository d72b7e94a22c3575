// The Morlet continuous wavelet transform (CWT) engine: frequency grid helpers, FFTW plans and
// the transform itself (the analysis of modes is in wavelet_analysis.hpp, the CSV writers in
// wavelet_io.hpp). No ROS; SI units (seconds, hertz); errors by return value, never by
// exceptions or printing.
//
// Conventions (all functions of this header):
// - Wavelet: the analytic Morlet wavelet with centre frequency omega0 [rad per unit of u],
//     psi(u) = sqrt(2/pi) * exp(i*omega0*u) * exp(-u^2/2)     (time domain, u dimensionless),
//     Psi(w) = 2 * exp(-(w - omega0)^2 / 2)  for w > 0, 0 for w <= 0   (Fourier transform),
//   i.e. the classical Morlet without admissibility correction whose negative-frequency tail
//   (at most 2*exp(-omega0^2/2): 3e-8 for omega0 = 6) is set to zero, so W is analytic.
// - Scale and frequency: s = omega0 / (2*pi*f) [s]. The Fourier wavelength of scale s equals the
//   period 1/f, so a sinusoid of frequency f peaks on the row labelled f.
// - Transform (L1 normalisation): W(f, tau) = integral y(t) (1/s) conj(psi((t - tau)/s)) dt,
//   computed as W = IFFT( FFT(y - mean(y)) * Psi(s*omega_k) ) on a zero-padded grid. A pure
//   sinusoid A*cos(2*pi*f*t + phi) reads W = A * exp(i*(2*pi*f*tau + phi)) on its ridge:
//   |W| = A, and the phase advances at 2*pi*f.
// - Bandwidth: |Psi| is a Gaussian of standard deviation 1 in s*w, so a row's relative
//   frequency resolution is 1/omega0 (standard deviation of |Psi|); its half-amplitude full
//   width is 2*sqrt(2 ln 2)/omega0. A sinusoid at frequency f_j leaks into the row of f_i with
//   the relative amplitude morletLeakage(f_j, f_i, omega0) = exp(-(omega0*(f_j/f_i - 1))^2 / 2).
// - Cone of influence (COI): the time half-width of the wavelet's Gaussian where its amplitude
//   |psi| has fallen by e (the e-folding time of the wavelet power of an edge, Torrence &
//   Compo 1998): tau_coi(f) = sqrt(2) * s = sqrt(2) * omega0 / (2*pi*f) [s]. Coefficients
//   closer than tau_coi to either end of the record are affected by the record's edges.
// - Zero padding: the signal is padded with zeros after its end to a fast FFTW length
//   (2^a 3^b 5^c 7^d) of at least n + 8*s_max*fs samples, so the circular convolution of the FFT
//   equals the linear one with the record taken as zero outside [0, n) (the wavelet's Gaussian
//   is below exp(-32) = 1e-14 at the wrap-around). Frequencies of the wavelet's spectrum above
//   the Nyquist frequency are cut (rows near Nyquist use a band-limited wavelet).
// - Time axis: sample j is at t = j / sample_rate [s] (t = 0 at the first sample).
//
// Thread safety: FFTW's planner is not thread-safe. All plan creation and destruction in this
// file is serialised by one internal mutex, so MorletCwt objects may be configured and
// destroyed from several threads, provided no other code in the process calls FFTW's planner
// concurrently. One MorletCwt object must not be used by two threads at once; distinct objects
// may run concurrently.

#pragma once

#include <complex>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "gear_sim/status.hpp"

namespace gear_damping_id {

/// How much time FFTW spends choosing its algorithm (see the FFTW manual).
/// Measure: times candidate algorithms at plan creation, capped at 5 s per plan
///   (fftw_set_timelimit; an uncapped search takes minutes for N ~ 1.8e6), once per size and
///   process (later plans of the same size reuse FFTW's wisdom). Worth it when many rows are
///   transformed (a full scalogram of a long record): the inverse FFT runs once per row.
/// Estimate: heuristic plan, no measurement; use for a handful of rows.
enum class FftPlanning { Estimate, Measure };

/// Arithmetic of the per-row inverse FFTs of |W| (MorletCwt::rowModulus, MorletScalogram).
/// The signal's FFT, the Morlet multiplier and the complex rows (row(), rowAt()) are always
/// double. kSingle rounds the band of each row that takes a full-length inverse FFT to float
/// and runs FFTW's single-precision transform: about half the time of that FFT and half the
/// memory traffic. Pruned rows (rowModulus) and MorletScalogram's blocked rows stay double in
/// either precision: their transforms are in cache, where float gains little. |W| agrees with
/// kDouble within 1e-6 of the scalogram's largest |W| (wavelet_scalogram_test bounds it;
/// measured ~2e-7), the precision fCWT works in.
enum class Precision { Double, Single };

/// Smallest length >= min_length whose only prime factors are 2, 3, 5 and 7 (fast for FFTW).
/// Returns -1 if min_length < 1 or the result would overflow.
long fastFftLength(long min_length);

/// Morlet scale s = omega0 / (2*pi*f) [s] of frequency f [Hz] (> 0).
double morletScale(double frequency_hz, double omega0);

/// Cone-of-influence half-width tau_coi = sqrt(2) * omega0 / (2*pi*f) [s] (see header notes).
double morletConeOfInfluence(double frequency_hz, double omega0);

/// Relative amplitude exp(-(omega0*(f_signal/f_row - 1))^2 / 2) with which a sinusoid of
/// frequency f_signal [Hz] appears on the row of frequency f_row [Hz] (1 on its own row).
double morletLeakage(double f_signal_hz, double f_row_hz, double omega0);

/// n frequencies [Hz] log-spaced from f_min to f_max inclusive (ascending); n = 1 gives
/// {f_min}. Empty if n < 1 or not 0 < f_min <= f_max.
std::vector<double> logSpacedFrequencies(double f_min_hz, double f_max_hz, int n);

/// Frequency [Hz] of the maximum of a sampled peak: the index of the largest value, refined by
/// a parabola through ln(value) against ln(frequency) at that index and its two neighbours.
/// frequencies must be positive and strictly increasing, values positive. Returns NaN if
/// count < 3, the maximum is at either end, or a value is not positive and finite.
double ridgeFrequency(const double* frequencies_hz, const double* values, int count);

/// Reusable Morlet CWT of signals of a fixed length: FFTW plans and aligned scratch buffers are
/// allocated once by configure() and reused for every row and every signal (allocation and the
/// first touch of fresh memory are slow; keep the object alive between calls).
///
/// Work per signal: one real-to-complex FFT of the mean-removed, zero-padded signal
/// (setSignal), then per row a multiplication by Psi(s*omega_k) over the bins where it exceeds
/// 1e-16 of its peak (the rest of the spectrum is zero) and one complex inverse FFT of the
/// padded length. Outputs are restricted to the n unpadded samples.
class MorletCwt {
 public:
  MorletCwt();
  ~MorletCwt();
  MorletCwt(MorletCwt&&) noexcept;
  MorletCwt& operator=(MorletCwt&&) noexcept;
  MorletCwt(const MorletCwt&) = delete;
  MorletCwt& operator=(const MorletCwt&) = delete;

  /// Prepares transforms of signals of n samples at sample_rate [Hz] on the rows
  /// frequencies_hz [Hz] (any order, each in (0, sample_rate/2)) with one omega0 for all rows
  /// (omega0s.size() == 1) or one per row. Plans the forward FFT now and the inverse FFT on the
  /// first row computed (so a spectrum-only use never plans it). Preconditions: n >= 2,
  /// sample_rate > 0, omega0 in [1, 1000]. On failure returns InvalidArgument naming the field
  /// (ResourceLimit for a padded length beyond 2^40 or no memory, Internal when FFTW cannot plan)
  /// and leaves the object unconfigured.
  gear_sim::Status configure(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                             const std::vector<double>& omega0s, FftPlanning planning);
  gear_sim::Status configure(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                             double omega0, FftPlanning planning) {
    return configure(n, sample_rate, frequencies_hz, std::vector<double>{omega0}, planning);
  }

  /// The FFT length configure() chooses for these rows: the fast length >= n + 8 scales of the
  /// widest row (sizes are not checked: -1 when the padding is beyond any FFT). Two
  /// configurations of one n and rate with the same length give the same spectrum for a signal.
  static long paddedLength(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                           const std::vector<double>& omega0s);

  /// Loads a signal of size() samples: removes its mean and computes its FFT. InvalidInput naming
  /// the first non-finite sample's index if y has a NaN/Inf; Internal if not configured.
  gear_sim::Status setSignal(const double* y);
  /// setSignal for a caller that has checked every sample finite and computed their mean as
  /// checkedMean does (as setSignal computes it): the same spectrum without a
  /// second pass over the samples. Internal if not configured.
  gear_sim::Status setCheckedSignal(const double* y, double mean);
  /// setCheckedSignal for a caller that computes the spectrum itself: fill(Y) writes bins
  /// 0..paddedSize()/2 of the r2c transform of the samples minus `mean`, zero-padded to
  /// paddedSize() (what setCheckedSignal's FFT would give, to rounding; the per-mode path's
  /// transform in two halves). Internal if not configured.
  gear_sim::Status setCheckedSpectrum(double mean,
                                      const std::function<void(std::complex<double>*)>& fill);
  /// setSignal's check of n samples: all finite (InvalidInput "<who>: sample j is not finite
  /// (v)" naming the first that is not; Internal if y is null) and their mean: sample j goes to
  /// partial sum j mod 8, and the eight are added in a fixed order. The mean setCheckedSignal
  /// expects. max_abs (optional): the largest |y_j|, from the same pass.
  static gear_sim::Status checkedMean(const double* y, long n, double* mean,
                                      const char* who = "MorletCwt", double* max_abs = nullptr);

  /// Coefficients W of row i (0 <= i < rows()) for the current signal: returns a pointer to
  /// size() complex values (time order, sample j at t = j/fs), owned by the object and valid
  /// until the next row()/rowAt()/transform call or setSignal. Null if no signal is loaded or i
  /// is out of range.
  const std::complex<double>* row(int i);
  /// Same for an arbitrary frequency [Hz] and omega0 not among the configured rows. Null if no
  /// signal is loaded, f is outside (0, fs/2), or the wavelet at (f, omega0) is wider than the
  /// padding allows (more than 8 s of it would wrap around: use a smaller omega0 or configure
  /// a row with that (f, omega0)).
  const std::complex<double>* rowAt(double frequency_hz, double omega0);
  /// Whether the padding holds 8 scales of the wavelet at (f [Hz], omega0), i.e. rowAt(f,
  /// omega0) is exact up to the e^-32 wrap-around (false if not configured).
  bool fitsPadding(double frequency_hz, double omega0) const;

  /// |W| of row i into out[0, size()) (double or float). False if row(i) would be null.
  /// Rows whose band of nonzero bins fits in M <= N/16 bins (M a divisor of N) skip the full
  /// inverse FFT: with j = q*(N/M) + p, W_j is the value of N/M inverse FFTs of size M of
  /// twiddled copies of the band (exact up to rounding, ~1e-14 relative to the row's peak;
  /// N log M work instead of N log N, in cache; one batch plan per size M, with the object's
  /// planning, transforms out of place into a transposed chunk buffer). With
  /// the default log grid (10 cycles per record to 0.4 fs, omega0 = 6) 2/3 to 3/4 of the rows
  /// take this path; row() and rowAt() use it too (complex W). setPrunedModulus(false) always
  /// uses the full inverse FFT. The pruned |W| leaves row()'s buffer untouched.
  bool rowModulus(int i, double* out);
  bool rowModulus(int i, float* out);
  void setPrunedModulus(bool enabled) { pruned_ = enabled; }
  /// Precision of rowModulus's inverse FFTs (default kDouble; see Precision).
  void setPrecision(Precision precision) { precision_ = precision; }
  Precision precision() const { return precision_; }

  /// Whole transform of y: setSignal(y) then every row; output row-major [row][time] with
  /// rows()*size() elements (caller-allocated; allocate once and reuse). A failed Status as
  /// setSignal's (nothing written beyond the rows completed).
  gear_sim::Status transform(const double* y, std::complex<double>* out);
  gear_sim::Status transformModulus(const double* y, double* out);
  gear_sim::Status transformModulus(const double* y, float* out);

  /// Mean over the whole zero-padded time axis of |W|^2 of row i, times paddedSize()/size():
  /// the time-averaged scalogram, computed exactly in the frequency domain by Parseval,
  /// (1/(n*N)) * sum_k |Y_k|^2 Psi(s*omega_k)^2, without an inverse FFT. A sinusoid of
  /// amplitude A gives A^2 on its own row. NaN if no signal or i out of range.
  double meanPower(int i) const;
  double meanPowerAt(double frequency_hz, double omega0) const;
  /// Noise gain g: white noise of standard deviation sigma_n per sample gives E|W|^2 =
  /// g * sigma_n^2 on this row ((1/N) * sum_k Psi(s*omega_k)^2, about 2/(s*fs*sqrt(pi))).
  double noiseGainAt(double frequency_hz, double omega0) const;

  /// Spectrum Y_k, k = 0..paddedSize()/2, of the mean-removed zero-padded signal (unnormalised
  /// FFTW r2c: Y_k = sum_j y_j exp(-2*pi*i*j*k/N), bin k at k*fs/N Hz). Null if no signal.
  const std::complex<double>* spectrum() const;

  bool configured() const { return n_ > 0; }
  bool hasSignal() const { return has_signal_; }
  long size() const { return n_; }            ///< samples per signal
  long paddedSize() const { return n_fft_; }  ///< FFT length N
  int rows() const { return static_cast<int>(frequencies_.size()); }
  double sampleRate() const { return fs_; }
  double signalMean() const { return mean_; }  ///< mean removed from the current signal
  const std::vector<double>& frequencies() const { return frequencies_; }  ///< [Hz] per row
  const std::vector<double>& omega0s() const { return omega0s_; }          ///< per row

 private:
  friend class MorletScalogram;
  struct Buffers;
  struct Fftw;
  static std::shared_ptr<Buffers> makeBuffers(long capacity);
  /// configure() on the buffers *shared when they hold the padded length (MorletScalogram's
  /// groups, used in turn by one thread; each use must start with setSignal, since another
  /// object's setSignal overwrites the spectrum); otherwise on new buffers, stored in *shared
  /// when shared is not null. fft_length > 0: the padded length, if at least the rows' own.
  gear_sim::Status configureOn(std::shared_ptr<Buffers>* shared, long n, double sample_rate,
                               const std::vector<double>& frequencies_hz,
                               const std::vector<double>& omega0s, FftPlanning planning,
                               long fft_length = 0);
  /// setSignal's transform of samples already checked, whose mean is `mean`.
  void loadChecked(const double* y, double mean);
  const std::complex<double>* computeRow(double frequency_hz, double omega0);
  bool rowAtAllowed(double frequency_hz, double omega0) const;
  bool fillRow(double frequency_hz, double omega0);
  bool setBand(long lo, long hi, bool full_double);
  bool bandRow(long lo, long hi, const double* g, std::complex<double>* out);
  template <typename T>
  bool prunedRow(T* out);
  bool fullRowSingle();
  bool fullInverse();
  template <typename T>
  bool rowModulusImpl(int i, T* out);
  void release();

  long n_ = 0, n_fft_ = 0;
  double fs_ = 0.0, mean_ = 0.0;
  bool has_signal_ = false;
  bool pruned_ = true;
  Precision precision_ = Precision::Double;
  FftPlanning planning_ = FftPlanning::Measure;
  std::vector<double> frequencies_, omega0s_;
  std::unique_ptr<Fftw> fftw_;
};

/// Full scalogram |W| of signals of a fixed length, faster than one MorletCwt over all rows:
/// - Padding per group of rows: the rows are grouped so that each group's FFT length is the
///   fast length >= n + 8 s_max fs of the group's own lowest row, within a factor
///   kGroupLengthRatio (1.05) of each member's own need. Each row keeps its 8-scale padding
///   (wrap-around e^-32: the same edge accuracy as MorletCwt); high rows no longer pay the
///   0.76 n padding of the lowest row. Rows whose band reaches the Nyquist frequency (a
///   band-limited wavelet, whose cut rings beyond 8 scales) keep the lowest row's padding.
///   One r2c FFT per group and signal.
/// - Rows in parallel on `threads` threads (std::thread, each with its own MorletCwt per
///   group; rows dealt round-robin). Every row is computed by the same code on the same FFT
///   length whatever the thread count, so results are bit-identical to one thread.
/// - Memory: one set of FFT buffers per thread, sized for the longest group and shared by the
///   thread's groups (its plans per group point into it), not one set per group.
/// - Blocked rows (either precision; their transforms are double): a row whose wavelet spans
///   K = ceil(8 s fs) samples either side, with a block length L (a power of two, 1024..16384,
///   >= 8 (2K + 1)) at most half its own FFT length and a band below the Nyquist frequency, is
///   computed in overlapping blocks
///   (overlap-save): per block of L samples one inverse FFT of L (in cache) gives L - 2A
///   outputs, A >= K the margin, so each output keeps the 8-scale margin of the row's padding.
///   The blocks' spectra are computed once per signal per L. The analytic cut at zero frequency
///   (Psi(0) = 2 e^{-omega0^2/2}, 1.5e-8 of the peak for omega0 = 6) rings over the whole record:
///   its part is one transform per signal on the lowest group's length, added to every blocked
///   row, so the blocks transform only a remainder continuous at zero frequency. |W| agrees with
///   one MorletCwt over all rows as the groups do (wavelet_scalogram_test).
class MorletScalogram {
 public:
  static constexpr double kGroupLengthRatio = 1.05;

  /// Same preconditions as MorletCwt::configure (one omega0 for all rows), plus threads >= 1.
  /// precision: of the rows' inverse FFTs (see Precision). A failed Status as MorletCwt's
  /// (threads out of range: InvalidArgument, field "threads").
  gear_sim::Status configure(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                             double omega0, FftPlanning planning, int threads,
                             Precision precision = Precision::Double);
  /// |W| of every row for signal y (n samples) into out, row-major [row][time], rows()*size()
  /// values (double or float). A failed Status as MorletCwt::setSignal's.
  gear_sim::Status modulus(const double* y, double* out);
  gear_sim::Status modulus(const double* y, float* out);
  /// Same rows, handed to sink(row, |W| of n values) instead of stored (the pointer is valid
  /// during the call only). With threads > 1, sink runs concurrently on distinct rows.
  gear_sim::Status forEachRow(const double* y, const std::function<void(int, const double*)>& sink);

  long size() const { return n_; }
  int rows() const { return static_cast<int>(frequencies_.size()); }
  int threads() const { return static_cast<int>(workers_.size()); }
  int groups() const { return static_cast<int>(group_rows_.size()); }
  /// FFT length of group g.
  long groupLength(int g) const;
  /// Rows computed in overlapping blocks (see the class notes).
  int blockedRows() const;

 private:
  template <typename T>
  gear_sim::Status modulusImpl(const double* y, T* out);
  template <typename T, typename Dest, typename Done>
  gear_sim::Status runRows(const double* y, Dest dest, Done done);
  struct Blocks;
  gear_sim::Status configureBlocks(long n, double sample_rate,
                                   const std::vector<double>& frequencies_hz, double omega0,
                                   FftPlanning planning, int threads, std::vector<long>* own);
  template <typename T>
  void blockedRow(int thread, int b, T* out);

  long n_ = 0;
  std::vector<double> frequencies_;
  std::vector<std::vector<int>> group_rows_;      ///< rows (indices into frequencies_) per group
  std::vector<std::vector<MorletCwt>> workers_;   ///< [thread][group]
  std::vector<std::vector<double>> row_buffers_;  ///< forEachRow's |W| row per thread
  std::shared_ptr<Blocks> blocks_;                ///< the rows computed in blocks (or null)
};

}  // namespace gear_damping_id
