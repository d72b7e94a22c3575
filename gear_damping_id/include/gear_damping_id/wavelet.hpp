// Morlet-wavelet validation of damping (DESIGN.md §5, paper §4.3): an FFTW-based continuous
// wavelet transform (CWT), spectra and automatic peak picking, and the envelope-decay damping
// ratio of each mode. No ROS; SI units (seconds, hertz); errors by return value, never by
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

#include "gear_damping_id/quality_warning.hpp"

#include <complex>
#include <iosfwd>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

namespace gear_damping_id {

/// How much time FFTW spends choosing its algorithm (see the FFTW manual).
/// kMeasure: times candidate algorithms at plan creation, capped at 5 s per plan
///   (fftw_set_timelimit; an uncapped search takes minutes for N ~ 1.8e6), once per size and
///   process (later plans of the same size reuse FFTW's wisdom). Worth it when many rows are
///   transformed (a full scalogram of a long record): the inverse FFT runs once per row.
/// kEstimate: heuristic plan, no measurement; use for a handful of rows.
enum class FftPlanning { kEstimate, kMeasure };

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
  /// sample_rate > 0, omega0 in [1, 1000]. On failure returns false with *error set (error may be
  /// null) and leaves the object unconfigured.
  bool configure(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                 const std::vector<double>& omega0s, FftPlanning planning, std::string* error);
  bool configure(long n, double sample_rate, const std::vector<double>& frequencies_hz,
                 double omega0, FftPlanning planning, std::string* error) {
    return configure(n, sample_rate, frequencies_hz, std::vector<double>{omega0}, planning,
                     error);
  }

  /// Loads a signal of size() samples: removes its mean and computes its FFT. Fails (false,
  /// *error names the first non-finite sample's index) if not configured or y has a NaN/Inf.
  bool setSignal(const double* y, std::string* error);

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

  /// |W| of row i into out[0, size()) (double or float). False if row(i) would be null.
  /// Rows whose band of nonzero bins fits in M <= N/16 bins (M a divisor of N) skip the full
  /// inverse FFT: with j = q*(N/M) + p, |W_j| is the modulus of N/M inverse FFTs of size M of
  /// twiddled copies of the band (exact up to rounding, ~1e-14 relative to the row's peak;
  /// N log M work instead of N log N, in cache; FFTW_ESTIMATE plans, one per size M). With
  /// the default log grid (10 cycles per record to 0.4 fs, omega0 = 6) 2/3 to 3/4 of the rows
  /// take this path. setPrunedModulus(false) always uses the full inverse FFT. The pruned
  /// path leaves row()'s buffer untouched.
  bool rowModulus(int i, double* out);
  bool rowModulus(int i, float* out);
  void setPrunedModulus(bool enabled) { pruned_ = enabled; }

  /// Whole transform of y: setSignal(y) then every row; output row-major [row][time] with
  /// rows()*size() elements (caller-allocated; allocate once and reuse). False + *error on
  /// failure (nothing written beyond the rows completed).
  bool transform(const double* y, std::complex<double>* out, std::string* error);
  bool transformModulus(const double* y, double* out, std::string* error);
  bool transformModulus(const double* y, float* out, std::string* error);

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
  long size() const { return n_; }           ///< samples per signal
  long paddedSize() const { return n_fft_; }  ///< FFT length N
  int rows() const { return static_cast<int>(frequencies_.size()); }
  double sampleRate() const { return fs_; }
  double signalMean() const { return mean_; }  ///< mean removed from the current signal
  const std::vector<double>& frequencies() const { return frequencies_; }  ///< [Hz] per row
  const std::vector<double>& omega0s() const { return omega0s_; }          ///< per row

 private:
  struct Fftw;
  const std::complex<double>* computeRow(double frequency_hz, double omega0);
  bool fillRow(double frequency_hz, double omega0);
  template <typename T>
  bool prunedModulus(T* out);
  template <typename T>
  bool rowModulusImpl(int i, T* out);
  bool fitsPadding(double frequency_hz, double omega0) const;
  void release();

  long n_ = 0, n_fft_ = 0;
  double fs_ = 0.0, mean_ = 0.0;
  bool has_signal_ = false;
  bool pruned_ = true;
  FftPlanning planning_ = FftPlanning::kMeasure;
  std::vector<double> frequencies_, omega0s_;
  std::unique_ptr<Fftw> fftw_;
};

/// Options of analyzeWavelet. Defaults suit free decays sampled at >= 10 samples per period of
/// the highest mode. validate() checks everything that does not depend on the data.
struct WaveletOptions {
  /// Scalogram / spectrum frequency grid [Hz], log-spaced. 0 = automatic: f_min = 10 cycles
  /// over the record (10*fs/n), f_max = 0.4*fs. Must satisfy f_min < f_max < fs/2.
  double f_min = 0.0;
  double f_max = 0.0;
  int n_scales = 200;  ///< rows of the log-spaced grid, >= 3
  /// Explicit grid [Hz] (positive, strictly increasing, < fs/2); overrides f_min/f_max/n_scales.
  std::vector<double> frequencies;
  /// Morlet centre frequency of the scalogram and the peak picking: 6 (Torrence & Compo), the
  /// usual balance of relative frequency resolution 1/omega0 = 17 % and time resolution
  /// tau_coi = 1.35 periods. Rule: 3 <= omega0 <= 100.
  double omega0 = 6.0;
  /// Morlet centre frequency of the time-averaged scalogram used for peak picking (computed by
  /// Parseval from the signal's FFT: no inverse FFT). 20 resolves modes about 10 % apart
  /// (relative bandwidth 1/20) and still averages the periodogram's noise over f/20. Rule:
  /// 3 <= peak_omega0 <= 100.
  double peak_omega0 = 20.0;
  /// Morlet centre frequency of the damping fits. 0 = automatic per mode (see analyzeWavelet):
  /// large enough that the neighbouring modes leak < 0.1 % into the mode's row, small enough
  /// that the wavelet does not span more than half an envelope time constant. Rule: 0 or in
  /// [3, max_fit_omega0].
  double fit_omega0 = 0.0;
  double max_fit_omega0 = 40.0;  ///< upper bound of the automatic choice; in [3, 100]
  /// Explicit mode frequencies [Hz] (positive, < fs/2): skip peak picking and fit these.
  std::vector<double> mode_frequencies;
  /// Decay regions [t0, t1] [s] overriding the automatic choice: empty (all automatic), one
  /// pair (used for every mode), or one per explicit mode frequency (same order). A pair with
  /// NaN members means automatic for that mode. Rule: t0 < t1, both finite, or both NaN.
  std::vector<std::pair<double, double>> decay_regions;
  /// A spectral peak becomes a mode if its topographic prominence (in amplitude = sqrt of the
  /// time-averaged scalogram) is at least this fraction of the highest peak's amplitude
  /// (0.05 = -26 dB in power). Rule: in (0, 1).
  double peak_prominence = 0.05;
  /// Peaks closer than this [Hz] are merged (the higher wins). 0 = automatic: one wavelet
  /// bandwidth f/peak_omega0 at the higher peak. Rule: >= 0.
  double min_separation_hz = 0.0;
  int max_modes = 6;  ///< most prominent peaks kept; >= 1
  /// Decay regions start at least coi_factor cone-of-influence half-widths from the record's
  /// start and end there from its end (the wavelet's Gaussian is below exp(-coi_factor^2)
  /// there: 1.2e-4 for 3). Rule: >= 1.
  double coi_factor = 3.0;
  /// A decay region ends where the envelope first falls below floor_factor times the noise
  /// floor (there ln|W| is biased by < 1e-5; see analyzeWavelet). Rule: >= 1.
  double floor_factor = 3.0;
  /// Compute and keep the full scalogram (for figures). false: only the rows the damping fits
  /// need are transformed, and the spectra come from the signal's FFT alone.
  bool full_scalogram = true;
  /// Time columns kept in WaveletResult::modulus: block means of at most this many columns
  /// (0 = every sample). Rule: >= 0.
  long max_scalogram_columns = 2000;
  /// FFTW planning of the scalogram's transforms. kEstimate (default) plans instantly; kMeasure
  /// costs ~0.1-3 s of planning once per FFT size and process and pays off for repeated
  /// full scalograms of long records (the benchmark uses it). The damping fits' few rows
  /// always use kEstimate.
  FftPlanning fft_planning = FftPlanning::kEstimate;

  /// Empty when valid; otherwise names the field, its value and the rule broken.
  std::string validate() const;
};

/// One mode: frequency and damping from the decay of its wavelet envelope (paper Table 2).
/// When the fit fails the numbers are NaN and `warning` says why.
struct WaveletMode {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double frequency_hz = kNaN;  ///< [Hz] damped frequency f_d from the ridge phase slope
  double spectrum_frequency_hz = kNaN;  ///< [Hz] spectral peak (parabolic interpolation)
  double damping_ratio = kNaN;  ///< [-] xi = sigma / sqrt(sigma^2 + (2*pi*f_d)^2)
  double sigma = kNaN;          ///< [1/s] decay rate: envelope ~ exp(-sigma*t)
  double r2 = kNaN;             ///< [-] weighted R^2 of the ln(envelope) line fit
  double t_start = kNaN;        ///< [s] decay region used
  double t_end = kNaN;          ///< [s]
  double peak_amplitude = kNaN;  ///< [unit of y] maximum of the envelope |W| on the mode's row
  double noise_floor = kNaN;     ///< [unit of y] RMS noise level of |W| on the mode's row
  double omega0 = kNaN;          ///< Morlet omega0 used for the fit
  double integral_xi = kNaN;     ///< [-] integral-method xi = C/(2*omega_n), filled by callers
  std::string warning;           ///< empty, or what limits this mode's estimate
  /// True when the envelope really decays over a long enough region (a damping estimate);
  /// false for a forced line (steady envelope, mesh/shaft-order harmonic).
  bool free_decay = true;
  QualityWarnings warnings;  ///< empty when the mode's estimate is clean
};

/// Everything analyzeWavelet computes. Frequencies [Hz], times [s], amplitudes in y's unit.
struct WaveletResult {
  std::vector<double> frequencies;   ///< scalogram rows [Hz], ascending
  std::vector<double> coi;           ///< cone-of-influence half-width per row [s]
  double omega0 = 0.0;               ///< omega0 of the scalogram
  /// Scalogram |W|, row-major [row][column]; empty unless options.full_scalogram. Column c is
  /// the mean of |W| over samples [c*d, min((c+1)*d, n)) with d = scalogram_decimation, at time
  /// scalogram_times[c] (mean time of its samples).
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> modulus;
  std::vector<double> scalogram_times;
  long scalogram_decimation = 1;
  /// One-sided power spectral density of the mean-removed record without window (a free decay
  /// is its own window; a Hann window would suppress the start where it carries its energy):
  /// psd_k = 2*|Y_k|^2 / (n*fs) [unit^2/Hz] on the zero-padded grid f_k = k*fs/N.
  std::vector<double> spectrum_freq, spectrum_power;
  /// Time-averaged scalogram (MorletCwt::meanPower) on `frequencies` [unit^2].
  std::vector<double> scalogram_power;
  /// Peak-picking spectrum: time-averaged scalogram at options.peak_omega0 [unit^2] on a log
  /// grid peak_freq [Hz] (relative step <= 1/(4*peak_omega0)) spanning `frequencies`.
  std::vector<double> peak_freq, peak_power;
  double noise_std = 0.0;  ///< [unit of y] white-noise estimate per sample (see analyzeWavelet)
  std::vector<WaveletMode> modes;     ///< ascending frequency
  std::vector<std::string> warnings;  ///< global remarks (modes also carry their own)
  /// Empty on success; otherwise why the analysis could not run (validateWavelet only: the
  /// bool-returning analyzeWavelet reports through its error argument). When set, everything
  /// else is empty.
  std::string error;
  bool ok() const { return error.empty(); }
};

/// Morlet-wavelet damping analysis of a record y[0..n) sampled at sample_rate [Hz]
/// (sample j at t = j/sample_rate; the record should hold free decays).
///
/// Steps: (1) FFT of the mean-removed record; PSD and time-averaged scalogram on the grid.
/// (2) Modes: options.mode_frequencies, or the peaks of sqrt(scalogram_power) passing the
/// prominence and separation rules (max_modes most prominent), each refined by a parabola
/// through the log PSD at its largest bin within one wavelet bandwidth.
/// (3) Per mode, the row W(f_mode, t) with omega0_fit: automatic omega0_fit = max(omega0,
/// sqrt(2 ln(R/1e-3))/r) with r the smallest relative distance |f_j/f_i - 1| to another mode
/// and R its amplitude ratio (leakage < 0.1 %), capped by max_fit_omega0 and, after a first
/// fit, by 0.5/xi (the wavelet then spans < half an envelope time constant).
/// (4) Decay region (unless given): from max(coi_factor*tau_coi, t_peak + tau_coi) +
/// sigma*s^2 (the Gaussian window, weighted by the growing past of exp(-sigma*t), looks
/// sigma*s^2 back) to the first time the envelope falls below floor_factor*noise_floor, and
/// at most T - coi_factor*tau_coi. noise_floor = min of two robust estimates of the RMS noise
/// of |W|: sqrt(noise gain) * sigma_n with sigma_n^2 = median_k |Y_k|^2 / (n ln 2) (white noise
/// makes |Y_k|^2 exponential with mean n*sigma_n^2; the median ignores the few peak bins), and
/// the median of |W| outside the COI / sqrt(ln 2) (Rayleigh median, right once a mode has
/// decayed into noise).
/// (5) Fit: weighted least-squares line ln|W| = a - sigma*t over the region with weights
/// |W|^2 (the variance of ln|W| is noise^2/(2|W|^2)); f_d from the weighted line fit of the
/// unwrapped phase of W (d phase/dt = 2*pi*f_d exactly for a decaying exponential);
/// xi = sigma / sqrt(sigma^2 + (2*pi*f_d)^2).
/// Why it is unbiased: for y = A exp(-sigma t) cos(w_d t) extending over the whole window,
/// W(tau) = A exp((-sigma + i w_d) tau) * exp(((-sigma + i w_d) s - i omega0)^2 / 2), so |W| is
/// exactly proportional to exp(-sigma tau) at any scale and any sigma; only the record's
/// edges (excluded above), noise and other modes (leakage) disturb it.
///
/// Returns false with *error (may be null) for invalid input: n < 64, sample_rate not finite
/// and > 0, a non-finite sample (its index is named), options.validate() failing, or
/// frequencies not in (0, fs/2) / f_min >= f_max. A mode whose fit fails (no decay region
/// outside the COI, too few samples, no decay) is still returned with NaN numbers and a
/// warning; *result is then otherwise complete and the call returns true.
bool analyzeWavelet(const double* y, long n, double sample_rate, const WaveletOptions& options,
                    WaveletResult* result, std::string* error);
bool analyzeWavelet(const std::vector<double>& y, double sample_rate,
                    const WaveletOptions& options, WaveletResult* result, std::string* error);
bool analyzeWavelet(const Eigen::VectorXd& y, double sample_rate, const WaveletOptions& options,
                    WaveletResult* result, std::string* error);

/// High-level entry point (the `analyze --wavelet` tool and the nodes): analyzeWavelet on
/// y[0..n) sampled at sample_rate [Hz], returning the result by value. Never throws for bad
/// input and never returns silent NaNs: on invalid input (options.validate() failing, a null
/// or too short signal (n < 64), a NaN/Inf sample (its index is named), a sample rate that is
/// not finite and > 0, a frequency grid or mode frequency at or above the Nyquist frequency)
/// the result has ok() == false, `error` says which field or sample is wrong and everything
/// else is empty. A mode whose fit fails has NaN numbers *and* a non-empty `warning`.
WaveletResult validateWavelet(const double* y, size_t n, double sample_rate,
                              const WaveletOptions& options = WaveletOptions());
WaveletResult validateWavelet(const std::vector<double>& y, double sample_rate,
                              const WaveletOptions& options = WaveletOptions());

/// Integral-method damping ratio xi = C / (2 * omega0) [-] for C = c / Me [1/s] and
/// omega0 = sqrt(mean(K)) = sqrt(k_mean / Me) [rad/s] (DESIGN.md §4 convention), shown beside
/// the wavelet's xi. NaN unless C is finite and omega0 finite and > 0.
double integralDampingRatio(double C_per_s, double omega0_rad_s);

/// Sets WaveletMode::integral_xi of every mode of `result` to xi_integral (the integral
/// method identifies one damping for the mesh mode; the wavelet may see several modes, and
/// the table shows the integral value beside each). No-op for a null result.
void attachIntegralDampingRatio(WaveletResult* result, double xi_integral);

/// Writes the table of modes (paper Table 2) as CSV with the header
///   frequency_hz,spectrum_frequency_hz,damping_ratio,integral_damping_ratio,sigma_per_s,r2,
///   t_start_s,t_end_s,omega0,peak_amplitude,noise_floor,warning
/// one row per mode (ascending frequency); NaN is written `nan`, the warning is quoted (any
/// '"' doubled). Returns "" on success, else a message.
std::string writeModesCsv(const WaveletResult& result, std::ostream& out);
std::string writeModesCsv(const WaveletResult& result, const std::string& path);

/// Writes the scalogram as CSV: a '#' comment line, then a numeric matrix M (comma-separated,
/// loadable with numpy.loadtxt(path, delimiter=',')): M[0][0] = M[0][1] = NaN, M[0][2:] = the
/// column times [s]; then one row per frequency: M[r][0] = frequency [Hz], M[r][1] = COI
/// half-width [s], M[r][2:] = |W|. Columns are block-averaged further so at most max_columns
/// remain. Returns "" on success, else a message (empty scalogram, I/O failure with the path).
std::string writeScalogramCsv(const WaveletResult& result, const std::string& path,
                              long max_columns = 2000);
std::string writeScalogramCsv(const WaveletResult& result, std::ostream& out,
                              long max_columns = 2000);

/// Writes the spectra as CSV with header `kind,frequency_hz,power`: rows of kind `psd`
/// (WaveletResult::spectrum_power [unit^2/Hz], up to the grid's highest frequency) then
/// `scalogram` (time-averaged scalogram [unit^2]). "" on success, else a message.
std::string writeSpectrumCsv(const WaveletResult& result, const std::string& path);
std::string writeSpectrumCsv(const WaveletResult& result, std::ostream& out);

}  // namespace gear_damping_id
