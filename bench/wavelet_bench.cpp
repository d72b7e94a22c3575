// Google Benchmark suite of the Morlet CWT (docs/method.md §7): throughput in (samples x scales)/s
// of gear_damping_id::MorletCwt, and the FFTW lower bound it is measured against (one inverse
// complex FFT of the same padded length per scale, same planner flags), of the grouped and
// threaded MorletScalogram (BM_Scalogram/n/threads, BM_ScalogramSingle in float) and of the
// per-mode damping without a scalogram (BM_ModeDamping). Nothing is asserted; bench/compare_peers
// runs this binary beside fCWT and PyWavelets and prints the ratios.
//
// Set-up (outside the timed region): the signal, MorletCwt::configure (FFTW plans, aligned
// buffers, first touch of every buffer) and one warm-up transform. The timed region of BM_Cwt
// is one complete transform of a signal: setSignal (mean removal, zero padding, one r2c FFT)
// and, for each of the 200 rows, the band-limited multiplication by the Morlet spectrum, the
// inverse FFT and |W| written into a reused row buffer of n doubles. (The full 200 x n modulus
// would not fit in memory at n = 1e6 as doubles, 1.6 GB; a caller keeping it writes each row
// where it wants instead, at the same cost.) No allocation happens inside the timed region.
//
// Grid: 200 log-spaced frequencies from 10 cycles per record to 0.4 * fs, omega0 = 6 (the
// defaults of analyzeWavelet), so the record is zero-padded by 8 scales of the lowest row to
// the next 2^a 3^b 5^c 7^d length (n = 1e5: N = 176400; n = 1e6: N = 1764000).
//
// Arguments: the usual --benchmark_* flags; --estimate plans with FFTW_ESTIMATE instead of
// FFTW_MEASURE (both the CWT and the bound). FFTW_MEASURE planning is capped at 5 s per plan
// (as in MorletCwt) and happens outside the timed region; the bound and the CWT of one size
// share FFTW's wisdom within the process, so whichever runs second reuses the first's plan
// search. --wisdom FILE imports FFTW's wisdom from FILE when it exists and exports it there at
// the end, so repeated runs (bench/compare_peers' rounds) plan once: a first FFTW_MEASURE run of
// a scalogram plans ~130 batch sizes and the groups' lengths, up to minutes at 1e6 samples.
#include <benchmark/benchmark.h>
#include <fftw3.h>
#include <sys/resource.h>

#include <cmath>
#include <complex>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "../test/unit/support/status_support.hpp"
#include "gear_damping_id/wavelet.hpp"

namespace {

using gear_damping_id::FftPlanning;
using gear_damping_id::MorletCwt;

constexpr int kScales = 200;
constexpr double kOmega0 = 6.0;
constexpr double kSampleRate = 1.0;  // frequencies are relative to fs; throughput does not care
FftPlanning g_planning = FftPlanning::Measure;

// User + system CPU time of the whole process (all threads) [s].
double processCpuSeconds() {
  rusage r{};
  getrusage(RUSAGE_SELF, &r);
  return static_cast<double>(r.ru_utime.tv_sec + r.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(r.ru_utime.tv_usec + r.ru_stime.tv_usec);
}

std::vector<double> gridFor(long n) {
  return gear_damping_id::logSpacedFrequencies(10.0 * kSampleRate / static_cast<double>(n),
                                               0.4 * kSampleRate, kScales);
}

// A free-decay-like test signal: three damped modes plus white noise (the CWT's cost does not
// depend on the data; this only keeps the numbers finite and realistic).
std::vector<double> signalOf(long n) {
  std::vector<double> y(static_cast<size_t>(n));
  std::mt19937_64 rng(1);
  std::normal_distribution<double> noise(0.0, 0.01);
  for (long j = 0; j < n; ++j) {
    const double t = static_cast<double>(j);
    y[static_cast<size_t>(j)] = std::exp(-2e-5 * t) * std::cos(0.05 * t) +
                                0.5 * std::exp(-5e-5 * t) * std::cos(0.3 * t) +
                                0.3 * std::exp(-1e-4 * t) * std::cos(1.2 * t) + noise(rng);
  }
  return y;
}

void BM_Cwt(benchmark::State& state) {
  const long n = state.range(0);
  const std::vector<double> y = signalOf(n);
  MorletCwt cwt;
  std::string error;
  if (!gear_test::ok(cwt.configure(n, kSampleRate, gridFor(n), kOmega0, g_planning), &error)) {
    state.SkipWithError(error.c_str());
    return;
  }
  std::vector<double> row(static_cast<size_t>(n), 0.0);
  auto once = [&]() {
    if (!gear_test::ok(cwt.setSignal(y.data()), &error)) return false;
    for (int i = 0; i < cwt.rows(); ++i) {
      if (!cwt.rowModulus(i, row.data())) return false;
    }
    return true;
  };
  if (!once()) {  // warm-up: plans the inverse FFT, touches every page
    state.SkipWithError("MorletCwt failed");
    return;
  }
  for (auto _ : state) {
    once();
    benchmark::DoNotOptimize(row.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(n) * kScales);
  state.counters["padded_length"] = static_cast<double>(cwt.paddedSize());
  state.counters["scales"] = kScales;
  state.SetLabel(g_planning == FftPlanning::Measure ? "FFTW_MEASURE" : "FFTW_ESTIMATE");
}

// The FFT lower bound: 200 inverse complex FFTs of the padded length N of BM_Cwt, out of place,
// planned with the same flags (a CWT row cannot cost less than its inverse FFT).
void BM_FftBound(benchmark::State& state) {
  const long n = state.range(0);
  MorletCwt probe;  // only to get the same padded length
  std::string error;
  if (!gear_test::ok(probe.configure(n, kSampleRate, gridFor(n), kOmega0, FftPlanning::Estimate),
                     &error)) {
    state.SkipWithError(error.c_str());
    return;
  }
  const long N = probe.paddedSize();
  fftw_complex* in = fftw_alloc_complex(static_cast<size_t>(N));
  fftw_complex* out = fftw_alloc_complex(static_cast<size_t>(N));
  // Same flags as MorletCwt, including its 5 s cap on FFTW_MEASURE planning.
  const unsigned flags = g_planning == FftPlanning::Measure ? FFTW_MEASURE : FFTW_ESTIMATE;
  fftw_set_timelimit(g_planning == FftPlanning::Measure ? 5.0 : FFTW_NO_TIMELIMIT);
  fftw_plan plan = fftw_plan_dft_1d(static_cast<int>(N), in, out, FFTW_BACKWARD, flags);
  std::memset(in, 0, sizeof(fftw_complex) * static_cast<size_t>(N));
  std::memset(out, 0, sizeof(fftw_complex) * static_cast<size_t>(N));
  for (long k = 0; k < N; k += 7) in[k][0] = 1.0;
  fftw_execute(plan);  // warm-up
  for (auto _ : state) {
    for (int i = 0; i < kScales; ++i) fftw_execute(plan);
    benchmark::DoNotOptimize(out);
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(n) * kScales);
  state.counters["padded_length"] = static_cast<double>(N);
  state.counters["scales"] = kScales;
  state.SetLabel(g_planning == FftPlanning::Measure ? "FFTW_MEASURE" : "FFTW_ESTIMATE");
  fftw_destroy_plan(plan);
  fftw_free(in);
  fftw_free(out);
}

// The full scalogram as analyzeWavelet computes it: MorletScalogram (padding per group of rows,
// rows on state.range(1) threads), |W| of each row into a per-thread buffer.
void scalogram(benchmark::State& state, gear_damping_id::Precision precision) {
  const long n = state.range(0);
  const int threads = static_cast<int>(state.range(1));
  const std::vector<double> y = signalOf(n);
  gear_damping_id::MorletScalogram scal;
  std::string error;
  if (!gear_test::ok(
          scal.configure(n, kSampleRate, gridFor(n), kOmega0, g_planning, threads, precision),
          &error)) {
    state.SkipWithError(error.c_str());
    return;
  }
  auto once = [&]() {
    return gear_test::ok(scal.forEachRow(y.data(), [](int, const double*) {}), &error);
  };
  if (!once()) {
    state.SkipWithError(error.c_str());
    return;
  }
  const double cpu0 = processCpuSeconds();
  for (auto _ : state) {
    once();
    benchmark::ClobberMemory();
  }
  // CPU time of every thread of the process per transform (Google Benchmark's cpu_time counts
  // the main thread only): the measure on a shared machine.
  state.counters["process_cpu_ms"] =
      1e3 * (processCpuSeconds() - cpu0) / static_cast<double>(state.iterations());
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(n) * kScales);
  state.counters["groups"] = scal.groups();
  state.counters["threads"] = threads;
  state.SetLabel(g_planning == FftPlanning::Measure ? "FFTW_MEASURE" : "FFTW_ESTIMATE");
}

void BM_Scalogram(benchmark::State& state) { scalogram(state, gear_damping_id::Precision::Double); }
// Same in single precision (Precision::Single: the rows' inverse FFTs in float, like fCWT).
void BM_ScalogramSingle(benchmark::State& state) {
  scalogram(state, gear_damping_id::Precision::Single);
}

// Per-mode damping without a scalogram (full_scalogram = false: only the rows the fits need)
// on 1e6 samples of three decaying modes, default options otherwise, on state.range(1) threads
// (WaveletOptions::threads; wall time, and the process's CPU time per analysis in
// process_cpu_ms); analyze(y, n, o, &r) is one analysis. With warm_up, one untimed call first
// (like BM_Cwt's). planning: WaveletOptions::fft_planning.
template <typename Analyze>
void modeDamping(benchmark::State& state, Analyze analyze, bool warm_up,
                 FftPlanning planning = FftPlanning::Estimate) {
  const long n = state.range(0);
  const std::vector<double> y = signalOf(n);
  gear_damping_id::WaveletOptions o;
  o.full_scalogram = false;
  o.threads = static_cast<int>(state.range(1));
  o.fft_planning = planning;
  state.SetLabel(planning == FftPlanning::Measure ? "FFTW_MEASURE" : "FFTW_ESTIMATE");
  gear_damping_id::WaveletResult r;
  std::string error;
  if (warm_up && !gear_test::ok(analyze(y.data(), n, o, &r), &error)) {
    state.SkipWithError(error.c_str());
    return;
  }
  const double cpu0 = processCpuSeconds();
  for (auto _ : state) {
    if (!gear_test::ok(analyze(y.data(), n, o, &r), &error)) {
      state.SkipWithError(error.c_str());
      return;
    }
    benchmark::DoNotOptimize(r.modes.data());
  }
  state.counters["modes"] = static_cast<double>(r.modes.size());
  state.counters["threads"] = static_cast<double>(o.threads);
  state.counters["process_cpu_ms"] =
      1e3 * (processCpuSeconds() - cpu0) / static_cast<double>(state.iterations());
}

// A fresh analyzeWavelet per call: FFTW planning and fresh buffers every time.
void BM_ModeDamping(benchmark::State& state) {
  modeDamping(
      state,
      [](const double* y, long n, const gear_damping_id::WaveletOptions& o,
         gear_damping_id::WaveletResult* r) {
        return gear_damping_id::analyzeWavelet(y, n, kSampleRate, o, r);
      },
      false);
}

// One WaveletAnalyzer and one result reused across iterations (a node analysing record after
// record): FFTW plans, FFT buffers and scratch vectors are kept, so no iteration re-plans or
// faults in fresh pages. Results are bit-identical to BM_ModeDamping's. state.range(2) = 1:
// the per-mode path's transforms planned by FFTW_MEASURE (g_planning; the untimed first call
// plans them, or FFTW's wisdom from --wisdom serves), 0: by FFTW_ESTIMATE (the default).
void BM_ModeDampingReused(benchmark::State& state) {
  gear_damping_id::WaveletAnalyzer analyzer;
  modeDamping(
      state,
      [&analyzer](const double* y, long n, const gear_damping_id::WaveletOptions& o,
                  gear_damping_id::WaveletResult* r) {
        return analyzer.analyze(y, n, kSampleRate, o, r);
      },
      true, state.range(2) == 1 ? g_planning : FftPlanning::Estimate);
}

BENCHMARK(BM_Cwt)->Arg(100000)->Arg(1000000)->Unit(benchmark::kMillisecond)->UseRealTime();
// Cases of the scalograms: n in {1e5, 1e6} x threads in {1, 2}.
void scalogramCases(benchmark::internal::Benchmark* b) {
  for (const long n : {100000L, 1000000L}) {
    for (const long threads : {1L, 2L}) b->Args({n, threads});
  }
  b->Unit(benchmark::kMillisecond)->UseRealTime();
}
BENCHMARK(BM_Scalogram)->Apply(scalogramCases);
BENCHMARK(BM_ScalogramSingle)->Apply(scalogramCases);
BENCHMARK(BM_ModeDamping)->Args({1000000, 1})->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ModeDampingReused)
    ->Args({1000000, 1, 0})
    ->Args({1000000, 2, 0})
    ->Args({1000000, 1, 1})
    ->Args({1000000, 2, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_FftBound)->Arg(100000)->Arg(1000000)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

int main(int argc, char** argv) {
  std::vector<char*> args;
  std::string wisdom;
  for (int i = 0; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--estimate") {
      g_planning = FftPlanning::Estimate;
    } else if (a.rfind("--wisdom=", 0) == 0) {
      wisdom = a.substr(9);
    } else {
      args.push_back(argv[i]);
    }
  }
  // Double-precision wisdom in FILE, single-precision (BM_ScalogramSingle) in FILE.f; absent
  // files: plan anew.
  const std::string wisdom_f = wisdom + ".f";
  if (!wisdom.empty()) {
    fftw_import_wisdom_from_filename(wisdom.c_str());
    fftwf_import_wisdom_from_filename(wisdom_f.c_str());
  }
  int n = static_cast<int>(args.size());
  benchmark::Initialize(&n, args.data());
  if (benchmark::ReportUnrecognizedArguments(n, args.data())) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  if (!wisdom.empty() && (!fftw_export_wisdom_to_filename(wisdom.c_str()) ||
                          !fftwf_export_wisdom_to_filename(wisdom_f.c_str()))) {
    std::fprintf(stderr, "bench_wavelet: cannot write wisdom to %s\n", wisdom.c_str());
  }
  return 0;
}
