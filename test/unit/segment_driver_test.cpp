// SegmentDriver: batch identify(), the bounded-memory streaming of a long record (SegmentFeeder,
// as `analyze` reads a bag) and live identification (StreamAssembler chunks into
// LiveIdentification) are one pipeline, so they give the same segment results for every
// formulation x damping model; and segments identified on several threads equal one thread's.
#include "gear_damping_id/segment_driver.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "gear_damping_id/live_identification.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/stream_assembler.hpp"
#include "id_test_support.hpp"
#include "status_support.hpp"

namespace {

namespace gd = gear_damping_id;
using gear_id_test::addWhiteNoise;
using gear_id_test::simulateOrFail;
using gear_id_test::table1Config;
using Refine = gd::IdentificationOptions::Refine;

// Same samples and arithmetic; the only difference allowed is the time axis: the batch view's
// step is (t_last - t_first) / (n - 1) of the table, the live view's 1 / sample_rate, which may
// differ in the last bit (measured: results equal to 1e-15 relative).
constexpr double kSameRelTol = 1e-12;

struct Record {
  gear_sim::SignalTable table;
  gd::GearConstants gear;
  double sample_rate = 0.0;
  gd::SteModelOptions ste;  // active() when the record has an STE to identify
  size_t ste_calibration = 0;
  explicit Record(bool with_ste = false) {
    gear_sim::SimConfig c = table1Config();
    c.simulation.duration = 0.006;  // six 1 ms segments
    if (with_ste) {  // three mesh harmonics and an offset; calibrated on the first 3 segments
      c.ste.mesh_cos = {1.0e-6, 0.3e-6, -0.12e-6};
      c.ste.mesh_sin = {-0.4e-6, 0.25e-6, 0.08e-6};
      c.ste.offset = 3e-6;
      ste.mesh_orders = 3;
      ste.pinion_teeth = c.gears.pinion.teeth;
      ste.gear_teeth = c.gears.gear.teeth;
      ste_calibration = 3;
    } else {
      ste.offset = false;
    }
    table = simulateOrFail(c);
    // 40 dB: the piecewise segments are refined (Auto), each on its own.
    addWhiteNoise(&table.dte, 40.0, 7);
    gear = gd::gearConstants(c.gearModel());
    sample_rate = c.simulation.sample_rate;
  }
};

const Record& plainRecord() {
  static const Record r;
  return r;
}
const Record& steRecord() {
  static const Record r(true);
  return r;
}
const Record* current = &plainRecord();  // the record the helpers below run on
const Record& record() { return *current; }

void setUp(gd::SegmentDriver* d) {
  if (record().ste.active()) {
    EXPECT_EQ(d->setSte(record().ste, record().ste_calibration).message(), "");
  }
}

gd::IdentificationOptions optionsFor(gd::Formulation f, gd::DampingModel m) {
  gd::IdentificationOptions o;
  o.formulation = f;
  o.model = m;
  // Shared unknowns are refined over the whole record only (a streamed or live run cannot):
  // the three paths are compared on their common ground, the integral estimate.
  o.refine = m == gd::DampingModel::Piecewise ? Refine::Auto : Refine::Never;
  o.window_length = gd::defaultWindowLength(gd::SignalView::of(record().table), record().gear);
  return o;
}

std::string label(const gd::IdentificationOptions& o) {
  return gd::toString(o.formulation) + "/" + gd::toString(o.model);
}

gd::IdentificationResult batch(const gd::IdentificationOptions& o, int threads = 1) {
  gd::IdentificationResult r;
  std::string e;
  if (!record().ste.active()) {
    EXPECT_TRUE(gear_test::ok(gd::identify(record().table, record().gear, o, &r, threads), &e))
        << e;
    return r;
  }
  // The STE: the whole record's segments fed to one driver (what identify() does without).
  const gd::SignalView whole = gd::SignalView::of(record().table);
  const gd::SampleRanges ranges = gd::segmentRanges(whole, o);
  gd::SegmentDriver driver(o, record().gear);
  setUp(&driver);
  driver.addAll(whole, ranges);
  return driver.finish(&whole, &ranges);
}

// Samples [a, a + n) of every column of `t`, as a block streamed from a bag.
gear_sim::SignalTable blockOf(const gear_sim::SignalTable& t, Eigen::Index a, Eigen::Index n) {
  gear_sim::SignalTable block;
  block.time = t.time.segment(a, n);
  block.dte = t.dte.segment(a, n);
  block.stiffness = t.stiffness.segment(a, n);
  block.torque = t.torque.segment(a, n);
  block.mesh_state = t.mesh_state.segment(a, n);
  block.mesh_phase = t.mesh_phase.segment(a, n);
  return block;
}

// The record read in blocks of `group` segments plus context, as analyze streams a bag: each
// block holds the feeder's held range (the group's read with its left context) and is used in
// place (pushHeld).
gd::IdentificationResult streamed(const gd::IdentificationOptions& o, size_t group,
                                  int threads = 1) {
  const gear_sim::SignalTable& t = record().table;
  const gd::SignalView whole = gd::SignalView::of(t);
  const gd::SampleRanges ranges = gd::segmentRanges(whole, o);
  gd::DriverLimits limits;
  limits.threads = threads;
  gd::SegmentDriver driver(o, record().gear, limits);
  setUp(&driver);
  if (o.formulation == gd::Formulation::Legacy)
    driver.setLegacyForcing(gd::legacyForcing(whole, ranges, record().gear));
  gd::SegmentFeeder feeder(ranges, whole.n, whole.t0, whole.dt, group);
  const gd::SampleRanges held = feeder.heldRanges();
  for (size_t k = 0; k < held.size(); ++k) {
    const Eigen::Index a = held[k].first, n = held[k].second - a;
    const gear_sim::SignalTable block = blockOf(t, a, n);  // only this block in memory
    const auto sink = [&](const gd::SignalView& v, const gd::SampleRanges& segs, size_t) {
      driver.addAll(v, segs);
      return true;
    };
    EXPECT_TRUE(feeder.pushHeld(block, k, sink));
  }
  return driver.finish();
}

// The record published in chunks of arbitrary sizes, assembled and identified live.
gd::IdentificationResult live(const gd::IdentificationOptions& o, unsigned seed) {
  const gear_sim::SignalTable& t = record().table;
  gd::StreamOptions so;
  so.segment_length = o.segment_length;
  so.max_jump = INFINITY;
  gd::StreamAssembler assembler(so);
  gd::LiveIdentification li(o, record().gear);
  if (record().ste.active()) {
    EXPECT_EQ(li.setSte(record().ste, record().ste_calibration).message(), "");
  }
  if (o.formulation == gd::Formulation::Legacy) {
    const gd::SignalView whole = gd::SignalView::of(t);
    li.setLegacyForcing(gd::legacyForcing(whole, gd::segmentRanges(whole, o), record().gear));
  }
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> size(1, 900);
  gd::StreamSegment s;
  auto drain = [&] {
    while (assembler.nextSegment(&s)) li.add(s.view(), s.begin, s.end);
  };
  for (Eigen::Index i = 0; i < t.size();) {
    const Eigen::Index n = std::min<Eigen::Index>(size(rng), t.size() - i);
    gd::ChunkData c;
    c.first_index = static_cast<std::uint64_t>(i);
    c.sample_rate = record().sample_rate;
    c.n = static_cast<size_t>(n);
    c.dte = t.dte.data() + i;
    c.stiffness = t.stiffness.data() + i;
    c.torque = t.torque.data() + i;
    c.mesh_state = t.mesh_state.data() + i;
    c.mesh_phase = t.mesh_phase.data() + i;
    assembler.push(c);
    drain();
    i += n;
  }
  assembler.endOfStream();
  drain();
  return li.cumulative();
}

void expectNear(double a, double b, double rel, const std::string& what) {
  if (std::isnan(b)) {
    EXPECT_TRUE(std::isnan(a)) << what;
    return;
  }
  EXPECT_NEAR(a, b, rel * std::abs(b) + 1e-300) << what;
}

void expectSameEstimate(const gd::SegmentEstimate& a, const gd::SegmentEstimate& b, double rel,
                        const std::string& what) {
  ASSERT_EQ(a.identifiable, b.identifiable) << what << " " << a.reason << " | " << b.reason;
  EXPECT_EQ(a.reason, b.reason) << what;
  EXPECT_EQ(a.samples, b.samples) << what;
  EXPECT_EQ(a.refined, b.refined) << what;
  EXPECT_EQ(gd::joinCodes(a.warnings), gd::joinCodes(b.warnings)) << what;
  EXPECT_NEAR(a.t_start, b.t_start, 1e-12) << what;
  expectNear(a.C, b.C, rel, what + " C");
  expectNear(a.C_std, b.C_std, rel, what + " C_std");
  expectNear(a.c, b.c, rel, what + " c");
  expectNear(a.xi, b.xi, rel, what + " xi");
  expectNear(a.k_min, b.k_min, rel, what + " k_min");
  expectNear(a.k_max, b.k_max, rel, what + " k_max");
  expectNear(a.C_integral, b.C_integral, rel, what + " C_integral");
}

void expectSameResult(const gd::IdentificationResult& a, const gd::IdentificationResult& b,
                      double rel, const std::string& what) {
  ASSERT_EQ(a.segments.size(), b.segments.size()) << what;
  expectNear(a.omega0, b.omega0, rel, what + " omega0");
  for (size_t i = 0; i < b.segments.size(); ++i)
    expectSameEstimate(a.segments[i], b.segments[i], rel, what + " segment " + std::to_string(i));
  ASSERT_EQ(a.constant.has_value(), b.constant.has_value()) << what;
  if (b.constant) expectSameEstimate(*a.constant, *b.constant, rel, what + " constant");
  ASSERT_EQ(a.load_law.has_value(), b.load_law.has_value()) << what;
  if (b.load_law) {
    expectNear(a.load_law->c0, b.load_law->c0, rel, what + " c0");
    expectNear(a.load_law->c1, b.load_law->c1, rel, what + " c1");
    expectNear(a.load_law->c0_std, b.load_law->c0_std, rel, what + " c0_std");
  }
}

TEST(SegmentDriver, BatchStreamedAndLiveGiveTheSameSegmentsForEveryFormulationAndModel) {
  int refined = 0;
  for (const auto f : gd::kFormulations) {
    for (const auto m : gd::kDampingModels) {
      const gd::IdentificationOptions o = optionsFor(f, m);
      const gd::IdentificationResult b = batch(o);
      ASSERT_EQ(b.segments.size(), 6u) << label(o);
      for (const auto& s : b.segments) refined += s.refined ? 1 : 0;
      // Smallest memory budget: one segment (plus its context) per read.
      expectSameResult(streamed(o, 1), b, 0.0, label(o) + " streamed");
      expectSameResult(live(o, 11), b, kSameRelTol, label(o) + " live");
      expectSameResult(live(o, 12), b, kSameRelTol, label(o) + " live, other chunking");
    }
  }
  EXPECT_GT(refined, 0) << "the case must exercise the per-segment refinement";
}

// The STE in the segment pipeline: calibrated jointly on the first 3 segments, held for the
// other 3; batch, streamed and live runs give the same segments (known and greybox, piecewise;
// the constant model's calibration is the whole record, so live refuses it), and a calibration
// span covering the record gives the batch identifyWithSte.
TEST(SegmentDriver, WithTheSteBatchStreamedAndLiveGiveTheSameSegments) {
  current = &steRecord();
  int refined = 0, held = 0;
  for (const auto f : {gd::Formulation::Known, gd::Formulation::Greybox}) {
    gd::IdentificationOptions o = optionsFor(f, gd::DampingModel::Piecewise);
    const gd::IdentificationResult b = batch(o);
    ASSERT_EQ(b.segments.size(), 6u) << label(o);
    for (size_t i = 0; i < b.segments.size(); ++i) {
      EXPECT_TRUE(b.segments[i].identifiable) << label(o) << " " << b.segments[i].reason;
      refined += b.segments[i].refined ? 1 : 0;
      held += i >= 3 && b.segments[i].identifiable ? 1 : 0;
    }
    expectSameResult(streamed(o, 1), b, 0.0, label(o) + " STE streamed");
    expectSameResult(live(o, 11), b, kSameRelTol, label(o) + " STE live");
    expectSameResult(live(o, 12), b, kSameRelTol, label(o) + " STE live, other chunking");
    // Calibration over the whole record = the batch joint identification.
    gd::SteModelOptions so = record().ste;
    const gd::SignalView whole = gd::SignalView::of(record().table);
    const gd::SampleRanges ranges = gd::segmentRanges(whole, o);
    gd::SegmentDriver all(o, record().gear);
    ASSERT_EQ(all.setSte(so, 100).message(), "");
    all.addAll(whole, ranges);
    gd::IdentificationResult joint;
    gd::SteResult ste;
    std::string e;
    ASSERT_TRUE(
        gear_test::ok(gd::identifyWithSte(record().table, record().gear, o, so, &joint, &ste), &e))
        << e;
    // (omega0 of the record: the driver's duration-weighted mean, identifyWithSte's plain mean.)
    const gd::IdentificationResult whole_span = all.finish(&whole, &ranges);
    ASSERT_EQ(whole_span.segments.size(), joint.segments.size());
    for (size_t i = 0; i < joint.segments.size(); ++i)
      expectSameEstimate(whole_span.segments[i], joint.segments[i], kSameRelTol,
                         label(o) + " whole span, segment " + std::to_string(i));
  }
  EXPECT_GT(refined, 0) << "the case must exercise the refinement";
  EXPECT_EQ(held, 6) << "every held segment identified";
  gd::LiveIdentification constant(optionsFor(gd::Formulation::Known, gd::DampingModel::Constant),
                                  record().gear);
  EXPECT_NE(constant.setSte(record().ste, 3).message(), "");
  current = &plainRecord();
}

TEST(SegmentDriver, SegmentsOnSeveralThreadsEqualOneThreadBitForBit) {
  for (const auto f : gd::kFormulations) {
    for (const auto m : gd::kDampingModels) {
      const gd::IdentificationOptions o = optionsFor(f, m);
      const gd::IdentificationResult one = batch(o, 1);
      expectSameResult(batch(o, 3), one, 0.0, label(o) + " 3 threads");
      expectSameResult(streamed(o, 4, 4), one, 0.0, label(o) + " streamed, 4 threads");
    }
  }
}

TEST(SegmentDriver, AStreamedSharedRunThatWantsRefinementSaysItWasSkipped) {
  gd::IdentificationOptions o = optionsFor(gd::Formulation::Known, gd::DampingModel::Constant);
  o.refine = Refine::Always;
  const gd::IdentificationResult s = streamed(o, 2);
  EXPECT_TRUE(gd::hasCode(s.warnings, gd::quality_code::kRefineSkipped));
  const gd::IdentificationResult b = batch(o);
  EXPECT_FALSE(gd::hasCode(b.warnings, gd::quality_code::kRefineSkipped));
  ASSERT_TRUE(b.constant.has_value());
  EXPECT_TRUE(b.constant->refined);
}

// The read ranges are contiguous and cover every segment with its context; the held ranges are
// the reads with the samples kept before them (the group's left context): here the second
// group's segment [300, 450) needs samples from 298 on.
TEST(SegmentFeeder, ReadAndHeldRangesCoverEverySegmentWithItsContext) {
  const gd::SampleRanges segs = {{0, 100}, {100, 200}, {200, 300}, {300, 450}};
  gd::SegmentFeeder feeder(segs, 460, 0.0, 1e-6, 3);
  using R = std::pair<Eigen::Index, Eigen::Index>;
  EXPECT_EQ(feeder.readRanges(), (gd::SampleRanges{R{0, 302}, R{302, 452}}));
  EXPECT_EQ(feeder.heldRanges(), (gd::SampleRanges{R{0, 302}, R{298, 452}}));
}

// Blocks of the held ranges used in place (pushHeld, as analyze streams a bag) give the results
// of the whole record read at once, bit for bit, for groups of 1, 2 and 7 segments, one and two
// threads, segment-local formulations and models. Only the segment's start time is computed
// otherwise: the block's origin t0 + first dt plus (i - first) dt, against t0 + i dt whole, which
// may round differently in the last bits (measured: at most 8.7e-19 s; expectSameEstimate's
// 1e-12 s).
TEST(SegmentFeeder, BlocksUsedInPlaceGiveTheWholeRecordsEstimatesBitForBit) {
  const auto sameBits = [](double x, double y) { return std::memcmp(&x, &y, sizeof x) == 0; };
  for (const auto f : {gd::Formulation::Known, gd::Formulation::Greybox}) {
    for (const auto m : {gd::DampingModel::Piecewise, gd::DampingModel::LoadLaw}) {
      const gd::IdentificationOptions o = optionsFor(f, m);
      for (const int threads : {1, 2}) {
        const gd::IdentificationResult whole = batch(o, threads);
        for (const size_t group : {size_t{1}, size_t{2}, size_t{7}}) {
          const gd::IdentificationResult b = streamed(o, group, threads);
          ASSERT_EQ(whole.segments.size(), b.segments.size());
          for (size_t i = 0; i < b.segments.size(); ++i) {
            const gd::SegmentEstimate &a = whole.segments[i], &s = b.segments[i];
            EXPECT_TRUE(sameBits(a.C, s.C)) << group << " " << i;
            EXPECT_TRUE(sameBits(a.C_std, s.C_std)) << group << " " << i;
            EXPECT_NEAR(a.t_start, s.t_start, 1e-12) << group << " " << i;
          }
        }
      }
    }
  }
}

// The sink's view of the segments of `segs` from `first` on (`local`, in view samples): each one
// has every channel of `whole` (record sample i at t0 + i dt), its samples and its stencil
// context where the record has them, at the record's times. Counts each segment in *seen.
void expectSegmentsOfTheWholeRecord(const gd::SignalView& v, const gd::SampleRanges& local,
                                    size_t first, const gd::SampleRanges& segs,
                                    const gear_sim::SignalTable& whole, double t0,
                                    std::vector<int>* seen) {
  using R = std::pair<Eigen::Index, Eigen::Index>;
  const double* got[5] = {v.dte, v.stiffness, v.torque, v.mesh_state, v.mesh_phase};
  const Eigen::VectorXd* want[5] = {&whole.dte, &whole.stiffness, &whole.torque, &whole.mesh_state,
                                    &whole.mesh_phase};
  const double dt = whole.time(1) - whole.time(0);
  const Eigen::Index origin = std::llround((v.t0 - t0) / dt);  // record sample of view sample 0
  EXPECT_EQ(v.t0, t0 + static_cast<double>(origin) * v.dt);
  for (size_t j = 0; j < local.size(); ++j) {
    const R& seg = segs[first + j];
    EXPECT_EQ(local[j], R(seg.first - origin, seg.second - origin)) << first + j;
    ++(*seen)[first + j];
    const Eigen::Index lo = std::max<Eigen::Index>(seg.first - gd::kStencilContext, 0);
    const Eigen::Index hi = std::min(seg.second + gd::kStencilContext, whole.size());
    ASSERT_GE(lo - origin, 0) << first + j;
    ASSERT_LE(hi - origin, v.n) << first + j;
    for (int c = 0; c < 5; ++c) {
      ASSERT_NE(got[c], nullptr) << "channel " << c << ", segment " << first + j;
      for (Eigen::Index i = lo; i < hi; ++i)
        EXPECT_EQ(got[c][i - origin], (*want[c])(i)) << "channel " << c << ", sample " << i;
    }
  }
}

// A group that reads no new sample (65 segments of 2 samples in groups of 64: the first read
// ends at the record's end, with the last segment's right context) still gets its segment with
// the samples before it: the block of its held range, used in place, gives the sink the
// segments of the whole record (every channel, the same samples at the same times, context
// included). push() of the read ranges, now removed, handed that group a view without channels.
TEST(SegmentFeeder, AGroupThatReadsNoNewSampleGetsTheSegmentsOfTheWholeRecord) {
  constexpr Eigen::Index kSegments = 65, kLength = 2, kSamples = kSegments * kLength;
  constexpr double t0 = 0.25, dt = 1e-6;
  gd::SampleRanges segs;
  for (Eigen::Index i = 0; i < kSegments; ++i) segs.emplace_back(i * kLength, (i + 1) * kLength);
  gear_sim::SignalTable whole;  // every sample of every channel distinct
  const Eigen::VectorXd count = Eigen::VectorXd::LinSpaced(kSamples, 0.0, kSamples - 1.0);
  whole.time = t0 + dt * count.array();
  whole.dte = count.array() + 1000.0;
  whole.stiffness = count.array() + 2000.0;
  whole.torque = count.array() + 3000.0;
  whole.mesh_state = count.array() + 4000.0;
  whole.mesh_phase = count.array() + 5000.0;
  gd::SegmentFeeder feeder(segs, kSamples, t0, dt, 64);
  using R = std::pair<Eigen::Index, Eigen::Index>;
  ASSERT_EQ(feeder.readRanges(), (gd::SampleRanges{R{0, kSamples}, R{kSamples, kSamples}}));
  const gd::SampleRanges held = feeder.heldRanges();
  ASSERT_EQ(held, (gd::SampleRanges{R{0, kSamples}, R{kSamples - 4, kSamples}}));
  std::vector<int> seen(kSegments, 0);
  const auto sink = [&](const gd::SignalView& v, const gd::SampleRanges& local, size_t first) {
    EXPECT_EQ(v.dt, dt);
    expectSegmentsOfTheWholeRecord(v, local, first, segs, whole, t0, &seen);
    return true;
  };
  for (size_t k = 0; k < held.size(); ++k) {
    const Eigen::Index a = held[k].first, n = held[k].second - a;
    EXPECT_TRUE(feeder.pushHeld(blockOf(whole, a, n), k, sink));
  }
  EXPECT_EQ(seen, std::vector<int>(kSegments, 1));
}

}  // namespace
