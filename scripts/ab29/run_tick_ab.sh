#!/bin/bash
# Per-tick CPU of the physics library, OLD checkout against this one, alternated three times.
#   scripts/ab29/run_tick_ab.sh /path/to/old/checkout [distro]
# (the old checkout built with colcon and its env.sh working; both run with ROS_DISTRO=distro)
old=${1:?an old checkout}; distro=${2:-kilted}
new="$(cd "$(dirname "$0")/../.." && pwd)"
for rep in 1 2 3; do
  for side in old new; do
    for u in 1 2; do
      if [ "$side" = old ]; then d=$old; else d=$new; fi
      ( unset AMENT_PREFIX_PATH CMAKE_PREFIX_PATH COLCON_PREFIX_PATH PYTHONPATH VIRTUAL_ENV
        cd "$d" && export ROS_DISTRO=$distro && source scripts/env.sh >/dev/null 2>&1
        echo "$side rep$rep $(python "$new/scripts/ab29/sim_tick.py" "$u" 300)" )
    done
  done
done
