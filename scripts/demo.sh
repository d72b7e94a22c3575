#!/usr/bin/env bash
# The main job: installs what is missing, builds, and runs the demo pipeline on default
# parameters. (Until the simulator and analysis land, it prints the package's version and
# its message types.)
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
gear_install_deps
gear_build
gear_source_ws
echo "gear_damping $(sed -n 's:.*<version>\(.*\)</version>.*:\1:p' "$GEAR_REPO/package.xml")"
echo "messages:"
rosmsg package gear_damping | sed 's/^/  /'
