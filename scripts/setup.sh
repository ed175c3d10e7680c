#!/usr/bin/env bash
# Idempotent bootstrap: ROS 2 underlay (system or pip wheels venv), Python deps, launch tooling,
# colcon build of the workspace. A second run with nothing changed takes about a second.
#   scripts/setup.sh                       # ROS 2 Jazzy (or the system ROS 2 under /opt/ros)
#   ROS_DISTRO=kilted scripts/setup.sh     # ROS 2 Kilted
# Which distro and where its venv (.venv-<distro>), tooling and colcon build go: scripts/distro.sh.
# Nothing here needs ../shared: the launch tooling builds from third_party/ros2/<distro>/.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
log() { echo "[setup] $*" >&2; }

exec 9>"$root/.setup.lock"
flock 9   # parallel setups (several shells, tests) wait for each other

need_apt=()
for tool in cmake g++ make; do command -v "$tool" >/dev/null || need_apt+=("$tool"); done
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    log "installing ${need_apt[*]} with apt-get"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq cmake g++ make >/dev/null
  else
    log "missing ${need_apt[*]}: install them (sudo apt-get install cmake g++ make) and re-run"; exit 1
  fi
fi

# Optional: the OpenNI2 runtime for the driver's live Kinect source (Debian libopenni2-0). Installed
# only when root with apt-get and not yet present; skipped silently otherwise (nothing else needs it).
if ! { ls /usr/lib/*/libOpenNI2.so.0 || ls /usr/lib/libOpenNI2.so.0; } >/dev/null 2>&1 &&
   [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  log "installing libopenni2-0 (OpenNI2 runtime for source:=live) with apt-get"
  { DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libopenni2-0 >/dev/null 2>&1 ||
    { apt-get update -qq >/dev/null 2>&1 &&
      DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libopenni2-0 >/dev/null 2>&1; }; } ||
    log "libopenni2-0 could not be installed: the live source will say so; everything else works"
fi

set +u
# shellcheck source=distro.sh
source "$root/scripts/distro.sh" || exit 1
set -u
underlay="$_kp_underlay"; venv="$_kp_venv"; read -r -a reqs <<< "$_kp_reqs"

# The wheels are cp311 builds: their venv needs Python 3.11 (PYTHON= picks the interpreter).
py=${PYTHON:-python3}
if [ -z "$underlay" ] && ! "$py" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
  if command -v python3.11 >/dev/null; then py=python3.11; else
    log "the ROS 2 $_kp_distro wheels need Python 3.11 ($py is $("$py" -V 2>&1)): install python3.11 or set PYTHON="
    exit 1
  fi
fi
stamp_of() { cat "$@" 2>/dev/null | sha256sum | cut -c1-16; }

# 1. venv -------------------------------------------------------------------------------------
if [ -n "$underlay" ]; then
  venv_args=(--system-site-packages)
  log "ROS 2 $_kp_distro: the system install at $underlay"
else
  venv_args=()
fi
want="$(stamp_of "${reqs[@]}" scripts/setup.sh scripts/distro.sh) ${underlay:-wheels}"
if [ ! -f "$venv/.kp-stamp" ] || [ "$(cat "$venv/.kp-stamp")" != "$want" ]; then
  log "ROS 2 $_kp_distro: creating/updating ${venv#"$root"/} (${reqs[*]}) — a few minutes the first time"
  [ -x "$venv/bin/python" ] || "$py" -m venv "${venv_args[@]}" "$venv"
  "$venv/bin/python" -m pip install -q --upgrade pip
  pip_args=(); for r in "${reqs[@]}"; do pip_args+=(-r "$r"); done
  "$venv/bin/python" -m pip install -q "${pip_args[@]}" ||
    { log "pip could not install ${reqs[*]} into ${venv#"$root"/} (output above)"; exit 1; }
  echo "$want" > "$venv/.kp-stamp"
  rm -f "$_kp_install/.kp-stamp"
fi

set +u
[ -n "$underlay" ] && source "$underlay/setup.bash"
source "$venv/bin/activate"
set -u

if [ -z "$underlay" ]; then
  # Quirk 1: the wheels bake /opt/python/cp311-cp311 paths into their CMake files.
  py_include=$(python -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
  np_include=$(python -c 'import numpy; print(numpy.get_include())')
  { grep -rlZ --include='*.cmake' '/opt/python/cp311-cp311' "$VIRTUAL_ENV/share" 2>/dev/null || true; } |
    xargs -0 -r sed -i \
      -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$np_include#g" \
      -e "s#/opt/python/cp311-cp311/include/python3.11#$py_include#g"
  export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
  export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"

  # 2. launch tooling (ros2 launch, launch_testing, launch_pytest, ros2 CLI, tf2_msgs) ----------
  if [ ! -f "$_kp_tools/.built" ]; then
    log "building the ROS 2 $_kp_distro launch tooling from third_party/ros2/$_kp_distro (~1 min)"
  fi
  bash third_party/ros2/build-into-venv.sh "$_kp_distro" "$_kp_tools" >&2 ||
    { log "the launch tooling did not build (output above)"; exit 1; }
  set +u
  source "$_kp_tools/local_setup.bash"
  set -u
fi

# 3. colcon build (skipped when no package file changed) --------------------------------------
# REP-155's hri_msgs: the underlay's, else built from third_party/hri_msgs (its README)
msg_src=(); [ -n "$underlay" ] && [ -d "$underlay/share/hri_msgs" ] ||
  msg_src=("$(bash third_party/hri_msgs/unpack.sh "$_kp_build/third_party")")
src_stamp="$( (cat third_party/hri_msgs/SHA256SUMS; echo "${msg_src[*]}"; \
      find src -type f \( -name package.xml -o -name setup.py -o -name setup.cfg \
      -o -name CMakeLists.txt -o -name '*.msg' -o -name '*.srv' -o -name '*.launch.py' -o -name '*.yaml' \
      -o -name '*.rviz' \) -print0 | sort -z | xargs -0 sha256sum; \
      find src -maxdepth 3 -type d -name __pycache__ -prune -o -type d -print | sort; \
      ls -I __pycache__ launch config 2>/dev/null; \
      echo "${underlay:-wheels}") | sha256sum | cut -c1-16)"
if [ ! -f "$_kp_install/.kp-stamp" ] || [ "$(cat "$_kp_install/.kp-stamp")" != "$src_stamp" ]; then
  log "colcon build (${_kp_install#"$root"/})"
  colcon --log-base "$_kp_log" build --symlink-install --base-paths src "${msg_src[@]}" \
    --build-base "$_kp_build" --install-base "$_kp_install" \
    --event-handlers console_direct- console_cohesion- console_stderr- status- summary+ \
    --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$(command -v python)" >&2 ||
    { log "colcon build failed; logs in $_kp_log/latest_build"; exit 1; }
  echo "$src_stamp" > "$_kp_install/.kp-stamp"
fi
log "ready: ROS 2 $_kp_distro (${underlay:-pip wheels in ${venv#"$root"/} + launch tooling})"

# 4. (issue 29) the nodes' default motion database: they load it, never build it (make build-db)
[ -f "${KINECT_POSTURE_CACHE:-$root/cache}/motion_db.npz" ] || (set +u; source scripts/env.sh; python -m skeleton_data.database_cli --no-progress >&2) || log "make build-db failed: nodes will not configure without a database"
