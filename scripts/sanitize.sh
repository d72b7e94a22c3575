#!/usr/bin/env bash
# The sanitizer stage of CI. Builds the package with clang, -fsanitize=address,undefined and
# -fno-sanitize-recover=all (plus libFuzzer's coverage instrumentation) in its own workspace,
# runs every unit test binary (among them hostile_inputs_test, whose tool runs then use the
# sanitized simulate/convert/analyze), then fuzzes each fuzz/ target for FUZZ_SECONDS from its
# seed corpus. Results are JUnit XML in RESULTS_DIR, one case per unit test and one per fuzz
# target, counted by CI with the other tests: any sanitizer report, crash or fuzz finding is a
# failed case (a test binary that dies without its XML gets a failed case of its own).
#
# Usage: scripts/sanitize.sh [--build-only] [FUZZ_SECONDS (default 25; 0: no fuzzing)]
# Environment: GEAR_DAMPING_ASAN_WS (workspace, default <GEAR_DAMPING_WS>_asan),
#   GEAR_SANITIZE_RESULTS (default <GEAR_DAMPING_WS>/build/test_results/gear_damping/sanitize).
# Exit status: non-zero when anything failed.
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
set +e
build_only=0
if [ "${1:-}" = "--build-only" ]; then build_only=1; shift; fi
fuzz_seconds=${1:-25}
fuzz_targets="csv yaml bag stream rig"
ASAN_WS=${GEAR_DAMPING_ASAN_WS:-${GEAR_WS}_asan}
results=${GEAR_SANITIZE_RESULTS:-$GEAR_WS/build/test_results/gear_damping/sanitize}
# A report aborts with a code no tool documents (86), so a tool test sees it as a failure too.
export ASAN_OPTIONS=${ASAN_OPTIONS:-exitcode=86:abort_on_error=0:detect_leaks=1:allocator_may_return_null=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-exitcode=86:print_stacktrace=1:halt_on_error=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$GEAR_REPO/fuzz/lsan.supp:print_suppressions=0}

sanitize_build() {
  mkdir -p "$ASAN_WS/src"
  if [ "$(readlink "$ASAN_WS/src/gear_damping" 2>/dev/null)" != "$GEAR_REPO" ]; then
    rm -rf "$ASAN_WS/src/gear_damping"
    ln -s "$GEAR_REPO" "$ASAN_WS/src/gear_damping"
  fi
  local flags="-fsanitize=address,undefined -fno-sanitize-recover=all -fsanitize=fuzzer-no-link"
  # Line tables only: reports keep file:line in every frame, and the build is ~15 % faster than -g.
  flags+=" -fno-omit-frame-pointer -gline-tables-only"
  # The libraries, tools and fuzz targets at -O1; the unit test sources at -O0
  # (GEAR_UNIT_TEST_FLAGS, test/tests.cmake), the code they test unchanged. Measured (CPU s,
  # compile without PCH + sanitized run): wavelet_test 20.6 + 9.2 at -O1, 10.4 + 17.0 at -O0
  # (its own loops run slower); stream_assembler_test 11.9 + 1.9 and 8.8 + 2.4.
  # Two goals, each built in parallel: make builds the goals named on catkin_make's command line
  # one after the other, so each one-source test target named alone compiled on one core only.
  # gear_unit_tests (test/tests.cmake) depends on every unit test and through them on the tools.
  (cd "$ASAN_WS" && CC=clang CXX=clang++ catkin_make -j"$GEAR_JOBS" \
      -DCMAKE_BUILD_TYPE=Release -DCMAKE_C_FLAGS_RELEASE="-O1" -DCMAKE_CXX_FLAGS_RELEASE="-O1" \
      -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_C_FLAGS="$flags" \
      -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
      -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
      -DGEAR_DAMPING_FUZZ=ON -DGEAR_TEST_PCH=ON -DGEAR_UNIT_TEST_FLAGS=-O0 \
      -DPYTHON_EXECUTABLE=/usr/bin/python3 \
      fuzz_targets gear_unit_tests)
}

# The bag target runs freely like the others: scanSignalBag checks every record's lengths
# (checkBagStructure) before rosbag opens the file, which closed ROS's header over-read
# (ros::Header::parse) and rosbag's up-to-4-GB buffer for a corrupt 32-bit record length.

# junit FILE SUITE NAME FAILURE_MESSAGE(empty = passed)
junit() {
  local msg=${4//&/&amp;}
  msg=${msg//</&lt;}
  msg=${msg//>/&gt;}
  {
    echo '<?xml version="1.0" encoding="UTF-8"?>'
    echo "<testsuite name=\"$2\" tests=\"1\" failures=\"$([ -n "$4" ] && echo 1 || echo 0)\">"
    if [ -n "$4" ]; then
      echo "  <testcase classname=\"$2\" name=\"$3\"><failure message=\"$msg\"/></testcase>"
    else
      echo "  <testcase classname=\"$2\" name=\"$3\"/>"
    fi
    echo '</testsuite>'
  } >"$1"
}

start=$(date +%s)
if ! sanitize_build; then
  mkdir -p "$results"
  junit "$results/sanitize_build.xml" sanitize build "the sanitizer build failed"
  echo "sanitize: the sanitizer build failed" >&2
  exit 1
fi
echo "sanitize: build $(($(date +%s) - start)) s" >&2
[ "$build_only" = 1 ] && exit 0

rm -rf "$results"
mkdir -p "$results"
bin="$ASAN_WS/devel/lib/gear_damping"
# The statistical tests (the same estimate over 30-50 noise seeds, to check coverage) repeat code
# paths the other tests already take once; under ASan at -O1 they cost minutes each (the encoder
# coverage tests alone took 710 s), so the sanitized run leaves them to the Release run.
# The SteRig accuracy tests (three rig cases end to end, minutes in Release on a loaded machine)
# likewise: their code paths run sanitized in SteModel.*, encoder_frontend_test, rig_cli_test
# and the rig fuzz target.
# Three end-to-end cases cost 49-125 s each sanitized (measured in CI's sanitizer stage) and
# repeat paths that run sanitized elsewhere: the unrepresentable-shape greybox case (other
# greybox_shape cases and quality_flags cover the shape refinement), the rig bag with STE (the
# rig bag without STE in rig_cli_test, SteModel.* and the rig fuzz target), and edge times at
# 5000 counts/rev (encoder_frontend's other cases and the rig fuzz target parse edge times).
asan_filter="-*Coverage*:*CoverTheTruth*:*OverSeeds:*OverFiftySeeds:SteRig.*"
asan_filter+=":*UnrepresentableShapeIsRightOrFlagged:*RigBagWithSteIdentifiesTheSpectrum"
asan_filter+=":*EdgeTimesGiveTheUniformC"
# Unit tests and fuzz targets are single-threaded: GEAR_JOBS of them run at once.
throttle() { while [ "$(jobs -rp | wc -l)" -ge "$GEAR_JOBS" ]; do wait -n; done; }

run_unit_test() {  # run_unit_test BINARY: XML, log and exit status in $results
  local name
  name=$(basename "$1")
  (cd "$GEAR_REPO" && "$1" --gtest_filter="$asan_filter" --gtest_output="xml:$results/asan_$name.xml" \
      >"$results/asan_$name.log" 2>&1)
  echo $? >"$results/asan_$name.rc"
}

run_fuzz_target() {  # run_fuzz_target TARGET: JUnit case and log in $results
  local target=$1 work tmp log rc execs left
  work=$(mktemp -d)
  tmp=$(mktemp -d)  # the target's TMPDIR: what it leaves behind is counted, then removed
  log="$results/fuzz_$target.log"
  # Single process; new inputs go to a scratch corpus, the seeds in the repository stay.
  TMPDIR="$tmp" "$bin/fuzz_$target" -seed=1 -max_total_time="$fuzz_seconds" -timeout=20 \
    -rss_limit_mb=2560 -print_final_stats=1 -artifact_prefix="$results/fuzz_${target}_" \
    "$work" "$GEAR_REPO/fuzz/corpus/$target" >"$log" 2>&1
  rc=$?
  execs=$(grep -m1 -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$')
  left=$(find "$tmp" -mindepth 1 | wc -l)
  if [ $rc -ne 0 ]; then
    echo "sanitize: fuzz_$target found a failure (exit $rc, log $log):" >&2
    grep -m5 -E "ERROR|runtime error|SUMMARY|Test unit written" "$log" >&2
    junit "$results/fuzz_$target.xml" fuzz "$target" "exit $rc after ${execs:-?} runs, see $log"
  elif [ "$left" -ne 0 ]; then
    echo "sanitize: fuzz_$target left $left temporary files in its TMPDIR:" \
      "$(find "$tmp" -mindepth 1 | head -3 | tr '\n' ' ')" >&2
    junit "$results/fuzz_$target.xml" fuzz "$target" "left $left temporary files after a clean exit"
  else
    junit "$results/fuzz_$target.xml" fuzz "$target" ""
  fi
  echo "sanitize: fuzz_$target ${fuzz_seconds} s, ${execs:-?} executions" >&2
  rm -rf "$work" "$tmp"
}

# One pool for both: a fuzz target starts as soon as a test binary's slot frees, so no core idles
# while the last test binaries run (each fuzz target still gets one core for FUZZ_SECONDS).
failed=0
start=$(date +%s)
for t in "$bin"/*_test; do
  throttle
  run_unit_test "$t" &
done
if [ "$fuzz_seconds" -gt 0 ]; then
  for target in $fuzz_targets; do
    throttle
    run_fuzz_target "$target" &
  done
fi
wait
for t in "$bin"/*_test; do
  name=$(basename "$t")
  rc=$(cat "$results/asan_$name.rc" 2>/dev/null || echo "no status")
  rm -f "$results/asan_$name.rc"
  if [ "$rc" != 0 ]; then
    failed=1
    echo "sanitize: $name exited $rc (log: $results/asan_$name.log)" >&2
    grep -m5 -E "ERROR: AddressSanitizer|runtime error|LeakSanitizer" "$results/asan_$name.log" >&2
    junit "$results/asan_${name}_exit.xml" "sanitize.$name" exit_status \
      "exit status $rc (a sanitizer report or a failed test; see asan_$name.log)"
  fi
done
grep -l "<failure" "$results"/fuzz_*.xml >/dev/null 2>&1 && failed=1
echo "sanitize: unit tests and fuzzing $(($(date +%s) - start)) s" >&2
exit $failed
