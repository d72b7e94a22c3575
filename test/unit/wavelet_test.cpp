// Unit tests of the Morlet-wavelet validation core (gear_damping_id/wavelet.hpp): the CWT
// against a direct time-domain convolution, its normalisation and ridge, damping ratios of
// analytic free decays (clean and at 30 dB SNR), overrides, warnings, invalid inputs and CSV.
#include "gear_damping_id/wavelet.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "../../gear_damping_id/src/core/decimated_row.hpp"
#include "../../gear_damping_id/src/core/halved_forward.hpp"
#include "../../gear_damping_id/src/core/vector_math.hpp"
#include "per_mode_agreement.hpp"
#include "scratch_dir.hpp"
#include "status_support.hpp"

namespace gear_damping_id {
namespace {

constexpr double kPi = 3.14159265358979323846;

// --- Named tolerances (with the reason for their size) ------------------------------------
// FFT CWT vs direct convolution: the brief's bar. Expected ~1e-13: the FFT's rounding, the
// 1e-16 band cut and the exp(-32) wrap-around of the padding.
constexpr double kCwtVsDirectTol = 1e-9;
// |W| of a pure sinusoid on its own row: exact in theory; rounding of the FFTs and the
// analytic cut (the sinusoid's negative frequency meets Psi(-s*w) <= 2 exp(-2*omega0^2)).
constexpr double kRidgeAmplitudeTol = 1e-9;
// Ridge frequency from 200 log-spaced rows (2.2 % apart) by a parabola in ln f: the brief's bar.
constexpr double kRidgeFrequencyTol = 1e-3;
// Time-averaged scalogram of a sinusoid on its own row: A^2 up to the energy of the edges
// (the wavelet's response to the start/end of the record spills over ~tau_coi/T = 0.2 %).
constexpr double kMeanPowerTol = 1e-2;
// Damping ratio, clean single mode: the brief's bar (measured: < 1e-4 relative).
constexpr double kSingleModeXiTol = 0.01;
// Clean multi-mode free decay: docs/method.md §7 / brief bars for xi and frequency.
constexpr double kMultiModeXiTol = 0.02;
constexpr double kModeFrequencyTol = 2e-3;
// 30 dB SNR, median over nine seeds: docs/method.md §7 bar (measured: < 1 %).
constexpr double kNoisyXiTol = 0.05;
// White-noise estimate from the wavelet row at 0.45 fs: Rayleigh median of ~1e4 correlated
// samples; 15 % leaves room for the scatter of a single record.
constexpr double kNoiseStdTol = 0.15;

// --- Signals -------------------------------------------------------------------------------
struct Mode {
  double f;   // damped frequency f_d [Hz]
  double xi;  // damping ratio
  double amplitude;
  double phase;  // [rad]
};

double sigmaOf(const Mode& m) {  // decay rate [1/s] for xi and f_d: sigma = xi*w_n
  return m.xi * 2.0 * kPi * m.f / std::sqrt(1.0 - m.xi * m.xi);
}

// Free decay sum_i A_i exp(-sigma_i (t - t0)) cos(2 pi f_i (t - t0) + phi_i) for t >= t0,
// 0 before, plus white Gaussian noise at snr_db = 20 log10(std(y - mean y) / sigma_noise)
// (no noise when snr_db is infinite).
std::vector<double> freeDecay(const std::vector<Mode>& modes, double fs, long n,
                              double snr_db = INFINITY, unsigned seed = 1, double t0 = 0.0) {
  std::vector<double> y(static_cast<size_t>(n), 0.0);
  for (const Mode& m : modes) {
    const double s = sigmaOf(m), w = 2.0 * kPi * m.f;
    for (long j = 0; j < n; ++j) {
      const double t = static_cast<double>(j) / fs - t0;
      if (t >= 0.0) y[size_t(j)] += m.amplitude * std::exp(-s * t) * std::cos(w * t + m.phase);
    }
  }
  if (std::isfinite(snr_db)) {
    double mean = 0.0, var = 0.0;
    for (double v : y) mean += v;
    mean /= static_cast<double>(n);
    for (double v : y) var += (v - mean) * (v - mean);
    const double sd = std::sqrt(var / static_cast<double>(n)) / std::pow(10.0, snr_db / 20.0);
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> noise(0.0, sd);
    for (double& v : y) v += noise(rng);
  }
  return y;
}

double noiseStdFor(const std::vector<double>& clean, double snr_db) {
  double mean = 0.0, var = 0.0;
  for (double v : clean) mean += v;
  mean /= static_cast<double>(clean.size());
  for (double v : clean) var += (v - mean) * (v - mean);
  return std::sqrt(var / static_cast<double>(clean.size())) / std::pow(10.0, snr_db / 20.0);
}

double relErr(double value, double truth) { return std::abs(value / truth - 1.0); }

// The record's mean, summed in index order (as MorletCwt::setSignal takes it).
double meanOf(const std::vector<double>& y) {
  double mean = 0.0;
  for (double v : y) mean += v;
  return mean / static_cast<double>(y.size());
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// The analysed mode nearest to f (nullptr if none within 5 %).
const WaveletMode* modeNear(const WaveletResult& r, double f) {
  const WaveletMode* best = nullptr;
  for (const WaveletMode& m : r.modes) {
    if (relErr(m.frequency_hz, f) < 0.05 &&
        (!best || relErr(m.frequency_hz, f) < relErr(best->frequency_hz, f))) {
      best = &m;
    }
  }
  return best;
}

// Gaussian tone bursts at the test rows' frequencies. With cut_at_edges the first and last
// bursts are cut by the record's ends (broadband steps reaching zero frequency).
std::vector<double> toneBursts(long n, double fs, bool cut_at_edges) {
  struct Burst {
    double t, width, f, amp;
  };
  const double T = static_cast<double>(n) / fs;
  const double e0 = cut_at_edges ? 0.02 : 0.1, e1 = cut_at_edges ? 0.97 : 0.93;
  const std::vector<Burst> bursts = {{e0 * T, 0.015 * T, 0.05 * fs, 1.0},
                                     {0.35 * T, 0.1 * T, 0.004 * fs, 0.7},
                                     {0.55 * T, 0.04 * T, 0.012 * fs, 0.5},
                                     {0.7 * T, 0.01 * T, 0.1 * fs, 0.6},
                                     {e1 * T, 0.008 * T, 0.18 * fs, 0.8}};
  std::vector<double> y(static_cast<size_t>(n), 0.0);
  for (long j = 0; j < n; ++j) {
    const double t = static_cast<double>(j) / fs;
    for (const Burst& b : bursts) {
      const double u = (t - b.t) / b.width;
      y[size_t(j)] += b.amp * std::exp(-0.5 * u * u) * std::cos(2.0 * kPi * b.f * t + 0.4);
    }
  }
  return y;
}

// erfcx(z) = exp(z^2) erfc(z) for Re z > 0 and |z| >= 4 by its asymptotic series
// 1/(z sqrt(pi)) * sum_k (-1)^k (2k-1)!! / (2 z^2)^k, summed to its smallest term (relative
// accuracy < 1e-8 for |z| >= 4.2).
std::complex<double> erfcxAsymptotic(std::complex<double> z) {
  const std::complex<double> q = 1.0 / (2.0 * z * z);
  std::complex<double> term = 1.0, sum = 1.0;
  double last = 1.0;
  for (int k = 1; k < 60; ++k) {
    term *= -static_cast<double>(2 * k - 1) * q;
    if (std::abs(term) >= last || std::abs(term) < 1e-18) break;
    last = std::abs(term);
    sum += term;
  }
  return sum / (z * std::sqrt(kPi));
}

// The documented analytic Morlet in the time domain: psi_a(u) = psi(u) - c(u) with the Gabor
// form psi(u) = sqrt(2/pi) e^{i w0 u} e^{-u^2/2} (Fourier transform 2 e^{-(w - w0)^2/2} on
// all w) minus its negative-frequency part
//   c(u) = (1/2 pi) int_{-inf}^0 2 e^{-(w - w0)^2/2} e^{i w u} dw
//        = (1/pi) e^{-w0^2/2} sqrt(pi/2) erfcx((w0 + i u)/sqrt(2)),
// which is ~ 2 e^{-w0^2/2} = 3e-8 of the peak for w0 = 6 and decays only like 1/u.
std::complex<double> analyticMorlet(double u, double omega0) {
  const std::complex<double> gabor =
      std::sqrt(2.0 / kPi) * std::exp(-0.5 * u * u) * std::polar(1.0, omega0 * u);
  const std::complex<double> c = std::exp(-0.5 * omega0 * omega0) / kPi * std::sqrt(kPi / 2.0) *
                                 erfcxAsymptotic(std::complex<double>(omega0, u) / std::sqrt(2.0));
  return gabor - c;
}

// W(f, t_m) by direct summation over the record (zero outside, mean removed, like the FFT
// path): sum_j (y_j - mean) (dt/s) conj(psi_a((t_j - t_m)/s)), over every tap (the cut's
// 1/u tail is long).
std::vector<std::complex<double>> directCwt(const std::vector<double>& y, double fs, double f,
                                            double omega0) {
  const long n = static_cast<long>(y.size());
  const double mean = meanOf(y);
  const double s = omega0 / (2.0 * kPi * f) * fs;  // scale [samples]
  std::vector<std::complex<double>> kernel(static_cast<size_t>(2 * n - 1));
  for (long d = -(n - 1); d <= n - 1; ++d) {  // conj(psi_a(d/s)) / s
    kernel[size_t(d + n - 1)] = std::conj(analyticMorlet(static_cast<double>(d) / s, omega0)) / s;
  }
  std::vector<std::complex<double>> w(static_cast<size_t>(n));
  for (long m = 0; m < n; ++m) {
    std::complex<double> acc = 0.0;
    for (long j = 0; j < n; ++j) acc += (y[size_t(j)] - mean) * kernel[size_t(j - m + n - 1)];
    w[size_t(m)] = acc;
  }
  return w;
}

// --- CWT core --------------------------------------------------------------------------------

TEST(MorletCwt, MatchesDirectConvolutionWithTheSameWaveletIncludingTheRecordEdges) {
  const double fs = 1000.0;
  const long n = 3000;
  // Rows whose wavelet spectrum stays below Nyquist (f (1 + 8.6/omega0) < fs/2), so no cut; the
  // 4 Hz row's wavelet (s = 239 samples at omega0 = 6) reaches 2000 samples past either end,
  // so any wrap-around of the circular convolution would show at the record's edges. Every
  // time, including the edges, is compared.
  const std::vector<double> freqs = {0.004 * fs, 0.012 * fs, 0.05 * fs, 0.18 * fs};
  struct Case {
    double omega0;
    bool cut_at_edges;
  };
  for (const Case c : {Case{6.0, false}, Case{6.0, true}, Case{12.0, true}}) {
    const std::vector<double> y = toneBursts(n, fs, c.cut_at_edges);
    MorletCwt cwt;
    std::string error;
    ASSERT_TRUE(gear_test::ok(cwt.configure(n, fs, freqs, c.omega0, FftPlanning::Estimate), &error))
        << error;
    std::vector<std::complex<double>> out(freqs.size() * size_t(n));
    ASSERT_TRUE(gear_test::ok(cwt.transform(y.data(), out.data()), &error)) << error;
    for (size_t i = 0; i < freqs.size(); ++i) {
      const auto direct = directCwt(y, fs, freqs[i], c.omega0);
      double peak = 0.0, worst = 0.0;
      for (long m = 0; m < n; ++m) peak = std::max(peak, std::abs(direct[size_t(m)]));
      for (long m = 0; m < n; ++m) {
        worst = std::max(worst, std::abs(out[i * size_t(n) + size_t(m)] - direct[size_t(m)]));
      }
      EXPECT_LT(worst / peak, kCwtVsDirectTol)
          << "omega0 " << c.omega0 << ", row " << freqs[i] << " Hz (peak |W| " << peak << ")";
      std::printf("[ measured ] direct vs FFT, omega0 %4.1f%s, f %5.1f Hz: max rel error %.2e\n",
                  c.omega0, c.cut_at_edges ? " (edge-cut bursts)" : "", freqs[i], worst / peak);
    }
  }
}

TEST(MorletCwt, PureSinusoidReadsItsAmplitudeAndFrequencyOnTheRidge) {
  const double fs = 20000.0, f = 1234.5, A = 2.5;
  const long n = 20000;
  std::vector<double> y(static_cast<size_t>(n));
  for (long j = 0; j < n; ++j) y[size_t(j)] = A * std::cos(2.0 * kPi * f * j / fs + 0.7);
  // Own row: |W| = A and phase advancing at 2 pi f, 5 COI half-widths from the edges (where
  // the wavelet's Gaussian is exp(-25) = 1e-11).
  MorletCwt own;
  std::string error;
  ASSERT_TRUE(gear_test::ok(own.configure(n, fs, {f}, 6.0, FftPlanning::Estimate), &error))
      << error;
  ASSERT_TRUE(gear_test::ok(own.setSignal(y.data()), &error)) << error;
  const std::complex<double>* w = own.row(0);
  ASSERT_NE(w, nullptr);
  const long edge = static_cast<long>(std::ceil(5.0 * morletConeOfInfluence(f, 6.0) * fs));
  double worst_amp = 0.0, worst_phase = 0.0;
  for (long j = edge; j < n - edge; ++j) {
    worst_amp = std::max(worst_amp, std::abs(std::abs(w[j]) / A - 1.0));
    const std::complex<double> expected = std::polar(A, 2.0 * kPi * f * j / fs + 0.7);
    worst_phase = std::max(worst_phase, std::abs(std::arg(w[j] / expected)));
  }
  EXPECT_LT(worst_amp, kRidgeAmplitudeTol);
  EXPECT_LT(worst_phase, kRidgeAmplitudeTol);
  EXPECT_NEAR(own.meanPower(0), A * A, kMeanPowerTol * A * A);
  std::printf("[ measured ] sinusoid: max ||W|/A - 1| %.2e, phase %.2e rad, mean power %.4f A^2\n",
              worst_amp, worst_phase, own.meanPower(0) / (A * A));

  // 200 log-spaced rows: the ridge (parabola in ln f) sits on f at every time outside the COI
  // of the lowest row.
  const std::vector<double> grid = logSpacedFrequencies(100.0, 8000.0, 200);
  MorletCwt cwt;
  ASSERT_TRUE(gear_test::ok(cwt.configure(n, fs, grid, 6.0, FftPlanning::Estimate), &error))
      << error;
  std::vector<double> modulus(grid.size() * size_t(n));
  ASSERT_TRUE(gear_test::ok(cwt.transformModulus(y.data(), modulus.data()), &error)) << error;
  const long e2 = static_cast<long>(std::ceil(3.0 * morletConeOfInfluence(f / 1.1, 6.0) * fs));
  double worst_f = 0.0;
  std::vector<double> column(grid.size());
  for (long j = e2; j < n - e2; j += 7) {
    for (size_t i = 0; i < grid.size(); ++i) column[i] = modulus[i * size_t(n) + size_t(j)];
    const double fr = ridgeFrequency(grid.data(), column.data(), static_cast<int>(grid.size()));
    worst_f = std::max(worst_f, relErr(fr, f));
  }
  EXPECT_LT(worst_f, kRidgeFrequencyTol);
  std::printf("[ measured ] sinusoid ridge frequency: max relative error %.2e\n", worst_f);
}

// MorletCwt::paddedLength is the FFT length configure() chooses (the per-mode path reuses a
// transform of that length for rows of other frequencies): rows of one and of several omega0s,
// lengths that are and are not fast, the widest row first or last.
TEST(MorletCwt, PaddedLengthIsTheLengthConfigureChooses) {
  const double fs = 50000.0;
  const std::vector<std::pair<std::vector<double>, std::vector<double>>> rows = {
      {{1000.0}, {6.0}},
      {{300.0, 1731.0, 7375.0}, {30.0}},
      {{7375.0, 1731.0, 300.0}, {6.0, 12.0, 30.0}},
      {{40.0, 20000.0}, {3.0, 6.0}},
  };
  for (const long n : {64L, 1000L, 12000L, 100003L}) {
    for (const auto& [f, w] : rows) {
      MorletCwt cwt;
      ASSERT_TRUE(cwt.configure(n, fs, f, w, FftPlanning::Estimate).ok());
      EXPECT_EQ(MorletCwt::paddedLength(n, fs, f, w), cwt.paddedSize())
          << "n " << n << ", lowest row " << *std::min_element(f.begin(), f.end()) << " Hz";
      EXPECT_GE(cwt.paddedSize(), n);
    }
  }
}

TEST(MorletCwt, ReusesItsPlansAndBuffersAcrossRowsAndSignals) {
  const double fs = 1000.0;
  const long n = 1500;
  const std::vector<double> grid = logSpacedFrequencies(20.0, 300.0, 12);
  const std::vector<double> a = toneBursts(n, fs, true);
  std::vector<double> b = a;
  std::reverse(b.begin(), b.end());
  MorletCwt reused, fresh;
  std::string error;
  ASSERT_TRUE(gear_test::ok(reused.configure(n, fs, grid, 6.0, FftPlanning::Estimate), &error))
      << error;
  ASSERT_TRUE(gear_test::ok(fresh.configure(n, fs, grid, 6.0, FftPlanning::Estimate), &error))
      << error;
  std::vector<double> first(grid.size() * size_t(n)), second(first.size()), ref(first.size());
  ASSERT_TRUE(gear_test::ok(reused.transformModulus(a.data(), first.data()), &error));
  ASSERT_TRUE(gear_test::ok(reused.transformModulus(b.data(), second.data()), &error));
  ASSERT_TRUE(gear_test::ok(fresh.transformModulus(b.data(), ref.data()), &error));
  EXPECT_EQ(second, ref);  // no state leaks from the first signal (same plan: bitwise equal)
  const std::complex<double>* p0 = reused.row(0);
  const std::complex<double>* p1 = reused.row(5);
  EXPECT_EQ(p0, p1) << "rows must reuse one output buffer";
  EXPECT_GE(reused.paddedSize(), n);
  EXPECT_EQ(reused.paddedSize(), fastFftLength(reused.paddedSize()));
}

// The pruned |W| of narrow-band rows (N/M batched size-M FFTs) against |row()| from the full
// inverse FFT: rounding only. Grid from 10 cycles per record to 0.4 fs, as in the benchmark,
// so most rows take the pruned path and the top ones the full one.
TEST(MorletCwt, PrunedModulusOfNarrowBandRowsEqualsTheFullInverseFft) {
  constexpr double kPrunedTol = 1e-12;  // relative to the row's peak; measured ~1e-15
  const double fs = 1000.0;
  const long n = 6000;
  const std::vector<double> grid = logSpacedFrequencies(10.0 * fs / n, 0.4 * fs, 40);
  const std::vector<double> y = toneBursts(n, fs, true);
  MorletCwt cwt;
  std::string error;
  ASSERT_TRUE(gear_test::ok(cwt.configure(n, fs, grid, 6.0, FftPlanning::Estimate), &error))
      << error;
  ASSERT_TRUE(gear_test::ok(cwt.setSignal(y.data()), &error)) << error;
  std::vector<double> fast(static_cast<size_t>(n));
  std::vector<float> fast_f(static_cast<size_t>(n));
  double worst = 0.0;
  for (int i = 0; i < cwt.rows(); ++i) {
    ASSERT_TRUE(cwt.rowModulus(i, fast.data()));
    ASSERT_TRUE(cwt.rowModulus(i, fast_f.data()));
    const std::complex<double>* w = cwt.row(i);
    ASSERT_NE(w, nullptr);
    double peak = 0.0, err = 0.0;
    for (long j = 0; j < n; ++j) peak = std::max(peak, std::abs(w[j]));
    for (long j = 0; j < n; ++j) {
      err = std::max(err, std::abs(fast[size_t(j)] - std::abs(w[j])));
      EXPECT_NEAR(fast_f[size_t(j)], std::abs(w[j]), 1e-6 * peak);
    }
    ASSERT_GT(peak, 0.0);
    worst = std::max(worst, err / peak);
  }
  std::printf("[ measured ] pruned vs full |W|: max error %.2e of the row's peak\n", worst);
  EXPECT_LT(worst, kPrunedTol);
  cwt.setPrunedModulus(false);
  ASSERT_TRUE(cwt.rowModulus(0, fast.data()));
  const std::complex<double>* w = cwt.row(0);
  for (long j = 0; j < n; ++j) EXPECT_DOUBLE_EQ(fast[size_t(j)], std::abs(w[j]));
}

// The test below: cwt configured for 10 rows from 2 to 400 Hz (omega0 6) holding
// toneBursts(n, fs) with edge-cut bursts.
void loadToneBursts(MorletCwt* cwt, long n, double fs) {
  std::string error;
  ASSERT_TRUE(gear_test::ok(
      cwt->configure(n, fs, logSpacedFrequencies(2.0, 400.0, 10), 6.0, FftPlanning::Estimate),
      &error))
      << error;
  ASSERT_TRUE(gear_test::ok(cwt->setSignal(toneBursts(n, fs, true).data()), &error)) << error;
}

// DecimatedRows (the per-mode path's fit rows): W at every D-th sample from one inverse FFT of
// length N/D of the band folded modulo N/D, against rowAt's full (or pruned) row at the same
// samples, for narrow and wide rows (up to the Nyquist cut) and D from 1 to past the band's
// rate (folded bins overlap: still exact at the samples). Bound 1e-12 of the row's peak: FFT
// rounding of two transforms of different lengths (measured ~1e-15).
TEST(MorletCwt, DecimatedRowsEqualTheFullRowAtTheirSamples) {
  constexpr double kDecimatedTol = 1e-12;
  const double fs = 1000.0;
  const long n = 6000;
  MorletCwt cwt;
  ASSERT_NO_FATAL_FAILURE(loadToneBursts(&cwt, n, fs));
  const long N = cwt.paddedSize();
  wavelet_detail::DecimatedRows rows;
  double worst = 0.0;
  for (double f : {5.0, 37.0, 120.0, 310.0, 450.0}) {
    const std::complex<double>* full = cwt.rowAt(f, 6.0);
    ASSERT_NE(full, nullptr) << f;
    const std::vector<std::complex<double>> w(full, full + n);
    double peak = 0.0;
    for (const auto& v : w) peak = std::max(peak, std::abs(v));
    const double a = 6.0 * fs / (f * static_cast<double>(N));
    const long band_d = wavelet_detail::DecimatedRows::bandDecimation(N, a, 6.0);
    for (long d : {1L, 2L, 3L, 7L, band_d, 4 * band_d}) {
      const long D = wavelet_detail::DecimatedRows::divisorAtMost(N, d);
      ASSERT_EQ(N % D, 0) << D;
      const std::complex<double>* dec = rows.row(cwt.spectrum(), N, a, 6.0, D);
      ASSERT_NE(dec, nullptr) << f << " Hz, D " << D;
      double err = 0.0;
      for (long m = 0; m * D < n; ++m) err = std::max(err, std::abs(dec[m] - w[size_t(m * D)]));
      EXPECT_LT(err / peak, kDecimatedTol) << f << " Hz, D " << D;
      worst = std::max(worst, err / peak);
    }
  }
  std::printf("[ measured ] decimated vs full rows: max error %.2e of the row's peak\n", worst);
  EXPECT_EQ(wavelet_detail::DecimatedRows::divisorAtMost(N, 0), 1);
  EXPECT_EQ(rows.row(cwt.spectrum(), N, 6.0 * fs / (100.0 * N), 6.0, N + 1), nullptr);
}

// BlockedRow (the per-mode path's rows of grid D = 1 over their peak and decay region): W from
// overlapping blocks of the record itself, against rowAt's padded row, over the whole record and
// on a range asked for alone. Bound 1e-7 of the row's peak: the analytic cut at zero frequency
// rings over the whole padded row (Psi(0) = 2e^-18 at omega0 = 6), not in a block; the rest is
// FFT rounding and the wavelet's tail beyond 8 scales (e^-32).
TEST(MorletCwt, BlockedRowsEqualThePaddedRow) {
  constexpr double kBlockedTol = 1e-7;
  const double fs = 1000.0;
  const long n = 6000;
  MorletCwt cwt;
  ASSERT_NO_FATAL_FAILURE(loadToneBursts(&cwt, n, fs));
  const std::vector<double> y = toneBursts(n, fs, true);
  const double mean = meanOf(y);
  wavelet_detail::BlockedRow blocked;
  double worst = 0.0;
  for (double s_fs : {4.7, 5.0, 12.0, 31.0}) {
    const double f = 6.0 * fs / (2.0 * kPi * s_fs);
    const std::complex<double>* full = cwt.rowAt(f, 6.0);
    ASSERT_NE(full, nullptr) << f;
    double peak = 0.0;
    for (long j = 0; j < n; ++j) peak = std::max(peak, std::abs(full[j]));
    ASSERT_TRUE(blocked.configure(y.data(), n, mean, s_fs, 6.0)) << s_fs;
    const long j0 = n / 3, j1 = n / 3 + 17;  // a range alone, then everything
    blocked.ensure(j0, j1);
    double err = 0.0;
    for (long j = j0; j <= j1; ++j) err = std::max(err, std::abs(blocked.w()[j] - full[j]));
    blocked.ensure(-5, n + 5);
    for (long j = 0; j < n; ++j) {
      err = std::max(err, std::abs(blocked.w()[j] - full[j]));
      EXPECT_EQ(blocked.env()[size_t(j)], std::sqrt(std::norm(blocked.w()[j]))) << j;
    }
    EXPECT_LT(err / peak, kBlockedTol) << s_fs;
    worst = std::max(worst, err / peak);
  }
  std::printf("[ measured ] blocked vs padded rows: max error %.2e of the row's peak\n", worst);
  // The band reaches the Nyquist frequency (s*fs = 2 at omega0 = 6): refused.
  EXPECT_FALSE(blocked.configure(y.data(), n, mean, 2.0, 6.0));
}

// The low band's two ways against FFTW's transform of the whole zero-padded record: a record
// with an offset, white noise, a low line and a line 1e4 times stronger at 0.3 fs that the
// decimation aliases onto the band. Bound of the decimation way: its stopband (10^(-200/20) of
// the aliased bins, the strongest being the line's peak) plus rounding of the FIR's sums and of
// the gains (a few 1e-13 of each bin); the polyphase way is exact to rounding.
TEST(MorletCwt, LowBandWaysEqualTheTransformOfTheWholePaddedRecord) {
  const long n = 200000, N = 352800;  // N = 2^5 3^2 5^2 7^2
  std::mt19937_64 rng(7);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::vector<double> y(static_cast<size_t>(n));
  for (long t = 0; t < n; ++t) {
    const double tt = static_cast<double>(t);
    y[size_t(t)] = 3.0 + noise(rng) + 5.0 * std::sin(2.0 * kPi * 0.004 * tt) +
                   1e4 * std::sin(2.0 * kPi * 0.3 * tt + 0.4);
  }
  const double mean = meanOf(y);
  std::vector<double> padded(static_cast<size_t>(N), 0.0);
  for (long t = 0; t < n; ++t) padded[size_t(t)] = y[size_t(t)] - mean;
  std::vector<std::complex<double>> ref(static_cast<size_t>(N / 2 + 1));
  fftw_plan p = fftw_plan_dft_r2c_1d(static_cast<int>(N), padded.data(),
                                     reinterpret_cast<fftw_complex*>(ref.data()), FFTW_ESTIMATE);
  ASSERT_NE(p, nullptr);
  fftw_execute(p);
  fftw_destroy_plan(p);
  double peak = 0.0;
  for (const auto& v : ref) peak = std::max(peak, std::abs(v));
  const double stopband = std::pow(10.0, -wavelet_detail::LowBand::kStopbandDb / 20.0);
  // FFT rounding: ~eps log2(N) times the record's 2-norm per bin (a margin of 64).
  double norm2 = 0.0;
  for (double v : padded) norm2 += v * v;
  const double rounding = 64.0 * 2.2e-16 * std::log2(static_cast<double>(N)) * std::sqrt(norm2);
  wavelet_detail::LowBand low;
  for (long K : {N / 60, N / 200, 300L, N / 12}) {
    for (bool exact : {false, true}) {
      ASSERT_TRUE(low.compute(y.data(), n, mean, N, K, exact)) << K;
      const long D = low.decimation();
      if (exact || N / (6 * K) < 3) {
        EXPECT_EQ(D, 0) << K;
      } else {
        EXPECT_GE(D, 3) << K;
        EXPECT_EQ(N % D, 0) << K;
      }
      double worst = 0.0, worst_rel = 0.0;
      for (long k = 0; k < K; ++k) {
        const double err = std::abs(low.spectrum()[k] - ref[size_t(k)]);
        const double bound = (D > 0 ? stopband * peak : 0.0) + rounding;
        EXPECT_LE(err, bound) << "K " << K << " D " << D << " bin " << k;
        worst = std::max(worst, err);
        if (k > 0) worst_rel = std::max(worst_rel, err / std::abs(ref[size_t(k)]));
      }
      std::printf(
          "[ measured ] low band K=%ld D=%ld: worst bin error %.2e (rounding bound %.1e, "
          "alias bound %.1e), relative %.2e\n",
          K, D, worst, rounding, stopband * peak, worst_rel);
    }
  }
  // A record filling the padding: the filter's outputs (n + 2H samples / D) no longer fit in
  // N/D, so the polyphase way answers.
  const long n_full = N - 4;
  std::vector<double> y_full(static_cast<size_t>(n_full), 0.0);
  for (long t = 0; t < n_full; ++t) y_full[size_t(t)] = y[size_t(t % n)];
  ASSERT_TRUE(low.compute(y_full.data(), n_full, mean, N, 300));
  EXPECT_EQ(low.decimation(), 0);
  // FFTW_MEASURE planning overwrites the arrays it plans on: the polyphase way's rows that stay
  // zero are zeroed after planning, so both ways still give the transform.
  for (bool exact : {true, false}) {
    wavelet_detail::LowBand measured;
    measured.setPlanning(FftPlanning::Measure);
    ASSERT_TRUE(measured.compute(y.data(), n, mean, N, N / 200, exact));
    const double alias = measured.decimation() > 0 ? stopband * peak : 0.0;
    for (long k = 0; k < N / 200; ++k)
      ASSERT_LE(std::abs(measured.spectrum()[k] - ref[size_t(k)]), alias + rounding)
          << "measured planning, exact " << exact << ", bin " << k;
  }
}

// The record's transform in two halves (even and odd samples) and one joining pass equals
// FFTW's transform of the whole zero-padded record to its rounding, for records shorter than,
// one sample shorter than and as long as the padded length, either planning; odd or tiny
// lengths are refused (the caller then takes the whole transform).
TEST(MorletCwt, HalvedForwardEqualsTheTransformOfTheWholePaddedRecord) {
  const long N = 352800;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::vector<double> y(static_cast<size_t>(N));
  for (long t = 0; t < N; ++t)
    y[size_t(t)] = 2.0 + noise(rng) + 1e3 * std::sin(2.0 * kPi * 0.21 * static_cast<double>(t));
  for (const FftPlanning planning : {FftPlanning::Estimate, FftPlanning::Measure}) {
    wavelet_detail::HalvedForward halves;
    ASSERT_TRUE(halves.configure(N, planning));
    for (const long n : {200000L, 200001L, N - 1, N}) {
      std::vector<double> rec(y.begin(), y.begin() + n);
      const double mean = meanOf(rec);
      std::vector<double> padded(static_cast<size_t>(N), 0.0);
      for (long t = 0; t < n; ++t) padded[size_t(t)] = rec[size_t(t)] - mean;
      std::vector<std::complex<double>> ref(static_cast<size_t>(N / 2 + 1)), got(ref.size());
      fftw_plan p =
          fftw_plan_dft_r2c_1d(static_cast<int>(N), padded.data(),
                               reinterpret_cast<fftw_complex*>(ref.data()), FFTW_ESTIMATE);
      ASSERT_NE(p, nullptr);
      fftw_execute(p);
      fftw_destroy_plan(p);
      halves.transformHalf(1, rec.data(), n, mean);
      halves.transformHalf(0, rec.data(), n, mean);
      halves.join(got.data());
      // Both are FFTs of the same record: each within ~eps log2(N) of the record's 2-norm per
      // bin of the exact transform (a margin of 64, as for the low band).
      double norm2 = 0.0, worst = 0.0;
      for (double v : padded) norm2 += v * v;
      const double rounding = 64.0 * 2.2e-16 * std::log2(static_cast<double>(N)) * std::sqrt(norm2);
      for (size_t k = 0; k < ref.size(); ++k) worst = std::max(worst, std::abs(got[k] - ref[k]));
      EXPECT_LE(worst, rounding) << "n " << n;
      EXPECT_EQ(got[0].imag(), 0.0);
      EXPECT_EQ(got.back().imag(), 0.0);
      std::printf(
          "[ measured ] halved transform, n %ld of N %ld: worst bin error %.2e (bound %.1e, "
          "largest bin %.1e)\n",
          n, N, worst, rounding, std::abs(ref[size_t(std::lround(0.21 * N))]));
    }
  }
  wavelet_detail::HalvedForward odd;
  EXPECT_FALSE(odd.configure(N + 1));
  EXPECT_FALSE(odd.configure(2));
  EXPECT_EQ(odd.size(), 0);
}

// MorletCwt::checkedMean names the first sample that is not finite, wherever it lies in the
// partial sums, and gives a finite mean of finite samples whose plain sum overflows.
TEST(MorletCwt, CheckedMeanNamesTheFirstBadSampleAndSurvivesAnOverflowingSum) {
  std::vector<double> y(1001, 1.0);
  double mean = 0.0;
  ASSERT_TRUE(MorletCwt::checkedMean(y.data(), 1001, &mean).ok());
  EXPECT_EQ(mean, 1.0);
  for (const long bad : {0L, 5L, 997L, 1000L}) {
    std::vector<double> z = y;
    z[size_t(bad)] = std::numeric_limits<double>::quiet_NaN();
    if (bad == 5) z[900] = std::numeric_limits<double>::infinity();
    const gear_sim::Status s = MorletCwt::checkedMean(z.data(), 1001, &mean, "probe");
    EXPECT_EQ(s.code(), gear_sim::StatusCode::InvalidInput);
    EXPECT_NE(s.message().find("probe: sample " + std::to_string(bad) + " is not finite"),
              std::string::npos)
        << s.message();
  }
  std::vector<double> huge(1000, 1.5e308);
  huge[3] = -1e308;
  ASSERT_TRUE(MorletCwt::checkedMean(huge.data(), 1000, &mean).ok());
  const double expected = (999.0 * 1.5e308 / 1000.0) + (-1e308 / 1000.0);
  EXPECT_TRUE(std::isfinite(mean));
  EXPECT_NEAR(mean, expected, 1e-12 * expected);
}

TEST(MorletCwt, RefusesRowsItCannotComputeAndInvalidConfigurations) {
  MorletCwt cwt;
  std::string error;
  EXPECT_EQ(cwt.row(0), nullptr);  // not configured
  EXPECT_FALSE(gear_test::ok(cwt.setSignal(nullptr), &error));
  EXPECT_NE(error.find("not configured"), std::string::npos) << error;
  EXPECT_FALSE(
      gear_test::ok(cwt.configure(100, 1000.0, {600.0}, 6.0, FftPlanning::Estimate), &error));
  EXPECT_NE(error.find("frequencies[0]"), std::string::npos) << error;
  EXPECT_FALSE(gear_test::ok(cwt.configure(100, -1.0, {10.0}, 6.0, FftPlanning::Estimate), &error));
  EXPECT_NE(error.find("sample_rate"), std::string::npos) << error;
  EXPECT_FALSE(
      gear_test::ok(cwt.configure(100, 1000.0, {10.0}, 0.5, FftPlanning::Estimate), &error));
  EXPECT_NE(error.find("omega0"), std::string::npos) << error;
  EXPECT_FALSE(
      gear_test::ok(cwt.configure(100, 1000.0, {10.0, 20.0}, std::vector<double>{6.0, 6.0, 6.0},
                                  FftPlanning::Estimate),
                    &error));
  EXPECT_NE(error.find("omega0s"), std::string::npos) << error;
  // A row whose 8 scales need ~7.6e9 samples of padding: more than FFTW's int lengths hold,
  // refused before any allocation (it was planned with a truncated int length before).
  EXPECT_FALSE(gear_test::ok(cwt.configure(1000, 1e9, {0.76}, 6.0, FftPlanning::Estimate), &error));
  EXPECT_NE(error.find("too large"), std::string::npos) << error;
  EXPECT_FALSE(cwt.configured());
  ASSERT_TRUE(
      gear_test::ok(cwt.configure(100, 1000.0, {100.0}, 6.0, FftPlanning::Estimate), &error))
      << error;
  EXPECT_EQ(cwt.row(0), nullptr);  // no signal yet
  std::vector<double> y(100, 1.0);
  y[42] = NAN;
  EXPECT_FALSE(gear_test::ok(cwt.setSignal(y.data()), &error));
  EXPECT_NE(error.find("sample 42"), std::string::npos) << error;
  y[42] = 0.0;
  ASSERT_TRUE(gear_test::ok(cwt.setSignal(y.data()), &error)) << error;
  EXPECT_NE(cwt.row(0), nullptr);
  EXPECT_EQ(cwt.row(1), nullptr);
  EXPECT_EQ(cwt.rowAt(2.0, 6.0), nullptr) << "a 2 Hz wavelet is wider than the padding";
  EXPECT_EQ(cwt.rowAt(600.0, 6.0), nullptr) << "above Nyquist";
}

// The fits' logarithm and phase, four at a time where libmvec and AVX2 are there, agree with
// libm's one at a time (libmvec: within 4 ulp), including the clamp of a point below the floor,
// zeros, NaN and a length that is not a multiple of four.
TEST(WaveletHelpers, VectorLogAndPhaseAgreeWithLibm) {
  const long n = 1003;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<std::complex<double>> w(static_cast<size_t>(n));
  std::vector<double> env(static_cast<size_t>(n)), ly(env.size()), arg(env.size());
  for (long i = 0; i < n; ++i) {
    const double scale = std::pow(10.0, 40.0 * u(rng));
    w[size_t(i)] = {scale * u(rng), scale * u(rng)};
    env[size_t(i)] = std::abs(w[size_t(i)]);
  }
  w[7] = {0.0, 0.0}, env[7] = 0.0;
  w[8] = {-1.0, 0.0}, env[8] = 1.0;
  w[9] = {-1.0, -0.0}, env[9] = 1.0;
  env[1001] = std::numeric_limits<double>::quiet_NaN();
  const double floor2 = 1e-30;
  wavelet_detail::logEnvelopeAndPhase(env.data(), w.data(), n, floor2, ly.data(), arg.data());
  for (long i = 0; i < n; ++i) {
    const double e = env[size_t(i)];
    const double ly_ref = 0.5 * std::log(std::max(e * e - floor2, 1e-300));
    const double arg_ref = std::arg(w[size_t(i)]);
    if (std::isnan(ly_ref)) {
      EXPECT_TRUE(std::isnan(ly[size_t(i)])) << i;
    } else {
      EXPECT_NEAR(ly[size_t(i)], ly_ref, 8.9e-16 * std::max(1.0, std::abs(ly_ref))) << i;
    }
    EXPECT_NEAR(arg[size_t(i)], arg_ref, 8.9e-16 * std::max(1.0, std::abs(arg_ref))) << i;
  }
  EXPECT_GT(arg[8], 3.14);  // the sign of a zero imaginary part picks the side of the cut
  EXPECT_LT(arg[9], -3.14);
  std::printf("[ measured ] vector log and atan2 on this machine: %s\n",
              wavelet_detail::vectorMathAvailable() ? "libmvec (AVX2)" : "libm");
}

TEST(WaveletHelpers, FollowTheDocumentedConventions) {
  EXPECT_DOUBLE_EQ(morletScale(1000.0, 6.0), 6.0 / (2.0 * kPi * 1000.0));
  EXPECT_DOUBLE_EQ(morletConeOfInfluence(1000.0, 6.0), std::sqrt(2.0) * 6.0 / (2.0 * kPi * 1000.0));
  EXPECT_DOUBLE_EQ(morletLeakage(500.0, 500.0, 6.0), 1.0);
  EXPECT_NEAR(morletLeakage(7375.0, 14750.0, 6.0), std::exp(-4.5), 1e-15);
  const std::vector<double> f = logSpacedFrequencies(10.0, 1000.0, 3);
  ASSERT_EQ(f.size(), 3u);
  EXPECT_DOUBLE_EQ(f[0], 10.0);
  EXPECT_NEAR(f[1], 100.0, 1e-12);
  EXPECT_DOUBLE_EQ(f[2], 1000.0);
  EXPECT_TRUE(logSpacedFrequencies(10.0, 1.0, 5).empty());
  // fastFftLength: the smallest 7-smooth number >= n.
  auto smooth = [](long v) {
    for (long p : {2, 3, 5, 7}) {
      while (v % p == 0) v /= p;
    }
    return v == 1;
  };
  for (long n = 1; n < 3000; ++n) {
    const long m = fastFftLength(n);
    ASSERT_GE(m, n);
    ASSERT_TRUE(smooth(m)) << n;
    for (long k = n; k < m; ++k) ASSERT_FALSE(smooth(k)) << n;
  }
  EXPECT_EQ(fastFftLength(1000001), 1000188);  // 2^2 * 3^6 * 7^3
  EXPECT_TRUE(smooth(fastFftLength(1000001)));
  EXPECT_EQ(fastFftLength(0), -1);
}

// --- Damping --------------------------------------------------------------------------------

struct SingleCase {
  double f, xi;
};

class SingleDampedSinusoid : public ::testing::TestWithParam<SingleCase> {};

TEST_P(SingleDampedSinusoid, GivesTheDampingRatioWithinOnePercent) {
  const SingleCase c = GetParam();
  const Mode m{c.f, c.xi, 1.0, 0.3};
  const double fs = 250000.0;                         // 25..250 samples per period
  const long n = std::lround(8.0 / sigmaOf(m) * fs);  // eight envelope time constants
  WaveletOptions options;
  options.full_scalogram = false;
  WaveletResult r;
  std::string error;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(freeDecay({m}, fs, n), fs, options, &r), &error))
      << error;
  ASSERT_EQ(r.modes.size(), 1u);
  const WaveletMode& w = r.modes[0];
  EXPECT_LT(relErr(w.damping_ratio, c.xi), kSingleModeXiTol) << warningText(w.warnings);
  EXPECT_LT(relErr(w.frequency_hz, c.f), kModeFrequencyTol);
  EXPECT_LT(relErr(w.sigma, sigmaOf(m)), kSingleModeXiTol);
  EXPECT_GT(w.r2, 0.999);
  EXPECT_TRUE(w.warnings.empty()) << warningText(w.warnings);
  std::printf("[ measured ] f %6.0f Hz xi %.3f: xi error %.2e, f error %.2e (omega0 %.2f)\n", c.f,
              c.xi, relErr(w.damping_ratio, c.xi), relErr(w.frequency_hz, c.f), w.omega0);
}

INSTANTIATE_TEST_SUITE_P(FromLightToHeavyDamping, SingleDampedSinusoid,
                         ::testing::Values(SingleCase{1000, 0.002}, SingleCase{1000, 0.1},
                                           SingleCase{4000, 0.005}, SingleCase{4000, 0.02},
                                           SingleCase{10000, 0.01}, SingleCase{10000, 0.05},
                                           SingleCase{10000, 0.1}, SingleCase{2500, 0.002}));

// The paper's three frequencies (§4.3) with realistic, distinct damping ratios; the 7375 and
// 14750 Hz modes are only an octave apart (at omega0 = 6 the lower leaks 1.1 % into the upper).
const std::vector<Mode> kPaperModes = {
    {1731.0, 0.01, 1.0, 0.1}, {7375.0, 0.02, 0.6, 1.0}, {14750.0, 0.005, 0.4, 2.0}};
constexpr double kPaperFs = 200000.0;  // 13.6 samples per period of the highest mode
constexpr long kPaperN = 12000;        // 60 ms: the 1731 Hz mode decays to exp(-6.5)

TEST(AnalyzeWavelet, FindsAndSeparatesThePapersThreeModesWithinTwoPercent) {
  WaveletResult r;
  std::string error;
  ASSERT_TRUE(gear_test::ok(
      analyzeWavelet(freeDecay(kPaperModes, kPaperFs, kPaperN), kPaperFs, WaveletOptions{}, &r),
      &error))
      << error;
  ASSERT_EQ(r.modes.size(), 3u) << "peak picking must find exactly the three modes";
  for (const Mode& m : kPaperModes) {
    const WaveletMode* w = modeNear(r, m.f);
    ASSERT_NE(w, nullptr) << m.f;
    EXPECT_LT(relErr(w->damping_ratio, m.xi), kMultiModeXiTol)
        << m.f << " Hz: " << warningText(w->warnings);
    EXPECT_LT(relErr(w->frequency_hz, m.f), kModeFrequencyTol) << m.f;
    EXPECT_LT(relErr(w->spectrum_frequency_hz, m.f), kModeFrequencyTol) << m.f;
    EXPECT_TRUE(w->warnings.empty()) << warningText(w->warnings);
    EXPECT_TRUE(std::isnan(w->integral_xi));
    EXPECT_LT(w->t_start, w->t_end);
    std::printf("[ measured ] clean %5.0f Hz: xi error %.2e, f error %.2e, omega0 %.2f, R2 %.6f\n",
                m.f, relErr(w->damping_ratio, m.xi), relErr(w->frequency_hz, m.f), w->omega0,
                w->r2);
  }
  // The figure data is there: scalogram rows x decimated columns, spectra, COI.
  EXPECT_EQ(r.modulus.rows(), 200);
  EXPECT_LE(r.modulus.cols(), 2000);
  EXPECT_EQ(r.coi.size(), r.frequencies.size());
  EXPECT_EQ(r.spectrum_freq.size(), r.spectrum_power.size());
  EXPECT_TRUE(r.modulus.allFinite());
}

TEST(AnalyzeWavelet, KeepsThePapersThreeModesWithinFivePercentAt30dBSnr) {
  constexpr double kSnrDb = 30.0;
  const double true_noise = noiseStdFor(freeDecay(kPaperModes, kPaperFs, kPaperN), kSnrDb);
  std::vector<std::vector<double>> xi_err(kPaperModes.size()), f_err(kPaperModes.size());
  WaveletOptions options;
  options.full_scalogram = false;
  for (unsigned seed = 1; seed <= 9; ++seed) {
    WaveletResult r;
    std::string error;
    ASSERT_TRUE(
        gear_test::ok(analyzeWavelet(freeDecay(kPaperModes, kPaperFs, kPaperN, kSnrDb, seed),
                                     kPaperFs, options, &r),
                      &error))
        << error;
    EXPECT_EQ(r.modes.size(), 3u) << "seed " << seed;
    EXPECT_LT(relErr(r.noise_std, true_noise), kNoiseStdTol) << "seed " << seed;
    for (size_t i = 0; i < kPaperModes.size(); ++i) {
      const WaveletMode* w = modeNear(r, kPaperModes[i].f);
      ASSERT_NE(w, nullptr) << "seed " << seed << ", " << kPaperModes[i].f << " Hz";
      xi_err[i].push_back(relErr(w->damping_ratio, kPaperModes[i].xi));
      f_err[i].push_back(relErr(w->frequency_hz, kPaperModes[i].f));
    }
  }
  for (size_t i = 0; i < kPaperModes.size(); ++i) {
    EXPECT_LT(median(xi_err[i]), kNoisyXiTol) << kPaperModes[i].f << " Hz";
    EXPECT_LT(median(f_err[i]), kModeFrequencyTol) << kPaperModes[i].f << " Hz";
    std::printf("[ measured ] 30 dB %5.0f Hz: median xi error %.2e (max %.2e), f error %.2e\n",
                kPaperModes[i].f, median(xi_err[i]),
                *std::max_element(xi_err[i].begin(), xi_err[i].end()), median(f_err[i]));
  }
}

TEST(AnalyzeWavelet, KeepsSingleModesFromLightToHeavyDampingWithinFivePercentAt30dBSnr) {
  const double fs = 100000.0;
  WaveletOptions options;
  options.full_scalogram = false;
  for (double xi : {0.002, 0.01, 0.05, 0.1}) {
    const Mode m{2000.0, xi, 1.0, 0.3};
    const long n = std::lround(8.0 / sigmaOf(m) * fs);
    std::vector<double> err;
    for (unsigned seed = 1; seed <= 9; ++seed) {
      WaveletResult r;
      std::string error;
      ASSERT_TRUE(gear_test::ok(analyzeWavelet(freeDecay({m}, fs, n, 30.0, seed), fs, options, &r),
                                &error));
      ASSERT_EQ(r.modes.size(), 1u);
      err.push_back(relErr(r.modes[0].damping_ratio, xi));
    }
    EXPECT_LT(median(err), kNoisyXiTol) << "xi " << xi;
    std::printf("[ measured ] 30 dB single xi %.3f: median xi error %.2e\n", xi, median(err));
  }
}

TEST(AnalyzeWavelet, HandlesADecayStartingInsideTheRecord) {
  const double fs = 50000.0;
  const Mode m{2000.0, 0.01, 1.0, 0.3};
  WaveletResult r;
  std::string error;
  ASSERT_TRUE(gear_test::ok(
      analyzeWavelet(freeDecay({m}, fs, 5000, INFINITY, 1, 0.02), fs, WaveletOptions{}, &r),
      &error));
  ASSERT_EQ(r.modes.size(), 1u);
  EXPECT_GT(r.modes[0].t_start, 0.02) << "the region must start after the impulse";
  EXPECT_LT(relErr(r.modes[0].damping_ratio, m.xi), kSingleModeXiTol);
}

TEST(AnalyzeWavelet, SeparatesModesTwentyPercentApartWithAnAutomaticOmega0) {
  const double fs = 50000.0;
  const std::vector<Mode> modes = {{1000.0, 0.005, 1.0, 0.1}, {1200.0, 0.005, 0.7, 1.0}};
  const std::vector<double> y = freeDecay(modes, fs, 20000);
  WaveletOptions options;
  options.full_scalogram = false;
  WaveletResult r;
  std::string error;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, fs, options, &r), &error)) << error;
  ASSERT_EQ(r.modes.size(), 2u);
  for (const Mode& m : modes) {
    const WaveletMode* w = modeNear(r, m.f);
    ASSERT_NE(w, nullptr);
    EXPECT_LT(relErr(w->damping_ratio, m.xi), kMultiModeXiTol);
    EXPECT_GT(w->omega0, 12.0) << "separating modes 20 % apart needs omega0 > 3.7/0.2/...";
    EXPECT_TRUE(w->warnings.empty()) << warningText(w->warnings);
  }
  // Forcing omega0 = 6 on the same data: the modes leak into each other, and each mode says so.
  options.fit_omega0 = 6.0;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, fs, options, &r), &error)) << error;
  ASSERT_EQ(r.modes.size(), 2u);
  for (const WaveletMode& w : r.modes) {
    EXPECT_NE(warningText(w.warnings).find("closer than the wavelet"), std::string::npos)
        << warningText(w.warnings);
  }
}

TEST(AnalyzeWavelet, UsesExplicitModeFrequenciesAndDecayRegions) {
  const Mode m{3000.0, 0.01, 1.0, 0.0};
  const double fs = 60000.0;
  const std::vector<double> y = freeDecay({m}, fs, 12000);
  WaveletOptions options;
  options.full_scalogram = false;
  options.mode_frequencies = {3000.0};
  options.decay_regions = {{0.005, 0.03}};
  WaveletResult r;
  std::string error;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, fs, options, &r), &error)) << error;
  ASSERT_EQ(r.modes.size(), 1u);
  EXPECT_DOUBLE_EQ(r.modes[0].t_start, 0.005);
  EXPECT_DOUBLE_EQ(r.modes[0].t_end, 0.03);
  EXPECT_LT(relErr(r.modes[0].damping_ratio, m.xi), kSingleModeXiTol);
  EXPECT_DOUBLE_EQ(r.modes[0].spectrum_frequency_hz, 3000.0);
}

TEST(AnalyzeWavelet, GivesTheSameModesWithoutTheFullScalogram) {
  const std::vector<double> y = freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 4);
  WaveletOptions with, without;
  without.full_scalogram = false;
  WaveletResult a, b;
  std::string error;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kPaperFs, with, &a), &error)) << error;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kPaperFs, without, &b), &error)) << error;
  EXPECT_GT(a.modulus.size(), 0);
  EXPECT_EQ(b.modulus.size(), 0);
  ASSERT_EQ(a.modes.size(), b.modes.size());
  for (size_t i = 0; i < a.modes.size(); ++i) {
    // The same decisions; the numbers' agreement is PerModePathMatchesTheFullPathOnThreeModes's.
    EXPECT_EQ(gear_test::modeDecisions(b.modes[i]), gear_test::modeDecisions(a.modes[i]));
  }
}

// The full path's (a) and the per-mode path's (b) xi and f_d of each mode (the same count), their
// decisions expected equal.
std::vector<gear_test::ModePair> modePairs(const WaveletResult& a, const WaveletResult& b,
                                           unsigned seed) {
  std::vector<gear_test::ModePair> pairs;
  for (size_t i = 0; i < a.modes.size() && i < b.modes.size(); ++i) {
    const WaveletMode &x = a.modes[i], &z = b.modes[i];
    EXPECT_EQ(gear_test::modeDecisions(x), gear_test::modeDecisions(z)) << seed << " mode " << i;
    pairs.push_back({x.damping_ratio, z.damping_ratio, x.frequency_hz, z.frequency_hz});
  }
  return pairs;
}

// The largest relative difference of b's peak spectrum and scalogram power from a's (the same
// sizes).
double worstPowerDifference(const WaveletResult& a, const WaveletResult& b) {
  double worst = 0.0;
  for (size_t i = 0; i < a.peak_power.size(); ++i)
    worst = std::max(worst, relErr(b.peak_power[i], a.peak_power[i]));
  for (size_t i = 0; i < a.scalogram_power.size(); ++i)
    worst = std::max(worst, relErr(b.scalogram_power[i], a.scalogram_power[i]));
  return worst;
}

// The per-mode path (full_scalogram = false: binned Parseval sums for the wide rows, envelope
// fits, region ends and noise medians on decimated grids) is its own estimator, required to be
// statistically indistinguishable from the full path (exact sums, every sample), not equal to it
// (docs/wavelet.md "Speed", gear_test::perModeAgreement): on the paper's three modes at 30 dB
// over 10 seeds, and on the clean record, every per-mode xi and f_d lies within 1/10 of the full
// path's seed-to-seed standard deviation of that mode's xi and f_d, and every mode's decisions
// (free decay, damping ratio given, warning codes) are the same. Measured standard deviations
// (full path, seeds 1-10): xi 6.6e-6 / 1.1e-4 / 1.4e-5, f_d 0.012 / 0.78 / 0.22 Hz (1731 / 7375
// / 14750 Hz); worst per-mode deviation 0.005 sd (xi) and 0.025 sd (f_d). The spectra and the
// peaks' spectral frequencies are the full path's (same FFT and padding; the binned Parseval
// sums within 1e-6 relative, the bound of their Taylor remainder).
TEST(AnalyzeWavelet, PerModePathMatchesTheFullPathOnThreeModes) {
  double worst_power = 0.0;
  std::vector<std::vector<gear_test::ModePair>> noisy, clean;
  for (unsigned seed = 0; seed <= 10; ++seed) {
    const std::vector<double> y = seed == 0 ? freeDecay(kPaperModes, kPaperFs, kPaperN)
                                            : freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, seed);
    WaveletOptions full, fast;
    fast.full_scalogram = false;
    WaveletResult a, b;
    std::string error;
    ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kPaperFs, full, &a), &error)) << error;
    ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kPaperFs, fast, &b), &error)) << error;
    ASSERT_EQ(a.spectrum_power, b.spectrum_power);
    ASSERT_EQ(a.peak_power.size(), b.peak_power.size());
    worst_power = std::max(worst_power, worstPowerDifference(a, b));
    ASSERT_EQ(a.modes.size(), 3u) << seed;
    ASSERT_EQ(b.modes.size(), 3u) << seed;
    for (size_t i = 0; i < 3; ++i)
      EXPECT_EQ(a.modes[i].spectrum_frequency_hz, b.modes[i].spectrum_frequency_hz) << seed;
    (seed == 0 ? clean : noisy).push_back(modePairs(a, b, seed));
  }
  const gear_test::PerModeAgreement g = gear_test::perModeAgreement(noisy, clean);
  std::printf(
      "[ measured ] full path's scatter over 10 seeds at 30 dB: xi %.2e %.2e %.2e, f_d %.2e "
      "%.2e %.2e Hz; per-mode vs full path: worst |dxi|/sd %.3f, |df_d|/sd %.3f; spectra %.2e\n",
      g.sd_xi[0], g.sd_xi[1], g.sd_xi[2], g.sd_fd[0], g.sd_fd[1], g.sd_fd[2], g.worst_xi,
      g.worst_fd, worst_power);
  EXPECT_LT(worst_power, 1e-6);
  EXPECT_LT(g.worst_xi, gear_test::kPerModeShareOfScatter);
  EXPECT_LT(g.worst_fd, gear_test::kPerModeShareOfScatter);
}

// The per-mode path's shared mode (records of n >= 32768 whose low band stays narrow: one
// transform padded by n/512 for the spectra, the fit rows and the noise row; the low rows' power
// from the grid padding's first bins, docs/wavelet.md "Speed") under the same contract: three
// modes in a 2e5-sample record at 30 dB, 10 seeds and the clean record: every per-mode xi and f_d
// within 1/10 of the full path's seed-to-seed standard deviation, the same decisions, the same
// number of spectral peaks, the peak spectrum and scalogram power within 1e-4 and the peaks'
// spectral frequencies within a quarter of the shared grid's bin (the PSD is on that grid).
// The power bar is not the paper case's 1e-6: on lines this narrow (xi 5e-5..1.5e-4) the binned
// Parseval sums' Taylor remainder alone reaches 2e-6..4e-6 in classic mode too
// (docs/performance.md, seventeenth session); measured here 1.1e-5.
TEST(AnalyzeWavelet, PerModePathSharedModeMatchesTheFullPathOnALongRecord) {
  const std::vector<Mode> modes = {
      {6000.0, 1.5e-4, 1.0, 0.1}, {16000.0, 1e-4, 0.5, 1.0}, {38000.0, 5e-5, 0.3, 2.0}};
  constexpr double kFs = 200000.0;
  constexpr long kN = 200000;
  double worst_power = 0.0, worst_bins = 0.0;
  std::vector<std::vector<gear_test::ModePair>> noisy, clean;
  for (unsigned seed = 0; seed <= 10; ++seed) {
    const std::vector<double> y =
        seed == 0 ? freeDecay(modes, kFs, kN) : freeDecay(modes, kFs, kN, 30.0, seed);
    WaveletOptions full, fast;
    fast.full_scalogram = false;
    WaveletResult a, b;
    std::string error;
    ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kFs, full, &a), &error)) << error;
    ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kFs, fast, &b), &error)) << error;
    ASSERT_LT(b.spectrum_power.size(), a.spectrum_power.size()) << "not the shared mode";
    const double bin = kFs / static_cast<double>(2 * (b.spectrum_power.size() - 1));
    ASSERT_EQ(a.peak_power.size(), b.peak_power.size());
    worst_power = std::max(worst_power, worstPowerDifference(a, b));
    ASSERT_EQ(a.modes.size(), 3u) << seed;
    ASSERT_EQ(b.modes.size(), 3u) << seed;
    for (size_t i = 0; i < 3; ++i) {
      const double df = a.modes[i].spectrum_frequency_hz - b.modes[i].spectrum_frequency_hz;
      worst_bins = std::max(worst_bins, std::abs(df) / bin);
    }
    (seed == 0 ? clean : noisy).push_back(modePairs(a, b, seed));
  }
  const gear_test::PerModeAgreement g = gear_test::perModeAgreement(noisy, clean);
  std::printf(
      "[ measured ] shared mode, full path's scatter: xi %.2e %.2e %.2e, f_d %.2e %.2e %.2e Hz; "
      "per-mode vs full: worst |dxi|/sd %.3f, |df_d|/sd %.3f; spectra %.2e; peak frequencies "
      "%.3f bins\n",
      g.sd_xi[0], g.sd_xi[1], g.sd_xi[2], g.sd_fd[0], g.sd_fd[1], g.sd_fd[2], g.worst_xi,
      g.worst_fd, worst_power, worst_bins);
  EXPECT_LT(worst_power, 1e-4);
  EXPECT_LT(worst_bins, 0.25);
  EXPECT_LT(g.worst_xi, gear_test::kPerModeShareOfScatter);
  EXPECT_LT(g.worst_fd, gear_test::kPerModeShareOfScatter);
}

// Every number of two results, compared exactly (NaN equals NaN).
void expectIdentical(const WaveletResult& a, const WaveletResult& b, const std::string& what) {
  auto same = [](double x, double y) { return x == y || (std::isnan(x) && std::isnan(y)); };
  auto sameVec = [&](const std::vector<double>& x, const std::vector<double>& y) {
    if (x.size() != y.size()) return false;
    for (size_t i = 0; i < x.size(); ++i)
      if (!same(x[i], y[i])) return false;
    return true;
  };
  EXPECT_TRUE(sameVec(a.frequencies, b.frequencies)) << what;
  EXPECT_TRUE(sameVec(a.spectrum_freq, b.spectrum_freq)) << what;
  EXPECT_TRUE(sameVec(a.spectrum_power, b.spectrum_power)) << what;
  EXPECT_TRUE(sameVec(a.scalogram_power, b.scalogram_power)) << what;
  EXPECT_TRUE(sameVec(a.peak_power, b.peak_power)) << what;
  EXPECT_TRUE(a.modulus == b.modulus) << what;
  EXPECT_EQ(a.noise_std, b.noise_std) << what;
  EXPECT_EQ(a.warnings, b.warnings) << what;
  ASSERT_EQ(a.modes.size(), b.modes.size()) << what;
  for (size_t i = 0; i < a.modes.size(); ++i) {
    const WaveletMode &x = a.modes[i], &y = b.modes[i];
    for (auto [u, v] : {std::pair{x.frequency_hz, y.frequency_hz},
                        {x.spectrum_frequency_hz, y.spectrum_frequency_hz},
                        {x.damping_ratio, y.damping_ratio},
                        {x.sigma, y.sigma},
                        {x.r2, y.r2},
                        {x.t_start, y.t_start},
                        {x.t_end, y.t_end},
                        {x.peak_amplitude, y.peak_amplitude},
                        {x.noise_floor, y.noise_floor},
                        {x.omega0, y.omega0}})
      EXPECT_TRUE(same(u, v)) << what << " mode " << i << ": " << u << " vs " << v;
    EXPECT_EQ(warningText(x.warnings), warningText(y.warnings)) << what;
  }
}

// The per-mode path (no full scalogram) with the defaults' mode search.
WaveletOptions perModeOptions() {
  WaveletOptions o;
  o.full_scalogram = false;
  return o;
}

// The per-mode path with the paper's three modes given and fit rows at omega0 30: 300 Hz at
// omega0 30 is wider than the grid's padding, so the fits use their own transform.
WaveletOptions explicitModeOptions() {
  WaveletOptions o = perModeOptions();
  o.mode_frequencies = {300.0, 1731.0, 7375.0};
  o.fit_omega0 = 30.0;
  return o;
}

// One WaveletAnalyzer reused over records of different lengths, signals and options (its
// plans, buffers and the result's capacity carried from call to call) gives exactly what a
// fresh analyzeWavelet gives: the reuse is a speed-up only.
TEST(WaveletAnalyzer, ReusedAcrossCallsGivesBitIdenticalResults) {
  WaveletAnalyzer analyzer;
  WaveletResult reused;  // reused too: its vectors keep their capacity
  std::string error;
  const WaveletOptions per_mode = perModeOptions();
  const WaveletOptions explicit_modes = explicitModeOptions();
  const std::vector<std::pair<std::vector<double>, const WaveletOptions*>> cases = {
      {freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 4), &per_mode},
      {freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 5), &per_mode},
      {freeDecay(kPaperModes, kPaperFs, kPaperN), &explicit_modes},
      {freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 6), &per_mode},
      {freeDecay(kPaperModes, kPaperFs, kPaperN / 2, 30.0, 7), &per_mode},
      {freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 8), &explicit_modes},
      {freeDecay(kPaperModes, kPaperFs, kPaperN / 2), nullptr},  // full scalogram (defaults)
  };
  for (size_t c = 0; c < cases.size(); ++c) {
    const WaveletOptions opt = cases[c].second ? *cases[c].second : WaveletOptions{};
    const std::vector<double>& y = cases[c].first;
    WaveletResult fresh;
    ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kPaperFs, opt, &fresh), &error)) << error;
    ASSERT_TRUE(gear_test::ok(
        analyzer.analyze(y.data(), static_cast<long>(y.size()), kPaperFs, opt, &reused), &error))
        << error;
    EXPECT_FALSE(fresh.modes.empty());
    expectIdentical(fresh, reused, "case " + std::to_string(c));
  }
  // An error leaves the analyzer usable.
  const std::vector<double> short_y(10, 1.0);
  EXPECT_FALSE(analyzer.analyze(short_y.data(), 10, kPaperFs, per_mode, &reused).ok());
  WaveletResult fresh;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(cases[0].first, kPaperFs, per_mode, &fresh), &error));
  ASSERT_TRUE(gear_test::ok(
      analyzer.analyze(cases[0].first.data(), kPaperN, kPaperFs, per_mode, &reused), &error));
  expectIdentical(fresh, reused, "after an error");
}

// The per-mode path on several threads (WaveletOptions::threads: the modes' fits on threads of
// their own, and in a reused analyzer the fit rows' transform loaded while the spectra are
// computed) gives exactly the one-thread result: records of the same length and modes in a row
// (the loaded transform used), then other fit rows (omega0 30: reconfigured after the spectra),
// another length (not loaded ahead), more threads than modes, and one mode. Two of the records
// carry noise coloured towards low frequencies (an MA(1) filter, weak at 0.45 fs), so that the
// noise row's level, computed beside the spectra in a reused analyzer, sets noise_std.
TEST(WaveletAnalyzer, PerModePathOnSeveralThreadsGivesTheOneThreadResult) {
  const auto coloured = [](unsigned seed) {
    std::vector<double> y = freeDecay(kPaperModes, kPaperFs, kPaperN);
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> e(0.0, 0.01), white(0.0, 0.001);
    double previous = e(rng);
    for (double& v : y) {
      const double now = e(rng);
      v += now + previous + white(rng);
      previous = now;
    }
    return y;
  };
  const WaveletOptions one = perModeOptions();
  const WaveletOptions explicit_modes = explicitModeOptions();
  const std::vector<std::pair<std::vector<double>, const WaveletOptions*>> cases = {
      {freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 11), &one},
      {freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 12), &one},
      {coloured(13), &one},
      {coloured(14), &one},
      {freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 14), &explicit_modes},
      {freeDecay(kPaperModes, kPaperFs, kPaperN, 30.0, 15), &one},
      {freeDecay(kPaperModes, kPaperFs, kPaperN / 2, 30.0, 16), &one},
      {freeDecay({{5000.0, 0.02, 1.0, 0.0}}, kPaperFs, kPaperN / 2, 30.0, 17), &one},
  };
  std::string error;
  for (const int threads : {2, 3}) {
    WaveletAnalyzer analyzer;
    WaveletResult reused;
    for (size_t c = 0; c < cases.size(); ++c) {
      const std::vector<double>& y = cases[c].first;
      WaveletOptions opt = *cases[c].second;
      WaveletResult serial, fresh;
      ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kPaperFs, opt, &serial), &error)) << error;
      opt.threads = threads;
      ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kPaperFs, opt, &fresh), &error)) << error;
      ASSERT_TRUE(gear_test::ok(
          analyzer.analyze(y.data(), static_cast<long>(y.size()), kPaperFs, opt, &reused), &error))
          << error;
      EXPECT_FALSE(serial.modes.empty());
      const std::string what = std::to_string(threads) + " threads, case " + std::to_string(c);
      expectIdentical(serial, fresh, what);
      expectIdentical(serial, reused, what + ", reused");
    }
  }
}

// Shared mode (a long record): on several threads the record's transform is taken in two halves
// at once, then a helper computes the low band and the rows' power while the calling thread
// computes the PSD and the noise row; the one-thread result in every bit, with either planning
// (FFTW_MEASURE's plans are FFTW's wisdom for their size once made, so every thread's row
// transforms take the same algorithm).
TEST(WaveletAnalyzer, SharedModeOnSeveralThreadsGivesTheOneThreadResult) {
  const std::vector<Mode> modes = {
      {6000.0, 1.5e-4, 1.0, 0.1}, {16000.0, 1e-4, 0.5, 1.0}, {38000.0, 5e-5, 0.3, 2.0}};
  constexpr double kFs = 200000.0;
  std::string error;
  for (const FftPlanning planning : {FftPlanning::Estimate, FftPlanning::Measure}) {
    // An odd length too (Measure planning of a length takes seconds: one length for it).
    for (const long n : planning == FftPlanning::Measure ? std::vector<long>{200000}
                                                         : std::vector<long>{200000, 200001}) {
      const std::vector<double> y =
          freeDecay(modes, kFs, n, 30.0, static_cast<unsigned>(3 + n % 97));
      WaveletOptions opt = perModeOptions();
      opt.fft_planning = planning;
      WaveletResult full, serial;
      ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kFs, WaveletOptions{}, &full), &error)) << error;
      ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kFs, opt, &serial), &error)) << error;
      ASSERT_LT(serial.spectrum_power.size(), full.spectrum_power.size()) << "not the shared mode";
      EXPECT_EQ(serial.modes.size(), 3u) << n;
      WaveletAnalyzer analyzer;
      for (const int threads : {2, 3}) {
        opt.threads = threads;
        WaveletResult fresh, reused;
        ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kFs, opt, &fresh), &error)) << error;
        for (int call = 0; call < 2; ++call)
          ASSERT_TRUE(gear_test::ok(
              analyzer.analyze(y.data(), static_cast<long>(y.size()), kFs, opt, &reused), &error))
              << error;
        const std::string what = std::to_string(threads) + " threads, n " + std::to_string(n) +
                                 (planning == FftPlanning::Measure ? ", measured plans" : "");
        expectIdentical(serial, fresh, what);
        expectIdentical(serial, reused, what + ", reused");
      }
    }
  }
}

TEST(AnalyzeWavelet, AcceptsEigenVectorsAndStdVectorsAlike) {
  const std::vector<double> y = freeDecay({{5000.0, 0.02, 1.0, 0.0}}, 100000.0, 4000);
  const Eigen::VectorXd e = Eigen::Map<const Eigen::VectorXd>(y.data(), long(y.size()));
  WaveletOptions options;
  options.full_scalogram = false;
  WaveletResult a, b;
  ASSERT_TRUE(analyzeWavelet(y, 100000.0, options, &a).ok());
  ASSERT_TRUE(analyzeWavelet(e, 100000.0, options, &b).ok());
  ASSERT_EQ(a.modes.size(), 1u);
  ASSERT_EQ(b.modes.size(), 1u);
  EXPECT_EQ(a.modes[0].damping_ratio, b.modes[0].damping_ratio);
}

TEST(AnalyzeWavelet, ReportsAModeWithoutAUsableDecayRegionAsNaNWithAWarning) {
  const double fs = 20000.0;
  const std::vector<double> y = freeDecay({{1000.0, 0.01, 1.0, 0.0}}, fs, 2000);
  WaveletOptions options;
  options.mode_frequencies = {1000.0};
  options.fit_omega0 = 40.0;  // COI 3 x 9 ms at each end: more than the 100 ms record allows?
  options.max_fit_omega0 = 100.0;
  options.coi_factor = 10.0;
  WaveletResult r;
  std::string error;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, fs, options, &r), &error)) << error;
  ASSERT_EQ(r.modes.size(), 1u);
  EXPECT_TRUE(std::isnan(r.modes[0].damping_ratio));
  EXPECT_NE(warningText(r.modes[0].warnings).find("cone of influence"), std::string::npos)
      << warningText(r.modes[0].warnings);
  ASSERT_EQ(r.modes[0].warnings.size(), 1u);
  EXPECT_EQ(r.modes[0].warnings[0].code, "fit_failed");
  EXPECT_FALSE(r.modes[0].free_decay);
}

// --- Invalid input ------------------------------------------------------------------------

std::string analyzeError(const std::vector<double>& y, double fs, const WaveletOptions& o) {
  WaveletResult r;
  std::string error;
  const bool ok = gear_test::ok(analyzeWavelet(y, fs, o, &r), &error);
  EXPECT_FALSE(ok);
  EXPECT_TRUE(r.modes.empty());
  EXPECT_TRUE(r.frequencies.empty());
  return error;
}

TEST(AnalyzeWavelet, RejectsInvalidInputWithAnErrorNamingTheProblem) {
  const std::vector<double> y = freeDecay({{1000.0, 0.01, 1.0, 0.0}}, 20000.0, 4000);
  const WaveletOptions ok;
  EXPECT_NE(analyzeError(std::vector<double>(63, 1.0), 20000.0, ok).find("n = 63"),
            std::string::npos);
  std::vector<double> bad = y;
  bad[1234] = NAN;
  EXPECT_NE(analyzeError(bad, 20000.0, ok).find("sample 1234"), std::string::npos);
  bad[1234] = INFINITY;
  EXPECT_NE(analyzeError(bad, 20000.0, ok).find("sample 1234"), std::string::npos);
  // Samples so large that the spectrum's power would overflow: an error, not NaN numbers
  // (both paths; the per-mode path on the shared mode's long records too).
  for (const double scale : {1e147, -1e300}) {
    for (const bool full : {true, false}) {
      for (const long n : {4000L, 300000L}) {
        std::vector<double> huge(static_cast<size_t>(n));
        for (long j = 0; j < n; ++j)
          huge[size_t(j)] = scale * std::sin(0.3 * static_cast<double>(j));
        WaveletOptions o = ok;
        o.full_scalogram = full;
        EXPECT_NE(analyzeError(huge, 20000.0, o).find("rescale the record"), std::string::npos)
            << scale << " " << full << " " << n;
      }
    }
  }
  std::vector<double> large = y;  // 2 n max|y| = 5e149, just below the limit: still analysed
  double peak = 0.0;
  for (double v : y) peak = std::max(peak, std::abs(v));
  for (double& v : large) v *= 5e149 / (2.0 * static_cast<double>(y.size()) * peak);
  WaveletResult fine;
  std::string error;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(large, 20000.0, ok, &fine), &error)) << error;
  EXPECT_TRUE(std::isfinite(fine.noise_std));
  EXPECT_EQ(fine.modes.size(), 1u);
  EXPECT_NE(analyzeError(y, 0.0, ok).find("sample_rate"), std::string::npos);
  EXPECT_NE(analyzeError(y, NAN, ok).find("sample_rate"), std::string::npos);
  // Each row: one option broken (the rest default) and what the error must name.
  const std::vector<std::pair<std::function<void(WaveletOptions*)>, std::string>> cases = {
      {[](WaveletOptions* o) { o->f_max = 10000.0; }, "f_max"},  // = Nyquist
      {[](WaveletOptions* o) { o->f_min = 3000.0, o->f_max = 2000.0; }, "f_min"},
      {[](WaveletOptions* o) { o->f_min = 9000.0; }, "f_min"},  // >= auto f_max = 8 kHz
      {[](WaveletOptions* o) { o->n_scales = 0; }, "n_scales"},
      {[](WaveletOptions* o) { o->omega0 = 0.0; }, "omega0"},
      {[](WaveletOptions* o) {
         o->frequencies = {100.0, 300.0, 200.0};
       },
       "frequencies[2]"},
      {[](WaveletOptions* o) {
         o->frequencies = {100.0, 200.0, 12000.0};
       },
       "Nyquist"},
      {[](WaveletOptions* o) {
         o->mode_frequencies = {1000.0, 11000.0};
       },
       "mode_frequencies[1]"},
      {[](WaveletOptions* o) {
         o->mode_frequencies = {1000.0}, o->decay_regions = {{0.02, 0.01}};
       },
       "decay_regions[0]"},
      {[](WaveletOptions* o) { o->peak_prominence = 1.5; }, "peak_prominence"},
      {[](WaveletOptions* o) { o->fit_omega0 = 2.0; }, "fit_omega0"},
  };
  for (const auto& c : cases) {
    WaveletOptions o = ok;
    c.first(&o);
    const std::string e = analyzeError(y, 20000.0, o);
    EXPECT_NE(e.find(c.second), std::string::npos) << "expected '" << c.second << "' in: " << e;
  }
  WaveletResult r;
  EXPECT_FALSE(analyzeWavelet(nullptr, 100, 1000.0, ok, &r).ok());
  EXPECT_FALSE(analyzeWavelet(y.data(), long(y.size()), 20000.0, ok, nullptr).ok());
}

TEST(WaveletOptions, DefaultsAreValidAndEachRuleNamesItsField) {
  EXPECT_EQ(WaveletOptions{}.check().message(), "");
  WaveletOptions o;
  o.max_modes = 0;
  EXPECT_NE(o.check().message().find("max_modes = 0"), std::string::npos) << o.check().message();
  o = WaveletOptions{};
  o.coi_factor = 0.5;
  EXPECT_NE(o.check().message().find("coi_factor = 0.5"), std::string::npos) << o.check().message();
  o = WaveletOptions{};
  o.floor_factor = NAN;
  EXPECT_NE(o.check().message().find("floor_factor"), std::string::npos) << o.check().message();
  o = WaveletOptions{};
  o.decay_regions = {{0.0, 1.0}, {0.0, 1.0}};  // two regions but no explicit modes
  EXPECT_NE(o.check().message().find("decay_regions.size()"), std::string::npos)
      << o.check().message();
  o = WaveletOptions{};
  o.max_scalogram_columns = -1;
  EXPECT_NE(o.check().message().find("max_scalogram_columns"), std::string::npos)
      << o.check().message();
}

// --- CSV export -------------------------------------------------------------------------------

TEST(WaveletCsv, WritesADecimatedScalogramAndTheSpectraOrReportsTheIoError) {
  const std::vector<double> y = freeDecay(kPaperModes, kPaperFs, kPaperN);
  WaveletOptions options;
  options.max_scalogram_columns = 0;  // keep every sample: the writer decimates
  WaveletResult r;
  std::string error;
  ASSERT_TRUE(gear_test::ok(analyzeWavelet(y, kPaperFs, options, &r), &error)) << error;
  ASSERT_EQ(r.modulus.cols(), kPaperN);
  const std::string dir = gear_test::processScratch("wavelet_test").string();
  const std::string scal = dir + "/wavelet_test_scalogram.csv";
  const std::string spec = dir + "/wavelet_test_spectrum.csv";
  ASSERT_EQ(writeScalogramCsv(r, scal, 1000).message(), "");
  ASSERT_EQ(writeSpectrumCsv(r, spec).message(), "");
  std::ifstream in(scal);
  std::string line;
  std::vector<std::string> lines;
  while (std::getline(in, line)) lines.push_back(line);
  ASSERT_EQ(lines.size(), 2u + 200u);  // comment, times, one row per frequency
  EXPECT_EQ(lines[0][0], '#');
  EXPECT_EQ(lines[1].rfind("nan,nan,", 0), 0u);
  const long commas = std::count(lines[2].begin(), lines[2].end(), ',');
  EXPECT_EQ(commas, 1 + 1000);  // frequency, COI, 1000 columns (12000 / 12)
  EXPECT_EQ(std::count(lines[1].begin(), lines[1].end(), ','), commas);
  std::ifstream sp(spec);
  std::getline(sp, line);
  EXPECT_EQ(line, "kind,frequency_hz,power");
  long psd = 0, wav = 0;
  while (std::getline(sp, line)) {
    psd += line.rfind("psd,", 0) == 0;
    wav += line.rfind("scalogram,", 0) == 0;
  }
  EXPECT_GT(psd, 1000);
  EXPECT_EQ(wav, 200);
  const std::string io = writeScalogramCsv(r, "/nonexistent_dir/x.csv").message();
  EXPECT_NE(io.find("/nonexistent_dir/x.csv"), std::string::npos) << io;
  EXPECT_NE(writeSpectrumCsv(r, "/nonexistent_dir/y.csv").message().find("cannot open"),
            std::string::npos);
  EXPECT_NE(writeScalogramCsv(WaveletResult{}, scal).message().find("no scalogram"),
            std::string::npos);
}

TEST(WaveletCsv, WritesTheTableOfModesWithTheIntegralMethodBesideEachMode) {
  const std::vector<double> y = freeDecay(kPaperModes, kPaperFs, kPaperN);
  WaveletResult r = validateWavelet(y, kPaperFs);
  ASSERT_TRUE(r.ok()) << r.status.message();
  ASSERT_EQ(r.modes.size(), kPaperModes.size());
  // C = 2*xi*omega0 for xi = 0.02 at omega0 = 2*pi*1731 Hz gives back 0.02.
  const double w0 = 2.0 * kPi * 1731.0;
  EXPECT_DOUBLE_EQ(integralDampingRatio(2.0 * 0.02 * w0, w0), 0.02);
  EXPECT_TRUE(std::isnan(integralDampingRatio(1.0, 0.0)));
  EXPECT_TRUE(std::isnan(integralDampingRatio(NAN, w0)));
  attachIntegralDampingRatio(&r, 0.02);
  attachIntegralDampingRatio(nullptr, 0.02);  // no-op, no crash
  r.modes[1].warnings = {{"close_modes", "a \"quoted\" remark"}};
  std::ostringstream out;
  ASSERT_EQ(writeModesCsv(r, out).message(), "");
  std::istringstream in(out.str());
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(
      line.rfind("frequency_hz,spectrum_frequency_hz,damping_ratio,integral_damping_ratio,", 0),
      0u);
  std::vector<std::string> rows;
  while (std::getline(in, line)) rows.push_back(line);
  ASSERT_EQ(rows.size(), kPaperModes.size());
  for (size_t i = 0; i < rows.size(); ++i) {
    const double f = std::stod(rows[i]);
    EXPECT_NEAR(f, r.modes[i].frequency_hz, 1e-6 * f);
    EXPECT_NE(rows[i].find(",0.02,"), std::string::npos) << rows[i];
  }
  EXPECT_NE(rows[1].find(",true,close_modes,\"close_modes: a \"\"quoted\"\" remark\""),
            std::string::npos)
      << rows[1];
  EXPECT_NE(writeModesCsv(r, "/nonexistent_dir/m.csv").message().find("/nonexistent_dir/m.csv"),
            std::string::npos);
  std::ostringstream scal, spec;
  EXPECT_EQ(writeScalogramCsv(r, scal, 100).message(), "");
  EXPECT_EQ(writeSpectrumCsv(r, spec).message(), "");
  EXPECT_GT(scal.str().size(), 1000u);
  EXPECT_EQ(spec.str().rfind("kind,frequency_hz,power\n", 0), 0u);
}

// --- High-level entry point -------------------------------------------------------------------

TEST(ValidateWavelet, ReturnsTheModesOfACleanFreeDecay) {
  const std::vector<double> y = freeDecay(kPaperModes, kPaperFs, kPaperN);
  const WaveletResult r = validateWavelet(y.data(), y.size(), kPaperFs);
  ASSERT_TRUE(r.ok()) << r.status.message();
  ASSERT_EQ(r.modes.size(), kPaperModes.size());
  for (size_t i = 0; i < r.modes.size(); ++i) {
    EXPECT_NEAR(r.modes[i].damping_ratio, kPaperModes[i].xi, kMultiModeXiTol * kPaperModes[i].xi);
    EXPECT_TRUE(r.modes[i].warnings.empty()) << warningText(r.modes[i].warnings);
  }
  EXPECT_EQ(r.modulus.rows(), 200);
}

TEST(ValidateWavelet, InvalidInputGivesAnErrorStringAndAnEmptyResultNeverNaNs) {
  const std::vector<double> y = freeDecay({{1000.0, 0.01, 1.0, 0.0}}, 20000.0, 4000);
  auto errorOf = [](const WaveletResult& r) {
    EXPECT_FALSE(r.ok());
    EXPECT_TRUE(r.modes.empty());
    EXPECT_TRUE(r.frequencies.empty());
    return r.status.message();
  };
  EXPECT_NE(errorOf(validateWavelet(y, 0.0)).find("sample_rate"), std::string::npos);
  EXPECT_NE(errorOf(validateWavelet(y, -5.0)).find("sample_rate"), std::string::npos);
  EXPECT_NE(errorOf(validateWavelet(y.data(), 10, 20000.0)).find("n = 10"), std::string::npos);
  EXPECT_NE(errorOf(validateWavelet(nullptr, 1000, 20000.0)).find("null"), std::string::npos);
  std::vector<double> bad = y;
  bad[77] = NAN;
  EXPECT_NE(errorOf(validateWavelet(bad, 20000.0)).find("sample 77"), std::string::npos);
  WaveletOptions o;
  o.f_max = 15000.0;
  EXPECT_NE(errorOf(validateWavelet(y, 20000.0, o)).find("Nyquist"), std::string::npos);
  o = WaveletOptions{};
  o.mode_frequencies = {10000.0};
  EXPECT_NE(errorOf(validateWavelet(y, 20000.0, o)).find("Nyquist"), std::string::npos);
  o = WaveletOptions{};
  o.peak_omega0 = NAN;
  EXPECT_NE(errorOf(validateWavelet(y, 20000.0, o)).find("peak_omega0"), std::string::npos);
  // A constant record is valid input with nothing to fit: ok, no modes, a global warning.
  const WaveletResult flat = validateWavelet(std::vector<double>(4000, 1.5), 20000.0);
  EXPECT_TRUE(flat.ok()) << flat.status.message();
  for (const WaveletMode& m : flat.modes) {
    EXPECT_TRUE(std::isfinite(m.damping_ratio) || !m.warnings.empty());
  }
}

}  // namespace
}  // namespace gear_damping_id
