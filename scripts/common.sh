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

# Every system package the build, the tests, the benchmarks and the report need, by name, and
# the Python message modules `rostopic echo` / `rosservice` / `dynparam` need for every topic the
# package publishes (gear_damping/*, std_msgs, diagnostic_msgs, rosgraph_msgs,
# dynamic_reconfigure). .ci/run installs the same list.
GEAR_APT_PACKAGES=(
  build-essential cmake pkg-config ccache
  catkin ros-core-dev ros-message-generation ros-message-runtime
  librosbag-dev librostest-dev libstd-msgs-dev libstd-srvs-dev libdiagnostic-updater-dev
  libdynamic-reconfigure-config-init-mutex-dev
  libdiagnostic-aggregator-dev libdiagnostic-aggregator-tools
  libsensor-msgs-dev libgeometry-msgs-dev libmessage-filters-dev
  python3-sensor-msgs python3-geometry-msgs
  rosbash python3-rostest python3-rosbag python3-catkin-pkg python3-std-srvs
  python3-roslaunch python3-rostopic python3-rosservice python3-rosmsg python3-genpy
  python3-std-msgs python3-diagnostic-msgs python3-rosgraph-msgs python3-dynamic-reconfigure
  libgtest-dev googletest libbenchmark-dev
  libeigen3-dev libfftw3-dev libyaml-cpp-dev libcli11-dev nlohmann-json3-dev
  python3-numpy python3-matplotlib python3-pywt python3-yaml
  chromium clang libclang-rt-14-dev clang-format
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

# Makes $GEAR_WS/src/gear_damping this checkout, never deleting or overwriting anything the
# scripts did not create:
#   - absent: a symlink to this checkout is created;
#   - a symlink (ours, from an earlier run, possibly of another clone): re-pointed here (only the
#     link changes, never what it pointed to);
#   - this checkout itself (the clone sits at $GEAR_WS/src/gear_damping, or anywhere under
#     $GEAR_WS/src): used in place, nothing is linked;
#   - anything else (another clone, a file): refused with a message, return status 1.
gear_link_checkout() {
  local src="$GEAR_WS/src" target="$GEAR_WS/src/gear_damping"
  mkdir -p "$src"
  local repo_real src_real
  repo_real=$(realpath "$GEAR_REPO")
  src_real=$(realpath "$src")
  case "$repo_real/" in
    "$src_real"/*)  # the checkout is inside this workspace's src: catkin finds it there
      if [ -L "$target" ] && [ "$(realpath "$target" 2>/dev/null)" = "$repo_real" ]; then
        return 0
      fi
      if [ -e "$target" ] || [ -L "$target" ]; then
        if [ "$(realpath "$target" 2>/dev/null)" = "$repo_real" ]; then return 0; fi
        echo "[gear_damping] refusing to use workspace $GEAR_WS: this checkout ($GEAR_REPO) is in" \
             "its src/ and $target is another copy of the package (catkin would find two)." >&2
        return 1
      fi
      return 0
      ;;
  esac
  if [ -L "$target" ]; then
    if [ "$(readlink "$target")" != "$GEAR_REPO" ]; then
      echo "[gear_damping] re-pointing the symlink $target -> $GEAR_REPO" >&2
      ln -sfn "$GEAR_REPO" "$target"
    fi
    return 0
  fi
  if [ -e "$target" ]; then
    echo "[gear_damping] refusing to touch $target: it exists, is not a symlink and is not this" \
         "checkout ($GEAR_REPO). Move it away, or set GEAR_DAMPING_WS to another workspace (or to" \
         "the workspace that contains this checkout)." >&2
    return 1
  fi
  ln -s "$GEAR_REPO" "$target"
}

# Prepares an output directory for the demo: created if absent; reused if empty or written by an
# earlier demo (it holds the marker .gear_damping_demo); refused (status 1, nothing written) if it
# holds files the demo did not create. Prints the absolute path.
gear_prepare_out_dir() {
  local dir=$1
  if [ -e "$dir" ] && [ ! -d "$dir" ]; then
    echo "[gear_damping] refusing to write into $dir: it is not a directory" >&2
    return 1
  fi
  if [ -d "$dir" ] && [ ! -e "$dir/.gear_damping_demo" ] && [ -n "$(ls -A "$dir")" ]; then
    echo "[gear_damping] refusing to write into $dir: it holds files the demo did not create" \
         "(no .gear_damping_demo marker). Pass an empty or new directory." >&2
    return 1
  fi
  mkdir -p "$dir"
  : > "$dir/.gear_damping_demo"
  (cd "$dir" && pwd)
}

gear_build() {
  gear_link_checkout
  # ccache when installed (the install-space test rebuilds the package in a sibling workspace:
  # with the base directory above the workspaces, its objects are cache hits).
  local launcher=()
  if command -v ccache >/dev/null; then
    export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$(dirname "$(realpath "$GEAR_WS")")}
    launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
  fi
  # GEAR_TEST_PCH=ON (set by .ci/run): the unit tests share one precompiled header. A fresh
  # machine has no ccache objects to lose, and it roughly halves the tests' compile time.
  (cd "$GEAR_WS" && catkin_make -j"$GEAR_JOBS" \
      -DCMAKE_BUILD_TYPE=Release -DPYTHON_EXECUTABLE=/usr/bin/python3 "${launcher[@]}" \
      -DGEAR_TEST_PCH="${GEAR_TEST_PCH:-OFF}" "$@")
}

# Sources the workspace's environment (setup.bash reads unset variables: relax -u around it).
gear_source_ws() {
  set +u
  # shellcheck disable=SC1091
  source "$GEAR_WS/devel/setup.bash"
  set -u
}
