#!/usr/bin/env bash
# Runs every test of the package (GoogleTest unit tests and rostest integration tests) after
# installing what is missing and building. Exit status: non-zero if any test failed.
# Results (JUnit XML) land in $GEAR_DAMPING_WS/build/test_results/gear_damping/.
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
gear_install_deps
gear_build
results="$GEAR_WS/build/test_results/gear_damping"
rm -rf "$results"   # count only this run's results
(cd "$GEAR_WS" && catkin_make -j"$GEAR_JOBS" run_tests \
    -DCMAKE_BUILD_TYPE=Release -DPYTHON_EXECUTABLE=/usr/bin/python3)
# catkin_make run_tests exits 0 even when tests fail: the XML results decide.
catkin_test_results --verbose "$results"
