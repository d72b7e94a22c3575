#!/usr/bin/env bash
# Runs ONE test of the package, from any state of the workspace (a fresh clone included):
# installs what is missing, builds the package and the test binaries, then runs
#
#   scripts/run_test.sh <unit>_test [gtest options]   one GoogleTest binary (test/unit/<unit>_test.cpp),
#                                                     e.g. gear_pair_test --gtest_filter='GearPair.Forc*'
#   scripts/run_test.sh <name>.test [rostest args]    one rostest (test/rostest/<name>.test)
#
# Exit status: 0 only if the test ran and passed; the test's own non-zero status otherwise
# (rostest: 1 a test failed or could not start, 2 a sub-test failed), 2 for a usage error.
# Environment: as scripts/test.sh (GEAR_DAMPING_WS, GEAR_DAMPING_JOBS).
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

usage() {
  echo "usage: scripts/run_test.sh <unit>_test [gtest options] | <name>.test [rostest args]" >&2
  echo "  unit tests: $(cd "$GEAR_REPO/test/unit" && ls ./*_test.cpp | sed 's#^./##; s#\.cpp$##' | tr '\n' ' ')" >&2
  echo "  rostests:   $(cd "$GEAR_REPO/test/rostest" && ls ./*.test | sed 's#^./##' | tr '\n' ' ')" >&2
}

if [ $# -lt 1 ]; then
  usage
  exit 2
fi
name=$1
shift
case "$name" in
  *.test) kind=rostest source_file="$GEAR_REPO/test/rostest/$name" ;;
  *_test) kind=unit source_file="$GEAR_REPO/test/unit/$name.cpp" ;;
  *) kind=none source_file="" ;;
esac
if [ "$kind" = none ] || [ ! -f "$source_file" ]; then
  echo "run_test: no such test: $name" >&2
  usage
  exit 2
fi

gear_install_deps
if [ "$kind" = unit ]; then
  gear_build "$name"
  exec "$GEAR_WS/devel/lib/gear_damping/$name" "$@"
fi
# A rostest starts the package's nodes (built by 'all') and its tester executables (built by
# 'tests', which catkin's run_tests_* targets do NOT build: that is why
# `catkin_make run_tests_..._<name>.test` on a fresh workspace reports a missing node and still
# exits 0).
gear_build
gear_build tests
gear_source_ws
exec rostest gear_damping "$name" "$@"
