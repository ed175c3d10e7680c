# Source this file (bash) to get the project's ROS 2 environment:
#   source scripts/env.sh
# It never builds anything (run scripts/setup.sh for that). Order of underlays:
#   1. a system ROS 2 under /opt/ros/<distro> (ROS_DISTRO_PATH to pick one),
#   2. else the project venv (.venv) with the pip ROS 2 Kilted wheels, plus the launch tooling
#      built from ../shared/ros2 into .venv/ros2-tools when it was built,
# then the workspace overlay install/setup.bash.
# DDS stays on this machine: discovery is limited to localhost before any ROS process starts.

_kp_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export KINECT_POSTURE_ROOT="$_kp_root"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-42}"
export PYTHONUNBUFFERED=1
# single-threaded BLAS: the per-frame maths is small matrices; BLAS threads only spin (see skeleton_core)
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}" OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
export RCUTILS_COLORIZED_OUTPUT="${RCUTILS_COLORIZED_OUTPUT:-0}"
export MPLBACKEND="${MPLBACKEND:-Agg}"

_kp_underlay=""
if [ -n "${ROS_DISTRO_PATH:-}" ] && [ -f "$ROS_DISTRO_PATH/setup.bash" ]; then
  _kp_underlay="$ROS_DISTRO_PATH"
else
  for _d in /opt/ros/kilted /opt/ros/jazzy /opt/ros/humble /opt/ros/rolling; do
    [ -f "$_d/setup.bash" ] && { _kp_underlay="$_d"; break; }
  done
fi
if [ -n "$_kp_underlay" ]; then
  # shellcheck disable=SC1091
  set +u; source "$_kp_underlay/setup.bash"; set -u 2>/dev/null || true
  export KINECT_POSTURE_ROS="system:$_kp_underlay"
fi
if [ -f "$_kp_root/.venv/bin/activate" ]; then
  # shellcheck disable=SC1091
  source "$_kp_root/.venv/bin/activate"
  if [ -z "$_kp_underlay" ]; then
    export KINECT_POSTURE_ROS="wheels:$_kp_root/.venv"
    export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
    export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
    if [ -f "$_kp_root/.venv/ros2-tools/local_setup.bash" ]; then
      # shellcheck disable=SC1091
      source "$_kp_root/.venv/ros2-tools/local_setup.bash"
      export KINECT_POSTURE_LAUNCH_TOOLING="$_kp_root/.venv/ros2-tools"
    fi
  fi
fi
# Humble has no ROS_AUTOMATIC_DISCOVERY_RANGE; later distros deprecate ROS_LOCALHOST_ONLY.
case "${ROS_DISTRO:-}" in
  humble|iron|"") [ -n "$_kp_underlay" ] && export ROS_LOCALHOST_ONLY=1 ;;
esac
if [ -f "$_kp_root/install/local_setup.bash" ]; then
  # shellcheck disable=SC1091
  source "$_kp_root/install/local_setup.bash"
fi
unset _d _kp_underlay
