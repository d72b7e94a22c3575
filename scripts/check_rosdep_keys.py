#!/usr/bin/env python3
"""Checks that every dependency key of package.xml resolves with rosdep, offline.

rosdep's database cannot be downloaded on every machine (`rosdep update` needs the network), so
the keys were verified once against the rosdistro rosdep database and are listed below with what
they resolve to on Debian. The check fails when package.xml names a key that is not listed (a key
added without verification, or a typo such as `fftw3`), and when a system key's Debian packages
are missing from GEAR_APT_PACKAGES in scripts/common.sh (the list the scripts and CI install).

When `rosdep` is installed and its cache is populated, it is also asked (`rosdep resolve`).

Usage: check_rosdep_keys.py [PACKAGE_XML]   (default: the package.xml beside scripts/)
Exit status: 0 all keys verified, 1 otherwise.
"""
import pathlib
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

# System keys, verified in github.com/ros/rosdistro rosdep/base.yaml (commit 8f8e55cd3a6f) and
# rosdep/python.yaml: key -> (file, Debian packages of the rule).
SYSTEM_KEYS = {
    "pkg-config": ("base.yaml", ["pkg-config"]),
    "eigen": ("base.yaml", ["libeigen3-dev"]),
    # The rule is debian: [libfftw3-3, libfftw3-dev]. Debian 12 has no libfftw3-3 (its double
    # precision library is libfftw3-double3, pulled in by libfftw3-dev), so `rosdep install` on
    # bookworm needs the rule fixed upstream; the scripts install libfftw3-dev by name.
    "libfftw3": ("base.yaml", ["libfftw3-dev"]),
    "yaml-cpp": ("base.yaml", ["libyaml-cpp-dev"]),
    "cli11": ("base.yaml", ["libcli11-dev"]),
    "nlohmann-json-dev": ("base.yaml", ["nlohmann-json3-dev"]),
    "gtest": ("base.yaml", ["libgtest-dev"]),
    "benchmark": ("base.yaml", ["libbenchmark-dev"]),
    "python3-numpy": ("python.yaml", ["python3-numpy"]),
    "python3-matplotlib": ("python.yaml", ["python3-matplotlib"]),
}

# ROS package keys: released packages of the Noetic distribution (rosdistro noetic/
# distribution.yaml; on Debian 12 the distribution's own ros-* / lib*-dev packages).
ROS_PACKAGES = {
    "catkin": ["catkin"],
    "message_generation": ["ros-message-generation"],
    "message_runtime": ["ros-message-runtime"],
    "roscpp": ["ros-core-dev"],
    "rosbag": ["librosbag-dev", "python3-rosbag"],
    "std_msgs": ["libstd-msgs-dev", "python3-std-msgs"],
    "std_srvs": ["libstd-srvs-dev", "python3-std-srvs"],
    "diagnostic_msgs": ["python3-diagnostic-msgs"],
    "diagnostic_updater": ["libdiagnostic-updater-dev"],
    "diagnostic_aggregator": ["libdiagnostic-aggregator-tools", "libdiagnostic-aggregator-dev"],
    "dynamic_reconfigure": ["libdynamic-reconfigure-config-init-mutex-dev",
                            "python3-dynamic-reconfigure"],
    "sensor_msgs": ["libsensor-msgs-dev", "python3-sensor-msgs"],
    "geometry_msgs": ["libgeometry-msgs-dev", "python3-geometry-msgs"],
    "message_filters": ["libmessage-filters-dev"],
    "roslaunch": ["python3-roslaunch"],
    "rosbash": ["rosbash"],
    "rostopic": ["python3-rostopic"],
    "rostest": ["librostest-dev", "python3-rostest"],
}

DEPEND_TAGS = ("depend", "build_depend", "buildtool_depend", "build_export_depend",
               "exec_depend", "run_depend", "test_depend", "doc_depend")


def apt_list(common_sh):
    text = common_sh.read_text()
    m = re.search(r"GEAR_APT_PACKAGES=\((.*?)\n\)", text, re.S)
    if not m:
        raise SystemExit(f"{common_sh}: GEAR_APT_PACKAGES=( ... ) not found")
    return set(m.group(1).split())


def main(argv):
    repo = pathlib.Path(__file__).resolve().parent.parent
    manifest = pathlib.Path(argv[1]) if len(argv) > 1 else repo / "package.xml"
    apt = apt_list(repo / "scripts" / "common.sh")
    root = ET.parse(manifest).getroot()
    keys = sorted({e.text.strip() for tag in DEPEND_TAGS for e in root.iter(tag) if e.text})
    errors = []
    for key in keys:
        if key in SYSTEM_KEYS:
            source, debs = SYSTEM_KEYS[key]
            kind = f"system key (rosdistro rosdep/{source})"
        elif key in ROS_PACKAGES:
            debs = ROS_PACKAGES[key]
            kind = "ROS package (noetic)"
        else:
            errors.append(f"{key}: not a verified rosdep key (see {pathlib.Path(__file__).name})")
            continue
        missing = [d for d in debs if d not in apt]
        if missing:
            errors.append(f"{key}: Debian package(s) {', '.join(missing)} missing from "
                          "GEAR_APT_PACKAGES in scripts/common.sh")
        print(f"ok  {key:22s} {kind} -> {' '.join(debs)}")
    rosdep = shutil.which("rosdep")
    if rosdep:
        for key in keys:
            r = subprocess.run([rosdep, "resolve", key], capture_output=True, text=True)
            if r.returncode != 0 and "cache" not in (r.stderr + r.stdout).lower():
                errors.append(f"{key}: rosdep resolve failed: {r.stderr.strip()}")
    for e in errors:
        print("ERROR " + e, file=sys.stderr)
    print(f"{len(keys) - len([e for e in errors if 'not a verified' in e])}/{len(keys)} keys "
          f"verified, {len(errors)} error(s)")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
