# Shared by scripts/demo.sh and scripts/test.sh (sourced, not run): installs the Debian packages
# the package needs, creates or reuses a catkin workspace outside the source tree and builds.
#
# Environment:
#   GEAR_DAMPING_WS   workspace directory (default: <repo>/../gear_damping_ws)
#   GEAR_DAMPING_JOBS parallel build jobs (default: number of cores)
set -euo pipefail

GEAR_REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
GEAR_WS=${GEAR_DAMPING_WS:-$(dirname "$GEAR_REPO")/gear_damping_ws}
GEAR_JOBS=${GEAR_DAMPING_JOBS:-$(nproc)}

# A pyenv (or other) python3 first on PATH lacks the ROS Python modules (catkin_pkg, rospkg,
# em) and makes CMake fail inside catkin's templates: Debian's ROS runs on /usr/bin/python3.
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
unset PYTHONHOME PYTHONPATH

# Every system package the build, the tests, the benchmarks and the report need, by name.
GEAR_APT_PACKAGES=(
  build-essential cmake pkg-config
  catkin ros-core-dev ros-message-generation ros-message-runtime
  librosbag-dev librostest-dev libstd-msgs-dev libstd-srvs-dev libdiagnostic-updater-dev
  rosbash python3-rostest python3-rosbag python3-catkin-pkg python3-std-srvs
  libgtest-dev googletest libbenchmark-dev
  libeigen3-dev libfftw3-dev libyaml-cpp-dev libcli11-dev nlohmann-json3-dev
  python3-numpy python3-matplotlib python3-pywt python3-yaml
  clang libclang-rt-14-dev
)

gear_install_deps() {
  local missing=()
  local p
  for p in "${GEAR_APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if ((${#missing[@]})); then
    echo "[gear_damping] installing: ${missing[*]}" >&2
    local sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    $sudo apt-get update -q
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends "${GEAR_APT_PACKAGES[@]}"
  fi
}

gear_build() {
  mkdir -p "$GEAR_WS/src"
  # (Re)point the workspace at this checkout, so one workspace serves whichever clone runs.
  if [ "$(readlink "$GEAR_WS/src/gear_damping" 2>/dev/null)" != "$GEAR_REPO" ]; then
    rm -rf "$GEAR_WS/src/gear_damping"
    ln -s "$GEAR_REPO" "$GEAR_WS/src/gear_damping"
  fi
  (cd "$GEAR_WS" && catkin_make -j"$GEAR_JOBS" \
      -DCMAKE_BUILD_TYPE=Release -DPYTHON_EXECUTABLE=/usr/bin/python3 "$@")
}

# Sources the workspace's environment (setup.bash reads unset variables: relax -u around it).
gear_source_ws() {
  set +u
  # shellcheck disable=SC1091
  source "$GEAR_WS/devel/setup.bash"
  set -u
}
