#!/usr/bin/env bash
# Run a command inside the project's ROS 2 environment, bootstrapping it first if needed:
#   scripts/run.sh ros2 run kinect_bringup demo
#   scripts/run.sh python -m ...
# ROS_DISTRO=kilted picks Kilted (scripts/distro.sh). Should the ros2 CLI be missing (a system ROS 2
# without ros2cli), `ros2 run PKG EXE` runs install/<distro>/PKG/lib/PKG/EXE.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
set +u
# shellcheck disable=SC1091
source "$root/scripts/env.sh"
set -u
if [ "${1:-}" = ros2 ] && [ "${2:-}" = run ] && ! command -v ros2 >/dev/null; then
  exe="$root/install/$ROS_DISTRO/$3/lib/$3/$4"; shift 4
  exec "$exe" "$@"
fi
exec "$@"
