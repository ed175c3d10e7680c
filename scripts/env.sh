# Source this file (bash) to get the project's ROS 2 environment:
#   source scripts/env.sh                       # ROS 2 Jazzy (default), or the system ROS 2
#   ROS_DISTRO=kilted source scripts/env.sh     # ROS 2 Kilted
# It never builds anything (run scripts/setup.sh, or any make target, for that). Which distro, and
# where its venv and build live: scripts/distro.sh. In order:
#   1. a system ROS 2 under /opt/ros/<distro>, when there is one (ROS_DISTRO_PATH to pick one),
#   2. the project venv .venv-<distro> (the pinned pip ROS 2 wheels, or the Python packages on top
#      of the system ROS 2), with the launch tooling built into .venv-<distro>/ros2-tools,
#   3. the workspace overlay install/<distro>.
# DDS stays on this machine: discovery is limited to localhost before any ROS process starts.

_kp_here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
if source "$_kp_here/distro.sh"; then
  export KINECT_POSTURE_ROOT="$_kp_root"
  export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-42}"
  export PYTHONUNBUFFERED=1
  # single-threaded BLAS: the per-frame maths is small matrices; BLAS threads only spin (see skeleton_core)
  export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}" OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
  export RCUTILS_COLORIZED_OUTPUT="${RCUTILS_COLORIZED_OUTPUT:-0}"
  export MPLBACKEND="${MPLBACKEND:-Agg}"
  unset KINECT_POSTURE_ROS KINECT_POSTURE_LAUNCH_TOOLING

  if [ -n "$_kp_underlay" ]; then
    # shellcheck disable=SC1091
    set +u; source "$_kp_underlay/setup.bash"; set -u 2>/dev/null || true
    export KINECT_POSTURE_ROS="system:$_kp_underlay"
  fi
  if [ -f "$_kp_venv/bin/activate" ]; then
    # shellcheck disable=SC1091
    source "$_kp_venv/bin/activate"
    if [ -z "$_kp_underlay" ]; then
      export KINECT_POSTURE_ROS="wheels:$_kp_venv"
      export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
      export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
      if [ -f "$_kp_tools/local_setup.bash" ]; then
        # shellcheck disable=SC1091
        source "$_kp_tools/local_setup.bash"
        export KINECT_POSTURE_LAUNCH_TOOLING="$_kp_tools"
      fi
    fi
  else
    echo "scripts/env.sh: no ${_kp_venv#"$_kp_root"/} yet: run 'make setup'${ROS_DISTRO:+ (ROS_DISTRO=$ROS_DISTRO)}" >&2
  fi
  export ROS_DISTRO="$_kp_distro"   # the wheels set none; a system setup.bash sets the same
  if [ -f "$_kp_install/local_setup.bash" ]; then
    # shellcheck disable=SC1091
    source "$_kp_install/local_setup.bash"
  fi
fi
unset _kp_here _kp_root _kp_distro _kp_underlay _kp_venv _kp_reqs _kp_tools _kp_build _kp_install _kp_log \
  _kp_wheel_distros _kp_default_distro
