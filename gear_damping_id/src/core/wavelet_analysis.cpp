// Morlet-wavelet damping analysis: see wavelet_analysis.hpp for the contracts. analyzeWavelet
// is a short sequence of named steps: check the input, build the grid, spectra and noise,
// scalogram, peak spectrum, modes, and per mode: omega0, envelope fit, trust checks.
#include "gear_damping_id/wavelet_analysis.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstring>
#include <future>
#include <memory>
#include <type_traits>

#include "decimated_row.hpp"
#include "gear_sim/async.hpp"
#include "halved_forward.hpp"
#include "vector_math.hpp"
#include "wavelet_detail.hpp"

namespace gear_damping_id {
namespace {

using gear_sim::Status;
using wavelet_detail::kNaN;
using wavelet_detail::kPi;
using wavelet_detail::median;
using wavelet_detail::medianInPlace;
using wavelet_detail::modulusOf;
using wavelet_detail::num;

// Automatic fit omega0: neighbours leak < kLeakTarget into a mode's row; a `close_modes`
// warning is given when the leakage at the omega0 used exceeds kLeakWarn.
constexpr double kLeakTarget = 1e-3;
constexpr double kLeakWarn = 1e-2;
// Automatic fit omega0 is lowered until xi*omega0 <= kMaxXiOmega0 (sigma*s <= 0.25: the
// wavelet's Gaussian spans a quarter of an envelope time constant), but not below
// kMinFitOmega0 (below 3 the analytic Morlet's cut at zero frequency is no longer negligible:
// Psi(0) = 2 exp(-4.5) = 2 % of its peak).
constexpr double kMaxXiOmega0 = 0.25;
constexpr double kMinFitOmega0 = 3.0;
constexpr long kMinSamples = 64;
constexpr long kMinRegionSamples = 16;
// Automatic peak picking (peak_prominence = 0): a peak of the time-averaged scalogram P(f) at
// peak_omega0 is a mode when it rises above both its surrounding terrain and the white-noise
// level Pn(f) = g(f) sigma_n^2 by kPeakNoiseZ standard deviations of the noise's time average.
// That average has about T / (sqrt(2 pi) s) independent values (the autocorrelation of |W|^2 of
// white noise is exp(-tau^2/(2 s^2)), of integral sqrt(2 pi) s), so its relative standard
// deviation is rel(f) = sqrt(sqrt(2 pi) s / T). 6 standard deviations: with ~100 independent
// bands on the default grid a noise peak passes with probability < 1e-4 even for the
// heavy-tailed chi-square of ~12 degrees of freedom at the lowest frequency.
constexpr double kPeakNoiseZ = 6.0;
// ... and whose prominence is at least kMinRelativeProminence of the highest peak's amplitude
// (80 dB in power: the dynamic range left when the noise estimate is the rounding floor of a
// noise-free record).
constexpr double kMinRelativeProminence = 1e-4;
// A forced line lies within kOrderToleranceBins frequency bins (1/T) (plus its half-power
// half-width sigma/(2 pi) when it decays) of a harmonic of an order frequency and persists to the
// end of the record; order frequencies whose harmonics are closer than kOrderMinSpacingBins bins
// are not resolved by the record and are skipped (with a global warning).
constexpr double kOrderToleranceBins = 1.0;
constexpr double kOrderMinSpacingBins = 4.0;
// With known order frequencies (a parametrically excited machine), a mode that decays at the
// rate of a stronger mode (within kSharedDecayTol) is flagged `shared_decay`: the free response
// of a mode whose stiffness is modulated is one decay seen at several frequencies (Floquet
// lines, or ripples of one broad line), and xi = sigma/omega at a line that is not the mode is
// no modal damping ratio. Two independent modes of equal decay rate are flagged too (the data
// cannot tell them apart); hence only when parametric excitation is known to be present.
constexpr double kSharedDecayTol = 0.15;
// The same modulated mode is also seen as side lines at k order frequencies (k != 0) from its
// main line, whatever decay rate the side line's own fit finds (its envelope is the weaker one,
// mixed with its neighbours' skirts: 16-45 % off the main line's sigma in held-out free
// responses). A weaker line within kOrderToleranceBins bins plus kSideLineWidthShare of the two
// lines' half-power half-widths (sigma_i + sigma_j)/(2 pi) of such a position (ridge frequencies)
// is flagged `shared_decay` too; order frequencies below kOrderMinSpacingBins times that
// tolerance are not resolved for this test. 0.25: of the 127 lines the decay-rate rule flags in
// 180 held-out gear free responses, 117 lie within 0.25 of the half-widths of such a position
// (median 0.024).
constexpr double kSideLineWidthShare = 0.25;
// With known order frequencies, a decay region shorter than kMinModulationPeriods periods of
// the highest of them (the mesh frequency of a gear pair) sees fewer than 2 kMinModulationPeriods
// switches of a square stiffness: the envelope's jumps at the switches (up to half the log of the
// stiffness ratio, in nepers) are not averaged over the mesh cycle and bias sigma
// (`slow_modulation`, damping ratio kept). In 180 held-out gear free responses the strongest
// lines with such a region were off the truth by 14 % rms (7 of 38 beyond the 10 % bar), those
// with a longer one by 5.5 % (3 of 46).
constexpr double kMinModulationPeriods = 2.0;
// A parametric instability's growth rate lambda (WaveletOptions::parametric_growth_rate) above
// this share of a mode's sigma: its decay is C/2 -+ lambda, off the damping's by more than half
// the gear case's 10 % bar (`parametric_resonance`, damping ratio kept).
constexpr double kParametricShare = 0.05;
// Modal overlap (sigma_i + sigma_j) / (2 pi |f_i - f_j|): the sum of the two lines' half-power
// half-widths over their spacing. Above kMaxModalOverlap the Lorentzian skirts of a heavily
// damped neighbour reach the mode's row far beyond the wavelet's Gaussian leakage estimate
// (the `close_modes` check) and the envelope is no longer one exponential:
// `overlapping_modes`, damping ratio NaN. 0.3: the mwdi-style multi-sine (0.18-0.19 for
// 600/800 Hz at xi 0.02-0.03) is estimated within 1 %; the square-wave gear case's free
// response (0.3-1.0) is biased by 20 %.
constexpr double kMaxModalOverlap = 0.3;

// ------------------------------------------------------------------------------------------
// Option checks: every violation is a gear_sim::OptionStatus of WaveletOptions.

template <class T>
gear_sim::OptionStatus violated(const std::string& field, const T& value, const std::string& rule) {
  return gear_sim::violated("WaveletOptions", field, value, rule);
}

struct Peak {
  int index;
  double frequency, amplitude, prominence;
};

// Local maxima of v with their topographic prominence (height above the higher of the lowest
// points between the peak and higher terrain, or the end of the array, on either side).
std::vector<Peak> findPeaks(const std::vector<double>& f, const std::vector<double>& v) {
  std::vector<Peak> peaks;
  const int n = static_cast<int>(v.size());
  for (int i = 1; i + 1 < n; ++i) {
    if (!(v[i] > v[i - 1] && v[i] >= v[i + 1])) continue;
    double left_min = v[i], right_min = v[i];
    for (int j = i - 1; j >= 0 && v[j] <= v[i]; --j) left_min = std::min(left_min, v[j]);
    for (int j = i + 1; j < n && !(v[j] > v[i]); ++j) right_min = std::min(right_min, v[j]);
    peaks.push_back({i, f[static_cast<size_t>(i)], v[i], v[i] - std::max(left_min, right_min)});
  }
  return peaks;
}

// Sums over i < n in four partial sums (lane i mod 4), added in a fixed order: independent
// chains, so a loop runs at the adders' throughput instead of their latency. add(i, lanes, q)
// adds term i into lane q of each of its C sums; the blocks of four unrolled, so the lanes
// stay in registers. total(c) is sum c.
template <int C>
struct Lanes4 {
  double s[C][4] = {};
  template <typename Add>
  void run(long n, Add add) {
    long i = 0;
    for (; i + 4 <= n; i += 4) {
#pragma GCC unroll 4
      for (int q = 0; q < 4; ++q) add(i + q, s, q);
    }
    for (; i < n; ++i) add(i, s, static_cast<int>(i & 3));
  }
  double total(int c) const { return (s[c][0] + s[c][2]) + (s[c][1] + s[c][3]); }
};

// Weighted least-squares lines through (x_i, a_i) and (x_i, p_i), weights w_i: both slopes, and
// the weighted R^2 of the first (NaN where the weights or the spread of x vanish).
struct DecayLines {
  double amp_slope = kNaN, amp_r2 = kNaN, phase_slope = kNaN;
};
DecayLines fitDecayLines(const double* x, const double* a, const double* p, const double* w,
                         long n) {
  DecayLines out;
  Lanes4<4> m;  // sums of w, w x, w a, w p
  m.run(n, [&](long i, double(*s)[4], int q) {
    s[0][q] += w[i], s[1][q] += w[i] * x[i], s[2][q] += w[i] * a[i], s[3][q] += w[i] * p[i];
  });
  const double W = m.total(0);
  if (!(W > 0.0)) return out;
  const double mx = m.total(1) / W, ma = m.total(2) / W, mp = m.total(3) / W;
  Lanes4<4> c;  // sums of w dx dx, w dx da, w da da, w dx dp
  c.run(n, [&](long i, double(*s)[4], int q) {
    const double dx = x[i] - mx, da = a[i] - ma, wdx = w[i] * dx;
    s[0][q] += wdx * dx, s[1][q] += wdx * da, s[2][q] += w[i] * da * da;
    s[3][q] += wdx * (p[i] - mp);
  });
  const double Sxx = c.total(0), Saa = c.total(2);
  if (!(Sxx > 0.0)) return out;
  out.amp_slope = c.total(1) / Sxx;
  out.phase_slope = c.total(3) / Sxx;
  const double b0 = ma - out.amp_slope * mx, b1 = out.amp_slope;
  Lanes4<1> res;
  res.run(n, [&](long i, double(*s)[4], int q) {
    const double r = a[i] - b0 - b1 * x[i];
    s[0][q] += w[i] * r * r;
  });
  out.amp_r2 = Saa > 0.0 ? 1.0 - res.total(0) / Saa : 1.0;
  return out;
}

// One mode to fit: spectral frequency, amplitude in the peak spectrum, optional fixed region.
struct ModeSeed {
  double f_spec, amplitude;
  const std::pair<double, double>* region;
};

// Result of the fit on one row. `ok`: sigma, f_d and R^2 are finite (sigma may be <= 0: a
// steady or growing envelope, classified later). `why`: the reason when not ok.
struct RowFit {
  bool ok = false;
  std::string why;
  double sigma = kNaN, xi = kNaN, fd = kNaN, r2 = kNaN, t0 = kNaN, t1 = kNaN;
  double peak = kNaN, floor = kNaN;
  bool reached_floor = false;  // the automatic region ended where the envelope met the floor
};

// One row's envelope and where the fit may look: everything the decay-region step needs.
// The row is known at the samples 0, D, 2D, ... (w[m] = W at sample m*D, `points` values):
// every sample (D = 1) on the full path, the row's decimated grid on the per-mode path
// (docs/wavelet.md "Speed").
struct RowEnvelope {
  const std::complex<double>* w = nullptr;
  long n = 0, D = 1, points = 0;
  double fs = 0.0, f = 0.0, omega0 = 0.0, s = 0.0, coi = 0.0;
  long j_peak = 0;    // sample index of the envelope's maximum
  bool full = false;  // the full path's row (every sample, medians over every sample)
  // Per-mode path, D = 1: w and |W| are computed on demand (BlockedRow, see prepareBlockedRow);
  // null: every point is there.
  wavelet_detail::BlockedRow* fine = nullptr;
  // Makes the points [m, m1] valid (on demand: a block's worth from m on); the last one made valid.
  long ready(long m, long m1) const {
    if (!fine) return m1;
    const long e = std::min(m1, m + kReadyChunk - 1);
    fine->ensure(m, e);
    return e;
  }
  static constexpr long kReadyChunk = 4096;
};

// The per-mode path's grid: every D-th sample, D = the largest divisor of the FFT length <=
// s*fs/kFitSamplesPerScale (at least 1). 16 samples per scale keep the per-mode path within its
// contract (docs/wavelet.md "Speed": within 1/10 of the full path's seed-to-seed scatter; the
// gear case at 40 dB, whose region end follows the grid, uses 0.07 of it); 12 or 8 samples per
// scale break it there (1.3 / 0.14 of the scatter), the band's rate (~2.7 per scale) by 3.4.
constexpr double kFitSamplesPerScale = 16.0;

// First grid point at or after sample j (j >= 0), last at or before it.
long gridCeil(long j, long D) { return (j + D - 1) / D; }
long gridFloor(long j, long D) { return j / D; }

// Median of count non-negative values v[0], v[stride], ..., v[(count-1)*stride]: the upper
// middle element, exactly wavelet_detail::medianInPlace's value, without copying or reordering
// them. The bit patterns of non-negative doubles sort like their values, so one pass counts the
// values per 16-bit prefix (sign, exponent, 4 mantissa bits), a second gathers the bucket that
// holds the median, and nth_element runs on that bucket alone (1e6 values: ~2 ms instead of
// ~12 ms of nth_element on all). Falls back to nth_element on a copy for short inputs or a value
// with its sign bit set. The histogram and the bucket are kept per thread (no allocation once
// warm).
template <typename T>
double medianOfNonNegative(const T* v, long count, long stride) {
  static_assert(sizeof(T) == 4 || sizeof(T) == 8, "float or double");
  using Bits = typename std::conditional<sizeof(T) == 8, uint64_t, uint32_t>::type;
  if (count <= 0) return kNaN;
  static thread_local std::vector<uint32_t> hist;
  static thread_local std::vector<T> bucket;
  const long k = count / 2;
  auto bits = [](T x) {
    Bits b;
    std::memcpy(&b, &x, sizeof b);
    return b;
  };
  constexpr int kShift = 8 * static_cast<int>(sizeof(T)) - 16;
  constexpr Bits kSignBucket = Bits(1) << 15;
  bool fallback = count < 4096;
  if (!fallback) {
    hist.assign(size_t(1) << 16, 0u);
    for (long i = 0; i < count; ++i) ++hist[bits(v[i * stride]) >> kShift];
    long below = 0;
    Bits b = 0;
    for (; b < kSignBucket; ++b) {
      if (below + static_cast<long>(hist[b]) > k) break;
      below += hist[b];
    }
    if (b < kSignBucket) {
      bucket.clear();
      for (long i = 0; i < count; ++i) {
        const T x = v[i * stride];
        if ((bits(x) >> kShift) == b) bucket.push_back(x);
      }
      const auto mid = bucket.begin() + (k - below);
      std::nth_element(bucket.begin(), mid, bucket.end());
      return static_cast<double>(*mid);
    }
    fallback = true;  // the median lies among values with the sign bit set
  }
  bucket.resize(static_cast<size_t>(count));
  for (long i = 0; i < count; ++i) bucket[static_cast<size_t>(i)] = v[i * stride];
  return medianInPlace(&bucket);
}

// The row's noise median on the per-mode path takes every k-th point of its grid, k =
// s*fs/(D*kMedianPointsPerScale) (at least 1): |W| of noise is correlated over ~s, so 4 points
// per scale hold nearly all its independent values (the full path: every sample).
constexpr double kMedianPointsPerScale = 4.0;
long medianStride(const RowEnvelope& r) {
  if (r.full) return 1;
  const double k = r.s * r.fs / (static_cast<double>(r.D) * kMedianPointsPerScale);
  return std::max(1L, static_cast<long>(k));
}

// Noise floor of |W| on a row (RMS of |W| for noise alone): the smaller of the spectral estimate
// sqrt(gain) * sigma_n and the Rayleigh median of |W| outside the COI (right once the mode has
// decayed into the noise).
double rowNoiseFloor(const RowEnvelope& r, const std::vector<double>& env, double noise_gain,
                     double noise_std, const WaveletOptions& opt) {
  const double t_last = static_cast<double>(r.n - 1) / r.fs;
  const double lo = opt.coi_factor * r.coi, hi = t_last - opt.coi_factor * r.coi;
  const double floor_spec = std::sqrt(noise_gain) * noise_std;
  const long a = static_cast<long>(std::ceil(std::max(0.0, lo) * r.fs));
  const long b = static_cast<long>(std::floor(std::max(0.0, hi) * r.fs));
  if (b <= a) return floor_spec;
  // Per-mode path: the median of every k-th grid point in [a, b] (medianStride).
  const long m0 = gridCeil(a, r.D), m1 = std::min(gridFloor(b, r.D), r.points - 1);
  if (m1 < m0) return floor_spec;
  const long k = medianStride(r);
  const double med = medianOfNonNegative(env.data() + m0, (m1 - m0) / k + 1, k);
  return std::min(floor_spec, med / std::sqrt(std::log(2.0)));
}

// Decay region [t0, t1] of a row: the given one (clipped to the record), or from
// max(coi_factor*tau_coi, t_peak + tau_coi) + sigma*s^2 to the first time the envelope falls
// below floor_factor * floor, at most T - coi_factor*tau_coi. False + out->why when none.
bool decayRegion(const RowEnvelope& r, const std::vector<double>& env, double sigma_guess,
                 const std::pair<double, double>* region, const WaveletOptions& opt, RowFit* out) {
  const double dt = 1.0 / r.fs, t_last = static_cast<double>(r.n - 1) * dt;
  if (region) {
    out->t0 = std::max(0.0, region->first);
    out->t1 = std::min(t_last, region->second);
    if (out->t1 > out->t0) return true;
    out->why = "decay region [" + num(region->first) + ", " + num(region->second) +
               "] s lies outside the record [0, " + num(t_last) + "] s";
    return false;
  }
  const double lo_coi = opt.coi_factor * r.coi, hi_coi = t_last - opt.coi_factor * r.coi;
  if (!(hi_coi > lo_coi)) {
    out->why = "record too short: the cone of influence (" + num(opt.coi_factor) + " x " +
               num(r.coi) + " s at each end) covers it";
    return false;
  }
  const double shift = std::isfinite(sigma_guess) ? std::max(0.0, sigma_guess) * r.s * r.s : 0.0;
  const double t0 = std::max(lo_coi, static_cast<double>(r.j_peak) * dt + r.coi) + shift;
  double t1 = hi_coi;
  const double limit = opt.floor_factor * out->floor;
  // On the row's grid (every sample when D = 1): the first point at or after t0, and the
  // region ends at the last point before the first one below the limit.
  const long m0 = gridCeil(std::max(0L, static_cast<long>(std::ceil(t0 * r.fs))), r.D);
  const long m1 = gridFloor(static_cast<long>(std::floor(t1 * r.fs)), r.D);
  if (m0 <= m1 && m0 < r.points) r.ready(m0, m0);
  if (m0 <= m1 && m0 < r.points && env[static_cast<size_t>(m0)] < limit) {
    out->why = "envelope is below " + num(opt.floor_factor) + " x noise floor (" + num(out->floor) +
               ") at the start of the decay region (" + num(t0) + " s)";
    return false;
  }
  long valid = m0 - 1;  // points up to here are computed (every point unless r.fine)
  for (long m = m0; m <= m1 && m < r.points; ++m) {
    if (m > valid) valid = r.ready(m, std::min(m1, r.points - 1));
    if (env[static_cast<size_t>(m)] < limit) {
      t1 = static_cast<double>((m - 1) * r.D) * dt;
      out->reached_floor = true;
      break;
    }
  }
  out->t0 = t0;
  out->t1 = t1;
  return true;
}

// Quadrature points of the region of samples [j0, j1] on the row's grid (samples m*D): the
// grid points m0*D <= ... <= m1*D inside it with the trapezoid rule's weights D, the first and
// last widened to the region's ends (weight D/2 + (m0*D - j0) + 1/2 and D/2 + (j1 - m1*D) +
// 1/2: the half sample the full sum has beyond its end samples, and the samples between the
// region's ends and the outermost grid points, taken at those points); the weights sum to
// j1 - j0 + 1, the full sum's count. With D = 1 every sample, weight 1.
// The decimated row is the signal filtered by the wavelet, whose spectrum is a Gaussian of
// standard deviation 1/s in omega, sampled at its band's rate (see fitModes): the line fits'
// integrands that are linear or quadratic in W (|W|^2, Re/Im cross terms with the noise) have
// spectra within twice that band, where the trapezoid sum of the points equals the full sum up
// to the Gaussian at the grid's sampling frequency (< e^-30); ln|W| and the phase are
// nonlinear in W and their spectra wider (where the envelope jumps or nears zero). Measured
// against the full path in PerModePathMatchesTheFullPathOnThreeModes and the gear case.
struct RegionPoints {
  long j0, j1, D, m0, m1;
  RegionPoints(long j0_, long m, long D_)
      : j0(j0_), j1(j0_ + m - 1), D(D_), m0(gridCeil(j0_, D_)), m1(gridFloor(j0_ + m - 1, D_)) {}
  long count() const { return std::max(0L, m1 - m0 + 1); }
  double weight(long i) const {
    if (m0 == m1) return static_cast<double>(j1 - j0 + 1);
    const double half = 0.5 * static_cast<double>(D);
    if (i == 0) return half + static_cast<double>(m0 * D - j0) + 0.5;
    if (i == m1 - m0) return half + static_cast<double>(j1 - m1 * D) + 0.5;
    return static_cast<double>(D);
  }
};

// Weighted line fits over [t0, t1]: ln|W| = a - sigma*t (weights |W|^2, the inverse variance
// of ln|W| under additive noise) and the unwrapped phase (slope 2*pi*f_d), on the samples of
// the region (D = 1) or on its decimated quadrature points (D > 1; the phase is unwrapped about
// the advance 2*pi*f*step/fs of the row's frequency f, which the ridge phase follows within
// its bandwidth f/omega0, far inside the half turn unwrapping allows).
// ln of the noise-corrected envelope and the raw phase arg W of a prepared row's grid points
// [c0, c1], kept for the row's second fit pass, whose region lies inside the first's (the same
// values: no log or atan2 computed twice). Emptied (c1 < c0) by prepareRow.
struct PointCache {
  long c0 = 0, c1 = -1;
  std::vector<double> ly, arg;
};

void envelopeFit(const RowEnvelope& r, const std::vector<double>& env, long j0, long m,
                 std::vector<double>* work, PointCache* cache, RowFit* out) {
  const long D = r.D;
  const RegionPoints pts(j0, m, D);
  const long np = pts.count();
  work->resize(static_cast<size_t>(3 * np));
  double* x = work->data();
  double* ph = x + np;
  double* wt = ph + np;
  Lanes4<1> lane_max;  // in lanes: no chain through one register (the same maximum)
  const double* e_reg = env.data() + pts.m0;
  lane_max.run(np, [&](long i, double(*s)[4], int q) { s[0][q] = std::max(s[0][q], e_reg[i]); });
  const double(&lm)[4] = lane_max.s[0];
  const double emax = std::max(std::max(lm[0], lm[1]), std::max(lm[2], lm[3]));
  if (!(emax > 0.0)) {
    out->why = "envelope is zero in the decay region";
    return;
  }
  // The noise adds its power to the envelope's: E|W|^2 = |W_mode|^2 + floor^2, which lifts the
  // region's tail (by 6 % in ln|W| at 3x the floor) and biases sigma low. The fit uses the
  // noise-corrected envelope sqrt(|W|^2 - floor^2).
  const double floor2 = std::isfinite(out->floor) ? out->floor * out->floor : 0.0;
  const double turn = 2.0 * kPi * r.f / r.fs;  // phase advance of the row's frequency per sample
  if (!(cache->c0 <= pts.m0 && pts.m0 + np - 1 <= cache->c1)) {
    cache->c0 = pts.m0;
    cache->c1 = pts.m0 + np - 1;
    cache->ly.resize(static_cast<size_t>(np));
    cache->arg.resize(static_cast<size_t>(np));
    wavelet_detail::logEnvelopeAndPhase(env.data() + pts.m0, r.w + pts.m0, np, floor2,
                                        cache->ly.data(), cache->arg.data());
  }
  const double* ly = cache->ly.data() + (pts.m0 - cache->c0);
  const double* arg = cache->arg.data() + (pts.m0 - cache->c0);
  // x in samples from the region's first (exact integers; the slopes are per sample, scaled
  // to seconds below), the weights relative to the largest.
  double prev = 0.0, offset = 0.0;
  const double inv_e2max = 1.0 / (emax * emax), inv_turn = 1.0 / (2.0 * kPi);
  for (long i = 0; i < np; ++i) {
    const long g = pts.m0 + i, j = g * D;  // grid point, sample
    const double e = env[static_cast<size_t>(g)];
    const double e2 = std::max(e * e - floor2, 1e-300);
    x[i] = static_cast<double>(j - j0);
    wt[i] = e2 * inv_e2max * (D > 1 ? pts.weight(i) : 1.0);
    const double p = arg[i];
    if (D > 1) {
      if (i > 0) {
        const double pred = turn * static_cast<double>(D);
        double d = p - prev - pred;
        d -= 2.0 * kPi * std::round(d * inv_turn);
        ph[i] = ph[i - 1] + pred + d;
      } else {
        ph[i] = p;
      }
      prev = p;
      continue;
    }
    if (i > 0) {
      const double d = p - prev;
      if (d > kPi) offset -= 2.0 * kPi;
      if (d < -kPi) offset += 2.0 * kPi;
    }
    prev = p;
    ph[i] = p + offset;
  }
  const DecayLines lines = fitDecayLines(x, ly, ph, wt, np);
  out->sigma = -lines.amp_slope * r.fs;
  out->r2 = lines.amp_r2;
  out->fd = lines.phase_slope * r.fs / (2.0 * kPi);
  if (!std::isfinite(out->sigma)) {
    out->why = "the envelope line fit failed in [" + num(out->t0) + ", " + num(out->t1) + "] s";
    return;
  }
  if (!(out->fd > 0.0)) {
    out->why = "ridge phase does not advance (f_d = " + num(out->fd) + " Hz)";
    return;
  }
  const double wd = 2.0 * kPi * out->fd;
  out->xi = out->sigma / std::sqrt(out->sigma * out->sigma + wd * wd);
  out->ok = true;
}

// Makes *v hold at least n values without shrinking it: the rows' |W| scratch alternates between
// rows of different lengths (noise row, decimated and full fit rows), and resize() would zero
// every value past the previous size on each growth. Only the first n values are meaningful.
void growScratch(std::vector<double>* v, long n) {
  if (v->size() < static_cast<size_t>(n)) v->resize(static_cast<size_t>(n));
}

// One row's envelope |W|, its peak and noise floor: what every fit on that row shares (the
// two passes of fitAt reuse it instead of recomputing |W|, its maximum and its median).
struct PreparedRow {
  RowEnvelope row;
  double peak = kNaN, floor = kNaN;
  PointCache* cache = nullptr;  // the fits' ln|W| and arg W (emptied here)
};

PreparedRow prepareRow(const RowEnvelope& r, double noise_gain, double noise_std,
                       const WaveletOptions& opt, std::vector<double>* env_scratch,
                       PointCache* cache) {
  PreparedRow p;
  p.cache = cache;
  cache->c1 = cache->c0 - 1;
  std::vector<double>& env = *env_scratch;
  growScratch(&env, r.points);
  modulusOf(reinterpret_cast<const double*>(r.w), r.points, env.data());
  p.row = r;
  const long g =
      static_cast<long>(std::max_element(env.begin(), env.begin() + r.points) - env.begin());
  p.row.j_peak = g * r.D;
  p.peak = env[static_cast<size_t>(g)];
  p.floor = rowNoiseFloor(p.row, env, noise_gain, noise_std, opt);
  return p;
}

// Decay region and fits on a prepared row (env: its |W| from prepareRow).
RowFit fitRow(const PreparedRow& p, const std::vector<double>& env, double sigma_guess,
              const std::pair<double, double>* region, const WaveletOptions& opt,
              std::vector<double>* work) {
  RowFit out;
  const RowEnvelope& r = p.row;
  out.peak = p.peak;
  out.floor = p.floor;
  if (!decayRegion(r, env, sigma_guess, region, opt, &out)) return out;
  const long j0 = std::max(0L, static_cast<long>(std::ceil(out.t0 * r.fs)));
  const long j1 = std::min(r.n - 1, static_cast<long>(std::floor(out.t1 * r.fs)));
  const long m = j1 - j0 + 1;
  if (m < kMinRegionSamples || (!region && (out.t1 - out.t0) < r.s)) {
    out.why = "decay region [" + num(out.t0) + ", " + num(out.t1) + "] s is too short (" +
              std::to_string(std::max(0L, m)) +
              " samples; needs >= " + std::to_string(kMinRegionSamples) +
              " and >= one wavelet scale " + num(r.s) + " s)";
    return out;
  }
  if (r.fine) r.fine->ensure(j0, j1);  // a given region (decayRegion's scan made its own)
  envelopeFit(r, env, j0, m, work, p.cache, &out);
  return out;
}

// Parseval sums sum_k w_k Psi(a*k)^2 (the time-averaged scalogram, MorletCwt::meanPowerAt, and
// the noise gain) of the per-mode path. A row whose Gaussian spans sigma_k = 1/(a sqrt 2) bins
// is summed bin by bin (bit-identical to MorletCwt) when sigma_k < 2^kBinnedMinLevel *
// kBinnedSigmaPerGroup = 128 bins (the smallest group, h = 4, needs that width); wider rows
// sum groups of h = 2^L <= sigma_k/kBinnedSigmaPerGroup bins through the second-order Taylor
// expansion of Psi^2 about each group's centre c, with the group's moments
// S0 = sum w, S1 = sum w (k - c), S2 = sum w (k - c)^2:
//   sum_{k in g} w_k G(k) = S0 G(c) + S1 G'(c) + S2 G''(c)/2 + R,  |R| <= |G'''| (h/2)^3 S0 / 6,
// i.e. |R| < 1e-6 of S0 * max G for h <= sigma_k/32 (|d^3/dx^3 exp(-x^2)| <= 3.5, a =
// 1/(sigma_k sqrt 2)). The wide rows (most of the peak spectrum's 850 rows span up to 6e5
// bins each) then cost ~1000 groups instead of ~1e5 bins. The groups' moments are built once
// per signal in O(N) (a pyramid: level L from level L-1).
constexpr double kBinnedSigmaPerGroup = 32.0;
constexpr int kBinnedMinLevel = 2;
using wavelet_detail::kPowerBandHalfWidth;
using wavelet_detail::kSumRecurrenceBlock;

class BinnedPower {
 public:
  // w_k = |Y_k|^2 (Y non-null) or 1 (Y null) for k = 1..K-1 (w_0 = 0: the analytic cut).
  void build(const std::complex<double>* Y, long K, int max_level) {
    Y_ = Y;
    K_ = K;
    levels_.resize(static_cast<size_t>(std::max(0, max_level - kBinnedMinLevel + 1)));
    for (size_t l = 0; l < levels_.size(); ++l) {
      const long h = 1L << (kBinnedMinLevel + static_cast<int>(l));
      std::vector<Moments>& m = levels_[l];
      m.assign(static_cast<size_t>((K + h - 1) / h), Moments{});
      if (l == 0) {
        // Group by group, bins in order (no division per bin; the same sums in the same order).
        const double c0 = 0.5 * static_cast<double>(h - 1);
        for (size_t gi = 0; gi < m.size(); ++gi) {
          const long k0 = static_cast<long>(gi) * h, k1 = std::min(K, k0 + h);
          Moments g;
          for (long k = std::max(1L, k0); k < k1; ++k) {
            const double w = weight(k);
            const double d = static_cast<double>(k - k0) - c0;
            g.s0 += w;
            g.s1 += w * d;
            g.s2 += w * d * d;
          }
          m[gi] = g;
        }
      } else {
        // Children of half the width, centred at c -+ h/4.
        const std::vector<Moments>& c = levels_[l - 1];
        const double q = 0.25 * static_cast<double>(h);
        for (size_t g = 0; g < m.size(); ++g) {
          for (int side = 0; side < 2; ++side) {
            const size_t ci = 2 * g + static_cast<size_t>(side);
            if (ci >= c.size()) break;
            const double d = side == 0 ? -q : q;
            m[g].s0 += c[ci].s0;
            m[g].s1 += c[ci].s1 + d * c[ci].s0;
            m[g].s2 += c[ci].s2 + 2.0 * d * c[ci].s1 + d * d * c[ci].s0;
          }
        }
      }
    }
  }

  // sum_k w_k 4 exp(-(a k - omega0)^2) over the band |a k - omega0| <= kPowerBandHalfWidth.
  double sum(double a, double omega0) const {
    const long lo = static_cast<long>(std::max(1.0, std::ceil((omega0 - kPowerBandHalfWidth) / a)));
    const long hi = static_cast<long>(
        std::min(static_cast<double>(K_ - 1), std::floor((omega0 + kPowerBandHalfWidth) / a)));
    const double sigma_k = 1.0 / (a * std::sqrt(2.0));
    int level = -1;
    while (level + 1 < static_cast<int>(levels_.size()) &&
           static_cast<double>(1L << (kBinnedMinLevel + level + 1)) * kBinnedSigmaPerGroup <=
               sigma_k)
      ++level;
    if (level < 0) return exactSum(a, omega0, lo, hi);
    const std::vector<Moments>& m = levels_[static_cast<size_t>(level)];
    const long h = 1L << (kBinnedMinLevel + level);
    const long g_lo = lo / h, g_hi = hi / h;
    const double dh = static_cast<double>(h), a2 = a * a;
    const double q = std::exp(-2.0 * a2 * dh * dh);
    double sum = 0.0;
    for (long g0 = g_lo; g0 <= g_hi; g0 += kSumRecurrenceBlock) {
      const long g1 = std::min(g_hi + 1, g0 + kSumRecurrenceBlock);
      double x = a * (static_cast<double>(g0) * dh + 0.5 * (dh - 1.0)) - omega0;
      double G = 4.0 * std::exp(-x * x);
      double r = std::exp(-2.0 * a * dh * x - a2 * dh * dh);  // G(c + h) / G(c)
      for (long g = g0; g < g1; ++g) {
        const Moments& s = m[static_cast<size_t>(g)];
        // G'(c) = -2 a x G, G''(c) = (4 a^2 x^2 - 2 a^2) G.
        sum += G * (s.s0 - 2.0 * a * x * s.s1 + (2.0 * a2 * x * x - a2) * s.s2);
        G *= r;
        r *= q;
        x += a * dh;
      }
    }
    return sum;
  }

 private:
  struct Moments {
    double s0 = 0.0, s1 = 0.0, s2 = 0.0;
  };
  double weight(long k) const {
    if (!Y_) return 1.0;
    const double* y = reinterpret_cast<const double*>(Y_);
    return y[2 * k] * y[2 * k] + y[2 * k + 1] * y[2 * k + 1];
  }
  // The bin-by-bin sum, MorletCwt's (bit-identical to it).
  double exactSum(double a, double omega0, long lo, long hi) const {
    return wavelet_detail::psi2Sum(a, omega0, lo, hi, [this](long k) { return weight(k); });
  }

  const std::complex<double>* Y_ = nullptr;
  long K_ = 0;
  std::vector<std::vector<Moments>> levels_;
};

// ------------------------------------------------------------------------------------------
// The steps of analyzeWavelet.

// What one thread's row fits write: the decimated rows (their plans and buffers), |W| of a row,
// the fits' scratch and the ln|W|/arg W cache. The per-mode path gives each of its fitting
// threads one (WaveletOptions::threads); the first also serves the noise row.
struct RowScratch {
  wavelet_detail::DecimatedRows decimated;
  wavelet_detail::BlockedRow blocked;  // the rows of grid D = 1 (prepareBlockedRow)
  std::vector<double> env, work, coarse;
  PointCache points;
};

// Everything the steps share: the input, the options, the result being filled.
struct Analysis {
  const double* y;
  long n;
  double fs;
  const WaveletOptions& opt;
  WaveletResult& res;
  std::vector<double> grid;
  MorletCwt& scal;           // the scalogram's grid; its spectrum serves the peak spectrum too
  MorletCwt& own;            // the fit rows' own transform (per-mode path, or when scal's
                             // padding does not hold them)
  std::vector<double>& psd;  // scratch: |Y_k|^2 for the noise median (keeps its size)
  BinnedPower& power;        // per-mode path: the Parseval sums of the wide rows (see above)
  std::vector<std::unique_ptr<RowScratch>>& rows;  // one per fitting thread (at least one)
  wavelet_detail::LowBand& low;           // shared mode: the low rows' bins on the grid's padding
  BinnedPower& low_power;                 // and their Parseval sums
  wavelet_detail::HalvedForward& halves;  // shared mode: the record's transform in two halves
  double mean = 0.0;                      // of the samples (checkInput)
  bool own_loaded = false;  // `own` holds this record's spectrum already (loadOwnAhead)
  double ahead_hf = kNaN;   // and the noise row's level from it (highFrequencyLevel)
  // Per-mode path, shared mode (sharedMode): `scal` is the one transform of the record, padded
  // by n/kSharedPadDivisor; rows whose 8 scales exceed that padding take their Parseval sums
  // from `low`, the first low_bins bins of the grid's padding low_n (0: none needed).
  bool shared = false;
  long low_n = 0, low_bins = 0;
  bool hf_ahead = false;  // ahead_hf is the noise row's level from `scal` (shared mode)
};

// Noise gain of row (f, omega): MorletCwt's sum, or its erf form on the per-mode path (within
// ~1e-10 of the sum; DecimatedRows::noiseGain).
double gainOf(const Analysis& a, const MorletCwt& fit, double f, double omega) {
  if (a.opt.full_scalogram) return fit.noiseGainAt(f, omega);
  const double coef = omega * a.fs / (f * static_cast<double>(fit.paddedSize()));
  return wavelet_detail::DecimatedRows::noiseGain(coef, omega, fit.paddedSize());
}

// Per-mode path: row (f, omega) of fit's spectrum at every D-th sample (see fitModes).
const std::complex<double>* decimatedRow(const Analysis& a, const MorletCwt& fit, double f,
                                         double omega, long D, RowScratch* rs) {
  const double coef = omega * a.fs / (f * static_cast<double>(fit.paddedSize()));  // s*w_k
  rs->decimated.setPlanning(a.opt.fft_planning);
  return rs->decimated.row(fit.spectrum(), fit.paddedSize(), coef, omega, D);
}

// Per-mode path: whether cwt is configured for these signals with the FFT length these fit rows
// need. Its rows are not used there (the decimated rows take any frequency from the spectrum,
// within the padding), so its plan and a spectrum already loaded serve rows of other
// frequencies, as a configuration for them would (same length, same spectrum): a reused
// analyzer re-plans only when the length changes, not for each record's peak frequencies.
bool sameLength(const MorletCwt& cwt, const Analysis& a, const std::vector<double>& f,
                const std::vector<double>& w) {
  return cwt.configured() && cwt.size() == a.n && cwt.sampleRate() == a.fs &&
         cwt.paddedSize() == MorletCwt::paddedLength(a.n, a.fs, f, w);
}

// Whether cwt is configured for exactly these signals and rows (then configure is skipped:
// its plans and buffers are reused, and the results are those of a fresh configure).
bool sameConfiguration(const MorletCwt& cwt, long n, double fs, const std::vector<double>& f,
                       const std::vector<double>& w) {
  if (!(cwt.configured() && cwt.size() == n && cwt.sampleRate() == fs && cwt.frequencies() == f))
    return false;
  const std::vector<double>& have = cwt.omega0s();  // one per row
  if (w.size() != 1) return have == w;
  return std::all_of(have.begin(), have.end(), [&](double x) { return x == w[0]; });
}

// Largest 2 n max|y| the transform takes (its square, the PSD's bound, stays far below the
// largest double, 1.8e308, with room for the gains and normalisations applied to it).
constexpr double kMaxSampleSum = 1e150;

// The input's sizes, rate and samples; a->mean is the samples' mean (MorletCwt::checkedMean's,
// as MorletCwt::setSignal computes it: both transforms load the record with it).
Status checkInput(Analysis* an) {
  const Analysis& a = *an;
  if (!a.y) return Status::internal("analyzeWavelet: null signal");
  if (a.n < kMinSamples) {
    return Status::invalidArgument("analyzeWavelet: n = " + std::to_string(a.n) +
                                       " samples; at least " + std::to_string(kMinSamples) +
                                       " are needed",
                                   "n");
  }
  if (!(a.fs > 0.0) || !std::isfinite(a.fs)) {
    return Status::invalidArgument(
        "analyzeWavelet: sample_rate = " + num(a.fs) + " Hz must be finite and > 0", "sample_rate");
  }
  double max_abs = 0.0;
  if (Status s = MorletCwt::checkedMean(a.y, a.n, &an->mean, "analyzeWavelet", &max_abs); !s.ok())
    return s;
  // The transform's bins are bounded by sum |y_j - mean| <= 2 n max|y| and the PSD by its
  // square: beyond kMaxSampleSum they could overflow to infinity and every number after them
  // would be NaN with no error (a record in the wrong unit, or a corrupt file).
  if (!(2.0 * static_cast<double>(a.n) * max_abs <= kMaxSampleSum)) {
    return Status::invalidInput("analyzeWavelet: samples reach |y| = " + num(max_abs) +
                                ": 2 n max|y| = " + num(2.0 * static_cast<double>(a.n) * max_abs) +
                                " exceeds " + num(kMaxSampleSum) +
                                ", where the spectrum's power would overflow; rescale the record");
  }
  return {};
}

// The frequency grid (explicit, or log-spaced from f_min to f_max) and the mode frequencies,
// all below the Nyquist frequency.
Status frequencyGrid(Analysis* a) {
  const WaveletOptions& o = a->opt;
  const double nyquist = 0.5 * a->fs;
  const std::string nyq = " the Nyquist frequency sample_rate/2 = " + num(nyquist) + " Hz";
  a->grid = o.frequencies;
  if (a->grid.empty()) {
    const double f_min = o.f_min > 0.0 ? o.f_min : 10.0 * a->fs / static_cast<double>(a->n);
    const double f_max = o.f_max > 0.0 ? o.f_max : 0.4 * a->fs;
    if (!(f_max < nyquist)) {
      return Status::invalidArgument(
          "WaveletOptions.f_max = " + num(f_max) + " Hz must be below" + nyq, "f_max");
    }
    if (!(f_min < f_max)) {
      return Status::invalidArgument("WaveletOptions.f_min = " + num(f_min) + " Hz (" +
                                         (o.f_min > 0.0 ? "given" : "auto: 10 cycles per record") +
                                         ") must be < f_max = " + num(f_max) + " Hz",
                                     "f_min");
    }
    a->grid = logSpacedFrequencies(f_min, f_max, o.n_scales);
  } else if (!(a->grid.back() < nyquist)) {
    return Status::invalidArgument(
        "WaveletOptions.frequencies.back() = " + num(a->grid.back()) + " Hz must be below" + nyq,
        "frequencies");
  }
  for (size_t i = 0; i < o.mode_frequencies.size(); ++i) {
    if (!(o.mode_frequencies[i] < nyquist)) {
      return Status::invalidArgument("WaveletOptions.mode_frequencies[" + std::to_string(i) +
                                         "] = " + num(o.mode_frequencies[i]) + " Hz must be below" +
                                         nyq,
                                     "mode_frequencies");
    }
  }
  a->res.frequencies = a->grid;
  a->res.omega0 = o.omega0;
  a->res.coi.resize(a->grid.size());
  for (size_t i = 0; i < a->grid.size(); ++i) {
    a->res.coi[i] = morletConeOfInfluence(a->grid[i], o.omega0);
  }
  return {};
}

// Time-averaged scalogram at (f, omega0) (MorletCwt::meanPowerAt): exact with the full
// scalogram; through the binned sums of the wide rows on the per-mode path (within 1e-6).
double meanPowerOf(const Analysis& a, double f, double omega0) {
  if (a.opt.full_scalogram) return a.scal.meanPowerAt(f, omega0);
  if (a.shared && !a.scal.fitsPadding(f, omega0)) {
    const double N1 = static_cast<double>(a.low_n);
    return a.low_power.sum(omega0 * a.fs / (f * N1), omega0) / (static_cast<double>(a.n) * N1);
  }
  const double N = static_cast<double>(a.scal.paddedSize());
  return a.power.sum(omega0 * a.fs / (f * N), omega0) / (static_cast<double>(a.n) * N);
}

// Row (f, omega0) on the low band's grid padding (shared mode): a = s*w per bin and the bins of
// its Parseval band (MorletCwt's).
struct LowRow {
  double coef;
  long lo = 0, hi = 0;
};
LowRow lowRow(const Analysis& a, double f, double omega0) {
  LowRow r{omega0 * a.fs / (f * static_cast<double>(a.low_n))};
  wavelet_detail::bandOf(r.coef, omega0, a.low_n, &r.lo, &r.hi, kPowerBandHalfWidth);
  return r;
}

// MorletCwt::meanPowerAt's exact sum, on the low band's grid padding for the low rows in shared
// mode (explicit mode frequencies).
double exactPowerOf(const Analysis& a, double f, double omega0) {
  if (!a.shared || a.scal.fitsPadding(f, omega0)) return a.scal.meanPowerAt(f, omega0);
  const LowRow r = lowRow(a, f, omega0);
  const double* y = reinterpret_cast<const double*>(a.low.spectrum());
  const double sum = wavelet_detail::psi2Sum(
      r.coef, omega0, r.lo, std::min(r.hi, a.low_bins - 1),
      [y](long k) { return y[2 * k] * y[2 * k] + y[2 * k + 1] * y[2 * k + 1]; });
  return sum / (static_cast<double>(a.n) * static_cast<double>(a.low_n));
}

// The white-noise gain of row (f, omega0) on the grid its mean power is summed on (meanPowerOf):
// the transform's, or the low band's grid padding in shared mode (MorletCwt::noiseGainAt's sum).
double noiseGainOf(const Analysis& a, double f, double omega0) {
  if (!a.shared || a.scal.fitsPadding(f, omega0)) return a.scal.noiseGainAt(f, omega0);
  const LowRow r = lowRow(a, f, omega0);
  return wavelet_detail::psi2Sum(r.coef, omega0, r.lo, r.hi, [](long) { return 1.0; }) /
         static_cast<double>(a.low_n);
}

// The PSD of the loaded record (a->scal's spectrum) and the white-noise estimate sigma_n from
// the median of its bins' |Y_k|^2 (spectraAndNoise).
void psdAndNoise(Analysis* a) {
  const long N = a->scal.paddedSize(), kmax = N / 2;
  const std::complex<double>* Y = a->scal.spectrum();
  WaveletResult& res = a->res;
  res.spectrum_freq.resize(static_cast<size_t>(kmax + 1));
  res.spectrum_power.resize(static_cast<size_t>(kmax + 1));
  std::vector<double>& p2 = a->psd;
  p2.resize(static_cast<size_t>(kmax));
  // Loops without branches or calls (each vectorises; the same values as bin by bin).
  const double fs = a->fs, nfs = static_cast<double>(a->n) * a->fs, dN = static_cast<double>(N);
  double* freq = res.spectrum_freq.data();
  for (long k = 0; k <= kmax; ++k) freq[k] = static_cast<double>(k) * fs / dN;
  const double* y = reinterpret_cast<const double*>(Y);
  double* power = res.spectrum_power.data();
  for (long k = 0; k <= kmax; ++k) power[k] = y[2 * k] * y[2 * k] + y[2 * k + 1] * y[2 * k + 1];
  for (long k = 1; k <= kmax; ++k) p2[static_cast<size_t>(k - 1)] = power[k];
  for (long k = 0; k <= kmax; ++k) power[k] = 2.0 * power[k] / nfs;
  power[0] = 0.5 * power[0];  // the edge bins count once: (1 p) / nfs = (2 p / nfs) / 2 exactly
  if (N % 2 == 0) power[kmax] = 0.5 * power[kmax];
  res.noise_std = std::sqrt(medianOfNonNegative(p2.data(), kmax, 1) /
                            (static_cast<double>(a->n) * std::log(2.0)));
}

// Per-mode path, shared mode (sharedMode, docs/wavelet.md "Speed"): the record's one transform is
// padded by n/kSharedPadDivisor samples (n >= kSharedPadDivisor * kMinSharedPad), enough for the
// fit rows of modes above ~650 omega0 cycles per record (8 scales within n/512); rows needing more
// padding take their Parseval sums from the low band, used while its bins are at most
// 1/kLowBandMaxShare of the grid's padding. kPadScales: MorletCwt's padding in scales.
constexpr long kSharedPadDivisor = 512;
constexpr long kMinSharedPad = 64;
constexpr long kLowBandMaxShare = 8;
constexpr double kPadScales = 8.0;

double highFrequencyLevel(const Analysis& an, MorletCwt* fit, RowScratch* rs);
void peakSpectrum(Analysis* a);

// The time-averaged scalogram of the grid's rows (per-mode path: the binned sums of *Y's K bins
// built first; a->power, see BinnedPower).
void scalogramPower(Analysis* a, const std::complex<double>* Y, long K, long N) {
  if (!a->opt.full_scalogram) {
    // Largest sigma_k of any row: f < fs/2, omega0 >= 3 (a > 6/N).
    const double sigma_max = static_cast<double>(N) / (6.0 * std::sqrt(2.0));
    a->power.build(Y, K, static_cast<int>(std::floor(std::log2(sigma_max / kBinnedSigmaPerGroup))));
  }
  a->res.scalogram_power.resize(a->grid.size());
  for (size_t i = 0; i < a->grid.size(); ++i)
    a->res.scalogram_power[i] = meanPowerOf(*a, a->grid[i], a->opt.omega0);
}

// One FFT of the record: the PSD, the white-noise estimate sigma_n (median of |Y_k|^2: white
// noise makes it exponential with mean n*sigma_n^2, the median ignores the few peak bins) and
// the time-averaged scalogram. Full path and the per-mode path's classic mode: on the grid's
// padding (sharedSpectra: shared mode).
Status spectraAndNoise(Analysis* a) {
  // The spectra need no inverse FFT: FFTW_ESTIMATE (the scalogram's rows are planned apart).
  if (!sameConfiguration(a->scal, a->n, a->fs, a->grid, {a->opt.omega0})) {
    if (Status s = a->scal.configure(a->n, a->fs, a->grid, a->opt.omega0, FftPlanning::Estimate);
        !s.ok())
      return s;
  }
  if (Status s = a->scal.setCheckedSignal(a->y, a->mean); !s.ok()) return s;
  const long N = a->scal.paddedSize();
  // Per-mode path on several threads: the PSD and its median on a thread of their own while
  // this one sums the rows' power (they read Y and write apart; the same values as in turn).
  std::future<void> psd;
  if (!a->opt.full_scalogram && a->opt.threads >= 2) {
    psd = gear_sim::startAsync([a] { psdAndNoise(a); });
  } else {
    psdAndNoise(a);
  }
  scalogramPower(a, a->scal.spectrum(), N / 2 + 1, N);
  if (psd.valid()) psd.get();
  return {};
}

// Per-mode path, shared mode: whether one transform padded by n/kSharedPadDivisor serves the
// spectra (rows within its padding; the low rows from the low band) and the fits. Sets a->shared,
// a->low_n (the grid's padding) and a->low_bins (the bins the low rows' bands reach on it: the
// band's top of the highest row beyond the shared padding, for omega0 and peak_omega0). Classic
// mode (false) when the record is short (the low band would reach past 1/kLowBandMaxShare of the
// grid's padding: no gain over its transform).
bool sharedMode(Analysis* a) {
  a->shared = false;
  if (a->opt.full_scalogram) return false;
  const long pad = a->n / kSharedPadDivisor;
  if (pad < kMinSharedPad) return false;
  a->low_n = MorletCwt::paddedLength(a->n, a->fs, a->grid, {a->opt.omega0});
  if (a->low_n <= 0) return false;
  double f_lowest = a->grid.front();
  for (double f : a->opt.mode_frequencies) f_lowest = std::min(f_lowest, f);
  long bins = 0;
  for (double w : {a->opt.omega0, a->opt.peak_omega0}) {
    // Rows below f_c need more than `pad` samples of padding (8 scales).
    const double f_c = kPadScales * w * a->fs / (2.0 * kPi * static_cast<double>(pad));
    if (!(f_c > f_lowest)) continue;
    const double top =
        (w + kPowerBandHalfWidth) * f_c * static_cast<double>(a->low_n) / (w * a->fs);
    bins = std::max(bins, static_cast<long>(std::ceil(std::min(top, 0.5 * a->low_n))) + 2);
  }
  if (bins > a->low_n / kLowBandMaxShare) return false;
  a->low_bins = bins;
  a->shared = true;
  return true;
}

// The frequency whose 8-scale padding at omega0 is `pad` samples (configures the shared
// transform's length through MorletCwt::configure's padding rule).
double paddingFrequency(double fs, double omega0, long pad) {
  return kPadScales * omega0 * fs / (2.0 * kPi * static_cast<double>(pad));
}

// Shared mode: the low band (when some rows need it) and its binned sums.
bool lowBandSpectra(Analysis* a) {
  if (a->low_bins == 0) return true;
  a->low.setPlanning(a->opt.fft_planning);
  if (!a->low.compute(a->y, a->n, a->mean, a->low_n, a->low_bins)) return false;
  const double sigma_max = static_cast<double>(a->low_n) / (6.0 * std::sqrt(2.0));
  a->low_power.build(a->low.spectrum(), a->low_bins,
                     static_cast<int>(std::floor(std::log2(sigma_max / kBinnedSigmaPerGroup))));
  return true;
}

// Shared mode: the record's transform, in two halves where its length is even (HalvedForward),
// on two threads when asked (the same arithmetic, so the same bits, as on one).
Status loadShared(Analysis* a) {
  const bool halved = a->halves.configure(a->scal.paddedSize(), a->opt.fft_planning);
  if (!halved) return a->scal.setCheckedSignal(a->y, a->mean);
  std::future<void> odd;
  auto transform = [a](int p) { a->halves.transformHalf(p, a->y, a->n, a->mean); };
  if (a->opt.threads >= 2) odd = gear_sim::startAsync([transform] { transform(1); });
  transform(0);
  if (odd.valid()) {
    odd.get();
  } else {
    transform(1);
  }
  return a->scal.setCheckedSpectrum(a->mean, [a](std::complex<double>* Y) { a->halves.join(Y); });
}

// Shared mode: the record's one transform (padded by n/kSharedPadDivisor) gives the PSD, the
// white-noise estimate, the rows' power within its padding and, in fitModes, the fit rows and
// the noise row; the low band gives the low rows' power. On several threads, once the transform
// is there, a helper computes the low band and the rows' power while this thread computes the
// PSD, its median and the noise row's level (its own RowScratch, which nothing else uses before
// the fits); on one, the noise row's level waits for fitModes. The peak spectrum follows the
// rows' power (it needs their sums only).
Status sharedSpectra(Analysis* a) {
  const long pad = a->n / kSharedPadDivisor;
  const std::vector<double> f_pad = {paddingFrequency(a->fs, a->opt.omega0, pad)};
  Status s;
  if (!sameConfiguration(a->scal, a->n, a->fs, f_pad, {a->opt.omega0}))
    s = a->scal.configure(a->n, a->fs, f_pad, a->opt.omega0, FftPlanning::Estimate);
  if (s.ok()) s = loadShared(a);
  if (!s.ok()) return s;
  const long N = a->scal.paddedSize();
  auto lowAndPower = [a, N] {
    if (!lowBandSpectra(a)) return false;
    scalogramPower(a, a->scal.spectrum(), N / 2 + 1, N);
    peakSpectrum(a);
    return true;
  };
  if (a->opt.threads < 2) {
    psdAndNoise(a);
    if (!lowAndPower())
      return Status::resourceLimit("analyzeWavelet: the low rows' spectrum failed");
    return {};
  }
  std::future<bool> helper = gear_sim::startAsync(lowAndPower);
  psdAndNoise(a);
  a->ahead_hf = highFrequencyLevel(*a, &a->scal, a->rows.front().get());
  a->hf_ahead = true;
  if (!helper.get()) return Status::resourceLimit("analyzeWavelet: the low rows' spectrum failed");
  return {};
}

// The full scalogram |W|, block-averaged in time to at most max_scalogram_columns columns.
Status fullScalogram(Analysis* a) {
  WaveletResult& res = a->res;
  const long n = a->n, maxc = a->opt.max_scalogram_columns;
  const long d = (maxc > 0 && n > maxc) ? (n + maxc - 1) / maxc : 1;
  const long cols = (n + d - 1) / d;
  res.scalogram_decimation = d;
  res.modulus.resize(static_cast<Eigen::Index>(a->grid.size()), cols);
  res.scalogram_times.resize(static_cast<size_t>(cols));
  for (long c = 0; c < cols; ++c) {
    const long e = std::min(n, (c + 1) * d);
    res.scalogram_times[static_cast<size_t>(c)] = 0.5 * static_cast<double>(c * d + e - 1) / a->fs;
  }
  MorletScalogram rows;
  if (Status s =
          rows.configure(n, a->fs, a->grid, a->opt.omega0, a->opt.fft_planning, a->opt.threads);
      !s.ok())
    return s;
  return rows.forEachRow(a->y, [&](int i, const double* row) {
    for (long c = 0; c < cols; ++c) {
      const long b = c * d, e = std::min(n, b + d);
      double sum = 0.0;
      for (long j = b; j < e; ++j) sum += row[j];
      res.modulus(i, c) = static_cast<float>(sum / static_cast<double>(e - b));
    }
  });
}

// Peak-picking spectrum: time-averaged scalogram at peak_omega0 on a log grid fine enough
// (relative step <= 1/(4*peak_omega0)) to sample its narrowest peak.
void peakSpectrum(Analysis* a) {
  const double wp = a->opt.peak_omega0, f0 = a->grid.front(), f1 = a->grid.back();
  const int m =
      std::max(a->opt.n_scales, static_cast<int>(std::ceil(std::log(f1 / f0) * 4.0 * wp)) + 1);
  a->res.peak_freq = logSpacedFrequencies(f0, f1, m);
  a->res.peak_power.resize(a->res.peak_freq.size());
  for (size_t i = 0; i < a->res.peak_freq.size(); ++i) {
    a->res.peak_power[i] = meanPowerOf(*a, a->res.peak_freq[i], wp);
  }
}

// Whether peak p passes the prominence rule: the fixed fraction of the highest peak
// (peak_prominence > 0), or the noise-adaptive rule (0; see kPeakNoiseZ).
bool prominentEnough(const Analysis& a, const Peak& p, double highest) {
  if (!(p.amplitude > 0.0)) return false;
  if (a.opt.peak_prominence > 0.0) return p.prominence >= a.opt.peak_prominence * highest;
  if (p.prominence < kMinRelativeProminence * highest) return false;
  const double wp = a.opt.peak_omega0;
  const double pn = noiseGainOf(a, p.frequency, wp) * a.res.noise_std * a.res.noise_std;
  const double T = static_cast<double>(a.n) / a.fs;
  const double rel =
      std::min(1.0, std::sqrt(std::sqrt(2.0 * kPi) * morletScale(p.frequency, wp) / T));
  const double base = p.amplitude - p.prominence;
  const double above = p.amplitude * p.amplitude - std::max(base * base, pn);
  return above >= kPeakNoiseZ * rel * pn;
}

// Spectral frequency of a peak: the largest PSD bin within one wavelet bandwidth of it,
// refined by a parabola through ln|Y|^2.
double refineOnPsd(const Analysis& a, double f_peak) {
  const long N = a.scal.paddedSize();
  const std::complex<double>* Y = a.scal.spectrum();
  const double fs = a.fs, wp = a.opt.peak_omega0;
  const long kc = std::lround(f_peak * N / fs);
  const long half = std::max(1L, std::lround(f_peak / wp * N / fs));
  const long lo = std::max(1L, kc - half), hi = std::min(N / 2 - 1, kc + half);
  long km = std::max(lo, std::min(kc, hi));
  for (long k = lo; k <= hi; ++k) {
    if (std::norm(Y[k]) > std::norm(Y[km])) km = k;
  }
  if (!(km > 1 && km < N / 2 - 1)) return f_peak;
  const double l0 = std::log(std::norm(Y[km - 1]) + 1e-300);
  const double l1 = std::log(std::norm(Y[km]) + 1e-300);
  const double l2 = std::log(std::norm(Y[km + 1]) + 1e-300);
  const double den = l0 - 2.0 * l1 + l2;
  const double delta = den < 0.0 ? std::max(-0.5, std::min(0.5, 0.5 * (l0 - l2) / den)) : 0.0;
  return (static_cast<double>(km) + delta) * fs / N;
}

const std::pair<double, double>* regionFor(const WaveletOptions& o, size_t i) {
  if (o.decay_regions.empty()) return nullptr;
  const auto& r = o.decay_regions.size() == 1 ? o.decay_regions[0] : o.decay_regions[i];
  return std::isnan(r.first) ? nullptr : &r;
}

// Modes: the explicit mode frequencies, or the peaks of sqrt(peak_power) passing the
// prominence and separation rules (max_modes most prominent), ascending in frequency.
std::vector<ModeSeed> pickModes(Analysis* a) {
  std::vector<ModeSeed> seeds;
  const WaveletOptions& o = a->opt;
  const double wp = o.peak_omega0;
  for (size_t i = 0; i < o.mode_frequencies.size(); ++i) {
    const double f = o.mode_frequencies[i];
    seeds.push_back({f, std::sqrt(std::max(0.0, exactPowerOf(*a, f, wp))), regionFor(o, i)});
  }
  if (!seeds.empty()) return seeds;
  std::vector<double> amp(a->res.peak_freq.size());
  for (size_t i = 0; i < amp.size(); ++i) amp[i] = std::sqrt(std::max(0.0, a->res.peak_power[i]));
  std::vector<Peak> peaks = findPeaks(a->res.peak_freq, amp);
  double highest = 0.0;
  for (const Peak& p : peaks) highest = std::max(highest, p.amplitude);
  std::vector<Peak> cand;
  for (const Peak& p : peaks) {
    if (prominentEnough(*a, p, highest)) cand.push_back(p);
  }
  std::sort(cand.begin(), cand.end(),
            [](const Peak& x, const Peak& y) { return x.amplitude > y.amplitude; });
  std::vector<Peak> kept;
  for (const Peak& p : cand) {
    bool separate = true;
    for (const Peak& q : kept) {
      const double sep = o.min_separation_hz > 0.0 ? o.min_separation_hz : q.frequency / wp;
      if (std::abs(p.frequency - q.frequency) < sep) separate = false;
    }
    if (separate && static_cast<int>(kept.size()) < o.max_modes) kept.push_back(p);
  }
  if (kept.empty()) a->res.warnings.push_back("no spectral peak found: no mode to fit");
  for (const Peak& p : kept)
    seeds.push_back({refineOnPsd(*a, p.frequency), p.amplitude, regionFor(o, 0)});
  std::sort(seeds.begin(), seeds.end(),
            [](const ModeSeed& x, const ModeSeed& y) { return x.f_spec < y.f_spec; });
  return seeds;
}

// The omega0 each mode's row needs so that its neighbours leak < kLeakTarget into it.
std::vector<double> separationOmega0(const std::vector<ModeSeed>& seeds, double max_omega0) {
  std::vector<double> need(seeds.size(), kMinFitOmega0);
  for (size_t i = 0; i < seeds.size(); ++i) {
    for (size_t j = 0; j < seeds.size(); ++j) {
      if (j == i) continue;
      const double r = std::abs(seeds[j].f_spec / seeds[i].f_spec - 1.0);
      const double ratio = seeds[i].amplitude > 0.0 ? seeds[j].amplitude / seeds[i].amplitude : 1.0;
      const double l = std::log(std::max(ratio, 1e-6) / kLeakTarget);
      if (l > 0.0) need[i] = std::max(need[i], r > 0.0 ? std::sqrt(2.0 * l) / r : 1e9);
    }
    need[i] = std::min(need[i], max_omega0);
  }
  return need;
}

// Per-mode path: the noise row is computed at every kNoiseRowStep-th sample only (exact there,
// DecimatedRows), on the fit rows' padding, and its median taken over those points.
constexpr long kNoiseRowStep = 4;

// Noise estimate from the wavelet row at 0.45*fs (far above the modes for omega0 >= 3: a mode at
// <= 0.3*fs leaks < exp(-4.5) into it): the median of its modulus outside its COI is the Rayleigh
// median sqrt(ln 2) * sqrt(gain) * sigma_n for white noise. Skipped when a mode lies within 3
// wavelet bandwidths of that row (highFrequencyNoise). This is the row's level from fit's
// spectrum (NaN when the record is too short for it or the row cannot be computed).
double highFrequencyLevel(const Analysis& an, MorletCwt* fit, RowScratch* rs) {
  const Analysis* a = &an;
  const double w0 = a->opt.omega0, f_hf = 0.45 * a->fs;
  const double edge = a->opt.coi_factor * morletConeOfInfluence(f_hf, w0) * a->fs;
  const long lo = static_cast<long>(std::ceil(edge)), hi = a->n - 1 - lo;
  if (hi - lo < kMinRegionSamples) return kNaN;
  // Per-mode path: the row's points m*D (D = kNoiseRowStep, or the largest divisor of the
  // padded length below it) in [lo, hi]; s*fs is ~2 samples at omega0 = 6, so points 4 samples
  // apart are nearly independent and the median keeps ~1/4 of the values it had over every
  // sample (its statistical scatter doubles: ~1e-3 relative at 1e6 samples; the per-mode
  // contract, docs/wavelet.md "Speed", bounds what that does to the damping ratios).
  const long D = a->opt.full_scalogram ? 1
                                       : wavelet_detail::DecimatedRows::divisorAtMost(
                                             fit->paddedSize(), kNoiseRowStep);
  const std::complex<double>* w =
      a->opt.full_scalogram ? fit->rowAt(f_hf, w0) : decimatedRow(*a, *fit, f_hf, w0, D, rs);
  if (!w) return kNaN;
  const long points = (a->n + D - 1) / D, m0 = gridCeil(lo, D), m1 = gridFloor(hi, D);
  if (m1 < m0) return kNaN;
  std::vector<double>* env = &rs->env;
  growScratch(env, points);
  modulusOf(reinterpret_cast<const double*>(w), points, env->data());
  const double med = medianOfNonNegative(env->data() + m0, m1 - m0 + 1, 1);
  const double gain = gainOf(*a, *fit, f_hf, w0);
  return med / std::sqrt(std::log(2.0) * gain);
}

// Lowers res.noise_std to the noise row's level hf (highFrequencyLevel) when that is smaller
// and no mode lies within 3 wavelet bandwidths of the row.
void highFrequencyNoise(Analysis* a, const std::vector<ModeSeed>& seeds, double hf) {
  const double w0 = a->opt.omega0, f_hf = 0.45 * a->fs;
  bool clear = true;
  for (const ModeSeed& m : seeds) clear = clear && m.f_spec < f_hf * (1.0 - 3.0 / w0);
  if (clear && hf > 0.0 && hf < a->res.noise_std) a->res.noise_std = hf;
}

// Per-mode path, a row whose grid is every sample (D = 1; BlockedRow configured for it): every
// sample is needed only about its peak and over its decay region, which BlockedRow computes on
// demand (decayRegion's scan, fitRow). The peak and the noise floor come from the row at every
// Dc-th sample (Dc the largest divisor of N <= max(2, s*fs/kMedianPointsPerScale,
// min(kCoarseStep, s*fs)): the noise median over its points outside the COI, the median's points
// per scale of the other rows, and on short scales (s*fs < 16) every kCoarseStep-th sample while
// that keeps a point per scale, |W|'s correlation length, else every 2nd), the peak refined on
// the samples within Dc of the coarse one. A null p.row.w when the coarse row cannot be computed.
// (kCoarseStep = 4 instead of every 2nd sample: the coarse row's transform of N/4 instead of N/2
// points, ~13 ms of a 1e6-sample analysis; the contract tests' numbers did not move.)
constexpr long kCoarseStep = 4;
PreparedRow prepareBlockedRow(const Analysis& a, const MorletCwt& fit, const RowEnvelope& r,
                              double gain, RowScratch* rs) {
  PreparedRow p;
  p.cache = &rs->points;
  p.cache->c1 = p.cache->c0 - 1;
  const double scale = r.s * r.fs;
  const long step = std::max({2L, static_cast<long>(scale / kMedianPointsPerScale),
                              std::min(kCoarseStep, static_cast<long>(scale))});
  const long Dc = wavelet_detail::DecimatedRows::divisorAtMost(fit.paddedSize(), step);
  RowEnvelope coarse = r;
  coarse.D = Dc;
  coarse.points = (r.n + Dc - 1) / Dc;
  coarse.w = decimatedRow(a, fit, r.f, r.omega0, Dc, rs);
  if (!coarse.w) return p;
  growScratch(&rs->coarse, coarse.points);
  modulusOf(reinterpret_cast<const double*>(coarse.w), coarse.points, rs->coarse.data());
  p.floor = rowNoiseFloor(coarse, rs->coarse, gain, a.res.noise_std, a.opt);
  const long g =
      static_cast<long>(std::max_element(rs->coarse.begin(), rs->coarse.begin() + coarse.points) -
                        rs->coarse.begin());
  const long j0 = std::max(0L, (g - 1) * Dc + 1), j1 = std::min(r.n - 1, (g + 1) * Dc - 1);
  rs->blocked.ensure(j0, j1);
  const std::vector<double>& env = rs->blocked.env();
  p.row = r;
  p.row.w = rs->blocked.w();
  p.row.fine = &rs->blocked;
  p.row.j_peak = std::max_element(env.begin() + j0, env.begin() + j1 + 1) - env.begin();
  p.peak = env[static_cast<size_t>(p.row.j_peak)];
  return p;
}

// Fit of one mode's row at omega0 (two passes: the second shifts the region's start by
// sigma*s^2 once sigma is known). Writes only *rs (and, on the full path, fit's row buffers):
// the per-mode path fits modes on several threads, each with its own RowScratch.
RowFit fitAt(const Analysis* a, MorletCwt* fit, const ModeSeed& seed, double omega,
             double sigma_guess, RowScratch* rs) {
  const double f = seed.f_spec;
  RowEnvelope row;
  row.s = morletScale(f, omega);
  row.n = a->n;
  row.fs = a->fs;
  row.f = f;
  row.omega0 = omega;
  row.coi = std::sqrt(2.0) * row.s;
  bool blocked = false;
  if (a->opt.full_scalogram) {
    row.w = fit->rowAt(f, omega);
    row.points = a->n;
    row.full = true;
  } else {
    // Per-mode path: the row on its grid of every D-th sample (see fitModes).
    row.D = wavelet_detail::DecimatedRows::divisorAtMost(
        fit->paddedSize(), static_cast<long>(row.s * a->fs / kFitSamplesPerScale));
    row.points = (a->n + row.D - 1) / row.D;
    rs->blocked.setPlanning(a->opt.fft_planning);
    blocked = row.D == 1 && fit->fitsPadding(f, omega) &&
              rs->blocked.configure(a->y, a->n, a->mean, row.s * a->fs, omega);
    if (!blocked && fit->fitsPadding(f, omega)) row.w = decimatedRow(*a, *fit, f, omega, row.D, rs);
  }
  const double gain = gainOf(*a, *fit, f, omega), sn = a->res.noise_std;
  PreparedRow p;
  if (blocked) {
    p = prepareBlockedRow(*a, *fit, row, gain, rs);
  } else if (row.w) {
    p = prepareRow(row, gain, sn, a->opt, &rs->env, &rs->points);
  }
  if (!p.row.w) {
    RowFit r;
    r.why = "could not compute the wavelet row";
    return r;
  }
  const std::vector<double>& env = blocked ? rs->blocked.env() : rs->env;
  RowFit r = fitRow(p, env, sigma_guess, seed.region, a->opt, &rs->work);
  if (r.ok && !seed.region && r.sigma > 0.0) {
    RowFit r2 = fitRow(p, env, r.sigma, nullptr, a->opt, &rs->work);
    if (r2.ok) r = r2;
  }
  return r;
}

// The fit of mode i with the automatic omega0 rules (fall back to omega0 when the separating
// omega0 fails; lower it for time resolution when xi*omega0 > kMaxXiOmega0).
RowFit fitMode(const Analysis* a, MorletCwt* fit, const ModeSeed& seed, double omega,
               double need_sep, double* omega_used, RowScratch* rs) {
  const bool auto_w = a->opt.fit_omega0 == 0.0;
  const double w0 = a->opt.omega0;
  RowFit r = fitAt(a, fit, seed, omega, kNaN, rs);
  if (!r.ok && auto_w && omega > w0) {
    omega = w0;
    r = fitAt(a, fit, seed, omega, kNaN, rs);
  }
  if (r.ok && auto_w && r.xi > 0.0 && r.xi * omega > kMaxXiOmega0) {
    const double lower = std::max(need_sep, kMaxXiOmega0 / r.xi);
    if (lower < omega) {
      RowFit r2 = fitAt(a, fit, seed, lower, r.sigma, rs);
      if (r2.ok) {
        r = r2;
        omega = lower;
      }
    }
  }
  *omega_used = omega;
  return r;
}

void addWarning(WaveletMode* m, const std::string& code, const std::string& text) {
  m->warnings.push_back({code, text});
}

// Base frequencies whose harmonics the record resolves (the others get a global warning).
std::vector<double> resolvedOrders(Analysis* a) {
  std::vector<double> out;
  const double bin = a->fs / static_cast<double>(a->n);
  for (double f : a->opt.order_frequencies) {
    if (f >= kOrderMinSpacingBins * bin) {
      out.push_back(f);
    } else {
      a->res.warnings.push_back("order frequency " + num(f) +
                                " Hz: its harmonics are closer than " + num(kOrderMinSpacingBins) +
                                " frequency bins (" + num(bin) +
                                " Hz) of this record; not used to flag forced lines");
    }
  }
  return out;
}

// The trust checks of one fitted mode: forced line (order harmonic or steady envelope), R^2,
// close modes. Forced lines and fits below min_r2 keep sigma and R^2 but no damping ratio.
void classifyMode(const Analysis& a, const std::vector<double>& orders, const RowFit& r,
                  WaveletMode* m) {
  const double bin = a.fs / static_cast<double>(a.n);
  const double f = m->spectrum_frequency_hz;
  // Within one bin, or within the line's own half-power half-width sigma/(2 pi) when it decays.
  const double tol =
      kOrderToleranceBins * bin + (r.ok && r.sigma > 0.0 ? r.sigma / (2.0 * kPi) : 0.0);
  for (double fo : orders) {
    const double k = std::max(1.0, std::round(f / fo));
    if (kOrderMinSpacingBins * tol > fo || !(std::abs(f - k * fo) <= tol)) continue;
    const std::string where = "line at " + num(f) + " Hz is harmonic " + num(k) +
                              " of the order frequency " + num(fo) + " Hz (within " + num(tol) +
                              " Hz)";
    if (r.ok && r.reached_floor) {
      addWarning(m, "near_order_harmonic",
                 where + " but decays into the noise within the record: taken as a free decay");
    } else {
      addWarning(m, "order_harmonic",
                 where +
                     " and persists to the end of the record: a forced "
                     "line, not a free decay (apparent xi " +
                     num(r.xi) + ")");
      m->free_decay = false;
    }
    break;
  }
  if (r.ok) {
    const double nepers = r.sigma * (r.t1 - r.t0);
    if (!(nepers >= a.opt.min_decay_nepers)) {
      addWarning(m, "not_free_decay",
                 "envelope decays by " + num(nepers) + " neper over [" + num(r.t0) + ", " +
                     num(r.t1) + "] s (needs >= " + num(a.opt.min_decay_nepers) +
                     "): a steady (forced) line or a record too short for this damping "
                     "(apparent xi " +
                     num(r.xi) + ")");
      m->free_decay = false;
    } else if (!(r.r2 >= a.opt.min_r2)) {
      addWarning(m, "low_r2",
                 "R^2 = " + num(r.r2) + " of the envelope fit is below min_r2 = " +
                     num(a.opt.min_r2) + " (apparent xi " + num(r.xi) + ")");
    }
  } else {
    m->free_decay = false;
    addWarning(m, "fit_failed", r.why);
  }
  if (m->free_decay && r.ok && r.r2 >= a.opt.min_r2) m->damping_ratio = r.xi;
}

// Leakage of the other modes into mode i's row at the omega0 used: `close_modes` above 1 %.
void closeModeWarning(const std::vector<ModeSeed>& seeds, size_t i, WaveletMode* m) {
  double worst = 0.0, f_worst = 0.0;
  for (size_t j = 0; j < seeds.size(); ++j) {
    if (j == i) continue;
    const double ratio = seeds[i].amplitude > 0.0 ? seeds[j].amplitude / seeds[i].amplitude : 1.0;
    const double l = ratio * morletLeakage(seeds[j].f_spec, seeds[i].f_spec, m->omega0);
    if (l > worst) worst = l, f_worst = seeds[j].f_spec;
  }
  if (worst > kLeakWarn) {
    addWarning(
        m, "close_modes",
        "mode at " + num(f_worst) + " Hz is closer than the wavelet (omega0 = " + num(m->omega0) +
            ") can separate: it leaks " + num(100.0 * worst) + " % into this mode's envelope");
  }
}

// With known order frequencies: modes decaying at the rate of a stronger mode (kSharedDecayTol)
// or lying at a side-line position of one (kSideLineWidthShare); bin: the record's frequency bin.
void sharedDecayWarnings(const std::vector<double>& orders, double bin,
                         std::vector<WaveletMode>* modes) {
  if (orders.empty()) return;
  for (WaveletMode& m : *modes) {
    if (!(m.sigma > 0.0) || !m.free_decay) continue;
    for (const WaveletMode& o : *modes) {
      if (&o == &m || !(o.peak_amplitude > m.peak_amplitude) || !(o.sigma > 0.0)) continue;
      std::string why;
      if (std::abs(m.sigma / o.sigma - 1.0) <= kSharedDecayTol) {
        why = "decays at the rate of the stronger line at " + num(o.spectrum_frequency_hz) +
              " Hz (sigma " + num(m.sigma) + " vs " + num(o.sigma) + " 1/s)";
      } else if (o.free_decay) {  // (a side line of a mode, not of a forced line)
        const double tol =
            kOrderToleranceBins * bin + kSideLineWidthShare * (m.sigma + o.sigma) / (2.0 * kPi);
        const double df = m.frequency_hz - o.frequency_hz;
        for (double fo : orders) {
          const double k = std::round(df / fo);
          if (kOrderMinSpacingBins * tol > fo || k == 0.0 || !(std::abs(df - k * fo) <= tol))
            continue;
          why = "lies " + num(k) + " x " + num(fo) + " Hz from the stronger line at " +
                num(o.frequency_hz) + " Hz (within " + num(tol) +
                " Hz): a side line of it, whose own fit decays at sigma " + num(m.sigma) +
                " against " + num(o.sigma) + " 1/s";
          break;
        }
      }
      if (why.empty()) continue;
      addWarning(&m, "shared_decay",
                 why +
                     " under known parametric excitation: likely one modulated mode seen at "
                     "several frequencies; xi = " +
                     num(m.damping_ratio) + " here is then not a modal damping ratio");
      m.damping_ratio = kNaN;
      break;
    }
  }
}

// With known order frequencies: a reported damping ratio whose decay region spans fewer than
// kMinModulationPeriods periods of the highest order frequency (`slow_modulation`, kept).
void slowModulationWarnings(const std::vector<double>& orders, std::vector<WaveletMode>* modes) {
  if (orders.empty()) return;
  const double fo = *std::max_element(orders.begin(), orders.end());
  for (WaveletMode& m : *modes) {
    if (!std::isfinite(m.damping_ratio)) continue;
    const double periods = fo * (m.t_end - m.t_start);
    if (!(periods < kMinModulationPeriods)) continue;
    addWarning(&m, "slow_modulation",
               "the decay region [" + num(m.t_start) + ", " + num(m.t_end) + "] s spans " +
                   num(periods) + " periods of the order frequency " + num(fo) +
                   " Hz (fewer than " + num(kMinModulationPeriods) +
                   "): the envelope's jumps at the stiffness changes are not averaged over the "
                   "cycle and can bias xi by tens of percent; compare with the integral method");
  }
}

// A parametric instability at the record's mesh frequency: `parametric_resonance` (kept) on each
// reported damping ratio whose sigma the largest growth rate over its decay region (the blocks
// of WaveletOptions::parametric_growth_rate it overlaps) exceeds kParametricShare of.
void parametricWarnings(const WaveletOptions& o, std::vector<WaveletMode>* modes) {
  const std::vector<double>& rates = o.parametric_growth_rate;
  if (rates.empty()) return;
  const long last = static_cast<long>(rates.size()) - 1;
  auto block = [&](double t) {
    if (last == 0 || !(t > 0.0)) return 0L;
    const double b = std::floor(t / o.parametric_growth_block);
    return b >= static_cast<double>(last) ? last : static_cast<long>(b);
  };
  for (WaveletMode& m : *modes) {
    if (!std::isfinite(m.damping_ratio)) continue;
    double lambda = 0.0;
    for (long b = block(m.t_start); b <= block(m.t_end); ++b)
      lambda = std::max(lambda, rates[static_cast<size_t>(b)]);
    if (!(lambda > kParametricShare * m.sigma)) continue;
    const double w = 2.0 * kPi * m.frequency_hz;
    addWarning(&m, "parametric_resonance",
               "the mesh stiffness is parametrically unstable at this speed: the undamped "
               "equation grows at lambda = " +
                   num(lambda) +
                   " 1/s (Floquet) over the decay region, so the free response decays at "
                   "C/2 -+ lambda, not at the damping's C/2; sigma = " +
                   num(m.sigma) + " 1/s here may be C/2 - lambda (xi would then be " +
                   num((m.sigma + lambda) / std::hypot(m.sigma + lambda, w)) + ")");
  }
}

// Modal overlap with any other fitted mode above kMaxModalOverlap: `overlapping_modes`.
void overlapWarnings(std::vector<WaveletMode>* modes) {
  for (WaveletMode& m : *modes) {
    for (const WaveletMode& o : *modes) {
      if (&o == &m || !(m.sigma > 0.0) || !(o.sigma > 0.0)) continue;
      const double df = std::abs(m.frequency_hz - o.frequency_hz);
      const double overlap = (m.sigma + o.sigma) / (2.0 * kPi * df);
      if (overlap > kMaxModalOverlap) {
        addWarning(&m, "overlapping_modes",
                   "modal overlap " + num(overlap) + " with the mode at " + num(o.frequency_hz) +
                       " Hz (half-power half-widths " + num(m.sigma / (2.0 * kPi)) + " + " +
                       num(o.sigma / (2.0 * kPi)) + " Hz over a spacing of " + num(df) +
                       " Hz) exceeds " + num(kMaxModalOverlap) +
                       ": the envelope mixes both decays (apparent xi " + num(m.damping_ratio) +
                       ")");
        m.damping_ratio = kNaN;
        break;
      }
    }
  }
}

// The fits of every mode (fitMode) into (*fits)[i], (*omegas)[i]: one after the other on the
// full path (its rows share fit's buffers); on the per-mode path on min(threads, modes) threads,
// each with its own RowScratch, taking the next mode as it becomes free. Each mode's fit reads
// only the analysis and fit's spectrum, so the results are those of one thread.
void fitAllModes(const Analysis& a, MorletCwt* fit, const std::vector<ModeSeed>& seeds,
                 const std::vector<double>& fit_w, const std::vector<double>& need,
                 std::vector<RowFit>* fits, std::vector<double>* omegas) {
  const size_t workers =
      a.opt.full_scalogram
          ? 1
          : std::min(seeds.size(), static_cast<size_t>(std::max(1, a.opt.threads)));
  while (a.rows.size() < workers) a.rows.push_back(std::make_unique<RowScratch>());
  std::atomic<size_t> next{0};
  auto work = [&](size_t t) {
    for (size_t i = next++; i < seeds.size(); i = next++)
      (*fits)[i] = fitMode(&a, fit, seeds[i], fit_w[i], need[i], &(*omegas)[i], a.rows[t].get());
  };
  std::vector<std::future<void>> helpers;
  for (size_t t = 1; t < workers; ++t)
    helpers.push_back(gear_sim::startAsync([&work, t] { work(t); }));
  work(0);
  for (auto& h : helpers) h.get();
}

// Per mode: the row at its omega0, the envelope fit and the trust checks.
Status fitModes(Analysis* a, const std::vector<ModeSeed>& seeds) {
  const std::vector<double> need = separationOmega0(seeds, a->opt.max_fit_omega0);
  const bool auto_w = a->opt.fit_omega0 == 0.0;
  std::vector<double> fit_f(seeds.size()), fit_w(seeds.size());
  for (size_t i = 0; i < seeds.size(); ++i) {
    fit_f[i] = seeds[i].f_spec;
    fit_w[i] = auto_w ? std::max(a->opt.omega0, need[i]) : a->opt.fit_omega0;
  }
  // The full path's fit rows come from the spectrum already computed (a->scal) when its
  // padding holds them (the usual case: the modes lie above the grid's lowest row); else, and
  // always on the per-mode path (docs/wavelet.md "Speed"), from their own transform, padded
  // for the fit rows alone. The noise row comes from the fit rows' transform.
  // On the per-mode path each fit row is computed on its grid of every D-th sample
  // (kFitSamplesPerScale), exact at those samples: one inverse FFT of length N/D of the row's
  // band folded modulo N/D (DecimatedRows) instead of the full or pruned inverse FFT.
  // The per-mode path's own transform may already hold the record (loadOwnAhead).
  // Shared mode: the fit rows from the record's one transform when its padding holds them, and
  // the noise row from it always (sharedSpectra).
  bool held = true;
  for (size_t i = 0; i < seeds.size(); ++i) held = held && a->scal.fitsPadding(fit_f[i], fit_w[i]);
  MorletCwt* fit = &a->scal;
  bool ahead = false;  // own and the noise row's level loaded with the spectra (loadOwnAhead)
  if (!held || (!a->opt.full_scalogram && !a->shared)) {
    Status s;
    const bool same = sameConfiguration(a->own, a->n, a->fs, fit_f, fit_w) ||
                      (!a->opt.full_scalogram && sameLength(a->own, *a, fit_f, fit_w));
    ahead = same && a->own_loaded;
    if (!same) s = a->own.configure(a->n, a->fs, fit_f, fit_w, FftPlanning::Estimate);
    if (s.ok() && !ahead) s = a->own.setCheckedSignal(a->y, a->mean);
    if (!s.ok()) return s;
    fit = &a->own;
  }
  MorletCwt* noise = a->shared ? &a->scal : fit;
  const double hf =
      ahead || a->hf_ahead ? a->ahead_hf : highFrequencyLevel(*a, noise, a->rows.front().get());
  highFrequencyNoise(a, seeds, hf);
  const std::vector<double> orders = resolvedOrders(a);
  std::vector<RowFit> fits(seeds.size());
  std::vector<double> omegas(seeds.size(), kNaN);
  fitAllModes(*a, fit, seeds, fit_w, need, &fits, &omegas);
  for (size_t i = 0; i < seeds.size(); ++i) {
    WaveletMode m;
    const RowFit& r = fits[i];
    m.omega0 = omegas[i];
    m.spectrum_frequency_hz = seeds[i].f_spec;
    m.frequency_hz = r.ok ? r.fd : seeds[i].f_spec;
    m.peak_amplitude = r.peak;
    m.noise_floor = r.floor;
    m.t_start = r.t0;
    m.t_end = r.t1;
    m.sigma = r.ok ? r.sigma : kNaN;
    m.r2 = r.ok ? r.r2 : kNaN;
    classifyMode(*a, orders, r, &m);
    closeModeWarning(seeds, i, &m);
    a->res.modes.push_back(m);
  }
  sharedDecayWarnings(orders, a->fs / static_cast<double>(a->n), &a->res.modes);
  overlapWarnings(&a->res.modes);
  slowModulationWarnings(orders, &a->res.modes);
  parametricWarnings(a->opt, &a->res.modes);
  return {};
}

}  // namespace

// ------------------------------------------------------------------------------------------
// Options

gear_sim::OptionStatus WaveletOptions::check() const {
  if (!std::isfinite(f_min) || f_min < 0.0)
    return violated("f_min", f_min, "must be >= 0 (0 = auto)");
  if (!std::isfinite(f_max) || f_max < 0.0)
    return violated("f_max", f_max, "must be >= 0 (0 = auto)");
  if (f_min > 0.0 && f_max > 0.0 && !(f_min < f_max)) {
    return violated("f_min", f_min, "must be < f_max = " + num(f_max));
  }
  if (n_scales < 3) return violated("n_scales", n_scales, "must be >= 3");
  for (size_t i = 0; i < frequencies.size(); ++i) {
    const double f = frequencies[i];
    const std::string field = "frequencies[" + std::to_string(i) + "]";
    if (!std::isfinite(f) || f <= 0.0) return violated(field, f, "must be finite and > 0");
    if (i > 0 && !(f > frequencies[i - 1]))
      return violated(field, f, "must be > the previous value");
  }
  if (!frequencies.empty() && frequencies.size() < 3) {
    return violated("frequencies.size()", static_cast<double>(frequencies.size()),
                    "must be 0 (log-spaced grid) or >= 3");
  }
  if (!(omega0 >= 3.0 && omega0 <= 100.0)) return violated("omega0", omega0, "must be in [3, 100]");
  if (!(peak_omega0 >= 3.0 && peak_omega0 <= 100.0)) {
    return violated("peak_omega0", peak_omega0, "must be in [3, 100]");
  }
  if (!(max_fit_omega0 >= 3.0 && max_fit_omega0 <= 100.0)) {
    return violated("max_fit_omega0", max_fit_omega0, "must be in [3, 100]");
  }
  if (!(fit_omega0 == 0.0 || (fit_omega0 >= 3.0 && fit_omega0 <= max_fit_omega0))) {
    return violated("fit_omega0", fit_omega0,
                    "must be 0 (auto) or in [3, max_fit_omega0 = " + num(max_fit_omega0) + "]");
  }
  return checkModesAndRules();
}

gear_sim::OptionStatus WaveletOptions::checkModesAndRules() const {
  for (size_t i = 0; i < mode_frequencies.size(); ++i) {
    const double f = mode_frequencies[i];
    if (!std::isfinite(f) || f <= 0.0) {
      return violated("mode_frequencies[" + std::to_string(i) + "]", f, "must be finite and > 0");
    }
  }
  if (decay_regions.size() > 1 && decay_regions.size() != mode_frequencies.size()) {
    return violated(
        "decay_regions.size()", static_cast<double>(decay_regions.size()),
        "must be 0, 1 or mode_frequencies.size() = " + std::to_string(mode_frequencies.size()));
  }
  for (size_t i = 0; i < decay_regions.size(); ++i) {
    const auto& r = decay_regions[i];
    const bool automatic = std::isnan(r.first) && std::isnan(r.second);
    if (!automatic && !(std::isfinite(r.first) && std::isfinite(r.second) && r.first < r.second)) {
      return violated(
          "decay_regions[" + std::to_string(i) + "].first", r.first,
          "must be < .second = " + num(r.second) + ", both finite (or both NaN = auto)");
    }
  }
  for (size_t i = 0; i < order_frequencies.size(); ++i) {
    const double f = order_frequencies[i];
    if (!std::isfinite(f) || f <= 0.0) {
      return violated("order_frequencies[" + std::to_string(i) + "]", f, "must be finite and > 0");
    }
  }
  for (size_t i = 0; i < parametric_growth_rate.size(); ++i) {
    const double v = parametric_growth_rate[i];
    if (!(v >= 0.0) || !std::isfinite(v)) {
      return violated("parametric_growth_rate[" + std::to_string(i) + "]", v,
                      "must be finite and >= 0");
    }
  }
  if (parametric_growth_rate.size() > 1 &&
      !(parametric_growth_block > 0.0 && std::isfinite(parametric_growth_block))) {
    return violated("parametric_growth_block", parametric_growth_block,
                    "must be finite and > 0 with more than one growth rate");
  }
  if (!(peak_prominence >= 0.0 && peak_prominence < 1.0)) {
    return violated("peak_prominence", peak_prominence, "must be 0 (noise-adaptive) or in (0, 1)");
  }
  if (!std::isfinite(min_separation_hz) || min_separation_hz < 0.0) {
    return violated("min_separation_hz", min_separation_hz, "must be >= 0 (0 = auto)");
  }
  if (max_modes < 1) return violated("max_modes", max_modes, "must be >= 1");
  if (!(coi_factor >= 1.0) || !std::isfinite(coi_factor)) {
    return violated("coi_factor", coi_factor, "must be finite and >= 1");
  }
  if (!(floor_factor >= 1.0) || !std::isfinite(floor_factor)) {
    return violated("floor_factor", floor_factor, "must be finite and >= 1");
  }
  if (!(min_r2 >= 0.0 && min_r2 < 1.0)) return violated("min_r2", min_r2, "must be in [0, 1)");
  if (!(min_decay_nepers > 0.0) || !std::isfinite(min_decay_nepers)) {
    return violated("min_decay_nepers", min_decay_nepers, "must be finite and > 0");
  }
  if (threads < 1 || threads > 256) return violated("threads", threads, "must be in [1, 256]");
  if (max_scalogram_columns < 0) {
    return violated("max_scalogram_columns", static_cast<double>(max_scalogram_columns),
                    "must be >= 0 (0 = every sample)");
  }
  return {};
}

// ------------------------------------------------------------------------------------------
// Analysis: a short loop over the named steps above.

// What a WaveletAnalyzer keeps between calls: the transforms (FFTW plans, FFT buffers) and
// the scratch vectors, so a repeated analysis neither re-plans nor faults in fresh pages.
struct WaveletAnalyzer::Workspace {
  MorletCwt scal, own;
  std::vector<double> psd;
  BinnedPower power;
  std::vector<std::unique_ptr<RowScratch>> rows;
  wavelet_detail::LowBand low;
  BinnedPower low_power;
  wavelet_detail::HalvedForward halves;
};

WaveletAnalyzer::WaveletAnalyzer() : ws_(std::make_unique<Workspace>()) {}
WaveletAnalyzer::~WaveletAnalyzer() = default;
WaveletAnalyzer::WaveletAnalyzer(WaveletAnalyzer&&) noexcept = default;
WaveletAnalyzer& WaveletAnalyzer::operator=(WaveletAnalyzer&&) noexcept = default;

namespace {
// Empties *r like WaveletResult{} but keeps its vectors' capacity (a reused result's large
// spectra then need no fresh pages), and the spectra's sizes: spectraAndNoise overwrites them
// (no zero fill of 2 x N/2 values first); analyze empties them when it stops before.
void clearKeepingCapacity(WaveletResult* r) {
  r->frequencies.clear();
  r->coi.clear();
  r->omega0 = 0.0;
  r->modulus.resize(0, 0);
  r->scalogram_times.clear();
  r->scalogram_decimation = 1;
  r->scalogram_power.clear();
  r->peak_freq.clear();
  r->peak_power.clear();
  r->noise_std = 0.0;
  r->modes.clear();
  r->warnings.clear();
  r->status = Status{};
}

// Per-mode path with threads > 1: the fit rows' transform of the previous record (an analyzer
// reused on records of the same length and rate, whose modes ask for the same fit rows) is loaded
// with this record on a thread of its own while the spectra are computed; fitModes uses it when
// the modes' configuration is the same, and otherwise configures and loads it after them. The
// same thread then computes the noise row's level (highFrequencyLevel, the first RowScratch's,
// which nothing else uses before the fits) into a.ahead_hf. An invalid future when not started;
// get() says whether the record was loaded.
std::future<bool> loadOwnAhead(Analysis* a) {
  MorletCwt& own = a->own;
  if (a->opt.full_scalogram || a->opt.threads < 2 || !own.configured() || own.size() != a->n ||
      own.sampleRate() != a->fs)
    return {};
  return gear_sim::startAsync([a] {
    if (!a->own.setCheckedSignal(a->y, a->mean).ok()) return false;
    a->ahead_hf = highFrequencyLevel(*a, &a->own, a->rows.front().get());
    return true;
  });
}
}  // namespace

Status WaveletAnalyzer::analyze(const double* y, long n, double sample_rate,
                                const WaveletOptions& options, WaveletResult* result) {
  if (!result) return Status::internal("analyzeWavelet: null result");
  if (!ws_) ws_ = std::make_unique<Workspace>();
  clearKeepingCapacity(result);
  auto stop = [result](Status s) {
    result->spectrum_freq.clear();
    result->spectrum_power.clear();
    return s;
  };
  if (Status s = options.check(); !s.ok()) return stop(s);
  Workspace& w = *ws_;
  if (w.rows.empty()) w.rows.push_back(std::make_unique<RowScratch>());
  Analysis a{y,     n,     sample_rate, options, *result, {},          w.scal,
             w.own, w.psd, w.power,     w.rows,  w.low,   w.low_power, w.halves};
  if (Status s = checkInput(&a); !s.ok()) return stop(s);
  if (Status s = frequencyGrid(&a); !s.ok()) return stop(s);
  std::future<bool> own = sharedMode(&a) ? std::future<bool>{} : loadOwnAhead(&a);
  const Status spectra = a.shared ? sharedSpectra(&a) : spectraAndNoise(&a);
  a.own_loaded = own.valid() && own.get();
  if (!spectra.ok()) return stop(spectra);
  if (options.full_scalogram)
    if (Status s = fullScalogram(&a); !s.ok()) return s;
  if (!a.shared) peakSpectrum(&a);  // shared mode computed it with the rows' power
  const std::vector<ModeSeed> seeds = pickModes(&a);
  if (seeds.empty()) return {};
  return fitModes(&a, seeds);
}

Status analyzeWavelet(const double* y, long n, double sample_rate, const WaveletOptions& options,
                      WaveletResult* result) {
  if (result) *result = WaveletResult{};
  WaveletAnalyzer analyzer;
  return analyzer.analyze(y, n, sample_rate, options, result);
}

Status analyzeWavelet(const std::vector<double>& y, double sample_rate,
                      const WaveletOptions& options, WaveletResult* result) {
  return analyzeWavelet(y.data(), static_cast<long>(y.size()), sample_rate, options, result);
}

Status analyzeWavelet(const Eigen::VectorXd& y, double sample_rate, const WaveletOptions& options,
                      WaveletResult* result) {
  return analyzeWavelet(y.data(), static_cast<long>(y.size()), sample_rate, options, result);
}

// ------------------------------------------------------------------------------------------
// High-level entry point and the integral-method comparison

WaveletResult validateWavelet(const double* y, size_t n, double sample_rate,
                              const WaveletOptions& options) {
  WaveletResult result;
  if (n > static_cast<size_t>(std::numeric_limits<long>::max())) {
    result.status = Status::resourceLimit(
        "validateWavelet: n = " + std::to_string(n) + " samples is too large", "n");
    return result;
  }
  if (Status s = analyzeWavelet(y, static_cast<long>(n), sample_rate, options, &result); !s.ok()) {
    result = WaveletResult{};
    result.status = s;
  }
  return result;
}

WaveletResult validateWavelet(const std::vector<double>& y, double sample_rate,
                              const WaveletOptions& options) {
  return validateWavelet(y.data(), y.size(), sample_rate, options);
}

double integralDampingRatio(double C_per_s, double omega0_rad_s) {
  if (!std::isfinite(C_per_s) || !std::isfinite(omega0_rad_s) || !(omega0_rad_s > 0.0)) {
    return kNaN;
  }
  return C_per_s / (2.0 * omega0_rad_s);
}

void attachIntegralDampingRatio(WaveletResult* result, double xi_integral) {
  if (!result) return;
  for (WaveletMode& m : result->modes) m.integral_xi = xi_integral;
}

std::string warningText(const QualityWarnings& warnings) {
  std::string s;
  for (const QualityWarning& w : warnings) s += (s.empty() ? "" : "; ") + w.code + ": " + w.text;
  return s;
}

std::vector<double> gearOrderFrequencies(double mesh_frequency_hz, int pinion_teeth,
                                         int gear_teeth) {
  std::vector<double> out;
  if (!(mesh_frequency_hz > 0.0) || !std::isfinite(mesh_frequency_hz)) return out;
  out.push_back(mesh_frequency_hz);
  if (pinion_teeth > 0) out.push_back(mesh_frequency_hz / pinion_teeth);
  if (gear_teeth > 0) out.push_back(mesh_frequency_hz / gear_teeth);
  return out;
}

}  // namespace gear_damping_id
