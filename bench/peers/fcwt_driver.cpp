// Timing driver for the fCWT peer of bench/compare_peers (compiled in a temp dir against an
// fCWT source tree given by option; never part of the package). Usage:
//   fcwt_driver N THREADS REPEATS WISDOM(0|1)
// Morlet (bandwidth 2 ~ omega0 = 2*pi*... as in fCWT's own benchmarks), 200 log-spaced
// frequencies from 10 cycles per record to 0.4 fs (fs = 1), float input, complex<float> output.
// Prints one line of JSON: {"times": [seconds per transform, ...]}.
#include <chrono>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "fcwt.h"

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
  if (wisdom) fcwt.create_FFT_optimization_plan(n, "FFTW_MEASURE");
  std::vector<std::complex<float>> out(size_t(n) * 200);
  fcwt.cwt(y.data(), n, out.data(), &scs);  // warm-up
  std::printf("{\"times\": [");
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    fcwt.cwt(y.data(), n, out.data(), &scs);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("%s%.6f", r ? ", " : "", s);
  }
  std::printf("]}\n");
  return 0;
}
