#!/usr/bin/env bash
# Build interfaces/tf2_msgs with the venv's ROS 2 Jazzy rosidl wheels and install it into the venv
# (`make tf2-msgs`; docs/ROS.md, "rosbag2 habits"). Usage: build_tf2_msgs.sh VENV [BUILD_DIR]
# Needs cmake, gcc and g++; about 7 s on 2 cores once the build-only wheels are installed.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
venv="$(cd "$1" && pwd)"
build="${2:-$here/../build/tf2_msgs}"
for tool in cmake cc c++; do
  command -v "$tool" > /dev/null || { echo "build_tf2_msgs.sh: $tool not found" >&2; exit 1; }
done
"$venv/bin/python" -m pip install -q -r "$here/requirements.txt"
rm -rf "$build"
mkdir -p "$build"
cmake -S "$here/tf2_msgs" -B "$build" --log-level=WARNING -DBUILD_TESTING=OFF \
  -DCMAKE_INSTALL_PREFIX="$venv" -DCMAKE_PREFIX_PATH="$venv" -DPython3_EXECUTABLE="$venv/bin/python" \
  > "$build/configure.log" 2>&1 || { cat "$build/configure.log" >&2; exit 1; }
cmake --build "$build" -j2 > "$build/build.log" 2>&1 || { cat "$build/build.log" >&2; exit 1; }
cmake --install "$build" > "$build/install.log"
"$venv/bin/python" -c "import tf2_msgs.msg"
