#!/usr/bin/env python3
"""Morlet CWT throughput: gear_damping's FFTW CWT (bench_wavelet) beside PyWavelets' pywt.cwt.

Runs, in one invocation on the same machine:
  * the Google Benchmark binary bench_wavelet (BM_Cwt and BM_FftBound at 1e5 and 1e6 samples
    x 200 scales, see bench/wavelet_bench.cpp for what is timed), and
  * pywt.cwt(method='fft') with the complex Morlet 'cmor1.8-1.0' (Gaussian of the same width
    as the analytic Morlet with omega0 = 2*pi*1.0*sqrt(1.8/2) = 5.96 ~ 6 used by bench_wavelet),
    on the same signal length, the same 200 log-spaced frequencies (10 cycles per record to
    0.4*fs) and double precision,
then prints both throughputs in (samples x scales)/s, the ratio, and the DESIGN.md §7 bars:
CWT within 1.5x of the FFTW bound and >= 10x faster than PyWavelets.

1e6 samples x 200 scales would need a 3.2 GB complex128 output from pywt: by default it is run
on every 10th of the 200 scales (20 scales spanning the same log range, so the long wavelets of
the low frequencies are represented in proportion) and its throughput per (sample x scale) is
reported as measured on that subset; this extrapolation is printed as such. --pywt-full-1e6
runs all 200 scales (needs ~4 GB of memory).

Usage: bench/compare_cwt.py [--bench PATH/TO/bench_wavelet] [--repeats N] [--estimate]
Requires python3 with numpy and pywt (Debian: python3-numpy python3-pywt).
"""
import argparse
import glob
import json
import os
import subprocess
import sys
import time

import numpy as np
import pywt

SCALES = 200
SIZES = (100_000, 1_000_000)
WAVELET = "cmor1.8-1.0"  # bandwidth B = 1.8, centre frequency 1.0 cycle per unit scale


def find_bench(explicit):
    """--bench, else bench_wavelet of a catkin workspace built from this checkout: $GEAR_DAMPING_WS,
    ../gear_damping_ws (scripts/common.sh's default) or /work/ws*; a workspace whose
    src/gear_damping links to this checkout is preferred over one built from another tree."""
    if explicit:
        return explicit
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    workspaces = []
    if os.environ.get("GEAR_DAMPING_WS"):
        workspaces.append(os.environ["GEAR_DAMPING_WS"])
    workspaces.append(os.path.join(os.path.dirname(repo), "gear_damping_ws"))
    workspaces += sorted(glob.glob("/work/ws*"))
    found = [w for w in workspaces
             if os.access(os.path.join(w, "devel/lib/gear_damping/bench_wavelet"), os.X_OK)]
    if not found:
        sys.exit("compare_cwt.py: bench_wavelet not found; build the package (gear_build) or pass --bench PATH")
    ours = [w for w in found
            if os.path.realpath(os.path.join(w, "src/gear_damping")) == os.path.realpath(repo)]
    ws = (ours or found)[0]
    if not ours:
        print(f"warning: {ws} was not built from {repo}", file=sys.stderr)
    return os.path.join(ws, "devel/lib/gear_damping/bench_wavelet")


def run_bench(path, estimate, repeats):
    cmd = [path, "--benchmark_format=json", f"--benchmark_repetitions={repeats}",
           "--benchmark_report_aggregates_only=true" if repeats > 1 else "--benchmark_min_time=0.5"]
    if estimate:
        cmd.append("--estimate")
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    data = json.loads(out)
    res = {}
    for b in data["benchmarks"]:
        if repeats > 1 and b.get("aggregate_name") != "median":
            continue
        name = b["run_name"] if "run_name" in b else b["name"]
        kind, n = name.split("/")[0], int(name.split("/")[1])
        res[(kind, n)] = (b["items_per_second"], b["real_time"], b["time_unit"])
    return res


def signal(n):
    t = np.arange(n, dtype=np.float64)
    rng = np.random.default_rng(1)
    return (np.exp(-2e-5 * t) * np.cos(0.05 * t) + 0.5 * np.exp(-5e-5 * t) * np.cos(0.3 * t)
            + 0.3 * np.exp(-1e-4 * t) * np.cos(1.2 * t) + rng.normal(0.0, 0.01, n))


def pywt_throughput(n, subset_step, repeats):
    freqs = np.geomspace(10.0 / n, 0.4, SCALES)[::subset_step]  # cycles per sample
    scales = pywt.central_frequency(WAVELET) / freqs
    y = signal(n)
    pywt.cwt(y[:4096], scales[:2], WAVELET, method="fft")  # warm-up (imports, caches)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        coef, _ = pywt.cwt(y, scales, WAVELET, method="fft")
        best = min(best, time.perf_counter() - t0)
        del coef
    return n * len(scales) / best, best, len(scales)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bench", help="path to bench_wavelet (default: searched in the workspace)")
    ap.add_argument("--repeats", type=int, default=3, help="repetitions (median for C++, best for pywt)")
    ap.add_argument("--estimate", action="store_true", help="FFTW_ESTIMATE plans instead of FFTW_MEASURE")
    ap.add_argument("--pywt-full-1e6", action="store_true", help="all 200 scales for pywt at 1e6 (~4 GB)")
    args = ap.parse_args()

    bench = find_bench(args.bench)
    print(f"bench_wavelet: {bench}")
    print(f"pywt {pywt.__version__}, numpy {np.__version__}, wavelet {WAVELET}, method='fft', float64")
    ours = run_bench(bench, args.estimate, args.repeats)

    ok = True
    print(f"\n{'samples':>9} {'ours [M(s*sc)/s]':>17} {'FFT bound':>10} {'CWT/bound time':>15} "
          f"{'pywt [M(s*sc)/s]':>17} {'ours/pywt':>10}  note")
    for n in SIZES:
        cwt = ours.get(("BM_Cwt", n))
        fft = ours.get(("BM_FftBound", n))
        if not cwt or not fft:
            print(f"{n:>9}  bench_wavelet did not report BM_Cwt/BM_FftBound for this size")
            ok = False
            continue
        step = 1 if (n < 1_000_000 or args.pywt_full_1e6) else 10
        py, secs, used = pywt_throughput(n, step, 1 if n >= 1_000_000 else args.repeats)
        note = (f"pywt: {used} scales in {secs:.2f} s" +
                ("" if step == 1 else f" (every {step}th scale; extrapolated to 200 at the same "
                                      f"per-(sample x scale) rate: ~{secs * step:.1f} s)"))
        bound_ratio = fft[0] / cwt[0]  # = CWT time / FFT-bound time
        speedup = cwt[0] / py
        print(f"{n:>9} {cwt[0] / 1e6:>17.1f} {fft[0] / 1e6:>10.1f} {bound_ratio:>15.3f} "
              f"{py / 1e6:>17.2f} {speedup:>10.1f}  {note}")
        ok &= bound_ratio <= 1.5 and speedup >= 10.0
        print(f"{'':>9} bars: CWT/FFT-bound {bound_ratio:.3f} <= 1.5: "
              f"{'yes' if bound_ratio <= 1.5 else 'NO'}; ours/pywt {speedup:.1f} >= 10: "
              f"{'yes' if speedup >= 10 else 'NO'}")
    print("\nall bars met" if ok else "\nsome bar NOT met (see above)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
