# Which ROS 2 the project runs on, and where its per-distro products live: the shell side of every
# difference between the distros, in one place (the Python side: skeleton_core.compat). Sourced by
# scripts/setup.sh and scripts/env.sh, never run; it only sets variables (prefix _kp_) and cleans
# the paths of this project's other distro out of the environment.
#
#   ROS_DISTRO=jazzy (default) | kilted   the pip-wheels venvs this project pins and tests
#                                         (requirements-<distro>.txt, third_party/ros2/<distro>/)
#   ROS_DISTRO=<any> with /opt/ros/<any>  that system ROS 2 (e.g. humble, rolling)
#   ROS_DISTRO_PATH=/opt/ros/<distro>     this system ROS 2, whatever ROS_DISTRO says
#
# Without ROS_DISTRO a system ROS 2 wins over the wheels (/opt/ros/jazzy, kilted, humble, rolling,
# in that order), as on a lab PC; without one the Jazzy wheels are used.
#
# Sets: _kp_root _kp_distro _kp_underlay (a system ROS 2 prefix, or empty: the wheels) _kp_venv
#       _kp_reqs (requirements files of the venv) _kp_tools (launch tooling prefix, wheels only)
#       _kp_build _kp_install _kp_log (colcon bases, one per distro, so that switching rebuilds nothing)
# Fails (returns 1 with one line on stderr) for a distro it has neither wheels nor a system ROS for.

_kp_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_kp_wheel_distros="jazzy kilted"   # a directory in third_party/ros2/ and a requirements-<distro>.txt each
_kp_default_distro=jazzy

_kp_underlay=""
if [ -n "${ROS_DISTRO_PATH:-}" ]; then
  if [ ! -f "$ROS_DISTRO_PATH/setup.bash" ]; then
    echo "ROS_DISTRO_PATH=$ROS_DISTRO_PATH has no setup.bash (a ROS 2 install prefix like /opt/ros/jazzy)" >&2
    return 1
  fi
  _kp_underlay="$ROS_DISTRO_PATH"
  _kp_distro="$(basename "$ROS_DISTRO_PATH")"
elif [ -n "${ROS_DISTRO:-}" ]; then
  _kp_distro="$ROS_DISTRO"
  [ -f "/opt/ros/$_kp_distro/setup.bash" ] && _kp_underlay="/opt/ros/$_kp_distro"
else
  _kp_distro="$_kp_default_distro"
  for _kp_d in jazzy kilted humble rolling; do
    if [ -f "/opt/ros/$_kp_d/setup.bash" ]; then _kp_underlay="/opt/ros/$_kp_d"; _kp_distro="$_kp_d"; break; fi
  done
  unset _kp_d
fi
if [ -z "$_kp_underlay" ] && [[ " $_kp_wheel_distros " != *" $_kp_distro "* ]]; then
  echo "ROS_DISTRO=$_kp_distro: no /opt/ros/$_kp_distro and no pinned wheels for it (wheels: $_kp_wheel_distros)" >&2
  return 1
fi

_kp_venv="$_kp_root/.venv-$_kp_distro"
if [ -n "$_kp_underlay" ]; then
  _kp_reqs="requirements-py.txt"; _kp_tools=""
else
  _kp_reqs="requirements-$_kp_distro.txt requirements-py.txt"; _kp_tools="$_kp_venv/ros2-tools"
fi
_kp_build="$_kp_root/build/$_kp_distro"
_kp_install="$_kp_root/install/$_kp_distro"
_kp_log="$_kp_root/log/$_kp_distro"

# A shell that sourced env.sh for one distro and now asks for another (`ROS_DISTRO=kilted make test`
# after `source scripts/env.sh`) must not keep the first one's venv, tooling and overlay on its paths.
_kp_strip() {  # _kp_strip VAR: drop the entries under this project's venvs and install/ from $VAR
  local out="" entry
  local IFS=:
  for entry in ${!1:-}; do
    case "$entry" in
      "$_kp_root"/.venv*|"$_kp_root"/install|"$_kp_root"/install/*) ;;
      *) out="${out:+$out:}$entry" ;;
    esac
  done
  if [ -n "$out" ]; then export "$1=$out"; else unset "$1"; fi
}
for _kp_v in PATH PYTHONPATH AMENT_PREFIX_PATH CMAKE_PREFIX_PATH COLCON_PREFIX_PATH LD_LIBRARY_PATH \
             PKG_CONFIG_PATH; do
  _kp_strip "$_kp_v"
done
unset _kp_v
case "${VIRTUAL_ENV:-}" in "$_kp_root"/.venv*) unset VIRTUAL_ENV VIRTUAL_ENV_PROMPT ;; esac
unset -f _kp_strip

export ROS_DISTRO="$_kp_distro"
# DDS discovery stays on this machine (as skeleton_core.compat does for Python). Humble has no
# ROS_AUTOMATIC_DISCOVERY_RANGE; Jazzy and later deprecate ROS_LOCALHOST_ONLY (and warn when set).
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
case "$_kp_distro" in
  foxy|galactic|humble) export ROS_LOCALHOST_ONLY=1 ;;
  *) unset ROS_LOCALHOST_ONLY ;;
esac
