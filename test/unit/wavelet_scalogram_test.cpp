// MorletScalogram (issue 18): padding per group of rows sized to the group's lowest row, rows in
// parallel. Same edge accuracy as one MorletCwt over all rows (each row keeps its 8-scale
// padding), bit-identical results for any thread count, shorter FFTs for the high rows.
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <random>
#include <string>
#include <vector>

#include "gear_damping_id/morlet_cwt.hpp"
#include "gear_damping_id/wavelet_analysis.hpp"
#include "status_support.hpp"

namespace gear_damping_id {
namespace {

// Group padding vs one padding for all rows, relative to the largest |W| of the record: both
// are the linear convolution up to the Gaussian's e^-32 at the wrap-around, the FFTs' rounding
// and the analytic cut at zero frequency (Psi(0) = 2 e^-18 = 3e-8 for omega0 = 6: its slowly
// decaying ringing wraps around differently for different FFT lengths; measured up to 3.6e-9
// on the middle rows). Bound: the cut in each of the two transforms, 2 x 2 e^-18 = 6e-8.
const double kGroupVsSingleTol = 2.0 * 2.0 * std::exp(-18.0);

std::vector<double> testSignal(long n, unsigned seed) {
  std::vector<double> y(static_cast<size_t>(n));
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.1);
  for (long j = 0; j < n; ++j) {
    const double t = static_cast<double>(j);
    y[size_t(j)] = std::exp(-3e-4 * t) * std::cos(0.07 * t) + 0.4 * std::cos(0.9 * t + 1.0) +
                   (j > n / 3 ? 1.0 : 0.0) + noise(rng);  // a step: broadband edges
  }
  return y;
}

// Every row of b (row-major, n values per row of the grid f) within kGroupVsSingleTol of the
// largest |W| of a, the reference.
void expectRowsWithinGroupBound(const std::vector<double>& a, const std::vector<double>& b,
                                const std::vector<double>& f, long n) {
  double peak = 0.0;
  for (double v : a) peak = std::max(peak, v);
  for (size_t r = 0; r < f.size(); ++r) {
    double worst = 0.0;
    for (long j = 0; j < n; ++j) {
      worst =
          std::max(worst, std::abs(a[r * size_t(n) + size_t(j)] - b[r * size_t(n) + size_t(j)]));
    }
    EXPECT_LE(worst, kGroupVsSingleTol * peak) << "row " << r << " f = " << f[r];
  }
}

TEST(MorletScalogram, MatchesOneMorletCwtOverAllRowsWithShorterFftsForHighRows) {
  for (const long n : {3000L, 5011L}) {
    SCOPED_TRACE("n = " + std::to_string(n));
    const std::vector<double> y = testSignal(n, 3);
    const std::vector<double> f = logSpacedFrequencies(10.0 / n, 0.45, 60);
    MorletCwt single;
    MorletScalogram grouped;
    std::string e;
    ASSERT_TRUE(gear_test::ok(single.configure(n, 1.0, f, 6.0, FftPlanning::Estimate), &e)) << e;
    ASSERT_TRUE(gear_test::ok(grouped.configure(n, 1.0, f, 6.0, FftPlanning::Estimate, 1), &e))
        << e;
    EXPECT_GE(grouped.groups(), 2);
    EXPECT_EQ(grouped.groupLength(0), single.paddedSize());  // the lowest rows' group
    EXPECT_LT(grouped.groupLength(grouped.groups() - 1), single.paddedSize());
    std::vector<double> a(f.size() * size_t(n)), b(a.size());
    ASSERT_TRUE(gear_test::ok(single.transformModulus(y.data(), a.data()), &e)) << e;
    ASSERT_TRUE(gear_test::ok(grouped.modulus(y.data(), b.data()), &e)) << e;
    expectRowsWithinGroupBound(a, b, f, n);
  }
}

// Rows computed in overlapping blocks (MorletScalogram::blockedRows: the rows whose wavelet
// spans a few hundred samples) against one MorletCwt over all rows, on records long enough for
// several blocks per row, with a drift (large low-frequency content: the analytic cut's
// ringing, which the blocks alone would lose beyond their margin, grows with it) and with
// omega0 = 10 (no cut part: Psi(0) = 2e^-50). Same bound as the groups.
TEST(MorletScalogram, BlockedRowsMatchOneMorletCwtOverAllRows) {
  for (const double omega0 : {6.0, 10.0}) {
    const long n = 40000;
    SCOPED_TRACE("omega0 = " + std::to_string(omega0));
    std::vector<double> y = testSignal(n, 7);
    for (long j = 0; j < n; ++j) y[size_t(j)] += 3.0 * static_cast<double>(j) / n;
    const std::vector<double> f = logSpacedFrequencies(10.0 / n, 0.4, 80);
    MorletCwt single;
    MorletScalogram blocked;
    std::string e;
    ASSERT_TRUE(gear_test::ok(single.configure(n, 1.0, f, omega0, FftPlanning::Estimate), &e)) << e;
    ASSERT_TRUE(gear_test::ok(blocked.configure(n, 1.0, f, omega0, FftPlanning::Estimate, 1), &e))
        << e;
    EXPECT_GE(blocked.blockedRows(), 20);
    std::vector<double> a(f.size() * size_t(n)), b(a.size());
    ASSERT_TRUE(gear_test::ok(single.transformModulus(y.data(), a.data()), &e)) << e;
    ASSERT_TRUE(gear_test::ok(blocked.modulus(y.data(), b.data()), &e)) << e;
    expectRowsWithinGroupBound(a, b, f, n);
  }
}

TEST(MorletScalogram, GivesBitIdenticalRowsForAnyThreadCount) {
  const long n = 4000;
  const std::vector<double> y = testSignal(n, 5);
  const std::vector<double> f = logSpacedFrequencies(10.0 / n, 0.4, 50);
  std::vector<float> one(f.size() * size_t(n));
  std::string e;
  MorletScalogram s1;
  ASSERT_TRUE(gear_test::ok(s1.configure(n, 1.0, f, 6.0, FftPlanning::Estimate, 1), &e)) << e;
  EXPECT_GT(s1.blockedRows(), 0);
  ASSERT_TRUE(gear_test::ok(s1.modulus(y.data(), one.data()), &e)) << e;
  for (int threads : {2, 3}) {
    MorletScalogram s;
    ASSERT_TRUE(gear_test::ok(s.configure(n, 1.0, f, 6.0, FftPlanning::Estimate, threads), &e))
        << e;
    EXPECT_EQ(s.threads(), threads);
    std::vector<float> out(one.size());
    ASSERT_TRUE(gear_test::ok(s.modulus(y.data(), out.data()), &e)) << e;
    EXPECT_EQ(out, one) << threads << " threads";
  }
  // The analysis' scalogram too.
  WaveletOptions o;
  WaveletResult r1 = validateWavelet(y, 1.0, o);
  o.threads = 2;
  WaveletResult r2 = validateWavelet(y, 1.0, o);
  ASSERT_TRUE(r1.ok() && r2.ok()) << r1.status.message() << r2.status.message();
  EXPECT_TRUE(r1.modulus == r2.modulus);
}

// Single precision (Precision::Single) against double, relative to the largest |W|: float
// rounds the band (2^-24 = 6e-8 relative) and each FFT stage adds about that again, so a few
// 1e-7 over the log2 N ~ 13 stages; bound 1e-6.
constexpr double kSingleVsDoubleTol = 1e-6;

TEST(MorletScalogram, SinglePrecisionAgreesWithDoubleWithinOnePpmOfThePeak) {
  for (const long n : {3000L, 5011L}) {
    SCOPED_TRACE("n = " + std::to_string(n));
    const std::vector<double> y = testSignal(n, 7);
    const std::vector<double> f = logSpacedFrequencies(10.0 / n, 0.45, 60);
    std::string e;
    MorletScalogram dbl, sgl;
    ASSERT_TRUE(gear_test::ok(dbl.configure(n, 1.0, f, 6.0, FftPlanning::Estimate, 1), &e)) << e;
    ASSERT_TRUE(gear_test::ok(
        sgl.configure(n, 1.0, f, 6.0, FftPlanning::Estimate, 1, Precision::Single), &e))
        << e;
    std::vector<double> a(f.size() * size_t(n)), b(a.size());
    ASSERT_TRUE(gear_test::ok(dbl.modulus(y.data(), a.data()), &e)) << e;
    ASSERT_TRUE(gear_test::ok(sgl.modulus(y.data(), b.data()), &e)) << e;
    double peak = 0.0, worst = 0.0;
    for (size_t i = 0; i < a.size(); ++i) {
      peak = std::max(peak, a[i]);
      worst = std::max(worst, std::abs(a[i] - b[i]));
    }
    EXPECT_LE(worst, kSingleVsDoubleTol * peak);
    EXPECT_GT(worst, 0.0);  // it did run in float
    // Threads: bit-identical in single precision too.
    MorletScalogram sgl2;
    ASSERT_TRUE(gear_test::ok(
        sgl2.configure(n, 1.0, f, 6.0, FftPlanning::Estimate, 2, Precision::Single), &e))
        << e;
    std::vector<double> c(a.size());
    ASSERT_TRUE(gear_test::ok(sgl2.modulus(y.data(), c.data()), &e)) << e;
    EXPECT_EQ(b, c);
  }
}

// The complex rows (row(), rowAt(): the damping fits) take the pruned path when the band is
// narrow; they equal the full inverse FFT up to rounding (relative to the row's peak).
constexpr double kPrunedVsFullTol = 1e-12;

// Two transforms of testSignal(n, seed) on 40 rows up to 0.45 fs: `pruned` with the pruned rows
// (the default), `full` with the full inverse FFT for every row.
struct PrunedAndFull {
  std::vector<double> y, f;
  MorletCwt pruned, full;
};
void loadPrunedAndFull(long n, unsigned seed, PrunedAndFull* t) {
  t->y = testSignal(n, seed);
  t->f = logSpacedFrequencies(10.0 / n, 0.45, 40);
  std::string e;
  ASSERT_TRUE(gear_test::ok(t->pruned.configure(n, 1.0, t->f, 6.0, FftPlanning::Estimate), &e))
      << e;
  ASSERT_TRUE(gear_test::ok(t->full.configure(n, 1.0, t->f, 6.0, FftPlanning::Estimate), &e)) << e;
  t->full.setPrunedModulus(false);
  ASSERT_TRUE(gear_test::ok(t->pruned.setSignal(t->y.data()), &e) &&
              gear_test::ok(t->full.setSignal(t->y.data()), &e))
      << e;
}

TEST(MorletCwt, PrunedComplexRowsEqualTheFullInverseFft) {
  const long n = 6000;
  PrunedAndFull t;
  ASSERT_NO_FATAL_FAILURE(loadPrunedAndFull(n, 11, &t));
  MorletCwt &pruned = t.pruned, &full = t.full;
  const std::vector<double>& f = t.f;
  for (int i = 0; i < pruned.rows(); ++i) {
    const std::vector<std::complex<double>> a(pruned.row(i), pruned.row(i) + n);
    const std::complex<double>* b = full.row(i);
    double peak = 0.0, worst = 0.0;
    for (long j = 0; j < n; ++j) {
      peak = std::max(peak, std::abs(b[j]));
      worst = std::max(worst, std::abs(a[size_t(j)] - b[j]));
    }
    EXPECT_LE(worst, kPrunedVsFullTol * peak) << "row " << i << " f = " << f[size_t(i)];
  }
  // An off-grid row (the fits' rowAt) as well.
  const std::vector<std::complex<double>> a(pruned.rowAt(0.0371, 14.0),
                                            pruned.rowAt(0.0371, 14.0) + n);
  const std::complex<double>* b = full.rowAt(0.0371, 14.0);
  ASSERT_NE(b, nullptr);
  double peak = 0.0, worst = 0.0;
  for (long j = 0; j < n; ++j) {
    peak = std::max(peak, std::abs(b[j]));
    worst = std::max(worst, std::abs(a[size_t(j)] - b[j]));
  }
  EXPECT_LE(worst, kPrunedVsFullTol * peak);
}

// The pruned |W| (rowModulus, the scalogram's rows) advances each batch's band from the previous
// batch's (one complex multiplication per bin, re-seeded exactly every 256 batches): equal to
// the full inverse FFT's |W| up to that drift (< 256 x 4 eps of the row's peak) and rounding.
// n = 60000 gives the lowest rows ~2500 batches, so the re-seeding is exercised.
TEST(MorletCwt, PrunedModulusRowsEqualTheFullInverseFft) {
  const long n = 60000;
  PrunedAndFull t;
  ASSERT_NO_FATAL_FAILURE(loadPrunedAndFull(n, 13, &t));
  std::vector<double> a(static_cast<size_t>(n)), b(a.size());
  std::vector<float> af(a.size());
  int differing = 0;
  for (int i = 0; i < t.pruned.rows(); ++i) {
    ASSERT_TRUE(t.pruned.rowModulus(i, a.data()) && t.full.rowModulus(i, b.data()));
    ASSERT_TRUE(t.pruned.rowModulus(i, af.data()));
    double peak = 0.0, worst = 0.0, worst_f = 0.0;
    for (size_t j = 0; j < a.size(); ++j) {
      peak = std::max(peak, b[j]);
      worst = std::max(worst, std::abs(a[j] - b[j]));
      worst_f = std::max(worst_f, std::abs(static_cast<double>(af[j]) - a[j]));
    }
    EXPECT_LE(worst, kPrunedVsFullTol * peak) << "row " << i << " f = " << t.f[size_t(i)];
    EXPECT_LE(worst_f, 1e-7 * peak) << "row " << i;  // the same row rounded to float
    differing += worst > 0.0;
  }
  EXPECT_GT(differing, 0);  // some rows did take the pruned path
}

// One object reconfigured in turn (larger and smaller n, more and fewer threads, other rows,
// double then single precision and back, a failed configure between) gives the bits of a fresh
// object each time: the per-thread buffer sets are resized or replaced with the configuration,
// never reused at a stale size.
TEST(MorletScalogram, ReconfiguredObjectGivesTheBitsOfAFreshOne) {
  struct Config {
    long n;
    int threads, rows;
    double f_max;
    Precision precision;
  };
  const Config configs[] = {
      {1500, 1, 30, 0.4, Precision::Double},  {6000, 2, 45, 0.45, Precision::Double},
      {700, 3, 20, 0.3, Precision::Double},   {6000, 1, 45, 0.45, Precision::Single},
      {2500, 2, 60, 0.49, Precision::Single}, {9000, 3, 12, 0.2, Precision::Double},
      {64, 2, 5, 0.4, Precision::Single},     {3000, 2, 40, 0.4, Precision::Double}};
  MorletScalogram reused;
  std::string e;
  for (const Config& c : configs) {
    SCOPED_TRACE("n = " + std::to_string(c.n) + ", threads " + std::to_string(c.threads));
    const std::vector<double> y = testSignal(c.n, static_cast<unsigned>(c.n));
    const std::vector<double> f = logSpacedFrequencies(10.0 / c.n, c.f_max, c.rows);
    // A refused configuration first (the object must still be usable afterwards).
    EXPECT_FALSE(gear_test::ok(reused.configure(c.n, 1.0, f, 6.0, FftPlanning::Estimate, 0), &e));
    ASSERT_TRUE(gear_test::ok(
        reused.configure(c.n, 1.0, f, 6.0, FftPlanning::Estimate, c.threads, c.precision), &e))
        << e;
    MorletScalogram fresh;
    ASSERT_TRUE(gear_test::ok(
        fresh.configure(c.n, 1.0, f, 6.0, FftPlanning::Estimate, c.threads, c.precision), &e))
        << e;
    EXPECT_EQ(reused.groups(), fresh.groups());
    std::vector<double> a(f.size() * size_t(c.n)), b(a.size());
    std::vector<float> af(a.size()), bf(a.size());
    ASSERT_TRUE(gear_test::ok(reused.modulus(y.data(), a.data()), &e)) << e;
    ASSERT_TRUE(gear_test::ok(fresh.modulus(y.data(), b.data()), &e)) << e;
    EXPECT_TRUE(a == b);
    ASSERT_TRUE(gear_test::ok(reused.modulus(y.data(), af.data()), &e)) << e;
    ASSERT_TRUE(gear_test::ok(fresh.modulus(y.data(), bf.data()), &e)) << e;
    EXPECT_TRUE(af == bf);
    // forEachRow on the reused object: the same rows as modulus.
    std::vector<double> rows(a.size());
    ASSERT_TRUE(gear_test::ok(reused.forEachRow(y.data(),
                                                [&](int r, const double* w) {
                                                  std::copy(w, w + c.n, rows.begin() + r * c.n);
                                                }),
                              &e))
        << e;
    EXPECT_TRUE(rows == a);
  }
}

TEST(MorletScalogram, RefusesBadThreadCountsAndNonFiniteSamples) {
  MorletScalogram s;
  std::string e;
  EXPECT_FALSE(gear_test::ok(s.configure(100, 1.0, {0.1, 0.2}, 6.0, FftPlanning::Estimate, 0), &e));
  EXPECT_NE(e.find("threads = 0"), std::string::npos) << e;
  ASSERT_TRUE(gear_test::ok(s.configure(100, 1.0, {0.1, 0.2}, 6.0, FftPlanning::Estimate, 2), &e))
      << e;
  std::vector<double> y(100, 1.0), out(200);
  y[42] = NAN;
  EXPECT_FALSE(gear_test::ok(s.modulus(y.data(), out.data()), &e));
  EXPECT_NE(e.find("sample 42"), std::string::npos) << e;
  WaveletOptions o;
  o.threads = 0;
  EXPECT_EQ(o.check().field, "threads");
}

}  // namespace
}  // namespace gear_damping_id
