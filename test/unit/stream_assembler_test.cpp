// StreamAssembler: chunk sequencing (gaps, duplicates, reordering, restarts, rejections) and
// segment assembly that reproduces the offline segmentation and the offline identification.
#include "gear_damping_id/stream_assembler.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/live_identification.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "status_support.hpp"

namespace gd = gear_damping_id;

namespace {

constexpr double kFs = 1e6;  // [Hz]
// Live and offline differ only in how t0 and dt are formed (index/fs vs the time column):
// rounding-level differences, far below this.
constexpr double kLiveVsOfflineRelTol = 1e-9;

// A synthetic record: dte = sin, stiffness alternating, torque constant.
struct Record {
  std::vector<double> dte, stiffness, torque;
  explicit Record(size_t n) : dte(n), stiffness(n), torque(n, 100.0) {
    for (size_t i = 0; i < n; ++i) {
      dte[i] = std::sin(0.01 * static_cast<double>(i));
      stiffness[i] = (i / 37) % 2 ? 4e8 : 2e8;
    }
  }
  gd::ChunkData chunk(size_t first, size_t n, double fs = kFs) const {
    gd::ChunkData c;
    c.first_index = first;
    c.sample_rate = fs;
    c.n = n;
    c.dte = dte.data() + first;
    c.stiffness = stiffness.data() + first;
    c.torque = torque.data() + first;
    return c;
  }
};

std::vector<gd::StreamSegment> drain(gd::StreamAssembler* a) {
  std::vector<gd::StreamSegment> out;
  gd::StreamSegment s;
  while (a->nextSegment(&s)) out.push_back(s);
  return out;
}

using Range = std::pair<std::uint64_t, std::uint64_t>;

// Global [begin, end) of an emitted segment.
std::pair<std::uint64_t, std::uint64_t> range(const gd::StreamSegment& s) {
  return {s.first_index + static_cast<std::uint64_t>(s.begin),
          s.first_index + static_cast<std::uint64_t>(s.end)};
}

std::vector<std::pair<std::uint64_t, std::uint64_t>> offlineRanges(size_t n,
                                                                   const gd::StreamOptions& so) {
  std::vector<double> y(n, 0.0);
  gd::SignalView v;
  v.t0 = 0.0;
  v.dt = 1.0 / kFs;
  v.n = static_cast<Eigen::Index>(n);
  v.dte = y.data();
  gd::IdentificationOptions o;
  o.segment_length = so.segment_length;
  o.t_start = so.t_start;
  o.t_end = so.t_end;
  std::vector<std::pair<std::uint64_t, std::uint64_t>> out;
  for (const auto& r : gd::segmentRanges(v, o)) out.emplace_back(r.first, r.second);
  return out;
}

TEST(StreamAssembler, ContiguousChunksGiveTheOfflineSegmentsWithStencilContext) {
  const Record rec(10000);
  gd::StreamOptions o;
  gd::StreamAssembler a(o);
  std::vector<gd::StreamSegment> segs;
  for (size_t b = 0; b < 10000; b += 1000) {
    EXPECT_EQ(a.push(rec.chunk(b, 1000)), gd::ChunkStatus::Accepted);
    for (auto& s : drain(&a)) segs.push_back(s);
  }
  EXPECT_EQ(segs.size(), 9u) << "the last segment waits for its context or the end";
  a.endOfStream();
  for (auto& s : drain(&a)) segs.push_back(s);
  const auto expected = offlineRanges(10000, o);
  ASSERT_EQ(segs.size(), expected.size());
  for (size_t i = 0; i < segs.size(); ++i) {
    EXPECT_EQ(range(segs[i]), expected[i]) << i;
    EXPECT_FALSE(segs[i].partial);
    EXPECT_EQ(segs[i].segment_number, static_cast<long>(i));
    // Two samples of context on each side where the record has them.
    EXPECT_EQ(segs[i].begin, i == 0 ? 0 : 2);
    EXPECT_EQ(static_cast<size_t>(segs[i].end) + (i + 1 < segs.size() ? 2 : 0), segs[i].dte.size());
    for (size_t j = 0; j < segs[i].dte.size(); ++j) {
      ASSERT_EQ(segs[i].dte[j], rec.dte[segs[i].first_index + j]);
      ASSERT_EQ(segs[i].stiffness[j], rec.stiffness[segs[i].first_index + j]);
    }
    EXPECT_TRUE(segs[i].mesh_state.empty());
  }
  EXPECT_EQ(a.counters().gaps, 0u);
  EXPECT_EQ(a.counters().samples_accepted, 10000u);
}

TEST(StreamAssembler, OddChunkSizesAndTimeRangeWithTailMergeMatchOfflineRanges) {
  const Record rec(10000);
  gd::StreamOptions o;
  o.segment_length = 0.7e-3;
  o.t_start = 0.35e-3;
  o.t_end = 9.2e-3;
  gd::StreamAssembler a(o);
  for (size_t b = 0; b < 10000; b += 333) a.push(rec.chunk(b, std::min<size_t>(333, 10000 - b)));
  a.endOfStream();
  const auto segs = drain(&a);
  const auto expected = offlineRanges(10000, o);
  ASSERT_EQ(segs.size(), expected.size());
  for (size_t i = 0; i < segs.size(); ++i) EXPECT_EQ(range(segs[i]), expected[i]) << i;
}

TEST(StreamAssembler, AMissingChunkIsAGapThatNoSegmentSpans) {
  const Record rec(10000);
  gd::StreamOptions o;
  o.reorder_chunks = 2;
  gd::StreamAssembler a(o);
  for (size_t b = 0; b < 10000; b += 250) {
    if (b == 3250) continue;  // dropped on purpose: mid-segment 3
    a.push(rec.chunk(b, 250));
  }
  a.endOfStream();
  const auto segs = drain(&a);
  EXPECT_EQ(a.counters().gaps, 1u);
  EXPECT_EQ(a.counters().samples_missing, 250u);
  ASSERT_EQ(segs.size(), 11u);  // segment 3 in two pieces
  for (const auto& s : segs) {
    const auto r = range(s);
    EXPECT_TRUE(r.second <= 3250 || r.first >= 3500) << r.first << " " << r.second;
    // The context never reaches across the gap either.
    EXPECT_TRUE(s.first_index + s.dte.size() <= 3250 || s.first_index >= 3500);
  }
  EXPECT_EQ(range(segs[3]), Range(3000, 3250));
  EXPECT_EQ(range(segs[4]), Range(3500, 4000));
  EXPECT_TRUE(segs[3].partial);
  EXPECT_TRUE(segs[4].partial);
  EXPECT_EQ(segs[4].segment_number, 3);
  EXPECT_FALSE(segs[5].partial);
}

TEST(StreamAssembler, ReorderedChunksAreReassembledWithoutAGap) {
  const Record rec(6000);
  gd::StreamAssembler a{gd::StreamOptions()};
  const size_t order[] = {0, 1000, 3000, 2000, 4000, 5000};
  for (size_t b : order) a.push(rec.chunk(b, 1000));
  a.endOfStream();
  const auto segs = drain(&a);
  EXPECT_EQ(a.counters().gaps, 0u);
  EXPECT_EQ(a.counters().out_of_order, 1u);
  ASSERT_EQ(segs.size(), 6u);
  for (size_t i = 0; i < 6; ++i) EXPECT_FALSE(segs[i].partial) << i;
}

TEST(StreamAssembler, DuplicatesAndLateChunksAreIgnoredAndCounted) {
  const Record rec(6000);
  gd::StreamOptions o;
  o.reorder_chunks = 0;
  gd::StreamAssembler a(o);
  EXPECT_EQ(a.push(rec.chunk(0, 1000)), gd::ChunkStatus::Accepted);
  EXPECT_EQ(a.push(rec.chunk(1000, 1000)), gd::ChunkStatus::Accepted);
  EXPECT_EQ(a.push(rec.chunk(1000, 1000)), gd::ChunkStatus::Duplicate);
  EXPECT_EQ(a.push(rec.chunk(3000, 1000)), gd::ChunkStatus::Held);  // gap at once
  EXPECT_EQ(a.counters().gaps, 1u);
  EXPECT_EQ(a.push(rec.chunk(2000, 1000)), gd::ChunkStatus::Late);
  EXPECT_EQ(a.push(rec.chunk(3500, 1000)), gd::ChunkStatus::Accepted);  // overlap trimmed
  EXPECT_EQ(a.counters().overlaps, 1u);
  EXPECT_EQ(a.counters().duplicates, 1u);
  EXPECT_EQ(a.counters().late, 1u);
  EXPECT_EQ(a.counters().samples_accepted, 3500u);
  EXPECT_EQ(a.nextIndex(), 4500u);
}

TEST(StreamAssembler, NonFiniteAndRateChangedAndMalformedChunksAreRejected) {
  Record rec(4000);
  rec.dte[1500] = std::numeric_limits<double>::quiet_NaN();
  rec.torque[2500] = std::numeric_limits<double>::infinity();
  gd::StreamAssembler a{gd::StreamOptions()};
  std::string why;
  EXPECT_EQ(a.push(rec.chunk(0, 1000)), gd::ChunkStatus::Accepted);
  EXPECT_EQ(a.push(rec.chunk(1000, 1000), &why), gd::ChunkStatus::RejectedNonFinite);
  EXPECT_NE(why.find("dte[500]"), std::string::npos) << why;
  EXPECT_EQ(a.push(rec.chunk(2000, 1000), &why), gd::ChunkStatus::RejectedNonFinite);
  EXPECT_NE(why.find("torque[500]"), std::string::npos) << why;
  EXPECT_EQ(a.push(rec.chunk(3000, 1000, 2e6), &why), gd::ChunkStatus::RejectedRate);
  gd::ChunkData empty;
  empty.sample_rate = kFs;
  EXPECT_EQ(a.push(empty), gd::ChunkStatus::RejectedMalformed);
  gd::ChunkData bad_rate = rec.chunk(3000, 10, std::numeric_limits<double>::quiet_NaN());
  EXPECT_EQ(a.push(bad_rate), gd::ChunkStatus::RejectedMalformed);
  gd::ChunkData huge = rec.chunk(3000, 10);
  huge.first_index = std::numeric_limits<std::uint64_t>::max() - 5;
  EXPECT_EQ(a.push(huge), gd::ChunkStatus::RejectedMalformed);
  gd::ChunkData slow = rec.chunk(3000, 10, 1e-3);  // < 4 samples per 1 ms segment
  EXPECT_EQ(a.push(slow), gd::ChunkStatus::RejectedMalformed);
  EXPECT_EQ(a.counters().rejected_malformed, 4u);
  EXPECT_EQ(a.counters().rejected_nonfinite, 2u);
  EXPECT_EQ(a.counters().rejected_rate, 1u);
  EXPECT_EQ(a.counters().samples_accepted, 1000u);
}

TEST(StreamAssembler, IndexZeroAfterLaterSamplesIsARestartWithANewEpoch) {
  const Record rec(3000);
  gd::StreamAssembler a{gd::StreamOptions()};
  for (size_t b = 0; b < 2500; b += 500) a.push(rec.chunk(b, 500));
  std::string why;
  EXPECT_EQ(a.push(rec.chunk(0, 500, 2e6), &why), gd::ChunkStatus::Accepted);  // new rate ok
  EXPECT_NE(why.find("restart"), std::string::npos);
  EXPECT_EQ(a.counters().restarts, 1u);
  EXPECT_EQ(a.epoch(), 1u);
  EXPECT_EQ(a.counters().gaps, 0u);
  EXPECT_EQ(a.sampleRate(), 2e6);
  a.endOfStream();
  const auto segs = drain(&a);
  ASSERT_EQ(segs.size(), 4u);  // old epoch: 0, 1, 2 (partial); new: [0, 500)
  EXPECT_EQ(segs[2].epoch, 0u);
  EXPECT_TRUE(segs[2].partial);
  EXPECT_EQ(segs[3].epoch, 1u);
  EXPECT_EQ(range(segs[3]), Range(0, 500));
}

// Random streams (drops, duplicates, reordering, overlaps, NaN, rate changes, restarts, odd
// sizes): every emitted segment holds exactly the source samples at its global indices, lies
// within one segment of the grid, and the counters add up.
TEST(StreamAssembler, RandomAbuseNeverMixesSamplesAcrossGapsOrSegments) {
  const Record rec(20000);
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    gd::StreamOptions o;
    o.reorder_chunks = static_cast<int>(rng() % 4);
    gd::StreamAssembler a(o);
    std::uint64_t next = 0;
    std::vector<double> nan_dte(rec.dte);
    for (int op = 0; op < 300; ++op) {
      const size_t n = 1 + rng() % 700;
      const unsigned r = rng() % 100;
      std::uint64_t first = next;
      if (r < 5)
        first = 0;  // restart
      else if (r < 15)
        first = next > n ? next - n : 0;  // duplicate / overlap
      else if (r < 25)
        first = next + rng() % 2000;  // drop
      if (first + n > rec.dte.size()) first = 0;
      // A rate change is rejected, except on a restart (index 0), which would start a new grid.
      const double fs = first > 0 && r >= 25 && r < 28 ? 2e6 : kFs;
      gd::ChunkData c = rec.chunk(static_cast<size_t>(first), n, fs);
      if (r >= 28 && r < 31) {
        nan_dte[first + n / 2] = std::nan("");
        c.dte = nan_dte.data() + first;
      }
      a.push(c);
      if (r >= 28 && r < 31) nan_dte[first + n / 2] = rec.dte[first + n / 2];
      next = first + n;
      if (rng() % 50 == 0) a.endOfStream();
      gd::StreamSegment s;
      while (a.nextSegment(&s)) {
        ASSERT_LE(s.begin, s.end);
        ASSERT_LE(static_cast<size_t>(s.end), s.dte.size());
        ASSERT_EQ(s.sample_rate, kFs);
        for (size_t j = 0; j < s.dte.size(); ++j) {
          ASSERT_EQ(s.dte[j], rec.dte[s.first_index + j]) << "trial " << trial;
        }
        const std::uint64_t g0 = s.first_index + static_cast<std::uint64_t>(s.begin);
        const std::uint64_t g1 = s.first_index + static_cast<std::uint64_t>(s.end);
        ASSERT_GE(g0, static_cast<std::uint64_t>(s.segment_number) * 1000);
        ASSERT_LE(g1, static_cast<std::uint64_t>(s.segment_number + 1) * 1000);
      }
    }
    const auto& k = a.counters();
    // Every sample given to push() is accounted for exactly once (or still pending).
    size_t pending = a.hasSuspect() ? 1 : 0;  // suspects cannot occur here: jumps < 2000
    EXPECT_EQ(pending, 0u);
    a.endOfStream();
    EXPECT_EQ(k.samples_received,
              k.samples_accepted + k.samples_duplicate + k.samples_late + k.samples_rejected)
        << "trial " << trial;
    EXPECT_LE(k.samples_missing_rejected, k.samples_missing);
    EXPECT_EQ(k.chunks_received, 300u);
    EXPECT_GE(k.chunks_received, k.duplicates + k.late + k.rejected_nonfinite + k.rejected_rate +
                                     k.rejected_malformed);
  }
}

// The glitch: one chunk with a far-future first_index (1e6 and 1e15 samples ahead),
// then a pause (endOfStream): the stream continues where it was, and every later segment gets
// through. The glitch is counted (jumps, rejected_jump) and never moves the expected index.
TEST(StreamAssembler, AFarFutureGlitchChunkIsDroppedAndTheStreamContinues) {
  const Record rec(20000);
  for (const std::uint64_t jump : {std::uint64_t{1000000}, std::uint64_t{1000000000000000}}) {
    for (const bool pause : {true, false}) {
      gd::StreamAssembler a{gd::StreamOptions()};
      for (size_t b = 0; b < 5000; b += 1000) a.push(rec.chunk(b, 1000));
      gd::ChunkData glitch = rec.chunk(5000, 1000);
      glitch.first_index += jump;
      std::string why;
      EXPECT_EQ(a.push(glitch, &why), gd::ChunkStatus::Suspect);
      EXPECT_NE(why.find("implausible index jump"), std::string::npos) << why;
      if (pause) a.endOfStream();
      for (size_t b = 5000; b < 20000; b += 1000) {
        EXPECT_EQ(a.push(rec.chunk(b, 1000)), gd::ChunkStatus::Accepted) << b;
      }
      a.endOfStream();
      const auto segs = drain(&a);
      // A pause closes the run after segment 4; the stream continues at 5000 in a new run.
      ASSERT_EQ(segs.size(), 20u) << jump;
      for (size_t i = 0; i < segs.size(); ++i) {
        EXPECT_EQ(range(segs[i]), Range(1000 * i, 1000 * (i + 1))) << i;
        EXPECT_EQ(segs[i].epoch, 0u);
      }
      const auto& k = a.counters();
      EXPECT_EQ(k.jumps, 1u);
      EXPECT_EQ(k.rejected_jump, 1u);
      EXPECT_EQ(k.jump_records, 0u);
      EXPECT_EQ(k.gaps, 0u);
      EXPECT_EQ(k.late, 0u);
      EXPECT_EQ(k.samples_accepted, 20000u);
      EXPECT_EQ(k.samplesLost(), 1000u);  // the glitch chunk's own samples
    }
  }
}

// A stream that really jumped (a DAQ restarted at a non-zero count, a backwards counter reset):
// the chunk after the suspect continues it, so a new record starts there and nothing is lost.
TEST(StreamAssembler, AConfirmedJumpStartsANewRecord) {
  const Record rec(20000);
  for (const bool forward : {true, false}) {
    gd::StreamAssembler a{gd::StreamOptions()};
    const std::uint64_t first = forward ? 0 : 10000000;
    const std::uint64_t then = forward ? 10000000 : 3000000;
    std::vector<std::pair<std::uint64_t, size_t>> sent;  // stream index -> record index
    for (size_t b = 0; b < 5000; b += 1000) {
      gd::ChunkData c = rec.chunk(b, 1000);
      c.first_index = first + b;
      a.push(c);
    }
    for (size_t b = 5000; b < 10000; b += 1000) {
      gd::ChunkData c = rec.chunk(b, 1000);
      c.first_index = then + b;
      EXPECT_EQ(a.push(c), b == 5000 ? gd::ChunkStatus::Suspect : gd::ChunkStatus::Accepted);
    }
    a.endOfStream();
    const auto segs = drain(&a);
    const auto& k = a.counters();
    EXPECT_EQ(k.jumps, 1u);
    EXPECT_EQ(k.jump_records, 1u);
    EXPECT_EQ(k.rejected_jump, 0u);
    EXPECT_EQ(k.samples_accepted, 10000u);
    EXPECT_EQ(k.samplesLost(), 0u);
    EXPECT_EQ(a.epoch(), 1u);
    ASSERT_FALSE(segs.empty());
    EXPECT_EQ(segs.back().epoch, 1u);
    EXPECT_EQ(segs.back().first_index + static_cast<std::uint64_t>(segs.back().end), then + 10000);
    for (const auto& s : segs) {  // samples stay with their record
      for (size_t j = 0; j < s.dte.size(); ++j) {
        const std::uint64_t g = s.first_index + j;
        const size_t src = static_cast<size_t>(s.epoch == 0 ? g - first : g - then);
        ASSERT_EQ(s.dte[j], rec.dte[src]);
      }
    }
  }
}

// Values no gear signal can hold are rejected and counted: mesh_state other than 0/1, a DTE of
// 1e308 m (above max_abs_dte) or a torque a million times the stream's running scale. Their
// indices become a gap attributed to the rejection, not to the transport.
TEST(StreamAssembler, ImplausibleValuesAreRejectedAndTheirGapAttributed) {
  Record rec(8000);
  std::vector<double> state(8000, 1.0);
  gd::StreamAssembler a{gd::StreamOptions()};
  auto chunk = [&](size_t b) {
    gd::ChunkData c = rec.chunk(b, 1000);
    c.mesh_state = state.data() + b;
    return c;
  };
  EXPECT_EQ(a.push(chunk(0)), gd::ChunkStatus::Accepted);
  std::string why;
  state[1500] = 7.0;
  EXPECT_EQ(a.push(chunk(1000), &why), gd::ChunkStatus::RejectedValue);
  EXPECT_NE(why.find("mesh_state[500] = 7"), std::string::npos) << why;
  rec.dte[2100] = 1e308;
  EXPECT_EQ(a.push(chunk(2000), &why), gd::ChunkStatus::RejectedValue);
  EXPECT_NE(why.find("max_abs_dte"), std::string::npos) << why;
  rec.torque[3999] = 100.0 * 2e6;  // the running scale is 100 N*m; the factor 1e6
  EXPECT_EQ(a.push(chunk(3000), &why), gd::ChunkStatus::RejectedValue);
  EXPECT_NE(why.find("torque"), std::string::npos) << why;
  rec.torque[4999] = 100.0 * 0.5e6;  // within the factor: a plausible (if large) value
  for (size_t b = 4000; b < 8000; b += 1000)
    EXPECT_NE(a.push(chunk(b)), gd::ChunkStatus::RejectedValue);
  a.endOfStream();
  const auto& k = a.counters();
  EXPECT_EQ(k.rejected_value, 3u);
  EXPECT_EQ(k.samples_rejected, 3000u);
  EXPECT_EQ(k.gaps, 1u);
  EXPECT_EQ(k.samples_missing, 3000u);
  EXPECT_EQ(k.samples_missing_rejected, 3000u);
  EXPECT_EQ(k.samplesNeverArrived(), 0u);
}

// A dropped chunk that never arrives (a subscriber-queue overflow) is inferred from the indices:
// a gap whose samples no chunk brought.
TEST(StreamAssembler, QueueOverflowShowsAsSamplesThatNeverArrived) {
  const Record rec(10000);
  gd::StreamAssembler a{gd::StreamOptions()};
  for (size_t b = 0; b < 10000; b += 1000) {
    if (b != 3000 && b != 4000) a.push(rec.chunk(b, 1000));
  }
  a.endOfStream();
  const auto& k = a.counters();
  EXPECT_EQ(k.samples_missing, 2000u);
  EXPECT_EQ(k.samplesNeverArrived(), 2000u);
  EXPECT_EQ(k.samplesLost(), 2000u);
  EXPECT_EQ(k.samples_received, 8000u);
}

// The diagnostics' health: one loss is WARN for LossMonitor::kHold seconds, a loss in each of
// kSustained reports in a row is ERROR, an implausible jump keeps WARN until reset(), a clean
// stream is OK.
TEST(LossMonitor, OneLossWarnsSustainedLossIsAnErrorAJumpWarnsUntilReset) {
  using L = gd::LossMonitor::Level;
  gd::LossMonitor m;
  gd::StreamCounters k;
  k.samples_accepted = 1000;
  EXPECT_EQ(m.update(k, 0.0).level, L::Ok);
  k.samples_missing = 1000;  // a gap
  EXPECT_EQ(m.update(k, 1.0).level, L::Warn);
  EXPECT_EQ(m.update(k, 2.0).level, L::Warn);  // held
  EXPECT_EQ(m.update(k, 1.0 + gd::LossMonitor::kHold + 0.1).level, L::Ok);
  double t = 20.0;
  for (int i = 0; i < gd::LossMonitor::kSustained; ++i) {
    k.samples_late += 10;
    const auto r = m.update(k, t += 1.0);
    EXPECT_EQ(r.level, i + 1 < gd::LossMonitor::kSustained ? L::Warn : L::Error) << i;
    if (r.level == L::Error) {
      EXPECT_NE(r.message.find("sustained"), std::string::npos);
    }
  }
  EXPECT_EQ(m.update(k, t += 1.0).level, L::Warn);  // the loss stopped: WARN while held
  k.jumps = 1;
  const auto jump = m.update(k, t += 100.0, "chunk at index 1000000000000000");
  EXPECT_EQ(jump.level, L::Warn);
  EXPECT_NE(jump.message.find("1000000000000000"), std::string::npos) << jump.message;
  EXPECT_EQ(m.update(k, t += 1000.0).level, L::Warn);  // persistent
  m.reset();
  gd::StreamCounters clean;
  EXPECT_EQ(m.update(clean, t += 1.0).level, L::Ok);
}

TEST(StreamAssembler, InvalidOptionsNameTheField) {
  gd::StreamOptions o;
  o.segment_length = -1.0;
  EXPECT_NE(o.check().message().find("segment_length = -1"), std::string::npos);
  o = gd::StreamOptions();
  o.reorder_chunks = -3;
  EXPECT_NE(o.check().message().find("reorder_chunks"), std::string::npos);
  o = gd::StreamOptions();
  o.max_jump = 0.0;
  EXPECT_NE(o.check().message().find("max_jump = 0"), std::string::npos);
  o = gd::StreamOptions();
  o.magnitude_factor = 2.0;
  EXPECT_NE(o.check().message().find("magnitude_factor = 2"), std::string::npos);
  o = gd::StreamOptions();
  o.max_abs_dte = -1.0;
  EXPECT_NE(o.check().message().find("max_abs_dte"), std::string::npos);
  EXPECT_EQ(gd::StreamOptions().check().message(), "");
}

// The live path (chunks -> assembler -> LiveIdentification) equals identify() on the
// same record with the same options (integral method only) on the default simulated case.
TEST(StreamAssembler, LiveIdentificationEqualsOfflineOnTheDefaultCase) {
  gear_sim::SimConfig cfg;
  std::string e;
  ASSERT_TRUE(gear_test::ok(
      gear_sim::loadSimConfigFile(std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml", &cfg), &e))
      << e;
  gear_sim::SignalTable t;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(cfg, &t), &e)) << e;
  const gd::GearConstants gear = gd::gearConstants(cfg.gearModel());
  gd::IdentificationOptions io;
  io.refine = gd::IdentificationOptions::Refine::Never;
  gd::IdentificationResult offline;
  ASSERT_TRUE(gear_test::ok(gd::identify(t, gear, io, &offline), &e)) << e;

  gd::StreamAssembler a{gd::StreamOptions()};
  gd::LiveIdentification live(io, gear);  // window resolved from the first segment, as the node
  std::vector<gd::SegmentEstimate> est;
  std::vector<double> state(static_cast<size_t>(t.size()));
  for (Eigen::Index i = 0; i < t.size(); ++i) state[static_cast<size_t>(i)] = t.mesh_state[i];
  auto run = [&] {
    gd::StreamSegment s;
    while (a.nextSegment(&s)) est.push_back(live.add(s.view(), s.begin, s.end).estimate);
  };
  for (Eigen::Index b = 0; b < t.size(); b += 1000) {
    gd::ChunkData c;
    c.first_index = static_cast<std::uint64_t>(b);
    c.sample_rate = cfg.simulation.sample_rate;
    c.n = 1000;
    c.dte = t.dte.data() + b;
    c.stiffness = t.stiffness.data() + b;
    c.torque = t.torque.data() + b;
    c.mesh_state = state.data() + b;
    c.mesh_phase = t.mesh_phase.data() + b;
    a.push(c);
    run();
  }
  a.endOfStream();
  run();
  ASSERT_EQ(est.size(), offline.segments.size());
  for (size_t i = 0; i < est.size(); ++i) {
    ASSERT_TRUE(est[i].identifiable) << est[i].reason;
    EXPECT_NEAR(est[i].C, offline.segments[i].C,
                kLiveVsOfflineRelTol * std::abs(offline.segments[i].C))
        << i;
    EXPECT_NEAR(est[i].t_start, offline.segments[i].t_start, 1e-12);
    EXPECT_NEAR(est[i].t_end, offline.segments[i].t_end, 1e-12);
  }
}

}  // namespace
