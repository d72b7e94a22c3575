#!/usr/bin/env bash
# install_space.sh DIR NS [BUILD_DIR]
#   Makes an install space in the temporary directory DIR and starts
#   `roslaunch gear_damping pipeline.launch ns:=NS` from it alone (a clean environment: no devel
#   space, no source tree on ROS_PACKAGE_PATH), in the background on the current ROS master
#   (ROS_MASTER_URI); its pid goes to DIR/launch.pid, its output to DIR/launch.log.
#   - With BUILD_DIR (the catkin build directory of the workspace under test, already built):
#     `DESTDIR=DIR/root cmake --install BUILD_DIR`, i.e. the install rules of the build being
#     tested (already built; nothing is rebuilt), into DIR/root/<its install prefix>.
#   - Without: a workspace DIR (DIR/src/gear_damping -> this checkout) and `catkin_make install`
#     into DIR/install, without tests and benchmarks, with ccache when it is there (a full build).
# install_space.sh DIR --stop   stops that launch (SIGINT, as Ctrl-C).
# Used by test/rostest/install_space.test (InstallSpace.* in ros_citizen_tester.cpp). Exit
# status: 0 launched, 1 build or install failed, 2 the package found is not the installed one,
# 3 its messages/services are not found.
set -euo pipefail
dir=$1
if [ "${2:-}" = --stop ]; then
  pid=$(cat "$dir/launch.pid" 2>/dev/null || true)
  [ -n "$pid" ] || exit 0
  kill -INT "$pid" 2>/dev/null || exit 0
  for _ in $(seq 200); do kill -0 "$pid" 2>/dev/null || exit 0; sleep 0.1; done
  kill -KILL "$pid" 2>/dev/null || true
  exit 0
fi
ns=$2
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
build_dir=${3:-}
# The caller's environment is dropped (a devel space on CMAKE_PREFIX_PATH or ROS_PACKAGE_PATH
# would hide what the install space lacks), apart from the master and ccache's settings.
clean_env=(env -i "HOME=$HOME" "PATH=/usr/bin:/bin:/usr/sbin:/sbin" "ROS_MASTER_URI=$ROS_MASTER_URI")
for v in CCACHE_DIR CCACHE_BASEDIR CCACHE_SLOPPINESS ROS_IP ROS_HOSTNAME ROS_HOME ROS_LOG_DIR; do
  if [ -n "${!v:-}" ]; then clean_env+=("$v=${!v}"); fi
done
start=$(date +%s)
install="$dir/install"
if [ -n "$build_dir" ]; then
  # DESTDIR, not --prefix: catkin's workspace files (setup.bash, ...) have absolute destinations.
  prefix=$(sed -n 's/^CMAKE_INSTALL_PREFIX:PATH=//p' "$build_dir/CMakeCache.txt")
  # `cmake --install`: the install rules only. (`--target install` first brings the whole build
  # up to date: under `make -j2 run_tests` it relinked the nodes while other rostests launched
  # them, and a node caught mid-relink "failed to launch".) Only the dynamic_reconfigure files
  # are made first: catkin_make's re-configure (for run_tests) can leave them missing in devel/,
  # and making them touches no node binary.
  if ! { "${clean_env[@]}" cmake --build "$build_dir" --target gear_damping_gencfg &&
         "${clean_env[@]}" "DESTDIR=$dir/root" cmake --install "$build_dir"; } >"$dir/build.log" 2>&1
  then
    tail -n 60 "$dir/build.log"
    exit 1
  fi
  install="$dir/root$prefix"
  echo "[install_space] DESTDIR=$dir/root cmake --install $build_dir: $(($(date +%s) - start)) s"
else
  mkdir -p "$dir/src"
  ln -sfn "$repo" "$dir/src/gear_damping"
  launcher=()
  if command -v ccache >/dev/null; then
    launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  fi
  if ! (cd "$dir" && "${clean_env[@]}" catkin_make install -j2 -DCMAKE_BUILD_TYPE=Release \
          -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCATKIN_ENABLE_TESTING=OFF \
          -DGEAR_BUILD_BENCHMARKS=OFF -DCMAKE_INSTALL_PREFIX="$install" "${launcher[@]}" \
          >"$dir/build.log" 2>&1); then
    tail -n 60 "$dir/build.log"
    exit 1
  fi
  echo "[install_space] catkin_make install: $(($(date +%s) - start)) s"
fi
found=$("${clean_env[@]}" bash -c "source '$install/setup.bash' && rospack find gear_damping")
if [ "$found" != "$install/share/gear_damping" ]; then
  echo "[install_space] rospack finds gear_damping at $found, not in the install space" >&2
  exit 2
fi
# Installed interfaces are visible to the command-line tools too.
if ! shown=$("${clean_env[@]}" bash -c "source '$install/setup.bash' && \
      rossrv show gear_damping/GetDamping && rosmsg show gear_damping/DampingSample" 2>&1); then
  echo "[install_space] rossrv/rosmsg show from the install space failed: $shown" >&2
  exit 3
fi
echo "[install_space] rossrv show gear_damping/GetDamping: $(echo "$shown" | head -n 1)"
"${clean_env[@]}" bash -c "source '$install/setup.bash' && \
  exec roslaunch gear_damping pipeline.launch ns:=$ns" >"$dir/launch.log" 2>&1 &
echo $! >"$dir/launch.pid"
echo "[install_space] roslaunch pid $(cat "$dir/launch.pid")"
