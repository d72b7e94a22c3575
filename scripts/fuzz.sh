#!/usr/bin/env bash
# A longer libFuzzer campaign on one target of fuzz/ (csv, yaml, bag, stream, rig), single process,
# in the sanitizer workspace of scripts/sanitize.sh (configured and built first if needed). New inputs
# accumulate in <asan workspace>/fuzz_corpus/TARGET across campaigns; a crash is written there
# as crash-* and the exit status is non-zero. Prints the number of executions.
#
# Usage: scripts/fuzz.sh TARGET MINUTES [extra libFuzzer options...]
set -uo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
target=${1:?usage: scripts/fuzz.sh TARGET MINUTES}
minutes=${2:?usage: scripts/fuzz.sh TARGET MINUTES}
shift 2
case "$target" in csv | yaml | bag | stream | rig) ;; *)
  echo "fuzz.sh: unknown target '$target' (csv, yaml, bag, stream, rig)" >&2
  exit 1
  ;;
esac
repo=$(dirname "$here")
ws_default=${GEAR_DAMPING_WS:-$(dirname "$repo")/gear_damping_ws}
asan_ws=${GEAR_DAMPING_ASAN_WS:-${ws_default}_asan}
bin="$asan_ws/devel/lib/gear_damping/fuzz_$target"
# The sanitizer workspace configured by scripts/sanitize.sh: rebuild just this target there.
if [ -n "${GEAR_FUZZ_NO_BUILD:-}" ] && [ -x "$bin" ]; then
  :  # GEAR_FUZZ_NO_BUILD=1: run the binary as built (e.g. while the workspace builds tests)
elif [ -f "$asan_ws/build/CMakeCache.txt" ]; then
  (cd "$asan_ws" && PATH=/usr/bin:/bin:$PATH catkin_make -j"${GEAR_DAMPING_JOBS:-$(nproc)}" \
    "fuzz_$target" >/dev/null) || exit 1
else
  bash "$here/sanitize.sh" --build-only || exit 1
fi
corpus="$asan_ws/fuzz_corpus/$target"
mkdir -p "$corpus"
export ASAN_OPTIONS=${ASAN_OPTIONS:-allocator_may_return_null=1:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$repo/fuzz/lsan.supp:print_suppressions=0}
log="$corpus/../$target.log"
"$bin" -max_total_time=$((minutes * 60)) -timeout=20 -rss_limit_mb=2560 -print_final_stats=1 \
  -artifact_prefix="$corpus/../${target}_" "$@" "$corpus" "$repo/fuzz/corpus/$target" 2>&1 |
  tee "$log" | grep -E "^#[0-9]+ *(pulse|DONE)|ERROR|SUMMARY|runtime error|stat::"
rc=${PIPESTATUS[0]}
echo "fuzz.sh: $target, $minutes min: exit $rc, $(grep -m1 -o 'number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$') executions (log $log)"
exit "$rc"
