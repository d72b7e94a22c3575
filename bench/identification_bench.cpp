// Identification throughput (issue 4 bar: >= 100 M samples/s single-threaded for the `known`
// piecewise integral method without refinement; reported here, not asserted).
//
// Data: the docs/method.md §3 default case (Table 1, sine load, load-dependent damping, 1 MHz)
// simulated once for N samples with white noise at 40 dB SNR (the integral method's cost does not
// depend on the noise; the refinement's iteration count does, and noisy data is what it is for), 1
// ms segments, automatic window. Simulation is outside the timed region.
//
// Allocation: the `identify()` benchmarks time the whole convenience call, so the allocation of
// the IntegralMethod's scratch rows, its per-segment records and the result are INSIDE the timed
// region (first touch of fresh pages included). BM_StreamKnownPiecewiseReused times the streaming
// API on one IntegralMethod reused across iterations (reset(), then addSegment per segment and
// finish()): its scratch is allocated before the timed loop, only the per-segment records and
// the result are allocated inside (small, and recycled by the allocator).
#include <benchmark/benchmark.h>

#include <map>
#include <stdexcept>
#include <string>

#include "../test/unit/support/status_support.hpp"
#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_sim/simulator.hpp"

namespace {

using gear_damping_id::DampingModel;
using gear_damping_id::Formulation;
using gear_damping_id::IdentificationOptions;

struct Data {
  gear_sim::SimConfig config;
  gear_sim::SignalTable table;
  gear_damping_id::GearConstants gear;
};

// One simulated record per length, made on first use (outside any timed region).
const Data& data(long n) {
  static std::map<long, Data> cache;
  auto it = cache.find(n);
  if (it != cache.end()) return it->second;
  Data d;
  d.config.simulation.sample_rate = 1e6;
  d.config.simulation.duration = static_cast<double>(n) / 1e6;
  d.config.simulation.noise_snr_db = 40.0;
  std::string e;
  if (!gear_test::ok(gear_sim::simulate(d.config, &d.table), &e)) throw std::runtime_error(e);
  d.gear = gear_damping_id::gearConstants(d.config.gearModel());
  return cache.emplace(n, std::move(d)).first->second;
}

void setRate(benchmark::State& state, long n) {
  state.SetItemsProcessed(state.iterations() * n);
  state.counters["samples/s"] =
      benchmark::Counter(static_cast<double>(state.iterations() * n), benchmark::Counter::kIsRate);
}

void runIdentify(benchmark::State& state, Formulation f, DampingModel m,
                 IdentificationOptions::Refine refine, int threads = 1) {
  const long n = state.range(0);
  const Data& d = data(n);
  IdentificationOptions o;
  o.formulation = f;
  o.model = m;
  o.refine = refine;
  gear_damping_id::IdentificationResult r;
  std::string e;
  for (auto _ : state) {
    if (!gear_test::ok(gear_damping_id::identify(d.table, d.gear, o, &r, threads), &e)) {
      state.SkipWithError(e.c_str());
      break;
    }
    benchmark::DoNotOptimize(r.segments.data());
  }
  setRate(state, n);
  state.counters["segments"] = static_cast<double>(r.segments.size());
  if (r.iterations > 0) state.counters["gn_iterations"] = r.iterations;
}

void BM_IdentifyKnownPiecewiseIntegral(benchmark::State& s) {
  runIdentify(s, Formulation::Known, DampingModel::Piecewise, IdentificationOptions::Refine::Never);
}
void BM_IdentifyGreyboxPiecewiseIntegral(benchmark::State& s) {
  runIdentify(s, Formulation::Greybox, DampingModel::Piecewise,
              IdentificationOptions::Refine::Never);
}
void BM_IdentifyKnownLoadLawIntegral(benchmark::State& s) {
  runIdentify(s, Formulation::Known, DampingModel::LoadLaw, IdentificationOptions::Refine::Never);
}
void BM_IdentifyKnownConstantIntegral(benchmark::State& s) {
  runIdentify(s, Formulation::Known, DampingModel::Constant, IdentificationOptions::Refine::Never);
}
void BM_IdentifyKnownPiecewiseRefined(benchmark::State& s) {
  runIdentify(s, Formulation::Known, DampingModel::Piecewise,
              IdentificationOptions::Refine::Always);
}
void BM_IdentifyGreyboxPiecewiseRefined(benchmark::State& s) {
  runIdentify(s, Formulation::Greybox, DampingModel::Piecewise,
              IdentificationOptions::Refine::Always);
}
void BM_IdentifyKnownLoadLawRefined(benchmark::State& s) {
  runIdentify(s, Formulation::Known, DampingModel::LoadLaw, IdentificationOptions::Refine::Always);
}

// identify() with segments on range(1) threads (SegmentDriver; results equal to one thread's).
void BM_IdentifyKnownPiecewiseIntegralThreads(benchmark::State& s) {
  runIdentify(s, Formulation::Known, DampingModel::Piecewise, IdentificationOptions::Refine::Never,
              static_cast<int>(s.range(1)));
}
void BM_IdentifyKnownPiecewiseRefinedThreads(benchmark::State& s) {
  runIdentify(s, Formulation::Known, DampingModel::Piecewise, IdentificationOptions::Refine::Always,
              static_cast<int>(s.range(1)));
}

// The streaming API as a node uses it, one IntegralMethod reused (see the file comment).
void BM_StreamKnownPiecewiseReused(benchmark::State& state) {
  const long n = state.range(0);
  const Data& d = data(n);
  const auto view = gear_damping_id::SignalView::of(d.table);
  IdentificationOptions o;
  o.refine = IdentificationOptions::Refine::Never;
  o.window_length = gear_damping_id::defaultWindowLength(view, d.gear);
  const auto ranges = gear_damping_id::segmentRanges(view, o);
  gear_damping_id::IntegralMethod m(o, d.gear);
  for (const auto& r : ranges) m.addSegment(view, r.first, r.second);  // warm-up: scratch
  for (auto _ : state) {
    m.reset();
    for (const auto& r : ranges) m.addSegment(view, r.first, r.second);
    const auto res = m.finish();
    benchmark::DoNotOptimize(res.segments.data());
  }
  setRate(state, n);
}

}  // namespace

BENCHMARK(BM_IdentifyKnownPiecewiseIntegral)
    ->Arg(10000)
    ->Arg(100000)
    ->Arg(1000000)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_StreamKnownPiecewiseReused)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_IdentifyGreyboxPiecewiseIntegral)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_IdentifyKnownLoadLawIntegral)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_IdentifyKnownConstantIntegral)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_IdentifyKnownPiecewiseRefined)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_IdentifyGreyboxPiecewiseRefined)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_IdentifyKnownLoadLawRefined)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_IdentifyKnownPiecewiseIntegralThreads)
    ->Args({1000000, 1})
    ->Args({1000000, 2})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_IdentifyKnownPiecewiseRefinedThreads)
    ->Args({1000000, 1})
    ->Args({1000000, 2})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
