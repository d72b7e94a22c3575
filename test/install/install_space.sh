#!/usr/bin/env bash
# install_space.sh DIR NS   builds the package's install space in the temporary workspace DIR
#                           (DIR/src/gear_damping -> this checkout; `catkin_make install`
#                           into DIR/install, without tests and benchmarks, with ccache when it
#                           is there), then starts `roslaunch gear_damping pipeline.launch ns:=NS`
#                           from the install space alone (a clean environment: no devel space,
#                           no source tree on ROS_PACKAGE_PATH), in the background on the current
#                           ROS master (ROS_MASTER_URI). Its pid goes to DIR/launch.pid, its
#                           output to DIR/launch.log.
# install_space.sh DIR --stop  stops that launch (SIGINT, as Ctrl-C).
# Used by test/rostest/install_space.test (InstallSpace.* in ros_citizen_tester.cpp). Exit
# status: 0 launched, 1 build or install failed, 2 the installed package is not the one found.
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
mkdir -p "$dir/src"
ln -sfn "$repo" "$dir/src/gear_damping"
# Only what running from the install space needs; the caller's environment is dropped (a devel
# space on CMAKE_PREFIX_PATH would otherwise be chained), apart from ccache's settings.
clean_env=(env -i "HOME=$HOME" "PATH=/usr/bin:/bin:/usr/sbin:/sbin" "ROS_MASTER_URI=$ROS_MASTER_URI")
for v in CCACHE_DIR CCACHE_BASEDIR CCACHE_SLOPPINESS ROS_IP ROS_HOSTNAME ROS_HOME ROS_LOG_DIR; do
  if [ -n "${!v:-}" ]; then clean_env+=("$v=${!v}"); fi
done
launcher=()
if command -v ccache >/dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi
start=$(date +%s)
if ! (cd "$dir" && "${clean_env[@]}" catkin_make install -j2 -DCMAKE_BUILD_TYPE=Release \
        -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCATKIN_ENABLE_TESTING=OFF \
        -DGEAR_BUILD_BENCHMARKS=OFF -DCMAKE_INSTALL_PREFIX="$dir/install" "${launcher[@]}" \
        >"$dir/build.log" 2>&1); then
  tail -n 60 "$dir/build.log"
  exit 1
fi
echo "[install_space] catkin_make install: $(($(date +%s) - start)) s"
found=$("${clean_env[@]}" bash -c "source '$dir/install/setup.bash' && rospack find gear_damping")
if [ "$found" != "$dir/install/share/gear_damping" ]; then
  echo "[install_space] rospack finds gear_damping at $found, not in the install space" >&2
  exit 2
fi
# Installed interfaces are visible to the command-line tools too.
"${clean_env[@]}" bash -c "source '$dir/install/setup.bash' && rossrv show gear_damping/GetDamping \
  && rosmsg show gear_damping/DampingSample" | head -n 3
"${clean_env[@]}" bash -c "source '$dir/install/setup.bash' && \
  exec roslaunch gear_damping pipeline.launch ns:=$ns" >"$dir/launch.log" 2>&1 &
echo $! >"$dir/launch.pid"
echo "[install_space] roslaunch pid $(cat "$dir/launch.pid")"
