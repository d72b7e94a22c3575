// Morlet-wavelet validation of damping (paper section 4.3): spectra and automatic peak picking,
// decay regions and the envelope-decay damping ratio of each mode, with its quality warnings.
// Built on the CWT engine of morlet_cwt.hpp (whose header states the wavelet, scale, transform,
// bandwidth, cone-of-influence and padding conventions used here). No ROS; SI units; errors by
// return value, never by exceptions or printing.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "gear_damping_id/morlet_cwt.hpp"
#include "gear_damping_id/quality_warning.hpp"
#include "gear_sim/option_status.hpp"
#include "gear_sim/status.hpp"

namespace gear_damping_id {

/// Options of analyzeWavelet. Defaults suit free decays sampled at >= 10 samples per period of
/// the highest mode. check() checks everything that does not depend on the data.
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
  /// Peak picking. 0 (default) = adapts to the noise floor: a peak of the time-averaged
  /// scalogram at peak_omega0 becomes a mode when it rises above both its surrounding terrain
  /// and the white-noise level of that scalogram (g(f) * noise_std^2) by 6 standard deviations
  /// of the noise's time average, and its prominence is at least 1e-4 of the highest peak's
  /// amplitude (80 dB). > 0: the fixed rule of earlier versions, prominence (in amplitude =
  /// sqrt of the time-averaged scalogram) at least this fraction of the highest peak's amplitude
  /// (0.05 = -26 dB in power). Rule: 0 or in (0, 1).
  double peak_prominence = 0.0;
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
  /// need are transformed, and the spectra come from the signal's FFT alone; the wide rows'
  /// Parseval sums are binned and the envelope fits and noise medians use decimated grids: an
  /// estimator statistically indistinguishable from the full path (xi and f_d within 1/10 of
  /// its seed-to-seed scatter, the same decisions; docs/wavelet.md, "Speed"). Records of
  /// n >= 32768 take one FFT padded by n/512 (the PSD then on that grid; "shared mode").
  bool full_scalogram = true;
  /// Time columns kept in WaveletResult::modulus: block means of at most this many columns
  /// (0 = every sample). Rule: >= 0.
  long max_scalogram_columns = 2000;
  /// FFTW planning of the transforms. Estimate (default) plans instantly; Measure times FFTW's
  /// candidate algorithms once per FFT size and process (~0.1-5 s per size; instant from FFTW's
  /// wisdom, fftw_import_wisdom_from_filename) and pays off where the plans serve many
  /// transforms: repeated full scalograms of long records, and a WaveletAnalyzer reused on the
  /// per-mode path (its record transform's halves, decimated and blocked rows and low band;
  /// docs/wavelet.md "Speed"). A size keeps the plan it was first given in an analyzer. The
  /// results differ from Estimate's by FFT rounding (~1e-16 relative), and, as FFTW chooses by
  /// timing, from one process to the next unless its wisdom is shared; within a process they
  /// do not depend on the thread count.
  FftPlanning fft_planning = FftPlanning::Estimate;
  /// Threads of the full scalogram (rows in parallel, MorletScalogram; results identical to
  /// one thread). Rule: in [1, 256].
  int threads = 1;

  /// Minimum weighted R^2 of the ln-envelope line fit for a reported damping ratio (see
  /// docs/wavelet.md, "When to trust the numbers"): below it the mode carries `low_r2` and
  /// damping_ratio is NaN. 0.9: an exponential decay over >= 1 neper with the envelope >= 3x
  /// the noise floor (the region's end) fits with R^2 > 0.97; a forced line or a beating pair
  /// fits with R^2 near 0. Rule: in [0, 1).
  double min_r2 = 0.9;
  /// A free decay: the fitted envelope falls by at least this many nepers (a factor e^x) over
  /// its decay region. Less (a steady or growing envelope, or a record too short for this
  /// damping) is a forced line: free_decay = false, warning `not_free_decay`, damping_ratio
  /// NaN. Rule: finite and > 0.
  double min_decay_nepers = 1.0;
  /// Known forcing base frequencies [Hz] (mesh frequency, shaft frequencies; see
  /// gearOrderFrequencies): a mode within one frequency bin (sample_rate/n; plus its half-power
  /// half-width sigma/(2 pi) when its envelope decays) of an integer
  /// multiple of one of them whose envelope persists to the end of the record is a forced line
  /// (free_decay = false, warning `order_harmonic`, damping_ratio NaN); one that decays into the
  /// noise within the record is a transient and keeps its xi with `near_order_harmonic`. A base
  /// frequency whose harmonics are closer than 4 bins is not resolved by the record and is
  /// skipped with a global warning. When order frequencies are given, a mode decaying at the
  /// rate of a stronger mode (within 15 %), or lying k order frequencies (k != 0) from a stronger
  /// free decay (within one bin plus a quarter of the two lines' half-power half-widths: a side
  /// line of it), is flagged `shared_decay` with damping_ratio NaN (a parametrically modulated
  /// mode appears at several frequencies with one decay rate); a damping ratio whose decay
  /// region spans fewer than 2 periods of the highest order frequency keeps its value with
  /// `slow_modulation` (the envelope's jumps at the stiffness changes are not averaged).
  /// Rule: each finite and > 0.
  std::vector<double> order_frequencies;
  /// Floquet growth rates lambda [1/s] of the undamped mesh equation at the record's mesh
  /// frequency (gear_sim::parametricGrowthRate; `analyze` sets them from the gear parameters):
  /// one value for the whole record, or one per block of parametric_growth_block seconds from
  /// the record's first sample (the last block to the end; a speed ramp can cross an instability
  /// region); empty or 0 when not known or stable. Inside a parametric instability region the
  /// free response decays as exp(-(C/2 -+ lambda) t), not at the damping's C/2: a reported
  /// damping ratio whose sigma the largest lambda over its decay region exceeds 5 % of keeps its
  /// value with `parametric_resonance` (the text gives (sigma + lambda) / omega, the damping's
  /// ratio if the slower solution dominates). Rule: each finite and >= 0; with more than one
  /// value parametric_growth_block finite and > 0.
  std::vector<double> parametric_growth_rate;
  double parametric_growth_block = 0.0;  ///< [s] see parametric_growth_rate

  /// Status of these options: ok, or the first rule broken (field, value, rule; option_status.hpp).
  gear_sim::OptionStatus check() const;

 private:
  gear_sim::OptionStatus checkModesAndRules() const;  ///< second half of check()
};

/// One mode: frequency and damping from the decay of its wavelet envelope (paper Table 2).
/// damping_ratio is finite only for a trusted free decay: free_decay, R^2 >= min_r2 and the fit
/// succeeded; otherwise it is NaN and `warnings` says why (codes below, texts with the numbers,
/// including the apparent xi of a forced line).
/// Warning codes: `fit_failed` (no usable decay region, too short, phase not advancing),
/// `not_free_decay` (envelope decays by < min_decay_nepers), `order_harmonic` (a line at a
/// harmonic of an order frequency that persists), `shared_decay` (decays like a stronger mode,
/// or lies at a side-line position of one, under known parametric excitation), `low_r2`
/// (R^2 < min_r2), `overlapping_modes` (modal overlap (sigma_i + sigma_j)/(2 pi |f_i - f_j|) >
/// 0.3 with another mode: the envelope mixes both decays); flagged but kept: `close_modes` (a
/// neighbour leaks > 1 % into the row at the omega0 used), `near_order_harmonic` (a decaying
/// line at an order harmonic), `slow_modulation` (a decay region shorter than 2 periods of the
/// highest order frequency), `parametric_resonance` (the mesh stiffness is parametrically
/// unstable at this speed: WaveletOptions::parametric_growth_rate above 5 % of sigma).
struct WaveletMode {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double frequency_hz = kNaN;           ///< [Hz] damped frequency f_d from the ridge phase slope
  double spectrum_frequency_hz = kNaN;  ///< [Hz] spectral peak (parabolic interpolation)
  double damping_ratio = kNaN;   ///< [-] xi = sigma / sqrt(sigma^2 + (2*pi*f_d)^2), see above
  double sigma = kNaN;           ///< [1/s] fitted decay rate: envelope ~ exp(-sigma*t)
  double r2 = kNaN;              ///< [-] weighted R^2 of the ln(envelope) line fit
  double t_start = kNaN;         ///< [s] decay region used
  double t_end = kNaN;           ///< [s]
  double peak_amplitude = kNaN;  ///< [unit of y] maximum of the envelope |W| on the mode's row
  double noise_floor = kNaN;     ///< [unit of y] RMS noise level of |W| on the mode's row
  double omega0 = kNaN;          ///< Morlet omega0 used for the fit
  double integral_xi = kNaN;     ///< [-] integral-method xi = C/(2*omega_n), filled by callers
  /// True when the envelope really decays (by >= min_decay_nepers over its region) and the line
  /// is not a harmonic of a known order frequency; false for a forced line or a failed fit.
  bool free_decay = true;
  QualityWarnings warnings;  ///< empty when the mode's estimate is clean
};

/// Everything analyzeWavelet computes. Frequencies [Hz], times [s], amplitudes in y's unit.
struct WaveletResult {
  std::vector<double> frequencies;  ///< scalogram rows [Hz], ascending
  std::vector<double> coi;          ///< cone-of-influence half-width per row [s]
  double omega0 = 0.0;              ///< omega0 of the scalogram
  /// Scalogram |W|, row-major [row][column]; empty unless options.full_scalogram. Column c is
  /// the mean of |W| over samples [c*d, min((c+1)*d, n)) with d = scalogram_decimation, at time
  /// scalogram_times[c] (mean time of its samples).
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> modulus;
  std::vector<double> scalogram_times;
  long scalogram_decimation = 1;
  /// One-sided power spectral density of the mean-removed record without window (a free decay
  /// is its own window; a Hann window would suppress the start where it carries its energy):
  /// psd_k = 2*|Y_k|^2 / (n*fs) [unit^2/Hz] on the zero-padded grid f_k = k*fs/N (N: the
  /// scalogram grid's padding, or the per-mode path's shared transform's; docs/wavelet.md).
  std::vector<double> spectrum_freq, spectrum_power;
  /// Time-averaged scalogram (MorletCwt::meanPower) on `frequencies` [unit^2].
  std::vector<double> scalogram_power;
  /// Peak-picking spectrum: time-averaged scalogram at options.peak_omega0 [unit^2] on a log
  /// grid peak_freq [Hz] (relative step <= 1/(4*peak_omega0)) spanning `frequencies`.
  std::vector<double> peak_freq, peak_power;
  double noise_std = 0.0;  ///< [unit of y] white-noise estimate per sample (see analyzeWavelet)
  std::vector<WaveletMode> modes;     ///< ascending frequency
  std::vector<std::string> warnings;  ///< global remarks (modes also carry their own)
  /// Ok on success; otherwise why the analysis could not run (validateWavelet only:
  /// analyzeWavelet returns its Status). When not ok, everything else is empty.
  gear_sim::Status status;
  bool ok() const { return status.ok(); }
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
/// (6) Trust checks (WaveletMode): forced line (harmonic of options.order_frequencies, or an
/// envelope decaying by < min_decay_nepers over its region), R^2 >= min_r2, close modes.
/// Why it is unbiased: for y = A exp(-sigma t) cos(w_d t) extending over the whole window,
/// W(tau) = A exp((-sigma + i w_d) tau) * exp(((-sigma + i w_d) s - i omega0)^2 / 2), so |W| is
/// exactly proportional to exp(-sigma tau) at any scale and any sigma; only the record's
/// edges (excluded above), noise and other modes (leakage) disturb it.
///
/// Returns InvalidArgument naming the field for invalid input: n < 64, sample_rate not finite
/// and > 0, options.check() failing, or frequencies not in (0, fs/2) / f_min >= f_max;
/// InvalidInput for a non-finite sample (its index is named). A mode whose fit fails (no decay
/// region outside the COI, too few samples) is still returned with NaN numbers and a
/// `fit_failed` warning; *result is then otherwise complete and the call returns ok.
gear_sim::Status analyzeWavelet(const double* y, long n, double sample_rate,
                                const WaveletOptions& options, WaveletResult* result);
gear_sim::Status analyzeWavelet(const std::vector<double>& y, double sample_rate,
                                const WaveletOptions& options, WaveletResult* result);
gear_sim::Status analyzeWavelet(const Eigen::VectorXd& y, double sample_rate,
                                const WaveletOptions& options, WaveletResult* result);

/// analyzeWavelet with reusable state: keeps the FFTW plans, the FFT buffers and the scratch
/// vectors of its last call (and reuses the capacity of the result passed in), so repeated
/// analyses of records of the same length, sample rate and grid (a node, a benchmark) skip
/// FFTW planning and the kernel's zeroing of fresh pages. Results are bit-identical to
/// analyzeWavelet's (tested). It holds about three FFT buffers of the padded length (~70 MB
/// for 1e6 samples with the default grid) until destroyed. One object per thread.
class WaveletAnalyzer {
 public:
  WaveletAnalyzer();
  ~WaveletAnalyzer();
  WaveletAnalyzer(WaveletAnalyzer&&) noexcept;
  WaveletAnalyzer& operator=(WaveletAnalyzer&&) noexcept;
  WaveletAnalyzer(const WaveletAnalyzer&) = delete;
  WaveletAnalyzer& operator=(const WaveletAnalyzer&) = delete;

  /// Same contract as analyzeWavelet.
  gear_sim::Status analyze(const double* y, long n, double sample_rate,
                           const WaveletOptions& options, WaveletResult* result);

 private:
  struct Workspace;
  std::unique_ptr<Workspace> ws_;
};

/// High-level entry point (the `analyze --wavelet` tool and the nodes): analyzeWavelet on
/// y[0..n) sampled at sample_rate [Hz], returning the result by value. Never throws for bad
/// input and never returns silent NaNs: on invalid input (options.check() failing, a null
/// or too short signal (n < 64), a NaN/Inf sample (its index is named), a sample rate that is
/// not finite and > 0, a frequency grid or mode frequency at or above the Nyquist frequency)
/// the result has ok() == false, `status` says which field or sample is wrong and everything
/// else is empty. A mode without a trusted damping ratio has damping_ratio NaN *and* non-empty
/// `warnings`.
WaveletResult validateWavelet(const double* y, size_t n, double sample_rate,
                              const WaveletOptions& options = WaveletOptions());
WaveletResult validateWavelet(const std::vector<double>& y, double sample_rate,
                              const WaveletOptions& options = WaveletOptions());

/// Integral-method damping ratio xi = C / (2 * omega0) [-] for C = c / Me [1/s] and
/// omega0 = sqrt(mean(K)) = sqrt(k_mean / Me) [rad/s] (docs/method.md §4 convention), shown beside
/// the wavelet's xi. NaN unless C is finite and omega0 finite and > 0.
double integralDampingRatio(double C_per_s, double omega0_rad_s);

/// Sets WaveletMode::integral_xi of every mode of `result` to xi_integral (the integral
/// method identifies one damping for the mesh mode; the wavelet may see several modes, and
/// the table shows the integral value beside each). No-op for a null result.
void attachIntegralDampingRatio(WaveletResult* result, double xi_integral);

/// The warnings as one line "code: text; code: text" (empty when none), for one-string outputs.
std::string warningText(const QualityWarnings& warnings);

/// Order frequencies of a gear pair for WaveletOptions::order_frequencies: the mesh frequency
/// [Hz] and the two shaft frequencies f_mesh/Z1, f_mesh/Z2 (teeth <= 0: omitted). Empty when
/// the mesh frequency is not finite and > 0.
std::vector<double> gearOrderFrequencies(double mesh_frequency_hz, int pinion_teeth,
                                         int gear_teeth);

}  // namespace gear_damping_id
