// Timing driver for the fCWT peer of bench/compare_peers (compiled in a temp dir against an
// fCWT source tree given by option; never part of the package). Usage:
//   fcwt_driver N THREADS REPEATS WISDOM(0|1)
// With WISDOM = 1, fCWT's FFTW_MEASURE wisdom files (n<2^k>_t<THREADS>.wis, in the working
// directory) are created only when the one for this size is missing, so a cache directory kept
// between runs plans once (planning every power of 2 up to 2^20 takes minutes).
// Morlet (bandwidth 2 ~ omega0 = 2*pi*... as in fCWT's own benchmarks), 200 log-spaced
// frequencies from 10 cycles per record to 0.4 fs (fs = 1), float input, complex<float> output.
// Prints one line of JSON: {"times": [wall seconds per transform, ...], "cpu": [CPU seconds of
// the process (all threads), ...]}.
#include <sys/resource.h>

#include <chrono>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "fcwt.h"

// User + system CPU time of the whole process (all threads) [s].
static double processCpuSeconds() {
  rusage r{};
  getrusage(RUSAGE_SELF, &r);
  return static_cast<double>(r.ru_utime.tv_sec + r.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(r.ru_utime.tv_usec + r.ru_stime.tv_usec);
}

int main(int argc, char** argv) {
  if (argc != 5) return 2;
  const int n = std::atoi(argv[1]), threads = std::atoi(argv[2]), repeats = std::atoi(argv[3]);
  const bool wisdom = std::atoi(argv[4]) != 0;
  const int fs = 1000000;  // fCWT takes an integer rate; frequencies scale with it
  std::vector<float> y(static_cast<size_t>(n));
  for (int j = 0; j < n; ++j) {
    const double t = j;
    y[size_t(j)] = static_cast<float>(std::exp(-2e-5 * t) * std::cos(0.05 * t) +
                                      0.5 * std::exp(-5e-5 * t) * std::cos(0.3 * t));
  }
  Morlet morl(2.0f);
  Scales scs(&morl, FCWT_LOGSCALES, fs, 10.0f * fs / n, 0.4f * fs, 200);  // same range
  FCWT fcwt(&morl, threads, wisdom, false);
  int pow2 = 1;
  while (pow2 < n) pow2 *= 2;  // fCWT's transform length (find2power)
  const std::string wisdom_file =
      "n" + std::to_string(pow2) + "_t" + std::to_string(threads) + ".wis";
  if (wisdom && !std::ifstream(wisdom_file).good()) {
    fcwt.create_FFT_optimization_plan(n, "FFTW_MEASURE");
  }
  std::vector<std::complex<float>> out(size_t(n) * 200);
  fcwt.cwt(y.data(), n, out.data(), &scs);  // warm-up
  std::vector<double> wall, cpu;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = processCpuSeconds();
    fcwt.cwt(y.data(), n, out.data(), &scs);
    cpu.push_back(processCpuSeconds() - c0);
    wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  std::printf("{\"times\": [");
  for (size_t r = 0; r < wall.size(); ++r) std::printf("%s%.6f", r ? ", " : "", wall[r]);
  std::printf("], \"cpu\": [");
  for (size_t r = 0; r < cpu.size(); ++r) std::printf("%s%.6f", r ? ", " : "", cpu[r]);
  std::printf("]}\n");
  return 0;
}
