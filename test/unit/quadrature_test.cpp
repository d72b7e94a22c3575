// Quadrature of the integral method (quadrature.hpp): the four-point cubic rules are exact for
// cubics (area, first moment and value, over a whole interval or a part of it cut at an
// arbitrary switch fraction), and fourth order on smooth signals, also for a held stiffness that
// jumps between two samples when the interval is split at the switch.
#include "gear_damping_id/quadrature.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>
#include <vector>

#include "gear_damping_id/forward_model.hpp"

namespace {

using gear_damping_id::CubicIntervalRule;
using gear_damping_id::CubicRules;

// p(u) = a0 + a1 u + a2 u^2 + a3 u^3 and its exact integrals.
struct Cubic {
  double a[4];
  double at(double u) const { return a[0] + u * (a[1] + u * (a[2] + u * a[3])); }
  // integral_{u0}^{u1} p(u) du
  double area(double u0, double u1) const {
    auto F = [&](double u) {
      return a[0] * u + a[1] * u * u / 2 + a[2] * u * u * u / 3 + a[3] * u * u * u * u / 4;
    };
    return F(u1) - F(u0);
  }
  // integral_{u0}^{u1} (1 - u) p(u) du = area - integral u p(u)
  double moment(double u0, double u1) const {
    auto G = [&](double u) {
      return a[0] * u * u / 2 + a[1] * u * u * u / 3 + a[2] * std::pow(u, 4) / 4 +
             a[3] * std::pow(u, 5) / 5;
    };
    return area(u0, u1) - (G(u1) - G(u0));
  }
};

double apply(const CubicIntervalRule::Weights& w, const Cubic& p, int offset) {
  double s = 0.0;
  for (int k = 0; k < 4; ++k) s += w[k] * p.at(offset + k);
  return s;
}

// Exactness is limited by rounding only: the weights are O(1) sums of a few O(1) terms.
constexpr double kRoundingTol = 1e-13;

TEST(CubicIntervalRule, IntegratesCubicsExactlyOverTheWholeInterval) {
  const Cubic p{{0.7, -1.3, 2.1, -0.9}};
  for (int offset : {-2, -1, 0}) {
    const CubicIntervalRule rule(offset);
    EXPECT_NEAR(apply(rule.area(), p, offset), p.area(0, 1), kRoundingTol) << offset;
    EXPECT_NEAR(apply(rule.moment(), p, offset), p.moment(0, 1), kRoundingTol) << offset;
    for (double u : {0.0, 0.25, 0.5, 1.0}) {
      EXPECT_NEAR(apply(rule.value(u), p, offset), p.at(u), kRoundingTol) << offset << " " << u;
    }
  }
}

TEST(CubicIntervalRule, IntegratesCubicsExactlyAcrossASwitchAtAnArbitraryFraction) {
  const Cubic p{{-0.4, 3.0, -1.7, 1.1}};
  for (int offset : {-2, -1, 0}) {
    const CubicIntervalRule rule(offset);
    for (double th : {0.0, 0.123456789, 0.5, 0.987654321, 1.0}) {
      const auto al = rule.area(0.0, th), ar = rule.area(th, 1.0);
      const auto ml = rule.moment(0.0, th), mr = rule.moment(th, 1.0);
      EXPECT_NEAR(apply(al, p, offset), p.area(0, th), kRoundingTol) << offset << " " << th;
      EXPECT_NEAR(apply(ar, p, offset), p.area(th, 1), kRoundingTol) << offset << " " << th;
      EXPECT_NEAR(apply(ml, p, offset), p.moment(0, th), kRoundingTol) << offset << " " << th;
      EXPECT_NEAR(apply(mr, p, offset), p.moment(th, 1), kRoundingTol) << offset << " " << th;
      // The two parts add up to the whole-interval weights.
      for (int k = 0; k < 4; ++k) {
        EXPECT_NEAR(al[k] + ar[k], rule.area()[k], kRoundingTol);
        EXPECT_NEAR(ml[k] + mr[k], rule.moment()[k], kRoundingTol);
      }
    }
  }
}

TEST(CubicRules, PickTheStencilThatStaysInsideTheRecord) {
  const CubicRules rules;
  const long lo = 10, hi = 20;  // samples [10, 20): intervals j = 10..18
  EXPECT_EQ(rules.forInterval(10, lo, hi).offset(), 0);
  EXPECT_EQ(rules.forInterval(11, lo, hi).offset(), -1);
  EXPECT_EQ(rules.forInterval(17, lo, hi).offset(), -1);
  EXPECT_EQ(rules.forInterval(18, lo, hi).offset(), -2);
  for (long j = lo; j + 1 < hi; ++j) {
    const int o = rules.forInterval(j, lo, hi).offset();
    EXPECT_GE(j + o, lo);
    EXPECT_LE(j + o + 3, hi - 1);
  }
}

// Composite rule over [0, 1] with n intervals, accumulated the way the integral method does
// (Q += h G + h^2 moment, G += h area): at every grid point t_i, the single integral
// G(t_i) = int_0^t_i k g and the double integral Q(t_i) = int_0^t_i int_0^s k g
// = int_0^t_i (t_i - s) k(s) g(s) ds. k is held: k_lo before `t_switch`, k_hi from it on; with
// `split` the interval containing the switch is cut at its exact fraction, else the value at the
// interval's start is held over the whole interval (sample-and-hold). Returns the largest errors
// over the grid points against closed forms of g(t) = sin(w t) + 0.3 cos(2.3 w t).
std::pair<double, double> errors(double t_switch, bool split, int n) {
  const double w = 7.0;  // about one oscillation on [0, 1]
  auto g = [&](double t) { return std::sin(w * t) + 0.3 * std::cos(2.3 * w * t); };
  const double k_lo = 2.0, k_hi = 4.0;  // the 2x stiffness jump of Table 1
  auto k = [&](double t) { return t < t_switch ? k_lo : k_hi; };
  const double v = 2.3 * w;
  auto Ig = [&](double t) { return -std::cos(w * t) / w + 0.3 * std::sin(v * t) / v; };
  auto Itg = [&](double t) {  // antiderivative of t g(t)
    return (std::sin(w * t) / (w * w) - t * std::cos(w * t) / w) +
           0.3 * (std::cos(v * t) / (v * v) + t * std::sin(v * t) / v);
  };
  // Exact G(t) and Q(t) = t G(t) - int_0^t s k g, per side of the switch.
  auto exact = [&](double t, double* G, double* Q) {
    const double ts = std::min(t, t_switch);
    double S = k_lo * (Ig(ts) - Ig(0.0)), M = k_lo * (Itg(ts) - Itg(0.0));
    if (t > t_switch) S += k_hi * (Ig(t) - Ig(t_switch)), M += k_hi * (Itg(t) - Itg(t_switch));
    *G = S;
    *Q = t * S - M;
  };
  const CubicRules rules;
  const double h = 1.0 / n;
  std::vector<double> y(n + 1);
  for (int i = 0; i <= n; ++i) y[i] = g(i * h);
  double G = 0.0, Q = 0.0, e1 = 0.0, e2 = 0.0;
  for (int j = 0; j < n; ++j) {
    const CubicIntervalRule& rule = rules.forInterval(j, 0, n + 1);
    const int b = j + rule.offset();
    const double ta = j * h, tb = (j + 1) * h;
    double th = 1.0;
    if (split && ta < t_switch && t_switch < tb) th = (t_switch - ta) / h;
    const double kl = k(ta), kr = (th < 1.0) ? k(tb) : kl;
    const auto al = rule.area(0.0, th), ar = rule.area(th, 1.0);
    const auto ml = rule.moment(0.0, th), mr = rule.moment(th, 1.0);
    double a = 0.0, m = 0.0;
    for (int c = 0; c < 4; ++c) {
      a += (kl * al[c] + kr * ar[c]) * y[b + c];
      m += (kl * ml[c] + kr * mr[c]) * y[b + c];
    }
    Q += h * G + h * h * m;
    G += h * a;
    double Ge, Qe;
    exact(tb, &Ge, &Qe);
    e1 = std::max(e1, std::abs(G - Ge));
    e2 = std::max(e2, std::abs(Q - Qe));
  }
  return {e1, e2};
}

// Observed order: least-squares slope of -log2(error) against log2(n) over n = 32 .. 1024 (a
// fit over six grids rather than one ratio: the error constant depends on where the switch falls
// within its interval, which differs from grid to grid).
std::pair<double, double> observedOrder(double t_switch, bool split) {
  double sx = 0, sy1 = 0, sy2 = 0, sxx = 0, sxy1 = 0, sxy2 = 0;
  int m = 0;
  for (int n = 32; n <= 1024; n *= 2, ++m) {
    const auto [e1, e2] = errors(t_switch, split, n);
    const double x = std::log2(n), y1 = -std::log2(e1), y2 = -std::log2(e2);
    sx += x, sxx += x * x, sy1 += y1, sy2 += y2, sxy1 += x * y1, sxy2 += x * y2;
  }
  const double d = m * sxx - sx * sx;
  return {(m * sxy1 - sx * sy1) / d, (m * sxy2 - sx * sy2) / d};
}

// Fourth order with the switch split (asymptotic range: w h = 7/32 .. 7/1024, around the
// identification's w dt = 0.06); the switch falls off the samples of every grid. The fitted
// slope scatters by a few tenths around 4 (the error constant of the interval holding the switch
// depends on its fraction); 0.5 still separates it from the sample-and-hold's first order.
constexpr double kOrderTol = 0.5;
TEST(CubicRules, ConvergeWithOrderFourWhenTheIntervalIsSplitAtTheSwitch) {
  for (double t_switch : {0.3217, 0.4321, 0.6789, 2.0 /* no switch in [0, 1] */}) {
    const auto [single, twice] = observedOrder(t_switch, /*split=*/true);
    EXPECT_NEAR(single, 4.0, kOrderTol) << t_switch;
    EXPECT_NEAR(twice, 4.0, kOrderTol) << t_switch;
    std::cout << "[ measured ] switch at " << t_switch << ": order " << single << " (single), "
              << twice << " (double)\n";
  }
}

// Holding the value over the whole interval that contains the switch makes an error of
// (fraction of an interval) x (jump) x h: first order, orders of magnitude above the split
// rule's at the identification's resolution. This is what docs/method.md §4 warns about.
TEST(CubicRules, SampleAndHoldAcrossTheSwitchIsFirstOrderAndFarWorseThanTheSplit) {
  // A factor 100 is conservative: at n = 64 the split error is ~h^4 ~ 1e-8 of the integral,
  // the held one ~h ~ 1e-2 times the switch's fraction of an interval.
  constexpr double kMinRatio = 100.0;
  for (double t_switch : {0.3217, 0.4321, 0.6789}) {
    const auto [h1, h2] = errors(t_switch, /*split=*/false, 64);
    const auto [s1, s2] = errors(t_switch, /*split=*/true, 64);
    EXPECT_GT(h1, kMinRatio * s1) << t_switch;
    EXPECT_GT(h2, kMinRatio * s2) << t_switch;
    const auto [o1, o2] = observedOrder(t_switch, /*split=*/false);
    EXPECT_NEAR(o1, 1.0, kOrderTol) << t_switch;
    EXPECT_NEAR(o2, 1.0, kOrderTol) << t_switch;
  }
}

// A channel held at two levels with switches at a seed's density (up to 0.6 per interval every
// fourth seed, so adjacent switches occur), n samples, and a sub-range [lo, hi) of it.
std::vector<double> randomHeldChannel(unsigned seed, long* n_out, long* lo, long* hi) {
  std::mt19937 rng(seed);
  const long n = std::uniform_int_distribution<long>(3, 300)(rng);
  const double p_switch =
      std::uniform_real_distribution<double>(0.0, seed % 4 == 0 ? 0.6 : 0.1)(rng);
  std::vector<double> k(static_cast<size_t>(n));
  double level = 2e8;
  for (long i = 0; i < n; ++i) {
    if (std::uniform_real_distribution<double>(0.0, 1.0)(rng) < p_switch)
      level = level == 2e8 ? 4e8 : 2e8;
    k[static_cast<size_t>(i)] = level;
  }
  *n_out = n;
  *lo = std::uniform_int_distribution<long>(0, n / 3)(rng);
  *hi = std::uniform_int_distribution<long>(std::min(n, *lo + 2), n)(rng);
  return k;
}

}  // namespace

// heldChanges (the integral method's one-pass scan) finds what channelIsHeld and findBreaks
// (held) find in two passes: over seeds, channels held with switches at every density (adjacent
// switches included, so some are smooth by channelIsHeld's rule), switches on the edges of the
// scan's 16-interval blocks, and sub-ranges [lo, hi) at every offset.
TEST(HeldChanges, AgreesWithChannelIsHeldAndFindBreaks) {
  int held_cases = 0, smooth_cases = 0;
  for (unsigned seed = 1; seed <= 400; ++seed) {
    long n = 0, lo = 0, hi = 0;
    const std::vector<double> k = randomHeldChannel(seed, &n, &lo, &hi);
    std::vector<long> changes;
    const bool held = gear_damping_id::heldChanges(k.data(), lo, hi, true, &changes);
    ASSERT_EQ(held, gear_damping_id::channelIsHeld(k.data(), lo, hi)) << "seed " << seed;
    // Without the pair check every change is listed (the greybox mesh state).
    std::vector<long> all;
    EXPECT_TRUE(gear_damping_id::heldChanges(k.data(), lo, hi, false, &all));
    gear_damping_id::SignalView v;
    v.n = n;
    v.dt = 1e-6;
    std::vector<gear_damping_id::QuadratureBreak> breaks;
    gear_damping_id::findBreaks(v, k.data(), true, 1.6, lo, hi, &breaks);
    ASSERT_EQ(all.size(), breaks.size()) << "seed " << seed;
    for (size_t b = 0; b < breaks.size(); ++b) EXPECT_EQ(all[b], breaks[b].j) << "seed " << seed;
    if (held) {
      EXPECT_EQ(changes, all) << "seed " << seed;
      ++held_cases;
    } else {
      ++smooth_cases;
    }
  }
  EXPECT_GT(held_cases, 100);
  EXPECT_GT(smooth_cases, 50);
}

// heldChangesAfter (the scan continued after the integral method's first read of a segment has
// flagged its blocks of 16 intervals that change, changesIn16) gives heldChanges' result and list
// for every split point `from` (lo plus a multiple of 16), with and without the pair check:
// held channels at every switch density, adjacent switches (smooth) and switches on block edges.
TEST(HeldChanges, ContinuedAfterFlaggedBlocksGivesTheOneScanResult) {
  long splits = 0, flagged_blocks = 0;
  for (unsigned seed = 1; seed <= 300; ++seed) {
    long n = 0, lo = 0, hi = 0;
    const std::vector<double> k = randomHeldChannel(seed, &n, &lo, &hi);
    for (const bool pairs : {true, false}) {
      std::vector<long> one;
      const bool one_held = gear_damping_id::heldChanges(k.data(), lo, hi, pairs, &one);
      std::vector<long> flagged;
      for (long from = lo; from == lo || from + 16 <= hi - 1; from += 16) {
        if (from > lo && gear_damping_id::changesIn16(k.data() + from - 16)) {
          flagged.push_back(from - 16);
          ++flagged_blocks;
        }
        std::vector<long> after;
        const bool held =
            gear_damping_id::heldChangesAfter(k.data(), lo, hi, pairs, flagged, from, &after);
        ASSERT_EQ(held, one_held) << "seed " << seed << " from " << from;
        if (held) {
          EXPECT_EQ(after, one) << "seed " << seed << " from " << from;
        }
        ++splits;
      }
    }
  }
  EXPECT_GT(splits, 1000);
  EXPECT_GT(flagged_blocks, 200);
}
