#!/usr/bin/env bash
# Make `from tf2_msgs.msg import TFMessage` work in the venv.
# Where tf2_msgs is already importable and was not built by us (a real ROS 2 install), use
# it and build nothing. Otherwise build vendor/tf2_msgs (upstream's TFMessage definition)
# with rosidl from the PyPI build wheels and install it into the venv prefix.
# Usage: scripts/ensure_tf2_msgs.sh VENV
set -eu
venv=$(cd "$1" && pwd)
py="$venv/bin/python"
here=$(cd "$(dirname "$0")/.." && pwd)
marker="$venv/share/tf2_msgs/built_by_dq_fk_ros"

if [ ! -e "$marker" ] && "$py" -c 'import tf2_msgs.msg' 2>/dev/null; then
  echo "tf2_msgs is provided by the environment; not building the vendored copy"
  exit 0
fi

"$py" -m pip install --disable-pip-version-check -r "$here/requirements/tf2_msgs-build.txt"
command -v cmake >/dev/null || { echo "error: cmake not found (needed to build tf2_msgs)"; exit 1; }

build=$(mktemp -d)
trap 'rm -rf "$build"' EXIT
export AMENT_PREFIX_PATH="$venv" CMAKE_PREFIX_PATH="$venv" PATH="$venv/bin:$PATH"
cmake -S "$here/vendor/tf2_msgs" -B "$build" -G Ninja \
  -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$py" -DBUILD_TESTING=OFF
cmake --build "$build"
cmake --install "$build"
touch "$marker"
"$py" -c 'from tf2_msgs.msg import TFMessage; TFMessage()'
echo "built and installed vendored tf2_msgs into $venv"
