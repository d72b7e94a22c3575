#!/usr/bin/env bash
# Soak test of the live pipeline (not run in CI): damping_id_node and wavelet_node with their
# default settings, fed by a rig stand-in (test/rostest/live_stream_tester.cpp) that repeats a
# simulated 0.1 s record (config/table1.yaml) with continuous indices at RATE samples/s in
# 1000-sample chunks for MINUTES minutes. Prints samples sent/received, losses by cause, each
# node's resident memory at the start, after the warm-up and at the end with its growth per
# hour, each node's CPU cost (capacity in samples/s at 100 % of one core), per-segment latency
# p50/p99, the estimates' drift against the truth, and whether every segment equals the offline
# identify() of the same samples. Exit status: that of the test (0 = nothing lost, memory
# bounded, all segments equal to offline).
#
# Usage: scripts/soak.sh MINUTES [RATE] [NOISE_SNR_DB]
#   MINUTES       streaming time (wall clock)
#   RATE          samples/s (default 1000000)
#   NOISE_SNR_DB  noise on the record in dB (default: none). With noise the nodes refine
#                 (refine: auto), so the comparison with the integral-only offline result is
#                 skipped.
# Environment: as scripts/test.sh (GEAR_DAMPING_WS, GEAR_DAMPING_JOBS).
# Warm-up (memory growth measured after it): 150 s, or a third of the run if shorter: the
# ~get_damping store (history_segments, default 20000 segments = 20 s at 1 kHz) fills first.
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
if [ $# -lt 1 ] || ! [[ "$1" =~ ^[0-9]+([.][0-9]+)?$ ]]; then
  echo "usage: $0 MINUTES [RATE] [NOISE_SNR_DB]" >&2
  exit 2
fi
minutes=$1
rate=${2:-1000000}
noise=${3:-0}
seconds=$(python3 -c "print(float('$minutes') * 60)")
warmup=$(python3 -c "print(min(150.0, float('$seconds') / 3))")
limit=$(python3 -c "print(float('$seconds') + 300)")
gear_install_deps
gear_build live_stream_tester damping_id_node wavelet_node
gear_source_ws
# Noise-free: the defaults with refine: never, so that every segment can be compared with the
# integral-only offline identify() (refine: auto decides per segment live and over the record
# offline, and table1's load-dependent damping makes some segments' standard errors exceed the
# threshold). Noisy: the defaults (refine: auto), no comparison.
extra=(id_extra_config:="$GEAR_REPO/test/rostest/refine_never.yaml")
compare=true
if [ "$noise" != "0" ]; then
  compare=false
  extra=(id_extra_config:="$GEAR_REPO/config/damping_id.yaml")  # loaded twice: the defaults
fi
echo "[soak] $minutes min at $rate samples/s (noise ${noise} dB; 0 = none); load: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
log=$(mktemp /tmp/gear_soak.XXXXXX.log)
set +e
rostest --text gear_damping live_stream.test duration:="$seconds" rate:="$rate" \
  warmup:="$warmup" noise_snr_db:="$noise" compare_offline:="$compare" \
  rss_growth_limit_mib:=10 time_limit:="$limit" "${extra[@]}" >"$log" 2>&1
set -e
# rostest --text exits 0 whatever the test's outcome: the gtest verdict decides.
status=1
grep -q '^\[  PASSED  \] 1 test' "$log" && status=0
grep -E '^\[live\]|Failure|Expected|actual' "$log" || true
echo "[soak] load after: $(cut -d' ' -f1-3 /proc/loadavg); full log: $log; exit status $status"
exit $status
