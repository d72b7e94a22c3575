// LiveIdentification: segment-at-a-time identification equals the offline identify() of the
// same record with the same options (piecewise, constant, load_law; refinement per segment).
#include "gear_damping_id/live_identification.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "status_support.hpp"

namespace gd = gear_damping_id;

namespace {

// Same samples, same view, same arithmetic: only summation order could differ (it does not).
constexpr double kSameComputationRelTol = 1e-12;
// Per-segment vs whole-record output-error refinement: independent segment problems, each
// Gauss-Newton run to its own convergence tolerance (measured 1e-12 on 40 dB data).
constexpr double kRefinementRelTol = 1e-8;

struct Case {
  gear_sim::SimConfig cfg;
  gear_sim::SignalTable table;
  gd::GearConstants gear;
  explicit Case(double snr_db = INFINITY) {
    std::string e;
    EXPECT_TRUE(gear_test::ok(
        gear_sim::loadSimConfigFile(std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml", &cfg),
        &e))
        << e;
    cfg.simulation.noise_snr_db = snr_db;
    EXPECT_TRUE(gear_test::ok(gear_sim::simulate(cfg, &table), &e)) << e;
    gear = gd::gearConstants(cfg.gearModel());
  }
  // Feeds every offline segment range to a LiveIdentification; returns its cumulative result.
  gd::IdentificationResult live(const gd::IdentificationOptions& o,
                                std::vector<gd::LiveIdentification::SegmentOutput>* outs = nullptr,
                                gd::SignalView view = gd::SignalView()) const {
    if (view.n == 0) view = gd::SignalView::of(table);
    gd::IdentificationOptions resolved = o;
    if (resolved.window_length <= 0.0) resolved.window_length = gd::defaultWindowLength(view, gear);
    gd::LiveIdentification li(resolved, gear);
    for (const auto& r : gd::segmentRanges(view, resolved)) {
      auto out = li.add(view, r.first, r.second);
      if (outs) outs->push_back(out);
    }
    return li.cumulative();
  }
  gd::IdentificationResult offline(const gd::IdentificationOptions& o) const {
    gd::IdentificationResult r;
    std::string e;
    EXPECT_TRUE(gear_test::ok(gd::identify(table, gear, o, &r), &e)) << e;
    return r;
  }
};

void expectSameSegments(const gd::IdentificationResult& live, const gd::IdentificationResult& off,
                        double tol) {
  ASSERT_EQ(live.segments.size(), off.segments.size());
  for (size_t i = 0; i < off.segments.size(); ++i) {
    const auto& a = live.segments[i];
    const auto& b = off.segments[i];
    ASSERT_EQ(a.identifiable, b.identifiable) << i << " " << a.reason;
    EXPECT_NEAR(a.C, b.C, tol * std::abs(b.C)) << i;
    EXPECT_NEAR(a.xi, b.xi, tol * std::abs(b.xi)) << i;
    EXPECT_NEAR(a.c, b.c, tol * std::abs(b.c)) << i;
  }
}

using Refine = gd::IdentificationOptions::Refine;

TEST(LiveIdentification, PiecewiseWithoutRefinementEqualsIdentify) {
  const Case k;
  gd::IdentificationOptions o;
  o.refine = Refine::Never;
  std::vector<gd::LiveIdentification::SegmentOutput> outs;
  const auto live = k.live(o, &outs);
  const auto off = k.offline(o);
  expectSameSegments(live, off, kSameComputationRelTol);
  EXPECT_NEAR(live.omega0, off.omega0, kSameComputationRelTol * off.omega0);
  // Each segment's own result carries its windows (for the modeled response).
  ASSERT_EQ(outs.size(), off.segments.size());
  for (const auto& out : outs) {
    ASSERT_EQ(out.result.segments.size(), 1u);
    EXPECT_FALSE(out.result.windows.empty());
    gd::ModeledResponse mr;
    std::string e;
    EXPECT_TRUE(gear_test::ok(
        gd::modeledResponse(gd::SignalView::of(k.table), k.gear, out.result, &mr), &e))
        << e;
    EXPECT_GT(mr.fit_percent, 90.0);
  }
}

TEST(LiveIdentification, PerSegmentRefinementEqualsWholeRecordRefinementOnNoisyData) {
  const Case k(40.0);
  gd::IdentificationOptions o;
  o.refine = Refine::Always;
  const auto live = k.live(o);
  const auto off = k.offline(o);
  ASSERT_EQ(off.estimator, "output_error");
  double worst = 0.0;
  for (size_t i = 0; i < off.segments.size(); ++i) {
    EXPECT_TRUE(live.segments[i].refined) << i;
    worst = std::max(worst, std::abs(live.segments[i].C - off.segments[i].C) / off.segments[i].C);
  }
  expectSameSegments(live, off, kRefinementRelTol);
  std::printf("per-segment vs whole-record refinement: max rel diff %.3g\n", worst);
}

TEST(LiveIdentification, SharedModelsEqualIdentifyOverTheSameSegments) {
  const Case k;
  for (gd::DampingModel m : {gd::DampingModel::Constant, gd::DampingModel::LoadLaw}) {
    gd::IdentificationOptions o;
    o.refine = Refine::Never;
    o.model = m;
    const auto live = k.live(o);
    const auto off = k.offline(o);
    expectSameSegments(live, off, kSameComputationRelTol);
    if (m == gd::DampingModel::Constant) {
      ASSERT_TRUE(live.constant && off.constant);
      EXPECT_NEAR(live.constant->C, off.constant->C, kSameComputationRelTol * off.constant->C);
    } else {
      ASSERT_TRUE(live.load_law && off.load_law);
      EXPECT_NEAR(live.load_law->c0, off.load_law->c0,
                  kSameComputationRelTol * std::abs(off.load_law->c0));
      EXPECT_NEAR(live.load_law->c1, off.load_law->c1,
                  kSameComputationRelTol * std::abs(off.load_law->c1));
    }
  }
}

TEST(LiveIdentification, SegmentsLackingANeededChannelAreNotIdentifiableNamingIt) {
  const Case k;
  gd::SignalView v = gd::SignalView::of(k.table);
  v.stiffness = nullptr;  // the known formulation needs it
  for (gd::DampingModel m : {gd::DampingModel::Piecewise, gd::DampingModel::Constant}) {
    gd::IdentificationOptions o;
    o.model = m;
    const auto r = k.live(o, nullptr, v);
    ASSERT_EQ(r.segments.size(), 10u);
    for (const auto& s : r.segments) {
      EXPECT_FALSE(s.identifiable);
      EXPECT_NE(s.reason.find("missing channel stiffness"), std::string::npos) << s.reason;
      EXPECT_TRUE(std::isnan(s.C));
    }
  }
}

TEST(LiveIdentification, ResetForgetsEverySegment) {
  const Case k;
  gd::IdentificationOptions o;
  o.window_length = gd::defaultWindowLength(gd::SignalView::of(k.table), k.gear);
  gd::LiveIdentification li(o, k.gear);
  li.add(gd::SignalView::of(k.table), 0, 1000);
  EXPECT_EQ(li.segmentCount(), 1u);
  li.reset();
  EXPECT_EQ(li.segmentCount(), 0u);
  EXPECT_TRUE(li.cumulative().segments.empty());
}

}  // namespace

// Bounded memory: only the last history_segments estimates are kept (equal to the offline ones;
// xi still uses omega0 of every segment so far), and the shared models solve over a sliding span
// of shared_segments to 2 * shared_segments - 1 segments: with 3 and 10 segments, the last solve
// covers segments 7..10 (after the swaps at 3, 6 and 9), i.e. identify() from t_start = 6 dT.
TEST(LiveIdentification, HistoryAndSharedProblemsAreBounded) {
  const Case k;
  const gd::SignalView view = gd::SignalView::of(k.table);
  gd::IdentificationOptions o;
  o.refine = Refine::Never;
  o.window_length = gd::defaultWindowLength(view, k.gear);
  gd::LiveLimits limits;
  limits.history_segments = 4;
  limits.shared_segments = 3;
  {
    gd::LiveIdentification li(o, k.gear, limits);
    for (const auto& r : gd::segmentRanges(view, o)) li.add(view, r.first, r.second);
    EXPECT_EQ(li.segmentsAdded(), 10u);
    EXPECT_EQ(li.segmentCount(), 4u);
    const auto live = li.cumulative();
    const auto last2 = li.cumulative(2);
    const auto off = k.offline(o);
    ASSERT_EQ(live.segments.size(), 4u);
    ASSERT_EQ(last2.segments.size(), 2u);
    EXPECT_NEAR(live.omega0, off.omega0, kSameComputationRelTol * off.omega0);
    for (size_t i = 0; i < 4; ++i) {
      const auto& b = off.segments[6 + i];
      EXPECT_NEAR(live.segments[i].C, b.C, kSameComputationRelTol * b.C) << i;
      EXPECT_NEAR(live.segments[i].xi, b.xi, kSameComputationRelTol * b.xi) << i;
    }
    EXPECT_EQ(last2.segments[1].t_start, live.segments[3].t_start);
  }
  o.model = gd::DampingModel::Constant;
  gd::LiveIdentification li(o, k.gear, limits);
  for (const auto& r : gd::segmentRanges(view, o)) li.add(view, r.first, r.second);
  const auto live = li.cumulative();
  gd::IdentificationOptions tail = o;
  tail.t_start = 6.0 * o.segment_length;
  const auto off = k.offline(tail);
  ASSERT_TRUE(live.constant && off.constant);
  ASSERT_EQ(off.segments.size(), 4u);
  EXPECT_NEAR(live.constant->C, off.constant->C, kSameComputationRelTol * off.constant->C);
  ASSERT_EQ(live.segments.size(), 4u);
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_NEAR(live.segments[i].t_start, off.segments[i].t_start, 1e-12) << i;
  }
}

// A caller that cannot keep up disallows refinement: the integral estimate comes back at once,
// flagged, equal to the Refine::Never estimate.
TEST(LiveIdentification, DisallowedRefinementReturnsTheIntegralEstimateFlagged) {
  const Case k(40.0);
  const gd::SignalView view = gd::SignalView::of(k.table);
  gd::IdentificationOptions o;
  o.refine = Refine::Always;
  o.window_length = gd::defaultWindowLength(view, k.gear);
  gd::IdentificationOptions never = o;
  never.refine = Refine::Never;
  gd::LiveIdentification li(o, k.gear), ref(never, k.gear);
  const auto r = gd::segmentRanges(view, o).front();
  const auto skipped = li.add(view, r.first, r.second, false);
  const auto integral = ref.add(view, r.first, r.second);
  EXPECT_TRUE(skipped.refinement_skipped);
  EXPECT_FALSE(skipped.estimate.refined);
  EXPECT_EQ(skipped.estimate.C, integral.estimate.C);
  const auto refined = li.add(view, r.first, r.second, true);
  EXPECT_FALSE(refined.refinement_skipped);
  EXPECT_TRUE(refined.estimate.refined);
  EXPECT_NE(refined.estimate.C, integral.estimate.C);
}
