#!/usr/bin/env bash
# Build a ROS 2 distro's launch tooling (ros2 launch, launch_testing, launch_pytest, the ros2 CLI,
# tf2_msgs) from the release tarballs in third_party/ros2/<distro>/, as an overlay on a venv that
# holds that distro's pip ROS 2 wheels (requirements-<distro>.txt). scripts/setup.sh calls it.
#
#   usage: build-into-venv.sh DISTRO INSTALL_DIR   (with the wheels venv active: $VIRTUAL_ENV set)
#   then:  source INSTALL_DIR/local_setup.bash    (puts `ros2`, launch, launch_pytest on the paths)
#
# Idempotent: a second run with the same sources and venv returns at once. Needs cmake, g++ and make
# for the two message packages. Merged from ../shared/ros2{,-jazzy}/build-into-venv.sh (README.md);
# the Python packages the tooling imports are pinned in requirements-<distro>.txt, not installed here.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
distro=${1:?usage: build-into-venv.sh DISTRO INSTALL_DIR}
install_dir=${2:?usage: build-into-venv.sh DISTRO INSTALL_DIR}
src="$here/$distro"
ls "$src"/*.tar.gz >/dev/null 2>&1 ||
  { echo "build-into-venv.sh: no release tarballs for '$distro' in $here (have: $(cd "$here" && ls -d */ | tr -d / | tr '\n' ' '))" >&2; exit 1; }
: "${VIRTUAL_ENV:?activate the venv that holds the ROS 2 wheels first}"
mkdir -p "$install_dir"
install_dir=$(cd "$install_dir" && pwd)
work="$install_dir.build"

# Only one distribution may provide the `lark` module: the rosidl wheels pull lark-parser, which
# shares its directory; removing it leaves lark's files broken ("cannot import name 'Lark' from
# 'lark'", Jazzy's rosidl_adapter), so the pinned lark is reinstalled over it.
# Checked on every run: a later `pip install -r` brings lark-parser back.
if python -c 'import importlib.metadata as m; m.distribution("lark-parser")' 2>/dev/null; then
  lark_version=$(python -c 'import importlib.metadata as m; print(m.version("lark"))')
  python -m pip uninstall -q -y lark-parser >/dev/null
  python -m pip install -q --force-reinstall --no-deps "lark==$lark_version"
fi
python -c 'from lark import Lark' 2>/dev/null ||
  { echo "build-into-venv.sh: the venv has no working 'lark' (pip install -r requirements-$distro.txt)" >&2; exit 1; }

stamp="$(cat "$src"/*.tar.gz "${BASH_SOURCE[0]}" | sha256sum | cut -c1-16) $VIRTUAL_ENV"
if [[ -f "$install_dir/.built" && "$(cat "$install_dir/.built")" == "$stamp" ]]; then
  exit 0
fi

for tool in cmake g++ make; do
  command -v "$tool" >/dev/null || { echo "build-into-venv.sh: '$tool' not found (apt-get install cmake g++ make)" >&2; exit 1; }
done

# The wheels were built under /opt/python/cp311-cp311; point their CMake exports at this venv.
py_include=$(python -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
np_include=$(python -c 'import numpy; print(numpy.get_include())')
{ grep -rlZ --include='*.cmake' '/opt/python/cp311-cp311' "$VIRTUAL_ENV/share" 2>/dev/null || true; } |
  xargs -0 -r sed -i \
    -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$np_include#g" \
    -e "s#/opt/python/cp311-cp311/include/python3.11#$py_include#g"

rm -rf "$work" && mkdir -p "$work/src"
for tarball in "$src"/*.tar.gz; do tar -xzf "$tarball" -C "$work/src"; done

export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
(cd "$work" && colcon --log-base "$work/log" build --merge-install \
  --build-base "$work/build" --install-base "$install_dir" \
  --event-handlers console_direct- console_cohesion- console_stderr- status- summary+ \
  --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$(command -v python)") ||
  { echo "build-into-venv.sh: colcon build failed; logs are in $work/log" >&2; exit 1; }
rm -rf "$work"
echo "$stamp" > "$install_dir/.built"
