#!/usr/bin/env bash
# Idempotent bootstrap: ROS 2 underlay (system or pip wheels venv), Python deps, launch tooling,
# colcon build of the workspace. A second run with nothing changed takes about a second.
#   scripts/setup.sh            # everything
#   KP_SKIP_TOOLING=1 ...       # don't build the launch tooling from ../shared/ros2
# Environment: ROS2_TOOLING_SRC (default ../shared/ros2), ROS_DISTRO_PATH (pick /opt/ros/<distro>).
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

underlay=""
for d in ${ROS_DISTRO_PATH:-} /opt/ros/kilted /opt/ros/jazzy /opt/ros/humble /opt/ros/rolling; do
  [ -f "$d/setup.bash" ] && { underlay="$d"; break; }
done

py=${PYTHON:-python3}
stamp_of() { cat "$@" 2>/dev/null | sha256sum | cut -c1-16; }

# 1. venv -------------------------------------------------------------------------------------
if [ -n "$underlay" ]; then
  venv_args=(--system-site-packages); reqs=(requirements-py.txt)
  log "using system ROS 2 at $underlay"
else
  venv_args=(); reqs=(requirements.txt requirements-py.txt)
fi
want="$(stamp_of "${reqs[@]}" scripts/setup.sh) ${underlay:-wheels}"
if [ ! -f .venv/.kp-stamp ] || [ "$(cat .venv/.kp-stamp)" != "$want" ]; then
  log "creating/updating .venv (${reqs[*]}) — a few minutes the first time"
  [ -x .venv/bin/python ] || "$py" -m venv "${venv_args[@]}" .venv
  .venv/bin/python -m pip install -q --upgrade pip
  pip_args=(); for r in "${reqs[@]}"; do pip_args+=(-r "$r"); done
  .venv/bin/python -m pip install -q "${pip_args[@]}"
  echo "$want" > .venv/.kp-stamp
  rm -f install/.kp-stamp
fi

set +u
[ -n "$underlay" ] && source "$underlay/setup.bash"
source .venv/bin/activate
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
  tooling_src="${ROS2_TOOLING_SRC:-$root/../shared/ros2}"
  if [ -z "${KP_SKIP_TOOLING:-}" ] && [ -x "$tooling_src/build-into-venv.sh" ]; then
    if [ ! -f .venv/ros2-tools/.built ]; then log "building ROS 2 launch tooling from $tooling_src (~1 min)"; fi
    bash "$tooling_src/build-into-venv.sh" "$root/.venv/ros2-tools" >&2
    # the tooling script swaps lark-parser for lark; both provide `lark`, keep exactly one
  elif [ ! -f .venv/ros2-tools/.built ]; then
    log "no launch tooling source at $tooling_src: 'ros2 launch' and launch tests will be unavailable"
  fi
  set +u
  [ -f .venv/ros2-tools/local_setup.bash ] && source .venv/ros2-tools/local_setup.bash
  set -u
fi

# 3. colcon build (skipped when no package file changed) --------------------------------------
src_stamp="$( (find src -type f \( -name package.xml -o -name setup.py -o -name setup.cfg \
      -o -name CMakeLists.txt -o -name '*.msg' -o -name '*.srv' -o -name '*.launch.py' -o -name '*.yaml' \
      -o -name '*.rviz' \) -print0 | sort -z | xargs -0 sha256sum; \
      find src -maxdepth 3 -type d -print | sort; ls launch config 2>/dev/null; \
      echo "${underlay:-wheels}") | sha256sum | cut -c1-16)"
if [ ! -f install/.kp-stamp ] || [ "$(cat install/.kp-stamp)" != "$src_stamp" ]; then
  log "colcon build"
  colcon --log-base log build --symlink-install \
    --event-handlers console_direct- console_cohesion- console_stderr- status- summary+ \
    --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$(command -v python)" >&2 ||
    { log "colcon build failed; logs in $root/log/latest_build"; exit 1; }
  echo "$src_stamp" > install/.kp-stamp
fi
log "ready (${underlay:-pip wheels venv}$( [ -f .venv/ros2-tools/.built ] && echo ' + launch tooling'))"

# 4. (lifecycle, issue 29) the nodes' default motion database: they load it, never build it (make build-db)
[ -f "${KINECT_POSTURE_CACHE:-$root/cache}/motion_db.npz" ] || (set +u; source scripts/env.sh; python -m skeleton_data.database_cli --no-progress >&2) || log "make build-db failed: nodes will not configure without a database"
